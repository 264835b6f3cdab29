//! `accomp discover --report` from the command line on a small simulated log: the three figures
//! exist, are PNG (or SVG with `--report-format svg`) and are linked from report.md.

use std::path::{Path, PathBuf};

#[path = "common/cli.rs"]
mod cli;
#[path = "common/scratch.rs"]
mod scratch;
use cli::accomp_ok;
use scratch::Scratch;

const FIGURES: [&str; 3] = ["residual_time", "residual_spectrum", "residual_adev"];

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A two-day 1 g log at one sample a minute (small enough for a debug build).
fn simulated_log(dir: &Path) -> PathBuf {
    let args = ["--seed", "5", "--days", "2", "--interval", "60"];
    cli::simulated_log(dir, "one_g.csv", "paper-1g", &args)
}

#[test]
fn report_writes_three_png_figures_and_links_them() {
    let dir = Scratch::new("discover-report-png");
    let log = simulated_log(&dir);
    let report = dir.join("report");
    accomp_ok(&["discover", s(&log), "--report", s(&report)], &[]);
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
}

#[test]
fn report_format_svg_writes_svg_figures() {
    let dir = Scratch::new("discover-report-svg");
    let log = simulated_log(&dir);
    let report = dir.join("report");
    accomp_ok(
        &[
            "discover",
            s(&log),
            "--report",
            s(&report),
            "--report-format",
            "svg",
        ],
        &[],
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
}
