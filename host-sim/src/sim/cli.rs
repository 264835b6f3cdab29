//! `accomp simulate`: run a scenario (file or preset) and write its log.

use std::fs::File;
use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};

use super::scenario::{self, Scenario, PRESETS};
use super::{simulate, Options};

/// Arguments of `accomp simulate`.
#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// Scenario: a TOML file or a preset (paper-1g, paper-0g).
    #[arg(required_unless_present = "print_preset")]
    pub scenario: Option<String>,
    /// Seed of every random draw (same seed, same scenario → byte-identical log).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output log (CSV in the accomp log format).
    #[arg(short, long, required_unless_present = "print_preset")]
    pub output: Option<PathBuf>,
    /// Override the sample interval, seconds (e.g. 1 for 1 Hz).
    #[arg(long)]
    pub interval: Option<f64>,
    /// Override the duration, days.
    #[arg(long)]
    pub days: Option<f64>,
    /// Add the raw ADC code columns accel_code, rtd_code, tilt_code.
    #[arg(long)]
    pub codes: bool,
    /// Print a preset as a complete scenario TOML and exit.
    #[arg(long, value_name = "PRESET", value_parser = PRESETS)]
    pub print_preset: Option<String>,
}

/// Runs the subcommand.
pub fn run(args: &SimulateArgs) -> anyhow::Result<()> {
    if let Some(name) = &args.print_preset {
        let s = Scenario::preset(name).context("unknown preset")?;
        print!("{}", s.to_toml());
        return Ok(());
    }
    let (Some(arg), Some(output)) = (&args.scenario, &args.output) else {
        anyhow::bail!("a scenario and -o OUTPUT are required");
    };
    let mut sc = scenario::load(arg)?;
    if let Some(dt) = args.interval {
        sc.run.interval_s = dt;
    }
    if let Some(days) = args.days {
        sc.run.duration_s = days * 86_400.0;
    }
    sc.validate()?;
    let file =
        File::create(output).with_context(|| format!("cannot create {}", output.display()))?;
    let bar = ProgressBar::new(sc.samples());
    bar.set_style(
        ProgressStyle::with_template("simulate {bar:40} {pos}/{len} rows, {eta} left")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let started = std::time::Instant::now();
    let (summary, _) = simulate(
        &sc,
        args.seed,
        &Options { codes: args.codes },
        file,
        &mut |done, _| bar.set_position(done),
    )?;
    bar.finish_and_clear();
    eprintln!(
        "simulated {} ({} rows, {} s interval, seed {}) in {:.1} s → {}",
        sc.name,
        summary.rows,
        sc.run.interval_s,
        args.seed,
        started.elapsed().as_secs_f64(),
        output.display()
    );
    Ok(())
}
