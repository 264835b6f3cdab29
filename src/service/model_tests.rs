//! Every sequence of load / activate / rollback over four tables, up to [`DEPTH`] operations,
//! checked against the protocol's reference model of what the user expects
//! ([`crate::protocol::model::TableHistory`]), on the live device, after erase-ahead and after a
//! reboot at every step.

use super::*;
use crate::protocol::model::TableHistory;
use crate::protocol::upload_requests;
use crate::storage::RamFlash;
use crate::table::tests::paper_table;

type Flash = RamFlash<3072, 1024, 4>;
const LAYOUT: SlotLayout = SlotLayout::consecutive(1024);
/// Longest sequence tried exhaustively: 9 operations per step, 9^5 = 59,049 sequences of
/// length 5 plus all shorter ones (66,429 nodes).
const DEPTH: usize = 5;
const TABLES: usize = 4;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Op {
    Load(usize),
    Activate(usize),
    Rollback,
}

/// What the device answered (the model's error codes, or Ok).
type Expect = Result<(), ErrorCode>;

/// The model's answer to `op` ([`crate::protocol::model::TableHistory`]).
fn apply(m: &mut TableHistory, op: Op, encoded: &[[u8; ENCODED_LEN]; TABLES]) -> Expect {
    match op {
        Op::Load(t) => {
            m.load(&encoded[t]);
            Ok(())
        }
        Op::Activate(t) => m.activate(crate::table::table_id(&encoded[t])),
        Op::Rollback => m.rollback(),
    }
}

fn tables() -> [CalibrationTable; TABLES] {
    core::array::from_fn(|i| {
        let mut t = paper_table();
        t.date.day = 1 + i as u8;
        t
    })
}

fn call(s: &mut Service<Flash>, request: Request) -> DeviceMessage {
    s.handle(HostFrame { id: 1, request }, &|| 0)
}

fn answer(m: &DeviceMessage) -> Expect {
    match m {
        DeviceMessage::Response { .. } => Ok(()),
        DeviceMessage::Error { error, .. } => {
            Err(ErrorCode::from_u16(error.code).unwrap_or(ErrorCode::Malformed))
        }
        other => panic!("unexpected {other:?}"),
    }
}

fn run(
    s: &mut Service<Flash>,
    op: Op,
    encoded: &[[u8; ENCODED_LEN]; TABLES],
    ids: &[u32],
) -> Expect {
    match op {
        Op::Load(t) => {
            let mut requests = upload_requests(0x5EED_0000 + t as u32, &encoded[t]).peekable();
            loop {
                let Some(request) = requests.next() else {
                    unreachable!("an upload ends with its commit")
                };
                let a = answer(&call(s, request));
                if requests.peek().is_none() {
                    break a;
                }
                assert_eq!(a, Ok(()));
            }
        }
        Op::Activate(t) => answer(&call(s, Request::Activate { table_id: ids[t] })),
        Op::Rollback => answer(&call(s, Request::Rollback)),
    }
}

/// (active, previous) table ids as Info reports them.
fn observed(s: &mut Service<Flash>) -> (Option<u32>, Option<u32>) {
    let DeviceMessage::Response {
        body: Response::Info(i),
        ..
    } = call(s, Request::Info)
    else {
        panic!("Info failed");
    };
    (i.active_table, i.previous_table)
}

struct Walk {
    encoded: [[u8; ENCODED_LEN]; TABLES],
    ids: [u32; TABLES],
    ops: [Op; 2 * TABLES + 1],
    nodes: usize,
}

impl Walk {
    fn visit(&mut self, s: &Service<Flash>, model: TableHistory, path: &mut std::vec::Vec<Op>) {
        if path.len() == DEPTH {
            return;
        }
        for op in self.ops {
            let mut dev = s.clone();
            let mut m = model;
            path.push(op);
            let expected = apply(&mut m, op, &self.encoded);
            let got = run(&mut dev, op, &self.encoded, &self.ids);
            assert_eq!(got, expected, "answer after {path:?}");
            assert_eq!(observed(&mut dev), m.ids(), "state after {path:?}");
            // The firmware erases ahead after every change; it must not change the state.
            let _ = dev.erase_ahead(&|| 0);
            assert_eq!(
                observed(&mut dev),
                m.ids(),
                "state after erase-ahead, {path:?}"
            );
            // Power off and on: the same state comes back from flash.
            let flash = dev.clone().into_flash().expect("store open");
            let mut rebooted = Service::new(Board::Qemu, flash, LAYOUT);
            assert_eq!(
                observed(&mut rebooted),
                m.ids(),
                "state after reboot, {path:?}"
            );
            self.nodes += 1;
            self.visit(&dev, m, path);
            path.pop();
        }
    }
}

#[test]
fn every_load_activate_rollback_sequence_of_four_tables_matches_what_the_user_expects() {
    let tables = tables();
    let mut ops = [Op::Rollback; 2 * TABLES + 1];
    for t in 0..TABLES {
        ops[t] = Op::Load(t);
        ops[TABLES + t] = Op::Activate(t);
    }
    let mut walk = Walk {
        encoded: tables.map(|t| t.encode()),
        ids: tables.map(|t| t.id()),
        ops,
        nodes: 0,
    };
    let start = Service::new(Board::Qemu, Flash::new(), LAYOUT);
    walk.visit(&start, TableHistory::default(), &mut std::vec::Vec::new());
    // 9 + 9² + … + 9⁵ sequences, each checked live, after erase-ahead and after a reboot.
    assert_eq!(
        walk.nodes,
        (1..=DEPTH as u32).map(|k| 9usize.pow(k)).sum::<usize>()
    );
}
