//! Stability analysis of a log, as the paper defines it, plus Allan-type deviations.
//!
//! - **Stability** (paper: "standard deviation of equally spaced readings over the test
//!   period"): the sample standard deviation (divisor `n - 1`) of the finite readings of a
//!   column, before and after compensation simply being two columns of the same log.
//! - **Coefficient stability / drift** (paper: "regression standard deviation when each
//!   coefficient is fitted linearly against time"): least-squares line `y = a + b t` against
//!   `time_s`, residual standard deviation `s = sqrt(RSS / (n - 2))`, slope `b` per second and its
//!   standard error `s / sqrt(sum (t - mean t)^2)`. Works for any spacing, so a log of repeated
//!   tumble-test coefficients (one row per test) is analysed the same way.
//! - **OADEV / MDEV** with intervals and noise identification: see [`crate::allan`].
//!
//! # Units
//!
//! Output columns are reported in g where the log allows it:
//! - a column ending `_g` is in g already;
//! - a column ending `_v` is divided by the metadata value `scale_factor_v_per_g` (the paper's
//!   K1, V/g) when the log has it; without it the column stays in V (reported unit `V`);
//! - any other column keeps its own unit, named by its suffix (`temperature_c` → `c`).
//!
//! # Sampling grid and gaps
//!
//! Allan deviations need equally spaced readings. `tau0` is the median spacing of `time_s`. If
//! every spacing is within 1 % of it, the readings are used as they are. Otherwise each reading
//! is placed on the grid `t0 + k tau0` (it must lie within `tau0 / 4` of a grid point, one
//! reading per point) and the empty grid points become gaps (NaN), which the Allan code skips
//! (never interpolates). A log whose time stamps do not fit a grid gets stability and regression
//! but no Allan curves, and the report says why. A recorder's log (`accomp record`) is split
//! into continuous segments instead ([`LogGrid`]): after each `board_reset` or `table_changed`
//! event line and at each change of sampling phase; no Allan term spans two segments.

use crate::allan::{AllanPoint, Phase, Statistic, TauSet};
use crate::log::{event_kind, unit_suffix, Event, Log, LogError, TIME_COLUMN};
use crate::text_table::Columns;
use serde::Serialize;

/// Metadata key of the accelerometer scale factor used to convert `_v` columns to g.
pub const SCALE_FACTOR_KEY: &str = "scale_factor_v_per_g";

/// Errors of the stability analysis.
#[derive(Debug, thiserror::Error)]
pub enum StabilityError {
    /// The log could not be read, or its metadata is malformed.
    #[error(transparent)]
    Log(#[from] LogError),
    /// A requested column is not a numeric column of the log.
    #[error("no numeric column {0:?} in the log")]
    NoSuchColumn(String),
    /// The log has no column that the default selection would analyse.
    #[error("no output column (`*_v` or `*_g` other than input_g); name one with --column")]
    NoOutputColumn,
    /// `scale_factor_v_per_g` is present but not a positive number.
    #[error("metadata scale_factor_v_per_g = {0} is not positive")]
    BadScaleFactor(f64),
    /// A column's values are so large that its statistics overflow (±1e308): no result is
    /// printed as ±inf.
    #[error(
        "column {0:?}: its values (up to {1:e}) overflow the statistics (mean, standard \
         deviation, drift): not a measurement, refused"
    )]
    Overflow(String, f64),
    /// `--taus all` on a record too long for an O(N^2) computation.
    #[error("--taus all on {0} samples would take hours (O(N^2)); use --taus octave")]
    TooLongForAllTaus(usize),
}

/// Why a time base is not an equally spaced grid.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GridError {
    /// Fewer than 3 samples.
    #[error("fewer than 3 samples")]
    TooShort,
    /// A time stamp is further than tau0/4 from the grid.
    #[error("time_s[{index}] = {time_s} is off the {tau0_s} s grid")]
    OffGrid {
        /// Sample index.
        index: usize,
        /// Its time stamp.
        time_s: f64,
        /// The grid spacing.
        tau0_s: f64,
    },
    /// The grid would be mostly gaps.
    #[error("time stamps span {grid} grid points for {samples} samples")]
    TooSparse {
        /// Grid points needed.
        grid: usize,
        /// Samples available.
        samples: usize,
    },
}

/// The sampling grid of a log.
#[derive(Debug, Clone, PartialEq)]
pub struct Grid {
    /// Spacing, s.
    pub tau0_s: f64,
    /// Grid index of each sample; `None` when the samples are the grid (no gaps in time).
    pub index: Option<Vec<usize>>,
    /// Number of grid points.
    pub len: usize,
}

/// The median time step of `t` (at least 3 stamps, strictly increasing): the grid's τ0,
/// refused when the grid it spans would hold more than four points a sample.
fn median_step(t: &[f64]) -> Result<f64, GridError> {
    let n = t.len();
    let mut d: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    let mid = d.len() / 2;
    let (_, &mut tau0, _) = d.select_nth_unstable_by(mid, f64::total_cmp);
    let grid = ((t[n - 1] - t[0]) / tau0).round() as usize + 1;
    if grid > 4 * n {
        return Err(GridError::TooSparse { grid, samples: n });
    }
    Ok(tau0)
}

impl Grid {
    /// Works out the grid from `time_s` (strictly increasing, as the log reader guarantees).
    pub fn from_time(t: &[f64]) -> Result<Self, GridError> {
        let n = t.len();
        if n < 3 {
            return Err(GridError::TooShort);
        }
        let (first, last) = (t[0], t[n - 1]);
        let nominal = (last - first) / (n - 1) as f64;
        // Fast path: equal spacing (the usual case) needs no sort.
        let regular = |tau0: f64| {
            t.windows(2)
                .all(|w| ((w[1] - w[0]) - tau0).abs() <= 0.01 * tau0)
        };
        if regular(nominal) {
            return Ok(Grid {
                tau0_s: nominal,
                index: None,
                len: n,
            });
        }
        let tau0 = median_step(t)?;
        let mut index = Vec::with_capacity(n);
        let mut prev: Option<usize> = None;
        for (i, &ti) in t.iter().enumerate() {
            let k_f = ((ti - first) / tau0).round();
            let off = (ti - first) - k_f * tau0;
            let k = k_f as usize;
            if off.abs() > 0.25 * tau0 || prev.is_some_and(|p| k <= p) {
                return Err(GridError::OffGrid {
                    index: i,
                    time_s: ti,
                    tau0_s: tau0,
                });
            }
            prev = Some(k);
            index.push(k);
        }
        let len = prev.map_or(0, |p| p + 1);
        Ok(Grid {
            tau0_s: tau0,
            index: Some(index),
            len,
        })
    }

    /// For a recorder's log (`accomp record`): as [`Grid::from_time`], but a row off the grid —
    /// a board reset, whose new boot samples at another phase — starts a new continuous segment
    /// instead of refusing the log, and so does every row of `forced` (ascending: the first rows
    /// after the record's `board_reset` and `table_changed` events, on the old phase or not).
    /// Each segment keeps its own time stamps; it is placed at the grid point nearest its first
    /// row, with at least one empty point before it, so no Allan term spans two segments (terms
    /// touching a gap are skipped): the deviation pools the terms within the segments and
    /// nothing is resampled. Returns the grid and the first row of every segment after the
    /// first; refuses (with the first new segment's row) beyond [`MAX_SEGMENTS`].
    pub fn from_time_segmented(
        t: &[f64],
        forced: &[usize],
    ) -> Result<(Self, Vec<usize>), GridError> {
        let n = t.len();
        if n < 3 {
            return Err(GridError::TooShort);
        }
        let first = t[0];
        let tau0 = median_step(t)?;
        let mut index = Vec::with_capacity(n);
        let mut starts = Vec::new();
        let mut prev: Option<usize> = None;
        // Phase of the current segment: its time stamps sit at first + shift + k tau0.
        let mut shift = 0.0;
        let mut forced = forced.iter().copied().filter(|&r| r > 0).peekable();
        for (i, &ti) in t.iter().enumerate() {
            let k_f = ((ti - first - shift) / tau0).round();
            let off = (ti - first - shift) - k_f * tau0;
            let mut k = k_f.max(0.0) as usize;
            let event = forced.next_if(|&r| r <= i).is_some();
            if event || off.abs() > 0.25 * tau0 || prev.is_some_and(|p| k <= p) {
                if starts.len() == MAX_SEGMENTS {
                    return Err(GridError::OffGrid {
                        index: starts[0],
                        time_s: t[starts[0]],
                        tau0_s: tau0,
                    });
                }
                let p = prev.unwrap_or(0);
                k = (((ti - first) / tau0).round().max(0.0) as usize).max(p + 2);
                shift = (ti - first) - k as f64 * tau0;
                starts.push(i);
            }
            prev = Some(k);
            index.push(k);
        }
        let len = prev.map_or(0, |p| p + 1);
        Ok((
            Grid {
                tau0_s: tau0,
                index: Some(index),
                len,
            },
            starts,
        ))
    }

    /// The column laid on the grid: samples where they fall, NaN at missing points.
    pub fn place(&self, y: &[f64]) -> Vec<f64> {
        match &self.index {
            None => y.to_vec(),
            Some(idx) => {
                let mut out = vec![f64::NAN; self.len];
                for (&k, &v) in idx.iter().zip(y) {
                    if let Some(slot) = out.get_mut(k) {
                        *slot = v;
                    }
                }
                out
            }
        }
    }
}

/// Least-squares line against time.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Regression {
    /// Value at `time_s = 0`.
    pub intercept: f64,
    /// Slope per second.
    pub slope_per_s: f64,
    /// Standard error of the slope.
    pub slope_se: f64,
    /// Residual standard deviation `sqrt(RSS / (n - 2))`.
    pub residual_std: f64,
    /// Pairs used.
    pub n: usize,
}

/// Interleaved partial sums of the stability passes: independent add chains that vectorise, so
/// a pass over a 41-day log runs at memory speed instead of one add latency per sample.
const SUM_LANES: usize = 4;

/// `(count, sums)` over the indices `k < n` where `keep(k)`: `sums[j] = sum f(k)[j]`, in
/// [`SUM_LANES`] interleaved partial sums. Skipped terms add nothing (a select, not a multiply
/// by zero, so a NaN in a skipped term cannot leak in).
fn masked_sums<const J: usize>(
    n: usize,
    keep: impl Fn(usize) -> bool,
    f: impl Fn(usize) -> [f64; J],
) -> (usize, [f64; J]) {
    let mut acc = [[0.0f64; J]; SUM_LANES];
    let mut cnt = [0usize; SUM_LANES];
    let mut add = |lane: usize, k: usize| {
        let on = keep(k);
        let v = f(k);
        for (a, x) in acc[lane].iter_mut().zip(v) {
            *a += if on { x } else { 0.0 };
        }
        cnt[lane] += usize::from(on);
    };
    for c in 0..n / SUM_LANES {
        for lane in 0..SUM_LANES {
            add(lane, c * SUM_LANES + lane);
        }
    }
    for k in n / SUM_LANES * SUM_LANES..n {
        add(0, k);
    }
    let mut total = [0.0f64; J];
    for (j, t) in total.iter_mut().enumerate() {
        *t = (acc[0][j] + acc[1][j]) + (acc[2][j] + acc[3][j]);
    }
    (cnt.iter().sum(), total)
}

/// Mean and sample standard deviation (divisor n - 1) of the finite values; `None` below 2.
pub fn mean_std(y: &[f64]) -> Option<(f64, f64, usize)> {
    let fin = |k: usize| y[k].is_finite();
    // Sums of the deviations from the first value: a constant column sums to exactly 0 (its
    // mean and standard deviation exact, std 0 rather than the 6e-14 of a rounded mean).
    let y0 = y.iter().copied().find(|v| v.is_finite())?;
    let (n, [s]) = masked_sums(y.len(), fin, |k| [y[k] - y0]);
    if n < 2 {
        return None;
    }
    let shift = s / n as f64;
    // Second pass on deviations: the one-pass formula loses everything for a 1 g output whose
    // scatter is 1e-6 g.
    let (_, [ss]) = masked_sums(y.len(), fin, |k| {
        let d = (y[k] - y0) - shift;
        [d * d]
    });
    Some((y0 + shift, (ss / (n - 1) as f64).sqrt(), n))
}

/// Linear regression of `y` on `t` over pairs where both are finite; `None` below 3 pairs or for
/// a constant `t`.
pub fn regression(t: &[f64], y: &[f64]) -> Option<Regression> {
    let len = t.len().min(y.len());
    let (t, y) = (&t[..len], &y[..len]);
    let both = |k: usize| t[k].is_finite() && y[k].is_finite();
    let (n, [st, sy]) = masked_sums(len, both, |k| [t[k], y[k]]);
    if n < 3 {
        return None;
    }
    let (tm, ym) = (st / n as f64, sy / n as f64);
    // Centred sums: t runs to 3.5e6 s and y sits near 1 g, raw sums would cancel.
    let (_, [sxx, sxy]) = masked_sums(len, both, |k| {
        let (dt, dy) = (t[k] - tm, y[k] - ym);
        [dt * dt, dt * dy]
    });
    if sxx <= 0.0 {
        return None;
    }
    let slope = sxy / sxx;
    let (_, [rss]) = masked_sums(len, both, |k| {
        let r = (y[k] - ym) - slope * (t[k] - tm);
        [r * r]
    });
    let s = (rss / (n - 2) as f64).sqrt();
    Some(Regression {
        intercept: ym - slope * tm,
        slope_per_s: slope,
        slope_se: s / sxx.sqrt(),
        residual_std: s,
        n,
    })
}

/// Analysis results for one column, in its reported unit.
#[derive(Debug, Clone, PartialEq)]
pub struct ColumnReport {
    /// Column name.
    pub name: String,
    /// Reported unit (`g`, `V`, or the column's suffix).
    pub unit: String,
    /// Finite readings.
    pub n: usize,
    /// Gaps (NaN readings in the column).
    pub gaps: usize,
    /// Mean.
    pub mean: Option<f64>,
    /// Sample standard deviation: the paper's stability.
    pub std: Option<f64>,
    /// Line against time.
    pub regression: Option<Regression>,
    /// The Allan deviation curves.
    pub allan: AllanCurves,
}

/// A column's Allan deviation curves, with why they are empty (or what limits them).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct AllanCurves {
    /// OADEV curve.
    pub adev: Vec<AllanPoint>,
    /// MDEV curve.
    pub mdev: Vec<AllanPoint>,
    /// Why the curves are empty, if they are, or the note on the segments they were taken over.
    pub note: Option<String>,
}

/// What to analyse.
#[derive(Debug, Clone, PartialEq)]
pub struct Options {
    /// Columns; empty = the default selection (see [`default_columns`]).
    pub columns: Vec<String>,
    /// Tau set of the Allan curves.
    pub taus: TauSet,
    /// Compute the Allan curves at all.
    pub allan: bool,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            columns: Vec::new(),
            taus: TauSet::Octave,
            allan: true,
        }
    }
}

/// Whole-log report.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    /// Sample spacing used for the Allan curves (None if the time base is not a grid).
    pub tau0_s: Option<f64>,
    /// Rows in the log.
    pub rows: usize,
    /// Grid points (rows + missing time stamps).
    pub grid_len: Option<usize>,
    /// Per-column results.
    pub columns: Vec<ColumnReport>,
}

/// The default selection: every numeric column whose unit suffix is `v` or `g`, except
/// `input_g` (the nominal input, not a reading).
pub fn default_columns(log: &Log) -> Vec<String> {
    log.column_names()
        .iter()
        .filter(|n| n.as_str() != TIME_COLUMN && n.as_str() != "input_g")
        .filter(|n| matches!(unit_suffix(n).as_deref(), Some("v" | "g")))
        .filter(|n| log.column(n).is_some())
        .cloned()
        .collect()
}

/// Unit and multiplier that bring a column to its reported unit.
pub fn column_unit(log: &Log, name: &str) -> Result<(String, f64), StabilityError> {
    match unit_suffix(name).as_deref() {
        Some("g") => Ok(("g".into(), 1.0)),
        Some("v") => match log.meta_f64(SCALE_FACTOR_KEY)? {
            Some(k1) if k1 > 0.0 => Ok(("g".into(), 1.0 / k1)),
            Some(k1) => Err(StabilityError::BadScaleFactor(k1)),
            None => Ok(("V".into(), 1.0)),
        },
        Some(u) => Ok((u.to_owned(), 1.0)),
        None => Ok((String::new(), 1.0)),
    }
}

/// Most continuous segments a recorder's log is split into for the Allan deviation
/// ([`Grid::from_time_segmented`]); beyond, the time base is taken as no grid.
pub const MAX_SEGMENTS: usize = 1000;

/// Metadata key that marks a recorder's log (`accomp record <version>`).
pub const RECORDER_KEY: &str = "recorder";

/// Above this many grid points `TauSet::All` is refused (O(N^2)).
pub const MAX_ALL_TAUS_LEN: usize = 200_000;

/// The event kinds of a record that start a new continuous segment at the first row after
/// them: a new boot (its readings need not continue the last boot's), and another compensation
/// table (the compensated output's level and scale may jump). A `seq_gap` or `link_lost` is no
/// boundary: its missing rows are empty grid points already.
pub const SEGMENT_EVENTS: [&str; 2] = [event_kind::BOARD_RESET, event_kind::TABLE_CHANGED];

/// Why a continuous segment of a recorder's log starts where it does.
#[derive(Debug, Clone, PartialEq)]
pub enum SegmentCause {
    /// Event lines of [`SEGMENT_EVENTS`] kinds just before the segment's first row (in file
    /// order, at least one).
    Events(Vec<Event>),
    /// The row is off the previous segment's sampling grid, with no such event before it.
    PhaseChange,
}

impl SegmentCause {
    /// What starts the segment, short: the event kinds (`board_reset`, `board_reset +
    /// table_changed`) or `phase change`.
    pub fn kind(&self) -> String {
        match self {
            SegmentCause::Events(ev) => ev
                .iter()
                .map(|e| e.kind.as_str())
                .collect::<Vec<_>>()
                .join(" + "),
            SegmentCause::PhaseChange => "phase change".into(),
        }
    }
}

/// The start of a continuous segment after the first.
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentStart {
    /// Its first row.
    pub row: usize,
    /// Why it starts there.
    pub cause: SegmentCause,
}

/// The sampling grid of a log for its Allan deviations, as `stability` and `plot` use it.
#[derive(Debug, Clone, PartialEq)]
pub struct LogGrid {
    /// The grid, or why the time base is none.
    pub grid: Result<Grid, GridError>,
    /// Every continuous segment after the first (empty unless a recorder's log crosses a board
    /// reset, a table change or a change of phase).
    pub segments: Vec<SegmentStart>,
}

impl LogGrid {
    /// The grid of `log`: a recorder's log is split into its continuous segments
    /// ([`Grid::from_time_segmented`]) after each of its [`SEGMENT_EVENTS`] and at each change
    /// of sampling phase; any other log off the grid has none.
    pub fn of(log: &Log) -> Self {
        let t = log.time_s();
        let recorder_log = log
            .meta(RECORDER_KEY)
            .is_some_and(|r| r.starts_with("accomp record"));
        let unsplit = |grid| LogGrid {
            grid,
            segments: Vec::new(),
        };
        if !recorder_log {
            return unsplit(Grid::from_time(t));
        }
        // Events before the first row or after the last start no segment.
        let boundary_events: Vec<&Event> = log
            .events()
            .iter()
            .filter(|e| SEGMENT_EVENTS.contains(&e.kind.as_str()) && e.row > 0 && e.row < t.len())
            .collect();
        let mut forced: Vec<usize> = boundary_events.iter().map(|e| e.row).collect();
        forced.dedup();
        let whole = Grid::from_time(t);
        match (&whole, forced.is_empty()) {
            (Ok(_), true) => return unsplit(whole),
            (Err(GridError::OffGrid { .. }), _) | (Ok(_), false) => {}
            (Err(_), _) => return unsplit(whole),
        }
        match Grid::from_time_segmented(t, &forced) {
            Ok((g, starts)) => LogGrid {
                grid: Ok(g),
                segments: starts
                    .into_iter()
                    .map(|row| {
                        let ev: Vec<Event> = boundary_events
                            .iter()
                            .filter(|e| e.row == row)
                            .map(|&e| e.clone())
                            .collect();
                        SegmentStart {
                            row,
                            cause: if ev.is_empty() {
                                SegmentCause::PhaseChange
                            } else {
                                SegmentCause::Events(ev)
                            },
                        }
                    })
                    .collect(),
            },
            // Beyond MAX_SEGMENTS: no grid (a whole grid would span the events silently).
            Err(e) => unsplit(whole.and(Err(e))),
        }
    }

    /// The first row of every segment after the first.
    pub fn segment_rows(&self) -> Vec<usize> {
        self.segments.iter().map(|s| s.row).collect()
    }
}

/// How many segment starts each cause gave, in words: `1 board_reset, 2 phase changes`.
pub fn segment_causes(segments: &[SegmentStart]) -> String {
    let mut counts: Vec<(String, usize)> = Vec::new();
    for s in segments {
        let kind = s.cause.kind();
        match counts.iter_mut().find(|(k, _)| *k == kind) {
            Some((_, n)) => *n += 1,
            None => counts.push((kind, 1)),
        }
    }
    counts
        .iter()
        .map(|(k, n)| match (k.as_str(), n) {
            ("phase change", 2..) => format!("{n} phase changes"),
            _ => format!("{n} {k}"),
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// What a log split into continuous segments means for its Allan deviation, in words (`None`
/// for one segment): how many segments each cause started, and where the first five start with
/// their cause (the event's kind and UTC, or a change of sampling phase).
pub fn segment_note(t: &[f64], segments: &[SegmentStart]) -> Option<String> {
    if segments.is_empty() {
        return None;
    }
    let shown: Vec<String> = segments
        .iter()
        .take(5)
        .map(|s| {
            let why = match &s.cause {
                SegmentCause::Events(ev) => ev
                    .iter()
                    .map(|e| format!("{} event at {}", e.kind, e.utc))
                    .collect::<Vec<_>>()
                    .join(", "),
                SegmentCause::PhaseChange => "the sampling phase changes".into(),
            };
            format!("{} ({why})", t[s.row])
        })
        .collect();
    Some(format!(
        "{} continuous segments ({}): new ones start at time_s = {}{}; the Allan deviation pools \
         the terms within each segment, none spans two, nothing is resampled",
        segments.len() + 1,
        segment_causes(segments),
        shown.join(", "),
        if segments.len() > 5 { ", …" } else { "" }
    ))
}

/// Analyses a log.
pub fn analyse(log: &Log, opts: &Options) -> Result<Report, StabilityError> {
    let names = if opts.columns.is_empty() {
        let d = default_columns(log);
        if d.is_empty() {
            return Err(StabilityError::NoOutputColumn);
        }
        d
    } else {
        opts.columns.clone()
    };
    let t = log.time_s();
    let LogGrid { grid, segments } = LogGrid::of(log);
    let segment_note = segment_note(t, &segments);
    if let (Ok(g), TauSet::All, true) = (&grid, opts.taus, opts.allan) {
        if g.len > MAX_ALL_TAUS_LEN {
            return Err(StabilityError::TooLongForAllTaus(g.len));
        }
    }
    let mut columns = Vec::with_capacity(names.len());
    for name in names {
        let raw = log
            .column(&name)
            .ok_or_else(|| StabilityError::NoSuchColumn(name.clone()))?;
        let (unit, k) = column_unit(log, &name)?;
        let scaled: Vec<f64>;
        let y: &[f64] = if k == 1.0 {
            raw
        } else {
            scaled = raw.iter().map(|v| v * k).collect();
            &scaled
        };
        let ms = mean_std(y);
        let regression = regression(t, y);
        let overflows = ms.is_some_and(|m| !(m.0.is_finite() && m.1.is_finite()))
            || regression.as_ref().is_some_and(|r| {
                ![r.intercept, r.slope_per_s, r.slope_se, r.residual_std]
                    .iter()
                    .all(|v| v.is_finite())
            });
        if overflows {
            let biggest = y
                .iter()
                .filter(|v| v.is_finite())
                .fold(0.0f64, |m, v| m.max(v.abs()));
            return Err(StabilityError::Overflow(name.clone(), biggest));
        }
        let mut rep = ColumnReport {
            name: name.clone(),
            unit,
            n: ms.map_or(y.iter().filter(|v| v.is_finite()).count(), |m| m.2),
            gaps: y.iter().filter(|v| v.is_nan()).count(),
            mean: ms.map(|m| m.0),
            std: ms.map(|m| m.1),
            regression,
            allan: AllanCurves::default(),
        };
        if opts.allan {
            match &grid {
                Err(e) => rep.allan.note = Some(format!("time base is not a grid: {e}")),
                Ok(g) => {
                    // A gapless grid is the column itself: no 28 MB copy for a 41-day log.
                    let on_grid: std::borrow::Cow<[f64]> = match g.index {
                        None => std::borrow::Cow::Borrowed(y),
                        Some(_) => std::borrow::Cow::Owned(g.place(y)),
                    };
                    match Phase::from_readings(&on_grid, g.tau0_s) {
                        Ok(p) => {
                            rep.allan.adev = p.deviation(Statistic::Oadev, opts.taus);
                            rep.allan.mdev = p.deviation(Statistic::Mdev, opts.taus);
                            rep.allan.note.clone_from(&segment_note);
                        }
                        Err(e) => rep.allan.note = Some(e.to_string()),
                    }
                }
            }
        }
        columns.push(rep);
    }
    Ok(Report {
        tau0_s: grid.as_ref().ok().map(|g| g.tau0_s),
        rows: log.len(),
        grid_len: grid.as_ref().ok().map(|g| g.len),
        columns,
    })
}

/// One Allan point as `accomp stability --json` prints it; the deviation is keyed by its
/// statistic (`adev` or `mdev`).
#[derive(Serialize)]
struct PointJson {
    tau_s: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    adev: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    mdev: Option<f64>,
    ci_low: f64,
    ci_high: f64,
    edf: f64,
    n: usize,
    alpha: i32,
    alpha_identified: bool,
}

impl PointJson {
    fn list(points: &[AllanPoint], statistic: Statistic) -> Vec<Self> {
        points
            .iter()
            .map(|p| PointJson {
                tau_s: p.tau_s,
                adev: (statistic == Statistic::Oadev).then_some(p.dev),
                mdev: (statistic == Statistic::Mdev).then_some(p.dev),
                ci_low: p.ci_low,
                ci_high: p.ci_high,
                edf: p.edf,
                n: p.n_terms,
                alpha: p.alpha_used,
                alpha_identified: p.alpha_identified.is_some(),
            })
            .collect()
    }
}

/// The regression as printed (without `n`, which is the column's).
#[derive(Serialize)]
struct RegressionJson {
    intercept: f64,
    slope_per_s: f64,
    slope_se: f64,
    residual_std: f64,
}

#[derive(Serialize)]
struct ColumnJson<'a> {
    name: &'a str,
    unit: &'a str,
    n: usize,
    gaps: usize,
    mean: Option<f64>,
    std: Option<f64>,
    regression: Option<RegressionJson>,
    adev: Vec<PointJson>,
    mdev: Vec<PointJson>,
    allan_note: Option<&'a str>,
}

/// The object `accomp stability --json` prints.
#[derive(Serialize)]
struct ReportJson<'a> {
    rows: usize,
    tau0_s: Option<f64>,
    grid_len: Option<usize>,
    ci: &'static str,
    columns: Vec<ColumnJson<'a>>,
}

/// The table of an Allan curve in [`Report::to_table`]; the `alpha` cell carries a `*` when the
/// noise exponent was carried from the shorter τ.
const ALLAN_TABLE: Columns<6> = Columns([
    ("tau_s", 12),
    ("dev", 13),
    ("ci_low", 13),
    ("ci_high", 13),
    ("edf", 10),
    ("alpha", 5),
]);

impl Report {
    /// The JSON object printed by `accomp stability --json` (serde views of the report).
    pub fn to_json(&self) -> serde_json::Value {
        let view = ReportJson {
            rows: self.rows,
            tau0_s: self.tau0_s,
            grid_len: self.grid_len,
            ci: "68.27% chi-squared, EDF from SP1065 Table 5 simple formulas (OADEV), noise by lag-1 ACF",
            columns: self
                .columns
                .iter()
                .map(|c| ColumnJson {
                    name: &c.name,
                    unit: &c.unit,
                    n: c.n,
                    gaps: c.gaps,
                    mean: c.mean,
                    std: c.std,
                    regression: c.regression.map(|r| RegressionJson {
                        intercept: r.intercept,
                        slope_per_s: r.slope_per_s,
                        slope_se: r.slope_se,
                        residual_std: r.residual_std,
                    }),
                    adev: PointJson::list(&c.allan.adev, Statistic::Oadev),
                    mdev: PointJson::list(&c.allan.mdev, Statistic::Mdev),
                    allan_note: c.allan.note.as_deref(),
                })
                .collect(),
        };
        // Serializing plain structs of numbers and strings cannot fail.
        serde_json::to_value(view).unwrap_or(serde_json::Value::Null)
    }

    /// The human-readable table.
    pub fn to_table(&self) -> String {
        use std::fmt::Write as _;
        let mut s = String::new();
        let _ = writeln!(
            s,
            "{} rows, tau0 = {}",
            self.rows,
            self.tau0_s
                .map_or("n/a (irregular time base)".into(), |t| format!("{t} s"))
        );
        for c in &self.columns {
            let _ = writeln!(
                s,
                "\n== {} [{}]  n = {}, gaps = {}",
                c.name, c.unit, c.n, c.gaps
            );
            let opt = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.6e}"));
            let _ = writeln!(s, "  mean          {}", opt(c.mean));
            let _ = writeln!(s, "  std (n-1)     {}", opt(c.std));
            if let Some(r) = c.regression {
                let _ = writeln!(
                    s,
                    "  drift         {:.6e} /s  ± {:.2e} (1σ)   = {:.6e} /day",
                    r.slope_per_s,
                    r.slope_se,
                    r.slope_per_s * 86_400.0
                );
                let _ = writeln!(s, "  residual std  {:.6e}", r.residual_std);
            }
            if let Some(n) = &c.allan.note {
                let _ = writeln!(s, "  Allan: {n}");
            }
            for (title, pts) in [("OADEV", &c.allan.adev), ("MDEV", &c.allan.mdev)] {
                if pts.is_empty() {
                    continue;
                }
                let _ = writeln!(s, "  {title:<6} {}", ALLAN_TABLE.header());
                for p in pts {
                    let carried = if p.alpha_identified.is_some() {
                        " "
                    } else {
                        "*"
                    };
                    let cells = [
                        p.tau_s.to_string(),
                        format!("{:.5e}", p.dev),
                        format!("{:.5e}", p.ci_low),
                        format!("{:.5e}", p.ci_high),
                        format!("{:.1}", p.edf),
                        format!("{:>4}{carried}", p.alpha_used),
                    ];
                    let _ = writeln!(s, "         {}", ALLAN_TABLE.row(cells));
                }
            }
        }
        let _ = writeln!(
            s,
            "\nIntervals: 68.27 % chi-squared; alpha = noise exponent by lag-1 ACF (* = too few \
             points, carried from the shorter tau); MDEV intervals approximate (OADEV EDF)."
        );
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rel(a: f64, b: f64) -> f64 {
        ((a - b) / b).abs()
    }

    #[test]
    fn std_is_the_sample_standard_deviation_and_skips_gaps() {
        let (mean, std, n) = mean_std(&[1.0, 2.0, f64::NAN, 3.0, 4.0]).unwrap();
        assert_eq!(n, 4);
        assert_eq!(mean, 2.5);
        // sum of squared deviations 5, divisor n - 1 = 3
        assert!(rel(std, (5.0f64 / 3.0).sqrt()) < 1e-15);
        assert!(mean_std(&[1.0, f64::NAN]).is_none());
    }

    #[test]
    fn regression_std_on_a_known_line() {
        // y = 3 + 0.5 t plus residuals (+e, -e, -e, +e): orthogonal to 1 and t, so the fit
        // recovers the line exactly; RSS = 4e^2, s = sqrt(4e^2/2) = e sqrt2, Sxx = 5.
        let e = 0.01;
        let t = [0.0, 1.0, 2.0, 3.0];
        let y = [3.0 + e, 3.5 - e, 4.0 - e, 4.5 + e];
        let r = regression(&t, &y).unwrap();
        assert!((r.intercept - 3.0).abs() < 1e-14);
        assert!((r.slope_per_s - 0.5).abs() < 1e-14);
        assert!(rel(r.residual_std, e * 2f64.sqrt()) < 1e-12);
        assert!(rel(r.slope_se, e * 2f64.sqrt() / 5f64.sqrt()) < 1e-12);
        assert_eq!(r.n, 4);
    }

    #[test]
    fn regression_stays_precise_on_a_41_day_time_base_near_one_g() {
        // Raw (uncentred) sums would lose the 1e-12 g/s slope entirely.
        let t: Vec<f64> = (0..3_542_400usize).step_by(97).map(|i| i as f64).collect();
        let y: Vec<f64> = t.iter().map(|&s| 1.000_012_3 + 2.0e-12 * s).collect();
        let r = regression(&t, &y).unwrap();
        assert!(rel(r.slope_per_s, 2.0e-12) < 1e-6, "{}", r.slope_per_s);
        assert!(r.residual_std < 1e-13);
    }

    #[test]
    fn volt_columns_are_converted_with_the_scale_factor() {
        let text = "# scale_factor_v_per_g: 1.25\n\
                    time_s,output_v,output_compensated_g,temperature_c,input_g\n\
                    0,1.25,1.0,60,1\n1,1.50,1.1,60,1\n2,1.00,0.9,60,1\n3,1.25,1.0,60,1\n";
        let log = Log::parse_str(text).unwrap();
        assert_eq!(
            default_columns(&log),
            vec!["output_v".to_string(), "output_compensated_g".to_string()]
        );
        let rep = analyse(&log, &Options::default()).unwrap();
        let v = &rep.columns[0];
        assert_eq!(v.unit, "g");
        // volts: 1.25, 1.5, 1.0, 1.25 -> g: 1.0, 1.2, 0.8, 1.0; std = sqrt(0.08/3)
        assert!(rel(v.std.unwrap(), (0.08f64 / 3.0).sqrt()) < 1e-12);
        let no_k1 = Log::parse_str("time_s,output_v\n0,1\n1,2\n2,4\n").unwrap();
        assert_eq!(column_unit(&no_k1, "output_v").unwrap(), ("V".into(), 1.0));
        let bad = Log::parse_str("# scale_factor_v_per_g: -1\ntime_s,output_v\n0,1\n").unwrap();
        assert!(matches!(
            column_unit(&bad, "output_v"),
            Err(StabilityError::BadScaleFactor(_))
        ));
    }

    #[test]
    fn missing_time_stamps_become_gaps_on_the_grid() {
        // 1 s grid with t = 5 missing: the readings are a line, so with the gap honoured every
        // OADEV term sees the same drift; had the sample been closed up, terms across it would
        // see a jump.
        let t: Vec<f64> = (0..40).filter(|&i| i != 5).map(f64::from).collect();
        let y: Vec<f64> = t.iter().map(|s| 1.0 + 1e-6 * s).collect();
        let g = Grid::from_time(&t).unwrap();
        assert_eq!(g.tau0_s, 1.0);
        assert_eq!(g.len, 40);
        let on = g.place(&y);
        assert!(on[5].is_nan());
        assert_eq!(on[6], y[5]);
        let p = Phase::from_readings(&on, g.tau0_s).unwrap();
        let q = p.point(Statistic::Oadev, 1).unwrap();
        // 41 phase points - 2 = 39 terms, minus the two windows touching reading 5.
        assert_eq!(q.n_terms, 37);
        assert!(rel(q.dev, 1e-6 / 2f64.sqrt()) < 1e-6);
    }

    #[test]
    fn off_grid_time_stamps_give_no_allan_curve_but_keep_stability() {
        let text = "time_s,k1_g\n0,1\n1,1.1\n2.5,0.9\n3,1\n4.4,1.05\n";
        let log = Log::parse_str(text).unwrap();
        let rep = analyse(
            &log,
            &Options {
                columns: vec!["k1_g".into()],
                ..Options::default()
            },
        )
        .unwrap();
        let c = &rep.columns[0];
        assert!(c.allan.adev.is_empty() && c.allan.note.is_some());
        assert!(c.std.is_some() && c.regression.is_some());
    }

    #[test]
    fn a_recorders_log_over_a_reset_gets_the_allan_deviation_pooled_within_its_segments() {
        // Boot 1: t = 0..9 s, readings 0, 1, 0, 1, …; boot 2 samples 0.4 s off that grid:
        // t = 10.4..20.4 s, readings constant 5. At tau = 1 s the segments' own terms are the
        // 9 first differences of boot 1 (each ±1) and the 10 of boot 2 (each 0):
        // σ² = Σ Δy² / (2 · terms) = 9 / 38; the difference across the reset is no term.
        let mut text = String::from("# recorder: accomp record 0.1.0\ntime_s,k1_g\n");
        for k in 0..10 {
            text.push_str(&format!("{k},{}\n", k % 2));
        }
        for k in 0..11 {
            text.push_str(&format!("{},5\n", 10.4 + f64::from(k)));
        }
        let note = two_segments_of_9_and_10_differences(&text);
        assert!(
            note.starts_with("2 continuous segments (1 phase change)")
                && note.contains("10.4 (the sampling phase changes)"),
            "{note}"
        );
        // The same rows without the recorder's mark: refused as off the grid, as before.
        let plain = text.replacen("# recorder: accomp record 0.1.0\n", "", 1);
        let rep = analyse(&Log::parse_str(&plain).unwrap(), &k1_only()).unwrap();
        assert!(rep.columns[0].allan.adev.is_empty());
        assert!(rep.columns[0]
            .allan
            .note
            .as_deref()
            .unwrap()
            .contains("off the"));
    }

    /// The options of the segment tests: `k1_g` alone, octave taus.
    fn k1_only() -> Options {
        Options {
            columns: vec!["k1_g".into()],
            ..Options::default()
        }
    }

    /// Boot 1's readings 0, 1, 0, 1, … over t = 0..9 s and a constant after a split: at
    /// tau = 1 s the segments' own terms are boot 1's 9 first differences (±1) and the second
    /// segment's 10 (0), σ² = 9 / (2 · 19). Checks that point and returns the Allan note.
    fn two_segments_of_9_and_10_differences(text: &str) -> String {
        let rep = analyse(&Log::parse_str(text).unwrap(), &k1_only()).unwrap();
        let c = &rep.columns[0];
        let p = &c.allan.adev[0];
        assert_eq!((p.m, p.n_terms), (1, 19));
        assert!((p.dev - (9.0f64 / 38.0).sqrt()).abs() < 1e-12, "{}", p.dev);
        c.allan.note.clone().unwrap()
    }

    #[test]
    fn a_board_reset_on_the_old_sampling_phase_starts_a_segment_at_its_event() {
        // Boot 1: t = 0..9 s, readings 0, 1, 0, 1, …; the new boot samples exactly on the old
        // grid, t = 10..20 s, readings constant 5, as `accomp record` writes it: the event line
        // between the boots. At tau = 1 s the segments' own terms are the 9 first differences of
        // boot 1 (±1) and the 10 of boot 2 (0): σ² = 9 / (2 · 19). Spanning the reset would add
        // the term 5 − 1 = 4: σ² = (9 + 16) / (2 · 20).
        let mut text = String::from(
            "# recorder: accomp record 0.1.0\n# start_utc: 2026-01-01T00:00:00Z\ntime_s,k1_g\n",
        );
        for k in 0..10 {
            text.push_str(&format!("{k},{}\n", k % 2));
        }
        text.push_str(
            "# event: 2026-01-01T00:00:10Z board_reset seq restarted at 0 after 9 (no READY \
             seen)\n",
        );
        for k in 10..21 {
            text.push_str(&format!("{k},5\n"));
        }
        let note = two_segments_of_9_and_10_differences(&text);
        assert!(
            note.starts_with("2 continuous segments (1 board_reset)")
                && note.contains("10 (board_reset event at 2026-01-01T00:00:10Z)"),
            "{note}"
        );
        // Without the event line the rows are one grid and a term spans the reset.
        let unmarked: String = text
            .lines()
            .filter(|l| !l.starts_with("# event"))
            .map(|l| format!("{l}\n"))
            .collect();
        let rep = analyse(&Log::parse_str(&unmarked).unwrap(), &k1_only()).unwrap();
        let p = &rep.columns[0].allan.adev[0];
        assert_eq!(p.n_terms, 20);
        assert!((p.dev - (25.0f64 / 40.0).sqrt()).abs() < 1e-12, "{}", p.dev);
        assert!(rep.columns[0].allan.note.is_none());
    }

    #[test]
    fn a_table_change_starts_a_segment_and_a_seq_gap_stays_a_gap() {
        // One boot on a 1 s grid, t = 0..29 s. Readings 5 and 6 are lost (a seq_gap event);
        // the table changes before t = 15 (a table_changed event) and the output jumps from
        // 0, 1, 0, … (by t) to 10. At tau = 1 s: before the change 14 first differences (±1)
        // less the 3 touching the lost readings = 11; after it 14 (all 0); none across the
        // change: σ² = 11 / (2 · 25). Spanning the change would add (10 − 0)² over 26 terms.
        let mut text = String::from(
            "# recorder: accomp record 0.1.0\n# start_utc: 2026-01-01T00:00:00Z\ntime_s,k1_g\n",
        );
        for k in 0..30 {
            match k {
                5 | 6 => continue,
                7 => text.push_str(
                    "# event: 2026-01-01T00:00:07Z seq_gap lost=2 seq 5..=6 missing (not flagged \
                     by the board: lost on the link or in the PC)\n",
                ),
                15 => text.push_str(
                    "# event: 2026-01-01T00:00:15Z table_changed 0x00000001 -> 0x00000002\n",
                ),
                _ => {}
            }
            let y = if k < 15 { k % 2 } else { 10 };
            text.push_str(&format!("{k},{y}\n"));
        }
        let log = Log::parse_str(&text).unwrap();
        let grid = LogGrid::of(&log);
        assert_eq!(grid.segment_rows(), vec![13]);
        let rep = analyse(&log, &k1_only()).unwrap();
        let c = &rep.columns[0];
        let p = &c.allan.adev[0];
        assert_eq!((p.m, p.n_terms), (1, 25));
        assert!((p.dev - (11.0f64 / 50.0).sqrt()).abs() < 1e-12, "{}", p.dev);
        let note = c.allan.note.as_deref().unwrap();
        assert!(
            note.starts_with("2 continuous segments (1 table_changed)")
                && note.contains("15 (table_changed event at 2026-01-01T00:00:15Z)")
                && !note.contains("seq_gap"),
            "{note}"
        );
    }

    #[test]
    fn unknown_column_and_log_without_outputs_are_named_errors() {
        let log = Log::parse_str("time_s,temperature_c\n0,1\n1,2\n2,3\n").unwrap();
        assert!(matches!(
            analyse(&log, &Options::default()),
            Err(StabilityError::NoOutputColumn)
        ));
        let opts = Options {
            columns: vec!["output_v".into()],
            ..Options::default()
        };
        assert!(matches!(
            analyse(&log, &opts),
            Err(StabilityError::NoSuchColumn(_))
        ));
    }

    #[test]
    fn whole_pipeline_on_the_fixture_log_reproduces_allantools() {
        let log = Log::parse_str(include_str!(
            "../../../tests/data/allantools_xcheck_log.csv"
        ))
        .unwrap();
        let exp: serde_json::Value =
            serde_json::from_str(include_str!("../../../tests/data/allantools_xcheck.json"))
                .unwrap();
        let rep = analyse(&log, &Options::default()).unwrap();
        assert_eq!(rep.tau0_s, Some(1.0));
        let c = &rep.columns[0];
        assert_eq!(c.name, "output_g");
        let devs = exp["oadev"]["dev"].as_array().unwrap();
        assert_eq!(c.allan.adev.len(), devs.len());
        for (p, d) in c.allan.adev.iter().zip(devs) {
            assert!(rel(p.dev, d.as_f64().unwrap()) < 1e-10);
        }
        let json = rep.to_json();
        let col = &json["columns"][0];
        assert_eq!(col["unit"], "g");
        assert!(col["regression"]["slope_se"].is_f64());
        assert!(col["adev"][0]["adev"].is_f64() && col["adev"][0]["ci_low"].is_f64());
        assert!(col["mdev"][0]["mdev"].is_f64() && col["mdev"][0]["edf"].is_f64());
        assert!(rep.to_table().contains("OADEV"));
    }

    /// The column names on which this command and `discover` read different units before they
    /// both asked `accomp_log::unit_suffix` (stability took `gravity_m_s2` as `s2` and `output_V`
    /// as volts without the scale factor; discover took `m_s2` and `v`).
    #[test]
    fn stability_and_discover_read_the_same_unit_of_a_column() {
        use crate::discover::import::{dataset_from_log, DatasetOptions};
        let rows: String = (0..120)
            .map(|i| format!("{i},{},{}\n", 1.0 + 1e-6 * f64::from(i % 3), 20.0))
            .collect();
        for (name, unit, per_g) in [
            ("gravity_m_s2", "m_s2", accomp::tide::STANDARD_GRAVITY_M_S2),
            (
                "gravity_NM_S2",
                "nm_s2",
                accomp::tide::STANDARD_GRAVITY_M_S2 * 1e9,
            ),
            ("output_V", "g", 2.5),
        ] {
            let text = format!("# scale_factor_v_per_g: 2.5\ntime_s,{name},temperature_c\n{rows}");
            let log = Log::parse_str(&text).unwrap();
            let (stability_unit, k) = column_unit(&log, name).unwrap();
            assert_eq!(stability_unit, unit, "{name}");
            let ds = dataset_from_log(&log, &DatasetOptions::default()).unwrap();
            let discover_per_g = ds.unit_per_g.unwrap();
            assert!((discover_per_g - per_g).abs() <= 1e-12 * per_g, "{name}");
            if unit == "g" {
                assert!((k * discover_per_g - 1.0).abs() < 1e-15, "{name}");
            }
        }
    }
}
