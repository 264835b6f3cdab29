//! Byte transports to the device.

use std::io::{self, Read, Write};
use std::net::TcpStream;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::time::Duration;

/// A bidirectional byte stream with a read timeout.
pub trait Transport: Send {
    /// Sends all bytes.
    fn send(&mut self, bytes: &[u8]) -> io::Result<()>;
    /// Reads what is available, waiting at most the transport's poll interval; Ok(0) when
    /// nothing came in that time.
    fn recv(&mut self, buf: &mut [u8]) -> io::Result<usize>;
}

/// Poll interval of reads: short, so that deadlines are checked often.
const POLL: Duration = Duration::from_millis(20);

/// QEMU's `-serial tcp:…` chardev.
pub struct TcpTransport {
    stream: TcpStream,
}

impl TcpTransport {
    /// Wraps a connected stream.
    pub fn new(stream: TcpStream) -> io::Result<Self> {
        stream.set_read_timeout(Some(POLL))?;
        stream.set_nodelay(true)?;
        Ok(TcpTransport { stream })
    }
}

/// A read that returned nothing for a benign reason is "no bytes yet": the poll timeout, or a
/// signal (a socket with SO_RCVTIMEO is never restarted after a signal handler, SA_RESTART or
/// not — signal(7) — so Ctrl-C or SIGTERM would otherwise surface as an I/O error while the
/// signal handler is still cleaning up).
fn timeout_is_empty(r: io::Result<usize>) -> io::Result<usize> {
    match r {
        Err(e)
            if matches!(
                e.kind(),
                io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut | io::ErrorKind::Interrupted
            ) =>
        {
            Ok(0)
        }
        Ok(0) => Err(io::Error::new(
            io::ErrorKind::UnexpectedEof,
            "device closed the connection",
        )),
        other => other,
    }
}

impl Transport for TcpTransport {
    fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.stream.write_all(bytes)
    }
    fn recv(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        timeout_is_empty(self.stream.read(buf))
    }
}

/// A real board on a serial port (8N1).
pub struct SerialTransport {
    port: Box<dyn serialport::SerialPort>,
    /// The port's path, named in every error.
    path: String,
}

/// `e` with the port named: "serial port /dev/ttyUSB0: …".
fn on_port(path: &str, e: io::Error) -> io::Error {
    io::Error::new(e.kind(), format!("serial port {path}: {e}"))
}

impl SerialTransport {
    /// Opens `path` at `baud`.
    pub fn open(path: &str, baud: u32) -> io::Result<Self> {
        let port = serialport::new(path, baud)
            .timeout(POLL)
            .open()
            .map_err(|e| {
                let kind = match e.kind() {
                    serialport::ErrorKind::NoDevice => io::ErrorKind::NotFound,
                    serialport::ErrorKind::Io(k) => k,
                    _ => io::ErrorKind::Other,
                };
                on_port(path, io::Error::new(kind, e.description))
            })?;
        Ok(SerialTransport {
            port,
            path: path.to_string(),
        })
    }

    /// Discards what the port has received and not yet been read (bytes from before this
    /// program opened it).
    pub fn clear_input(&mut self) {
        let _ = self.port.clear(serialport::ClearBuffer::Input);
    }

    /// This port with a thread of its own that reads it all the time ([`DrainedSerial`]).
    pub fn drained(self) -> io::Result<DrainedSerial> {
        let reader = SerialTransport {
            port: self
                .port
                .try_clone()
                .map_err(|e| on_port(&self.path, io::Error::other(e.description)))?,
            path: self.path.clone(),
        };
        let (tx, rx) = mpsc::channel();
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let stop = stop.clone();
            std::thread::Builder::new()
                .name("serial-drain".into())
                .spawn(move || drain(reader, &tx, &stop))
                .map_err(|e| on_port(&self.path, e))?
        };
        Ok(DrainedSerial {
            port: self,
            rx,
            pending: Vec::new(),
            taken: 0,
            stop,
            thread: Some(thread),
        })
    }
}

/// A serial port read by a thread of its own, into memory, whatever the reading side is doing
/// meanwhile: writing and syncing a file on a loaded disk (an fsync has taken seconds on the
/// shared test machine), or not being scheduled. Without it the bytes wait in the kernel's tty
/// buffers (tens of KiB: 20 KiB on a Linux pseudo-terminal, a few seconds of a full 115200 Bd
/// line) and, once they are full, the line loses them, with nothing to say so but the gap in
/// seq. The memory held grows only while the reading side stalls, at the line's rate
/// (11.5 kB/s at most at 115200 Bd).
pub struct DrainedSerial {
    /// Sends (requests); its clone is read by the thread.
    port: SerialTransport,
    rx: mpsc::Receiver<io::Result<Vec<u8>>>,
    /// The chunk being handed out, and how much of it has been.
    pending: Vec<u8>,
    taken: usize,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

/// The reading thread: every chunk the port gives goes to the channel, until the port fails
/// (its error goes too), the receiver is gone or `stop` is set (checked every poll interval).
fn drain(mut port: SerialTransport, tx: &mpsc::Sender<io::Result<Vec<u8>>>, stop: &AtomicBool) {
    let mut buf = [0u8; 4096];
    while !stop.load(Ordering::Relaxed) {
        match port.recv(&mut buf) {
            Ok(0) => {}
            Ok(n) => {
                if tx.send(Ok(buf[..n].to_vec())).is_err() {
                    return;
                }
            }
            Err(e) => {
                let _ = tx.send(Err(e));
                return;
            }
        }
    }
}

impl Transport for DrainedSerial {
    fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.port.send(bytes)
    }
    fn recv(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        if self.taken == self.pending.len() {
            match self.rx.recv_timeout(POLL) {
                Ok(Ok(chunk)) => {
                    self.pending = chunk;
                    self.taken = 0;
                }
                Ok(Err(e)) => return Err(e),
                Err(mpsc::RecvTimeoutError::Timeout) => return Ok(0),
                Err(mpsc::RecvTimeoutError::Disconnected) => {
                    return Err(on_port(
                        &self.port.path,
                        io::Error::new(io::ErrorKind::UnexpectedEof, "reading thread ended"),
                    ))
                }
            }
        }
        let n = buf.len().min(self.pending.len() - self.taken);
        buf[..n].copy_from_slice(&self.pending[self.taken..self.taken + n]);
        self.taken += n;
        Ok(n)
    }
}

impl Drop for DrainedSerial {
    /// Stops the thread and waits for it (one poll interval at most), so the port is closed
    /// when this is dropped: the recorder reopens the same path after a lost link.
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Transport for SerialTransport {
    fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.port
            .write_all(bytes)
            .map_err(|e| on_port(&self.path, e))
    }
    fn recv(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        match self.port.read(buf) {
            // A serial port has no end of stream: zero bytes only means the timeout passed.
            Ok(0) => Ok(0),
            other => timeout_is_empty(other).map_err(|e| on_port(&self.path, e)),
        }
    }
}
