//! The one reader of the project's CSV files: `# key: value` metadata, one header row, then rows.
//!
//! Every command reads through it — stability logs ([`super::Log`]), Table 1 and the printed
//! models (`fit`), tumble logs (`tumble`), `compensate` sample files (`device::samples_csv`) — so
//! the rules below hold everywhere, and every error names its 1-based line (comments included):
//!
//! - A UTF-8 byte-order mark at the very start of the file is stripped (spreadsheet exports
//!   write one; it would otherwise glue itself to the first key or column name).
//! - Before the header, a line starting with `#` is metadata when it reads `# key: value` (the
//!   first `:` splits; key and value trimmed; an empty key makes it a comment) and a free comment
//!   otherwise. **A repeated key is refused** ([`ReadError::RepeatedMeta`], both lines named):
//!   one file with two values for `input_g` is usually two files pasted together, and which one
//!   wins would otherwise depend on the reader.
//! - The first other non-blank line is the header: comma-separated names, none empty, none
//!   repeated. Fields are parsed by the `csv` crate (RFC 4180 quoting), trimmed of whitespace.
//! - Then one record per line, exactly as many fields as the header. Blank lines are skipped; a
//!   `#` line after the header is refused ([`ReadError::CommentAfterHeader`]) unless it is an
//!   event line, `# event: <UTC> <kind> <details>` (what `accomp record` writes in place for a
//!   gap, a reset, a reconnection …; not a record: the rows around it are the data, and the line is
//!   kept with the number of records before it, [`RowStream::take_events`]): a comment in the
//!   middle of the samples means two logs were concatenated.
//!
//! What a field means (number, gap, text) is the caller's business: [`Row`] hands out the
//! trimmed bytes or text of each field with the line they came from.

use std::collections::VecDeque;
use std::io::{BufRead, Chain, Cursor, Read};

/// The start of an event line, allowed among the rows ([`crate::Event::line`] writes it).
pub const EVENT_PREFIX: &[u8] = crate::EVENT_LINE_PREFIX.as_bytes();

/// An event line met among the records (`# event: <UTC> <kind> <details>`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EventLine {
    /// 1-based line in the file.
    pub line: usize,
    /// Records the stream handed out before it (the index of the first record after it).
    pub rows_before: usize,
    /// The line after `# event:`, trimmed.
    pub text: String,
}

/// The event lines a stream met, and the records it handed out so far.
#[derive(Debug, Default)]
struct Events {
    lines: Vec<EventLine>,
    rows: usize,
}

impl Events {
    /// Keeps `text` (a whole line, or its fields joined) when it is an event line: true then.
    fn keep(&mut self, line: usize, text: &[u8]) -> bool {
        let Some(rest) = text.trim_ascii_start().strip_prefix(EVENT_PREFIX) else {
            return false;
        };
        self.lines.push(EventLine {
            line,
            rows_before: self.rows,
            text: String::from_utf8_lossy(rest).trim().to_owned(),
        });
        true
    }
}

/// The UTF-8 byte-order mark.
const BOM: &[u8] = b"\xEF\xBB\xBF";

/// Why a file is refused, with the 1-based line where it happened.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// The file could not be read.
    #[error("I/O: {0}")]
    Io(#[from] std::io::Error),
    /// The file ended before a header row.
    #[error("no header row (the file holds only comments and blank lines)")]
    NoHeader,
    /// A line is not UTF-8.
    #[error("line {line}: not UTF-8")]
    NotUtf8 {
        /// 1-based line.
        line: usize,
    },
    /// A metadata key appears twice before the header.
    #[error("line {line}: metadata key `{key}` repeated (first given on line {first_line})")]
    RepeatedMeta {
        /// The key.
        key: String,
        /// Line of the repetition.
        line: usize,
        /// Line of the first occurrence.
        first_line: usize,
    },
    /// The header is malformed.
    #[error("header (line {line}): {reason}")]
    BadHeader {
        /// Header line.
        line: usize,
        /// What is wrong with it.
        reason: String,
    },
    /// A column the caller requires is not in the header.
    #[error("header (line {line}) has no `{column}` column")]
    MissingColumn {
        /// Header line.
        line: usize,
        /// The column.
        column: String,
    },
    /// A record has more or fewer fields than the header.
    #[error("line {line}: wrong column count: {found} fields, header has {expected}")]
    FieldCount {
        /// 1-based line.
        line: usize,
        /// Fields in the header.
        expected: usize,
        /// Fields in this record.
        found: usize,
    },
    /// A `#` line after the header.
    #[error("line {line}: comment line after the header (two files concatenated?)")]
    CommentAfterHeader {
        /// 1-based line.
        line: usize,
    },
    /// The file is UTF-16 (with or without its byte-order mark): every other byte of its text
    /// is NUL. Read as UTF-8 it would be garbage; said as such.
    #[error("line {line}: the file is UTF-16 text ({endian}), not UTF-8: save it as UTF-8 (or CSV UTF-8)")]
    Utf16 {
        /// 1-based line.
        line: usize,
        /// "little-endian" or "big-endian".
        endian: &'static str,
    },
    /// A line longer than any record: not a log (`/dev/zero`, a binary file).
    #[error("line {line}: longer than {limit} bytes, the limit of one line: not a log")]
    LineTooLong {
        /// 1-based line.
        line: usize,
        /// [`MAX_LINE_BYTES`].
        limit: usize,
    },
    /// More lines or bytes than the reader takes.
    #[error("{what}, above the limit of {limit}: refused (--allow-large lifts it)")]
    TooLarge {
        /// 1-based line where the limit was passed.
        line: usize,
        /// "more than N data lines", "more than N bytes".
        what: String,
        /// The limit, with its unit.
        limit: String,
    },
    /// A field is not what its column holds (an infinity, junk, nothing where a value is
    /// required): [`Row::number`].
    #[error("line {line}: {reason}")]
    Field {
        /// 1-based line.
        line: usize,
        /// Column, text and what is wrong.
        reason: String,
    },
    /// The CSV layer refused the record (e.g. an unterminated quote).
    #[error("line {line}: {reason}")]
    Csv {
        /// 1-based line.
        line: usize,
        /// What the csv crate said.
        reason: String,
    },
}

impl ReadError {
    /// What is wrong, without the line number (for callers that print the line themselves).
    pub fn what(&self) -> String {
        match self {
            Self::NotUtf8 { .. } => "not UTF-8".into(),
            Self::RepeatedMeta {
                key, first_line, ..
            } => format!("metadata key `{key}` repeated (first given on line {first_line})"),
            Self::BadHeader { reason, .. }
            | Self::Csv { reason, .. }
            | Self::Field { reason, .. } => reason.clone(),
            Self::MissingColumn { column, .. } => format!("header has no `{column}` column"),
            Self::FieldCount {
                expected, found, ..
            } => format!("wrong column count: {found} fields, header has {expected}"),
            Self::CommentAfterHeader { .. } => {
                "comment line after the header (two files concatenated?)".into()
            }
            Self::Utf16 { endian, .. } => {
                format!("the file is UTF-16 text ({endian}), not UTF-8: save it as UTF-8")
            }
            Self::LineTooLong { limit, .. } => {
                format!("longer than {limit} bytes, the limit of one line: not a log")
            }
            Self::TooLarge { what, limit, .. } => {
                format!("{what}, above the limit of {limit}: refused (--allow-large lifts it)")
            }
            Self::Io(_) | Self::NoHeader => self.to_string(),
        }
    }

    /// As an I/O error (for readers whose errors carry one), the message kept.
    pub fn into_io(self) -> std::io::Error {
        match self {
            Self::Io(e) => e,
            other => std::io::Error::other(other.to_string()),
        }
    }

    /// The line the error points at, if any.
    pub fn line(&self) -> Option<usize> {
        match self {
            Self::Io(_) | Self::NoHeader => None,
            Self::NotUtf8 { line }
            | Self::RepeatedMeta { line, .. }
            | Self::BadHeader { line, .. }
            | Self::MissingColumn { line, .. }
            | Self::FieldCount { line, .. }
            | Self::CommentAfterHeader { line }
            | Self::LineTooLong { line, .. }
            | Self::TooLarge { line, .. }
            | Self::Utf16 { line, .. }
            | Self::Field { line, .. }
            | Self::Csv { line, .. } => Some(*line),
        }
    }
}

/// Why a numeric field is refused ([`parse_number`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NumberError {
    /// `inf`, `-inf`, `infinity`, or a number beyond the range of an f64 (`1e400`, which
    /// parses as one): no measurement, and it would turn every statistic into ±inf.
    Infinite,
    /// Not a number at all.
    NotANumber,
    /// Empty or NaN where the caller needs a value ([`parse_required_number`]).
    Missing,
}

impl NumberError {
    /// The refusal in words, naming the column and the text.
    pub fn in_column(self, column: &str, text: &str) -> String {
        match self {
            Self::Infinite => format!(
                "column {column:?}: {text:?} is infinite (or beyond an f64): refused (a missing \
                 reading is an empty field or NaN)"
            ),
            Self::NotANumber => format!("column {column:?}: non-numeric field {text:?}"),
            Self::Missing => format!("column {column:?}: {text:?} where a value is required"),
        }
    }
}

/// Parses one numeric field, as every reader of the project does: empty or NaN → NaN (a missing
/// reading); ±inf (and a number beyond an f64) and junk are refused.
///
/// std's `f64::from_str` is an Eisel–Lemire implementation (correctly rounded, ~20 ns per field),
/// which is why no float-parsing crate is pulled in; the bytes are ASCII-checked by it.
pub fn parse_number(field: &[u8]) -> Result<f64, NumberError> {
    if field.is_empty() {
        return Ok(f64::NAN);
    }
    if let Some(v) = parse_plain_decimal(field) {
        return Ok(v);
    }
    // Safe to view as str only if UTF-8; numbers are ASCII, anything else is junk anyway.
    let s = std::str::from_utf8(field).map_err(|_| NumberError::NotANumber)?;
    match s.parse::<f64>() {
        Ok(v) if v.is_infinite() => Err(NumberError::Infinite),
        Ok(v) => Ok(v),
        Err(_) => Err(NumberError::NotANumber),
    }
}

/// [`parse_number`] where a value is required (a time stamp, a table entry): empty or NaN is
/// refused too.
pub fn parse_required_number(field: &[u8]) -> Result<f64, NumberError> {
    match parse_number(field)? {
        v if v.is_nan() => Err(NumberError::Missing),
        v => Ok(v),
    }
}

/// Powers of ten an f64 holds exactly.
const EXACT_POWERS_OF_TEN: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
];

/// The value of a plain decimal (`[+-]digits[.digits]`, what logs hold) whose digits make an
/// integer m ≤ 2⁵³ with at most 22 after the point — `None` for anything else (std's parser
/// takes it). m and 10^k are then exact f64s and one IEEE division rounds m/10^k correctly:
/// bit for bit what `f64::from_str` returns (Clinger's fast path, which std takes too after
/// its general scan; here without the UTF-8 check and the scan, about 4× faster).
pub(crate) fn parse_plain_decimal(field: &[u8]) -> Option<f64> {
    let (negative, digits) = match field.split_first() {
        Some((b'-', rest)) => (true, rest),
        Some((b'+', rest)) => (false, rest),
        _ => (false, field),
    };
    let (mut m, mut after_point, mut any, mut point) = (0u64, 0usize, false, false);
    for &c in digits {
        match c {
            b'0'..=b'9' => {
                m = m * 10 + u64::from(c - b'0');
                if m > 1 << 53 {
                    return None;
                }
                any = true;
                after_point += usize::from(point);
            }
            b'.' if !point => point = true,
            _ => return None,
        }
    }
    if !any {
        return None;
    }
    let v = m as f64 / *EXACT_POWERS_OF_TEN.get(after_point)?;
    Some(if negative { -v } else { v })
}

/// The longest line any reader takes (a log's record is a few hundred bytes): `/dev/zero` or a
/// binary file is refused after this much, not read until memory runs out.
pub const MAX_LINE_BYTES: usize = 1 << 20;
/// Data lines a file may have without `--allow-large`: what `accomp simulate` writes without it
/// (231 days at 1 s).
pub const MAX_ROWS: u64 = 20_000_000;
/// Bytes a file may have without `--allow-large`: what `accomp simulate` writes without it.
pub const MAX_FILE_BYTES: u64 = 4 << 30;
/// Bytes of metadata and comments before the header.
const MAX_PREAMBLE_BYTES: usize = 16 << 20;

/// Whether this process reads files above [`MAX_ROWS`] / [`MAX_FILE_BYTES`] (`--allow-large`).
static ALLOW_LARGE: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Lifts the row and byte limits of every reader of this process (the commands'
/// `--allow-large`); the line limit stays.
pub fn set_allow_large(allow: bool) {
    ALLOW_LARGE.store(allow, std::sync::atomic::Ordering::Relaxed);
}

/// The (rows, bytes) limits in force.
pub fn limits() -> (u64, u64) {
    if ALLOW_LARGE.load(std::sync::atomic::Ordering::Relaxed) {
        (u64::MAX, u64::MAX)
    } else {
        (MAX_ROWS, MAX_FILE_BYTES)
    }
}

fn too_many_bytes(line: usize, bytes: u64) -> ReadError {
    ReadError::TooLarge {
        line,
        what: format!("more than {bytes} bytes read by line {line}"),
        limit: format!("{} bytes", limits().1),
    }
}

/// Refuses a file whose size alone is above the byte limit, before anything is read.
pub fn check_file_size(path: &std::path::Path) -> Result<(), ReadError> {
    let len = std::fs::metadata(path)?.len();
    let (_, max) = limits();
    if len > max {
        return Err(ReadError::TooLarge {
            line: 0,
            what: format!("{}: {len} bytes", path.display()),
            limit: format!("{max} bytes"),
        });
    }
    Ok(())
}

/// Bytes of the small text files read whole (Table 1 and model CSVs, tumble logs).
pub const MAX_SMALL_TEXT_BYTES: u64 = 64 << 20;

/// Reads a whole text file of at most `max_bytes` (no limit under `--allow-large`), line by line
/// with no line longer than [`MAX_LINE_BYTES`]: for the small files read whole (tables, tumble
/// logs, sample files), so that `/dev/zero` or a huge file is refused with the limit named
/// instead of filling memory.
pub fn read_text_limited(path: &std::path::Path, max_bytes: u64) -> Result<String, ReadError> {
    let max_bytes = if ALLOW_LARGE.load(std::sync::atomic::Ordering::Relaxed) {
        u64::MAX
    } else {
        max_bytes
    };
    let f = std::fs::File::open(path)?;
    let len = f.metadata()?.len();
    if len > max_bytes {
        return Err(ReadError::TooLarge {
            line: 0,
            what: format!("{}: {len} bytes", path.display()),
            limit: format!("{max_bytes} bytes"),
        });
    }
    let mut r = std::io::BufReader::with_capacity(1 << 16, f);
    let mut all = Vec::new();
    let mut line = 0usize;
    loop {
        let n = (&mut r)
            .take(MAX_LINE_BYTES as u64 + 1)
            .read_until(b'\n', &mut all)?;
        if n == 0 {
            break;
        }
        line += 1;
        if line == 1 {
            if let Some(endian) = utf16_endianness(&all) {
                return Err(ReadError::Utf16 { line, endian });
            }
        }
        if n > MAX_LINE_BYTES && all.last() != Some(&b'\n') {
            return Err(ReadError::LineTooLong {
                line,
                limit: MAX_LINE_BYTES,
            });
        }
        if all.len() as u64 > max_bytes {
            return Err(ReadError::TooLarge {
                line,
                what: format!("more than {max_bytes} bytes by line {line}"),
                limit: format!("{max_bytes} bytes"),
            });
        }
    }
    String::from_utf8(all).map_err(|e| {
        let at = e.utf8_error().valid_up_to();
        let bytes = e.as_bytes();
        ReadError::NotUtf8 {
            line: 1 + memchr::memchr_iter(b'\n', &bytes[..at]).count(),
        }
    })
}

/// Whether a line is UTF-16 text: a UTF-16 byte-order mark, or (without one) NUL in every
/// other byte of a line of ASCII text — which no UTF-8 log has (a UTF-8 text holds no NUL).
/// Returns the byte order.
fn utf16_endianness(line: &[u8]) -> Option<&'static str> {
    if line.starts_with(b"\xFF\xFE") {
        return Some("little-endian");
    }
    if line.starts_with(b"\xFE\xFF") {
        return Some("big-endian");
    }
    let text = line.strip_suffix(b"\n").unwrap_or(line);
    let text = text.strip_suffix(b"\0").unwrap_or(text);
    if text.len() < 2 || !text.contains(&0) {
        return None;
    }
    let even_nul = text.iter().step_by(2).all(|&b| b == 0);
    let odd_nul = text.iter().skip(1).step_by(2).all(|&b| b == 0);
    match (even_nul, odd_nul) {
        (false, true) => Some("little-endian"),
        (true, false) => Some("big-endian"),
        _ => None,
    }
}

/// Bytes of complete lines one worker of [`Records::for_each_block`] parses at a time.
/// (A few lines in the unit tests, so that their logs span many blocks.)
const BLOCK_BYTES: usize = if cfg!(test) { 256 } else { 4 << 20 };
/// Bytes asked of the underlying reader per read while lines are split here.
const READ_BYTES: usize = 1 << 20;

/// An open file: metadata and header read, records on demand.
///
/// Lines without a quote are split on commas here (what the csv crate makes of such a line,
/// without its per-record buffer work); from the first line with a quote (or a carriage return
/// that does not end the line) on, the csv crate reads the rest (RFC 4180 quoting, quoted
/// fields across lines). Both give the same fields and the same line numbers.
pub struct Records<R: Read> {
    meta: Vec<(String, String)>,
    header: Vec<String>,
    header_line: usize,
    source: Source<R>,
    /// Trimmed field bounds of the current line (split lines).
    bounds: Vec<(usize, usize)>,
    /// The current record (csv crate).
    record: csv::ByteRecord,
    /// Event lines met, and the records handed out.
    events: Events,
}

/// Where the records come from.
enum Source<R: Read> {
    /// Every data line so far was free of quotes and stray carriage returns.
    Lines(Lines<R>),
    /// The csv crate, from the first line that needs it.
    Csv(CsvSource<R>),
    /// Only while switching from one to the other.
    Switching,
}

/// The csv crate's reader over the rest of the file.
struct CsvSource<R: Read> {
    csv: csv::Reader<NewlineOffsets<Chain<Cursor<Vec<u8>>, R>>>,
    /// File line of the csv stream's first byte.
    first_line: usize,
    /// Newlines of the csv stream before the current record.
    newlines_before: usize,
    /// The last file line the row limit allows.
    last_line: usize,
}

/// The last file line the row limit allows after a header on `header_line`.
fn last_line(header_line: usize) -> usize {
    usize::try_from(limits().0)
        .unwrap_or(usize::MAX)
        .saturating_add(header_line)
}

fn too_many_rows(line: usize) -> ReadError {
    ReadError::TooLarge {
        line,
        what: format!("more than {} data lines (line {line})", limits().0),
        limit: format!("{} data lines", limits().0),
    }
}

/// Raw lines of the data section, read in large pieces.
struct Lines<R> {
    r: R,
    buf: Vec<u8>,
    /// Start of the unread bytes of `buf`.
    pos: usize,
    /// File line of the line starting at `pos`.
    line: usize,
    eof: bool,
    /// Bytes of the file read so far (for the byte limit).
    read: u64,
    /// The last file line the row limit allows.
    last_line: usize,
}

impl<R: Read> Lines<R> {
    /// Appends up to [`READ_BYTES`] to `buf` (after dropping the bytes before `pos`).
    fn refill(&mut self) -> Result<(), ReadError> {
        if self.pos > 0 {
            self.buf.drain(..self.pos);
            self.pos = 0;
        }
        let old = self.buf.len();
        self.buf.resize(old + READ_BYTES, 0);
        let n = loop {
            match self.r.read(&mut self.buf[old..]) {
                Ok(n) => break n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(e) => {
                    self.buf.truncate(old);
                    return Err(e.into());
                }
            }
        };
        self.buf.truncate(old + n);
        self.eof = n == 0;
        self.read += n as u64;
        if self.read > limits().1 {
            return Err(too_many_bytes(self.line, self.read));
        }
        Ok(())
    }

    /// The end (index of its `\n`, or the end of the file) of the line at `pos`; `None` at the
    /// end of the file. A line longer than [`MAX_LINE_BYTES`] is refused.
    fn line_end(&mut self) -> Result<Option<usize>, ReadError> {
        let mut scanned = 0;
        loop {
            let from = self.pos + scanned;
            if let Some(i) = memchr::memchr(b'\n', &self.buf[from..]) {
                if from + i - self.pos > MAX_LINE_BYTES {
                    break;
                }
                return Ok(Some(from + i));
            }
            if self.eof {
                return Ok((self.pos < self.buf.len()).then_some(self.buf.len()));
            }
            scanned = self.buf.len() - self.pos;
            if scanned > MAX_LINE_BYTES {
                break;
            }
            self.refill()?;
        }
        Err(ReadError::LineTooLong {
            line: self.line,
            limit: MAX_LINE_BYTES,
        })
    }
}

/// Splits one line (without its `\n`) on commas into trimmed field bounds, exactly as the csv
/// crate does a line without quotes: `None` when the line has a quote or a carriage return
/// before its end (the csv crate's rules apply from there), `Some(false)` for an empty line
/// (which the csv crate skips), `Some(true)` for a record.
fn split_line(line: &[u8], bounds: &mut Vec<(usize, usize)>) -> Option<bool> {
    let line = line.strip_suffix(b"\r").unwrap_or(line);
    if line.is_empty() {
        return Some(false);
    }
    if memchr::memchr2(b'"', b'\r', line).is_some() {
        return None;
    }
    bounds.clear();
    let mut start = 0;
    for end in memchr::memchr_iter(b',', line).chain(std::iter::once(line.len())) {
        let (mut a, mut b) = (start, end);
        while a < b && line[a].is_ascii_whitespace() {
            a += 1;
        }
        while b > a && line[b - 1].is_ascii_whitespace() {
            b -= 1;
        }
        bounds.push((a, b));
        start = end + 1;
    }
    Some(true)
}

/// True when every line of `bytes` can be split by [`split_line`]: no quote, and every
/// carriage return ends a line (or the bytes).
fn splittable(bytes: &[u8]) -> bool {
    memchr::memchr(b'"', bytes).is_none()
        && memchr::memchr_iter(b'\r', bytes).all(|i| bytes.get(i + 1).is_none_or(|&b| b == b'\n'))
}

/// The rules every record passes, whoever split it: no `#` line after the header, a line of
/// spaces is blank (`Ok(false)`: skipped), exactly as many fields as the header.
fn check_record(
    line: usize,
    first: &[u8],
    fields: usize,
    expected: usize,
) -> Result<bool, ReadError> {
    if first.starts_with(EVENT_PREFIX) {
        return Ok(false);
    }
    if first.starts_with(b"#") {
        return Err(ReadError::CommentAfterHeader { line });
    }
    if fields == 1 && first.is_empty() {
        return Ok(false);
    }
    if fields != expected {
        return Err(ReadError::FieldCount {
            line,
            expected,
            found: fields,
        });
    }
    Ok(true)
}

/// The csv crate's reader over `start` then `r`; `before`: bytes of the file before `start`.
fn csv_reader<R: Read>(
    start: Vec<u8>,
    r: R,
    before: u64,
) -> csv::Reader<NewlineOffsets<Chain<Cursor<Vec<u8>>, R>>> {
    csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .trim(csv::Trim::All)
        .from_reader(NewlineOffsets {
            inner: Cursor::new(start).chain(r),
            offset: 0,
            pending: VecDeque::new(),
            before,
            since_newline: 0,
        })
}

/// Remembers the byte offsets of the newlines that pass through, so that a record's byte
/// position gives its line exactly: csv's own line counter skips blank lines. Only the newlines
/// read ahead of the current record are kept (a buffer's worth).
/// Also where the csv crate's reading is bounded: no line (a quoted field included) longer
/// than [`MAX_LINE_BYTES`], no more than the byte limit in all.
struct NewlineOffsets<R> {
    inner: R,
    offset: u64,
    pending: VecDeque<u64>,
    /// Bytes of the file before this stream.
    before: u64,
    /// Bytes since the last newline.
    since_newline: usize,
}

impl<R: Read> Read for NewlineOffsets<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        let mut last = None;
        for i in memchr::memchr_iter(b'\n', &buf[..n]) {
            self.pending.push_back(self.offset + i as u64);
            last = Some(i);
        }
        self.since_newline = match last {
            Some(i) => n - i - 1,
            None => self.since_newline + n,
        };
        self.offset += n as u64;
        if self.since_newline > MAX_LINE_BYTES {
            return Err(std::io::Error::other(format!(
                "a line longer than {MAX_LINE_BYTES} bytes, the limit of one line: not a log"
            )));
        }
        let total = self.before + self.offset;
        if total > limits().1 {
            return Err(std::io::Error::other(format!(
                "more than {total} bytes, above the limit of {} bytes (--allow-large lifts it)",
                limits().1
            )));
        }
        Ok(n)
    }
}

/// The fields of one record.
#[derive(Debug, Clone, Copy)]
enum Fields<'a> {
    /// Split here: the line and the trimmed bounds of its fields.
    Split {
        line: &'a [u8],
        bounds: &'a [(usize, usize)],
    },
    /// Read by the csv crate (trimmed).
    Csv(&'a csv::ByteRecord),
}

/// One record and the line it starts on.
#[derive(Debug, Clone, Copy)]
pub struct Row<'a> {
    /// 1-based line in the file.
    pub line: usize,
    fields: Fields<'a>,
}

impl<'a> Row<'a> {
    /// Number of fields (always the header's).
    pub fn len(&self) -> usize {
        match self.fields {
            Fields::Split { bounds, .. } => bounds.len(),
            Fields::Csv(r) => r.len(),
        }
    }

    /// True for a record without fields (never returned by [`Records::next_row`]).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The trimmed bytes of field `i` (empty past the end).
    pub fn bytes(&self, i: usize) -> &'a [u8] {
        match self.fields {
            Fields::Split { line, bounds } => bounds.get(i).map_or(b"", |&(a, b)| &line[a..b]),
            Fields::Csv(r) => r.get(i).unwrap_or(b""),
        }
    }

    /// The trimmed text of field `i`.
    pub fn text(&self, i: usize) -> Result<&'a str, ReadError> {
        std::str::from_utf8(self.bytes(i)).map_err(|_| ReadError::NotUtf8 { line: self.line })
    }

    /// Field `i` of column `column` as a number ([`parse_number`]: NaN for a missing reading);
    /// a refusal names the line, the column and the text.
    pub fn number(&self, i: usize, column: &str) -> Result<f64, ReadError> {
        self.checked(i, column, parse_number)
    }

    /// Field `i` of column `column` as a number that must be there
    /// ([`parse_required_number`]).
    pub fn required_number(&self, i: usize, column: &str) -> Result<f64, ReadError> {
        self.checked(i, column, parse_required_number)
    }

    fn checked(
        &self,
        i: usize,
        column: &str,
        parse: fn(&[u8]) -> Result<f64, NumberError>,
    ) -> Result<f64, ReadError> {
        let field = self.bytes(i);
        parse(field).map_err(|e| ReadError::Field {
            line: self.line,
            reason: e.in_column(column, &String::from_utf8_lossy(field)),
        })
    }
}

/// Something that hands out records in file order: an open file ([`Records`]) or one block of
/// it ([`BlockRows`], on a worker thread of [`Records::for_each_block`]).
pub trait RowStream {
    /// The next record, `None` at the end.
    fn next_row(&mut self) -> Result<Option<Row<'_>>, ReadError>;
    /// The event lines met so far (taken out), each with the number of records this stream
    /// handed out before it.
    fn take_events(&mut self) -> Vec<EventLine>;
}

/// Complete data lines, none needing the csv crate, with the file line of the first.
struct Block {
    bytes: Vec<u8>,
    first_line: usize,
}

impl Block {
    fn rows(&self, expected: usize) -> BlockRows<'_> {
        BlockRows {
            bytes: &self.bytes,
            pos: 0,
            line: self.first_line,
            expected,
            bounds: Vec::new(),
            events: Events::default(),
        }
    }
}

/// The records of one block.
pub struct BlockRows<'a> {
    bytes: &'a [u8],
    pos: usize,
    line: usize,
    expected: usize,
    bounds: Vec<(usize, usize)>,
    events: Events,
}

impl RowStream for BlockRows<'_> {
    fn take_events(&mut self) -> Vec<EventLine> {
        std::mem::take(&mut self.events.lines)
    }

    fn next_row(&mut self) -> Result<Option<Row<'_>>, ReadError> {
        while self.pos < self.bytes.len() {
            let rest = &self.bytes[self.pos..];
            let len = memchr::memchr(b'\n', rest).unwrap_or(rest.len());
            let text = &rest[..len];
            let line = self.line;
            self.pos += len + 1;
            self.line += 1;
            match split_line(text, &mut self.bounds) {
                Some(true) => {}
                Some(false) => continue,
                // `splittable` was checked on the whole block.
                None => {
                    return Err(ReadError::Csv {
                        line,
                        reason: "a quote in a block that was checked to have none".into(),
                    })
                }
            }
            let first = self.bounds.first().map_or(&b""[..], |&(a, b)| &text[a..b]);
            if first.starts_with(EVENT_PREFIX) && self.events.keep(line, text) {
                continue;
            }
            if check_record(line, first, self.bounds.len(), self.expected)? {
                self.events.rows += 1;
                return Ok(Some(Row {
                    line,
                    fields: Fields::Split {
                        line: text,
                        bounds: &self.bounds,
                    },
                }));
            }
        }
        Ok(None)
    }
}

/// What follows the blocks [`Records::take_blocks`] took.
enum After {
    /// Maybe more blocks.
    More,
    /// The end of the file.
    End,
    /// Lines that need the csv crate.
    Sequential,
    /// The file could not be read on.
    Failed(ReadError),
}

/// What [`Records::take_block`] found.
enum Taken {
    Block(Block),
    /// The file is read.
    End,
    /// The next lines need the csv crate (or a line is longer than a block): read on.
    Sequential,
}

impl<'s> Records<&'s [u8]> {
    /// Opens a file held in a string.
    pub fn from_text(text: &'s str) -> Result<Self, ReadError> {
        Self::new(text.as_bytes())
    }
}

impl<R: BufRead> Records<R> {
    /// Reads the metadata and the header; records follow with [`Records::next_row`].
    pub fn new(mut r: R) -> Result<Self, ReadError> {
        let mut buf = Vec::with_capacity(256);
        let mut line = 0usize;
        let mut meta: Vec<(String, String, usize)> = Vec::new();
        let mut preamble = 0usize;
        let header_bytes = loop {
            buf.clear();
            let n = (&mut r)
                .take(MAX_LINE_BYTES as u64 + 1)
                .read_until(b'\n', &mut buf)?;
            if n == 0 {
                return Err(ReadError::NoHeader);
            }
            line += 1;
            if n > MAX_LINE_BYTES && buf.last() != Some(&b'\n') {
                return Err(ReadError::LineTooLong {
                    line,
                    limit: MAX_LINE_BYTES,
                });
            }
            preamble += n;
            if preamble > MAX_PREAMBLE_BYTES {
                return Err(ReadError::Csv {
                    line,
                    reason: format!(
                        "no header row in the first {MAX_PREAMBLE_BYTES} bytes (the limit of \
                         metadata and comments)"
                    ),
                });
            }
            let bytes = if line == 1 {
                buf.strip_prefix(BOM).unwrap_or(&buf)
            } else {
                &buf[..]
            };
            if let Some(endian) = utf16_endianness(bytes) {
                return Err(ReadError::Utf16 { line, endian });
            }
            if bytes.iter().all(u8::is_ascii_whitespace) {
                continue;
            }
            let text = std::str::from_utf8(bytes).map_err(|_| ReadError::NotUtf8 { line })?;
            let text = text.trim();
            let Some(comment) = text.strip_prefix('#') else {
                break bytes.to_vec();
            };
            let Some((k, v)) = comment.split_once(':') else {
                continue;
            };
            let k = k.trim();
            if k.is_empty() {
                continue;
            }
            if let Some((_, _, first_line)) = meta.iter().find(|(mk, ..)| mk == k) {
                return Err(ReadError::RepeatedMeta {
                    key: k.to_owned(),
                    line,
                    first_line: *first_line,
                });
            }
            meta.push((k.to_owned(), v.trim().to_owned(), line));
        };
        let header_line = line;
        let mut bounds = Vec::new();
        let mut record = csv::ByteRecord::new();
        let header_text = header_bytes.strip_suffix(b"\n").unwrap_or(&header_bytes);
        let (names, source): (Vec<&[u8]>, Source<R>) = match split_line(header_text, &mut bounds) {
            Some(_) => (
                bounds.iter().map(|&(a, b)| &header_text[a..b]).collect(),
                Source::Lines(Lines {
                    r,
                    buf: Vec::new(),
                    pos: 0,
                    line: header_line + 1,
                    eof: false,
                    read: preamble as u64,
                    last_line: last_line(header_line),
                }),
            ),
            None => {
                // A quoted header: the csv crate reads it and everything after.
                let mut csv = csv_reader(header_bytes.clone(), r, preamble as u64);
                let more = csv
                    .read_byte_record(&mut record)
                    .map_err(|e| ReadError::Csv {
                        line: header_line,
                        reason: e.to_string(),
                    })?;
                if !more {
                    return Err(ReadError::NoHeader);
                }
                (
                    record.iter().collect(),
                    Source::Csv(CsvSource {
                        csv,
                        first_line: header_line,
                        newlines_before: 0,
                        last_line: last_line(header_line),
                    }),
                )
            }
        };
        let mut header = Vec::with_capacity(names.len());
        for (i, name) in names.into_iter().enumerate() {
            let name = std::str::from_utf8(name)
                .map_err(|_| ReadError::NotUtf8 { line: header_line })?
                .to_owned();
            if name.is_empty() {
                return Err(ReadError::BadHeader {
                    line: header_line,
                    reason: format!("column {} has an empty name", i + 1),
                });
            }
            if header.contains(&name) {
                return Err(ReadError::BadHeader {
                    line: header_line,
                    reason: format!("duplicate column {name:?}"),
                });
            }
            header.push(name);
        }
        Ok(Self {
            meta: meta.into_iter().map(|(k, v, _)| (k, v)).collect(),
            header,
            header_line,
            source,
            bounds,
            record: csv::ByteRecord::new(),
            events: Events::default(),
        })
    }

    /// `# key: value` metadata in file order (keys unique).
    pub fn meta(&self) -> &[(String, String)] {
        &self.meta
    }

    /// The value of one metadata key.
    pub fn meta_value(&self, key: &str) -> Option<&str> {
        self.meta
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    /// Takes the metadata out (the records stay readable).
    pub fn take_meta(&mut self) -> Vec<(String, String)> {
        std::mem::take(&mut self.meta)
    }

    /// The column names.
    pub fn header(&self) -> &[String] {
        &self.header
    }

    /// 1-based line of the header.
    pub fn header_line(&self) -> usize {
        self.header_line
    }

    /// Index of a column, if present.
    pub fn column(&self, name: &str) -> Option<usize> {
        self.header.iter().position(|c| c == name)
    }

    /// Index of a column the caller cannot do without.
    pub fn require(&self, name: &str) -> Result<usize, ReadError> {
        self.column(name).ok_or_else(|| ReadError::MissingColumn {
            line: self.header_line,
            column: name.to_owned(),
        })
    }

    /// Hands the rest of the file, from the line at the split position on, to the csv crate.
    fn switch_to_csv(&mut self) {
        if let Source::Lines(l) = std::mem::replace(&mut self.source, Source::Switching) {
            let rest = l.buf[l.pos..].to_vec();
            let before = l.read - rest.len() as u64;
            self.source = Source::Csv(CsvSource {
                csv: csv_reader(rest, l.r, before),
                first_line: l.line,
                newlines_before: 0,
                last_line: l.last_line,
            });
        }
    }

    /// Takes the next [`BLOCK_BYTES`] or so of whole lines if none of them needs the csv crate.
    fn take_block(&mut self) -> Result<Taken, ReadError> {
        let Source::Lines(l) = &mut self.source else {
            return Ok(Taken::Sequential);
        };
        while l.buf.len() - l.pos < BLOCK_BYTES && !l.eof {
            l.refill()?;
        }
        let avail = &l.buf[l.pos..];
        if avail.is_empty() {
            return Ok(Taken::End);
        }
        let take = if l.eof && avail.len() <= BLOCK_BYTES {
            avail.len()
        } else {
            match memchr::memrchr(b'\n', &avail[..BLOCK_BYTES.min(avail.len())]) {
                Some(i) => i + 1,
                None => return Ok(Taken::Sequential),
            }
        };
        let bytes = &avail[..take];
        if !splittable(bytes) {
            return Ok(Taken::Sequential);
        }
        let block = Block {
            bytes: bytes.to_vec(),
            first_line: l.line,
        };
        l.line += memchr::memchr_iter(b'\n', bytes).count();
        l.pos += take;
        if l.line > l.last_line.saturating_add(1) {
            return Err(too_many_rows(l.line - 1));
        }
        Ok(Taken::Block(block))
    }

    /// Up to `n` blocks, and what follows them.
    fn take_blocks(&mut self, n: usize) -> (Vec<Block>, After) {
        let mut blocks = Vec::with_capacity(n);
        while blocks.len() < n {
            match self.take_block() {
                Ok(Taken::Block(b)) => blocks.push(b),
                Ok(Taken::End) => return (blocks, After::End),
                Ok(Taken::Sequential) => return (blocks, After::Sequential),
                Err(e) => return (blocks, After::Failed(e)),
            }
        }
        (blocks, After::More)
    }

    /// Reads every remaining record: blocks of lines that need no csv crate are parsed by
    /// `work` on up to [`std::thread::available_parallelism`] threads at once while this thread
    /// reads the next blocks from the file and hands the previous blocks' results to `merge`,
    /// in file order; from the first line that needs the csv crate on, `work` reads the rest of
    /// the file here (one last result). `merge` stops the reading by returning an error; a
    /// worker reports its own errors inside its result (it stops at its first), so `merge`
    /// decides which comes first in the file; an error reading the file is returned after every
    /// block before it is merged.
    pub fn for_each_block<T: Send, E: From<ReadError>>(
        &mut self,
        work: impl Fn(&mut dyn RowStream) -> T + Sync,
        mut merge: impl FnMut(T) -> Result<(), E>,
    ) -> Result<(), E> {
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get().min(8));
        let expected = self.header.len();
        let work = &work;
        // The results of the blocks parsed last, merged while the next ones are parsed.
        let mut parsed: Vec<T> = Vec::new();
        let (mut blocks, mut after) = self.take_blocks(threads);
        loop {
            let (results, next, merged) = std::thread::scope(|s| {
                let handles: Vec<_> = blocks
                    .iter()
                    .map(|b| s.spawn(move || work(&mut b.rows(expected))))
                    .collect();
                let next = matches!(after, After::More).then(|| self.take_blocks(threads));
                let merged = parsed.drain(..).try_for_each(&mut merge);
                let results: Vec<T> = handles
                    .into_iter()
                    .map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
                    .collect();
                (results, next, merged)
            });
            merged?;
            parsed = results;
            match next {
                Some(n) => (blocks, after) = n,
                None => {
                    parsed.into_iter().try_for_each(&mut merge)?;
                    return match after {
                        After::Sequential => merge(work(self)),
                        After::Failed(e) => Err(e.into()),
                        After::End | After::More => Ok(()),
                    };
                }
            }
        }
    }
}

impl<R: BufRead> RowStream for Records<R> {
    fn next_row(&mut self) -> Result<Option<Row<'_>>, ReadError> {
        Records::next_row(self)
    }

    fn take_events(&mut self) -> Vec<EventLine> {
        std::mem::take(&mut self.events.lines)
    }
}

impl<R: BufRead> Records<R> {
    /// The next record, `None` at the end of the file.
    pub fn next_row(&mut self) -> Result<Option<Row<'_>>, ReadError> {
        let expected = self.header.len();
        // Where the record is, found first; the row borrowing it is made after the loop.
        let split: Option<(usize, usize, usize)> = loop {
            match &mut self.source {
                Source::Lines(l) => {
                    let Some(end) = l.line_end()? else {
                        return Ok(None);
                    };
                    let (start, line) = (l.pos, l.line);
                    let split = split_line(&l.buf[start..end], &mut self.bounds);
                    if split.is_none() {
                        self.switch_to_csv();
                        continue;
                    }
                    l.pos = (end + 1).min(l.buf.len());
                    l.line += 1;
                    if line > l.last_line {
                        return Err(too_many_rows(line));
                    }
                    if split == Some(false) {
                        continue;
                    }
                    let text = &l.buf[start..end];
                    let first = self.bounds.first().map_or(&b""[..], |&(a, b)| &text[a..b]);
                    if first.starts_with(EVENT_PREFIX) && self.events.keep(line, text) {
                        continue;
                    }
                    if check_record(line, first, self.bounds.len(), expected)? {
                        break Some((start, end, line));
                    }
                }
                Source::Csv(c) => {
                    let read = c.csv.read_byte_record(&mut self.record);
                    let more = match read {
                        Ok(more) => more,
                        Err(e) => {
                            let at = e.position().map_or(u64::MAX, |p| p.byte());
                            return Err(ReadError::Csv {
                                line: c.line_at(at),
                                reason: e.to_string(),
                            });
                        }
                    };
                    if !more {
                        return Ok(None);
                    }
                    // csv's record position counts skipped blank lines into the record; the
                    // reader's position just after it does not: the record's last byte is the
                    // one before.
                    let end = c.csv.position().byte();
                    let line = c.line_at(end.saturating_sub(1));
                    if line > c.last_line {
                        return Err(too_many_rows(line));
                    }
                    let first = self.record.get(0).unwrap_or(b"");
                    if first.starts_with(EVENT_PREFIX) {
                        // The fields as they were (the csv crate split the details on commas).
                        let text = self.record.iter().collect::<Vec<_>>().join(&b","[..]);
                        self.events.keep(line, &text);
                        continue;
                    }
                    if check_record(line, first, self.record.len(), expected)? {
                        break Some((0, 0, line));
                    }
                }
                Source::Switching => break None,
            }
        };
        if split.is_some() {
            self.events.rows += 1;
        }
        Ok(match (split, &self.source) {
            (Some((start, end, line)), Source::Lines(l)) => Some(Row {
                line,
                fields: Fields::Split {
                    line: &l.buf[start..end],
                    bounds: &self.bounds,
                },
            }),
            (Some((_, _, line)), _) => Some(Row {
                line,
                fields: Fields::Csv(&self.record),
            }),
            (None, _) => None,
        })
    }
}

impl<R: Read> CsvSource<R> {
    /// The file line of the byte at `offset` of the csv stream.
    fn line_at(&mut self, offset: u64) -> usize {
        let pending = &mut self.csv.get_mut().pending;
        while pending.front().is_some_and(|&nl| nl < offset) {
            pending.pop_front();
            self.newlines_before += 1;
        }
        self.first_line + self.newlines_before
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows(text: &str) -> Result<Vec<(usize, Vec<String>)>, ReadError> {
        let mut r = Records::from_text(text)?;
        let mut out = Vec::new();
        while let Some(row) = r.next_row()? {
            let fields = (0..row.len())
                .map(|i| row.text(i).map(str::to_owned))
                .collect::<Result<_, _>>()?;
            out.push((row.line, fields));
        }
        Ok(out)
    }

    #[test]
    fn numbers_are_one_rule_infinities_refused_gaps_nan_required_values_present() {
        for (text, want) in [
            ("1.25", Ok(1.25)),
            ("-3e-7", Ok(-3e-7)),
            ("1e308", Ok(1e308)),
            ("inf", Err(NumberError::Infinite)),
            ("-Infinity", Err(NumberError::Infinite)),
            ("1e400", Err(NumberError::Infinite)),
            ("-1e400", Err(NumberError::Infinite)),
            ("x", Err(NumberError::NotANumber)),
            ("1,5", Err(NumberError::NotANumber)),
        ] {
            assert_eq!(parse_number(text.as_bytes()), want, "{text}");
            assert_eq!(parse_required_number(text.as_bytes()), want, "{text}");
        }
        for gap in ["", "NaN", "nan"] {
            assert!(
                parse_number(gap.as_bytes()).is_ok_and(f64::is_nan),
                "{gap:?}"
            );
            assert_eq!(
                parse_required_number(gap.as_bytes()),
                Err(NumberError::Missing),
                "{gap:?}"
            );
        }
        // Through a row: the line, the column and the text named.
        let mut r = Records::from_text("time_s,output_v\n0,1\n1,-inf\n").unwrap();
        assert_eq!(
            r.next_row()
                .unwrap()
                .unwrap()
                .number(1, "output_v")
                .unwrap(),
            1.0
        );
        let row = r.next_row().unwrap().unwrap();
        let e = row.number(1, "output_v").unwrap_err().to_string();
        assert!(
            e.starts_with("line 3: column \"output_v\": \"-inf\" is infinite"),
            "{e}"
        );
    }

    #[test]
    fn metadata_header_and_records_keep_their_line_numbers() {
        let text = "# instrument: JN-06\n# a free comment\n\n# input_g: 1\ntime_s, output_v\n\
                    0, 1.5\n\n1,\"2\"\n";
        let r = Records::from_text(text).unwrap();
        assert_eq!(r.meta_value("instrument"), Some("JN-06"));
        assert_eq!(r.meta_value("input_g"), Some("1"));
        assert_eq!(r.meta().len(), 2);
        assert_eq!(r.header(), ["time_s", "output_v"]);
        assert_eq!(r.header_line(), 5);
        let rows = rows(text).unwrap();
        assert_eq!(rows[0], (6, vec!["0".into(), "1.5".into()]));
        assert_eq!(rows[1], (8, vec!["1".into(), "2".into()]));
    }

    #[test]
    fn a_byte_order_mark_is_stripped_before_metadata_or_header() {
        let r = Records::from_text("\u{feff}temperature_c,k0_g\n30,1\n").unwrap();
        assert_eq!(r.header()[0], "temperature_c");
        let r = Records::from_text("\u{feff}# input_g: 1\ntime_s,output_v\n").unwrap();
        assert_eq!(r.meta_value("input_g"), Some("1"));
    }

    #[test]
    fn a_repeated_metadata_key_is_refused_with_both_lines() {
        let e = Records::from_text("# input_g: 1\n# other: x\n# input_g: 0\ntime_s,v\n")
            .err()
            .unwrap();
        assert!(
            matches!(e, ReadError::RepeatedMeta { line: 3, first_line: 1, ref key } if key == "input_g"),
            "{e}"
        );
    }

    #[test]
    fn malformed_files_name_the_line_and_the_problem() {
        let count = rows("time_s,v\n0,1\n1,2,3\n").unwrap_err();
        assert!(matches!(
            count,
            ReadError::FieldCount {
                line: 3,
                expected: 2,
                found: 3
            }
        ));
        let comment = rows("time_s,v\n0,1\n# second log\n1,2\n").unwrap_err();
        assert!(matches!(comment, ReadError::CommentAfterHeader { line: 3 }));
        // An event line of a record is no comment: skipped, the rows around it kept.
        let events = rows("time_s,v\n0,1\n# event: 2026-01-01T00:00:00Z seq_gap lost=2, x\n1,2\n");
        assert_eq!(
            events.unwrap().iter().map(|r| r.0).collect::<Vec<_>>(),
            vec![2, 4]
        );
        assert_err!(Records::from_text("# only: meta\n\n"), ReadError::NoHeader);
        assert_err!(
            Records::from_text("time_s,v,v\n"),
            ReadError::BadHeader { line: 1, .. }
        );
        assert_err!(
            Records::from_text("time_s,,v\n"),
            ReadError::BadHeader { line: 1, .. }
        );
        let r = Records::from_text("a,b\n").unwrap();
        assert_err!(
            r.require("time_s"),
            ReadError::MissingColumn { line: 1, .. }
        );
        let bad = Records::new(&b"# k: \xff\na,b\n"[..]).err().unwrap();
        assert!(matches!(bad, ReadError::NotUtf8 { line: 1 }));
    }

    #[test]
    fn a_quote_hands_the_rest_to_the_csv_crate_with_the_same_fields_and_lines() {
        let body = "0,1\n\n  \n1, 2 \r\n2,\"3\n4\"\n3,\"a,b\"\n4,5\n";
        // Split here until line 5, the csv crate after; against the csv crate from the
        // (quoted) header on.
        let split = rows(&format!("# k: v\ntime_s,v\n{body}")).unwrap();
        let csv = rows(&format!("# k: v\n\"time_s\",v\n{body}")).unwrap();
        assert_eq!(split, csv);
        assert_eq!(
            split,
            vec![
                (3, vec!["0".into(), "1".into()]),
                (6, vec!["1".into(), "2".into()]),
                (8, vec!["2".into(), "3\n4".into()]),
                (9, vec!["3".into(), "a,b".into()]),
                (10, vec!["4".into(), "5".into()]),
            ]
        );
        // A carriage return inside a line is a record end to the csv crate: handed over too.
        let cr = rows("time_s,v\n0,1\r1,2\n").unwrap();
        assert_eq!(cr.len(), 2);
    }

    #[test]
    fn blocks_on_worker_threads_keep_file_order_and_lines() {
        let mut text = String::from("time_s,v\n");
        for i in 0..500 {
            text.push_str(&format!("{i},{}\n", i * 3));
            if i % 37 == 0 {
                text.push('\n');
            }
        }
        let want = rows(&text).unwrap();
        let mut r = Records::from_text(&text).unwrap();
        let mut got = Vec::new();
        r.for_each_block(
            |rows| {
                let mut out = Vec::new();
                while let Some(row) = rows.next_row().unwrap() {
                    out.push((
                        row.line,
                        vec![
                            row.text(0).unwrap().to_owned(),
                            row.text(1).unwrap().to_owned(),
                        ],
                    ));
                }
                out
            },
            |part| -> Result<(), ReadError> {
                got.extend(part);
                Ok(())
            },
        )
        .unwrap();
        assert!(text.len() > 10 * BLOCK_BYTES);
        assert_eq!(got, want);
    }

    #[test]
    fn a_read_error_is_returned_after_every_line_read_before_it() {
        /// Hands out `data` up to `fail_at` bytes, then fails.
        struct FailAfter {
            data: Vec<u8>,
            pos: usize,
            fail_at: usize,
        }
        impl std::io::Read for FailAfter {
            fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
                if self.pos >= self.fail_at {
                    return Err(std::io::Error::other("the disk went away"));
                }
                let n = buf.len().min(self.fail_at - self.pos).min(100);
                buf[..n].copy_from_slice(&self.data[self.pos..self.pos + n]);
                self.pos += n;
                Ok(n)
            }
        }
        let mut text = String::from("time_s,v\n");
        for i in 0..2000 {
            text.push_str(&format!("{i},{}\n", i * 7));
        }
        let want = rows(&text).unwrap();
        let fail_at = text.len() * 3 / 4;
        // The byte after each line (line k at index k − 1).
        let line_ends: Vec<usize> = text.match_indices('\n').map(|(i, _)| i + 1).collect();
        let reader = FailAfter {
            data: text.into_bytes(),
            pos: 0,
            fail_at,
        };
        let mut r = Records::new(std::io::BufReader::new(reader)).unwrap();
        let mut got = Vec::new();
        let res = r.for_each_block(
            |rows| {
                let mut out = Vec::new();
                while let Ok(Some(row)) = rows.next_row() {
                    out.push((row.line, vec![row.text(0).unwrap().to_owned()]));
                }
                out
            },
            |part| -> Result<(), ReadError> {
                got.extend(part);
                Ok(())
            },
        );
        assert!(matches!(res, Err(ReadError::Io(_))), "{res:?}");
        // The lines before the failure were merged, in order, but for less than a block's
        // bytes at its end (too few to make a block when the read failed).
        let merged_to = got.last().map_or(0, |(line, _)| line_ends[line - 1]);
        assert!(
            merged_to <= fail_at && fail_at - merged_to < BLOCK_BYTES,
            "{merged_to} of {fail_at}"
        );
        assert_eq!(
            got.len(),
            want.iter()
                .filter(|w| line_ends[w.0 - 1] <= merged_to)
                .count()
        );
        for (g, w) in got.iter().zip(&want) {
            assert_eq!((g.0, &g.1[0]), (w.0, &w.1[0]));
        }
    }

    #[test]
    fn crlf_line_ends_and_blank_lines_are_accepted() {
        let rows = rows("# k: v\r\ntime_s,v\r\n0,1\r\n   \r\n1,2\r\n").unwrap();
        assert_eq!(rows.len(), 2);
        assert_eq!(rows[1].0, 5);
    }
}
