//! A test's scratch folder under the system temp dir, `accomp-<name>-<pid>-<n>`: fresh when made,
//! removed when dropped, whether the test passes or fails, so no test run leaves files behind. To
//! look at what a failing test wrote, run it with `ACCOMP_KEEP_TEST_FILES=1`: the folder is then
//! kept and its path printed. Used by the CLI tests (`#[path = "common/scratch.rs"] mod scratch;`) and by
//! the plot module's unit tests (through a `#[path]` from `src/plot/tests.rs`).
#![allow(dead_code)]

use std::ops::Deref;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// Set (to anything) to keep the scratch folders instead of removing them.
pub const KEEP_ENV: &str = "ACCOMP_KEEP_TEST_FILES";

/// One test's folder; dereferences to its path; removed on drop (also when the test panics).
#[derive(Debug)]
pub struct Scratch {
    dir: PathBuf,
}

impl Scratch {
    /// A fresh, empty folder for the test `name` (unique per process and per call).
    pub fn new(name: &str) -> Self {
        static NEXT: AtomicUsize = AtomicUsize::new(0);
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let dir = std::env::temp_dir().join(format!("accomp-{name}-{}-{n}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir)
            .unwrap_or_else(|e| panic!("cannot create {}: {e}", dir.display()));
        Scratch { dir }
    }

    /// A fresh folder with a 64 KiB tmpfs mounted on it, for the tests of a full disk (needs
    /// root: the test fails, never skips, without it). Unmount with [`Scratch::unmount`].
    pub fn tmpfs_64k(name: &str) -> Self {
        let s = Scratch::new(name);
        let mounted = std::process::Command::new("mount")
            .args(["-t", "tmpfs", "-o", "size=64k", "tmpfs"])
            .arg(&s.dir)
            .status();
        assert!(
            mounted.is_ok_and(|st| st.success()),
            "mounting a tmpfs is needed for this test (root)"
        );
        s
    }

    /// Unmounts what [`Scratch::tmpfs_64k`] mounted.
    pub fn unmount(&self) {
        let _ = std::process::Command::new("umount").arg(&self.dir).status();
    }

    /// A file name inside the folder.
    pub fn path(&self, file: &str) -> PathBuf {
        self.dir.join(file)
    }
}

impl Deref for Scratch {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.dir
    }
}

impl AsRef<std::ffi::OsStr> for Scratch {
    fn as_ref(&self) -> &std::ffi::OsStr {
        self.dir.as_os_str()
    }
}

impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        &self.dir
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        if std::env::var_os(KEEP_ENV).is_some() {
            eprintln!(
                "{KEEP_ENV} is set: the test's files are kept in {}",
                self.dir.display()
            );
        } else {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}
