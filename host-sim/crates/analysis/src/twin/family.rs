//! The noise family the twin's members draw from, fitted to the record by maximum likelihood in
//! the frequency domain.
//!
//! One-sided power spectral density of the record's grid series (output unit²/Hz):
//!
//! S(f) = [h₀ + h₋₁/f + h₋₂/f² + h₋₄/f⁴ + q / (1 + (f/f_g)²)] / (1 + (f/f_c)²)
//!
//! white (h₀), flicker (h₋₁), random walk (h₋₂), drift-rate random walk (h₋₄: the drift rate
//! itself wanders, what a spring's or a proof mass's slow non-linear drift looks like over a
//! record), a Gauss–Markov process (first-order Markov, Lorentzian: level q, corner f_g,
//! correlation time 1/(2π f_g) — a disturbance with a memory of hours, such as the room's or the
//! instrument's thermal regulation, which no power law has) and the instrument's output filter
//! (a first-order low-pass with corner f_c: averaging or an anti-alias filter lowers the power
//! towards Nyquist). The linear drift is not in S: the level and the drift rate are calibration
//! constants that every comparison removes.
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
//! [`FILTER_DELTA`]. The Gauss–Markov corner likewise, with the filter held: kept when it
//! lowers −ℓ by more than [`FILTER_DELTA`], q is resolved and the corner is not within
//! [`GM_EDGE`] of an end of its range [`GM_RANGE`] (a corner at an edge is the fit wanting a
//! process outside the record's band, not a finding). Uncertainties: the inverse Fisher
//! information (levels, ln f_c and ln f_g jointly)
//! × the Hann window's equivalent noise bandwidth (1.5 bins: neighbouring tapered bins are not
//! independent). A level within [`RESOLVED_SIGMAS`] σ of zero is reported as not resolved.
//!
//! Members: [`NoiseFamily::spec`] hands the fit to the simulator (`accomp-sim`, `twin::family`),
//! which draws each member's own parameters from the fit's covariance and synthesises its noise
//! on the record's grid.

// Index loops over the five levels and the 3-bin window read as the formulas do.
#![allow(clippy::needless_range_loop)]

use crate::numerics::optimize::golden_section_min;
#[cfg(test)]
use crate::sim::noise::gauss;

/// Number of parameters: ln h₀, ln h₋₁, ln h₋₂, ln h₋₄, ln f_c, ln q, ln f_g.
pub const PARAMS: usize = 7;
/// Names of the parameters, in order.
pub const NAMES: [&str; PARAMS] = [
    "white",
    "flicker",
    "random_walk",
    "drift_rate_random_walk",
    "filter_corner",
    "gauss_markov",
    "gauss_markov_corner",
];
/// Levels (linear in S): the four power laws and the Gauss–Markov level q.
const LEVELS: usize = 5;
/// Index in the parameters of each level.
const LEVEL_PARAM: [usize; LEVELS] = [0, 1, 2, 3, 5];
/// The Gauss–Markov corner's search range, × the record's Nyquist frequency (from about 20
/// cycles over a 50 000-cell record up to a fifth of Nyquist).
const GM_RANGE: (f64, f64) = (1e-3, 0.2);
/// A Gauss–Markov corner within this fraction of the (log) range of an end is at the edge.
const GM_EDGE: f64 = 0.02;
/// Golden-section steps over ln f_g.
const GM_GOLDEN_STEPS: usize = 30;
/// Power-law exponents of the four noise terms.
const ALPHA: [i32; 4] = [0, -1, -2, -4];
/// Lowest periodogram bins of a segment left out of the likelihood (bin 1 mixes in bin 0,
/// where a steep spectrum has no finite value).
pub const SKIP_BINS: usize = 2;
/// The whole record's lowest bin in the likelihood: bin 1, the slowest wander of the drift
/// (one cycle over the record). It mixes in bin 0, the differences' mean, which the comparison's
/// detrending removes (its power is taken as zero). A residual with a drift polynomial of
/// order N removed starts at bin ⌈(N + 1)/2⌉ instead ([`NoiseFamily::fit_after_drift`]).
const RECORD_FIRST_BIN: usize = 1;

/// The whole record's lowest bin in the likelihood of a residual from which a polynomial of
/// `order` was removed: ⌈(order + 1)/2⌉ (at least bin 1). The polynomial has `order` zeros, so
/// it takes out about the record's lowest (order + 1)/2 cycles along with the drift; fitted with
/// those bins in, the family would carry their removal into the members, which the comparison
/// then removes the polynomial from again — the slowest power lost twice.
pub fn record_first_bin(order: usize) -> usize {
    (order + 2) / 2
}
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
    /// ln h₀, ln h₋₁, ln h₋₂, ln h₋₄ (−∞: the term is absent), ln f_c (+∞: no filter), ln q
    /// (−∞: no Gauss–Markov term), ln f_g (+∞: none).
    pub ln_params: [f64; PARAMS],
    /// Covariance of h₀, h₋₁, h₋₂, h₋₄, q (inverse Fisher information × the Hann ENBW).
    pub h_cov: [[f64; LEVELS]; LEVELS],
    /// Variance of ln f_c (curvature of the profile likelihood; 0 without a filter).
    pub ln_fc_var: f64,
    /// Variance of ln f_g (0 without a Gauss–Markov term).
    pub ln_fg_var: f64,
    /// Periodogram bins in the likelihood.
    pub bins: usize,
    /// The whole record's lowest bin in the likelihood.
    pub record_first_bin: usize,
    /// Bins left out as narrow lines (not noise; [`line_bins`]).
    pub line_bins: usize,
    /// −ℓ at the optimum.
    pub neg_loglik: f64,
    /// The Gauss–Markov term's search, kept or not.
    pub gm_search: GaussMarkovSearch,
}

/// What the search for a Gauss–Markov term found (for the report, also when it was refused).
#[derive(Debug, Clone, PartialEq)]
pub struct GaussMarkovSearch {
    /// ln of the best corner, Hz.
    pub ln_corner: f64,
    /// Whether that corner is at an edge of [`GM_RANGE`] (then refused).
    pub at_edge: bool,
    /// −ℓ without the term minus −ℓ with it (kept when above [`FILTER_DELTA`]).
    pub neg_loglik_gain: f64,
}

impl GaussMarkovSearch {
    /// Why the term is not in the family (None: it is).
    pub fn refusal(&self, kept: bool) -> Option<String> {
        if kept {
            return None;
        }
        let fg = self.ln_corner.exp();
        Some(if self.at_edge {
            format!(
                "best corner {fg:.3e} Hz at the edge of its search range: a process outside the \
                 record's band, not a finding"
            )
        } else if self.neg_loglik_gain <= FILTER_DELTA {
            format!(
                "best corner {fg:.3e} Hz improves −ℓ by {:.1} (needs > {FILTER_DELTA})",
                self.neg_loglik_gain
            )
        } else {
            format!("best corner {fg:.3e} Hz: its level is not resolved")
        })
    }
}

/// PSD of the family with log parameters `p` at frequency `f` (Hz).
pub fn psd(p: &[f64; PARAMS], f: f64) -> f64 {
    let mut s = 0.0;
    for (i, a) in ALPHA.iter().enumerate() {
        s += p[i].exp() * f.powi(*a);
    }
    if p[5].is_finite() {
        s += p[5].exp() / (1.0 + (f / p[6].exp()).powi(2));
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
    /// The expected periodogram's columns: one per level, at the corners `fc` (filter) and
    /// `fg` (Gauss–Markov; +∞: none, its column is zero).
    fn cols(&self, fc: f64, fg: f64) -> [f64; LEVELS] {
        let mut c = [0.0; LEVELS];
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
            if fg.is_finite() {
                c[4] += l / (1.0 + (f / fg).powi(2));
            }
        }
        c
    }

    /// Σ `term(w, f)` over the mixed frequencies f > 0, w the Hann weight times the
    /// differencing gain at f: the expected periodogram is linear in the PSD.
    fn mixed(&self, term: impl Fn(f64, f64) -> f64) -> f64 {
        (0..3)
            .filter(|&j| self.f[j] > 0.0)
            .map(|j| term(HANN_MIX[j] * self.g[j], self.f[j]))
            .sum()
    }

    /// The expected periodogram with log parameters `p`.
    fn expected(&self, p: &[f64; PARAMS]) -> f64 {
        self.mixed(|w, f| w * psd(p, f))
    }

    /// ∂E/∂ln f_c with levels `h`.
    fn d_ln_fc(&self, h: &[f64; LEVELS], fc: f64, fg: f64) -> f64 {
        self.mixed(|w, f| {
            let u = (f / fc).powi(2);
            let mut s = h[0] + h[1] / f + h[2] / (f * f) + h[3] / (f * f * f * f);
            if fg.is_finite() {
                s += h[4] / (1.0 + (f / fg).powi(2));
            }
            w * s / (1.0 + u) * 2.0 * u / (1.0 + u)
        })
    }

    /// ∂E/∂ln f_g with levels `h`.
    fn d_ln_fg(&self, h: &[f64; LEVELS], fc: f64, fg: f64) -> f64 {
        self.mixed(|w, f| {
            let v = (f / fg).powi(2);
            w / (1.0 + (f / fc).powi(2)) * h[4] * 2.0 * v / (1.0 + v).powi(2)
        })
    }
}

/// Periodograms of the first differences of a grid series (gaps filled linearly for the
/// transform) in [`SEGMENTS_PER_RECORD`]-th segments overlapping by half, Hann taper: every
/// part of the record weighs about the same (a non-stationary record, noisier at its start or
/// with a glitch near an end, is fitted as the comparison's ADEV and Welch PSD see it).
fn diff_periodograms(
    placed: &[f64],
    dt_s: f64,
    record_first: usize,
) -> Result<Vec<Bin>, FamilyError> {
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
        record_first,
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

/// The bins without those at the (ascending) indices `lines`.
fn without_lines(bins: &[Bin], lines: &[usize]) -> Vec<Bin> {
    bins.iter()
        .enumerate()
        .filter(|(k, _)| lines.binary_search(k).is_err())
        .map(|(_, b)| *b)
        .collect()
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
        Self::fit_from_bin(placed, dt_s, RECORD_FIRST_BIN)
    }

    /// Fits the family to a residual from which a drift polynomial of `order` was removed: the
    /// whole record's bins from [`record_first_bin`]`(order)` up.
    pub fn fit_after_drift(
        placed: &[f64],
        dt_s: f64,
        order: usize,
    ) -> Result<NoiseFamily, FamilyError> {
        Self::fit_from_bin(placed, dt_s, record_first_bin(order))
    }

    fn fit_from_bin(
        placed: &[f64],
        dt_s: f64,
        record_first: usize,
    ) -> Result<NoiseFamily, FamilyError> {
        let all = diff_periodograms(placed, dt_s, record_first)?;
        if all.len() < 16 {
            return Err(FamilyError::TooShort(placed.len()));
        }
        if all.iter().all(|b| b.i <= 0.0) {
            return Err(FamilyError::Constant);
        }
        let mut fam = Self::fit_bins(&all, dt_s, record_first);
        for _ in 0..LINE_PASSES {
            let lines = line_bins(&all, &fam.ln_params);
            if lines.len() == fam.line_bins {
                break;
            }
            let kept = without_lines(&all, &lines);
            if kept.len() < 16 {
                break;
            }
            fam = Self::fit_bins(&kept, dt_s, record_first);
            fam.line_bins = lines.len();
        }
        Ok(fam)
    }

    /// The family's maximum-likelihood fit to the bins.
    fn fit_bins(bins: &[Bin], dt_s: f64, record_first: usize) -> NoiseFamily {
        let nyq = 0.5 / dt_s;
        let (lo, hi) = ((CORNER_RANGE.0 * nyq).ln(), (CORNER_RANGE.1 * nyq).ln());
        // The profile likelihood in ln f_c (the levels at their maximum for each corner), and
        // without a filter.
        let none = f64::INFINITY;
        let best = golden_section_min(|v| levels(bins, v, none).1, lo, hi, GOLDEN_STEPS);
        let (h_f, nll_f) = levels_best(bins, best, none);
        let (h_0, nll_0) = levels_best(bins, none, none);
        // The filter is kept when it improves −ℓ by more than FILTER_DELTA (a likelihood-ratio
        // test with one parameter at about 2σ).
        let filtered = nll_0 - nll_f > FILTER_DELTA;
        let (mut h, ln_fc, mut nll) = if filtered {
            (h_f, best, nll_f)
        } else {
            (h_0, none, nll_0)
        };
        // The Gauss–Markov term: its corner by golden section on the profile likelihood (the
        // filter held), kept when it improves −ℓ by more than FILTER_DELTA, its level is
        // resolved and its corner is not at an edge of the range.
        let nll_without_gm = nll;
        let (glo, ghi) = ((GM_RANGE.0 * nyq).ln(), (GM_RANGE.1 * nyq).ln());
        let fg = golden_section_min(|v| levels(bins, ln_fc, v).1, glo, ghi, GM_GOLDEN_STEPS);
        let (h_g, nll_g) = levels_best(bins, ln_fc, fg);
        let edge = GM_EDGE * (ghi - glo);
        let inside = fg - glo > edge && ghi - fg > edge;
        let mut ln_fg = none;
        if nll - nll_g > FILTER_DELTA && inside && h_g[4] > 0.0 {
            let (cov, _, _) = covariance(bins, &h_g, ln_fc, fg);
            if h_g[4] > RESOLVED_SIGMAS * cov[4][4].max(0.0).sqrt() {
                (h, nll, ln_fg) = (h_g, nll_g, fg);
            }
        }
        let gm_search = GaussMarkovSearch {
            ln_corner: fg,
            at_edge: !inside,
            neg_loglik_gain: nll_without_gm - nll_g,
        };
        let ln_params = ln_params_of(&h, ln_fc, ln_fg);
        let (h_cov, ln_fc_var, ln_fg_var) = covariance(bins, &h, ln_fc, ln_fg);
        NoiseFamily {
            dt_s,
            ln_params,
            h_cov,
            ln_fc_var,
            ln_fg_var,
            bins: bins.len(),
            record_first_bin: record_first,
            line_bins: 0,
            neg_loglik: nll,
            gm_search,
        }
    }

    /// Whether parameter `i` is resolved (above the bottom of its range; the filter: below the
    /// top, i.e. a corner inside the record's band).
    pub fn resolved(&self, i: usize) -> bool {
        match i {
            4 | 6 => self.ln_params[i].is_finite(),
            _ => {
                let l = LEVEL_PARAM.iter().position(|&p| p == i).unwrap_or(0);
                let h = self.ln_params[i].exp();
                h > RESOLVED_SIGMAS * self.h_cov[l][l].max(0.0).sqrt()
            }
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
                let level_index = LEVEL_PARAM.iter().position(|&p| p == i);
                let sigma = match (i, level_index) {
                    (_, Some(l)) => self.h_cov[l][l].max(0.0).sqrt(),
                    (4, _) => c * self.ln_fc_var.max(0.0).sqrt(),
                    _ => c * self.ln_fg_var.max(0.0).sqrt(),
                };
                // Each level is √(k·c): its σ is half the coefficient's relative σ. The
                // Gauss–Markov level: the process' σ, √(q · f_g · π/2).
                let (k, level_unit) = match i {
                    0 => (1.0 / (2.0 * self.dt_s), format!("{unit} per point")),
                    1 => (2.0 * std::f64::consts::LN_2, format!("{unit} (ADEV floor)")),
                    2 => (2.0 * pi2, format!("{unit}/√s")),
                    3 => (8.0 * pi2 * pi2, format!("{unit}/s^1.5")),
                    5 => (
                        self.ln_params[6].exp() * std::f64::consts::FRAC_PI_2,
                        format!("{unit} (process σ)"),
                    ),
                    _ => (f64::NAN, "Hz".to_owned()),
                };
                let (level, level_sigma) = if level_index.is_some() {
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

    /// The family as the simulator's description (`accomp-sim`, `twin::family`), which draws
    /// the members' parameters and synthesises their noise: the four power laws (and the
    /// Gauss–Markov term, white with its own corner, when fitted) with their covariance and the
    /// first-order output filter (`corner_hz = 0`: none).
    pub fn spec(&self) -> crate::sim::twin::family::NoiseFamily {
        use crate::sim::twin::family::{NoiseFamily as Spec, NoiseFilter, PowerLaw};
        // The Gauss–Markov term is a fifth term only when fitted (a family without it is
        // written, and drawn, as the four power laws).
        let gm = self.ln_params[5].is_finite() && self.ln_params[6].is_finite();
        let terms = if gm { LEVELS } else { 4 };
        Spec {
            grid_interval_s: self.dt_s,
            terms: (0..4)
                .map(|i| PowerLaw {
                    name: NAMES[i].to_owned(),
                    alpha: ALPHA[i],
                    coefficient: self.ln_params[i].exp(),
                    corner_hz: 0.0,
                    ln_corner_sigma: 0.0,
                })
                .chain(gm.then(|| PowerLaw {
                    name: NAMES[5].to_owned(),
                    alpha: 0,
                    coefficient: self.ln_params[5].exp(),
                    corner_hz: self.ln_params[6].exp(),
                    ln_corner_sigma: self.ln_fg_var.max(0.0).sqrt(),
                }))
                .collect(),
            covariance: self.h_cov[..terms]
                .iter()
                .map(|r| r[..terms].to_vec())
                .collect(),
            filters: vec![NoiseFilter::FirstOrderLowPass {
                corner_hz: if self.ln_params[4].is_finite() {
                    self.ln_params[4].exp()
                } else {
                    0.0
                },
                ln_corner_sigma: self.ln_fc_var.max(0.0).sqrt(),
            }],
        }
    }
}

/// The levels h₀, h₋₁, h₋₂, h₋₄ (and q when `ln_fg` is finite) that maximise the Whittle
/// likelihood at the corners e^`ln_fc` and e^`ln_fg`, and −ℓ there. The spectrum is linear in
/// the levels, so Fisher scoring is iteratively reweighted least squares: h ← (XᵀWX)⁻¹XᵀW I
/// with W = 1/E², columns scaled to unit weight; a level a step takes below zero shrinks ×0.1
/// per step instead.
fn levels(bins: &[Bin], ln_fc: f64, ln_fg: f64) -> ([f64; LEVELS], f64) {
    let gm = ln_fg.is_finite();
    scoring(bins, ln_fc, ln_fg, [true, true, true, true, gm], false)
}

/// The best of the term subsets (white always in): each fitted by [`scoring`] with its terms
/// held positive at convergence (a subset whose unconstrained optimum puts a term below zero
/// is not a candidate), the largest likelihood taken — the constrained maximum.
fn levels_best(bins: &[Bin], ln_fc: f64, ln_fg: f64) -> ([f64; LEVELS], f64) {
    let mut best = levels(bins, ln_fc, ln_fg);
    let masks = if ln_fg.is_finite() { 16u32 } else { 8 };
    for mask in 0..masks {
        let active = [
            true,
            mask & 1 != 0,
            mask & 2 != 0,
            mask & 4 != 0,
            mask & 8 != 0,
        ];
        let c = scoring(bins, ln_fc, ln_fg, active, true);
        if c.1 < best.1 {
            best = c;
        }
    }
    best
}

/// Fisher scoring of the `active` levels at the corner e^`ln_fc`; `strict`: −ℓ = +∞ when the
/// converged step still puts an active level at or below zero.
fn scoring(
    bins: &[Bin],
    ln_fc: f64,
    ln_fg: f64,
    active: [bool; LEVELS],
    strict: bool,
) -> ([f64; LEVELS], f64) {
    let mut negative = false;
    let (fc, fg) = (ln_fc.exp(), ln_fg.exp());
    let cols: Vec<[f64; LEVELS]> = bins.iter().map(|b| b.cols(fc, fg)).collect();
    // Start: the white level alone from the highest frequencies.
    let f_max = bins.iter().map(|b| b.f[1]).fold(0.0, f64::max);
    let upper: Vec<f64> = bins
        .iter()
        .zip(&cols)
        .filter(|(b, _)| b.f[1] > 0.5 * f_max)
        .map(|(b, c)| b.i / c[0])
        .collect();
    let w0 = upper.iter().sum::<f64>() / upper.len().max(1) as f64;
    let mut h = [w0.max(f64::MIN_POSITIVE), 0.0, 0.0, 0.0, 0.0];
    for _ in 0..SCORING_ITERS {
        let e: Vec<f64> = cols
            .iter()
            .map(|c| (0..LEVELS).map(|a| c[a] * h[a]).sum::<f64>())
            .collect();
        if e.iter().any(|v| v.is_nan() || *v <= 0.0) {
            break;
        }
        let idx: Vec<usize> = (0..LEVELS).filter(|&a| active[a]).collect();
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
    (h, whittle(&ln_params_of(&h, ln_fc, ln_fg), bins))
}

/// The parameters in logs: ln of each level (−∞ for a level at zero) and ln f_c.
fn ln_params_of(h: &[f64; LEVELS], ln_fc: f64, ln_fg: f64) -> [f64; PARAMS] {
    let mut p = [0.0; PARAMS];
    for (&i, &ha) in LEVEL_PARAM.iter().zip(h) {
        p[i] = if ha > 0.0 { ha.ln() } else { f64::NEG_INFINITY };
    }
    p[4] = ln_fc;
    // Without a Gauss–Markov level its corner is absent too.
    p[6] = if p[5].is_finite() {
        ln_fg
    } else {
        f64::INFINITY
    };
    p
}

/// Covariance of the levels and of ln f_c, ln f_g: the inverse Fisher information of the
/// Whittle likelihood, Σ ∂E/∂a · ∂E/∂b / E², over the levels that are not zero, ln f_c when
/// there is a filter and ln f_g when there is a Gauss–Markov term (so the levels' σ include
/// their trade-off with the corners), × the Hann ENBW.
fn covariance(
    bins: &[Bin],
    h: &[f64; LEVELS],
    ln_fc: f64,
    ln_fg: f64,
) -> ([[f64; LEVELS]; LEVELS], f64, f64) {
    const FC: usize = LEVELS;
    const FG: usize = LEVELS + 1;
    let (fc, fg) = (ln_fc.exp(), ln_fg.exp());
    let gm = ln_fg.is_finite() && h[4] > 0.0;
    // Parameters: the non-zero levels (scaled by their value), ln f_c and ln f_g.
    let mut idx: Vec<usize> = (0..LEVELS)
        .filter(|&a| h[a] > 0.0 && (a < 4 || gm))
        .collect();
    if ln_fc.is_finite() {
        idx.push(FC);
    }
    if gm {
        idx.push(FG);
    }
    let m = idx.len();
    let scale: Vec<f64> = idx
        .iter()
        .map(|&a| if a < LEVELS { h[a] } else { 1.0 })
        .collect();
    let mut info = vec![vec![0.0; m]; m];
    for b in bins {
        let x = b.cols(fc, fg);
        let e: f64 = (0..LEVELS).map(|a| x[a] * h[a]).sum();
        let d: Vec<f64> = idx
            .iter()
            .zip(&scale)
            .map(|(&a, s)| match a {
                FC => b.d_ln_fc(h, fc, fg),
                FG => b.d_ln_fg(h, fc, fg),
                _ => x[a] * s,
            })
            .collect();
        for p in 0..m {
            for q in 0..m {
                info[p][q] += d[p] * d[q] / (e * e);
            }
        }
    }
    let mut cov = [[0.0; LEVELS]; LEVELS];
    let (mut var_fc, mut var_fg) = (0.0, 0.0);
    for q in 0..m {
        let mut e = vec![0.0; m];
        e[q] = 1.0;
        if let Some(col) = crate::numerics::linalg::solve_square(&info, &e) {
            for p in 0..m {
                let v = HANN_ENBW * col[p] * scale[p] * scale[q];
                match (idx[p], idx[q]) {
                    (FC, FC) => var_fc = v,
                    (FG, FG) => var_fg = v,
                    (a, b) if a < LEVELS && b < LEVELS => cov[a][b] = v,
                    _ => {}
                }
            }
        }
    }
    (cov, var_fc, var_fg)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::noise::stream;

    /// The family with log parameters `ln_params` at step `dt_s` and nothing fitted: a truth to
    /// draw a series from.
    fn truth(dt_s: f64, ln_params: [f64; PARAMS]) -> NoiseFamily {
        NoiseFamily {
            dt_s,
            ln_params,
            h_cov: [[0.0; LEVELS]; LEVELS],
            ln_fc_var: 0.0,
            ln_fg_var: 0.0,
            bins: 0,
            record_first_bin: RECORD_FIRST_BIN,
            line_bins: 0,
            neg_loglik: 0.0,
            gm_search: GaussMarkovSearch {
                ln_corner: ln_params[6],
                at_edge: false,
                neg_loglik_gain: 0.0,
            },
        }
    }

    /// A series synthesised from known parameters is fitted back within a few σ, and the σ are
    /// those of the fit (the truth within 4σ for every resolved term).
    #[test]
    fn a_synthesised_record_gives_back_its_parameters() {
        let dt = 60.0;
        let truth = truth(
            dt,
            [
                (1e-2f64).ln(),
                (1e-6f64).ln(),
                (1e-11f64).ln(),
                (1e-22f64).ln(),
                (0.3 * 0.5 / dt).ln(),
                f64::NEG_INFINITY,
                f64::INFINITY,
            ],
        );
        let mut rng = stream(11, 0);
        let x = truth.spec().synthesise(20_000, &mut rng);
        let fit = NoiseFamily::fit(&x, dt).expect("fit");
        let c = fit.components("u");
        // No Gauss–Markov term where there is none.
        assert!(!fit.resolved(5) && !fit.resolved(6), "{:?}", &c[5..]);
        for i in 0..5 {
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

    /// White noise plus a Gauss–Markov process of 2 h correlation time: the term is found, its
    /// level and corner within 4σ of the truth; drawn through the simulator's spec.
    #[test]
    fn a_gauss_markov_process_is_found_with_its_corner() {
        let dt = 60.0;
        let fg = 1.0 / (2.0 * std::f64::consts::PI * 7200.0);
        let truth = truth(
            dt,
            [
                (1e-2f64).ln(),
                f64::NEG_INFINITY,
                f64::NEG_INFINITY,
                f64::NEG_INFINITY,
                f64::INFINITY,
                (0.5f64).ln(),
                fg.ln(),
            ],
        );
        let x = truth.spec().synthesise(30_000, &mut stream(5, 0));
        let fit = NoiseFamily::fit(&x, dt).expect("fit");
        let c = fit.components("u");
        assert!(fit.resolved(5) && fit.resolved(6), "{:?}", fit.gm_search);
        for (i, want) in [(5, 0.5), (6, fg)] {
            let z = (c[i].coefficient - want) / c[i].sigma;
            assert!(
                z.abs() < 4.0 && c[i].sigma < 0.5 * want,
                "{}: fitted {:.3e} ± {:.1e}, truth {want:.3e}",
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
        assert!(!fit.resolved(5) && !fit.resolved(6), "{:?}", fit.gm_search);
        let f = 40.0 / 8192.0;
        let white = fit.ln_params[0].exp();
        assert!(fit.psd(f) < 1.3 * white, "{} vs {white}", fit.psd(f));
    }
}
