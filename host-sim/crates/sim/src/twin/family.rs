//! The noise family a twin's members draw from: a sum of power-law terms through output
//! filters, with the coefficients' covariance, and its synthesis on the record's grid.
//!
//! One-sided PSD of the grid series (output unit²/Hz):
//!
//! S(f) = Σ_j h_j · f^α_j / (1 + (f/c_j)²) · Π_m |H_m(f)|²
//!
//! A term's own corner c_j is absent (0) for a power law; a white term with a corner is a
//! Gauss–Markov (first-order Markov, Lorentzian) process of correlation time 1/(2π c_j).
//!
//! The terms (`[[twin.noise.terms]]`) and the filters (`[[twin.noise.filters]]`) are lists, so a
//! new power law or a new filter kind is one more entry. The analysis fits the family
//! (`accomp-analysis`, `twin::family`); this module only describes it, draws a member's own
//! parameters and synthesises the member's noise, so that `accomp simulate` draws a member
//! exactly as the ensemble of `accomp discover --simulate` does.

use serde::{Deserialize, Serialize};

use super::transients::Transients;
use crate::noise::{gauss, SimRng};

/// Synthesis length: this many times the record's grid (rounded up to a power of two), so that
/// the lowest frequencies are not forced periodic.
pub const SYNTHESIS_FACTOR: usize = 4;

/// One power-law term h·f^α of the PSD.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PowerLaw {
    /// Name (white, flicker, random_walk, drift_rate_random_walk, …).
    pub name: String,
    /// Exponent α of f.
    pub alpha: i32,
    /// Coefficient h (output unit² · Hz^(−α−1)); 0: the term is absent.
    pub coefficient: f64,
    /// The term's own first-order corner c, Hz (0: none, a pure power law). A member draws
    /// ln c + `ln_corner_sigma`·N(0, 1).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub corner_hz: f64,
    /// 1σ of ln c.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub ln_corner_sigma: f64,
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

impl PowerLaw {
    /// The term's PSD at `f` Hz.
    fn psd(&self, f: f64) -> f64 {
        let s = self.coefficient * f.powi(self.alpha);
        if self.corner_hz > 0.0 {
            s / (1.0 + (f / self.corner_hz).powi(2))
        } else {
            s
        }
    }
}

/// A filter the summed noise passes through (the instrument's output filter).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum NoiseFilter {
    /// |H|² = 1 / (1 + (f/f_c)²); `corner_hz = 0`: no filter (the member still takes its normal). A member draws
    /// ln f_c + `ln_corner_sigma`·N(0, 1).
    FirstOrderLowPass {
        /// Corner f_c, Hz.
        corner_hz: f64,
        /// 1σ of ln f_c.
        ln_corner_sigma: f64,
    },
}

impl NoiseFilter {
    /// 1 / |H(f)|²: what the filter divides the PSD by.
    fn attenuation(&self, f: f64) -> f64 {
        match self {
            NoiseFilter::FirstOrderLowPass { corner_hz, .. } if *corner_hz > 0.0 => {
                1.0 + (f / corner_hz).powi(2)
            }
            NoiseFilter::FirstOrderLowPass { .. } => 1.0,
        }
    }

    /// A member's filter: its parameters drawn with the normal `z`.
    fn drawn(&self, z: f64) -> NoiseFilter {
        match self {
            NoiseFilter::FirstOrderLowPass {
                corner_hz,
                ln_corner_sigma,
            } => NoiseFilter::FirstOrderLowPass {
                corner_hz: if *corner_hz > 0.0 {
                    (corner_hz.ln() + ln_corner_sigma.max(0.0) * z).exp()
                } else {
                    *corner_hz
                },
                ln_corner_sigma: *ln_corner_sigma,
            },
        }
    }
}

/// Why a noise family is refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FamilyError {
    /// The grid spacing is not a positive number.
    #[error("noise family: grid_interval_s = {0} is not a positive number")]
    Interval(f64),
    /// A coefficient is negative or not finite.
    #[error("noise family: term {name:?} has coefficient {value} (must be finite and ≥ 0)")]
    Coefficient {
        /// The term.
        name: String,
        /// Its value.
        value: f64,
    },
    /// The covariance is not terms × terms of finite numbers.
    #[error("noise family: the covariance must be {terms} × {terms} finite numbers")]
    Covariance {
        /// Number of terms.
        terms: usize,
    },
    /// A filter parameter is out of range.
    #[error("noise family: filter {0}")]
    Filter(String),
}

/// The family: power-law terms, their covariance and the output filters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseFamily {
    /// Grid spacing, s.
    pub grid_interval_s: f64,
    /// The power-law terms.
    pub terms: Vec<PowerLaw>,
    /// Covariance of the terms' coefficients (terms × terms, same order).
    pub covariance: Vec<Vec<f64>>,
    /// The output filters, applied to the sum.
    #[serde(default)]
    pub filters: Vec<NoiseFilter>,
}

impl NoiseFamily {
    /// Checks the ranges.
    pub fn validate(&self) -> Result<(), FamilyError> {
        if !(self.grid_interval_s > 0.0 && self.grid_interval_s.is_finite()) {
            return Err(FamilyError::Interval(self.grid_interval_s));
        }
        for t in &self.terms {
            if !(t.coefficient >= 0.0 && t.coefficient.is_finite()) {
                return Err(FamilyError::Coefficient {
                    name: t.name.clone(),
                    value: t.coefficient,
                });
            }
            if !(t.corner_hz >= 0.0
                && t.corner_hz.is_finite()
                && t.ln_corner_sigma >= 0.0
                && t.ln_corner_sigma.is_finite())
            {
                return Err(FamilyError::Filter(format!(
                    "term {:?}: corner_hz = {}, ln_corner_sigma = {} (must be finite and ≥ 0;                      corner 0: none)",
                    t.name, t.corner_hz, t.ln_corner_sigma
                )));
            }
        }
        let n = self.terms.len();
        if self.covariance.len() != n
            || self
                .covariance
                .iter()
                .any(|r| r.len() != n || r.iter().any(|v| !v.is_finite()))
        {
            return Err(FamilyError::Covariance { terms: n });
        }
        for f in &self.filters {
            match f {
                NoiseFilter::FirstOrderLowPass {
                    corner_hz,
                    ln_corner_sigma,
                } => {
                    if !corner_hz.is_finite() || *corner_hz < 0.0 {
                        return Err(FamilyError::Filter(format!(
                            "first_order_low_pass: corner_hz = {corner_hz} (must be ≥ 0; 0: none)"
                        )));
                    }
                    if !(*ln_corner_sigma >= 0.0 && ln_corner_sigma.is_finite()) {
                        return Err(FamilyError::Filter(format!(
                            "first_order_low_pass: ln_corner_sigma = {ln_corner_sigma} (must be \
                             finite and ≥ 0)"
                        )));
                    }
                }
            }
        }
        Ok(())
    }

    /// The PSD at `f` Hz.
    pub fn psd(&self, f: f64) -> f64 {
        let mut s = 0.0;
        for t in &self.terms {
            s += t.psd(f);
        }
        for h in &self.filters {
            s /= h.attenuation(f);
        }
        s
    }

    /// A member's parameters: one N(0, 1) per term, correlated through the covariance's
    /// Cholesky factor (a coefficient drawn below zero is zero), then one per filter, then one
    /// per term with its own corner.
    pub fn drawn(&self, rng: &mut SimRng) -> NoiseFamily {
        let n = self.terms.len();
        let l = cholesky(&self.covariance, n);
        let z: Vec<f64> = (0..n).map(|_| gauss(rng)).collect();
        let mut f = self.clone();
        for (i, t) in f.terms.iter_mut().enumerate() {
            let d: f64 = (0..=i).map(|j| l[i][j] * z[j]).sum();
            let v = t.coefficient + d;
            t.coefficient = if v > 0.0 { v } else { 0.0 };
        }
        for h in f.filters.iter_mut() {
            let zf = gauss(rng);
            *h = h.drawn(zf);
        }
        // The terms' own corners last (a family without any draws exactly as before).
        for t in f.terms.iter_mut().filter(|t| t.corner_hz > 0.0) {
            t.corner_hz = (t.corner_hz.ln() + t.ln_corner_sigma * gauss(rng)).exp();
        }
        f
    }

    /// One draw of the noise on a grid of `cells` cells: Gaussian Fourier coefficients with
    /// variance from S, an inverse real FFT over [`SYNTHESIS_FACTOR`] × the grid.
    pub fn synthesise(&self, cells: usize, rng: &mut SimRng) -> Vec<f64> {
        if cells == 0 {
            return Vec::new();
        }
        let len = (SYNTHESIS_FACTOR * cells).next_power_of_two().max(4);
        let dt = self.grid_interval_s;
        let mut spec = vec![(0.0, 0.0); len / 2 + 1];
        // E|X_k|² = len · S(f_k) / (4Δ) per real and imaginary part, so that the series' one-sided
        // PSD is S; the Nyquist bin is real.
        for (k, c) in spec.iter_mut().enumerate() {
            if k == 0 {
                continue;
            }
            let f = k as f64 / (len as f64 * dt);
            let sd = (len as f64 * self.psd(f) / (4.0 * dt)).sqrt();
            if k == len / 2 {
                c.0 = sd * std::f64::consts::SQRT_2 * gauss(rng);
                c.1 = 0.0;
            } else {
                c.0 = sd * gauss(rng);
                c.1 = sd * gauss(rng);
            }
        }
        let mut out = accomp_numerics::fft::real_from_half_spectrum(&spec);
        out.truncate(cells);
        for v in &mut out {
            *v /= len as f64;
        }
        out
    }
}

/// The family laid on the record's grid: where each record point falls.
#[derive(Debug, Clone, PartialEq)]
pub struct GridNoise {
    /// The family.
    pub family: NoiseFamily,
    /// Grid cell of each record point.
    pub cells: Vec<usize>,
    /// Cells in the grid.
    pub len: usize,
    /// The record's transient disturbances, when found: members draw them on the grid too.
    pub transients: Option<Transients>,
}

impl GridNoise {
    /// Adds one member's noise (its own family parameters, then its series, then its draw of
    /// the transients, all from `rng`) at the record's points.
    pub fn add_member(&self, out: &mut [f64], rng: &mut SimRng) {
        let f = self.family.drawn(rng);
        let mut x = f.synthesise(self.len, rng);
        if let Some(t) = &self.transients {
            t.add_drawn(&mut x, rng);
        }
        for (y, &c) in out.iter_mut().zip(&self.cells) {
            *y += x.get(c).copied().unwrap_or(f64::NAN);
        }
    }
}

/// Lower Cholesky factor of the n × n `a` (a non-positive pivot zeroes its column: that
/// direction is held).
fn cholesky(a: &[Vec<f64>], n: usize) -> Vec<Vec<f64>> {
    let mut l = vec![vec![0.0; n]; n];
    let at = |i: usize, j: usize| a.get(i).and_then(|r| r.get(j)).copied().unwrap_or(0.0);
    for i in 0..n {
        for j in 0..=i {
            let s: f64 = (0..j).map(|k| l[i][k] * l[j][k]).sum();
            if i == j {
                let d = at(i, i) - s;
                l[i][j] = if d > 0.0 { d.sqrt() } else { 0.0 };
            } else if l[j][j] > 0.0 {
                l[i][j] = (at(i, j) - s) / l[j][j];
            }
        }
    }
    l
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::noise::stream;

    /// A white term with its own corner is a Gauss–Markov process: its synthesised variance is
    /// the Lorentzian's integral q·f_g·π/2 (correlation time 1 h on a 60 s grid; 50 000 cells
    /// hold about 800 correlation times, so the sample variance is within ~5 %).
    #[test]
    fn a_term_with_a_corner_synthesises_a_gauss_markov_process() {
        let fg = 1.0 / (2.0 * std::f64::consts::PI * 3600.0);
        let family = NoiseFamily {
            grid_interval_s: 60.0,
            terms: vec![PowerLaw {
                name: "gauss_markov".into(),
                alpha: 0,
                coefficient: 2.0,
                corner_hz: fg,
                ln_corner_sigma: 0.0,
            }],
            covariance: vec![vec![0.0]],
            filters: Vec::new(),
        };
        family.validate().expect("valid");
        assert!((family.psd(fg) - 1.0).abs() < 1e-12);
        let x = family.synthesise(50_000, &mut stream(9, 0));
        let mean = x.iter().sum::<f64>() / x.len() as f64;
        let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / x.len() as f64;
        let want = 2.0 * fg * std::f64::consts::FRAC_PI_2;
        assert!(
            (var / want - 1.0).abs() < 0.15,
            "variance {var:.4e}, Lorentzian {want:.4e}"
        );
        // A negative corner is refused by name.
        let mut bad = family.clone();
        bad.terms[0].corner_hz = -1.0;
        assert!(bad
            .validate()
            .unwrap_err()
            .to_string()
            .contains("gauss_markov"));
    }
}
