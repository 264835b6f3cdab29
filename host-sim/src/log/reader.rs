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
//!   `#` line after the header is refused ([`ReadError::CommentAfterHeader`]): a comment in the
//!   middle of the samples means two logs were concatenated.
//!
//! What a field means (number, gap, text) is the caller's business: [`Row`] hands out the
//! trimmed bytes or text of each field with the line they came from.

use std::collections::VecDeque;
use std::io::{BufRead, Chain, Cursor, Read};

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
            Self::BadHeader { reason, .. } | Self::Csv { reason, .. } => reason.clone(),
            Self::MissingColumn { column, .. } => format!("header has no `{column}` column"),
            Self::FieldCount {
                expected, found, ..
            } => format!("wrong column count: {found} fields, header has {expected}"),
            Self::CommentAfterHeader { .. } => {
                "comment line after the header (two files concatenated?)".into()
            }
            Self::Io(_) | Self::NoHeader => self.to_string(),
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
            | Self::Csv { line, .. } => Some(*line),
        }
    }
}

/// An open file: metadata and header read, records on demand.
pub struct Records<R: Read> {
    meta: Vec<(String, String)>,
    header: Vec<String>,
    header_line: usize,
    csv: csv::Reader<NewlineOffsets<Chain<Cursor<Vec<u8>>, R>>>,
    record: csv::ByteRecord,
    /// Newlines of the csv stream before the current record (the stream starts at the header).
    newlines_before: usize,
}

/// Remembers the byte offsets of the newlines that pass through, so that a record's byte
/// position gives its line exactly: csv's own line counter skips blank lines. Only the newlines
/// read ahead of the current record are kept (a buffer's worth).
struct NewlineOffsets<R> {
    inner: R,
    offset: u64,
    pending: VecDeque<u64>,
}

impl<R: Read> Read for NewlineOffsets<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        for (i, _) in buf[..n].iter().enumerate().filter(|(_, b)| **b == b'\n') {
            self.pending.push_back(self.offset + i as u64);
        }
        self.offset += n as u64;
        Ok(n)
    }
}

/// One record and the line it starts on.
#[derive(Debug, Clone, Copy)]
pub struct Row<'a> {
    /// 1-based line in the file.
    pub line: usize,
    record: &'a csv::ByteRecord,
}

impl<'a> Row<'a> {
    /// Number of fields (always the header's).
    pub fn len(&self) -> usize {
        self.record.len()
    }

    /// True for a record without fields (never returned by [`Records::next_row`]).
    pub fn is_empty(&self) -> bool {
        self.record.is_empty()
    }

    /// The trimmed bytes of field `i` (empty past the end).
    pub fn bytes(&self, i: usize) -> &'a [u8] {
        self.record.get(i).unwrap_or(b"")
    }

    /// The trimmed text of field `i`.
    pub fn text(&self, i: usize) -> Result<&'a str, ReadError> {
        std::str::from_utf8(self.bytes(i)).map_err(|_| ReadError::NotUtf8 { line: self.line })
    }
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
        let header_bytes = loop {
            buf.clear();
            if r.read_until(b'\n', &mut buf)? == 0 {
                return Err(ReadError::NoHeader);
            }
            line += 1;
            let bytes = if line == 1 {
                buf.strip_prefix(BOM).unwrap_or(&buf)
            } else {
                &buf[..]
            };
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
        let mut csv = csv::ReaderBuilder::new()
            .has_headers(false)
            .flexible(true)
            .trim(csv::Trim::All)
            .from_reader(NewlineOffsets {
                inner: Cursor::new(header_bytes).chain(r),
                offset: 0,
                pending: VecDeque::new(),
            });
        let mut record = csv::ByteRecord::new();
        let csv_error = |e: csv::Error| ReadError::Csv {
            line: header_line,
            reason: e.to_string(),
        };
        if !csv.read_byte_record(&mut record).map_err(csv_error)? {
            return Err(ReadError::NoHeader);
        }
        let mut header = Vec::with_capacity(record.len());
        for (i, name) in record.iter().enumerate() {
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
            csv,
            record,
            newlines_before: 0,
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

    /// The file line of the byte at `offset` of the csv stream.
    fn line_at(&mut self, offset: u64) -> usize {
        let pending = &mut self.csv.get_mut().pending;
        while pending.front().is_some_and(|&nl| nl < offset) {
            pending.pop_front();
            self.newlines_before += 1;
        }
        self.header_line + self.newlines_before
    }

    /// The next record, `None` at the end of the file.
    pub fn next_row(&mut self) -> Result<Option<Row<'_>>, ReadError> {
        loop {
            let read = self.csv.read_byte_record(&mut self.record);
            let more = match read {
                Ok(more) => more,
                Err(e) => {
                    let at = e.position().map_or(u64::MAX, |p| p.byte());
                    return Err(ReadError::Csv {
                        line: self.line_at(at),
                        reason: e.to_string(),
                    });
                }
            };
            if !more {
                return Ok(None);
            }
            // csv's record position counts skipped blank lines into the record; the reader's
            // position just after it does not: the record's last byte is the one before.
            let end = self.csv.position().byte();
            let line = self.line_at(end.saturating_sub(1));
            if self.record.get(0).is_some_and(|f| f.starts_with(b"#")) {
                return Err(ReadError::CommentAfterHeader { line });
            }
            // A line of spaces is blank, not a record of one empty field.
            if self.record.len() == 1 && self.record.get(0).is_some_and(<[u8]>::is_empty) {
                continue;
            }
            if self.record.len() != self.header.len() {
                return Err(ReadError::FieldCount {
                    line,
                    expected: self.header.len(),
                    found: self.record.len(),
                });
            }
            return Ok(Some(Row {
                line,
                record: &self.record,
            }));
        }
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
        assert!(matches!(
            Records::from_text("# only: meta\n\n"),
            Err(ReadError::NoHeader)
        ));
        assert!(matches!(
            Records::from_text("time_s,v,v\n"),
            Err(ReadError::BadHeader { line: 1, .. })
        ));
        assert!(matches!(
            Records::from_text("time_s,,v\n"),
            Err(ReadError::BadHeader { line: 1, .. })
        ));
        let r = Records::from_text("a,b\n").unwrap();
        assert!(matches!(
            r.require("time_s"),
            Err(ReadError::MissingColumn { line: 1, .. })
        ));
        let bad = Records::new(&b"# k: \xff\na,b\n"[..]).err().unwrap();
        assert!(matches!(bad, ReadError::NotUtf8 { line: 1 }));
    }

    #[test]
    fn crlf_line_ends_and_blank_lines_are_accepted() {
        let rows = rows("# k: v\r\ntime_s,v\r\n0,1\r\n   \r\n1,2\r\n").unwrap();
        assert_eq!(rows.len(), 2);
        assert_eq!(rows[1].0, 5);
    }
}
