//! Drift families for the drift tests (`discover_drift_families.rs`) and the detection-limit
//! measurement (`examples/drift_detection_limit.rs`): the shapes, written here without the
//! detector's columns; the ideal detector's χ² of a shape under the log's noise; and how a
//! discovery's named drift is judged against what was hidden.
//!
//! The ideal χ² is `hidden::matched_filter_snr`² — the known shape whitened by the true noise
//! (white + flicker + random walk as a state-space model), after the static baseline's nuisance
//! columns (offset, linear drift, temperature cubic) took what they can. Beside it the pure
//! random-walk form Σ(Δs − mean Δs)²/(q²Δt) (the linear drift removed: the mean increment),
//! which the white and flicker noise lower at the shortest periods.

// Each test crate uses a different subset of this module.
#![allow(dead_code)]

use accomp_host::allan::detrend_linear;
use accomp_host::discover::effects::Param;
use accomp_host::discover::select::Accepted;
use accomp_host::discover::Discovery;
use rand::Rng;
use rand_chacha::ChaCha8Rng;

const DAY_S: f64 = 86_400.0;

/// A drift's shape. The first three are the catalogue's families (the detector's columns are
/// the same functions); the last two are shapes no family holds exactly.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Family {
    /// Exponential aging A·(1 − e^(−t/τ)), τ 10–28 % of the span (1.4–3.9 d in 14 days; the
    /// detector's grid ends at a third of the span): `warmup` (exponential), τ within ±50 %.
    Exponential,
    /// Logarithmic aging A·ln(1 + t/τ), τ 0.3–1 d: `aging_drift` (logarithmic), τ within a
    /// factor e^1.6 (ln(1 + t/τ) changes little with τ over a record many τ long).
    Logarithmic,
    /// Power-law creep A·(t/span)^p, p 1.6–2.8: `creep_drift` (power law), exponent ±0.3.
    PowerLaw,
    /// A logistic A/(1 + e^(−(t − t_c)/w)), t_c at 40–60 % of the span, w 0.7–1.5 d.
    Logistic,
    /// Two exponential agings A·((1 − e^(−t/τ₁)) + (1 − e^(−t/τ₂)))/2, τ₁ 0.4–1 d, τ₂ 2–4 d
    /// (the detector fits one τ).
    TwoExponentials,
}

impl Family {
    /// The catalogue entry a family of the catalogue is named as (None: not in the catalogue).
    pub fn entry(self) -> Option<&'static str> {
        match self {
            Family::Exponential => Some("warmup"),
            Family::Logarithmic => Some("aging_drift"),
            Family::PowerLaw => Some("creep_drift"),
            Family::Logistic | Family::TwoExponentials => None,
        }
    }
}

/// The shape of `family` at unit amplitude on `t_s` (from 0), with its drawn parameters.
pub fn unit_shape(family: Family, t_s: &[f64], rng: &mut ChaCha8Rng) -> (Vec<f64>, Vec<f64>) {
    let span = t_s.last().copied().unwrap_or(0.0) + t_s.get(1).copied().unwrap_or(0.0);
    match family {
        Family::Exponential => {
            let tau = rng.random_range(0.10..0.28) * span;
            let s = t_s.iter().map(|t| 1.0 - (-t / tau).exp()).collect();
            (s, vec![tau])
        }
        Family::Logarithmic => {
            let tau = rng.random_range(0.3..1.0) * DAY_S;
            (
                t_s.iter().map(|t| (1.0 + t / tau).ln()).collect(),
                vec![tau],
            )
        }
        Family::PowerLaw => {
            let p = rng.random_range(1.6..2.8);
            (t_s.iter().map(|t| (t / span).powf(p)).collect(), vec![p])
        }
        Family::Logistic => {
            let tc = rng.random_range(0.4..0.6) * span;
            let w = rng.random_range(0.7..1.5) * DAY_S;
            let s = t_s
                .iter()
                .map(|t| 1.0 / (1.0 + (-(t - tc) / w).exp()))
                .collect();
            (s, vec![tc, w])
        }
        Family::TwoExponentials => {
            let t1 = rng.random_range(0.4..1.0) * DAY_S;
            let t2 = rng.random_range(2.0..4.0) * DAY_S;
            let s = t_s
                .iter()
                .map(|t| 1.0 - 0.5 * ((-t / t1).exp() + (-t / t2).exp()))
                .collect();
            (s, vec![t1, t2])
        }
    }
}

/// The pure random-walk χ² of a shape: Σ(Δs − mean Δs)²/(q²Δt).
pub fn random_walk_chi2(s: &[f64], dt_s: f64, q_per_sqrt_s: f64) -> f64 {
    let d: Vec<f64> = s.windows(2).map(|w| w[1] - w[0]).collect();
    let m = d.iter().sum::<f64>() / d.len().max(1) as f64;
    d.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (q_per_sqrt_s.powi(2) * dt_s)
}

/// A family's curve as the detector reports it (written here from the report's definitions):
/// `warmup` e^(−t/τ), `aging_drift` ln(1 + t/τ), `creep_drift` (t/1 day)^θ, t from the first row.
pub fn reported_curve(name: &str, shape_param: f64, t_s: &[f64]) -> Option<Vec<f64>> {
    let t0 = t_s.first().copied().unwrap_or(0.0);
    let f: Box<dyn Fn(f64) -> f64> = match name {
        "warmup" => Box::new(move |t| (-t / shape_param).exp()),
        "aging_drift" => Box::new(move |t| (1.0 + t / shape_param).ln()),
        "creep_drift" => Box::new(move |t| (t.max(0.0) / DAY_S).powf(shape_param)),
        _ => return None,
    };
    Some(t_s.iter().map(|t| f(t - t0)).collect())
}

fn rms(x: &[f64]) -> f64 {
    (x.iter().map(|v| v * v).sum::<f64>() / x.len().max(1) as f64).sqrt()
}

/// How a discovery named a hidden drift.
#[derive(Debug, Clone)]
pub struct Verdict {
    /// The drift entry the discovery named (None: no drift family).
    pub named: Option<String>,
    /// The other family it reported as equally good ("ambiguous: A or B"), if one: the hidden
    /// one when it is among the alternatives, else the closest.
    pub or: Option<String>,
    /// Shape parameter (τ s or exponent) with its σ of the entry that matches the hidden
    /// family, when one does (the named one or the ambiguity's other).
    pub shape_param: Option<Param>,
    /// RMS of (hidden − the named drifts' curves × their amplitudes, summed) over the RMS of the
    /// hidden drift, both after an offset and a linear drift (the baseline's) are removed.
    pub mismatch: f64,
    /// Accepted effects that are not a drift family.
    pub others: Vec<String>,
}

/// Judges `d` against the hidden drift `shape` (output unit, one value per row of `t_s`).
pub fn verdict(d: &Discovery, t_s: &[f64], shape: &[f64], family: Family) -> Verdict {
    let is_drift = |a: &Accepted| a.effect.drift_family().is_some();
    let acc = &d.selection.accepted;
    let drift = acc.iter().find(|a| is_drift(a));
    let others = acc
        .iter()
        .filter(|a| !is_drift(a))
        .map(|a| a.effect.name().to_owned())
        .collect();
    let Some(a) = drift else {
        return Verdict {
            named: None,
            or: None,
            shape_param: None,
            mismatch: 1.0,
            others,
        };
    };
    let name = a.effect.name().to_owned();
    let amb = a
        .ambiguous_with
        .iter()
        .find(|x| Some(x.other.as_str()) == family.entry())
        .or(a.ambiguous_with.first());
    let or = amb.map(|x| x.other.clone());
    let key = |n: &str| {
        if n == "creep_drift" {
            "exponent"
        } else {
            "tau_s"
        }
    };
    let get = |ps: &[(String, Param)], k: &str| ps.iter().find(|(q, _)| q == k).map(|(_, p)| *p);
    let shape_param = match family.entry() {
        Some(e) if e == name => get(&a.params, key(e)),
        Some(e) if or.as_deref() == Some(e) => amb.and_then(|x| get(&x.other_parameters, key(e))),
        _ => None,
    };
    // Every accepted drift family together: a shape outside the catalogue may be named as two.
    let mut fit = vec![0.0; t_s.len()];
    for b in acc.iter().filter(|a| is_drift(a)) {
        let n = b.effect.name();
        let theta = get(&b.params, key(n)).map_or(f64::NAN, |p| p.value);
        let amp = get(&b.params, "amplitude").map_or(f64::NAN, |p| p.value);
        if let Some(c) = reported_curve(n, theta, t_s) {
            fit.iter_mut().zip(&c).for_each(|(f, v)| *f += amp * v);
        }
    }
    let diff: Vec<f64> = shape.iter().zip(&fit).map(|(s, f)| s - f).collect();
    let mismatch = rms(&detrend_linear(&diff)) / rms(&detrend_linear(shape));
    Verdict {
        named: Some(name),
        or,
        shape_param,
        mismatch,
        others,
    }
}

/// Whether the hidden family is named right: its catalogue entry named (or reported as equally
/// good beside the named one) with its shape parameter within the family's tolerance or 3 σ; a shape
/// outside the catalogue: any family whose curve reproduces it within `max_mismatch`.
pub fn named_right(v: &Verdict, family: Family, truth: &[f64], max_mismatch: f64) -> bool {
    // Within the family's tolerance, or within 3 σ of its own reported uncertainty.
    let ok_param = |p: Param| {
        let near = (p.value - truth[0]).abs() <= 3.0 * p.sigma;
        near || match family {
            Family::Exponential => (p.value / truth[0]).ln().abs() <= 0.405,
            Family::Logarithmic => (p.value / truth[0]).ln().abs() <= 1.6,
            Family::PowerLaw => (p.value - truth[0]).abs() <= 0.3,
            Family::Logistic | Family::TwoExponentials => true,
        }
    };
    match family.entry() {
        Some(_) => v.shape_param.is_some_and(ok_param),
        None => v.named.is_some() && v.mismatch <= max_mismatch,
    }
}

/// Rows and spacing of the synthetic drift logs: 14 days at 120 s.
pub const ROWS: usize = 14 * 720;
/// Spacing, s.
pub const DT_S: f64 = 120.0;

/// A synthetic drift log and what was hidden in it (never passed to the tool).
pub struct Drawn {
    /// The log (`common/synth.rs`: a regulated station, white 2 µg·√s + 1/f flicker 0.3–1 µg +
    /// random walk 2–8 ng/√s).
    pub log: accomp_host::log::Log,
    /// Time, s.
    pub t_s: Vec<f64>,
    /// The hidden drift, g.
    pub shape_g: Vec<f64>,
    /// Its amplitude, g.
    pub amplitude_g: f64,
    /// The family's drawn parameters (`unit_shape`).
    pub truth: Vec<f64>,
    /// The ideal detector's χ² of the hidden drift (`hidden::matched_filter_snr`²).
    pub chi2: f64,
    /// The pure random-walk χ² of the same drift.
    pub chi2_random_walk: f64,
    /// The noise drawn: white at 1 s, flicker floor, random walk per √s (g).
    pub noise: [f64; 3],
}

/// A 14-day log from `seed` with a drift of `family` sized for an ideal χ² of `chi2` (its sign
/// drawn). The station, the noise and the shape depend only on the seed, so one seed at several
/// `chi2` is one record with the drift scaled.
pub fn synthetic(family: Family, seed: u64, chi2: f64) -> Drawn {
    use super::{hidden, synth};
    let mut r = synth::rng(seed);
    let st = synth::station(ROWS, DT_S, synth::Thermal::Regulated, &mut r);
    let noise = synth::draw_noise(&mut r);
    let (unit, truth) = unit_shape(family, &st.t_s, &mut r);
    let sign = hidden::sign(&mut r);
    let allan = accomp_host::sim::noise::AllanParams {
        white_adev_1s: noise.white_1s,
        flicker_floor: noise.flicker_floor,
        random_walk_per_sqrt_s: noise.rw_per_sqrt_s,
    };
    let span = ROWS as f64 * DT_S;
    let nuisance = hidden::static_nuisance(&st.t_s, &st.temp_meas_c);
    let unit_chi2 = hidden::matched_filter_snr(&unit, &nuisance, &allan, DT_S, span).powi(2);
    let amplitude_g = sign * (chi2 / unit_chi2).sqrt();
    let shape_g: Vec<f64> = unit.iter().map(|u| amplitude_g * u).collect();
    let chi2_random_walk = random_walk_chi2(&shape_g, DT_S, noise.rw_per_sqrt_s);
    let y = synth::output_g(&st, &noise, &shape_g, &mut r);
    Drawn {
        log: synth::log_of(&st, y),
        t_s: st.t_s.clone(),
        shape_g,
        amplitude_g,
        truth,
        chi2,
        chi2_random_walk,
        noise: [noise.white_1s, noise.flicker_floor, noise.rw_per_sqrt_s],
    }
}
