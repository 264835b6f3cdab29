//! Minimal reader of sample CSVs for `compensate`, and the writer of its output.
//!
//! Kept apart on purpose: the project's log reader (host-sim/src/log.rs, branch `stability`)
//! will replace the reader once merged. Format: `# key: value` metadata lines, one header row,
//! then rows; required columns `time_s, output_v, temperature_c`, optional `tilt_arcsec`.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use accomp::pipeline::{Frame, Status};

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
    /// A cell is not a number.
    #[error("line {line}: `{cell}` in column {column} is not a number")]
    BadNumber {
        /// Line number.
        line: usize,
        /// Column name.
        column: String,
        /// The cell.
        cell: String,
    },
    /// A row has fewer cells than the header.
    #[error("line {0}: too few cells")]
    ShortRow(usize),
}

/// Parses the text of a sample file.
pub fn parse(text: &str) -> Result<SampleFile, CsvError> {
    let mut file = SampleFile::default();
    let mut header: Option<Vec<String>> = None;
    let mut cols = [0usize; 3];
    let mut tilt_col = None;
    for (i, line) in text.lines().enumerate() {
        let line_no = i + 1;
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        if let Some(meta) = line.strip_prefix('#') {
            if let Some((k, v)) = meta.split_once(':') {
                file.metadata
                    .insert(k.trim().to_string(), v.trim().to_string());
            }
            continue;
        }
        let cells: Vec<&str> = line.split(',').map(str::trim).collect();
        let Some(h) = &header else {
            let names: Vec<String> = cells.iter().map(|c| c.to_string()).collect();
            let find = |n: &'static str| {
                names
                    .iter()
                    .position(|c| c == n)
                    .ok_or(CsvError::MissingColumn(n))
            };
            cols = [find("time_s")?, find("output_v")?, find("temperature_c")?];
            tilt_col = names.iter().position(|c| c == "tilt_arcsec");
            header = Some(names);
            continue;
        };
        let num = |c: usize| -> Result<f64, CsvError> {
            let cell = cells.get(c).ok_or(CsvError::ShortRow(line_no))?;
            // Empty or NaN cells are missing values: NaN, which the injection flags.
            if cell.is_empty() || cell.eq_ignore_ascii_case("nan") {
                return Ok(f64::NAN);
            }
            cell.parse().map_err(|_| CsvError::BadNumber {
                line: line_no,
                column: h.get(c).cloned().unwrap_or_default(),
                cell: cell.to_string(),
            })
        };
        file.rows.push(SampleRow {
            time_s: num(cols[0])?,
            output_v: num(cols[1])?,
            temperature_c: num(cols[2])?,
            tilt_arcsec: tilt_col.map(num).transpose()?,
        });
    }
    if header.is_none() {
        return Err(CsvError::NoHeader);
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
        assert!(matches!(
            parse("time_s,output_v,temperature_c\n0,x,1\n").unwrap_err(),
            CsvError::BadNumber { line: 2, .. }
        ));
        assert_eq!(parse("# only: meta\n").unwrap_err(), CsvError::NoHeader);
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
