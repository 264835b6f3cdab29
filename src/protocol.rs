//! The UART protocol between the lab PC and the board: messages, framing, error codes.
//!
//! Wire format of every frame, in both directions (docs/protocol.md has the table of messages):
//!
//! ```text
//! COBS( postcard(message) ‖ CRC-16/IBM-SDLC(postcard bytes), little-endian ) ‖ 0x00
//! ```
//!
//! COBS removes every 0x00 from the frame so that 0x00 is an unambiguous delimiter: a receiver
//! that starts in the middle of a frame, or sees garbage, resynchronises at the next 0x00. The
//! CRC sits inside the COBS frame so that a corrupted byte is caught before postcard sees it.

use heapless::Vec;
use serde::{Deserialize, Serialize};

use crate::pipeline::{Frame, RawSample};
use crate::table::{Coefficient, Field, TableError};

/// Protocol version reported by Info; bumped on any incompatible message change.
pub const PROTOCOL_VERSION: u16 = 3;
/// Largest data chunk of an upload or read-back.
pub const CHUNK_LEN: usize = 64;
/// Largest postcard message body (before CRC and COBS).
pub const MAX_MESSAGE_LEN: usize = 120;
/// Largest frame on the wire: body + CRC + COBS overhead (1 per 254) + delimiter.
pub const MAX_FRAME_LEN: usize = MAX_MESSAGE_LEN + 2 + 2 + 1;

/// CRC of the frame body: CRC-16/IBM-SDLC (X.25), Hamming distance 4 for frames this short.
pub const CRC16: crc::Crc<u16> = crc::Crc::<u16>::new(&crc::CRC_16_IBM_SDLC);

/// Which board the firmware was built for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Board {
    /// QEMU netduinoplus2: samples are injected over the UART.
    Qemu,
    /// The real front-end board with its ADCs.
    Frontend,
}

/// Host → device: a request with the id the response will carry.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HostFrame {
    /// Chosen by the host; echoed in the response (0 is reserved for unsolicited messages).
    pub id: u32,
    /// What to do.
    pub request: Request,
}

/// Host → device requests.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Request {
    /// Liveness check; answered with Pong.
    Ping,
    /// Firmware version, board, tables, uptime, counters.
    Info,
    /// Start upload `upload_id` of `total_len` bytes. `body_crc32` is the CRC-32/ISO-HDLC of
    /// the upload without its last four bytes: for a table, its own stored CRC-32, i.e. its id.
    /// (A CRC over a whole table is the same constant for every valid table — the CRC residue —
    /// and would identify nothing.)
    UploadBegin {
        /// Chosen by the host, different for each upload; chunks and commit must repeat it.
        upload_id: u32,
        /// Bytes that will follow in chunks.
        total_len: u32,
        /// CRC-32 of all bytes but the last four, checked before decoding.
        body_crc32: u32,
    },
    /// The next chunk of upload `upload_id`; `offset` must equal the bytes received so far.
    UploadChunk {
        /// The id given in UploadBegin.
        upload_id: u32,
        /// Byte offset of `data` in the upload.
        offset: u32,
        /// At most [`CHUNK_LEN`] bytes.
        data: Vec<u8, CHUNK_LEN>,
    },
    /// Validate upload `upload_id` and make it the active table (the old one becomes
    /// previous). A table identical to the active one is a no-op that keeps the previous one.
    UploadCommit {
        /// The id given in UploadBegin.
        upload_id: u32,
    },
    /// Read the active table's encoding from `offset` (answered with a TableChunk).
    ReadTable {
        /// Byte offset into the encoded table.
        offset: u32,
    },
    /// Make the table with this id active (must be the active or the previous one).
    Activate {
        /// CRC-32 table id.
        table_id: u32,
    },
    /// Swap the active and the previous table.
    Rollback,
    /// Start streaming acquired samples (front-end board).
    StreamStart,
    /// Stop streaming acquired samples.
    StreamStop,
    /// Set the ADS1262 data rate in samples per second (one of [`SET_RATES_SPS`]).
    SetRate {
        /// Samples per second.
        hz: u32,
    },
    /// Process this raw sample as if acquired now (QEMU board); answered with a Sample.
    InjectSample {
        /// The raw codes and driver flags.
        raw: RawSample,
    },
    /// Run the pipeline `count` times on `raw` with the active table and report the firmware
    /// time it took (benchmark; under `qemu -icount shift=0` 1 µs = 1000 instructions).
    Bench {
        /// The sample to process.
        raw: RawSample,
        /// How many times, 1..=MAX_BENCH_COUNT.
        count: u32,
        /// 0: the same sample every time, the steady state between RTD readings (temperature
        /// terms cached). Non-zero: the RTD code alternates between `raw.rtd` and
        /// `raw.rtd + rtd_step` (wrapping), a new temperature every sample (terms recomputed).
        rtd_step: u32,
    },
}

/// The checksum UploadBegin carries for `bytes`: CRC-32/ISO-HDLC of all but the last four
/// bytes (for a calibration table: its stored CRC-32, which is its id).
pub fn upload_body_crc32(bytes: &[u8]) -> u32 {
    crate::table::CRC32.checksum(bytes.get(..bytes.len().saturating_sub(4)).unwrap_or(&[]))
}

/// Largest Bench count (keeps the device answering within a few seconds on the board).
pub const MAX_BENCH_COUNT: u32 = 100_000;

/// The ADS1262 data rates SetRate accepts, in samples per second (MODE2.DR). Each frame needs
/// one settled conversion per channel, 4 periods each with sinc4: frames come at rate / 8. The
/// top rate keeps the frames (50/s, ≈ 70 bytes each) inside 115200 Bd with room for replies.
pub const SET_RATES_SPS: [u32; 7] = [5, 10, 20, 50, 60, 100, 400];

/// Highest rate SetRate accepts (InvalidRate's detail).
pub const MAX_RATE_HZ: u32 = 400;

/// Device → host messages.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum DeviceMessage {
    /// Sent once after boot when the UART receiver is live.
    Ready {
        /// Board the firmware was built for.
        board: Board,
        /// Protocol version.
        protocol: u16,
    },
    /// Successful answer to request `id`.
    Response {
        /// Id of the request.
        id: u32,
        /// The answer.
        body: Response,
    },
    /// A processed sample; `id` is the InjectSample's request id, 0 for acquired samples.
    Sample {
        /// Request id or 0.
        id: u32,
        /// The output frame.
        frame: Frame,
    },
    /// Failure of request `id` (0 when the id could not be read).
    Error {
        /// Id of the request, or 0.
        id: u32,
        /// What failed.
        error: ErrorReply,
    },
}

/// Successful answers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Response {
    /// Answer to Ping.
    Pong,
    /// Answer to Info.
    Info(DeviceInfo),
    /// The request was carried out (UploadBegin, UploadChunk, Activate, Rollback, Stream*).
    Ok,
    /// The upload was validated and activated.
    Committed {
        /// Id of the now active table.
        table_id: u32,
    },
    /// Result of Bench.
    Bench {
        /// Samples processed.
        count: u32,
        /// Firmware time for all of them, in µs.
        elapsed_us: u64,
        /// Sum of the a_i results (keeps the work observable; NaN if any sample was invalid).
        a_i_sum_g: f64,
    },
    /// Part of the active table.
    TableChunk {
        /// Offset of `data`.
        offset: u32,
        /// Length of the whole encoded table.
        total_len: u32,
        /// Up to [`CHUNK_LEN`] bytes.
        data: Vec<u8, CHUNK_LEN>,
    },
}

/// What Info reports.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DeviceInfo {
    /// Firmware version (Cargo package version).
    pub firmware: heapless::String<16>,
    /// Board.
    pub board: Board,
    /// Protocol version.
    pub protocol: u16,
    /// Id of the active table.
    pub active_table: Option<u32>,
    /// Id of the previous table (rollback target).
    pub previous_table: Option<u32>,
    /// Milliseconds since boot.
    pub uptime_ms: u64,
    /// Frames dropped by the receiver (bad CRC, overflow, queue full) since boot.
    pub frames_dropped: u32,
    /// Samples processed since boot.
    pub samples: u32,
    /// Streaming of acquired samples on.
    pub streaming: bool,
    /// ADS1262 data rate in samples per second (SetRate; one frame per 8 conversions with
    /// sinc4, see docs/protocol.md).
    pub rate_hz: u32,
    /// Why the MCU last reset, and which clock it runs on.
    pub boot: BootReport,
}

/// Reset cause and clock source, read once at boot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct BootReport {
    /// RCC_CSR[31:25] of the boot (RM0090 "RCC clock control & status register"): bit 0 BOR,
    /// 1 PIN (reset pin), 2 POR/PDR, 3 SFT (software: a panic, a fatal start-up error), 4 IWDG
    /// (watchdog: acquisition or the worker stopped), 5 WWDG, 6 LPWR. 0 = unknown (QEMU).
    pub reset_cause: u8,
    /// The crystal did not start within 100 ms: the PLL runs from the HSI (±1 %).
    pub clock_fallback: bool,
}

impl BootReport {
    /// Brown-out reset.
    pub const BOR: u8 = 1 << 0;
    /// Reset pin (includes every other reset on the F4).
    pub const PIN: u8 = 1 << 1;
    /// Power-on / power-down reset.
    pub const POR: u8 = 1 << 2;
    /// Software reset: panic or fatal start-up error.
    pub const SOFTWARE: u8 = 1 << 3;
    /// Independent watchdog.
    pub const IWDG: u8 = 1 << 4;
    /// Window watchdog.
    pub const WWDG: u8 = 1 << 5;
    /// Low-power reset.
    pub const LOW_POWER: u8 = 1 << 6;
}

/// A failure: a stable numeric code plus one number of detail (documented per code).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ErrorReply {
    /// [`ErrorCode`] as a number.
    pub code: u16,
    /// Code-specific detail (expected offset, computed CRC, field, …), 0 when none.
    pub detail: u32,
}

/// Every failure reachable from the UART, with its number on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u16)]
pub enum ErrorCode {
    /// The frame decoded (CRC good) but is not a known request. Detail: 0.
    Malformed = 1,
    /// Frame CRC mismatch (counted; not answered since the id is untrusted). Detail: computed CRC.
    FrameCrc = 2,
    /// Frame longer than the receive buffer (counted; not answered). Detail: buffer size.
    FrameTooLong = 3,
    /// COBS structure broken (counted; not answered). Detail: 0.
    FrameCobs = 4,
    /// Chunk or commit without an UploadBegin. Detail: 0.
    NoUpload = 10,
    /// Chunk offset is not the next expected one. Detail: expected offset.
    ChunkOutOfOrder = 11,
    /// Upload longer than a table can be. Detail: maximum length.
    UploadTooLong = 12,
    /// Commit before all announced bytes arrived. Detail: bytes received.
    UploadIncomplete = 13,
    /// Bytes received do not match UploadBegin's CRC-32. Detail: computed CRC.
    UploadCrcMismatch = 14,
    /// Chunk or commit of an upload other than the one in progress (a later UploadBegin
    /// replaced it). Detail: the id of the upload in progress.
    UploadIdMismatch = 15,
    /// Table: wrong magic. Detail: 0.
    TableBadMagic = 20,
    /// Table: unsupported format version. Detail: version found.
    TableUnsupportedVersion = 21,
    /// Table: wrong length. Detail: length found.
    TableBadLength = 22,
    /// Table: stored CRC wrong. Detail: computed CRC.
    TableBadCrc = 23,
    /// Table: NaN or infinite number. Detail: field code (see docs/protocol.md).
    TableNonFinite = 24,
    /// Table: polynomial order above 4. Detail: coefficient code.
    TableOrderTooHigh = 25,
    /// Table: empty or inverted temperature range. Detail: 0.
    TableEmptyRange = 26,
    /// Table: T0 outside the calibrated range. Detail: 0.
    TableReferenceOutsideRange = 27,
    /// Table: K1 implausible. Detail: 0.
    TableScaleFactorImplausible = 28,
    /// Table: RTD constants out of range. Detail: 0.
    TableRtdConstants = 29,
    /// Table: ADC constants out of range. Detail: 0.
    TableAdcConstants = 30,
    /// Table: serial not UTF-8. Detail: 0.
    TableSerial = 31,
    /// Table: date invalid. Detail: 0.
    TableDate = 32,
    /// Table: tilt axis code invalid. Detail: 0.
    TableTiltAxis = 33,
    /// Table: reserved header field not zero. Detail: its value.
    TableReserved = 34,
    /// Table: a finite value outside its physical bounds. Detail: field code.
    TableOutOfBounds = 35,
    /// ReadTable with no active table. Detail: 0.
    NoTable = 40,
    /// ReadTable offset beyond the table. Detail: table length.
    OffsetOutOfRange = 41,
    /// Rollback with no previous table. Detail: 0.
    NoPreviousTable = 42,
    /// Activate with an id that is neither active nor previous. Detail: 0.
    TableNotFound = 43,
    /// The device could not queue the answer or the sample. Detail: 0.
    Busy = 50,
    /// The request does not exist on this board (InjectSample on the front-end). Detail: 0.
    NotSupported = 51,
    /// SetRate with a rate not in [`SET_RATES_SPS`]. Detail: MAX_RATE_HZ.
    InvalidRate = 52,
    /// Bench count outside 1..=MAX_BENCH_COUNT. Detail: MAX_BENCH_COUNT.
    InvalidCount = 53,
    /// The flash driver failed to erase, program or read. Detail: 0 not aligned, 1 out of
    /// bounds, 2 other (embedded-storage `NorFlashErrorKind`). The active table is unchanged.
    FlashFailed = 60,
    /// What was read back from the slot differs from what was written; the slot was left
    /// uncommitted and the active table is unchanged. Detail: slot (0 = A, 1 = B).
    FlashVerify = 61,
    /// The calibration store could not be opened at boot (slot layout does not fit the flash),
    /// so nothing can be committed. Detail: 0.
    StorageUnavailable = 62,
    /// STM32 flash controller PGSERR (programming sequence error, RM0090 §3.8.4). Detail: 0.
    /// Like every flash error: the active table is unchanged, the flag is cleared, the next
    /// operation runs normally.
    FlashProgramSequence = 63,
    /// STM32 flash controller PGPERR (programming parallelism error). Detail: 0.
    FlashProgramParallelism = 64,
    /// STM32 flash controller PGAERR (programming alignment error). Detail: 0.
    FlashProgramAlignment = 65,
    /// STM32 flash controller WRPERR: the calibration sector is write-protected (option bytes
    /// nWRP). Detail: 0.
    FlashWriteProtected = 66,
    /// STM32 flash controller OPERR (operation error). Detail: 0.
    FlashOperation = 67,
    /// FLASH_CR stayed locked after the unlock keys (a wrong key sequence locks it until
    /// reset, RM0090 §3.5.1). Detail: 0.
    FlashLocked = 68,
}

impl ErrorCode {
    /// Every code, for documentation and exhaustive tests.
    pub const ALL: [ErrorCode; 43] = [
        ErrorCode::Malformed,
        ErrorCode::FrameCrc,
        ErrorCode::FrameTooLong,
        ErrorCode::FrameCobs,
        ErrorCode::NoUpload,
        ErrorCode::ChunkOutOfOrder,
        ErrorCode::UploadTooLong,
        ErrorCode::UploadIncomplete,
        ErrorCode::UploadCrcMismatch,
        ErrorCode::UploadIdMismatch,
        ErrorCode::TableBadMagic,
        ErrorCode::TableUnsupportedVersion,
        ErrorCode::TableBadLength,
        ErrorCode::TableBadCrc,
        ErrorCode::TableNonFinite,
        ErrorCode::TableOrderTooHigh,
        ErrorCode::TableEmptyRange,
        ErrorCode::TableReferenceOutsideRange,
        ErrorCode::TableScaleFactorImplausible,
        ErrorCode::TableRtdConstants,
        ErrorCode::TableAdcConstants,
        ErrorCode::TableSerial,
        ErrorCode::TableDate,
        ErrorCode::TableTiltAxis,
        ErrorCode::TableReserved,
        ErrorCode::TableOutOfBounds,
        ErrorCode::NoTable,
        ErrorCode::OffsetOutOfRange,
        ErrorCode::NoPreviousTable,
        ErrorCode::TableNotFound,
        ErrorCode::Busy,
        ErrorCode::NotSupported,
        ErrorCode::InvalidRate,
        ErrorCode::InvalidCount,
        ErrorCode::FlashFailed,
        ErrorCode::FlashVerify,
        ErrorCode::StorageUnavailable,
        ErrorCode::FlashProgramSequence,
        ErrorCode::FlashProgramParallelism,
        ErrorCode::FlashProgramAlignment,
        ErrorCode::FlashWriteProtected,
        ErrorCode::FlashOperation,
        ErrorCode::FlashLocked,
    ];

    /// The code for a number from the wire.
    pub fn from_u16(n: u16) -> Option<ErrorCode> {
        ErrorCode::ALL.iter().copied().find(|c| *c as u16 == n)
    }

    /// A reply with this code and detail.
    pub const fn reply(self, detail: u32) -> ErrorReply {
        ErrorReply {
            code: self as u16,
            detail,
        }
    }
}

const fn coefficient_code(c: Coefficient) -> u32 {
    match c {
        Coefficient::Bias => 0,
        Coefficient::ScaleFactor => 1,
        Coefficient::Nonlinearity => 2,
        Coefficient::MisalignmentP => 3,
        Coefficient::MisalignmentO => 4,
    }
}

/// Field codes of TableNonFinite's detail.
pub const fn field_code(f: Field) -> u32 {
    match f {
        Field::TemperatureScale => 0,
        Field::ReferenceTemperature => 1,
        Field::Polynomial(c) => 10 + coefficient_code(c),
        Field::Tilt => 2,
        Field::Rtd => 3,
        Field::Adc => 4,
        Field::Orientation => 5,
        Field::Serial => 6,
        Field::Date => 7,
    }
}

impl From<TableError> for ErrorReply {
    fn from(e: TableError) -> Self {
        use ErrorCode as C;
        match e {
            TableError::BadMagic => C::TableBadMagic.reply(0),
            TableError::UnsupportedVersion(v) => C::TableUnsupportedVersion.reply(u32::from(v)),
            TableError::BadLength { found, .. } => C::TableBadLength.reply(found),
            TableError::BadCrc { computed, .. } => C::TableBadCrc.reply(computed),
            TableError::NonFinite(f) => C::TableNonFinite.reply(field_code(f)),
            TableError::OrderTooHigh(c) => C::TableOrderTooHigh.reply(coefficient_code(c)),
            TableError::EmptyRange => C::TableEmptyRange.reply(0),
            TableError::ReferenceOutsideRange => C::TableReferenceOutsideRange.reply(0),
            TableError::ScaleFactorImplausible => C::TableScaleFactorImplausible.reply(0),
            TableError::RtdConstants => C::TableRtdConstants.reply(0),
            TableError::AdcConstants => C::TableAdcConstants.reply(0),
            TableError::Serial => C::TableSerial.reply(0),
            TableError::Date => C::TableDate.reply(0),
            TableError::TiltAxis => C::TableTiltAxis.reply(0),
            TableError::Reserved(v) => C::TableReserved.reply(u32::from(v)),
            TableError::OutOfBounds(f) => C::TableOutOfBounds.reply(field_code(f)),
        }
    }
}

/// Why a frame could not be built or read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameError {
    /// The output buffer is too small for the encoded frame.
    BufferTooSmall,
    /// The message does not serialize into [`MAX_MESSAGE_LEN`] bytes.
    MessageTooLong,
    /// Received frame exceeded the receive buffer; discarded up to the next delimiter.
    TooLong,
    /// Received frame is not valid COBS.
    Cobs,
    /// Received frame is shorter than its CRC.
    TooShort,
    /// CRC mismatch.
    Crc {
        /// CRC computed over the received body.
        computed: u16,
    },
    /// CRC fine but postcard could not decode the message.
    Decode,
}

impl FrameError {
    /// The protocol error code of a receive-side failure.
    pub const fn reply(self) -> ErrorReply {
        match self {
            FrameError::TooLong => ErrorCode::FrameTooLong.reply(MAX_FRAME_LEN as u32),
            FrameError::Cobs | FrameError::TooShort => ErrorCode::FrameCobs.reply(0),
            FrameError::Crc { computed } => ErrorCode::FrameCrc.reply(computed as u32),
            FrameError::Decode | FrameError::BufferTooSmall | FrameError::MessageTooLong => {
                ErrorCode::Malformed.reply(0)
            }
        }
    }
}

/// COBS-encodes `src` into `dst` (no delimiter); returns the encoded length. The `cobs` crate
/// (the one postcard's COBS flavour is built on); a `dst` too small is an error, not a panic.
pub fn cobs_encode(src: &[u8], dst: &mut [u8]) -> Result<usize, FrameError> {
    cobs::try_encode(src, dst).map_err(|_| FrameError::BufferTooSmall)
}

/// COBS-decodes `buf` in place (no delimiter inside); returns the decoded length.
///
/// `cobs::decode_in_place` stops at the first 0x00; a frame handed over here has had its
/// delimiter removed, so a 0x00 inside is a broken frame and refused rather than truncated.
pub fn cobs_decode_in_place(buf: &mut [u8]) -> Result<usize, FrameError> {
    if buf.contains(&0) {
        return Err(FrameError::Cobs);
    }
    cobs::decode_in_place(buf).map_err(|_| FrameError::Cobs)
}

/// Serializes `msg`, appends the CRC, COBS-encodes and appends the 0x00 delimiter into `out`.
/// Returns the number of bytes to send.
pub fn encode_frame<T: Serialize>(msg: &T, out: &mut [u8]) -> Result<usize, FrameError> {
    let mut body = [0u8; MAX_MESSAGE_LEN + 2];
    let n = postcard::to_slice(msg, body.get_mut(..MAX_MESSAGE_LEN).unwrap_or(&mut []))
        .map_err(|_| FrameError::MessageTooLong)?
        .len();
    let crc = CRC16.checksum(body.get(..n).unwrap_or(&[]));
    body.get_mut(n..n + 2)
        .ok_or(FrameError::MessageTooLong)?
        .copy_from_slice(&crc.to_le_bytes());
    let m = cobs_encode(body.get(..n + 2).unwrap_or(&[]), out)?;
    *out.get_mut(m).ok_or(FrameError::BufferTooSmall)? = 0;
    Ok(m + 1)
}

/// Checks the CRC of a COBS-decoded frame and returns its message body.
pub fn check_crc(decoded: &[u8]) -> Result<&[u8], FrameError> {
    if decoded.len() < 3 {
        return Err(FrameError::TooShort);
    }
    let (body, crc) = decoded.split_at(decoded.len() - 2);
    let stored = u16::from_le_bytes([
        crc.first().copied().unwrap_or(0),
        crc.get(1).copied().unwrap_or(0),
    ]);
    let computed = CRC16.checksum(body);
    if stored != computed {
        return Err(FrameError::Crc { computed });
    }
    Ok(body)
}

/// Decodes a message body (after [`check_crc`]).
pub fn decode_message<'a, T: Deserialize<'a>>(body: &'a [u8]) -> Result<T, FrameError> {
    postcard::from_bytes(body).map_err(|_| FrameError::Decode)
}

/// Reads only the request id of a host frame whose request could not be decoded, so that the
/// error can still be addressed to it (postcard puts the id first, as a varint).
pub fn peek_request_id(body: &[u8]) -> Option<u32> {
    postcard::take_from_bytes::<u32>(body)
        .ok()
        .map(|(id, _)| id)
}

/// Accumulates received bytes into frames, in a fixed buffer of `N` bytes.
///
/// Survives anything: bytes of an over-long frame are dropped up to the next 0x00, empty frames
/// (two delimiters in a row) are ignored, and every 0x00 starts afresh.
pub struct FrameDecoder<const N: usize> {
    buf: Vec<u8, N>,
    overflow: bool,
    /// The previous call handed out a frame from `buf`: clear it before the next byte.
    handed_out: bool,
}

impl<const N: usize> Default for FrameDecoder<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> FrameDecoder<N> {
    /// An empty decoder.
    pub const fn new() -> Self {
        FrameDecoder {
            buf: Vec::new(),
            overflow: false,
            handed_out: false,
        }
    }

    /// Feeds one byte. At a delimiter returns the checked message body of the frame (or why it
    /// was refused); otherwise None.
    pub fn push(&mut self, byte: u8) -> Option<Result<&[u8], FrameError>> {
        if self.handed_out {
            self.handed_out = false;
            self.buf.clear();
        }
        if byte != 0 {
            if !self.overflow && self.buf.push(byte).is_err() {
                self.overflow = true;
            }
            return None;
        }
        if self.overflow {
            self.overflow = false;
            self.buf.clear();
            return Some(Err(FrameError::TooLong));
        }
        if self.buf.is_empty() {
            return None;
        }
        let result = match cobs_decode_in_place(&mut self.buf) {
            Ok(n) => {
                let decoded = self.buf.get(..n).unwrap_or(&[]);
                check_crc(decoded).map(|body| body.len())
            }
            Err(e) => Err(e),
        };
        // The buffer is reset on the next byte; the body is borrowed from it until then.
        self.handed_out = true;
        Some(result.map(|n| self.buf.get(..n).unwrap_or(&[])))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::{ChannelFlags, Status};
    use proptest::prelude::*;

    type Decoder = FrameDecoder<MAX_FRAME_LEN>;

    fn wire<T: Serialize>(msg: &T) -> std::vec::Vec<u8> {
        let mut out = [0u8; MAX_FRAME_LEN];
        let n = encode_frame(msg, &mut out).unwrap();
        out[..n].to_vec()
    }

    /// Feeds bytes and collects every host frame that decodes, and the count of refused frames.
    fn feed(d: &mut Decoder, bytes: &[u8]) -> (std::vec::Vec<HostFrame>, usize) {
        let mut good = std::vec::Vec::new();
        let mut bad = 0;
        for &b in bytes {
            match d.push(b) {
                Some(Ok(body)) => match decode_message::<HostFrame>(body) {
                    Ok(f) => good.push(f),
                    Err(_) => bad += 1,
                },
                Some(Err(_)) => bad += 1,
                None => {}
            }
        }
        (good, bad)
    }

    fn sample_request(id: u32) -> HostFrame {
        HostFrame {
            id,
            request: Request::InjectSample {
                raw: RawSample {
                    accel: -123_456_789,
                    rtd: 0x00AB_CDEF,
                    tilt: 0,
                    accel_flags: ChannelFlags(0),
                    rtd_flags: ChannelFlags(ChannelFlags::CHECKSUM),
                    tilt_flags: ChannelFlags(0),
                },
            },
        }
    }

    #[test]
    fn cobs_matches_the_published_examples() {
        // Examples from Cheshire & Baker, "Consistent Overhead Byte Stuffing" (1999).
        let cases: [(&[u8], &[u8]); 4] = [
            (&[0x00], &[0x01, 0x01]),
            (&[0x00, 0x00], &[0x01, 0x01, 0x01]),
            (&[0x11, 0x22, 0x00, 0x33], &[0x03, 0x11, 0x22, 0x02, 0x33]),
            (&[0x11, 0x00, 0x00, 0x00], &[0x02, 0x11, 0x01, 0x01, 0x01]),
        ];
        for (raw, encoded) in cases {
            let mut out = [0u8; 16];
            let n = cobs_encode(raw, &mut out).unwrap();
            assert_eq!(&out[..n], encoded);
            let mut back = encoded.to_vec();
            let m = cobs_decode_in_place(&mut back).unwrap();
            assert_eq!(&back[..m], raw);
        }
        // 254 non-zero bytes take one 0xFF block and no trailing code.
        let long = [0x42u8; 254];
        let mut out = [0u8; 260];
        let n = cobs_encode(&long, &mut out).unwrap();
        assert_eq!((out[0], n), (0xFF, 255));
        let mut back = out[..n].to_vec();
        let m = cobs_decode_in_place(&mut back).unwrap();
        assert_eq!(&back[..m], &long[..]);
        // The hand-written encoder before the `cobs` crate closed such a block with a trailing
        // 0x01: a peer still sending that form is decoded to the same bytes.
        let mut old_form = out[..n].to_vec();
        old_form.push(0x01);
        let m = cobs_decode_in_place(&mut old_form).unwrap();
        assert_eq!(&old_form[..m], &long[..]);
        // A destination too small is an error, a 0x00 inside a frame is refused.
        assert_eq!(
            cobs_encode(&long, &mut [0u8; 200]),
            Err(FrameError::BufferTooSmall)
        );
        assert_eq!(
            cobs_decode_in_place(&mut [0x03, 0x11, 0x00, 0x01]),
            Err(FrameError::Cobs)
        );
        // A code pointing past the end of the frame is refused.
        assert_eq!(
            cobs_decode_in_place(&mut [0x05, 0x11, 0x22]),
            Err(FrameError::Cobs)
        );
    }

    #[test]
    fn every_message_kind_round_trips_through_the_wire() {
        let mut d = Decoder::new();
        let reqs = [
            HostFrame {
                id: 1,
                request: Request::Ping,
            },
            HostFrame {
                id: u32::MAX,
                request: Request::UploadChunk {
                    upload_id: u32::MAX,
                    offset: 384,
                    data: Vec::from_slice(&[0u8; CHUNK_LEN]).unwrap(),
                },
            },
            sample_request(3),
        ];
        for r in &reqs {
            let bytes = wire(r);
            assert!(bytes.len() <= MAX_FRAME_LEN);
            assert_eq!(bytes.iter().filter(|b| **b == 0).count(), 1);
            assert_eq!(feed(&mut d, &bytes), (vec![r.clone()], 0));
        }
        let sample = DeviceMessage::Sample {
            id: 5,
            frame: Frame {
                seq: 1,
                time_us: u64::MAX,
                output_v: 1.25,
                temperature_c: f64::NAN,
                rtd_ohms: -0.0,
                tilt_arcsec: 1e-300,
                a_i_exact_g: 0.1,
                output_linearized_v: f64::INFINITY,
                status: Status(0xFFFF),
            },
        };
        let bytes = wire(&sample);
        let mut dev = Decoder::new();
        let mut got = None;
        for &b in &bytes {
            if let Some(f) = dev.push(b) {
                got = Some(decode_message::<DeviceMessage>(f.unwrap()).unwrap());
            }
        }
        // NaN != NaN: compare the bit patterns of the frame's floats.
        let Some(DeviceMessage::Sample { frame, .. }) = got else {
            panic!()
        };
        assert!(frame.temperature_c.is_nan());
        assert_eq!(frame.rtd_ohms.to_bits(), (-0.0f64).to_bits());
        assert_eq!(frame.tilt_arcsec, 1e-300);
        assert_eq!(frame.time_us, u64::MAX);
    }

    #[test]
    fn the_largest_messages_fit_the_frame_buffer() {
        let chunk = DeviceMessage::Response {
            id: u32::MAX,
            body: Response::TableChunk {
                offset: u32::MAX,
                total_len: u32::MAX,
                data: Vec::from_slice(&[0xFF; CHUNK_LEN]).unwrap(),
            },
        };
        let mut out = [0u8; MAX_FRAME_LEN];
        assert!(encode_frame(&chunk, &mut out).is_ok());
        let info = DeviceMessage::Response {
            id: u32::MAX,
            body: Response::Info(DeviceInfo {
                firmware: heapless::String::try_from("0123456789abcdef").unwrap(),
                board: Board::Frontend,
                protocol: u16::MAX,
                active_table: Some(u32::MAX),
                previous_table: Some(u32::MAX),
                uptime_ms: u64::MAX,
                frames_dropped: u32::MAX,
                samples: u32::MAX,
                streaming: true,
                rate_hz: u32::MAX,
                boot: BootReport {
                    reset_cause: u8::MAX,
                    clock_fallback: true,
                },
            }),
        };
        assert!(encode_frame(&info, &mut out).is_ok());
    }

    #[test]
    fn garbage_before_between_and_after_frames_does_not_hide_them() {
        let mut d = Decoder::new();
        let mut line = vec![0x13, 0x37, 0xFF, 0x00, 0x00, 0x42, 0x00];
        line.extend(wire(&sample_request(1)));
        line.extend([0x55; 300]); // longer than the buffer: overflow, then resync
        line.push(0);
        line.extend(wire(&sample_request(2)));
        let (good, bad) = feed(&mut d, &line);
        assert_eq!(good, vec![sample_request(1), sample_request(2)]);
        assert!(bad >= 2, "garbage frames must be reported, got {bad}");
    }

    #[test]
    fn a_truncated_frame_is_refused_and_the_next_one_is_served() {
        let mut d = Decoder::new();
        let full = wire(&sample_request(1));
        let mut line = full[..full.len() / 2].to_vec();
        line.push(0); // cut short by a delimiter
        line.extend(wire(&sample_request(2)));
        let (good, bad) = feed(&mut d, &line);
        assert_eq!(good, vec![sample_request(2)]);
        assert_eq!(bad, 1);
    }

    #[test]
    fn every_single_bit_flip_of_a_frame_is_detected() {
        let bytes = wire(&sample_request(7));
        for i in 0..bytes.len() - 1 {
            for bit in 0..8 {
                let mut c = bytes.clone();
                c[i] ^= 1 << bit;
                let mut d = Decoder::new();
                let (good, _) = feed(&mut d, &c);
                // A flip that creates a 0x00 splits the frame; neither half may decode.
                assert!(good.is_empty(), "flip at {i}:{bit} decoded as {good:?}");
            }
        }
    }

    #[test]
    fn table_errors_map_to_distinct_documented_codes() {
        let mut seen = std::collections::BTreeSet::new();
        for c in ErrorCode::ALL {
            assert!(seen.insert(c as u16), "duplicate {c:?}");
            assert_eq!(ErrorCode::from_u16(c as u16), Some(c));
        }
        assert_eq!(ErrorCode::from_u16(999), None);
        let e: ErrorReply = TableError::UnsupportedVersion(2).into();
        assert_eq!((e.code, e.detail), (21, 2));
        let e: ErrorReply = TableError::NonFinite(Field::Polynomial(Coefficient::Bias)).into();
        assert_eq!((e.code, e.detail), (24, 10));
    }

    /// Bounded fuzzing inside `cargo test` (the cargo-fuzz target `frame_decoder` runs the
    /// same unbounded). Runs exactly `CASES` inputs, counted.
    #[test]
    fn random_and_mutated_lines_never_panic_and_the_next_frame_is_always_found() {
        use core::sync::atomic::{AtomicU64, Ordering};
        use proptest::test_runner::{Config, TestRunner};
        const CASES: u32 = 100_000;
        let count = AtomicU64::new(0);
        let mutated_decoded = AtomicU64::new(0);
        let strategy = (
            proptest::collection::vec(any::<u8>(), 0..300),
            proptest::collection::vec((any::<usize>(), any::<u8>()), 0..4),
            any::<u32>(),
            any::<bool>(),
        );
        // Explicit case count: PROPTEST_CASES in the environment cannot lower it.
        let mut runner = TestRunner::new(Config {
            cases: CASES,
            failure_persistence: None,
            ..Config::default()
        });
        runner
            .run(&strategy, |(garbage, edits, id, terminated)| {
                count.fetch_add(1, Ordering::Relaxed);
                let mut d = Decoder::new();
                // Random line noise, then a valid frame with a few bytes overwritten.
                let mut line = garbage;
                let mut victim = wire(&sample_request(id));
                let n = victim.len();
                for (at, v) in &edits {
                    victim[at % n] = *v;
                }
                line.extend(&victim);
                let (good, _) = feed(&mut d, &line);
                // A mutated frame may pass the 16-bit CRC (about 1 in 65 536 multi-byte edits);
                // it then decodes to *some* request, which is all the decoder promises.
                if !edits.is_empty() && !good.is_empty() {
                    mutated_decoded.fetch_add(1, Ordering::Relaxed);
                }
                // Whatever came before, a delimiter and a good frame are served.
                let mut tail = if terminated { vec![0] } else { vec![] };
                tail.extend(wire(&sample_request(id ^ 1)));
                if !terminated {
                    // Without a delimiter the leftovers merge into this frame: send it again.
                    tail.extend(wire(&sample_request(id ^ 1)));
                }
                let (good, _) = feed(&mut d, &tail);
                prop_assert!(good.contains(&sample_request(id ^ 1)));
                Ok(())
            })
            .unwrap();
        assert_eq!(count.load(Ordering::Relaxed), u64::from(CASES));
        eprintln!(
            "{CASES} lines; requests decoded from the noisy part: {}",
            mutated_decoded.load(Ordering::Relaxed)
        );
    }
}
