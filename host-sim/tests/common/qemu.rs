//! The QEMU board as the end-to-end tests boot it (`#[path = "common/qemu.rs"] mod qemu;`), and
//! the replayable noise they drive it with.
//!
//! No skipping: a missing ELF or qemu-system-arm fails the test with the fix in the message.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use accomp::table::CalibrationTable;
use accomp_host::device::qemu::QemuOptions;
use accomp_host::device::{firmware_path, Client, Qemu};

/// The firmware ELF `cargo xtask firmware` built, asserted present.
pub fn elf() -> PathBuf {
    let elf = firmware_path(None);
    assert!(
        elf.exists(),
        "firmware ELF missing at {} (cargo xtask firmware)",
        elf.display()
    );
    elf
}

/// Boots the firmware with `opts`.
pub fn boot_with(opts: &QemuOptions) -> (Qemu, Client) {
    Qemu::launch(&elf(), opts).unwrap_or_else(|e| panic!("QEMU end-to-end cannot run: {e}"))
}

/// Boots the firmware on a blank board.
pub fn boot() -> (Qemu, Client) {
    boot_with(&QemuOptions::default())
}

/// Boots the firmware on a blank board and loads `table` into it.
pub fn boot_loaded(table: &CalibrationTable) -> (Qemu, Client) {
    let (qemu, mut c) = boot();
    c.load(&table.encode(), |_, _| {}).unwrap();
    (qemu, c)
}

/// Boots the firmware on the board state (flash image) in `state`.
pub fn boot_on(state: &Path) -> (Qemu, Client) {
    boot_with(&QemuOptions {
        state_dir: Some(state.to_path_buf()),
        ..QemuOptions::default()
    })
}

/// (active, previous) table ids the firmware finds when it boots on `state`.
pub fn tables_after_boot(state: &Path) -> (Option<u32>, Option<u32>) {
    let (q, mut c) = boot_on(state);
    let i = c.info().expect("info");
    q.shutdown();
    (i.active_table, i.previous_table)
}

/// Deterministic pseudo-random numbers (xorshift64), so a failure can be replayed.
pub struct Rng(pub u64);

impl Rng {
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }

    /// A uniform number in [0, 1) (the top 53 bits).
    pub fn next(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// The temporary folders (`accomp-qemu-<pid>-*` in `tmp`) of the QEMUs that process `pid`
/// runs. Give that process its own `TMPDIR` (= `tmp`): every `accomp` launch removes the
/// folders of dead processes it finds in its temp dir, so in a shared one a parallel test can
/// remove the folder this test is looking at.
pub fn temp_dirs_of(tmp: &Path, pid: u32) -> Vec<PathBuf> {
    let prefix = format!("{}{pid}-", accomp_host::device::qemu::TEMP_PREFIX);
    std::fs::read_dir(tmp)
        .map(|r| {
            r.flatten()
                .filter(|e| e.file_name().to_string_lossy().starts_with(&prefix))
                .map(|e| e.path())
                .collect()
        })
        .unwrap_or_default()
}
