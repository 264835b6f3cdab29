//! The instrument's smooth drift as a twin holds it: a polynomial in time, written in Legendre
//! polynomials of the record's time mapped onto [−1, 1] (the first instant −1, the last +1), so
//! that the coefficients are nearly independent.
//!
//! The analysis (`accomp-analysis`, `discover::simulate::drift`) selects the order and fits the
//! coefficients; the comparison removes a polynomial of that order from the record and from
//! every member alike (the drift's shape is a calibration constant of the instrument, not a
//! prediction). Every member carries the fitted polynomial at its nominal coefficients — drawn
//! coefficients would change no residual the comparison looks at — so that a member (and
//! `accomp simulate` of a written twin) looks like the record, drift included. The σ are kept
//! for the reader.

use serde::{Deserialize, Serialize};

use super::draw::Drawn;

/// Legendre polynomials P₀…P_order at `u` ∈ [−1, 1].
pub fn legendre(u: f64, order: usize) -> Vec<f64> {
    let mut p = vec![1.0; order + 1];
    if order >= 1 {
        p[1] = u;
    }
    for n in 1..order {
        let nf = n as f64;
        p[n + 1] = ((2.0 * nf + 1.0) * u * p[n] - nf * p[n - 1]) / (nf + 1.0);
    }
    p
}

/// The record's time mapped onto [−1, 1].
pub fn unit_time(t: &[f64]) -> Vec<f64> {
    let (a, b) = (
        t.first().copied().unwrap_or(0.0),
        t.last().copied().unwrap_or(0.0),
    );
    let h = 0.5 * (b - a);
    t.iter()
        .map(|&x| if h > 0.0 { (x - a) / h - 1.0 } else { 0.0 })
        .collect()
}

/// The drift polynomial: Legendre coefficients of P₀…P_order (order = their number − 1), output
/// unit, with their 1σ.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DriftPolynomial {
    /// Coefficient k multiplies P_k of the record's time on [−1, 1].
    pub legendre: Vec<Drawn>,
}

impl DriftPolynomial {
    /// Checks the coefficients are finite numbers.
    pub fn validate(&self) -> Result<(), String> {
        match self
            .legendre
            .iter()
            .position(|c| !(c.value.is_finite() && c.sigma.is_finite()))
        {
            Some(k) => Err(format!(
                "drift: Legendre coefficient {k} must be a finite value and σ"
            )),
            None => Ok(()),
        }
    }

    /// Adds the polynomial at the record's instants `t_s` to `y`.
    pub fn add(&self, y: &mut [f64], t_s: &[f64]) {
        let Some(order) = self.legendre.len().checked_sub(1) else {
            return;
        };
        for (v, u) in y.iter_mut().zip(unit_time(t_s)) {
            *v += legendre(u, order)
                .iter()
                .zip(&self.legendre)
                .map(|(p, c)| p * c.value)
                .sum::<f64>();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_polynomial_added_is_its_legendre_sum_on_the_record_span() {
        let t: Vec<f64> = (0..101).map(|i| 1000.0 + i as f64 * 10.0).collect();
        let d = DriftPolynomial {
            legendre: [2.0, -1.0, 0.5]
                .iter()
                .map(|&value| Drawn { value, sigma: 0.1 })
                .collect(),
        };
        let mut y = vec![0.0; t.len()];
        d.add(&mut y, &t);
        // u = −1, 0, +1 at the first, middle and last instants: P₂ = (3u² − 1)/2.
        assert!((y[0] - (2.0 + 1.0 + 0.5)).abs() < 1e-12, "{}", y[0]);
        assert!((y[50] - (2.0 - 0.25)).abs() < 1e-12, "{}", y[50]);
        assert!((y[100] - (2.0 - 1.0 + 0.5)).abs() < 1e-12, "{}", y[100]);
        let p = legendre(0.3, 3);
        assert!((p[3] - 0.5 * (5.0 * 0.027 - 3.0 * 0.3)).abs() < 1e-12);
    }
}
