//! The record on disk: the project's log format (`# key: value` metadata, one header row, one
//! row per frame) with `# event: <UTC> <kind> <details>` lines in place between the rows.
//!
//! Durability: rows go through a buffer that is flushed and `fsync`ed at least every
//! [`SYNC_INTERVAL`], and after every event line, so a crash or a power cut loses at most the
//! last second. A record killed in the middle of a line leaves a cut last line; `--append`
//! trims it and says so.
//!
//! `--rotate daily` makes the output a directory of one file per UTC day (`YYYY-MM-DD.csv`),
//! each with the full header and the same `start_utc`, so that `time_s` runs on across files
//! and the readers take the directory as one record. With compression on
//! ([`RecordFile::compress_finished_days`], `--rotate daily-gz`), every plain day older than
//! yesterday is gzip-compressed (level 1) in a background thread when a new day begins:
//! `X.csv` → `X.csv.gz.tmp` (synced) → renamed `X.csv.gz` → `X.csv` removed, each step only
//! after the one before succeeded, so a crash leaves at worst a stale `.tmp` (redone next time)
//! or both files (the reader then refuses the day twice, naming both). Yesterday stays plain
//! because an event line stamped by the PC's clock may still land in it just after midnight.

use std::fs::{File, OpenOptions};
use std::io::{self, BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use accomp::pipeline::Frame;

use crate::samples_csv::status_names;
use accomp_log::time::{utc_date, Utc};
use accomp_log::writer::push_fixed;

/// Longest time rows stay in the buffer before they are written and synced.
pub const SYNC_INTERVAL: Duration = Duration::from_millis(500);

/// The columns of a record, in order: (name, decimals; None for integers and text).
pub const COLUMNS: [(&str, Option<u8>); 12] = [
    ("time_s", Some(6)),
    ("seq", None),
    ("board_time_us", None),
    ("unix_time_s", Some(6)),
    ("output_v", Some(10)),
    ("temperature_c", Some(6)),
    ("rtd_ohms", Some(6)),
    ("tilt_arcsec", Some(6)),
    ("a_i_exact_g", Some(12)),
    ("output_linearized_v", Some(10)),
    ("status_flags", None),
    ("status", None),
];

/// Metadata keys that must match for `--append` to continue a record (another board or table
/// is another record).
pub const IDENTITY_KEYS: [&str; 4] = [
    "device_board",
    "device_firmware",
    "calibration_id",
    "calibration_serial",
];

/// Why a record file cannot be opened as asked.
#[derive(Debug, thiserror::Error)]
pub enum RecordFileError {
    /// I/O.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What failed.
        error: io::Error,
    },
    /// The output exists and neither --append nor --force was given.
    #[error("{0} exists: --append continues it, --force writes over it")]
    Exists(PathBuf),
    /// --append to a file whose header says another board or table.
    #[error(
        "{path}: cannot append: {key} is {old:?} in the file, {new:?} now (--force appends anyway)"
    )]
    HeaderMismatch {
        /// The file.
        path: PathBuf,
        /// The metadata key.
        key: String,
        /// In the file.
        old: String,
        /// Now.
        new: String,
    },
    /// --append to something that is not a record.
    #[error("{path}: not a record to append to: {reason}")]
    NotARecord {
        /// The file.
        path: PathBuf,
        /// Why.
        reason: String,
    },
}

fn io_err(path: &Path) -> impl Fn(io::Error) -> RecordFileError + '_ {
    move |error| RecordFileError::Io {
        path: path.to_owned(),
        error,
    }
}

/// What an existing record says about itself, for appending.
#[derive(Debug, Clone, PartialEq)]
pub struct Existing {
    /// Its metadata, in file order.
    pub meta: Vec<(String, String)>,
    /// `start_utc`, Unix seconds.
    pub start_unix_s: f64,
    /// The last data row: (time_s, seq, board_time_us).
    pub last: Option<(f64, u32, u64)>,
    /// Bytes of a cut last line that were trimmed.
    pub trimmed: usize,
}

/// Reads the header and the last row of `path`, trimming a cut last line in place.
pub fn open_existing(path: &Path) -> Result<Existing, RecordFileError> {
    let not = |reason: &str| RecordFileError::NotARecord {
        path: path.to_owned(),
        reason: reason.to_owned(),
    };
    let mut f = OpenOptions::new()
        .read(true)
        .write(true)
        .open(path)
        .map_err(io_err(path))?;
    let len = f.metadata().map_err(io_err(path))?.len();
    // Header: read from the start until the header row.
    let mut head = Vec::new();
    (&mut f)
        .take(64 * 1024)
        .read_to_end(&mut head)
        .map_err(io_err(path))?;
    let text = String::from_utf8_lossy(&head);
    let mut meta = Vec::new();
    let mut header: Option<Vec<String>> = None;
    for line in text.lines() {
        let l = line.trim();
        if l.is_empty() {
            continue;
        }
        if let Some(c) = l.strip_prefix('#') {
            if let Some((k, v)) = c.split_once(':') {
                meta.push((k.trim().to_owned(), v.trim().to_owned()));
            }
            continue;
        }
        header = Some(l.split(',').map(|s| s.trim().to_owned()).collect());
        break;
    }
    let header = header.ok_or_else(|| not("no header row"))?;
    let col = |name: &str| header.iter().position(|h| h == name);
    let (Some(ti), Some(si), Some(bi)) = (col("time_s"), col("seq"), col("board_time_us")) else {
        return Err(not("no time_s, seq and board_time_us columns"));
    };
    let start = meta
        .iter()
        .find(|(k, _)| k == "start_utc")
        .and_then(|(_, v)| Utc::parse(v).ok())
        .ok_or_else(|| not("no start_utc"))?;
    // Tail: the last complete line, trimming what follows it.
    let tail_len = len.min(64 * 1024);
    f.seek(SeekFrom::Start(len - tail_len))
        .map_err(io_err(path))?;
    let mut tail = Vec::new();
    f.read_to_end(&mut tail).map_err(io_err(path))?;
    let mut trimmed = 0;
    if tail.last().is_some_and(|&b| b != b'\n') {
        let keep = tail.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
        trimmed = tail.len() - keep;
        tail.truncate(keep);
        f.set_len(len - trimmed as u64).map_err(io_err(path))?;
        f.sync_all().map_err(io_err(path))?;
    }
    let tail = String::from_utf8_lossy(&tail);
    let last = tail.lines().rev().find_map(|l| {
        let l = l.trim();
        if l.is_empty() || l.starts_with('#') {
            return None;
        }
        let fields: Vec<&str> = l.split(',').map(str::trim).collect();
        if fields.len() != header.len() {
            return None;
        }
        Some((
            fields[ti].parse::<f64>().ok()?,
            fields[si].parse::<u32>().ok()?,
            fields[bi].parse::<u64>().ok()?,
        ))
    });
    Ok(Existing {
        meta,
        start_unix_s: start.0,
        last,
        trimmed,
    })
}

/// The first key of [`IDENTITY_KEYS`] whose value differs: (key, in the file, now).
pub fn identity_difference(
    old: &[(String, String)],
    new: &[(String, String)],
) -> Option<(String, String, String)> {
    let get = |m: &[(String, String)], k: &str| {
        m.iter()
            .find(|(mk, _)| mk == k)
            .map(|(_, v)| v.clone())
            .unwrap_or_default()
    };
    IDENTITY_KEYS
        .iter()
        .map(|k| (k.to_string(), get(old, k), get(new, k)))
        .find(|(_, o, n)| o != n)
}

/// Where the rows go: one file, or one file per UTC day in a directory.
#[derive(Debug, Clone, PartialEq)]
pub enum Layout {
    /// One file.
    File(PathBuf),
    /// A directory of `YYYY-MM-DD.csv`.
    Daily(PathBuf),
}

/// `YYYY-MM-DD` of a Unix time.
pub fn day_name(unix_s: f64) -> String {
    let d = utc_date((unix_s.floor() as i64).div_euclid(86_400) * 86_400);
    d.map_or_else(
        || "out-of-range".into(),
        |d| format!("{:04}-{:02}-{:02}", d.year(), d.month(), d.day()),
    )
}

/// The open record.
pub struct RecordFile {
    layout: Layout,
    meta: Vec<(String, String)>,
    start_unix_s: f64,
    path: PathBuf,
    day: String,
    w: BufWriter<File>,
    line: Vec<u8>,
    last_sync: Instant,
    /// Bytes written (rows and events) since opening.
    pub bytes: u64,
    /// Compress finished days (daily layout).
    compress: bool,
    /// The compression running in the background: the lines it reports when done.
    compressing: Option<std::thread::JoinHandle<Vec<(String, String)>>>,
}

/// gzip-compresses `X.csv` into `X.csv.gz` (see the module docs for the order of the steps).
/// Returns the event (kind, details) that says what happened.
pub fn compress_day(plain: &Path) -> (String, String) {
    let gz = plain.with_extension("csv.gz");
    let tmp = plain.with_extension("csv.gz.tmp");
    let run = || -> io::Result<(u64, u64)> {
        let mut src = File::open(plain)?;
        let out = File::create(&tmp)?;
        let mut e = flate2::write::GzEncoder::new(
            BufWriter::with_capacity(1 << 16, out),
            flate2::Compression::fast(),
        );
        let n = io::copy(&mut src, &mut e)?;
        let out = e.finish()?.into_inner().map_err(|e| e.into_error())?;
        out.sync_all()?;
        let m = out.metadata()?.len();
        std::fs::rename(&tmp, &gz)?;
        if let Some(dir) = gz.parent() {
            File::open(dir)?.sync_all()?;
        }
        std::fs::remove_file(plain)?;
        Ok((n, m))
    };
    match run() {
        Ok((n, m)) => (
            "compressed".into(),
            format!("{} -> {} ({n} -> {m} bytes)", plain.display(), gz.display()),
        ),
        Err(e) => (
            "compress_failed".into(),
            format!("{}: {e} (the plain file is kept)", plain.display()),
        ),
    }
}

/// Plain `YYYY-MM-DD.csv` files of `dir` older than `before` (a day name).
fn plain_days_before(dir: &Path, before: &str) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| {
                    p.extension().is_some_and(|e| e == "csv")
                        && p.file_stem()
                            .and_then(|s| s.to_str())
                            .is_some_and(|s| s < before)
                })
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

impl RecordFile {
    /// Starts a new record (the file or the day's file must not exist unless `force`).
    pub fn create(
        layout: Layout,
        meta: Vec<(String, String)>,
        start_unix_s: f64,
        force: bool,
    ) -> Result<Self, RecordFileError> {
        let (path, day) = Self::path_for(&layout, start_unix_s)?;
        if path.exists() && !force {
            return Err(RecordFileError::Exists(path));
        }
        let f = File::create(&path).map_err(io_err(&path))?;
        let mut r = RecordFile::writing(layout, meta, start_unix_s, path, day, f);
        r.write_header()?;
        Ok(r)
    }

    /// Continues `path` (already checked with [`open_existing`]).
    pub fn append(
        layout: Layout,
        path: PathBuf,
        meta: Vec<(String, String)>,
        start_unix_s: f64,
    ) -> Result<Self, RecordFileError> {
        let f = OpenOptions::new()
            .append(true)
            .open(&path)
            .map_err(io_err(&path))?;
        let day = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        Ok(RecordFile::writing(
            layout,
            meta,
            start_unix_s,
            path,
            day,
            f,
        ))
    }

    /// A record writing to `f` (the file of `day` at `path`), nothing written yet.
    fn writing(
        layout: Layout,
        meta: Vec<(String, String)>,
        start_unix_s: f64,
        path: PathBuf,
        day: String,
        f: File,
    ) -> Self {
        RecordFile {
            layout,
            meta,
            start_unix_s,
            path,
            day,
            w: BufWriter::with_capacity(1 << 16, f),
            line: Vec::with_capacity(256),
            last_sync: Instant::now(),
            bytes: 0,
            compress: false,
            compressing: None,
        }
    }

    /// Compress finished days from now on (daily layout; see the module docs).
    pub fn compress_finished_days(&mut self, on: bool) {
        self.compress = on;
    }

    /// Waits for a compression in the background and returns what it reports (event lines).
    pub fn finish_compression(&mut self) -> Vec<(String, String)> {
        self.compressing
            .take()
            .and_then(|h| h.join().ok())
            .unwrap_or_default()
    }

    /// Starts compressing the plain days older than yesterday (at a new day `unix_s`).
    fn start_compression(&mut self, unix_s: f64) -> Result<(), RecordFileError> {
        let Layout::Daily(dir) = self.layout.clone() else {
            return Ok(());
        };
        if !self.compress {
            return Ok(());
        }
        if self.compressing.as_ref().is_some_and(|h| !h.is_finished()) {
            // Still busy with the days before: the next new day picks the rest up.
            return Ok(());
        }
        for (kind, details) in self.finish_compression() {
            self.event(unix_s, &kind, &details)?;
        }
        let days = plain_days_before(&dir, &day_name(unix_s - 86_400.0));
        if !days.is_empty() {
            self.compressing = Some(std::thread::spawn(move || {
                days.iter().map(|d| compress_day(d)).collect()
            }));
        }
        Ok(())
    }

    fn path_for(layout: &Layout, unix_s: f64) -> Result<(PathBuf, String), RecordFileError> {
        Ok(match layout {
            Layout::File(p) => (p.clone(), String::new()),
            Layout::Daily(dir) => {
                std::fs::create_dir_all(dir).map_err(io_err(dir))?;
                let day = day_name(unix_s);
                (dir.join(format!("{day}.csv")), day)
            }
        })
    }

    fn write_header(&mut self) -> Result<(), RecordFileError> {
        let mut h = String::new();
        for (k, v) in &self.meta {
            h.push_str(&format!("# {k}: {v}\n"));
        }
        let names: Vec<&str> = COLUMNS.iter().map(|c| c.0).collect();
        h.push_str(&names.join(","));
        h.push('\n');
        self.w.write_all(h.as_bytes()).map_err(io_err(&self.path))?;
        self.bytes += h.len() as u64;
        self.sync()
    }

    /// The file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Unix time of `start_utc`.
    pub fn start_unix_s(&self) -> f64 {
        self.start_unix_s
    }

    /// Opens the next day's file when `unix_s` is on another UTC day (daily layout).
    fn rotate(&mut self, unix_s: f64) -> Result<(), RecordFileError> {
        if !matches!(self.layout, Layout::Daily(_)) {
            return Ok(());
        }
        let day = day_name(unix_s);
        if day == self.day {
            return Ok(());
        }
        self.sync()?;
        let (path, day) = Self::path_for(&self.layout, unix_s)?;
        let exists = path.exists();
        let f = OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .map_err(io_err(&path))?;
        self.w = BufWriter::with_capacity(1 << 16, f);
        let forward = day > self.day;
        self.path = path;
        self.day = day;
        if !exists {
            self.write_header()?;
        }
        if forward {
            self.start_compression(unix_s)?;
        }
        Ok(())
    }

    /// One frame at record time `time_s`.
    pub fn row(&mut self, time_s: f64, frame: &Frame) -> Result<(), RecordFileError> {
        let unix = self.start_unix_s + time_s;
        self.rotate(unix)?;
        let l = &mut self.line;
        l.clear();
        push_fixed(l, time_s, 6);
        l.push(b',');
        push_fixed(l, f64::from(frame.seq), 0);
        l.push(b',');
        push_fixed(l, frame.time_us as f64, 0);
        l.push(b',');
        push_fixed(l, unix, 6);
        for (v, d) in [
            (frame.output_v, 10),
            (frame.temperature_c, 6),
            (frame.rtd_ohms, 6),
            (frame.tilt_arcsec, 6),
            (frame.a_i_exact_g, 12),
            (frame.output_linearized_v, 10),
        ] {
            l.push(b',');
            // An infinity (an open RTD's resistance) is no reading: a gap, as NaN is.
            push_fixed(l, if v.is_finite() { v } else { f64::NAN }, d);
        }
        l.extend_from_slice(format!(",{:#06x},", frame.status.0).as_bytes());
        l.extend_from_slice(status_names(frame.status).as_bytes());
        l.push(b'\n');
        self.w.write_all(l).map_err(io_err(&self.path))?;
        self.bytes += l.len() as u64;
        if self.last_sync.elapsed() >= SYNC_INTERVAL {
            self.sync()?;
        }
        Ok(())
    }

    /// `# event: <UTC> <kind> <details>`, written and synced at once.
    pub fn event(&mut self, unix_s: f64, kind: &str, details: &str) -> Result<(), RecordFileError> {
        self.rotate(unix_s)?;
        // One line, no quote (a quote would make the CSV layer read on past the line end).
        let details: String = details
            .chars()
            .map(|c| match c {
                '"' => '\'',
                '\n' | '\r' => ' ',
                c => c,
            })
            .collect();
        let line = accomp_log::Event::line(Utc(unix_s), kind, &details);
        self.w
            .write_all(line.as_bytes())
            .map_err(io_err(&self.path))?;
        self.bytes += line.len() as u64;
        self.sync()
    }

    /// Writes what is buffered and syncs it to the disk.
    pub fn sync(&mut self) -> Result<(), RecordFileError> {
        self.w.flush().map_err(io_err(&self.path))?;
        self.w.get_ref().sync_data().map_err(io_err(&self.path))?;
        self.last_sync = Instant::now();
        Ok(())
    }

    /// Syncs if the last sync is older than [`SYNC_INTERVAL`] (call when idle).
    pub fn sync_if_due(&mut self) -> Result<(), RecordFileError> {
        if self.last_sync.elapsed() >= SYNC_INTERVAL {
            self.sync()?;
        }
        Ok(())
    }
}

/// The file to append to in a daily directory: the newest `YYYY-MM-DD.csv`.
pub fn newest_daily(dir: &Path) -> Option<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .ok()?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "csv"))
        .collect();
    files.sort();
    files.pop()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cut_last_line_is_trimmed_and_the_last_row_found_past_event_lines() {
        let dir = crate::scratch::Scratch::new("rec-file");
        let p = dir.join("r.csv");
        let names: Vec<&str> = COLUMNS.iter().map(|c| c.0).collect();
        let row =
            |t: &str, seq: &str, b: &str| format!("{t},{seq},{b},1.5,1,45,117,0.1,1,1,0x0000,OK\n");
        let text = format!(
            "# start_utc: 2026-01-01T00:00:00Z\n# device_board: Frontend\n{}\n{}{}# event: \
             2026-01-01T00:00:01Z link_lost x\n1.6,12,16000",
            names.join(","),
            row("0.8", "10", "800000"),
            row("1.6", "11", "1600000"),
        );
        std::fs::write(&p, &text).unwrap();
        let e = open_existing(&p).unwrap();
        assert_eq!(e.trimmed, "1.6,12,16000".len());
        assert_eq!(e.last, Some((1.6, 11, 1_600_000)));
        assert_eq!(
            e.start_unix_s,
            Utc::parse("2026-01-01T00:00:00Z").unwrap().0
        );
        assert!(std::fs::read_to_string(&p)
            .unwrap()
            .ends_with("link_lost x\n"));
    }

    #[test]
    fn another_table_is_named_as_the_difference() {
        let m = |id: &str| {
            vec![
                ("device_board".to_string(), "Frontend".to_string()),
                ("calibration_id".to_string(), id.to_string()),
            ]
        };
        assert_eq!(identity_difference(&m("0x1"), &m("0x1")), None);
        assert_eq!(
            identity_difference(&m("0x1"), &m("0x2")),
            Some(("calibration_id".into(), "0x1".into(), "0x2".into()))
        );
    }

    /// A daily record started at `start_utc` in a fresh scratch folder (removed on drop).
    fn daily_record(name: &str, start_utc: &str) -> (crate::scratch::Scratch, f64, RecordFile) {
        let dir = crate::scratch::Scratch::new(&format!("rec-{name}"));
        let start = Utc::parse(start_utc).unwrap().0;
        let meta = vec![("start_utc".to_string(), Utc(start).to_string())];
        let f = RecordFile::create(Layout::Daily(dir.to_path_buf()), meta, start, false).unwrap();
        (dir, start, f)
    }

    /// The file names in `dir`, sorted.
    fn names_in(dir: &Path) -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    }

    fn frame(seq: u32) -> Frame {
        Frame {
            seq,
            time_us: u64::from(seq) * 1_000_000,
            lost: accomp::pipeline::LossFlags::default(),
            output_v: 1.25,
            temperature_c: 45.0,
            rtd_ohms: f64::INFINITY,
            tilt_arcsec: 0.5,
            a_i_exact_g: 1.0,
            output_linearized_v: 1.25,
            status: accomp::pipeline::Status(accomp::pipeline::Status::RTD_OPEN),
        }
    }

    #[test]
    fn daily_files_split_at_utc_midnight_and_read_back_as_one_record() {
        // 23:59:58 UTC: rows at +0, +1, +2 (midnight), +3 s.
        let (dir, start, mut f) = daily_record("daily", "2026-03-01T23:59:58Z");
        for k in 0..4u32 {
            f.row(f64::from(k), &frame(k)).unwrap();
            if k == 1 {
                f.event(start + 1.5, "link_lost", "a \"quoted\" reason")
                    .unwrap();
            }
        }
        f.sync().unwrap();
        assert_eq!(names_in(&dir), ["2026-03-01.csv", "2026-03-02.csv"]);
        let day2 = std::fs::read_to_string(dir.join("2026-03-02.csv")).unwrap();
        assert!(day2.starts_with("# start_utc: 2026-03-01T23:59:58Z\n"));
        let log = accomp_log::Log::read_path(&dir).unwrap();
        assert_eq!(log.time_s(), &[0.0, 1.0, 2.0, 3.0]);
        // An open RTD's infinite resistance is written as a gap.
        assert!(log.column("rtd_ohms").unwrap().iter().all(|v| v.is_nan()));
        assert_eq!(log.column("seq").unwrap(), &[0.0, 1.0, 2.0, 3.0]);
    }

    #[test]
    fn days_before_yesterday_are_compressed_and_still_read_as_one_record() {
        let (dir, _, mut f) = daily_record("gz", "2026-03-01T23:59:59Z");
        f.compress_finished_days(true);
        // Rows on 03-01, 03-02 and 03-03: entering 03-03 compresses 03-01 (older than yesterday).
        for (k, t) in [0.0, 1.0, 86_401.0].into_iter().enumerate() {
            f.row(t, &frame(k as u32)).unwrap();
        }
        let done = f.finish_compression();
        assert_eq!(done.len(), 1, "{done:?}");
        assert_eq!(done[0].0, "compressed", "{done:?}");
        f.sync().unwrap();
        assert_eq!(
            names_in(&dir),
            ["2026-03-01.csv.gz", "2026-03-02.csv", "2026-03-03.csv"]
        );
        let log = accomp_log::Log::read_path(&dir).unwrap();
        assert_eq!(log.time_s(), &[0.0, 1.0, 86_401.0]);
    }

    #[test]
    fn days_are_named_in_utc() {
        assert_eq!(day_name(0.0), "1970-01-01");
        assert_eq!(day_name(86_399.9), "1970-01-01");
        assert_eq!(day_name(86_400.0), "1970-01-02");
    }
}
