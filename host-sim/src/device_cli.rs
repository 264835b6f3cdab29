//! CLI glue of the device commands: `accomp compensate`, `accomp load`, `accomp table get`.

use std::path::PathBuf;

use crate::device::{compensate, Connection, Target};
use anyhow::Context as _;

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
}

/// Upload a calibration table to the device, verify by read-back, activate it.
#[derive(clap::Args, Debug)]
pub struct LoadArgs {
    /// qemu or serial:<port>
    #[arg(long)]
    pub target: Target,
    /// Calibration table file.
    pub calibration: PathBuf,
    /// Send the file even if it does not validate here (tests the device's validation).
    #[arg(long)]
    pub no_local_check: bool,
    /// Firmware ELF for --target qemu.
    #[arg(long)]
    pub firmware: Option<PathBuf>,
}

/// Read the device's active table into a file.
#[derive(clap::Args, Debug)]
pub struct TableGetArgs {
    /// qemu or serial:<port>
    #[arg(long)]
    pub target: Target,
    /// Where to write the table.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Firmware ELF for --target qemu.
    #[arg(long)]
    pub firmware: Option<PathBuf>,
}

/// Runs `accomp compensate` (streams its output: docs/protocol.md).
pub fn run_compensate(args: &CompensateArgs) -> anyhow::Result<()> {
    compensate::run_to_file(
        &args.target,
        args.firmware.as_deref(),
        &args.calibration,
        &args.input,
        &args.output,
    )
}

/// Runs `accomp load`.
pub fn run_load(args: &LoadArgs) -> anyhow::Result<()> {
    let bytes = crate::calibration_file::read_table_bytes(&args.calibration)?;
    if !args.no_local_check {
        crate::calibration_file::decode_named(&bytes).context("table refused locally")?;
    }
    let mut conn = Connection::open(&args.target, args.firmware.as_deref())?;
    // A bar on a terminal, nothing when stderr is a file or a pipe (the `\r` line it replaces
    // ran together there: "upload 64/426 bytesupload 128/426 …").
    let bar = indicatif::ProgressBar::new(bytes.len() as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("upload [{bar:30}] {bytes}/{total_bytes}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    let loaded = conn
        .client
        .load(&bytes, |sent, _| bar.set_position(sent as u64));
    bar.finish_and_clear();
    let id = loaded?;
    eprintln!("active table {id:#010x} (read back and verified)");
    Ok(())
}

/// Runs `accomp table get`.
pub fn run_table_get(args: &TableGetArgs) -> anyhow::Result<()> {
    let mut conn = Connection::open(&args.target, args.firmware.as_deref())?;
    let bytes = conn.client.read_table()?;
    std::fs::write(&args.output, &bytes)
        .with_context(|| format!("writing {}", args.output.display()))?;
    eprintln!("{} bytes written to {}", bytes.len(), args.output.display());
    Ok(())
}
