//! `accomp`: the lab-PC command line. Each subcommand lives in its own module; this file only
//! dispatches.

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
    /// Fit temperature models of the calibration coefficients (orders 0–4), compare them with
    /// the paper's printed models, optionally write a calibration table.
    Fit(accomp_host::fit::FitArgs),
    /// Inspect or check a calibration table file.
    Table(accomp_host::table_cli::TableArgs),
    /// Solve dividing-head tumble logs for K0, K1, K2, δ (and K3) per test (docs/tumble.md).
    Tumble(accomp_host::tumble_cli::TumbleArgs),
    /// Generate a tumble log from true temperature models (the paper's printed order-2 models).
    SimulateTumble(accomp_host::tumble_cli::SimulateTumbleArgs),
    /// Simulate the test station (scenario file or preset) and write a log.
    Simulate(accomp_host::sim::cli::SimulateArgs),
    /// Stream samples through the firmware (or the same core on the host) and write what it
    /// returns.
    Compensate(accomp_host::device_cli::CompensateArgs),
    /// Upload a calibration table to the device, verify by read-back, activate it.
    Load(accomp_host::device_cli::LoadArgs),
    /// Find what the static model gets wrong in a log, name the physical cause, measure the gain.
    Discover(accomp_host::discover::DiscoverArgs),
    /// Figures like the paper's Figs. 2–5 and Allan deviation with confidence bands.
    Plot(accomp_host::plot::PlotArgs),
    /// Stability (std, drift), OADEV and MDEV of a log's output columns.
    Stability(accomp_host::stability::StabilityArgs),
    /// The paper's two experiments through the firmware in QEMU: fit, upload, stream raw codes,
    /// record, report stability before/after compensation next to the paper and the floor.
    Demo(accomp_host::demo::DemoArgs),
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Fit(args) => accomp_host::fit::run(&args),
        Command::Table(args) => accomp_host::table_cli::run(&args),
        Command::Tumble(args) => accomp_host::tumble_cli::run(args),
        Command::SimulateTumble(args) => accomp_host::tumble_cli::run_simulate(args),
        Command::Simulate(args) => accomp_host::sim::cli::run(&args),
        Command::Compensate(args) => accomp_host::device_cli::run_compensate(&args),
        Command::Load(args) => accomp_host::device_cli::run_load(&args),
        Command::Discover(args) => accomp_host::discover::run(&args),
        Command::Plot(args) => accomp_host::plot::run(&args),
        Command::Stability(args) => Ok(accomp_host::stability::run(&args)?),
        Command::Demo(args) => accomp_host::demo::run(&args),
    }
}
