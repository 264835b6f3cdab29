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
    /// A flash image put in QEMU's working directory before it boots (a working copy of a
    /// [`BoardState`]'s image); None: whatever is there (nothing: a factory-new board).
    pub initial_flash: Option<Vec<u8>>,
}

impl Default for QemuOptions {
    fn default() -> Self {
        QemuOptions {
            ready_timeout: Duration::from_secs(20),
            icount_shift: None,
            log_dir: None,
            state_dir: None,
            initial_flash: None,
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
    /// A file or folder QEMU needs could not be made: named, with the system's reason (not
    /// the emulator's fault: a state path under a regular file, a full or read-only disk).
    #[error("{what} {}: {source}", path.display())]
    Io {
        /// What the path is for.
        what: &'static str,
        /// The path.
        path: PathBuf,
        /// The system's reason.
        source: std::io::Error,
    },
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
    /// QEMU's working directory, holding the board's flash image.
    state_dir: PathBuf,
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

/// The listening socket of QEMU's UART, made here and handed to QEMU (`-chardev socket,fd=N`):
/// the port is this launch's from the moment the OS picks it until QEMU exits, so the host's
/// connection can only reach this QEMU. (A port picked by binding port 0 and released for QEMU
/// to bind can be picked again in between by another launch's bind — the OS chooses among the
/// free odd ports of one half of the ephemeral range, a few thousand — and then one QEMU fails
/// to bind while both hosts connect to the other: one of them gets the wrong board, the other a
/// connection that is never accepted, and its QEMU waits for a client that never comes.)
fn uart_listener() -> std::io::Result<TcpListener> {
    TcpListener::bind("127.0.0.1:0")
}

/// Lets the child inherit descriptor `fd` across exec (Rust opens every descriptor
/// close-on-exec, so no other child of this process gets it).
fn inherit_fd(cmd: &mut Command, fd: std::os::fd::RawFd) {
    use std::os::unix::process::CommandExt as _;
    // SAFETY: fcntl is async-signal-safe and touches no memory of ours; `fd` is open in the
    // child (a copy of the parent's descriptor table, the listener alive until after spawn).
    unsafe {
        cmd.pre_exec(move || {
            if libc::fcntl(fd, libc::F_SETFD, 0) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
}

impl Qemu {
    /// Boots `elf`, connects to its UART and waits for READY.
    pub fn launch(elf: &Path, opts: &QemuOptions) -> Result<(Qemu, Client), QemuError> {
        if !elf.is_file() {
            return Err(QemuError::NoFirmware(elf.to_path_buf()));
        }
        install_signal_cleanup();
        reclaim_orphaned_dirs();
        let temporary_log_dir = opts.log_dir.is_none();
        let log_dir = match &opts.log_dir {
            Some(d) => d.clone(),
            None => std::env::temp_dir().join(format!(
                "{TEMP_PREFIX}{}-{:016x}",
                std::process::id(),
                rand_suffix()
            )),
        };
        let io_err = |what: &'static str, path: &Path| {
            let path = path.to_path_buf();
            move |source| QemuError::Io { what, path, source }
        };
        fs::create_dir_all(&log_dir)
            .map_err(io_err("cannot create QEMU's log folder", &log_dir))?;
        // Until a `Qemu` owns the temporary folder (and removes it when dropped), an early
        // return removes it here.
        let mut guard = DirGuard(temporary_log_dir.then(|| log_dir.clone()));
        let state_dir = opts.state_dir.clone().unwrap_or_else(|| log_dir.clone());
        fs::create_dir_all(&state_dir)
            .map_err(io_err("cannot create the board's state folder", &state_dir))?;
        if let Some(image) = &opts.initial_flash {
            let path = state_dir.join(FLASH_IMAGE);
            fs::write(&path, image)
                .map_err(io_err("cannot write the board's flash image", &path))?;
        }
        // Absolute: QEMU runs in the state directory.
        let elf = &fs::canonicalize(elf).unwrap_or_else(|_| elf.to_path_buf());
        let stdout_path = log_dir.join("semihosting.bin");
        let stdout = File::create(&stdout_path)
            .map_err(io_err("cannot create the firmware log", &stdout_path))?;
        let stderr_path = log_dir.join("qemu-stderr.txt");
        let stderr = File::create(&stderr_path)
            .map_err(io_err("cannot create QEMU's stderr file", &stderr_path))?;
        let listener = uart_listener().map_err(QemuError::Spawn)?;
        let port = listener.local_addr().map_err(QemuError::Spawn)?.port();
        let listener_fd = {
            use std::os::fd::AsRawFd as _;
            listener.as_raw_fd()
        };
        let mut cmd = Command::new("qemu-system-arm");
        cmd.args([
            "-machine",
            "netduinoplus2",
            "-display",
            "none",
            "-monitor",
            "none",
        ])
        .arg("-chardev")
        .arg(format!(
            "socket,id=uart,fd={listener_fd},server=on,wait=on,nodelay=on"
        ))
        .args(["-serial", "chardev:uart"])
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
        die_with_parent(&mut cmd);
        inherit_fd(&mut cmd, listener_fd);
        let child = cmd.spawn().map_err(QemuError::Spawn)?;
        // QEMU holds the listener now; this process's copy goes (it never accepts).
        drop(listener);
        register(child.id(), temporary_log_dir.then(|| log_dir.clone()));
        guard.0 = None;
        let mut qemu = Qemu {
            child,
            log_dir,
            state_dir,
            temporary_log_dir,
            elf: elf.to_path_buf(),
        };
        let deadline = Instant::now() + opts.ready_timeout;
        // The port listens already (QEMU's own socket): the connection waits in its backlog
        // until QEMU accepts it, which starts the guest (wait=on). Refused means QEMU is gone.
        let stream = match TcpStream::connect(("127.0.0.1", port)) {
            Ok(s) => s,
            Err(e) => return Err(qemu.failure(format!("cannot connect to QEMU's UART: {e}"))),
        };
        let transport = match TcpTransport::new(stream) {
            Ok(t) => t,
            Err(e) => return Err(qemu.failure(format!("socket set-up: {e}"))),
        };
        let mut client = Client::new(Box::new(transport));
        let left = deadline.saturating_duration_since(Instant::now());
        if let Err(e) = client.wait_ready(left) {
            return Err(qemu.failure(format!("no READY from the firmware: {e}")));
        }
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

    /// Cuts the board's power (kills QEMU, reaps it) and returns its exit code and the flash
    /// image it left in its working directory, read before the temporary folder goes.
    pub fn power_off(mut self) -> (Option<i32>, std::io::Result<Vec<u8>>) {
        let code = match self.exited() {
            Some(s) => s.code(),
            None => {
                let _ = self.child.kill();
                self.child.wait().ok().and_then(|s| s.code())
            }
        };
        let image = fs::read(self.state_dir.join(FLASH_IMAGE));
        self.stop();
        (code, image)
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

/// Name prefix of the temporary folders, `accomp-qemu-<pid>-<random>` in the system temp dir.
pub const TEMP_PREFIX: &str = "accomp-qemu-";

/// Removes a temporary folder when dropped, unless emptied first.
struct DirGuard(Option<PathBuf>);

impl Drop for DirGuard {
    fn drop(&mut self) {
        if let Some(d) = self.0.take() {
            let _ = fs::remove_dir_all(d);
        }
    }
}

/// Whether process `pid` exists (a zombie counts as gone: it holds no files).
fn process_alive(pid: u32) -> bool {
    match fs::read_to_string(format!("/proc/{pid}/stat")) {
        Err(_) => false,
        Ok(s) => !s
            .rsplit(')')
            .next()
            .is_some_and(|r| r.trim_start().starts_with('Z')),
    }
}

/// Removes the temporary folders left by `accomp` processes that no longer exist (killed with
/// SIGKILL, which no handler sees): their QEMU died with them ([`die_with_parent`]), the folder
/// stays until this next launch. Folders of living processes, this one included, are left.
fn reclaim_orphaned_dirs() {
    let Ok(entries) = fs::read_dir(std::env::temp_dir()) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name();
        let Some(rest) = name.to_str().and_then(|n| n.strip_prefix(TEMP_PREFIX)) else {
            continue;
        };
        let Some(pid) = rest.split('-').next().and_then(|p| p.parse::<u32>().ok()) else {
            continue;
        };
        if pid != std::process::id() && !process_alive(pid) {
            let _ = fs::remove_dir_all(e.path());
        }
    }
}

/// Makes the kernel kill the child when the thread that spawned it ends (the `accomp` process
/// killed with SIGKILL included, which leaves no chance for a handler): `PR_SET_PDEATHSIG`,
/// set between fork and exec. If the parent died before that, the child exits at once.
/// (The signal follows the spawning *thread*: a [`Qemu`] is used and dropped on the thread that
/// launched it.)
fn die_with_parent(cmd: &mut Command) {
    use std::os::unix::process::CommandExt as _;
    // SAFETY: getpid/prctl/getppid/_exit are async-signal-safe and touch no memory of ours.
    let parent = unsafe { libc::getpid() };
    unsafe {
        cmd.pre_exec(move || {
            if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL as libc::c_ulong) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            if libc::getppid() != parent {
                libc::_exit(1);
            }
            Ok(())
        });
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

/// Bytes of the QEMU board's flash image: three 1 KiB slots (`src/bsp/qemu.rs`,
/// `RamCalibrationFlash`).
pub const FLASH_IMAGE_LEN: usize = 3 * 1024;
/// The lock file beside the flash image: held (flock, exclusive) by the one command using the
/// board, and holding that command's pid for the others' message.
pub const LOCK_FILE: &str = "accomp-board.lock";

/// How a command takes the board state.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StateOptions {
    /// Refuse at once when another command holds the board, instead of waiting for it.
    pub no_wait: bool,
    /// Move a damaged flash image aside (renamed with a time stamp) and start with a blank
    /// board, instead of refusing it.
    pub reset_state: bool,
}

/// Why the board state cannot be used; every message names the path.
#[derive(Debug, thiserror::Error)]
pub enum StateError {
    /// The folder or a file in it could not be made, written or read.
    #[error("board state {}: {what}: {source}", path.display())]
    Io {
        /// What was being done.
        what: String,
        /// The path.
        path: PathBuf,
        /// The system's reason.
        source: std::io::Error,
    },
    /// Another command holds the board and `--no-wait` was given.
    #[error("board state {} in use by {holder} (--no-wait given)", dir.display())]
    Busy {
        /// The state folder.
        dir: PathBuf,
        /// "pid N", or "another process".
        holder: String,
    },
    /// The flash image is not a flash image of this board.
    #[error(
        "board state {}: flash image is {size} bytes, expected {expected}: refused, nothing \
         sent or overwritten (--reset-state moves it aside and starts a blank board)",
        path.display()
    )]
    Damaged {
        /// The image.
        path: PathBuf,
        /// Its size.
        size: u64,
        /// [`FLASH_IMAGE_LEN`].
        expected: usize,
    },
    /// What was written is not what reads back.
    #[error("board state {}: {what}", path.display())]
    NotPersisted {
        /// The image.
        path: PathBuf,
        /// What differs.
        what: String,
    },
}

/// The persistent board state, locked for this process until dropped: the flash image
/// `accomp-flash.bin` in a folder ([`board_state_dir`]), and the lock file beside it.
///
/// QEMU never writes the image in place: it runs on a working copy in its temporary folder
/// ([`QemuOptions::initial_flash`]), and [`BoardState::persist`] puts what the board left there
/// back by writing a temporary file in the state folder, syncing it, renaming it over the image
/// and reading it back. So a command killed at any moment leaves the old or the new image, and
/// a folder where the image cannot be persisted is found before anything is sent.
#[derive(Debug)]
pub struct BoardState {
    dir: PathBuf,
    /// Open with an exclusive flock for as long as this lives (released by the kernel when the
    /// process dies, however it dies; close-on-exec, so QEMU never holds it).
    _lock: File,
}

/// The options the command line chose for this process ([`StateOptions::set_for_process`]).
static PROCESS_STATE_OPTIONS: std::sync::OnceLock<StateOptions> = std::sync::OnceLock::new();

impl StateOptions {
    /// Sets the options every [`super::Connection::open`] of this process uses (the CLI's
    /// `--no-wait`, `--reset-state`); the first call wins.
    pub fn set_for_process(self) {
        let _ = PROCESS_STATE_OPTIONS.set(self);
    }

    /// What [`StateOptions::set_for_process`] set, else the defaults (wait, refuse damage).
    pub fn for_process() -> StateOptions {
        PROCESS_STATE_OPTIONS.get().copied().unwrap_or_default()
    }
}

fn state_io(what: impl Into<String>, path: &Path) -> impl FnOnce(std::io::Error) -> StateError {
    let (what, path) = (what.into(), path.to_path_buf());
    move |source| StateError::Io { what, path, source }
}

impl BoardState {
    /// Creates the folder if needed, takes the lock (waiting with a message on stderr, or
    /// refusing with `no_wait`), proves the folder writable with a synced probe file the size
    /// of an image, and checks the image: a file of the wrong size or an unreadable one is
    /// refused (or moved aside with `reset_state`).
    pub fn open(dir: &Path, opts: StateOptions) -> Result<BoardState, StateError> {
        fs::create_dir_all(dir).map_err(state_io("cannot create the folder", dir))?;
        let lock_path = dir.join(LOCK_FILE);
        let mut lock = fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&lock_path)
            .map_err(state_io("cannot open the lock file", &lock_path))?;
        match lock.try_lock() {
            Ok(()) => {}
            Err(fs::TryLockError::WouldBlock) => {
                // The holder writes its pid right after it locks: give it that moment.
                std::thread::sleep(Duration::from_millis(20));
                let holder = fs::read_to_string(&lock_path)
                    .ok()
                    .and_then(|t| t.trim().parse::<u32>().ok())
                    .map_or_else(|| "another process".to_string(), |p| format!("pid {p}"));
                if opts.no_wait {
                    return Err(StateError::Busy {
                        dir: dir.to_path_buf(),
                        holder,
                    });
                }
                eprintln!("board state {} in use by {holder}, waiting…", dir.display());
                lock.lock()
                    .map_err(state_io("cannot lock the lock file", &lock_path))?;
            }
            Err(fs::TryLockError::Error(e)) => {
                return Err(state_io("cannot lock the lock file", &lock_path)(e))
            }
        }
        {
            use std::io::{Seek as _, Write as _};
            let pid = std::process::id();
            let _ = lock
                .set_len(0)
                .and_then(|()| lock.seek(std::io::SeekFrom::Start(0)))
                .and_then(|_| writeln!(lock, "{pid}"));
        }
        let state = BoardState {
            dir: dir.to_path_buf(),
            _lock: lock,
        };
        // Left by a command killed while persisting (it held the lock, which is ours now).
        if let Ok(entries) = fs::read_dir(dir) {
            for e in entries.flatten() {
                if e.file_name()
                    .to_string_lossy()
                    .starts_with(TEMP_IMAGE_PREFIX)
                {
                    let _ = fs::remove_file(e.path());
                }
            }
        }
        // A read-only, immutable or full folder fails here, before QEMU boots: as much as an
        // image, synced.
        let probe = dir.join(format!("{TEMP_IMAGE_PREFIX}probe-{}", std::process::id()));
        let probed = write_synced(&probe, &[0xFF; FLASH_IMAGE_LEN]);
        let _ = fs::remove_file(&probe);
        probed.map_err(state_io(
            "cannot write there (read-only, immutable or full?): nothing sent",
            &probe,
        ))?;
        state.check_image(opts.reset_state)?;
        Ok(state)
    }

    /// The state folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The flash image's path.
    pub fn image_path(&self) -> PathBuf {
        self.dir.join(FLASH_IMAGE)
    }

    fn check_image(&self, reset: bool) -> Result<(), StateError> {
        let path = self.image_path();
        let size = match fs::metadata(&path) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
            Err(e) => return Err(state_io("cannot read the flash image", &path)(e)),
            Ok(m) if !m.is_file() => {
                return Err(StateError::Io {
                    what: "the flash image is not a regular file".into(),
                    path,
                    source: std::io::Error::other("not a file"),
                })
            }
            Ok(m) => m.len(),
        };
        let readable = fs::File::open(&path).map(|_| ());
        let damaged = size != FLASH_IMAGE_LEN as u64 || readable.is_err();
        if !damaged {
            return Ok(());
        }
        if !reset {
            return match readable {
                Err(e) => Err(state_io("cannot read the flash image", &path)(e)),
                Ok(()) => Err(StateError::Damaged {
                    path,
                    size,
                    expected: FLASH_IMAGE_LEN,
                }),
            };
        }
        let stamp = jiff::Timestamp::now()
            .strftime("%Y%m%dT%H%M%SZ")
            .to_string();
        let aside = self.dir.join(format!("{FLASH_IMAGE}.damaged-{stamp}"));
        fs::rename(&path, &aside).map_err(state_io("cannot move the flash image aside", &path))?;
        eprintln!(
            "board state: damaged flash image ({size} bytes, expected {FLASH_IMAGE_LEN}) moved \
             to {}; the board starts blank",
            aside.display()
        );
        Ok(())
    }

    /// The image on disk, None when there is none yet (a factory-new board).
    pub fn image(&self) -> Result<Option<Vec<u8>>, StateError> {
        let path = self.image_path();
        match fs::read(&path) {
            Ok(b) => Ok(Some(b)),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(state_io("cannot read the flash image", &path)(e)),
        }
    }

    /// Persists `image`: a temporary file in the state folder, synced, renamed over the image,
    /// the folder synced, then the image read back and compared. Returns what was read back.
    pub fn persist(&self, image: &[u8]) -> Result<Vec<u8>, StateError> {
        let path = self.image_path();
        if image.len() != FLASH_IMAGE_LEN {
            return Err(StateError::NotPersisted {
                path,
                what: format!(
                    "the board left an image of {} bytes, expected {FLASH_IMAGE_LEN}: not written",
                    image.len()
                ),
            });
        }
        let tmp = self
            .dir
            .join(format!("{TEMP_IMAGE_PREFIX}{}", std::process::id()));
        if let Err(e) = write_synced(&tmp, image) {
            let _ = fs::remove_file(&tmp);
            return Err(state_io("cannot write the new flash image", &tmp)(e));
        }
        if let Err(e) = fs::rename(&tmp, &path) {
            let _ = fs::remove_file(&tmp);
            return Err(state_io(
                "cannot rename the new flash image into place",
                &path,
            )(e));
        }
        File::open(&self.dir)
            .and_then(|d| d.sync_all())
            .map_err(state_io("cannot sync the folder", &self.dir))?;
        let back = fs::read(&path).map_err(state_io("cannot read the image back", &path))?;
        if back != image {
            return Err(StateError::NotPersisted {
                path,
                what: "the image read back differs from the one written".into(),
            });
        }
        Ok(back)
    }
}

/// Name prefix of the temporary files in the state folder.
const TEMP_IMAGE_PREFIX: &str = ".accomp-flash.tmp-";

/// Writes `bytes` to a new file at `path` and syncs it to the disk.
fn write_synced(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    use std::io::Write as _;
    let mut f = File::create(path)?;
    f.write_all(bytes)?;
    f.sync_all()
}

/// The (active, previous) table ids a flash image holds, as the firmware's boot scan would
/// find them (the core's own [`accomp::storage::CalibrationStore`] on the image's bytes).
pub fn image_tables(image: &[u8]) -> Option<(Option<u32>, Option<u32>)> {
    use accomp::storage::{CalibrationStore, RamFlash, SlotLayout};
    let bytes: [u8; FLASH_IMAGE_LEN] = image.try_into().ok()?;
    let flash = RamFlash::<FLASH_IMAGE_LEN, 1024, 4>::from_bytes(bytes);
    let mut store = CalibrationStore::new(flash, SlotLayout::consecutive(1024)).ok()?;
    let v = store.valid_slots().ok()?;
    Some((v.newest.map(|s| s.table_id), v.previous.map(|s| s.table_id)))
}
