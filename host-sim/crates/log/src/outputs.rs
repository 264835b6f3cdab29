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

/// Why an output cannot be written; every message names the path and says nothing was computed
/// when the check came first.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// The path is of the wrong kind or its folder is missing.
    #[error("output {}: {what} (nothing computed)", path.display())]
    Unusable {
        /// The output.
        path: PathBuf,
        /// What is wrong with it.
        what: String,
    },
    /// The system refused the probe, the creation or the write.
    #[error("output {}: {what}: {source}", path.display())]
    Io {
        /// The output.
        path: PathBuf,
        /// What was being done.
        what: String,
        /// The system's reason.
        source: std::io::Error,
    },
}

fn io(path: &Path, what: impl Into<String>) -> impl FnOnce(std::io::Error) -> OutputError {
    let (path, what) = (path.to_path_buf(), what.into());
    move |source| OutputError::Io { path, what, source }
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

/// Checks that `path` can be written as a file: not a directory, its folder exists and takes
/// a file. Creates nothing that stays.
pub fn check_file(path: &Path) -> Result<(), OutputError> {
    let unusable = |what: String| OutputError::Unusable {
        path: path.to_path_buf(),
        what,
    };
    if path.is_dir() {
        return Err(unusable("is a directory, a file is expected".into()));
    }
    let dir = parent_of(path);
    if !dir.is_dir() {
        return Err(unusable(format!(
            "its folder {} does not exist",
            dir.display()
        )));
    }
    if path.exists() {
        // Opened for writing without truncating: the existing file stays as it is.
        std::fs::OpenOptions::new()
            .write(true)
            .open(path)
            .map_err(io(path, "cannot be written (nothing computed)"))?;
    }
    probe(&dir).map_err(io(
        path,
        format!(
            "its folder {} cannot be written (nothing computed)",
            dir.display()
        ),
    ))
}

/// Checks that `dir` can take the files of an output folder: created if missing, a directory,
/// writable.
pub fn check_dir(dir: &Path) -> Result<(), OutputError> {
    if dir.exists() && !dir.is_dir() {
        return Err(OutputError::Unusable {
            path: dir.to_path_buf(),
            what: "is a file, a directory is expected".into(),
        });
    }
    std::fs::create_dir_all(dir).map_err(io(dir, "folder cannot be created (nothing computed)"))?;
    probe(dir).map_err(io(dir, "folder cannot be written (nothing computed)"))
}

/// Writes `bytes` to `path` and syncs it: every failure, a short write on a full disk
/// included, is an error naming the path.
pub fn write_file(path: &Path, bytes: &[u8]) -> Result<(), OutputError> {
    let mut f = File::create(path).map_err(io(path, "cannot create"))?;
    f.write_all(bytes)
        .and_then(|()| f.sync_all())
        .map_err(io(path, format!("writing {} bytes", bytes.len())))
}

/// Flushes a buffered output file and syncs it to the disk, the error naming the path.
pub fn finish(w: std::io::BufWriter<File>, path: &Path) -> Result<(), OutputError> {
    let f = w
        .into_inner()
        .map_err(|e| e.into_error())
        .map_err(io(path, "writing"))?;
    f.sync_all().map_err(io(path, "writing"))
}
