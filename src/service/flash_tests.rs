//! FLASH_SR errors through the service, as the UART sees them (issue #12.5): the board's flash
//! driver on the register-level controller model (drivers/stm32f4_flash/model.rs, RM0090), with
//! the board's slot layout (sectors 9–11).

use super::*;
use crate::drivers::stm32f4_flash::model::{FlashModel, SR_ERROR_FLAGS};
use crate::drivers::stm32f4_flash::{sr, FlashRegisters, Stm32f4Flash};
use crate::table::tests::paper_table;

type BoardFlash = Stm32f4Flash<FlashModel>;

fn board_service() -> Service<BoardFlash> {
    Service::new(
        Board::Frontend,
        Stm32f4Flash::new(FlashModel::new()),
        SlotLayout::STM32F405_SECTORS_9_11,
    )
}

/// The frame id of every [`call`].
const CALL_ID: u32 = 5;

/// A board service whose active table is `t`, uploaded and committed as upload 1.
fn service_with_active(t: &CalibrationTable) -> Service<BoardFlash> {
    let mut s = board_service();
    let r = upload(&mut s, &t.encode(), 1);
    assert!(matches!(r, DeviceMessage::Response { .. }), "{r:?}");
    s
}

fn call(s: &mut Service<BoardFlash>, request: Request) -> DeviceMessage {
    s.handle(
        HostFrame {
            id: CALL_ID,
            request,
        },
        &|| 0,
    )
}

/// The service's answer to a [`call`] it refuses with `code`.
fn refused(code: ErrorCode) -> DeviceMessage {
    DeviceMessage::Error {
        id: CALL_ID,
        error: code.reply(0),
    }
}

fn upload(s: &mut Service<BoardFlash>, bytes: &[u8], uid: u32) -> DeviceMessage {
    let mut last = None;
    for request in crate::protocol::upload_requests(uid, bytes) {
        if let Some(r) = last.replace(call(s, request)) {
            assert!(matches!(r, DeviceMessage::Response { .. }), "{r:?}");
        }
    }
    last.expect("an upload ends with its commit")
}

fn tables(s: &mut Service<BoardFlash>) -> (Option<u32>, Option<u32>) {
    match call(s, Request::Info) {
        DeviceMessage::Response {
            body: Response::Info(i),
            ..
        } => (i.active_table, i.previous_table),
        other => panic!("{other:?}"),
    }
}

fn model(s: &mut Service<BoardFlash>) -> &mut FlashModel {
    let store = s.store.as_mut().expect("store opened");
    store.flash_mut().registers()
}

fn two_tables() -> (CalibrationTable, CalibrationTable) {
    let t1 = paper_table();
    let mut t2 = paper_table();
    t2.date.day = 2;
    (t1, t2)
}

/// Each FLASH_SR error during a commit answers with its own code, keeps the active table, and
/// the same upload repeated afterwards commits (before: the flag stayed set and every later
/// commit failed until reset).
#[test]
fn each_flash_error_of_a_commit_has_its_code_and_the_retry_commits() {
    let (t1, t2) = two_tables();
    for (flag, _, code) in SR_ERROR_FLAGS {
        let mut s = service_with_active(&t1);
        let _ = s.erase_ahead(&|| 0);
        model(&mut s).fail_next = Some(flag);
        let r = upload(&mut s, &t2.encode(), 2);
        assert_eq!(r, refused(code), "flag {flag:#x}");
        assert_eq!(tables(&mut s), (Some(t1.id()), None), "active kept");
        assert_eq!(model(&mut s).sr & sr::ERRORS, 0, "flag left set");
        let r = upload(&mut s, &t2.encode(), 3);
        assert!(
            matches!(
                r,
                DeviceMessage::Response {
                    body: Response::Committed { .. },
                    ..
                }
            ),
            "retry after {flag:#x}: {r:?}"
        );
        assert_eq!(tables(&mut s), (Some(t2.id()), Some(t1.id())));
        // And it survives a reset of the MCU (registers to reset values, cells kept).
        let mut flash = s.into_flash().unwrap();
        flash.registers().reset();
        let mut s = Service::new(Board::Frontend, flash, SlotLayout::STM32F405_SECTORS_9_11);
        assert_eq!(tables(&mut s), (Some(t2.id()), Some(t1.id())));
    }
}

/// Write protection set on the calibration sectors (not injected: the model's nWRP rule):
/// rollback and commit answer FlashWriteProtected, nothing changes; cleared, both work.
#[test]
fn write_protected_calibration_sectors_are_named_and_nothing_is_lost() {
    let (t1, t2) = two_tables();
    let mut s = service_with_active(&t1);
    upload(&mut s, &t2.encode(), 2);
    model(&mut s).n_wrp &= !(0b111 << 9);
    let wrp = refused(ErrorCode::FlashWriteProtected);
    assert_eq!(call(&mut s, Request::Rollback), wrp);
    assert_eq!(tables(&mut s), (Some(t2.id()), Some(t1.id())));
    model(&mut s).n_wrp = 0x0FFF;
    assert!(matches!(
        call(&mut s, Request::Rollback),
        DeviceMessage::Response { .. }
    ));
    assert_eq!(tables(&mut s), (Some(t1.id()), Some(t2.id())));
}

/// A controller locked until reset (a wrong key was written): FlashLocked, active kept.
#[test]
fn a_locked_flash_controller_is_named() {
    let (t1, t2) = two_tables();
    let mut s = service_with_active(&t1);
    model(&mut s).key(0);
    let r = upload(&mut s, &t2.encode(), 2);
    assert_eq!(r, refused(ErrorCode::FlashLocked));
    assert_eq!(tables(&mut s), (Some(t1.id()), None));
}
