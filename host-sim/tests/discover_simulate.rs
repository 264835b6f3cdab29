//! `discover --simulate` on a record with a hidden effect: the mismatch between the record and
//! its simulated twin must appear in the band where the hidden effect lives, and vanish once the
//! twin is extended by what the catalogue search names.
//!
//! Non-circular: the effect is injected into the **real** gMetrology record (its own noise,
//! drift and tide errors — not the simulator's noise), with a shape the catalogue does not
//! parametrise (a non-sinusoidal, slowly amplitude-modulated 5.3 h wave: `periodic` is one
//! sinusoid of constant amplitude). The tool is not told what was hidden. Cheap: the first
//! 12 days binned to ~5 min, 8 members.

use accomp_host::discover::import::{self, Dataset, DatasetOptions};
use accomp_host::discover::select;
use accomp_host::discover::simulate::mismatch::Quantity;
use accomp_host::discover::simulate::Simulation;
use accomp_host::discover::simulate::{simulate_dataset, write_scenario};

#[path = "common/scratch.rs"]
mod scratch;

#[path = "common/real.rs"]
mod real;

/// Hidden period (s) and amplitude (mGal): 5.3 h ≈ 4.5 cycles/day, between the ter- and
/// quarter-diurnal tides; 6 µGal, a few times the residual's noise in that band.
const HIDDEN_PERIOD_S: f64 = 5.3 * 3600.0;
const HIDDEN_AMPLITUDE: f64 = 0.006;
const DAYS: f64 = 12.0;

fn record() -> Dataset {
    real::first_days(DAYS, 15_000)
}

/// A rounded, skewed wave (fundamental + 2nd harmonic) whose amplitude drifts by ±25 % over the
/// record.
fn hidden(t: f64) -> f64 {
    let w = 2.0 * std::f64::consts::PI / HIDDEN_PERIOD_S;
    let env = 1.0 + 0.25 * (2.0 * std::f64::consts::PI * t / (DAYS * 86_400.0 * 1.7)).sin();
    HIDDEN_AMPLITUDE * env * ((w * t).sin() + 0.3 * (2.0 * w * t + 1.0).sin())
}

/// PSD mismatches above the envelope that contain the frequency f (cycles/day).
fn psd_above_at(s: &Simulation, after: bool, f_cpd: f64) -> usize {
    psd_mismatches_above_at(s, after, f_cpd).len()
}

/// The PSD mismatches above the envelope whose band holds `f_cpd`.
fn psd_mismatches_above_at(
    s: &Simulation,
    after: bool,
    f_cpd: f64,
) -> Vec<&accomp_host::discover::simulate::mismatch::Mismatch> {
    let c = if after { &s.after } else { &s.before };
    c.mismatches
        .iter()
        .filter(|m| m.quantity == Quantity::Psd && m.direction == "above")
        .filter(|m| {
            // The range is given by band centres: widen by half a band either side.
            let half = 10f64.powf(0.5 / 8.0);
            m.from / half <= f_cpd && f_cpd <= m.to * half
        })
        .collect()
}

#[test]
fn hidden_wave_in_the_real_record_is_a_mismatch_in_its_band_that_the_extension_removes() {
    let mut ds = record();
    for (y, &t) in ds.y.iter_mut().zip(&ds.t_s) {
        *y += hidden(t);
    }
    let s = simulate_dataset(&ds, None, 8, &select::Config::default()).expect("simulate");
    let unit = ds.output_unit.clone();
    eprintln!(
        "{}",
        accomp_host::discover::simulate::output::text(&s, &unit)
    );
    let f_hidden = 86_400.0 / HIDDEN_PERIOD_S;
    assert_eq!(
        psd_above_at(&s, false, f_hidden),
        1,
        "no PSD mismatch at the hidden {f_hidden:.2} cycles/day before the extension"
    );
    // After the extension the line is gone; what the one `periodic` line cannot take — the
    // wave's ±25 % amplitude drift, sidebands within its band — may stay above the envelope,
    // at a small fraction of the excess before and named unmodelled (the members pass through
    // the line's fit like the record, so its fitted amplitude and phase take the same share of
    // noise from both and no parameter spread widens the members' band).
    let before = psd_mismatches_above_at(&s, false, f_hidden)[0].factor;
    for m in psd_mismatches_above_at(&s, true, f_hidden) {
        assert!(
            m.factor < before / 20.0 && m.unmodelled.is_some(),
            "the mismatch at {f_hidden:.2} cycles/day after the extension: ×{} (×{before} \
             before), named {:?}",
            m.factor,
            m.unmodelled
        );
    }
    // The cause: the mismatch at the hidden band is explained by an accepted periodic line at
    // its period (within 2 %).
    let idx = s
        .before
        .mismatches
        .iter()
        .position(|m| {
            m.quantity == Quantity::Psd
                && m.direction == "above"
                && m.from / 1.2 <= f_hidden
                && f_hidden <= m.to * 1.2
        })
        .expect("the mismatch");
    let line = s
        .cause
        .selection
        .accepted
        .iter()
        .find(|a| {
            a.effect.name() == "periodic" && (a.theta.value / HIDDEN_PERIOD_S - 1.0).abs() < 0.02
        })
        .expect("a periodic line at the hidden period");
    assert!(line.theta.value > 0.0);
    assert!(
        s.explained_by
            .iter()
            .any(|(n, idxs)| n.starts_with("periodic") && idxs.contains(&idx)),
        "{:?}",
        s.explained_by
    );
    // The gain: lower out-of-sample residual after.
    assert!(s.after_scores.residual_std_out_of_sample < s.before_scores.residual_std_out_of_sample);
    // The extended twin is written and `accomp simulate` runs a member of it; it holds the line.
    let dir = scratch::Scratch::new("discover-simulate");
    let toml = dir.join("extended.toml");
    let mut s = s;
    write_scenario(&mut s, Some(&toml)).expect("write scenario");
    let text = std::fs::read_to_string(&toml).unwrap();
    let sc = accomp_host::sim::scenario::Scenario::from_toml(&text).expect("scenario parses");
    assert!(sc.effects.iter().any(|e| matches!(e,
        accomp_host::sim::effects::ScenarioEffect::Periodic { period_s, .. }
            if (period_s / HIDDEN_PERIOD_S - 1.0).abs() < 0.02)));
    let out = dir.join("extended.csv");
    let st = std::process::Command::new(env!("CARGO_BIN_EXE_accomp"))
        .args(["simulate", toml.to_str().unwrap(), "-o"])
        .arg(&out)
        .status()
        .expect("accomp simulate");
    assert!(st.success(), "accomp simulate refused the written scenario");
    let log = std::fs::read_to_string(&out).unwrap();
    assert!(
        log.lines().any(|l| l.starts_with("t_s,gravity_mgal")),
        "no gravity column"
    );
}

#[test]
fn without_the_hidden_wave_there_is_no_mismatch_in_that_band() {
    let ds = record();
    let s = simulate_dataset(&ds, None, 8, &select::Config::default()).expect("simulate");
    let f_hidden = 86_400.0 / HIDDEN_PERIOD_S;
    assert_eq!(
        psd_above_at(&s, false, f_hidden),
        0,
        "{}",
        accomp_host::discover::simulate::output::text(&s, &ds.output_unit)
    );
}

// ---------------------------------------------------------------------------------------------
// A simulated accelerometer log (paper-1g-like) with a hidden second-order thermal path.
//
// The station simulator writes a 1 g log; the test then adds to its output column a bias that
// follows the *true* mount temperature (the log's truth column, not the RTD reading the twin
// sees) through two thermal masses in series (time constants 10 min and 4 min): b =
// c·(L₂L₁[T] − T). The catalogue's `thermal_lag` is one first-order lag of the measured
// temperature: it describes this path only approximately (its shape check says so on some
// seeds). The tool gets the log, nothing else; seeds 7–11 were tried, all pass with the margins
// below (after the extension at most ×1.3 beyond the envelope edge, control ×1.25).
// The effect's band is measured from the injected series itself (its PSD against the control
// run's envelope), never from what the tool reports.
// ---------------------------------------------------------------------------------------------

use accomp_host::discover::simulate::ensemble::Yardstick;
use accomp_host::log::Log;
use accomp_host::sim::scenario::Scenario;

const ACCEL_DAYS: f64 = 4.0;
const ACCEL_INTERVAL_S: f64 = 120.0;
const PATH_TAU1_S: f64 = 10.0 * 60.0;
const PATH_TAU2_S: f64 = 4.0 * 60.0;
/// Output volts per °C of lag error (≈ 45 µg/°C at the preset's ≈ 1.3 V/g): a few µg against
/// the thermostat's 0.17 °C, 15 min fluctuation.
const PATH_COEFFICIENT_V_PER_C: f64 = 6.0e-5;
const ACCEL_SEED: u64 = 7;

/// The paper-1g log (4 days at 2 min), optionally with the hidden thermal path added to its
/// output column.
fn accelerometer_log(hidden: bool) -> (Dataset, Vec<f64>) {
    let mut s = Scenario::preset("paper-1g").expect("preset");
    s.run.duration_s = ACCEL_DAYS * 86_400.0;
    s.run.interval_s = ACCEL_INTERVAL_S;
    s.tide.step_s = ACCEL_INTERVAL_S;
    // What the twin does not model (docs/simulator.md, "What the twin does not do"): it reads
    // the RTD as the proof mass's temperature and treats the ADC as ideal. Left in, they are
    // hidden thermal effects of their own (a 60 s proof-mass lag, the reference's tempco) that
    // the control would rightly report.
    s.thermostat.proof_mass_lag_s = 0.0;
    s.adc.ads1262.vref_tempco_ppm_per_c = 0.0;
    s.rtd.accuracy_c = 0.0;
    let log = accomp_host::sim::simulate_log(&s, ACCEL_SEED).expect("simulate");
    let t = log.time_s().to_vec();
    let truth = log.column("truth_mount_temperature_c").expect("truth T");
    // Two first-order lags in series (exact for a temperature held over each interval).
    let (mut x1, mut x2) = (truth[0], truth[0]);
    let mut effect = vec![0.0; t.len()];
    for i in 0..t.len() {
        if i > 0 {
            let dt = t[i] - t[i - 1];
            let a1 = (-dt / PATH_TAU1_S).exp();
            let a2 = (-dt / PATH_TAU2_S).exp();
            x1 = a1 * x1 + (1.0 - a1) * truth[i];
            x2 = a2 * x2 + (1.0 - a2) * x1;
        }
        effect[i] = PATH_COEFFICIENT_V_PER_C * (x2 - truth[i]);
    }
    let mut out = Log::with_time(t.clone()).expect("time");
    for (k, v) in log.metadata() {
        out.set_meta(k, v).expect("meta");
    }
    for name in log.column_names().iter().filter(|n| n.as_str() != "time_s") {
        let mut v = log.column(name).expect("column").to_vec();
        if hidden && name == "output_v" {
            for (y, e) in v.iter_mut().zip(&effect) {
                *y += e;
            }
        }
        out.push_column(name, v).expect("push");
    }
    let ds = import::dataset_from_log(&out, &DatasetOptions::default()).expect("dataset");
    assert_eq!(ds.output_name, "output_v");
    // The effect at the dataset's rows (no binning at this length: the same instants).
    let e: Vec<f64> = ds
        .t_s
        .iter()
        .map(|&x| effect[((x - t[0]) / ACCEL_INTERVAL_S).round() as usize])
        .collect();
    (ds, e)
}

/// PSD bands (indices) where the injected effect alone is ≥ 4× the control residual's 95 %
/// envelope edge: where the effect lives, measured from the effect itself.
fn effect_bands(ds: &Dataset, effect: &[f64], control: &Simulation) -> Vec<usize> {
    let yard = Yardstick::new(ds);
    let v = yard.views(&yard.detrend(effect));
    v.psd
        .iter()
        .zip(&control.before.psd.high)
        .enumerate()
        .filter(|(_, (e, hi))| **e >= 4.0 * **hi)
        .map(|(i, _)| i)
        .collect()
}

fn psd_above_runs(
    c: &accomp_host::discover::simulate::mismatch::Comparison,
) -> Vec<(usize, usize)> {
    c.mismatches
        .iter()
        .filter(|m| m.quantity == Quantity::Psd && m.direction == "above")
        .map(|m| m.index)
        .collect()
}

/// Measured PSD / the envelope's 95 % edge in each band (> 1: outside above).
fn beyond_high(c: &accomp_host::discover::simulate::mismatch::Comparison) -> Vec<f64> {
    c.measured
        .psd
        .iter()
        .zip(&c.psd.high)
        .map(|(m, h)| m / h)
        .collect()
}

#[test]
fn a_hidden_thermal_path_in_a_simulated_accelerometer_log_is_found_in_its_band_and_removed() {
    let (ds0, _) = accelerometer_log(false);
    let control = simulate_dataset(&ds0, None, 20, &select::Config::default()).expect("control");
    let (ds, effect) = accelerometer_log(true);
    let s = simulate_dataset(&ds, None, 20, &select::Config::default()).expect("simulate");
    eprintln!(
        "{}",
        accomp_host::discover::simulate::output::text(&s, &ds.output_unit)
    );
    let band = effect_bands(&ds, &effect, &control);
    let hz = &s.frequencies_hz;
    let cpd = |i: usize| hz[i] * 86_400.0;
    let (b0, b1, bc) = (
        beyond_high(&s.before),
        beyond_high(&s.after),
        beyond_high(&control.before),
    );
    for &i in &band {
        eprintln!(
            "{:7.2} cycles/day: measured / 95 % edge before {:6.2}, after {:5.2}, control {:5.2}",
            cpd(i),
            b0[i],
            b1[i],
            bc[i]
        );
    }
    assert!(
        band.len() >= 3,
        "the hidden path is too weak to matter ({} bands)",
        band.len()
    );
    let inside = |runs: &[(usize, usize)], i: usize| runs.iter().any(|&(a, b)| a <= i && i < b);
    // Before the extension every band of the effect is inside a PSD mismatch above the
    // envelope, and well outside it (×2 beyond the 95 % edge at least).
    let runs = psd_above_runs(&s.before);
    let missed: Vec<String> = band
        .iter()
        .filter(|&&i| !inside(&runs, i) || b0[i] < 2.0)
        .map(|&i| format!("{:.2}", cpd(i)))
        .collect();
    assert!(
        missed.is_empty(),
        "effect bands not clearly outside before the extension: {missed:?} cycles/day"
    );
    // The cause is named: an accepted lag of the temperature (one stage, or the catalogue's two
    // equal stages, closer to the two masses in series) explains the mismatch over the band.
    let is_lag = |n: &str| n.starts_with("thermal_lag") || n.starts_with("lag2_coupling");
    assert!(
        s.cause
            .selection
            .accepted
            .iter()
            .any(|a| is_lag(a.effect.name())),
        "no lag of the temperature accepted"
    );
    let idx: Vec<usize> = s
        .before
        .mismatches
        .iter()
        .enumerate()
        .filter(|(_, m)| {
            m.quantity == Quantity::Psd
                && m.direction == "above"
                && band.iter().any(|&i| m.index.0 <= i && i < m.index.1)
        })
        .map(|(k, _)| k)
        .collect();
    assert!(
        s.explained_by
            .iter()
            .any(|(n, k)| is_lag(n) && idx.iter().any(|i| k.contains(i))),
        "{:?} (mismatches {idx:?})",
        s.explained_by
    );
    // After the extension, and in the control without the path, the effect's band is at most
    // marginally beyond the envelope: no band by more than the ×1.5 a lone point needs to be
    // reported (mismatch.rs, SINGLE_POINT_FACTOR), where the hidden path put it ×2 and more.
    // (A 5–95 % envelope leaves about one band in ten outside by chance; the first-order lag
    // only approximates the two-mass path.)
    let worst = |b: &[f64]| band.iter().map(|&i| b[i]).fold(0.0, f64::max);
    assert!(
        worst(&b1) < 1.5,
        "still outside after the extension: ×{:.2}",
        worst(&b1)
    );
    assert!(
        worst(&bc) < 1.5,
        "the control is outside in the effect's band: ×{:.2}\n{}",
        worst(&bc),
        accomp_host::discover::simulate::output::text(&control, &ds0.output_unit)
    );
    // The extended twin holds the whole log, not only the effect's band: at most a fifth of
    // its ADEV points and of its PSD bands outside the envelope (70 % and 72 % before).
    assert!(
        s.after.adev_outside_fraction <= 0.2 && s.after.psd_outside_fraction <= 0.2,
        "after the extension ADEV {:.0} %, PSD {:.0} % outside",
        100.0 * s.after.adev_outside_fraction,
        100.0 * s.after.psd_outside_fraction
    );
    // The gain: the out-of-sample residual drops.
    let (b, a) = (
        s.before_scores.residual_std_out_of_sample,
        s.after_scores.residual_std_out_of_sample,
    );
    assert!(a < 0.8 * b, "out-of-sample std {b:e} → {a:e}");
}
