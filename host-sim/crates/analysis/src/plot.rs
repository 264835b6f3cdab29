//! `accomp plot`: figures like the paper's Figs. 2–5 and an Allan deviation plot, as PNG or SVG.
//!
//! | kind          | file                  | what                                                     |
//! |---------------|-----------------------|----------------------------------------------------------|
//! | `temperature` | `<stem>_fig2_temperature` | `temperature_c` (and `truth_temperature_c`) vs time  |
//! | `output`      | `<stem>_fig3_output_1g`   | 1 g output before / after compensation, µg from mean |
//! | `tilt`        | `<stem>_fig4_tilt`        | `tilt_arcsec` (and `truth_tilt_arcsec`) vs time      |
//! | `zero-g`      | `<stem>_fig5_output_0g`   | 0 g output before / after tilt compensation          |
//! | `adev`        | `<stem>_adev`             | OADEV, log-log, shaded 68 % confidence bands         |
//!
//! `--kind all` draws every figure the log has columns for: the output figure is Fig. 3 or Fig. 5
//! depending on the log's `input_g` (metadata, else the column; 0 → Fig. 5), and figures whose
//! columns are missing are skipped with a note. Asking for one kind whose column is missing is an
//! error naming the column.
//!
//! Output series: the uncompensated one is `--raw` (default `output_v`), the compensated ones are
//! `--compensated` (repeatable; default: whichever of [`DEFAULT_COMPENSATED`] the log has). Volt
//! columns are converted to g with the metadata `scale_factor_v_per_g` exactly as `accomp
//! stability` does ([`crate::stability::column_unit`]), and the stability printed in the legends is
//! the same sample standard deviation ([`crate::stability::mean_std`]), so the figures and the
//! stability report agree.
//!
//! A recorder's log is split into its continuous segments exactly as `accomp stability` splits
//! it ([`crate::stability::LogGrid`]: after each `board_reset` or `table_changed` event line, and
//! where the sampling phase changes): the time figures draw each segment as its own line with a
//! dashed vertical line where a new one starts, labelled by its cause (the event's kind, or
//! `phase change`), the Allan deviation pools the terms within the segments, and the outcome
//! carries the same note `stability` prints.
//!
//! Time series are decimated per pixel column ([`decimate`]) before drawing: the line is the
//! column mean, the light shading its min..max envelope, so a 41-day 1 Hz log plots in about a
//! second, slow effects show through the noise and every spike stays visible.

pub mod decimate;
pub mod draw;

use std::path::PathBuf;

use plotters::style::RGBColor;

use crate::allan::{AllanError, Phase, Statistic, TauSet};
use crate::log::{Log, LogError, TIME_COLUMN};
use crate::stability::{
    column_unit, mean_std, segment_causes, segment_note, GridError, LogGrid, SegmentStart,
    StabilityError,
};
use decimate::buckets_broken;
use draw::{AdevCurve, AdevFigure, DrawError, Figure, Marker, Panel, TimeFigure, Trace};

/// Compensated output columns looked for when `--compensated` is not given, in this order.
pub const DEFAULT_COMPENSATED: [&str; 3] =
    ["a_i_exact_g", "output_linearized_v", "output_compensated_g"];
/// Default uncompensated output column.
pub const DEFAULT_RAW: &str = "output_v";
/// Instrument temperature column (Fig. 2).
pub const TEMPERATURE: &str = "temperature_c";
/// Foundation tilt column (Fig. 4).
pub const TILT: &str = "tilt_arcsec";
/// Prefix of the simulator's true-value columns, drawn beside the measured ones when present.
pub const TRUTH_PREFIX: &str = "truth_";

const ARCSEC_RAD: f64 = std::f64::consts::PI / (180.0 * 3600.0);
const SECONDS_PER_DAY: f64 = 86_400.0;
const RED: RGBColor = RGBColor(200, 40, 40);
const BLUE: RGBColor = RGBColor(25, 90, 200);
const GREEN: RGBColor = RGBColor(20, 140, 60);
const PURPLE: RGBColor = RGBColor(130, 60, 170);
const GREY: RGBColor = RGBColor(60, 60, 60);
const COMPENSATED_COLORS: [RGBColor; 3] = [BLUE, GREEN, PURPLE];

/// Image format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// Raster, text drawn with the embedded DejaVu Sans.
    Png,
    /// Vector, text left to the viewer's sans-serif font.
    Svg,
}

impl Format {
    /// File extension.
    pub fn ext(self) -> &'static str {
        match self {
            Format::Png => "png",
            Format::Svg => "svg",
        }
    }
}

/// Which figure(s).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// Every figure the log has columns for.
    All,
    /// Fig. 2: instrument temperature.
    Temperature,
    /// Fig. 3: 1 g output before/after compensation.
    Output,
    /// Fig. 4: foundation tilt.
    Tilt,
    /// Fig. 5: 0 g output before/after tilt compensation.
    ZeroG,
    /// Overlapping Allan deviation with confidence bands.
    Adev,
}

impl Kind {
    /// File name part and human name of a single kind.
    fn names(self) -> (&'static str, &'static str) {
        match self {
            Kind::All => ("all", "all figures"),
            Kind::Temperature => ("fig2_temperature", "Fig. 2 (temperature)"),
            Kind::Output => ("fig3_output_1g", "Fig. 3 (1 g output)"),
            Kind::Tilt => ("fig4_tilt", "Fig. 4 (tilt)"),
            Kind::ZeroG => ("fig5_output_0g", "Fig. 5 (0 g output)"),
            Kind::Adev => ("adev", "the Allan deviation plot"),
        }
    }
}

/// Errors of `accomp plot`.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// The log could not be read.
    #[error(transparent)]
    Log(#[from] LogError),
    /// A column a figure needs is not in the log.
    #[error(
        "{figure} needs column `{column}`, which the log does not have (columns: {available})"
    )]
    MissingColumn {
        /// The figure.
        figure: &'static str,
        /// The missing column.
        column: String,
        /// The log's columns, comma-separated.
        available: String,
    },
    /// Every Allan deviation is exactly 0 (constant columns): a log-log plot would be blank.
    #[error("the Allan deviation of {0} is {1} at every τ: nothing to draw on log axes")]
    ZeroDeviation(String, &'static str),
    /// A column has no finite reading at all.
    #[error("column `{0}` has no finite reading to plot")]
    EmptyColumn(String),
    /// A unit conversion failed (bad `scale_factor_v_per_g`).
    #[error(transparent)]
    Units(#[from] StabilityError),
    /// The time stamps are not an equally spaced grid (needed for Allan deviations).
    #[error("the Allan deviation plot needs equally spaced time stamps: {0}")]
    Grid(#[from] GridError),
    /// The Allan deviation of a column failed.
    #[error("Allan deviation of `{column}`: {source}")]
    Allan {
        /// The column.
        column: String,
        /// Why.
        source: AllanError,
    },
    /// The output directory could not be created.
    #[error("cannot create output directory {path}: {source}")]
    OutDir {
        /// The directory.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// Drawing or writing a figure failed.
    #[error("writing {path}: {source}")]
    Draw {
        /// The file.
        path: PathBuf,
        /// Why.
        source: DrawError,
    },
    /// `--kind all` found no figure the log has columns for.
    #[error("nothing to plot: {0}")]
    NothingToPlot(String),
}

/// What to plot and where.
#[derive(Debug, Clone, PartialEq)]
pub struct PlotOptions {
    /// Output directory.
    pub out_dir: PathBuf,
    /// File name prefix (the log's file stem on the command line).
    pub stem: String,
    /// Image format.
    pub format: Format,
    /// Which figure(s).
    pub kind: Kind,
    /// Uncompensated output column.
    pub raw: String,
    /// Compensated output columns; empty = the defaults present in the log.
    pub compensated: Vec<String>,
}

impl PlotOptions {
    /// Defaults for a log whose figures go to `out_dir` named after `stem`.
    pub fn new(out_dir: impl Into<PathBuf>, stem: &str) -> Self {
        PlotOptions {
            out_dir: out_dir.into(),
            stem: stem.to_owned(),
            format: Format::Png,
            kind: Kind::All,
            raw: DEFAULT_RAW.to_owned(),
            compensated: Vec::new(),
        }
    }
}

/// Result of plotting a log.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PlotOutcome {
    /// Files written.
    pub written: Vec<PathBuf>,
    /// Figures `--kind all` skipped, with the reason.
    pub skipped: Vec<String>,
    /// What the reader of the figures must know (a record split into segments).
    pub notes: Vec<String>,
}

/// Writes the figures `opts` asks for.
pub fn plot_log(log: &Log, opts: &PlotOptions) -> Result<PlotOutcome, PlotError> {
    let mut out = PlotOutcome::default();
    let grid = LogGrid::of(log);
    if let Some(n) = segment_note(log.time_s(), &grid.segments) {
        out.notes.push(format!(
            "{n} (the time figures mark where each segment starts with a dashed line, labelled by \
             its cause)"
        ));
    }
    let mut figures = Vec::new();
    if opts.kind == Kind::All {
        let output_kind = if is_zero_g(log)? {
            Kind::ZeroG
        } else {
            Kind::Output
        };
        for kind in [Kind::Temperature, output_kind, Kind::Tilt, Kind::Adev] {
            match build_on(log, opts, kind, &grid) {
                Ok(f) => figures.push((kind, f)),
                Err(e @ (PlotError::MissingColumn { .. } | PlotError::ZeroDeviation(..))) => {
                    out.skipped.push(format!("{}: {e}", kind.names().1));
                }
                Err(e) => return Err(e),
            }
        }
        if figures.is_empty() {
            return Err(PlotError::NothingToPlot(out.skipped.join("; ")));
        }
    } else {
        figures.push((opts.kind, build_on(log, opts, opts.kind, &grid)?));
    }
    std::fs::create_dir_all(&opts.out_dir).map_err(|source| PlotError::OutDir {
        path: opts.out_dir.clone(),
        source,
    })?;
    for (kind, fig) in figures {
        let path = opts.out_dir.join(format!(
            "{}_{}.{}",
            opts.stem,
            kind.names().0,
            opts.format.ext()
        ));
        draw::render(&fig, &path, opts.format).map_err(|source| PlotError::Draw {
            path: path.clone(),
            source,
        })?;
        out.written.push(path);
    }
    Ok(out)
}

/// Describes one figure without drawing it.
pub fn build(log: &Log, opts: &PlotOptions, kind: Kind) -> Result<Figure, PlotError> {
    build_on(log, opts, kind, &LogGrid::of(log))
}

/// [`build`] with the log's grid worked out once for every figure.
fn build_on(
    log: &Log,
    opts: &PlotOptions,
    kind: Kind,
    grid: &LogGrid,
) -> Result<Figure, PlotError> {
    let resets = &grid.segments;
    match kind {
        Kind::All => Err(PlotError::NothingToPlot(
            "`all` is not a single figure".into(),
        )),
        Kind::Temperature => temperature_figure(log, resets),
        Kind::Tilt => tilt_figure(log, resets),
        Kind::Output => output_figure(log, opts, false, resets),
        Kind::ZeroG => output_figure(log, opts, true, resets),
        Kind::Adev => adev_figure(log, opts, grid),
    }
}

/// True when the log is a 0 g test: `input_g` metadata (or first finite `input_g` reading) is 0.
fn is_zero_g(log: &Log) -> Result<bool, PlotError> {
    let input = match log.meta_f64("input_g")? {
        Some(v) => Some(v),
        None => log
            .column("input_g")
            .and_then(|c| c.iter().copied().find(|v| v.is_finite())),
    };
    Ok(input.is_some_and(|g| g.abs() < 0.5))
}

fn need<'a>(log: &'a Log, figure: &'static str, name: &str) -> Result<&'a [f64], PlotError> {
    let col = log.column(name).ok_or_else(|| PlotError::MissingColumn {
        figure,
        column: name.to_owned(),
        available: log.column_names().join(", "),
    })?;
    if col.iter().any(|v| v.is_finite()) {
        Ok(col)
    } else {
        Err(PlotError::EmptyColumn(name.to_owned()))
    }
}

/// The time axis: hours for records up to two days (the 0 g test), days beyond.
struct TimeAxis {
    x: Vec<f64>,
    desc: String,
    range: (f64, f64),
    /// First rows of the continuous segments after the first.
    breaks: Vec<usize>,
    /// What starts each of them (`board_reset`, `table_changed`, `phase change`).
    causes: Vec<String>,
}

impl TimeAxis {
    /// The figure, with a dashed line where each new segment starts, labelled by its cause.
    fn figure(&self, fig: TimeFigure) -> Figure {
        if self.breaks.is_empty() {
            return Figure::Time(fig);
        }
        let markers = self
            .breaks
            .iter()
            .zip(&self.causes)
            .map(|(&i, cause)| Marker {
                at: self.x[i],
                label: cause.clone(),
            })
            .collect();
        Figure::TimeMarked(fig, markers)
    }
}

fn time_axis(log: &Log, resets: &[SegmentStart]) -> TimeAxis {
    let t = log.time_s();
    let (first, last) = (
        t.first().copied().unwrap_or(0.0),
        t.last().copied().unwrap_or(0.0),
    );
    let (unit, div) = if last - first <= 2.0 * SECONDS_PER_DAY {
        ("h", 3600.0)
    } else {
        ("days", SECONDS_PER_DAY)
    };
    let desc = match log.meta("start_utc") {
        Some(s) => format!("time since {s} ({unit})"),
        None => format!("{TIME_COLUMN} ({unit})"),
    };
    let (a, b) = (first / div, last / div);
    TimeAxis {
        x: t.iter().map(|v| v / div).collect(),
        desc,
        range: if b > a { (a, b) } else { (a, a + 1.0) },
        breaks: resets.iter().map(|s| s.row).collect(),
        causes: resets.iter().map(|s| s.cause.kind()).collect(),
    }
}

fn trace(axis: &TimeAxis, y: &[f64], label: String, color: RGBColor) -> Trace {
    Trace {
        label,
        runs: buckets_broken(&axis.x, y, draw::WIDTH_PX as usize, &axis.breaks),
        color,
    }
}

/// `title — instrument` when the log names its instrument.
fn titled(log: &Log, title: &str) -> String {
    match log.meta("instrument") {
        Some(i) => format!("{title} — {i}"),
        None => title.to_owned(),
    }
}

/// Three significant digits, scientific: the paper prints stabilities as 1.43e-5 g.
fn sci(v: f64) -> String {
    format!("{v:.2e}")
}

fn temperature_figure(log: &Log, resets: &[SegmentStart]) -> Result<Figure, PlotError> {
    let label = |name: &str, y: &[f64]| match mean_std(y) {
        Some((m, s, _)) => format!("{name}: mean {m:.4} °C, σ {s:.4} °C"),
        None => name.to_owned(),
    };
    channel_figure(
        log,
        resets,
        ("Fig. 2 (temperature)", "Instrument temperature"),
        (TEMPERATURE, "temperature (°C)"),
        label,
    )
}

fn tilt_figure(log: &Log, resets: &[SegmentStart]) -> Result<Figure, PlotError> {
    let t = log.time_s();
    let label = |name: &str, y: &[f64]| {
        let ms = mean_std(y);
        match (block_mean_range(t, y, TILT_BLOCK_S), ms) {
            (Some(pp), Some((_, s, _))) => format!(
                "{name}: peak-to-peak of {:.0}-min means {pp:.3}″, σ {s:.3}″",
                TILT_BLOCK_S / 60.0
            ),
            _ => name.to_owned(),
        }
    };
    channel_figure(
        log,
        resets,
        ("Fig. 4 (tilt)", "Foundation tilt"),
        (TILT, "tilt (arcsec)"),
        label,
    )
}

/// One channel against time, with its `truth_` twin in grey when the log has one, each trace
/// labelled by `label(name, values)`. `fig` is (the figure named in errors, its title); `column`
/// is (the column, the y axis's description); `resets` the starts of a record's segments.
fn channel_figure(
    log: &Log,
    resets: &[SegmentStart],
    (fig, title): (&'static str, &str),
    (column, y_desc): (&str, &str),
    label: impl Fn(&str, &[f64]) -> String,
) -> Result<Figure, PlotError> {
    let axis = time_axis(log, resets);
    let y = need(log, fig, column)?;
    let mut traces = vec![trace(&axis, y, label(column, y), RED)];
    let truth = format!("{TRUTH_PREFIX}{column}");
    if let Some(tt) = log.column(&truth) {
        traces.push(trace(&axis, tt, label(&truth, tt), GREY));
    }
    Ok(axis.figure(TimeFigure {
        title: titled(log, title),
        x_desc: axis.desc.clone(),
        x_range: axis.range,
        panels: vec![Panel {
            y_desc: y_desc.into(),
            traces,
        }],
        shared_y: false,
    }))
}

/// Block length for the tilt figure's peak-to-peak: long enough to average the tiltmeter noise
/// out, short against the daily tilt cycle the paper reports (0.45″ in a day).
pub const TILT_BLOCK_S: f64 = 600.0;

/// Range (max − min) of the means of consecutive `block_s`-long blocks of finite readings.
/// `None` without finite readings.
pub fn block_mean_range(t: &[f64], y: &[f64], block_s: f64) -> Option<f64> {
    let t0 = *t.first()?;
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    let (mut block, mut n, mut sum) = (0i64, 0usize, 0.0);
    let mut close = |n: usize, sum: f64| {
        if n > 0 {
            let m = sum / n as f64;
            lo = lo.min(m);
            hi = hi.max(m);
        }
    };
    for (&ti, &yi) in t.iter().zip(y) {
        let k = ((ti - t0) / block_s).floor() as i64;
        if k != block {
            close(n, sum);
            (block, n, sum) = (k, 0, 0.0);
        }
        if yi.is_finite() {
            n += 1;
            sum += yi;
        }
    }
    close(n, sum);
    (hi >= lo).then_some(hi - lo)
}

/// An output column brought to g (or left in V without a scale factor).
struct OutputSeries {
    name: String,
    /// `output_v / K1` for converted volt columns, else the name.
    desc: String,
    unit: String,
    values: Vec<f64>,
}

fn output_series(log: &Log, figure: &'static str, name: &str) -> Result<OutputSeries, PlotError> {
    let raw = need(log, figure, name)?;
    let (unit, k) = column_unit(log, name)?;
    let desc = if k != 1.0 {
        format!("{name} / K1")
    } else {
        name.to_owned()
    };
    Ok(OutputSeries {
        name: name.to_owned(),
        desc,
        unit,
        values: raw.iter().map(|v| v * k).collect(),
    })
}

/// The uncompensated series and the compensated ones (explicit ones must exist).
fn output_selection(
    log: &Log,
    opts: &PlotOptions,
    figure: &'static str,
) -> Result<(OutputSeries, Vec<OutputSeries>), PlotError> {
    let raw = output_series(log, figure, &opts.raw)?;
    let names: Vec<String> = if opts.compensated.is_empty() {
        DEFAULT_COMPENSATED
            .iter()
            .filter(|n| log.column(n).is_some())
            .map(|n| (*n).to_owned())
            .collect()
    } else {
        opts.compensated.clone()
    };
    let comp = names
        .iter()
        .map(|n| output_series(log, figure, n))
        .collect::<Result<Vec<_>, _>>()?;
    Ok((raw, comp))
}

fn output_figure(
    log: &Log,
    opts: &PlotOptions,
    zero_g: bool,
    resets: &[SegmentStart],
) -> Result<Figure, PlotError> {
    let figure = if zero_g {
        Kind::ZeroG.names().1
    } else {
        Kind::Output.names().1
    };
    let (raw, comp) = output_selection(log, opts, figure)?;
    let axis = time_axis(log, resets);
    let what = if zero_g {
        "tilt compensation"
    } else {
        "temperature compensation"
    };
    let mut panels = Vec::new();
    let mut units = Vec::new();
    for (i, s) in std::iter::once(&raw).chain(&comp).enumerate() {
        let (mean, std, _) =
            mean_std(&s.values).ok_or_else(|| PlotError::EmptyColumn(s.name.clone()))?;
        // µg (µV) deviations: the 1 g output sits at ~1 g and varies by ~1e-5 g.
        let dev: Vec<f64> = s.values.iter().map(|v| (v - mean) * 1e6).collect();
        let (role, color) = if i == 0 {
            (format!("before {what}"), RED)
        } else {
            (
                format!("after {what}"),
                COMPENSATED_COLORS[(i - 1) % COMPENSATED_COLORS.len()],
            )
        };
        let mut traces = vec![trace(
            &axis,
            &dev,
            format!("{} ({role}): σ = {} {}", s.desc, sci(std), s.unit),
            color,
        )];
        // On the 0 g figure, the input the tilt puts on the instrument, sin(φ − φ0) in g, shown
        // against the uncompensated output it explains.
        if zero_g && i == 0 && s.unit == "g" {
            if let Some(tilt) = log.column(TILT) {
                if let Some(&phi0) = tilt.iter().find(|v| v.is_finite()) {
                    let term: Vec<f64> = tilt
                        .iter()
                        .map(|phi| ((phi - phi0) * ARCSEC_RAD).sin())
                        .collect();
                    if let Some((m, _, _)) = mean_std(&term) {
                        let dev_t: Vec<f64> = term.iter().map(|v| (v - m) * 1e6).collect();
                        traces.push(trace(
                            &axis,
                            &dev_t,
                            "tilt input sin(φ − φ0) from tilt_arcsec".into(),
                            GREY,
                        ));
                    }
                }
            }
        }
        units.push(s.unit.clone());
        panels.push(Panel {
            y_desc: format!("{} − mean (µ{})", s.desc, s.unit),
            traces,
        });
    }
    let title = match (zero_g, comp.is_empty()) {
        (true, false) => "0 g output before/after tilt compensation",
        (false, false) => "1 g output before/after temperature compensation",
        (true, true) => "0 g output (the log has no compensated column)",
        (false, true) => "1 g output (the log has no compensated column)",
    };
    // A shared y range only makes sense when every panel is in the same unit.
    let same_unit = units.windows(2).all(|w| w[0] == w[1]);
    Ok(axis.figure(TimeFigure {
        title: titled(log, title),
        x_desc: axis.desc.clone(),
        x_range: axis.range,
        panels,
        shared_y: same_unit,
    }))
}

fn adev_figure(log: &Log, opts: &PlotOptions, grid: &LogGrid) -> Result<Figure, PlotError> {
    let (raw, comp) = output_selection(log, opts, Kind::Adev.names().1)?;
    let causes = segment_causes(&grid.segments);
    let segments = grid.segments.len() + 1;
    let grid = grid.grid.clone()?;
    let mut curves = Vec::new();
    let mut units = Vec::new();
    // Whether any deviation was not finite (values that overflow), for the message when none
    // can be drawn.
    let mut overflow = false;
    for (i, s) in std::iter::once(&raw).chain(&comp).enumerate() {
        let on_grid = grid.place(&s.values);
        let phase =
            Phase::from_readings(&on_grid, grid.tau0_s).map_err(|source| PlotError::Allan {
                column: s.name.clone(),
                source,
            })?;
        let devs = phase.deviation(Statistic::Oadev, TauSet::Octave);
        overflow |= devs.iter().any(|p| !p.dev.is_finite());
        let points: Vec<(f64, f64, f64, f64)> = devs
            .iter()
            .filter(|p| p.dev.is_finite() && p.dev > 0.0 && p.ci_high.is_finite())
            .map(|p| (p.tau_s, p.dev, p.ci_low, p.ci_high))
            .collect();
        let (role, color) = if i == 0 {
            ("uncompensated", RED)
        } else {
            (
                "compensated",
                COMPENSATED_COLORS[(i - 1) % COMPENSATED_COLORS.len()],
            )
        };
        units.push(s.unit.clone());
        curves.push(AdevCurve {
            label: format!("{} ({role})", s.desc),
            color,
            points,
        });
    }
    if curves.iter().all(|c| c.points.is_empty()) {
        let names: Vec<String> = std::iter::once(&raw)
            .chain(&comp)
            .map(|s| format!("`{}`", s.name))
            .collect();
        let what = if overflow {
            "not finite (values so large that their differences overflow)"
        } else {
            "0 (a constant column)"
        };
        return Err(PlotError::ZeroDeviation(names.join(", "), what));
    }
    units.dedup();
    let unit = units.join(" / ");
    Ok(Figure::Adev(AdevFigure {
        title: titled(
            log,
            &if segments > 1 {
                format!(
                    "Overlapping Allan deviation pooled within {segments} continuous segments \
                     ({causes}), shaded: 68 % confidence interval"
                )
            } else {
                "Overlapping Allan deviation, shaded: 68 % confidence interval".to_owned()
            },
        ),
        y_desc: format!("σ_y(τ) ({unit})"),
        curves,
    }))
}

#[cfg(test)]
mod tests;
