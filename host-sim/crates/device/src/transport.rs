//! Byte transports to the device.

use std::io::{self, Read, Write};
use std::net::TcpStream;
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
