//! Register-level model of the STM32F405 flash controller for host tests, from RM0090 (Rev 4
//! numbering) §3.5 (unlock, erase, programming) and §3.8 (FLASH_KEYR, FLASH_SR, FLASH_CR):
//! - FLASH_CR is locked at reset (LOCK = 1, value 0x8000_0000); KEY1 then KEY2 in FLASH_KEYR
//!   unlock it; a wrong key leaves it locked until reset (§3.5.1; the bus error is not modelled,
//!   the lock is). Writes to a locked FLASH_CR are ignored; setting LOCK locks it.
//! - Sector erase: SER + SNB, then STRT; the sector reads 0xFF afterwards (§3.5.3).
//! - Programming: with PG set, each bus write programs the addressed cells (NOR: bits only go
//!   1 → 0; §3.5.4 "successive write operations are possible without erase when changing bits
//!   from 1 to 0"). A write with PG clear or FLASH_CR locked sets PGSERR; a byte write with PSIZE ≠ x8
//!   sets PGPERR (§3.5.2, §3.8.4). A sector whose nWRP bit is cleared refuses both with WRPERR.
//! - FLASH_SR error flags are sticky (rc_w1): they stay set until written with 1 — the cause of
//!   issue #12.5's "every later write fails".
//! - BSY reads 1 for a few polls after each operation; touching FLASH_CR or the flash memory
//!   while BSY is set is refused (panics: a driver bug the tests must catch).
//! - Fault injection: `fail_next` makes the next erase or program raise the given SR flag(s)
//!   without changing the cells (as the hardware does when it aborts), and OPERR is added when
//!   ERRIE is set.

use super::{cr, sector_of, sr, FlashError, FlashRegisters, FLASH_BYTES, KEY1, KEY2};
use crate::protocol::ErrorCode;
use std::vec::Vec;

/// Each FLASH_SR error flag `fail_next` can raise, with the error the driver must name it by and
/// the code a commit that meets it must answer (RM0090 §3.8.4; protocol codes 63–68).
pub(crate) const SR_ERROR_FLAGS: [(u32, FlashError, ErrorCode); 5] = [
    (
        sr::PGSERR,
        FlashError::ProgramSequence,
        ErrorCode::FlashProgramSequence,
    ),
    (
        sr::PGPERR,
        FlashError::ProgramParallelism,
        ErrorCode::FlashProgramParallelism,
    ),
    (
        sr::PGAERR,
        FlashError::ProgramAlignment,
        ErrorCode::FlashProgramAlignment,
    ),
    (
        sr::WRPERR,
        FlashError::WriteProtected,
        ErrorCode::FlashWriteProtected,
    ),
    (sr::OPERR, FlashError::Operation, ErrorCode::FlashOperation),
];

/// The model's state.
pub(crate) struct FlashModel {
    pub mem: Vec<u8>,
    pub sr: u32,
    pub cr: u32,
    /// Keys accepted so far in the unlock sequence (0 or 1).
    key_stage: u8,
    /// A wrong key was written: locked until reset.
    pub keys_broken: bool,
    /// Bit n clear = sector n write-protected (option byte nWRP, RM0090 §3.6).
    pub n_wrp: u16,
    /// SR flags the next erase or program raises instead of running.
    pub fail_next: Option<u32>,
    /// Polls for which BSY still reads 1.
    busy_polls: u32,
    /// BSY polls after each operation.
    pub busy_for: u32,
    pub erases: u32,
    pub programmed_bytes: u32,
    /// FLASH_ACR (reset value with the caches on, as the firmware runs).
    pub acr: u32,
    /// Cache resets done while the caches were disabled (RM0090 §3.5.2), and refused ones.
    pub cache_resets: u32,
    pub cache_resets_while_enabled: u32,
}

impl FlashModel {
    pub(crate) fn new() -> Self {
        FlashModel {
            mem: std::vec![0xFF; FLASH_BYTES],
            sr: 0,
            cr: cr::LOCK,
            key_stage: 0,
            keys_broken: false,
            n_wrp: 0x0FFF,
            fail_next: None,
            busy_polls: 0,
            busy_for: 3,
            erases: 0,
            programmed_bytes: 0,
            acr: super::acr::ICEN | super::acr::DCEN,
            cache_resets: 0,
            cache_resets_while_enabled: 0,
        }
    }

    /// A system reset: registers to their reset values, memory kept.
    pub(crate) fn reset(&mut self) {
        self.sr = 0;
        self.cr = cr::LOCK;
        self.key_stage = 0;
        self.keys_broken = false;
        self.busy_polls = 0;
    }

    fn not_busy(&self, what: &str) {
        assert!(
            self.busy_polls == 0,
            "{what} while FLASH_SR.BSY = 1 (RM0090 §3.5: wait for BSY = 0 first)"
        );
    }

    fn raise(&mut self, flags: u32) {
        self.sr |= flags;
        if self.cr & cr::ERRIE != 0 {
            self.sr |= sr::OPERR;
        }
    }

    fn write_protected(&self, offset: u32) -> bool {
        let (sector, _) = sector_of(offset);
        self.n_wrp & (1 << sector) == 0
    }
}

impl FlashRegisters for FlashModel {
    fn acr(&mut self) -> u32 {
        self.acr
    }

    fn set_acr(&mut self, value: u32) {
        use super::acr;
        if value & (acr::ICRST | acr::DCRST) != 0 {
            if self.acr & (acr::ICEN | acr::DCEN) != 0 || value & (acr::ICEN | acr::DCEN) != 0 {
                self.cache_resets_while_enabled += 1;
            } else {
                self.cache_resets += 1;
            }
        }
        self.acr = value;
    }

    fn sr(&mut self) -> u32 {
        if self.busy_polls > 0 {
            self.busy_polls -= 1;
            self.sr | sr::BSY
        } else {
            self.sr
        }
    }

    fn clear_sr(&mut self, bits: u32) {
        self.sr &= !(bits & (sr::EOP | sr::ERRORS));
    }

    fn cr(&mut self) -> u32 {
        self.cr
    }

    fn set_cr(&mut self, value: u32) {
        self.not_busy("FLASH_CR write");
        if self.cr & cr::LOCK != 0 {
            return;
        }
        if value & cr::STRT != 0 && value & (cr::SER | cr::MER) != 0 {
            self.cr = value & !cr::STRT;
            self.busy_polls = self.busy_for;
            if value & cr::PG != 0 {
                self.raise(sr::PGSERR);
                return;
            }
            let sector = (value & cr::SNB_MASK) >> cr::SNB_SHIFT;
            let (start, size) = match sector {
                0..=3 => (sector * 16 * 1024, 16 * 1024),
                4 => (64 * 1024, 64 * 1024),
                5..=11 => ((sector - 4) * 128 * 1024, 128 * 1024),
                _ => {
                    self.raise(sr::PGSERR);
                    return;
                }
            };
            if let Some(f) = self.fail_next.take() {
                self.raise(f);
            } else if self.write_protected(start) {
                self.raise(sr::WRPERR);
            } else {
                self.mem[start as usize..(start + size) as usize].fill(0xFF);
                self.erases += 1;
            }
            return;
        }
        self.cr = value;
    }

    fn key(&mut self, key: u32) {
        if self.keys_broken || self.cr & cr::LOCK == 0 {
            return;
        }
        match (self.key_stage, key) {
            (0, KEY1) => self.key_stage = 1,
            (1, KEY2) => {
                self.key_stage = 0;
                self.cr &= !cr::LOCK;
            }
            _ => self.keys_broken = true,
        }
    }

    fn write_byte(&mut self, offset: u32, byte: u8) {
        self.not_busy("flash memory write");
        self.busy_polls = self.busy_for;
        if self.cr & cr::LOCK != 0 || self.cr & cr::PG == 0 {
            self.raise(sr::PGSERR);
        } else if self.cr & cr::PSIZE_MASK != 0 {
            self.raise(sr::PGPERR);
        } else if let Some(f) = self.fail_next.take() {
            self.raise(f);
        } else if self.write_protected(offset) {
            self.raise(sr::WRPERR);
        } else {
            self.mem[offset as usize] &= byte;
            self.programmed_bytes += 1;
        }
    }

    fn read(&mut self, offset: u32, bytes: &mut [u8]) {
        bytes.copy_from_slice(&self.mem[offset as usize..offset as usize + bytes.len()]);
    }
}
