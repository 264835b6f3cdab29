//! Errors of the calibration table: a table whose bias temperature coefficient has drifted since
//! calibration leaves a residual ∝ (T − T0) on a cycling temperature; `discover --calibration`
//! names it as that table error (K0, power 1, its size), not as a thermal lag or a loop, and the
//! table it writes with `--write-table`, loaded, removes it.
//!
//! The record is made independently of the detector (`synth.rs`: a regulated thermostat with a
//! ±0.5 °C cycling programme, white + 1/f flicker + random-walk sensor noise, an RTD with offset
//! and reading noise) with the output the true table's eq. (1) predicts at the true temperature
//! (the core's model, which is what a table means).

#[path = "common/scratch.rs"]
mod scratch;
#[path = "common/synth.rs"]
mod synth;

use accomp::table::CalibrationTable;
use accomp::units::{Celsius, Gs};
use accomp_host::discover::{self as disc, Discovery};
use accomp_host::log::Log;
use rand_chacha::ChaCha8Rng;
use std::process::Command;

/// Three days at one row a minute.
const ROWS: usize = 3 * 1440;
const DT_S: f64 = 60.0;
/// The drift of the bias temperature coefficient since calibration, g/°C.
const DRIFT_G_PER_C: f64 = 3.0e-6;

/// The station, the true table (T0 at the station's mean temperature) and the record in g.
fn record(seed: u64) -> (Log, CalibrationTable) {
    let mut rng = synth::rng(seed);
    let st = synth::station(ROWS, DT_S, synth::EIGHT_HOUR_CYCLE, &mut rng);
    let truth = paper_table_at_mean(&st);
    (record_through(&truth, &st, &mut rng, |_| 0.0), truth)
}

/// The paper's order-2 table with T0 at the station's mean true temperature (rounded).
fn paper_table_at_mean(st: &synth::Station) -> CalibrationTable {
    let mean = st.temp_true_c.iter().sum::<f64>() / ROWS as f64;
    let mut table = accomp::reference::paper_order2_table();
    table.thermal = accomp::reference::paper_order2_models(Celsius(mean.round()));
    table
}

/// The record of a 1 g input read through `table`'s eq. (1) at the station's true temperatures,
/// with `error(T)` (g) and the sensor noise (drawn from `rng`) added: time, the output in g and
/// the measured temperature.
fn record_through(
    table: &CalibrationTable,
    st: &synth::Station,
    rng: &mut ChaCha8Rng,
    error: impl Fn(f64) -> f64,
) -> Log {
    let noise = synth::sensor_noise(ROWS, DT_S, 2.0e-6, 0.5e-6, 3.0e-9, rng);
    let y: Vec<f64> = st
        .temp_true_c
        .iter()
        .zip(&noise)
        .map(|(&t, e)| {
            let (k, _) = table.thermal.coefficients_at(Celsius(t)).expect("in range");
            k.output(Gs(1.0), table.orientation.cross).0 / k.scale_factor_v_per_g + error(t) + e
        })
        .collect();
    let mut log = Log::with_time(st.t_s.clone()).expect("time");
    log.set_meta("input_g", "1").expect("meta");
    log.push_column("output_g", y).expect("column");
    log.push_column("temperature_c", st.temp_meas_c.clone())
        .expect("column");
    log
}

/// The table as it would be after its bias temperature coefficient drifted by `DRIFT_G_PER_C`:
/// K0 + δ·(T − T0), written into the normalised polynomial by hand (x = (T − Tc)/Ts, so
/// δ·(T − T0) = δ·Ts·x + δ·(Tc − T0)).
fn drifted(truth: &CalibrationTable) -> CalibrationTable {
    let mut t = *truth;
    let s = t.thermal.scale;
    let p = &mut t.thermal.models.bias_g;
    p.coeffs[1] += DRIFT_G_PER_C * s.half_span_c;
    p.coeffs[0] += DRIFT_G_PER_C * (s.center.0 - t.thermal.reference.0);
    t.validate().expect("a valid table");
    t
}

fn run(log: &Log, table: &CalibrationTable) -> Discovery {
    synth::discover(log.clone(), Some(table))
}

fn named(d: &Discovery) -> Vec<&'static str> {
    d.selection
        .accepted
        .iter()
        .map(|a| a.effect.name())
        .collect()
}

/// Discovers `log` against `given`, prints the table check and what was accepted, and asserts
/// that neither a thermal lag nor a hysteresis took the table's error.
fn run_checked(log: &Log, given: &CalibrationTable) -> Discovery {
    let d = run(log, given);
    let check = d.table_check.as_ref().expect("a calibration was given");
    print!("{}", disc::table_error::text_of(check, "g"));
    println!("accepted: {:?}", named(&d));
    assert!(
        !named(&d)
            .iter()
            .any(|n| matches!(*n, "thermal_lag" | "thermal_hysteresis")),
        "{:?}",
        named(&d)
    );
    d
}

#[test]
fn a_drifted_bias_tempco_is_named_as_the_table_error_and_the_corrected_table_removes_it() {
    let (log, truth) = record(3);
    let given = drifted(&truth);
    let d = run_checked(&log, &given);
    let check = d.table_check.as_ref().expect("a calibration was given");
    let t = check.terms.first().expect("a table error");
    assert_eq!((t.symbol, t.power), ("K0", 1), "{t:?}");
    // The table must lose the drift: its change is −δ.
    let err = (t.change + DRIFT_G_PER_C).abs();
    assert!(
        err < (0.2 * DRIFT_G_PER_C).max(3.0 * t.sigma),
        "change {:e} ± {:e} for a drift of {DRIFT_G_PER_C:e}",
        t.change,
        t.sigma
    );
    // The corrected table, through the file format and the core's validator, loaded again.
    let corrected = check.corrected.expect("a corrected table");
    let bytes = corrected.encode();
    let loaded = accomp_host::log::calibration_file::decode_named(&bytes).expect("valid");
    let again = run(&log, &loaded);
    let check2 = again.table_check.as_ref().expect("a calibration was given");
    print!("{}", disc::table_error::text_of(check2, "g"));
    assert!(check2.terms.is_empty(), "{:?}", check2.terms);
    let (before, after) = (
        check.std_given_out_of_sample,
        check.std_corrected_out_of_sample.expect("gain measured"),
    );
    assert!(after < before, "out of sample {before:e} → {after:e}");
    // The true table has no error to find.
    let null = run(&log, &truth);
    let c = null.table_check.as_ref().expect("a calibration was given");
    assert!(c.terms.is_empty(), "{:?}", c.terms);
}

/// `--write-table` from the command line writes the corrected table (a file the core reads);
/// without an error to correct it writes nothing and says why.
#[test]
fn write_table_writes_the_corrected_table_and_refuses_when_there_is_nothing_to_correct() {
    let (log, truth) = record(5);
    let dir = scratch::Scratch::new("table-error");
    let csv = dir.join("log.csv");
    log.write_to(std::fs::File::create(&csv).expect("create"))
        .expect("write log");
    let given = dir.join("given.acal");
    std::fs::write(&given, drifted(&truth).encode()).expect("write table");
    let out = dir.join("corrected.acal");
    let run = |table: &std::path::Path| {
        Command::new(env!("CARGO_BIN_EXE_accomp"))
            .args(["discover", csv.to_str().unwrap(), "--calibration"])
            .arg(table)
            .arg("--write-table")
            .arg(&out)
            .output()
            .expect("run accomp")
    };
    let r = run(&given);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let text = String::from_utf8_lossy(&r.stdout);
    assert!(text.contains("table_error: K0"), "{text}");
    let written = accomp_host::log::calibration_file::read_table(&out).expect("a valid table");
    // The written bias model is the true one: over T0 ± 0.5 °C its slope differs from the true
    // slope by much less than the drift did (the drift is zero at T0, so is the correction).
    let diff = |dt: f64| {
        let at = |t: &CalibrationTable| {
            t.thermal
                .coefficients_at(Celsius(t.thermal.reference.0 + dt))
                .expect("in range")
                .0
                .bias_g
        };
        at(&written) - at(&truth)
    };
    let slope_err = diff(0.5) - diff(-0.5);
    assert!(slope_err.abs() < 0.3 * DRIFT_G_PER_C, "{slope_err:e} g/°C");
    std::fs::remove_file(&out).expect("remove");
    let truth_file = dir.join("truth.acal");
    std::fs::write(&truth_file, truth.encode()).expect("write table");
    let r = run(&truth_file);
    assert!(!r.status.success());
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(err.contains("nothing written"), "{err}");
    assert!(!out.exists());
}

/// A bias error the table cannot hold exactly — ε·sign(T − T0)·|T − T0|^1.5, no coefficient
/// has that power — in white + flicker + random-walk noise: named an error of K0 (whichever
/// power fits best), and the written table's bias model follows the true error within 40 % RMS
/// over the record's temperatures (stated before measuring), with no lag or loop beside it.
#[test]
fn a_bias_error_of_power_one_and_a_half_is_corrected_by_the_nearest_table() {
    let mut rng = synth::rng(17);
    let st = synth::station(ROWS, DT_S, synth::EIGHT_HOUR_CYCLE, &mut rng);
    let given = paper_table_at_mean(&st);
    given.validate().expect("a valid table");
    let t0 = given.thermal.reference.0;
    // 10 µg at 1 °C from T0: ≈ 3.5 µg over the ±0.5 °C cycle.
    let eps = 1.0e-5;
    let error = |t: f64| eps * (t - t0).signum() * (t - t0).abs().powf(1.5);
    let log = record_through(&given, &st, &mut rng, error);
    let d = run_checked(&log, &given);
    let check = d.table_check.as_ref().expect("a calibration was given");
    let first = check.terms.first().expect("a table error");
    assert_eq!(first.symbol, "K0", "{:?}", check.terms);
    let corrected = check.corrected.expect("a corrected table");
    let bias = synth::bias_g_at;
    let (mut err2, mut true2) = (0.0, 0.0);
    for &t in &st.temp_true_c {
        err2 += (bias(&corrected, t) - bias(&given, t) - error(t)).powi(2);
        true2 += error(t).powi(2);
    }
    let rel = (err2 / true2).sqrt();
    println!("corrected bias model off the true error by {rel:.3} RMS");
    assert!(rel < 0.4, "corrected bias model off by {rel:.3} RMS");
}
