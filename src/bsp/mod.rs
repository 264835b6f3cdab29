//! Board support package: the firmware glue for everything that differs between QEMU's
//! netduinoplus2 and the real front-end (the front-end's description is `accomp::board`).
//!
//! Each board provides: `BOARD`, `SYSTICK_HZ`, `HAS_ADCS`, `UartRx`/`UartTx`, the acquisition
//! types (`AdsAcquisition`, `RtdAcquisition`, `DrdyPin`, `acknowledge_drdy`, `drdy_capture`),
//! `Watchdog`, `init` (clocks, UART with the RX interrupt enabled, the TIM2 time base,
//! acquisition, watchdog), `fatal` (no way back), and the logger/panic plumbing (a panic never
//! ends in a HardFault loop).
//! The shared UART helpers are here because both boards use the HAL's USART1.

use core::sync::atomic::AtomicU32;

use stm32f4xx_hal::prelude::*;

#[cfg(feature = "board-frontend")]
mod frontend;
#[cfg(feature = "board-frontend")]
pub use frontend::*;
#[cfg(feature = "board-frontend")]
pub(crate) mod internal_flash;
#[cfg(feature = "board-frontend")]
pub use internal_flash::{Flash, SLOT_LAYOUT};

#[cfg(feature = "board-qemu")]
mod qemu;
#[cfg(feature = "board-qemu")]
pub use qemu::*;

/// The HAL's UART receive half (USART1 on both boards); each board wraps it in its `UartRx`
/// (QEMU: byte by byte from the interrupt; front-end: a DMA ring).
pub type HalRx = stm32f4xx_hal::serial::Rx<stm32f4xx_hal::pac::USART1>;
/// UART transmit half.
pub type UartTx = stm32f4xx_hal::serial::Tx<stm32f4xx_hal::pac::USART1>;

/// What a board hands to the application after `init`.
pub struct Parts {
    pub rx: UartRx,
    pub tx: UartTx,
    /// ADS1262 sequencer (accelerometer + tilt), booted.
    pub ads: AdsAcquisition,
    /// AD7124 sequencer (RTD), booted.
    pub rtd: RtdAcquisition,
    /// The ADS1262 DRDY interrupt pin.
    pub drdy: DrdyPin,
    /// The independent watchdog, running (QEMU: none).
    pub watchdog: Watchdog,
    /// The NOR flash holding the two calibration slots ([`SLOT_LAYOUT`]).
    pub flash: Flash,
    /// Reset cause and clock source, for Info.
    pub boot: accomp::protocol::BootReport,
}

/// Unrecoverable start-up failures, each with its own exit code under QEMU.
#[derive(Debug, Clone, Copy, defmt::Format)]
pub enum Fatal {
    /// The UART could not be configured.
    Uart = 3,
    /// The worker task could not be spawned.
    Spawn = 4,
    /// The PLL locked neither from the crystal nor from the HSI (front-end).
    #[cfg(feature = "board-frontend")]
    Clock = 6,
    /// The calibration flash could not be set up (QEMU: its RAM flash singleton was taken).
    #[cfg(feature = "board-qemu")]
    Flash = 5,
}

/// USART1 on PA9 (TX) / PA10 (RX) at 115200 8N1 with the RX interrupt on: the console of both
/// boards.
pub(crate) fn uart1(
    usart1: stm32f4xx_hal::pac::USART1,
    pins: (stm32f4xx_hal::gpio::PA9, stm32f4xx_hal::gpio::PA10),
    rcc: &mut stm32f4xx_hal::rcc::Rcc,
) -> (UartTx, HalRx) {
    let config = stm32f4xx_hal::serial::Config::default().baudrate(115_200.bps());
    let serial = match stm32f4xx_hal::serial::Serial::new(usart1, pins, config, rcc) {
        Ok(s) => s,
        Err(_) => fatal(Fatal::Uart),
    };
    let (tx, mut rx) = serial.split();
    rx.listen();
    (tx, rx)
}

/// The common start of both boards' panic handlers: interrupts off, where it happened logged.
pub(crate) fn log_panic(info: &core::panic::PanicInfo) {
    cortex_m::interrupt::disable();
    if let Some(loc) = info.location() {
        defmt::error!("panic at {}:{}", loc.file(), loc.line());
    } else {
        defmt::error!("panic");
    }
}

/// TIM2 as the time base of both boards: a 32-bit up-counter at 1 MHz, free running over its
/// whole range (RM0090 §18: PSC divides the kernel clock `kernel_hz` by PSC + 1, loaded at the
/// update event UG forces, which also clears the count). `accomp::timebase` extends it to 64
/// bits.
pub(crate) fn start_time_base(
    rcc: &stm32f4xx_hal::pac::RCC,
    tim2: &stm32f4xx_hal::pac::TIM2,
    kernel_hz: u32,
) {
    // APB1ENR.TIM2EN (the HAL's Rcc derefs to the RCC registers).
    rcc.apb1enr().modify(|_, w| w.tim2en().set_bit());
    tim2.psc()
        .write(|w| w.psc().set((kernel_hz / 1_000_000 - 1) as u16));
    tim2.arr().write(|w| w.arr().set(u32::MAX));
    tim2.egr().write(|w| w.ug().set_bit());
    tim2.cr1().modify(|_, w| w.cen().set_bit());
}

/// The time base's count in µs (wraps every 71.6 min; `accomp::timebase` extends it).
pub fn time_base_count() -> u32 {
    // SAFETY: a read of the counter register of the timer `start_time_base` configured, which
    // nothing else writes; reading CNT has no side effect.
    unsafe { (*stm32f4xx_hal::pac::TIM2::ptr()).cnt().read().bits() }
}

/// UART receiver overruns (SR.ORE) since boot.
pub static UART_OVERRUNS: AtomicU32 = AtomicU32::new(0);
/// UART bytes received with a framing or noise error (SR.FE / SR.NF) since boot.
pub static UART_LINE_ERRORS: AtomicU32 = AtomicU32::new(0);

/// What a boot keeps in RAM that survives a reset but not a power cycle: magic, then
/// (watchdog, brown-out) reset counts, then the boot id. Written once per boot, before
/// interrupts run.
#[link_section = ".uninit.accomp_resets"]
static mut KEPT_RESETS: core::mem::MaybeUninit<[u32; 3]> = core::mem::MaybeUninit::uninit();
const KEPT_MAGIC: u32 = 0xACC0_4E5F;

/// RAM the program never writes: after a power-on it holds the SRAM's power-up state, whose
/// unstable cells differ from one power-on to the next; hashed with the time base into the
/// power-on nonce of the boot id. (Under QEMU it is zero and the time base nearly constant:
/// boots of one QEMU process still differ by their count, a new QEMU process may repeat an id,
/// and the host then falls back to the board's uptime.)
#[link_section = ".uninit.accomp_power_on_noise"]
static mut POWER_ON_NOISE: core::mem::MaybeUninit<[u32; 32]> = core::mem::MaybeUninit::uninit();

/// What a boot learns from the RAM kept across resets.
#[derive(Clone, Copy)]
pub struct KeptAcrossResets {
    /// Independent-watchdog resets since power-on, this boot included.
    pub watchdog_resets: u16,
    /// Brown-out resets since power-on, this boot included.
    pub brownout_resets: u16,
    /// This boot's id (Info's `boot.boot_id`).
    pub boot_id: u32,
}

/// The reset counts since power-on including this boot (RCC_CSR flags in `boot`) and this
/// boot's id, and keeps them for the next boot.
pub fn keep_across_resets(boot: accomp::protocol::BootReport) -> KeptAcrossResets {
    // SAFETY: called once from `init`, before any task runs: nothing else touches the static.
    // Its bytes may be garbage after a power-on; the magic word decides whether they count.
    let cell = unsafe { &mut *core::ptr::addr_of_mut!(KEPT_RESETS) };
    let words = cell.as_mut_ptr().cast::<u32>();
    // SAFETY: the three words lie inside the static; volatile so the read of memory the
    // program never wrote in this boot is not assumed away.
    let (magic, counts, id) = unsafe {
        (
            core::ptr::read_volatile(words),
            core::ptr::read_volatile(words.add(1)),
            core::ptr::read_volatile(words.add(2)),
        )
    };
    let valid = magic == KEPT_MAGIC;
    let kept = valid.then_some(((counts >> 16) as u16, counts as u16));
    let (watchdog_resets, brownout_resets) = boot.counted_resets(kept);
    let boot_id = boot.next_boot_id(valid.then_some(id), power_on_nonce);
    // SAFETY: as above.
    unsafe {
        core::ptr::write_volatile(words, KEPT_MAGIC);
        core::ptr::write_volatile(
            words.add(1),
            u32::from(watchdog_resets) << 16 | u32::from(brownout_resets),
        );
        core::ptr::write_volatile(words.add(2), boot_id);
    }
    KeptAcrossResets {
        watchdog_resets,
        brownout_resets,
        boot_id,
    }
}

/// FNV-1a over the never-written RAM's power-up state, then the time base's count.
fn power_on_nonce() -> u32 {
    let noise = core::ptr::addr_of!(POWER_ON_NOISE).cast::<u32>();
    let mut h: u32 = 0x811C_9DC5;
    for i in 0..32 {
        // SAFETY: `i` < 32 stays inside the static, which nothing writes; volatile because the
        // compiler would otherwise treat memory never written as undefined.
        let w = unsafe { core::ptr::read_volatile(noise.add(i)) };
        h = (h ^ w).wrapping_mul(0x0100_0193);
    }
    (h ^ time_base_count()).wrapping_mul(0x0100_0193)
}

/// Sends bytes, blocking on the transmit register (115200 Bd: ~87 µs per byte).
pub fn write_all(tx: &mut UartTx, bytes: &[u8]) {
    for &b in bytes {
        // The HAL's only write error is impossible for u8 words; retrying is the safe answer.
        while tx.write(b).is_err() {}
    }
}
