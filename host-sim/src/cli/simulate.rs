//! `accomp simulate`: run a scenario (file or preset) and write its log (the simulator is
//! [`crate::sim`]).

use std::fmt::Write as _;
use std::fs::File;
use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};

use crate::sim::scenario::{self, Scenario, PRESETS};
use crate::sim::twin::MemberModel;
use crate::sim::{simulate, Options};

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
    /// Allow a log above the size limits (MAX_ROWS rows, MAX_LOG_BYTES bytes).
    #[arg(long)]
    pub allow_large: bool,
}

/// Rows a simulation writes without `--allow-large`: 20 million (231 days at 1 s).
pub const MAX_ROWS: u64 = 20_000_000;
/// Estimated log size written without `--allow-large`: 4 GiB.
pub const MAX_LOG_BYTES: u64 = 4 << 30;
/// Rows no flag allows: 1e12 rows is beyond any disk (≈ 100 TB).
pub const HARD_MAX_ROWS: f64 = 1e12;

/// Bytes per row of this scenario's log, measured by simulating a few rows into memory.
fn bytes_per_row(sc: &Scenario, seed: u64, codes: bool) -> anyhow::Result<f64> {
    let size = |n: f64| -> anyhow::Result<f64> {
        let mut small = sc.clone();
        small.run.duration_s = n * small.run.interval_s;
        let mut buf = Vec::new();
        simulate(&small, seed, &Options { codes }, &mut buf, &mut |_, _| {})?;
        Ok(buf.len() as f64)
    };
    Ok((size(40.0)? - size(20.0)?) / 20.0)
}

/// Refuses a log above the limits (unless allowed), printing the estimate either way.
fn check_size(sc: &Scenario, seed: u64, codes: bool, allow_large: bool) -> anyhow::Result<()> {
    // In f64: an interval of 1e-300 s or 1e300 days overflows any integer count.
    let rows = (sc.run.duration_s / sc.run.interval_s).floor();
    let bytes = rows * bytes_per_row(sc, seed, codes)?;
    let estimate = format!(
        "{rows:.3e} rows, about {:.3} GB ({} s interval over {:.4} days)",
        bytes / 1e9,
        sc.run.interval_s,
        sc.run.duration_s / 86_400.0
    );
    if rows.is_nan() || rows > HARD_MAX_ROWS {
        anyhow::bail!(
            "refused: the log would be {estimate}; no flag allows more than {HARD_MAX_ROWS:e} rows"
        );
    }
    if (rows > MAX_ROWS as f64 || bytes > MAX_LOG_BYTES as f64) && !allow_large {
        anyhow::bail!(
            "refused: the log would be {estimate}, above the limit of {MAX_ROWS} rows / {} GiB; \
             pass --allow-large to write it anyway",
            MAX_LOG_BYTES >> 30
        );
    }
    eprintln!("simulate: {estimate}");
    Ok(())
}

/// Member `seed` of a written twin (the scenario's `[twin]` section and its driver file) at the
/// record's instants, written as CSV `t_s,<output>` with numbers in their shortest round-trip
/// form (docs/simulator.md, "The written twin").
fn run_twin_member(sc: &Scenario, path: &Path, seed: u64, output: &Path) -> anyhow::Result<()> {
    let started = std::time::Instant::now();
    let model = MemberModel::load(sc, path)?;
    let y = model.member(seed)?;
    let spec = sc.twin.as_ref().context("not a written twin")?;
    let mut text = String::with_capacity(40 * y.len());
    let _ = writeln!(
        text,
        "# accomp simulate: member {seed} of the written twin {:?} ({}, {})",
        sc.name, spec.output_name, spec.output_unit
    );
    let _ = writeln!(text, "t_s,{}", spec.output_name);
    for (t, v) in model.record.t_s.iter().zip(&y) {
        let _ = writeln!(text, "{t:?},{v:?}");
    }
    crate::outputs::write_file(output, text.as_bytes())
        .with_context(|| format!("writing {}", output.display()))?;
    eprintln!(
        "simulated member {seed} of the twin {} ({} points) in {:.1} s → {}",
        sc.name,
        y.len(),
        started.elapsed().as_secs_f64(),
        output.display()
    );
    Ok(())
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
    crate::outputs::check_file(output)?;
    let mut sc = scenario::load(arg)?;
    if sc.twin.is_some() {
        if args.interval.is_some() || args.days.is_some() || args.codes {
            anyhow::bail!(
                "{arg} is a written twin (it has a [twin] section): a member is computed at the \
                 record's own instants, so --interval, --days and --codes do not apply"
            );
        }
        return run_twin_member(&sc, Path::new(arg), args.seed, output);
    }
    if let Some(dt) = args.interval {
        sc.run.interval_s = dt;
    }
    if let Some(days) = args.days {
        sc.run.duration_s = days * 86_400.0;
    }
    // An absurd size is said as such (with the estimate) even when it also puts the run's end
    // outside the calendar the scenario checks.
    if let Err(e) = sc.validate() {
        check_size(&sc, args.seed, args.codes, args.allow_large)?;
        return Err(e.into());
    }
    check_size(&sc, args.seed, args.codes, args.allow_large)?;
    let file =
        File::create(output).with_context(|| format!("cannot create {}", output.display()))?;
    let bar = ProgressBar::new(sc.samples());
    bar.set_style(
        ProgressStyle::with_template("simulate {bar:40} {pos}/{len} rows, {eta} left")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    // Off a terminal the bar is not drawn: a line a minute instead.
    let lines = crate::numerics::parallel::ProgressLines::new(
        format!("simulate {}", sc.name),
        sc.samples() as usize,
        "rows",
    );
    let started = std::time::Instant::now();
    let (summary, file) = simulate(
        &sc,
        args.seed,
        &Options { codes: args.codes },
        file,
        &mut |done, _| {
            bar.set_position(done);
            lines.set(done as usize);
        },
    )
    .with_context(|| format!("writing {}", output.display()))?;
    // A full disk can refuse the data only now (delayed allocation): said, never exit 0.
    file.sync_all()
        .with_context(|| format!("writing {}", output.display()))?;
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
