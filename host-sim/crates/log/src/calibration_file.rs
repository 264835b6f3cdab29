//! Calibration table files on the PC: read and decode with the validator the board runs, the
//! error naming the file. Shared by `accomp table …` and the device commands (which must not
//! import each other).

use accomp::table::{CalibrationTable, TableError, ENCODED_LEN};
use std::path::Path;

/// Why a calibration table file was not read; each names the file.
#[derive(Debug, thiserror::Error)]
pub enum TableFileError {
    /// The file could not be opened or read.
    #[error("cannot read {path}")]
    Io {
        /// The file.
        path: String,
        /// What the system said.
        #[source]
        source: std::io::Error,
    },
    /// The file is not a table's size.
    #[error("{path} is refused: {size}, a calibration table is exactly {ENCODED_LEN} bytes")]
    Size {
        /// The file.
        path: String,
        /// Its size, as far as it is known.
        size: String,
    },
    /// The validator the board runs refused the contents.
    #[error("{path} is refused")]
    Refused {
        /// The file.
        path: String,
        /// The validator's verdict.
        #[source]
        source: TableRefused,
    },
}

/// The board's validator refused a table (`CalibrationTable::decode`'s error, with its name).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0} ({0:?})")]
pub struct TableRefused(pub TableError);

/// Reads and decodes a table file; the error names the file and the validator's verdict.
pub fn read_table(path: &Path) -> Result<CalibrationTable, TableFileError> {
    let bytes = read_table_bytes(path)?;
    decode_named(&bytes).map_err(|source| TableFileError::Refused {
        path: path.display().to_string(),
        source,
    })
}

/// Reads a table file's bytes, never more than one byte beyond a table's size (issue #15.5:
/// `/dev/zero` or a multi-GB file given by mistake is refused after 427 bytes, not read into
/// memory). A file of the wrong size is refused with both sizes named.
pub fn read_table_bytes(path: &Path) -> Result<Vec<u8>, TableFileError> {
    use std::io::Read as _;
    let io = |source| TableFileError::Io {
        path: path.display().to_string(),
        source,
    };
    let file = std::fs::File::open(path).map_err(io)?;
    let mut bytes = Vec::with_capacity(ENCODED_LEN + 1);
    file.take(ENCODED_LEN as u64 + 1)
        .read_to_end(&mut bytes)
        .map_err(io)?;
    if bytes.len() > ENCODED_LEN {
        let size = std::fs::metadata(path).ok().filter(|m| m.is_file()).map_or(
            format!("more than {ENCODED_LEN} bytes (read stopped there)"),
            |m| format!("{} bytes", m.len()),
        );
        return Err(TableFileError::Size {
            path: path.display().to_string(),
            size,
        });
    }
    Ok(bytes)
}

/// `CalibrationTable::decode` with its error carrying the variant's name.
pub fn decode_named(bytes: &[u8]) -> Result<CalibrationTable, TableRefused> {
    CalibrationTable::decode(bytes).map_err(TableRefused)
}
