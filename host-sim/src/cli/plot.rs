//! `accomp plot`: figures like the paper's Figs. 2–5 and an Allan deviation plot (drawing is
//! [`crate::plot`]).

use std::path::PathBuf;

use super::values::{ImageFormat, PlotKind};
use super::LogLimitArgs;
use crate::log::Log;
use crate::plot::{plot_log, Format, Kind, PlotOptions, DEFAULT_RAW};

/// `accomp plot`: figures like the paper's Figs. 2–5 and an Allan deviation plot.
#[derive(Debug, Clone, clap::Args)]
pub struct PlotArgs {
    /// The log (CSV with `# key: value` metadata, header, one row per sample).
    pub log: PathBuf,
    /// Directory the figures are written to (created if needed).
    #[arg(long, default_value = "plots")]
    pub out_dir: PathBuf,
    /// Image format.
    #[arg(long, value_enum, default_value_t = ImageFormat(Format::Png))]
    pub format: ImageFormat,
    /// Which figure(s).
    #[arg(long, value_enum, default_value_t = PlotKind(Kind::All))]
    pub kind: PlotKind,
    /// Uncompensated output column.
    #[arg(long, default_value = DEFAULT_RAW)]
    pub raw: String,
    /// Compensated output column (repeatable). Default: those of a_i_exact_g,
    /// output_linearized_v, output_compensated_g that the log has.
    #[arg(long = "compensated")]
    pub compensated: Vec<String>,
    #[command(flatten)]
    pub limits: LogLimitArgs,
}

/// Runs the subcommand: reads the log, writes the figures, prints their paths.
pub fn run(args: &PlotArgs) -> anyhow::Result<()> {
    args.limits.apply();
    crate::outputs::check_dir(&args.out_dir)?;
    let log = Log::read_path(&args.log).map_err(|e| e.in_file(&args.log))?;
    let stem = args
        .log
        .file_stem()
        .map_or_else(|| "log".to_owned(), |s| s.to_string_lossy().into_owned());
    let opts = PlotOptions {
        out_dir: args.out_dir.clone(),
        stem,
        format: args.format.0,
        kind: args.kind.0,
        raw: args.raw.clone(),
        compensated: args.compensated.clone(),
    };
    let out = plot_log(&log, &opts)?;
    for s in &out.skipped {
        eprintln!("skipped {s}");
    }
    for n in &out.notes {
        eprintln!("note: {n}");
    }
    for p in &out.written {
        println!("{}", p.display());
    }
    Ok(())
}
