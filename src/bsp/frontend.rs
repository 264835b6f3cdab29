//! The real front-end board: HSE 8 MHz → PLL 168 MHz (HSI fallback after a 100 ms crystal
//! timeout), USART1 (PA9/PA10) to the lab PC, the ADS1262 alone on SPI1 in mode 1, the AD7124-4
//! alone on SPI2 in mode 3, ADS1262 DRDY on PA1 (EXTI1, and TIM2_CH2 input capture for its time
//! stamp), the independent watchdog, defmt over
//! RTT, and a panic or HardFault that resets the MCU. Pin map in docs/drivers.md ("Front-end
//! board wiring"); not verified on hardware.
//!
//! The acquisition sequencing itself is the core's [`accomp::acquisition`] (tested on the host
//! against chip models); this file only builds the buses, pins and clocks it runs on.

use core::sync::atomic::{AtomicBool, Ordering};

use cortex_m_rt::{exception, ExceptionFrame};
use defmt_rtt as _;
use embedded_hal::delay::DelayNs;
use embedded_hal_bus::spi::ExclusiveDevice;
use stm32f4xx_hal::{
    gpio::{Alternate, Edge, Output, Pin, PinState, PushPull},
    pac,
    prelude::*,
    rcc::Config,
    spi::Spi,
    watchdog::IndependentWatchdog,
};

use super::{Fatal, Parts};
use accomp::acquisition::{AdsSequencer, InterruptDrdy, RtdSequencer};
use accomp::board::{self as bus, *};
use accomp::drivers::ad7124::Ad7124;
use accomp::drivers::ads1262::Ads1262;
use accomp::protocol::{Board, BootReport};
use accomp::rx_ring::RxRing;

/// Board reported in READY and Info.
pub const BOARD: Board = Board::Frontend;

/// This board has converters: the acquisition tasks run.
pub const HAS_ADCS: bool = true;

/// Core clock after the PLL (crystal or HSI); SysTick runs from it.
pub const SYSTICK_HZ: u32 = 168_000_000;

/// TIM2's kernel clock: APB1 (42 MHz) × 2, since the APB1 prescaler is not 1 (RM0090 §6.2,
/// "the timer clock frequencies are twice the APB frequency").
const TIM2_CLOCK_HZ: u32 = 2 * bus::APB1_HZ;

/// How long the crystal gets to start (ST's HAL uses the same HSE_STARTUP_TIMEOUT, 100 ms).
const HSE_TIMEOUT_MS: u32 = 100;

/// Independent watchdog period, 16 s nominal (prescaler 128, reload 4000 at the LSI's nominal
/// 32 kHz). Its shortest value, at the LSI's maximum 47 kHz (datasheet DS8626, "LSI oscillator
/// characteristics"), is 16 s × 32/47 = 10.9 s, and half of that, 5.45 s, covers the longest
/// stretch without a feed the firmware allows: 4.85 s (docs/drivers.md, "Faults, watchdog"),
/// mostly a 128 KiB sector erase that stalls the core (≤ 2 s at x32), which no code running
/// from flash can feed through. At the LSI's minimum 17 kHz a hang resets after ≤ 30 s.
pub const WATCHDOG_MS: u32 = 16_000;

/// Busy-wait delay from the core clock (SysTick belongs to the RTIC monotonic). Waits at least
/// the requested time. The drivers take one, but the sequencers never ask it for the reset
/// waits (they step over ticks instead); only the SPI devices' CS set-up could use it.
#[derive(Debug, Clone, Copy, Default)]
pub struct CycleDelay;

impl DelayNs for CycleDelay {
    fn delay_ns(&mut self, ns: u32) {
        let cycles = (u64::from(ns) * u64::from(SYSTICK_HZ)).div_ceil(1_000_000_000);
        cortex_m::asm::delay(u32::try_from(cycles).unwrap_or(u32::MAX));
    }
}

/// The HAL pin the board description names (`accomp::board`): a pin moved there must move in
/// `init` too, or the types disagree and the firmware does not build.
macro_rules! board_pin {
    ($pin:ident) => { Pin<{ $pin.port }, { $pin.number }> };
    ($pin:ident, $mode:ty) => { Pin<{ $pin.port }, { $pin.number }, $mode> };
}

type AdsCs = board_pin!(ADS1262_CS, Output<PushPull>);
type RtdCs = board_pin!(AD7124_CS, Output<PushPull>);
type AdsDevice = ExclusiveDevice<Spi<pac::SPI1>, AdsCs, CycleDelay>;
type RtdDevice = ExclusiveDevice<Spi<pac::SPI2>, RtdCs, CycleDelay>;

/// The ADS1262 sequencer (shared by the DRDY interrupt and its supervisor task).
pub type AdsAcquisition = AdsSequencer<AdsDevice, InterruptDrdy, CycleDelay>;
/// The AD7124-4 sequencer (owned by the RTD task).
pub type RtdAcquisition = RtdSequencer<RtdDevice, InterruptDrdy, CycleDelay>;

/// The ADS1262 DRDY input (PA1: TIM2_CH2 input capture, and EXTI1 on the falling edge).
pub type DrdyPin = board_pin!(ADS1262_DRDY, Alternate<ADS1262_DRDY_AF>);

/// Clears the EXTI1 pending bit (first thing in the DRDY handler).
pub fn acknowledge_drdy(pin: &mut DrdyPin) {
    pin.clear_interrupt_pending_bit();
}

/// The independent watchdog, started in [`init`].
pub struct Watchdog(IndependentWatchdog);

impl Watchdog {
    /// Reload the counter (only the watchdog task calls this, and only after progress).
    pub fn feed(&mut self) {
        self.0.feed();
    }
}

/// Reset flags (RCC_CSR[31:25]), then clear them so the next boot reports its own cause.
fn take_reset_cause(rcc: &pac::RCC) -> u8 {
    let csr = rcc.csr().read().bits();
    rcc.csr().modify(|_, w| w.rmvf().set_bit());
    (csr >> 25) as u8
}

/// Start the crystal and wait for HSERDY at most [`HSE_TIMEOUT_MS`]; on timeout switch it off
/// again (the PLL then runs from the 16 MHz HSI: same 168 MHz, ±1 % instead of crystal
/// accuracy, which the UART tolerates; Info reports it).
fn start_crystal(rcc: &pac::RCC) -> bool {
    rcc.cr().modify(|_, w| w.hseon().set_bit());
    for _ in 0..HSE_TIMEOUT_MS {
        if rcc.cr().read().hserdy().bit_is_set() {
            return true;
        }
        // The core still runs on the 16 MHz HSI here: 16 000 cycles = 1 ms.
        cortex_m::asm::delay(16_000);
    }
    rcc.cr().modify(|_, w| w.hseon().clear_bit());
    false
}

/// Whether the PLL locks from the crystal (`from_crystal`) or the HSI within [`CLOCK_POLLS`]
/// polls of PLLRDY (DS8626 "Main PLL characteristics": t_LOCK ≤ 200 µs; 10,000 polls take
/// ≥ 2.5 ms on the 16 MHz HSI the core runs on here). Factors 168 MHz from a 1 MHz VCO input
/// (M = source / 1 MHz, N 336, P 2, Q 7), as the CSS handler's. The PLL is switched off again
/// (wait bounded too): PLLCFGR may be written only while it is off (RM0090 §6.3.2), and the
/// HAL's `freeze` writes its own factors, then finds the PLL locking as it just did.
fn pll_locks(rcc: &pac::RCC, from_crystal: bool) -> bool {
    // SAFETY: PLLCFGR field values within their ranges (RM0090 §6.3.2), PLL off.
    rcc.pllcfgr()
        .write(|w| unsafe { w.bits(pllcfgr(from_crystal)) });
    rcc.cr().modify(|_, w| w.pllon().set_bit());
    let locked = poll(|| rcc.cr().read().pllrdy().bit_is_set());
    rcc.cr().modify(|_, w| w.pllon().clear_bit());
    poll(|| rcc.cr().read().pllrdy().bit_is_clear());
    locked
}

/// RCC_PLLCFGR for 168 MHz from a 1 MHz VCO input (RM0090 §6.3.2): M = 8 (the 8 MHz crystal,
/// PLLSRC = 1) or 16 (the 16 MHz HSI), N 336, P 2 (PLLP 00), Q 7 (48 MHz).
const fn pllcfgr(from_crystal: bool) -> u32 {
    let (m, source) = if from_crystal { (8, 1 << 22) } else { (16, 0) };
    m | (336 << 6) | source | (7 << 24)
}

/// Polls `done` at most [`CLOCK_POLLS`] times; true once it held.
fn poll(mut done: impl FnMut() -> bool) -> bool {
    (0..CLOCK_POLLS).any(|_| done())
}

/// Clocks (crystal or HSI fallback), USART1 115200 8N1, SPI1 (ADS1262, mode 1) and SPI2
/// (AD7124, mode 3) at the frequencies of [`accomp::board`], the two sequencers
/// (they initialise their converters from their first tick), DRDY falling edge on PA1 (EXTI1 and
/// TIM2_CH2 capture), TIM2 as the time base; the watchdog is started first, before the clocks.
pub fn init(mut dp: pac::Peripherals) -> Parts {
    let reset_cause = take_reset_cause(&dp.RCC);
    // The watchdog first: it runs on the LSI, independent of the clock setup below, so a hang
    // there (a PLL that never locks) resets the MCU instead of hanging it.
    let mut watchdog = IndependentWatchdog::new(dp.IWDG);
    watchdog.stop_on_debug(&dp.DBGMCU, true);
    watchdog.start(WATCHDOG_MS.millis());
    let mut crystal = start_crystal(&dp.RCC);
    // The HAL's `freeze` waits for PLLRDY without a bound: lock the PLL once here first, with a
    // bounded wait, from the source `freeze` will use.
    if crystal && !pll_locks(&dp.RCC, true) {
        dp.RCC.cr().modify(|_, w| w.hseon().clear_bit());
        crystal = false;
    }
    if !crystal && !pll_locks(&dp.RCC, false) {
        // A PLL that locks from neither source: the part is broken. Reset (and try again)
        // rather than hang; the bus, UART and time-base prescalers all assume 168 MHz.
        fatal(Fatal::Clock)
    }
    let config = if crystal {
        Config::hse(8.MHz())
    } else {
        Config::hsi()
    };
    let mut rcc = dp
        .RCC
        .freeze(config.sysclk(168.MHz()).pclk1(42.MHz()).pclk2(84.MHz()));
    if crystal {
        // Clock Security System: should the crystal stop, the hardware switches SYSCLK to the
        // HSI and raises the NMI ([`NonMaskableInt`] relocks the PLL on the HSI).
        rcc.cr().modify(|_, w| w.csson().set_bit());
    } else {
        defmt::error!(
            "HSE did not start in {} ms: running from HSI",
            HSE_TIMEOUT_MS
        );
    }
    if rcc.clocks.pclk2().raw() != bus::APB2_HZ || rcc.clocks.pclk1().raw() != bus::APB1_HZ {
        // The SPI prescalers below are exact only at these clocks.
        defmt::error!(
            "APB clocks {} / {} Hz differ from the SPI plan",
            rcc.clocks.pclk2().raw(),
            rcc.clocks.pclk1().raw()
        );
    }
    let mut syscfg = dp.SYSCFG.constrain(&mut rcc);
    let gpioa = dp.GPIOA.split(&mut rcc);
    let gpiob = dp.GPIOB.split(&mut rcc);
    let gpioc = dp.GPIOC.split(&mut rcc);

    let uart_pins: (board_pin!(UART_TX), board_pin!(UART_RX)) = (gpioa.pa9, gpioa.pa10);
    let (tx, rx) = super::uart1(dp.USART1, uart_pins, &mut rcc);
    let rx = start_rx_dma(&rcc, &dp.DMA2, rx);

    // One bus per converter, each in its datasheet's mode: no mode switching, no sharing, no
    // lock between the DRDY interrupt and the RTD task.
    let spi1_pins: (
        board_pin!(ADS1262_SCK),
        board_pin!(ADS1262_MISO),
        board_pin!(ADS1262_MOSI),
    ) = (gpioa.pa5, gpioa.pa6, gpioa.pa7);
    let spi2_pins: (
        board_pin!(AD7124_SCK),
        board_pin!(AD7124_MISO),
        board_pin!(AD7124_MOSI),
    ) = (gpiob.pb13, gpiob.pb14, gpiob.pb15);
    let spi1 = dp.SPI1.spi(
        (Some(spi1_pins.0), Some(spi1_pins.1), Some(spi1_pins.2)),
        bus::ADS1262_BUS.mode,
        bus::ADS1262_BUS.sclk_hz.Hz(),
        &mut rcc,
    );
    let spi2 = dp.SPI2.spi(
        (Some(spi2_pins.0), Some(spi2_pins.1), Some(spi2_pins.2)),
        bus::AD7124_BUS.mode,
        bus::AD7124_BUS.sclk_hz.Hz(),
        &mut rcc,
    );
    // CS pins are driven high here (GPIO writes are infallible).
    // Chip selects high *before* the pins become outputs (ODR first, then MODER): the reset ODR
    // is 0, so switching the mode first would pull CS low until `ExclusiveDevice::new` raised it
    // — a CS pulse with no clocks, which frames nothing and resets the chips' serial interface
    // in the middle of whatever they believe (SBAS661C "Chip Select (CS)"; AD7124 Rev. B
    // "Serial Interface"). Between transactions the bus manager raises CS only after the last
    // byte was received (the HAL's full-duplex write waits for RXNE of every byte), so no
    // transaction is cut short.
    let ads_cs: AdsCs = gpioa.pa4.into_push_pull_output_in_state(PinState::High);
    let rtd_cs: RtdCs = gpiob.pb12.into_push_pull_output_in_state(PinState::High);
    // START and CLKIN at a defined level from here on (see `accomp::board`): low.
    let _start: board_pin!(ADS1262_START, Output<PushPull>) =
        gpioc.pc5.into_push_pull_output_in_state(PinState::Low);
    let _clkin: board_pin!(ADS1262_CLKIN, Output<PushPull>) =
        gpioa.pa8.into_push_pull_output_in_state(PinState::Low);
    let Ok(ads_dev) = ExclusiveDevice::new(spi1, ads_cs, CycleDelay);
    let Ok(rtd_dev) = ExclusiveDevice::new(spi2, rtd_cs, CycleDelay);

    // Neither converter is touched here: each sequencer initialises its chip in steps from its
    // first tick (reset, then the configuration on a later tick), so nothing waits at boot
    // either, and a chip that fails to start is retried while the frames say why.
    let ads = AdsSequencer::new(Ads1262::new(
        ads_dev,
        InterruptDrdy,
        CycleDelay,
        ads1262_config(),
    ));
    let rtd = RtdSequencer::new(Ad7124::new(
        rtd_dev,
        InterruptDrdy,
        CycleDelay,
        ad7124_config(),
    ));

    let mut drdy: DrdyPin = gpioa
        .pa1
        .into_alternate::<ADS1262_DRDY_AF>()
        .internal_pull_up(true);
    drdy.make_interrupt_source(&mut syscfg);
    drdy.trigger_on_edge(&mut dp.EXTI, Edge::Falling);
    drdy.enable_interrupt(&mut dp.EXTI);

    super::start_time_base(&rcc, &dp.TIM2, TIM2_CLOCK_HZ);
    start_drdy_capture(&dp.TIM2);

    Parts {
        rx,
        tx,
        ads,
        rtd,
        drdy,
        watchdog: Watchdog(watchdog),
        flash: super::internal_flash::new(dp.FLASH),
        boot: BootReport {
            reset_cause,
            clock_fallback: !crystal,
            // Set by `init` from the RAM kept across resets.
            boot_id: 0,
        },
    }
}

/// Bytes of the UART receive ring. The DMA writes every received byte into it whatever the
/// core does (DMA2 reads USART1 on APB2 and writes SRAM1: no flash access, so a flash erase
/// that stalls the core does not stall it); bytes are lost only if the reader falls a whole
/// ring behind. What the reader can fall behind by: while the core runs, the USART1 interrupt
/// (priority 2) waits at most for the DRDY handler and a priority-2 task (an AD7124
/// re-configuration, ≈ 200 µs ≈ 3 bytes at 115,200 Bd); across a flash-erase stall (≤ 2 s) the
/// host can have sent only what it has in flight — at most 8 requests × 127 B (frame + leading
/// delimiter) = 1,016 B, since it sends no more before answers come — and 2,048 B holds two
/// such windows. At line rate 2,048 B is 178 ms of continuous input without a read.
const RX_RING_LEN: usize = 2048;

/// The ring the DMA writes (SRAM1, DMA-capable; memory.x leaves the CCM out).
static mut RX_RING: [u8; RX_RING_LEN] = [0; RX_RING_LEN];

/// DMA2 stream 2, channel 4: USART1_RX (RM0090 Table 43, "DMA2 request mapping").
const RX_STREAM: usize = 2;

/// UART receive half: USART1 → DMA2 stream 2 → [`RX_RING`], read by [`read_byte`]. The RXNE
/// interrupt stays enabled only to wake the reader (the ISR never reads USART_DR, the DMA
/// does); the ADS1262 supervisor also pends it every 20 ms, so a byte whose interrupt came
/// before its DMA transfer is read at the latest then.
pub struct UartRx {
    _hal: super::HalRx,
    ring: RxRing<RX_RING_LEN>,
    /// Ring position when a line error was last counted (the USART_SR error flags stay set until
    /// the DMA's next read of USART_DR, so one damaged byte is counted once).
    error_head: usize,
}

/// Circular DMA from USART1_DR into [`RX_RING`] (RM0090 §10.3.9 circular mode, §10.5.5
/// DMA_SxCR: CHSEL 4, priority high, byte to byte, memory increment, peripheral → memory),
/// then USART_CR3.DMAR (§30.6.6) so every received byte is a DMA request.
fn start_rx_dma(rcc: &pac::RCC, dma2: &pac::DMA2, hal: super::HalRx) -> UartRx {
    rcc.ahb1enr().modify(|_, w| w.dma2en().set_bit());
    let st = dma2.st(RX_STREAM);
    // SAFETY: the USART1 data register's address (RM0090 §30.6.2) and a static buffer only the
    // DMA writes; the stream is disabled (reset state) while it is configured.
    unsafe {
        st.par().write(|w| w.bits(pac::USART1::ptr() as u32 + 4));
        st.m0ar()
            .write(|w| w.bits(core::ptr::addr_of!(RX_RING) as u32));
        st.ndtr().write(|w| w.bits(RX_RING_LEN as u32));
        let cr = (4 << 25) | (0b10 << 16) | (1 << 10) | (1 << 8);
        st.cr().write(|w| w.bits(cr));
        // EN last, once the stream is configured (RM0090 §10.3.17, "Stream configuration
        // procedure", step 9).
        st.cr().write(|w| w.bits(cr | 1));
        (*pac::USART1::ptr())
            .cr3()
            .modify(|r, w| w.bits(r.bits() | (1 << 6)));
    }
    UartRx {
        _hal: hal,
        ring: RxRing::new(),
        error_head: 0,
    }
}

/// The next received byte from the DMA ring, or None when all are read. Line errors (USART_SR
/// ORE, FE, NF) are counted by kind, once per damaged stretch; the frame CRC refuses the
/// damaged frame.
pub fn read_byte(rx: &mut UartRx) -> Option<u8> {
    // SAFETY: reads of USART1_SR and of the stream's NDTR: no side effect on the DMA (reading
    // SR is half of the flag-clearing sequence, whose other half is the DMA's next DR read).
    let (sr, ndtr) = unsafe {
        (
            (*pac::USART1::ptr()).sr().read().bits(),
            (*pac::DMA2::ptr()).st(RX_STREAM).ndtr().read().bits(),
        )
    };
    let head = RxRing::<RX_RING_LEN>::head(ndtr);
    // ORE bit 3, NF bit 2, FE bit 1 (RM0090 §30.6.1).
    if sr & 0b1110 != 0 && head != rx.error_head {
        rx.error_head = head;
        let counter = if sr & 0b1000 != 0 {
            &super::UART_OVERRUNS
        } else {
            &super::UART_LINE_ERRORS
        };
        counter.fetch_add(1, Ordering::Relaxed);
    }
    let byte = rx.ring.next(ndtr, |i| {
        // SAFETY: `i` < RX_RING_LEN (RxRing's read position); a volatile read of a byte the DMA
        // wrote before it advanced NDTR past it.
        unsafe { core::ptr::read_volatile(core::ptr::addr_of!(RX_RING).cast::<u8>().add(i)) }
    });
    if byte.is_none() {
        rearm_if_stopped(rx);
    }
    byte
}

/// A transfer error (a bus fault on the stream's AHB access) makes the hardware clear the
/// stream's EN bit (RM0090 §10.3.18 "Error management"): reception would stop for good while
/// USART_DR fills and overruns. Once the bytes written before the stop are read, clear the
/// stream's flags (DMA_LIFCR bits 21:16, §10.5.3), reload NDTR and enable it again; the reader
/// follows it to slot 0. Counted as a receiver overrun: what arrived while it was stopped is lost.
fn rearm_if_stopped(rx: &mut UartRx) {
    // SAFETY: DMA2 stream 2 belongs to this receiver alone; while EN is 0 its NDTR is writable
    // (§10.5.6) and setting EN last follows §10.3.17's configuration order.
    unsafe {
        let dma2 = &*pac::DMA2::ptr();
        let st = dma2.st(RX_STREAM);
        let cr = st.cr().read().bits();
        if cr & 1 != 0 {
            return;
        }
        dma2.lifcr().write(|w| w.bits(0b11_1101 << 16));
        st.ndtr().write(|w| w.bits(RX_RING_LEN as u32));
        st.cr().write(|w| w.bits(cr | 1));
    }
    rx.ring.restart();
    super::UART_OVERRUNS.fetch_add(1, Ordering::Relaxed);
}

/// TIM2's channel 2 capturing the time base's count at each falling DRDY edge on PA1 (RM0090
/// §18.3.5 "Input capture mode").
fn start_drdy_capture(tim2: &pac::TIM2) {
    // CC2 as an input from TI2 (TIMx_CCMR1 CC2S = 01, §18.4.7), no input prescaler (IC2PSC 00:
    // every edge) and no filter (IC2F 0000: the ADS1262's DRDY is a push-pull CMOS output).
    // CC2S is writable only while CC2E is 0, so before the capture is enabled.
    // SAFETY: CCMR1 bits 15:8 are channel 2's; the value is a valid CC2S/IC2PSC/IC2F code.
    tim2.ccmr1_input()
        .modify(|r, w| unsafe { w.bits((r.bits() & !0xFF00) | (0b01 << 8)) });
    // Falling edge: CC2P = 1, CC2NP = 0; capture enabled: CC2E = 1 (TIMx_CCER, §18.4.9).
    // SAFETY: CCER bits 7:4 are channel 2's CC2NP, -, CC2P, CC2E.
    tim2.ccer()
        .modify(|r, w| unsafe { w.bits((r.bits() & !0xF0) | CCER_CC2P | CCER_CC2E) });
}

/// TIMx_CCER.CC2E: capture on channel 2 enabled (RM0090 §18.4.9).
const CCER_CC2E: u32 = 1 << 4;
/// TIMx_CCER.CC2P: with CC2NP = 0, capture on the falling edge of TI2 (RM0090 §18.4.9).
const CCER_CC2P: u32 = 1 << 5;
/// TIMx_SR.CC2IF: a capture happened since CCR2 was last read (RM0090 §18.4.5).
const SR_CC2IF: u32 = 1 << 2;
/// TIMx_SR.CC2OF: a capture happened while CC2IF was still set (RM0090 §18.4.5).
const SR_CC2OF: u32 = 1 << 10;
/// The TIMx_SR flags (UIF, CC1–4IF, TIF, CC1–4OF): all are cleared by writing 0 and kept by
/// writing 1, so writing this mask without one flag clears that flag alone (rc_w0).
const SR_FLAGS: u32 = 0x1E5F;

/// The count TIM2 latched at the last falling DRDY edge, if there was one since the last call.
/// Read in the DRDY handler *before* the counter itself ([`accomp::timebase::drdy_edge_time`]).
/// CC2IF says a capture is there; reading CCR2 clears it (RM0090 §18.4.5). Several edges
/// before the handler ran (a flash-erase stall) set CC2OF and leave the latest edge's count in
/// CCR2 — the conversion the handler is about to read, which the ADS1262 keeps until the next
/// one — so the overcapture is only cleared. None: no capture pending; the handler's own read
/// of the counter is the stamp then.
pub fn drdy_capture() -> Option<u32> {
    // SAFETY: TIM2 is configured in `start_time_base` and otherwise only read; reading SR and
    // CCR2 and clearing CC2OF touch only channel 2's capture state.
    let tim2 = unsafe { &*pac::TIM2::ptr() };
    let sr = tim2.sr().read().bits();
    if sr & SR_CC2IF == 0 {
        return None;
    }
    let capture = tim2.ccr2().read().bits();
    if sr & SR_CC2OF != 0 {
        // SAFETY: rc_w0 flags; every other flag is written 1 and so kept.
        tim2.sr().write(|w| unsafe { w.bits(SR_FLAGS & !SR_CC2OF) });
    }
    Some(capture)
}

/// The Clock Security System saw the crystal fail (the NMI ran).
static CLOCK_FAILED: AtomicBool = AtomicBool::new(false);

/// True once the crystal failed while running: the core runs from the HSI (±1 %).
pub fn clock_failed() -> bool {
    CLOCK_FAILED.load(Ordering::Relaxed)
}

/// Polls allowed for PLLRDY and for the clock switch in the NMI: at 16 MHz on the HSI the PLL
/// locks in ≈ 100 µs (datasheet t_LOCK ≤ 200 µs), far below 10 000 polls.
const CLOCK_POLLS: u32 = 10_000;

/// CSS: the crystal failed (RM0090 §6.2.7). The hardware has switched SYSCLK to the HSI and
/// turned the PLL off; the NMI repeats until CSSC is written. Relock the PLL on the HSI at the
/// same 168 MHz (16 MHz / M 16 × N 336 / P 2; Q 7 → 48 MHz), so the UART, SPI and TIM2 keep
/// their rates, every wait bounded, and record the event for Info.
// SAFETY (cortex-m-rt asks NMI handlers to be `unsafe fn`: an NMI can preempt critical
// sections): it touches only the RCC registers and an atomic flag, nothing a critical section
// of the application guards.
#[exception]
unsafe fn NonMaskableInt() {
    // SAFETY: the NMI owns the RCC while it runs; the application never touches these
    // registers after `init`.
    let rcc = unsafe { &*pac::RCC::ptr() };
    rcc.cir().modify(|_, w| w.cssc().set_bit());
    CLOCK_FAILED.store(true, Ordering::Relaxed);
    // SAFETY: PLLCFGR field values within their ranges (RM0090 §6.3.2): M 16, N 336, P /2,
    // source HSI, Q 7; the PLL is off (the CSS switched it off).
    rcc.pllcfgr().write(|w| unsafe { w.bits(pllcfgr(false)) });
    rcc.cr().modify(|_, w| w.pllon().set_bit());
    if poll(|| rcc.cr().read().pllrdy().bit_is_set()) {
        rcc.cfgr().modify(|_, w| w.sw().pll());
        poll(|| rcc.cfgr().read().sws().is_pll());
    }
}

/// Logs the failure and resets: on the bench a reboot is the only way back.
pub fn fatal(reason: Fatal) -> ! {
    defmt::error!("fatal: {}", reason);
    cortex_m::peripheral::SCB::sys_reset()
}

/// A panic resets the MCU (the watchdog would too, ≤ 30 s later); the next boot reports
/// SFTRSTF in Info's reset cause.
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    super::log_panic(info);
    cortex_m::peripheral::SCB::sys_reset()
}

#[exception]
unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
    defmt::error!("HardFault at pc={=u32:#x}", frame.pc());
    cortex_m::peripheral::SCB::sys_reset()
}
