//! The input tables: coefficients vs temperature (Table 1's layout) and the paper's printed
//! models, through the project's one CSV reader.

use super::*;
use crate::log::reader::NumberError;

/// Name of the temperature column of the input table.
pub const TEMPERATURE_COLUMN: &str = "temperature_c";
/// Column names that map onto the coefficients of equation (1).
pub const BIAS_COLUMN: &str = "k0_g";
/// K1 column (V/g).
pub const SCALE_FACTOR_COLUMN: &str = "k1_v_per_g";
/// K2 column (g/g²).
pub const NONLINEARITY_COLUMN: &str = "k2_g_per_g2";
/// δp column (arcmin).
pub const MISALIGNMENT_P_COLUMN: &str = "delta_p_arcmin";
/// δo column (arcmin).
pub const MISALIGNMENT_O_COLUMN: &str = "delta_o_arcmin";
/// File name of the paper's printed models, looked up beside the input table.
pub const PAPER_MODELS_FILE: &str = "paper_printed_temperature_models.csv";

/// Why a row of a CSV table is refused.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum RowError {
    /// The row has more or fewer fields than the header.
    #[error("expected {expected} comma-separated fields, found {found}")]
    FieldCount {
        /// Fields in the header.
        expected: usize,
        /// Fields in this row.
        found: usize,
    },
    /// A field is empty where a number is required.
    #[error("column `{column}` is empty")]
    Empty {
        /// Column name.
        column: String,
    },
    /// A field does not parse as a number.
    #[error("column `{column}`: `{text}` is not a number")]
    NotANumber {
        /// Column name.
        column: String,
        /// The offending text.
        text: String,
    },
    /// A field parses to NaN or infinity.
    #[error("column `{column}`: `{text}` is not a finite number")]
    NonFinite {
        /// Column name.
        column: String,
        /// The offending text.
        text: String,
    },
    /// A model order outside 0–4 (printed-models table).
    #[error("order `{text}` is not an integer from 0 to 4")]
    BadOrder {
        /// The offending text.
        text: String,
    },
}

/// Why a CSV table is refused. Line numbers count every physical line from 1, comments included.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum CsvError {
    /// A data row is malformed.
    #[error("line {line}: {reason}")]
    Row {
        /// 1-based line number in the file.
        line: usize,
        /// What is wrong with it.
        reason: RowError,
    },
    /// Only comments and blank lines.
    #[error("no header line (the file holds only comments and blank lines)")]
    NoHeader,
    /// A required column is missing from the header.
    #[error("line {line}: header has no `{column}` column")]
    MissingColumn {
        /// Header line number.
        line: usize,
        /// The missing column.
        column: &'static str,
    },
    /// The header is malformed (a name empty or repeated).
    #[error("line {line}: header: {reason}")]
    BadHeader {
        /// Header line number.
        line: usize,
        /// What is wrong with it.
        reason: String,
    },
    /// The file breaks a rule of the project's CSV reader (repeated metadata key, comment after
    /// the header, not UTF-8, bad quoting), see `log::reader`.
    #[error("line {line}: {reason}")]
    Format {
        /// 1-based line.
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// A file that cannot be read.
    #[error("{0}")]
    Io(String),
    /// A calibration temperature no platinum RTD reading can stand for.
    #[error(
        "line {line}: temperature {value} °C is outside the RTD's range {min}…{max} °C \
         (IEC 60751 span, the one the core's RTD conversion accepts: accomp::rtd::T_MIN_C/T_MAX_C)"
    )]
    TemperatureOutOfRange {
        /// 1-based line.
        line: usize,
        /// The temperature.
        value: f64,
        /// Lower end, °C.
        min: f64,
        /// Upper end, °C.
        max: f64,
    },
    /// Too few data rows to fit and compare even a constant (AICc needs n ≥ 3).
    #[error("{rows} data rows: at least 3 are needed")]
    TooFewRows {
        /// Data rows found.
        rows: usize,
    },
    /// All temperatures are equal: no range to normalize over.
    #[error("all temperatures are equal ({0} °C): no range to fit over")]
    EmptyRange(f64),
}

/// One column of the coefficient table.
#[derive(Debug, Clone, PartialEq)]
pub struct Column {
    /// Header name (e.g. `k0_g`).
    pub name: String,
    /// One value per row.
    pub values: Vec<f64>,
}

/// The coefficient-vs-temperature table (Table 1 of the paper, or any table with that layout).
#[derive(Debug, Clone, PartialEq)]
pub struct CoefficientTable {
    /// The temperature of each row, °C.
    pub temperatures_c: Vec<f64>,
    /// Every other column, in header order.
    pub columns: Vec<Column>,
    /// What the fit should be told about the input (e.g. a temperature given twice); printed on
    /// stderr by `accomp fit`.
    pub warnings: Vec<String>,
}

impl CoefficientTable {
    /// The calibrated range min..max of the table temperatures, normalized to x ∈ [−1, 1].
    pub fn scale(&self) -> Result<TemperatureScale, CsvError> {
        let min = self
            .temperatures_c
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min);
        let max = self
            .temperatures_c
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max);
        TemperatureScale::for_range(Celsius(min), Celsius(max))
            .map_err(|_| CsvError::EmptyRange(min))
    }
}

impl From<ReadError> for CsvError {
    fn from(e: ReadError) -> Self {
        match e {
            ReadError::NoHeader => CsvError::NoHeader,
            ReadError::Io(e) => CsvError::Io(e.to_string()),
            ReadError::BadHeader { line, reason } => CsvError::BadHeader { line, reason },
            ReadError::FieldCount {
                line,
                expected,
                found,
            } => CsvError::Row {
                line,
                reason: RowError::FieldCount { expected, found },
            },
            other => CsvError::Format {
                line: other.line().unwrap_or(0),
                reason: other.what(),
            },
        }
    }
}

/// A table entry: the reader's rule for numbers (`log::reader::parse_number`), a value required.
fn parse_number(column: &str, text: &str) -> Result<f64, RowError> {
    if text.is_empty() {
        return Err(RowError::Empty {
            column: column.to_owned(),
        });
    }
    crate::log::reader::parse_required_number(text.as_bytes()).map_err(|e| match e {
        NumberError::NotANumber => RowError::NotANumber {
            column: column.to_owned(),
            text: text.to_owned(),
        },
        NumberError::Infinite | NumberError::Missing => RowError::NonFinite {
            column: column.to_owned(),
            text: text.to_owned(),
        },
    })
}

/// The index of a required column, or the named error.
fn find_column(records: &Records<&[u8]>, column: &'static str) -> Result<usize, CsvError> {
    records.column(column).ok_or(CsvError::MissingColumn {
        line: records.header_line(),
        column,
    })
}

/// Parses a coefficient table (project CSV format, `log::reader`): a header with
/// `temperature_c` and any number of coefficient columns (mapped to coefficients by name
/// later), then one row per temperature. Temperatures outside the RTD's range are refused; a
/// temperature given twice is kept (two measurements weigh twice) with a warning.
pub fn parse_coefficient_table(text: &str) -> Result<CoefficientTable, CsvError> {
    let mut records = Records::from_text(text)?;
    let names = records.header().to_vec();
    let t_index = find_column(&records, TEMPERATURE_COLUMN)?;
    let mut temperatures_c = Vec::new();
    let mut lines = Vec::new();
    let mut columns: Vec<Column> = names
        .iter()
        .enumerate()
        .filter(|(i, _)| *i != t_index)
        .map(|(_, n)| Column {
            name: n.clone(),
            values: Vec::new(),
        })
        .collect();
    while let Some(row) = records.next_row()? {
        let line = row.line;
        let mut col = columns.iter_mut();
        for (i, name) in names.iter().enumerate() {
            let text = row.text(i)?;
            let v = parse_number(name, text).map_err(|reason| CsvError::Row { line, reason })?;
            if i == t_index {
                if !(rtd::T_MIN_C..=rtd::T_MAX_C).contains(&v) {
                    return Err(CsvError::TemperatureOutOfRange {
                        line,
                        value: v,
                        min: rtd::T_MIN_C,
                        max: rtd::T_MAX_C,
                    });
                }
                temperatures_c.push(v);
                lines.push(line);
            } else if let Some(c) = col.next() {
                c.values.push(v);
            }
        }
    }
    if temperatures_c.len() < 3 {
        return Err(CsvError::TooFewRows {
            rows: temperatures_c.len(),
        });
    }
    let mut warnings = Vec::new();
    for (i, t) in temperatures_c.iter().enumerate() {
        let first = temperatures_c[..i].iter().position(|u| u == t);
        if let Some(first) = first {
            warnings.push(format!(
                "line {}: temperature {t} °C repeats line {}: both rows are fitted (a repeated \
                 measurement weighs twice); remove one if it is a copy",
                lines[i], lines[first]
            ));
        }
    }
    let table = CoefficientTable {
        temperatures_c,
        columns,
        warnings,
    };
    table.scale()?;
    Ok(table)
}

/// One printed model: K(T) = Σ c_j·T^j in raw °C, as published.
#[derive(Debug, Clone, PartialEq)]
pub struct PrintedModel {
    /// The coefficient column it models.
    pub coefficient: String,
    /// Polynomial order.
    pub order: usize,
    /// c0..c4 (empty cells read as 0: the term is absent).
    pub coeffs_celsius: [f64; MAX_ORDER + 1],
    /// The paper's reported standard deviation, if printed.
    pub reported_std: Option<f64>,
}

/// Parses the printed-models table (`coefficient,order,c0..c4,reported_std`).
pub fn parse_printed_models(text: &str) -> Result<Vec<PrintedModel>, CsvError> {
    let mut records = Records::from_text(text)?;
    let names = records.header().to_vec();
    let i_name = find_column(&records, "coefficient")?;
    let i_order = find_column(&records, "order")?;
    let i_c = [
        find_column(&records, "c0")?,
        find_column(&records, "c1")?,
        find_column(&records, "c2")?,
        find_column(&records, "c3")?,
        find_column(&records, "c4")?,
    ];
    let i_std = find_column(&records, "reported_std")?;
    let mut out = Vec::new();
    while let Some(row) = records.next_row()? {
        let line = row.line;
        let row_err = |reason| CsvError::Row { line, reason };
        let order_text = row.text(i_order)?;
        let order: usize = order_text
            .parse()
            .ok()
            .filter(|o| *o <= MAX_ORDER)
            .ok_or_else(|| {
                row_err(RowError::BadOrder {
                    text: order_text.to_owned(),
                })
            })?;
        let mut coeffs_celsius = [0.0; MAX_ORDER + 1];
        for (j, (c, idx)) in coeffs_celsius.iter_mut().zip(i_c).enumerate() {
            let text = row.text(idx)?;
            // Empty means "term absent" — but only above the stated order.
            if text.is_empty() && j > order {
                continue;
            }
            *c = parse_number(&names[idx], text).map_err(row_err)?;
        }
        let std_text = row.text(i_std)?;
        let reported_std = if std_text.is_empty() {
            None
        } else {
            Some(parse_number("reported_std", std_text).map_err(row_err)?)
        };
        out.push(PrintedModel {
            coefficient: row.text(i_name)?.to_owned(),
            order,
            coeffs_celsius,
            reported_std,
        });
    }
    Ok(out)
}
