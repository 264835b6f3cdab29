//! Rendering of the figure descriptions with plotters (SVG or PNG), nothing else.
//!
//! The figures are described as plain data ([`Figure`]) by the parent module, so what is plotted
//! can be tested without pixels, and this module only turns them into drawing calls.
//!
//! Fonts: plotters' `ab_glyph` feature is used with DejaVu Sans embedded from the `dejavu` crate,
//! registered once as "sans-serif". That gives real text metrics for layout in both backends and
//! glyphs in PNGs without any system font library or font file (CI machines are bare Debian).
//! SVG files name the family `sans-serif` and leave the glyphs to the viewer.

use std::path::Path;
use std::sync::OnceLock;

use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::{register_font, FontStyle};

use super::decimate::Run;
use super::Format;

/// A drawing failed: the backend's message, with the file it was writing.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct DrawError(pub String);

impl<E: std::error::Error + Send + Sync> From<DrawingAreaErrorKind<E>> for DrawError {
    fn from(e: DrawingAreaErrorKind<E>) -> Self {
        DrawError(e.to_string())
    }
}

/// One series of a time panel, already decimated.
#[derive(Debug, Clone, PartialEq)]
pub struct Trace {
    /// Legend text.
    pub label: String,
    /// Decimated runs (broken at gaps): line through the means, shading min..max.
    pub runs: Vec<Run>,
    /// Line colour.
    pub color: RGBColor,
}

/// One panel of a time figure.
#[derive(Debug, Clone, PartialEq)]
pub struct Panel {
    /// Y axis description, with unit.
    pub y_desc: String,
    /// Series drawn in this panel.
    pub traces: Vec<Trace>,
}

/// A figure of one or more stacked panels sharing the time axis.
#[derive(Debug, Clone, PartialEq)]
pub struct TimeFigure {
    /// Title over the whole figure.
    pub title: String,
    /// X axis description, with unit.
    pub x_desc: String,
    /// X range (start, end) in the axis unit.
    pub x_range: (f64, f64),
    /// Panels, top to bottom.
    pub panels: Vec<Panel>,
    /// Same y range in every panel (so before/after scatter compares by eye).
    pub shared_y: bool,
}

/// One Allan deviation curve: `(tau_s, dev, ci_low, ci_high)` per point.
#[derive(Debug, Clone, PartialEq)]
pub struct AdevCurve {
    /// Legend text.
    pub label: String,
    /// Line and band colour.
    pub color: RGBColor,
    /// Points with positive finite values only.
    pub points: Vec<(f64, f64, f64, f64)>,
}

/// A log-log Allan deviation figure with shaded confidence bands.
#[derive(Debug, Clone, PartialEq)]
pub struct AdevFigure {
    /// Title.
    pub title: String,
    /// Y axis description, with unit.
    pub y_desc: String,
    /// Curves.
    pub curves: Vec<AdevCurve>,
}

/// One line of an [`XYFigure`].
#[derive(Debug, Clone, PartialEq)]
pub struct XYCurve {
    /// Legend text.
    pub label: String,
    /// Line colour.
    pub color: RGBColor,
    /// Points in drawing order; non-finite ones (and non-positive ones on a log axis) are
    /// skipped and break the line.
    pub points: Vec<(f64, f64)>,
}

/// A labelled reference line across the plot: vertical at an x value, or horizontal at a y value.
#[derive(Debug, Clone, PartialEq)]
pub struct Marker {
    /// Position on its axis.
    pub at: f64,
    /// Text written next to the line.
    pub label: String,
}

/// A general line plot of y against x, each axis linear or logarithmic (spectra, sweeps).
#[derive(Debug, Clone, PartialEq)]
pub struct XYFigure {
    /// Title.
    pub title: String,
    /// The x axis; its markers are vertical lines (e.g. significant spectral lines).
    pub x: XYAxis,
    /// The y axis; its markers are horizontal lines (e.g. a significance level).
    pub y: XYAxis,
    /// Y values below this are drawn at it (a log axis otherwise spans the deep, empty troughs
    /// of a periodogram). `None`: the data's own minimum.
    pub y_floor: Option<f64>,
    /// Curves.
    pub curves: Vec<XYCurve>,
    /// X ranges shaded across the plot (e.g. where a record leaves a simulation's envelope).
    pub x_spans: Vec<(f64, f64)>,
}

/// One axis of an [`XYFigure`].
#[derive(Debug, Clone, PartialEq)]
pub struct XYAxis {
    /// Description, with unit.
    pub desc: String,
    /// Logarithmic rather than linear.
    pub log: bool,
    /// Labelled reference lines across the plot at values of this axis.
    pub markers: Vec<Marker>,
}

impl XYAxis {
    /// A logarithmic axis.
    pub fn log(desc: String, markers: Vec<Marker>) -> Self {
        XYAxis {
            desc,
            log: true,
            markers,
        }
    }
}

/// Any figure this module draws.
#[derive(Debug, Clone, PartialEq)]
pub enum Figure {
    /// Series against time.
    Time(TimeFigure),
    /// Series against time with dashed vertical lines across every panel (board resets),
    /// labelled in the legend.
    TimeMarked(TimeFigure, Vec<Marker>),
    /// Allan deviation.
    Adev(AdevFigure),
    /// Y against x, linear or log axes.
    XY(XYFigure),
}

/// The drawing area of a whole figure (pixel coordinates from its top left corner).
type FigureArea<DB> = DrawingArea<DB, Shift>;

/// Width of every figure, px. The decimation uses one bucket per pixel column of it.
pub const WIDTH_PX: u32 = 1100;
const PANEL_HEIGHT_PX: u32 = 380;
const TITLE_HEIGHT_PX: u32 = 40;
const FONT: &str = "sans-serif";
const GREY_BAND: RGBColor = RGBColor(200, 200, 200);
/// Shaded x ranges of an [`XYFigure`].
const SPAN: RGBColor = RGBColor(240, 160, 60);

impl Figure {
    /// Size in pixels (SVG user units).
    pub fn size(&self) -> (u32, u32) {
        match self {
            Figure::Time(t) | Figure::TimeMarked(t, _) => (
                WIDTH_PX,
                TITLE_HEIGHT_PX + PANEL_HEIGHT_PX * t.panels.len().max(1) as u32,
            ),
            Figure::Adev(_) | Figure::XY(_) => (900, 680),
        }
    }
}

/// Registers the embedded font once; `false` if the font bytes were rejected.
fn font_ready() -> bool {
    static READY: OnceLock<bool> = OnceLock::new();
    *READY.get_or_init(|| register_font(FONT, FontStyle::Normal, dejavu::sans::regular()).is_ok())
}

/// Writes `fig` to `path` in `format`.
pub fn render(fig: &Figure, path: &Path, format: Format) -> Result<(), DrawError> {
    if !font_ready() {
        return Err(DrawError(
            "the embedded DejaVu Sans font could not be loaded".into(),
        ));
    }
    let size = fig.size();
    match format {
        Format::Svg => draw(&SVGBackend::new(path, size).into_drawing_area(), fig),
        Format::Png => draw(&BitMapBackend::new(path, size).into_drawing_area(), fig),
    }
}

fn draw<DB: DrawingBackend>(root: &FigureArea<DB>, fig: &Figure) -> Result<(), DrawError>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    match fig {
        Figure::Time(t) => draw_time(root, t, &[])?,
        Figure::TimeMarked(t, markers) => draw_time(root, t, markers)?,
        Figure::Adev(a) => draw_adev(root, a)?,
        Figure::XY(f) => draw_xy(root, f)?,
    }
    root.present()?;
    Ok(())
}

/// Finite (min, max) of all points of the given panels.
fn y_extent<'a>(panels: impl IntoIterator<Item = &'a Panel>) -> Option<(f64, f64)> {
    let mut ext: Option<(f64, f64)> = None;
    for p in panels {
        for tr in &p.traces {
            for b in tr.runs.iter().flatten() {
                if b.min.is_finite() && b.max.is_finite() {
                    ext =
                        Some(ext.map_or((b.min, b.max), |(lo, hi)| (lo.min(b.min), hi.max(b.max))));
                }
            }
        }
    }
    ext
}

/// Pads a range by 5 % each side (legend room on top: 15 %); a flat range gets a unit-sized one.
fn padded((lo, hi): (f64, f64)) -> (f64, f64) {
    let span = hi - lo;
    if span > 0.0 {
        (lo - 0.05 * span, hi + 0.15 * span)
    } else {
        let d = if lo != 0.0 { lo.abs() * 1e-3 } else { 1.0 };
        (lo - d, hi + d)
    }
}

/// Decimals that make ~10 ticks over `span` distinct.
pub fn tick_decimals(span: f64) -> usize {
    if !(span.is_finite() && span > 0.0) {
        return 0;
    }
    let step = span / 10.0;
    (-step.log10().floor()).clamp(0.0, 9.0) as usize
}

/// Fixed-point tick label without a "-0.00" for values that round to zero.
pub fn fixed(v: f64, decimals: usize) -> String {
    let s = format!("{v:.decimals$}");
    if s.starts_with('-') && s[1..].chars().all(|c| c == '0' || c == '.') {
        s[1..].to_owned()
    } else {
        s
    }
}

/// Log-axis tick label: plain for 0.001 ≤ v < 10 000, `1e-6` style otherwise.
pub fn log_tick(v: f64) -> String {
    if (1e-3..1e4).contains(&v.abs()) {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        format!("{v:.0e}")
    }
}

/// True when `v` is 1, 2 or 5 times a power of ten (to a part in 1e6).
pub fn is_125(v: f64) -> bool {
    if !(v.is_finite() && v > 0.0) {
        return false;
    }
    let mantissa = v / 10f64.powf(v.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .iter()
        .any(|m| (mantissa - m).abs() < 1e-6 * m)
}

/// A log axis' label: only on the 1, 2 and 5 of each decade (the other key points are grid lines).
fn log_label_125(v: f64) -> String {
    if is_125(v) {
        log_tick(v)
    } else {
        String::new()
    }
}

/// A shaded band between the (x, low, high) edges: the upper edge left to right, then the lower
/// edge back.
fn band<I>(edges: I, style: ShapeStyle) -> Polygon<(f64, f64)>
where
    I: DoubleEndedIterator<Item = (f64, f64, f64)> + Clone,
{
    let upper = edges.clone().map(|(x, _, high)| (x, high));
    let lower = edges.rev().map(|(x, low, _)| (x, low));
    Polygon::new(upper.chain(lower).collect::<Vec<_>>(), style)
}

/// A legend entry's sample: a short line in the series' style.
fn legend_line(style: ShapeStyle) -> impl Fn((i32, i32)) -> PathElement<(i32, i32)> {
    move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], style)
}

/// The legend box, top right, over a half-transparent white.
fn draw_legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
) -> Result<(), DrawError>
where
    DB::ErrorType: 'static,
{
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .label_font((FONT, 15))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.5))
        .draw()?;
    Ok(())
}

/// A one-panel chart with its title, room for the axis labels and descriptions.
fn captioned<'a, 'b, DB: DrawingBackend>(
    root: &'a FigureArea<DB>,
    title: &str,
) -> ChartBuilder<'a, 'b, DB> {
    let mut builder = ChartBuilder::on(root);
    builder
        .caption(title, (FONT, 20))
        .margin(15)
        .x_label_area_size(50)
        .y_label_area_size(80);
    builder
}

fn draw_time<DB: DrawingBackend>(
    root: &FigureArea<DB>,
    fig: &TimeFigure,
    x_markers: &[Marker],
) -> Result<(), DrawError>
where
    DB::ErrorType: 'static,
{
    let body = root.titled(&fig.title, (FONT, 22))?;
    let areas = body.split_evenly((fig.panels.len().max(1), 1));
    let shared = if fig.shared_y {
        y_extent(&fig.panels)
    } else {
        None
    };
    let (x0, x1) = fig.x_range;
    let x_dec = tick_decimals(x1 - x0);
    let last = fig.panels.len().saturating_sub(1);
    for (i, (area, panel)) in areas.iter().zip(&fig.panels).enumerate() {
        let (y0, y1) = padded(shared.or_else(|| y_extent([panel])).unwrap_or((0.0, 1.0)));
        let y_dec = tick_decimals(y1 - y0);
        let mut chart = ChartBuilder::on(area)
            .margin(12)
            .x_label_area_size(if i == last { 45 } else { 25 })
            .y_label_area_size(85)
            .build_cartesian_2d(x0..x1, y0..y1)?;
        // The time axis is named once, under the bottom panel.
        let x_desc = if i == last { fig.x_desc.as_str() } else { "" };
        chart
            .configure_mesh()
            .x_desc(x_desc)
            .y_desc(panel.y_desc.as_str())
            .label_style((FONT, 14))
            .axis_desc_style((FONT, 16))
            .x_label_formatter(&|v| fixed(*v, x_dec))
            .y_label_formatter(&|v| fixed(*v, y_dec))
            .light_line_style(WHITE.mix(0.0))
            .draw()?;
        // Bands first, so no trace's shading covers another trace's line.
        let mut any_band = false;
        for tr in &panel.traces {
            for run in &tr.runs {
                if run.iter().all(|b| b.min == b.max) {
                    continue;
                }
                any_band = true;
                let edges = run.iter().map(|b| (b.x, b.min, b.max));
                chart.draw_series(std::iter::once(band(edges, tr.color.mix(0.25).filled())))?;
            }
        }
        for tr in &panel.traces {
            let style = tr.color.stroke_width(1);
            let mut first = true;
            for run in &tr.runs {
                let series =
                    chart.draw_series(LineSeries::new(run.iter().map(|b| (b.x, b.mean)), style))?;
                if first {
                    let c = tr.color;
                    series
                        .label(tr.label.as_str())
                        .legend(legend_line(c.stroke_width(2)));
                    first = false;
                }
            }
        }
        // One colour and one legend entry per kind of marker (board_reset, table_changed, …).
        let mut kinds: Vec<&str> = Vec::new();
        for m in x_markers {
            let k = kinds
                .iter()
                .position(|&l| l == m.label)
                .unwrap_or(kinds.len());
            let new_kind = k == kinds.len();
            if new_kind {
                kinds.push(&m.label);
            }
            let marker_style = MARKER_COLORS[k % MARKER_COLORS.len()]
                .mix(0.55)
                .stroke_width(1);
            let dashes = dashed_vertical(m.at, y0, y1);
            let series = chart.draw_series(
                dashes
                    .into_iter()
                    .map(|seg| PathElement::new(seg, marker_style)),
            )?;
            if new_kind {
                series
                    .label(format!("{} (dashed)", m.label))
                    .legend(legend_line(marker_style));
            }
        }
        if any_band {
            chart
                .draw_series(std::iter::empty::<Rectangle<(f64, f64)>>())?
                .label("line: mean per pixel column; shading: its min–max")
                .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 24, y + 5)], GREY_BAND.filled()));
        }
        if panel.traces.iter().any(|t| !t.label.is_empty()) {
            draw_legend(&mut chart)?;
        }
    }
    Ok(())
}

/// Colours of the dashed lines of a time figure, one per kind of marker, in order of appearance.
const MARKER_COLORS: [RGBColor; 3] = [BLACK, RGBColor(0, 90, 200), RGBColor(150, 60, 0)];

/// A dashed vertical line at `x` from `y0` to `y1`: 40 dashes, each half a period long.
fn dashed_vertical(x: f64, y0: f64, y1: f64) -> Vec<Vec<(f64, f64)>> {
    const DASHES: usize = 40;
    let step = (y1 - y0) / DASHES as f64;
    (0..DASHES)
        .map(|k| {
            let a = y0 + k as f64 * step;
            vec![(x, a), (x, a + 0.5 * step)]
        })
        .collect()
}

fn draw_adev<DB: DrawingBackend>(root: &FigureArea<DB>, fig: &AdevFigure) -> Result<(), DrawError>
where
    DB::ErrorType: 'static,
{
    let pts = || fig.curves.iter().flat_map(|c| c.points.iter());
    let tau_lo = pts().map(|p| p.0).fold(f64::INFINITY, f64::min);
    let tau_hi = pts().map(|p| p.0).fold(0.0, f64::max);
    let y_lo = pts().map(|p| p.2.min(p.1)).fold(f64::INFINITY, f64::min);
    let y_hi = pts().map(|p| p.3.max(p.1)).fold(0.0, f64::max);
    if !(tau_lo.is_finite() && tau_hi > 0.0 && y_lo.is_finite() && y_hi > 0.0) {
        return Err(DrawError(
            "no positive Allan deviation point to draw".into(),
        ));
    }
    // Lower ends on a power of ten: plotters' log axis puts key points (and so labels) only from
    // the first power of ten inside the range, so a range starting at 3e-6 would get none below
    // 1e-5 (and it finds that power with a rounded `ceil(ln / ln 10)`, hence the 0.99, so the
    // decade itself is inside). The upper end leaves room for the legend.
    let decade_below = |v: f64| 0.99 * 10f64.powf(v.log10().floor());
    let (tau_lo, tau_hi) = (decade_below(tau_lo / 1.2), tau_hi * 1.5);
    let (y_lo, y_hi) = (decade_below(y_lo / 1.2), y_hi * 3.0);
    let mut chart = captioned(root, &fig.title)
        .build_cartesian_2d((tau_lo..tau_hi).log_scale(), (y_lo..y_hi).log_scale())?;
    chart
        .configure_mesh()
        .x_desc("averaging time τ (s)")
        .y_desc(fig.y_desc.as_str())
        .label_style((FONT, 14))
        .axis_desc_style((FONT, 16))
        // Enough key points for 1..9 in every decade (grid lines), labels only on 1, 2, 5.
        .y_labels(40)
        .light_line_style(WHITE.mix(0.0))
        .bold_line_style(BLACK.mix(0.12))
        .x_label_formatter(&|v| log_tick(*v))
        .y_label_formatter(&|v| log_label_125(*v))
        .draw()?;
    for c in &fig.curves {
        let edges = c.points.iter().map(|p| (p.0, p.2.max(y_lo), p.3));
        chart.draw_series(std::iter::once(band(edges, c.color.mix(0.18).filled())))?;
    }
    for c in &fig.curves {
        let col = c.color;
        chart
            .draw_series(LineSeries::new(
                c.points.iter().map(|p| (p.0, p.1)),
                col.stroke_width(2),
            ))?
            .label(c.label.as_str())
            .legend(legend_line(col.stroke_width(2)));
        chart.draw_series(
            c.points
                .iter()
                .map(|p| Circle::new((p.0, p.1), 3, col.filled())),
        )?;
    }
    draw_legend(&mut chart)?;
    Ok(())
}

/// Clamps `y` to the figure's floor.
fn floored(fig: &XYFigure, y: f64) -> f64 {
    fig.y_floor.map_or(y, |f| y.max(f))
}

/// True when a point can be drawn on the figure's axes.
fn drawable(fig: &XYFigure, (x, y): (f64, f64)) -> bool {
    let y = floored(fig, y);
    x.is_finite() && y.is_finite() && (!fig.x.log || x > 0.0) && (!fig.y.log || y > 0.0)
}

/// Axis range over `values`: a log axis starts just under a power of ten (see [`draw_adev`]) and
/// gets ×3 headroom for the legend; a linear one is [`padded`].
fn axis_range(values: impl Iterator<Item = f64>, log: bool) -> Option<(f64, f64)> {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    if !(lo.is_finite() && hi.is_finite()) {
        return None;
    }
    Some(if log {
        let lo = 0.99 * 10f64.powf(lo.log10().floor());
        (lo, if hi > lo { hi * 3.0 } else { lo * 100.0 })
    } else {
        padded((lo, hi))
    })
}

fn draw_xy<DB: DrawingBackend>(root: &FigureArea<DB>, fig: &XYFigure) -> Result<(), DrawError>
where
    DB::ErrorType: 'static,
{
    let pts = || {
        fig.curves
            .iter()
            .flat_map(|c| c.points.iter().copied())
            .filter(|&p| drawable(fig, p))
    };
    let (Some(xr), Some(yr)) = (
        axis_range(pts().map(|p| p.0), fig.x.log),
        axis_range(pts().map(|p| floored(fig, p.1)), fig.y.log),
    ) else {
        return Err(DrawError("no finite point to draw".into()));
    };
    // plotters gives log and linear axes different coordinate types: one call per combination.
    match (fig.x.log, fig.y.log) {
        (false, false) => draw_xy_on(root, fig, xr.0..xr.1, yr.0..yr.1, yr),
        (true, false) => draw_xy_on(root, fig, (xr.0..xr.1).log_scale(), yr.0..yr.1, yr),
        (false, true) => draw_xy_on(root, fig, xr.0..xr.1, (yr.0..yr.1).log_scale(), yr),
        (true, true) => draw_xy_on(
            root,
            fig,
            (xr.0..xr.1).log_scale(),
            (yr.0..yr.1).log_scale(),
            yr,
        ),
    }
}

fn draw_xy_on<DB, X, Y>(
    root: &FigureArea<DB>,
    fig: &XYFigure,
    x_spec: X,
    y_spec: Y,
    (y_lo, y_hi): (f64, f64),
) -> Result<(), DrawError>
where
    DB: DrawingBackend,
    DB::ErrorType: 'static,
    X: AsRangedCoord<Value = f64>,
    Y: AsRangedCoord<Value = f64>,
    X::CoordDescType: ValueFormatter<f64>,
    Y::CoordDescType: ValueFormatter<f64>,
{
    let mut chart = captioned(root, &fig.title).build_cartesian_2d(x_spec, y_spec)?;
    let (x_lo, x_hi) = {
        let r = chart.x_range();
        (r.start, r.end)
    };
    let x_dec = tick_decimals(x_hi - x_lo);
    let y_dec = tick_decimals(y_hi - y_lo);
    let (x_log, y_log) = (fig.x.log, fig.y.log);
    let x_fmt = move |v: &f64| {
        if x_log {
            log_label_125(*v)
        } else {
            fixed(*v, x_dec)
        }
    };
    let y_fmt = move |v: &f64| {
        if y_log {
            log_label_125(*v)
        } else {
            fixed(*v, y_dec)
        }
    };
    chart
        .configure_mesh()
        .x_desc(fig.x.desc.as_str())
        .y_desc(fig.y.desc.as_str())
        .label_style((FONT, 14))
        .axis_desc_style((FONT, 16))
        // Log y: key points for 1..9 in every decade (grid lines), labels on 1, 2, 5 only.
        // (x: plotters repeats decade labels when asked for many log key points on x.)
        .y_labels(if y_log { 40 } else { 10 })
        .light_line_style(WHITE.mix(0.0))
        .bold_line_style(BLACK.mix(0.12))
        .x_label_formatter(&x_fmt)
        .y_label_formatter(&y_fmt)
        .draw()?;
    for &(a, b) in &fig.x_spans {
        let (a, b) = (a.max(x_lo), b.min(x_hi));
        if a < b {
            chart.draw_series(std::iter::once(Rectangle::new(
                [(a, y_lo), (b, y_hi)],
                SPAN.mix(0.25).filled(),
            )))?;
        }
    }
    let marker_style = BLACK.mix(0.45).stroke_width(1);
    let inside = fig.x.markers.iter().filter(|m| m.at > x_lo && m.at < x_hi);
    for (i, m) in inside.enumerate() {
        chart.draw_series(std::iter::once(PathElement::new(
            vec![(m.at, y_lo), (m.at, y_hi)],
            marker_style,
        )))?;
        // Text under the top, right of the line, on one of three staggered heights so labels
        // of neighbouring lines do not overprint.
        let h = 0.95 - 0.04 * (i % 3) as f64;
        let y_text = if y_log {
            y_lo * (y_hi / y_lo).powf(h)
        } else {
            y_lo + h * (y_hi - y_lo)
        };
        chart.draw_series(std::iter::once(Text::new(
            m.label.clone(),
            (m.at, y_text),
            (FONT, 13).into_font().color(&BLACK.mix(0.7)),
        )))?;
    }
    for m in fig.y.markers.iter().filter(|m| m.at > y_lo && m.at < y_hi) {
        chart
            .draw_series(std::iter::once(PathElement::new(
                vec![(x_lo, m.at), (x_hi, m.at)],
                marker_style,
            )))?
            .label(m.label.as_str())
            .legend(legend_line(marker_style));
    }
    for c in &fig.curves {
        let col = c.color;
        let mut first = true;
        // Runs of drawable points: a skipped point breaks the line instead of bridging it.
        let mut runs: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
        for &p in &c.points {
            if drawable(fig, p) {
                if let Some(r) = runs.last_mut() {
                    r.push((p.0, floored(fig, p.1)));
                }
            } else if runs.last().is_some_and(|r| !r.is_empty()) {
                runs.push(Vec::new());
            }
        }
        for run in runs.into_iter().filter(|r| !r.is_empty()) {
            let series = chart.draw_series(LineSeries::new(run, col.stroke_width(1)))?;
            // An unlabelled curve (e.g. the second edge of a band) gets no legend entry.
            if first && !c.label.is_empty() {
                series
                    .label(c.label.as_str())
                    .legend(legend_line(col.stroke_width(2)));
                first = false;
            }
        }
    }
    draw_legend(&mut chart)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tick_decimals_resolve_a_tenth_of_the_span() {
        for (span, decimals) in [(41.0, 0), (0.02, 3), (1.0, 1), (0.0, 0)] {
            assert_eq!(tick_decimals(span), decimals, "span {span}");
        }
    }

    #[test]
    fn fixed_labels_never_show_negative_zero() {
        for (v, decimals, label) in [
            (-0.001, 2, "0.00"),
            (-0.0, 0, "0"),
            (-0.1, 2, "-0.10"),
            (12.345, 1, "12.3"),
        ] {
            assert_eq!(fixed(v, decimals), label);
        }
    }

    #[test]
    fn only_1_2_5_mantissas_get_log_labels() {
        assert!(is_125(1e-7) && is_125(2e-7) && is_125(5e-6) && is_125(100.0));
        assert!(!is_125(3e-7) && !is_125(9e-7) && !is_125(0.0) && !is_125(-1.0));
    }

    #[test]
    fn log_ticks_are_plain_in_the_middle_and_scientific_at_the_ends() {
        for (v, label) in [
            (10.0, "10"),
            (0.5, "0.5"),
            (1e-6, "1e-6"),
            (1e6, "1e6"),
            (1e4, "1e4"),
            (2e-7, "2e-7"),
        ] {
            assert_eq!(log_tick(v), label);
        }
    }
}
