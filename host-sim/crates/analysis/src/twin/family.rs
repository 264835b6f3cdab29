//! The noise family the twin's members draw from, fitted to the record by maximum likelihood in
//! the frequency domain.
//!
//! One-sided power spectral density of the record's grid series (output unit²/Hz):
//!
//! S(f) = [h₀ + h₋₁/f + h₋₂/f² + h₋₄/f⁴] / (1 + (f/f_c)²)
//!
//! white (h₀), flicker (h₋₁), random walk (h₋₂), drift-rate random walk (h₋₄: the drift rate
//! itself wanders, what a spring's or a proof mass's slow non-linear drift looks like over a
//! record) and the instrument's output filter (a first-order low-pass with corner f_c: averaging
//! or an anti-alias filter lowers the power towards Nyquist). The linear drift is not in S: the
//! level and the drift rate are calibration constants that every comparison removes.
//!
//! Fit: the Whittle likelihood −ℓ = Σ_k [ln E_k + I_k / E_k] of Hann-tapered periodograms I_k
//! of the record's first differences (differencing takes 40 dB of dynamic range off an f⁻⁴
//! spectrum, so the taper keeps the leakage of the lowest frequencies off the white floor), in
//! [`SEGMENTS_PER_RECORD`] half-overlapping segments (every part of the record weighs the same,
//! as in the comparison's ADEV and Welch PSD) plus the whole record's bins below the segments'
//! lowest; E_k = Σ_j w_j · 4 sin²(π f_j Δ) · S(f_j) over bins k − 1, k, k + 1 (the Hann
//! window's mixing). S is linear in the four levels, so at a given corner they are fitted by
//! Fisher scoring (iteratively reweighted least squares; every subset of the coloured terms is
//! tried, the best with all levels positive is taken); the corner by the toolkit's
//! golden-section search on that profile likelihood, kept only when it improves −ℓ by more than
//! [`FILTER_DELTA`]. Uncertainties: the inverse Fisher information (levels and ln f_c jointly)
//! × the Hann window's equivalent noise bandwidth (1.5 bins: neighbouring tapered bins are not
//! independent). A level within [`RESOLVED_SIGMAS`] σ of zero is reported as not resolved.
//!
//! Members: spectral synthesis on the record's grid (Gaussian Fourier coefficients with variance
//! from S, inverse real FFT over 4 × the record's length so that the lowest frequencies are not
//! forced periodic), after drawing the member's own parameters from the fit's covariance.

// Index loops over the four levels and the 3-bin window read as the formulas do.
#![allow(clippy::needless_range_loop)]

use crate::numerics::optimize::golden_section_min;
use crate::sim::noise::{gauss, SimRng};

/// Number of parameters: ln h₀, ln h₋₁, ln h₋₂, ln h₋₄, ln f_c.
pub const PARAMS: usize = 5;
/// Names of the parameters, in order.
pub const NAMES: [&str; PARAMS] = [
    "white",
    "flicker",
    "random_walk",
    "drift_rate_random_walk",
    "filter_corner",
];
/// Power-law exponents of the four noise terms.
const ALPHA: [i32; 4] = [0, -1, -2, -4];
/// Lowest periodogram bins of a segment left out of the likelihood (bin 1 mixes in bin 0,
/// where a steep spectrum has no finite value).
pub const SKIP_BINS: usize = 2;
/// The whole record's lowest bin in the likelihood: bin 1, the slowest wander of the drift
/// (one cycle over the record). It mixes in bin 0, the differences' mean, which the comparison's
/// detrending removes (its power is taken as zero).
const RECORD_FIRST_BIN: usize = 1;
/// The record is cut into this many segments overlapping by half.
pub const SEGMENTS_PER_RECORD: usize = 7;
/// Equivalent noise bandwidth of the Hann window, bins.
const HANN_ENBW: f64 = 1.5;
/// Golden-section steps over ln f_c.
const GOLDEN_STEPS: usize = 40;
/// Fisher-scoring iterations of the levels at one corner.
const SCORING_ITERS: usize = 30;
/// The filter is kept when it lowers −ℓ by more than this (likelihood ratio: ≈ 3σ for one
/// parameter once the tapered bins' correlation, the ENBW, is allowed for).
const FILTER_DELTA: f64 = 3.0 * HANN_ENBW;
/// A level is resolved when it is more than this many σ above zero.
const RESOLVED_SIGMAS: f64 = 2.0;
/// Synthesis length: this many times the record's grid (rounded up to a power of two).
const SYNTHESIS_FACTOR: usize = 4;
/// The filter corner's range, × Nyquist.
const CORNER_RANGE: (f64, f64) = (0.05, 50.0);

/// Why the family could not be fitted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FamilyError {
    /// Too few finite grid values for a spectrum.
    #[error("{0} usable grid values: the noise family needs at least 64")]
    TooShort(usize),
    /// The record's differences are all zero or not finite.
    #[error("the residual is constant: no spectrum to fit")]
    Constant,
}

/// One fitted component (for the report).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Component {
    /// Name (see [`NAMES`]).
    pub name: &'static str,
    /// The PSD coefficient (h₀ unit²/Hz, h₋₁ unit², h₋₂ unit²·Hz, h₋₄ unit²·Hz³; f_c Hz).
    pub coefficient: f64,
    /// Its 1σ uncertainty (from the log-parameter covariance, first order).
    pub sigma: f64,
    /// The same in the user's terms: white σ per point, flicker ADEV floor, random-walk K
    /// (unit/√s), drift-rate walk (unit/s^1.5), corner (Hz).
    pub level: f64,
    /// Its 1σ.
    pub level_sigma: f64,
    /// Unit of `level`.
    pub level_unit: String,
    /// False when the fit pushed it to the bottom of its range (an upper bound).
    pub resolved: bool,
}

/// The fitted family.
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseFamily {
    /// Grid spacing, s.
    pub dt_s: f64,
    /// ln h₀, ln h₋₁, ln h₋₂, ln h₋₄ (−∞: the term is absent), ln f_c (+∞: no filter).
    pub ln_params: [f64; PARAMS],
    /// Covariance of h₀, h₋₁, h₋₂, h₋₄ (inverse Fisher information × the Hann ENBW).
    pub h_cov: [[f64; 4]; 4],
    /// Variance of ln f_c (curvature of the profile likelihood; 0 without a filter).
    pub ln_fc_var: f64,
    /// Periodogram bins in the likelihood.
    pub bins: usize,
    /// Bins left out as narrow lines (not noise; [`line_bins`]).
    pub line_bins: usize,
    /// −ℓ at the optimum.
    pub neg_loglik: f64,
}

/// PSD of the family with log parameters `p` at frequency `f` (Hz).
pub fn psd(p: &[f64; PARAMS], f: f64) -> f64 {
    let mut s = 0.0;
    for (i, a) in ALPHA.iter().enumerate() {
        s += p[i].exp() * f.powi(*a);
    }
    s / (1.0 + (f / p[4].exp()).powi(2))
}

/// One periodogram bin of one segment: the three frequencies the Hann window mixes (k − 1, k,
/// k + 1), their differencing gains 4 sin²(π f Δ), and the periodogram value.
#[derive(Debug, Clone, Copy)]
struct Bin {
    f: [f64; 3],
    g: [f64; 3],
    i: f64,
    /// Which periodogram (segment, or the whole record's lowest bins) it belongs to.
    group: usize,
}

/// Weights of bins k − 1, k, k + 1 in the expected Hann-tapered periodogram at k (the periodic
/// Hann window is −¼, ½, −¼ in the DFT; normalised by its mean square 3/8).
const HANN_MIX: [f64; 3] = [1.0 / 6.0, 2.0 / 3.0, 1.0 / 6.0];

impl Bin {
    /// The expected periodogram's columns: one per noise term, at the corner `fc`.
    fn cols(&self, fc: f64) -> [f64; 4] {
        let mut c = [0.0; 4];
        for j in 0..3 {
            let f = self.f[j];
            if f <= 0.0 {
                continue;
            }
            let l = HANN_MIX[j] * self.g[j] / (1.0 + (f / fc).powi(2));
            c[0] += l;
            c[1] += l / f;
            c[2] += l / (f * f);
            c[3] += l / (f * f * f * f);
        }
        c
    }

    /// The expected periodogram with log parameters `p`.
    fn expected(&self, p: &[f64; PARAMS]) -> f64 {
        (0..3)
            .filter(|&j| self.f[j] > 0.0)
            .map(|j| HANN_MIX[j] * self.g[j] * psd(p, self.f[j]))
            .sum()
    }

    /// ∂E/∂ln f_c with levels `h`.
    fn d_ln_fc(&self, h: &[f64; 4], fc: f64) -> f64 {
        (0..3)
            .filter(|&j| self.f[j] > 0.0)
            .map(|j| {
                let f = self.f[j];
                let u = (f / fc).powi(2);
                let s = h[0] + h[1] / f + h[2] / (f * f) + h[3] / (f * f * f * f);
                HANN_MIX[j] * self.g[j] * s / (1.0 + u) * 2.0 * u / (1.0 + u)
            })
            .sum()
    }
}

/// Periodograms of the first differences of a grid series (gaps filled linearly for the
/// transform) in [`SEGMENTS_PER_RECORD`]-th segments overlapping by half, Hann taper: every
/// part of the record weighs about the same (a non-stationary record, noisier at its start or
/// with a glitch near an end, is fitted as the comparison's ADEV and Welch PSD see it).
fn diff_periodograms(placed: &[f64], dt_s: f64) -> Result<Vec<Bin>, FamilyError> {
    let x = filled(placed);
    let finite = placed.iter().filter(|v| v.is_finite()).count();
    if finite < 64 || x.len() < 65 {
        return Err(FamilyError::TooShort(finite));
    }
    let d: Vec<f64> = x.windows(2).map(|w| w[1] - w[0]).collect();
    if d.iter().all(|v| *v == 0.0) {
        return Err(FamilyError::Constant);
    }
    let n = (2 * d.len() / (SEGMENTS_PER_RECORD + 1))
        .max(64)
        .min(d.len());
    let mut out = Vec::new();
    let mut start = 0;
    let mut group = 0;
    while start + n <= d.len() {
        segment_bins(&d[start..start + n], dt_s, 0.0, SKIP_BINS, group, &mut out);
        start += (n / 2).max(1);
        group += 1;
    }
    // The frequencies below the segments' lowest bin (the slowest drift): the whole record.
    segment_bins(
        &d,
        dt_s,
        SKIP_BINS.max(2) as f64 / (n as f64 * dt_s),
        RECORD_FIRST_BIN,
        group,
        &mut out,
    );
    Ok(out)
}

/// Hann-tapered periodogram bins of one stretch of differences, bins ≥ `first` (and below
/// `below` Hz when it is positive).
fn segment_bins(d: &[f64], dt_s: f64, below: f64, first: usize, group: usize, out: &mut Vec<Bin>) {
    let n = d.len();
    let w: Vec<f64> = (0..n)
        .map(|i| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * i as f64 / n as f64).cos())
        .collect();
    let sw2: f64 = w.iter().map(|v| v * v).sum();
    let gain = |f: f64| 4.0 * (std::f64::consts::PI * f * dt_s).sin().powi(2);
    let freq = |k: usize| k as f64 / (n as f64 * dt_s);
    let mut xw: Vec<f64> = d.iter().zip(&w).map(|(a, b)| a * b).collect();
    let spec = crate::numerics::fft::half_spectrum(&mut xw);
    for k in first.max(1)..spec.len().saturating_sub(1) {
        if below > 0.0 && freq(k) >= below {
            break;
        }
        let (re, im) = spec[k];
        let f = [freq(k - 1), freq(k), freq(k + 1)];
        out.push(Bin {
            f,
            g: [gain(f[0]), gain(f[1]), gain(f[2])],
            i: 2.0 * dt_s * (re * re + im * im) / sw2,
            group,
        });
    }
}

/// Gaps (NaN) filled linearly between their finite neighbours, the ends held.
fn filled(placed: &[f64]) -> Vec<f64> {
    let mut x = placed.to_vec();
    let idx: Vec<usize> = (0..x.len()).filter(|&i| x[i].is_finite()).collect();
    let (Some(&first), Some(&last)) = (idx.first(), idx.last()) else {
        return Vec::new();
    };
    for v in x.iter_mut().take(first) {
        *v = placed[first];
    }
    for v in x.iter_mut().skip(last + 1) {
        *v = placed[last];
    }
    for w in idx.windows(2) {
        let (a, b) = (w[0], w[1]);
        for j in a + 1..b {
            let f = (j - a) as f64 / (b - a) as f64;
            x[j] = placed[a] + (placed[b] - placed[a]) * f;
        }
    }
    x
}

/// Refits without the line bins at most this many times (the lines found under the previous
/// fit; a fit inflated by the lines still shows them against their neighbours).
pub const LINE_PASSES: usize = 3;
/// Neighbours each side whose median is a bin's local level, bins.
const LINE_WINDOW: usize = 8;
/// False-alarm probability of one line bin over the whole likelihood (Bonferroni).
const LINE_FAP: f64 = 0.01;

/// Indices (ascending) of the bins that are narrow lines, not noise, under the family `p`:
/// the ratio q = I/E, normalised by its median over the ±[`LINE_WINDOW`] neighbours of the
/// same periodogram (÷ ln 2: the median of the unit exponential q is under a Gaussian family),
/// exceeds ln(bins / [`LINE_FAP`]) — for a Gaussian family each bin's q is exponential, so all
/// the bins of a record pass together with probability 1 − [`LINE_FAP`]. The local median
/// makes the test see a line against its own neighbours even when the family was inflated by
/// it. A line bin's two neighbours (the Hann window's main lobe) go with it.
fn line_bins(bins: &[Bin], p: &[f64; PARAMS]) -> Vec<usize> {
    let threshold = (bins.len() as f64 / LINE_FAP).ln();
    let q: Vec<f64> = bins
        .iter()
        .map(|b| {
            let e = b.expected(p);
            if e > 0.0 && e.is_finite() {
                b.i / e
            } else {
                0.0
            }
        })
        .collect();
    let mut out = std::collections::BTreeSet::new();
    let mut start = 0;
    while start < bins.len() {
        let g = bins[start].group;
        let end = start + bins[start..].iter().take_while(|b| b.group == g).count();
        if end - start > 2 * LINE_WINDOW {
            for k in start..end {
                let (a, b) = (
                    k.saturating_sub(LINE_WINDOW).max(start),
                    (k + LINE_WINDOW + 1).min(end),
                );
                let mut w: Vec<f64> = q[a..b].to_vec();
                w.sort_by(f64::total_cmp);
                let med = w[w.len() / 2];
                if med > 0.0 && q[k] * std::f64::consts::LN_2 / med > threshold {
                    out.extend(k.saturating_sub(1).max(start)..(k + 2).min(end));
                }
            }
        }
        start = end;
    }
    out.into_iter().collect()
}

/// −ℓ (Whittle) of log parameters `p` on the bins.
fn whittle(p: &[f64; PARAMS], bins: &[Bin]) -> f64 {
    let mut s = 0.0;
    for b in bins {
        let e = b.expected(p);
        if !(e > 0.0 && e.is_finite()) {
            return f64::INFINITY;
        }
        s += e.ln() + b.i / e;
    }
    s
}

impl NoiseFamily {
    /// Fits the family to a residual laid on its regular grid (NaN = gap).
    ///
    /// Narrow lines (a tide or a periodic disturbance the twin's deterministic part leaves in
    /// the residual) are not noise: in the Whittle likelihood a bin's cost grows with I/E, so a
    /// few bins of a strong line pull the coloured terms up by orders of magnitude everywhere
    /// (a 25-day gMetrology half with its tidal residual: the random walk ×4.6, the members
    /// ×20–2000 in power below 1 cycle/day). Bins where the periodogram stands out of its
    /// neighbours beyond what a Gaussian family allows ([`line_bins`]) are left out and the
    /// family refitted, at most [`LINE_PASSES`] times; the count is reported.
    pub fn fit(placed: &[f64], dt_s: f64) -> Result<NoiseFamily, FamilyError> {
        let all = diff_periodograms(placed, dt_s)?;
        if all.len() < 16 {
            return Err(FamilyError::TooShort(placed.len()));
        }
        if all.iter().all(|b| b.i <= 0.0) {
            return Err(FamilyError::Constant);
        }
        let mut fam = Self::fit_bins(&all, dt_s);
        for _ in 0..LINE_PASSES {
            let lines = line_bins(&all, &fam.ln_params);
            if lines.len() == fam.line_bins {
                break;
            }
            let kept: Vec<Bin> = all
                .iter()
                .enumerate()
                .filter(|(k, _)| lines.binary_search(k).is_err())
                .map(|(_, b)| *b)
                .collect();
            if kept.len() < 16 {
                break;
            }
            fam = Self::fit_bins(&kept, dt_s);
            fam.line_bins = lines.len();
        }
        Ok(fam)
    }

    /// The family's maximum-likelihood fit to the bins.
    fn fit_bins(bins: &[Bin], dt_s: f64) -> NoiseFamily {
        let nyq = 0.5 / dt_s;
        let (lo, hi) = ((CORNER_RANGE.0 * nyq).ln(), (CORNER_RANGE.1 * nyq).ln());
        // The profile likelihood in ln f_c (the levels at their maximum for each corner), and
        // without a filter.
        let best = golden_section_min(|v| levels(bins, v).1, lo, hi, GOLDEN_STEPS);
        let (h_f, nll_f) = levels_best(bins, best);
        let (h_0, nll_0) = levels_best(bins, f64::INFINITY);
        // The filter is kept when it improves −ℓ by more than FILTER_DELTA (a likelihood-ratio
        // test with one parameter at about 2σ).
        let filtered = nll_0 - nll_f > FILTER_DELTA;
        let (h, ln_fc, nll) = if filtered {
            (h_f, best, nll_f)
        } else {
            (h_0, f64::INFINITY, nll_0)
        };
        let ln_params = ln_params_of(&h, ln_fc);
        let (h_cov, ln_fc_var) = covariance(bins, &h, ln_fc);
        NoiseFamily {
            dt_s,
            ln_params,
            h_cov,
            ln_fc_var,
            bins: bins.len(),
            line_bins: 0,
            neg_loglik: nll,
        }
    }

    /// −ℓ of the family refitted to another series at this fit's corner (the levels at their
    /// maximum, the corner held): the profile likelihood of a change to the series' mean, such
    /// as a drift polynomial removed.
    pub fn neg_loglik_of(&self, placed: &[f64]) -> f64 {
        match diff_periodograms(placed, self.dt_s) {
            Ok(all) => {
                let lines = line_bins(&all, &self.ln_params);
                let bins: Vec<Bin> = all
                    .iter()
                    .enumerate()
                    .filter(|(k, _)| lines.binary_search(k).is_err())
                    .map(|(_, b)| *b)
                    .collect();
                levels_best(&bins, self.ln_params[4]).1
            }
            _ => f64::INFINITY,
        }
    }

    /// Whether parameter `i` is resolved (above the bottom of its range; the filter: below the
    /// top, i.e. a corner inside the record's band).
    pub fn resolved(&self, i: usize) -> bool {
        if i == 4 {
            self.ln_params[4].is_finite()
        } else {
            let h = self.ln_params[i].exp();
            h > RESOLVED_SIGMAS * self.h_cov[i][i].max(0.0).sqrt()
        }
    }

    /// The PSD at `f` Hz.
    pub fn psd(&self, f: f64) -> f64 {
        psd(&self.ln_params, f)
    }

    /// The components with uncertainties, in the user's terms.
    pub fn components(&self, unit: &str) -> Vec<Component> {
        let pi2 = std::f64::consts::PI.powi(2);
        (0..PARAMS)
            .map(|i| {
                let c = self.ln_params[i].exp();
                let sigma = if i < 4 {
                    self.h_cov[i][i].max(0.0).sqrt()
                } else {
                    c * self.ln_fc_var.max(0.0).sqrt()
                };
                // Each level is √(k·c): its σ is half the coefficient's relative σ.
                let (k, level_unit) = match i {
                    0 => (1.0 / (2.0 * self.dt_s), format!("{unit} per point")),
                    1 => (2.0 * std::f64::consts::LN_2, format!("{unit} (ADEV floor)")),
                    2 => (2.0 * pi2, format!("{unit}/√s")),
                    3 => (8.0 * pi2 * pi2, format!("{unit}/s^1.5")),
                    _ => (f64::NAN, "Hz".to_owned()),
                };
                let (level, level_sigma) = if i < 4 {
                    let l = (k * c).sqrt();
                    (
                        l,
                        if c > 0.0 {
                            0.5 * l * sigma / c
                        } else {
                            (k * sigma).sqrt()
                        },
                    )
                } else {
                    (c, sigma)
                };
                Component {
                    name: NAMES[i],
                    coefficient: c,
                    sigma,
                    level,
                    level_sigma,
                    level_unit,
                    resolved: self.resolved(i),
                }
            })
            .collect()
    }

    /// A member's parameters: the levels drawn from their covariance (a draw below zero is
    /// held at zero), the corner from its log-normal.
    pub fn drawn(&self, rng: &mut SimRng) -> NoiseFamily {
        let l = cholesky4(&self.h_cov);
        let z: Vec<f64> = (0..4).map(|_| gauss(rng)).collect();
        let zf = gauss(rng);
        let mut f = self.clone();
        for i in 0..4 {
            let h = self.ln_params[i].exp();
            let d: f64 = (0..=i).map(|j| l[i][j] * z[j]).sum();
            let v = h + d;
            f.ln_params[i] = if v > 0.0 { v.ln() } else { f64::NEG_INFINITY };
        }
        if self.ln_params[4].is_finite() {
            f.ln_params[4] += self.ln_fc_var.max(0.0).sqrt() * zf;
        }
        f
    }

    /// One draw of the noise on a grid of `cells` cells (spacing `dt_s`).
    pub fn synthesise(&self, cells: usize, rng: &mut SimRng) -> Vec<f64> {
        if cells == 0 {
            return Vec::new();
        }
        let len = (SYNTHESIS_FACTOR * cells).next_power_of_two().max(4);
        let dt = self.dt_s;
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
        let mut out = crate::numerics::fft::real_from_half_spectrum(&spec);
        out.truncate(cells);
        for v in &mut out {
            *v /= len as f64;
        }
        out
    }
}

/// The levels h₀, h₋₁, h₋₂, h₋₄ that maximise the Whittle likelihood at the corner
/// e^`ln_fc`, and −ℓ there. The spectrum is linear in the levels, so Fisher scoring is
/// iteratively reweighted least squares: h ← (XᵀWX)⁻¹XᵀW I with W = 1/E², columns scaled to
/// unit weight; a level a step takes below zero shrinks ×0.1 per step instead.
fn levels(bins: &[Bin], ln_fc: f64) -> ([f64; 4], f64) {
    scoring(bins, ln_fc, [true; 4], false)
}

/// The best of the term subsets (white always in): each fitted by [`scoring`] with its terms
/// held positive at convergence (a subset whose unconstrained optimum puts a term below zero
/// is not a candidate), the largest likelihood taken — the constrained maximum.
fn levels_best(bins: &[Bin], ln_fc: f64) -> ([f64; 4], f64) {
    let mut best = levels(bins, ln_fc);
    for mask in 0..8u32 {
        let active = [true, mask & 1 != 0, mask & 2 != 0, mask & 4 != 0];
        let c = scoring(bins, ln_fc, active, true);
        if c.1 < best.1 {
            best = c;
        }
    }
    best
}

/// Fisher scoring of the `active` levels at the corner e^`ln_fc`; `strict`: −ℓ = +∞ when the
/// converged step still puts an active level at or below zero.
fn scoring(bins: &[Bin], ln_fc: f64, active: [bool; 4], strict: bool) -> ([f64; 4], f64) {
    let mut negative = false;
    let fc = ln_fc.exp();
    let cols: Vec<[f64; 4]> = bins.iter().map(|b| b.cols(fc)).collect();
    // Start: the white level alone from the highest frequencies.
    let f_max = bins.iter().map(|b| b.f[1]).fold(0.0, f64::max);
    let upper: Vec<f64> = bins
        .iter()
        .zip(&cols)
        .filter(|(b, _)| b.f[1] > 0.5 * f_max)
        .map(|(b, c)| b.i / c[0])
        .collect();
    let w0 = upper.iter().sum::<f64>() / upper.len().max(1) as f64;
    let mut h = [w0.max(f64::MIN_POSITIVE), 0.0, 0.0, 0.0];
    for _ in 0..SCORING_ITERS {
        let e: Vec<f64> = cols
            .iter()
            .map(|c| (0..4).map(|a| c[a] * h[a]).sum::<f64>())
            .collect();
        if e.iter().any(|v| v.is_nan() || *v <= 0.0) {
            break;
        }
        let idx: Vec<usize> = (0..4).filter(|&a| active[a]).collect();
        let scale: Vec<f64> = idx
            .iter()
            .map(|&a| {
                cols.iter()
                    .zip(&e)
                    .map(|(c, e)| (c[a] / e).powi(2))
                    .sum::<f64>()
                    .sqrt()
            })
            .collect();
        let m = idx.len();
        let mut xtx = vec![vec![0.0; m]; m];
        let mut xty = vec![0.0; m];
        for ((c, e), b) in cols.iter().zip(&e).zip(bins) {
            let w = 1.0 / (e * e);
            for p in 0..m {
                let xp = c[idx[p]] / scale[p];
                xty[p] += w * xp * b.i;
                for q in p..m {
                    xtx[p][q] += w * xp * c[idx[q]] / scale[q];
                }
            }
        }
        for p in 0..m {
            for q in 0..p {
                xtx[p][q] = xtx[q][p];
            }
        }
        let Some(sol) = crate::numerics::linalg::solve_square(&xtx, &xty) else {
            break;
        };
        // A level the step takes below zero shrinks towards zero instead (it stays in the
        // model, so that it can come back when the others move).
        negative = false;
        for p in 0..m {
            let a = idx[p];
            let v = sol[p] / scale[p];
            h[a] = if v > 0.0 {
                if h[a] > 0.0 {
                    // Geometric half steps keep the weights (1/E²) from jumping.
                    (h[a] * v).sqrt()
                } else {
                    0.5 * v
                }
            } else {
                negative = true;
                0.1 * h[a]
            };
        }
    }
    if strict && negative {
        return (h, f64::INFINITY);
    }
    (h, whittle(&ln_params_of(&h, ln_fc), bins))
}

/// The parameters in logs: ln of each level (−∞ for a level at zero) and ln f_c.
fn ln_params_of(h: &[f64; 4], ln_fc: f64) -> [f64; PARAMS] {
    let mut p = [0.0; PARAMS];
    for (pa, &ha) in p.iter_mut().zip(h) {
        *pa = if ha > 0.0 { ha.ln() } else { f64::NEG_INFINITY };
    }
    p[4] = ln_fc;
    p
}

/// Covariance of the levels and of ln f_c: the inverse Fisher information of the Whittle
/// likelihood, Σ ∂E/∂a · ∂E/∂b / E², over the levels that are not zero and ln f_c when there is
/// a filter (so the levels' σ include their trade-off with the corner), × the Hann ENBW.
fn covariance(bins: &[Bin], h: &[f64; 4], ln_fc: f64) -> ([[f64; 4]; 4], f64) {
    let fc = ln_fc.exp();
    // Parameters: the non-zero levels (scaled by their value) and ln f_c (index 4).
    let mut idx: Vec<usize> = (0..4).filter(|&a| h[a] > 0.0).collect();
    if ln_fc.is_finite() {
        idx.push(4);
    }
    let m = idx.len();
    let scale: Vec<f64> = idx
        .iter()
        .map(|&a| if a < 4 { h[a] } else { 1.0 })
        .collect();
    let mut info = vec![vec![0.0; m]; m];
    for b in bins {
        let x = b.cols(fc);
        let e: f64 = (0..4).map(|a| x[a] * h[a]).sum();
        let d: Vec<f64> = idx
            .iter()
            .zip(&scale)
            .map(|(&a, s)| if a < 4 { x[a] * s } else { b.d_ln_fc(h, fc) })
            .collect();
        for p in 0..m {
            for q in 0..m {
                info[p][q] += d[p] * d[q] / (e * e);
            }
        }
    }
    let mut cov = [[0.0; 4]; 4];
    let mut var_fc = 0.0;
    for q in 0..m {
        let mut e = vec![0.0; m];
        e[q] = 1.0;
        if let Some(col) = crate::numerics::linalg::solve_square(&info, &e) {
            for p in 0..m {
                let v = HANN_ENBW * col[p] * scale[p] * scale[q];
                match (idx[p], idx[q]) {
                    (4, 4) => var_fc = v,
                    (a, b) if a < 4 && b < 4 => cov[a][b] = v,
                    _ => {}
                }
            }
        }
    }
    (cov, var_fc)
}

/// Lower Cholesky factor (a non-positive pivot zeroes its column: that direction is held).
fn cholesky4(a: &[[f64; 4]; 4]) -> [[f64; 4]; 4] {
    let mut l = [[0.0; 4]; 4];
    for i in 0..4 {
        for j in 0..=i {
            let s: f64 = (0..j).map(|k| l[i][k] * l[j][k]).sum();
            if i == j {
                let d = a[i][i] - s;
                l[i][j] = if d > 0.0 { d.sqrt() } else { 0.0 };
            } else if l[j][j] > 0.0 {
                l[i][j] = (a[i][j] - s) / l[j][j];
            }
        }
    }
    l
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::noise::stream;

    /// A series synthesised from known parameters is fitted back within a few σ, and the σ are
    /// those of the fit (the truth within 4σ for every resolved term).
    #[test]
    fn a_synthesised_record_gives_back_its_parameters() {
        let dt = 60.0;
        let truth = NoiseFamily {
            dt_s: dt,
            ln_params: [
                (1e-2f64).ln(),
                (1e-6f64).ln(),
                (1e-11f64).ln(),
                (1e-22f64).ln(),
                (0.3 * 0.5 / dt).ln(),
            ],
            h_cov: [[0.0; 4]; 4],
            ln_fc_var: 0.0,
            bins: 0,
            line_bins: 0,
            neg_loglik: 0.0,
        };
        let mut rng = stream(11, 0);
        let x = truth.synthesise(20_000, &mut rng);
        let fit = NoiseFamily::fit(&x, dt).expect("fit");
        let c = fit.components("u");
        for i in 0..PARAMS {
            let truth_c = truth.ln_params[i].exp();
            let z = (c[i].coefficient - truth_c) / c[i].sigma;
            let must_resolve = [0, 1, 4].contains(&i);
            assert!(
                z.abs() < 4.0 && (!must_resolve || (c[i].resolved && c[i].sigma < 0.3 * truth_c)),
                "{}: fitted {:.3e} ± {:.1e}, truth {truth_c:.3e}",
                NAMES[i],
                c[i].coefficient,
                c[i].sigma
            );
        }
    }

    #[test]
    fn white_noise_leaves_the_coloured_terms_unresolved_and_no_filter() {
        let mut rng = stream(3, 0);
        let x: Vec<f64> = (0..8192).map(|_| gauss(&mut rng)).collect();
        let fit = NoiseFamily::fit(&x, 1.0).expect("fit");
        // White σ per point 1: h₀ = 2Δσ² = 2.
        let c = fit.components("u");
        assert!((c[0].level - 1.0).abs() < 0.05, "{:?}", c[0]);
        assert!(
            !fit.resolved(4),
            "a filter was found in white noise: {:?}",
            c[4]
        );
        // No coloured term is resolved; together they carry under 30 % of the power a decade
        // above the lowest bins.
        assert!(c[1..4].iter().all(|c| !c.resolved), "{c:?}");
        let f = 40.0 / 8192.0;
        let white = fit.ln_params[0].exp();
        assert!(fit.psd(f) < 1.3 * white, "{} vs {white}", fit.psd(f));
    }
}
