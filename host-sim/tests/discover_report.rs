//! `accomp discover --report` from the command line on a small simulated log: the three figures
//! exist, are PNG (or SVG with `--report-format svg`) and are linked from report.md.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const FIGURES: [&str; 3] = ["residual_time", "residual_spectrum", "residual_adev"];

fn accomp(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_accomp"))
        .args(args)
        .output()
        .expect("run accomp")
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "accomp-discover-report-{}-{name}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A two-day 1 g log at one sample a minute (small enough for a debug build).
fn simulated_log(dir: &Path) -> PathBuf {
    let log = dir.join("one_g.csv");
    let sim = accomp(&[
        "simulate",
        "paper-1g",
        "--seed",
        "5",
        "--days",
        "2",
        "--interval",
        "60",
        "-o",
        s(&log),
    ]);
    assert!(
        sim.status.success(),
        "{}",
        String::from_utf8_lossy(&sim.stderr)
    );
    log
}

#[test]
fn report_writes_three_png_figures_and_links_them() {
    let dir = scratch("png");
    let log = simulated_log(&dir);
    let report = dir.join("report");
    let out = accomp(&["discover", s(&log), "--report", s(&report)]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let md = std::fs::read_to_string(report.join("report.md")).unwrap();
    for stem in FIGURES {
        let name = format!("{stem}.png");
        let bytes = std::fs::read(report.join(&name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(bytes.len() > 8, "{name} is empty");
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{name} is not a PNG");
        assert!(
            md.contains(&format!("]({name})")),
            "{name} not linked:\n{md}"
        );
    }
    assert!(!md.contains("not drawn"), "{md}");
    // Kept when an assertion above fails, for inspection; removed when the test passes.
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn report_format_svg_writes_svg_figures() {
    let dir = scratch("svg");
    let log = simulated_log(&dir);
    let report = dir.join("report");
    let out = accomp(&[
        "discover",
        s(&log),
        "--report",
        s(&report),
        "--report-format",
        "svg",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let md = std::fs::read_to_string(report.join("report.md")).unwrap();
    for stem in FIGURES {
        let name = format!("{stem}.svg");
        let text =
            std::fs::read_to_string(report.join(&name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(text.contains("<svg"), "{name} is not an SVG");
        assert!(md.contains(&format!("]({name})")), "{name} not linked");
        assert!(!report.join(format!("{stem}.png")).exists());
    }
    let _ = std::fs::remove_dir_all(&dir);
}
