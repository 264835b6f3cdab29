//! `accomp`: the lab-PC command line.
use std::path::PathBuf;

use accomp_host::device::{compensate, samples_csv, Connection, Target};
use anyhow::Context as _;
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
    /// Stream samples through the firmware (or the same core on the host) and write what it
    /// returns.
    Compensate {
        /// host, qemu or serial:<port>
        #[arg(long)]
        target: Target,
        /// Calibration table (binary, as written by `accomp fit -o`).
        #[arg(long)]
        calibration: PathBuf,
        /// Samples CSV: time_s, output_v, temperature_c[, tilt_arcsec].
        #[arg(long)]
        input: PathBuf,
        /// Output CSV.
        #[arg(long)]
        output: PathBuf,
        /// Firmware ELF for --target qemu (default: $ACCOMP_FIRMWARE_ELF, then
        /// target/thumbv7em-none-eabihf/release/accomp-fw).
        #[arg(long)]
        firmware: Option<PathBuf>,
    },
    /// Upload a calibration table to the device, verify by read-back, activate it.
    Load {
        /// qemu or serial:<port>
        #[arg(long)]
        target: Target,
        /// Calibration table file.
        calibration: PathBuf,
        /// Send the file even if it does not validate here (tests the device's validation).
        #[arg(long)]
        no_local_check: bool,
        /// Firmware ELF for --target qemu.
        #[arg(long)]
        firmware: Option<PathBuf>,
    },
    /// Device tables.
    #[command(subcommand)]
    Table(TableCommand),
}

#[derive(Subcommand)]
enum TableCommand {
    /// Read the device's active table into a file.
    Get {
        /// qemu or serial:<port>
        #[arg(long)]
        target: Target,
        /// Where to write the table.
        #[arg(short, long)]
        output: PathBuf,
        /// Firmware ELF for --target qemu.
        #[arg(long)]
        firmware: Option<PathBuf>,
    },
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Compensate {
            target,
            calibration,
            input,
            output,
            firmware,
        } => {
            let table = std::fs::read(&calibration)
                .with_context(|| format!("reading {}", calibration.display()))?;
            let text = std::fs::read_to_string(&input)
                .with_context(|| format!("reading {}", input.display()))?;
            let file = samples_csv::parse(&text)?;
            let started = std::time::Instant::now();
            let rows = compensate::compensate(
                &target,
                firmware.as_deref(),
                &table,
                &file.rows,
                |what, done, total| {
                    if done == total || done % 1000 == 0 {
                        eprint!("\r{what}: {done}/{total}   ");
                    }
                },
            )?;
            eprintln!(
                "\n{} samples through {target:?} in {:.2} s",
                rows.len(),
                started.elapsed().as_secs_f64()
            );
            std::fs::write(&output, samples_csv::write_output(&file.metadata, &rows))
                .with_context(|| format!("writing {}", output.display()))?;
        }
        Command::Load {
            target,
            calibration,
            no_local_check,
            firmware,
        } => {
            let bytes = std::fs::read(&calibration)
                .with_context(|| format!("reading {}", calibration.display()))?;
            if !no_local_check {
                accomp::table::CalibrationTable::decode(&bytes)
                    .map_err(|e| anyhow::anyhow!("table refused locally: {e:?}"))?;
            }
            let mut conn = Connection::open(&target, firmware.as_deref())?;
            let id = conn.client.load(&bytes, |sent, total| {
                eprint!("\rupload {sent}/{total} bytes");
            })?;
            eprintln!("\nactive table {id:#010x} (read back and verified)");
        }
        Command::Table(TableCommand::Get {
            target,
            output,
            firmware,
        }) => {
            let mut conn = Connection::open(&target, firmware.as_deref())?;
            let bytes = conn.client.read_table()?;
            std::fs::write(&output, &bytes)?;
            eprintln!("{} bytes written to {}", bytes.len(), output.display());
        }
    }
    Ok(())
}
