//! `accomp plot` from the command line: on a simulated log, on a hand-written one, and the error
//! for a missing column.

use std::path::Path;

#[path = "common/cli.rs"]
mod cli;
#[path = "common/scratch.rs"]
mod scratch;

use cli::{accomp, accomp_ok};
use scratch::Scratch;

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn plots_a_simulated_zero_g_log_as_fig2_fig5_fig4_and_adev() {
    let dir = Scratch::new("plot-cli-sim");
    let log = dir.join("zero.csv");
    accomp_ok(&["simulate", "paper-0g", "--seed", "3", "-o", s(&log)], &[]);
    let figs = dir.join("figs");
    let out = accomp_ok(
        &["plot", s(&log), "--out-dir", s(&figs), "--format", "png"],
        &[],
    );
    let listed: Vec<String> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(str::to_owned)
        .collect();
    let want = [
        "zero_fig2_temperature.png",
        "zero_fig5_output_0g.png",
        "zero_fig4_tilt.png",
        "zero_adev.png",
    ];
    assert_eq!(listed.len(), want.len(), "{listed:?}");
    for (line, name) in listed.iter().zip(want) {
        let p = figs.join(name);
        assert_eq!(line, s(&p));
        let bytes = std::fs::read(&p).unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{name}");
    }
}

#[test]
fn one_kind_as_svg_and_a_missing_column_named_on_stderr() {
    let dir = Scratch::new("plot-cli-hand");
    let log = dir.join("small.csv");
    let header = "# input_g: 1\n# scale_factor_v_per_g: 1.3\ntime_s,output_v\n";
    cli::write_csv(&log, header, 200, |i| {
        let v = 1.3 + if i % 3 == 0 { 2e-6 } else { -1e-6 };
        format!("{i},{v}")
    });
    accomp_ok(
        &[
            "plot",
            s(&log),
            "--out-dir",
            s(&dir),
            "--format",
            "svg",
            "--kind",
            "output",
        ],
        &[],
    );
    let svg = std::fs::read_to_string(dir.join("small_fig3_output_1g.svg")).unwrap();
    assert!(svg.contains("<svg") && svg.trim_end().ends_with("</svg>"));
    assert!(svg.contains("1 g output (the log has no compensated column)"));

    let bad = accomp(&[
        "plot",
        s(&log),
        "--out-dir",
        s(&dir),
        "--kind",
        "temperature",
    ]);
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(err.contains("`temperature_c`"), "{err}");
}

#[test]
fn a_record_over_a_board_reset_is_plotted_and_the_reset_said() {
    // As `accomp record` writes one over a reset: the new boot samples 0.4 s off the old grid,
    // after the reset's event line.
    let dir = Scratch::new("plot-cli-reset");
    let log = dir.join("rec.csv");
    let mut text = String::from(
        "# recorder: accomp record 0.1.0\n# start_utc: 2026-01-01T00:00:00Z\n# input_g: 1\n\
         time_s,seq,output_v,temperature_c,status\n",
    );
    for k in 0..300u32 {
        let t = if k < 150 {
            f64::from(k)
        } else {
            f64::from(k) + 0.4
        };
        let seq = if k < 150 { k } else { k - 150 };
        text += &format!("{t},{seq},{},60,OK\n", 1.0 + 1e-6 * f64::from(k % 7));
        if k == 149 {
            text += "# event: 2026-01-01T00:02:30Z board_reset seq restarted at 0 after 149\n";
        }
    }
    std::fs::write(&log, text).unwrap();
    let figs = dir.join("figs");
    let out = accomp(&["plot", s(&log), "--out-dir", s(&figs), "--format", "svg"]);
    let err = cli::stderr(&out);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains(
            "note: 2 continuous segments (1 board_reset): new ones start at time_s = 150.4 \
             (board_reset event at 2026-01-01T00:02:30Z)"
        ) && err.contains("dashed line"),
        "{err}"
    );
    let adev = std::fs::read_to_string(figs.join("rec_adev.svg")).unwrap();
    assert!(adev.contains("pooled within 2 continuous segments (1 board_reset)"));
    let fig3 = std::fs::read_to_string(figs.join("rec_fig3_output_1g.svg")).unwrap();
    assert!(fig3.contains("board_reset (dashed)"));
}
