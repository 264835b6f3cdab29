//! Fast physics at the rate it lives at: a lag of a minute in a record binned to 86 s is found
//! on the full-rate rows (`discover::fullrate`), and nothing is found where there is no lag.
//!
//! The records are short (one day at 1 Hz) and binned coarsely by `max_points` so that the bins
//! hide the lag as the 41-day preset's 71 s bins do (docs/benchmarks.md measures that one).

#[path = "common/hidden.rs"]
mod hidden;
#[path = "common/synth.rs"]
mod synth;

use accomp_host::discover::import::DatasetOptions;
use accomp_host::discover::{self as disc, select, Discovery};
use accomp_host::log::Log;
use accomp_host::sim::scenario::Scenario;
use accomp_host::sim::Simulator;

/// One day at 1 Hz.
const ROWS: usize = 86_400;
/// Binned to 87 s (86.4 s rounded up to whole samples): the binned lag grid starts at two bins
/// (174 s).
const MAX_POINTS: usize = 1_000;

fn run(log: Log) -> Discovery {
    let opts = DatasetOptions {
        max_points: MAX_POINTS,
        ..DatasetOptions::default()
    };
    disc::discover_log(log, &[], &opts, None, &select::Config::default()).expect("discover")
}

fn lag_of(d: &Discovery) -> Option<f64> {
    let f = d.full_rate.as_ref()?.as_ref().ok()?;
    f.terms
        .iter()
        .find(|t| t.name == "thermal_lag")
        .and_then(|t| disc::fullrate::param(t, "tau_s"))
        .map(|p| p.value)
}

/// The paper-1g preset one day at 1 Hz with `effects` added, simulated from `seed`, as a log.
fn paper_1g_day(effects: Vec<accomp_host::sim::effects::ScenarioEffect>, seed: u64) -> Log {
    paper_1g(effects, seed, ROWS)
}

/// The paper-1g preset for `rows` s at 1 Hz with `effects` added, simulated from `seed`.
fn paper_1g(
    effects: Vec<accomp_host::sim::effects::ScenarioEffect>,
    seed: u64,
    rows: usize,
) -> Log {
    let mut sc = Scenario::preset("paper-1g").expect("preset");
    sc.run.duration_s = rows as f64;
    sc.run.interval_s = 1.0;
    sc.effects.extend(effects);
    let mut sim = Simulator::new(&sc, seed).expect("simulator");
    let n = sim.samples() as usize;
    let mut cols: [Vec<f64>; 5] = Default::default();
    for _ in 0..n {
        let s = sim.step().expect("step");
        for (c, v) in cols.iter_mut().zip([
            s.time_s,
            s.output_v,
            s.temperature_c,
            s.tilt_arcsec,
            s.pressure_hpa,
        ]) {
            c.push(v);
        }
    }
    let [t, out, temp, tilt, p] = cols;
    let mut log = Log::with_time(t).expect("time");
    for (k, v) in sim.metadata(seed) {
        log.set_meta(&k, &v).expect("meta");
    }
    for (name, v) in [
        ("output_v", out),
        ("temperature_c", temp),
        ("tilt_arcsec", tilt),
        ("pressure_hpa", p),
    ] {
        log.push_column(name, v).expect("column");
    }
    log
}

/// The paper-1g station as simulated (its proof mass lags the RTD's mounting block by 60 s,
/// its tide, tilt and reference tempco on), one day at 1 Hz.
#[test]
fn a_one_minute_proof_mass_lag_is_found_at_the_full_rate() {
    let log = paper_1g_day(Vec::new(), 7);
    let d = run(log);
    print!("{}", disc::fullrate::text_of(&d.full_rate, "v"));
    assert!(d.dataset.dt_s > 80.0, "bins of {} s", d.dataset.dt_s);
    // The bins alone cannot resolve it: no lag the binned rounds accepted within 25 % of a
    // minute.
    assert!(!d.selection.accepted.iter().any(|a| {
        !a.full_rate
            && a.effect.name() == "thermal_lag"
            && (a.theta.value / 60.0 - 1.0).abs() < 0.25
    }));
    let tau = lag_of(&d).expect("a thermal_lag at the full rate");
    assert!((tau / 60.0 - 1.0).abs() < 0.25, "τ = {tau} s");
    // It is in the final model: accepted with the full-rate τ held, its coefficient refitted
    // on the bins with everything else (the bins see the lag's low-frequency part, c·τ·dT/dt,
    // so at the held τ they give c), and the final residual is smaller for it.
    let text = disc::report::text(&d);
    print!("{text}");
    let a = d
        .selection
        .accepted
        .iter()
        .find(|a| a.full_rate)
        .unwrap_or_else(|| panic!("the full-rate lag in the final model: {text}"));
    assert_eq!(a.effect.name(), "thermal_lag");
    assert_eq!(a.theta.value, tau);
    let c_full = d
        .full_rate
        .as_ref()
        .and_then(|f| f.as_ref().ok())
        .and_then(|f| {
            f.terms
                .iter()
                .find(|t| t.name == "thermal_lag")
                .and_then(|t| disc::fullrate::param(t, "coefficient"))
        });
    let c_full = c_full.expect("its coefficient at the full rate");
    let c_bins = hidden::param(a, "coefficient").expect("coefficient");
    assert!(
        (c_bins.value / c_full.value - 1.0).abs() < 0.2,
        "coefficient on the bins {c_bins:?}, at the full rate {c_full:?}"
    );
    assert!(
        a.std_after < a.std_before,
        "{} → {}",
        a.std_before,
        a.std_after
    );
    // A binned lag refused at the lower edge of its grid is not blamed on the channel's noise.
    for (n, why) in &d.selection.refused {
        assert!(
            !(n == "thermal_lag" && why.contains("reading noise")),
            "{n}: {why}"
        );
    }
}

/// A regulated station whose output follows its temperature without a lag (independent of the
/// simulator: `synth.rs`), white + flicker + random-walk noise: nothing is found at the full rate.
#[test]
fn no_lag_is_found_where_the_output_follows_the_temperature_at_once() {
    let mut rng = synth::rng(11);
    let st = synth::station(ROWS, 1.0, synth::Thermal::Regulated, &mut rng);
    let noise = synth::draw_noise(&mut rng);
    let y = synth::output_g(&st, &noise, &vec![0.0; ROWS], &mut rng);
    let d = run(synth::log_of(&st, y));
    print!("{}", disc::fullrate::text_of(&d.full_rate, "g"));
    let f = d
        .full_rate
        .as_ref()
        .expect("binned, so the full-rate stage applies")
        .as_ref()
        .expect("the full-rate stage runs");
    assert!(f.terms.is_empty(), "{:?}", f.terms);
}

/// The same station with a gain on the rate of the mount temperature beside its 60 s lag
/// (4e-3 V·s/°C): on the bins the rate and the lag's image −c·τ·dT/dt are one column, so
/// without the rate term in the full-rate transfer function the lag was not found (τ at the
/// grid's lower edge). Both within 25 % (the tolerance of the 41-day goal).
#[test]
fn a_rate_coupling_beside_the_lag_leaves_the_lag_found_and_is_measured_at_the_full_rate() {
    let g = 4e-3;
    let log = paper_1g_day(
        vec![accomp_host::sim::effects::ScenarioEffect::RateCoupling {
            channel: "temperature_c".into(),
            coefficient: g,
        }],
        7,
    );
    let d = run(log);
    print!("{}", disc::fullrate::text_of(&d.full_rate, "v"));
    let tau = lag_of(&d).expect("a thermal_lag at the full rate");
    assert!((tau / 60.0 - 1.0).abs() < 0.25, "τ = {tau} s");
    let rate = d
        .full_rate
        .as_ref()
        .and_then(|f| f.as_ref().ok())
        .and_then(|f| f.terms.iter().find(|t| t.name == "thermal_lag"))
        .and_then(|t| t.rate_coefficient)
        .expect("the channel's gain on its rate beside the lag");
    assert!((rate.0 / g - 1.0).abs() < 0.25, "rate gain {rate:?}");
    assert!(d.selection.accepted.iter().any(|a| a.full_rate));
}

/// The full-rate stage alone (no binned selection: its lags held in H are none here) on one
/// day of `log` binned as [`run`] bins it: its `thermal_lag`, if found.
fn full_rate_lag(log: &Log) -> Option<disc::fullrate::FastTerm> {
    use accomp_host::discover::import::{dataset_from_log, full_rate_from_log};
    let opts = DatasetOptions {
        max_points: MAX_POINTS,
        ..DatasetOptions::default()
    };
    let binned = dataset_from_log(log, &opts).expect("binned");
    let full = full_rate_from_log(log, &opts).expect("full rate");
    let f = disc::fullrate::analyse(&full, &binned, &[]).expect("the stage runs");
    f.terms.into_iter().find(|t| t.name == "thermal_lag")
}

/// The σ of τ reported at the full rate covers the true τ over independent records: ten seeds
/// of the paper-1g day with the rate coupling of 4e-3 V·s/°C beside its 60 s lag (10 segments
/// of 8192 s, so 10 jackknife groups); 60 s within ±1σ for at least 5 of the 10 (≈ 7 expected;
/// 5 or more holds with 95 % probability) and within ±2σ for at least 8.
/// Measured: τ 56.2–65.5 s (std 3.4 s over the seeds) while the χ² curvature's σ_τ is
/// 1.8–2.3 s: ±1 curvature σ hold 60 s for 1 of the 10, ±2 for 8; the reported σ (the
/// jackknife's on 9 seeds, 2.9–8.1 s; on seed 8 the curvature's, 1.8 s against 1.78) holds it
/// within ±1σ for 8 and ±2σ for 10. Without the rate coupling the two are closer (τ std 2.4 s,
/// curvature σ ≈ 2 s: ±2 curvature σ hold 60 s for 8 of the 10, the reported σ for 10).
/// ≈ 1 s a seed in the dev profile.
#[test]
fn the_lags_sigma_covers_the_true_tau_over_independent_records() {
    let (tau_true, n) = (60.0, 10u64);
    // Within ±1σ and ±2σ: reported, curvature alone.
    let (mut one, mut two, mut one_curvature, mut two_curvature) = (0, 0, 0, 0);
    for seed in 1..=n {
        let log = paper_1g_day(
            vec![accomp_host::sim::effects::ScenarioEffect::RateCoupling {
                channel: "temperature_c".into(),
                coefficient: 4e-3,
            }],
            seed,
        );
        let t = full_rate_lag(&log).unwrap_or_else(|| panic!("seed {seed}: no thermal_lag"));
        let tau = disc::fullrate::param(&t, "tau_s").expect("tau_s");
        let s = t.sigmas.iter().find(|s| s.name == "tau_s").expect("σ of τ");
        assert_eq!(s.used, tau.sigma);
        assert!(t.sigma_method.contains("jackknife"), "{}", t.sigma_method);
        let err = (tau.value - tau_true).abs();
        one += usize::from(err <= tau.sigma);
        two += usize::from(err <= 2.0 * tau.sigma);
        one_curvature += usize::from(err <= s.curvature);
        two_curvature += usize::from(err <= 2.0 * s.curvature);
        println!(
            "seed {seed}: τ = {:.2} s, σ {:.2} s ({}; curvature {:.2}, jackknife {:.2?})",
            tau.value, tau.sigma, s.method, s.curvature, s.jackknife
        );
    }
    println!(
        "within ±1σ: {one}/{n}, ±2σ: {two}/{n} (curvature alone: {one_curvature}/{n}, \
         {two_curvature}/{n})"
    );
    assert!(one >= 5 && two >= 8, "within ±1σ {one}/{n}, ±2σ {two}/{n}");
}
