//! QEMU `netduinoplus2` board: HSI clock, USART1 on the first `-serial`, samples injected as
//! frames, defmt over semihosting, and every fatal path ends QEMU with a distinct exit code.

use cortex_m_rt::{exception, ExceptionFrame};
use defmt_semihosting as _;
use stm32f4xx_hal::{
    pac,
    prelude::*,
    rcc::Config,
    serial::{self, Serial},
};

use super::{Fatal, Parts};
use accomp::acquisition::{AdsReading, RtdReading};
use accomp::drivers::ads1262::DataRate;
use accomp::protocol::{Board, BootReport};
use accomp::storage::{RamFlash, SlotLayout};

/// Board reported in READY and Info.
pub const BOARD: Board = Board::Qemu;

/// QEMU clocks SysTick at 168 MHz whatever RCC says (qemu-notes.md), so that is the figure the
/// monotonic needs to count milliseconds.
pub const SYSTICK_HZ: u32 = 168_000_000;

/// Bytes per calibration slot in RAM flash: one 1 KiB erase block holds the 444-byte slot image
/// and its commit marker (docs/storage.md); three slots.
const SLOT_BYTES: usize = 1024;

/// RAM standing in for flash (QEMU's STM32 flash model is not worth trusting, and a QEMU
/// restart is a power-off anyway): two slots, 4-byte program unit like the F405 at x32.
pub type RamCalibrationFlash = RamFlash<{ 3 * SLOT_BYTES }, SLOT_BYTES, 4>;

/// The calibration flash: a static RamFlash.
pub type Flash = &'static mut RamCalibrationFlash;

/// Slot A at 0, slot B at 1 KiB, slot C at 2 KiB.
pub const SLOT_LAYOUT: SlotLayout = SlotLayout::consecutive(SLOT_BYTES as u32);

/// Exit codes seen by the host launcher (QEMU's own exit status).
pub mod exit_code {
    /// A Rust panic.
    pub const PANIC: i32 = 101;
    /// A HardFault exception.
    pub const HARD_FAULT: i32 = 102;
    /// Base of [`super::Fatal`] start-up failures (code = 100 + variant).
    pub const FATAL_BASE: i32 = 100;
}

/// HSI clock (QEMU hangs on any HSE/PLL set-up), USART1 at 115200 8N1 with the RX interrupt on.
pub fn init(dp: pac::Peripherals) -> Parts {
    let mut rcc = dp.RCC.freeze(Config::hsi());
    let gpioa = dp.GPIOA.split(&mut rcc);
    let serial = match Serial::new(
        dp.USART1,
        (gpioa.pa9, gpioa.pa10),
        serial::Config::default().baudrate(115_200.bps()),
        &mut rcc,
    ) {
        Ok(s) => s,
        Err(_) => fatal(Fatal::Uart),
    };
    let (tx, mut rx) = serial.split();
    rx.listen();
    // Taken once, in init: None would mean init ran twice.
    let flash = match cortex_m::singleton!(: RamCalibrationFlash = RamCalibrationFlash::new()) {
        Some(f) => f,
        None => fatal(Fatal::Flash),
    };
    Parts {
        rx,
        tx,
        ads: AdsAcquisition,
        rtd: RtdAcquisition,
        drdy: DrdyPin,
        watchdog: Watchdog,
        flash,
        // QEMU models no RCC: no reset flags, and the HSI is what this board runs on by design.
        boot: BootReport {
            reset_cause: 0,
            clock_fallback: false,
        },
    }
}

/// No ADCs in QEMU: samples arrive as InjectSample frames; EXTI4 is never enabled and the
/// acquisition tasks are not spawned.
pub const HAS_ADCS: bool = false;

/// Stand-in for the ADS1262 sequencer (never called on this board).
pub struct AdsAcquisition;

impl AdsAcquisition {
    /// Never called (EXTI4 is not enabled).
    pub fn on_drdy(&mut self, _now_us: u64) -> Option<AdsReading> {
        None
    }
    /// Never called (the supervisor is not spawned).
    pub fn on_tick(&mut self, _now_us: u64) -> Option<AdsReading> {
        None
    }
    /// Nothing to reprogram.
    pub fn request_rate(&mut self, _rate: DataRate) {}
}

/// Stand-in for the AD7124 sequencer.
pub struct RtdAcquisition;

impl RtdAcquisition {
    /// Never called (the RTD task is not spawned).
    pub fn on_tick(&mut self, _now_us: u64) -> Option<RtdReading> {
        None
    }
    /// The RTD task's period if it ran.
    pub fn period_us(&self) -> u64 {
        100_000
    }
}

/// No DRDY pin.
pub struct DrdyPin;

/// Nothing to acknowledge.
pub fn acknowledge_drdy(_pin: &mut DrdyPin) {}

/// QEMU's netduinoplus2 has no IWDG model: feeding is a no-op (the watchdog task still checks
/// worker progress the same way).
pub struct Watchdog;

impl Watchdog {
    /// No-op.
    pub fn feed(&mut self) {}
}

/// Ends the QEMU run with the failure's code.
pub fn fatal(reason: Fatal) -> ! {
    defmt::error!("fatal: {}", reason);
    semihosting::process::exit(exit_code::FATAL_BASE + reason as i32)
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    cortex_m::interrupt::disable();
    if let Some(loc) = info.location() {
        defmt::error!("panic at {}:{}", loc.file(), loc.line());
    } else {
        defmt::error!("panic");
    }
    semihosting::process::exit(exit_code::PANIC)
}

#[exception]
unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
    defmt::error!("HardFault at pc={=u32:#x}", frame.pc());
    semihosting::process::exit(exit_code::HARD_FAULT)
}
