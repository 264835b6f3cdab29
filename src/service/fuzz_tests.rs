//! Stateful protocol fuzzing (issue #15.4): random sequences of valid and invalid requests —
//! interleaved uploads with reused and foreign ids, wrong offsets, corrupted and truncated
//! tables, read-back at any offset, activate/rollback by right and wrong ids, samples, bench,
//! garbage bodies, erase-ahead and reboots — are driven through `Service` and every answer and
//! the state reported by Info are checked against a reference model of the protocol written
//! from docs/protocol.md ([`crate::protocol::model`]).
//!
//! [`SEQUENCES`] sequences per `cargo test` run (split over two tests so both CI cores work);
//! the count and the runtime are in docs/benchmarks.md.

use super::*;
use crate::pipeline::Status;
use crate::protocol::model::{Expect, ProtocolModel};
use crate::storage::RamFlash;
use crate::table::tests::paper_table;
use crate::table::CRC32;
use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};
use std::vec::Vec;

type Flash = RamFlash<3072, 1024, 4>;
const LAYOUT: SlotLayout = SlotLayout::consecutive(1024);
/// Sequences per run, over the two test functions below.
const SEQUENCES: u32 = 100_000;
const MAX_OPS: usize = 24;
/// Sources of upload bytes: four valid tables, a bit-flipped one, one with a NaN (CRC fixed).
const SOURCES: usize = 6;

#[derive(Debug, Clone)]
enum Op {
    Ping,
    Info,
    /// Begin upload `uid` of source `src`; `len` 0 = the table's length, else a wrong one;
    /// `crc_ok` false announces a wrong checksum.
    Begin {
        uid: u32,
        src: usize,
        len: u16,
        crc_ok: bool,
    },
    /// A chunk of source `src` for upload `uid`: at the expected offset (or `offset` when
    /// `at_expected` is false), `n` bytes.
    Chunk {
        uid: u32,
        src: usize,
        at_expected: bool,
        offset: u16,
        n: usize,
    },
    /// A whole upload of source `src`, then commit (the common, well-formed case).
    Load {
        uid: u32,
        src: usize,
    },
    Commit {
        uid: u32,
    },
    ReadTable {
        offset: u16,
    },
    /// Activate source `src`'s id (or an arbitrary id when `src` ≥ SOURCES).
    Activate {
        src: usize,
        other: u32,
    },
    Rollback,
    Stream(bool),
    SetRate(u32),
    Inject,
    Bench(u32),
    /// A body that is not a valid frame (random bytes; if they decode, the model follows).
    Garbage(Vec<u8>),
    /// A frame the receiver rejected (bad CRC/COBS): counted, not answered.
    Dropped,
    EraseAhead,
    Reboot,
}

fn op() -> impl Strategy<Value = Op> {
    let uid = 1u32..4;
    prop_oneof![
        1 => Just(Op::Ping),
        2 => Just(Op::Info),
        4 => (uid.clone(), 0..SOURCES, prop_oneof![6 => Just(0u16), 1 => 0u16..600], prop::bool::weighted(0.9))
            .prop_map(|(uid, src, len, crc_ok)| Op::Begin { uid, src, len, crc_ok }),
        10 => (uid.clone(), 0..SOURCES, prop::bool::weighted(0.9), 0u16..500, prop_oneof![6 => Just(CHUNK_LEN), 1 => 1..=CHUNK_LEN])
            .prop_map(|(uid, src, at_expected, offset, n)| Op::Chunk { uid, src, at_expected, offset, n }),
        4 => (uid.clone(), 0..SOURCES).prop_map(|(uid, src)| Op::Load { uid, src }),
        3 => uid.prop_map(|uid| Op::Commit { uid }),
        2 => (0u16..500).prop_map(|offset| Op::ReadTable { offset }),
        3 => (0..SOURCES + 1, any::<u32>()).prop_map(|(src, other)| Op::Activate { src, other }),
        3 => Just(Op::Rollback),
        1 => any::<bool>().prop_map(Op::Stream),
        1 => prop_oneof![0u32..10, 3590u32..3610, any::<u32>()].prop_map(Op::SetRate),
        2 => Just(Op::Inject),
        1 => (0u32..3).prop_map(Op::Bench),
        2 => prop::collection::vec(any::<u8>(), 0..40).prop_map(Op::Garbage),
        1 => Just(Op::Dropped),
        2 => Just(Op::EraseAhead),
        2 => Just(Op::Reboot),
    ]
}

fn sources() -> [[u8; ENCODED_LEN]; SOURCES] {
    let mut out = [[0u8; ENCODED_LEN]; SOURCES];
    for (i, o) in out.iter_mut().enumerate().take(4) {
        let mut t = paper_table();
        t.date.day = 1 + i as u8;
        *o = t.encode();
    }
    out[4] = out[0];
    out[4][200] ^= 0x08;
    let mut nan = paper_table();
    nan.thermal.models.bias_g.coeffs[0] = f64::NAN;
    out[5] = nan.encode();
    out
}

fn id_of(bytes: &[u8; ENCODED_LEN]) -> u32 {
    crate::table::table_id(bytes)
}

struct Harness {
    dev: Service<Flash>,
    model: ProtocolModel,
    src: [[u8; ENCODED_LEN]; SOURCES],
    raw: RawSample,
}

impl Harness {
    fn send(&mut self, request: Request) -> Result<(), TestCaseError> {
        let expect = self.model.request(&request);
        let msg = self.dev.handle(
            HostFrame {
                id: 42,
                request: request.clone(),
            },
            &|| 5,
        );
        self.check(&request, expect, msg, 42)
    }

    fn check(
        &mut self,
        request: &Request,
        expect: Expect,
        msg: DeviceMessage,
        id: u32,
    ) -> Result<(), TestCaseError> {
        match (expect, msg) {
            (Expect::Body(b), DeviceMessage::Response { id: got, body }) => {
                prop_assert_eq!(got, id);
                prop_assert_eq!(body, b, "{:?}", request);
            }
            (Expect::Err(code, detail), DeviceMessage::Error { id: got, error }) => {
                prop_assert_eq!(got, id);
                prop_assert_eq!(
                    (error.code, error.detail),
                    (code as u16, detail),
                    "{:?}: expected {:?}",
                    request,
                    code
                );
            }
            (Expect::Sample { seq, calibrated }, DeviceMessage::Sample { id: got, frame }) => {
                prop_assert_eq!(got, id);
                prop_assert_eq!(frame.seq, seq);
                prop_assert_eq!(!frame.status.has(Status::NO_CALIBRATION), calibrated);
            }
            (Expect::Special, msg) => match (request, msg) {
                (
                    Request::Info,
                    DeviceMessage::Response {
                        body: Response::Info(i),
                        ..
                    },
                ) => {
                    let m = &self.model;
                    prop_assert_eq!((i.active_table, i.previous_table), m.tables.ids());
                    prop_assert_eq!(i.streaming, m.streaming);
                    prop_assert_eq!(i.samples, m.samples);
                    prop_assert_eq!(i.frames_dropped, m.frames_dropped);
                    if let Some(rate) = m.rate_hz {
                        prop_assert_eq!(i.rate_hz, rate);
                    }
                }
                (
                    Request::SetRate { hz },
                    DeviceMessage::Response {
                        body: Response::Ok, ..
                    },
                ) => {
                    prop_assert!(*hz > 0);
                    self.model.rate_hz = Some(*hz);
                }
                (Request::SetRate { .. }, DeviceMessage::Error { error, .. }) => {
                    prop_assert_eq!(error.code, ErrorCode::InvalidRate as u16);
                }
                (
                    Request::Bench { count, .. },
                    DeviceMessage::Response {
                        body: Response::Bench { count: c, .. },
                        ..
                    },
                ) => prop_assert_eq!(*count, c),
                (r, m) => prop_assert!(false, "{r:?} answered {m:?}"),
            },
            (e, m) => prop_assert!(false, "{request:?}: expected {e:?}, got {m:?}"),
        }
        Ok(())
    }

    fn run(&mut self, op: &Op) -> Result<(), TestCaseError> {
        match op {
            Op::Ping => self.send(Request::Ping),
            Op::Info => self.send(Request::Info),
            Op::Begin {
                uid,
                src,
                len,
                crc_ok,
            } => {
                let bytes = &self.src[*src];
                let total = if *len == 0 {
                    ENCODED_LEN as u32
                } else {
                    u32::from(*len)
                };
                let n = (total as usize).min(ENCODED_LEN);
                let mut crc = CRC32.checksum(&bytes[..n.saturating_sub(4)]);
                if !crc_ok {
                    crc ^= 0x0100_0000;
                }
                self.send(Request::UploadBegin {
                    upload_id: *uid,
                    total_len: total,
                    body_crc32: crc,
                })
            }
            Op::Chunk {
                uid,
                src,
                at_expected,
                offset,
                n,
            } => {
                let expected = self.model.expected_offset();
                let offset = if *at_expected {
                    expected
                } else {
                    usize::from(*offset)
                };
                let start = offset.min(ENCODED_LEN);
                let end = (start + n).min(ENCODED_LEN);
                let data =
                    heapless::Vec::from_slice(&self.src[*src][start..end]).unwrap_or_default();
                self.send(Request::UploadChunk {
                    upload_id: *uid,
                    offset: offset as u32,
                    data,
                })
            }
            Op::Load { uid, src } => {
                let bytes = self.src[*src];
                let crc = CRC32.checksum(&bytes[..ENCODED_LEN - 4]);
                self.send(Request::UploadBegin {
                    upload_id: *uid,
                    total_len: ENCODED_LEN as u32,
                    body_crc32: crc,
                })?;
                for offset in (0..ENCODED_LEN).step_by(CHUNK_LEN) {
                    let end = (offset + CHUNK_LEN).min(ENCODED_LEN);
                    let data = heapless::Vec::from_slice(&bytes[offset..end]).unwrap_or_default();
                    self.send(Request::UploadChunk {
                        upload_id: *uid,
                        offset: offset as u32,
                        data,
                    })?;
                }
                self.send(Request::UploadCommit { upload_id: *uid })
            }
            Op::Commit { uid } => self.send(Request::UploadCommit { upload_id: *uid }),
            Op::ReadTable { offset } => self.send(Request::ReadTable {
                offset: u32::from(*offset),
            }),
            Op::Activate { src, other } => {
                let table_id = self.src.get(*src).map_or(*other, id_of);
                self.send(Request::Activate { table_id })
            }
            Op::Rollback => self.send(Request::Rollback),
            Op::Stream(on) => self.send(if *on {
                Request::StreamStart
            } else {
                Request::StreamStop
            }),
            Op::SetRate(hz) => self.send(Request::SetRate { hz: *hz }),
            Op::Inject => self.send(Request::InjectSample { raw: self.raw }),
            Op::Bench(count) => self.send(Request::Bench {
                raw: self.raw,
                count: *count,
                // Both loop variants: the same sample, and the RTD code alternating.
                rtd_step: *count % 2,
            }),
            Op::Garbage(body) => {
                let msg = self.dev.handle_frame(Ok(body), &|| 5);
                match decode_message::<HostFrame>(body) {
                    Ok(frame) => {
                        // Random bytes that happen to be a request: the model answers it.
                        let expect = self.model.request(&frame.request);
                        let msg = msg.ok_or_else(|| TestCaseError::fail("no answer"))?;
                        self.check(&frame.request, expect, msg, frame.id)
                    }
                    Err(_) => {
                        let Some(DeviceMessage::Error { id, error }) = msg else {
                            return Err(TestCaseError::fail(format!("garbage answered {msg:?}")));
                        };
                        prop_assert_eq!(id, peek_request_id(body).unwrap_or(0));
                        prop_assert_eq!(error.code, ErrorCode::Malformed as u16);
                        Ok(())
                    }
                }
            }
            Op::Dropped => {
                let msg = self.dev.handle_frame(Err(FrameError::Cobs), &|| 5);
                prop_assert!(msg.is_none());
                self.model.frame_dropped();
                Ok(())
            }
            Op::EraseAhead => {
                prop_assert!(self.dev.erase_ahead(&|| 0).is_ok());
                Ok(())
            }
            Op::Reboot => {
                let flash = self
                    .dev
                    .clone()
                    .into_flash()
                    .ok_or_else(|| TestCaseError::fail("store closed"))?;
                self.dev = Service::new(Board::Qemu, flash, LAYOUT);
                self.model.reboot();
                Ok(())
            }
        }
    }
}

fn fuzz(seed_name: &str, cases: u32) {
    let src = sources();
    let raw = crate::pipeline::raw_from_physical(
        &paper_table(),
        crate::units::Volts(1.3),
        crate::units::Celsius(50.0),
        crate::units::TiltArcsec(0.0),
    )
    .unwrap_or(RawSample::from_codes(0, 0, 0));
    let config = Config {
        cases,
        failure_persistence: None,
        ..Config::default()
    };
    let mut runner = TestRunner::new_with_rng(
        config,
        proptest::test_runner::TestRng::from_seed(proptest::test_runner::RngAlgorithm::ChaCha, &{
            let mut seed = [0u8; 32];
            for (s, b) in seed.iter_mut().zip(seed_name.bytes()) {
                *s = b;
            }
            seed
        }),
    );
    let ran = core::cell::Cell::new(0u32);
    let started = std::time::Instant::now();
    runner
        .run(&prop::collection::vec(op(), 1..=MAX_OPS), |ops| {
            ran.set(ran.get() + 1);
            let mut h = Harness {
                dev: Service::new(Board::Qemu, Flash::new(), LAYOUT),
                model: ProtocolModel::default(),
                src,
                raw,
            };
            for op in &ops {
                h.run(op)?;
            }
            Ok(())
        })
        .unwrap_or_else(|e| panic!("{e}"));
    std::eprintln!(
        "stateful protocol fuzz {seed_name}: {} sequences in {:.1} s",
        ran.get(),
        started.elapsed().as_secs_f64()
    );
    assert!(ran.get() >= cases, "only {} sequences ran", ran.get());
}

#[test]
fn random_request_sequences_follow_the_protocol_model_first_half() {
    fuzz("accomp stateful fuzz, half 1", SEQUENCES / 2);
}

#[test]
fn random_request_sequences_follow_the_protocol_model_second_half() {
    fuzz("accomp stateful fuzz, half 2", SEQUENCES / 2);
}

#[test]
fn the_garbage_generator_can_reach_a_valid_request() {
    // The Garbage op's model branch is live: a well-formed body is answered as its request.
    let mut buf = [0u8; 16];
    let body = postcard::to_slice(
        &HostFrame {
            id: 3,
            request: Request::Ping,
        },
        &mut buf,
    )
    .map(|b| b.to_vec())
    .unwrap_or_default();
    assert!(!body.is_empty());
    let mut h = Harness {
        dev: Service::new(Board::Qemu, Flash::new(), LAYOUT),
        model: ProtocolModel::default(),
        src: sources(),
        raw: RawSample::from_codes(0, 0, 0),
    };
    assert!(h.run(&Op::Garbage(body)).is_ok());
}
