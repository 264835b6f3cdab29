//! `accomp record --tui`: the full-screen live view of a record.
//!
//! The view is fed by the recorder's [`Progress`] (a few times a second: the rows and event lines
//! since the previous call, the counters, the link state) and keeps only bounded state, so a
//! six-week record does not grow it: the output, temperature and tilt as means over
//! [`TRACE_BIN_S`]-second bins of record time for the last [`TRACE_WINDOW_S`], and the series of
//! the Allan deviation so far, halved (pairs averaged) whenever it reaches [`ALLAN_MAX_POINTS`].
//!
//! The Allan deviation shown is a preview: the overlapping Allan deviation (with its 68 %
//! χ² band, `accomp_analysis::allan`) of `a_i_exact_g` in record order, with a NaN for every
//! missing seq (so a gap is a gap, as `accomp stability` treats it). Once the series has been
//! halved its shortest tau is 2^k frames and fewer windows overlap than in `accomp stability`,
//! which stays the reference. A board reset starts a new sampling grid: the live series just
//! continues (the view says how many resets it spans); `accomp stability` on the file is exact.

use std::collections::VecDeque;

use ratatui::layout::{Constraint, Direction, Layout, Rect};
use ratatui::style::{Color, Style};
use ratatui::symbols::Marker;
use ratatui::text::Line;
use ratatui::widgets::{Axis, Block, Borders, Chart, Dataset, GraphType, Paragraph};

use crate::allan::{self, AllanPoint, TauSet};
use crate::device::record::{Link, Progress};

/// Width of one point of the time traces, s of record time.
pub const TRACE_BIN_S: f64 = 30.0;
/// How much record time the traces show, s.
pub const TRACE_WINDOW_S: f64 = 6.0 * 3600.0;
/// The Allan series is halved when it reaches this many points.
pub const ALLAN_MAX_POINTS: usize = 1 << 16;
/// Event lines kept for the events panel.
const EVENTS_SHOWN: usize = 6;

/// Means of a quantity over fixed bins of record time, the last `window_s` of them kept.
#[derive(Debug, Clone)]
pub struct Trace {
    bin_s: f64,
    cap: usize,
    points: VecDeque<(f64, f64)>,
    /// The bin being filled: (bin index, sum, count).
    current: Option<(i64, f64, u32)>,
}

impl Trace {
    /// Bins of `bin_s` seconds, the last `window_s` seconds kept.
    pub fn new(bin_s: f64, window_s: f64) -> Self {
        Self {
            bin_s,
            cap: (window_s / bin_s).ceil().max(1.0) as usize,
            points: VecDeque::new(),
            current: None,
        }
    }

    /// Adds a value at record time `t_s`; NaN/∞ (a gap in the row) is skipped.
    pub fn push(&mut self, t_s: f64, v: f64) {
        if !(v.is_finite() && t_s.is_finite()) {
            return;
        }
        let bin = (t_s / self.bin_s).floor() as i64;
        match &mut self.current {
            Some((b, sum, n)) if *b == bin => {
                *sum += v;
                *n += 1;
            }
            _ => {
                self.flush();
                self.current = Some((bin, v, 1));
            }
        }
    }

    fn flush(&mut self) {
        if let Some((b, sum, n)) = self.current.take() {
            if self.points.len() == self.cap {
                self.points.pop_front();
            }
            self.points
                .push_back(((b as f64 + 0.5) * self.bin_s, sum / f64::from(n)));
        }
    }

    /// The points (bin centre, mean), the bin being filled last; at most the window's bins + 1.
    pub fn points(&self) -> Vec<(f64, f64)> {
        let mut v: Vec<(f64, f64)> = self.points.iter().copied().collect();
        if let Some((b, sum, n)) = self.current {
            v.push(((b as f64 + 0.5) * self.bin_s, sum / f64::from(n)));
        }
        v
    }
}

/// The readings for the live Allan deviation: one per seq (NaN where a seq is missing), averaged
/// in pairs whenever the series reaches its cap, so memory stays bounded.
#[derive(Debug, Clone)]
pub struct AllanSeries {
    cap: usize,
    /// Readings, each the mean of `2^level` frames (NaN if any of them is missing).
    y: Vec<f64>,
    level: u32,
    /// The point being filled: (sum, frames in it, any missing).
    pending: (f64, u64, bool),
    last: Option<(u32, f64)>,
    /// Frame period, s (from the first two consecutive frames).
    tau0_s: Option<f64>,
    /// Board resets (seq going back) the series spans.
    pub resets: u32,
}

impl AllanSeries {
    /// An empty series halved at `cap` points.
    pub fn new(cap: usize) -> Self {
        Self {
            cap: cap.max(4),
            y: Vec::new(),
            level: 0,
            pending: (0.0, 0, false),
            last: None,
            tau0_s: None,
            resets: 0,
        }
    }

    fn push_reading(&mut self, v: f64) {
        let (sum, n, missing) = &mut self.pending;
        *n += 1;
        if v.is_finite() {
            *sum += v;
        } else {
            *missing = true;
        }
        if *n == 1u64 << self.level {
            let mean = if *missing { f64::NAN } else { *sum / *n as f64 };
            self.pending = (0.0, 0, false);
            self.y.push(mean);
            if self.y.len() >= self.cap {
                // Pairs averaged (NaN stays NaN): the series at twice the spacing.
                self.y = self
                    .y
                    .chunks_exact(2)
                    .map(|p| (p[0] + p[1]) / 2.0)
                    .collect();
                self.level += 1;
            }
        }
    }

    /// Adds the frame `seq` at record time `t_s` with value `v` (NaN: invalid in the frame).
    pub fn push(&mut self, seq: u32, t_s: f64, v: f64) {
        if let Some((last_seq, last_t)) = self.last {
            if seq > last_seq {
                let step = seq - last_seq;
                if step == 1 && self.tau0_s.is_none() && t_s > last_t {
                    self.tau0_s = Some(t_s - last_t);
                }
                // Missing frames are gaps; a gap longer than the whole series is capped (the
                // terms across it are skipped either way).
                let missing = u64::from(step - 1).min((self.cap as u64) << self.level);
                for _ in 0..missing {
                    self.push_reading(f64::NAN);
                }
            } else {
                self.resets += 1;
            }
        }
        self.last = Some((seq, t_s));
        self.push_reading(v);
    }

    /// Spacing of the series' points, s (None before two consecutive frames).
    pub fn spacing_s(&self) -> Option<f64> {
        self.tau0_s.map(|t| t * f64::from(1u32 << self.level))
    }

    /// Points in the series (bounded by the cap).
    pub fn len(&self) -> usize {
        self.y.len()
    }

    /// True before the first point.
    pub fn is_empty(&self) -> bool {
        self.y.is_empty()
    }

    /// Octave-spaced overlapping Allan deviation of the series so far (empty while too short).
    pub fn deviation(&self) -> Vec<AllanPoint> {
        match self.spacing_s() {
            Some(tau0) => allan::oadev(&self.y, tau0, TauSet::Octave).unwrap_or_default(),
            None => Vec::new(),
        }
    }
}

/// Everything the live view shows, updated from the recorder's progress.
#[derive(Debug, Clone)]
pub struct LiveView {
    /// Accelerometer output, V.
    pub output: Trace,
    /// RTD temperature, °C.
    pub temperature: Trace,
    /// Tilt, arcsec.
    pub tilt: Trace,
    /// a_i (exact) for the Allan deviation, g.
    pub allan: AllanSeries,
    /// The Allan deviation as last computed.
    pub allan_points: Vec<AllanPoint>,
    samples: u64,
    record_s: f64,
    lost: u64,
    events: u64,
    link: Link,
    drift_ppm: f64,
    to_go: Option<String>,
    counters: Vec<(&'static str, u64)>,
    live_rows_skipped: u64,
    recent_events: VecDeque<String>,
}

impl Default for LiveView {
    fn default() -> Self {
        Self::new()
    }
}

impl LiveView {
    /// An empty view.
    pub fn new() -> Self {
        Self {
            output: Trace::new(TRACE_BIN_S, TRACE_WINDOW_S),
            temperature: Trace::new(TRACE_BIN_S, TRACE_WINDOW_S),
            tilt: Trace::new(TRACE_BIN_S, TRACE_WINDOW_S),
            allan: AllanSeries::new(ALLAN_MAX_POINTS),
            allan_points: Vec::new(),
            samples: 0,
            record_s: 0.0,
            lost: 0,
            events: 0,
            link: Link::Down,
            drift_ppm: 0.0,
            to_go: None,
            counters: Vec::new(),
            live_rows_skipped: 0,
            recent_events: VecDeque::new(),
        }
    }

    /// Takes the rows, events and counters of one progress report.
    pub fn update(&mut self, p: &Progress) {
        for (t, f) in &p.rows {
            self.output.push(*t, f.output_v);
            self.temperature.push(*t, f.temperature_c);
            self.tilt.push(*t, f.tilt_arcsec);
            self.allan.push(f.seq, *t, f.a_i_exact_g);
        }
        for (unix_s, kind, details) in &p.new_events {
            if self.recent_events.len() == EVENTS_SHOWN {
                self.recent_events.pop_front();
            }
            self.recent_events.push_back(format!(
                "{} {kind} {details}",
                accomp_log::time::Utc(*unix_s)
            ));
        }
        self.samples = p.samples;
        self.record_s = p.record_s;
        self.lost = p.lost;
        self.events = p.events;
        self.link = p.link;
        self.drift_ppm = p.drift_ppm;
        self.to_go = p.to_go.clone();
        if !p.counters.is_empty() {
            self.counters = p.counters.clone();
        }
        self.live_rows_skipped += p.live_rows_skipped;
    }

    /// Recomputes the Allan deviation (a few ms on the capped series: call every few seconds).
    pub fn refresh_allan(&mut self) {
        self.allan_points = self.allan.deviation();
    }

    /// The status line at the top.
    pub fn status_line(&self) -> String {
        format!(
            "link {} | {} samples | {:.0} s recorded | {} lost | {} events | drift {:.2} ppm{}",
            match self.link {
                Link::Up => "UP",
                Link::Down => "DOWN (reopening)",
            },
            self.samples,
            self.record_s,
            self.lost,
            self.events,
            self.drift_ppm,
            self.to_go
                .as_ref()
                .map_or_else(String::new, |t| format!(" | {t}"))
        )
    }

    /// Draws the whole view into `area`.
    pub fn draw(&self, f: &mut ratatui::Frame) {
        let area = f.area();
        let rows = Layout::default()
            .direction(Direction::Vertical)
            .constraints([
                Constraint::Length(3),
                Constraint::Percentage(60),
                Constraint::Min(8),
            ])
            .split(area);
        let status = Paragraph::new(self.status_line()).block(
            Block::default()
                .borders(Borders::ALL)
                .title("accomp record (q or Ctrl-C: stop)"),
        );
        f.render_widget(status, rows[0]);
        let grid = Layout::default()
            .direction(Direction::Horizontal)
            .constraints([Constraint::Percentage(50), Constraint::Percentage(50)])
            .split(rows[1]);
        let left = Layout::default()
            .direction(Direction::Vertical)
            .constraints([
                Constraint::Ratio(1, 3),
                Constraint::Ratio(1, 3),
                Constraint::Ratio(1, 3),
            ])
            .split(grid[0]);
        self.draw_trace(f, left[0], "Output (V)", &self.output, Color::Cyan);
        self.draw_trace(
            f,
            left[1],
            "Temperature (°C)",
            &self.temperature,
            Color::Yellow,
        );
        self.draw_trace(f, left[2], "Tilt (arcsec)", &self.tilt, Color::Green);
        self.draw_allan(f, grid[1]);
        let bottom = Layout::default()
            .direction(Direction::Horizontal)
            .constraints([Constraint::Percentage(40), Constraint::Percentage(60)])
            .split(rows[2]);
        let mut lines: Vec<Line> = vec![
            Line::from(format!("samples {}", self.samples)),
            Line::from(format!("lost (seq gaps) {}", self.lost)),
        ];
        for (name, v) in &self.counters {
            lines.push(Line::from(format!("{name} {v}")));
        }
        if self.live_rows_skipped > 0 {
            lines.push(Line::from(format!(
                "rows not shown (view behind) {}",
                self.live_rows_skipped
            )));
        }
        f.render_widget(
            Paragraph::new(lines).block(Block::default().borders(Borders::ALL).title("Counters")),
            bottom[0],
        );
        let ev: Vec<Line> = self
            .recent_events
            .iter()
            .map(|e| Line::from(e.clone()))
            .collect();
        f.render_widget(
            Paragraph::new(ev).block(
                Block::default()
                    .borders(Borders::ALL)
                    .title(format!("Events ({} written)", self.events)),
            ),
            bottom[1],
        );
    }

    fn draw_trace(
        &self,
        f: &mut ratatui::Frame,
        area: Rect,
        title: &str,
        trace: &Trace,
        color: Color,
    ) {
        let pts = trace.points();
        let title = format!(
            "{title}, last {:.0} h, {:.0} s means",
            TRACE_WINDOW_S / 3600.0,
            TRACE_BIN_S
        );
        let Some(bounds) = bounds(&pts) else {
            f.render_widget(
                Paragraph::new("no data yet")
                    .block(Block::default().borders(Borders::ALL).title(title)),
                area,
            );
            return;
        };
        let (x, y) = bounds;
        let ds = Dataset::default()
            .marker(Marker::Braille)
            .graph_type(GraphType::Line)
            .style(Style::default().fg(color))
            .data(&pts);
        let chart = Chart::new(vec![ds])
            .block(Block::default().borders(Borders::ALL).title(title))
            .x_axis(Axis::default().bounds(x).labels([fmt_h(x[0]), fmt_h(x[1])]))
            .y_axis(
                Axis::default()
                    .bounds(y)
                    .labels([format!("{:.6}", y[0]), format!("{:.6}", y[1])]),
            );
        f.render_widget(chart, area);
    }

    fn draw_allan(&self, f: &mut ratatui::Frame, area: Rect) {
        let title = format!(
            "Allan deviation of a_i (µg), 68 % band{}",
            if self.allan.resets > 0 {
                format!(", across {} reset(s)", self.allan.resets)
            } else {
                String::new()
            }
        );
        let lg = |p: &AllanPoint, v: f64| (p.tau_s.log10(), (v * 1e6).log10());
        let pts: Vec<&AllanPoint> = self
            .allan_points
            .iter()
            .filter(|p| p.dev > 0.0 && p.ci_low > 0.0 && p.ci_high.is_finite())
            .collect();
        let dev: Vec<(f64, f64)> = pts.iter().map(|p| lg(p, p.dev)).collect();
        let lo: Vec<(f64, f64)> = pts.iter().map(|p| lg(p, p.ci_low)).collect();
        let hi: Vec<(f64, f64)> = pts.iter().map(|p| lg(p, p.ci_high)).collect();
        let all: Vec<(f64, f64)> = lo.iter().chain(&hi).copied().collect();
        let Some((x, y)) = bounds(&all) else {
            f.render_widget(
                Paragraph::new("too few readings yet")
                    .block(Block::default().borders(Borders::ALL).title(title)),
                area,
            );
            return;
        };
        let band = Style::default().fg(Color::DarkGray);
        let chart = Chart::new(vec![
            Dataset::default()
                .name("ADEV")
                .marker(Marker::Braille)
                .graph_type(GraphType::Line)
                .style(Style::default().fg(Color::Magenta))
                .data(&dev),
            Dataset::default()
                .name("68 %")
                .marker(Marker::Dot)
                .graph_type(GraphType::Line)
                .style(band)
                .data(&lo),
            Dataset::default()
                .marker(Marker::Dot)
                .graph_type(GraphType::Line)
                .style(band)
                .data(&hi),
        ])
        .block(Block::default().borders(Borders::ALL).title(title))
        .x_axis(
            Axis::default()
                .title("tau (s)")
                .bounds(x)
                .labels([fmt_pow(x[0]), fmt_pow(x[1])]),
        )
        .y_axis(
            Axis::default()
                .bounds(y)
                .labels([fmt_pow(y[0]), fmt_pow(y[1])]),
        );
        f.render_widget(chart, area);
    }
}

/// Bounds of a point set, widened when flat; None when empty.
fn bounds(pts: &[(f64, f64)]) -> Option<([f64; 2], [f64; 2])> {
    let fin = pts.iter().filter(|(x, y)| x.is_finite() && y.is_finite());
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    let mut any = false;
    for &(x, y) in fin {
        any = true;
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    if !any {
        return None;
    }
    if x1 <= x0 {
        x1 = x0 + 1.0;
    }
    if y1 <= y0 {
        let d = y0.abs().max(1e-12) * 1e-6;
        y0 -= d;
        y1 += d;
    }
    Some(([x0, x1], [y0, y1]))
}

fn fmt_h(t_s: f64) -> String {
    format!("{:.2} h", t_s / 3600.0)
}

fn fmt_pow(log10: f64) -> String {
    format!("{:.3}", 10f64.powf(log10))
}

#[cfg(test)]
mod tests {
    use super::*;
    use accomp::pipeline::{Frame, LossFlags, Status};
    use ratatui::backend::TestBackend;
    use ratatui::Terminal;

    fn frame(seq: u32, a_g: f64) -> Frame {
        Frame {
            seq,
            time_us: u64::from(seq) * 100_000,
            lost: LossFlags::default(),
            output_v: 2.5 + a_g,
            temperature_c: 60.0,
            rtd_ohms: 123.0,
            tilt_arcsec: 1.5,
            a_i_exact_g: a_g,
            output_linearized_v: 2.5,
            status: Status::default(),
        }
    }

    fn progress(rows: Vec<(f64, Frame)>) -> Progress {
        Progress {
            samples: rows.len() as u64,
            record_s: rows.last().map_or(0.0, |r| r.0),
            lost: 0,
            events: 1,
            frames_dropped: 0,
            link: Link::Up,
            drift_ppm: 0.0,
            to_go: None,
            counters: vec![("frames_dropped", 0), ("conversions_lost", 7)],
            rows,
            live_rows_skipped: 0,
            new_events: vec![(1.7e9, "start".into(), "recording from /tmp/b".into())],
        }
    }

    #[test]
    fn trace_averages_each_bin_and_keeps_only_the_window() {
        let mut t = Trace::new(10.0, 30.0);
        // Bin 0: 1, 3 → 2; bin 1: 5; a NaN is skipped; bins 2, 3, 4 push bins 0, 1 out.
        for (s, v) in [(1.0, 1.0), (9.0, 3.0), (12.0, 5.0), (13.0, f64::NAN)] {
            t.push(s, v);
        }
        assert_eq!(t.points(), vec![(5.0, 2.0), (15.0, 5.0)]);
        for (s, v) in [(21.0, 7.0), (31.0, 8.0), (41.0, 9.0), (42.0, 11.0)] {
            t.push(s, v);
        }
        // Three finished bins kept (window 30 s) plus the one being filled.
        assert_eq!(
            t.points(),
            vec![(15.0, 5.0), (25.0, 7.0), (35.0, 8.0), (45.0, 10.0)]
        );
    }

    #[test]
    fn allan_series_puts_nan_at_missing_seqs_and_halves_at_its_cap() {
        let mut s = AllanSeries::new(8);
        s.push(0, 0.0, 1.0);
        s.push(1, 0.8, 2.0);
        s.push(4, 3.2, 3.0); // seq 2, 3 missing
        assert_eq!(s.spacing_s(), Some(0.8));
        assert_eq!(s.len(), 5);
        assert!(s.y[2].is_nan() && s.y[3].is_nan());
        for q in 5..8 {
            s.push(q, f64::from(q) * 0.8, 4.0);
        }
        // 8 readings reached the cap: pairs averaged, NaN pairs stay NaN, spacing doubled.
        assert_eq!(s.len(), 4);
        assert_eq!(s.y[0], 1.5);
        assert!(s.y[1].is_nan());
        assert_eq!(s.y[2], 3.5);
        assert_eq!(s.y[3], 4.0);
        assert_eq!(s.spacing_s(), Some(1.6));
        // Now two frames make one point.
        s.push(8, 6.4, 10.0);
        assert_eq!(s.len(), 4);
        s.push(9, 7.2, 20.0);
        assert_eq!(s.y[4], 15.0);
        // seq going back is a reset, counted, no gap inserted.
        s.push(0, 8.0, 1.0);
        assert_eq!(s.resets, 1);
        assert_eq!(s.len(), 5);
    }

    #[test]
    fn live_allan_of_alternating_readings_is_root_two_times_their_amplitude() {
        // Alternating ±1 µg: at tau0 every difference is 2 µg, so σ² = (2 µg)² / 2, σ = √2 µg.
        let mut v = LiveView::new();
        let rows: Vec<(f64, Frame)> = (0..64u32)
            .map(|q| {
                let a = if q % 2 == 0 { 1e-6 } else { -1e-6 };
                (f64::from(q) * 0.8, frame(q, a))
            })
            .collect();
        v.update(&progress(rows));
        v.refresh_allan();
        let p = &v.allan_points[0];
        assert_eq!(p.m, 1);
        assert!((p.tau_s - 0.8).abs() < 1e-12);
        assert!((p.dev - 2f64.sqrt() * 1e-6).abs() < 1e-15, "{}", p.dev);
        assert!(p.ci_low < p.dev && p.dev < p.ci_high);
    }

    #[test]
    fn update_takes_rows_counters_and_events() {
        let mut v = LiveView::new();
        let rows = (0..100u32)
            .map(|q| (f64::from(q), frame(q, 1e-6 * f64::from(q % 3))))
            .collect();
        v.update(&progress(rows));
        assert_eq!(v.samples, 100);
        assert_eq!(v.counters[1], ("conversions_lost", 7));
        assert_eq!(v.recent_events.len(), 1);
        assert!(v.recent_events[0].ends_with("start recording from /tmp/b"));
        // 100 s of rows in 30 s bins: 4 points, temperature constant.
        assert_eq!(v.temperature.points().len(), 4);
        assert!(v.temperature.points().iter().all(|p| p.1 == 60.0));
        assert!(v.status_line().starts_with("link UP | 100 samples"));
    }

    #[test]
    fn draw_shows_the_panels_and_the_counters() {
        let mut v = LiveView::new();
        let rows = (0..400u32)
            .map(|q| (f64::from(q) * 0.8, frame(q, 1e-6 * f64::from(q % 5))))
            .collect();
        v.update(&progress(rows));
        v.refresh_allan();
        let mut term = Terminal::new(TestBackend::new(160, 48)).unwrap();
        term.draw(|f| v.draw(f)).unwrap();
        let buf = term.backend().buffer();
        let text: String = (0..buf.area.height)
            .map(|y| {
                (0..buf.area.width)
                    .map(|x| buf[(x, y)].symbol())
                    .collect::<String>()
                    + "\n"
            })
            .collect();
        for title in [
            "Output (V)",
            "Temperature (°C)",
            "Tilt (arcsec)",
            "Allan deviation of a_i",
            "Counters",
            "Events (1 written)",
            "link UP | 400 samples",
            "conversions_lost 7",
        ] {
            assert!(text.contains(title), "{title:?} not drawn:\n{text}");
        }
        assert!(!text.contains("too few readings yet"), "{text}");
    }
}
