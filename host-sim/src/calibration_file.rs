//! Calibration table files on the PC: read and decode with the validator the board runs, the
//! error naming the file. Shared by `accomp table …` and the device commands (which must not
//! import each other).

use accomp::table::{CalibrationTable, TableError};
use anyhow::{Context, Result};
use std::path::Path;

/// Reads and decodes a table file; the error names the file and the validator's verdict.
pub fn read_table(path: &Path) -> Result<CalibrationTable> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    decode_named(&bytes).with_context(|| format!("{} is refused", path.display()))
}

/// `CalibrationTable::decode` with its error turned into an `anyhow` error carrying the name.
pub fn decode_named(bytes: &[u8]) -> Result<CalibrationTable> {
    CalibrationTable::decode(bytes).map_err(|e: TableError| anyhow::anyhow!("{e} ({e:?})"))
}
