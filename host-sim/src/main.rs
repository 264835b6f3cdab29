//! `accomp`: the lab-PC command line.
use clap::{Parser, Subcommand};

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
    /// Stability (std, drift), OADEV and MDEV of a log's output columns.
    Stability(accomp_host::stability::StabilityArgs),
    /// Simulate the test station (scenario file or preset) and write a log.
    Simulate(accomp_host::sim::cli::SimulateArgs),
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Stability(args) => accomp_host::stability::run(&args)?,
        Command::Simulate(args) => accomp_host::sim::cli::run(&args)?,
    }
    Ok(())
}
