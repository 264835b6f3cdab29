//! The device side of the protocol as a pure state machine: requests in, one message out.
//!
//! The firmware only moves bytes between the UART and this type, so every rule of the protocol
//! (upload sequencing, validation before activation, rollback, error codes) is unit-tested on the
//! host and is the same code that runs on the board.

use crate::pipeline::{self, RawSample};
use crate::prepared::PreparedCalibration;
use crate::protocol::{
    decode_message, peek_request_id, Board, DeviceInfo, DeviceMessage, ErrorCode, ErrorReply,
    FrameError, HostFrame, Request, Response, CHUNK_LEN, MAX_BENCH_COUNT, MAX_RATE_HZ,
    PROTOCOL_VERSION,
};
use crate::table::{CalibrationTable, CRC32, ENCODED_LEN};

/// Default acquisition rate in samples per second.
pub const DEFAULT_RATE_HZ: u32 = 10;

struct Upload {
    in_progress: bool,
    total_len: usize,
    crc32: u32,
    received: usize,
    buf: [u8; ENCODED_LEN],
}

/// Protocol state of the device: tables, upload in progress, counters.
pub struct Service {
    board: Board,
    active: Option<CalibrationTable>,
    previous: Option<CalibrationTable>,
    /// The active table prepared for the per-sample path; rebuilt whenever `active` changes.
    prepared: Option<PreparedCalibration>,
    upload: Upload,
    seq: u32,
    frames_dropped: u32,
    streaming: bool,
    rate_hz: u32,
}

impl Service {
    /// A device with no table (until storage restores one).
    pub const fn new(board: Board) -> Self {
        Service {
            board,
            active: None,
            previous: None,
            prepared: None,
            upload: Upload {
                in_progress: false,
                total_len: 0,
                crc32: 0,
                received: 0,
                buf: [0; ENCODED_LEN],
            },
            seq: 0,
            frames_dropped: 0,
            streaming: false,
            rate_hz: DEFAULT_RATE_HZ,
        }
    }

    /// The table used for samples, if any.
    pub fn active_table(&self) -> Option<&CalibrationTable> {
        self.active.as_ref()
    }

    /// Installs a table without the upload dance (restored from flash at boot).
    pub fn install(&mut self, table: CalibrationTable) {
        self.previous = self.active.replace(table);
        self.prepare_active();
    }

    /// True when acquired samples are to be streamed.
    pub fn streaming(&self) -> bool {
        self.streaming
    }

    /// Acquisition rate in samples per second.
    pub fn rate_hz(&self) -> u32 {
        self.rate_hz
    }

    /// Counts a frame the transport had to drop (queue full) without handing it over.
    pub fn count_dropped(&mut self) {
        self.frames_dropped = self.frames_dropped.wrapping_add(1);
    }

    /// Prepares the active table for the per-sample path (after every change of `active`).
    fn prepare_active(&mut self) {
        self.prepared = self
            .active
            .as_ref()
            .and_then(|t| PreparedCalibration::new(t).ok());
    }

    /// Runs one acquired or injected sample through the pipeline with the active table.
    pub fn sample(&mut self, id: u32, raw: &RawSample, now_us: u64) -> DeviceMessage {
        let frame = pipeline::process_prepared(self.seq, now_us, raw, self.prepared.as_ref());
        self.seq = self.seq.wrapping_add(1);
        DeviceMessage::Sample { id, frame }
    }

    /// Handles what the frame decoder produced. Frames with broken framing are counted and
    /// dropped (their id cannot be trusted); a frame with a good CRC always gets an answer.
    pub fn handle_frame(
        &mut self,
        frame: Result<&[u8], FrameError>,
        clock: &dyn Fn() -> u64,
    ) -> Option<DeviceMessage> {
        let body = match frame {
            Ok(body) => body,
            Err(_) => {
                self.count_dropped();
                return None;
            }
        };
        match decode_message::<HostFrame>(body) {
            Ok(f) => Some(self.handle(f, clock)),
            Err(e) => Some(DeviceMessage::Error {
                id: peek_request_id(body).unwrap_or(0),
                error: e.reply(),
            }),
        }
    }

    /// Handles one decoded request; `clock` gives the firmware time in µs.
    pub fn handle(&mut self, frame: HostFrame, clock: &dyn Fn() -> u64) -> DeviceMessage {
        let id = frame.id;
        let now_us = clock();
        if let Request::Bench { raw, count } = &frame.request {
            return match self.bench(raw, *count, clock) {
                Ok(body) => DeviceMessage::Response { id, body },
                Err(error) => DeviceMessage::Error { id, error },
            };
        }
        if let Request::InjectSample { raw } = &frame.request {
            if self.board == Board::Qemu {
                return self.sample(id, raw, now_us);
            }
        }
        match self.respond(frame.request, now_us) {
            Ok(body) => DeviceMessage::Response { id, body },
            Err(error) => DeviceMessage::Error { id, error },
        }
    }

    fn respond(&mut self, request: Request, now_us: u64) -> Result<Response, ErrorReply> {
        match request {
            Request::Ping => Ok(Response::Pong),
            Request::Info => Ok(Response::Info(self.info(now_us))),
            Request::UploadBegin { total_len, crc32 } => {
                let total_len = total_len as usize;
                // A new Begin always restarts: a host that lost track can start over.
                self.upload.in_progress = false;
                if total_len > ENCODED_LEN {
                    return Err(ErrorCode::UploadTooLong.reply(ENCODED_LEN as u32));
                }
                self.upload.in_progress = true;
                self.upload.total_len = total_len;
                self.upload.crc32 = crc32;
                self.upload.received = 0;
                Ok(Response::Ok)
            }
            Request::UploadChunk { offset, data } => {
                let u = &mut self.upload;
                if !u.in_progress {
                    return Err(ErrorCode::NoUpload.reply(0));
                }
                if offset as usize != u.received {
                    return Err(ErrorCode::ChunkOutOfOrder.reply(u.received as u32));
                }
                let end = u.received + data.len();
                if end > u.total_len {
                    return Err(ErrorCode::UploadTooLong.reply(u.total_len as u32));
                }
                u.buf
                    .get_mut(u.received..end)
                    .ok_or(ErrorCode::UploadTooLong.reply(u.total_len as u32))?
                    .copy_from_slice(&data);
                u.received = end;
                Ok(Response::Ok)
            }
            Request::UploadCommit => self.commit(),
            Request::ReadTable { offset } => {
                let table = self.active.as_ref().ok_or(ErrorCode::NoTable.reply(0))?;
                // Re-encoding is deterministic (decode → encode is bit-exact), so the device
                // keeps the decoded table only and the read-back is what it really uses.
                let encoded = table.encode();
                let start = offset as usize;
                if start > ENCODED_LEN {
                    return Err(ErrorCode::OffsetOutOfRange.reply(ENCODED_LEN as u32));
                }
                let end = (start + CHUNK_LEN).min(ENCODED_LEN);
                let mut data = heapless::Vec::new();
                data.extend_from_slice(encoded.get(start..end).unwrap_or(&[]))
                    .map_err(|_| ErrorCode::OffsetOutOfRange.reply(ENCODED_LEN as u32))?;
                Ok(Response::TableChunk {
                    offset,
                    total_len: ENCODED_LEN as u32,
                    data,
                })
            }
            Request::Activate { table_id } => {
                if self.active.as_ref().map(CalibrationTable::id) == Some(table_id) {
                    Ok(Response::Ok)
                } else if self.previous.as_ref().map(CalibrationTable::id) == Some(table_id) {
                    core::mem::swap(&mut self.active, &mut self.previous);
                    self.prepare_active();
                    Ok(Response::Ok)
                } else {
                    Err(ErrorCode::TableNotFound.reply(0))
                }
            }
            Request::Rollback => {
                if self.previous.is_none() {
                    return Err(ErrorCode::NoPreviousTable.reply(0));
                }
                core::mem::swap(&mut self.active, &mut self.previous);
                self.prepare_active();
                Ok(Response::Ok)
            }
            Request::StreamStart => {
                self.streaming = true;
                Ok(Response::Ok)
            }
            Request::StreamStop => {
                self.streaming = false;
                Ok(Response::Ok)
            }
            Request::SetRate { hz } => {
                if hz == 0 || hz > MAX_RATE_HZ {
                    return Err(ErrorCode::InvalidRate.reply(MAX_RATE_HZ));
                }
                self.rate_hz = hz;
                Ok(Response::Ok)
            }
            Request::InjectSample { .. } => Err(ErrorCode::NotSupported.reply(0)),
            Request::Bench { .. } => Err(ErrorCode::Malformed.reply(0)),
        }
    }

    fn bench(
        &self,
        raw: &RawSample,
        count: u32,
        clock: &dyn Fn() -> u64,
    ) -> Result<Response, ErrorReply> {
        if count == 0 || count > MAX_BENCH_COUNT {
            return Err(ErrorCode::InvalidCount.reply(MAX_BENCH_COUNT));
        }
        let table = self.prepared.as_ref();
        let start = clock();
        let mut sum = 0.0;
        for i in 0..count {
            // black_box: the same sample each time must still be computed each time.
            let r = core::hint::black_box(raw);
            sum += pipeline::process_prepared(i, start, r, table).a_i_exact_g;
        }
        let elapsed_us = clock().saturating_sub(start);
        Ok(Response::Bench {
            count,
            elapsed_us,
            a_i_sum_g: sum,
        })
    }

    fn commit(&mut self) -> Result<Response, ErrorReply> {
        let u = &mut self.upload;
        if !u.in_progress {
            return Err(ErrorCode::NoUpload.reply(0));
        }
        // Whatever happens next, this upload is finished: a retry starts with UploadBegin.
        u.in_progress = false;
        if u.received != u.total_len {
            return Err(ErrorCode::UploadIncomplete.reply(u.received as u32));
        }
        let bytes = u.buf.get(..u.total_len).unwrap_or(&[]);
        let computed = CRC32.checksum(bytes);
        if computed != u.crc32 {
            return Err(ErrorCode::UploadCrcMismatch.reply(computed));
        }
        let table = CalibrationTable::decode(bytes).map_err(ErrorReply::from)?;
        let table_id = table.id();
        self.install(table);
        Ok(Response::Committed { table_id })
    }

    fn info(&self, now_us: u64) -> DeviceInfo {
        let mut firmware = heapless::String::new();
        // The version string is short ("0.1.0"); a longer one is cut, not a failure.
        for c in env!("CARGO_PKG_VERSION").chars() {
            if firmware.push(c).is_err() {
                break;
            }
        }
        DeviceInfo {
            firmware,
            board: self.board,
            protocol: PROTOCOL_VERSION,
            active_table: self.active.as_ref().map(CalibrationTable::id),
            previous_table: self.previous.as_ref().map(CalibrationTable::id),
            uptime_ms: now_us / 1000,
            frames_dropped: self.frames_dropped,
            samples: self.seq,
            streaming: self.streaming,
            rate_hz: self.rate_hz,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::{raw_from_physical, Status};
    use crate::protocol::{encode_frame, FrameDecoder, MAX_FRAME_LEN};
    use crate::table::tests::paper_table;
    use crate::units::{Celsius, TiltArcsec, Volts};

    fn req(s: &mut Service, request: Request) -> DeviceMessage {
        s.handle(HostFrame { id: 9, request }, &|| 1_000)
    }

    fn upload(s: &mut Service, bytes: &[u8]) -> DeviceMessage {
        let crc32 = CRC32.checksum(bytes);
        let begin = req(
            s,
            Request::UploadBegin {
                total_len: bytes.len() as u32,
                crc32,
            },
        );
        if !matches!(begin, DeviceMessage::Response { .. }) {
            return begin;
        }
        for (i, chunk) in bytes.chunks(CHUNK_LEN).enumerate() {
            let r = req(
                s,
                Request::UploadChunk {
                    offset: (i * CHUNK_LEN) as u32,
                    data: heapless::Vec::from_slice(chunk).unwrap(),
                },
            );
            assert_eq!(
                r,
                DeviceMessage::Response {
                    id: 9,
                    body: Response::Ok
                }
            );
        }
        req(s, Request::UploadCommit)
    }

    fn error_code(m: &DeviceMessage) -> Option<(u16, u32)> {
        match m {
            DeviceMessage::Error { error, .. } => Some((error.code, error.detail)),
            _ => None,
        }
    }

    fn active_id(s: &mut Service) -> Option<u32> {
        match req(s, Request::Info) {
            DeviceMessage::Response {
                body: Response::Info(i),
                ..
            } => i.active_table,
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_good_upload_is_committed_and_becomes_active() {
        let mut s = Service::new(Board::Qemu);
        let t = paper_table();
        let r = upload(&mut s, &t.encode());
        assert_eq!(
            r,
            DeviceMessage::Response {
                id: 9,
                body: Response::Committed { table_id: t.id() }
            }
        );
        assert_eq!(active_id(&mut s), Some(t.id()));
    }

    #[test]
    fn corrupted_uploads_are_refused_with_their_code_and_the_good_table_stays() {
        let mut s = Service::new(Board::Qemu);
        let good = paper_table();
        upload(&mut s, &good.encode());

        let mut flipped = good.encode();
        flipped[100] ^= 0x04;
        assert_eq!(
            error_code(&upload(&mut s, &flipped)).map(|e| e.0),
            Some(ErrorCode::TableBadCrc as u16)
        );
        let truncated = &good.encode()[..ENCODED_LEN - 10];
        assert_eq!(
            error_code(&upload(&mut s, truncated)).map(|e| e.0),
            Some(ErrorCode::TableBadLength as u16)
        );
        let mut nan = good;
        nan.thermal.models.scale_factor_v_per_g.coeffs[0] = f64::NAN;
        assert_eq!(
            error_code(&upload(&mut s, &nan.encode())),
            Some((ErrorCode::TableNonFinite as u16, 11))
        );
        assert_eq!(active_id(&mut s), Some(good.id()));
    }

    #[test]
    fn chunks_out_of_order_name_the_expected_offset() {
        let mut s = Service::new(Board::Qemu);
        let bytes = paper_table().encode();
        req(
            &mut s,
            Request::UploadBegin {
                total_len: ENCODED_LEN as u32,
                crc32: CRC32.checksum(&bytes),
            },
        );
        let chunk = |o: usize| Request::UploadChunk {
            offset: o as u32,
            data: heapless::Vec::from_slice(&bytes[o..o + CHUNK_LEN]).unwrap(),
        };
        req(&mut s, chunk(0));
        let r = req(&mut s, chunk(2 * CHUNK_LEN));
        assert_eq!(
            error_code(&r),
            Some((ErrorCode::ChunkOutOfOrder as u16, CHUNK_LEN as u32))
        );
        let r = req(&mut s, Request::UploadCommit);
        assert_eq!(
            error_code(&r),
            Some((ErrorCode::UploadIncomplete as u16, CHUNK_LEN as u32))
        );
        // The commit closed the upload: a further chunk has no upload to join.
        assert_eq!(
            error_code(&req(&mut s, chunk(CHUNK_LEN))).map(|e| e.0),
            Some(ErrorCode::NoUpload as u16)
        );
    }

    #[test]
    fn upload_crc_mismatch_is_caught_before_decoding() {
        let mut s = Service::new(Board::Qemu);
        let bytes = paper_table().encode();
        req(
            &mut s,
            Request::UploadBegin {
                total_len: ENCODED_LEN as u32,
                crc32: 0x1234_5678,
            },
        );
        for (i, c) in bytes.chunks(CHUNK_LEN).enumerate() {
            req(
                &mut s,
                Request::UploadChunk {
                    offset: (i * CHUNK_LEN) as u32,
                    data: heapless::Vec::from_slice(c).unwrap(),
                },
            );
        }
        let r = req(&mut s, Request::UploadCommit);
        assert_eq!(
            error_code(&r),
            Some((ErrorCode::UploadCrcMismatch as u16, CRC32.checksum(&bytes)))
        );
        assert_eq!(active_id(&mut s), None);
    }

    #[test]
    fn read_back_returns_the_committed_bytes() {
        let mut s = Service::new(Board::Qemu);
        let bytes = paper_table().encode();
        upload(&mut s, &bytes);
        let mut back = std::vec::Vec::new();
        while back.len() < ENCODED_LEN {
            match req(
                &mut s,
                Request::ReadTable {
                    offset: back.len() as u32,
                },
            ) {
                DeviceMessage::Response {
                    body: Response::TableChunk { data, .. },
                    ..
                } => back.extend_from_slice(&data),
                other => panic!("{other:?}"),
            }
        }
        assert_eq!(back, bytes);
    }

    #[test]
    fn rollback_and_activate_switch_between_the_two_tables() {
        let mut s = Service::new(Board::Qemu);
        assert_eq!(
            error_code(&req(&mut s, Request::Rollback)).map(|e| e.0),
            Some(ErrorCode::NoPreviousTable as u16)
        );
        let a = paper_table();
        let mut b = paper_table();
        b.date.day = 2;
        upload(&mut s, &a.encode());
        upload(&mut s, &b.encode());
        assert_eq!(active_id(&mut s), Some(b.id()));
        req(&mut s, Request::Rollback);
        assert_eq!(active_id(&mut s), Some(a.id()));
        req(&mut s, Request::Activate { table_id: b.id() });
        assert_eq!(active_id(&mut s), Some(b.id()));
        assert_eq!(
            error_code(&req(&mut s, Request::Activate { table_id: 1 })).map(|e| e.0),
            Some(ErrorCode::TableNotFound as u16)
        );
    }

    #[test]
    fn injected_samples_use_the_active_table_and_count_up() {
        let mut s = Service::new(Board::Qemu);
        let t = paper_table();
        let raw = raw_from_physical(&t, Volts(1.3), Celsius(50.0), TiltArcsec(0.0)).unwrap();
        let m = req(&mut s, Request::InjectSample { raw });
        let DeviceMessage::Sample { id: 9, frame } = m else {
            panic!("{m:?}")
        };
        assert_eq!(frame.status, Status(Status::NO_CALIBRATION));
        upload(&mut s, &t.encode());
        let DeviceMessage::Sample { frame, .. } = req(&mut s, Request::InjectSample { raw }) else {
            panic!()
        };
        assert_eq!(frame.seq, 1);
        assert_eq!(frame, pipeline::process(1, 1_000, &raw, Some(&t)));
    }

    #[test]
    fn bench_runs_the_pipeline_count_times_and_reports_the_clock() {
        let mut s = Service::new(Board::Qemu);
        let t = paper_table();
        upload(&mut s, &t.encode());
        let raw = raw_from_physical(&t, Volts(1.3), Celsius(50.0), TiltArcsec(0.0)).unwrap();
        let ticks = core::cell::Cell::new(0u64);
        let clock = || {
            ticks.set(ticks.get() + 250);
            ticks.get()
        };
        let m = s.handle(
            HostFrame {
                id: 1,
                request: Request::Bench { raw, count: 3 },
            },
            &clock,
        );
        let one = pipeline::process(0, 0, &raw, Some(&t)).a_i_exact_g;
        match m {
            DeviceMessage::Response {
                body:
                    Response::Bench {
                        count,
                        elapsed_us,
                        a_i_sum_g,
                    },
                ..
            } => {
                assert_eq!((count, elapsed_us), (3, 250));
                assert_eq!(a_i_sum_g, one + one + one);
            }
            other => panic!("{other:?}"),
        }
        let m = s.handle(
            HostFrame {
                id: 1,
                request: Request::Bench { raw, count: 0 },
            },
            &clock,
        );
        assert!(
            matches!(m, DeviceMessage::Error { error, .. } if error.code == ErrorCode::InvalidCount as u16)
        );
    }

    #[test]
    fn the_frontend_refuses_injection_and_bad_rates() {
        let mut s = Service::new(Board::Frontend);
        let raw =
            raw_from_physical(&paper_table(), Volts(1.0), Celsius(50.0), TiltArcsec(0.0)).unwrap();
        assert_eq!(
            error_code(&req(&mut s, Request::InjectSample { raw })).map(|e| e.0),
            Some(ErrorCode::NotSupported as u16)
        );
        assert_eq!(
            error_code(&req(&mut s, Request::SetRate { hz: 0 })),
            Some((ErrorCode::InvalidRate as u16, MAX_RATE_HZ))
        );
        req(&mut s, Request::SetRate { hz: 100 });
        assert_eq!(s.rate_hz(), 100);
    }

    #[test]
    fn a_frame_with_a_good_crc_but_unknown_request_is_answered_with_its_id() {
        let mut s = Service::new(Board::Qemu);
        // id 77 then variant index 200: not a request.
        let mut wire = [0u8; MAX_FRAME_LEN];
        #[derive(serde::Serialize)]
        struct Fake(u32, u8);
        let n = encode_frame(&Fake(77, 200), &mut wire).unwrap();
        let mut d = FrameDecoder::<MAX_FRAME_LEN>::new();
        let mut out = None;
        for &b in &wire[..n] {
            if let Some(f) = d.push(b) {
                out = s.handle_frame(f, &|| 0);
            }
        }
        assert_eq!(
            error_code(out.as_ref().unwrap()),
            Some((ErrorCode::Malformed as u16, 0))
        );
        match out.unwrap() {
            DeviceMessage::Error { id, .. } => assert_eq!(id, 77),
            other => panic!("{other:?}"),
        }
    }
}
