//! A short `accomp demo` end to end: the firmware ELF that `cargo xtask test` built (via
//! ACCOMP_FIRMWARE_ELF) in QEMU, 288 samples of each experiment.
//!
//! No skipping: a missing ELF, qemu-system-arm or Table 1 fails the test with the reason.

use std::path::{Path, PathBuf};
use std::process::Command;

use accomp_host::log::Log;

fn table1() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../data/jn06_a12124_coefficients_vs_temperature.csv")
}

#[path = "common/scratch.rs"]
mod scratch;

fn out_dir() -> scratch::Scratch {
    scratch::Scratch::new("demo-smoke")
}

fn num(v: &serde_json::Value, key: &str) -> f64 {
    v[key]
        .as_f64()
        .unwrap_or_else(|| panic!("{key} is not a number in {v}"))
}

fn figure(e: &serde_json::Value, column: &str) -> f64 {
    let f = e["figures"]
        .as_array()
        .and_then(|a| a.iter().find(|f| f["column"] == column))
        .unwrap_or_else(|| panic!("no figure for {column} in {}", e["name"]));
    num(f, "std_g")
}

#[test]
fn a_short_demo_reports_both_experiments_and_compensation_improves_the_1g_stability() {
    let out = out_dir();
    let run = Command::new(env!("CARGO_BIN_EXE_accomp"))
        .arg("demo")
        .arg("--table1")
        .arg(table1())
        .arg("--out-dir")
        .arg(&out)
        .args(["--days-1g", "2", "--days-0g", "0.1", "--seed", "3"])
        .output()
        .expect("the accomp binary runs");
    let stdout = String::from_utf8_lossy(&run.stdout);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "demo failed:\n{stdout}\n{stderr}");

    // The printed report: both experiments, the rows, the paper's figures, where things went.
    for needle in [
        "paper-1g",
        "paper-0g",
        "before compensation",
        "after: firmware exact a_i",
        "after: firmware linearized",
        "floor: true models",
        "1.43e-5 g",
        "6.60e-6 g",
        "1.60 µg",
        "1.30 µg",
        "uploaded and read back",
        "log: ",
        "figures: ",
        "report: ",
    ] {
        assert!(
            stdout.contains(needle),
            "{needle:?} missing from:\n{stdout}"
        );
    }

    let json: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("report.json")).expect("report.json written"),
    )
    .expect("report.json parses");
    let exps = json["experiments"].as_array().expect("experiments");
    let names: Vec<&str> = exps.iter().filter_map(|e| e["name"].as_str()).collect();
    assert_eq!(names, ["paper-1g", "paper-0g"]);
    for e in exps {
        // 2 days at 600 s and 0.1 day at 30 s: 288 samples each, every one returned.
        assert_eq!(e["samples"], 288, "{}", e["name"]);
        assert_eq!(e["host_mismatches"], 0, "firmware differs from the core");
        for f in e["figures"].as_array().expect("figures") {
            let s = num(f, "std_g");
            assert!(s.is_finite() && s > 0.0, "{f}");
        }
        assert_eq!(
            e["plots"].as_array().map(Vec::len),
            Some(4),
            "{}",
            e["name"]
        );

        // The recorded log is in simulated seconds; the firmware's own clock ran far faster.
        let log = Log::read_path(e["log"].as_str().expect("log path")).expect("log reads back");
        let t = log.time_s();
        let interval = num(e, "interval_s");
        assert_eq!(t.len(), 288);
        assert!(
            (t[287] - t[0] - 287.0 * interval).abs() < 1e-6,
            "time_s span"
        );
        let fw = log.column("fw_time_s").expect("fw_time_s");
        assert!(
            fw[287] - fw[0] < (t[287] - t[0]) / 100.0,
            "firmware time is not compressed"
        );
        // The same form as `accomp record` writes: 0x + 8 hex digits.
        let id = log.meta("calibration_id").unwrap_or_default();
        assert!(
            id.len() == 10 && id.starts_with("0x") && u32::from_str_radix(&id[2..], 16).is_ok(),
            "{id}"
        );
    }

    // The claim of the demo: compensation removes most of the thermal scatter at 1 g.
    let g1 = &exps[0];
    let before = figure(g1, "output_v");
    let after = figure(g1, "a_i_exact_g");
    let floor = figure(g1, "floor_a_i_g");
    assert!(
        after < 0.5 * before,
        "1 g: after {after:e} g not below half of before {before:e} g"
    );
    assert!(
        after < 3.0 * floor,
        "1 g: after {after:e} g far above the floor {floor:e} g"
    );
}
