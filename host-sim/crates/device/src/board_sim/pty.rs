//! The virtual board's serial line: the master side of a pseudo-terminal. The slave side is a
//! real tty (`/dev/pts/N`) that any serial program, `accomp` included, opens as it would open
//! `/dev/ttyUSB0`; it is set to raw mode here so nothing is echoed or translated before the
//! first client configures it.

use std::io;
use std::os::fd::{AsRawFd, FromRawFd, IntoRawFd, OwnedFd};
use std::path::{Path, PathBuf};

use serialport::SerialPort as _;

/// The master side, non-blocking.
pub struct Pty {
    master: OwnedFd,
    /// The slave's path.
    pub path: PathBuf,
}

impl Pty {
    /// Opens a new pseudo-terminal pair in raw mode and keeps only the master.
    pub fn open() -> io::Result<Self> {
        let (master, mut slave) = serialport::TTYPort::pair()
            .map_err(|e| io::Error::other(format!("cannot open a pseudo-terminal: {e}")))?;
        let path = slave
            .name()
            .map(PathBuf::from)
            .ok_or_else(|| io::Error::other("pseudo-terminal without a name"))?;
        // `pair` opened the slave exclusively (TIOCEXCL); a client must be able to open it.
        let _ = slave.set_exclusive(false);
        drop(slave);
        // SAFETY: `into_raw_fd` hands over sole ownership of the open descriptor.
        let master = unsafe { OwnedFd::from_raw_fd(master.into_raw_fd()) };
        let fd = master.as_raw_fd();
        // SAFETY: plain fcntl on a descriptor we own.
        unsafe {
            let flags = libc::fcntl(fd, libc::F_GETFL);
            libc::fcntl(fd, libc::F_SETFL, flags | libc::O_NONBLOCK);
        }
        Ok(Pty { master, path })
    }

    /// Reads what the client sent: Ok(0) when nothing came, Err when no client has the port
    /// open (EIO: every descriptor of the slave is closed).
    pub fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        // SAFETY: `buf` is valid for `buf.len()` bytes.
        let n = unsafe { libc::read(self.master.as_raw_fd(), buf.as_mut_ptr().cast(), buf.len()) };
        match usize::try_from(n) {
            Ok(n) => Ok(n),
            Err(_) => match io::Error::last_os_error() {
                e if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted
                ) =>
                {
                    Ok(0)
                }
                e => Err(e),
            },
        }
    }

    /// Writes as much of `bytes` as the line takes now; returns how many bytes went.
    pub fn write(&mut self, bytes: &[u8]) -> usize {
        if bytes.is_empty() {
            return 0;
        }
        // SAFETY: `bytes` is valid for `bytes.len()` bytes.
        let n = unsafe { libc::write(self.master.as_raw_fd(), bytes.as_ptr().cast(), bytes.len()) };
        usize::try_from(n).unwrap_or(0)
    }

    /// Discards what is queued toward the client (what a cable pulled out loses).
    pub fn discard_output(&mut self) {
        // SAFETY: tcflush on a descriptor we own.
        unsafe {
            libc::tcflush(self.master.as_raw_fd(), libc::TCIOFLUSH);
        }
    }
}

/// Makes `link` a symbolic link to `target`, replacing an old link (never a regular file).
pub fn link(target: &Path, link: &Path) -> io::Result<()> {
    match std::fs::symlink_metadata(link) {
        Ok(m) if m.file_type().is_symlink() => std::fs::remove_file(link)?,
        Ok(_) => {
            return Err(io::Error::new(
                io::ErrorKind::AlreadyExists,
                format!("{} exists and is not a link: not replaced", link.display()),
            ))
        }
        Err(_) => {}
    }
    std::os::unix::fs::symlink(target, link)
}
