//! Streaming writer of the log format (docs/log-format.md; read back by [`crate::Log`]):
//! `# key: value` metadata lines, one header row, one row per sample.
//!
//! `log::Log` holds a whole log in memory, which for 41 days at 1 Hz and ~18 columns would be
//! half a gigabyte before the first byte is written; this writer streams rows instead. Numbers
//! are written in fixed point with a per-column number of decimals chosen below each channel's
//! resolution (e.g. 1e-10 V for an ADS1262 LSB of 1.16e-9 V), which keeps a 1 Hz month-long log
//! at ~150 bytes a row and is formatted with integer arithmetic only.

use std::io::{self, Write};

/// A column: its name and how it is printed.
#[derive(Debug, Clone, Copy)]
pub struct Column {
    /// Header name (unit suffix included).
    pub name: &'static str,
    /// Decimals after the point; `None` for an integer column.
    pub decimals: Option<u8>,
}

/// Streams rows of numbers to `W`.
pub struct LogWriter<W: Write> {
    w: io::BufWriter<W>,
    columns: Vec<Column>,
    line: Vec<u8>,
}

const POW10: [f64; 16] = [
    1.0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15,
];

/// Appends `v` with `decimals` digits after the point, rounded half away from zero; NaN (a gap)
/// is an empty field. Falls back to Rust's shortest representation beyond ±9e15 units of the
/// last digit.
pub fn push_fixed(out: &mut Vec<u8>, v: f64, decimals: u8) {
    if v.is_nan() {
        return;
    }
    let d = usize::from(decimals).min(POW10.len() - 1);
    let scale = POW10[d];
    let scaled = (v * scale).round();
    if scaled.is_infinite() || scaled.abs() >= 9e15 {
        let _ = write!(out, "{v}");
        return;
    }
    let n = scaled as i64;
    if n < 0 {
        out.push(b'-');
    }
    let n = n.unsigned_abs();
    let p = 10u64.pow(d as u32);
    push_u64(out, n / p);
    if d > 0 {
        out.push(b'.');
        let frac = n % p;
        let mut buf = [b'0'; 16];
        let mut f = frac;
        for i in (0..d).rev() {
            buf[i] = b'0' + (f % 10) as u8;
            f /= 10;
        }
        out.extend_from_slice(&buf[..d]);
    }
}

fn push_u64(out: &mut Vec<u8>, mut n: u64) {
    let mut buf = [0u8; 20];
    let mut i = buf.len();
    loop {
        i -= 1;
        buf[i] = b'0' + (n % 10) as u8;
        n /= 10;
        if n == 0 {
            break;
        }
    }
    out.extend_from_slice(&buf[i..]);
}

impl<W: Write> LogWriter<W> {
    /// Writes the metadata and the header.
    pub fn new(w: W, metadata: &[(String, String)], columns: Vec<Column>) -> io::Result<Self> {
        let mut w = io::BufWriter::with_capacity(1 << 20, w);
        for (k, v) in metadata {
            writeln!(w, "# {k}: {v}")?;
        }
        let names: Vec<&str> = columns.iter().map(|c| c.name).collect();
        writeln!(w, "{}", names.join(","))?;
        Ok(LogWriter {
            w,
            columns,
            line: Vec::with_capacity(512),
        })
    }

    /// Writes one row; `values` in column order (integer columns take the value as f64, exact
    /// for codes up to 2^53).
    pub fn row(&mut self, values: &[f64]) -> io::Result<()> {
        self.line.clear();
        for (i, (c, v)) in self.columns.iter().zip(values).enumerate() {
            if i > 0 {
                self.line.push(b',');
            }
            match c.decimals {
                Some(d) => push_fixed(&mut self.line, *v, d),
                None => push_fixed(&mut self.line, *v, 0),
            }
        }
        self.line.push(b'\n');
        self.w.write_all(&self.line)
    }

    /// Flushes and returns the inner writer.
    pub fn finish(self) -> io::Result<W> {
        self.w.into_inner().map_err(|e| e.into_error())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fixed(v: f64, d: u8) -> String {
        let mut o = Vec::new();
        push_fixed(&mut o, v, d);
        String::from_utf8(o).unwrap()
    }

    #[test]
    fn fixed_point_matches_hand_written_strings() {
        assert_eq!(fixed(1.32701234567891, 10), "1.3270123457");
        assert_eq!(fixed(-0.000123, 6), "-0.000123");
        assert_eq!(fixed(60.0, 3), "60.000");
        assert_eq!(fixed(-0.0000004, 6), "0.000000");
        assert_eq!(fixed(2_147_483_647.0, 0), "2147483647");
        assert_eq!(fixed(f64::NAN, 3), "");
        assert_eq!(fixed(0.5, 0), "1");
    }

    #[test]
    fn written_logs_read_back_with_the_log_reader() {
        let meta = vec![("instrument".to_string(), "X".to_string())];
        let cols = vec![
            Column {
                name: "time_s",
                decimals: Some(3),
            },
            Column {
                name: "output_v",
                decimals: Some(10),
            },
            Column {
                name: "accel_code",
                decimals: None,
            },
        ];
        let mut w = LogWriter::new(Vec::new(), &meta, cols).unwrap();
        w.row(&[0.0, 1.25, -5.0]).unwrap();
        w.row(&[60.0, f64::NAN, 2_147_483_647.0]).unwrap();
        let bytes = w.finish().unwrap();
        let log = crate::Log::read(&bytes[..]).unwrap();
        assert_eq!(log.meta("instrument"), Some("X"));
        assert_eq!(log.time_s(), &[0.0, 60.0]);
        let out = log.column("output_v").unwrap();
        assert_eq!(out[0], 1.25);
        assert!(out[1].is_nan());
        assert_eq!(log.column("accel_code").unwrap(), &[-5.0, 2_147_483_647.0]);
    }
}
