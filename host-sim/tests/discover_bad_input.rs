//! `accomp discover` on bad input (issue #15, "6."): each case used to be answered silently —
//! an all-NaN temperature reported as "0 dropped", one 1e300 value giving an infinite residual
//! std with exit 0, `--max-points 0` fitting one point, a constant output "explained" by a tilt
//! gain of −1, a 10-year gap coarsening every bin to hours. Now each is refused with a named
//! error or announced in the text and the JSON `warnings`.

#[path = "common/hidden.rs"]
mod hidden;

use accomp_host::discover::import::{dataset_from_log, DatasetOptions};
use accomp_host::discover::{self, report, select};
use accomp_host::log::Log;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

const INTERVAL_S: f64 = 10.0;

/// A 1 g record in volts: a temperature wandering by ±0.3 °C with 5 mK reading noise, an
/// output with a 2e-6 V/°C temperature coefficient, white noise of 1e-6 V and a slow random
/// walk. `rows` rows at 10 s from `t0`, then (when `second_at` is set) as many again from there.
fn record(rows: usize, second_at: Option<f64>, seed: u64) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let unit = Normal::new(0.0, 1.0).expect("normal");
    let mut t = Vec::new();
    for k in 0..rows {
        t.push(k as f64 * INTERVAL_S);
    }
    if let Some(t2) = second_at {
        for k in 0..rows {
            t.push(t2 + k as f64 * INTERVAL_S);
        }
    }
    let mut walk = 0.0;
    let (mut temp, mut out) = (Vec::new(), Vec::new());
    for (i, &ti) in t.iter().enumerate() {
        let phase = 2.0 * std::f64::consts::PI * (i as f64 * INTERVAL_S) / 86_400.0;
        let true_t = 25.0 + 0.3 * phase.sin();
        walk += 2e-8 * unit.sample(&mut rng);
        temp.push(true_t + 0.005 * unit.sample(&mut rng));
        out.push(5.0 + 2e-6 * (true_t - 25.0) + walk + 1e-6 * unit.sample(&mut rng));
        let _ = ti;
    }
    (t, temp, out)
}

fn log_of(t: Vec<f64>, temp: Vec<f64>, out: Vec<f64>) -> Log {
    let meta = vec![
        ("input_g".to_owned(), "1".to_owned()),
        ("scale_factor_v_per_g".to_owned(), "5".to_owned()),
    ];
    hidden::log_with(t, &meta, vec![("output_v", out), ("temperature_c", temp)])
}

fn options(max_points: usize) -> DatasetOptions {
    DatasetOptions {
        max_points,
        ..DatasetOptions::default()
    }
}

fn warnings(d: &discover::Discovery) -> Vec<String> {
    let j = report::json(d);
    j["warnings"]
        .as_array()
        .expect("JSON has a warnings array")
        .iter()
        .map(|w| w.as_str().unwrap_or_default().to_owned())
        .collect()
}

fn run(log: &Log, max_points: usize) -> discover::Discovery {
    let ds = dataset_from_log(log, &options(max_points)).expect("dataset");
    discover::discover(ds, None, &select::Config::default()).expect("discovery")
}

#[test]
fn an_all_nan_temperature_is_named_in_the_warnings_and_the_text() {
    let (t, temp, out) = record(2000, None, 1);
    let log = log_of(t, vec![f64::NAN; temp.len()], out);
    let d = run(&log, 50_000);
    let w = warnings(&d);
    assert!(
        w.iter()
            .any(|w| w.contains("temperature_c") && w.contains("all")),
        "{w:?}"
    );
    let text = report::text(&d);
    assert!(
        text.contains("WARNING: channel temperature_c is empty"),
        "{text}"
    );
}

#[test]
fn one_absurd_output_value_is_dropped_with_a_warning_and_the_residual_stays_finite() {
    let (t, temp, mut out) = record(2000, None, 2);
    out[777] = 1e300;
    let d = run(&log_of(t, temp, out), 50_000);
    let w = warnings(&d);
    assert!(
        w.iter()
            .any(|w| w.contains("output_v") && w.contains("1e300")),
        "{w:?}"
    );
    assert!(d.selection.baseline_std.is_finite() && d.selection.baseline_std < 1e-3);
    assert!(d.selection.final_std.is_finite());
}

#[test]
fn max_points_outside_the_sane_range_is_refused_with_the_memory_estimate() {
    let (t, temp, out) = record(2000, None, 3);
    let log = log_of(t, temp, out);
    for bad in [0, 1, 999, 100_000_000] {
        let err = dataset_from_log(&log, &options(bad))
            .expect_err("an absurd --max-points must be refused")
            .to_string();
        assert!(
            err.contains("--max-points") && err.contains("MB"),
            "{bad}: {err}"
        );
    }
    let ds = dataset_from_log(&log, &options(1_000)).expect("1000 is allowed");
    assert!(
        ds.notes.iter().any(|n| n.contains("memory estimate")),
        "{:?}",
        ds.notes
    );
}

#[test]
fn a_constant_output_is_refused_by_name() {
    let (t, temp, out) = record(2000, None, 4);
    let log = log_of(t, temp, vec![5.0; out.len()]);
    let err = dataset_from_log(&log, &options(50_000))
        .expect_err("a constant output has nothing to discover")
        .to_string();
    assert!(err.contains("constant"), "{err}");
}

#[test]
fn a_ten_year_gap_keeps_the_bins_of_the_data_and_is_announced() {
    // 2 × 4000 rows at 10 s, ten years apart, binned to at most 5000 points: the bins must
    // come from the 22 hours of data (16 s), not from the ten-year span (≈ 63 000 s).
    let ten_years = 10.0 * 365.25 * 86_400.0;
    let (t, temp, out) = record(4000, Some(ten_years), 5);
    let d = run(&log_of(t, temp, out), 5_000);
    assert!(d.dataset.dt_s < 20.0, "bin {} s", d.dataset.dt_s);
    assert!(d.dataset.len() > 4_000, "{} points", d.dataset.len());
    let w = warnings(&d);
    assert!(w.iter().any(|w| w.contains("gap")), "{w:?}");
    // The noise model is fitted (not a silent white fallback) and nothing absurd is accepted.
    assert_eq!(
        d.selection.baseline_noise.method,
        accomp_host::discover::noise::METHOD_KALMAN_ML
    );
    for a in &d.selection.accepted {
        for (k, p) in &a.params {
            assert!(p.value.is_finite(), "{} {k} {}", a.effect.name(), p.value);
        }
    }
}

#[test]
fn the_noise_model_is_fitted_and_reported_in_the_json() {
    let (t, temp, out) = record(3000, None, 6);
    let d = run(&log_of(t, temp, out), 50_000);
    let j = report::json(&d);
    for part in ["baseline", "final"] {
        let n = &j[part]["noise"];
        assert_eq!(n["method"], "kalman_innovations_ml", "{n}");
        let white = n["white"].as_f64().expect("white");
        // The output's white noise is 1e-6 V per 10 s point.
        assert!((0.5e-6..2e-6).contains(&white), "{part}: white {white}");
        assert!(n["flicker"].as_f64().is_some() && n["random_walk"].as_f64().is_some());
    }
}
