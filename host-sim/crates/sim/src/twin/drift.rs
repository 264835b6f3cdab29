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
//!
//! A record that starts while the instrument is still settling (a spring gravimeter moved or
//! unclamped shortly before) also carries a [`Settling`]: A·exp(−(t − t₀)/τ) from the record's
//! first instant t₀. It is a property of the instrument's history inside the record, fitted
//! with the polynomial and removed with it — not a cause the discovery names, and nothing the
//! twin forecasts beyond the record. Members draw its τ and A from their fitted values and σ
//! (like the accepted effects' parameters); the comparison removes it at the fitted τ.

use serde::{Deserialize, Serialize};

use super::draw::Drawn;
use super::InvalidTwin;
use crate::noise::{gauss, stream};

/// Random stream of a member's draw of the settling's parameters (apart from the noise's and
/// the effects' streams, so adding a settling changes no other draw).
pub const SETTLING_DRAW_STREAM: u64 = 12;

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

/// The instrument's settling at the record's start: `amplitude`·exp(−(t − t₀)/`tau_s`), t₀ the
/// record's first instant, output unit (in-sample: a property of the instrument's history, not
/// a cause).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Settling {
    /// Time constant, s, and its 1σ.
    pub tau_s: Drawn,
    /// Its size at the record's first instant, output unit, and its 1σ.
    pub amplitude: Drawn,
}

impl Settling {
    /// The unit settling exp(−(t − t₀)/τ) at the record's instants `t_s` (t₀ = the first).
    pub fn column(t_s: &[f64], tau_s: f64) -> Vec<f64> {
        let t0 = t_s.first().copied().unwrap_or(0.0);
        t_s.iter().map(|&t| (-(t - t0) / tau_s).exp()).collect()
    }

    /// Checks the values are usable (τ > 0, everything finite).
    pub fn validate(&self) -> Result<(), InvalidTwin> {
        let finite = |d: &Drawn| d.value.is_finite() && d.sigma.is_finite();
        if !(finite(&self.tau_s) && finite(&self.amplitude) && self.tau_s.value > 0.0) {
            return Err(InvalidTwin::Settling);
        }
        Ok(())
    }

    /// Member `seed`'s τ and A: each drawn as value + σ·N(0, 1) (stream
    /// [`SETTLING_DRAW_STREAM`]); a τ drawn ≤ 0 falls back to the fitted value.
    pub fn drawn(&self, seed: u64) -> (f64, f64) {
        let mut rng = stream(seed, SETTLING_DRAW_STREAM);
        let mut draw = |d: &Drawn| {
            let z = gauss(&mut rng);
            if d.sigma > 0.0 {
                d.value + d.sigma * z
            } else {
                d.value
            }
        };
        let tau = draw(&self.tau_s);
        let amplitude = draw(&self.amplitude);
        (if tau > 0.0 { tau } else { self.tau_s.value }, amplitude)
    }

    /// Adds A·exp(−(t − t₀)/τ) to `y`.
    fn add_with(y: &mut [f64], t_s: &[f64], tau_s: f64, amplitude: f64) {
        let t0 = t_s.first().copied().unwrap_or(0.0);
        for (v, &t) in y.iter_mut().zip(t_s) {
            *v += amplitude * crate::catalogue::warmup(t - t0, tau_s);
        }
    }
}

/// The drift polynomial: Legendre coefficients of P₀…P_order (order = their number − 1), output
/// unit, with their 1σ; and the settling at the record's start, when the record has one.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DriftPolynomial {
    /// Coefficient k multiplies P_k of the record's time on [−1, 1].
    pub legendre: Vec<Drawn>,
    /// The instrument's settling at the record's start (fitted with the polynomial); absent:
    /// none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub settling: Option<Settling>,
}

impl DriftPolynomial {
    /// Checks the coefficients are finite numbers.
    pub fn validate(&self) -> Result<(), InvalidTwin> {
        match self
            .legendre
            .iter()
            .position(|c| !(c.value.is_finite() && c.sigma.is_finite()))
        {
            Some(order) => Err(InvalidTwin::DriftCoefficient { order }),
            None => self.settling.as_ref().map_or(Ok(()), Settling::validate),
        }
    }

    /// Adds the polynomial at the record's instants `t_s` to `y`, and the settling at its
    /// fitted values.
    pub fn add(&self, y: &mut [f64], t_s: &[f64]) {
        self.add_polynomial(y, t_s);
        if let Some(s) = &self.settling {
            Settling::add_with(y, t_s, s.tau_s.value, s.amplitude.value);
        }
    }

    /// Member `seed`'s drift: the polynomial at its fitted coefficients (the comparison removes
    /// it from every member) and the settling with its τ and A drawn ([`Settling::drawn`]).
    pub fn add_member(&self, y: &mut [f64], t_s: &[f64], seed: u64) {
        self.add_polynomial(y, t_s);
        if let Some(s) = &self.settling {
            let (tau, a) = s.drawn(seed);
            Settling::add_with(y, t_s, tau, a);
        }
    }

    /// The polynomial alone, by the three-term recurrence at each instant (no allocation per
    /// point).
    fn add_polynomial(&self, y: &mut [f64], t_s: &[f64]) {
        let c = &self.legendre;
        if c.is_empty() {
            return;
        }
        for (v, u) in y.iter_mut().zip(unit_time(t_s)) {
            let (mut p_prev, mut p) = (1.0, u);
            let mut sum = c[0].value;
            for (n, ck) in c.iter().enumerate().skip(1) {
                if n > 1 {
                    let nf = (n - 1) as f64;
                    let next = ((2.0 * nf + 1.0) * u * p - nf * p_prev) / (nf + 1.0);
                    p_prev = p;
                    p = next;
                }
                sum += ck.value * p;
            }
            *v += sum;
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
            settling: None,
        };
        let mut y = vec![0.0; t.len()];
        d.add(&mut y, &t);
        // u = −1, 0, +1 at the first, middle and last instants: P₂ = (3u² − 1)/2.
        assert!((y[0] - (2.0 + 1.0 + 0.5)).abs() < 1e-12, "{}", y[0]);
        assert!((y[50] - (2.0 - 0.25)).abs() < 1e-12, "{}", y[50]);
        assert!((y[100] - (2.0 - 1.0 + 0.5)).abs() < 1e-12, "{}", y[100]);
        let p = legendre(0.3, 3);
        assert!((p[3] - 0.5 * (5.0 * 0.027 - 3.0 * 0.3)).abs() < 1e-12);
        // The recurrence without allocation is the Legendre sum at every order.
        let c: Vec<Drawn> = [0.3, -0.2, 0.7, 1.1, -0.4, 0.25, -0.6]
            .iter()
            .map(|&value| Drawn { value, sigma: 0.0 })
            .collect();
        let d = DriftPolynomial {
            legendre: c.clone(),
            settling: None,
        };
        let mut y = vec![0.0; t.len()];
        d.add(&mut y, &t);
        for (v, u) in y.iter().zip(unit_time(&t)) {
            let want: f64 = legendre(u, 6)
                .iter()
                .zip(&c)
                .map(|(p, c)| p * c.value)
                .sum();
            assert!((v - want).abs() < 1e-12, "{v} against {want}");
        }
    }

    /// A member's settling is A·exp(−(t − t₀)/τ) at its own draw of τ and A; the draws scatter
    /// by their σ about the fitted values, and a member without σ carries the fitted curve.
    #[test]
    fn a_members_settling_is_drawn_from_its_fitted_values_and_sigma() {
        let t: Vec<f64> = (0..200).map(|i| 5_000.0 + i as f64 * 600.0).collect();
        let fitted = Settling {
            tau_s: Drawn {
                value: 20_000.0,
                sigma: 2_000.0,
            },
            amplitude: Drawn {
                value: 0.08,
                sigma: 0.004,
            },
        };
        let d = DriftPolynomial {
            legendre: Vec::new(),
            settling: Some(fitted),
        };
        let (mut taus, mut amps) = (Vec::new(), Vec::new());
        for seed in 1..=400u64 {
            let mut y = vec![0.0; t.len()];
            d.add_member(&mut y, &t, seed);
            let (tau, a) = fitted.drawn(seed);
            assert!((y[0] - a).abs() < 1e-15);
            assert!((y[50] - a * (-(t[50] - t[0]) / tau).exp()).abs() < 1e-15);
            taus.push(tau);
            amps.push(a);
        }
        let mean_sd = |v: &[f64]| {
            let m = v.iter().sum::<f64>() / v.len() as f64;
            let sd = (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len() as f64).sqrt();
            (m, sd)
        };
        let (mt, st) = mean_sd(&taus);
        let (ma, sa) = mean_sd(&amps);
        assert!((mt - 20_000.0).abs() < 300.0 && (st / 2_000.0 - 1.0).abs() < 0.15);
        assert!((ma - 0.08).abs() < 6e-4 && (sa / 0.004 - 1.0).abs() < 0.15);
        let fixed = Settling {
            tau_s: Drawn {
                value: 20_000.0,
                sigma: 0.0,
            },
            amplitude: Drawn {
                value: 0.08,
                sigma: 0.0,
            },
        };
        assert_eq!(fixed.drawn(3), (20_000.0, 0.08));
        assert!(Settling {
            tau_s: Drawn {
                value: -1.0,
                sigma: 0.0
            },
            ..fixed
        }
        .validate()
        .is_err());
    }
}
