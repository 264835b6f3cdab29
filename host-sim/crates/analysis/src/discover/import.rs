//! Loading a record for discovery: our log format, the gMetrology `.tsf` and the AQG CSV, and the
//! reduction of any of them to a [`Dataset`] (output in its own unit, auxiliary channels, gaps as
//! segment breaks, optional binning).
//!
//! Nothing is interpolated: a row with a NaN in the output or in a used auxiliary channel is
//! dropped and counted, and a spacing larger than 2.5 × the median spacing starts a new segment
//! (filters, differences and whitening restart there).

use crate::log::{Log, LogError};
use std::path::Path;

pub use accomp_log::{unit_per_g_for_suffix, M_S2_PER_MGAL};

/// Record formats `accomp discover` reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// Guess from the extension and the header.
    Auto,
    /// Our stability-test log (docs/log-format.md).
    Log,
    /// gMetrology relative gravimeter, whitespace columns, Beijing time.
    GmetrologyTsf,
    /// AQG quantum gravimeter CSV converted from MiniSEED (time_s from 2020-07-31T12:15:00.015Z).
    AqgCsv,
}

/// Why a record could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    /// Reading the file failed.
    #[error("cannot read {path}: {source}")]
    Io {
        /// File.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// The log reader refused the file.
    #[error(transparent)]
    Log(#[from] LogError),
    /// No usable output column or too few rows.
    #[error("{0}")]
    Shape(String),
}

/// A row the importer refused, with its 1-based line number.
#[derive(Debug, Clone, PartialEq)]
pub struct BadRow {
    /// 1-based line in the file.
    pub line: usize,
    /// Why.
    pub reason: String,
}

/// Site of the gMetrology record (from the repository's own scripts).
pub const GMETROLOGY_SITE: (f64, f64, f64) = (33.98, 116.79, 0.0);
/// Site of the AQG record (station XML), latitude, longitude, height in metres.
pub const AQG_SITE: (f64, f64, f64) = (37.76589, 15.016805, 2920.0);
/// Epoch of the AQG `time_s` column.
pub const AQG_START_UTC: &str = "2020-07-31T12:15:00.015Z";
/// Beijing time − UTC, hours.
pub const BEIJING_UTC_OFFSET_H: i64 = 8;

pub use crate::log::time::{format_utc, parse_utc};
use accomp::tide::UtcTime;

fn read_text(path: &Path) -> Result<String, ImportError> {
    let (_, max_bytes) = crate::log::reader::limits();
    crate::log::reader::read_text_limited(path, max_bytes).map_err(|e| ImportError::Io {
        path: path.display().to_string(),
        source: e.into_io(),
    })
}

/// Reads a gMetrology `.tsf` text: `year month day hour minute second gravity_mGal pressure_hPa`
/// in Beijing time. Returns a log in our format (time_s from the first good row, start_utc in
/// UTC, site metadata, `input_g: 1`) and the refused rows.
pub fn gmetrology_from_str(text: &str) -> Result<(Log, Vec<BadRow>), ImportError> {
    let mut bad = Vec::new();
    let mut unix = Vec::new();
    let mut g = Vec::new();
    let mut p = Vec::new();
    let mut backwards = 0usize;
    for (i, line) in text.lines().enumerate() {
        let line_no = i + 1;
        let trimmed = line.trim();
        if trimmed.is_empty() || trimmed.starts_with(['#', '[']) {
            continue;
        }
        let f: Vec<&str> = trimmed.split_whitespace().collect();
        if f.len() != 8 {
            bad.push(BadRow {
                line: line_no,
                reason: format!("{} fields, expected 8", f.len()),
            });
            continue;
        }
        let ints: Option<Vec<i64>> = f[..5].iter().map(|v| v.parse().ok()).collect();
        let sec: Option<f64> = f[5].parse().ok();
        let (gv, pv) = (f[6].parse::<f64>().ok(), f[7].parse::<f64>().ok());
        let (Some(ints), Some(sec), Some(gv), Some(pv)) = (ints, sec, gv, pv) else {
            bad.push(BadRow {
                line: line_no,
                reason: "unparsable number".into(),
            });
            continue;
        };
        // `try_from`, not `as`: a month of 257 must not wrap to 1.
        let field = |k: usize| u8::try_from(ints[k]).ok();
        let Some(local) = (|| {
            let t = UtcTime::new(
                i32::try_from(ints[0]).ok()?,
                field(1)?,
                field(2)?,
                field(3)?,
                field(4)?,
                sec,
            );
            Some(t.ok()?.posix_seconds())
        })() else {
            bad.push(BadRow {
                line: line_no,
                reason: "invalid date/time".into(),
            });
            continue;
        };
        // Beijing time is UTC+8: UTC = local − 8 h.
        let u = local - (BEIJING_UTC_OFFSET_H * 3600) as f64;
        if unix.last().is_some_and(|&last: &f64| u <= last) {
            backwards += 1;
            bad.push(BadRow {
                line: line_no,
                reason: "time not increasing".into(),
            });
            continue;
        }
        // 9999-style fill values are gaps, not readings.
        let ok = |v: f64| v.is_finite() && v.abs() < 9.0e4;
        unix.push(u);
        g.push(if ok(gv) { gv } else { f64::NAN });
        p.push(if ok(pv) && pv > 0.0 { pv } else { f64::NAN });
    }
    // A file in reverse order keeps its first row and refuses every other one as "not
    // increasing": said for what it is.
    if backwards > unix.len() {
        return Err(ImportError::Shape(format!(
            "time runs backwards: {backwards} rows are not later than the row before and only \
             {} are; the file looks reversed (newest first): sort it by time, oldest first \
             (e.g. `tac`)",
            unix.len()
        )));
    }
    let Some(&t0) = unix.first() else {
        return Err(ImportError::Shape("no readable rows".into()));
    };
    let mut log = Log::with_time(unix.iter().map(|u| u - t0).collect())?;
    log.set_meta(
        "instrument",
        "gMetrology relative spring gravimeter (George-Gou/gMetrology, MIT)",
    )?;
    log.set_meta("start_utc", &format_utc(t0))?;
    log.set_meta("latitude_deg", &GMETROLOGY_SITE.0.to_string())?;
    log.set_meta("longitude_deg", &GMETROLOGY_SITE.1.to_string())?;
    log.set_meta("height_m", &GMETROLOGY_SITE.2.to_string())?;
    log.set_meta("input_g", "1")?;
    log.push_column("gravity_mgal", g)?;
    log.push_column("pressure_hpa", p)?;
    Ok((log, bad))
}

/// Adds the AQG record's metadata (epoch, site, 1 g) to its CSV read as a log.
pub fn aqg_from_log(mut log: Log) -> Result<Log, ImportError> {
    if log.meta("start_utc").is_none() {
        log.set_meta(
            "instrument",
            "Exail/Muquans AQG quantum gravimeter (NEWTON-g/AQG2MSEED)",
        )?;
        log.set_meta("start_utc", AQG_START_UTC)?;
        log.set_meta("latitude_deg", &AQG_SITE.0.to_string())?;
        log.set_meta("longitude_deg", &AQG_SITE.1.to_string())?;
        log.set_meta("height_m", &AQG_SITE.2.to_string())?;
        log.set_meta("input_g", "1")?;
    }
    Ok(log)
}

/// Loads a record in any supported format as a log in our format plus refused rows.
pub fn load(path: &Path, format: Format) -> Result<(Log, Vec<BadRow>), ImportError> {
    load_impl(path, format, None)
}

/// [`load`] for [`dataset_from_log`]: of a log in our format (or the AQG CSV) only the
/// columns a dataset can be made of are stored — time, output candidates, channels, and the
/// `requested` output (`--output`) — while every field is still checked. A simulated 41-day
/// 1 Hz log holds 14 truth columns the discovery never reads (0.4 GB as numbers).
pub fn load_for_dataset(
    path: &Path,
    format: Format,
    requested: Option<&str>,
) -> Result<(Log, Vec<BadRow>), ImportError> {
    let keep = |name: &str| requested == Some(name) || usable_column(name);
    load_impl(path, format, Some(&keep))
}

fn load_impl(
    path: &Path,
    format: Format,
    keep: Option<&(dyn Fn(&str) -> bool + Sync)>,
) -> Result<(Log, Vec<BadRow>), ImportError> {
    let format = match format {
        Format::Auto => {
            let name = path.to_string_lossy().to_ascii_lowercase();
            if name.ends_with(".tsf") {
                Format::GmetrologyTsf
            } else {
                let first = first_nonblank_line(path)?;
                if first.starts_with("time_s,gravity_nm_s2,tilt_1_urad") {
                    Format::AqgCsv
                } else {
                    Format::Log
                }
            }
        }
        f => f,
    };
    match format {
        Format::GmetrologyTsf => gmetrology_from_str(&read_text(path)?),
        Format::AqgCsv => {
            read_log_with_bad_rows(path, keep).and_then(|(l, b)| Ok((aqg_from_log(l)?, b)))
        }
        _ => read_log_with_bad_rows(path, keep),
    }
}

/// The first line of a file that is not blank (the format guess reads no further: a 41-day
/// 1 Hz log is 0.8 GB).
fn first_nonblank_line(path: &Path) -> Result<String, ImportError> {
    use std::io::BufRead;
    let io = |source| ImportError::Io {
        path: path.display().to_string(),
        source,
    };
    // Through the record opener: a `.csv.gz` is guessed on its text, a directory on its first file.
    let mut r = crate::log::open_record(path)?;
    let mut buf = Vec::new();
    let limit = crate::log::reader::MAX_LINE_BYTES;
    for _ in 0..limit {
        buf.clear();
        let n = std::io::Read::take(&mut r, limit as u64 + 1)
            .read_until(b'\n', &mut buf)
            .map_err(io)?;
        if n == 0 {
            return Ok(String::new());
        }
        if n > limit {
            // Not a text file of lines: the reader of the guessed format says why.
            return Ok(String::from_utf8_lossy(&buf[..256]).into_owned());
        }
        let line = String::from_utf8_lossy(&buf);
        if !line.trim().is_empty() {
            return Ok(line.into_owned());
        }
    }
    Ok(String::new())
}

/// Reads our log format (the columns `keep` accepts, all without it). The log reader refuses a
/// file with bad rows as a whole (naming the line); this is reported as an error, never
/// skipped silently.
fn read_log_with_bad_rows(
    path: &Path,
    keep: Option<&(dyn Fn(&str) -> bool + Sync)>,
) -> Result<(Log, Vec<BadRow>), ImportError> {
    let log = match keep {
        Some(keep) => Log::read_path_selected(path, keep)?,
        None => Log::read_path(path)?,
    };
    Ok((log, Vec::new()))
}

/// A column a dataset may be made of: an output candidate or a channel (not a truth column, a
/// raw code or a resistance; see [`classify`]). Text columns are never used.
fn usable_column(name: &str) -> bool {
    !crate::log::is_text_column_name(name) && (is_output_name(name) || classify(name).is_some())
}

/// What a channel is to the discovery.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChannelKind {
    /// The accelerometer temperature (RTD); the baseline's temperature.
    Temperature,
    /// A tilt, stored in radians.
    Tilt,
    /// Pressure, stored in Pa.
    Pressure,
    /// The applied input acceleration, g.
    Input,
    /// Any other auxiliary channel (another temperature, humidity, supply …), own unit.
    Other,
}

/// An auxiliary channel (all finite after row selection).
#[derive(Debug, Clone, PartialEq)]
pub struct Channel {
    /// Column name in the log.
    pub name: String,
    /// Role.
    pub kind: ChannelKind,
    /// Values (Pa for pressure, rad for tilt, own unit otherwise).
    pub values: Vec<f64>,
}

/// The record as the discovery sees it.
#[derive(Debug, Clone, PartialEq)]
pub struct Dataset {
    /// Seconds since `start_utc` (or since the log's zero).
    pub t_s: Vec<f64>,
    /// Output, in the log's output unit.
    pub y: Vec<f64>,
    /// True at the first sample of each contiguous segment.
    pub segment_start: Vec<bool>,
    /// Auxiliary channels.
    pub channels: Vec<Channel>,
    /// Output column name.
    pub output_name: String,
    /// Output unit (column suffix).
    pub output_unit: String,
    /// Output units per g, if known (unit suffix, `scale_factor_v_per_g`, or the calibration).
    pub unit_per_g: Option<f64>,
    /// Nominal input acceleration of the test, g (metadata `input_g` or the mean input channel).
    pub input_g: Option<f64>,
    /// Unix seconds of `time_s = 0`.
    pub start_unix_s: Option<f64>,
    /// Latitude, longitude (degrees), height (m).
    pub site: Option<(f64, f64, f64)>,
    /// Nominal sample spacing after binning, seconds.
    pub dt_s: f64,
    /// Samples averaged into each point (bins of unequal counts have unequal white noise, see
    /// `noise::white_scale_from_counts`); empty when not known (every point alike).
    pub samples_per_point: Vec<f64>,
    /// Rows read, rows dropped for NaN, bins used: what happened on the way.
    pub notes: Vec<String>,
    /// What the user must not miss about the input (empty channels, absurd values, gaps that
    /// coarsen the bins, too few points): printed first, and in the JSON `warnings`.
    pub warnings: Vec<String>,
}

/// A column's unit (lower case, "" without a suffix), as `accomp_log` reads it.
fn suffix_of(name: &str) -> String {
    accomp_log::unit_suffix(name).unwrap_or_default()
}

/// Picks the output column: `requested`, else the first whose name starts with `output`,
/// `gravity` or `a_i`.
pub fn output_column(log: &Log, requested: Option<&str>) -> Option<String> {
    if let Some(r) = requested {
        return log.column(r).map(|_| r.to_owned());
    }
    log.column_names()
        .iter()
        .find(|n| is_output_name(n) && log.column(n).is_some())
        .cloned()
}

/// A name [`output_column`] picks by default: `output*`, `gravity*`, `a_i*`.
fn is_output_name(name: &str) -> bool {
    let l = name.to_ascii_lowercase();
    l.starts_with("output") || l.starts_with("gravity") || l.starts_with("a_i")
}

fn classify(name: &str) -> Option<(ChannelKind, f64)> {
    let l = name.to_ascii_lowercase();
    // Truth columns of simulated logs, raw ADC codes and resistances duplicate other channels
    // or are not observables: never regressors.
    if l.contains("true")
        || l.contains("truth")
        || l.ends_with("_code")
        || l.ends_with("_ohm")
        || l.ends_with("_ohms")
        || l.starts_with("output")
        || l.starts_with("a_i")
        || l.starts_with("gravity")
    {
        return None;
    }
    // Bookkeeping of a recorded or demo log, not a physical channel: a sequence number and the
    // clocks rise with time, so as regressors they would pose as a drift or an "ambient"
    // coupling; the floor is the same output compensated with the simulation's truth.
    if l == "seq"
        || l.ends_with("_seq")
        || l.ends_with("time_s")
        || l.ends_with("time_us")
        || l.starts_with("floor_")
    {
        return None;
    }
    if l == "input_g" {
        return Some((ChannelKind::Input, 1.0));
    }
    if l.starts_with("tilt") {
        let f = match suffix_of(&l).as_str() {
            "arcsec" => accomp::units::RAD_PER_ARCSEC,
            "mas" => accomp::units::RAD_PER_ARCSEC * 1.0e-3,
            "urad" => 1.0e-6,
            "mrad" => 1.0e-3,
            "rad" => 1.0,
            _ => return Some((ChannelKind::Other, 1.0)),
        };
        return Some((ChannelKind::Tilt, f));
    }
    match suffix_of(&l).as_str() {
        "hpa" | "mbar" => Some((ChannelKind::Pressure, 100.0)),
        "pa" => Some((ChannelKind::Pressure, 1.0)),
        _ => Some((ChannelKind::Other, 1.0)),
    }
}

/// An `input_g` channel with a larger standard deviation than this (g) is a changing input.
pub const CHANGING_INPUT_STD_G: f64 = 1.0e-3;

/// Options of the reduction to a dataset.
#[derive(Debug, Clone, PartialEq)]
pub struct DatasetOptions {
    /// Output column (default: see [`output_column`]).
    pub output: Option<String>,
    /// Bin to at most this many points (block means, never across a gap).
    pub max_points: usize,
    /// Output units per g from a calibration (K1), used when the log does not say it.
    pub unit_per_g_from_calibration: Option<f64>,
}

/// `--max-points` below this is refused: the selection's blocked cross-validation cuts the
/// record into 100 blocks and the noise model's flicker needs several points per decade.
pub const MIN_MAX_POINTS: usize = 1_000;
/// `--max-points` above this is refused: the fit keeps ≈ [`BYTES_PER_POINT`] per point
/// (design columns, their whitened copies, the Kalman gains of the noise model and of each
/// cross-validation fold), so 2 M points is ≈ 3 GB.
pub const MAX_MAX_POINTS: usize = 2_000_000;
/// Working memory of the fit per point, bytes (measured order of magnitude, see above).
pub const BYTES_PER_POINT: usize = 1_500;
/// Fewer points than this after binning are refused: 100 cross-validation blocks of at least
/// one point, and a baseline of up to ~10 columns.
pub const MIN_POINTS: usize = 100;
/// A value further than this many times the central 98 % range of its column from the
/// column's median is not a measurement (1e300, a stuck converter's full scale); its row is
/// dropped with a warning.
pub const ABSURD_SPREAD: f64 = 1.0e4;

/// The memory the fit will use for `points` points, bytes (stated in the notes).
pub fn memory_estimate_bytes(points: usize, rows: usize, columns: usize) -> usize {
    points
        .saturating_mul(BYTES_PER_POINT)
        .saturating_add(rows.saturating_mul(columns).saturating_mul(8))
}

/// Rows of `col` that are not measurements: non-finite, or further than [`ABSURD_SPREAD`] times
/// the central 98 % range (at least 1e-9 of the median's magnitude) from the median.
fn absurd_rows(col: &[f64]) -> Vec<usize> {
    let mut v: Vec<f64> = col.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return Vec::new();
    }
    // Three order statistics: selections, not a sort (a 41-day 1 Hz column is 3.5 M values).
    let last = v.len() - 1;
    let mut q = |p: f64| {
        *v.select_nth_unstable_by(((last as f64) * p).round() as usize, f64::total_cmp)
            .1
    };
    let med = q(0.5);
    let spread = (q(0.99) - q(0.01))
        .max(1e-9 * med.abs())
        .max(f64::MIN_POSITIVE);
    col.iter()
        .enumerate()
        .filter(|(_, x)| {
            x.is_infinite() || (x.is_finite() && (*x - med).abs() > ABSURD_SPREAD * spread)
        })
        .map(|(i, _)| i)
        .collect()
}

impl Default for DatasetOptions {
    fn default() -> Self {
        Self {
            output: None,
            max_points: 50_000,
            unit_per_g_from_calibration: None,
        }
    }
}

impl DatasetOptions {
    /// The default options binning to at most `max_points` points.
    pub fn with_max_points(max_points: usize) -> Self {
        Self {
            max_points,
            ..Self::default()
        }
    }
}

/// Bins this many sampling intervals wide or wider are rounded up to a whole number of them
/// (the width grows by less than 1/8, the points fall by as much).
const WHOLE_SAMPLES_FROM: f64 = 8.0;

/// The bin width for `raw_s` (the record's covered time over the points kept) on a record
/// sampled every `median_dt_s`: from [`WHOLE_SAMPLES_FROM`] intervals up, a whole number of
/// them. Why: a regular record then gives every bin the same count of samples and its mean
/// the same spacing to the next, so the noise model's Kalman filter reaches its steady state
/// and stops updating its covariance (`noise::Riccati`); with a fractional width the counts
/// alternate (70 and 71 samples on 41 days at 1 Hz in 50 000 bins), the spacing alternates
/// with them, and each of the ≈ 10⁵ likelihood evaluations on the bins pays the full O(k²)
/// update on every bin. Narrower bins keep their width: rounding 1.4 intervals up to 2 would
/// drop 30 % of the points.
fn whole_samples_bin_s(raw_s: f64, median_dt_s: f64) -> f64 {
    let n = raw_s / median_dt_s;
    if median_dt_s > 0.0 && n >= WHOLE_SAMPLES_FROM {
        // The 1e-9 keeps a width already whole (up to rounding) at its count.
        (n - 1e-9).ceil() * median_dt_s
    } else {
        raw_s
    }
}

/// Reduces a log to a dataset: picks the output and channels, drops rows with gaps (counted),
/// bins to at most `max_points`, marks segments.
pub fn dataset_from_log(log: &Log, opts: &DatasetOptions) -> Result<Dataset, ImportError> {
    reduce(log, opts, true)
}

/// The same rows as [`dataset_from_log`] (same output, channels, dropped rows and segments),
/// never binned: what the full-rate stage (`fullrate`) fits the fast terms on.
pub fn full_rate_from_log(log: &Log, opts: &DatasetOptions) -> Result<Dataset, ImportError> {
    reduce(log, opts, false)
}

/// The block means, on the bins of `binned`, of a series `v` over the rows of `full` (both from
/// the same log and options: [`full_rate_from_log`], [`dataset_from_log`]): the bins are
/// rebuilt with the [`Bins`] that [`reduce`] builds them with. `None` when the rebuilt bins are not the dataset's (count or mean time differ).
pub fn block_means_like(full: &Dataset, binned: &Dataset, v: &[f64]) -> Option<Vec<f64>> {
    let bin = binned.dt_s;
    let (&t0, true) = (full.t_s.first()?, v.len() == full.len() && bin > 0.0) else {
        return None;
    };
    let input = full
        .channel(ChannelKind::Input)
        .map(|c| c.values.as_slice());
    let mut bins = Bins::new(t0, bin, input);
    let (ts, means, _) =
        crate::numerics::series::block_means(&full.t_s, v, |i, t| bins.opens(i, t));
    let same = ts.len() == binned.len()
        && ts
            .iter()
            .zip(&binned.t_s)
            .all(|(t, tb)| (t - tb).abs() <= 1e-6 * bin);
    same.then_some(means)
}

/// Which rows open a new bin of block means: bins of `bin_s` seconds counted from `t0` (none,
/// `bin_s` = 0: one bin per row), and a new bin wherever the input changes. A changing input
/// (a dividing-head programme) closes a bin: a block mean across a head move would be an input
/// value the head never held, and the baseline's one level per input value would need a level
/// for every mixed bin.
struct Bins<'a> {
    t0: f64,
    bin_s: f64,
    input: Option<&'a [f64]>,
    cur: Option<i64>,
    cur_input: f64,
}

impl<'a> Bins<'a> {
    fn new(t0: f64, bin_s: f64, input: Option<&'a [f64]>) -> Self {
        Self {
            t0,
            bin_s,
            input,
            cur: None,
            cur_input: f64::NAN,
        }
    }

    /// Whether row `i` (time `t`, rows in time order) opens a new bin.
    fn opens(&mut self, i: usize, t: f64) -> bool {
        let b = if self.bin_s > 0.0 {
            ((t - self.t0) / self.bin_s).floor() as i64
        } else {
            i as i64
        };
        let moved = self.input.is_some_and(|c| c[i] != self.cur_input);
        if self.cur != Some(b) || moved {
            self.cur = Some(b);
            self.cur_input = self.input.map_or(f64::NAN, |c| c[i]);
            return true;
        }
        false
    }
}

fn reduce(log: &Log, opts: &DatasetOptions, binning: bool) -> Result<Dataset, ImportError> {
    if binning && !(MIN_MAX_POINTS..=MAX_MAX_POINTS).contains(&opts.max_points) {
        return Err(ImportError::Shape(format!(
            "--max-points {} is outside {MIN_MAX_POINTS}..={MAX_MAX_POINTS} (the fit keeps \
             ≈ {BYTES_PER_POINT} bytes per point: {} MB at {}; fewer than {MIN_MAX_POINTS} \
             cannot hold the cross-validation's blocks and the noise model)",
            opts.max_points,
            memory_estimate_bytes(opts.max_points, 0, 0) / 1_000_000,
            opts.max_points
        )));
    }
    let mut warnings = Vec::new();
    let out_name = output_column(log, opts.output.as_deref())
        .ok_or_else(|| ImportError::Shape("no output column (output*, gravity*, a_i*)".into()))?;
    let y_raw = log
        .column(&out_name)
        .ok_or_else(|| ImportError::Shape(format!("no column {out_name}")))?;
    let unit = suffix_of(&out_name);
    let meta = |k: &str| log.meta(k).and_then(|v| v.trim().parse::<f64>().ok());
    let unit_per_g = unit_per_g_for_suffix(&unit)
        .or_else(|| {
            (unit == "v")
                .then(|| meta("scale_factor_v_per_g"))
                .flatten()
        })
        .or(opts.unit_per_g_from_calibration);
    // Temperature: `temperature_c`, else the first `*_c` channel.
    let names: Vec<String> = log.column_names().to_vec();
    let temp_name = names
        .iter()
        .find(|n| n.as_str() == "temperature_c")
        .or_else(|| {
            names
                .iter()
                .find(|n| n.ends_with("_c") && classify(n).is_some())
        })
        .cloned();
    let mut chans: Vec<(String, ChannelKind, f64, &[f64])> = Vec::new();
    for n in &names {
        if n == "time_s" || *n == out_name {
            continue;
        }
        let Some(col) = log.column(n) else { continue };
        let Some((mut kind, f)) = classify(n) else {
            continue;
        };
        if Some(n) == temp_name.as_ref() {
            kind = ChannelKind::Temperature;
        }
        let finite = col.iter().filter(|v| v.is_finite()).count();
        // A channel mostly empty would cost most rows; it is left out and said so.
        if finite * 10 < col.len() * 9 {
            warnings.push(if finite == 0 {
                format!(
                    "channel {n} is empty (all {} values NaN): left out of the model",
                    col.len()
                )
            } else {
                format!(
                    "channel {n} has only {finite} finite values of {}: left out of the model",
                    col.len()
                )
            });
            continue;
        }
        chans.push((n.clone(), kind, f, col));
    }
    let t = log.time_s();
    // Values that are not measurements (±inf, 1e300) are dropped with a warning: one of them
    // makes every sum of squares infinite.
    let mut absurd = vec![false; t.len()];
    for (name, col) in std::iter::once((&out_name, y_raw)).chain(chans.iter().map(|c| (&c.0, c.3)))
    {
        let rows = absurd_rows(col);
        if let Some(&first) = rows.first() {
            warnings.push(format!(
                "{} value(s) of {name} are not measurements (non-finite or absurdly far from \
                 the rest, e.g. {:e} at data row {}): their rows are dropped",
                rows.len(),
                col[first],
                first + 1
            ));
        }
        for i in rows {
            absurd[i] = true;
        }
    }
    let keep: Vec<usize> = (0..t.len())
        .filter(|&i| !absurd[i] && y_raw[i].is_finite() && chans.iter().all(|c| c.3[i].is_finite()))
        .collect();
    let mut notes = vec![format!(
        "{} rows read, {} dropped for a gap (NaN) in the output or a channel",
        t.len(),
        t.len() - keep.len()
    )];
    if keep.len() < MIN_POINTS {
        return Err(ImportError::Shape(format!(
            "only {} usable rows: the models need at least {MIN_POINTS}",
            keep.len()
        )));
    }
    // The fit squares deviations: kept values whose squares overflow (±1e308 throughout, so
    // none is absurd against the others) would print an infinite residual as a result.
    if let Some(big) = keep
        .iter()
        .map(|&i| y_raw[i].abs())
        .max_by(f64::total_cmp)
        .filter(|m| (m * m).is_infinite())
    {
        return Err(ImportError::Shape(format!(
            "output column {out_name}: values up to {big:e} overflow the fit (their squares are \
             infinite): not a measurement"
        )));
    }
    let mut dts: Vec<f64> = keep.windows(2).map(|w| t[w[1]] - t[w[0]]).collect();
    // Unstable: values equal under `total_cmp` are the same bits, so the order is the same.
    dts.sort_unstable_by(f64::total_cmp);
    let median_dt = dts[dts.len() / 2];
    // The bin width comes from the time the record covers, not its span: a long gap (a year
    // between two sessions) would otherwise coarsen every bin of the data there is.
    let gap_limit = 2.5 * median_dt;
    let covered: f64 = dts.iter().map(|d| d.min(gap_limit)).sum();
    let longest_gap = dts.last().copied().unwrap_or(0.0);
    if longest_gap > covered.max(gap_limit) {
        warnings.push(format!(
            "a gap of {:.3e} s ({:.1} days) is longer than all the data together ({:.1} days): \
             the two sides are fitted as one record with separate segments; a drift or a slow \
             effect across the gap is extrapolated over it",
            longest_gap,
            longest_gap / 86_400.0,
            covered / 86_400.0
        ));
    }
    let bin = if binning && keep.len() > opts.max_points {
        whole_samples_bin_s((covered / opts.max_points as f64).max(median_dt), median_dt)
    } else {
        0.0
    };
    // Block means in bins of `bin` seconds (a bin never spans a gap: it simply has fewer
    // samples, and an empty bin is a break).
    let mut ts = Vec::new();
    let mut ys = Vec::new();
    let mut cs: Vec<Vec<f64>> = vec![Vec::new(); chans.len()];
    let mut counts = Vec::new();
    let t0 = t[keep[0]];
    let input_col = chans
        .iter()
        .find(|c| c.1 == ChannelKind::Input)
        .map(|c| c.3);
    let mut bins = Bins::new(t0, bin, input_col);
    for &i in &keep {
        if bins.opens(i, t[i]) {
            ts.push(0.0);
            ys.push(0.0);
            for c in cs.iter_mut() {
                c.push(0.0);
            }
            counts.push(0.0);
        }
        let k = ts.len() - 1;
        ts[k] += t[i];
        ys[k] += y_raw[i];
        for (c, ch) in cs.iter_mut().zip(&chans) {
            c[k] += ch.3[i] * ch.2;
        }
        counts[k] += 1.0;
    }
    for k in 0..ts.len() {
        ts[k] /= counts[k];
        ys[k] /= counts[k];
        for c in cs.iter_mut() {
            c[k] /= counts[k];
        }
    }
    let dt = if bin > 0.0 { bin } else { median_dt };
    if ts.len() < MIN_POINTS {
        return Err(ImportError::Shape(format!(
            "only {} points after binning: the models need at least {MIN_POINTS}",
            ts.len()
        )));
    }
    let out_std = crate::numerics::stats::std(&ys);
    let out_mean = ys.iter().sum::<f64>() / ys.len() as f64;
    if out_std.is_nan() || out_std <= 1e-12 * out_mean.abs() {
        return Err(ImportError::Shape(format!(
            "the output {out_name} is constant ({out_mean:e}, standard deviation {out_std:e}): \
             there is nothing to discover"
        )));
    }
    let segment_start: Vec<bool> = (0..ts.len())
        .map(|k| k == 0 || ts[k] - ts[k - 1] > 2.5 * dt)
        .collect();
    let n_seg = segment_start.iter().filter(|&&s| s).count();
    notes.push(format!(
        "{} points used (bin {:.3} s{}), {} contiguous segment(s)",
        ts.len(),
        dt,
        if bin > 0.0 {
            ", block means"
        } else {
            ", unbinned"
        },
        n_seg
    ));
    notes.push(format!(
        "memory estimate {} MB ({} points × {BYTES_PER_POINT} B for the fit + {} rows × {} \
         columns read)",
        memory_estimate_bytes(ts.len(), t.len(), names.len()) / 1_000_000 + 1,
        ts.len(),
        t.len(),
        names.len()
    ));
    let channels: Vec<Channel> = chans
        .iter()
        .zip(cs)
        .map(|(c, v)| Channel {
            name: c.0.clone(),
            kind: c.1,
            values: v,
        })
        .collect();
    let input_g = meta("input_g").or_else(|| {
        channels
            .iter()
            .find(|c| c.kind == ChannelKind::Input)
            .map(|c| c.values.iter().sum::<f64>() / c.values.len() as f64)
    });
    let site = match (meta("latitude_deg"), meta("longitude_deg")) {
        (Some(la), Some(lo)) => Some((la, lo, meta("height_m").unwrap_or(0.0))),
        _ => None,
    };
    Ok(Dataset {
        t_s: ts,
        y: ys,
        segment_start,
        channels,
        output_name: out_name,
        output_unit: unit,
        unit_per_g,
        input_g,
        start_unix_s: log.meta("start_utc").and_then(parse_utc),
        site,
        dt_s: dt,
        samples_per_point: counts,
        notes,
        warnings,
    })
}

#[cfg(test)]
impl Dataset {
    /// A record in g starting one segment at its first point, with no channels, date or site:
    /// the base the unit tests build on (`Dataset { channels, ..Dataset::test_g(..) }`).
    pub(crate) fn test_g(t_s: Vec<f64>, y: Vec<f64>, dt_s: f64) -> Self {
        let segment_start = (0..t_s.len()).map(|i| i == 0).collect();
        Dataset {
            t_s,
            y,
            segment_start,
            channels: Vec::new(),
            output_name: "output_g".into(),
            output_unit: "g".into(),
            unit_per_g: Some(1.0),
            input_g: Some(1.0),
            start_unix_s: None,
            site: None,
            dt_s,
            samples_per_point: Vec::new(),
            notes: Vec::new(),
            warnings: Vec::new(),
        }
    }
}

impl Dataset {
    /// The unit a channel's values are stored in (Pa for pressure, rad for tilt, °C for a
    /// `_c` column, else its column suffix), as a coupling's coefficient is per it.
    pub fn channel_unit(&self, name: &str) -> String {
        match self
            .channels
            .iter()
            .find(|c| c.name == name)
            .map(|c| c.kind)
        {
            Some(ChannelKind::Pressure) => "Pa".into(),
            Some(ChannelKind::Tilt) => "rad".into(),
            _ => match suffix_of(name).as_str() {
                "c" => "°C".into(),
                "" => "channel unit".into(),
                s => s.to_owned(),
            },
        }
    }

    /// Mean rows read per point (1 when not binned or not known).
    pub fn rows_per_point(&self) -> f64 {
        if self.samples_per_point.is_empty() {
            1.0
        } else {
            self.samples_per_point.iter().sum::<f64>() / self.samples_per_point.len() as f64
        }
    }
    /// The first channel of a kind.
    pub fn channel(&self, kind: ChannelKind) -> Option<&Channel> {
        self.channels.iter().find(|c| c.kind == kind)
    }
    /// Number of points.
    pub fn len(&self) -> usize {
        self.y.len()
    }
    /// No points.
    pub fn is_empty(&self) -> bool {
        self.y.is_empty()
    }
    /// Duration covered, seconds.
    pub fn span_s(&self) -> f64 {
        match (self.t_s.first(), self.t_s.last()) {
            (Some(a), Some(b)) => b - a,
            _ => 0.0,
        }
    }
    /// Whether this is a "1 g" record (|input| > 0.5 g); tilt enters as cos, tides as gravity.
    pub fn is_one_g(&self) -> bool {
        self.input_g.is_some_and(|g| g.abs() > 0.5)
    }
    /// The per-row input (g) when the record has an `input_g` channel that changes (a
    /// dividing-head programme; more than 1 mg standard deviation), else `None` (a static test:
    /// the scalar [`Dataset::input_g`] describes it).
    pub fn changing_input(&self) -> Option<&[f64]> {
        self.channel(ChannelKind::Input)
            .filter(|c| crate::numerics::stats::std(&c.values) > CHANGING_INPUT_STD_G)
            .map(|c| c.values.as_slice())
    }
    /// The nominal input at row `i`, g: the input channel when it changes, else the scalar.
    pub fn input_at(&self, i: usize) -> Option<f64> {
        match self.changing_input() {
            Some(v) => v.get(i).copied(),
            None => self.input_g,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn beijing_time_is_moved_to_utc_and_bad_rows_keep_their_line_numbers() {
        let text = "2021 06 08 08 00 00  5882.3353 1002.2656\n\
                    2021 06 08 08 01 00  5882.3373\n\
                    2021 06 08 08 02 00  5882.3393 1002.2000\n\
                    2021 06 08 08 02 00  5882.3393 1002.2000\n";
        let (log, bad) = gmetrology_from_str(text).unwrap();
        assert_eq!(log.meta("start_utc"), Some("2021-06-08T00:00:00.000Z"));
        assert_eq!(log.time_s(), &[0.0, 120.0]);
        assert_eq!(bad.iter().map(|b| b.line).collect::<Vec<_>>(), vec![2, 4]);
    }

    #[test]
    fn dates_that_do_not_exist_are_bad_rows_not_wrapped_or_rolled_over() {
        // Month 257 would wrap to 1 through an `as u8`; 2021-02-29 and 24:00 do not exist.
        let text = "2021 06 08 08 00 00  5882.3353 1002.2656
                    2021 257 08 08 01 00  5882.3373 1002.2656
                    2021 02 29 08 01 00  5882.3373 1002.2656
                    2021 06 08 24 00 00  5882.3373 1002.2656
                    2021 06 08 08 02 00  5882.3393 1002.2000
";
        let (log, bad) = gmetrology_from_str(text).unwrap();
        assert_eq!(log.time_s(), &[0.0, 120.0]);
        assert_eq!(
            bad.iter().map(|b| b.line).collect::<Vec<_>>(),
            vec![2, 3, 4]
        );
        assert!(bad.iter().all(|b| b.reason == "invalid date/time"));
        // A leap year's 29 February exists.
        assert_eq!(
            UtcTime::new(2024, 2, 29, 23, 59, 30.5).map(|t| t.posix_seconds()),
            Ok(1_709_251_170.5)
        );
    }

    #[test]
    fn an_input_g_column_is_the_input_channel_and_bins_never_straddle_a_head_move() {
        // 2000 rows at 1 s, the head at +1 g for 701 s, then 0 g.
        let mut log = Log::with_time((0..2000).map(f64::from).collect()).unwrap();
        log.set_meta("input_g", "1").unwrap();
        log.push_column(
            "output_v",
            (0..2000).map(|i| 0.5 + 1e-3 * f64::from(i % 7)).collect(),
        )
        .unwrap();
        let a: Vec<f64> = (0..2000).map(|i| if i < 701 { 1.0 } else { 0.0 }).collect();
        log.push_column("input_g", a).unwrap();
        let opts = DatasetOptions {
            max_points: 1000,
            ..DatasetOptions::default()
        };
        let ds = dataset_from_log(&log, &opts).unwrap();
        let input = ds.changing_input().unwrap();
        assert!(input.iter().all(|&v| v == 1.0 || v == 0.0), "{input:?}");
        // Bins of 1999 s / 1000 = 1.999 s: 1001 by time (the last holds t = 1999 s), and the
        // one over 699.65–701.65 s split at the move (t = 700 at 1 g, t = 701 at 0 g).
        assert_eq!(ds.len(), 1002);
        assert_eq!(ds.input_at(350), Some(1.0));
        assert_eq!(ds.input_at(351), Some(0.0));
    }

    #[test]
    fn wide_bins_hold_a_whole_number_of_samples_so_their_means_are_evenly_spaced() {
        // 100 000 rows at 1 s into at most 1000 points: 99.999 s rounds up to 100 s, so every
        // bin holds 100 samples and the bin means are exactly 100 s apart.
        let n = 100_000;
        let mut log = Log::with_time((0..n).map(f64::from).collect()).unwrap();
        log.push_column(
            "output_v",
            (0..n).map(|i| 0.5 + 1e-6 * f64::from(i % 13)).collect(),
        )
        .unwrap();
        let opts = DatasetOptions {
            max_points: 1000,
            ..DatasetOptions::default()
        };
        let ds = dataset_from_log(&log, &opts).unwrap();
        assert_eq!(ds.dt_s, 100.0);
        assert_eq!(ds.len(), 1000);
        assert!(
            ds.t_s
                .windows(2)
                .all(|w| (w[1] - w[0] - 100.0).abs() < 1e-9),
            "uneven spacing"
        );
        // A width under 8 intervals is kept as it is (rounding 1.4 up to 2 would drop points).
        assert_eq!(whole_samples_bin_s(1.4, 1.0), 1.4);
        assert_eq!(whole_samples_bin_s(70.848, 1.0), 71.0);
        assert_eq!(whole_samples_bin_s(71.0, 1.0), 71.0);
    }

    #[test]
    fn sequence_numbers_and_clocks_of_a_record_are_not_channels() {
        // The columns `accomp record` and the demo write beside the physical ones.
        for name in [
            "seq",
            "fw_seq",
            "board_time_us",
            "unix_time_s",
            "fw_time_s",
            "floor_a_i_g",
        ] {
            assert_eq!(classify(name), None, "{name}");
        }
        assert_eq!(
            classify("temperature_c").map(|c| c.0),
            Some(ChannelKind::Other)
        );
        assert_eq!(
            classify("tilt_arcsec").map(|c| c.0),
            Some(ChannelKind::Tilt)
        );
        assert_eq!(
            classify("pressure_hpa").map(|c| c.0),
            Some(ChannelKind::Pressure)
        );
    }

    #[test]
    fn utc_round_trips_through_text() {
        let u = parse_utc("2020-07-31T12:15:00.015Z").unwrap();
        assert_eq!(format_utc(u), "2020-07-31T12:15:00.015Z");
        // 2020-07-31 is day 18474 after 1970-01-01.
        assert!((u - (18_474.0 * 86_400.0 + 12.0 * 3600.0 + 900.015)).abs() < 1e-6);
    }

    #[test]
    fn a_gap_splits_segments_and_nan_rows_are_dropped_not_filled() {
        let mut log = Log::with_time(vec![0.0, 1.0, 2.0, 3.0, 10.0, 11.0, 12.0]).unwrap();
        let mut y: Vec<f64> = (0..7).map(f64::from).collect();
        y[2] = f64::NAN;
        log.push_column("output_g", y).unwrap();
        let mut ds_rows = vec![20.0; 7];
        ds_rows[0] = 21.0;
        log.push_column("temperature_c", ds_rows).unwrap();
        let ds = dataset_from_log(&log, &DatasetOptions::default());
        // Fewer than MIN_POINTS rows is refused outright.
        assert!(ds.is_err());
        let t: Vec<f64> = (0..200)
            .map(|i| if i < 100 { i as f64 } else { i as f64 + 50.0 })
            .collect();
        let mut log = Log::with_time(t).unwrap();
        let mut y: Vec<f64> = (0..200).map(|i| f64::from(i % 5)).collect();
        y[5] = f64::NAN;
        log.push_column("output_g", y).unwrap();
        let ds = dataset_from_log(&log, &DatasetOptions::default()).unwrap();
        assert_eq!(ds.len(), 199);
        assert_eq!(ds.segment_start.iter().filter(|&&s| s).count(), 2);
        assert!(ds.segment_start[99]);
        assert_eq!(ds.unit_per_g, Some(1.0));
    }
}
