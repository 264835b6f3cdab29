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

use anyhow::Context as _;

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
pub fn check_file(path: &Path) -> anyhow::Result<()> {
    if path.is_dir() {
        anyhow::bail!(
            "output {}: is a directory, a file is expected (nothing computed)",
            path.display()
        );
    }
    let dir = parent_of(path);
    if !dir.is_dir() {
        anyhow::bail!(
            "output {}: its folder {} does not exist (nothing computed)",
            path.display(),
            dir.display()
        );
    }
    if path.exists() {
        // Opened for writing without truncating: the existing file stays as it is.
        std::fs::OpenOptions::new()
            .write(true)
            .open(path)
            .with_context(|| {
                format!(
                    "output {}: cannot be written (nothing computed)",
                    path.display()
                )
            })?;
    }
    probe(&dir).with_context(|| {
        format!(
            "output {}: its folder {} cannot be written (nothing computed)",
            path.display(),
            dir.display()
        )
    })
}

/// Checks that `dir` can take the files of an output folder: created if missing, a directory,
/// writable.
pub fn check_dir(dir: &Path) -> anyhow::Result<()> {
    if dir.exists() && !dir.is_dir() {
        anyhow::bail!(
            "output folder {}: is a file, a directory is expected (nothing computed)",
            dir.display()
        );
    }
    std::fs::create_dir_all(dir).with_context(|| {
        format!(
            "output folder {}: cannot be created (nothing computed)",
            dir.display()
        )
    })?;
    probe(dir).with_context(|| {
        format!(
            "output folder {}: cannot be written (nothing computed)",
            dir.display()
        )
    })
}

/// Writes `bytes` to `path` and syncs it: every failure, a short write on a full disk
/// included, is an error naming the path.
pub fn write_file(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    let mut f = File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    f.write_all(bytes)
        .and_then(|()| f.sync_all())
        .with_context(|| format!("writing {} ({} bytes)", path.display(), bytes.len()))
}

/// Flushes a buffered output file and syncs it to the disk, the error naming the path.
pub fn finish(w: std::io::BufWriter<File>, path: &Path) -> anyhow::Result<()> {
    let f = w
        .into_inner()
        .map_err(|e| e.into_error())
        .with_context(|| format!("writing {}", path.display()))?;
    f.sync_all()
        .with_context(|| format!("writing {}", path.display()))
}
