//! Output paths checked before the work starts, and writes that fail loudly.
//!
//! A command that computes for minutes must not find out at the end that its `-o` is a
//! directory or its folder read-only: [`check_file`] and [`check_dir`] prove each output
//! writable first (a probe file in the same folder, written, synced and removed). And a write
//! cut short (a full disk) is an error naming the path, never a 0-byte file with exit 0:
//! [`write_file`] syncs what it wrote, so the disk's refusal comes back here.

use std::fs::File;
use std::io::Write as _;
use std::path::{Path, PathBuf};

/// Why an output cannot be written: each names the path, and says whether work was skipped.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// The output is refused before any computing (wrong kind of path, missing folder).
    #[error("{0} (nothing computed)")]
    Refused(String),
    /// The file system refused the output; the context names the path and what was done.
    #[error("{context}: {reason}")]
    Io {
        /// What was being done, naming the path.
        context: String,
        /// The operating system's reason.
        reason: std::io::Error,
    },
}

/// Attaches the path-naming context to an I/O error.
fn io<T>(r: std::io::Result<T>, context: impl FnOnce() -> String) -> Result<T, OutputError> {
    r.map_err(|reason| OutputError::Io {
        context: context(),
        reason,
    })
}

/// The folder a file path lands in ("." for a bare name).
fn parent_of(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// Writes, syncs and removes a probe file in `dir`.
fn probe(dir: &Path) -> std::io::Result<()> {
    let p = dir.join(format!(".accomp-write-probe-{}", std::process::id()));
    let r = File::create(&p).and_then(|mut f| {
        f.write_all(b"probe")?;
        f.sync_all()
    });
    let _ = std::fs::remove_file(&p);
    r
}

/// [`check_file`] of an optional output: nothing to check when there is none.
pub fn check_optional_file(path: Option<&Path>) -> Result<(), OutputError> {
    path.map_or(Ok(()), check_file)
}

/// Checks that `path` can be written as a file: not a directory, its folder exists and takes
/// a file. Creates nothing that stays.
pub fn check_file(path: &Path) -> Result<(), OutputError> {
    if path.is_dir() {
        return Err(OutputError::Refused(format!(
            "output {}: is a directory, a file is expected",
            path.display()
        )));
    }
    let dir = parent_of(path);
    if !dir.is_dir() {
        return Err(OutputError::Refused(format!(
            "output {}: its folder {} does not exist",
            path.display(),
            dir.display()
        )));
    }
    if path.exists() {
        // Opened for writing without truncating: the existing file stays as it is.
        io(std::fs::OpenOptions::new().write(true).open(path), || {
            format!(
                "output {}: cannot be written (nothing computed)",
                path.display()
            )
        })?;
    }
    io(probe(&dir), || {
        format!(
            "output {}: its folder {} cannot be written (nothing computed)",
            path.display(),
            dir.display()
        )
    })
}

/// Checks that `dir` can take the files of an output folder: created if missing, a directory,
/// writable.
pub fn check_dir(dir: &Path) -> Result<(), OutputError> {
    if dir.exists() && !dir.is_dir() {
        return Err(OutputError::Refused(format!(
            "output folder {}: is a file, a directory is expected",
            dir.display()
        )));
    }
    io(std::fs::create_dir_all(dir), || {
        format!(
            "output folder {}: cannot be created (nothing computed)",
            dir.display()
        )
    })?;
    io(probe(dir), || {
        format!(
            "output folder {}: cannot be written (nothing computed)",
            dir.display()
        )
    })
}

/// Writes `bytes` to `path` and syncs it: every failure, a short write on a full disk
/// included, is an error naming the path.
pub fn write_file(path: &Path, bytes: &[u8]) -> Result<(), OutputError> {
    let mut f = io(File::create(path), || {
        format!("cannot create {}", path.display())
    })?;
    io(f.write_all(bytes).and_then(|()| f.sync_all()), || {
        format!("writing {} ({} bytes)", path.display(), bytes.len())
    })
}

/// Flushes a buffered output file and syncs it to the disk, the error naming the path.
pub fn finish(w: std::io::BufWriter<File>, path: &Path) -> Result<(), OutputError> {
    let f = io(w.into_inner().map_err(|e| e.into_error()), || {
        format!("writing {}", path.display())
    })?;
    io(f.sync_all(), || format!("writing {}", path.display()))
}
