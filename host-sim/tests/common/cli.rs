//! The `accomp` binary as the CLI tests run it (`#[path = "common/cli.rs"] mod cli;`).
#![allow(dead_code)]

use std::process::{Command, Output};

/// Runs `accomp` with `args` and waits for it.
pub fn accomp(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_accomp"))
        .args(args)
        .output()
        .expect("accomp runs")
}

/// What it wrote to stderr, as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}
