//! Request *sequences* into `Service`, coverage-guided (issue #15.4). Random bytes almost never
//! make a CRC-valid frame, so `frame_decoder` never gets past the first request; here the input
//! is read as a list of operations, each turned into a well-formed request (or a deliberately
//! wrong one: foreign upload ids, wrong offsets and checksums, random chunk bytes, unknown ids),
//! plus reboots, erase-ahead and **power cuts inside a flash operation**.
//!
//! Checked against the protocol's reference model of what the user expects
//! (`accomp::protocol::model::TableHistory`, from docs/protocol.md and docs/storage.md):
//! - every request is answered with its own id; Ping with Pong;
//! - Info's (active, previous) follow the model: a commit makes the new table active and the
//!   old one previous (re-uploading the active table changes nothing), Rollback and
//!   Activate(previous) swap them, nothing else changes them, a reboot keeps them;
//! - ReadTable of the whole active table decodes to a table whose id is the active id;
//! - a power cut during a commit, rollback, activate or erase-ahead leaves, at the next boot,
//!   the state before or the state after the operation — never anything else.
//!
//! The stateful proptest in `src/service/fuzz_tests.rs` checks each answer in more detail against
//! the whole `ProtocolModel` (100,000 sequences in every `cargo xtask test`); this target adds
//! coverage guidance, arbitrary lengths and power cuts at every flash operation.
#![no_main]

use accomp::pipeline::{ChannelFlags, RawSample};
use accomp::protocol::model::TableHistory;
use accomp::protocol::{
    upload_body_crc32, Board, DeviceMessage, HostFrame, Request, Response, CHUNK_LEN,
};
use accomp::reference::paper_order2_table;
use accomp::protocol::FlashErrorReply;
use accomp::service::Service;
use accomp::storage::{RamFlash, RamFlashError, SlotLayout};
use accomp::table::{CalibrationDate, CalibrationTable, ENCODED_LEN};
use embedded_storage::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};
use libfuzzer_sys::arbitrary::{Result as AResult, Unstructured};
use libfuzzer_sys::fuzz_target;

type Ram = RamFlash<3072, 1024, 4>;
const LAYOUT: SlotLayout = SlotLayout::consecutive(1024);
const TABLES: usize = 4;
const MAX_OPS: usize = 64;

/// The QEMU board's RAM flash with a power-cut switch: the `cut_at`-th erase or program from
/// now changes only its first `quarters`/4 of the bytes it should (an erase sets them to 0xFF, a
/// program ANDs them in — what NOR cells do), then fails; the caller then reboots.
struct CutFlash {
    ram: Ram,
    cut_at: Option<u32>,
    quarters: u8,
    cut: bool,
}

#[derive(Debug)]
enum CutError {
    Ram(RamFlashError),
    PowerCut,
}

impl NorFlashError for CutError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            CutError::Ram(e) => e.kind(),
            CutError::PowerCut => NorFlashErrorKind::Other,
        }
    }
}

/// Its errors answer as FlashFailed (kind 2, "other").
impl FlashErrorReply for CutError {}

impl ErrorType for CutFlash {
    type Error = CutError;
}

impl ReadNorFlash for CutFlash {
    const READ_SIZE: usize = <Ram as ReadNorFlash>::READ_SIZE;
    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), CutError> {
        self.ram.read(offset, bytes).map_err(CutError::Ram)
    }
    fn capacity(&self) -> usize {
        self.ram.capacity()
    }
}

impl CutFlash {
    /// True when this operation is the one the power goes in.
    fn cutting(&mut self) -> bool {
        match self.cut_at {
            Some(0) => {
                self.cut_at = None;
                self.cut = true;
                true
            }
            Some(n) => {
                self.cut_at = Some(n - 1);
                false
            }
            None => false,
        }
    }
    fn part(&self, len: usize) -> usize {
        len / 4 * usize::from(self.quarters)
    }
}

impl NorFlash for CutFlash {
    const WRITE_SIZE: usize = <Ram as NorFlash>::WRITE_SIZE;
    const ERASE_SIZE: usize = <Ram as NorFlash>::ERASE_SIZE;
    fn erase(&mut self, from: u32, to: u32) -> Result<(), CutError> {
        if self.cut {
            return Err(CutError::PowerCut);
        }
        if self.cutting() {
            let n = self.part((to - from) as usize);
            let from = from as usize;
            if let Some(cells) = self.ram.as_bytes_mut().get_mut(from..from + n) {
                cells.fill(0xFF);
            }
            return Err(CutError::PowerCut);
        }
        self.ram.erase(from, to).map_err(CutError::Ram)
    }
    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), CutError> {
        if self.cut {
            return Err(CutError::PowerCut);
        }
        if self.cutting() {
            let n = self.part(bytes.len());
            let at = offset as usize;
            if let Some(cells) = self.ram.as_bytes_mut().get_mut(at..at + n) {
                for (c, b) in cells.iter_mut().zip(bytes) {
                    *c &= *b;
                }
            }
            return Err(CutError::PowerCut);
        }
        self.ram.write(offset, bytes).map_err(CutError::Ram)
    }
}

/// Four valid tables (encoded once: encoding validates, and dominated the run time).
fn tables() -> [[u8; ENCODED_LEN]; TABLES] {
    static TABLES_ONCE: std::sync::OnceLock<[[u8; ENCODED_LEN]; TABLES]> =
        std::sync::OnceLock::new();
    *TABLES_ONCE.get_or_init(|| {
        core::array::from_fn(|k| {
            let mut t: CalibrationTable = paper_order2_table();
            t.date = CalibrationDate {
                year: 2017,
                month: 4,
                day: 1 + k as u8,
            };
            t.encode()
        })
    })
}

fn id_of(bytes: &[u8; ENCODED_LEN]) -> u32 {
    upload_body_crc32(bytes)
}

/// (active, previous) table ids, as Info reports them.
type State = (Option<u32>, Option<u32>);

struct Harness {
    dev: Option<Service<CutFlash>>,
    next_id: u32,
    model: TableHistory,
    tables: [[u8; ENCODED_LEN]; TABLES],
}

impl Harness {
    fn dev(&mut self) -> &mut Service<CutFlash> {
        self.dev
            .as_mut()
            .expect("service present between operations")
    }

    fn call(&mut self, request: Request) -> DeviceMessage {
        self.next_id = self.next_id.wrapping_add(1).max(1);
        let id = self.next_id;
        let clock = || 0u64;
        let answer = self.dev().handle(HostFrame { id, request }, &clock);
        let got = match &answer {
            DeviceMessage::Response { id, .. }
            | DeviceMessage::Error { id, .. }
            | DeviceMessage::Sample { id, .. } => *id,
            DeviceMessage::Ready { .. } => panic!("Ready as an answer"),
        };
        assert_eq!(got, id, "answer carries another request's id: {answer:?}");
        answer
    }

    fn reboot(&mut self) {
        let flash = self
            .dev
            .take()
            .and_then(Service::into_flash)
            .expect("the RAM flash store always opens");
        let flash = CutFlash {
            cut_at: None,
            cut: false,
            ..flash
        };
        self.dev = Some(Service::new(Board::Qemu, flash, LAYOUT));
    }

    fn state(&mut self) -> State {
        match self.call(Request::Info) {
            DeviceMessage::Response {
                body: Response::Info(i),
                ..
            } => (i.active_table, i.previous_table),
            other => panic!("Info answered {other:?}"),
        }
    }

    fn check(&mut self, what: &str) {
        let s = self.state();
        assert_eq!(s, self.model.ids(), "after {what}: (active, previous)");
        assert!(
            s.0.is_some() || s.1.is_none(),
            "a previous table without an active one"
        );
        if let Some(active) = s.0 {
            assert_ne!(s.1, Some(active), "previous == active");
            let mut buf = [0u8; ENCODED_LEN];
            let mut at = 0usize;
            while at < ENCODED_LEN {
                match self.call(Request::ReadTable { offset: at as u32 }) {
                    DeviceMessage::Response {
                        body:
                            Response::TableChunk {
                                offset,
                                total_len,
                                data,
                            },
                        ..
                    } => {
                        assert_eq!((offset as usize, total_len as usize), (at, ENCODED_LEN));
                        assert!(!data.is_empty());
                        buf[at..at + data.len()].copy_from_slice(&data);
                        at += data.len();
                    }
                    other => panic!("ReadTable({at}) with an active table: {other:?}"),
                }
            }
            let t = CalibrationTable::decode(&buf).expect("the active table reads back valid");
            assert_eq!(t.id(), active, "read-back id");
        }
    }

    /// A whole upload of `bytes` with `uid` and its commit, stopping at the first refusal
    /// (which is returned) — for runs where the power may go.
    fn load_unchecked(&mut self, uid: u32, bytes: &[u8; ENCODED_LEN]) -> DeviceMessage {
        let a = self.call(Request::UploadBegin {
            upload_id: uid,
            total_len: ENCODED_LEN as u32,
            body_crc32: upload_body_crc32(bytes),
        });
        if !is_ok(&a) {
            return a;
        }
        for (i, c) in bytes.chunks(CHUNK_LEN).enumerate() {
            let a = self.call(Request::UploadChunk {
                upload_id: uid,
                offset: (i * CHUNK_LEN) as u32,
                data: heapless::Vec::from_slice(c).expect("chunk fits"),
            });
            if !is_ok(&a) {
                return a;
            }
        }
        self.call(Request::UploadCommit { upload_id: uid })
    }

    /// A whole well-formed upload of `bytes` with `uid`, then the commit's answer.
    fn load(&mut self, uid: u32, bytes: &[u8; ENCODED_LEN]) -> DeviceMessage {
        let begin = self.call(Request::UploadBegin {
            upload_id: uid,
            total_len: ENCODED_LEN as u32,
            body_crc32: upload_body_crc32(bytes),
        });
        assert!(
            matches!(
                begin,
                DeviceMessage::Response {
                    body: Response::Ok,
                    ..
                }
            ),
            "UploadBegin: {begin:?}"
        );
        for (i, c) in bytes.chunks(CHUNK_LEN).enumerate() {
            let a = self.call(Request::UploadChunk {
                upload_id: uid,
                offset: (i * CHUNK_LEN) as u32,
                data: heapless::Vec::from_slice(c).expect("chunk fits"),
            });
            assert!(
                matches!(
                    a,
                    DeviceMessage::Response {
                        body: Response::Ok,
                        ..
                    }
                ),
                "UploadChunk: {a:?}"
            );
        }
        self.call(Request::UploadCommit { upload_id: uid })
    }

    /// Model of a successful commit of `bytes`.
    fn committed(&self, bytes: &[u8; ENCODED_LEN]) -> TableHistory {
        let mut m = self.model;
        m.load(bytes);
        m
    }

    /// Model of a rollback (unchanged when there is nothing to roll back to).
    fn swapped(&self) -> TableHistory {
        let mut m = self.model;
        let _ = m.rollback();
        m
    }
}

fn is_ok(a: &DeviceMessage) -> bool {
    matches!(a, DeviceMessage::Response { .. })
}

fn run(u: &mut Unstructured) -> AResult<()> {
    let tables = tables();
    let mut h = Harness {
        dev: Some(Service::new(
            Board::Qemu,
            CutFlash {
                ram: Ram::new(),
                cut_at: None,
                quarters: 0,
                cut: false,
            },
            LAYOUT,
        )),
        next_id: 0,
        model: TableHistory::default(),
        tables,
    };
    // Upload in progress: its id, source table, bytes sent so far (all from that table).
    let mut upload: Option<(u32, usize, usize)> = None;
    for _ in 0..MAX_OPS {
        if u.is_empty() {
            break;
        }
        let op: u8 = u.int_in_range(0..=15)?;
        let what;
        match op {
            0 => {
                what = "Ping";
                let a = h.call(Request::Ping);
                assert!(
                    matches!(
                        a,
                        DeviceMessage::Response {
                            body: Response::Pong,
                            ..
                        }
                    ),
                    "Ping: {a:?}"
                );
            }
            1 | 2 => {
                what = "Load";
                let src = u.choose_index(TABLES)?;
                let uid = u.int_in_range(1..=3)?;
                let bytes = h.tables[src];
                let a = h.load(uid, &bytes);
                assert!(is_ok(&a), "commit of a valid table refused: {a:?}");
                h.model = h.committed(&bytes);
                upload = None;
            }
            3 => {
                what = "Begin";
                let src = u.choose_index(TABLES)?;
                let uid = u.int_in_range(1..=3)?;
                let len_ok = u.ratio(7, 8)?;
                let crc_ok = u.ratio(7, 8)?;
                let total_len = if len_ok {
                    ENCODED_LEN as u32
                } else {
                    u.arbitrary()?
                };
                let crc = upload_body_crc32(&h.tables[src]) ^ u32::from(!crc_ok);
                let a = h.call(Request::UploadBegin {
                    upload_id: uid,
                    total_len,
                    body_crc32: crc,
                });
                upload = (is_ok(&a) && len_ok && crc_ok).then_some((uid, src, 0));
            }
            4 | 5 => {
                what = "Chunk";
                let (uid, src, sent) = upload.unwrap_or((1, 0, 0));
                let uid = if u.ratio(7, 8)? {
                    uid
                } else {
                    u.int_in_range(0..=4)?
                };
                let offset = if u.ratio(7, 8)? {
                    sent
                } else {
                    u.int_in_range(0..=ENCODED_LEN)?
                };
                let n = u.int_in_range(0..=CHUNK_LEN)?;
                let real = u.ratio(7, 8)?;
                let mut data = heapless::Vec::<u8, CHUNK_LEN>::new();
                for k in 0..n {
                    let b = if real {
                        h.tables[src].get(offset + k).copied().unwrap_or(0)
                    } else {
                        u.arbitrary()?
                    };
                    let _ = data.push(b);
                }
                let a = h.call(Request::UploadChunk {
                    upload_id: uid,
                    offset: offset as u32,
                    data,
                });
                if let Some((cur, s, sent)) = upload {
                    let good = is_ok(&a) && uid == cur && offset == sent && real;
                    upload = good.then_some((cur, s, sent + n));
                    if !is_ok(&a) && uid == cur {
                        // A refused chunk of the upload in progress may end it: start over.
                        upload = None;
                    }
                }
            }
            6 | 7 => {
                what = "Commit";
                let uid = match upload {
                    Some((uid, _, _)) if u.ratio(7, 8)? => uid,
                    _ => u.int_in_range(0..=4)?,
                };
                let a = h.call(Request::UploadCommit { upload_id: uid });
                if let DeviceMessage::Response {
                    body: Response::Committed { table_id },
                    ..
                } = a
                {
                    let bytes = *h
                        .tables
                        .iter()
                        .find(|t| id_of(t) == table_id)
                        .unwrap_or_else(|| panic!("committed an unknown table {table_id:#x}"));
                    h.model = h.committed(&bytes);
                }
                if matches!(upload, Some((cur, _, _)) if cur == uid) {
                    upload = None;
                }
            }
            8 => {
                what = "Rollback";
                let a = h.call(Request::Rollback);
                let mut m = h.model;
                assert_eq!(is_ok(&a), m.rollback().is_ok(), "Rollback: {a:?}");
                h.model = m;
            }
            9 => {
                what = "Activate";
                let id = if u.ratio(3, 4)? {
                    id_of(&h.tables[u.choose_index(TABLES)?])
                } else {
                    u.arbitrary()?
                };
                let a = h.call(Request::Activate { table_id: id });
                let mut m = h.model;
                assert_eq!(
                    is_ok(&a),
                    m.activate(id).is_ok(),
                    "Activate({id:#x}) with {:?}: {a:?}",
                    h.model.ids()
                );
                h.model = m;
            }
            10 => {
                what = "ReadTable";
                let offset = u.int_in_range(0..=2 * ENCODED_LEN as u32)?;
                let a = h.call(Request::ReadTable { offset });
                // offset = length: an empty chunk, the end of the table.
                let readable = h.model.active.is_some() && (offset as usize) <= ENCODED_LEN;
                assert_eq!(is_ok(&a), readable, "ReadTable({offset}): {a:?}");
            }
            11 => {
                what = "Stream/SetRate";
                let r = match u.int_in_range(0..=2)? {
                    0 => Request::StreamStart,
                    1 => Request::StreamStop,
                    _ => Request::SetRate { hz: u.arbitrary()? },
                };
                h.call(r);
            }
            12 => {
                what = "InjectSample/Bench";
                let raw = RawSample {
                    accel: u.arbitrary()?,
                    rtd: u.arbitrary()?,
                    tilt: u.arbitrary()?,
                    accel_flags: ChannelFlags(u.arbitrary()?),
                    rtd_flags: ChannelFlags(u.arbitrary()?),
                    tilt_flags: ChannelFlags(u.arbitrary()?),
                };
                if u.ratio(3, 4)? {
                    let a = h.call(Request::InjectSample { raw });
                    assert!(matches!(a, DeviceMessage::Sample { .. }), "Inject: {a:?}");
                } else {
                    h.call(Request::Bench {
                        raw,
                        count: u.int_in_range(0..=3)?,
                        rtd_step: u.arbitrary()?,
                    });
                }
            }
            13 => {
                what = "EraseAhead";
                let _ = h.dev().erase_ahead(&|| 0);
            }
            14 => {
                what = "Reboot";
                h.reboot();
                upload = None;
            }
            _ => {
                what = "PowerCut";
                // Power cycle, then cut the power inside the k-th flash operation from this
                // boot (0–3 quarters of it reaching the cells) while doing one of: the boot's
                // erase ahead, a load, a rollback, an activate of the previous table.
                let k = u.int_in_range(0..=7)?;
                let quarters = u.int_in_range(0..=3)?;
                let kind = u.int_in_range(0..=3)?;
                let before = h.model;
                let mut flash = h
                    .dev
                    .take()
                    .and_then(Service::into_flash)
                    .expect("the RAM flash store always opens");
                flash.cut_at = Some(k);
                flash.quarters = quarters;
                flash.cut = false;
                h.dev = Some(Service::new(Board::Qemu, flash, LAYOUT));
                let _ = h.dev().erase_ahead(&|| 0);
                let after = match kind {
                    0 => before,
                    1 => {
                        let bytes = h.tables[u.choose_index(TABLES)?];
                        let _ = h.load_unchecked(1, &bytes);
                        h.committed(&bytes)
                    }
                    _ => {
                        let r = if kind == 2 {
                            Request::Rollback
                        } else {
                            Request::Activate {
                                table_id: before.ids().1.unwrap_or(0),
                            }
                        };
                        let _ = h.call(r);
                        h.swapped()
                    }
                };
                // Power back on (the switch is reset by the reboot): old or new, nothing else.
                h.reboot();
                let got = h.state();
                assert!(
                    got == before.ids() || got == after.ids(),
                    "power cut (kind {kind}, flash op {k}, {quarters}/4 written): \
                     before {:?}, expected that or {:?}, booted with {got:?}",
                    before.ids(),
                    after.ids()
                );
                h.model = if got == after.ids() { after } else { before };
                upload = None;
            }
        }
        // Info and the read-back (8 requests; Info and ReadTable re-encode the tables, which
        // dominated the run time) only where the tables can have changed; every other answer
        // is checked against the model above.
        if matches!(
            what,
            "Load" | "Commit" | "Rollback" | "Activate" | "Reboot" | "PowerCut"
        ) {
            h.check(what);
        }
    }
    // Still answering after all that.
    let a = h.call(Request::Ping);
    assert!(matches!(
        a,
        DeviceMessage::Response {
            body: Response::Pong,
            ..
        }
    ));
    Ok(())
}

fuzz_target!(|data: &[u8]| {
    let mut u = Unstructured::new(data);
    let _ = run(&mut u);
});
