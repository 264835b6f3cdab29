//! `accomp load`: upload a calibration table to the device, verify by read-back, activate it.

use std::path::PathBuf;

use crate::device::{Connection, Target};
use anyhow::Context as _;

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

/// Runs `accomp load`.
pub fn run(args: &LoadArgs) -> anyhow::Result<()> {
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
