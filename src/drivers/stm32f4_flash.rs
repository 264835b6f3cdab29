//! The STM32F405's embedded flash controller as an `embedded-storage` NOR flash, written from the
//! reference manual RM0090: §3.5 "Erase and program operations" (3.5.1 unlocking FLASH_CR, 3.5.2
//! parallelism, 3.5.3 sector erase, 3.5.4 programming) and §3.8 "Flash interface registers"
//! (FLASH_KEYR, FLASH_SR, FLASH_CR). Section numbers as in RM0090 Rev 4 (Doc ID 018909); later
//! revisions insert a section before them and number them §3.6 and §3.9. Generic over [`FlashRegisters`], so the same
//! sequence runs on the board (PAC registers, `bsp/internal_flash.rs`) and on the host against
//! a register-level model of the controller (`stm32f4_flash/model.rs`).
//!
//! Why not the HAL's `UnlockedFlash`: it never clears FLASH_SR's error flags. They are sticky
//! (rc_w1: set by hardware, cleared only by writing 1), so after one failed operation every later
//! erase or program read the old flag and failed until the next reset — a calibration could no
//! longer be loaded. Here every operation (1) waits for BSY = 0, (2) clears EOP and all error
//! flags, (3) runs, (4) reads the flags it caused and names them, and (5) leaves PG/SER cleared
//! and FLASH_CR locked, also on failure.

use core::sync::atomic::{compiler_fence, AtomicBool, Ordering};

use embedded_storage::nor_flash::{
    check_erase, check_read, check_write, ErrorType, NorFlash, NorFlashError, NorFlashErrorKind,
    ReadNorFlash,
};

/// FLASH_SR bits (RM0090 §3.8.4). The error flags and EOP are rc_w1.
pub mod sr {
    /// End of operation (only set with EOPIE; cleared here anyway).
    pub const EOP: u32 = 1 << 0;
    /// Operation error (set with ERRIE when an operation cannot run).
    pub const OPERR: u32 = 1 << 1;
    /// Write protection error: the address belongs to a write-protected sector.
    pub const WRPERR: u32 = 1 << 4;
    /// Programming alignment error: the data does not fit one 128-bit row.
    pub const PGAERR: u32 = 1 << 5;
    /// Programming parallelism error: the access size differs from PSIZE.
    pub const PGPERR: u32 = 1 << 6;
    /// Programming sequence error: a write to flash memory without FLASH_CR set up for it.
    pub const PGSERR: u32 = 1 << 7;
    /// Busy: an erase or program is in progress (read-only).
    pub const BSY: u32 = 1 << 16;
    /// Every flag a driver must clear before an operation.
    pub const ERRORS: u32 = OPERR | WRPERR | PGAERR | PGPERR | PGSERR;
}

/// FLASH_CR bits (RM0090 §3.8.5).
pub mod cr {
    /// Programming.
    pub const PG: u32 = 1 << 0;
    /// Sector erase.
    pub const SER: u32 = 1 << 1;
    /// Mass erase.
    pub const MER: u32 = 1 << 2;
    /// Sector number, bits 6:3.
    pub const SNB_SHIFT: u32 = 3;
    /// SNB mask.
    pub const SNB_MASK: u32 = 0xF << SNB_SHIFT;
    /// Program size, bits 9:8 (00 = x8, 01 = x16, 10 = x32, 11 = x64).
    pub const PSIZE_MASK: u32 = 0b11 << 8;
    /// PSIZE = 10: x32 parallelism.
    pub const PSIZE_X32: u32 = 0b10 << 8;
    /// Start an erase.
    pub const STRT: u32 = 1 << 16;
    /// Error interrupt enable (OPERR is only set when this is on).
    pub const ERRIE: u32 = 1 << 25;
    /// FLASH_CR locked (set by software, cleared by the KEYR sequence).
    pub const LOCK: u32 = 1 << 31;
}

/// FLASH_ACR bits (RM0090 §3.9.1).
pub mod acr {
    /// Instruction cache enable.
    pub const ICEN: u32 = 1 << 9;
    /// Data cache enable.
    pub const DCEN: u32 = 1 << 10;
    /// Instruction cache reset (only while ICEN = 0).
    pub const ICRST: u32 = 1 << 11;
    /// Data cache reset (only while DCEN = 0).
    pub const DCRST: u32 = 1 << 12;
}

/// FLASH_KEYR unlock sequence (RM0090 §3.5.1). A wrong key locks FLASH_CR until reset.
pub const KEY1: u32 = 0x4567_0123;
/// Second key.
pub const KEY2: u32 = 0xCDEF_89AB;

/// Main memory size of the STM32F405RG (1 MiB, sectors 0–11).
pub const FLASH_BYTES: usize = 1024 * 1024;

/// Sector number and size of the sector holding `offset` (RM0090 Table 5: 4 × 16 KiB, 64 KiB,
/// 7 × 128 KiB).
pub const fn sector_of(offset: u32) -> (u8, u32) {
    const K: u32 = 1024;
    if offset < 64 * K {
        ((offset / (16 * K)) as u8, 16 * K)
    } else if offset < 128 * K {
        (4, 64 * K)
    } else {
        ((4 + offset / (128 * K)) as u8, 128 * K)
    }
}

/// True from the start of an erase or program until the controller is idle again. An interrupt
/// that finds it set may have waited for the flash (the core stalls on every flash read
/// meanwhile, RM0090 §3.5): the DRDY handler drops the conversion it would have stamped late.
pub static OPERATION: AtomicBool = AtomicBool::new(false);

/// Access to the controller's registers and to the flash memory bus.
pub trait FlashRegisters {
    /// Reads FLASH_SR.
    fn sr(&mut self) -> u32;
    /// Writes FLASH_SR (1 clears an rc_w1 flag, 0 leaves it).
    fn clear_sr(&mut self, bits: u32);
    /// Reads FLASH_CR.
    fn cr(&mut self) -> u32;
    /// Writes FLASH_CR.
    fn set_cr(&mut self, value: u32);
    /// Writes FLASH_KEYR.
    fn key(&mut self, key: u32);
    /// A byte-wide bus write into the flash memory at `offset` from its base (with PG set, the
    /// controller programs it).
    fn write_byte(&mut self, offset: u32, byte: u8);
    /// Reads the flash memory from `offset`.
    fn read(&mut self, offset: u32, bytes: &mut [u8]);
    /// Reads FLASH_ACR.
    fn acr(&mut self) -> u32;
    /// Writes FLASH_ACR.
    fn set_acr(&mut self, value: u32);
}

/// What an erase or program can fail with: each FLASH_SR error flag named (RM0090 §3.8.4), plus
/// the refusals made before the controller is touched.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FlashError {
    /// Offset or length not aligned to WRITE_SIZE / ERASE_SIZE.
    NotAligned,
    /// Range outside the flash.
    OutOfBounds,
    /// FLASH_CR stayed locked after the key sequence.
    Locked,
    /// PGSERR: programming sequence error.
    ProgramSequence,
    /// PGPERR: programming parallelism error.
    ProgramParallelism,
    /// PGAERR: programming alignment error.
    ProgramAlignment,
    /// WRPERR: write-protected sector.
    WriteProtected,
    /// OPERR: operation error.
    Operation,
}

/// Each FLASH_SR flag has its own protocol code (63–68), so the host names what the controller
/// refused; the refusals made before the controller is touched are FlashFailed 0/1.
impl crate::protocol::FlashErrorReply for FlashError {
    fn reply(&self) -> crate::protocol::ErrorReply {
        use crate::protocol::ErrorCode as C;
        let code = match self {
            FlashError::NotAligned => return C::FlashFailed.reply(0),
            FlashError::OutOfBounds => return C::FlashFailed.reply(1),
            FlashError::ProgramSequence => C::FlashProgramSequence,
            FlashError::ProgramParallelism => C::FlashProgramParallelism,
            FlashError::ProgramAlignment => C::FlashProgramAlignment,
            FlashError::WriteProtected => C::FlashWriteProtected,
            FlashError::Operation => C::FlashOperation,
            FlashError::Locked => C::FlashLocked,
        };
        code.reply(0)
    }
}

impl FlashError {
    /// The error named by the flags of `sr`, most specific first (None if no error flag is set).
    pub const fn from_sr(sr: u32) -> Option<Self> {
        if sr & sr::WRPERR != 0 {
            Some(FlashError::WriteProtected)
        } else if sr & sr::PGAERR != 0 {
            Some(FlashError::ProgramAlignment)
        } else if sr & sr::PGPERR != 0 {
            Some(FlashError::ProgramParallelism)
        } else if sr & sr::PGSERR != 0 {
            Some(FlashError::ProgramSequence)
        } else if sr & sr::OPERR != 0 {
            Some(FlashError::Operation)
        } else {
            None
        }
    }

    /// For logs (defmt without `core::fmt`).
    pub const fn name(&self) -> &'static str {
        match self {
            FlashError::NotAligned => "NotAligned",
            FlashError::OutOfBounds => "OutOfBounds",
            FlashError::Locked => "Locked",
            FlashError::ProgramSequence => "PGSERR",
            FlashError::ProgramParallelism => "PGPERR",
            FlashError::ProgramAlignment => "PGAERR",
            FlashError::WriteProtected => "WRPERR",
            FlashError::Operation => "OPERR",
        }
    }
}

impl NorFlashError for FlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            FlashError::NotAligned | FlashError::ProgramAlignment => NorFlashErrorKind::NotAligned,
            FlashError::OutOfBounds => NorFlashErrorKind::OutOfBounds,
            _ => NorFlashErrorKind::Other,
        }
    }
}

/// The embedded flash, programmed at x8 parallelism (PSIZE = 00: valid over the whole 1.8–3.6 V
/// supply range, RM0090 Table 9; one byte per program operation), locked between operations.
pub struct Stm32f4Flash<R> {
    regs: R,
}

impl<R: FlashRegisters> Stm32f4Flash<R> {
    /// Takes the controller (it stays locked until an operation).
    pub fn new(regs: R) -> Self {
        Stm32f4Flash { regs }
    }

    /// The register access (tests inspect the model through it).
    pub fn registers(&mut self) -> &mut R {
        &mut self.regs
    }

    fn wait_ready(&mut self) -> u32 {
        // BSY clears when the operation ends (a sector erase: up to 4 s at x8, DS8626 t_ERASE128KB;
        // the CPU stalls on flash fetches meanwhile anyway). A controller that stays busy
        // forever is a dead part: the independent watchdog resets the MCU.
        loop {
            let s = self.regs.sr();
            if s & sr::BSY == 0 {
                return s;
            }
        }
    }

    /// Steps 1–2 of every operation: not busy, sticky flags cleared, FLASH_CR unlocked.
    fn begin(&mut self) -> Result<(), FlashError> {
        OPERATION.store(true, Ordering::Relaxed);
        // Set before the controller is touched (no instruction emitted: the DRDY handler runs
        // on this core and sees program order).
        compiler_fence(Ordering::SeqCst);
        self.wait_ready();
        self.regs.clear_sr(sr::EOP | sr::ERRORS);
        if self.regs.cr() & cr::LOCK != 0 {
            self.regs.key(KEY1);
            self.regs.key(KEY2);
            if self.regs.cr() & cr::LOCK != 0 {
                OPERATION.store(false, Ordering::Relaxed);
                return Err(FlashError::Locked);
            }
        }
        Ok(())
    }

    /// Steps 4–5: the flags this operation raised, PG/SER/SNB cleared, FLASH_CR locked.
    fn end(&mut self) -> Result<(), FlashError> {
        let s = self.wait_ready();
        compiler_fence(Ordering::SeqCst);
        OPERATION.store(false, Ordering::Relaxed);
        let c = self.regs.cr() & !(cr::PG | cr::SER | cr::MER | cr::SNB_MASK | cr::STRT);
        self.regs.set_cr(c | cr::LOCK);
        match FlashError::from_sr(s) {
            Some(e) => {
                // Cleared now, so nothing stale is left for the next operation either.
                self.regs.clear_sr(sr::ERRORS);
                Err(e)
            }
            None => Ok(()),
        }
    }

    fn erase_sector(&mut self, sector: u8) -> Result<(), FlashError> {
        self.begin()?;
        let base = self.regs.cr() & !(cr::PG | cr::MER | cr::SNB_MASK | cr::PSIZE_MASK);
        // SER and SNB first, then STRT (RM0090 §3.5.3 steps 2–3). PSIZE x32: the erase takes
        // half the time of x8 (datasheet "Flash memory programming": t_ERASE128KB 1 s typ.,
        // 2 s max at x32 against 2 s / 4 s at x8) and the whole MCU stalls for it; x32 needs
        // VDD 2.7–3.6 V, which the board's 3.3 V rail is.
        let set = base | cr::SER | cr::PSIZE_X32 | (u32::from(sector) << cr::SNB_SHIFT);
        self.regs.set_cr(set);
        self.regs.set_cr(set | cr::STRT);
        self.end()
    }

    /// After an erase the ART accelerator's caches may hold lines of the erased sector: RM0090
    /// §3.5.2 asks to flush them — disable, reset, re-enable (a reset only acts while the
    /// cache is disabled).
    fn reset_caches(&mut self) {
        let on = self.regs.acr();
        let off = on & !(acr::ICEN | acr::DCEN);
        self.regs.set_acr(off);
        self.regs.set_acr(off | acr::ICRST | acr::DCRST);
        self.regs.set_acr(off);
        self.regs.set_acr(on);
    }

    fn program(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
        self.begin()?;
        let base = self.regs.cr() & !(cr::SER | cr::MER | cr::SNB_MASK | cr::PSIZE_MASK);
        // PSIZE x8 (00) and PG (RM0090 §3.5.4 step 2); then one byte-wide write per byte.
        self.regs.set_cr(base | cr::PG);
        for (at, &b) in (offset..).zip(bytes) {
            self.regs.write_byte(at, b);
            let s = self.wait_ready();
            if FlashError::from_sr(s).is_some() {
                break;
            }
        }
        self.end()
    }
}

impl<R> ErrorType for Stm32f4Flash<R> {
    type Error = FlashError;
}

fn refused(k: NorFlashErrorKind) -> FlashError {
    match k {
        NorFlashErrorKind::NotAligned => FlashError::NotAligned,
        _ => FlashError::OutOfBounds,
    }
}

impl<R: FlashRegisters> ReadNorFlash for Stm32f4Flash<R> {
    const READ_SIZE: usize = 1;
    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), FlashError> {
        check_read(self, offset, bytes.len()).map_err(refused)?;
        self.regs.read(offset, bytes);
        Ok(())
    }
    fn capacity(&self) -> usize {
        FLASH_BYTES
    }
}

impl<R: FlashRegisters> NorFlash for Stm32f4Flash<R> {
    const WRITE_SIZE: usize = 1;
    /// The 128 KiB sectors (5–11); sectors 0–4 are erased together as one 128 KiB block.
    const ERASE_SIZE: usize = 128 * 1024;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), FlashError> {
        check_erase(self, from, to).map_err(refused)?;
        let mut at = from;
        let mut result = Ok(());
        while at < to && result.is_ok() {
            let (sector, size) = sector_of(at);
            result = self.erase_sector(sector);
            at += size;
        }
        self.reset_caches();
        result
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
        check_write(self, offset, bytes.len()).map_err(refused)?;
        if bytes.is_empty() {
            return Ok(());
        }
        self.program(offset, bytes)
    }
}

#[cfg(test)]
pub(crate) mod model;
#[cfg(test)]
mod tests;
