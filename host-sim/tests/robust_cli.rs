//! What a careless or unlucky user gives the commands: endless or huge inputs (refused within
//! seconds under a 1 GB address-space limit, the limit named), outputs that cannot be written
//! (refused before any work, by path; a full disk an error, never exit 0), parameters out of
//! their ranges (refused with the field or flag and the range), and the minor lies (a constant
//! log's standard deviation, a blank Allan plot, UTF-16 text, a reversed record, ±inf results).

use std::os::unix::process::CommandExt as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

#[path = "common/cli.rs"]
mod cli;
#[path = "common/scratch.rs"]
mod scratch;
use cli::{accomp, accomp_ok, stderr};
use scratch::Scratch;

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Runs `accomp` with its address space limited to 1 GiB (what it maps, not only what it
/// touches: a reader that slurps `/dev/zero` fails on its first big allocation).
fn accomp_in_1_gib(args: &[&str]) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_accomp"));
    c.args(args).env("RUST_BACKTRACE", "0");
    // SAFETY: setrlimit is async-signal-safe and touches only the child.
    unsafe {
        c.pre_exec(|| {
            let lim = libc::rlimit {
                rlim_cur: 1 << 30,
                rlim_max: 1 << 30,
            };
            if libc::setrlimit(libc::RLIMIT_AS, &lim) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    c.output().expect("accomp runs")
}

fn simulated_log(dir: &Path) -> String {
    let log = cli::simulated_log(
        dir,
        "sim.csv",
        "paper-0g",
        &["--days", "2", "--interval", "60"],
    );
    log.to_str().unwrap().to_owned()
}

/// A file of `len` zero bytes, sparse (no disk used).
fn sparse_file(dir: &Scratch, name: &str, len: u64) -> PathBuf {
    let p = dir.path(name);
    std::fs::File::create(&p).unwrap().set_len(len).unwrap();
    p
}

fn table_file(dir: &Path) -> String {
    let p = dir.join("t.acal");
    std::fs::write(&p, accomp_host::device::paper_table().encode()).unwrap();
    p.to_str().unwrap().to_owned()
}

#[test]
fn dev_zero_and_a_10_gb_file_are_refused_within_seconds_under_1_gib_naming_the_limit() {
    let dir = Scratch::new("robust-huge");
    // 10 GB of zero bytes, sparse: no disk used, a 10 GB file all the same.
    let huge = sparse_file(&dir, "huge.csv", 10_000_000_000);
    let huge_tsf = sparse_file(&dir, "huge.tsf", 10_000_000_000);
    let cal = table_file(&dir);
    let out = dir.path("out");
    for input in [
        "/dev/zero",
        huge.to_str().unwrap(),
        huge_tsf.to_str().unwrap(),
    ] {
        let commands: Vec<Vec<&str>> = vec![
            vec!["stability", input],
            vec!["plot", input, "--out-dir", out.to_str().unwrap()],
            vec!["discover", input],
            vec!["fit", input],
            vec!["tumble", input],
            cli::compensate_args("host", &cal, input, "/dev/null"),
        ];
        for args in commands {
            let started = Instant::now();
            let o = accomp_in_1_gib(&args);
            let e = stderr(&o);
            // Exit 1 with a message: not an abort (134) or a kill by the memory limit.
            assert_eq!(o.status.code(), Some(1), "{args:?}: {:?}\n{e}", o.status);
            assert!(
                started.elapsed() < Duration::from_secs(30),
                "{args:?} took {:?}",
                started.elapsed()
            );
            assert!(
                e.contains("1048576 bytes, the limit of one line")
                    || (e.contains("10000000000 bytes") && e.contains("above the limit of")),
                "{args:?}: the limit is not named: {e}"
            );
        }
    }
}

#[test]
fn outputs_are_checked_before_any_work_and_named() {
    let dir = Scratch::new("robust-outputs");
    let log = simulated_log(&dir);
    let a_dir = dir.path("a-dir");
    std::fs::create_dir_all(&a_dir).unwrap();
    let a_file = dir.path("a-file");
    std::fs::write(&a_file, "x").unwrap();
    let (d, f) = (a_dir.to_str().unwrap(), a_file.to_str().unwrap());
    let cal = table_file(&dir);
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec!["discover", &log, "--simulate", "--write-scenario", d],
            "is a directory",
        ),
        (vec!["discover", &log, "--report", f], "is a file"),
        (
            vec!["discover", &log, "--simulate", "--report", f],
            "is a file",
        ),
        (
            vec!["simulate", "paper-0g", "--days", "1", "-o", d],
            "is a directory",
        ),
        (
            vec![
                "fit",
                "../data/jn06_a12124_coefficients_vs_temperature.csv",
                "-o",
                d,
            ],
            "is a directory",
        ),
        (vec!["tumble", &log, "-o", d], "is a directory"),
        (vec!["simulate-tumble", "-o", d], "is a directory"),
        (vec!["plot", &log, "--out-dir", f], "is a file"),
        (
            cli::compensate_args("host", &cal, &log, d),
            "is a directory",
        ),
        (
            vec!["table", "get", "--target", "qemu", "-o", d],
            "is a directory",
        ),
        (
            vec![
                "simulate",
                "paper-0g",
                "--days",
                "1",
                "-o",
                "/nonexistent-folder/x.csv",
            ],
            "does not exist",
        ),
    ];
    for (args, said) in cases {
        let started = Instant::now();
        let o = Command::new(env!("CARGO_BIN_EXE_accomp"))
            .args(&args)
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .output()
            .unwrap();
        let e = stderr(&o);
        assert!(!o.status.success(), "{args:?} succeeded");
        assert!(
            e.contains(said) && e.contains("nothing computed"),
            "{args:?}: {e}"
        );
        let named = args.last().unwrap();
        assert!(e.contains(named), "{args:?}: the path is not named: {e}");
        // Refused before the work: no twin, no simulation ran (each takes seconds here).
        assert!(
            !e.contains("twin ensemble") && !e.contains("simulated "),
            "{args:?}: {e}"
        );
        let _ = started;
    }
    // An immutable folder (root writes through permission bits, not through this).
    let frozen = dir.path("frozen");
    std::fs::create_dir_all(&frozen).unwrap();
    let target = frozen.join("x.csv");
    assert!(
        Command::new("chattr")
            .arg("+i")
            .arg(&frozen)
            .status()
            .is_ok_and(|s| s.success()),
        "chattr +i is needed for this test"
    );
    let o = accomp(&[
        "simulate",
        "paper-0g",
        "--days",
        "1",
        "-o",
        target.to_str().unwrap(),
    ]);
    let _ = Command::new("chattr").arg("-i").arg(&frozen).status();
    let e = stderr(&o);
    assert!(!o.status.success());
    assert!(
        e.contains("cannot be written") && e.contains(frozen.to_str().unwrap()),
        "{e}"
    );
    assert!(!target.exists());
}

#[test]
fn a_full_disk_is_an_error_naming_the_output_never_exit_0() {
    let mnt = Scratch::tmpfs_64k("robust-full");
    // 2 days at 60 s is about 0.9 MB of log: the 64 KiB disk fills during the run.
    let out = mnt.join("sim.csv");
    let o = accomp(&[
        "simulate",
        "paper-0g",
        "--days",
        "2",
        "--interval",
        "60",
        "-o",
        out.to_str().unwrap(),
    ]);
    // And a table onto the now full disk: a short write said, not a 0-byte table.
    let cal = mnt.join("t.acal");
    let fit = Command::new(env!("CARGO_BIN_EXE_accomp"))
        .args([
            "fit",
            "../data/jn06_a12124_coefficients_vs_temperature.csv",
            "-o",
        ])
        .arg(&cal)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    mnt.unmount();
    let e = stderr(&o);
    assert!(
        !o.status.success(),
        "simulate onto a full disk exited 0: {e}"
    );
    assert!(
        e.contains(out.to_str().unwrap()) && e.contains("No space left"),
        "{e}"
    );
    let e = stderr(&fit);
    assert!(!fit.status.success(), "fit onto a full disk exited 0: {e}");
    assert!(e.contains(cal.to_str().unwrap()), "{e}");
}

#[test]
fn parameters_out_of_range_are_refused_with_the_name_and_the_range() {
    let dir = Scratch::new("robust-params");
    let log = simulated_log(&dir);
    for n in ["0", "1", "1001", "100000"] {
        let o = accomp(&["discover", &log, "--simulate", "--ensemble", n]);
        assert!(!o.status.success(), "--ensemble {n} accepted");
        let e = stderr(&o);
        assert!(
            e.contains("--ensemble") && e.contains("2..=1000"),
            "{n}: {e}"
        );
    }
    // Off a terminal, progress lines (every member here, every minute by default).
    let o = Command::new(env!("CARGO_BIN_EXE_accomp"))
        .args(["discover", &log, "--simulate", "--ensemble", "3"])
        .env("ACCOMP_PROGRESS_EVERY_S", "0")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(e.contains("twin ensemble (base): 3/3 members"), "{e}");
    assert!(e.contains("twin ensemble (extended): 3/3 members"), "{e}");
    let o = Command::new(env!("CARGO_BIN_EXE_accomp"))
        .args([
            "simulate",
            "paper-0g",
            "--days",
            "1",
            "--interval",
            "1",
            "-o",
        ])
        .arg(dir.path("p.csv"))
        .env("ACCOMP_PROGRESS_EVERY_S", "0")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    cli::assert_stderr_contains(&o, "simulate paper-0g: 16384/86400 rows");
    // Scenario fields.
    let preset = stdout(&accomp(&["simulate", "--print-preset", "paper-1g"]));
    let out = dir.path("s.csv");
    for (from, to, said) in [
        (
            "mean_c = 20.0",
            "mean_c = 1e30",
            "room.mean_c = 1000000000000000000000000000000: outside its physical range -50 ..= 60",
        ),
        (
            "setpoint_c = 60.0",
            "setpoint_c = nan",
            "thermostat.setpoint_c = NaN: must be a finite number",
        ),
        (
            "2016-03-01T00:00:00Z",
            "9999-12-31T00:00:00Z",
            "year 9999 outside 1900..=2199",
        ),
    ] {
        let sc = dir.path("s.toml");
        assert!(preset.contains(from), "{from}");
        std::fs::write(&sc, preset.replace(from, to)).unwrap();
        let o = accomp(&[
            "simulate",
            sc.to_str().unwrap(),
            "--days",
            "1",
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(!o.status.success(), "{to} accepted");
        assert!(stderr(&o).contains(said), "{to}: {}", stderr(&o));
    }
    // ±1e308 in a log: the statistics overflow; refused by column, no `inf` printed.
    let big = dir.path("big.csv");
    cli::write_csv(&big, "time_s,output_v\n", 200, |i| {
        let v = if i % 2 == 0 { "1e308" } else { "-1e308" };
        format!("{},{v}", i * 60)
    });
    let o = accomp(&["stability", big.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(!stdout(&o).contains("inf"), "{}", stdout(&o));
    let e = stderr(&o);
    assert!(e.contains("\"output_v\"") && e.contains("overflow"), "{e}");
    let o = accomp(&["discover", big.to_str().unwrap()]);
    assert!(!o.status.success(), "discover printed {}", stdout(&o));
    cli::assert_stderr_contains(&o, "values up to 1e308 overflow the fit");
    let plots = dir.path("p");
    let o = accomp(&[
        "plot",
        big.to_str().unwrap(),
        "--out-dir",
        plots.to_str().unwrap(),
    ]);
    cli::assert_stderr_contains(&o, "is not finite (values so large");
}

#[test]
fn a_constant_log_has_std_0_and_no_blank_allan_plot() {
    let dir = Scratch::new("robust-constant");
    let log = dir.path("c.csv");
    cli::write_csv(&log, "time_s,output_v,temperature_c\n", 2000, |i| {
        format!("{},1.2345678,60", i * 60)
    });
    let o = accomp(&["stability", log.to_str().unwrap()]);
    assert!(o.status.success());
    assert!(
        stdout(&o).contains("std (n-1)     0.000000e0"),
        "{}",
        stdout(&o)
    );
    let plots = dir.path("plots");
    let o = accomp_ok(
        &[
            "plot",
            log.to_str().unwrap(),
            "--out-dir",
            plots.to_str().unwrap(),
        ],
        &[],
    );
    cli::assert_stderr_contains(&o, "skipped the Allan deviation plot: the Allan deviation of `output_v` is 0 (a constant column) at every τ");
    assert!(!plots.join("c_adev.png").exists());
}

#[test]
fn utf16_text_and_a_reversed_tsf_are_named_for_what_they_are() {
    let dir = Scratch::new("robust-encodings");
    let text = "time_s,output_v\n0,1\n60,1.1\n120,1.2\n";
    let le: Vec<u8> = text.encode_utf16().flat_map(|u| u.to_le_bytes()).collect();
    let be: Vec<u8> = text.encode_utf16().flat_map(|u| u.to_be_bytes()).collect();
    for (name, bytes, endian) in [
        ("le.csv", le, "little-endian"),
        ("be.csv", be, "big-endian"),
    ] {
        let p = dir.path(name);
        std::fs::write(&p, bytes).unwrap();
        let o = accomp(&["stability", p.to_str().unwrap()]);
        assert!(!o.status.success());
        cli::assert_stderr_contains(&o, &format!("UTF-16 text ({endian})"));
    }
    let tsf = dir.path("rev.tsf");
    let mut rows = String::new();
    for i in (0..500).rev() {
        let s = i * 60;
        rows += &format!(
            "2020 01 {:02} {:02} {:02} 00 {:.4} 1013.2\n",
            1 + s / 86_400,
            (s / 3600) % 24,
            (s / 60) % 60,
            1000.0 + i as f64 * 0.001
        );
    }
    std::fs::write(&tsf, rows).unwrap();
    let o = accomp(&["discover", tsf.to_str().unwrap()]);
    assert!(!o.status.success());
    cli::assert_stderr_contains(&o, "the file looks reversed");
}

#[test]
fn a_ten_year_gap_in_a_record_does_not_stall_discover() {
    // Two days at 60 s, the second ten years after the first: the periodogram's frequency grid
    // followed the ten-year span (1e7 frequencies × 2880 points, over 5 minutes); it follows
    // the time the data cover.
    let dir = Scratch::new("robust-gap");
    let log = simulated_log(&dir);
    let text = std::fs::read_to_string(&log).unwrap();
    let mut rows = 0;
    let shifted: Vec<String> = text
        .lines()
        .map(|l| {
            if !l.starts_with(|c: char| c.is_ascii_digit()) {
                return l.to_owned();
            }
            rows += 1;
            if rows <= 1440 {
                return l.to_owned();
            }
            let (t, rest) = l.split_once(',').unwrap();
            let t: f64 = t.parse().unwrap();
            format!("{},{rest}", t + 10.0 * 365.25 * 86_400.0)
        })
        .collect();
    let gap = dir.path("gap.csv");
    std::fs::write(&gap, shifted.join("\n") + "\n").unwrap();
    let started = Instant::now();
    let o = accomp_ok(&["discover", gap.to_str().unwrap(), "--json"], &[]);
    assert!(
        stdout(&o).contains("gap"),
        "the gap is not announced: {}",
        stdout(&o)
    );
    // A hang guard, not a benchmark (the figure is in the report of the change).
    assert!(
        started.elapsed() < Duration::from_secs(120),
        "{:?}",
        started.elapsed()
    );
}

#[test]
fn fit_compensate_and_tumble_take_allow_large_and_their_limits_name_it() {
    let dir = Scratch::new("robust-allow-large");
    // 5 GiB of zero bytes, sparse: above the byte limit of every reader (64 MiB for tables and
    // tumble logs, 4 GiB for sample files) by its size alone.
    let huge = sparse_file(&dir, "huge.csv", 5 << 30);
    let h = huge.to_str().unwrap();
    let cal = table_file(&dir);
    let commands: Vec<Vec<&str>> = vec![
        vec!["fit", h],
        vec!["tumble", h],
        cli::compensate_args("host", &cal, h, "/dev/null"),
    ];
    for args in commands {
        let o = accomp(&args);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {e}");
        assert!(
            e.contains("5368709120 bytes") && e.contains("refused (--allow-large lifts it)"),
            "{args:?}: {e}"
        );
        // With the flag the size is no refusal: the zeros are, as a line longer than any.
        let mut large = args.clone();
        large.push("--allow-large");
        let o = accomp(&large);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{large:?}: {e}");
        assert!(
            e.contains("1048576 bytes, the limit of one line") && !e.contains("5368709120"),
            "{large:?}: {e}"
        );
    }
}

#[test]
fn infinities_are_refused_by_every_reader_with_file_line_and_column() {
    let dir = Scratch::new("robust-inf");
    let cal = table_file(&dir);
    let write = |name: &str, text: &str| {
        let p = dir.path(name);
        std::fs::write(&p, text).unwrap();
        p.to_str().unwrap().to_owned()
    };
    let mut log = String::from("time_s,output_v,temperature_c,tilt_arcsec\n");
    for i in 0..50 {
        let v = if i == 20 { "-inf" } else { "1.25" };
        log += &format!("{},{v},60,0.1\n", i * 60);
    }
    let log = write("log.csv", &log);
    // 1e400 is beyond an f64 and parses as +inf: the same refusal.
    let huge = write(
        "huge.csv",
        "time_s,output_v,temperature_c\n0,1.25,60\n60,1e400,60\n120,1.25,60\n",
    );
    let table = write(
        "table1.csv",
        "temperature_c,K0_g,K1_v_per_g\n20,1e-4,1.3\n40,inf,1.3\n60,1e-4,1.3\n",
    );
    let tumble = write(
        "tumble.csv",
        "angle_deg,output_v\n0,1.3\n90,Infinity\n180,-1.3\n270,0\n",
    );
    let no_time = write(
        "no_time.csv",
        "time_s,output_v,temperature_c\n0,1.25,60\nNaN,1.25,60\n",
    );
    let plots = dir.path("plots");
    let own = |v: &[&str]| v.iter().map(|s| (*s).to_owned()).collect::<Vec<_>>();
    let out = dir.path("out.csv");
    let compensate = |input: &str| {
        own(&cli::compensate_args(
            "host",
            &cal,
            input,
            out.to_str().unwrap(),
        ))
    };
    let cases: Vec<(Vec<String>, &str, &str, &str)> = vec![
        (own(&["stability", &log]), &log, "line 22", "output_v"),
        (
            own(&["plot", &log, "--out-dir", plots.to_str().unwrap()]),
            &log,
            "line 22",
            "output_v",
        ),
        (own(&["discover", &log]), &log, "line 22", "output_v"),
        (own(&["stability", &huge]), &huge, "line 3", "output_v"),
        (own(&["fit", &table]), &table, "line 3", "K0_g"),
        (own(&["tumble", &tumble]), &tumble, "line 3", "output_v"),
        (compensate(&log), &log, "line 22", "output_v"),
        (compensate(&huge), &huge, "line 3", "output_v"),
        // A time stamp is required: NaN is refused there, not taken as a missing reading.
        (compensate(&no_time), &no_time, "line 3", "time_s"),
    ];
    for (args, file, line, column) in cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = accomp(&args);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {e}");
        assert!(
            e.contains(file) && e.contains(line) && e.contains(column),
            "{args:?}: file, line or column not named: {e}"
        );
        assert!(!stdout(&o).contains("inf"), "{args:?}: {}", stdout(&o));
    }
    assert!(
        !dir.path("out.csv").exists() || std::fs::read(dir.path("out.csv")).unwrap().is_empty()
    );
}

#[test]
fn compensate_prints_progress_lines_when_not_on_a_terminal() {
    let dir = Scratch::new("robust-compensate-progress");
    let cal = table_file(&dir);
    let input = dir.path("in.csv");
    cli::write_csv(&input, "time_s,output_v,temperature_c\n", 200, |i| {
        format!("{i},1.3,60")
    });
    let o = Command::new(env!("CARGO_BIN_EXE_accomp"))
        .args([
            "compensate",
            "--target",
            "host",
            "--calibration",
            &cal,
            "--input",
        ])
        .arg(&input)
        .arg("--output")
        .arg(dir.path("out.csv"))
        .env("ACCOMP_PROGRESS_EVERY_S", "0")
        .output()
        .unwrap();
    let e = stderr(&o);
    assert!(o.status.success(), "{e}");
    assert!(
        e.contains(&format!("compensate {}: 200/200 samples", input.display())),
        "{e}"
    );
}
