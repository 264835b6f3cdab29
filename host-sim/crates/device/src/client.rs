//! Request/response client of the device protocol, with a pipelined sample stream.

use std::collections::{HashMap, VecDeque};
use std::io;
use std::time::{Duration, Instant};

use accomp::pipeline::{Frame, RawSample};
use accomp::protocol::{
    decode_message, encode_frame, peek_protocol_version, upload_body_crc32, DeviceInfo,
    DeviceMessage, ErrorCode, ErrorReply, FrameDecoder, HostFrame, Request, Response, CHUNK_LEN,
    MAX_FRAME_LEN, PROTOCOL_VERSION,
};

use super::transport::Transport;

/// How long one request may take before the client gives up.
pub const DEFAULT_TIMEOUT: Duration = Duration::from_secs(5);
/// Injected samples in flight at once. The firmware queues 16 inbound frames; 8 keeps the
/// line busy in both directions without ever filling that queue.
pub const DEFAULT_WINDOW: usize = 8;

/// Client failures, each naming what went wrong.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// The transport failed.
    #[error("transport: {0}")]
    Io(#[from] io::Error),
    /// No answer in time.
    #[error("timed out after {0:?} waiting for {1}")]
    Timeout(Duration, &'static str),
    /// The device answered with an error.
    #[error("device error {} ({}), detail {}", .0.code, code_name(.0.code), .0.detail)]
    Device(ErrorReply),
    /// The device answered something that does not fit the request.
    #[error("unexpected answer: {0}")]
    Unexpected(String),
    /// The table read back differs from the one uploaded.
    #[error("read-back differs from the upload at byte {0}")]
    ReadBackMismatch(usize),
    /// The device speaks another protocol version: its messages cannot be read.
    #[error(
        "the device speaks protocol version {device}, this host speaks version {host}: \
         update the firmware or the host tools so that both match"
    )]
    ProtocolMismatch {
        /// This host's version.
        host: u16,
        /// The device's version (from Ready or Info).
        device: u16,
    },
}

/// The device's protocol version when it is not this host's.
fn foreign_version(device: u16) -> Result<(), ClientError> {
    if device == PROTOCOL_VERSION {
        Ok(())
    } else {
        Err(ClientError::ProtocolMismatch {
            host: PROTOCOL_VERSION,
            device,
        })
    }
}

impl ClientError {
    /// The device's error code, when this is a device error.
    pub fn device_code(&self) -> Option<ErrorCode> {
        match self {
            ClientError::Device(e) => ErrorCode::from_u16(e.code),
            _ => None,
        }
    }
}

fn code_name(code: u16) -> String {
    ErrorCode::from_u16(code)
        .map(|c| format!("{c:?}"))
        .unwrap_or_else(|| "unknown code".into())
}

/// The protocol client over any transport.
pub struct Client {
    transport: Box<dyn Transport>,
    decoder: FrameDecoder<MAX_FRAME_LEN>,
    next_id: u32,
    /// Id of the next upload: random per client, so two hosts (or a restarted one) never
    /// continue each other's upload.
    next_upload_id: u32,
    /// Messages received while waiting for something else (ids answered later, READY …).
    inbox: VecDeque<DeviceMessage>,
    /// Frames from the device that failed CRC/COBS/decoding.
    pub bad_frames: u64,
    /// Request timeout.
    pub timeout: Duration,
}

impl Client {
    /// A client over `transport`.
    pub fn new(transport: Box<dyn Transport>) -> Self {
        Client {
            transport,
            decoder: FrameDecoder::new(),
            next_id: 1,
            next_upload_id: random_u32(),
            inbox: VecDeque::new(),
            bad_frames: 0,
            timeout: DEFAULT_TIMEOUT,
        }
    }

    /// Sends raw bytes as they are (tests of the device's robustness).
    pub fn send_raw(&mut self, bytes: &[u8]) -> Result<(), ClientError> {
        Ok(self.transport.send(bytes)?)
    }

    /// Sends one request; returns its id.
    pub fn send(&mut self, request: Request) -> Result<u32, ClientError> {
        let id = self.next_id;
        // 0 is reserved for unsolicited messages.
        self.next_id = self.next_id.wrapping_add(1).max(1);
        let mut buf = [0u8; MAX_FRAME_LEN];
        let n = encode_frame(&HostFrame { id, request }, &mut buf)
            .map_err(|e| ClientError::Unexpected(format!("cannot encode request: {e:?}")))?;
        self.transport.send(&buf[..n])?;
        Ok(id)
    }

    /// Next message from the device, waiting until `deadline`.
    fn next_message(
        &mut self,
        deadline: Instant,
        what: &'static str,
    ) -> Result<DeviceMessage, ClientError> {
        if let Some(m) = self.inbox.pop_front() {
            return Ok(m);
        }
        let mut buf = [0u8; 512];
        loop {
            let n = self.transport.recv(&mut buf)?;
            let mut got = None;
            for &b in &buf[..n] {
                match self.decoder.push(b) {
                    Some(Ok(body)) => match decode_message::<DeviceMessage>(body) {
                        Ok(m) => {
                            if let DeviceMessage::Ready { protocol, .. }
                            | DeviceMessage::Response {
                                body: Response::Info(DeviceInfo { protocol, .. }),
                                ..
                            } = &m
                            {
                                foreign_version(*protocol)?;
                            }
                            if got.is_none() {
                                got = Some(m);
                            } else {
                                self.inbox.push_back(m);
                            }
                        }
                        Err(_) => {
                            // Ready and Info keep the place of their version in every
                            // version: a board of another version is named, not timed out on.
                            if let Some(v) = peek_protocol_version(body) {
                                foreign_version(v)?;
                            }
                            self.bad_frames += 1;
                        }
                    },
                    Some(Err(_)) => self.bad_frames += 1,
                    None => {}
                }
            }
            if let Some(m) = got {
                return Ok(m);
            }
            if Instant::now() >= deadline {
                return Err(ClientError::Timeout(self.timeout, what));
            }
        }
    }

    /// The next message from the device, whatever it answers, within `timeout` (robustness
    /// tests that send requests with [`Self::send`] and collect the answers themselves).
    pub fn recv(&mut self, timeout: Duration) -> Result<DeviceMessage, ClientError> {
        let deadline = Instant::now() + timeout;
        match self.next_message(deadline, "a message") {
            Err(ClientError::Timeout(..)) => Err(ClientError::Timeout(timeout, "a message")),
            other => other,
        }
    }

    /// Takes the messages received while waiting for answers and not handed out yet (samples
    /// that streamed in during a request/response exchange).
    pub fn take_inbox(&mut self) -> Vec<DeviceMessage> {
        self.inbox.drain(..).collect()
    }

    /// Waits for READY (sent once by the firmware when its receiver is live).
    pub fn wait_ready(&mut self, timeout: Duration) -> Result<(), ClientError> {
        let deadline = Instant::now() + timeout;
        loop {
            match self.next_message(deadline, "READY") {
                Ok(DeviceMessage::Ready { .. }) => return Ok(()),
                Ok(_) => continue,
                Err(ClientError::Timeout(..)) => {
                    return Err(ClientError::Timeout(timeout, "READY"))
                }
                Err(e) => return Err(e),
            }
        }
    }

    /// Sends a request and waits for its answer; messages for other ids are kept for later.
    pub fn call(&mut self, request: Request) -> Result<Response, ClientError> {
        let id = self.send(request)?;
        self.wait_for(id)
    }

    fn wait_for(&mut self, id: u32) -> Result<Response, ClientError> {
        let deadline = Instant::now() + self.timeout;
        let mut skipped = Vec::new();
        let result = loop {
            let m = match self.next_message(deadline, "a response") {
                Ok(m) => m,
                Err(e) => break Err(e),
            };
            match m {
                DeviceMessage::Response { id: got, body } if got == id => break Ok(body),
                DeviceMessage::Error { id: got, error } if got == id => {
                    break Err(ClientError::Device(error))
                }
                DeviceMessage::Sample { id: got, .. } if got == id => {
                    break Err(ClientError::Unexpected("a sample for a request".into()))
                }
                other => skipped.push(other),
            }
        };
        // Keep what belonged to others, in order, ahead of anything newer.
        for m in skipped.into_iter().rev() {
            self.inbox.push_front(m);
        }
        result
    }

    /// Liveness check.
    pub fn ping(&mut self) -> Result<(), ClientError> {
        match self.call(Request::Ping)? {
            Response::Pong => Ok(()),
            other => Err(ClientError::Unexpected(format!("{other:?}"))),
        }
    }

    /// Firmware version, board, tables, uptime.
    pub fn info(&mut self) -> Result<DeviceInfo, ClientError> {
        match self.call(Request::Info)? {
            Response::Info(i) => Ok(i),
            other => Err(ClientError::Unexpected(format!("{other:?}"))),
        }
    }

    /// A fresh upload id (never 0, different from the previous one).
    pub fn new_upload_id(&mut self) -> u32 {
        let id = self.next_upload_id;
        self.next_upload_id = self.next_upload_id.wrapping_add(1).max(1);
        id.max(1)
    }

    /// Uploads `bytes` in chunks and commits; `progress(sent, total)` after each chunk.
    /// Returns the id of the now active table.
    pub fn upload(
        &mut self,
        bytes: &[u8],
        progress: impl FnMut(usize, usize),
    ) -> Result<u32, ClientError> {
        let upload_id = self.begin_upload(bytes)?;
        self.send_chunks(upload_id, bytes, progress)?;
        match self.call(Request::UploadCommit { upload_id })? {
            Response::Committed { table_id } => Ok(table_id),
            other => Err(ClientError::Unexpected(format!("{other:?}"))),
        }
    }

    /// The first step of [`Client::upload`]: announces an upload of `bytes` under a fresh
    /// upload id, which it returns.
    pub fn begin_upload(&mut self, bytes: &[u8]) -> Result<u32, ClientError> {
        let upload_id = self.new_upload_id();
        self.expect_ok(Request::UploadBegin {
            upload_id,
            total_len: bytes.len() as u32,
            body_crc32: upload_body_crc32(bytes),
        })?;
        Ok(upload_id)
    }

    /// The second step of [`Client::upload`]: sends `bytes` in chunks (not committed);
    /// `progress(sent, total)` after each chunk.
    pub fn send_chunks(
        &mut self,
        upload_id: u32,
        bytes: &[u8],
        mut progress: impl FnMut(usize, usize),
    ) -> Result<(), ClientError> {
        for (i, chunk) in bytes.chunks(CHUNK_LEN).enumerate() {
            let data = heapless::Vec::from_slice(chunk)
                .map_err(|_| ClientError::Unexpected("chunk too long".into()))?;
            self.expect_ok(Request::UploadChunk {
                upload_id,
                offset: (i * CHUNK_LEN) as u32,
                data,
            })?;
            progress((i * CHUNK_LEN + chunk.len()).min(bytes.len()), bytes.len());
        }
        Ok(())
    }

    /// Upload, then read the active table back and compare byte by byte.
    pub fn load(
        &mut self,
        bytes: &[u8],
        progress: impl FnMut(usize, usize),
    ) -> Result<u32, ClientError> {
        let id = self.upload(bytes, progress)?;
        let back = self.read_table()?;
        if let Some(at) = (0..bytes.len().max(back.len())).find(|&i| bytes.get(i) != back.get(i)) {
            return Err(ClientError::ReadBackMismatch(at));
        }
        Ok(id)
    }

    /// The active table's encoding.
    pub fn read_table(&mut self) -> Result<Vec<u8>, ClientError> {
        let mut out = Vec::new();
        loop {
            match self.call(Request::ReadTable {
                offset: out.len() as u32,
            })? {
                Response::TableChunk {
                    offset,
                    total_len,
                    data,
                } if offset as usize == out.len() => {
                    out.extend_from_slice(&data);
                    if out.len() >= total_len as usize || data.is_empty() {
                        return Ok(out);
                    }
                }
                other => return Err(ClientError::Unexpected(format!("{other:?}"))),
            }
        }
    }

    fn expect_ok(&mut self, request: Request) -> Result<(), ClientError> {
        match self.call(request)? {
            Response::Ok => Ok(()),
            other => Err(ClientError::Unexpected(format!("{other:?}"))),
        }
    }

    /// Runs every raw sample through the device, keeping `window` requests in flight, and
    /// returns the frames in input order. `progress(done, total)` is called as frames arrive.
    pub fn process_samples(
        &mut self,
        raws: &[RawSample],
        window: usize,
        mut progress: impl FnMut(usize, usize),
    ) -> Result<Vec<Frame>, ClientError> {
        let mut out = Vec::with_capacity(raws.len());
        self.stream_samples(raws, window, |i, frame| {
            out.push(frame);
            progress(i + 1, raws.len());
            Ok(())
        })?;
        Ok(out)
    }

    /// Runs every raw sample through the device, keeping `window` requests in flight, and hands
    /// each frame to `on_frame(index, frame)` in input order as soon as it and all before it
    /// have arrived (a streaming writer; nothing is kept beyond the window).
    pub fn stream_samples(
        &mut self,
        raws: &[RawSample],
        window: usize,
        mut on_frame: impl FnMut(usize, Frame) -> Result<(), ClientError>,
    ) -> Result<(), ClientError> {
        let window = window.max(1);
        // Frames that arrived ahead of an earlier one, by index.
        let mut pending: HashMap<usize, Frame> = HashMap::new();
        let mut emitted = 0usize;
        let mut in_flight: HashMap<u32, usize> = HashMap::new();
        let mut next = 0usize;
        let mut done = 0usize;
        while done < raws.len() {
            while in_flight.len() < window && next < raws.len() {
                let id = self.send(Request::InjectSample { raw: raws[next] })?;
                in_flight.insert(id, next);
                next += 1;
            }
            let deadline = Instant::now() + self.timeout;
            match self.next_message(deadline, "a sample")? {
                DeviceMessage::Sample { id, frame } => {
                    if let Some(i) = in_flight.remove(&id) {
                        pending.insert(i, frame);
                        done += 1;
                        while let Some(f) = pending.remove(&emitted) {
                            on_frame(emitted, f)?;
                            emitted += 1;
                        }
                    }
                }
                DeviceMessage::Error { id, error } if in_flight.contains_key(&id) => {
                    return Err(ClientError::Device(error));
                }
                // Unsolicited messages (acquired samples, errors for garbage) do not stop us.
                _ => {}
            }
        }
        Ok(())
    }
}

/// A random number from std's randomly keyed hasher (no extra dependency).
fn random_u32() -> u32 {
    use std::hash::{BuildHasher, Hasher};
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    h.write_u32(std::process::id());
    h.finish() as u32
}

#[cfg(test)]
mod tests {
    use super::*;
    use accomp::protocol::Board;

    /// A device that answers every read with the same bytes.
    struct Replay(Vec<u8>);

    impl Transport for Replay {
        fn send(&mut self, _: &[u8]) -> io::Result<()> {
            Ok(())
        }
        fn recv(&mut self, buf: &mut [u8]) -> io::Result<usize> {
            let n = self.0.len().min(buf.len());
            buf[..n].copy_from_slice(&self.0[..n]);
            self.0.drain(..n);
            Ok(n)
        }
    }

    fn wire<T: serde::Serialize>(msg: &T) -> Vec<u8> {
        let mut out = [0u8; MAX_FRAME_LEN];
        let n = encode_frame(msg, &mut out).unwrap();
        out[..n].to_vec()
    }

    #[test]
    fn a_board_of_another_protocol_version_is_refused_with_both_versions_named() {
        let old_ready = DeviceMessage::Ready {
            board: Board::Frontend,
            protocol: PROTOCOL_VERSION - 1,
        };
        let mut c = Client::new(Box::new(Replay(wire(&old_ready))));
        let e = c.wait_ready(Duration::from_millis(50)).unwrap_err();
        assert!(
            matches!(e, ClientError::ProtocolMismatch { host, device }
                if host == PROTOCOL_VERSION && device == PROTOCOL_VERSION - 1),
            "{e}"
        );
        let text = e.to_string();
        assert!(
            text.contains(&format!("version {}", PROTOCOL_VERSION - 1)),
            "{text}"
        );
        assert!(
            text.contains(&format!("version {PROTOCOL_VERSION}")),
            "{text}"
        );

        // An Info of another version does not decode as this version's: the version is still
        // read from its head (Response, id, Info, firmware, board, protocol, …).
        let old_info = (
            1u32,
            1u32,
            1u32,
            "0.1.0",
            Board::Qemu,
            3u16,
            7u64,
            0u32,
            0u32,
        );
        let mut c = Client::new(Box::new(Replay(wire(&old_info))));
        c.timeout = Duration::from_millis(50);
        let e = c.info().unwrap_err();
        assert!(
            matches!(e, ClientError::ProtocolMismatch { device: 3, .. }),
            "{e}"
        );
    }
}
