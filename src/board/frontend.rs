//! The real front-end board: HSE 8 MHz → PLL 168 MHz (HSI fallback after a 100 ms crystal
//! timeout), USART1 (PA9/PA10) to the lab PC, the ADS1262 alone on SPI1 in mode 1, the AD7124-4
//! alone on SPI2 in mode 3, ADS1262 DRDY on PC4 (EXTI4), the independent watchdog, defmt over
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
    gpio::{Edge, Input, Output, PushPull, PA4, PB12, PC4},
    pac,
    prelude::*,
    rcc::Config,
    spi::Spi,
    watchdog::IndependentWatchdog,
};

use super::{Fatal, Parts};
use accomp::acquisition::{board as bus, AdsSequencer, InterruptDrdy, RtdSequencer};
use accomp::drivers::ad7124::{Ad7124, Ad7124Config};
use accomp::drivers::ads1262::{Ads1262, Ads1262Config};
use accomp::protocol::{Board, BootReport};

/// Board reported in READY and Info.
pub const BOARD: Board = Board::Frontend;

/// This board has converters: the acquisition tasks run.
pub const HAS_ADCS: bool = true;

/// Core clock after the PLL (crystal or HSI); SysTick runs from it.
pub const SYSTICK_HZ: u32 = 168_000_000;

/// How long the crystal gets to start (ST's HAL uses the same HSE_STARTUP_TIMEOUT, 100 ms).
const HSE_TIMEOUT_MS: u32 = 100;

/// Independent watchdog period. Longer than the slowest thing the firmware may legitimately do
/// without progress: a 128 KiB flash sector erase stalls the CPU up to 4 s (STM32F405
/// datasheet DS8626, t_ERASE128KB max at x8, the parallelism the flash driver uses), and a DRDY
/// timeout plus re-init takes < 2 s at 5 SPS.
/// The LSI (17–47 kHz) makes the real period 5.6–15 s.
pub const WATCHDOG_MS: u32 = 8_000;

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

type AdsDevice = ExclusiveDevice<Spi<pac::SPI1>, PA4<Output<PushPull>>, CycleDelay>;
type RtdDevice = ExclusiveDevice<Spi<pac::SPI2>, PB12<Output<PushPull>>, CycleDelay>;

/// The ADS1262 sequencer (shared by the DRDY interrupt and its supervisor task).
pub type AdsAcquisition = AdsSequencer<AdsDevice, InterruptDrdy, CycleDelay>;
/// The AD7124-4 sequencer (owned by the RTD task).
pub type RtdAcquisition = RtdSequencer<RtdDevice, InterruptDrdy, CycleDelay>;

/// The ADS1262 DRDY input (PC4, EXTI4, falling edge).
pub type DrdyPin = PC4<Input>;

/// Clears the EXTI4 pending bit (first thing in the DRDY handler).
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

/// Clocks (crystal or HSI fallback), USART1 115200 8N1, SPI1 (ADS1262, mode 1) and SPI2
/// (AD7124, mode 3) at the frequencies of [`accomp::acquisition::board`], the two sequencers
/// (they initialise their converters from their first tick), DRDY falling edge on PC4, TIM2 as
/// the time base; the watchdog is started first, before the clocks.
pub fn init(mut dp: pac::Peripherals) -> Parts {
    let reset_cause = take_reset_cause(&dp.RCC);
    // The watchdog first: it runs on the LSI, independent of the clock setup below, so a hang
    // there (a PLL that never locks) resets the MCU instead of hanging it.
    let mut watchdog = IndependentWatchdog::new(dp.IWDG);
    watchdog.stop_on_debug(&dp.DBGMCU, true);
    watchdog.start(WATCHDOG_MS.millis());
    let crystal = start_crystal(&dp.RCC);
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

    let (tx, rx) = super::uart1(dp.USART1, (gpioa.pa9, gpioa.pa10), &mut rcc);

    // One bus per converter, each in its datasheet's mode: no mode switching, no sharing, no
    // lock between the DRDY interrupt and the RTD task.
    let spi1 = dp.SPI1.spi(
        (Some(gpioa.pa5), Some(gpioa.pa6), Some(gpioa.pa7)),
        bus::ADS1262_BUS.mode,
        bus::ADS1262_BUS.sclk_hz.Hz(),
        &mut rcc,
    );
    let spi2 = dp.SPI2.spi(
        (Some(gpiob.pb13), Some(gpiob.pb14), Some(gpiob.pb15)),
        bus::AD7124_BUS.mode,
        bus::AD7124_BUS.sclk_hz.Hz(),
        &mut rcc,
    );
    // CS pins are driven high here (GPIO writes are infallible).
    let Ok(ads_dev) = ExclusiveDevice::new(spi1, gpioa.pa4.into_push_pull_output(), CycleDelay);
    let Ok(rtd_dev) = ExclusiveDevice::new(spi2, gpiob.pb12.into_push_pull_output(), CycleDelay);

    // Neither converter is touched here: each sequencer initialises its chip in steps from its
    // first tick (reset, then the configuration on a later tick), so nothing waits at boot
    // either, and a chip that fails to start is retried while the frames say why.
    let ads = AdsSequencer::new(Ads1262::new(
        ads_dev,
        InterruptDrdy,
        CycleDelay,
        Ads1262Config::board_default(),
    ));
    let rtd = RtdSequencer::new(Ad7124::new(
        rtd_dev,
        InterruptDrdy,
        CycleDelay,
        Ad7124Config::board_default(),
    ));

    let mut drdy = gpioc.pc4.into_pull_up_input();
    drdy.make_interrupt_source(&mut syscfg);
    drdy.trigger_on_edge(&mut dp.EXTI, Edge::Falling);
    drdy.enable_interrupt(&mut dp.EXTI);

    start_time_base(&rcc, &dp.TIM2);

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
        },
    }
}

/// TIM2's kernel clock: APB1 (42 MHz) × 2, since the APB1 prescaler is not 1 (RM0090 §6.2,
/// "the timer clock frequencies are twice the APB frequency").
const TIM2_CLOCK_HZ: u32 = 2 * bus::APB1_HZ;

/// TIM2 as the time base: 32-bit up-counter at 1 MHz, free running over its whole range
/// (RM0090 §18: PSC divides by PSC + 1, loaded at the update event UG forces).
fn start_time_base(rcc: &pac::RCC, tim2: &pac::TIM2) {
    // Through the HAL's Rcc (it derefs to the RCC registers): APB1ENR.TIM2EN.
    rcc.apb1enr().modify(|_, w| w.tim2en().set_bit());
    tim2.psc()
        .write(|w| w.psc().set((TIM2_CLOCK_HZ / 1_000_000 - 1) as u16));
    tim2.arr().write(|w| w.arr().set(u32::MAX));
    tim2.egr().write(|w| w.ug().set_bit());
    tim2.cr1().modify(|_, w| w.cen().set_bit());
}

/// The time base's count in µs (wraps every 71.6 min; `accomp::timebase` extends it).
pub fn time_base_count() -> Option<u32> {
    // SAFETY: a read of the counter register of a timer this module configured and nothing
    // else writes; reading CNT has no side effect.
    Some(unsafe { (*pac::TIM2::ptr()).cnt().read().bits() })
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
    // source HSI, Q 7.
    rcc.pllcfgr()
        .write(|w| unsafe { w.bits(16 | (336 << 6) | (7 << 24)) });
    rcc.cr().modify(|_, w| w.pllon().set_bit());
    let mut polls = 0;
    while rcc.cr().read().pllrdy().bit_is_clear() && polls < CLOCK_POLLS {
        polls += 1;
    }
    if rcc.cr().read().pllrdy().bit_is_set() {
        rcc.cfgr().modify(|_, w| w.sw().pll());
        let mut polls = 0;
        while !rcc.cfgr().read().sws().is_pll() && polls < CLOCK_POLLS {
            polls += 1;
        }
    }
}

/// Logs the failure and resets: on the bench a reboot is the only way back.
pub fn fatal(reason: Fatal) -> ! {
    defmt::error!("fatal: {}", reason);
    cortex_m::peripheral::SCB::sys_reset()
}

/// A panic resets the MCU (the watchdog would too, 8 s later); the next boot reports
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
