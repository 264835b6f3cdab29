//! What a user expects the device to answer, written from docs/protocol.md and docs/storage.md,
//! not from the service's code. The one reference model of the protocol: the exhaustive
//! load/activate/rollback walk and the stateful fuzzing of `Service`, the cargo-fuzz target
//! `request_sequence` and the host's QEMU persistence test all check the device against it.
//!
//! - loading the table that is active changes nothing (the rollback table stays);
//! - loading another table makes it active and the table active before it the rollback table;
//! - rollback (or activating the rollback table by id) swaps the two; activating the active
//!   table changes nothing; any other id is TableNotFound; rollback without a rollback table
//!   is NoPreviousTable;
//! - a reboot (power off/on) keeps the tables and starts everything else afresh;
//! - uploads: one at a time, chunks in order, checked against UploadBegin's length and CRC-32,
//!   decoded and validated before the commit makes the table active.

use heapless::Vec;

use super::codes::{ErrorCode, ErrorReply};
use super::messages::{upload_body_crc32, Request, Response, CHUNK_LEN, MAX_BENCH_COUNT};
use crate::table::{table_id, CalibrationTable, ENCODED_LEN};

/// An encoded calibration table, as uploaded and as read back.
pub type TableBytes = [u8; ENCODED_LEN];

/// The active table and the rollback table.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct TableHistory {
    /// The table samples are compensated with.
    pub active: Option<TableBytes>,
    /// The rollback target.
    pub previous: Option<TableBytes>,
}

impl TableHistory {
    /// A table was loaded (validated and committed).
    pub fn load(&mut self, table: &TableBytes) {
        if self.active.as_ref() != Some(table) {
            self.previous = self.active.replace(*table);
        }
    }

    /// Activate by id: the active one is a no-op, the previous one swaps, anything else fails.
    pub fn activate(&mut self, id: u32) -> Result<(), ErrorCode> {
        let (active, previous) = self.ids();
        if active == Some(id) {
            Ok(())
        } else if previous == Some(id) {
            core::mem::swap(&mut self.active, &mut self.previous);
            Ok(())
        } else {
            Err(ErrorCode::TableNotFound)
        }
    }

    /// Swap the active and the rollback table.
    pub fn rollback(&mut self) -> Result<(), ErrorCode> {
        if self.previous.is_none() {
            return Err(ErrorCode::NoPreviousTable);
        }
        core::mem::swap(&mut self.active, &mut self.previous);
        Ok(())
    }

    /// (active, previous) table ids, as Info reports them.
    pub fn ids(&self) -> (Option<u32>, Option<u32>) {
        (
            self.active.as_ref().map(table_id),
            self.previous.as_ref().map(table_id),
        )
    }
}

/// An upload in progress.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ModelUpload {
    /// Its id.
    pub upload_id: u32,
    /// Announced length.
    pub total_len: usize,
    /// Announced CRC-32 of all bytes but the last four.
    pub body_crc32: u32,
    /// Bytes received so far.
    pub bytes: Vec<u8, ENCODED_LEN>,
}

/// What the model expects for one request.
#[derive(Debug, Clone, PartialEq)]
pub enum Expect {
    /// This exact answer.
    Body(Response),
    /// This error code with this detail.
    Err(ErrorCode, u32),
    /// A sample with this sequence number, compensated (`calibrated`) or flagged NO_CALIBRATION.
    Sample {
        /// Sequence number.
        seq: u32,
        /// A table is active.
        calibrated: bool,
    },
    /// Depends on the device (Info, SetRate, Bench): the caller checks it against the model's
    /// state.
    Special,
}

/// The protocol's state as a user sees it.
#[derive(Debug, Clone, Default)]
pub struct ProtocolModel {
    /// Tables (kept across reboots).
    pub tables: TableHistory,
    /// Upload in progress.
    pub upload: Option<ModelUpload>,
    /// Streaming of acquired samples on.
    pub streaming: bool,
    /// Rate last accepted by SetRate, when the caller told the model.
    pub rate_hz: Option<u32>,
    /// Samples processed since boot (the next sample's seq).
    pub samples: u32,
    /// Frames the receiver refused since boot.
    pub frames_dropped: u32,
}

impl ProtocolModel {
    /// The next offset the upload in progress expects (0 without one).
    pub fn expected_offset(&self) -> usize {
        self.upload.as_ref().map_or(0, |u| u.bytes.len())
    }

    /// A frame the receiver refused (bad CRC or COBS): counted, not answered.
    pub fn frame_dropped(&mut self) {
        self.frames_dropped = self.frames_dropped.wrapping_add(1);
    }

    /// Applies a request and says what the device must answer.
    pub fn request(&mut self, r: &Request) -> Expect {
        use ErrorCode as C;
        match r {
            Request::Ping => Expect::Body(Response::Pong),
            Request::Info | Request::SetRate { .. } => Expect::Special,
            Request::UploadBegin {
                upload_id,
                total_len,
                body_crc32,
            } => {
                self.upload = None;
                if *total_len as usize > ENCODED_LEN {
                    return Expect::Err(C::UploadTooLong, ENCODED_LEN as u32);
                }
                self.upload = Some(ModelUpload {
                    upload_id: *upload_id,
                    total_len: *total_len as usize,
                    body_crc32: *body_crc32,
                    bytes: Vec::new(),
                });
                Expect::Body(Response::Ok)
            }
            Request::UploadChunk {
                upload_id,
                offset,
                data,
            } => {
                let Some(u) = self.upload.as_mut() else {
                    return Expect::Err(C::NoUpload, 0);
                };
                if *upload_id != u.upload_id {
                    return Expect::Err(C::UploadIdMismatch, u.upload_id);
                }
                if *offset as usize != u.bytes.len() {
                    return Expect::Err(C::ChunkOutOfOrder, u.bytes.len() as u32);
                }
                if u.bytes.len() + data.len() > u.total_len
                    || u.bytes.extend_from_slice(data).is_err()
                {
                    return Expect::Err(C::UploadTooLong, u.total_len as u32);
                }
                Expect::Body(Response::Ok)
            }
            Request::UploadCommit { upload_id } => {
                let Some(u) = self.upload.take() else {
                    return Expect::Err(C::NoUpload, 0);
                };
                if *upload_id != u.upload_id {
                    let id = u.upload_id;
                    self.upload = Some(u);
                    return Expect::Err(C::UploadIdMismatch, id);
                }
                if u.bytes.len() != u.total_len {
                    return Expect::Err(C::UploadIncomplete, u.bytes.len() as u32);
                }
                let body = upload_body_crc32(&u.bytes);
                if body != u.body_crc32 {
                    return Expect::Err(C::UploadCrcMismatch, body);
                }
                if let Err(e) = CalibrationTable::decode(&u.bytes) {
                    let e = ErrorReply::from(e);
                    return Expect::Err(
                        ErrorCode::from_u16(e.code).unwrap_or(C::Malformed),
                        e.detail,
                    );
                }
                let mut t = [0u8; ENCODED_LEN];
                t.copy_from_slice(&u.bytes);
                self.tables.load(&t);
                Expect::Body(Response::Committed {
                    table_id: table_id(&t),
                })
            }
            Request::ReadTable { offset } => {
                let Some(a) = self.tables.active.as_ref() else {
                    return Expect::Err(C::NoTable, 0);
                };
                let start = *offset as usize;
                let Some(rest) = a.get(start..) else {
                    return Expect::Err(C::OffsetOutOfRange, ENCODED_LEN as u32);
                };
                Expect::Body(Response::TableChunk {
                    offset: *offset,
                    total_len: ENCODED_LEN as u32,
                    data: Vec::from_slice(rest.get(..CHUNK_LEN).unwrap_or(rest))
                        .unwrap_or_default(),
                })
            }
            Request::Activate { table_id } => match self.tables.activate(*table_id) {
                Ok(()) => Expect::Body(Response::Ok),
                Err(c) => Expect::Err(c, 0),
            },
            Request::Rollback => match self.tables.rollback() {
                Ok(()) => Expect::Body(Response::Ok),
                Err(c) => Expect::Err(c, 0),
            },
            Request::StreamStart | Request::StreamStop => {
                self.streaming = matches!(r, Request::StreamStart);
                Expect::Body(Response::Ok)
            }
            Request::InjectSample { .. } => {
                let seq = self.samples;
                self.samples = self.samples.wrapping_add(1);
                Expect::Sample {
                    seq,
                    calibrated: self.tables.active.is_some(),
                }
            }
            Request::Bench { count, .. } => {
                if *count == 0 || *count > MAX_BENCH_COUNT {
                    Expect::Err(C::InvalidCount, MAX_BENCH_COUNT)
                } else {
                    Expect::Special
                }
            }
        }
    }

    /// Power off and on: the tables come back from flash, everything else starts over.
    pub fn reboot(&mut self) {
        *self = ProtocolModel {
            tables: self.tables,
            ..ProtocolModel::default()
        };
    }
}
