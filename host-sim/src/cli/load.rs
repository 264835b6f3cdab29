//! `accomp load`: upload a calibration table to the device, verify by read-back, activate it.

use std::path::PathBuf;

use crate::device::{Connection, Target};
use anyhow::Context as _;

/// Upload a calibration table to the device, verify by read-back, activate it.
#[derive(clap::Args, Debug)]
pub struct LoadArgs {
    #[command(flatten)]
    pub device: DeviceArgs,
    /// Calibration table file.
    pub calibration: PathBuf,
    /// Send the file even if it does not validate here (tests the device's validation).
    #[arg(long)]
    pub no_local_check: bool,
}

/// The device a command talks to: where, which firmware QEMU boots, how the board state is taken.
#[derive(clap::Args, Debug)]
pub struct DeviceArgs {
    /// qemu or serial:<port>
    #[arg(long)]
    pub target: Target,
    /// Firmware ELF for --target qemu.
    #[arg(long)]
    pub firmware: Option<PathBuf>,
    #[command(flatten)]
    pub state: BoardStateArgs,
}

impl DeviceArgs {
    /// Connects to the device (the board state options apply to every connection of the process).
    pub fn open(&self) -> anyhow::Result<Connection> {
        self.state.apply();
        Ok(Connection::open(&self.target, self.firmware.as_deref())?)
    }
}

/// How a command takes the QEMU board's persistent state (one command at a time).
#[derive(clap::Args, Debug, Clone, Copy, Default)]
pub struct BoardStateArgs {
    /// --target qemu: refuse at once when another command is using the board state, instead
    /// of waiting for it.
    #[arg(long)]
    pub no_wait: bool,
    /// --target qemu: move a damaged board state (flash image of the wrong size) aside,
    /// renamed with a time stamp, and start with a blank board.
    #[arg(long)]
    pub reset_state: bool,
}

impl BoardStateArgs {
    /// Makes these the options of every device connection of this process.
    pub fn apply(self) {
        crate::device::qemu::StateOptions {
            no_wait: self.no_wait,
            reset_state: self.reset_state,
        }
        .set_for_process();
    }
}

/// Runs `accomp load`.
pub fn run(args: &LoadArgs) -> anyhow::Result<()> {
    let bytes = crate::calibration_file::read_table_bytes(&args.calibration)?;
    if !args.no_local_check {
        crate::calibration_file::decode_named(&bytes).context("table refused locally")?;
    }
    let mut conn = args.device.open()?;
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
    let state = conn.state_image();
    // The board said so; for the QEMU board it counts once the image on disk says so too.
    match conn.close()? {
        None => eprintln!("active table {id:#010x} (read back and verified)"),
        Some((active, previous)) => {
            let path = state.map(|p| p.display().to_string()).unwrap_or_default();
            anyhow::ensure!(
                active == Some(id),
                "{path}: the persisted image's active table is {}, not {id:#010x}: not loaded",
                active.map_or("none".into(), |a| format!("{a:#010x}"))
            );
            let rollback = previous.map_or("none".into(), |p| format!("{p:#010x}"));
            eprintln!(
                "active table {id:#010x} (read back and verified, persisted in {path}; \
                 rollback table {rollback})"
            );
        }
    }
    Ok(())
}
