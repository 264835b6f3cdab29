//! The `accomp` binary as the CLI tests run it (`#[path = "common/cli.rs"] mod cli;`).
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Runs `accomp` with `args` and waits for it.
pub fn accomp(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_accomp"))
        .args(args)
        .output()
        .expect("accomp runs")
}

/// Runs `accomp` with `args` and these environment variables; fails the test, showing
/// accomp's stderr, when accomp fails.
pub fn accomp_ok(args: &[&str], env: &[(&str, &Path)]) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_accomp"));
    cmd.args(args);
    for (key, value) in env {
        cmd.env(key, value);
    }
    let out = cmd.output().expect("accomp runs");
    assert!(
        out.status.success(),
        "accomp {args:?} failed:\n{}",
        stderr(&out)
    );
    out
}

/// Asserts that stderr holds `needle`, showing stderr when it does not.
pub fn assert_stderr_contains(o: &Output, needle: &str) {
    let e = stderr(o);
    assert!(e.contains(needle), "{e}");
}

/// What it wrote to stderr, as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// `accomp simulate <preset> <extra…> -o <dir>/<file>`, asserted to succeed; the log's path.
pub fn simulated_log(dir: &Path, file: &str, preset: &str, extra: &[&str]) -> PathBuf {
    let log = dir.join(file);
    let out = log.to_str().expect("a UTF-8 path");
    let args: Vec<&str> = ["simulate", preset]
        .into_iter()
        .chain(extra.iter().copied())
        .chain(["-o", out])
        .collect();
    accomp_ok(&args, &[]);
    log
}

/// `accomp compensate --target <target>` of `input` with the table `cal` into `output`.
pub fn compensate_args<'a>(
    target: &'a str,
    cal: &'a str,
    input: &'a str,
    output: &'a str,
) -> Vec<&'a str> {
    vec![
        "compensate",
        "--target",
        target,
        "--calibration",
        cal,
        "--input",
        input,
        "--output",
        output,
    ]
}

/// Writes a hand-made CSV log to `path`: `header` (its metadata and column lines, each ending in
/// a newline), then `rows` data lines, line i being `row(i)`.
pub fn write_csv(path: &Path, header: &str, rows: usize, row: impl FnMut(usize) -> String) {
    let mut text = String::from(header);
    for line in (0..rows).map(row) {
        text.push_str(&line);
        text.push('\n');
    }
    std::fs::write(path, text).unwrap_or_else(|e| panic!("cannot write {}: {e}", path.display()));
}
