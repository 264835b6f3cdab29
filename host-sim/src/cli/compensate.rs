//! `accomp compensate`: stream samples through the firmware (or the same core on the host) and
//! write what it returns (the streaming is [`crate::device::compensate`]).

use std::path::PathBuf;

use crate::device::{compensate, Target};

/// Stream samples through the firmware (or the same core on the host) and write what it returns.
#[derive(clap::Args, Debug)]
pub struct CompensateArgs {
    /// host, qemu or serial:<port>
    #[arg(long)]
    pub target: Target,
    /// Calibration table (binary, as written by `accomp fit -o`).
    #[arg(long)]
    pub calibration: PathBuf,
    /// Samples CSV: time_s, output_v, temperature_c[, tilt_arcsec].
    #[arg(long)]
    pub input: PathBuf,
    /// Output CSV.
    #[arg(long)]
    pub output: PathBuf,
    /// Firmware ELF for --target qemu (default: $ACCOMP_FIRMWARE_ELF, then
    /// target/thumbv7em-none-eabihf/release/accomp-fw).
    #[arg(long)]
    pub firmware: Option<PathBuf>,
    #[command(flatten)]
    pub state: super::load::BoardStateArgs,
    /// Read a samples file above the reader's limits (20 million data lines, 4 GiB).
    #[arg(long)]
    pub allow_large: bool,
}

/// Runs `accomp compensate` (streams its output: docs/protocol.md).
pub fn run(args: &CompensateArgs) -> anyhow::Result<()> {
    args.state.apply();
    crate::log::reader::set_allow_large(args.allow_large);
    compensate::run_to_file(
        &args.target,
        args.firmware.as_deref(),
        &args.calibration,
        &args.input,
        &args.output,
    )?;
    Ok(())
}
