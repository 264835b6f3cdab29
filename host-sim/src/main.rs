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
enum Command {}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {}
}
