//! Issue #15.5 and #15.9 through the CLI: table files are read at most one byte beyond a
//! table, `simulate` refuses logs above its stated limits (with the estimate, and an override
//! flag), and the messages name the actual problem (sizes of a padded table, the serial port,
//! a non-UTF-8 scenario file).

use std::time::{Duration, Instant};

#[path = "common/cli.rs"]
mod cli;
#[path = "common/scratch.rs"]
mod scratch;

use cli::{accomp, accomp_ok, stderr};
use scratch::Scratch;

#[test]
fn table_verify_of_an_endless_file_stops_after_one_table_and_says_why() {
    // /dev/zero used to be read until the OOM killer came (24 GB).
    let started = Instant::now();
    let o = accomp(&["table", "verify", "/dev/zero"]);
    assert!(!o.status.success());
    assert!(started.elapsed() < Duration::from_secs(20));
    let e = stderr(&o);
    assert!(e.contains("exactly 426 bytes"), "{e}");
}

#[test]
fn a_table_with_one_trailing_byte_names_both_sizes() {
    let mut bytes = accomp_host::device::paper_table().encode().to_vec();
    bytes.push(0);
    let dir = Scratch::new("cli-limits");
    let path = dir.path("padded.acal");
    std::fs::write(&path, &bytes).unwrap();
    for cmd in ["verify", "show"] {
        let o = accomp(&["table", cmd, path.to_str().unwrap()]);
        assert!(!o.status.success());
        let e = stderr(&o);
        assert!(
            e.contains("427 bytes") && e.contains("426 bytes"),
            "{cmd}: {e}"
        );
    }
}

#[test]
fn simulate_refuses_absurd_sizes_and_prints_the_estimate() {
    let dir = Scratch::new("cli-limits");
    let out = dir.path("huge.csv");
    for (interval, days) in [("1e-9", "365"), ("1e-300", "1"), ("60", "1e300")] {
        let started = Instant::now();
        let o = accomp(&[
            "simulate",
            "paper-0g",
            "--interval",
            interval,
            "--days",
            days,
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(!o.status.success(), "{interval} s over {days} d accepted");
        assert!(started.elapsed() < Duration::from_secs(30));
        let e = stderr(&o);
        assert!(
            e.contains("refused") && e.contains("rows") && e.contains("GB"),
            "{e}"
        );
        assert!(!out.exists(), "an output file was created");
    }
    // Above the soft limit, the flag lets it through (the estimate shown); an hour at 1 s
    // is far below it and runs without the flag.
    let o = accomp(&[
        "simulate",
        "paper-0g",
        "--interval",
        "0.01",
        "--days",
        "3",
        "-o",
        out.to_str().unwrap(),
    ]);
    let e = stderr(&o);
    assert!(!o.status.success() && e.contains("--allow-large"), "{e}");
    let o = accomp_ok(
        &[
            "simulate",
            "paper-0g",
            "--interval",
            "1",
            "--days",
            "0.01",
            "-o",
            out.to_str().unwrap(),
        ],
        &[],
    );
    assert!(stderr(&o).contains("rows, about"));
}

#[test]
fn a_non_utf8_scenario_file_is_reported_as_such() {
    let dir = Scratch::new("cli-limits");
    let path = dir.path("latin1.toml");
    std::fs::write(&path, b"name = \"caf\xe9\"\n").unwrap();
    let o = accomp(&[
        "simulate",
        path.to_str().unwrap(),
        "-o",
        dir.path("x.csv").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(e.contains("not UTF-8"), "{e}");
    assert!(!e.contains("no scenario file or preset"), "{e}");
}

#[test]
fn serial_errors_name_the_port() {
    let dir = Scratch::new("cli-limits");
    let table = dir.path("t.acal");
    std::fs::write(&table, accomp_host::device::paper_table().encode()).unwrap();
    let port = "/dev/accomp-no-such-port";
    let o = accomp(&[
        "load",
        "--target",
        &format!("serial:{port}"),
        table.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(e.contains(port), "{e}");
}
