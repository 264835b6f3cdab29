//! Reading a tumble log (through the project's CSV reader) into rows and metadata.

use super::*;
use crate::log::reader::{ReadError, Records};

/// One data row.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    /// 1-based line in the file.
    pub line: usize,
    /// Nominal dividing-head angle (°).
    pub angle_deg: f64,
    /// Accelerometer output (V).
    pub output_v: f64,
    /// Operating temperature (°C), when logged.
    pub temperature_c: Option<f64>,
    /// Seconds since start, when logged.
    pub time_s: Option<f64>,
    /// Test id, when logged.
    pub test: Option<String>,
}

/// A parsed tumble log.
#[derive(Debug, Clone, PartialEq)]
pub struct TumbleLog {
    /// `# key: value` metadata in file order.
    pub metadata: Vec<(String, String)>,
    /// Data rows in file order.
    pub rows: Vec<Row>,
}

impl TumbleLog {
    /// The value of a metadata key (keys are unique: the reader refuses a repeated one).
    pub fn meta(&self, key: &str) -> Option<&str> {
        self.metadata
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }
}

/// A reading of a tumble log: the reader's rule for numbers (`log::reader::parse_number`), a
/// value required.
pub(super) fn parse_number(line: usize, column: &str, cell: &str) -> Result<f64, TumbleError> {
    use crate::log::reader::{parse_required_number, NumberError};
    parse_required_number(cell.trim().as_bytes()).map_err(|e| match e {
        NumberError::NotANumber => TumbleError::Malformed {
            line,
            reason: format!("`{column}` = {:?} is not a number", cell.trim()),
        },
        NumberError::Infinite | NumberError::Missing => TumbleError::NonFinite {
            line,
            column: column.to_string(),
        },
    })
}

impl From<ReadError> for TumbleError {
    fn from(e: ReadError) -> Self {
        match e {
            ReadError::NoHeader => TumbleError::NoHeader,
            other => TumbleError::Malformed {
                line: other.line().unwrap_or(0),
                reason: other.what(),
            },
        }
    }
}

/// Reads a tumble log through the project's CSV reader (`log::reader`: `# key: value` lines,
/// one header row, then comma-separated rows). Required columns `angle_deg`, `output_v`;
/// optional `temperature_c`, `time_s`, `test`; other columns are ignored.
pub fn parse_log(text: &str) -> Result<TumbleLog, TumbleError> {
    let mut records = Records::from_text(text)?;
    let find = |n: &'static str| records.column(n).ok_or(TumbleError::MissingColumn(n));
    let (ia, io) = (find("angle_deg")?, find("output_v")?);
    let (it, its, itest) = (
        records.column("temperature_c"),
        records.column("time_s"),
        records.column("test"),
    );
    let metadata = records.take_meta();
    let mut rows = Vec::new();
    while let Some(row) = records.next_row()? {
        let line = row.line;
        let cell = |j: usize| row.text(j);
        let opt = |j: Option<usize>, name: &str| -> Result<Option<f64>, TumbleError> {
            j.map(|j| parse_number(line, name, cell(j)?)).transpose()
        };
        let test = match itest {
            Some(j) if cell(j)?.is_empty() => {
                return Err(TumbleError::Malformed {
                    line,
                    reason: "empty `test` id".into(),
                })
            }
            Some(j) => Some(cell(j)?.to_string()),
            None => None,
        };
        rows.push(Row {
            line,
            angle_deg: parse_number(line, "angle_deg", cell(ia)?)?,
            output_v: parse_number(line, "output_v", cell(io)?)?,
            temperature_c: opt(it, "temperature_c")?,
            time_s: opt(its, "time_s")?,
            test,
        });
    }
    if rows.is_empty() {
        return Err(TumbleError::Empty);
    }
    Ok(TumbleLog { metadata, rows })
}
