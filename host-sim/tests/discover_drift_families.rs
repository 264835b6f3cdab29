//! Drift families named where the record can show them. Each family — exponential aging,
//! logarithmic aging, power-law creep — and a sum of two exponential agings (no family holds it
//! exactly) is hidden at an amplitude set by the ideal detector's χ² (`common/drift.rs`: the
//! known shape whitened by the known noise, after the baseline's offset, linear drift and
//! temperature cubic), then found blind:
//!
//! - in 14-day synthetic logs at 120 s (white 2 µg·√s + 1/f flicker 0.3–1 µg + random walk
//!   2–8 ng/√s, a regulated thermostat), at ideal χ² 400, two logs per family;
//! - in the real gMetrology residual (tide, pressure, offsets and drift removed,
//!   `common/real.rs`), 10-day windows at 1 min, at ideal χ² 300–500 against the window's own
//!   noise (white, flicker and random-walk levels fitted to its Allan variance), each family
//!   on each window that names no drift of its own.
//!
//! The charge of a drift family is ln n + max(ln n, 2 ln 24) ≈ 18–19 here, yet χ² 400 is not
//! a margin chosen for comfort: the discovery re-fits the noise model (random walk and flicker
//! included) with and without the drift, and on 14 days that re-fit gives back most of the
//! ideal χ² (measured by `examples/drift_detection_limit.rs`, docs/discovery-causes.md,
//! "Drift families"); 400 is where every family was named right on every seed there.
//!
//! Right: the family's catalogue entry named — or reported as equally good beside the named one
//! ("ambiguous: A or B") — with its shape parameter within the family's tolerance or 3 σ of
//! its reported uncertainty (`drift::named_right`: exponential τ ±50 %, logarithmic τ within
//! e^1.6, power-law exponent ±0.3); the sum of two exponentials: the named drift families'
//! curves (their reported parameters and amplitudes) reproduce it within 30 % RMS after the
//! baseline's offset and linear drift. A logistic (an inflection no family has) must be either
//! reproduced so or said as unexplained structure at time scales of days, never another cause.

#[path = "common/drift.rs"]
mod drift;
#[path = "common/hidden.rs"]
mod hidden;
#[path = "common/real.rs"]
mod real;
#[path = "common/synth.rs"]
mod synth;

use accomp_host::discover as disc;
use accomp_host::log::Log;
use drift::Family;
use rand::Rng;

/// The families with a catalogue entry, and a sum of two exponentials (no entry holds it
/// exactly, a logarithm and an exponential come close).
const NAMED: [Family; 4] = [
    Family::Exponential,
    Family::Logarithmic,
    Family::PowerLaw,
    Family::TwoExponentials,
];

/// Ideal χ² (known noise) of the synthetic drifts: 20 × a drift family's charge. Where the
/// families are named right on every seed of `examples/drift_detection_limit.rs` (χ² ≥ 320);
/// below it the record's own noise re-fit gives most of the χ² back (docs/discovery-causes.md).
const SYNTHETIC_CHI2: f64 = 400.0;
/// Largest RMS mismatch of a shape outside the catalogue and the named family's curve.
const MAX_MISMATCH: f64 = 0.3;

fn print(label: &str, x: &drift::Drawn, d: &disc::Discovery, v: &drift::Verdict, ok: bool) {
    eprintln!(
        "{label}: A {:.1} µg, truth {:?}, ideal χ² {:.0} (random-walk form {:.0}), noise {:?} → \
         {:?} or {:?}, param {:?}, mismatch {:.2}, others {:?}; right {ok}; accepted {:?}; \
         refused {:?}; unexplained {:?}",
        x.amplitude_g * 1e6,
        x.truth,
        x.chi2,
        x.chi2_random_walk,
        x.noise,
        v.named,
        v.or,
        v.shape_param,
        v.mismatch,
        v.others,
        hidden::accepted_with_params(d),
        d.selection.refused,
        d.unexplained
    );
}

#[test]
fn each_drift_family_well_above_the_ideal_limit_is_named_in_synthetic_noise() {
    let mut wrong = Vec::new();
    let mut extras = 0;
    for (i, &family) in NAMED.iter().enumerate() {
        for k in 0..2u64 {
            let x = drift::synthetic(family, 0xD41F_A000 + 16 * i as u64 + k, SYNTHETIC_CHI2);
            let (_, d) = hidden::discover_blind(&x.log);
            let v = drift::verdict(&d, &x.t_s, &x.shape_g, family);
            let ok = drift::named_right(&v, family, &x.truth, MAX_MISMATCH);
            print(&format!("{family:?} {k}"), &x, &d, &v, ok);
            extras += v.others.len();
            if !ok {
                wrong.push(format!("{family:?} {k}"));
            }
        }
    }
    eprintln!("SYNTHETIC DRIFTS: wrong {wrong:?}, extras {extras}");
    assert!(wrong.is_empty(), "not named right: {wrong:?}");
    assert!(extras == 0, "extras {extras}");
}

/// A logistic has an inflection no family has (each family's rate is monotonic): it is either
/// reproduced by a family within the tolerance or said as unexplained structure at the time
/// scales of days, never another cause.
#[test]
fn a_logistic_drift_no_family_holds_is_said_as_structure_at_days_not_forced_into_a_cause() {
    for k in 0..2u64 {
        let x = drift::synthetic(Family::Logistic, 0xD41F_A100 + k, SYNTHETIC_CHI2);
        let (_, d) = hidden::discover_blind(&x.log);
        let v = drift::verdict(&d, &x.t_s, &x.shape_g, Family::Logistic);
        let structure_at_days = d.unexplained.iter().any(|u| {
            matches!(u, disc::unexplained::Structure::AllanExcess { tau_to_s, .. }
                if *tau_to_s >= 86_400.0)
        });
        let ok = v.others.is_empty()
            && (drift::named_right(&v, Family::Logistic, &x.truth, MAX_MISMATCH)
                || (v.named.is_none() && structure_at_days));
        print(&format!("Logistic {k}"), &x, &d, &v, ok);
        assert!(ok, "logistic {k}: {v:?}, unexplained {:?}", d.unexplained);
    }
}

/// Ten days at the record's one minute.
const WINDOW_ROWS: usize = 10 * 1440;
/// The window's noise as white + flicker + random walk, from its overlapping Allan variance
/// at τ = 2^k·Δt up to an eighth of the window: σ²(τ) = h_w/τ + f² + q²τ/3 by least squares
/// in relative error, each level non-negative (the best fit over the subsets of terms).
fn allan_params(x: &[f64], dt_s: f64) -> accomp_host::sim::noise::AllanParams {
    let n = x.len();
    let mut cum = vec![0.0; n + 1];
    for (i, v) in x.iter().enumerate() {
        cum[i + 1] = cum[i] + v;
    }
    let mut pts: Vec<(f64, f64)> = Vec::new();
    let mut m = 1;
    while 8 * m <= n {
        let k = n - 2 * m + 1;
        let s: f64 = (0..k)
            .map(|i| {
                let a = (cum[i + m] - cum[i]) / m as f64;
                let b = (cum[i + 2 * m] - cum[i + m]) / m as f64;
                (b - a).powi(2)
            })
            .sum();
        pts.push((m as f64 * dt_s, s / (2.0 * k as f64)));
        m *= 2;
    }
    let basis = |tau: f64| [1.0 / tau, 1.0, tau / 3.0];
    let mut best = ([0.0; 3], f64::INFINITY);
    for mask in 1..8u32 {
        let on: Vec<usize> = (0..3).filter(|j| mask & (1 << j) != 0).collect();
        // Normal equations of Σ((model − v)/v)².
        let mut a = vec![vec![0.0; on.len()]; on.len()];
        let mut b = vec![0.0; on.len()];
        for &(tau, v) in &pts {
            let g = basis(tau);
            for (r, &j) in on.iter().enumerate() {
                b[r] += g[j] / v;
                for (c, &l) in on.iter().enumerate() {
                    a[r][c] += g[j] * g[l] / (v * v);
                }
            }
        }
        let Some(sol) = accomp_numerics::linalg::solve_square(&a, &b) else {
            continue;
        };
        if sol.iter().any(|c| *c < 0.0) {
            continue;
        }
        let mut h = [0.0; 3];
        for (r, &j) in on.iter().enumerate() {
            h[j] = sol[r];
        }
        let cost: f64 = pts
            .iter()
            .map(|&(tau, v)| {
                let g = basis(tau);
                ((g[0] * h[0] + g[1] * h[1] + g[2] * h[2]) / v - 1.0).powi(2)
            })
            .sum();
        if cost < best.1 {
            best = (h, cost);
        }
    }
    let h = best.0;
    accomp_host::sim::noise::AllanParams {
        white_adev_1s: h[0].sqrt(),
        flicker_floor: h[1].sqrt(),
        random_walk_per_sqrt_s: h[2].sqrt(),
    }
}

/// The ideal χ² of `shape` against the real window's noise: the window's Allan levels
/// (`allan_params`) as the known noise of `hidden::matched_filter_snr`, after offset and drift.
fn real_chi2(shape: &[f64], window: &[f64]) -> f64 {
    let n = shape.len();
    let noise = allan_params(window, DT_REAL_S);
    let nuisance = [
        vec![1.0; n],
        (0..n).map(|i| i as f64 / n as f64).collect::<Vec<_>>(),
    ];
    hidden::matched_filter_snr(shape, &nuisance, &noise, DT_REAL_S, n as f64 * DT_REAL_S).powi(2)
}

/// The record's spacing, s.
const DT_REAL_S: f64 = 60.0;

fn real_log(t: &[f64], y: Vec<f64>) -> Log {
    let mut log = Log::with_time(t.iter().map(|x| x - t[0]).collect()).expect("time");
    log.set_meta("input_g", "1").expect("meta");
    log.push_column("gravity_mgal", y).expect("column");
    log
}

fn run(log: &Log) -> disc::Discovery {
    synth::discover(log.clone(), None)
}

/// Ideal χ² of the drifts injected into the real residual, against the window's Allan levels.
const REAL_CHI2: std::ops::Range<f64> = 300.0..500.0;

#[test]
fn drift_families_injected_into_the_real_residual_are_named() {
    let res = real::residual_after_tide();
    let wins = real::windows(&res, WINDOW_ROWS);
    // The record's own settling: a window where the residual alone names a drift family holds
    // a drift of its own, which would be a second drift beside the injected one. Measured on
    // the windows, not chosen: those are left out, at least two must remain.
    let clean: Vec<(std::ops::Range<usize>, Vec<String>)> = wins
        .iter()
        .filter_map(|w| {
            let d0 = run(&real_log(
                &res.t_s[(*w).clone()],
                res.r_mgal[(*w).clone()].to_vec(),
            ));
            let own = d0
                .selection
                .accepted
                .iter()
                .any(|a| a.effect.drift_family().is_some());
            eprintln!(
                "null window at row {}: {:?}{}",
                w.start,
                hidden::accepted_with_params(&d0),
                if own {
                    " (a drift of its own: not used)"
                } else {
                    ""
                }
            );
            (!own).then(|| (w.clone(), hidden::accepted_names(&d0)))
        })
        .collect();
    assert!(
        clean.len() >= 2,
        "{} windows without a drift of their own",
        clean.len()
    );
    let mut rng = synth::rng(0xD41F_B000);
    let (mut wrong, mut missed, mut extras) = (Vec::new(), 0, 0);
    for (family, (w, own)) in NAMED
        .iter()
        .flat_map(|&f| clean.iter().map(move |c| (f, c.clone())))
    {
        let t: Vec<f64> = res.t_s[w.clone()]
            .iter()
            .map(|x| x - res.t_s[w.start])
            .collect();
        let (unit, truth) = drift::unit_shape(family, &t, &mut rng);
        let noise = &res.r_mgal[w.clone()];
        let chi2 = rng.random_range(REAL_CHI2);
        let a = hidden::sign(&mut rng) * (chi2 / real_chi2(&unit, noise)).sqrt();
        let shape: Vec<f64> = unit.iter().map(|u| a * u).collect();
        let y: Vec<f64> = noise.iter().zip(&shape).map(|(r, s)| r + s).collect();
        let d = run(&real_log(&res.t_s[w.clone()], y));
        let v = drift::verdict(&d, &t, &shape, family);
        let ok = drift::named_right(&v, family, &truth, MAX_MISMATCH);
        eprintln!(
            "{family:?} window at row {}: A {a:.4} mGal, truth {truth:?}, χ² {chi2:.0} → {:?} or \
             {:?}, param {:?}, mismatch {:.2}, others {:?}; right {ok}; accepted {:?}; refused \
             {:?}",
            w.start,
            v.named,
            v.or,
            v.shape_param,
            v.mismatch,
            v.others,
            hidden::accepted_with_params(&d),
            d.selection.refused
        );
        if !ok {
            wrong.push(format!("{family:?} at row {}", w.start));
        }
        missed += usize::from(v.named.is_none());
        // What the window names without the drift is the record's own, not an extra.
        extras += v.others.iter().filter(|n| !own.contains(n)).count();
    }
    let cases = NAMED.len() * clean.len();
    eprintln!(
        "REAL DRIFTS: {} of {cases} right, wrong {wrong:?}, missed {missed}, extras {extras}",
        cases - wrong.len()
    );
    assert_eq!(missed, 0, "a drift family named on every injection");
    assert!(
        cases - wrong.len() >= REAL_RIGHT_AT_LEAST.min(cases),
        "not named right: {wrong:?}"
    );
    assert!(extras <= 2, "extras {extras}");
}

/// Injections into the real residual named with the right family and parameters, measured
/// when this test was written (10 of 12: a logarithm named an exponential on the window with
/// the record's two steps, and a power law's exponent 2.04 ± 0.11 for 2.58 on the window whose
/// own jump the steps' validation refuses); the test fails below it.
const REAL_RIGHT_AT_LEAST: usize = 10;
