//! `accomp`: the lab-PC command line. Each subcommand's arguments and glue live in its own file
//! of `accomp_host::cli`; this file only dispatches.

use accomp_host::cli;
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
    Fit(cli::fit::FitArgs),
    /// Inspect or check a calibration table file.
    Table(cli::table::TableArgs),
    /// Solve dividing-head tumble logs for K0, K1, K2, δ (and K3) per test (docs/tumble.md).
    Tumble(cli::tumble::TumbleArgs),
    /// Generate a tumble log from true temperature models (the paper's printed order-2 models).
    SimulateTumble(cli::simulate_tumble::SimulateTumbleArgs),
    /// Simulate the test station (scenario file or preset) and write a log.
    Simulate(cli::simulate::SimulateArgs),
    /// Stream samples through the firmware (or the same core on the host) and write what it
    /// returns.
    Compensate(cli::compensate::CompensateArgs),
    /// Upload a calibration table to the device, verify by read-back, activate it.
    Load(cli::load::LoadArgs),
    /// Find what the static model gets wrong in a log, name the physical cause, measure the gain.
    Discover(cli::discover::DiscoverArgs),
    /// Figures like the paper's Figs. 2–5 and Allan deviation with confidence bands.
    Plot(cli::plot::PlotArgs),
    /// Stability (std, drift), OADEV and MDEV of a log's output columns.
    Stability(cli::stability::StabilityArgs),
    /// The paper's two experiments through the firmware in QEMU: fit, upload, stream raw codes,
    /// record, report stability before/after compensation next to the paper and the floor.
    Demo(cli::demo::DemoArgs),
    /// One request to the board: info, ping, rollback, activate, set-rate.
    Device(cli::device::DeviceArgs),
    /// Record the board's sample stream into a log, through unplugging and resets.
    Record(cli::record::RecordArgs),
    /// The virtual front-end board (firmware core on chip models, station physics) on a
    /// pseudo-terminal.
    BoardSim(cli::board_sim::BoardSimArgs),
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Fit(args) => cli::fit::run(&args),
        Command::Table(args) => cli::table::run(&args),
        Command::Tumble(args) => cli::tumble::run(args),
        Command::SimulateTumble(args) => cli::simulate_tumble::run(args),
        Command::Simulate(args) => cli::simulate::run(&args),
        Command::Compensate(args) => cli::compensate::run(&args),
        Command::Load(args) => cli::load::run(&args),
        Command::Discover(args) => cli::discover::run(&args),
        Command::Plot(args) => cli::plot::run(&args),
        Command::Stability(args) => Ok(cli::stability::run(&args)?),
        Command::Demo(args) => cli::demo::run(&args),
        Command::Device(args) => cli::device::run(&args),
        Command::Record(args) => cli::record::run(&args),
        Command::BoardSim(args) => cli::board_sim::run(&args),
    }
}
