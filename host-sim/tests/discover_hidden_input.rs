//! Hidden-effect test of `accomp discover` with a changing input: the paper-1g station runs a
//! dividing-head programme, the log carries the commanded input as an `input_g` column, and a
//! seeded draw *inside the test* hides a torquer self-heating (bias = coefficient × the input²
//! lagged by the coil's thermal time constant) in the output. The discovery runs blind and must
//! name `self_heating` with its time constant and coefficient; null logs with the same programme
//! must accept nothing. Rates are printed and asserted; they are quoted in docs/discovery.md
//! ("Changing input (self_heating)").

#[path = "common/hidden.rs"]
mod hidden_snr;

use accomp_host::log::Log;
use accomp_host::sim::accelerometer::HeadPosition;
use accomp_host::sim::scenario::Scenario;
use accomp_host::sim::Sample;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const DAY_S: f64 = 86_400.0;
const DURATION_S: f64 = 2.0 * DAY_S;
const INTERVAL_S: f64 = 10.0;

/// Head programme, degrees: +1 g, 0 g, −1 g, 0 g (θ from the horizontal to the input axis,
/// a_i = sin θ; see sim/accelerometer.rs). The head swings back through 0° rather than going on
/// to 180°: an `input_g` column cannot tell 0° from 180°, and the baseline's eq. (5) tilt term
/// takes θ in [−90°, 90°]. Every move changes a² (1 → 0 → 1 → 0), so every move heats or cools
/// the coil.
const PROGRAMME_DEG: [f64; 4] = [90.0, 0.0, -90.0, 0.0];
/// Dwell per position: 3 h ≥ 3.6 × the longest drawn time constant (3000 s), so each
/// transient has settled and the position's level is defined by the settled part; 16 moves in
/// the 2-day record.
const DWELL_S: f64 = 3.0 * 3600.0;

/// Time constants drawn log-uniformly in this range, s (coil thermal time constants, 5–50 min).
const TAU_S: std::ops::Range<f64> = 300.0..3000.0;
/// Matched-filter signal-to-noise ratio of the hidden effect against the station's sensor noise,
/// after the static baseline's columns and one level per head position (tests/common/hidden.rs
/// says why this measure); the same range as discover_hidden.rs.
const SNR: std::ops::Range<f64> = 5.0..10.0;

/// The hidden self-heating (the test's secret).
#[derive(Debug, Clone, Copy)]
struct Hidden {
    tau_s: f64,
    /// Bias per g² of input, g/g² (the coil's settled heating at 1 g).
    coefficient_g: f64,
}

/// Draws τ log-uniform in [`TAU_S`], a unit coefficient of either sign, and the SNR the
/// coefficient is to be scaled to once the log exists.
fn draw(rng: &mut ChaCha8Rng) -> (Hidden, f64) {
    let tau_s = (rng.random_range(TAU_S.start.ln()..TAU_S.end.ln())).exp();
    let snr = rng.random_range(SNR);
    let sign = if rng.random::<bool>() { 1.0 } else { -1.0 };
    (
        Hidden {
            tau_s,
            coefficient_g: sign,
        },
        snr,
    )
}

/// The coil's heating in units of g² of input: a first-order lag of the true a² (with the
/// head's indexing error), exact for an input held constant between samples — the head moves
/// at a sample instant, and the value read at a sample holds until the next one. The coil is
/// settled at the first position when the record starts.
fn coil_heating_g2(truth_input_g: &[f64], t_s: &[f64], tau_s: f64) -> Vec<f64> {
    let mut out = Vec::with_capacity(t_s.len());
    let mut held = truth_input_g.first().map_or(0.0, |a| a * a);
    let mut x = held;
    for (k, a) in truth_input_g.iter().enumerate() {
        if k > 0 {
            let decay = (-(t_s[k] - t_s[k - 1]) / tau_s).exp();
            x = held + (x - held) * decay;
        }
        held = a * a;
        out.push(x);
    }
    out
}

/// Simulates the station running the programme, scales the hidden effect (if any, drawn with a
/// unit coefficient) to the matched-filter SNR `snr`, adds it to the output and returns the log
/// as the board would record it plus the commanded input column, and the effect as hidden.
fn simulate(unit: Option<Hidden>, snr: f64, seed: u64) -> (Log, Option<Hidden>) {
    let mut sc = Scenario::preset("paper-1g").expect("preset");
    sc.run.duration_s = DURATION_S;
    sc.run.interval_s = INTERVAL_S;
    hidden_snr::quiet_station(&mut sc);
    sc.accelerometer.orientation.positions = PROGRAMME_DEG
        .iter()
        .map(|&angle_deg| HeadPosition {
            angle_deg,
            dwell_s: DWELL_S,
        })
        .collect();
    let hidden_snr::StationRun { k1, meta, samples } = hidden_snr::run_station(&sc, seed);
    let col = |f: fn(&Sample) -> f64| hidden_snr::column(&samples, f);
    let (t, mut out, temp, tilt, truth_a) = (
        col(|s| s.time_s),
        col(|s| s.output_v),
        col(|s| s.temperature_c),
        col(|s| s.tilt_arcsec),
        col(|s| s.truth_input_g),
    );
    // What the lab knows: the commanded position's nominal input sin θ (the truth carries the
    // indexing error and the tilt), rounded as the log writes it.
    let nominal_a = col(|s| {
        let commanded =
            (s.time_s.rem_euclid(DWELL_S * PROGRAMME_DEG.len() as f64) / DWELL_S).floor() as usize;
        let theta = PROGRAMME_DEG[commanded.min(PROGRAMME_DEG.len() - 1)].to_radians();
        (theta.sin() * 1e12).round() / 1e12
    });
    let hidden = unit.map(|h| {
        let heat = coil_heating_g2(&truth_a, &t, h.tau_s);
        let mut nuisance = hidden_snr::static_nuisance(&t, &temp);
        let mut levels: Vec<f64> = Vec::new();
        for a in &nominal_a {
            if !levels.contains(a) {
                levels.push(*a);
            }
        }
        for level in levels.iter().skip(1) {
            nuisance.push(
                nominal_a
                    .iter()
                    .map(|a| if a == level { 1.0 } else { 0.0 })
                    .collect(),
            );
        }
        let shape: Vec<f64> = heat.iter().map(|x| h.coefficient_g * x).collect();
        let k = hidden_snr::scale_to_snr(
            &shape,
            &nuisance,
            &sc.accelerometer.noise_g,
            INTERVAL_S,
            DURATION_S,
            snr,
        );
        for (o, x) in out.iter_mut().zip(&shape) {
            *o += k1 * k * x;
        }
        Hidden {
            coefficient_g: k * h.coefficient_g,
            ..h
        }
    });
    let log = hidden_snr::log_with(
        t,
        &meta,
        vec![
            ("output_v", out),
            ("temperature_c", temp),
            ("tilt_arcsec", tilt),
            ("input_g", nominal_a),
        ],
    );
    (log, hidden)
}

/// Tolerances: the coefficient within ±30 %; τ within a factor e^0.7, the same as for
/// `thermal_lag` in discover_hidden.rs (first stated as e^0.3 for draws sized by the Allan
/// deviation, which are 2–3× larger than the matched-filter SNR 5–10 draws; widened after
/// measuring at the smaller size, where τ̂ scattered by up to e^0.56 — docs/discovery.md).
const TAU_LN_TOL: f64 = 0.7;
const COEFFICIENT_REL_TOL: f64 = 0.3;

/// Runs the discovery blind; returns the accepted names and, if `self_heating` was named, its
/// (tau_s, coefficient_g).
fn run_one(
    unit: Option<Hidden>,
    snr: f64,
    seed: u64,
) -> (Vec<String>, Option<(f64, f64)>, Option<Hidden>) {
    let (log, hidden) = simulate(unit, snr, seed);
    let (_, d) = hidden_snr::discover_blind(&log);
    let found = hidden_snr::find_named(&d, "self_heating").map(|a| {
        (
            hidden_snr::param_value(a, "tau_s"),
            hidden_snr::param_value(a, "coefficient_g"),
        )
    });
    let names = hidden_snr::accepted_names(&d);
    (names, found, hidden)
}

const SEED: u64 = 20_240_715;
/// Draws per test: each discovery of a 17 280-point record takes a few seconds in the dev
/// profile, and the file must run in < 60 s.
const HIDDEN_DRAWS: usize = 8;
const NULL_DRAWS: usize = 8;

#[test]
fn coil_heating_follows_a_first_order_lag_of_the_squared_input() {
    // Input 1 g until t = 100 s, then 0 g; τ = 50 s: e^{−1} of the step left 50 s after the move.
    let t: Vec<f64> = (0..=30).map(|i| 10.0 * f64::from(i)).collect();
    let a: Vec<f64> = t
        .iter()
        .map(|&x| if x < 100.0 { 1.0 } else { 0.0 })
        .collect();
    let x = coil_heating_g2(&a, &t, 50.0);
    assert_eq!(x[10], 1.0);
    assert!((x[15] - (-1.0_f64).exp()).abs() < 1e-12, "{}", x[15]);
}

#[test]
fn self_heating_is_named_with_its_time_constant_and_coefficient() {
    let mut rng = ChaCha8Rng::seed_from_u64(SEED);
    let (mut named, mut ok) = (0, 0);
    for i in 0..HIDDEN_DRAWS {
        let (unit, snr) = draw(&mut rng);
        let seed = rng.random::<u64>();
        let (names, found, hidden) = run_one(Some(unit), snr, seed);
        let Some(h) = hidden else {
            panic!("the hidden effect was not built");
        };
        let good = found.is_some_and(|(tau, c)| {
            (tau.ln() - h.tau_s.ln()).abs() <= TAU_LN_TOL
                && (c - h.coefficient_g).abs() <= COEFFICIENT_REL_TOL * h.coefficient_g.abs()
        });
        eprintln!(
            "draw {i}: hidden τ = {:.0} s, coefficient {:.3e} g/g² (SNR {snr:.1}); accepted {names:?}; \
             self_heating {found:?}; within tolerance {good}",
            h.tau_s, h.coefficient_g
        );
        named += usize::from(found.is_some());
        ok += usize::from(good);
    }
    eprintln!("SELF-HEATING: named {named}/{HIDDEN_DRAWS}, within tolerance {ok}/{HIDDEN_DRAWS}");
    // Thresholds stated before measuring: named in ≥ 80 % of the draws, with τ and coefficient
    // within tolerance in ≥ 80 % of the draws.
    hidden_snr::assert_at_least_percent(named, HIDDEN_DRAWS, 80, "self_heating named");
    hidden_snr::assert_at_least_percent(ok, HIDDEN_DRAWS, 80, "self_heating within tolerance");
}

#[test]
fn null_logs_with_a_head_programme_accept_nothing() {
    // Threshold stated before measuring: nothing accepted in ≥ 90 % of the null logs.
    hidden_snr::assert_null_rate_at_most("head-programme", SEED ^ 0x5EED, NULL_DRAWS, 10, |seed| {
        run_one(None, 0.0, seed).0
    });
}
