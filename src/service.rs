//! The device side of the protocol as a pure state machine: requests in, one message out.
//!
//! The firmware only moves bytes between the UART and this type, so every rule of the protocol
//! (upload sequencing, validation before activation, rollback, error codes) is unit-tested on the
//! host and is the same code that runs on the board.
//!
//! Tables persist in a [`CalibrationStore`] over the board's NOR flash (internal sectors 9–11
//! on the front-end, a [`crate::storage::RamFlash`] on QEMU): a table becomes active in RAM only
//! after the store has committed it, and boot restores the newest valid slot (and the newest
//! one with another table as the rollback table). The RAM copies are what the pipeline uses;
//! flash is touched only by commit, activate, rollback and [`Service::erase_ahead`].
//!
//! What the user expects of load/activate/rollback (tested exhaustively against a reference
//! model): loading the active table again changes nothing; any change of the active table
//! (load of another table, activate of the previous one, rollback) makes the table active
//! before it the rollback table; rollback and activate swap back; all of it survives a reboot.

use crate::pipeline::{self, LossFlags, RawSample};
use crate::prepared::PreparedCalibration;
use crate::protocol::{
    decode_message, peek_request_id, upload_body_crc32, Board, BootReport, DeviceInfo,
    DeviceMessage, ErrorCode, ErrorReply, FlashErrorReply, FrameError, HostFrame, LossCounters,
    Request, Response, CHUNK_LEN, MAX_BENCH_COUNT, MAX_RATE_HZ, PROTOCOL_VERSION, SET_RATES_SPS,
};
use crate::storage::{CalibrationStore, SlotLayout, StorageError, ValidSlots};
use crate::table::{CalibrationTable, ENCODED_LEN};
use embedded_storage::nor_flash::NorFlash;

/// Default acquisition rate in samples per second.
pub const DEFAULT_RATE_HZ: u32 = 10;

#[derive(Clone)]
struct Upload {
    in_progress: bool,
    upload_id: u32,
    total_len: usize,
    body_crc32: u32,
    received: usize,
    buf: [u8; ENCODED_LEN],
}

/// What the calibration store said at boot (kept for diagnostics; the firmware logs it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BootTable {
    /// The newest valid slot's table is active.
    Restored {
        /// Sequence number of the slot it came from.
        sequence: u32,
        /// Whether a different, older table was restored as the rollback table too.
        with_previous: bool,
    },
    /// No valid slot (factory-empty flash or both slots corrupted): samples carry
    /// NO_CALIBRATION until a table is uploaded.
    Empty,
    /// The store could not be read or opened; the device runs without a table and refuses
    /// commits with StorageUnavailable (or FlashFailed).
    StorageFault,
}

/// Protocol state of the device: tables, upload in progress, counters, and the flash store.
/// Clone (with a cloneable flash) lets tests branch a device's state.
#[derive(Clone)]
pub struct Service<F> {
    board: Board,
    active: Option<CalibrationTable>,
    previous: Option<CalibrationTable>,
    /// The active table prepared for the per-sample path; rebuilt whenever `active` changes.
    prepared: Option<PreparedCalibration>,
    upload: Upload,
    /// Sequence number the next reading is expected to carry.
    seq: u32,
    frames_dropped: u32,
    losses: LossCounters,
    /// Losses noticed here (a frame that could not be sent) to report on the next frame.
    pending_lost: LossFlags,
    streaming: bool,
    rate_hz: u32,
    /// None when the store could not be opened at boot (layout does not fit the flash).
    store: Option<CalibrationStore<F>>,
    boot: BootTable,
    boot_report: BootReport,
    /// The spare slot may not be erased yet: [`Service::erase_ahead`] has work to do.
    erase_pending: bool,
}

/// A calibration flash: any embedded-storage NOR flash whose error has a protocol code
/// ([`FlashErrorReply`]: each driver says how its errors read on the wire, the service names
/// no driver).
pub trait CalibrationFlash: NorFlash {
    /// The reply for a driver error.
    fn error_reply(e: &Self::Error) -> ErrorReply;
}

impl<F: NorFlash> CalibrationFlash for F
where
    F::Error: FlashErrorReply,
{
    fn error_reply(e: &Self::Error) -> ErrorReply {
        e.reply()
    }
}

/// The protocol reply for a storage failure of flash `F`.
pub fn storage_reply<F: CalibrationFlash>(e: StorageError<F::Error>) -> ErrorReply {
    match e {
        StorageError::Flash(f) => F::error_reply(&f),
        StorageError::Table(t) => t.into(),
        StorageError::Verify(slot) => ErrorCode::FlashVerify.reply(slot.index() as u32),
        StorageError::NoValidSlot | StorageError::NoPreviousSlot => {
            ErrorCode::NoPreviousTable.reply(0)
        }
        StorageError::Layout(_) => ErrorCode::StorageUnavailable.reply(0),
    }
}

impl<F: CalibrationFlash> Service<F> {
    /// Opens the calibration store on `flash` and restores the newest valid table (active) and
    /// the newest valid slot with another table (previous, for rollback). Never fails: a device
    /// without a usable store still answers and streams (flagged NO_CALIBRATION).
    pub fn new(board: Board, flash: F, layout: SlotLayout) -> Self {
        let mut s = Service {
            board,
            active: None,
            previous: None,
            prepared: None,
            upload: Upload {
                in_progress: false,
                upload_id: 0,
                total_len: 0,
                body_crc32: 0,
                received: 0,
                buf: [0; ENCODED_LEN],
            },
            seq: 0,
            frames_dropped: 0,
            losses: LossCounters::default(),
            pending_lost: LossFlags(0),
            streaming: false,
            rate_hz: DEFAULT_RATE_HZ,
            store: None,
            boot: BootTable::StorageFault,
            boot_report: BootReport::default(),
            erase_pending: false,
        };
        if let Ok(mut store) = CalibrationStore::new(flash, layout) {
            s.boot = s.restore(&mut store).unwrap_or(BootTable::StorageFault);
            s.store = Some(store);
            // An erase is remembered in RAM only: after a boot the spare is erased again.
            s.erase_pending = true;
        }
        s
    }

    fn restore(
        &mut self,
        store: &mut CalibrationStore<F>,
    ) -> Result<BootTable, StorageError<F::Error>> {
        let ValidSlots { newest, previous } = store.valid_slots()?;
        let Some(newest) = newest else {
            return Ok(BootTable::Empty);
        };
        self.active = Some(store.load_slot(newest.slot)?);
        self.prepare_active();
        if let Some(previous) = previous {
            self.previous = store.load_slot(previous.slot).ok();
        }
        Ok(BootTable::Restored {
            sequence: newest.sequence,
            with_previous: self.previous.is_some(),
        })
    }

    /// The board's reset cause and clock source, reported in Info.
    pub fn set_boot_report(&mut self, report: BootReport) {
        self.boot_report = report;
    }

    /// The boot report Info gives.
    pub fn boot_report(&self) -> BootReport {
        self.boot_report
    }

    /// The crystal failed while running (Clock Security System): Info's `clock_fallback`.
    pub fn clock_fell_back(&mut self) {
        self.boot_report.clock_fallback = true;
    }

    /// What the store gave at boot.
    pub fn boot_table(&self) -> BootTable {
        self.boot
    }

    /// The flash behind the store (tests reboot by building a new service on it).
    pub fn into_flash(self) -> Option<F> {
        self.store.map(CalibrationStore::into_flash)
    }

    /// The table used for samples, if any.
    pub fn active_table(&self) -> Option<&CalibrationTable> {
        self.active.as_ref()
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

    /// Runs one injected sample through the pipeline with the active table; it takes the
    /// next sequence number.
    pub fn sample(&mut self, id: u32, raw: &RawSample, now_us: u64) -> DeviceMessage {
        let seq = self.seq;
        self.seq = seq.wrapping_add(1);
        let mut frame = pipeline::process_prepared(seq, now_us, raw, self.prepared.as_ref());
        frame.lost = core::mem::take(&mut self.pending_lost);
        DeviceMessage::Sample { id, frame }
    }

    /// An acquired reading with sequence number `seq`, missing readings before it explained by
    /// `lost`. Every number skipped since the last reading is counted as lost (and flagged on
    /// this frame); the frame is returned while streaming.
    pub fn acquired(
        &mut self,
        seq: u32,
        lost: LossFlags,
        raw: &RawSample,
        time_us: u64,
    ) -> Option<DeviceMessage> {
        let gap = seq.wrapping_sub(self.seq);
        self.seq = seq.wrapping_add(1);
        self.losses.conversions_lost = self.losses.conversions_lost.wrapping_add(gap);
        let lost = LossFlags(lost.0 | core::mem::take(&mut self.pending_lost).0);
        if !self.streaming {
            // Nothing is sent while not streaming: losses before the stream starts are
            // counted, but flag no frame of it.
            return None;
        }
        let mut frame = pipeline::process_prepared(seq, time_us, raw, self.prepared.as_ref());
        frame.lost = lost;
        Some(DeviceMessage::Sample { id: 0, frame })
    }

    /// A frame that could not be sent (the transmitter was full): counted, and flagged on the
    /// next frame.
    pub fn frame_not_sent(&mut self) {
        self.losses.tx_frames_dropped = self.losses.tx_frames_dropped.wrapping_add(1);
        self.pending_lost.0 |= LossFlags::TX_DROPPED;
    }

    /// The loss counters, for the board's own counts (UART errors, queue, erase stalls,
    /// resets) to be added.
    pub fn losses_mut(&mut self) -> &mut LossCounters {
        &mut self.losses
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
        if let Request::Bench {
            raw,
            count,
            rtd_step,
        } = &frame.request
        {
            return match self.bench(raw, *count, *rtd_step, clock) {
                Ok(body) => DeviceMessage::Response { id, body },
                Err(error) => DeviceMessage::Error { id, error },
            };
        }
        if let Request::InjectSample { raw } = &frame.request {
            if self.board == Board::Qemu {
                return self.sample(id, raw, now_us);
            }
        }
        let erases = self.erase_count();
        let result = self.respond(frame.request, now_us);
        self.count_erase_stalls(erases, now_us, clock);
        match result {
            Ok(body) => DeviceMessage::Response { id, body },
            Err(error) => DeviceMessage::Error { id, error },
        }
    }

    fn erase_count(&self) -> u32 {
        self.store.as_ref().map_or(0, CalibrationStore::erase_count)
    }

    /// Counts the sector erases run since `erases_before` as stalls, with the time they took
    /// (the operation's whole duration: the erase dominates it by three orders of magnitude).
    fn count_erase_stalls(&mut self, erases_before: u32, since_us: u64, clock: &dyn Fn() -> u64) {
        let n = self.erase_count().wrapping_sub(erases_before);
        if n > 0 {
            let l = &mut self.losses;
            l.erase_stalls = l.erase_stalls.wrapping_add(n);
            l.erase_stall_us = l
                .erase_stall_us
                .wrapping_add(clock().saturating_sub(since_us));
        }
    }

    fn respond(&mut self, request: Request, now_us: u64) -> Result<Response, ErrorReply> {
        match request {
            Request::Ping => Ok(Response::Pong),
            Request::Info => Ok(Response::Info(self.info(now_us))),
            Request::UploadBegin {
                upload_id,
                total_len,
                body_crc32,
            } => {
                let total_len = total_len as usize;
                // A new Begin always restarts: a host that lost track can start over.
                self.upload.in_progress = false;
                if total_len > ENCODED_LEN {
                    return Err(ErrorCode::UploadTooLong.reply(ENCODED_LEN as u32));
                }
                self.upload.in_progress = true;
                self.upload.upload_id = upload_id;
                self.upload.total_len = total_len;
                self.upload.body_crc32 = body_crc32;
                self.upload.received = 0;
                Ok(Response::Ok)
            }
            Request::UploadChunk {
                upload_id,
                offset,
                data,
            } => {
                let u = &mut self.upload;
                if !u.in_progress {
                    return Err(ErrorCode::NoUpload.reply(0));
                }
                if upload_id != u.upload_id {
                    return Err(ErrorCode::UploadIdMismatch.reply(u.upload_id));
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
            Request::UploadCommit { upload_id } => self.commit(upload_id),
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
                    self.switch_to_previous()
                } else {
                    Err(ErrorCode::TableNotFound.reply(0))
                }
            }
            Request::Rollback => self.switch_to_previous(),
            Request::StreamStart => {
                self.streaming = true;
                Ok(Response::Ok)
            }
            Request::StreamStop => {
                self.streaming = false;
                Ok(Response::Ok)
            }
            Request::SetRate { hz } => {
                if !SET_RATES_SPS.contains(&hz) {
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
        rtd_step: u32,
        clock: &dyn Fn() -> u64,
    ) -> Result<Response, ErrorReply> {
        if count == 0 || count > MAX_BENCH_COUNT {
            return Err(ErrorCode::InvalidCount.reply(MAX_BENCH_COUNT));
        }
        let table = self.prepared.as_ref();
        let start = clock();
        let mut sum = 0.0;
        let mut sample = *raw;
        for i in 0..count {
            // black_box: the same sample each time must still be computed each time.
            let r = core::hint::black_box(&sample);
            sum += pipeline::process_prepared(i, start, r, table).a_i_exact_g;
            // Alternates between two neighbouring codes (no drift out of range); 0 keeps it.
            sample.rtd = if i % 2 == 0 {
                raw.rtd.wrapping_add(rtd_step)
            } else {
                raw.rtd
            };
        }
        let elapsed_us = clock().saturating_sub(start);
        Ok(Response::Bench {
            count,
            elapsed_us,
            a_i_sum_g: sum,
        })
    }

    /// Whether [`Self::erase_ahead`] has work to do.
    pub fn erase_pending(&self) -> bool {
        self.erase_pending
    }

    /// Erases the slot the next upload (or rollback) will write, so that the upload itself
    /// only programs. The firmware calls it after it has sent the answer to a request that
    /// changed the active table, and once after boot. The spare holds neither the active nor
    /// the rollback table, so this loses nothing and is power-fail safe (docs/storage.md).
    /// Returns Ok(true) when an erase ran. A failure is reported for logging only: the next
    /// commit erases the slot itself.
    ///
    /// Never while streaming: on a single-bank MCU an erase stalls the acquisition for seconds
    /// (docs/storage.md). It stays pending until the stream stops; a commit during a stream
    /// erases itself, and that stall is counted and shows as a STALL gap in `seq`. A spare that
    /// already reads blank is not erased (no stall at all).
    pub fn erase_ahead(&mut self, clock: &dyn Fn() -> u64) -> Result<bool, ErrorReply> {
        if !self.erase_pending || self.streaming {
            return Ok(false);
        }
        self.erase_pending = false;
        let erases = self.erase_count();
        let since = clock();
        let Some(store) = self.store.as_mut() else {
            return Ok(false);
        };
        if store.spare_erased().map_err(storage_reply::<F>)? {
            return Ok(false);
        }
        let result = store.prepare_commit().map_err(storage_reply::<F>);
        self.count_erase_stalls(erases, since, clock);
        result?;
        Ok(self.erase_count() != erases)
    }

    fn commit(&mut self, upload_id: u32) -> Result<Response, ErrorReply> {
        let u = &mut self.upload;
        if !u.in_progress {
            return Err(ErrorCode::NoUpload.reply(0));
        }
        if upload_id != u.upload_id {
            // Not this upload's commit: the upload in progress stays open.
            return Err(ErrorCode::UploadIdMismatch.reply(u.upload_id));
        }
        // Whatever happens next, this upload is finished: a retry starts with UploadBegin.
        u.in_progress = false;
        if u.received != u.total_len {
            return Err(ErrorCode::UploadIncomplete.reply(u.received as u32));
        }
        let bytes = u.buf.get(..u.total_len).unwrap_or(&[]);
        let computed = upload_body_crc32(bytes);
        if computed != u.body_crc32 {
            return Err(ErrorCode::UploadCrcMismatch.reply(computed));
        }
        // Validated before the store sees it: a refused table never reaches flash.
        let table = CalibrationTable::decode(bytes).map_err(ErrorReply::from)?;
        // The active table again: nothing to write, and the rollback table stays.
        if self
            .active
            .as_ref()
            .is_some_and(|a| a.encode()[..] == *bytes)
        {
            return Ok(Response::Committed {
                table_id: table.id(),
            });
        }
        let store = self
            .store
            .as_mut()
            .ok_or(ErrorCode::StorageUnavailable.reply(0))?;
        // Only a table the store has committed (programmed, read back, marked) becomes active.
        let slot = store.commit(bytes).map_err(storage_reply::<F>)?;
        self.erase_pending = true;
        self.previous = self.active.replace(table);
        self.prepare_active();
        Ok(Response::Committed {
            table_id: slot.table_id,
        })
    }

    /// Makes the previous table active, in flash first: it is committed anew into the spare
    /// slot, so the table active until now stays in its slot and becomes the rollback table
    /// (also after a reboot).
    fn switch_to_previous(&mut self) -> Result<Response, ErrorReply> {
        let target = self
            .previous
            .as_ref()
            .ok_or(ErrorCode::NoPreviousTable.reply(0))?;
        let store = self
            .store
            .as_mut()
            .ok_or(ErrorCode::StorageUnavailable.reply(0))?;
        store.commit(&target.encode()).map_err(storage_reply::<F>)?;
        self.erase_pending = true;
        core::mem::swap(&mut self.active, &mut self.previous);
        self.prepare_active();
        Ok(Response::Ok)
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
            uptime_us: now_us,
            frames_dropped: self.frames_dropped,
            samples: self.seq,
            losses: self.losses,
            streaming: self.streaming,
            rate_hz: self.rate_hz,
            boot: self.boot_report,
        }
    }
}

#[cfg(test)]
mod flash_tests;
#[cfg(test)]
mod fuzz_tests;
#[cfg(test)]
mod model_tests;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::{raw_from_physical, Status};
    use crate::protocol::{encode_frame, FrameDecoder, MAX_FRAME_LEN};
    use crate::storage::RamFlash;
    use crate::table::tests::paper_table;
    use crate::table::CRC32;
    use crate::units::{Celsius, TiltArcsec, Volts};

    /// The QEMU board's flash: three 1 KiB slots.
    type Flash = RamFlash<3072, 1024, 4>;
    const LAYOUT: SlotLayout = SlotLayout::consecutive(1024);

    fn qemu_service() -> Service<Flash> {
        Service::new(Board::Qemu, Flash::new(), LAYOUT)
    }

    /// Power off and on: a new service on the same flash cells.
    fn reboot<F: CalibrationFlash>(s: Service<F>) -> Service<F> {
        let board = s.board;
        Service::new(board, s.into_flash().unwrap(), LAYOUT)
    }

    fn req<F: CalibrationFlash>(s: &mut Service<F>, request: Request) -> DeviceMessage {
        s.handle(HostFrame { id: 9, request }, &|| 1_000)
    }

    /// The checksum UploadBegin carries: CRC-32 of all but the last four bytes.
    fn body_crc(bytes: &[u8]) -> u32 {
        CRC32.checksum(&bytes[..bytes.len().saturating_sub(4)])
    }

    fn chunk(upload_id: u32, bytes: &[u8], offset: usize) -> Request {
        let end = (offset + CHUNK_LEN).min(bytes.len());
        Request::UploadChunk {
            upload_id,
            offset: offset as u32,
            data: heapless::Vec::from_slice(&bytes[offset..end]).unwrap(),
        }
    }

    fn begin(upload_id: u32, bytes: &[u8]) -> Request {
        Request::UploadBegin {
            upload_id,
            total_len: bytes.len() as u32,
            body_crc32: body_crc(bytes),
        }
    }

    fn upload<F: CalibrationFlash>(s: &mut Service<F>, bytes: &[u8]) -> DeviceMessage {
        let begin = req(s, begin(7, bytes));
        if !matches!(begin, DeviceMessage::Response { .. }) {
            return begin;
        }
        for offset in (0..bytes.len()).step_by(CHUNK_LEN) {
            let r = req(s, chunk(7, bytes, offset));
            assert_eq!(
                r,
                DeviceMessage::Response {
                    id: 9,
                    body: Response::Ok
                }
            );
        }
        req(s, Request::UploadCommit { upload_id: 7 })
    }

    fn error_code(m: &DeviceMessage) -> Option<(u16, u32)> {
        match m {
            DeviceMessage::Error { error, .. } => Some((error.code, error.detail)),
            _ => None,
        }
    }

    fn active_id<F: CalibrationFlash>(s: &mut Service<F>) -> Option<u32> {
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
        let mut s = qemu_service();
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
        let mut s = qemu_service();
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
        let mut s = qemu_service();
        let bytes = paper_table().encode();
        req(&mut s, begin(3, &bytes));
        req(&mut s, chunk(3, &bytes, 0));
        let r = req(&mut s, chunk(3, &bytes, 2 * CHUNK_LEN));
        assert_eq!(
            error_code(&r),
            Some((ErrorCode::ChunkOutOfOrder as u16, CHUNK_LEN as u32))
        );
        let r = req(&mut s, Request::UploadCommit { upload_id: 3 });
        assert_eq!(
            error_code(&r),
            Some((ErrorCode::UploadIncomplete as u16, CHUNK_LEN as u32))
        );
        // The commit closed the upload: a further chunk has no upload to join.
        assert_eq!(
            error_code(&req(&mut s, chunk(3, &bytes, CHUNK_LEN))).map(|e| e.0),
            Some(ErrorCode::NoUpload as u16)
        );
    }

    #[test]
    fn upload_crc_mismatch_is_caught_before_decoding() {
        let mut s = qemu_service();
        let bytes = paper_table().encode();
        req(
            &mut s,
            Request::UploadBegin {
                upload_id: 1,
                total_len: ENCODED_LEN as u32,
                body_crc32: 0x1234_5678,
            },
        );
        for offset in (0..bytes.len()).step_by(CHUNK_LEN) {
            req(&mut s, chunk(1, &bytes, offset));
        }
        let r = req(&mut s, Request::UploadCommit { upload_id: 1 });
        assert_eq!(
            error_code(&r),
            Some((ErrorCode::UploadCrcMismatch as u16, paper_table().id()))
        );
        assert_eq!(active_id(&mut s), None);
    }

    #[test]
    fn the_upload_checksum_is_the_table_id_and_differs_between_tables() {
        // Regression (#15.2): a CRC over a whole table is the CRC-32 residue, the same for every
        // valid table; the body CRC is the table's own CRC, i.e. its id.
        let (a, b) = (paper_table(), second_table());
        assert_eq!(body_crc(&a.encode()), a.id());
        assert_ne!(body_crc(&a.encode()), body_crc(&b.encode()));
        assert_eq!(CRC32.checksum(&a.encode()), CRC32.checksum(&b.encode()));
    }

    #[test]
    fn chunks_and_commit_of_a_replaced_upload_are_refused_by_id() {
        // Begin A, chunk A0, Begin B, chunk B0, then A's remaining chunks and commit: refused
        // with UploadIdMismatch naming B; B continues and commits B.
        let mut s = qemu_service();
        let (a, b) = (paper_table().encode(), second_table().encode());
        req(&mut s, begin(1, &a));
        req(&mut s, chunk(1, &a, 0));
        req(&mut s, begin(2, &b));
        req(&mut s, chunk(2, &b, 0));
        for offset in (CHUNK_LEN..a.len()).step_by(CHUNK_LEN) {
            assert_eq!(
                error_code(&req(&mut s, chunk(1, &a, offset))),
                Some((ErrorCode::UploadIdMismatch as u16, 2))
            );
        }
        assert_eq!(
            error_code(&req(&mut s, Request::UploadCommit { upload_id: 1 })),
            Some((ErrorCode::UploadIdMismatch as u16, 2))
        );
        assert_eq!(active_id(&mut s), None);
        for offset in (CHUNK_LEN..b.len()).step_by(CHUNK_LEN) {
            req(&mut s, chunk(2, &b, offset));
        }
        assert!(matches!(
            req(&mut s, Request::UploadCommit { upload_id: 2 }),
            DeviceMessage::Response { body: Response::Committed { table_id }, .. }
                if table_id == second_table().id()
        ));
    }

    #[test]
    fn a_chunk_of_another_upload_with_the_same_bytes_is_still_refused() {
        // Same table uploaded twice under two ids: the stale upload's chunk is refused even
        // though its bytes would fit.
        let mut s = qemu_service();
        let a = paper_table().encode();
        req(&mut s, begin(10, &a));
        req(&mut s, begin(11, &a));
        assert_eq!(
            error_code(&req(&mut s, chunk(10, &a, 0))).map(|e| e.0),
            Some(ErrorCode::UploadIdMismatch as u16)
        );
    }

    #[test]
    fn read_back_returns_the_committed_bytes() {
        let mut s = qemu_service();
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
        let mut s = qemu_service();
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
        let mut s = qemu_service();
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
        let mut s = qemu_service();
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
                request: Request::Bench {
                    raw,
                    count: 3,
                    rtd_step: 0,
                },
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
                request: Request::Bench {
                    raw,
                    count: 0,
                    rtd_step: 0,
                },
            },
            &clock,
        );
        assert!(
            matches!(m, DeviceMessage::Error { error, .. } if error.code == ErrorCode::InvalidCount as u16)
        );
    }

    #[test]
    fn the_frontend_refuses_injection_and_bad_rates() {
        let mut s = Service::new(Board::Frontend, Flash::new(), LAYOUT);
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
        // Only the ADS1262's listed data rates: 15 SPS is no MODE2.DR setting, 1200 is one the
        // link cannot carry.
        for hz in [15, 1200, 3600] {
            assert_eq!(
                error_code(&req(&mut s, Request::SetRate { hz })),
                Some((ErrorCode::InvalidRate as u16, MAX_RATE_HZ)),
                "{hz}"
            );
        }
        assert_eq!(s.rate_hz(), 100);
        for hz in crate::protocol::SET_RATES_SPS {
            req(&mut s, Request::SetRate { hz });
            assert_eq!(s.rate_hz(), hz);
            assert!(crate::drivers::ads1262::DataRate::from_sps(hz).is_some());
        }
    }

    #[test]
    fn a_frame_with_a_good_crc_but_unknown_request_is_answered_with_its_id() {
        let mut s = qemu_service();
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

    /// RamFlash that counts erases and can be told to fail every program (a worn cell, a
    /// driver error), to see where the service erases and what a flash failure does.
    struct Probe {
        inner: Flash,
        erases: std::rc::Rc<core::cell::Cell<u32>>,
        fail_writes: bool,
    }

    impl embedded_storage::nor_flash::ErrorType for Probe {
        type Error = crate::storage::RamFlashError;
    }

    impl embedded_storage::nor_flash::ReadNorFlash for Probe {
        const READ_SIZE: usize = 1;
        fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
            self.inner.read(offset, bytes)
        }
        fn capacity(&self) -> usize {
            self.inner.capacity()
        }
    }

    impl NorFlash for Probe {
        const WRITE_SIZE: usize = 4;
        const ERASE_SIZE: usize = 1024;
        fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
            self.erases.set(self.erases.get() + 1);
            self.inner.erase(from, to)
        }
        fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
            if self.fail_writes {
                return Err(crate::storage::RamFlashError::OutOfBounds);
            }
            self.inner.write(offset, bytes)
        }
    }

    fn probe_service() -> Service<Probe> {
        let flash = Probe {
            inner: Flash::new(),
            erases: Default::default(),
            fail_writes: false,
        };
        Service::new(Board::Qemu, flash, LAYOUT)
    }

    /// The erase counter of the service's flash (shared, so no reboot is needed to read it).
    fn probe_counter(s: &mut Service<Probe>) -> std::rc::Rc<core::cell::Cell<u32>> {
        let flash = s.store.take().unwrap().into_flash();
        let counter = flash.erases.clone();
        *s = Service::new(Board::Qemu, flash, LAYOUT);
        counter
    }

    fn flash_bytes(s: Service<Probe>) -> (Service<Probe>, std::vec::Vec<u8>) {
        let flash = s.into_flash().unwrap();
        let bytes = flash.inner.as_bytes().to_vec();
        (Service::new(Board::Qemu, flash, LAYOUT), bytes)
    }

    fn second_table() -> CalibrationTable {
        let mut b = paper_table();
        b.date.day = 2;
        b
    }

    fn third_table() -> CalibrationTable {
        let mut c = paper_table();
        c.date.day = 3;
        c
    }

    fn raw() -> RawSample {
        raw_from_physical(&paper_table(), Volts(1.3), Celsius(50.0), TiltArcsec(0.0)).unwrap()
    }

    fn info<F: CalibrationFlash>(s: &mut Service<F>) -> DeviceInfo {
        match req(s, Request::Info) {
            DeviceMessage::Response {
                body: Response::Info(i),
                ..
            } => i,
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn factory_empty_flash_boots_without_a_table_and_flags_samples() {
        let mut s = qemu_service();
        assert_eq!(s.boot_table(), BootTable::Empty);
        let DeviceMessage::Sample { frame, .. } = req(&mut s, Request::InjectSample { raw: raw() })
        else {
            panic!()
        };
        assert!(frame.status.has(Status::NO_CALIBRATION));
        assert!(frame.a_i_exact_g.is_nan());
    }

    #[test]
    fn a_committed_table_is_active_after_a_reboot_and_used_for_samples() {
        let mut s = qemu_service();
        let t = paper_table();
        upload(&mut s, &t.encode());
        let mut s = reboot(s);
        assert_eq!(
            s.boot_table(),
            BootTable::Restored {
                sequence: 1,
                with_previous: false
            }
        );
        assert_eq!(active_id(&mut s), Some(t.id()));
        let DeviceMessage::Sample { frame, .. } = req(&mut s, Request::InjectSample { raw: raw() })
        else {
            panic!()
        };
        assert_eq!(frame, pipeline::process(0, 1_000, &raw(), Some(&t)));
    }

    #[test]
    fn two_commits_survive_a_reboot_as_active_and_previous() {
        let mut s = qemu_service();
        let (a, b) = (paper_table(), second_table());
        upload(&mut s, &a.encode());
        upload(&mut s, &b.encode());
        let mut s = reboot(s);
        let i = info(&mut s);
        assert_eq!(
            (i.active_table, i.previous_table),
            (Some(b.id()), Some(a.id()))
        );
        // And the rollback table restored from flash can be rolled back to.
        req(&mut s, Request::Rollback);
        assert_eq!(active_id(&mut s), Some(a.id()));
    }

    #[test]
    fn a_rollback_is_persisted_with_its_own_rollback_table() {
        let mut s = qemu_service();
        let (a, b) = (paper_table(), second_table());
        upload(&mut s, &a.encode());
        upload(&mut s, &b.encode());
        assert!(matches!(
            req(&mut s, Request::Rollback),
            DeviceMessage::Response {
                body: Response::Ok,
                ..
            }
        ));
        let mut s = reboot(s);
        let i = info(&mut s);
        assert_eq!(
            (i.active_table, i.previous_table),
            (Some(a.id()), Some(b.id())),
            "the rolled-back-from table is the rollback table after a reboot"
        );
        req(&mut s, Request::Activate { table_id: b.id() });
        let mut s = reboot(s);
        let i = info(&mut s);
        assert_eq!(
            (i.active_table, i.previous_table),
            (Some(b.id()), Some(a.id()))
        );
    }

    #[test]
    fn re_uploading_the_active_table_keeps_the_rollback_table() {
        // Regression (#15.1): T1, T2, T2 again used to make "previous" T2, Rollback a no-op
        // and Activate(T1) TableNotFound, with T1's slot erased.
        let mut s = probe_service();
        let counter = probe_counter(&mut s);
        let (t1, t2) = (paper_table(), second_table());
        upload(&mut s, &t1.encode());
        upload(&mut s, &t2.encode());
        let erases = counter.get();
        let (mut s, before) = flash_bytes(s);
        assert!(matches!(
            upload(&mut s, &t2.encode()),
            DeviceMessage::Response { body: Response::Committed { table_id }, .. } if table_id == t2.id()
        ));
        let (mut s, after) = flash_bytes(s);
        assert!(before == after, "the no-op upload wrote to flash");
        assert_eq!(counter.get(), erases);
        let i = info(&mut s);
        assert_eq!(
            (i.active_table, i.previous_table),
            (Some(t2.id()), Some(t1.id()))
        );
        req(&mut s, Request::Rollback);
        assert_eq!(active_id(&mut s), Some(t1.id()));
        req(&mut s, Request::Activate { table_id: t2.id() });
        assert_eq!(active_id(&mut s), Some(t2.id()));
    }

    #[test]
    fn refused_uploads_leave_both_slots_untouched() {
        let (a, b) = (paper_table(), second_table());
        let mut nan = paper_table();
        nan.thermal.models.bias_g.coeffs[1] = f64::NAN;
        let mut flipped = b.encode();
        flipped[150] ^= 0x20;
        let refused: [&[u8]; 3] = [&nan.encode(), &flipped, &b.encode()[..ENCODED_LEN - 3]];
        // With one table in flash (other slot blank) and with two different tables.
        for preload in [&[a][..], &[a, b][..]] {
            let mut s = probe_service();
            for t in preload {
                upload(&mut s, &t.encode());
            }
            let (mut s, before) = flash_bytes(s);
            for bytes in refused {
                assert!(error_code(&upload(&mut s, bytes)).is_some());
            }
            let (mut s, after) = flash_bytes(s);
            assert!(before == after, "a refused upload changed the flash");
            assert_eq!(
                active_id(&mut s),
                Some(preload.last().unwrap().id()),
                "after reboot"
            );
        }
    }

    #[test]
    fn the_spare_is_erased_ahead_after_a_change_so_the_next_commit_does_not_erase() {
        let (a, b, c) = (paper_table(), second_table(), third_table());
        let mut s = probe_service();
        let counter = probe_counter(&mut s);
        // After boot on empty flash the spare (A) reads blank: nothing to erase.
        assert!(s.erase_pending());
        assert_eq!(s.erase_ahead(&|| 0), Ok(false));
        assert!(!s.erase_pending(), "nothing pending any more");
        assert_eq!(counter.get(), 0);
        // Begin, chunks and a refused upload erase nothing.
        let mut nan = paper_table();
        nan.rtd.cvd.r0 = f64::NAN;
        assert!(error_code(&upload(&mut s, &nan.encode())).is_some());
        assert!(!s.erase_pending());
        // a → A, b → B, c → C: blank slots; after c the spare is A, holding a: erased ahead.
        // Then a → A (erased ahead: the commit erases nothing), spare B (b) erased ahead.
        for (t, erased_ahead) in [(a, false), (b, false), (c, true), (a, true)] {
            let before = counter.get();
            upload(&mut s, &t.encode());
            assert_eq!(counter.get(), before, "a commit erased: not erased ahead");
            assert!(s.erase_pending());
            assert_eq!(s.erase_ahead(&|| 0), Ok(erased_ahead));
            assert_eq!(counter.get(), before + u32::from(erased_ahead));
        }
        assert_eq!(counter.get(), 2);
        // A rollback writes into the erased spare (B) too, then erases the next one (C).
        req(&mut s, Request::Rollback);
        assert_eq!(counter.get(), 2);
        assert_eq!(s.erase_ahead(&|| 0), Ok(true));
        assert_eq!(counter.get(), 3);
        let i = info(&mut s);
        assert_eq!(
            (i.active_table, i.previous_table),
            (Some(c.id()), Some(a.id()))
        );
        let mut s = reboot(s);
        let i = info(&mut s);
        assert_eq!(
            (i.active_table, i.previous_table),
            (Some(c.id()), Some(a.id()))
        );
        let _ = b;
    }

    #[test]
    fn no_erase_runs_while_streaming_and_a_commit_that_must_erase_counts_the_stall() {
        let (a, b, c, d) = (paper_table(), second_table(), third_table(), paper_table());
        let mut s = probe_service();
        let counter = probe_counter(&mut s);
        for t in [a, b, c] {
            upload(&mut s, &t.encode());
        }
        // The spare (A) holds a: an erase is pending, but not while streaming.
        req(&mut s, Request::StreamStart);
        assert!(s.erase_pending());
        assert_eq!(s.erase_ahead(&|| 0), Ok(false));
        assert!(s.erase_pending(), "still pending for when the stream stops");
        assert_eq!(counter.get(), 0);
        // A commit during the stream must erase its slot itself: the stall is counted, with
        // the time the operation took on the device's clock.
        let mut d = d;
        d.date.day = 9;
        let t = core::cell::Cell::new(1_000u64);
        let clock = || {
            t.set(t.get() + 1_500_000);
            t.get()
        };
        let bytes = d.encode();
        let uid = 77;
        let begin = Request::UploadBegin {
            upload_id: uid,
            total_len: ENCODED_LEN as u32,
            body_crc32: upload_body_crc32(&bytes),
        };
        s.handle(
            HostFrame {
                id: 1,
                request: begin,
            },
            &clock,
        );
        for (k, chunk) in bytes.chunks(CHUNK_LEN).enumerate() {
            let request = Request::UploadChunk {
                upload_id: uid,
                offset: (k * CHUNK_LEN) as u32,
                data: heapless::Vec::from_slice(chunk).unwrap(),
            };
            s.handle(HostFrame { id: 2, request }, &clock);
        }
        let commit = Request::UploadCommit { upload_id: uid };
        s.handle(
            HostFrame {
                id: 3,
                request: commit,
            },
            &clock,
        );
        assert_eq!(counter.get(), 1);
        let l = info(&mut s).losses;
        assert_eq!((l.erase_stalls, l.erase_stall_us), (1, 1_500_000));
        // Stream stopped: the pending erase runs (spare B holds b).
        req(&mut s, Request::StreamStop);
        assert_eq!(s.erase_ahead(&|| 0), Ok(true));
        assert_eq!(counter.get(), 2);
    }

    #[test]
    fn a_flash_failure_is_reported_and_the_active_table_stays() {
        let mut s = probe_service();
        let (a, b) = (paper_table(), second_table());
        upload(&mut s, &a.encode());
        let mut flash = s.into_flash().unwrap();
        flash.fail_writes = true;
        let mut s = Service::new(Board::Qemu, flash, LAYOUT);
        assert_eq!(
            error_code(&upload(&mut s, &b.encode())),
            Some((ErrorCode::FlashFailed as u16, 1))
        );
        assert_eq!(active_id(&mut s), Some(a.id()));
        let mut s = reboot(s);
        assert_eq!(active_id(&mut s), Some(a.id()));
    }

    #[test]
    fn a_layout_that_does_not_fit_leaves_a_running_device_that_refuses_commits() {
        let mut s = Service::new(Board::Qemu, Flash::new(), SlotLayout::consecutive(4096));
        assert_eq!(s.boot_table(), BootTable::StorageFault);
        assert_eq!(
            error_code(&upload(&mut s, &paper_table().encode())),
            Some((ErrorCode::StorageUnavailable as u16, 0))
        );
        assert_eq!(active_id(&mut s), None);
        assert!(matches!(
            req(&mut s, Request::Ping),
            DeviceMessage::Response { .. }
        ));
    }
}
