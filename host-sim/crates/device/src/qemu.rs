//! Boots the firmware ELF in `qemu-system-arm -machine netduinoplus2` and connects to its UART.
//!
//! QEMU's stderr and the firmware's semihosting output (defmt frames, binary) go to files in a
//! log directory; any failure to boot is reported with both, and with QEMU's exit status (the
//! firmware exits with 101 on panic, 102 on HardFault, 103/104 on start-up failures).
//!
//! The emulated board's flash lives in `accomp-flash.bin` in QEMU's working directory (the
//! firmware reads and writes it by semihosting): [`QemuOptions::state_dir`]. The CLI uses a
//! persistent directory ([`board_state_dir`]), so `accomp load` then `accomp table get` see the
//! same board; tests use a fresh temporary one. A temporary log/state directory is removed when
//! the [`Qemu`] is dropped, and on SIGINT/SIGTERM every running QEMU is killed and its
//! temporary directory removed ([`install_signal_cleanup`]).

use std::fs::{self, File};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use super::client::Client;
use super::transport::TcpTransport;

/// How QEMU is started.
#[derive(Debug, Clone)]
pub struct QemuOptions {
    /// Time allowed from spawn to READY.
    pub ready_timeout: Duration,
    /// `-icount shift=N` for deterministic virtual time (benchmarks), None for real time.
    pub icount_shift: Option<u32>,
    /// Directory for `qemu-stderr.txt` and `semihosting.bin`; a fresh temp dir when None
    /// (removed when the QEMU is dropped, unless `ACCOMP_KEEP_QEMU_LOGS` is set).
    pub log_dir: Option<PathBuf>,
    /// QEMU's working directory, where the board keeps `accomp-flash.bin`: the board's state
    /// across runs. None: the log directory (a fresh board, forgotten with it).
    pub state_dir: Option<PathBuf>,
}

impl Default for QemuOptions {
    fn default() -> Self {
        QemuOptions {
            ready_timeout: Duration::from_secs(20),
            icount_shift: None,
            log_dir: None,
            state_dir: None,
        }
    }
}

/// Why QEMU could not be used; the message carries QEMU's stderr and the firmware log.
#[derive(Debug, thiserror::Error)]
pub enum QemuError {
    /// The ELF is not there.
    #[error("firmware ELF {0} not found: build it with `cargo xtask firmware` (or set ACCOMP_FIRMWARE_ELF / --firmware)")]
    NoFirmware(PathBuf),
    /// qemu-system-arm could not be started.
    #[error(
        "cannot start qemu-system-arm ({0}); install it with: apt-get install qemu-system-arm"
    )]
    Spawn(std::io::Error),
    /// Something failed after QEMU started.
    #[error("{0}")]
    Failed(Box<QemuFailure>),
}

/// The report of a QEMU run that went wrong.
#[derive(Debug, thiserror::Error)]
#[error("{what}\n--- qemu exit: {exit}\n--- qemu stderr ({stderr_path}):\n{stderr}\n--- firmware log ({log_path}): {log}")]
pub struct QemuFailure {
    /// What went wrong.
    what: String,
    /// QEMU's exit status, or "still running".
    exit: String,
    /// QEMU's stderr.
    stderr: String,
    /// Where it is kept.
    stderr_path: String,
    /// The firmware's semihosting output, decoded when defmt-print is available.
    log: String,
    /// Where it is kept.
    log_path: String,
}

/// A running QEMU; killed and reaped on drop.
pub struct Qemu {
    child: Child,
    /// Directory with QEMU's stderr and the firmware's semihosting output.
    pub log_dir: PathBuf,
    /// Whether `log_dir` was created for this run (then it is removed on drop).
    temporary_log_dir: bool,
    elf: PathBuf,
}

/// Name of the board's flash image in its state directory (read by the firmware).
pub const FLASH_IMAGE: &str = "accomp-flash.bin";
/// Environment variable naming the CLI's persistent board state directory.
pub const STATE_ENV: &str = "ACCOMP_QEMU_STATE";

/// The persistent state directory of the emulated board used by the CLI:
/// `$ACCOMP_QEMU_STATE`, else `$XDG_STATE_HOME/accomp/qemu-board`, else
/// `~/.local/state/accomp/qemu-board`, else a directory in the system temp dir.
pub fn board_state_dir() -> PathBuf {
    if let Some(d) = std::env::var_os(STATE_ENV) {
        return PathBuf::from(d);
    }
    let base = std::env::var_os("XDG_STATE_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".local/state")))
        .unwrap_or_else(std::env::temp_dir);
    base.join("accomp").join("qemu-board")
}

/// QEMUs running in this process (pid, temporary directory to remove), for the signal handler.
static RUNNING: std::sync::Mutex<Vec<(u32, Option<PathBuf>)>> = std::sync::Mutex::new(Vec::new());

/// Installs (once) a SIGINT/SIGTERM handler that kills every QEMU this process started, removes
/// their temporary directories and exits with 130. Called by every launch; the CLI's commands
/// all go through it.
pub fn install_signal_cleanup() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let _ = ctrlc::set_handler(cleanup_running);
    });
}

/// Kills the registered QEMUs and removes their temporary directories. Holds the registry's
/// lock throughout and exits with it: a [`Qemu`] being stopped meanwhile (its connection just
/// broke) either finished its own clean-up before (`Qemu::stop` holds the lock too) or waits
/// for the lock until the process ends.
fn cleanup_running() {
    let mut list = match RUNNING.lock() {
        Ok(l) => l,
        Err(p) => p.into_inner(),
    };
    for (pid, dir) in list.drain(..) {
        // SIGKILL: the guest has nothing to flush (the flash file is written through).
        let _ = Command::new("kill").arg("-9").arg(pid.to_string()).status();
        wait_gone(pid);
        if let Some(d) = dir {
            let _ = fs::remove_dir_all(d);
        }
    }
    eprintln!("\ninterrupted: QEMU stopped");
    // Exit with the lock held, so no `Qemu::stop` starts a clean-up the exit would cut short.
    std::process::exit(130);
}

/// Waits (briefly) until process `pid` is gone, so its files can be removed.
fn wait_gone(pid: u32) {
    let proc_dir = PathBuf::from(format!("/proc/{pid}"));
    for _ in 0..50 {
        match fs::read_to_string(proc_dir.join("stat")) {
            // Gone, or a zombie (state Z) that holds no files any more.
            Err(_) => return,
            Ok(s)
                if s.rsplit(')')
                    .next()
                    .is_some_and(|r| r.trim_start().starts_with('Z')) =>
            {
                return
            }
            Ok(_) => std::thread::sleep(Duration::from_millis(10)),
        }
    }
}

fn register(pid: u32, dir: Option<PathBuf>) {
    if let Ok(mut l) = RUNNING.lock() {
        l.push((pid, dir));
    }
}

/// Connections tried before giving up on READY (see `Qemu::launch`).
const CONNECT_ATTEMPTS: u32 = 3;

/// Whether a local TCP connection ended up connected to itself (same address on both ends).
fn is_self_connection(s: &TcpStream) -> bool {
    matches!((s.local_addr(), s.peer_addr()), (Ok(a), Ok(b)) if a == b)
}

fn free_port() -> std::io::Result<u16> {
    // The OS picks a free port; QEMU binds it right after we release it.
    Ok(TcpListener::bind("127.0.0.1:0")?.local_addr()?.port())
}

impl Qemu {
    /// Boots `elf`, connects to its UART and waits for READY.
    pub fn launch(elf: &Path, opts: &QemuOptions) -> Result<(Qemu, Client), QemuError> {
        if !elf.is_file() {
            return Err(QemuError::NoFirmware(elf.to_path_buf()));
        }
        install_signal_cleanup();
        let temporary_log_dir = opts.log_dir.is_none();
        let log_dir = match &opts.log_dir {
            Some(d) => d.clone(),
            None => std::env::temp_dir().join(format!(
                "accomp-qemu-{}-{:016x}",
                std::process::id(),
                rand_suffix()
            )),
        };
        let io_err = |e: std::io::Error| QemuError::Spawn(e);
        fs::create_dir_all(&log_dir).map_err(io_err)?;
        let state_dir = opts.state_dir.clone().unwrap_or_else(|| log_dir.clone());
        fs::create_dir_all(&state_dir).map_err(io_err)?;
        // Absolute: QEMU runs in the state directory.
        let elf = &fs::canonicalize(elf).unwrap_or_else(|_| elf.to_path_buf());
        let stdout = File::create(log_dir.join("semihosting.bin")).map_err(io_err)?;
        let stderr = File::create(log_dir.join("qemu-stderr.txt")).map_err(io_err)?;
        let port = free_port().map_err(io_err)?;
        let mut cmd = Command::new("qemu-system-arm");
        cmd.args([
            "-machine",
            "netduinoplus2",
            "-display",
            "none",
            "-monitor",
            "none",
        ])
        .arg("-serial")
        .arg(format!("tcp:127.0.0.1:{port},server=on,wait=on,nodelay=on"))
        .args(["-semihosting-config", "enable=on,target=native"]);
        if let Some(shift) = opts.icount_shift {
            cmd.arg("-icount").arg(format!("shift={shift}"));
        }
        cmd.arg("-kernel")
            .arg(elf)
            .current_dir(&state_dir)
            .stdin(Stdio::null())
            .stdout(stdout)
            .stderr(stderr);
        let child = cmd.spawn().map_err(QemuError::Spawn)?;
        register(child.id(), temporary_log_dir.then(|| log_dir.clone()));
        let mut qemu = Qemu {
            child,
            log_dir,
            temporary_log_dir,
            elf: elf.to_path_buf(),
        };
        let deadline = Instant::now() + opts.ready_timeout;
        // A connection can fail after it is made: connecting in a loop to a local port nobody
        // listens on yet can, on Linux, connect the socket to itself (source port = the
        // destination, both in the ephemeral range), and under load a first connection has been
        // reset before READY (CI, 2026-11-21) while QEMU stayed up and kept waiting. QEMU's
        // server socket takes a new client after a disconnect, so such a connection is dropped
        // and the next one tried, as long as QEMU runs and time is left.
        let mut attempt = 0u32;
        let client = loop {
            attempt += 1;
            let stream = loop {
                match TcpStream::connect(("127.0.0.1", port)) {
                    Ok(s) if is_self_connection(&s) => {
                        drop(s);
                        std::thread::sleep(Duration::from_millis(20));
                    }
                    Ok(s) => break s,
                    Err(e) => {
                        if qemu.exited().is_some() || Instant::now() >= deadline {
                            return Err(qemu.failure(format!("cannot connect to QEMU's UART: {e}")));
                        }
                        std::thread::sleep(Duration::from_millis(20));
                    }
                }
            };
            let transport = match TcpTransport::new(stream) {
                Ok(t) => t,
                Err(e) => return Err(qemu.failure(format!("socket set-up: {e}"))),
            };
            let mut client = Client::new(Box::new(transport));
            let left = deadline.saturating_duration_since(Instant::now());
            // On a later connection the guest may have booted already and sent READY down the
            // dropped one: then a ping answered proves the link instead.
            let ready = if attempt == 1 {
                client.wait_ready(left)
            } else {
                client
                    .wait_ready(left.min(Duration::from_secs(3)))
                    .or_else(|_| client.ping())
            };
            match ready {
                Ok(()) => break client,
                Err(e) => {
                    let give_up = attempt >= CONNECT_ATTEMPTS
                        || qemu.exited().is_some()
                        || Instant::now() >= deadline;
                    if give_up {
                        return Err(qemu.failure(format!(
                            "no READY from the firmware (connection {attempt}): {e}"
                        )));
                    }
                }
            }
        };
        Ok((qemu, client))
    }

    fn exited(&mut self) -> Option<std::process::ExitStatus> {
        self.child.try_wait().ok().flatten()
    }

    /// QEMU's exit status if it has stopped (the firmware's semihosting exit code).
    pub fn exit_status(&mut self) -> Option<i32> {
        self.exited().and_then(|s| s.code())
    }

    /// Builds the error report: what failed, exit status, stderr, firmware log.
    pub fn failure(&mut self, what: String) -> QemuError {
        // Give a dying QEMU a moment so its exit status and last words are in.
        std::thread::sleep(Duration::from_millis(100));
        let exit = match self.exited() {
            Some(s) => s.to_string(),
            None => "still running".into(),
        };
        let stderr_path = self.log_dir.join("qemu-stderr.txt");
        let log_path = self.log_dir.join("semihosting.bin");
        QemuError::Failed(Box::new(QemuFailure {
            what,
            exit,
            stderr: fs::read_to_string(&stderr_path).unwrap_or_default(),
            stderr_path: stderr_path.display().to_string(),
            log: self.firmware_log(),
            log_path: log_path.display().to_string(),
        }))
    }

    /// The firmware's defmt log: decoded with `defmt-print` when it is installed, otherwise
    /// its size and how to decode it.
    pub fn firmware_log(&self) -> String {
        let path = self.log_dir.join("semihosting.bin");
        let raw = fs::read(&path).unwrap_or_default();
        if raw.is_empty() {
            return "(empty)".into();
        }
        // defmt-print 1.2 reads the frames from stdin (its subcommands are stdin, tcp, serial).
        let decoded = File::open(&path).and_then(|frames| {
            Command::new("defmt-print")
                .arg("-e")
                .arg(&self.elf)
                .arg("stdin")
                .stdin(frames)
                .output()
        });
        match decoded {
            Ok(o) if o.status.success() => String::from_utf8_lossy(&o.stdout).into_owned(),
            _ => format!(
                "{} bytes of defmt frames; decode with `defmt-print -e {} < {}`",
                raw.len(),
                self.elf.display(),
                path.display()
            ),
        }
    }

    /// Stops QEMU and reaps it.
    pub fn shutdown(mut self) -> Option<i32> {
        self.stop()
    }

    /// Waits up to `timeout` for QEMU to exit by itself (the firmware's semihosting exit) and
    /// returns its exit code.
    pub fn wait_exit(&mut self, timeout: Duration) -> Option<i32> {
        let deadline = Instant::now() + timeout;
        while Instant::now() < deadline {
            if let Some(s) = self.exited() {
                return s.code();
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        None
    }

    /// Kills QEMU, reaps it and removes its temporary directory, all under the registry lock,
    /// and only then unregisters it. The SIGINT/SIGTERM handler takes the same lock: it either
    /// finds this QEMU still registered and stops it itself, or waits until this is done. (When
    /// the entry was dropped first and the folder removed after, a signal whose handler ran in
    /// between exited the process with the folder still there: the signal itself interrupts the
    /// UART read, so the main thread drops its `Qemu` just as the handler runs.)
    fn stop(&mut self) -> Option<i32> {
        let mut list = match RUNNING.lock() {
            Ok(l) => l,
            Err(p) => p.into_inner(),
        };
        let code = match self.exited() {
            Some(s) => s.code(),
            None => {
                // The guest has nothing to flush (the flash file is written through): killing
                // the emulator is a clean stop, and exactly a power cut.
                let _ = self.child.kill();
                self.child.wait().ok().and_then(|s| s.code())
            }
        };
        if self.temporary_log_dir && std::env::var_os("ACCOMP_KEEP_QEMU_LOGS").is_none() {
            let _ = fs::remove_dir_all(&self.log_dir);
        }
        let pid = self.child.id();
        list.retain(|(p, _)| *p != pid);
        code
    }
}

/// A per-launch random number (std's randomly keyed hasher), so parallel tests do not share logs.
fn rand_suffix() -> u64 {
    use std::hash::{BuildHasher, Hasher};
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    h.write_u32(std::process::id());
    h.finish()
}

impl Drop for Qemu {
    fn drop(&mut self) {
        self.stop();
    }
}
