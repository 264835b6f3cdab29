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

use std::fs;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::device::samples_csv::status_names;
use accomp::compensation::tilt_compensated;
use accomp::model::CrossAxis;
use accomp::pipeline::{self, ChannelFlags, Frame, RawSample, Status};
use accomp::table::{CalibrationDate, CalibrationTable, TiltAxis};
use accomp::units::{Celsius, Gs, TiltArcsec, Volts};
use anyhow::Context;
use clap::Args;
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

/// Arguments of `accomp demo`.
#[derive(Debug, Args)]
pub struct DemoArgs {
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

/// Table 1 in the repository's `data/` (where the sources were built from).
fn default_table1() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../data")
        .join(TABLE1_FILE)
}

/// Fits Table 1 and builds the lab's calibration table (T0 = 60 °C, the paper's 1 g test).
fn fit_table1(path: &Path) -> anyhow::Result<(CalibrationTable, Vec<(String, usize)>)> {
    let text =
        fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let table = fit::parse_coefficient_table(&text)
        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    let report = fit::fit_table(&table, &[], Celsius(50.0))?;
    let scale = table
        .scale()
        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    let cal = fit::calibration_table(&report, scale, Celsius(60.0), "JN-06 A12124", DEMO_DATE)?;
    let orders = report
        .coefficients
        .iter()
        .map(|c| (c.name.clone(), c.selected_order))
        .collect();
    Ok((cal, orders))
}

/// The table of one experiment: the fitted models with the test's orientation and tilt set-up.
///
/// - 1 g (input axis up): tilt about the spindle changes a_i only as cos φ (second order), so the
///   tilt axis is `None`; no cross-axis input.
/// - 0 g (input axis horizontal): eq. (5) applies (`TiltAxis::Input`) with φ0 = the first tilt
///   reading, and the cross axis along the spindle carries 1 g. T0 moves to the nearest edge of
///   the calibrated range (the table refuses a T0 outside it), so the linearized output is not
///   offset by a 30 °C extrapolation.
fn experiment_table(
    base: &CalibrationTable,
    sc: &Scenario,
    first: &Sample,
) -> anyhow::Result<CalibrationTable> {
    let mut t = *base;
    let o = &sc.accelerometer.orientation;
    let angle = o
        .positions
        .first()
        .map_or(0.0, |p| p.angle_deg)
        .to_radians();
    let (a_i, cross) = crate::sim::accelerometer::axes(o.spindle_axis, o.cross_sign, angle, 1.0);
    // Round the nominal orientation to the exact values a lab would type in.
    let round = |v: f64| (v * 1e6).round() / 1e6;
    t.orientation.nominal_input = Gs(round(a_i.0));
    t.orientation.cross = CrossAxis {
        a_p: Gs(round(cross.a_p.0)),
        a_o: Gs(round(cross.a_o.0)),
    };
    let zero_g = a_i.0.abs() < 0.5;
    if zero_g {
        t.tilt.axis = TiltAxis::Input;
        // φ0: what the board reads at the start, through the same conversion the firmware uses.
        let f = pipeline::process(0, 0, &raw(first), Some(&t));
        t.tilt.reference = TiltArcsec(f.tilt_arcsec);
        let (lo, hi) = (t.thermal.scale.min.0, t.thermal.scale.max.0);
        t.thermal.reference = Celsius(sc.thermostat.setpoint_c.clamp(lo, hi));
    } else {
        t.tilt.axis = TiltAxis::None;
    }
    t.validate()
        .map_err(|e| anyhow::anyhow!("experiment table refused: {e:?}"))?;
    Ok(t)
}

/// The raw sample the board would acquire: the simulator's codes, no driver faults.
fn raw(s: &Sample) -> RawSample {
    RawSample {
        accel: s.accel_code,
        rtd: s.rtd_code,
        tilt: s.tilt_code,
        accel_flags: ChannelFlags::default(),
        rtd_flags: ChannelFlags::default(),
        tilt_flags: ChannelFlags::default(),
    }
}

fn bar(len: u64, prefix: &str) -> ProgressBar {
    let b = ProgressBar::new(len);
    b.set_style(
        ProgressStyle::with_template(
            "{prefix:>9} {bar:40} {pos}/{len} samples, {per_sec}, {eta} left",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    b.set_prefix(prefix.to_owned());
    b
}

/// Log metadata as (key, value) pairs.
type Metadata = Vec<(String, String)>;

/// A truth column of the log: its name and how to read it from a sample.
type TruthColumn = (&'static str, fn(&Sample) -> f64);

fn simulate(sc: &Scenario, seed: u64) -> anyhow::Result<(Vec<Sample>, Metadata)> {
    let mut sim = Simulator::new(sc, seed)?;
    let n = sim.samples();
    let b = bar(n, "simulate");
    let mut out = Vec::with_capacity(n as usize);
    for i in 0..n {
        out.push(sim.step()?);
        if i % 256 == 0 {
            b.set_position(i);
        }
    }
    b.finish_and_clear();
    Ok((out, sim.metadata(seed)))
}

/// Bit-for-bit equality of the values of two frames (NaN equals NaN; seq/time differ by design).
fn same_values(a: &Frame, b: &Frame) -> bool {
    let v = |f: &Frame| {
        [
            f.output_v,
            f.temperature_c,
            f.rtd_ohms,
            f.tilt_arcsec,
            f.a_i_exact_g,
            f.output_linearized_v,
        ]
        .map(f64::to_bits)
    };
    v(a) == v(b) && a.status == b.status
}

fn std_of(y: &[f64]) -> f64 {
    mean_std(y).map_or(f64::NAN, |(_, s, _)| s)
}

fn peak_to_peak(y: &[f64]) -> f64 {
    let finite = y.iter().copied().filter(|v| v.is_finite());
    let (lo, hi) = finite.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    hi - lo
}

/// Readings per `process_samples` call: a lost frame costs at most one chunk's retry.
const STREAM_CHUNK: usize = 256;
/// Retries of one chunk before the demo gives up.
const STREAM_RETRIES: usize = 3;

/// Streams `raws` through the device in chunks. The device drops inbound frames when its queue
/// is full and a frame can be lost on the line; the pipeline is stateless, so a chunk whose
/// answers stop coming is simply sent again (late answers to the old ids are ignored by the
/// client). Returns the frames in input order and the number of chunks retried.
fn stream(
    client: &mut device::Client,
    raws: &[RawSample],
    bar: &ProgressBar,
) -> anyhow::Result<(Vec<Frame>, usize)> {
    let mut out = Vec::with_capacity(raws.len());
    let mut retried = 0;
    for chunk in raws.chunks(STREAM_CHUNK) {
        let base = out.len() as u64;
        let mut tries = 0;
        loop {
            match client.process_samples(chunk, DEFAULT_WINDOW, |done, _| {
                bar.set_position(base + done as u64)
            }) {
                Ok(frames) => {
                    out.extend(frames);
                    break;
                }
                Err(device::ClientError::Timeout(..)) if tries < STREAM_RETRIES => {
                    tries += 1;
                    retried += 1;
                    bar.println(format!(
                        "no answer within {:?} at reading {base}+: sending those {} readings again",
                        client.timeout,
                        chunk.len()
                    ));
                }
                Err(e) => return Err(e.into()),
            }
        }
    }
    Ok((out, retried))
}

/// The floor: the measured output inverted with the simulation's *true* models at the true
/// proof-mass temperature and true cross-axis inputs; for 0 g also eq. (5) with the true tilt.
/// What remains is the instrument noise, the ADC and the input's own changes (tide gravity).
fn floor_g(sc: &Scenario, samples: &[Sample], zero_g: bool) -> anyhow::Result<Vec<f64>> {
    let models = sc
        .accelerometer
        .calibration
        .load(sc.thermostat.setpoint_c)?;
    let phi0 = samples.first().map_or(0.0, |s| s.truth_tilt_arcsec);
    Ok(samples
        .iter()
        .map(|s| {
            let k = true_coefficients(&models, s.truth_temperature_c);
            let e = if zero_g {
                tilt_compensated(
                    Volts(s.output_v),
                    k.scale_factor_v_per_g,
                    TiltArcsec(s.truth_tilt_arcsec),
                    TiltArcsec(phi0),
                )
            } else {
                Volts(s.output_v)
            };
            let cross = CrossAxis {
                a_p: Gs(s.truth_a_p_g),
                a_o: Gs(s.truth_a_o_g),
            };
            k.input(e, cross).map_or(f64::NAN, |g| g.0)
        })
        .collect())
}

struct Run<'a> {
    name: &'a str,
    interval_s: f64,
    days: Option<f64>,
    paper: (f64, f64),
}

#[allow(clippy::too_many_lines)]
fn run_experiment(
    qemu_client: &mut device::Client,
    base: &CalibrationTable,
    args: &DemoArgs,
    run: &Run<'_>,
) -> anyhow::Result<Experiment> {
    let mut sc = Scenario::preset(run.name).context("unknown preset")?;
    if let Some(d) = run.days {
        sc.run.duration_s = d * 86_400.0;
    }
    // The station is simulated at the preset's step (60 s) or finer, and every n-th reading is
    // streamed: simulating directly at 600 s would discretize the 60 s proof-mass lag and the
    // 900 s controller away (a first-order lag sampled at 10 τ is no lag at all), and the
    // compensation would look better than the physics allows.
    let sim_step = sc.run.interval_s.min(run.interval_s);
    let every = (run.interval_s / sim_step).round().max(1.0);
    anyhow::ensure!(
        (every * sim_step - run.interval_s).abs() < 1e-9 * run.interval_s,
        "interval {} s is not a multiple of the simulation step {sim_step} s",
        run.interval_s
    );
    sc.run.interval_s = sim_step;
    sc.validate()?;
    let (all, mut sim_meta) = simulate(&sc, args.seed)?;
    let samples: Vec<Sample> = all.into_iter().step_by(every as usize).collect();
    for (k, v) in &mut sim_meta {
        if k == "interval_s" {
            *v = run.interval_s.to_string();
        }
    }
    sim_meta.push(("simulation_step_s".into(), sim_step.to_string()));
    let first = samples.first().context("the scenario has no samples")?;
    let table = experiment_table(base, &sc, first)?;
    let zero_g = table.orientation.nominal_input.0.abs() < 0.5;
    let table_path = args.out_dir.join(format!("{}.acal", run.name));
    fs::write(&table_path, table.encode())
        .with_context(|| format!("cannot write {}", table_path.display()))?;

    // Upload, verified by read-back (Client::load compares byte by byte).
    let id = qemu_client.load(&table.encode(), |_, _| {})?;
    anyhow::ensure!(
        id == table.id(),
        "device activated table {id:08x}, uploaded {:08x}",
        table.id()
    );

    let raws: Vec<RawSample> = samples.iter().map(raw).collect();
    eprintln!(
        "{}: streaming {} raw-code samples ({} s of simulated time each) through the firmware",
        run.name,
        raws.len(),
        run.interval_s
    );
    let b = bar(raws.len() as u64, run.name);
    let started = Instant::now();
    let (frames, retried_chunks) = stream(qemu_client, &raws, &b)?;
    b.finish_and_clear();
    let info = qemu_client.info()?;
    let stream_wall_s = started.elapsed().as_secs_f64();
    anyhow::ensure!(
        frames.len() == raws.len(),
        "{} of {} frames came back",
        frames.len(),
        raws.len()
    );

    // The same core on the PC: the firmware must give the same bits.
    let host_mismatches = raws
        .iter()
        .zip(&frames)
        .enumerate()
        .filter(|(i, (r, f))| !same_values(&pipeline::process(*i as u32, 0, r, Some(&table)), f))
        .count();

    let k1_t0 = table
        .thermal
        .coefficients_at(table.thermal.reference)
        .map_err(|e| anyhow::anyhow!("K1 at T0: {e:?}"))?
        .0
        .scale_factor_v_per_g;
    let col = |f: fn(&Frame) -> f64| frames.iter().map(f).collect::<Vec<f64>>();
    let time_s: Vec<f64> = samples.iter().map(|s| s.time_s).collect();
    let output_v = col(|f| f.output_v);
    let a_i = col(|f| f.a_i_exact_g);
    let lin_v = col(|f| f.output_linearized_v);
    let tilt = col(|f| f.tilt_arcsec);
    let temperature = col(|f| f.temperature_c);
    let floor = floor_g(&sc, &samples, zero_g)?;
    let to_g = |v: &[f64]| v.iter().map(|x| x / k1_t0).collect::<Vec<f64>>();

    let mut figures = vec![
        Figure {
            label: "before compensation (E / K1(T0))".into(),
            column: "output_v".into(),
            std_g: std_of(&to_g(&output_v)),
            paper_g: Some(run.paper.0),
        },
        Figure {
            label: if zero_g {
                "after: firmware exact a_i (thermal + eq. 5 tilt)".into()
            } else {
                "after: firmware exact a_i".into()
            },
            column: "a_i_exact_g".into(),
            std_g: std_of(&a_i),
            paper_g: Some(run.paper.1),
        },
        Figure {
            label: "after: firmware linearized eq. (3)/(4) / K1(T0)".into(),
            column: "output_linearized_v".into(),
            std_g: std_of(&to_g(&lin_v)),
            paper_g: None,
        },
    ];
    let mut extra_cols = Vec::new();
    if zero_g {
        // What eq. (5) contributes: the same codes through the same core without the tilt term.
        let mut no_tilt = table;
        no_tilt.tilt.axis = TiltAxis::None;
        let thermal_only: Vec<f64> = raws
            .iter()
            .map(|r| pipeline::process(0, 0, r, Some(&no_tilt)).a_i_exact_g)
            .collect();
        figures.push(Figure {
            label: "thermal only, no eq. (5) (same core on the PC)".into(),
            column: "a_i_no_tilt_g".into(),
            std_g: std_of(&thermal_only),
            paper_g: None,
        });
        extra_cols.push(("a_i_no_tilt_g", thermal_only));
    }
    figures.push(Figure {
        label: "floor: true models at true temperature".into(),
        column: "floor_a_i_g".into(),
        std_g: std_of(&floor),
        paper_g: None,
    });

    let mut status_counts: Vec<(String, usize)> = Status::NAMES
        .iter()
        .map(|(bit, name)| {
            (
                (*name).to_owned(),
                frames.iter().filter(|f| f.status.has(*bit)).count(),
            )
        })
        .filter(|(_, n)| *n > 0)
        .collect();
    status_counts.sort_by_key(|c| std::cmp::Reverse(c.1));

    let mut notes = Vec::new();
    if zero_g {
        notes.push(format!(
            "the firmware applies eq. (5) itself (table tilt axis = input, φ0 = first reading {:.2}\")",
            table.tilt.reference.0
        ));
    } else {
        notes.push("tilt axis = none: at 1 g a tilt changes a_i only as cos φ".into());
    }
    if let Some((name, n)) = status_counts.iter().find(|(n, _)| n == "TEMP_OUT_OF_RANGE") {
        notes.push(format!(
            "{name} on {n} frames: {:.1} °C is outside Table 1's 30–65 °C, so the models are \
             evaluated at the clamped edge and the thermal correction is constant",
            sc.thermostat.setpoint_c
        ));
    }

    // The recorded log: simulated time, the firmware's frames, and the truth beside them.
    let mut log = Log::with_time(time_s.clone())?;
    for (k, v) in &sim_meta {
        log.set_meta(k, v)?;
    }
    log.set_meta(
        "truth_scale_factor_v_per_g",
        sim_meta
            .iter()
            .find(|(k, _)| k == "scale_factor_v_per_g")
            .map_or("", |(_, v)| v.as_str()),
    )?;
    log.set_meta("scale_factor_v_per_g", &format!("{k1_t0:.9}"))?;
    log.set_meta("calibration_id", &format!("{:08x}", table.id()))?;
    log.set_meta("calibration_file", &table_path.display().to_string())?;
    log.set_meta("reference_c", &table.thermal.reference.0.to_string())?;
    log.set_meta("tilt_axis", if zero_g { "input" } else { "none" })?;
    log.set_meta(
        "time_base",
        "time_s is simulated time (host maps each InjectSample id to its simulated sample); \
         fw_time_s is the firmware's own clock in QEMU",
    )?;
    log.set_meta("recorded_by", "accomp demo (firmware in QEMU)")?;
    log.push_column("output_v", output_v.clone())?;
    log.push_column("temperature_c", temperature.clone())?;
    log.push_column("rtd_ohms", col(|f| f.rtd_ohms))?;
    log.push_column("tilt_arcsec", tilt.clone())?;
    log.push_column("a_i_exact_g", a_i)?;
    log.push_column("output_linearized_v", lin_v)?;
    for (name, v) in extra_cols {
        log.push_column(name, v)?;
    }
    log.push_column("floor_a_i_g", floor)?;
    log.push_text_column(
        "status",
        TextColumn::from_strings(
            &frames
                .iter()
                .map(|f| status_names(f.status))
                .collect::<Vec<_>>(),
        ),
    )?;
    log.push_column("fw_seq", col(|f| f64::from(f.seq)))?;
    log.push_column("fw_time_s", col(|f| f.time_us as f64 * 1e-6))?;
    log.push_column(
        "accel_code",
        samples.iter().map(|s| f64::from(s.accel_code)).collect(),
    )?;
    log.push_column(
        "rtd_code",
        samples.iter().map(|s| f64::from(s.rtd_code)).collect(),
    )?;
    log.push_column(
        "tilt_code",
        samples.iter().map(|s| f64::from(s.tilt_code)).collect(),
    )?;
    let truth: [TruthColumn; 5] = [
        ("truth_input_g", |s| s.truth_input_g),
        ("truth_temperature_c", |s| s.truth_temperature_c),
        ("truth_tilt_arcsec", |s| s.truth_tilt_arcsec),
        ("truth_noise_g", |s| s.truth_noise_g),
        ("truth_room_c", |s| s.truth_room_c),
    ];
    for (name, f) in truth {
        log.push_column(name, samples.iter().map(f).collect())?;
    }
    let log_path = args.out_dir.join(format!("{}.csv", run.name));
    log.write_path(&log_path)?;

    let plots = if args.no_plots {
        Vec::new()
    } else {
        let mut opts = PlotOptions::new(&args.out_dir, run.name);
        opts.compensated = vec!["a_i_exact_g".into(), "output_linearized_v".into()];
        plot::plot_log(&log, &opts)?.written
    };

    let sim_span = time_s.last().copied().unwrap_or(0.0) + run.interval_s;
    Ok(Experiment {
        name: run.name.to_owned(),
        instrument: sc.accelerometer.instrument.clone(),
        input_g: table.orientation.nominal_input.0,
        setpoint_c: sc.thermostat.setpoint_c,
        samples: frames.len(),
        interval_s: run.interval_s,
        duration_days: sc.run.duration_s / 86_400.0,
        table_id: format!("{:08x}", table.id()),
        figures,
        host_mismatches,
        retried_chunks,
        device_frames_dropped: info.frames_dropped,
        host_bad_frames: qemu_client.bad_frames,
        status_counts,
        tilt_pp_arcsec: peak_to_peak(&tilt),
        temperature_std_c: std_of(&temperature),
        stream_wall_s,
        time_compression: sim_span / stream_wall_s.max(1e-9),
        notes,
        log: log_path,
        plots,
    })
}

/// Formats a stability in the unit the paper uses for the experiment (g for 1 g, µg for 0 g).
fn fmt_g(v: f64, micro: bool) -> String {
    if micro {
        format!("{:.2} µg", v * 1e6)
    } else {
        format!("{v:.2e} g")
    }
}

impl Report {
    /// The text printed at the end of the demo.
    pub fn to_text(&self) -> String {
        let mut s = String::new();
        s.push_str(&format!(
            "accomp demo — seed {}, firmware {}\n",
            self.seed,
            self.firmware.display()
        ));
        let orders: Vec<String> = self
            .fit_orders
            .iter()
            .map(|(n, o)| format!("{n} order {o}"))
            .collect();
        s.push_str(&format!(
            "Table 1 fit ({}): {} → {}\n",
            self.table1.display(),
            orders.join(", "),
            self.calibration.display()
        ));
        for e in &self.experiments {
            let micro = e.input_g.abs() < 0.5;
            s.push_str(&format!(
                "\n{} — {}, {:.0} g input, {} °C, {} days: {} samples every {} s (time-compressed {:.0}×: {:.1} s of streaming)\n",
                e.name,
                e.instrument,
                e.input_g,
                e.setpoint_c,
                e.duration_days,
                e.samples,
                e.interval_s,
                e.time_compression,
                e.stream_wall_s
            ));
            s.push_str(&format!(
                "  table {} uploaded and read back; firmware frames identical to the host core: {}\n",
                e.table_id,
                if e.host_mismatches == 0 {
                    "all".to_owned()
                } else {
                    format!("NO ({} differ)", e.host_mismatches)
                }
            ));
            if e.retried_chunks > 0 || e.device_frames_dropped > 0 || e.host_bad_frames > 0 {
                s.push_str(&format!(
                    "  link: {} chunk(s) of {STREAM_CHUNK} readings sent again, device dropped {} frame(s), host could not decode {}\n",
                    e.retried_chunks, e.device_frames_dropped, e.host_bad_frames
                ));
            }
            s.push_str(&format!(
                "  measured temperature std {:.4} °C, tilt peak-to-peak {:.2}\"\n",
                e.temperature_std_c, e.tilt_pp_arcsec
            ));
            s.push_str(&format!(
                "  {:<52} {:>12} {:>12}\n",
                "stability (std of equally spaced readings)", "this run", "paper"
            ));
            for f in &e.figures {
                s.push_str(&format!(
                    "  {:<52} {:>12} {:>12}\n",
                    f.label,
                    fmt_g(f.std_g, micro),
                    f.paper_g.map_or("–".into(), |p| fmt_g(p, micro))
                ));
            }
            for n in &e.notes {
                s.push_str(&format!("  note: {n}\n"));
            }
            if !e.status_counts.is_empty() {
                let c: Vec<String> = e
                    .status_counts
                    .iter()
                    .map(|(n, k)| format!("{n} ×{k}"))
                    .collect();
                s.push_str(&format!("  status flags: {}\n", c.join(", ")));
            }
            s.push_str(&format!("  log: {}\n", e.log.display()));
            if !e.plots.is_empty() {
                let p: Vec<String> = e.plots.iter().map(|p| p.display().to_string()).collect();
                s.push_str(&format!("  figures: {}\n", p.join(", ")));
            }
        }
        s.push_str(&format!("\ndemo wall time {:.1} s\n", self.wall_s));
        s
    }
}

/// Runs the demo; returns the report (also printed and written to the output directory).
pub fn run_demo(args: &DemoArgs) -> anyhow::Result<Report> {
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

/// `accomp demo`.
pub fn run(args: &DemoArgs) -> anyhow::Result<()> {
    let report = run_demo(args)?;
    print!("{}", report.to_text());
    println!(
        "report: {} and {}",
        args.out_dir.join("report.txt").display(),
        args.out_dir.join("report.json").display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fitted() -> CalibrationTable {
        let path = default_table1();
        fit_table1(&path).expect("Table 1 fits").0
    }

    fn first_sample(preset: &str) -> (Scenario, Sample) {
        let sc = Scenario::preset(preset).expect("preset");
        let s = Simulator::new(&sc, 1)
            .and_then(|mut sim| sim.step())
            .expect("one sample");
        (sc, s)
    }

    #[test]
    fn the_1g_table_ignores_tilt_and_keeps_t0_at_60_c() {
        let (sc, s) = first_sample("paper-1g");
        let t = experiment_table(&fitted(), &sc, &s).expect("table");
        assert_eq!(t.tilt.axis, TiltAxis::None);
        assert_eq!(t.orientation.nominal_input, Gs(1.0));
        assert_eq!(t.orientation.cross, CrossAxis::default());
        assert_eq!(t.thermal.reference, Celsius(60.0));
    }

    #[test]
    fn the_0g_table_applies_eq5_from_the_first_reading_with_t0_inside_the_range() {
        let (sc, s) = first_sample("paper-0g");
        let t = experiment_table(&fitted(), &sc, &s).expect("table");
        assert_eq!(t.tilt.axis, TiltAxis::Input);
        // φ0 is the first reading as the board converts it: the simulator's measured tilt.
        assert!((t.tilt.reference.0 - s.tilt_arcsec).abs() < 1e-6);
        assert_eq!(t.orientation.nominal_input, Gs(0.0));
        // Spindle along the output axis, input horizontal: the pendulum axis carries 1 g.
        assert_eq!(t.orientation.cross.a_p, Gs(1.0));
        // 25 °C is below Table 1's 30–65 °C: T0 moves to the edge.
        assert_eq!(t.thermal.reference, Celsius(30.0));
    }

    #[test]
    fn frames_with_the_same_nan_values_compare_equal_and_a_one_ulp_change_does_not() {
        let f = Frame {
            seq: 1,
            time_us: 2,
            output_v: 1.0,
            temperature_c: 60.0,
            rtd_ohms: 123.0,
            tilt_arcsec: f64::NAN,
            a_i_exact_g: 1.0,
            output_linearized_v: 1.3,
            status: Status::default(),
        };
        let mut g = f;
        g.seq = 9;
        g.time_us = 99;
        assert!(same_values(&f, &g));
        g.a_i_exact_g = f64::from_bits(1.0f64.to_bits() + 1);
        assert!(!same_values(&f, &g));
    }
}
