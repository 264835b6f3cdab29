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
/// How often an unanswered request that is safe to repeat is sent again before the client
/// gives up (so at most 1 + this many sends).
pub const DEFAULT_RETRIES: u32 = 2;
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
    /// Repeats of an unanswered request that is safe to repeat (Ping, Info, ReadTable,
    /// UploadBegin, UploadChunk) before giving up.
    pub retries: u32,
    /// Requests sent again: their ids, whose late or repeated answers are dropped when they
    /// come.
    repeated: std::collections::HashSet<u32>,
    /// Requests sent again since this client was made (diagnostics and tests).
    pub resent: u64,
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
            retries: DEFAULT_RETRIES,
            repeated: Default::default(),
            resent: 0,
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
        self.send_as(id, request)?;
        Ok(id)
    }

    fn send_as(&mut self, id: u32, request: Request) -> Result<u32, ClientError> {
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

    /// [`Self::call`] for a request the device may get twice without harm (it answers the same
    /// or, for a chunk it already has, says which offset it expects): unanswered within the
    /// timeout, it is sent again under the same id, up to [`Self::retries`] times. The request
    /// or its answer may have been lost on the line (noise, a frame dropped on a full queue);
    /// an answer that comes late is taken whichever send it answers, and the other one's
    /// answer is dropped when it comes.
    fn call_repeatable(&mut self, request: Request) -> Result<Response, ClientError> {
        let id = self.send(request.clone())?;
        let mut left = self.retries;
        loop {
            match self.wait_for(id) {
                Err(ClientError::Timeout(..)) if left > 0 => {
                    left -= 1;
                    self.resent += 1;
                    self.repeated.insert(id);
                    self.send_as(id, request.clone())?;
                }
                other => return other,
            }
        }
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
                // The second answer to a request that was sent again.
                DeviceMessage::Response { id: got, .. } | DeviceMessage::Error { id: got, .. }
                    if self.repeated.contains(&got) => {}
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
        match self.call_repeatable(Request::Ping)? {
            Response::Pong => Ok(()),
            other => Err(ClientError::Unexpected(format!("{other:?}"))),
        }
    }

    /// Firmware version, board, tables, uptime.
    pub fn info(&mut self) -> Result<DeviceInfo, ClientError> {
        match self.call_repeatable(Request::Info)? {
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
        // A commit is not repeated (a second one would find the upload finished). Unanswered,
        // Info says whether it took: the table's id is its body CRC.
        match self.call(Request::UploadCommit { upload_id }) {
            Ok(Response::Committed { table_id }) => Ok(table_id),
            Ok(other) => Err(ClientError::Unexpected(format!("{other:?}"))),
            Err(e @ ClientError::Timeout(..)) => {
                let table_id = upload_body_crc32(bytes);
                match self.info() {
                    Ok(info) if info.active_table == Some(table_id) => Ok(table_id),
                    _ => Err(e),
                }
            }
            Err(e) => Err(e),
        }
    }

    /// The first step of [`Client::upload`]: announces an upload of `bytes` under a fresh
    /// upload id, which it returns.
    pub fn begin_upload(&mut self, bytes: &[u8]) -> Result<u32, ClientError> {
        let upload_id = self.new_upload_id();
        // Repeatable: a second Begin of the same upload restarts it at offset 0, before any
        // chunk is sent.
        let begin = Request::UploadBegin {
            upload_id,
            total_len: bytes.len() as u32,
            body_crc32: upload_body_crc32(bytes),
        };
        match self.call_repeatable(begin)? {
            Response::Ok => Ok(upload_id),
            other => Err(ClientError::Unexpected(format!("{other:?}"))),
        }
    }

    /// The second step of [`Client::upload`]: sends `bytes` in chunks (not committed);
    /// `progress(sent, total)` after each chunk. A chunk whose answer was lost is sent again;
    /// if the device had it, it answers ChunkOutOfOrder with the offset it expects, and the
    /// upload resumes there (protocol: "UploadChunk").
    pub fn send_chunks(
        &mut self,
        upload_id: u32,
        bytes: &[u8],
        mut progress: impl FnMut(usize, usize),
    ) -> Result<(), ClientError> {
        let mut offset = 0;
        while offset < bytes.len() {
            let chunk = &bytes[offset..(offset + CHUNK_LEN).min(bytes.len())];
            let data = heapless::Vec::from_slice(chunk)
                .map_err(|_| ClientError::Unexpected("chunk too long".into()))?;
            let request = Request::UploadChunk {
                upload_id,
                offset: offset as u32,
                data,
            };
            let resent = self.resent;
            offset = match self.call_repeatable(request) {
                Ok(Response::Ok) => offset + chunk.len(),
                Ok(other) => return Err(ClientError::Unexpected(format!("{other:?}"))),
                Err(ClientError::Device(e))
                    if ErrorCode::from_u16(e.code) == Some(ErrorCode::ChunkOutOfOrder)
                        && self.resent > resent
                        && (e.detail as usize) <= bytes.len() =>
                {
                    e.detail as usize
                }
                Err(e) => return Err(e),
            };
            progress(offset, bytes.len());
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
            match self.call_repeatable(Request::ReadTable {
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

    /// Which frame of the line is lost: the request the host sent as its k-th frame, or the
    /// board's answer to it.
    #[derive(Clone, Copy, PartialEq)]
    enum Lose {
        Request,
        Answer,
    }

    /// The host end of a line to the virtual board (`accomp board-sim`'s board: the firmware's
    /// service and acquisition on the chip models) that loses the frames in `lose`. The board
    /// runs in its own thread (its chip models are not `Send`); it returns the requests it got.
    struct LossyLine {
        to_board: std::sync::mpsc::Sender<Vec<u8>>,
        from_board: std::sync::mpsc::Receiver<Vec<u8>>,
        pending: Vec<u8>,
    }

    impl Transport for LossyLine {
        fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
            self.to_board.send(bytes.to_vec()).map_err(io::Error::other)
        }
        fn recv(&mut self, buf: &mut [u8]) -> io::Result<usize> {
            if self.pending.is_empty() {
                use std::sync::mpsc::RecvTimeoutError;
                match self.from_board.recv_timeout(Duration::from_millis(5)) {
                    Ok(b) => self.pending = b,
                    Err(RecvTimeoutError::Timeout) => return Ok(0),
                    Err(RecvTimeoutError::Disconnected) => {
                        return Err(io::Error::other("board gone"))
                    }
                }
            }
            let n = self.pending.len().min(buf.len());
            buf[..n].copy_from_slice(&self.pending[..n]);
            self.pending.drain(..n);
            Ok(n)
        }
    }

    fn board_on_lossy_line(
        lose: HashMap<usize, Lose>,
    ) -> (LossyLine, std::thread::JoinHandle<Vec<Request>>) {
        use crate::board_sim::{flash, VirtualBoard};
        let (to_board, requests) = std::sync::mpsc::channel::<Vec<u8>>();
        let (answers, from_board) = std::sync::mpsc::channel();
        let board = std::thread::spawn(move || {
            let mut board = VirtualBoard::boot(flash::open(None).unwrap(), 0, 0);
            board.tx.clear();
            let mut got = Vec::new();
            for (k, bytes) in requests.iter().enumerate() {
                if lose.get(&k) == Some(&Lose::Request) {
                    continue;
                }
                let mut d = FrameDecoder::<MAX_FRAME_LEN>::new();
                for &b in &bytes {
                    if let Some(Ok(body)) = d.push(b) {
                        got.push(decode_message::<HostFrame>(body).unwrap().request);
                    }
                }
                board.receive(&bytes);
                board.idle();
                let answer = std::mem::take(&mut board.tx);
                if lose.get(&k) != Some(&Lose::Answer) {
                    let _ = answers.send(answer);
                }
            }
            got
        });
        let line = LossyLine {
            to_board,
            from_board,
            pending: Vec::new(),
        };
        (line, board)
    }

    #[test]
    fn lost_requests_and_answers_are_retried_where_safe_and_an_upload_resumes_at_the_devices_offset(
    ) {
        let table = accomp::reference::paper_order2_table().encode();
        // The host's frames in order, repeats included: 0–1 Ping, 2–3 Info, 4 Begin, 5–13 the
        // chunks, 14 the commit, 15 Info, 16– the read-back.
        let lose = HashMap::from([
            (0, Lose::Request), // Ping never arrives: sent again (1)
            (2, Lose::Answer),  // Info answered, the answer lost: sent again (3)
            (6, Lose::Answer),  // chunk 64 taken, its Ok lost: sent again (7), refused
            // with ChunkOutOfOrder(128): resumed at 128 (8)
            (8, Lose::Request), // chunk 128 lost: sent again (9)
            (14, Lose::Answer), // the commit's answer lost: Info (15) confirms it
            (17, Lose::Answer), // ReadTable 64's answer lost: sent again (18)
        ]);
        let (line, board) = board_on_lossy_line(lose);
        let mut c = Client::new(Box::new(line));
        c.timeout = Duration::from_millis(200);
        c.ping().unwrap();
        assert_eq!(c.info().unwrap().active_table, None);
        let id = c.load(&table, |_, _| {}).unwrap();
        assert_eq!(id, upload_body_crc32(&table));
        assert_eq!(c.resent, 5, "Ping, Info, two chunks, one ReadTable");
        assert_eq!(c.info().unwrap().active_table, Some(id));
        drop(c);
        let got = board.join().unwrap();
        // What the board received: the upload resumed where the device was, never restarted,
        // and the commit went once.
        let chunks: Vec<u32> = got
            .iter()
            .filter_map(|r| match r {
                Request::UploadChunk { offset, .. } => Some(*offset),
                _ => None,
            })
            .collect();
        assert_eq!(chunks, [0, 64, 64, 128, 192, 256, 320, 384]);
        let begins = got
            .iter()
            .filter(|r| matches!(r, Request::UploadBegin { .. }))
            .count();
        let commits = got
            .iter()
            .filter(|r| matches!(r, Request::UploadCommit { .. }))
            .count();
        assert_eq!((begins, commits), (1, 1));
    }

    #[test]
    fn an_unanswered_commit_is_not_sent_again_and_fails_when_info_does_not_show_the_table() {
        let table = accomp::reference::paper_order2_table().encode();
        // 0 Begin, 1–7 chunks, 8 the commit: lost on its way. Info (9) shows no table.
        let (line, board) = board_on_lossy_line(HashMap::from([(8, Lose::Request)]));
        let mut c = Client::new(Box::new(line));
        c.timeout = Duration::from_millis(200);
        let e = c.upload(&table, |_, _| {}).unwrap_err();
        assert!(matches!(e, ClientError::Timeout(..)), "{e}");
        drop(c);
        let got = board.join().unwrap();
        assert!(!got
            .iter()
            .any(|r| matches!(r, Request::UploadCommit { .. })));
        assert!(matches!(got.last(), Some(Request::Info)));
    }
}
