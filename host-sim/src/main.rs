//! `accomp`: the lab-PC command line.
use accomp_host::table_cli;
use clap::{Parser, Subcommand};
use std::path::PathBuf;

#[derive(Parser)]
#[command(
    name = "accomp",
    version,
    about = "Accelerometer stability-test compensation tools"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Inspect or check a calibration table file.
    Table {
        #[command(subcommand)]
        action: TableAction,
    },
    /// Stability (std, drift), OADEV and MDEV of a log's output columns.
    Stability(accomp_host::stability::StabilityArgs),
    /// Find what the model gets wrong on a record, name the effect, measure the gain.
    Discover(accomp_host::discover::DiscoverArgs),
    /// Fit temperature models of the calibration coefficients (orders 0–4), compare them with
    /// the paper's printed models, optionally write a calibration table.
    Fit(accomp_host::fit::FitArgs),
    /// Simulate the test station (scenario file or preset) and write a log.
    Simulate(accomp_host::sim::cli::SimulateArgs),
}

#[derive(Subcommand)]
enum TableAction {
    /// Print what a table holds.
    Show {
        /// Calibration table file (as written by `accomp fit -o`).
        path: PathBuf,
        /// One JSON object instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Check a table as the firmware would; exits non-zero with the named error if refused.
    Verify {
        /// Calibration table file.
        path: PathBuf,
        /// One JSON object instead of text.
        #[arg(long)]
        json: bool,
    },
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Table { action } => match action {
            TableAction::Show { path, json } => {
                let t = table_cli::read_table(&path)?;
                if json {
                    println!(
                        "{}",
                        serde_json::to_string_pretty(&table_cli::table_json(&t))?
                    );
                } else {
                    print!("{}", table_cli::table_text(&t));
                }
            }
            TableAction::Verify { path, json } => {
                let bytes = std::fs::read(&path)?;
                match table_cli::decode_named(&bytes) {
                    Ok(t) => {
                        if json {
                            println!(
                                "{}",
                                serde_json::json!({"valid": true, "id": format!("{:08x}", t.id())})
                            );
                        } else {
                            println!("{}: valid, id {:08x}", path.display(), t.id());
                        }
                    }
                    Err(e) => {
                        if json {
                            println!(
                                "{}",
                                serde_json::json!({"valid": false, "error": e.to_string()})
                            );
                        }
                        anyhow::bail!("{}: refused: {e}", path.display());
                    }
                }
            }
        },
        Command::Stability(args) => accomp_host::stability::run(&args)?,
        Command::Discover(args) => accomp_host::discover::run(&args)?,
        Command::Fit(args) => accomp_host::fit::run(&args)?,
        Command::Simulate(args) => accomp_host::sim::cli::run(&args)?,
    }
    Ok(())
}
