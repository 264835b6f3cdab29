//! `accomp tumble`: solve dividing-head tumble logs (the analysis is [`crate::tumble`]).

use std::path::PathBuf;

use crate::tumble::{self, RotationAxis, TumbleOptions};
use anyhow::Context;

/// `--rotation-axis` (also of `accomp simulate-tumble`).
pub(crate) fn parse_axis(s: &str) -> Result<RotationAxis, String> {
    RotationAxis::parse(s).ok_or_else(|| format!("expected output or pendulum, got {s:?}"))
}

/// Solve dividing-head tumble logs for K0, K1, K2, δ (and K3) per test (docs/tumble.md).
#[derive(clap::Args, Debug)]
pub struct TumbleArgs {
    /// Tumble log(s); several logs are combined into one table (e.g. δp and δo mountings).
    #[arg(required = true)]
    pub logs: Vec<PathBuf>,
    /// Print the full report as JSON.
    #[arg(long)]
    pub json: bool,
    /// Write the coefficient table (Table 1 CSV format) here.
    #[arg(short = 'o', long = "output")]
    pub output: Option<PathBuf>,
    /// Append standard-error columns to the coefficient table.
    #[arg(long)]
    pub with_se: bool,
    /// Local gravity in standard g (overrides the `local_gravity_m_s2` metadata).
    #[arg(long)]
    pub gravity_g: Option<f64>,
    /// Dividing-head index error, arcsec 1σ (default: metadata, else 0.2).
    #[arg(long)]
    pub index_error_arcsec: Option<f64>,
    /// Axis along the head's rotation axis: output or pendulum (overrides the metadata).
    #[arg(long, value_parser = parse_axis)]
    pub rotation_axis: Option<RotationAxis>,
    /// Gap in time_s that starts a new test when the log has no `test` column (s).
    #[arg(long)]
    pub gap_s: Option<f64>,
    /// Read a log above the reader's limits (20 million data lines, 64 MiB).
    #[arg(long)]
    pub allow_large: bool,
}

/// Runs `accomp tumble`.
pub fn run(args: TumbleArgs) -> anyhow::Result<()> {
    crate::log::reader::set_allow_large(args.allow_large);
    crate::outputs::check_optional_file(args.output.as_deref())?;
    let TumbleArgs {
        logs,
        json,
        output,
        with_se,
        gravity_g,
        index_error_arcsec,
        rotation_axis,
        gap_s,
        allow_large: _,
    } = args;
    let mut parsed = Vec::new();
    for path in &logs {
        let text =
            crate::log::reader::read_text_limited(path, crate::log::reader::MAX_SMALL_TEXT_BYTES)
                .with_context(|| format!("reading {}", path.display()))?;
        parsed.push(tumble::parse_log(&text).with_context(|| format!("{}", path.display()))?);
    }
    let opts = TumbleOptions {
        gravity_g,
        index_error_arcsec,
        rotation_axis,
        gap_s,
    };
    let refs: Vec<&tumble::TumbleLog> = parsed.iter().collect();
    let report = tumble::analyse(&refs, &opts)?;
    if json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", tumble::render_text(&report));
    }
    if let Some(path) = output {
        crate::outputs::write_file(&path, tumble::table_csv(&report, with_se)?.as_bytes())?;
    }

    Ok(())
}
