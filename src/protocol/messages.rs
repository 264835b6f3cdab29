//! The messages: every request the host can send and every message the device sends, with
//! the fields each carries. This file is the protocol's table (docs/protocol.md renders it).

use heapless::Vec;
use serde::{Deserialize, Serialize};

use crate::pipeline::{Frame, RawSample};

use super::codes::ErrorReply;

/// Protocol version reported by Info; bumped on any incompatible message change.
pub const PROTOCOL_VERSION: u16 = 3;
/// Largest data chunk of an upload or read-back.
pub const CHUNK_LEN: usize = 64;

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
