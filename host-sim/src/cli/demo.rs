//! `accomp demo` (run by `cargo xtask demo`): the flags and the printed report (the demo itself
//! is [`crate::demo`]).

use std::path::PathBuf;

use clap::Args;

use crate::demo::{run_demo, DemoOptions};

/// Arguments of `accomp demo`.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Table 1 CSV (default: data/jn06_a12124_coefficients_vs_temperature.csv of the repository
    /// the binary was built from).
    #[arg(long)]
    pub table1: Option<PathBuf>,
    /// Where the log, figures, tables and report are written.
    #[arg(short, long, default_value = "target/demo")]
    pub out_dir: PathBuf,
    /// Seed of the simulation (both experiments).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Sample interval of paper-1g, s (600 s: 5 904 samples over 41 days).
    #[arg(long, default_value_t = 600.0)]
    pub interval_1g: f64,
    /// Sample interval of paper-0g, s (30 s: 2 880 samples over 1 day).
    #[arg(long, default_value_t = 30.0)]
    pub interval_0g: f64,
    /// Override the duration of paper-1g, days (default: the preset's 41).
    #[arg(long)]
    pub days_1g: Option<f64>,
    /// Override the duration of paper-0g, days (default: the preset's 1).
    #[arg(long)]
    pub days_0g: Option<f64>,
    /// Firmware ELF (default: $ACCOMP_FIRMWARE_ELF, else target/thumbv7em-none-eabihf/release/accomp-fw).
    #[arg(long)]
    pub firmware: Option<PathBuf>,
    /// Skip the figures.
    #[arg(long)]
    pub no_plots: bool,
}

impl DemoArgs {
    /// The demo's options from the flags.
    pub fn options(&self) -> DemoOptions {
        DemoOptions {
            table1: self.table1.clone(),
            out_dir: self.out_dir.clone(),
            seed: self.seed,
            interval_1g: self.interval_1g,
            interval_0g: self.interval_0g,
            days_1g: self.days_1g,
            days_0g: self.days_0g,
            firmware: self.firmware.clone(),
            no_plots: self.no_plots,
        }
    }
}

/// `accomp demo`.
pub fn run(args: &DemoArgs) -> anyhow::Result<()> {
    let report = run_demo(&args.options())?;
    print!("{}", report.to_text());
    println!(
        "report: {} and {}",
        args.out_dir.join("report.txt").display(),
        args.out_dir.join("report.json").display()
    );
    Ok(())
}
