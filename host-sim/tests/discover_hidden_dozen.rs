//! The discovery's score over a dozen-plus logs with one cause each, varied causes and realistic
//! noise: 14-day 1 g logs at 120 s from `common/synth.rs` (white 2 µg·√s + 1/f flicker
//! 0.3–1 µg by spectral synthesis + random walk 2–8 ng/√s, an RTD with offset and reading noise,
//! tilt and pressure channels), generated without the simulator or the detector. The causes'
//! shapes are not the catalogue's exact ones where a real sensor's would not be: a drift of a
//! sum of two powers, a logistic drift, flips of unequal sizes, a lag and a rate coupling on
//! the true temperature.
//!
//! The tool runs blind. A log is **right** when the accepted effect that explains its cause is
//! named as stated below with its parameters within the stated tolerance (null logs: when
//! nothing is accepted); every accepted effect that is not the cause is an **extra**. Goals
//! (stated before measuring): at most 2 extras over all logs; the right count may not fall
//! below the one measured. Measured score: docs/discovery.md, "Hidden-effect tests"
//! (≈ 20 s in the dev profile).

#[path = "common/hidden.rs"]
mod hidden;
#[path = "common/synth.rs"]
mod synth;

use accomp_host::discover::select::Accepted;
use accomp_host::discover::Discovery;
use rand::Rng;
use rand_chacha::ChaCha8Rng;

const DT_S: f64 = 120.0;
const ROWS: usize = 14 * 720;
const DAY_S: f64 = 86_400.0;

/// One cause per log. The tolerances are stated with each.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Cause {
    /// Nothing hidden: right when nothing is accepted.
    Null,
    /// Nothing hidden, the noise a strong random walk (20–40 ng/√s) and no flicker: right when
    /// nothing is accepted (a random walk is noise, not a drift).
    RandomWalk,
    /// A drift that accelerates as a sum of two powers, A·((t/span)^p₁ + (t/span)^p₂)/2, p₁
    /// 1.3–1.7, p₂ 2.3–3, |A| 80–150 µg: `creep_drift` (power law) with its exponent within
    /// [p₁ − 0.3, p₂ + 0.5].
    TwoPowers,
    /// A logistic drift A/(1 + e^(−(t − t_c)/w)), t_c at 40–60 % of the span, w 0.7–1.5 d,
    /// |A| 30–60 µg (no catalogue family holds it): right when a drift family is named.
    Logistic,
    /// Exponential aging A·(1 − e^(−t/τ)), τ 1.5–4 d, |A| 40–80 µg: `warmup` (exponential)
    /// with τ within ±50 %.
    ExponentialAging,
    /// Logarithmic aging A·ln(1 + t/τ), τ 0.3–1 d, |A| 10–20 µg: `aging_drift` (logarithmic)
    /// with τ within a factor e^1.6.
    LogAging,
    /// A warm-up A·e^(−t/τ), τ 3–8 h, |A| 10–30 µg: `warmup` with τ within ±50 %.
    Warmup,
    /// A 4 µg step at 20–80 % of the span: `step` within 10 min, size within 30 % (or 3 σ).
    SmallStep,
    /// A bistable sensor: 3–5 flips of unequal sizes (4–10 µg, alternating sign) at least 1 d
    /// apart: every flip a `step` within 10 min, size within 30 % (or 3 σ).
    Flips,
    /// A first-order lag of the true temperature, τ 20–40 min, 5–10 µg/°C, on a programme of
    /// ±0.5 °C ramps: `thermal_lag` (or a `lag2_coupling` of the temperature) with τ within
    /// a factor e^0.7 for the first order.
    ThermalLag,
    /// A 3–7 h sinusoid of 1–2 µg: `periodic` with its period within 2 %.
    Periodic,
    /// A pressure admittance of 0.6–1.2 µg/hPa on the true pressure: `pressure_admittance`
    /// within ±40 %.
    Pressure,
}

const CAUSES: [Cause; 14] = [
    Cause::Null,
    Cause::RandomWalk,
    Cause::TwoPowers,
    Cause::TwoPowers,
    Cause::Logistic,
    Cause::ExponentialAging,
    Cause::LogAging,
    Cause::Warmup,
    Cause::SmallStep,
    Cause::Flips,
    Cause::ThermalLag,
    Cause::Periodic,
    Cause::Pressure,
    Cause::Null,
];

/// What was hidden, for the comparison afterwards (never passed to the tool).
#[derive(Debug, Clone)]
struct Hidden {
    cause: Cause,
    /// The cause's parameters: exponents, τ, period, coefficient, size.
    p: Vec<f64>,
    /// Steps (time s, size g).
    steps: Vec<(f64, f64)>,
    /// The ideal detector's χ² of what was hidden (the known shape under the known noise,
    /// `hidden::matched_filter_snr`²), for the record: docs/discovery-causes.md compares it with
    /// where the drifts are named.
    ideal_chi2: f64,
}

fn sign(r: &mut ChaCha8Rng) -> f64 {
    hidden::sign(r)
}

/// One log of `cause` from `seed`: its station, output and what was hidden.
fn draw(cause: Cause, seed: u64) -> (accomp_host::log::Log, Hidden) {
    let mut r = synth::rng(seed);
    let thermal = match cause {
        Cause::ThermalLag => synth::Thermal::Programme {
            amplitude_c: 0.5,
            min_half_s: 2.0 * 3600.0,
            max_half_s: 6.0 * 3600.0,
        },
        _ => synth::Thermal::Regulated,
    };
    let st = synth::station(ROWS, DT_S, thermal, &mut r);
    let mut noise = synth::draw_noise(&mut r);
    let span = ROWS as f64 * DT_S;
    let t = &st.t_s;
    let mut h = Hidden {
        cause,
        p: Vec::new(),
        steps: Vec::new(),
        ideal_chi2: 0.0,
    };
    let extra: Vec<f64> = match cause {
        Cause::Null => vec![0.0; ROWS],
        Cause::RandomWalk => {
            noise.flicker_floor = 1e-12;
            noise.rw_per_sqrt_s = r.random_range(20.0e-9..40.0e-9);
            vec![0.0; ROWS]
        }
        Cause::TwoPowers => {
            let (p1, p2) = (r.random_range(1.3..1.7), r.random_range(2.3..3.0));
            let a = sign(&mut r) * r.random_range(80.0e-6..150.0e-6);
            h.p = vec![p1, p2, a];
            t.iter()
                .map(|x| 0.5 * a * ((x / span).powf(p1) + (x / span).powf(p2)))
                .collect()
        }
        Cause::Logistic => {
            let tc = r.random_range(0.4..0.6) * span;
            let w = r.random_range(0.7..1.5) * DAY_S;
            let a = sign(&mut r) * r.random_range(30.0e-6..60.0e-6);
            h.p = vec![tc, w, a];
            t.iter()
                .map(|x| a / (1.0 + (-(x - tc) / w).exp()))
                .collect()
        }
        Cause::ExponentialAging => {
            let tau = r.random_range(1.5..4.0) * DAY_S;
            let a = sign(&mut r) * r.random_range(40.0e-6..80.0e-6);
            h.p = vec![tau, a];
            t.iter().map(|x| a * (1.0 - (-x / tau).exp())).collect()
        }
        Cause::LogAging => {
            let tau = r.random_range(0.3..1.0) * DAY_S;
            let a = sign(&mut r) * r.random_range(10.0e-6..20.0e-6);
            h.p = vec![tau, a];
            t.iter().map(|x| a * (1.0 + x / tau).ln()).collect()
        }
        Cause::Warmup => {
            let tau = r.random_range(3.0..8.0) * 3600.0;
            let a = sign(&mut r) * r.random_range(10.0e-6..30.0e-6);
            h.p = vec![tau, a];
            t.iter().map(|x| a * (-x / tau).exp()).collect()
        }
        Cause::SmallStep => {
            let tj = r.random_range(0.2..0.8) * span;
            h.steps = vec![(tj, sign(&mut r) * 4.0e-6)];
            step_series(t, &h.steps)
        }
        Cause::Flips => {
            let k = r.random_range(3..=5);
            let mut times: Vec<f64> = Vec::new();
            while times.len() < k {
                let x = r.random_range(0.05..0.95) * span;
                if times.iter().all(|y| (x - y).abs() > DAY_S) {
                    times.push(x);
                }
            }
            times.sort_by(f64::total_cmp);
            let mut up = r.random::<bool>();
            for x in times {
                let s = r.random_range(4.0e-6..10.0e-6);
                h.steps.push((x, if up { s } else { -s }));
                up = !up;
            }
            step_series(t, &h.steps)
        }
        Cause::ThermalLag => {
            let tau = r.random_range(1200.0..2400.0);
            let k = sign(&mut r) * r.random_range(5.0e-6..10.0e-6);
            h.p = vec![tau, k];
            let lag = synth::low_pass(&st.temp_true_c, DT_S, tau);
            synth::lag_error(&lag, &st.temp_true_c, k)
        }
        Cause::Periodic => {
            let period = r.random_range(3.0..7.0) * 3600.0;
            let a = r.random_range(1.0e-6..2.0e-6);
            let ph = r.random_range(0.0..std::f64::consts::TAU);
            h.p = vec![period, a];
            t.iter()
                .map(|x| a * (std::f64::consts::TAU * x / period + ph).sin())
                .collect()
        }
        Cause::Pressure => {
            let k = sign(&mut r) * r.random_range(0.6e-6..1.2e-6);
            h.p = vec![k / 100.0];
            let p0 = st.pressure_true_hpa[0];
            st.pressure_true_hpa.iter().map(|p| k * (p - p0)).collect()
        }
    };
    let allan = accomp_host::sim::noise::AllanParams {
        white_adev_1s: noise.white_1s,
        flicker_floor: noise.flicker_floor,
        random_walk_per_sqrt_s: noise.rw_per_sqrt_s,
    };
    let nuisance = hidden::static_nuisance(t, &st.temp_meas_c);
    h.ideal_chi2 = hidden::matched_filter_snr(&extra, &nuisance, &allan, DT_S, span).powi(2);
    let y = synth::output_g(&st, &noise, &extra, &mut r);
    (synth::log_of(&st, y), h)
}

fn step_series(t_s: &[f64], steps: &[(f64, f64)]) -> Vec<f64> {
    t_s.iter()
        .map(|&t| steps.iter().filter(|s| t >= s.0).map(|s| s.1).sum())
        .collect()
}

fn value(a: &Accepted, key: &str) -> f64 {
    hidden::param_value(a, key)
}

fn within_factor(x: f64, truth: f64, ln_factor: f64) -> bool {
    x > 0.0 && truth > 0.0 && (x / truth).ln().abs() <= ln_factor
}

/// (right, extras) of one log: which accepted effects explain the cause, the rest are extras.
fn score(d: &Discovery, h: &Hidden) -> (bool, usize) {
    let acc = &d.selection.accepted;
    let is_drift =
        |a: &Accepted| matches!(a.effect.name(), "creep_drift" | "aging_drift" | "warmup");
    // Indices of the accepted effects that are the cause, and whether they are right.
    let (matched, right): (Vec<usize>, bool) = match h.cause {
        Cause::Null | Cause::RandomWalk => (Vec::new(), acc.is_empty()),
        Cause::TwoPowers => {
            let i = acc.iter().position(|a| a.effect.name() == "creep_drift");
            let ok = i.is_some_and(|i| {
                let th = value(&acc[i], "exponent");
                th >= h.p[0] - 0.3 && th <= h.p[1] + 0.5
            });
            (i.into_iter().collect(), ok)
        }
        Cause::Logistic => {
            // Any drift family; a step beside it is part of the same cause, not an extra.
            let m: Vec<usize> = (0..acc.len())
                .filter(|&i| is_drift(&acc[i]) || acc[i].effect.name() == "step")
                .collect();
            let ok = m.iter().any(|&i| is_drift(&acc[i]));
            (m, ok)
        }
        Cause::ExponentialAging | Cause::Warmup => {
            let i = acc.iter().position(|a| a.effect.name() == "warmup");
            let ok = i.is_some_and(|i| within_factor(value(&acc[i], "tau_s"), h.p[0], 0.405));
            (i.into_iter().collect(), ok)
        }
        Cause::LogAging => {
            let i = acc.iter().position(|a| a.effect.name() == "aging_drift");
            let ok = i.is_some_and(|i| within_factor(value(&acc[i], "tau_s"), h.p[0], 1.6));
            (i.into_iter().collect(), ok)
        }
        Cause::SmallStep | Cause::Flips => {
            let mut used = Vec::new();
            let mut found = 0;
            for &(tj, s) in &h.steps {
                let hit = (0..acc.len()).find(|&i| {
                    let a = &acc[i];
                    if a.effect.name() != "step" || used.contains(&i) {
                        return false;
                    }
                    let size = a.params.iter().find(|(k, _)| k == "size").map(|(_, p)| *p);
                    size.is_some_and(|z| {
                        (value(a, "time_s") - tj).abs() <= 600.0
                            && (z.value - s).abs() <= (0.3 * s.abs()).max(3.0 * z.sigma)
                    })
                });
                if let Some(i) = hit {
                    used.push(i);
                    found += 1;
                }
            }
            (used, found == h.steps.len())
        }
        Cause::ThermalLag => {
            let i = acc
                .iter()
                .position(|a| matches!(a.effect.name(), "thermal_lag" | "lag2_coupling"));
            let ok = i.is_some_and(|i| {
                acc[i].effect.name() == "lag2_coupling"
                    || within_factor(value(&acc[i], "tau_s"), h.p[0], 0.7)
            });
            (i.into_iter().collect(), ok)
        }
        Cause::Periodic => {
            let i = acc.iter().position(|a| a.effect.name() == "periodic");
            let ok = i.is_some_and(|i| within_factor(value(&acc[i], "period_s"), h.p[0], 0.02));
            (i.into_iter().collect(), ok)
        }
        Cause::Pressure => {
            let i = acc
                .iter()
                .position(|a| a.effect.name() == "pressure_admittance");
            let ok = i.is_some_and(|i| {
                let c = value(&acc[i], "coefficient");
                c * h.p[0] > 0.0 && (c / h.p[0] - 1.0).abs() <= 0.4
            });
            (i.into_iter().collect(), ok)
        }
    };
    (right, acc.len() - matched.len())
}

/// Right logs measured when this test was written (10 of 14); the test fails below it.
const RIGHT_AT_LEAST: usize = 10;
/// Extra effects over all logs, at most (the goal).
const EXTRAS_AT_MOST: usize = 2;

#[test]
fn a_dozen_logs_with_one_cause_each_are_named_right_with_few_extras() {
    let mut rng = synth::rng(0x0D0_2E4);
    let (mut right, mut extras) = (0, 0);
    for (i, &cause) in CAUSES.iter().enumerate() {
        let (log, h) = draw(cause, rng.random::<u64>());
        let (_, d) = hidden::discover_blind(&log);
        let (ok, extra) = score(&d, &h);
        eprintln!(
            "log {i} {cause:?} {:?} steps {:?} ideal χ² {:.1}: right {ok}, extras {extra}; \
             accepted {:?}; refused {:?}; last round {:?}",
            h.p,
            h.steps,
            h.ideal_chi2,
            hidden::accepted_with_params(&d),
            d.selection.refused,
            d.selection.last_round
        );
        right += usize::from(ok);
        extras += extra;
    }
    eprintln!("DOZEN: {right}/{} right, {extras} extras", CAUSES.len());
    assert!(right >= RIGHT_AT_LEAST, "right {right}/{}", CAUSES.len());
    assert!(extras <= EXTRAS_AT_MOST, "extras {extras}");
}
