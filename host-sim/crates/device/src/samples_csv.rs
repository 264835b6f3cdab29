//! Sample CSVs for `compensate` (read through the project's CSV reader, `log::reader`), and the
//! writer of its output. Format: `# key: value` metadata lines, one header row, then rows;
//! required columns `time_s, output_v, temperature_c`, optional `tilt_arcsec`. Empty or NaN
//! cells are missing values (NaN, which the pipeline flags), except in `time_s`; ±inf is refused
//! (`log::reader::parse_number`, the rule of every reader).

use std::collections::BTreeMap;
use std::fmt::Write as _;

use accomp::pipeline::{Frame, Status};

use accomp_log::reader::{ReadError, Records};

/// One input row.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SampleRow {
    /// Seconds since start.
    pub time_s: f64,
    /// Accelerometer output E in volts.
    pub output_v: f64,
    /// Temperature in °C.
    pub temperature_c: f64,
    /// Tilt in arcsec, when the file has the column.
    pub tilt_arcsec: Option<f64>,
}

/// A parsed sample file.
#[derive(Debug, Clone, Default)]
pub struct SampleFile {
    /// `# key: value` metadata (input_g, orientation, …).
    pub metadata: BTreeMap<String, String>,
    /// The rows in file order.
    pub rows: Vec<SampleRow>,
}

/// Parse failures with their line number (1-based).
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum CsvError {
    /// No header row.
    #[error("no header row")]
    NoHeader,
    /// A required column is missing.
    #[error("missing column `{0}`")]
    MissingColumn(&'static str),
    /// The file breaks a rule of the project's CSV reader (field count, repeated metadata key,
    /// comment after the header, not UTF-8, a field that is no number or infinite, I/O).
    #[error("line {line}: {reason}")]
    Format {
        /// Line number (0 when the error is not about a line).
        line: usize,
        /// What is wrong.
        reason: String,
    },
}

impl From<ReadError> for CsvError {
    fn from(e: ReadError) -> Self {
        match e {
            ReadError::NoHeader => CsvError::NoHeader,
            other => CsvError::Format {
                line: other.line().unwrap_or(0),
                reason: other.what(),
            },
        }
    }
}

/// Parses the text of a sample file.
pub fn parse(text: &str) -> Result<SampleFile, CsvError> {
    let mut records = Records::from_text(text)?;
    let find = |n: &'static str| records.column(n).ok_or(CsvError::MissingColumn(n));
    let cols = [find("time_s")?, find("output_v")?, find("temperature_c")?];
    let tilt_col = records.column("tilt_arcsec");
    let header = records.header().to_vec();
    let mut file = SampleFile {
        metadata: records.take_meta().into_iter().collect(),
        rows: Vec::new(),
    };
    while let Some(row) = records.next_row()? {
        // Empty or NaN cells are missing values: NaN, which the injection flags; an infinity is
        // refused (the reader's rule), and a row without a time stamp too.
        let num = |c: usize| row.number(c, &header[c]);
        file.rows.push(SampleRow {
            time_s: row.required_number(cols[0], &header[cols[0]])?,
            output_v: num(cols[1])?,
            temperature_c: num(cols[2])?,
            tilt_arcsec: tilt_col.map(num).transpose()?,
        });
    }
    Ok(file)
}

/// Status bits as `NAME|NAME`, or `OK`.
pub fn status_names(s: Status) -> String {
    let names: Vec<&str> = Status::NAMES
        .iter()
        .filter(|(bit, _)| s.has(*bit))
        .map(|(_, n)| *n)
        .collect();
    if names.is_empty() {
        "OK".into()
    } else {
        names.join("|")
    }
}

/// Output CSV: metadata, header, one row per frame (f64 printed shortest-exact, NaN as NaN).
pub fn write_output(metadata: &BTreeMap<String, String>, rows: &[(f64, Frame)]) -> String {
    let mut out = output_header(metadata);
    for (t, f) in rows {
        out += &output_row(*t, f);
    }
    out
}

/// The metadata lines and the header of the output CSV (streamed writers start with this).
pub fn output_header(metadata: &BTreeMap<String, String>) -> String {
    let mut out = String::new();
    for (k, v) in metadata {
        let _ = writeln!(out, "# {k}: {v}");
    }
    out.push_str(
        "time_s,output_v,temperature_c,tilt_arcsec,a_i_exact_g,output_linearized_v,status\n",
    );
    out
}

/// One output row, newline included.
pub fn output_row(t: f64, f: &Frame) -> String {
    format!(
        "{t},{},{},{},{},{},{}\n",
        f.output_v,
        f.temperature_c,
        f.tilt_arcsec,
        f.a_i_exact_g,
        f.output_linearized_v,
        status_names(f.status)
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn metadata_header_and_optional_tilt_are_read() {
        let f = parse(
            "# input_g: 1.0\n# orientation: up\ntime_s,temperature_c,output_v,tilt_arcsec\n\
             0,50.5,1.3,0.25\n1.5,51,1.31,\n",
        )
        .unwrap();
        assert_eq!(f.metadata["input_g"], "1.0");
        assert_eq!(f.rows.len(), 2);
        assert_eq!(f.rows[0].output_v, 1.3);
        assert_eq!(f.rows[0].temperature_c, 50.5);
        assert_eq!(f.rows[0].tilt_arcsec, Some(0.25));
        assert!(f.rows[1].tilt_arcsec.unwrap().is_nan());
    }

    #[test]
    fn missing_columns_and_bad_numbers_are_named() {
        assert_eq!(
            parse("time_s,output_v\n0,1\n").unwrap_err(),
            CsvError::MissingColumn("temperature_c")
        );
        let refused = |text: &str| match parse(text).unwrap_err() {
            CsvError::Format { line, reason } => format!("line {line}: {reason}"),
            other => panic!("expected a refused field, got {other:?}"),
        };
        let e = refused("time_s,output_v,temperature_c\n0,x,1\n");
        assert!(
            e.starts_with("line 2: column \"output_v\"") && e.contains("\"x\""),
            "{e}"
        );
        // ±inf (or beyond an f64) is no missing value: refused with line and column.
        for (text, column) in [("-inf", "temperature_c"), ("1e400", "temperature_c")] {
            let e = refused(&format!(
                "time_s,output_v,temperature_c\n0,1,60\n1,1,{text}\n"
            ));
            assert!(
                e.starts_with(&format!("line 3: column \"{column}\"")) && e.contains("infinite"),
                "{e}"
            );
        }
        // A missing value is fine in a reading, not in the time stamp.
        assert!(parse("time_s,output_v,temperature_c\n0,NaN,\n").is_ok());
        let e = refused("time_s,output_v,temperature_c\n0,1,60\nNaN,1,60\n");
        assert!(
            e.starts_with("line 3: column \"time_s\"") && e.contains("required"),
            "{e}"
        );
        assert_eq!(parse("# only: meta\n").unwrap_err(), CsvError::NoHeader);
        // A short row is refused with its line (it was read as missing values before).
        assert!(matches!(
            parse("time_s,output_v,temperature_c\n0,1,2\n1,2\n").unwrap_err(),
            CsvError::Format { line: 3, .. }
        ));
    }

    #[test]
    fn status_is_written_by_name() {
        assert_eq!(status_names(Status(0)), "OK");
        assert_eq!(
            status_names(Status(Status::RTD_OPEN | Status::TILT_INVALID)),
            "RTD_OPEN|TILT_INVALID"
        );
    }
}
