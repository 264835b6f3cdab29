//! Is an accepted effect's shape right? The catalogue names the *closest* cause; a real effect
//! need not have the catalogue's exact shape (a second-order thermal path named `thermal_lag`,
//! a ramp named `step`, a distribution of hysteresis widths named by one play, a power-law
//! settling named `aging_drift`). The check asks whether the same effect at a second value of
//! its nonlinear parameter — a two-component version of the shape — explains significantly
//! more of the final residual:
//!
//! Δχ² = whitened RSS reduction from adding the effect's columns at θ′ (best θ′ away from θ),
//! charged exactly like a new effect: (columns)·ln n + max(ln n, 2 ln M), M the number of θ′
//! tried. If the extension would pass that BIC, the single-parameter shape does not describe
//! the data: the fit is reported as **poor** (text and JSON), with θ′. A shape that is right
//! leaves only noise for θ′, whose largest Δχ² over M trials is ≈ 2 ln M, under the charge.
//!
//! Steps are checked at θ ± 1…55 samples (a ramp or a two-stage jump is two steps close
//! together); gridded effects (lags, τ, play width) over their search grid minus the points
//! within a factor 1.5 of θ; `periodic` and the linear effects are not checked (no shape
//! parameter).

use super::baseline::{orthogonalize, Basis, Rows};
use super::effects::{self, columns, Context, Effect};
use super::import::Dataset;
use super::noise::NoiseModel;
use super::select::Accepted;

/// The result of the shape check of one accepted effect.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ShapeCheck {
    /// Catalogue name.
    pub effect: String,
    /// The accepted nonlinear parameter.
    pub theta: f64,
    /// The best second value of it.
    pub second_theta: f64,
    /// Whitened χ² reduction from the second component.
    pub delta_chi2: f64,
    /// What a new effect is charged (the BIC penalty with look-elsewhere).
    pub threshold: f64,
    /// Whether the single-parameter shape is inadequate (Δχ² above the charge).
    pub poor: bool,
}

/// Second parameter values to try for an accepted effect (empty: not checked).
fn second_thetas(e: &Effect, ds: &Dataset, theta: f64) -> Vec<f64> {
    if !theta.is_finite() {
        return Vec::new();
    }
    match e {
        Effect::Step { .. } => [1.0, 2.0, 3.0, 5.0, 8.0, 13.0, 21.0, 34.0, 55.0]
            .iter()
            .flat_map(|k| [theta - k * ds.dt_s, theta + k * ds.dt_s])
            .filter(|x| {
                let (a, b) = (ds.t_s.first().copied(), ds.t_s.last().copied());
                a.zip(b).is_some_and(|(a, b)| *x > a && *x < b)
            })
            .collect(),
        Effect::Periodic => Vec::new(),
        _ => effects::grid(e, ds)
            .into_iter()
            .filter(|&g| g > 0.0 && (g / theta).ln().abs() > 1.5_f64.ln())
            .collect(),
    }
}

/// Shape checks of the accepted effects against the final model `cols` (baseline and effects)
/// of `y`, whitened by `noise`.
pub fn check(
    ds: &Dataset,
    ctx: &Context,
    cols: &[Vec<f64>],
    y: &[f64],
    accepted: &[Accepted],
    noise: &NoiseModel,
) -> Vec<ShapeCheck> {
    if accepted.is_empty() || y.is_empty() {
        return Vec::new();
    }
    let rows = Rows::with_noise(noise, &ds.t_s, None);
    let wc: Vec<Vec<f64>> = cols.iter().map(|c| rows.whiten(c, 0.0)).collect();
    let basis = Basis::new(&wc);
    let r_w = basis.residual(&rows.whiten(y, 0.0));
    let rss: f64 = r_w.iter().map(|v| v * v).sum();
    let n = r_w.len() as f64;
    if rss <= 0.0 || n < 10.0 {
        return Vec::new();
    }
    let mut out = Vec::new();
    for a in accepted {
        let thetas = second_thetas(&a.effect, ds, a.theta.value);
        if thetas.is_empty() {
            continue;
        }
        let mut best = (f64::NAN, 0.0_f64, 0usize);
        for &th in &thetas {
            let extra = columns(&a.effect, ds, ctx, th);
            let mut red = 0.0;
            let mut q: Vec<Vec<f64>> = basis.q.clone();
            for c in &extra {
                let mut w = rows.whiten(c, 0.0);
                if w.iter().any(|v| !v.is_finite()) {
                    red = 0.0;
                    break;
                }
                orthogonalize(&q, &mut w);
                let norm = w.iter().map(|v| v * v).sum::<f64>().sqrt();
                if norm <= 1e-9 * n.sqrt() {
                    continue;
                }
                w.iter_mut().for_each(|v| *v /= norm);
                let d: f64 = w.iter().zip(&r_w).map(|(a, b)| a * b).sum();
                red += d * d;
                q.push(w);
            }
            if red > best.1 {
                best = (th, red, extra.len());
            }
        }
        // The same charge as the selection's ΔBIC for a new effect, in χ² units of the
        // whitened residual (n·ln(RSS/RSS′) ≈ Δχ²·n/RSS).
        let m = thetas.len() as f64;
        let k = best.2.max(1) as f64;
        let threshold = k * n.ln() + n.ln().max(2.0 * m.ln());
        let delta = if best.1 < rss {
            -n * (1.0 - best.1 / rss).ln()
        } else {
            f64::INFINITY
        };
        out.push(ShapeCheck {
            effect: a.effect.name().to_owned(),
            theta: a.theta.value,
            second_theta: best.0,
            delta_chi2: delta,
            threshold,
            poor: delta > threshold,
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::discover::effects::Param;
    use crate::discover::select::CvScore;

    fn dataset(y: Vec<f64>) -> Dataset {
        let n = y.len();
        let mut seg = vec![false; n];
        seg[0] = true;
        Dataset {
            t_s: (0..n).map(|i| 10.0 * i as f64).collect(),
            y,
            segment_start: seg,
            channels: Vec::new(),
            output_name: "output_g".into(),
            output_unit: "g".into(),
            unit_per_g: Some(1.0),
            input_g: Some(1.0),
            start_unix_s: None,
            site: None,
            dt_s: 10.0,
            samples_per_point: Vec::new(),
            notes: Vec::new(),
            warnings: Vec::new(),
        }
    }

    /// The check of a step accepted at `theta` on `y` (white noise of the pseudo-noise's
    /// variance): is it called poor?
    fn step_is_poor(y: Vec<f64>, theta: f64, noise_std: f64) -> bool {
        let ds = dataset(y);
        let ctx = Context::default();
        let mut cols = vec![vec![1.0; ds.len()]];
        cols.extend(columns(&Effect::Step { duration_s: 0.0 }, &ds, &ctx, theta));
        let cv = CvScore {
            raw: 1.0,
            prediction_z: 1.0,
        };
        let acc = Accepted {
            effect: Effect::Step { duration_s: 0.0 },
            theta: Param {
                value: theta,
                sigma: f64::NAN,
            },
            params: Vec::new(),
            params_at_acceptance: Vec::new(),
            delta_bic: -100.0,
            std_before: 1.0,
            std_after: 1.0,
            cv_before: cv,
            cv_after: cv,
            forward_before: cv,
            forward_after: cv,
        };
        let c = check(
            &ds,
            &ctx,
            &cols,
            &ds.y,
            &[acc],
            &NoiseModel::white(noise_std * noise_std),
        );
        assert_eq!(c.len(), 1);
        c[0].poor
    }

    #[test]
    fn a_ramp_fitted_as_a_step_is_poor_and_a_step_is_not() {
        let n = 600;
        // Deterministic pseudo-noise of std ≈ 0.07 (irrational frequencies, no step-like part).
        let e = |i: usize| 0.1 * ((i as f64 * 2.399_963).sin() * (i as f64 * 0.618).cos());
        let sd = 0.1 * 0.5;
        // A unit change spread over 40 samples (400 s) around t = 3000 s.
        let ramp: Vec<f64> = (0..n)
            .map(|i| ((10.0 * i as f64 - 2800.0) / 400.0).clamp(0.0, 1.0) + e(i))
            .collect();
        assert!(step_is_poor(ramp, 2995.0, sd));
        let step: Vec<f64> = (0..n)
            .map(|i| f64::from(10.0 * i as f64 >= 2995.0) + e(i))
            .collect();
        assert!(!step_is_poor(step, 2995.0, sd));
    }
}
