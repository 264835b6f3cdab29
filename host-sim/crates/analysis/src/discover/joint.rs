//! The final joint fit of the accepted effects: each nonlinear parameter re-optimised with all
//! other columns in the model, the tide's instrument delay by Gauss–Newton, the covariance.

use super::baseline::{gls, Basis, Rows};
use super::current_model::{fit_state, leftover_correlation_inflation, NoiseChoice};
use super::effects::{self, columns, Context, Effect, Param};
use super::fitters::profile_sigma;
use super::import::Dataset;
use super::noise::NoiseFit;
use super::select::Accepted;
use crate::numerics::optimize::golden_section_min as golden;

/// The final joint fit: every accepted effect refitted together with the baseline, nonlinear
/// parameters included (one coordinate sweep: each θ re-optimised with all other columns in
/// the model), under the final noise model.
#[derive(Debug, Clone)]
pub struct JointFit {
    /// Names of the effects' linear coefficients, in order (`<index>:<effect>:c<j>`).
    pub names: Vec<String>,
    /// Their covariance (output units², conditional on the nonlinear parameters, whose own
    /// uncertainties come from the profile curvature), scaled by the whitened residual variance.
    pub covariance: Vec<Vec<f64>>,
    /// Columns of each effect at its jointly fitted θ.
    pub effect_columns: Vec<Vec<Vec<f64>>>,
}

/// Joint refit of the accepted effects; replaces each one's `params` and `theta` by the joint
/// values (the acceptance round's stay in `params_at_acceptance`).
pub(super) fn joint_fit(
    ds: &Dataset,
    target: &[f64],
    base_cols: &[Vec<f64>],
    accepted: &mut [Accepted],
    ctx: &Context,
    noise: &NoiseFit,
) -> JointFit {
    let mut thetas: Vec<f64> = accepted.iter().map(|a| a.theta.value).collect();
    let mut ecols: Vec<Vec<Vec<f64>>> = accepted
        .iter()
        .zip(&thetas)
        .map(|(a, &th)| columns(&a.effect, ds, ctx, th))
        .collect();
    let others = |ecols: &[Vec<Vec<f64>>], skip: usize| {
        let mut c = base_cols.to_vec();
        for (j, e) in ecols.iter().enumerate() {
            if j != skip {
                c.extend(e.iter().cloned());
            }
        }
        c
    };
    let mut sigmas = vec![f64::NAN; accepted.len()];
    for i in 0..accepted.len() {
        let th = thetas[i];
        // A lag found on the full-rate rows keeps its τ and σ from there: on the bins its τ is
        // not resolved (only its column at that τ is known, `Context::full_rate`).
        if !th.is_finite() {
            continue;
        }
        if ctx.full_rate_column(&accepted[i].effect, th).is_some() {
            sigmas[i] = accepted[i].theta.sigma;
            continue;
        }
        let e = accepted[i].effect.clone();
        let (cur, _, _) = fit_state(ds, &others(&ecols, i), target, NoiseChoice::Fixed(noise));
        let eval = |x: f64| cur.rss_with(&columns(&e, ds, ctx, x));
        let g = effects::grid(&e, ds);
        let (lo, hi, h) = match e {
            Effect::Step { duration_s } => {
                let w = (3.0 * ds.dt_s).max(0.5 * duration_s);
                (th - w, th + w, ds.dt_s)
            }
            Effect::Periodic => {
                let span = ds.span_s().max(ds.dt_s);
                let f = 1.0 / th;
                (
                    1.0 / (f + 0.5 / span),
                    1.0 / (f - 0.5 / span).max(0.5 / span),
                    0.02 * th,
                )
            }
            _ => {
                let (gmin, gmax) = (
                    g.iter()
                        .copied()
                        .filter(|v| *v > 0.0)
                        .fold(f64::INFINITY, f64::min),
                    g.iter().copied().fold(0.0, f64::max),
                );
                ((th / 1.5).max(gmin), (th * 1.5).min(gmax), 0.02 * th)
            }
        };
        let best = if matches!(e, Effect::ThermalHysteresis) || hi <= lo || hi.is_nan() || lo <= 0.0
        {
            th
        } else {
            let x = golden(|lx| eval(lx.exp()), lo.ln(), hi.ln(), 16).exp();
            if eval(x) < eval(th) {
                x
            } else {
                th
            }
        };
        thetas[i] = best;
        ecols[i] = columns(&e, ds, ctx, best);
        // σ_θ from the RSS profile's curvature, with the others in the model.
        let (r0, rp, rm) = (eval(best), eval(best + h), eval((best - h).max(h * 0.01)));
        sigmas[i] = profile_sigma(
            (r0, rp, rm),
            h,
            cur.r_w.len(),
            cur.basis.q.len() + ecols[i].len(),
        );
    }
    let rows = Rows::with_noise(&noise.model, &ds.t_s, None);
    let delay = tide_delay(ds, target, ctx, base_cols, accepted, &mut ecols, &rows);
    let mut all = others(&ecols, usize::MAX);
    if let Some(d) = &delay {
        all.push(d.derivative.clone());
    }
    let fit = gls(&all, target, 0.0, &rows);
    let wc: Vec<Vec<f64>> = all.iter().map(|c| rows.whiten(c, 0.0)).collect();
    let basis = Basis::new(&wc);
    // Standard errors inflated for the correlation the whitening left, as in each round.
    let r_w = basis.residual(&rows.whiten(target, 0.0));
    let infl2 = leftover_correlation_inflation(&r_w);
    let s2 = infl2 * fit.rss_w / (fit.n_w.saturating_sub(fit.k).max(1)) as f64;
    let cov_all = basis.covariance();
    let se: Vec<f64> = fit.se.iter().map(|v| v * infl2.sqrt()).collect();
    let k0 = base_cols.len();
    let mut names = Vec::new();
    let mut at = k0;
    let mut tide_at = None;
    for (i, a) in accepted.iter_mut().enumerate() {
        let m = ecols[i].len();
        for j in 0..m {
            names.push(format!("{i}:{}:c{j}", a.effect.name()));
        }
        if delay.as_ref().is_some_and(|d| d.effect == i) {
            tide_at = Some(at);
        }
        a.theta = Param {
            value: thetas[i],
            sigma: sigmas[i],
        };
        a.params = effects::parameters(
            &a.effect,
            ds,
            a.theta,
            &fit.beta[at..at + m],
            &se[at..at + m],
        );
        at += m;
    }
    // The delay: the tide a·C(τ̂) + b·∂C/∂τ is a·C(τ̂ + b/a) to first order, so τ = τ̂ + b/a
    // and its row of the covariance is the derivative coefficient's divided by a.
    let mut scale = vec![1.0; all.len()];
    if let (Some(d), Some(ta)) = (&delay, tide_at) {
        let last = all.len() - 1;
        let (a, b) = (fit.beta[ta], fit.beta[last]);
        scale[last] = 1.0 / a;
        names.push(format!(
            "{}:{}:delay_s",
            d.effect,
            Effect::TidalGravity.name()
        ));
        accepted[d.effect].params.push((
            "delay_s".into(),
            Param {
                value: d.delay_s + b / a,
                sigma: se[last] / a.abs(),
            },
        ));
    }
    let covariance = (k0..all.len())
        .map(|r| {
            (k0..all.len())
                .map(|c| cov_all[r][c] * s2 * scale[r] * scale[c])
                .collect()
        })
        .collect();
    JointFit {
        names,
        covariance,
        effect_columns: ecols,
    }
}

/// Largest instrument delay of the record behind the tide that the joint fit follows, s: a
/// delay beyond it (a tide too weak to time) is not reported.
pub const DELAY_MAX_S: f64 = 3600.0;
/// Half-step of the tide's numerical derivative in the delay, s.
const DELAY_STEP_S: f64 = 30.0;

/// The tide's instrument delay from the joint fit.
struct TideDelay {
    /// Index of the tide in the accepted effects.
    effect: usize,
    /// The delay the tide column is evaluated at, s.
    delay_s: f64,
    /// ∂(tide column)/∂delay at it.
    derivative: Vec<f64>,
}

/// The tide's instrument delay fitted jointly with every other accepted effect: Gauss–Newton
/// on the delayed tide column (the model's tide read at t − τ), each step one GLS of all
/// columns plus the column's derivative in τ under the final noise model. On return the tide's
/// columns in `ecols` are at the fitted delay. `None` without a tide, a clock (start time and
/// site) or when the delay leaves ±[`DELAY_MAX_S`].
fn tide_delay(
    ds: &Dataset,
    target: &[f64],
    ctx: &Context,
    base_cols: &[Vec<f64>],
    accepted: &[Accepted],
    ecols: &mut [Vec<Vec<f64>>],
    rows: &Rows,
) -> Option<TideDelay> {
    let all = |ecols: &[Vec<Vec<f64>>]| -> Vec<Vec<f64>> {
        let mut c = base_cols.to_vec();
        for e in ecols {
            c.extend(e.iter().cloned());
        }
        c
    };
    let it = accepted
        .iter()
        .position(|a| a.effect == Effect::TidalGravity)?;
    if ecols[it].len() != 1 {
        return None;
    }
    let clock = super::tidal::TideClock::new(ds, DELAY_MAX_S + 2.0 * DELAY_STEP_S)?;
    let col_at = |d: f64| -> Vec<f64> {
        let c = Context {
            tide_gravity_g: Some(clock.delayed(&ds.t_s, d)),
            ..ctx.clone()
        };
        columns(&Effect::TidalGravity, ds, &c, f64::NAN)
            .into_iter()
            .next()
            .unwrap_or_default()
    };
    let derivative_at = |d: f64| -> Vec<f64> {
        let (p, m) = (col_at(d + DELAY_STEP_S), col_at(d - DELAY_STEP_S));
        p.iter()
            .zip(&m)
            .map(|(a, b)| (a - b) / (2.0 * DELAY_STEP_S))
            .collect()
    };
    let k_tide = base_cols.len() + ecols[..it].iter().map(Vec::len).sum::<usize>();
    let mut d = 0.0;
    for _ in 0..5 {
        let mut cols = all(ecols);
        cols.push(derivative_at(d));
        let f = gls(&cols, target, 0.0, rows);
        let step = f.beta[cols.len() - 1] / f.beta[k_tide];
        if !step.is_finite() || (d + step).abs() > DELAY_MAX_S {
            ecols[it] = vec![col_at(0.0)];
            return None;
        }
        d += step;
        ecols[it] = vec![col_at(d)];
        if step.abs() < 0.01 {
            break;
        }
    }
    Some(TideDelay {
        effect: it,
        delay_s: d,
        derivative: derivative_at(d),
    })
}
