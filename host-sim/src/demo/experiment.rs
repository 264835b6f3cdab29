//! One experiment, step by step: simulate the station, derive and upload its table, stream the
//! raw codes through the firmware, compute the stability figures, record the log, plot.

use super::*;

use super::record::{frame_column, record_log, ExtraColumns, Metadata};
use super::stream::{bar, raw, same_values, stream};
use super::tables::experiment_table;

pub(super) struct Run<'a> {
    pub(super) name: &'a str,
    pub(super) interval_s: f64,
    pub(super) days: Option<f64>,
    pub(super) paper: (f64, f64),
}

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

/// The station simulated for one experiment, sampled at the experiment's interval.
pub(super) struct Station {
    pub(super) sc: Scenario,
    pub(super) samples: Vec<Sample>,
    pub(super) meta: Metadata,
}

/// Step 1: the station simulated at the preset's step (60 s) or finer, every n-th reading kept.
fn simulate_station(args: &DemoOptions, run: &Run<'_>) -> anyhow::Result<Station> {
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
    let (all, mut meta) = simulate(&sc, args.seed)?;
    let samples: Vec<Sample> = all.into_iter().step_by(every as usize).collect();
    for (k, v) in &mut meta {
        if k == "interval_s" {
            *v = run.interval_s.to_string();
        }
    }
    meta.push(("simulation_step_s".into(), sim_step.to_string()));
    Ok(Station { sc, samples, meta })
}

/// Step 2: the experiment's table, written beside the log and uploaded (verified by read-back:
/// `Client::load` compares byte by byte).
fn upload_table(
    qemu_client: &mut device::Client,
    base: &CalibrationTable,
    station: &Station,
    args: &DemoOptions,
    run: &Run<'_>,
) -> anyhow::Result<(CalibrationTable, PathBuf)> {
    let first = station
        .samples
        .first()
        .context("the scenario has no samples")?;
    let table = experiment_table(base, &station.sc, first)?;
    let table_path = args.out_dir.join(format!("{}.acal", run.name));
    fs::write(&table_path, table.encode())
        .with_context(|| format!("cannot write {}", table_path.display()))?;
    let id = qemu_client.load(&table.encode(), |_, _| {})?;
    anyhow::ensure!(
        id == table.id(),
        "device activated table {id:08x}, uploaded {:08x}",
        table.id()
    );
    Ok((table, table_path))
}

/// What came back from the firmware.
pub(super) struct Streamed {
    pub(super) raws: Vec<RawSample>,
    pub(super) frames: Vec<Frame>,
    retried_chunks: usize,
    frames_dropped: u32,
    stream_wall_s: f64,
    /// Frames whose values differ from the same core run on the PC (must be 0).
    host_mismatches: usize,
}

/// Step 3: the raw codes through the firmware, every frame checked against the same core on
/// the PC (the firmware must give the same bits).
fn stream_through_firmware(
    qemu_client: &mut device::Client,
    samples: &[Sample],
    table: &CalibrationTable,
    run: &Run<'_>,
) -> anyhow::Result<Streamed> {
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
    let host_mismatches = raws
        .iter()
        .zip(&frames)
        .enumerate()
        .filter(|(i, (r, f))| !same_values(&pipeline::process(*i as u32, 0, r, Some(table)), f))
        .count();
    Ok(Streamed {
        raws,
        frames,
        retried_chunks,
        frames_dropped: info.frames_dropped,
        stream_wall_s,
        host_mismatches,
    })
}

/// K1 at the table's reference temperature: volts → g for the uncompensated figures.
fn reference_scale_factor(table: &CalibrationTable) -> anyhow::Result<f64> {
    Ok(table
        .thermal
        .coefficients_at(table.thermal.reference)
        .map_err(|e| anyhow::anyhow!("K1 at T0: {e:?}"))?
        .0
        .scale_factor_v_per_g)
}

/// Step 4: the stability figures before and after compensation, beside the paper's and the
/// floor; at 0 g also what eq. (5) contributes (the same codes through the same core without
/// the tilt term), which the log records too.
fn stability_figures(
    table: &CalibrationTable,
    streamed: &Streamed,
    floor: &[f64],
    run: &Run<'_>,
    zero_g: bool,
    k1_t0: f64,
) -> (Vec<Figure>, ExtraColumns) {
    let frames = &streamed.frames;
    let to_g = |v: &[f64]| v.iter().map(|x| x / k1_t0).collect::<Vec<f64>>();
    let mut figures = vec![
        Figure {
            label: "before compensation (E / K1(T0))".into(),
            column: "output_v".into(),
            std_g: std_of(&to_g(&frame_column(frames, |f| f.output_v))),
            paper_g: Some(run.paper.0),
        },
        Figure {
            label: if zero_g {
                "after: firmware exact a_i (thermal + eq. 5 tilt)".into()
            } else {
                "after: firmware exact a_i".into()
            },
            column: "a_i_exact_g".into(),
            std_g: std_of(&frame_column(frames, |f| f.a_i_exact_g)),
            paper_g: Some(run.paper.1),
        },
        Figure {
            label: "after: firmware linearized eq. (3)/(4) / K1(T0)".into(),
            column: "output_linearized_v".into(),
            std_g: std_of(&to_g(&frame_column(frames, |f| f.output_linearized_v))),
            paper_g: None,
        },
    ];
    let mut extra_cols = Vec::new();
    if zero_g {
        let mut no_tilt = *table;
        no_tilt.tilt.axis = TiltAxis::None;
        let thermal_only: Vec<f64> = streamed
            .raws
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
        std_g: std_of(floor),
        paper_g: None,
    });
    (figures, extra_cols)
}

/// Step 5: how many frames carry each status flag, most frequent first.
fn status_counts(frames: &[Frame]) -> Vec<(String, usize)> {
    let mut counts: Vec<(String, usize)> = Status::NAMES
        .iter()
        .map(|(bit, name)| {
            (
                (*name).to_owned(),
                frames.iter().filter(|f| f.status.has(*bit)).count(),
            )
        })
        .filter(|(_, n)| *n > 0)
        .collect();
    counts.sort_by_key(|c| std::cmp::Reverse(c.1));
    counts
}

/// What the reader of the report must know about this experiment's compensation.
fn experiment_notes(
    table: &CalibrationTable,
    sc: &Scenario,
    zero_g: bool,
    status_counts: &[(String, usize)],
) -> Vec<String> {
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
    notes
}

/// One experiment: the steps above, then the log (step 6, `record`) and its plots.
pub(super) fn run_experiment(
    qemu_client: &mut device::Client,
    base: &CalibrationTable,
    args: &DemoOptions,
    run: &Run<'_>,
) -> anyhow::Result<Experiment> {
    let station = simulate_station(args, run)?;
    let (table, table_path) = upload_table(qemu_client, base, &station, args, run)?;
    let zero_g = table.orientation.nominal_input.0.abs() < 0.5;
    let streamed = stream_through_firmware(qemu_client, &station.samples, &table, run)?;
    let k1_t0 = reference_scale_factor(&table)?;
    let floor = floor_g(&station.sc, &station.samples, zero_g)?;
    let (figures, extra_cols) = stability_figures(&table, &streamed, &floor, run, zero_g, k1_t0);
    let status_counts = status_counts(&streamed.frames);
    let notes = experiment_notes(&table, &station.sc, zero_g, &status_counts);

    let log = record_log(
        &station.samples,
        &station.meta,
        &table,
        &table_path,
        &streamed.frames,
        k1_t0,
        zero_g,
        extra_cols,
        floor,
    )?;
    let log_path = args.out_dir.join(format!("{}.csv", run.name));
    log.write_path(&log_path)?;
    let plots = if args.no_plots {
        Vec::new()
    } else {
        let mut opts = PlotOptions::new(&args.out_dir, run.name);
        opts.compensated = vec!["a_i_exact_g".into(), "output_linearized_v".into()];
        plot::plot_log(&log, &opts)?.written
    };

    let frames = &streamed.frames;
    let sim_span = station.samples.last().map_or(0.0, |s| s.time_s) + run.interval_s;
    Ok(Experiment {
        name: run.name.to_owned(),
        instrument: station.sc.accelerometer.instrument.clone(),
        input_g: table.orientation.nominal_input.0,
        setpoint_c: station.sc.thermostat.setpoint_c,
        samples: frames.len(),
        interval_s: run.interval_s,
        duration_days: station.sc.run.duration_s / 86_400.0,
        table_id: format!("{:08x}", table.id()),
        figures,
        host_mismatches: streamed.host_mismatches,
        retried_chunks: streamed.retried_chunks,
        device_frames_dropped: streamed.frames_dropped,
        host_bad_frames: qemu_client.bad_frames,
        status_counts,
        tilt_pp_arcsec: peak_to_peak(&frame_column(frames, |f| f.tilt_arcsec)),
        temperature_std_c: std_of(&frame_column(frames, |f| f.temperature_c)),
        stream_wall_s: streamed.stream_wall_s,
        time_compression: sim_span / streamed.stream_wall_s.max(1e-9),
        notes,
        log: log_path,
        plots,
    })
}
