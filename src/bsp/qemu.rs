//! QEMU `netduinoplus2` board: HSI clock, USART1 on the first `-serial`, samples injected as
//! frames, defmt over semihosting, and every fatal path ends QEMU with a distinct exit code.
//!
//! The calibration flash is a [`RamFlash`] mirrored, operation by operation, into the host
//! file `accomp-flash.bin` in QEMU's working directory (semihosting file I/O): restored at
//! boot, written through after every erase and program. So the emulated board keeps its
//! tables across QEMU runs like a real board across power cycles, and killing QEMU at any
//! instant is a power cut between two flash operations (docs/storage.md, "QEMU board").

use cortex_m_rt::{exception, ExceptionFrame};
use defmt_semihosting as _;
use stm32f4xx_hal::{pac, prelude::*, rcc::Config};

use super::{Fatal, Parts};
use accomp::acquisition::{AdsReading, RtdReading};
use accomp::drivers::ads1262::DataRate;
use accomp::protocol::{Board, BootReport};
use accomp::storage::{RamFlash, RamFlashError, SlotLayout};
use embedded_storage::nor_flash::{ErrorType, NorFlash, ReadNorFlash};
use semihosting::io::{Read as _, Seek as _, SeekFrom, Write as _};

/// Board reported in READY and Info.
pub const BOARD: Board = Board::Qemu;

/// QEMU models no crystal and no Clock Security System.
pub fn clock_failed() -> bool {
    false
}

/// The kernel clock of QEMU's TIM2 model (`stm32f2xx-timer`): its `clock-frequency` property,
/// which the netduinoplus2 machine leaves at the model's default of 1 GHz (`info qtree` in the
/// QEMU monitor); the model counts QEMU's virtual nanoseconds × that clock / (PSC + 1), so
/// PSC = 999 gives the front-end's 1 MHz (docs/architecture.md, "QEMU").
const TIM2_CLOCK_HZ: u32 = 1_000_000_000;

/// QEMU clocks SysTick at 168 MHz whatever RCC says (docs/architecture.md), so that is the figure the
/// monotonic needs to count milliseconds.
pub const SYSTICK_HZ: u32 = 168_000_000;

/// Bytes per calibration slot in RAM flash: one 1 KiB erase block holds the 444-byte slot image
/// and its commit marker (docs/storage.md); three slots.
const SLOT_BYTES: usize = 1024;

/// RAM standing in for flash (QEMU's STM32 flash model is not worth trusting, and a QEMU
/// restart is a power-off anyway): two slots, 4-byte program unit like the F405 at x32.
pub type RamCalibrationFlash = RamFlash<{ 3 * SLOT_BYTES }, SLOT_BYTES, 4>;

/// The calibration flash: a static RamFlash persisted to the host.
pub type Flash = PersistentFlash;

/// Host file holding the flash image (relative to QEMU's working directory).
const FLASH_FILE: &core::ffi::CStr = c"accomp-flash.bin";
/// Test hook for the system-level power-cut test: if this file exists and holds "N Q" (two
/// decimal numbers), the first Q quarters of the (N+1)-th flash operation since boot reach the
/// file (Q = 0: none, 2: a torn half) and QEMU exits with [`exit_code::POWER_CUT`] — the power
/// goes during that operation.
const CUT_FILE: &core::ffi::CStr = c"accomp-power-cut.txt";

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
    /// The power-cut test hook fired (see `CUT_FILE`).
    pub const POWER_CUT: i32 = 120;
}

/// [`RamCalibrationFlash`] written through to [`FLASH_FILE`] after every operation.
pub struct PersistentFlash {
    ram: &'static mut RamCalibrationFlash,
    /// None when the host file could not be opened: the board then runs with RAM only.
    file: Option<semihosting::fs::File>,
    /// Flash operations persisted since boot.
    ops: u32,
    /// From [`CUT_FILE`]: the operation during which the power goes, and how many quarters of
    /// it are persisted.
    cut_at: Option<(u32, u32)>,
}

impl PersistentFlash {
    /// Restores the image from the host file (a missing or short file is a factory-new,
    /// erased part, and is created).
    fn open(ram: &'static mut RamCalibrationFlash) -> Self {
        let existing = semihosting::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(FLASH_FILE);
        let file = match existing {
            Ok(mut f) => {
                let mut image = [0xFFu8; 3 * SLOT_BYTES];
                let mut got = 0;
                while let Some(rest) = image.get_mut(got..) {
                    match f.read(rest) {
                        Ok(0) | Err(_) => break,
                        Ok(n) => got += n,
                    }
                }
                if got == image.len() {
                    ram.as_bytes_mut().copy_from_slice(&image);
                    defmt::info!("flash image restored from the host");
                } else {
                    defmt::warn!("flash image short ({} bytes): starting erased", got);
                }
                Some(f)
            }
            Err(_) => semihosting::fs::OpenOptions::new()
                .read(true)
                .write(true)
                .create(true)
                .truncate(true)
                .open(FLASH_FILE)
                .ok(),
        };
        if file.is_none() {
            defmt::warn!("no host flash file: tables live in RAM only");
        }
        let mut flash = PersistentFlash {
            ram,
            file,
            ops: 0,
            cut_at: read_cut_at(),
        };
        // A new or short file gets the whole (erased) image, so later offsets exist.
        if flash.file.is_some() {
            let len = flash.ram.as_bytes().len() as u32;
            flash.persist_range(0, len, false);
        }
        flash
    }

    fn persist(&mut self, from: u32, to: u32) {
        if let Some((op, quarters)) = self.cut_at.filter(|(op, _)| *op == self.ops) {
            // Power cut during this operation: only part of it reaches the cells.
            let part = (to - from) / 4 * quarters.min(4);
            self.persist_range(from, from + part, false);
            defmt::warn!("power-cut hook: exiting during flash operation {}", op);
            semihosting::process::exit(exit_code::POWER_CUT)
        }
        self.persist_range(from, to, true);
    }

    fn persist_range(&mut self, from: u32, to: u32, count: bool) {
        if count {
            self.ops = self.ops.wrapping_add(1);
        }
        let Some(file) = self.file.as_mut() else {
            return;
        };
        let Some(bytes) = self.ram.as_bytes().get(from as usize..to as usize) else {
            return;
        };
        let written = file.seek(SeekFrom::Start(u64::from(from))).is_ok() && write_all(file, bytes);
        if !written {
            defmt::warn!("host flash file write failed: tables kept in RAM only");
            self.file = None;
        }
    }
}

/// Writes all of `bytes`; false if the host refused some. `Write::write_all` does the same
/// with a slice index (`&buf[n..]`) whose bounds check would bring `core::fmt`'s integer
/// formatting into the firmware for a panic the host's byte counts never cause.
fn write_all(file: &mut semihosting::fs::File, mut bytes: &[u8]) -> bool {
    while !bytes.is_empty() {
        match file.write(bytes) {
            Ok(n) if n > 0 => bytes = bytes.get(n..).unwrap_or(&[]),
            _ => return false,
        }
    }
    true
}

/// The power-cut hook's operation number and persisted quarters, if the test asked for one.
fn read_cut_at() -> Option<(u32, u32)> {
    let mut f = semihosting::fs::File::open(CUT_FILE).ok()?;
    let mut buf = [0u8; 24];
    let n = f.read(&mut buf).ok()?;
    let text = core::str::from_utf8(buf.get(..n)?).ok()?;
    let mut words = text.split_whitespace();
    let op = words.next()?.parse().ok()?;
    let quarters = words.next().and_then(|w| w.parse().ok()).unwrap_or(2);
    Some((op, quarters))
}

impl ErrorType for PersistentFlash {
    type Error = RamFlashError;
}

impl ReadNorFlash for PersistentFlash {
    const READ_SIZE: usize = 1;
    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        self.ram.read(offset, bytes)
    }
    fn capacity(&self) -> usize {
        self.ram.capacity()
    }
}

impl NorFlash for PersistentFlash {
    const WRITE_SIZE: usize = RamCalibrationFlash::WRITE_SIZE;
    const ERASE_SIZE: usize = RamCalibrationFlash::ERASE_SIZE;
    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        self.ram.erase(from, to)?;
        self.persist(from, to);
        Ok(())
    }
    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        self.ram.write(offset, bytes)?;
        self.persist(offset, offset + bytes.len() as u32);
        Ok(())
    }
}

/// HSI clock (QEMU hangs on any HSE/PLL set-up), USART1 at 115200 8N1 with the RX interrupt on.
pub fn init(dp: pac::Peripherals) -> Parts {
    let mut rcc = dp.RCC.freeze(Config::hsi());
    let gpioa = dp.GPIOA.split(&mut rcc);
    let (tx, rx) = super::uart1(dp.USART1, (gpioa.pa9, gpioa.pa10), &mut rcc);
    super::start_time_base(&rcc, &dp.TIM2, TIM2_CLOCK_HZ);
    // Taken once, in init: None would mean init ran twice.
    let ram = match cortex_m::singleton!(: RamCalibrationFlash = RamCalibrationFlash::new()) {
        Some(f) => f,
        None => fatal(Fatal::Flash),
    };
    let flash = PersistentFlash::open(ram);
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
            // Set by `init` from the RAM kept across resets.
            boot_id: 0,
        },
    }
}

/// No ADCs in QEMU: samples arrive as InjectSample frames; EXTI1 is never enabled and the
/// acquisition tasks are not spawned.
pub const HAS_ADCS: bool = false;

/// Stand-in for the ADS1262 sequencer (never called on this board).
pub struct AdsAcquisition;

impl AdsAcquisition {
    /// Never called (EXTI1 is not enabled).
    pub fn on_drdy(&mut self, _now_us: u64) -> Option<AdsReading> {
        None
    }
    /// Never called (the supervisor is not spawned).
    pub fn on_tick(&mut self, _now_us: u64) -> Option<AdsReading> {
        None
    }
    /// Nothing to reprogram.
    pub fn request_rate(&mut self, _rate: DataRate) {}
    /// Never called (the DRDY interrupt is not enabled on this board).
    pub fn restart_pair(&mut self) {}
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

/// No DRDY edge to capture.
pub fn drdy_capture() -> Option<u32> {
    None
}

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
    super::log_panic(info);
    semihosting::process::exit(exit_code::PANIC)
}

#[exception]
unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
    defmt::error!("HardFault at pc={=u32:#x}", frame.pc());
    semihosting::process::exit(exit_code::HARD_FAULT)
}

/// UART receive half: read byte by byte from the USART1 interrupt. The front-end's DMA ring is
/// not used here: whether QEMU 7.2's STM32F405 emulates the DMA controller is unverified.
pub type UartRx = super::HalRx;

/// Next received byte, or None when the receive register is empty. A line error (overrun,
/// framing, noise) loses bytes: it is counted by kind (Info's loss counters) and the frame CRC
/// refuses the damaged frame.
pub fn read_byte(rx: &mut UartRx) -> Option<u8> {
    use stm32f4xx_hal::serial::Error as E;
    loop {
        match rx.read() {
            Ok(b) => return Some(b),
            Err(stm32f4xx_hal::nb::Error::WouldBlock) => return None,
            Err(stm32f4xx_hal::nb::Error::Other(E::Overrun)) => {
                super::UART_OVERRUNS.fetch_add(1, core::sync::atomic::Ordering::Relaxed);
            }
            Err(stm32f4xx_hal::nb::Error::Other(_)) => {
                super::UART_LINE_ERRORS.fetch_add(1, core::sync::atomic::Ordering::Relaxed);
            }
        }
    }
}
