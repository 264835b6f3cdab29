//! The STM32F405's internal flash as the calibration store's NOR flash (sectors 9, 10, 11).
//!
//! The HAL's `UnlockedFlash` implements `NorFlash` but borrows `LockedFlash` for as long as it
//! lives, and the store must own its flash for the whole run. [`InternalFlash`] owns the
//! `LockedFlash` and unlocks it only for the duration of one erase or program, so a stray write
//! anywhere else in the firmware still hits a locked controller.

use embedded_storage::nor_flash::{
    check_erase, check_read, check_write, ErrorType, NorFlash, NorFlashError, NorFlashErrorKind,
    ReadNorFlash,
};
use stm32f4xx_hal::flash::{self, FlashExt, LockedFlash};
use stm32f4xx_hal::pac;

use accomp::storage::SlotLayout;

/// The calibration flash of this board.
pub type Flash = InternalFlash;

/// Sectors 9 (0x080A_0000), 10 and 11; memory.x keeps the program below them.
pub const SLOT_LAYOUT: SlotLayout = SlotLayout::STM32F405_SECTORS_9_11;

/// Why a flash operation failed.
#[derive(Debug, Clone, Copy)]
pub enum InternalFlashError {
    /// Refused before reaching the controller (alignment, bounds).
    Refused(NorFlashErrorKind),
    /// The flash controller reported an error (sequence, parallelism, protection, …).
    Controller(flash::Error),
}

impl NorFlashError for InternalFlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            InternalFlashError::Refused(k) => *k,
            InternalFlashError::Controller(e) => e.kind(),
        }
    }
}

/// Internal flash, locked except during one erase or program.
pub struct InternalFlash {
    flash: LockedFlash,
}

impl InternalFlash {
    /// Takes the flash controller.
    pub fn new(flash: pac::FLASH) -> Self {
        InternalFlash {
            flash: LockedFlash::new(flash),
        }
    }
}

impl ErrorType for InternalFlash {
    type Error = InternalFlashError;
}

impl ReadNorFlash for InternalFlash {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        // The HAL slices the memory map without a bounds check: check here, never panic.
        check_read(self, offset, bytes.len()).map_err(InternalFlashError::Refused)?;
        let start = offset as usize;
        let src = self
            .flash
            .read()
            .get(start..start + bytes.len())
            .ok_or(InternalFlashError::Refused(NorFlashErrorKind::OutOfBounds))?;
        bytes.copy_from_slice(src);
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.flash.len()
    }
}

impl NorFlash for InternalFlash {
    /// The HAL programs at x8 parallelism (PSIZE = 8 bits), one byte per program operation.
    const WRITE_SIZE: usize = 1;
    /// The largest sector; sectors 10 and 11 are exactly this size.
    const ERASE_SIZE: usize = 128 * 1024;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        check_erase(self, from, to).map_err(InternalFlashError::Refused)?;
        // Locked again when `unlocked` drops at the end of this statement.
        NorFlash::erase(&mut self.flash.unlocked(), from, to)
            .map_err(InternalFlashError::Controller)
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        check_write(self, offset, bytes.len()).map_err(InternalFlashError::Refused)?;
        NorFlash::write(&mut self.flash.unlocked(), offset, bytes)
            .map_err(InternalFlashError::Controller)
    }
}
