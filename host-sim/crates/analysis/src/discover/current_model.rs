//! The current model in the noise model's GLS-whitened domain: the noise model fitted by maximum
//! likelihood to the model's residual ([`fit_state`]), and the fast scoring of extra columns on
//! top of it ([`Current`]).

use super::baseline::{ar1, gls, raw_residual, Basis, Rows};
use super::import::Dataset;
use super::noise::{NoiseFit, NoiseModel};
use super::residual;

/// The current model in the whitened domain, ready to score extensions quickly.
pub(super) struct Current<'a> {
    pub(super) ds: &'a Dataset,
    pub(super) rows: Rows,
    pub(super) phi: f64,
    pub(super) noise: NoiseFit,
    pub(super) basis: Basis,
    pub(super) r_w: Vec<f64>,
    pub(super) rss: f64,
}

impl Current<'_> {
    /// −2 ln L of the current model under its noise model (constant dropped).
    pub(super) fn neg2_loglik(&self) -> f64 {
        self.rss + self.rows.kalman.as_ref().map_or(0.0, |w| w.log_det())
    }

    /// Raw columns whitened and projected off the current model.
    pub(super) fn projected(&self, extra: &[Vec<f64>]) -> Vec<Vec<f64>> {
        extra
            .iter()
            .map(|c| {
                let mut w = self.rows.whiten(c, self.phi);
                super::baseline::orthogonalize(&self.basis.q, &mut w);
                w
            })
            .collect()
    }

    /// Whitened RSS with extra raw columns (projected on the current basis first).
    pub(super) fn rss_with(&self, extra: &[Vec<f64>]) -> f64 {
        let mut small = Basis::new(&[]);
        for c in extra {
            let mut w = self.rows.whiten(c, self.phi);
            if w.iter().any(|v| !v.is_finite()) {
                return self.rss;
            }
            super::baseline::orthogonalize(&self.basis.q, &mut w);
            small.push(w);
        }
        let red: f64 = small
            .q
            .iter()
            .map(|q| {
                let d: f64 = q.iter().zip(&self.r_w).map(|(a, b)| a * b).sum();
                d * d
            })
            .sum();
        (self.rss - red).max(0.0)
    }
}

/// Likelihood evaluations of a cold noise fit (start grid + Nelder–Mead).
const ML_EVALS_COLD: usize = 110;
/// Likelihood evaluations of a warm-started noise fit (previous model as the start).
const ML_EVALS_WARM: usize = 36;

/// Noise model of a residual by maximum likelihood of its Kalman innovations, started from
/// `warm` (and from the Allan-deviation fit when the record's time grid allows one).
fn noise_of(ds: &Dataset, r: &[f64], warm: Option<&NoiseModel>) -> NoiseFit {
    let idx: Vec<usize> = (0..r.len()).collect();
    let scale = point_white_scale(ds);
    let fit = |start: &[&NoiseModel], evals: usize| {
        NoiseModel::fit_ml(
            &ds.t_s,
            &idx,
            r,
            ds.dt_s,
            ds.span_s(),
            start,
            evals,
            scale.clone(),
        )
    };
    match warm {
        Some(m) => fit(&[m], ML_EVALS_WARM),
        None => {
            let adev_start = NoiseModel::fit(&residual::adev(ds, r), ds.dt_s, ds.span_s());
            // The Allan fit is a second start, fitted beside the cold one (another core).
            let (cold, alt) = std::thread::scope(|s| {
                let alt = adev_start
                    .as_ref()
                    .map(|a| s.spawn(move || fit(&[a], ML_EVALS_WARM)));
                let cold = fit(&[], ML_EVALS_COLD);
                let alt = alt.map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)));
                (cold, alt)
            });
            match alt {
                Some(alt) if cold.failure.is_none() => {
                    // Keep the more likely of the two.
                    if alt.failure.is_none() && alt.neg2_loglik < cold.neg2_loglik {
                        NoiseFit {
                            evaluations: alt.evaluations + cold.evaluations,
                            ..alt
                        }
                    } else {
                        cold
                    }
                }
                _ => cold,
            }
        }
    }
}

/// Per-point white-variance factors of the record's bins (a bin of n samples has white
/// variance σ²/n), when its bins hold unequal counts.
fn point_white_scale(ds: &Dataset) -> Option<std::sync::Arc<[f64]>> {
    if ds.samples_per_point.len() != ds.len() {
        return None;
    }
    super::noise::white_scale_from_counts(&ds.samples_per_point)
}

/// How `fit_state` gets its noise model.
#[derive(Clone, Copy)]
pub(super) enum NoiseChoice<'m> {
    /// Held fixed.
    Fixed(&'m NoiseFit),
    /// Fitted by maximum likelihood (warm-started from the given model if any).
    Fit(Option<&'m NoiseModel>),
}

/// Fits the model (columns) with the noise model of its own residual: least squares → noise
/// likelihood fit → GLS → noise fit again (warm) → GLS; or with a fixed noise model.
pub(super) fn fit_state<'a>(
    ds: &'a Dataset,
    cols: &[Vec<f64>],
    y: &[f64],
    choice: NoiseChoice,
) -> (Current<'a>, Vec<f64>, Vec<f64>) {
    let noise = match choice {
        NoiseChoice::Fixed(m) => m.clone(),
        NoiseChoice::Fit(warm) => {
            let first = match warm {
                Some(m) => m.clone(),
                None => {
                    let all = Rows::new(&ds.segment_start, None);
                    let ols = gls(cols, y, 0.0, &all);
                    noise_of(ds, &raw_residual(cols, &ols.beta, y), None).model
                }
            };
            let rows1 = Rows::with_noise(&first, &ds.t_s, None);
            let f1 = gls(cols, y, 0.0, &rows1);
            noise_of(ds, &raw_residual(cols, &f1.beta, y), Some(&first))
        }
    };
    let all = Rows::with_noise(&noise.model, &ds.t_s, None);
    let phi = 0.0;
    let fit = gls(cols, y, phi, &all);
    let raw = raw_residual(cols, &fit.beta, y);
    let wc: Vec<Vec<f64>> = cols.iter().map(|c| all.whiten(c, phi)).collect();
    let basis = Basis::new(&wc);
    let r_w = basis.residual(&all.whiten(y, phi));
    let rss = r_w.iter().map(|v| v * v).sum();
    (
        Current {
            ds,
            rows: all,
            phi,
            noise,
            basis,
            r_w,
            rss,
        },
        raw,
        fit.beta,
    )
}

/// Loud statements for noise fits that failed (the selection then ran on white noise).
pub(super) fn noise_warnings(base: &NoiseFit, fin: &NoiseFit) -> Vec<String> {
    let mut w = Vec::new();
    for (which, f) in [("baseline", base), ("final", fin)] {
        if let Some(why) = &f.failure {
            w.push(format!(
                "the {which} residual's noise model could not be fitted ({why}): white noise of \
                 the residual's variance was used instead, so the selection's likelihood and \
                 uncertainties treat correlated noise as independent"
            ));
        }
    }
    w
}

/// Variance factor for the correlation the whitening left in a whitened residual: (1 + ρ)/(1 − ρ),
/// ρ its lag-1 autocorrelation (at most 0.99); standard errors are multiplied by its root.
pub(super) fn leftover_correlation_inflation(r_w: &[f64]) -> f64 {
    let mut seg = vec![false; r_w.len()];
    if let Some(f) = seg.first_mut() {
        *f = true;
    }
    let rho = ar1(r_w, &seg).min(0.99);
    (1.0 + rho) / (1.0 - rho)
}
