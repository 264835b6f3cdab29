//! The framing: how a message becomes bytes on the wire and back.
//!
//! ```text
//! 0x00 ‖ COBS( postcard(message) ‖ CRC-16/IBM-SDLC(postcard bytes), little-endian ) ‖ 0x00
//! ```
//!
//! COBS removes every 0x00 from the frame so that 0x00 is an unambiguous delimiter: a receiver
//! that starts in the middle of a frame, or sees garbage, resynchronises at the next 0x00. The
//! delimiter before the frame ends whatever garbage (line noise, a half-received frame) the
//! receiver holds, so the frame itself is never merged into it; two delimiters in a row are an
//! empty frame and ignored. The
//! CRC sits inside the COBS frame so that a corrupted byte is caught before postcard sees it.

use heapless::Vec;
use serde::{Deserialize, Serialize};

use super::codes::{ErrorCode, ErrorReply};

/// Largest postcard message body (before CRC and COBS).
pub const MAX_MESSAGE_LEN: usize = 120;
/// Largest frame on the wire: body + CRC + COBS overhead (1 per 254) + two delimiters.
pub const MAX_FRAME_LEN: usize = MAX_MESSAGE_LEN + 2 + 2 + 2;

/// CRC of the frame body: CRC-16/IBM-SDLC (X.25), Hamming distance 4 for frames this short.
pub const CRC16: crc::Crc<u16> = crc::Crc::<u16>::new(&crc::CRC_16_IBM_SDLC);

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
/// The same decoding as the `cobs` crate's `decode_in_place` (0.3), which the encoder above
/// comes from (test `the_decoder_agrees_with_the_cobs_crate_on_any_input`): each code byte `n`
/// is followed by n − 1 data bytes and stands for a 0x00 after them, except after a 0xFF code
/// (a full 254-byte run) and at the end of the frame. Written here because the crate's decoder
/// indexes the buffer (`buf[i]`): its bounds checks bring `core::fmt`'s integer formatting and
/// padding (≈ 1.2 KiB of the front-end's flash) into the firmware for a panic that cannot
/// happen. This one reads and writes through `get`/`get_mut` only: no panicking path.
///
/// A frame handed over here has had its delimiter removed, so a 0x00 inside is a broken frame
/// and refused rather than truncated; so is an empty one and a code byte that points past the
/// end. Writing never overtakes reading (each group writes at most what it read), so the
/// decoding can overwrite the buffer as it goes.
pub fn cobs_decode_in_place(buf: &mut [u8]) -> Result<usize, FrameError> {
    if buf.is_empty() {
        return Err(FrameError::Cobs);
    }
    let len = buf.len();
    let (mut read, mut write) = (0usize, 0usize);
    while let Some(&code) = buf.get(read) {
        // The group's end: the code byte, then code − 1 data bytes. `read` < `len` ≤ isize::MAX,
        // so the sum cannot overflow.
        let end = read + usize::from(code);
        if code == 0 || end > len {
            return Err(FrameError::Cobs);
        }
        read += 1;
        while read < end {
            let byte = buf.get(read).copied().unwrap_or(0);
            if byte == 0 {
                return Err(FrameError::Cobs);
            }
            *buf.get_mut(write).ok_or(FrameError::Cobs)? = byte;
            read += 1;
            write += 1;
        }
        if code != 0xFF && read < len {
            *buf.get_mut(write).ok_or(FrameError::Cobs)? = 0;
            write += 1;
        }
    }
    Ok(write)
}

/// Serializes `msg`, appends the CRC, COBS-encodes and puts a 0x00 delimiter before and after
/// it into `out`. Returns the number of bytes to send.
pub fn encode_frame<T: Serialize>(msg: &T, out: &mut [u8]) -> Result<usize, FrameError> {
    let mut body = [0u8; MAX_MESSAGE_LEN + 2];
    let n = postcard::to_slice(msg, body.get_mut(..MAX_MESSAGE_LEN).unwrap_or(&mut []))
        .map_err(|_| FrameError::MessageTooLong)?
        .len();
    let crc = CRC16.checksum(body.get(..n).unwrap_or(&[]));
    body.get_mut(n..n + 2)
        .ok_or(FrameError::MessageTooLong)?
        .copy_from_slice(&crc.to_le_bytes());
    *out.first_mut().ok_or(FrameError::BufferTooSmall)? = 0;
    let m = cobs_encode(
        body.get(..n + 2).unwrap_or(&[]),
        out.get_mut(1..).unwrap_or(&mut []),
    )?;
    *out.get_mut(m + 1).ok_or(FrameError::BufferTooSmall)? = 0;
    Ok(m + 2)
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
    use crate::pipeline::{ChannelFlags, Frame, LossFlags, RawSample, Status};
    use crate::protocol::messages::*;
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

    /// `line` on a fresh decoder: one frame refused, then `served` decoded, and nothing else.
    fn assert_one_refused_then_served(line: &[u8], served: HostFrame) {
        assert_eq!(feed(&mut Decoder::new(), line), (vec![served], 1));
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

    /// The crate's decoder as the reference: the frame decoder hands over frames without their
    /// delimiter, so a 0x00 inside is refused (the crate would stop there).
    fn crate_decode(bytes: &[u8]) -> Result<std::vec::Vec<u8>, ()> {
        if bytes.contains(&0) {
            return Err(());
        }
        let mut buf = bytes.to_vec();
        let n = cobs::decode_in_place(&mut buf).map_err(|_| ())?;
        buf.truncate(n);
        Ok(buf)
    }

    fn own_decode(bytes: &[u8]) -> Result<std::vec::Vec<u8>, ()> {
        let mut buf = bytes.to_vec();
        let n = cobs_decode_in_place(&mut buf).map_err(|_| ())?;
        buf.truncate(n);
        Ok(buf)
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 20_000, failure_persistence: None, ..ProptestConfig::default() })]

        /// Any bytes: random lines (mostly invalid), encodings of random messages (valid, with
        /// runs of non-zero bytes longer than 254) and those encodings with a few bytes
        /// overwritten or cut short. Same bytes out, or both refuse.
        #[test]
        fn the_decoder_agrees_with_the_cobs_crate_on_any_input(
            raw in proptest::collection::vec(any::<u8>(), 0..300),
            dense in proptest::collection::vec(1u8..=255, 0..600),
            edits in proptest::collection::vec((any::<usize>(), any::<u8>()), 0..3),
            cut in any::<usize>(),
            pick in 0u8..4,
        ) {
            let message = if pick == 0 { &dense } else { &raw };
            let mut encoded = vec![0u8; message.len() + message.len() / 254 + 2];
            let n = cobs_encode(message, &mut encoded).unwrap();
            encoded.truncate(n);
            // (The crate encodes an empty message as nothing; a frame always has its CRC.)
            if !message.is_empty() {
                prop_assert_eq!(own_decode(&encoded), Ok(message.clone()));
            }
            let input = match pick {
                0 | 1 => encoded,
                2 => {
                    let mut e = encoded;
                    if e.is_empty() {
                        e.push(1);
                    }
                    for (at, v) in &edits {
                        let i = at % e.len();
                        e[i] = *v;
                    }
                    e.truncate(1 + cut % e.len());
                    e
                }
                _ => raw.clone(),
            };
            prop_assert_eq!(own_decode(&input), crate_decode(&input), "input {:?}", input);
        }
    }

    #[test]
    fn the_decoder_agrees_with_the_cobs_crate_on_every_short_frame() {
        // Exhaustive over every frame of up to 3 bytes drawn from codes and data that matter
        // (0x00 refused, 0x01 empty group, 0x02..0x04 short groups, 0xFE/0xFF long groups, 0x11
        // data): 8 + 64 + 512 frames.
        let alphabet = [0x00u8, 0x01, 0x02, 0x03, 0x04, 0x11, 0xFE, 0xFF];
        let mut frames: std::vec::Vec<std::vec::Vec<u8>> = vec![vec![]];
        for len in 1..=3 {
            let mut next = std::vec::Vec::new();
            for f in frames.iter().filter(|f| f.len() == len - 1) {
                for &b in &alphabet {
                    let mut g = f.clone();
                    g.push(b);
                    next.push(g);
                }
            }
            frames.extend(next);
        }
        assert_eq!(frames.len(), 1 + 8 + 64 + 512);
        for f in &frames {
            assert_eq!(own_decode(f), crate_decode(f), "frame {f:?}");
        }
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
            assert_eq!(bytes.iter().filter(|b| **b == 0).count(), 2);
            assert_eq!((bytes[0], bytes[bytes.len() - 1]), (0, 0));
            assert_eq!(feed(&mut d, &bytes), (vec![r.clone()], 0));
        }
        let sample = DeviceMessage::Sample {
            id: 5,
            frame: Frame {
                seq: 1,
                time_us: u64::MAX,
                lost: LossFlags(0xFF),
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
                uptime_us: u64::MAX,
                frames_dropped: u32::MAX,
                samples: u32::MAX,
                losses: LossCounters {
                    conversions_lost: u32::MAX,
                    queue_full: u32::MAX,
                    uart_rx_overrun: u32::MAX,
                    uart_framing_noise: u32::MAX,
                    tx_frames_dropped: u32::MAX,
                    erase_stalls: u32::MAX,
                    erase_stall_us: u64::MAX,
                    watchdog_resets: u16::MAX,
                    brownout_resets: u16::MAX,
                },
                streaming: true,
                rate_hz: u32::MAX,
                boot: BootReport {
                    reset_cause: u8::MAX,
                    clock_fallback: true,
                    boot_id: u32::MAX,
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
    fn garbage_right_before_a_frame_without_a_delimiter_does_not_hide_it() {
        // The frame's own leading 0x00 ends the garbage.
        let mut line = vec![0x13, 0x37, 0x42];
        line.extend(wire(&sample_request(1)));
        assert_one_refused_then_served(&line, sample_request(1));
    }

    #[test]
    fn a_truncated_frame_is_refused_and_the_next_one_is_served() {
        let full = wire(&sample_request(1));
        let mut line = full[..full.len() / 2].to_vec();
        line.push(0); // cut short by a delimiter
        line.extend(wire(&sample_request(2)));
        assert_one_refused_then_served(&line, sample_request(2));
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
