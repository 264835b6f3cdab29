//! The flash driver against the register-level controller model (model.rs, RM0090 §3.5/§3.8).

use super::model::{FlashModel, SR_ERROR_FLAGS};
use super::*;

const SECTOR_9: u32 = 0xA_0000;
const SECTOR_10: u32 = 0xC_0000;
const SECTOR: u32 = 128 * 1024;

fn flash() -> Stm32f4Flash<FlashModel> {
    Stm32f4Flash::new(FlashModel::new())
}

fn read(f: &mut Stm32f4Flash<FlashModel>, at: u32, n: usize) -> std::vec::Vec<u8> {
    let mut buf = std::vec![0u8; n];
    assert_eq!(f.read(at, &mut buf), Ok(()));
    buf
}

/// After every operation, failed or not: FLASH_CR locked, PG/SER cleared, no error flag left.
fn assert_idle(f: &mut Stm32f4Flash<FlashModel>) {
    let m = f.registers();
    assert_ne!(m.cr & cr::LOCK, 0, "FLASH_CR left unlocked");
    assert_eq!(
        m.cr & (cr::PG | cr::SER | cr::STRT),
        0,
        "PG/SER/STRT left set"
    );
    assert_eq!(m.sr & sr::ERRORS, 0, "error flags left set: {:#x}", m.sr);
}

#[test]
fn erase_program_read_round_trip_and_the_controller_is_left_locked() {
    let mut f = flash();
    f.registers().mem[SECTOR_9 as usize..][..4].copy_from_slice(&[1, 2, 3, 4]);
    assert_eq!(f.erase(SECTOR_9, SECTOR_9 + SECTOR), Ok(()));
    assert_eq!(read(&mut f, SECTOR_9, 4), [0xFF; 4]);
    assert_idle(&mut f);
    assert_eq!(f.write(SECTOR_9 + 5, &[0x12, 0x34, 0x56]), Ok(()));
    assert_eq!(
        read(&mut f, SECTOR_9 + 4, 5),
        [0xFF, 0x12, 0x34, 0x56, 0xFF]
    );
    assert_idle(&mut f);
    assert_eq!(f.registers().erases, 1);
    assert_eq!(f.registers().programmed_bytes, 3);
    // Sector 10 untouched by sector 9's erase.
    f.registers().mem[SECTOR_10 as usize] = 0;
    assert_eq!(f.erase(SECTOR_9, SECTOR_9 + SECTOR), Ok(()));
    assert_eq!(read(&mut f, SECTOR_10, 1), [0]);
}

#[test]
fn every_erase_resets_the_caches_while_they_are_disabled_and_turns_them_back_on() {
    let mut f = flash();
    assert_eq!(f.erase(SECTOR_9, SECTOR_9 + SECTOR), Ok(()));
    let m = f.registers();
    assert_eq!((m.cache_resets, m.cache_resets_while_enabled), (1, 0));
    assert_eq!(m.acr & (acr::ICEN | acr::DCEN), acr::ICEN | acr::DCEN);
    assert_eq!(m.acr & (acr::ICRST | acr::DCRST), 0);
    // A failed erase (write-protected sector) may have erased nothing, but resets all the same.
    f.registers().n_wrp &= !(1 << 10);
    assert!(f.erase(SECTOR_10, SECTOR_10 + SECTOR).is_err());
    assert_eq!(f.registers().cache_resets, 2);
}

#[test]
fn sectors_follow_the_f405_map() {
    assert_eq!(sector_of(0), (0, 16 * 1024));
    assert_eq!(sector_of(0xC000), (3, 16 * 1024));
    assert_eq!(sector_of(0x1_0000), (4, 64 * 1024));
    assert_eq!(sector_of(0x2_0000), (5, 128 * 1024));
    assert_eq!(sector_of(SECTOR_9), (9, SECTOR));
    assert_eq!(sector_of(0xE_0000), (11, SECTOR));
    let mut f = flash();
    assert_eq!(f.erase(0, SECTOR), Ok(()));
    assert_eq!(
        f.registers().erases,
        5,
        "sectors 0–4 make up the first 128 KiB"
    );
}

/// Each FLASH_SR error flag, raised by a failing program and by a failing erase, comes back as
/// its own named error; the flag is cleared, and the next operation succeeds (issue #12.5: the
/// HAL left the sticky flag set, so every later write failed until reset).
#[test]
fn each_flash_error_is_named_and_the_next_operation_succeeds() {
    for (flag, named, _) in SR_ERROR_FLAGS {
        let mut f = flash();
        assert_eq!(f.erase(SECTOR_9, SECTOR_9 + SECTOR), Ok(()));
        f.registers().fail_next = Some(flag);
        assert_eq!(
            f.write(SECTOR_9, &[0xA5, 0x5A]),
            Err(named),
            "program, {flag:#x}"
        );
        assert_idle(&mut f);
        assert_eq!(f.write(SECTOR_9 + 16, &[0x11, 0x22]), Ok(()));
        assert_eq!(read(&mut f, SECTOR_9 + 16, 2), [0x11, 0x22]);

        f.registers().fail_next = Some(flag);
        assert_eq!(
            f.erase(SECTOR_9, SECTOR_9 + SECTOR),
            Err(named),
            "erase, {flag:#x}"
        );
        assert_eq!(
            read(&mut f, SECTOR_9 + 16, 2),
            [0x11, 0x22],
            "aborted erase changed cells"
        );
        assert_idle(&mut f);
        assert_eq!(f.erase(SECTOR_9, SECTOR_9 + SECTOR), Ok(()));
        assert_eq!(read(&mut f, SECTOR_9 + 16, 2), [0xFF, 0xFF]);
    }
}

/// Flags left set by someone else (a reset between an operation and its clean-up, a debugger)
/// do not fail the next operation: they are cleared before it starts.
#[test]
fn stale_error_flags_are_cleared_before_an_operation() {
    let mut f = flash();
    f.registers().sr = sr::ERRORS | sr::EOP;
    assert_eq!(f.erase(SECTOR_9, SECTOR_9 + SECTOR), Ok(()));
    f.registers().sr = sr::PGSERR;
    assert_eq!(f.write(SECTOR_9, &[0]), Ok(()));
    assert_eq!(read(&mut f, SECTOR_9, 1), [0]);
}

/// The model's own rules (not injected): a write-protected sector refuses erase and program
/// with WRPERR and keeps its content; the other sectors still work.
#[test]
fn a_write_protected_sector_gives_wrperr_and_keeps_its_cells() {
    let mut f = flash();
    f.registers().mem[SECTOR_10 as usize] = 0x42;
    f.registers().n_wrp &= !(1 << 10);
    assert_eq!(
        f.erase(SECTOR_10, SECTOR_10 + SECTOR),
        Err(FlashError::WriteProtected)
    );
    assert_eq!(
        f.write(SECTOR_10 + 1, &[0]),
        Err(FlashError::WriteProtected)
    );
    assert_eq!(read(&mut f, SECTOR_10, 2), [0x42, 0xFF]);
    assert_idle(&mut f);
    assert_eq!(f.erase(SECTOR_9, SECTOR_9 + SECTOR), Ok(()));
    assert_eq!(f.write(SECTOR_9, &[7]), Ok(()));
}

/// A wrong key sequence locks FLASH_CR until reset (RM0090 §3.5.1): named, nothing written.
#[test]
fn a_controller_locked_until_reset_is_named() {
    let mut f = flash();
    f.registers().key(0xDEAD_BEEF);
    assert_eq!(f.write(SECTOR_9, &[0]), Err(FlashError::Locked));
    assert_eq!(
        f.erase(SECTOR_9, SECTOR_9 + SECTOR),
        Err(FlashError::Locked)
    );
    assert_eq!(read(&mut f, SECTOR_9, 1), [0xFF]);
    f.registers().reset();
    assert_eq!(f.write(SECTOR_9, &[0]), Ok(()));
}

/// Alignment and bounds are refused before the controller is touched.
#[test]
fn misaligned_or_out_of_range_requests_never_reach_the_controller() {
    let mut f = flash();
    assert_eq!(
        f.erase(SECTOR_9 + 1, SECTOR_9 + SECTOR),
        Err(FlashError::NotAligned)
    );
    assert_eq!(
        f.write(FLASH_BYTES as u32 - 1, &[0, 0]),
        Err(FlashError::OutOfBounds)
    );
    let m = f.registers();
    assert_eq!((m.erases, m.programmed_bytes, m.cr), (0, 0, cr::LOCK));
}
