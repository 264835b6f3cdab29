//! The instrument's settling at the record's start, in the twin's drift model: an exponential
//! A·exp(−(t − t₀)/τ) from the record's first instant, fitted jointly with the drift
//! polynomial and removed with it from the record's residual and every member's.
//!
//! A spring gravimeter moved or unclamped shortly before a record starts keeps relaxing for a
//! day or two: a curve no polynomial of a few orders over weeks follows (it bends within the
//! first tenth of the span). The discovery may refuse it as a cause — over before the first
//! forward cut, it forecasts nothing — but it is in the record, and a twin without it leaves
//! the record's Allan deviation at hours to days above every member's. So the twin carries it
//! as what it is: a property of the instrument's history inside the record (like the drift's
//! shape, a calibration of this record), not a cause and not a forecast.
//!
//! The fit: τ on a log grid from [`MIN_TAU_S`] (or four spacings) to [`MAX_TAU_FRACTION`] of the
//! span, refined by golden-section search on ln τ, each τ by generalised least squares (the
//! noise model's Kalman whitening) with the polynomial of the highest order tried; A and its σ
//! from that fit, τ's σ from the curvature of −ℓ in ln τ. Kept when the profile likelihood
//! (the noise model refitted with and without it) improves by more than the BIC price of its
//! two parameters (ln n), A is beyond [`MIN_SIGMAS`] σ and τ is not at an end of its range.

use super::drift::{legendre, remove_with};
use crate::numerics::optimize::golden_section_min;
use crate::sim::twin::draw::Drawn;
use crate::sim::twin::drift::Settling;

/// Shortest settling time constant tried, s (faster is the noise's or a transient's).
pub const MIN_TAU_S: f64 = 3_600.0;
/// Longest, as a fraction of the span (slower is the polynomial's).
pub const MAX_TAU_FRACTION: f64 = 0.2;
/// Grid points of τ (log-spaced).
const GRID: usize = 24;
/// An amplitude within this many σ of zero is not a settling.
pub const MIN_SIGMAS: f64 = 3.0;

/// The settling fitted to a record, kept or not.
#[derive(Debug, Clone, PartialEq)]
pub struct SettlingFit {
    /// The fitted curve (τ and A with their 1σ).
    pub fitted: Settling,
    /// Profile −ℓ without it minus with it (the noise model refitted each way).
    pub gain: f64,
    /// The BIC price of its two parameters, ln n.
    pub price: f64,
    /// Why it is not in the twin (None: it is).
    pub refused: Option<String>,
}

impl SettlingFit {
    /// The settling the twin carries, if kept.
    pub fn kept(&self) -> Option<&Settling> {
        self.refused.is_none().then_some(&self.fitted)
    }
}

/// The τ grid for a record of `span_s` at spacing `dt_s` (empty when the range is empty).
fn tau_grid(span_s: f64, dt_s: f64) -> Vec<f64> {
    let lo = MIN_TAU_S.max(4.0 * dt_s);
    let hi = MAX_TAU_FRACTION * span_s;
    if hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater) {
        return Vec::new();
    }
    (0..GRID)
        .map(|i| lo * (hi / lo).powf(i as f64 / (GRID - 1) as f64))
        .collect()
}

/// The whitened least-squares fit of the polynomial (columns `pw`, whitened) and one whitened
/// column `e` to the whitened data `y`: (½ RSS, coefficient of `e`, its variance).
fn fit_one(pw: &[Vec<f64>], e: &[f64], y: &[f64]) -> Option<(f64, f64, f64)> {
    let m = pw.len() + 1;
    let col = |k: usize| if k < pw.len() { &pw[k][..] } else { e };
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let aty: Vec<f64> = (0..m).map(|a| dot(col(a), y)).collect();
    let ata: Vec<Vec<f64>> = (0..m)
        .map(|a| (0..m).map(|b| dot(col(a), col(b))).collect())
        .collect();
    let c = crate::numerics::linalg::solve_square(&ata, &aty)?;
    let rss = dot(y, y) - c.iter().zip(&aty).map(|(c, v)| c * v).sum::<f64>();
    let mut unit = vec![0.0; m];
    unit[m - 1] = 1.0;
    let var = crate::numerics::linalg::solve_square(&ata, &unit)?[m - 1];
    Some((0.5 * rss, c[m - 1], var))
}

/// Fits the settling to residual `r` at instants `t_s` (unit times `u`) with the drift
/// polynomial of `order`, `whiten` the noise model's whitening. None when the record is too
/// short for the τ range or the fits are singular.
pub fn search(
    t_s: &[f64],
    u: &[f64],
    r: &[f64],
    order: usize,
    dt_s: f64,
    whiten: impl Fn(&[f64]) -> Vec<f64>,
) -> Option<(Settling, bool)> {
    let span = t_s.last()? - t_s.first()?;
    let grid = tau_grid(span, dt_s);
    if grid.is_empty() {
        return None;
    }
    let pw: Vec<Vec<f64>> = (0..=order)
        .map(|k| whiten(&u.iter().map(|&x| legendre(x, order)[k]).collect::<Vec<_>>()))
        .collect();
    let y = whiten(r);
    let at = |ln_tau: f64| fit_one(&pw, &whiten(&Settling::column(t_s, ln_tau.exp())), &y);
    let costs: Vec<f64> = grid
        .iter()
        .map(|t| at(t.ln()).map_or(f64::INFINITY, |f| f.0))
        .collect();
    let best = (0..grid.len()).min_by(|&a, &b| costs[a].total_cmp(&costs[b]))?;
    if !costs[best].is_finite() {
        return None;
    }
    let edge = best == 0 || best == grid.len() - 1;
    // Golden-section search on ln τ between the best grid point's neighbours.
    let (a, b) = (
        grid[best.saturating_sub(1)].ln(),
        grid[(best + 1).min(grid.len() - 1)].ln(),
    );
    let cost = |x: f64| at(x).map_or(f64::INFINITY, |f| f.0);
    let x = golden_section_min(cost, a, b, 20);
    let (c0, amp, var) = at(x)?;
    // τ's σ: the curvature of −ℓ = ½ RSS (unit-variance innovations) in ln τ.
    let h = 0.02;
    let curv = (cost(x + h) - 2.0 * c0 + cost(x - h)) / (h * h);
    let sigma_ln = if curv > 0.0 {
        curv.sqrt().recip()
    } else {
        f64::INFINITY
    };
    let tau = x.exp();
    Some((
        Settling {
            tau_s: Drawn {
                value: tau,
                sigma: tau * sigma_ln,
            },
            amplitude: Drawn {
                value: amp,
                sigma: var.max(0.0).sqrt(),
            },
        },
        edge,
    ))
}

/// Decides whether the twin keeps a settling found by [`search`] (`edge`: τ at an end of its
/// grid): `profile` is the profile −ℓ of a residual (noise model refitted), `r` the residual,
/// `u` its unit times, `order` the polynomial's, `n` the points.
pub fn decide(
    found: (Settling, bool),
    t_s: &[f64],
    u: &[f64],
    r: &[f64],
    order: usize,
    profile: impl Fn(&[f64]) -> f64,
) -> SettlingFit {
    let (fitted, edge) = found;
    let col = Settling::column(t_s, fitted.tau_s.value);
    let without = profile(&remove_with(u, r, order, &[]).1);
    let with = profile(&remove_with(u, r, order, std::slice::from_ref(&col)).1);
    let gain = without - with;
    let price = (r.len().max(2) as f64).ln();
    let a = fitted.amplitude;
    let refused = if edge {
        Some(format!(
            "τ at an end of its range ({:.3} d): not a settling the record resolves",
            fitted.tau_s.value / 86_400.0
        ))
    } else if a.value.abs().partial_cmp(&(MIN_SIGMAS * a.sigma))
        != Some(std::cmp::Ordering::Greater)
    {
        Some(format!(
            "amplitude {:.3e} ± {:.1e} within {MIN_SIGMAS} σ of zero",
            a.value, a.sigma
        ))
    } else if gain.partial_cmp(&price) != Some(std::cmp::Ordering::Greater) {
        Some(format!(
            "the likelihood improves by {gain:.1}, not more than the price of two parameters \
             {price:.1}"
        ))
    } else {
        None
    };
    SettlingFit {
        fitted,
        gain,
        price,
        refused,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An exponential settling of τ 0.8 d on a 20-day record with a cubic drift and white noise
    /// is found at its τ and amplitude within their σ-scaled tolerance; the same record without
    /// it keeps nothing.
    #[test]
    fn a_settling_at_the_start_is_found_and_a_record_without_one_keeps_none() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let dt = 900.0;
        let t: Vec<f64> = (0..1920).map(|i| 1e5 + i as f64 * dt).collect();
        let u = super::super::drift::unit_time(&t);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let noise: Vec<f64> = (0..t.len())
            .map(|_| {
                let z: f64 = StandardNormal.sample(&mut rng);
                1e-3 * z
            })
            .collect();
        let base: Vec<f64> = (0..t.len())
            .map(|i| noise[i] + 0.02 * u[i] - 0.01 * u[i].powi(3))
            .collect();
        let tau = 0.8 * 86_400.0;
        let with: Vec<f64> = base
            .iter()
            .zip(&t)
            .map(|(y, &x)| y + 0.03 * (-(x - t[0]) / tau).exp())
            .collect();
        let white = |x: &[f64]| x.iter().map(|v| v / 1e-3).collect::<Vec<_>>();
        // −ℓ of white noise of σ 1e-3 with the polynomial already removed.
        let profile = |x: &[f64]| 0.5 * x.iter().map(|v| (v / 1e-3).powi(2)).sum::<f64>();
        let found = search(&t, &u, &with, 3, dt, white).expect("a fit");
        let s = found.0;
        assert!(
            (s.tau_s.value / tau - 1.0).abs() < 0.1,
            "τ {} ± {}",
            s.tau_s.value,
            s.tau_s.sigma
        );
        assert!((s.amplitude.value - 0.03).abs() < 4.0 * s.amplitude.sigma);
        let kept = decide(found, &t, &u, &with, 3, profile);
        assert!(kept.kept().is_some(), "{kept:?}");
        let none = decide(
            search(&t, &u, &base, 3, dt, white).expect("a fit"),
            &t,
            &u,
            &base,
            3,
            profile,
        );
        assert!(none.kept().is_none(), "{none:?}");
    }
}
