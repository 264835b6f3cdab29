//! `accomp stability`: stability, drift, OADEV and MDEV of a log's output columns (the analysis
//! is [`crate::stability`]).

use std::path::PathBuf;

use super::LogLimitArgs;
use crate::allan::TauSet;
use crate::log::Log;
use crate::stability::{analyse, Options, StabilityError};

/// `accomp stability`: stability, drift, OADEV and MDEV of a log's output columns.
#[derive(Debug, clap::Args)]
pub struct StabilityArgs {
    /// The log (CSV with `# key: value` metadata, header, one row per sample).
    pub log: PathBuf,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Column to analyse (repeatable). Default: every `*_v` / `*_g` column except input_g.
    #[arg(long = "column")]
    pub columns: Vec<String>,
    /// Averaging times: octave (m = 1, 2, 4, ...) or all (every m; short logs only).
    #[arg(long, value_enum, default_value_t = TausArg::Octave)]
    pub taus: TausArg,
    #[command(flatten)]
    pub limits: LogLimitArgs,
}

/// `--taus` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum TausArg {
    /// m = 1, 2, 4, 8, ...
    Octave,
    /// Every m.
    All,
}

/// Runs the subcommand, printing to stdout.
pub fn run(args: &StabilityArgs) -> Result<(), StabilityError> {
    args.limits.apply();
    let log = Log::read_path(&args.log).map_err(|e| e.in_file(&args.log))?;
    let opts = Options {
        columns: args.columns.clone(),
        taus: match args.taus {
            TausArg::Octave => TauSet::Octave,
            TausArg::All => TauSet::All,
        },
        allan: true,
    };
    let report = analyse(&log, &opts)?;
    if args.json {
        println!("{}", report.to_json());
    } else {
        print!("{}", report.to_table());
    }
    Ok(())
}
