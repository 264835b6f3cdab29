//! The messages: every request the host can send and every message the device sends, with
//! the fields each carries. This file is the protocol's table (docs/protocol.md renders it).

use heapless::Vec;
use serde::{Deserialize, Serialize};

use crate::pipeline::{Frame, RawSample};

use super::codes::ErrorReply;

/// Protocol version reported by Ready and Info; bumped on any incompatible message change. The
/// host refuses a board of another version, naming both ([`peek_protocol_version`]).
pub const PROTOCOL_VERSION: u16 = 5;
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

/// The protocol version of a device message body, read from the fields that keep their place
/// in every version: Ready's `protocol`, and Info's (firmware, board, protocol) at the start
/// of the reply. None for any other message or bytes that are not one. Lets the host name the
/// device's version when the rest of its messages do not decode.
pub fn peek_protocol_version(body: &[u8]) -> Option<u16> {
    use postcard::take_from_bytes as take;
    let (variant, rest) = take::<u32>(body).ok()?;
    let rest = match variant {
        0 => rest,
        1 => {
            let (_id, rest) = take::<u32>(rest).ok()?;
            let (response, rest) = take::<u32>(rest).ok()?;
            if response != 1 {
                return None;
            }
            take::<heapless::String<16>>(rest).ok()?.1
        }
        _ => return None,
    };
    let (_board, rest) = take::<Board>(rest).ok()?;
    take::<u16>(rest).ok().map(|(v, _)| v)
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
    /// Sent once after boot when the UART receiver is live. Its layout (variant 0, board,
    /// protocol) is the same in every protocol version, so any host can read the version.
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
    /// Microseconds since boot, from the board's time base.
    pub uptime_us: u64,
    /// Frames dropped by the receiver (bad CRC, overflow, queue full) since boot.
    pub frames_dropped: u32,
    /// Readings acquired or injected since boot: the next frame's `seq`.
    pub samples: u32,
    /// Everything lost since boot, by cause.
    pub losses: LossCounters,
    /// Streaming of acquired samples on.
    pub streaming: bool,
    /// ADS1262 data rate in samples per second (SetRate; one frame per 8 conversions with
    /// sinc4, see docs/protocol.md).
    pub rate_hz: u32,
    /// Why the MCU last reset, and which clock it runs on.
    pub boot: BootReport,
}

/// What was lost since boot, by cause: every reading missing from the `seq` sequence and every
/// byte the UART could not take is counted here (docs/protocol.md, "Loss accounting").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct LossCounters {
    /// Readings missing from the `seq` sequence, whatever the cause (the sum of the gaps).
    pub conversions_lost: u32,
    /// Readings dropped because the worker's queue was full.
    pub queue_full: u32,
    /// UART receiver overruns (USART_SR.ORE): a byte arrived before the previous was read.
    pub uart_rx_overrun: u32,
    /// UART framing or noise errors (USART_SR.FE / NF): a byte received damaged.
    pub uart_framing_noise: u32,
    /// Device → host frames dropped because the transmitter could not take them.
    pub tx_frames_dropped: u32,
    /// Flash erases that stalled the core (each one a stretch without instruction fetch).
    pub erase_stalls: u32,
    /// Total time the core spent stalled in those erases, in µs.
    pub erase_stall_us: u64,
    /// Independent-watchdog resets seen at boot (RCC_CSR.IWDGRSTF), since power-on.
    pub watchdog_resets: u16,
    /// Brown-out resets seen at boot (RCC_CSR.BORRSTF), since power-on.
    pub brownout_resets: u16,
}

/// Reset cause and clock source, read once at boot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct BootReport {
    /// RCC_CSR[31:25] of the boot (RM0090 "RCC clock control & status register"): bit 0 BOR,
    /// 1 PIN (reset pin), 2 POR/PDR, 3 SFT (software: a panic, a fatal start-up error), 4 IWDG
    /// (watchdog: acquisition or the worker stopped), 5 WWDG, 6 LPWR. 0 = unknown (QEMU).
    pub reset_cause: u8,
    /// The crystal did not start within 100 ms, or failed later (Clock Security System): the
    /// core runs from the HSI (±1 %).
    pub clock_fallback: bool,
    /// Differs from one boot to the next, so a host that lost the link across a reset (and
    /// missed READY) still tells a new boot from the old one: uptime alone cannot, since a new
    /// boot's clock can have passed the old boot's last time stamp by the time the host is
    /// back. High 16 bits: a nonce drawn at power-on; low 16 bits: boots since power-on
    /// ([`BootReport::next_boot_id`]).
    pub boot_id: u32,
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

    /// This boot's id, given the id kept from the boot before (memory that survives a reset but
    /// not a power cycle; None when it held nothing valid) and `power_on_nonce`, bits that differ
    /// between power-ons (read only when a new nonce is needed). A reset keeps the nonce and
    /// counts the boot; a power-on (or nothing kept) draws a new nonce and starts the count at 1.
    pub fn next_boot_id(self, kept: Option<u32>, power_on_nonce: impl FnOnce() -> u32) -> u32 {
        match kept {
            Some(id) if self.reset_cause & Self::POR == 0 => {
                // The count skips 0, so a kept id never equals a fresh one's count by wrapping.
                let count = match (id as u16).wrapping_add(1) {
                    0 => 1,
                    n => n,
                };
                id & 0xFFFF_0000 | u32::from(count)
            }
            _ => {
                let n = power_on_nonce();
                // Fold all 32 bits into the 16 the id keeps.
                (n ^ (n << 16)) & 0xFFFF_0000 | 1
            }
        }
    }

    /// The (watchdog, brown-out) reset counts after this boot, given the counts kept from the
    /// boot before (memory that survives a reset but not a power cycle; None when it held
    /// nothing valid). A power-on starts both at zero. RM0090 §7.3.21: a power-on sets PORRSTF
    /// and BORRSTF together, so BORRSTF alone is a brown-out the supply recovered from.
    pub fn counted_resets(self, kept: Option<(u16, u16)>) -> (u16, u16) {
        let cause = self.reset_cause;
        let (mut watchdog, mut brownout) = match kept {
            Some(k) if cause & Self::POR == 0 => k,
            _ => (0, 0),
        };
        if cause & Self::IWDG != 0 {
            watchdog = watchdog.saturating_add(1);
        }
        if cause & Self::BOR != 0 && cause & Self::POR == 0 {
            brownout = brownout.saturating_add(1);
        }
        (watchdog, brownout)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_protocol_version_is_read_from_ready_and_info_of_any_version() {
        let mut buf = [0u8; 128];
        let ready = DeviceMessage::Ready {
            board: Board::Frontend,
            protocol: PROTOCOL_VERSION,
        };
        let body = postcard::to_slice(&ready, &mut buf).unwrap();
        assert_eq!(peek_protocol_version(body), Some(PROTOCOL_VERSION));
        // Info of version 3: (Response, id, Info, firmware, board, protocol, …) with a
        // different tail from this version's.
        let old_info = (
            1u32,
            77u32,
            1u32,
            "0.1.0",
            Board::Qemu,
            3u16,
            12_345u64,
            1u32,
        );
        let body = postcard::to_slice(&old_info, &mut buf).unwrap();
        assert_eq!(peek_protocol_version(body), Some(3));
        // Not a Ready or an Info: no version.
        let pong = DeviceMessage::Response {
            id: 1,
            body: Response::Pong,
        };
        let body = postcard::to_slice(&pong, &mut buf).unwrap();
        assert_eq!(peek_protocol_version(body), None);
        assert_eq!(peek_protocol_version(&[]), None);
    }

    #[test]
    fn watchdog_and_brown_out_resets_are_counted_from_power_on() {
        let boot = |cause| BootReport {
            reset_cause: cause,
            ..BootReport::default()
        };
        let power_on = boot(BootReport::POR | BootReport::BOR | BootReport::PIN);
        assert_eq!(power_on.counted_resets(Some((7, 7))), (0, 0));
        let dog = boot(BootReport::IWDG | BootReport::PIN);
        assert_eq!(dog.counted_resets(Some((0, 0))), (1, 0));
        assert_eq!(dog.counted_resets(Some((1, 0))), (2, 0));
        let brown = boot(BootReport::BOR | BootReport::PIN);
        assert_eq!(brown.counted_resets(Some((2, 0))), (2, 1));
        // Nothing kept (first boot after flashing, or memory lost): counting starts afresh.
        assert_eq!(dog.counted_resets(None), (1, 0));
        assert_eq!(boot(BootReport::PIN).counted_resets(Some((3, 4))), (3, 4));
    }

    #[test]
    fn a_reset_keeps_the_power_on_nonce_and_counts_the_boot_while_a_power_on_draws_a_new_one() {
        let boot = |cause| BootReport {
            reset_cause: cause,
            ..BootReport::default()
        };
        let no_nonce = || -> u32 { panic!("a reset must not draw a new nonce") };
        let dog = boot(BootReport::IWDG | BootReport::PIN);
        assert_eq!(dog.next_boot_id(Some(0xBEEF_0001), no_nonce), 0xBEEF_0002);
        assert_eq!(
            boot(BootReport::PIN).next_boot_id(Some(0xBEEF_0002), no_nonce),
            0xBEEF_0003
        );
        // The count skips 0 when it wraps, so every boot of one power-on differs from the last.
        assert_eq!(dog.next_boot_id(Some(0xBEEF_FFFF), no_nonce), 0xBEEF_0001);
        // A power-on (POR set) or nothing kept: a new nonce, folded to 16 bits, count 1.
        let power_on = boot(BootReport::POR | BootReport::BOR | BootReport::PIN);
        assert_eq!(
            power_on.next_boot_id(Some(0xBEEF_0005), || 0x1234_0000),
            0x1234_0001
        );
        assert_eq!(dog.next_boot_id(None, || 0x0000_5678), 0x5678_0001);
        // Nonces that differ only in their high or only in their low half still give new ids.
        assert_ne!(
            dog.next_boot_id(None, || 0x0001_0000),
            dog.next_boot_id(None, || 0x0002_0000)
        );
        assert_ne!(
            dog.next_boot_id(None, || 0x0000_0001),
            dog.next_boot_id(None, || 0x0000_0002)
        );
    }
}
