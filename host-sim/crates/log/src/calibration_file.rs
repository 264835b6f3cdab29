//! Calibration table files on the PC: read and decode with the validator the board runs, the
//! error naming the file. Shared by `accomp table …` and the device commands (which must not
//! import each other).

use accomp::table::{CalibrationTable, TableError, ENCODED_LEN};
use anyhow::{Context, Result};
use std::path::Path;

/// Reads and decodes a table file; the error names the file and the validator's verdict.
pub fn read_table(path: &Path) -> Result<CalibrationTable> {
    let bytes = read_table_bytes(path)?;
    decode_named(&bytes).with_context(|| format!("{} is refused", path.display()))
}

/// Reads a table file's bytes, never more than one byte beyond a table's size (issue #15.5:
/// `/dev/zero` or a multi-GB file given by mistake is refused after 427 bytes, not read into
/// memory). A file of the wrong size is refused with both sizes named.
pub fn read_table_bytes(path: &Path) -> Result<Vec<u8>> {
    use std::io::Read as _;
    let file =
        std::fs::File::open(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mut bytes = Vec::with_capacity(ENCODED_LEN + 1);
    file.take(ENCODED_LEN as u64 + 1)
        .read_to_end(&mut bytes)
        .with_context(|| format!("cannot read {}", path.display()))?;
    if bytes.len() > ENCODED_LEN {
        let size = std::fs::metadata(path).ok().filter(|m| m.is_file()).map_or(
            format!("more than {ENCODED_LEN} bytes (read stopped there)"),
            |m| format!("{} bytes", m.len()),
        );
        anyhow::bail!(
            "{} is refused: {size}, a calibration table is exactly {ENCODED_LEN} bytes",
            path.display()
        );
    }
    Ok(bytes)
}

/// `CalibrationTable::decode` with its error turned into an `anyhow` error carrying the name.
pub fn decode_named(bytes: &[u8]) -> Result<CalibrationTable> {
    CalibrationTable::decode(bytes).map_err(|e: TableError| anyhow::anyhow!("{e} ({e:?})"))
}
