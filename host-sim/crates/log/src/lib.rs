//! Stability-test logs: the CSV the board streams, the CLI records and every analysis reads.
//!
//! # Format (docs/log-format.md)
//!
//! ```text
//! # instrument: JN-06 A12124
//! # start_utc: 2024-03-01T00:00:00Z
//! # input_g: 1
//! # scale_factor_v_per_g: 1.3301
//! time_s,output_v,temperature_c,tilt_arcsec,status
//! 0,1.3301234,60.001,0.12,ok
//! 1,1.3301236,60.002,,ok
//! ```
//!
//! - Lines starting with `#` *before the header* are metadata. `# key: value` lines are kept as
//!   (key, value) pairs in file order (the first `:` splits key from value; both are trimmed). A
//!   `#` line without a `:` is a free comment and is ignored. `#` lines after the header are
//!   rejected as bad rows: a comment in the middle of the samples usually means two logs were
//!   concatenated, which must not pass silently. The exception is an event line of a record,
//!   `# event: <UTC> <kind> <details>`: kept as an [`Event`] with the row it precedes.
//! - Empty lines (also `\r\n` ones) are skipped wherever they are.
//! - One header row of comma-separated column names. `time_s` (seconds since `start_utc`) is
//!   required, and so is at least one other column. Names carry their unit as a suffix
//!   (`temperature_c`, `tilt_arcsec`, `output_v`, `a_i_exact_g`, ...).
//! - One row per sample, exactly as many fields as the header. Fields are trimmed of spaces.
//! - `time_s` must be finite and strictly increasing: a repeated or backwards time stamp is a bad
//!   row, because every later analysis (spacing, Allan deviation, regression against time)
//!   silently breaks on it.
//! - **Gaps**: in any numeric column other than `time_s`, an empty field or `NaN`/`nan` is an
//!   explicit gap and is stored as `f64::NAN`. Analyses treat NaN as "no reading" (see
//!   `stability` and `allan` for their policies); nothing is interpolated. Infinities are rejected.
//! - **Text columns**: a column named `status` or ending in `_status` or `_flags` holds
//!   free text (status words, hex flag masks). Its values are kept verbatim, interned (each
//!   distinct string stored once), see [`TextColumn`].
//!
//! Writing ([`Log::write_to`]) produces the same format; numbers are printed with Rust's shortest
//! round-trip representation, so `read(write(log)) == log` bit for bit, NaN gaps as empty fields.

use std::collections::HashMap;
use std::fmt;
use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Read, Write};
use std::path::Path;

use accomp::tide::STANDARD_GRAVITY_M_S2;

/// Unit tests: asserts that `result` is an `Err` matching `pattern`, saying which error it was
/// when not (a bare `assert!(matches!(…))` says only that it failed). Defined before the modules
/// so that their tests have it too.
#[cfg(test)]
macro_rules! assert_err {
    ($result:expr, $pattern:pat) => {
        match $result {
            Err($pattern) => {}
            Err(other) => panic!("expected {}, got {other:?}", stringify!($pattern)),
            Ok(_) => panic!("expected {}, got Ok", stringify!($pattern)),
        }
    };
}

pub mod calibration_file;
pub mod outputs;
pub mod reader;
pub mod time;
pub mod writer;

/// Unit tests' scratch folders, removed on drop (the integration tests' own helper).
#[cfg(test)]
#[path = "../../../tests/common/scratch.rs"]
mod scratch;
use reader::{ReadError, Records};

/// Whether a record file is gzip-compressed (`.gz`, as `rec.csv.gz`): it is decompressed as it
/// is read.
pub fn is_gzip(path: &Path) -> bool {
    path.extension().is_some_and(|e| e == "gz")
}

/// One file of a record, decompressed as it is read when it is `.gz`. The byte limit is checked
/// on the file's size here and on the bytes read (decompressed) by the reader, so a `.csv.gz`
/// has the same row and byte limits as the `.csv` it holds.
fn open_one(path: &Path) -> Result<Box<dyn BufRead + Send>, LogError> {
    reader::check_file_size(path)?;
    let f = File::open(path)?;
    Ok(if is_gzip(path) {
        // Multi-member: a file compressed in pieces (or appended to) is read whole.
        Box::new(BufReader::with_capacity(
            1 << 20,
            flate2::read::MultiGzDecoder::new(BufReader::with_capacity(1 << 16, f)),
        ))
    } else {
        Box::new(BufReader::with_capacity(1 << 20, f))
    })
}

/// The bytes of a log file (`.csv`, or `.csv.gz` decompressed as it is read), or of a directory
/// of daily files (`*.csv` and `*.csv.gz` in name order, as `accomp record --rotate daily` writes
/// them) read as one record: every file after the first must have the same header row and
/// `start_utc` (its metadata and header are skipped, so `time_s` runs on), or the directory is
/// refused naming the file. A day present both plain and compressed is refused, naming both.
pub fn open_record(path: &Path) -> Result<Box<dyn BufRead + Send>, LogError> {
    if !path.is_dir() {
        return open_one(path);
    }
    let mut files: Vec<std::path::PathBuf> = std::fs::read_dir(path)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.is_file()
                && p.file_name()
                    .and_then(|n| n.to_str())
                    .is_some_and(|n| n.ends_with(".csv") || n.ends_with(".csv.gz"))
        })
        .collect();
    files.sort();
    for w in files.windows(2) {
        if is_gzip(&w[1]) && w[1].with_extension("") == w[0] {
            return Err(LogError::Shape(format!(
                "{} and {}: the same day twice (plain and compressed); remove one",
                w[0].display(),
                w[1].display()
            )));
        }
    }
    let mut first: Option<(String, Option<String>)> = None;
    let mut chain: Box<dyn Read + Send> = Box::new(std::io::empty());
    for f in files {
        let mut r = open_one(&f)?;
        // The preamble: `#` lines and blank lines up to the header row.
        let mut preamble = Vec::new();
        let mut start = None;
        let header = loop {
            let mut line = String::new();
            if r.read_line(&mut line)? == 0 {
                break None;
            }
            preamble.extend_from_slice(line.as_bytes());
            let t = line.trim();
            if t.is_empty() {
                continue;
            }
            match t.strip_prefix('#') {
                Some(c) => {
                    if let Some(("start_utc", v)) = c.split_once(':').map(|(k, v)| (k.trim(), v)) {
                        start = Some(v.trim().to_owned());
                    }
                }
                None => break Some(t.to_owned()),
            }
        };
        let Some(header) = header else { continue };
        match &first {
            None => {
                first = Some((header, start));
                chain = Box::new(chain.chain(std::io::Cursor::new(preamble)).chain(r));
            }
            Some((h, s)) if *h == header && *s == start => {
                // A cut last line of the file before must not run into this one.
                chain = Box::new(chain.chain(&b"\n"[..]).chain(r));
            }
            Some(_) => {
                return Err(LogError::Shape(format!(
                    "{}: its header row or start_utc differs from the first file's: not the \
                     same record",
                    f.display()
                )))
            }
        }
    }
    if first.is_none() {
        return Err(LogError::MissingHeader);
    }
    Ok(Box::new(BufReader::with_capacity(1 << 20, chain)))
}

/// Name of the required time column (seconds since `start_utc`).
pub const TIME_COLUMN: &str = "time_s";

/// What went wrong while reading or writing a log.
#[derive(Debug, thiserror::Error)]
pub enum LogError {
    /// The file could not be opened, read or written.
    #[error("log I/O: {0}")]
    Io(#[from] std::io::Error),
    /// The file ended before a header row.
    #[error("log has no header row")]
    MissingHeader,
    /// The file is beyond a limit of the reader (size, rows, line length).
    #[error("log refused: {0}")]
    Limit(String),
    /// The header has no `time_s` column.
    #[error("log header (line {line}) has no `time_s` column")]
    MissingTime {
        /// 1-based line number of the header.
        line: usize,
    },
    /// The header has only `time_s`.
    #[error("log header (line {line}) has no column besides `time_s`")]
    NoOutputColumn {
        /// 1-based line number of the header.
        line: usize,
    },
    /// The header is malformed (empty or duplicate name).
    #[error("log header (line {line}): {reason}")]
    BadHeader {
        /// 1-based line number of the header.
        line: usize,
        /// What is wrong with it.
        reason: String,
    },
    /// A data row is malformed.
    #[error("log line {line}: {reason}")]
    BadRow {
        /// 1-based line number in the file.
        line: usize,
        /// What is wrong with the row.
        reason: String,
    },
    /// A metadata value could not be parsed as the type asked for.
    #[error("log metadata `{key}`: cannot parse {value:?} as a number")]
    BadMeta {
        /// The metadata key.
        key: String,
        /// Its raw value.
        value: String,
    },
    /// A log being built has columns of different lengths or a bad name.
    #[error("log construction: {0}")]
    Shape(String),
    /// One of the errors above, in the file named (what the commands print).
    // `error`, not `source`: the message holds it already, no "Caused by" repeating it.
    #[error("{}: {error}", path.display())]
    InFile {
        /// The file (or directory of daily files).
        path: std::path::PathBuf,
        /// What is wrong in it.
        error: Box<LogError>,
    },
}

impl LogError {
    /// The error as said of the file `path`.
    pub fn in_file(self, path: &Path) -> Self {
        LogError::InFile {
            path: path.to_owned(),
            error: Box::new(self),
        }
    }
}

impl From<ReadError> for LogError {
    /// The reader's errors in the log's terms: I/O stays I/O, a file without a header is
    /// [`LogError::MissingHeader`], header faults are [`LogError::BadHeader`], everything
    /// about a line is a [`LogError::BadRow`] with that line.
    fn from(e: ReadError) -> Self {
        match e {
            ReadError::Io(e) => LogError::Io(e),
            ReadError::NoHeader => LogError::MissingHeader,
            e @ (ReadError::TooLarge { .. } | ReadError::LineTooLong { .. }) => {
                LogError::Limit(e.to_string())
            }
            ReadError::BadHeader { line, reason } => LogError::BadHeader { line, reason },
            other => LogError::BadRow {
                line: other.line().unwrap_or(0),
                reason: other.what(),
            },
        }
    }
}

/// A text column (e.g. `status`): values interned, one index per row.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TextColumn {
    /// Distinct values in order of first appearance.
    values: Vec<String>,
    /// Per row, an index into `values`. u32: a log of more than 4 G distinct status words is
    /// not a log.
    rows: Vec<u32>,
}

impl TextColumn {
    /// Builds a column from per-row strings.
    pub fn from_strings<S: AsRef<str>>(rows: &[S]) -> Self {
        let mut c = TextColumn::default();
        let mut index: HashMap<String, u32> = HashMap::new();
        for r in rows {
            c.push(r.as_ref(), &mut index);
        }
        c
    }

    fn push(&mut self, s: &str, index: &mut HashMap<String, u32>) {
        // Status words repeat on almost every row: look up the previous row's value first.
        if let Some(&last) = self.rows.last() {
            if self.values.get(last as usize).is_some_and(|v| v == s) {
                self.rows.push(last);
                return;
            }
        }
        let id = match index.get(s) {
            Some(&id) => id,
            None => {
                let id = self.values.len() as u32;
                self.values.push(s.to_owned());
                index.insert(s.to_owned(), id);
                id
            }
        };
        self.rows.push(id);
    }

    /// Appends the rows of `other` (its values interned into this column through `index`, the
    /// map of this column's values to their ids).
    fn append(&mut self, other: &TextColumn, index: &mut HashMap<String, u32>) {
        if other.rows.is_empty() {
            return;
        }
        let ids: Vec<u32> = other
            .values
            .iter()
            .map(|v| match index.get(v) {
                Some(&id) => id,
                None => {
                    let id = self.values.len() as u32;
                    self.values.push(v.clone());
                    index.insert(v.clone(), id);
                    id
                }
            })
            .collect();
        self.rows.extend(
            other
                .rows
                .iter()
                .map(|&r| ids.get(r as usize).copied().unwrap_or(0)),
        );
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    /// True if the column has no rows.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// The value of row `i`, or `None` past the end.
    pub fn get(&self, i: usize) -> Option<&str> {
        let id = *self.rows.get(i)?;
        self.values.get(id as usize).map(String::as_str)
    }

    /// Distinct values, in order of first appearance.
    pub fn distinct(&self) -> &[String] {
        &self.values
    }

    /// Iterates over the rows' values.
    pub fn iter(&self) -> impl Iterator<Item = &str> + '_ {
        self.rows
            .iter()
            .map(move |&id| self.values.get(id as usize).map_or("", String::as_str))
    }
}

/// One column's storage.
#[derive(Debug, Clone, PartialEq)]
enum ColumnData {
    Numeric(Vec<f64>),
    Text(TextColumn),
}

/// True if a column of this name holds text rather than numbers (see module docs).
pub fn is_text_column_name(name: &str) -> bool {
    name == "status" || name.ends_with("_status") || name.ends_with("_flags")
}

/// Units whose own name holds an `_`: taken whole (`gravity_m_s2` is in `m_s2`, not `s2`).
const COMPOUND_UNITS: [&str; 2] = ["nm_s2", "m_s2"];

/// The gravity units a gravimeter column can be in (`gravity_<unit>`), each known to
/// [`unit_per_g_for_suffix`].
pub const GRAVITY_UNITS: [&str; 4] = ["mgal", "ugal", "nm_s2", "m_s2"];

/// The unit of a column, from its name, in lower case: the part after the last `_`
/// (`temperature_c` → `c`, `output_V` → `v`), or a whole compound unit (`gravity_nm_s2` →
/// `nm_s2`). `None` when the name has no suffix. Every reader of a column's unit asks here.
pub fn unit_suffix(name: &str) -> Option<String> {
    let l = name.to_ascii_lowercase();
    if let Some(u) = COMPOUND_UNITS
        .iter()
        .find(|u| l.strip_suffix(*u).is_some_and(|head| head.ends_with('_')))
    {
        return Some((*u).to_owned());
    }
    l.rsplit_once('_')
        .map(|(_, u)| u.to_owned())
        .filter(|u| !u.is_empty())
}

/// 1 mGal in m/s².
pub const M_S2_PER_MGAL: f64 = 1.0e-5;

/// Output units per g for a column unit suffix, when the suffix says it.
pub fn unit_per_g_for_suffix(unit: &str) -> Option<f64> {
    match unit {
        "g" => Some(1.0),
        "mg" => Some(1.0e3),
        "ug" => Some(1.0e6),
        "m_s2" => Some(STANDARD_GRAVITY_M_S2),
        "nm_s2" => Some(STANDARD_GRAVITY_M_S2 * 1.0e9),
        "mgal" => Some(STANDARD_GRAVITY_M_S2 / M_S2_PER_MGAL),
        "ugal" => Some(STANDARD_GRAVITY_M_S2 / M_S2_PER_MGAL * 1.0e3),
        _ => None,
    }
}

/// An event line of a record (`# event: <UTC> <kind> <details>`, what `accomp record` writes
/// between the rows where something happened: a reset, a gap, a changed table …).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Event {
    /// Index of the first row after the event line (the log's length when none follows).
    pub row: usize,
    /// When, as written (the `start_utc` form).
    pub utc: String,
    /// One word: `board_reset`, `table_changed`, `seq_gap`, … (docs/log-format.md).
    pub kind: String,
    /// The rest of the line (in a file the csv crate reads, one with a quoted field before
    /// the event line, its comma-separated parts trimmed and joined by commas).
    pub details: String,
}

/// The start of a record's event line.
pub const EVENT_LINE_PREFIX: &str = "# event:";

/// Event kinds more than one crate acts on: the recorder writes them, the analysis starts a
/// new continuous segment at them.
pub mod event_kind {
    /// The board restarted (a new boot, seen by READY, the boot id or seq going back).
    pub const BOARD_RESET: &str = "board_reset";
    /// Another compensation table became active.
    pub const TABLE_CHANGED: &str = "table_changed";
}

impl Event {
    /// The line a record holds for an event, newline included: `# event: <UTC> <kind>
    /// <details>` (`utc` in the `start_utc` form).
    pub fn line(utc: impl fmt::Display, kind: &str, details: &str) -> String {
        format!("{EVENT_LINE_PREFIX} {utc} {kind} {details}\n")
    }

    /// The event of the text after `# event:` (trimmed), before row `row`.
    fn parse(row: usize, text: &str) -> Self {
        let mut words = text.splitn(3, ' ');
        let mut word = || words.next().unwrap_or("").trim().to_owned();
        Event {
            row,
            utc: word(),
            kind: word(),
            details: word(),
        }
    }
}

/// A stability-test log in memory: metadata, column names, and columns.
#[derive(Debug, Clone, PartialEq)]
pub struct Log {
    meta: Vec<(String, String)>,
    names: Vec<String>,
    columns: Vec<ColumnData>,
    rows: usize,
    /// Event lines of a record, in file order.
    events: Vec<Event>,
}

impl Log {
    /// A log with the given `time_s` values and no other column yet (add them with
    /// [`Log::push_column`] / [`Log::push_text_column`]); for writers such as the simulator.
    pub fn with_time(time_s: Vec<f64>) -> Result<Self, LogError> {
        for (i, w) in time_s.windows(2).enumerate() {
            let (a, b) = (w[0], w[1]);
            if b <= a || b.is_nan() || a.is_nan() || b.is_infinite() || a.is_infinite() {
                return Err(LogError::Shape(format!(
                    "time_s not finite and strictly increasing at sample {}",
                    i + 1
                )));
            }
        }
        if time_s.len() == 1 && !time_s[0].is_finite() {
            return Err(LogError::Shape("time_s not finite".into()));
        }
        Ok(Log {
            meta: Vec::new(),
            names: vec![TIME_COLUMN.to_owned()],
            rows: time_s.len(),
            columns: vec![ColumnData::Numeric(time_s)],
            events: Vec::new(),
        })
    }

    fn check_new_name(&self, name: &str, len: usize) -> Result<(), LogError> {
        if name.is_empty() || name.contains([',', '\n', '\r', '#']) || name.trim() != name {
            return Err(LogError::Shape(format!("bad column name {name:?}")));
        }
        if self.names.iter().any(|n| n == name) {
            return Err(LogError::Shape(format!("duplicate column {name:?}")));
        }
        if len != self.rows {
            return Err(LogError::Shape(format!(
                "column {name:?} has {len} rows, log has {}",
                self.rows
            )));
        }
        Ok(())
    }

    /// Appends a numeric column (NaN = gap). Its length must match `time_s`.
    pub fn push_column(&mut self, name: &str, values: Vec<f64>) -> Result<(), LogError> {
        self.check_new_name(name, values.len())?;
        if is_text_column_name(name) {
            return Err(LogError::Shape(format!(
                "{name:?} is a text column name; use push_text_column"
            )));
        }
        if values.iter().any(|v| v.is_infinite()) {
            return Err(LogError::Shape(format!("column {name:?} has an infinity")));
        }
        self.names.push(name.to_owned());
        self.columns.push(ColumnData::Numeric(values));
        Ok(())
    }

    /// Appends a text column (name must be `status`, `*_status` or `*_flags`). Values must not
    /// contain commas or line breaks.
    pub fn push_text_column(&mut self, name: &str, values: TextColumn) -> Result<(), LogError> {
        self.check_new_name(name, values.len())?;
        if !is_text_column_name(name) {
            return Err(LogError::Shape(format!(
                "{name:?} is not a text column name (status, *_status, *_flags)"
            )));
        }
        if values
            .distinct()
            .iter()
            .any(|v| v.contains([',', '\n', '\r']))
        {
            return Err(LogError::Shape(format!(
                "text column {name:?} has a value with a comma or line break"
            )));
        }
        self.names.push(name.to_owned());
        self.columns.push(ColumnData::Text(values));
        Ok(())
    }

    /// Sets (or replaces) a metadata entry. Keys must not contain `:` or line breaks.
    pub fn set_meta(&mut self, key: &str, value: &str) -> Result<(), LogError> {
        if key.is_empty() || key.contains([':', '\n', '\r']) || value.contains(['\n', '\r']) {
            return Err(LogError::Shape(format!("bad metadata {key:?}: {value:?}")));
        }
        match self.meta.iter_mut().find(|(k, _)| k == key) {
            Some((_, v)) => *v = value.to_owned(),
            None => self.meta.push((key.to_owned(), value.to_owned())),
        }
        Ok(())
    }

    /// Number of sample rows.
    pub fn len(&self) -> usize {
        self.rows
    }

    /// True if the log has no sample rows.
    pub fn is_empty(&self) -> bool {
        self.rows == 0
    }

    /// Metadata value for `key` (`# key: value`), trimmed.
    pub fn meta(&self, key: &str) -> Option<&str> {
        self.meta
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    /// Metadata value for `key` parsed as a number: `Ok(None)` if absent, an error if present but
    /// not a finite number.
    pub fn meta_f64(&self, key: &str) -> Result<Option<f64>, LogError> {
        match self.meta(key) {
            None => Ok(None),
            Some(v) => match v.parse::<f64>() {
                Ok(x) if x.is_finite() => Ok(Some(x)),
                _ => Err(LogError::BadMeta {
                    key: key.to_owned(),
                    value: v.to_owned(),
                }),
            },
        }
    }

    /// All metadata entries in file order.
    pub fn metadata(&self) -> &[(String, String)] {
        &self.meta
    }

    /// Column names in file order (`time_s` included).
    pub fn column_names(&self) -> &[String] {
        &self.names
    }

    /// The `time_s` column.
    pub fn time_s(&self) -> &[f64] {
        // The constructor and the reader guarantee a numeric time column; an empty slice is the
        // only sane answer should that ever be broken.
        self.column(TIME_COLUMN).unwrap_or(&[])
    }

    /// A numeric column by name (NaN = gap); `None` if absent or a text column.
    pub fn column(&self, name: &str) -> Option<&[f64]> {
        let i = self.names.iter().position(|n| n == name)?;
        match self.columns.get(i)? {
            ColumnData::Numeric(v) => Some(v),
            ColumnData::Text(_) => None,
        }
    }

    /// A text column by name; `None` if absent or numeric.
    pub fn text_column(&self, name: &str) -> Option<&TextColumn> {
        let i = self.names.iter().position(|n| n == name)?;
        match self.columns.get(i)? {
            ColumnData::Text(t) => Some(t),
            ColumnData::Numeric(_) => None,
        }
    }

    /// The event lines of a record (`accomp record`), in file order, each with the row it
    /// precedes; empty for any other log.
    pub fn events(&self) -> &[Event] {
        &self.events
    }

    /// Reads a log from a file, or from a directory of daily files as one record
    /// ([`open_record`]).
    pub fn read_path(path: impl AsRef<Path>) -> Result<Self, LogError> {
        Self::read(open_record(path.as_ref())?)
    }

    /// Parses a log held in a string.
    pub fn parse_str(s: &str) -> Result<Self, LogError> {
        Self::read(s.as_bytes())
    }

    /// Reads a log from any buffered reader, through the project's one CSV reader
    /// ([`reader::Records`]: metadata, BOM, header and field-count rules, line numbers). Numeric
    /// fields are parsed in place from the record's bytes: no per-row allocation; blocks of
    /// lines are parsed on all cores ([`Records::for_each_block`]).
    pub fn read<R: BufRead>(r: R) -> Result<Self, LogError> {
        Self::read_selected(r, &|_| true)
    }

    /// Reads a log from a file keeping only the columns whose name `keep` accepts (and
    /// `time_s`). Every field of every column is still checked (a malformed value in a column
    /// not kept is refused with its line all the same); the columns not kept are only not
    /// stored.
    pub fn read_path_selected(
        path: impl AsRef<Path>,
        keep: &(dyn Fn(&str) -> bool + Sync),
    ) -> Result<Self, LogError> {
        Self::read_selected(open_record(path.as_ref())?, keep)
    }

    /// [`Log::read`] keeping only some columns (see [`Log::read_path_selected`]).
    pub fn read_selected<R: BufRead>(
        r: R,
        keep: &(dyn Fn(&str) -> bool + Sync),
    ) -> Result<Self, LogError> {
        let mut records = Records::new(r)?;
        let header_line = records.header_line();
        let all_names: Vec<String> = records.header().to_vec();
        let time_idx = records
            .column(TIME_COLUMN)
            .ok_or(LogError::MissingTime { line: header_line })?;
        if all_names.len() < 2 {
            return Err(LogError::NoOutputColumn { line: header_line });
        }
        let meta = records.take_meta();

        let is_text: Vec<bool> = all_names.iter().map(|n| is_text_column_name(n)).collect();
        let kept: Vec<bool> = all_names
            .iter()
            .enumerate()
            .map(|(i, n)| i == time_idx || keep(n))
            .collect();
        let layout = RowLayout {
            names: &all_names,
            is_text: &is_text,
            kept: &kept,
            time_idx,
        };
        let mut all = Part::new(all_names.len());
        let mut text_index: Vec<HashMap<String, u32>> = vec![HashMap::new(); all_names.len()];
        let mut events = Vec::new();
        records.for_each_block(
            |rows| layout.parse(rows),
            |part| {
                // The block's first time stamp against the last one before it: a worker cannot
                // see across its block's start. Of that and the block's own first fault, the
                // one earlier in the file (line, then column) is the file's error.
                let boundary = part.first_time.and_then(|(t, line)| {
                    (t <= all.last_t).then(|| RowFault {
                        line,
                        rank: time_idx + 1,
                        error: LogError::BadRow {
                            line,
                            reason: format!("non-monotonic time: time_s {t} after {}", all.last_t),
                        },
                    })
                });
                let fault = match (boundary, part.fault) {
                    (Some(b), Some(f)) => Some(if (f.line, f.rank) < (b.line, b.rank) {
                        f
                    } else {
                        b
                    }),
                    (b, f) => b.or(f),
                };
                if let Some(f) = fault {
                    return Err(f.error);
                }
                events.extend(
                    part.events
                        .into_iter()
                        .map(|e| Event::parse(all.rows + e.rows_before, &e.text)),
                );
                all.rows += part.rows;
                if part.rows > 0 {
                    all.last_t = part.last_t;
                }
                for (col, (n, t)) in part.numeric.into_iter().zip(part.text).enumerate() {
                    all.numeric[col].extend_from_slice(&n);
                    all.text[col].append(&t, &mut text_index[col]);
                }
                Ok(())
            },
        )?;

        let mut names = Vec::new();
        let mut columns = Vec::new();
        for (col, (n, t)) in all.numeric.into_iter().zip(all.text).enumerate() {
            if !kept[col] {
                continue;
            }
            names.push(all_names[col].clone());
            columns.push(if is_text[col] {
                ColumnData::Text(t)
            } else {
                ColumnData::Numeric(n)
            });
        }
        Ok(Log {
            meta,
            names,
            columns,
            rows: all.rows,
            events,
        })
    }

    /// Writes the log in the format described in the module docs.
    pub fn write_to<W: Write>(&self, w: W) -> Result<(), LogError> {
        let mut w = BufWriter::with_capacity(1 << 20, w);
        for (k, v) in &self.meta {
            writeln!(w, "# {k}: {v}")?;
        }
        writeln!(w, "{}", self.names.join(","))?;
        let mut line = String::with_capacity(256);
        let mut events = self.events.iter().peekable();
        for row in 0..=self.rows {
            while let Some(e) = events.next_if(|e| e.row <= row) {
                w.write_all(Event::line(&e.utc, &e.kind, &e.details).as_bytes())?;
            }
            if row == self.rows {
                break;
            }
            line.clear();
            for (i, c) in self.columns.iter().enumerate() {
                if i > 0 {
                    line.push(',');
                }
                match c {
                    ColumnData::Numeric(v) => push_f64(&mut line, v.get(row).copied()),
                    ColumnData::Text(t) => line.push_str(t.get(row).unwrap_or("")),
                }
            }
            line.push('\n');
            w.write_all(line.as_bytes())?;
        }
        w.flush()?;
        Ok(())
    }

    /// Writes the log to a file (created or truncated).
    pub fn write_path(&self, path: impl AsRef<Path>) -> Result<(), LogError> {
        self.write_to(File::create(path)?)
    }

    /// Reads a log from any reader (unbuffered readers get a buffer).
    pub fn read_unbuffered<R: Read>(r: R) -> Result<Self, LogError> {
        Self::read(BufReader::with_capacity(1 << 20, r))
    }
}

impl fmt::Display for Log {
    /// A one-line summary, for messages.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "log: {} rows, columns [{}]",
            self.rows,
            self.names.join(", ")
        )
    }
}

/// A refused row found by a reading worker: its line, and the rank of the check that refused it
/// in the row (0 for the reader's own rules, 1 + the column index for a field).
struct RowFault {
    line: usize,
    rank: usize,
    error: LogError,
}

/// The columns of a run of rows (one block of the file, or all of it).
struct Part {
    numeric: Vec<Vec<f64>>,
    text: Vec<TextColumn>,
    rows: usize,
    /// The first row's time stamp and line.
    first_time: Option<(f64, usize)>,
    last_t: f64,
    /// Where the rows stopped, if they stopped early.
    fault: Option<RowFault>,
    /// Event lines among the rows (`rows_before` counted within the part).
    events: Vec<reader::EventLine>,
}

impl Part {
    fn new(columns: usize) -> Self {
        Part {
            numeric: vec![Vec::new(); columns],
            text: vec![TextColumn::default(); columns],
            rows: 0,
            first_time: None,
            last_t: f64::NEG_INFINITY,
            fault: None,
            events: Vec::new(),
        }
    }
}

/// What the reading workers need to know of the header.
struct RowLayout<'a> {
    names: &'a [String],
    is_text: &'a [bool],
    kept: &'a [bool],
    time_idx: usize,
}

impl RowLayout<'_> {
    /// Parses rows until the end or the first refused one (kept in `fault`).
    #[allow(clippy::needless_range_loop)] // one column index into five parallel vectors
    fn parse(&self, rows: &mut dyn reader::RowStream) -> Part {
        let ncols = self.names.len();
        let mut part = Part::new(ncols);
        let mut text_index: Vec<HashMap<String, u32>> = vec![HashMap::new(); ncols];
        loop {
            let row = match rows.next_row() {
                Ok(Some(row)) => row,
                Ok(None) => break,
                Err(e) => {
                    part.fault = Some(RowFault {
                        // A fault without a line (I/O) comes after every line read before it.
                        line: e.line().unwrap_or(usize::MAX),
                        rank: 0,
                        error: e.into(),
                    });
                    break;
                }
            };
            let line = row.line;
            let bad = |col: usize, reason: String| RowFault {
                line,
                rank: col + 1,
                error: LogError::BadRow { line, reason },
            };
            let mut fault = None;
            for col in 0..ncols {
                if self.is_text[col] {
                    match row.text(col) {
                        Ok(s) if self.kept[col] => part.text[col].push(s, &mut text_index[col]),
                        Ok(_) => {}
                        Err(_) => {
                            fault =
                                Some(bad(col, format!("column {:?}: not UTF-8", self.names[col])));
                            break;
                        }
                    }
                    continue;
                }
                let field = row.bytes(col);
                let v = match reader::parse_number(field) {
                    Ok(v) => v,
                    Err(e) => {
                        fault = Some(bad(
                            col,
                            e.in_column(&self.names[col], &String::from_utf8_lossy(field)),
                        ));
                        break;
                    }
                };
                if col == self.time_idx {
                    if !v.is_finite() {
                        fault = Some(bad(col, "time_s is empty or not a number".into()));
                        break;
                    }
                    if part.first_time.is_none() {
                        part.first_time = Some((v, line));
                    } else if v <= part.last_t {
                        fault = Some(bad(
                            col,
                            format!("non-monotonic time: time_s {v} after {}", part.last_t),
                        ));
                        break;
                    }
                    part.last_t = v;
                }
                if self.kept[col] {
                    part.numeric[col].push(v);
                }
            }
            if fault.is_some() {
                part.fault = fault;
                break;
            }
            part.rows += 1;
        }
        part.events = rows.take_events();
        part
    }
}

/// Shortest round-trip text for a float; NaN → empty (a gap). Plain notation where it is short,
/// exponent notation for very small or large magnitudes (Display would print 1e-20 with 20 zeros).
fn push_f64(out: &mut String, v: Option<f64>) {
    use std::fmt::Write as _;
    match v {
        None => {}
        Some(v) if v.is_nan() => {}
        Some(v) => {
            let a = v.abs();
            // Writing into a String cannot fail.
            let _ = if a == 0.0 || (1e-5..1e16).contains(&a) {
                write!(out, "{v}")
            } else {
                write!(out, "{v:e}")
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = "# instrument: JN-06 A12124\n\
        # a free comment without colon\n\
        # start_utc: 2024-03-01T00:00:00Z\n\
        # input_g: 1\n\
        time_s,output_v,temperature_c,status\n\
        0,1.25,60.0,ok\n\
        1.0, 1.5 ,60.5,clamped\r\n\
        \n\
        2,,61,ok\n";

    fn gzip(bytes: &[u8]) -> Vec<u8> {
        let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        e.write_all(bytes).unwrap();
        e.finish().unwrap()
    }

    fn scratch(name: &str) -> crate::scratch::Scratch {
        crate::scratch::Scratch::new(&format!("log-{name}"))
    }

    #[test]
    fn a_csv_gz_reads_as_the_csv_it_holds() {
        let d = scratch("gz");
        std::fs::write(d.join("rec.csv"), GOOD).unwrap();
        std::fs::write(d.join("rec.csv.gz"), gzip(GOOD.as_bytes())).unwrap();
        let plain = Log::read_path(d.join("rec.csv")).unwrap();
        let gz = Log::read_path(d.join("rec.csv.gz")).unwrap();
        assert_eq!(gz.len(), 3);
        assert_eq!(gz.time_s(), plain.time_s());
        assert_eq!(gz.meta("start_utc"), Some("2024-03-01T00:00:00Z"));
        // Two gzip members (a file compressed in pieces) read as one.
        let (a, b) = GOOD.split_at(GOOD.find("1.0,").unwrap());
        let mut two = gzip(a.as_bytes());
        two.extend(gzip(b.as_bytes()));
        std::fs::write(d.join("two.csv.gz"), two).unwrap();
        assert_eq!(Log::read_path(d.join("two.csv.gz")).unwrap().len(), 3);
        // A cut compressed file is an error, not a shorter record.
        let full = gzip(GOOD.as_bytes());
        std::fs::write(d.join("cut.csv.gz"), &full[..full.len() - 12]).unwrap();
        assert!(Log::read_path(d.join("cut.csv.gz")).is_err());
    }

    #[test]
    fn a_directory_of_plain_and_compressed_days_is_one_record_but_not_a_day_twice() {
        let d = scratch("days");
        let day2 =
            "# start_utc: 2024-03-01T00:00:00Z\ntime_s,output_v,temperature_c,status\n3,2,62,ok\n";
        std::fs::write(d.join("2024-03-01.csv.gz"), gzip(GOOD.as_bytes())).unwrap();
        std::fs::write(d.join("2024-03-02.csv"), day2).unwrap();
        let log = Log::read_path(&d).unwrap();
        assert_eq!(log.time_s(), &[0.0, 1.0, 2.0, 3.0]);
        std::fs::write(d.join("2024-03-02.csv.gz"), gzip(day2.as_bytes())).unwrap();
        match Log::read_path(&d) {
            Err(LogError::Shape(m)) => assert!(
                m.contains("2024-03-02.csv and") && m.contains("2024-03-02.csv.gz"),
                "{m}"
            ),
            other => panic!("expected the day twice refused, got {other:?}"),
        }
    }

    #[test]
    fn reads_metadata_columns_gaps_and_status() {
        let log = Log::parse_str(GOOD).unwrap();
        assert_eq!(log.meta("instrument"), Some("JN-06 A12124"));
        assert_eq!(log.meta("start_utc"), Some("2024-03-01T00:00:00Z"));
        assert_eq!(log.meta_f64("input_g").unwrap(), Some(1.0));
        assert_eq!(log.meta("a free comment without colon"), None);
        assert_eq!(log.len(), 3);
        assert_eq!(log.time_s(), &[0.0, 1.0, 2.0]);
        let out = log.column("output_v").unwrap();
        assert_eq!(&out[..2], &[1.25, 1.5]);
        assert!(out[2].is_nan(), "empty cell is a gap");
        assert_eq!(log.column("temperature_c").unwrap(), &[60.0, 60.5, 61.0]);
        let st = log.text_column("status").unwrap();
        assert_eq!(st.iter().collect::<Vec<_>>(), vec!["ok", "clamped", "ok"]);
        assert_eq!(st.distinct().len(), 2);
        assert!(log.column("status").is_none(), "status is not numeric");
        assert!(log.column("pressure_hpa").is_none());
    }

    fn bad_row(s: &str) -> (usize, String) {
        match Log::parse_str(s) {
            Err(LogError::BadRow { line, reason }) => (line, reason),
            other => panic!("expected BadRow, got {other:?}"),
        }
    }

    /// `s` is refused at `line` with a reason naming every one of `words`.
    fn assert_bad_row(s: &str, line: usize, words: &[&str]) {
        let (at, reason) = bad_row(s);
        assert_eq!(at, line, "{reason}");
        for w in words {
            assert!(reason.contains(w), "{w:?} not in {reason}");
        }
    }

    #[test]
    fn wrong_column_count_is_reported_with_its_line() {
        assert_bad_row(
            "# k: v\ntime_s,output_v\n0,1\n1,2,3\n",
            4,
            &["column count"],
        );
        assert_bad_row(
            "time_s,output_v,temperature_c\n0,1,2\n1,2\n",
            3,
            &["column count"],
        );
    }

    #[test]
    fn non_numeric_field_is_reported_with_its_line_and_column() {
        assert_bad_row(
            "time_s,output_v\n0,1\n1,2\n2,1.2.3\n",
            4,
            &["output_v", "1.2.3"],
        );
        let (line, _) = bad_row("time_s,output_v\n0,inf\n");
        assert_eq!(line, 2, "infinity is not a gap");
    }

    #[test]
    fn non_monotonic_or_missing_time_is_a_bad_row() {
        assert_bad_row("time_s,output_v\n0,1\n1,2\n1,3\n", 4, &["non-monotonic"]);
        assert_bad_row(
            "time_s,output_v\n0,1\n0.5,2\n0.25,3\n",
            4,
            &["non-monotonic"],
        );
        assert_bad_row("time_s,output_v\n0,1\n,2\n", 3, &["time_s"]);
    }

    #[test]
    fn event_lines_are_kept_with_the_row_they_precede_across_blocks_and_written_back() {
        // 120 rows span many 256-byte test blocks; events before the first row, between rows
        // in different blocks, two in a row, and after the last row.
        let at = [0usize, 37, 90, 90, 120];
        let mut text = String::from("# recorder: accomp record 0.1.0\ntime_s,output_v\n");
        for i in 0..=120usize {
            for (n, _) in at.iter().enumerate().filter(|&(_, &r)| r == i) {
                text.push_str(&format!(
                    "# event: 2026-01-01T00:00:{n:02}Z kind{n} detail {n}, with a comma\n"
                ));
            }
            if i < 120 {
                text.push_str(&format!("{i},1.5\n"));
            }
        }
        let check = |log: &Log, csv_from_row: usize| {
            let ev = log.events();
            assert_eq!(ev.iter().map(|e| e.row).collect::<Vec<_>>(), at);
            for (n, e) in ev.iter().enumerate() {
                assert_eq!(e.utc, format!("2026-01-01T00:00:{n:02}Z"));
                assert_eq!(e.kind, format!("kind{n}"));
                let space = if e.row > csv_from_row { "" } else { " " };
                assert_eq!(e.details, format!("detail {n},{space}with a comma"));
            }
        };
        let log = Log::parse_str(&text).unwrap();
        assert_eq!(log.len(), 120);
        check(&log, usize::MAX);
        // The csv crate's path (a quoted field from row 50 on) keeps them at the same rows; the
        // details are its trimmed fields joined.
        let quoted = text.replacen("\n50,1.5\n", "\n50,\"1.5\"\n", 1);
        check(&Log::parse_str(&quoted).unwrap(), 50);
        // Written back in place: the text read is the text written.
        let mut out = Vec::new();
        log.write_to(&mut out).unwrap();
        assert_eq!(String::from_utf8(out).unwrap(), text);
    }

    #[test]
    fn a_log_of_many_blocks_reads_like_one_and_names_the_first_bad_line() {
        let mut text = String::from("time_s,output_v,status\n");
        for i in 0..2000u32 {
            let status = if i % 3 == 2 { "x" } else { "ok" };
            text.push_str(&format!("{i},{},{status}\n", f64::from(i) * 0.25));
        }
        let log = Log::parse_str(&text).unwrap();
        assert_eq!(log.len(), 2000);
        assert_eq!(log.time_s()[1999], 1999.0);
        assert_eq!(log.column("output_v").unwrap()[7], 1.75);
        let st = log.text_column("status").unwrap();
        assert_eq!(st.distinct(), ["ok", "x"]);
        assert_eq!(st.get(1999), Some("ok"));
        assert_eq!(st.get(2), Some("x"));
        // Only what is kept is stored; the rest is still checked.
        let sel = Log::read_selected(text.as_bytes(), &|n| n == "status").unwrap();
        assert_eq!(sel.column_names(), ["time_s", "status"]);
        let lines: Vec<&str> = text.lines().collect();
        let with = |edits: &[(usize, &str)]| {
            let mut l = lines.clone();
            for &(i, s) in edits {
                l[i - 1] = s;
            }
            l.join("\n")
        };
        // A time going back at any line, whatever block it starts: named at its line. Of two
        // faults, the first in the file.
        for at in [3, 500, 1000, 1501, 2001] {
            assert_bad_row(&with(&[(at, "-5,1,ok")]), at, &["non-monotonic"]);
        }
        assert_bad_row(&with(&[(1200, "1198.5,junk,ok"), (1700, "0,1")]), 1200, &[]);
        assert_bad_row(&with(&[(1700, "0,1,ok"), (1200, "1198,1")]), 1200, &[]);
        let sel = Log::read_selected(with(&[(900, "898,1e999,ok")]).as_bytes(), &|_| false);
        assert!(
            matches!(sel, Err(LogError::BadRow { line: 900, .. })),
            "{sel:?}"
        );
    }

    #[test]
    fn comment_after_header_is_a_bad_row() {
        assert_bad_row("time_s,output_v\n0,1\n# second log\n", 3, &[]);
    }

    #[test]
    fn header_without_time_or_outputs_is_rejected() {
        assert_err!(
            Log::parse_str("# a: b\nt,output_v\n0,1\n"),
            LogError::MissingTime { line: 2 }
        );
        assert_err!(
            Log::parse_str("time_s\n0\n"),
            LogError::NoOutputColumn { line: 1 }
        );
        assert_err!(Log::parse_str("# only: meta\n"), LogError::MissingHeader);
        assert_err!(
            Log::parse_str("time_s,a_v,a_v\n"),
            LogError::BadHeader { line: 1, .. }
        );
    }

    #[test]
    fn bad_metadata_number_is_a_named_error() {
        let log = Log::parse_str("# input_g: one\ntime_s,output_v\n0,1\n").unwrap();
        assert_err!(log.meta_f64("input_g"), LogError::BadMeta { .. });
    }

    #[test]
    fn write_then_read_round_trips_bit_for_bit() {
        let t: Vec<f64> = (0..50).map(|i| f64::from(i) * 0.54 + 0.015).collect();
        let mut log = Log::with_time(t).unwrap();
        log.set_meta("instrument", "SNJ-103").unwrap();
        log.set_meta("scale_factor_v_per_g", "1.3301").unwrap();
        let y: Vec<f64> = (0..50)
            .map(|i| match i {
                7 => f64::NAN,
                8 => 1e-300,
                9 => -3.0e20,
                _ => 1.33 + f64::from(i) * 1.234_567_890_123e-7,
            })
            .collect();
        log.push_column("output_v", y).unwrap();
        let st: Vec<&str> = (0..50)
            .map(|i| if i % 7 == 0 { "0x0003" } else { "ok" })
            .collect();
        log.push_text_column("status", TextColumn::from_strings(&st))
            .unwrap();
        let mut out = Vec::new();
        log.write_to(&mut out).unwrap();
        let back = Log::read(out.as_slice()).unwrap();
        assert_eq!(back.metadata(), log.metadata());
        assert_eq!(back.column_names(), log.column_names());
        let (a, b) = (
            log.column("output_v").unwrap(),
            back.column("output_v").unwrap(),
        );
        for (x, y) in a.iter().zip(b) {
            assert!(
                x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()),
                "{x} vs {y}"
            );
        }
        assert_eq!(back.time_s(), log.time_s());
        assert_eq!(back.text_column("status"), log.text_column("status"));
    }

    #[test]
    fn builder_rejects_mismatched_lengths_and_bad_time() {
        let mut log = Log::with_time(vec![0.0, 1.0]).unwrap();
        assert!(log.push_column("output_v", vec![1.0]).is_err());
        assert!(log.push_column("time_s", vec![1.0, 2.0]).is_err());
        assert!(log.push_column("status", vec![1.0, 2.0]).is_err());
        assert!(Log::with_time(vec![0.0, 0.0]).is_err());
    }

    #[test]
    fn the_plain_decimal_fast_path_gives_std_parse_bit_for_bit() {
        let fields = [
            "0",
            "-0",
            "+0.0",
            "1.3352596236",
            "60.291105",
            "-0.000004258458",
            "1005.620",
            "3542399.000",
            "9007199254740992",
            "9007199254740993",
            "0.1",
            "1.",
            ".5",
            "123456789012345678",
            "0.0000000000000000000001",
            "0.00000000000000000000001",
            "-1e-5",
            ".",
            "-",
            "1.2.3",
            "1,5",
            "nan",
            "inf",
        ];
        for f in fields {
            let std = f.parse::<f64>().ok();
            match reader::parse_plain_decimal(f.as_bytes()) {
                Some(v) => assert_eq!(Some(v.to_bits()), std.map(f64::to_bits), "{f}"),
                // Left to std: only what the fast path cannot do exactly, or not a decimal.
                None => assert!(
                    std.is_none()
                        || f.contains(['e', 'n', 'i'])
                        || f.trim_start_matches(['-', '+']).replace('.', "").len() > 15,
                    "{f}"
                ),
            }
        }
        // Plain decimals of every length round-trip exactly through the fast path.
        let mut x = 0.123_456_789_f64;
        for _ in 0..2000 {
            x = (x * 7.3 + 0.61).fract() * 1e4;
            let text = format!("{x}");
            let fast = reader::parse_plain_decimal(text.as_bytes());
            assert!(fast.is_none_or(|v| v.to_bits() == x.to_bits()), "{text}");
        }
    }

    #[test]
    fn unit_suffix_is_the_part_after_the_last_underscore() {
        assert_eq!(unit_suffix("temperature_c").as_deref(), Some("c"));
        assert_eq!(unit_suffix("a_i_exact_g").as_deref(), Some("g"));
        assert_eq!(unit_suffix("status"), None);
    }

    #[test]
    fn unit_suffix_takes_compound_units_whole_and_ignores_case() {
        assert_eq!(unit_suffix("gravity_m_s2").as_deref(), Some("m_s2"));
        assert_eq!(unit_suffix("gravity_nm_s2").as_deref(), Some("nm_s2"));
        assert_eq!(unit_suffix("output_V").as_deref(), Some("v"));
        assert_eq!(unit_suffix("Tilt_ARCSEC").as_deref(), Some("arcsec"));
        for u in GRAVITY_UNITS {
            let name = format!("gravity_{u}");
            assert_eq!(unit_suffix(&name).as_deref(), Some(u), "{name}");
            assert!(unit_per_g_for_suffix(u).is_some(), "{u}");
        }
    }
}
