//! The instrument's smooth drift as calibration constants: a polynomial in time (Legendre
//! polynomials on the record's span, so the coefficients are nearly independent) removed from
//! the measured residual and from every member's residual alike. Level and linear rate are
//! always removed (order 1); a spring gravimeter's drift is a smooth curve over weeks (the
//! spring relaxing), which the order selected here describes.
//!
//! The order is selected by maximum likelihood: for each order the polynomial is removed and
//! the noise family (white, flicker, random walk, drift-rate random walk; Whittle likelihood,
//! `twin::family`) refitted to what is left; the order with the lowest BIC (profile −ℓ + ½ ln n
//! per coefficient, n the points) is taken. The family's random walk and drift-rate walk absorb
//! as much of the drift as a stationary process can, so a coefficient is kept only for a curve
//! the noise does not explain. The coefficients' uncertainties are those of generalised least
//! squares under the likelihood noise model (Kalman whitening) refitted with the drift removed.
//! Records shorter than [`MIN_SPAN_S`] keep order 1.

// Index loops over the normal equations read as the formulas do.
#![allow(clippy::needless_range_loop)]

/// Highest order tried.
pub const MAX_ORDER: usize = 6;
/// Records shorter than this keep the linear drift (a curve over a few days is the noise's).
pub const MIN_SPAN_S: f64 = 7.0 * 86_400.0;

// The polynomials and the time mapping are the simulator's: a written twin's members add the
// drift with the same code (`accomp-sim`, `twin::drift`).
pub use crate::sim::twin::drift::{legendre, unit_time};

/// Least-squares coefficients of P₀…P_order fitted to `r` at unit times `u`, and `r` minus the
/// fit. A singular system (fewer points than coefficients) removes nothing.
pub fn remove(u: &[f64], r: &[f64], order: usize) -> (Vec<f64>, Vec<f64>) {
    remove_with(u, r, order, &[])
}

/// [`remove`] with `extra` columns (each at the record's instants, e.g. the settling) fitted
/// jointly: the coefficients of P₀…P_order then of the extra columns, and `r` minus the fit.
pub fn remove_with(u: &[f64], r: &[f64], order: usize, extra: &[Vec<f64>]) -> (Vec<f64>, Vec<f64>) {
    let m = order + 1 + extra.len();
    let row = |i: usize, x: f64| {
        let mut p = legendre(x, order);
        p.extend(extra.iter().map(|c| c[i]));
        p
    };
    let mut ata = vec![vec![0.0; m]; m];
    let mut aty = vec![0.0; m];
    for (i, (&x, &y)) in u.iter().zip(r).enumerate() {
        let p = row(i, x);
        for i in 0..m {
            aty[i] += p[i] * y;
            for j in i..m {
                ata[i][j] += p[i] * p[j];
            }
        }
    }
    for i in 0..m {
        for j in 0..i {
            ata[i][j] = ata[j][i];
        }
    }
    let Some(c) = crate::numerics::linalg::solve_square(&ata, &aty) else {
        return (vec![0.0; m], r.to_vec());
    };
    let out = u
        .iter()
        .zip(r)
        .enumerate()
        .map(|(i, (&x, &y))| y - row(i, x).iter().zip(&c).map(|(p, c)| p * c).sum::<f64>())
        .collect();
    (c, out)
}

/// The drift order selected for a record, with the profile −ℓ of each order tried.
#[derive(Debug, Clone, PartialEq)]
pub struct DriftOrder {
    /// Selected order (1: level and linear rate only).
    pub order: usize,
    /// (order, profile −ℓ with that polynomial removed and the noise refitted).
    pub neg_loglik: Vec<(usize, f64)>,
    /// The price of one coefficient, ½ ln n.
    pub threshold: f64,
}

/// Selects the drift order of residual `r` (at the record's unit times `u`): of orders
/// 1…[`MAX_ORDER`], the one with the lowest BIC, the profile −ℓ (`neg_loglik` of the residual
/// with the polynomial and the `extra` columns removed) + ½ ln n per coefficient.
pub fn select_order(
    u: &[f64],
    r: &[f64],
    extra: &[Vec<f64>],
    span_s: f64,
    neg_loglik: impl Fn(&[f64]) -> f64,
) -> DriftOrder {
    let threshold = 0.5 * (r.len().max(2) as f64).ln();
    let mut tried = Vec::new();
    if span_s < MIN_SPAN_S {
        return DriftOrder {
            order: 1,
            neg_loglik: tried,
            threshold,
        };
    }
    let mut order = 1;
    let mut best = f64::INFINITY;
    for k in 1..=MAX_ORDER {
        let v = neg_loglik(&remove_with(u, r, k, extra).1);
        tried.push((k, v));
        // The BIC: −ℓ + ½ ln n per coefficient.
        let bic = v + threshold * k as f64;
        if bic < best {
            order = k;
            best = bic;
        }
    }
    DriftOrder {
        order,
        neg_loglik: tried,
        threshold,
    }
}

/// Generalised-least-squares coefficients of P₀…P_order, then of the `extra` columns, in `r`
/// and their 1σ, with `whiten` the noise model's whitening (normalised Kalman innovations) of a
/// series.
pub fn gls(
    u: &[f64],
    r: &[f64],
    order: usize,
    extra: &[Vec<f64>],
    whiten: impl Fn(&[f64]) -> Vec<f64>,
) -> Vec<(f64, f64)> {
    let m = order + 1 + extra.len();
    let cols: Vec<Vec<f64>> = (0..=order)
        .map(|k| whiten(&u.iter().map(|&x| legendre(x, order)[k]).collect::<Vec<_>>()))
        .chain(extra.iter().map(|c| whiten(c)))
        .collect();
    let y = whiten(r);
    let mut ata = vec![vec![0.0; m]; m];
    let mut aty = vec![0.0; m];
    for i in 0..y.len() {
        for a in 0..m {
            aty[a] += cols[a][i] * y[i];
            for b in 0..m {
                ata[a][b] += cols[a][i] * cols[b][i];
            }
        }
    }
    let Some(c) = crate::numerics::linalg::solve_square(&ata, &aty) else {
        return vec![(f64::NAN, f64::NAN); m];
    };
    (0..m)
        .map(|a| {
            let mut e = vec![0.0; m];
            e[a] = 1.0;
            let v = crate::numerics::linalg::solve_square(&ata, &e).map_or(f64::NAN, |col| col[a]);
            (c[a], v.max(0.0).sqrt())
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cubic_is_removed_exactly_and_legendre_matches_its_closed_form() {
        let t: Vec<f64> = (0..200).map(|i| i as f64 * 10.0).collect();
        let u = unit_time(&t);
        let r: Vec<f64> = u
            .iter()
            .map(|x| 2.0 - x + 0.5 * x * x + 3.0 * x * x * x)
            .collect();
        let (_, out) = remove(&u, &r, 3);
        assert!(out.iter().all(|v| v.abs() < 1e-9), "{:?}", &out[..3]);
        let (_, out2) = remove(&u, &r, 2);
        assert!(out2.iter().any(|v| v.abs() > 0.1));
        let p = legendre(0.3, 3);
        assert!((p[2] - 0.5 * (3.0 * 0.09 - 1.0)).abs() < 1e-12);
        assert!((p[3] - 0.5 * (5.0 * 0.027 - 3.0 * 0.3)).abs() < 1e-12);
    }
}
