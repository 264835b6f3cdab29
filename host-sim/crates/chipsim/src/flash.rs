//! How long the STM32F405's flash is busy, from the datasheet (DS8626, "Flash memory
//! programming" table): a wrapper around any NOR flash that adds each erase's and program's
//! duration to a shared counter. On the single-bank F405 every flash read — instruction
//! fetches and vector fetches included — waits while the flash is busy (RM0090 §3.5), so the
//! harness turns that time into a stall of the simulated core.

use std::cell::Cell;
use std::rc::Rc;

use embedded_storage::nor_flash::{ErrorType, NorFlash, ReadNorFlash};

/// Durations of the flash operations, µs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FlashTiming {
    /// One sector erase (the calibration slots are 128 KiB sectors).
    pub sector_erase_us: u64,
    /// One byte programmed (the driver programs at x8, PSIZE = 00).
    pub byte_program_us: u64,
}

impl FlashTiming {
    /// Worst case: t_ERASE128KB 2 s maximum at x32 (the driver's erase parallelism), t_prog
    /// 100 µs maximum per byte at x8.
    pub const MAX: FlashTiming = FlashTiming {
        sector_erase_us: 2_000_000,
        byte_program_us: 100,
    };
}

/// `F` with every erase and program adding its duration to `busy_us`.
pub struct TimedFlash<F> {
    pub flash: F,
    pub timing: FlashTiming,
    /// Total time the flash was busy (the core stalled), µs.
    pub busy_us: Rc<Cell<u64>>,
    /// Sector erases run.
    pub erases: Rc<Cell<u32>>,
}

impl<F> TimedFlash<F> {
    pub fn new(flash: F, timing: FlashTiming) -> Self {
        Self {
            flash,
            timing,
            busy_us: Rc::default(),
            erases: Rc::default(),
        }
    }
}

impl<F: ErrorType> ErrorType for TimedFlash<F> {
    type Error = F::Error;
}

impl<F: ReadNorFlash> ReadNorFlash for TimedFlash<F> {
    const READ_SIZE: usize = F::READ_SIZE;
    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), F::Error> {
        self.flash.read(offset, bytes)
    }
    fn capacity(&self) -> usize {
        self.flash.capacity()
    }
}

impl<F: NorFlash> NorFlash for TimedFlash<F> {
    const WRITE_SIZE: usize = F::WRITE_SIZE;
    const ERASE_SIZE: usize = F::ERASE_SIZE;
    fn erase(&mut self, from: u32, to: u32) -> Result<(), F::Error> {
        // One slot is one sector on the board, whatever the host flash's block size.
        self.erases.set(self.erases.get() + 1);
        self.busy_us
            .set(self.busy_us.get() + self.timing.sector_erase_us);
        self.flash.erase(from, to)
    }
    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), F::Error> {
        self.busy_us
            .set(self.busy_us.get() + bytes.len() as u64 * self.timing.byte_program_us);
        self.flash.write(offset, bytes)
    }
}
