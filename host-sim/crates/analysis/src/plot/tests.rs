use super::*;

use std::path::Path;

#[path = "../../../../tests/common/scratch.rs"]
mod scratch;
use scratch::Scratch;

const K1_V_PER_G: f64 = 1.25;

/// A fresh empty directory under the system temp dir, removed when the test passes.
fn scratch(name: &str) -> Scratch {
    Scratch::new(&format!("plot-{name}"))
}

/// Deterministic pseudo-noise in [-1, 1) (no rand dependency; the exact values do not matter).
fn wiggle(i: usize, salt: u64) -> f64 {
    let mut z = (i as u64)
        .wrapping_add(salt)
        .wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z ^= z >> 29;
    z = z.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z ^= z >> 32;
    (z >> 11) as f64 / (1u64 << 52) as f64 - 1.0
}

/// A small log with every column the figures use: 1 g (or 0 g) output with a temperature-driven
/// error that the "compensated" columns do not have.
fn synthetic(n: usize, dt_s: f64, input_g: f64) -> Log {
    let t: Vec<f64> = (0..n).map(|i| i as f64 * dt_s).collect();
    let temp: Vec<f64> = t
        .iter()
        .enumerate()
        .map(|(i, &s)| {
            60.0 + 0.02 * (s / 86_400.0 * std::f64::consts::TAU).sin() + 0.002 * wiggle(i, 1)
        })
        .collect();
    let tilt: Vec<f64> = t
        .iter()
        .enumerate()
        .map(|(i, &s)| 0.2 * (s / 86_400.0 * std::f64::consts::TAU).cos() + 0.01 * wiggle(i, 2))
        .collect();
    let truth_g: Vec<f64> = (0..n).map(|i| input_g + 2e-6 * wiggle(i, 3)).collect();
    let raw_g: Vec<f64> = truth_g
        .iter()
        .zip(&temp)
        .map(|(g, c)| g + 5e-4 * (c - 60.0))
        .collect();
    let mut log = Log::with_time(t).unwrap();
    log.set_meta("instrument", "synthetic unit").unwrap();
    log.set_meta("start_utc", "2024-03-01T00:00:00Z").unwrap();
    log.set_meta("input_g", &input_g.to_string()).unwrap();
    log.set_meta("scale_factor_v_per_g", &K1_V_PER_G.to_string())
        .unwrap();
    log.push_column("output_v", raw_g.iter().map(|g| g * K1_V_PER_G).collect())
        .unwrap();
    log.push_column("a_i_exact_g", truth_g.clone()).unwrap();
    log.push_column(
        "output_linearized_v",
        truth_g.iter().map(|g| g * K1_V_PER_G).collect(),
    )
    .unwrap();
    log.push_column("temperature_c", temp.clone()).unwrap();
    log.push_column(
        "truth_temperature_c",
        temp.iter().map(|c| c - 0.05).collect(),
    )
    .unwrap();
    log.push_column("tilt_arcsec", tilt).unwrap();
    log
}

fn opts(dir: &Path, format: Format, kind: Kind) -> PlotOptions {
    PlotOptions {
        format,
        kind,
        ..PlotOptions::new(dir, "t")
    }
}

fn time_figure(f: Figure) -> TimeFigure {
    match f {
        Figure::Time(t) | Figure::TimeMarked(t, _) => t,
        _ => panic!("expected a time figure"),
    }
}

/// The temperature figure of a log with events or phase changes, which marks them.
fn marked_temperature_figure(log: &Log, dir: &Path) -> (TimeFigure, Vec<Marker>) {
    match build(
        log,
        &opts(dir, Format::Svg, Kind::Temperature),
        Kind::Temperature,
    )
    .unwrap()
    {
        Figure::TimeMarked(t, markers) => (t, markers),
        other => panic!("expected a marked time figure, got {other:?}"),
    }
}

/// Minimal structural check of an SVG document written by plotters.
fn assert_svg(path: &Path) -> String {
    let s = std::fs::read_to_string(path).unwrap();
    let body = s.trim_start_matches(|c: char| c != '<');
    assert!(body.starts_with("<svg"), "{path:?} does not open with <svg");
    assert!(s.trim_end().ends_with("</svg>"), "{path:?} is not closed");
    assert!(s.contains("xmlns=\"http://www.w3.org/2000/svg\""));
    assert_eq!(s.matches("<svg").count(), 1);
    // Something was drawn: lines and text.
    assert!(
        s.contains("<polyline") || s.contains("<path"),
        "{path:?} has no lines"
    );
    assert!(s.contains("<text"), "{path:?} has no text");
    s
}

/// PNG signature and the IHDR size.
fn png_size(path: &Path) -> (u32, u32) {
    let b = std::fs::read(path).unwrap();
    assert_eq!(&b[..8], b"\x89PNG\r\n\x1a\n", "{path:?} is not a PNG");
    assert_eq!(&b[12..16], b"IHDR");
    let w = u32::from_be_bytes([b[16], b[17], b[18], b[19]]);
    let h = u32::from_be_bytes([b[20], b[21], b[22], b[23]]);
    (w, h)
}

/// The files' names without their folder.
fn file_names(paths: &[PathBuf]) -> Vec<String> {
    paths
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect()
}

#[test]
fn all_kinds_of_a_1g_log_write_four_valid_svgs() {
    let dir = scratch("svg");
    let log = synthetic(3 * 1440, 60.0, 1.0);
    let out = plot_log(&log, &opts(&dir, Format::Svg, Kind::All)).unwrap();
    let names = file_names(&out.written);
    assert_eq!(
        names,
        [
            "t_fig2_temperature.svg",
            "t_fig3_output_1g.svg",
            "t_fig4_tilt.svg",
            "t_adev.svg"
        ]
    );
    assert!(out.skipped.is_empty());
    for p in &out.written {
        assert!(std::fs::metadata(p).unwrap().len() > 1000);
        assert_svg(p);
    }
    let fig3 = assert_svg(&out.written[1]);
    assert!(fig3.contains("before temperature compensation"));
    assert!(fig3.contains("after temperature compensation"));
    assert!(fig3.contains("synthetic unit"));
}

#[test]
fn png_figures_have_the_signature_and_the_figure_size() {
    let dir = scratch("png");
    let log = synthetic(2000, 30.0, 1.0);
    for kind in [Kind::Temperature, Kind::Output, Kind::Tilt, Kind::Adev] {
        let o = opts(&dir, Format::Png, kind);
        let fig = build(&log, &o, kind).unwrap();
        let out = plot_log(&log, &o).unwrap();
        assert_eq!(out.written.len(), 1);
        assert_eq!(png_size(&out.written[0]), fig.size(), "{kind:?}");
        // A blank white PNG of this size compresses to a few kB; drawn text and lines do not.
        assert!(std::fs::metadata(&out.written[0]).unwrap().len() > 15_000);
    }
}

#[test]
fn a_zero_g_log_gets_fig5_instead_of_fig3() {
    let dir = scratch("zero");
    let log = synthetic(1440, 60.0, 0.0);
    let out = plot_log(&log, &opts(&dir, Format::Svg, Kind::All)).unwrap();
    let names = file_names(&out.written);
    assert!(
        names.contains(&"t_fig5_output_0g.svg".to_string()),
        "{names:?}"
    );
    assert!(!names.iter().any(|n| n.contains("fig3")));
    let s = assert_svg(&dir.join("t_fig5_output_0g.svg"));
    assert!(s.contains("tilt compensation"));
    assert!(s.contains("sin(φ − φ0)"));
}

#[test]
fn a_missing_column_is_an_error_naming_it() {
    let dir = scratch("missing");
    let mut log = Log::with_time((0..100).map(f64::from).collect()).unwrap();
    log.push_column("output_v", vec![1.0; 100]).unwrap();
    for (kind, column) in [
        (Kind::Temperature, "temperature_c"),
        (Kind::Tilt, "tilt_arcsec"),
    ] {
        let e = plot_log(&log, &opts(&dir, Format::Svg, kind)).unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains(&format!("`{column}`")), "{msg}");
        assert!(
            msg.contains("output_v"),
            "lists the columns there are: {msg}"
        );
    }
    let mut o = opts(&dir, Format::Svg, Kind::Output);
    o.raw = "output_volts".into();
    let msg = plot_log(&log, &o).unwrap_err().to_string();
    assert!(msg.contains("`output_volts`"), "{msg}");
    let mut o = opts(&dir, Format::Svg, Kind::Adev);
    o.compensated = vec!["a_comp_g".into()];
    let msg = plot_log(&log, &o).unwrap_err().to_string();
    assert!(msg.contains("`a_comp_g`"), "{msg}");
    // Nothing was written for the failed requests.
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0);
}

#[test]
fn kind_all_skips_figures_without_their_columns_and_says_so() {
    let dir = scratch("skip");
    let mut log = Log::with_time((0..100).map(f64::from).collect()).unwrap();
    log.push_column("output_v", (0..100).map(|i| wiggle(i, 9)).collect())
        .unwrap();
    let out = plot_log(&log, &opts(&dir, Format::Svg, Kind::All)).unwrap();
    assert_eq!(out.written.len(), 2, "output and adev: {:?}", out.written);
    assert_eq!(out.skipped.len(), 2);
    assert!(out.skipped[0].contains("temperature_c"));
    assert!(out.skipped[1].contains("tilt_arcsec"));
}

#[test]
fn kind_all_on_a_log_with_nothing_plottable_fails() {
    let dir = scratch("nothing");
    let mut log = Log::with_time((0..10).map(f64::from).collect()).unwrap();
    log.push_column("pressure_hpa", vec![1000.0; 10]).unwrap();
    let e = plot_log(&log, &opts(&dir, Format::Svg, Kind::All)).unwrap_err();
    assert!(matches!(e, PlotError::NothingToPlot(_)), "{e}");
}

#[test]
fn output_panels_are_microg_deviations_with_the_sample_std_in_the_legend() {
    // output_v alternates 1 g ± 10 µg: mean 1 g, sample std 10 µg * sqrt(n / (n - 1)).
    let n = 400;
    let mut log = Log::with_time((0..n).map(|i| i as f64).collect()).unwrap();
    log.set_meta("scale_factor_v_per_g", "2").unwrap();
    let g: Vec<f64> = (0..n)
        .map(|i| if i % 2 == 0 { 1.0 + 1e-5 } else { 1.0 - 1e-5 })
        .collect();
    log.push_column("output_v", g.iter().map(|v| 2.0 * v).collect())
        .unwrap();
    log.push_column("a_i_exact_g", vec![1.0; n]).unwrap();
    let o = opts(Path::new("unused"), Format::Svg, Kind::Output);
    let fig = time_figure(build(&log, &o, Kind::Output).unwrap());
    assert_eq!(fig.panels.len(), 2);
    assert!(fig.shared_y);
    let raw = &fig.panels[0].traces[0];
    assert_eq!(
        raw.label,
        "output_v / K1 (before temperature compensation): σ = 1.00e-5 g"
    );
    let ys: Vec<f64> = raw.runs.iter().flatten().map(|b| b.mean).collect();
    assert_eq!(ys.len(), n);
    for (i, y) in ys.iter().enumerate() {
        let want = if i % 2 == 0 { 10.0 } else { -10.0 };
        assert!((y - want).abs() < 1e-6, "point {i}: {y} µg");
    }
    assert_eq!(fig.panels[0].y_desc, "output_v / K1 − mean (µg)");
    let comp = &fig.panels[1].traces[0];
    assert_eq!(
        comp.label,
        "a_i_exact_g (after temperature compensation): σ = 0.00e0 g"
    );
}

#[test]
fn without_a_scale_factor_volt_panels_stay_in_volts_and_are_not_shared() {
    let mut log = Log::with_time((0..50).map(f64::from).collect()).unwrap();
    log.push_column(
        "output_v",
        (0..50).map(|i| 1.3 + 1e-6 * wiggle(i, 4)).collect(),
    )
    .unwrap();
    log.push_column(
        "a_i_exact_g",
        (0..50).map(|i| 1.0 + 1e-6 * wiggle(i, 5)).collect(),
    )
    .unwrap();
    let o = opts(Path::new("unused"), Format::Svg, Kind::Output);
    let fig = time_figure(build(&log, &o, Kind::Output).unwrap());
    assert_eq!(fig.panels[0].y_desc, "output_v − mean (µV)");
    assert!(!fig.shared_y);
}

#[test]
fn time_axis_is_in_days_for_long_logs_and_hours_for_short_ones() {
    let long = synthetic(100, 41.0 * 86_400.0 / 99.0, 1.0);
    let f = time_figure(build(&long, &PlotOptions::new("x", "t"), Kind::Temperature).unwrap());
    assert_eq!(f.x_desc, "time since 2024-03-01T00:00:00Z (days)");
    assert!((f.x_range.1 - 41.0).abs() < 1e-9);
    let short = synthetic(100, 864.0, 0.0);
    let f = time_figure(build(&short, &PlotOptions::new("x", "t"), Kind::Tilt).unwrap());
    assert!(f.x_desc.ends_with("(h)"));
    assert!((f.x_range.1 - 99.0 * 864.0 / 3600.0).abs() < 1e-9);
}

#[test]
fn truth_columns_are_drawn_beside_the_measured_ones() {
    let log = synthetic(100, 60.0, 1.0);
    let f = time_figure(build(&log, &PlotOptions::new("x", "t"), Kind::Temperature).unwrap());
    let labels: Vec<&str> = f.panels[0]
        .traces
        .iter()
        .map(|t| t.label.as_str())
        .collect();
    assert_eq!(labels.len(), 2);
    assert!(labels[0].starts_with("temperature_c: mean "));
    assert!(labels[1].starts_with("truth_temperature_c: mean "));
}

#[test]
fn adev_curves_have_bands_around_them_and_start_at_tau0() {
    let log = synthetic(4096, 10.0, 1.0);
    let o = opts(Path::new("unused"), Format::Svg, Kind::Adev);
    let Figure::Adev(a) = build(&log, &o, Kind::Adev).unwrap() else {
        panic!("expected an Allan figure");
    };
    // Raw plus the two default compensated columns present in the synthetic log.
    assert_eq!(a.curves.len(), 3);
    assert_eq!(a.y_desc, "σ_y(τ) (g)");
    for c in &a.curves {
        assert_eq!(c.points[0].0, 10.0);
        assert!(c.points.len() >= 8, "{} points", c.points.len());
        for p in &c.points {
            assert!(p.2 <= p.1 && p.1 <= p.3, "{p:?}");
        }
    }
    // White noise of 2e-6 g: the compensated curve at tau0 is near 2e-6 / sqrt(3) (uniform
    // noise of half-width 2e-6 has std 2e-6 / sqrt(3)), far below the temperature-driven raw one.
    let comp0 = a.curves[1].points[0].1;
    assert!((comp0 / (2e-6 / 3f64.sqrt()) - 1.0).abs() < 0.1, "{comp0}");
}

#[test]
fn adev_of_a_log_off_any_time_grid_is_an_error() {
    let t = vec![0.0, 1.0, 2.7, 3.1, 9.0, 9.5, 20.0];
    let mut log = Log::with_time(t).unwrap();
    log.push_column("output_v", vec![1.0, 2.0, 1.0, 2.0, 1.0, 2.0, 1.0])
        .unwrap();
    let e = build(
        &log,
        &opts(Path::new("x"), Format::Svg, Kind::Adev),
        Kind::Adev,
    )
    .unwrap_err();
    assert!(matches!(e, PlotError::Grid(_)), "{e}");
}

#[test]
fn a_million_sample_log_makes_a_small_svg_that_keeps_its_spike() {
    let dir = scratch("big");
    let n = 1_000_000;
    let mut log = Log::with_time((0..n).map(|i| i as f64).collect()).unwrap();
    let mut y: Vec<f64> = (0..n).map(|i| 1.0 + 1e-6 * wiggle(i, 6)).collect();
    y[654_321] = 1.0 + 1e-3;
    log.push_column("output_v", y).unwrap();
    let o = opts(&dir, Format::Svg, Kind::Output);
    let fig = time_figure(build(&log, &o, Kind::Output).unwrap());
    let b: Vec<decimate::Bucket> = fig.panels[0].traces[0]
        .runs
        .iter()
        .flatten()
        .copied()
        .collect();
    assert_eq!(b.len(), draw::WIDTH_PX as usize);
    let top = b.iter().map(|q| q.max).fold(f64::MIN, f64::max);
    // The spike, in µV from the mean (no scale factor: volts).
    assert!((top - 1e3).abs() < 1.0, "{top}");
    let out = plot_log(&log, &o).unwrap();
    let size = std::fs::metadata(&out.written[0]).unwrap().len();
    assert!(size < 500_000, "{size} bytes");
}

#[test]
fn tilt_peak_to_peak_is_taken_on_block_means_not_on_noisy_readings() {
    // A 0.4″ step after 1 h plus ±0.1″ alternating noise: readings span 0.6″, 10-min means 0.4″.
    let t: Vec<f64> = (0..7200).map(f64::from).collect();
    let y: Vec<f64> = t
        .iter()
        .enumerate()
        .map(|(i, &s)| {
            let step = if s >= 3600.0 { 0.4 } else { 0.0 };
            step + if i % 2 == 0 { 0.1 } else { -0.1 }
        })
        .collect();
    let pp = block_mean_range(&t, &y, 600.0).unwrap();
    assert!((pp - 0.4).abs() < 1e-12, "{pp}");
    assert_eq!(block_mean_range(&t, &vec![f64::NAN; 7200], 600.0), None);
    let mut log = Log::with_time(t).unwrap();
    log.push_column("tilt_arcsec", y).unwrap();
    let f = time_figure(build(&log, &PlotOptions::new("x", "t"), Kind::Tilt).unwrap());
    assert!(
        f.panels[0].traces[0]
            .label
            .starts_with("tilt_arcsec: peak-to-peak of 10-min means 0.400″"),
        "{}",
        f.panels[0].traces[0].label
    );
}

/// A recorder's log over a board reset, written as `accomp record` writes one: 1 s readings,
/// then the new boot 0.4 s off the old grid with the reset's event line between.
fn recorder_log_over_a_reset() -> Log {
    let mut text = String::from(
        "# recorder: accomp record 0.1.0\n# start_utc: 2026-01-01T00:00:00Z\n\
         # input_g: 1\ntime_s,output_v,a_i_exact_g,temperature_c,tilt_arcsec\n",
    );
    for k in 0..200 {
        let w = wiggle(k, 7);
        text += &format!("{k},{},{},60,{}\n", 1.0 + 1e-5 * w, 1.0 + 1e-6 * w, 0.1 * w);
    }
    text += "# event: 2026-01-01T00:03:20Z board_reset seq restarted at 0 after 199\n";
    for k in 0..200 {
        let w = wiggle(k, 8);
        let t = 200.4 + k as f64;
        text += &format!("{t},{},{},61,{}\n", 1.0 + 1e-5 * w, 1.0 + 1e-6 * w, 0.1 * w);
    }
    Log::parse_str(&text).unwrap()
}

#[test]
fn a_record_over_a_board_reset_is_plotted_in_segments_with_the_reset_marked() {
    let dir = scratch("reset");
    let log = recorder_log_over_a_reset();
    let out = plot_log(&log, &opts(&dir, Format::Svg, Kind::All)).unwrap();
    // Every figure drawn, none refused for the phase change.
    assert_eq!(out.written.len(), 4, "{:?}", out.skipped);
    assert!(out.skipped.is_empty(), "{:?}", out.skipped);
    // The note is the one `stability` prints, with where the reset is.
    assert_eq!(out.notes.len(), 1);
    assert!(
        out.notes[0].starts_with(
            "2 continuous segments (1 board_reset): new ones start at time_s = 200.4 \
             (board_reset event at 2026-01-01T00:03:20Z)"
        ),
        "{}",
        out.notes[0]
    );
    // The time figures: a dashed line at the reset (200.4 s = 0.0557 h), no line across it.
    let (t, markers) = marked_temperature_figure(&log, &dir);
    assert_eq!(markers.len(), 1);
    assert!((markers[0].at - 200.4 / 3600.0).abs() < 1e-12);
    let runs = &t.panels[0].traces[0].runs;
    assert_eq!(runs.len(), 2);
    assert_eq!(runs[0].last().unwrap().mean, 60.0);
    assert_eq!(runs[1].first().unwrap().mean, 61.0);
    let svg = assert_svg(&dir.join("t_fig2_temperature.svg"));
    assert!(svg.contains("board_reset (dashed)"));
    // The Allan deviation pools within the segments: its title says so.
    match build(&log, &opts(&dir, Format::Svg, Kind::Adev), Kind::Adev).unwrap() {
        Figure::Adev(a) => {
            assert!(
                a.title
                    .contains("pooled within 2 continuous segments (1 board_reset)"),
                "{}",
                a.title
            );
            assert!(a.curves.iter().all(|c| !c.points.is_empty()));
        }
        other => panic!("expected the Allan figure, got {other:?}"),
    }
    // Without the recorder's mark the same rows are off the grid: refused as before.
    let mut plain = Log::with_time(log.time_s().to_vec()).unwrap();
    plain
        .push_column("output_v", log.column("output_v").unwrap().to_vec())
        .unwrap();
    assert!(matches!(
        build(&plain, &opts(&dir, Format::Svg, Kind::Adev), Kind::Adev),
        Err(PlotError::Grid(GridError::OffGrid { .. }))
    ));
}

#[test]
fn a_record_is_split_at_its_events_and_phase_changes_each_line_labelled_by_its_kind() {
    // Four stretches of 100 s at 1 s, written as `accomp record` writes them: a board reset on
    // the old phase (t = 100, event line), a table change (t = 200, event line), a reset without
    // its event whose boot samples 0.4 s off the grid (t = 300.4). Each stretch has its own
    // temperature, so a line drawn across a boundary would show as a run holding two levels.
    let mut text = String::from(
        "# recorder: accomp record 0.1.0\n# start_utc: 2026-01-01T00:00:00Z\n\
         # input_g: 1\ntime_s,output_v,a_i_exact_g,temperature_c,tilt_arcsec\n",
    );
    for (stretch, (t0, event)) in [
        (0.0, ""),
        (
            100.0,
            "# event: 2026-01-01T00:01:40Z board_reset seq restarted at 0 after 99 (no READY seen)\n",
        ),
        (
            200.0,
            "# event: 2026-01-01T00:03:20Z table_changed 0x00000001 -> 0x00000002\n",
        ),
        (300.4, ""),
    ]
    .into_iter()
    .enumerate()
    {
        text += event;
        for k in 0..100 {
            let w = wiggle(k, 9 + stretch as u64);
            let t = t0 + k as f64;
            let temp = 60 + stretch;
            text += &format!("{t},{},{},{temp},{}\n", 1.0 + 1e-5 * w, 1.0 + 1e-6 * w, 0.1 * w);
        }
    }
    let log = Log::parse_str(&text).unwrap();
    let dir = scratch("events");
    let out = plot_log(&log, &opts(&dir, Format::Svg, Kind::Temperature)).unwrap();
    let note = &out.notes[0];
    assert!(
        note.starts_with("4 continuous segments (1 board_reset, 1 table_changed, 1 phase change)")
            && note.contains("100 (board_reset event at 2026-01-01T00:01:40Z)")
            && note.contains("200 (table_changed event at 2026-01-01T00:03:20Z)")
            && note.contains("300.4 (the sampling phase changes)"),
        "{note}"
    );
    let (t, markers) = marked_temperature_figure(&log, &dir);
    let labels: Vec<&str> = markers.iter().map(|m| m.label.as_str()).collect();
    assert_eq!(labels, ["board_reset", "table_changed", "phase change"]);
    let runs = &t.panels[0].traces[0].runs;
    assert_eq!(runs.len(), 4);
    for (run, level) in runs.iter().zip([60.0, 61.0, 62.0, 63.0]) {
        assert!(run.iter().all(|b| b.min == level && b.max == level));
    }
    let svg = assert_svg(&dir.join("t_fig2_temperature.svg"));
    for kind in ["board_reset", "table_changed", "phase change"] {
        assert!(svg.contains(&format!("{kind} (dashed)")), "{kind}");
    }
}
