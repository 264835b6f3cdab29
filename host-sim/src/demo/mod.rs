//! `accomp demo` (run by `cargo xtask demo`): the paper's two experiments end to end through the
//! firmware in QEMU.
//!
//! 1. fit Table 1 (`fit::fit_table`) → the lab's calibration table;
//! 2. boot the firmware in QEMU;
//! 3. for `paper-1g` and `paper-0g` (fixed seed): simulate the station, derive the experiment's
//!    table from the fitted one (orientation, tilt axis, φ0), upload it (read-back verified),
//!    stream the simulated **raw ADC codes** through the firmware (`InjectSample`), check every
//!    returned frame against the same core on the PC, record the stream as a log;
//! 4. stability (std of equally spaced readings) before/after compensation, next to the paper's
//!    figures and the floor (the same data compensated with the simulation's true parameters);
//! 5. figures (`plot::plot_log`), `report.txt` and `report.json`.
//!
//! Time compression: `InjectSample` carries no time field (docs/protocol.md), so the firmware
//! stamps each frame with its own clock. The host knows which simulated sample each request id
//! carried, so the recorded log's `time_s` is simulated time and the firmware's own stamp is kept
//! as `fw_time_s`. Figures: docs/demo.md.
//!
//! Files: `mod.rs` the options, the run and the report types (the command's flags and printing:
//! [`crate::cli::demo`]); `tables.rs` Table 1's fit and each
//! experiment's table; `experiment.rs` one experiment, step by step; `stream.rs` raw codes
//! through the firmware; `record.rs` the recorded log; `report.rs` report.txt; `tests.rs`.

mod experiment;
mod record;
mod report;
mod stream;
mod tables;
#[cfg(test)]
mod tests;

use experiment::{run_experiment, Run};
#[cfg(test)]
use tables::experiment_table;
use tables::{default_table1, fit_table1};

use std::fs;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::device::samples_csv::status_names;
use accomp::compensation::tilt_compensated;
use accomp::model::CrossAxis;
use accomp::pipeline::{self, Frame, RawSample, Status};
use accomp::table::{CalibrationDate, CalibrationTable, TiltAxis};
use accomp::units::{Celsius, Gs, TiltArcsec, Volts};
use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;

use crate::device::{self, client::DEFAULT_WINDOW, qemu::QemuOptions, Qemu};
use crate::fit;
use crate::log::{Log, TextColumn};
use crate::plot::{self, PlotOptions};
use crate::sim::accelerometer::true_coefficients;
use crate::sim::scenario::Scenario;
use crate::sim::{Sample, Simulator};
use crate::stability::mean_std;

/// File name of Table 1 under the repository's `data/`.
pub const TABLE1_FILE: &str = "jn06_a12124_coefficients_vs_temperature.csv";
/// The paper's figures: (uncompensated, compensated) stability in g.
pub const PAPER_1G: (f64, f64) = (1.43e-5, 6.6e-6);
/// 0 g: 1.6 µg → 1.3 µg.
pub const PAPER_0G: (f64, f64) = (1.6e-6, 1.3e-6);
/// Calibration date written into the demo's tables: fixed, so the table ids are reproducible.
const DEMO_DATE: CalibrationDate = CalibrationDate {
    year: 2017,
    month: 4,
    day: 1,
};

/// What `accomp demo` runs and where it writes: the command's flags (`accomp demo --help`), also
/// the options of [`run_demo`].
#[derive(Debug, Clone, clap::Args)]
pub struct DemoOptions {
    /// Table 1 CSV (default: data/jn06_a12124_coefficients_vs_temperature.csv of the repository
    /// the binary was built from).
    #[arg(long)]
    pub table1: Option<PathBuf>,
    /// Where the log, figures, tables and report are written.
    #[arg(short, long, default_value = "target/demo")]
    pub out_dir: PathBuf,
    /// Seed of the simulation (both experiments).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Sample interval of paper-1g, s (600 s: 5 904 samples over 41 days).
    #[arg(long, default_value_t = 600.0)]
    pub interval_1g: f64,
    /// Sample interval of paper-0g, s (30 s: 2 880 samples over 1 day).
    #[arg(long, default_value_t = 30.0)]
    pub interval_0g: f64,
    /// Override the duration of paper-1g, days (default: the preset's 41).
    #[arg(long)]
    pub days_1g: Option<f64>,
    /// Override the duration of paper-0g, days (default: the preset's 1).
    #[arg(long)]
    pub days_0g: Option<f64>,
    /// Firmware ELF (default: $ACCOMP_FIRMWARE_ELF, else target/thumbv7em-none-eabihf/release/accomp-fw).
    #[arg(long)]
    pub firmware: Option<PathBuf>,
    /// Skip the figures.
    #[arg(long)]
    pub no_plots: bool,
}

/// One stability figure of the report.
#[derive(Debug, Clone, Serialize)]
pub struct Figure {
    /// What was measured.
    pub label: String,
    /// Log column it comes from (after the conversion named in `label`).
    pub column: String,
    /// Sample standard deviation, g.
    pub std_g: f64,
    /// The paper's figure for the same quantity, g.
    pub paper_g: Option<f64>,
}

/// One experiment of the report.
#[derive(Debug, Clone, Serialize)]
pub struct Experiment {
    /// Preset name.
    pub name: String,
    /// Instrument named by the scenario.
    pub instrument: String,
    /// Nominal input, g.
    pub input_g: f64,
    /// Thermostat set point, °C.
    pub setpoint_c: f64,
    /// Samples streamed through the firmware.
    pub samples: usize,
    /// Sample interval, simulated seconds.
    pub interval_s: f64,
    /// Simulated duration, days.
    pub duration_days: f64,
    /// Id of the table uploaded for this experiment (verified by read-back).
    pub table_id: String,
    /// Stability figures: before, after (exact, linearized), floor and any extra rows.
    pub figures: Vec<Figure>,
    /// Frames whose values differ from the same core run on the PC (bit for bit).
    pub host_mismatches: usize,
    /// Chunks of readings sent again after a lost answer.
    pub retried_chunks: usize,
    /// Inbound frames the device dropped since boot (Info, after this experiment).
    pub device_frames_dropped: u32,
    /// Frames from the device the host could not decode (since boot).
    pub host_bad_frames: u64,
    /// Status bits seen, with the number of frames carrying each.
    pub status_counts: Vec<(String, usize)>,
    /// Peak-to-peak of the measured tilt, arcsec.
    pub tilt_pp_arcsec: f64,
    /// Std of the measured temperature, °C.
    pub temperature_std_c: f64,
    /// Streaming wall time, s.
    pub stream_wall_s: f64,
    /// Simulated seconds per wall-clock second while streaming.
    pub time_compression: f64,
    /// Notes on how to read the figures.
    pub notes: Vec<String>,
    /// The recorded log.
    pub log: PathBuf,
    /// Figures written.
    pub plots: Vec<PathBuf>,
}

/// The whole report (also written as report.json).
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// Seed of both simulations.
    pub seed: u64,
    /// Table 1 input.
    pub table1: PathBuf,
    /// The fitted calibration table.
    pub calibration: PathBuf,
    /// Selected polynomial order per coefficient.
    pub fit_orders: Vec<(String, usize)>,
    /// Firmware ELF booted.
    pub firmware: PathBuf,
    /// The experiments, 1 g first.
    pub experiments: Vec<Experiment>,
    /// Total wall time, s.
    pub wall_s: f64,
}

/// Runs the demo; returns the report (also printed and written to the output directory).
pub fn run_demo(args: &DemoOptions) -> anyhow::Result<Report> {
    let started = Instant::now();
    fs::create_dir_all(&args.out_dir)
        .with_context(|| format!("cannot create {}", args.out_dir.display()))?;
    let table1 = args.table1.clone().unwrap_or_else(default_table1);
    let (base, fit_orders) = fit_table1(&table1)?;
    let calibration = args.out_dir.join("jn06_table1.acal");
    fs::write(&calibration, base.encode())
        .with_context(|| format!("cannot write {}", calibration.display()))?;
    eprintln!(
        "fitted Table 1 → {} (id {:08x})",
        calibration.display(),
        base.id()
    );

    let firmware = device::firmware_path(args.firmware.as_deref());
    let opts = QemuOptions {
        log_dir: Some(args.out_dir.join("qemu")),
        ..QemuOptions::default()
    };
    eprintln!("booting {} in QEMU", firmware.display());
    let (qemu, mut client) = Qemu::launch(&firmware, &opts)?;
    client.timeout = Duration::from_secs(5);

    let runs = [
        Run {
            name: "paper-1g",
            interval_s: args.interval_1g,
            days: args.days_1g,
            paper: PAPER_1G,
        },
        Run {
            name: "paper-0g",
            interval_s: args.interval_0g,
            days: args.days_0g,
            paper: PAPER_0G,
        },
    ];
    let mut experiments = Vec::new();
    for run in &runs {
        experiments.push(run_experiment(&mut client, &base, args, run)?);
    }
    qemu.shutdown();

    let report = Report {
        seed: args.seed,
        table1,
        calibration,
        fit_orders,
        firmware,
        experiments,
        wall_s: started.elapsed().as_secs_f64(),
    };
    fs::write(
        args.out_dir.join("report.json"),
        serde_json::to_string_pretty(&report)?,
    )?;
    fs::write(args.out_dir.join("report.txt"), report.to_text())?;
    Ok(report)
}
