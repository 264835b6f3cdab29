//! The virtual board's calibration flash: NOR flash in RAM (the core's [`RamFlash`], which
//! refuses what real NOR refuses) mirrored to a file after every erase and program, so a
//! restarted `board-sim` boots with the tables it had — as the board does after a power cut.
//! An erase can be made to stall the board for a while (the STM32F405 stalls its CPU for a
//! sector erase, up to seconds): the time is counted here and lived through by the board.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use accomp::storage::{RamFlash, RamFlashError, SlotLayout, Watched, Watcher};

/// One 1 KiB erase block per slot, three slots (the QEMU board's layout).
const SLOT_BYTES: usize = 1024;
type Ram = RamFlash<{ 3 * SLOT_BYTES }, SLOT_BYTES, 4>;

/// Slot A at 0, B at 1 KiB, C at 2 KiB.
pub const SLOT_LAYOUT: SlotLayout = SlotLayout::consecutive(SLOT_BYTES as u32);

/// Name of the flash image in the state directory.
pub const FLASH_FILE: &str = "flash.bin";

/// The flash, its file, and the erase-stall switch.
pub type BoardFlash = Watched<Ram, BoardImage>;

/// The file the flash is mirrored to, and the erase-stall switch.
pub struct BoardImage {
    file: Option<PathBuf>,
    /// Milliseconds the next erase stalls (0: none); shared with the fault control.
    pub erase_stall_ms: Arc<AtomicU64>,
    /// Total time erases stalled the board, µs: the board's clock goes on by it.
    pub stalled_us: Arc<AtomicU64>,
}

/// The flash stored in `dir` (erased if there is none yet), mirrored back there.
pub fn open(dir: Option<&Path>) -> std::io::Result<BoardFlash> {
    let mut ram = Ram::new();
    let file = dir.map(|d| d.join(FLASH_FILE));
    if let Some(f) = &file {
        match std::fs::read(f) {
            Ok(bytes) if bytes.len() == 3 * SLOT_BYTES => {
                let mut image = [0xFFu8; 3 * SLOT_BYTES];
                image.copy_from_slice(&bytes);
                ram = Ram::from_bytes(image);
            }
            Ok(bytes) => {
                return Err(std::io::Error::other(format!(
                    "{}: {} bytes, a board flash image has {}",
                    f.display(),
                    bytes.len(),
                    3 * SLOT_BYTES
                )))
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(e),
        }
    }
    Ok(Watched {
        flash: ram,
        watcher: BoardImage {
            file,
            erase_stall_ms: Arc::new(AtomicU64::new(0)),
            stalled_us: Arc::new(AtomicU64::new(0)),
        },
    })
}

impl Watcher<Ram> for BoardImage {
    fn before_erase(&mut self, _from: u32, _to: u32) -> Result<(), RamFlashError> {
        let stall = self.erase_stall_ms.swap(0, Ordering::Relaxed);
        if stall > 0 {
            // The CPU is stalled: the board (`VirtualBoard`) lives through it on its own clock
            // before anything else of it runs.
            self.stalled_us.fetch_add(stall * 1000, Ordering::Relaxed);
        }
        Ok(())
    }

    fn changed(&mut self, ram: &Ram, _from: u32, _to: u32) {
        if let Some(f) = &self.file {
            // Written whole and renamed: a kill in the middle leaves the old image.
            let tmp = f.with_extension("tmp");
            if std::fs::write(&tmp, ram.as_bytes()).is_ok() {
                let _ = std::fs::rename(&tmp, f);
            }
        }
    }
}
