//! How long the STM32F405's flash is busy, from the datasheet (DS8626, "Flash memory
//! programming" table): a wrapper around any NOR flash that adds each erase's and program's
//! duration to a shared counter. On the single-bank F405 every flash read — instruction
//! fetches and vector fetches included — waits while the flash is busy (RM0090 §3.5), so the
//! harness turns that time into a stall of the simulated core.

use std::cell::Cell;
use std::rc::Rc;

use accomp::storage::{Watched, Watcher};
use embedded_storage::nor_flash::ErrorType;

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

/// `F` with every erase and program adding its duration to `busy_us` ([`timed`]).
pub type TimedFlash<F> = Watched<F, FlashClock>;

/// What [`TimedFlash`] adds to a flash: how long it was busy, and the erases run.
pub struct FlashClock {
    pub timing: FlashTiming,
    /// Total time the flash was busy (the core stalled), µs.
    pub busy_us: Rc<Cell<u64>>,
    /// Sector erases run.
    pub erases: Rc<Cell<u32>>,
}

/// `flash`, timed by `timing`.
pub fn timed<F>(flash: F, timing: FlashTiming) -> TimedFlash<F> {
    Watched {
        flash,
        watcher: FlashClock {
            timing,
            busy_us: Rc::default(),
            erases: Rc::default(),
        },
    }
}

impl<F: ErrorType> Watcher<F> for FlashClock {
    fn before_erase(&mut self, _from: u32, _to: u32) -> Result<(), F::Error> {
        // One slot is one sector on the board, whatever the host flash's block size.
        self.erases.set(self.erases.get() + 1);
        self.busy_us
            .set(self.busy_us.get() + self.timing.sector_erase_us);
        Ok(())
    }

    fn before_write(&mut self, _offset: u32, bytes: &[u8]) -> Result<(), F::Error> {
        self.busy_us
            .set(self.busy_us.get() + bytes.len() as u64 * self.timing.byte_program_us);
        Ok(())
    }
}
