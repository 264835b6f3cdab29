//! Fast terms at the rate they live at.
//!
//! The selection works on block means (`import`: a 41-day 1 Hz record becomes 71 s bins), where a
//! lag of a minute is only its low-frequency limit −τ·dT/dt: its coefficient × τ is seen, τ is
//! not. Here the lags faster than a few bins are fitted on the full-rate rows, in the frequency
//! domain: the record is cut into gap-free segments of L rows (first-differenced, so that a
//! random walk's low frequencies do not leak through the window into the band, then detrended
//! and Hann-windowed; the spectra are divided by the difference's |1 − e^{−iω}|²), and the
//! transfer function from each channel to the output is estimated as the averaged cross-spectrum
//! over the channel's spectrum, H_k = S_yx/S_xx. A lag term of the catalogue, c·(L_τ[x] − x),
//! with the static coupling a beside it, is H(f) = a + c·(G_τ(f) − 1), G_τ the discrete
//! first-order lag of [`effects::lag_filter`] (x_k = α x_{k−1} + (1 − α) u_k, α = e^{−Δt/τ}):
//! its roll-over at f ≈ 1/(2πτ) is what fixes τ.
//!
//! Why this is the right likelihood: with y = H·x + n and the noise n independent of the
//! channel, each segment's Fourier coefficients give Y = H·X + N with N complex Gaussian of the
//! output's residual spectrum P(f); summed over K segments, up to a constant,
//! −2 ln L = Σ_k 2K·S_xx|Ĥ_k − H_k|²/P_k. P is the output's spectrum less what the channel explains, so flicker and random walk
//! are weighted as they are at each frequency; the slow terms (tide, drift, the binned model)
//! are below the band or removed by each segment's detrending. Neighbouring bins of a Hann window
//! are correlated: χ² is divided by its equivalent noise bandwidth (1.5 bins). The channel's
//! white reading noise (the floor of S_xx, [`super::rate::reading_floor`]) attenuates Ĥ: it is
//! subtracted from S_xx and the band stops where the channel's spectrum falls below
//! [`FLOOR_FACTOR`] × that floor.
//!
//! The band's points are not independent and white as χ² takes them (neighbouring bins, P
//! estimated from the same segments, what the model leaves in the band): besides χ²'s curvature
//! each parameter's σ is measured on the record by a delete-one-group jackknife over contiguous
//! groups of segments ([`jackknife`]), and the larger is reported ([`Sigma`]).

use super::effects::{self, log_grid, Effect, FastColumn, Param};
use super::import::{block_means_like, ChannelKind, Dataset};
use super::select::Accepted;
use crate::numerics::linalg::least_squares;
use crate::numerics::optimize::golden_section_min as golden;

/// The full-rate stage runs when a bin holds at least this many rows: below that the binned
/// selection's lag grid (from two bins) already reaches the fast terms.
pub const MIN_ROWS_PER_BIN: f64 = 4.0;
/// A segment spans at least this many bins (its lowest frequencies overlap the binned model's
/// resolution, so a lag near the upper end of the grid still shows its roll-over). Measured on
/// the 41-day 1 Hz preset (60 s lag, σ the jackknife's): τ 58.6 ± 0.4 s with segments of 32
/// bins, 59.5 ± 0.4 s with 64 (57.7 and 59.2 s without the first differences).
pub const SEGMENT_BINS: f64 = 64.0;
/// Segments of this many bins when the record holds fewer than [`MIN_SEGMENTS`] of
/// [`SEGMENT_BINS`].
pub const MIN_SEGMENT_BINS: f64 = 32.0;
/// At least this many segments (the residual spectrum P is estimated from them).
pub const MIN_SEGMENTS: usize = 8;
/// The band ends where the channel's spectrum falls below this factor × its white floor
/// (reading noise), so the floor's subtraction changes Ĥ by at most 1/FLOOR_FACTOR.
pub const FLOOR_FACTOR: f64 = 10.0;
/// τ grid: log-spaced from two rows to this many bins.
pub const TAU_MAX_BINS: f64 = 4.0;
/// Points of the τ grid (charged as a 24-point search, like the binned grids).
pub const TAU_GRID: usize = 24;
/// Equivalent noise bandwidth of the Hann window, bins.
pub const HANN_ENBW: f64 = 1.5;
/// The segments are split into this many contiguous groups (or one a segment when there are
/// fewer) for the delete-one-group jackknife of the fit's σ.
pub const JACKKNIFE_GROUPS: usize = 32;
/// Below this many groups the jackknife's σ is too rough to use: the curvature's stands alone.
pub const MIN_JACKKNIFE_GROUPS: usize = 8;

/// A fast term found at the full rate.
#[derive(Debug, Clone, serde::Serialize)]
pub struct FastTerm {
    /// Catalogue name (`thermal_lag`, `ambient_coupling`).
    pub name: &'static str,
    /// The channel it acts through.
    pub channel: String,
    /// Parameters in the catalogue's order, with 1-σ uncertainties.
    pub params: Vec<(String, f64, f64)>,
    /// The static coupling fitted beside it (output per channel unit).
    pub static_coefficient: (f64, f64),
    /// ΔBIC against the static coupling alone (with the charge for the lag and its τ search).
    pub delta_bic: f64,
    /// χ² per degree of freedom of the transfer-function fit with the term (≈ 1 when the
    /// model describes the band).
    pub chi2_per_dof: f64,
    /// Frequency band of the fit, Hz.
    pub band_hz: (f64, f64),
    /// Frequency bins in the band.
    pub bins: usize,
    /// The channel's gain on its rate fitted beside the lag (output·s per channel unit, σ), when
    /// the band shows one: H(f) = a + d·D(f) + c·(G_τ(f) − 1), D = (1 − e^{−iωΔt})/Δt the
    /// transfer function of the catalogue's rate (`RateOfChange`: (u − u_prev)/Δt; at 0.1 Hz on
    /// 1 s rows the central difference's differs from it by 31 % in its real part, which the lag
    /// would otherwise take at a strong rate coupling), kept when it lowers χ²
    /// by more than one column's charge ln n. A lag's low-frequency part is −c·τ·iω, the same
    /// as a rate's, so without this term a rate coupling beside a fast lag pulls τ (measured: a
    /// 60 s lag with 4e-3 V·s/°C on the rate beside it ended at the lower edge of the grid).
    pub rate_coefficient: Option<(f64, f64)>,
    /// How the σ above were obtained: `max(curvature, jackknife (G groups))`, or `curvature
    /// (no jackknife: why)`.
    pub sigma_method: String,
    /// Each parameter's σ from either method (the parameters, then `static_coefficient` and
    /// `rate_coefficient`).
    pub sigmas: Vec<Sigma>,
}

/// One parameter's σ: the χ² curvature's (scaled by χ²/dof when above 1; of τ from the profile
/// in ln τ, of the coefficients from the least-squares covariance), the delete-one-group
/// jackknife's over the record's segments, and the one reported (the larger).
#[derive(Debug, Clone, serde::Serialize)]
pub struct Sigma {
    /// The parameter (`tau_s`, `coefficient`, `lag_s`, `static_coefficient`, `rate_coefficient`).
    pub name: String,
    /// From the curvature of χ².
    pub curvature: f64,
    /// From the jackknife; `None` when it did not run (`FastTerm::sigma_method` says why).
    pub jackknife: Option<f64>,
    /// The larger: the one reported.
    pub used: f64,
    /// Which one that is (`curvature`, `jackknife`).
    pub method: &'static str,
}

impl Sigma {
    fn new(name: &str, curvature: f64, jackknife: Option<f64>) -> Self {
        let (used, method) = match jackknife {
            Some(j) if j > curvature => (j, "jackknife"),
            _ => (curvature, "curvature"),
        };
        Self {
            name: name.to_owned(),
            curvature,
            jackknife,
            used,
            method,
        }
    }
}

/// The full-rate stage's result.
#[derive(Debug, Clone, serde::Serialize)]
pub struct FullRate {
    /// Spacing of the rows, s.
    pub row_spacing_s: f64,
    /// Width of the selection's bins, s.
    pub bin_s: f64,
    /// Rows per segment.
    pub segment_rows: usize,
    /// Segments averaged.
    pub segments: usize,
    /// Rows used.
    pub rows: usize,
    /// Terms found.
    pub terms: Vec<FastTerm>,
    /// Terms tried and refused, with why.
    pub refused: Vec<(String, String)>,
}

/// Cross-spectra of the output with one channel: summed over a group of segments
/// ([`group_spectra`]) or averaged over the segments of several groups ([`pooled`]).
#[derive(Clone)]
struct Spectra {
    /// Channel auto-spectrum.
    sxx: Vec<f64>,
    /// Output auto-spectrum.
    syy: Vec<f64>,
    /// Cross-spectrum Y·conj(X) (re, im).
    syx: Vec<(f64, f64)>,
    segments: usize,
}

impl Spectra {
    fn zeros(m: usize) -> Self {
        Self {
            sxx: vec![0.0; m],
            syy: vec![0.0; m],
            syx: vec![(0.0, 0.0); m],
            segments: 0,
        }
    }
}

/// Gap-free runs of uniformly spaced rows (spacing within 1 % of `dt`), as index ranges.
fn uniform_runs(ds: &Dataset, dt: f64) -> Vec<(usize, usize)> {
    let mut runs = Vec::new();
    let mut start = 0;
    for i in 1..=ds.t_s.len() {
        let brk = i == ds.t_s.len()
            || ds.segment_start[i]
            || ((ds.t_s[i] - ds.t_s[i - 1]) - dt).abs() > 0.01 * dt;
        if brk {
            runs.push((start, i));
            start = i;
        }
    }
    runs
}

/// Removes the least-squares line and applies the Hann window.
fn detrend_window(x: &[f64], hann: &[f64]) -> Vec<f64> {
    let mut d = crate::allan::detrend_linear(x);
    for (v, w) in d.iter_mut().zip(hann) {
        *v *= w;
    }
    d
}

/// The segments' spectra summed in `groups` contiguous groups (segment i of K in group
/// ⌊i·G/K⌋): the record's spectra and those with one group left out are sums of them.
fn group_spectra(y: &[f64], x: &[f64], segs: &[usize], len: usize, groups: usize) -> Vec<Spectra> {
    let hann: Vec<f64> = (0..len)
        .map(|k| (std::f64::consts::PI * k as f64 / len as f64).sin().powi(2))
        .collect();
    let m = len / 2;
    let mut out = vec![Spectra::zeros(m); groups];
    for (i, &a) in segs.iter().enumerate() {
        let s = &mut out[i * groups / segs.len()];
        s.segments += 1;
        let d =
            |v: &[f64]| -> Vec<f64> { v[a - 1..a + len].windows(2).map(|w| w[1] - w[0]).collect() };
        let mut yw = detrend_window(&d(y), &hann);
        let mut xw = detrend_window(&d(x), &hann);
        let fy = crate::numerics::fft::half_spectrum(&mut yw);
        let fx = crate::numerics::fft::half_spectrum(&mut xw);
        for k in 0..m {
            let (yr, yi) = fy[k];
            let (xr, xi) = fx[k];
            s.sxx[k] += xr * xr + xi * xi;
            s.syy[k] += yr * yr + yi * yi;
            s.syx[k].0 += yr * xr + yi * xi;
            s.syx[k].1 += yi * xr - yr * xi;
        }
    }
    // The differences' spectra are the series' times |1 − e^{−iω}|² = 2(1 − cos ω): divided
    // by it, they are the series' own, without the leakage of a random walk's low frequencies
    // through the window into the band.
    for s in &mut out {
        for k in 1..m {
            let g = 2.0 * (1.0 - (2.0 * std::f64::consts::PI * k as f64 / len as f64).cos());
            s.sxx[k] /= g;
            s.syy[k] /= g;
            s.syx[k].0 /= g;
            s.syx[k].1 /= g;
        }
    }
    out
}

/// The spectra averaged over the segments of all groups but `skip`.
fn pooled(groups: &[Spectra], skip: Option<usize>) -> Spectra {
    let m = groups.first().map_or(0, |g| g.sxx.len());
    let mut s = Spectra::zeros(m);
    for (_, g) in groups.iter().enumerate().filter(|(i, _)| Some(*i) != skip) {
        s.segments += g.segments;
        for k in 0..m {
            s.sxx[k] += g.sxx[k];
            s.syy[k] += g.syy[k];
            s.syx[k].0 += g.syx[k].0;
            s.syx[k].1 += g.syx[k].1;
        }
    }
    let kf = s.segments.max(1) as f64;
    for k in 0..m {
        s.sxx[k] /= kf;
        s.syy[k] /= kf;
        s.syx[k].0 /= kf;
        s.syx[k].1 /= kf;
    }
    s
}

/// The discrete first-order lag's transfer function at bin k of an L-point DFT: (1 − α) /
/// (1 − α e^{−iω}), ω = 2πk/L, α = e^{−Δt/τ}.
fn lag_response(k: usize, len: usize, dt: f64, tau: f64) -> (f64, f64) {
    let a = (-dt / tau).exp();
    let w = 2.0 * std::f64::consts::PI * k as f64 / len as f64;
    let (dr, di) = (1.0 - a * w.cos(), a * w.sin());
    let d2 = dr * dr + di * di;
    ((1.0 - a) * dr / d2, -(1.0 - a) * di / d2)
}

/// The band's estimated transfer function and weights.
struct Band {
    k: Vec<usize>,
    h: Vec<(f64, f64)>,
    w: Vec<f64>,
}

/// The band of `s` (from bin 2 up to where the channel's spectrum falls to [`FLOOR_FACTOR`] ×
/// its floor), or its bins `only` (a jackknife replicate is fitted on the record's band).
fn band(s: &Spectra, only: Option<&[usize]>) -> Option<Band> {
    let m = s.sxx.len();
    // The channel's white reading noise under its signal (`rate::reading_floor`: the white
    // level of a power law + white fit to the upper three quarters, never above their lowest
    // band mean).
    let floor = super::rate::reading_floor(&s.sxx);
    if !(floor.is_finite() && floor >= 0.0) {
        return None;
    }
    let kf = s.segments as f64;
    let mut b = Band {
        k: Vec::new(),
        h: Vec::new(),
        w: Vec::new(),
    };
    // Bin 1 carries the detrending's leakage; the band starts at bin 2.
    let bins: Box<dyn Iterator<Item = usize>> = match only {
        Some(ks) => Box::new(ks.iter().copied()),
        None => Box::new(2..m),
    };
    for k in bins {
        if only.is_none() && s.sxx[k] <= FLOOR_FACTOR * floor {
            break;
        }
        let sig = s.sxx[k] - floor;
        let (cr, ci) = s.syx[k];
        let p = (s.syy[k] - (cr * cr + ci * ci) / s.sxx[k]) * kf / (kf - 1.0);
        if !(p > 0.0 && sig > 0.0) {
            continue;
        }
        b.k.push(k);
        b.h.push((cr / sig, ci / sig));
        b.w.push(2.0 * kf * sig * sig / (s.sxx[k] * p * HANN_ENBW));
    }
    (b.k.len() >= 8).then_some(b)
}

/// The lag's column of H on the band: G_τ − 1.
fn lag_shape(b: &Band, len: usize, dt: f64, tau: f64) -> Vec<(f64, f64)> {
    b.k.iter()
        .map(|&k| {
            let (r, i) = lag_response(k, len, dt, tau);
            (r - 1.0, i)
        })
        .collect()
}

/// The channel's gain on its rate, D = (1 − e^{−iωΔt})/Δt, on the band.
fn rate_shape(b: &Band, len: usize, dt: f64) -> Vec<(f64, f64)> {
    b.k.iter()
        .map(|&k| {
            let w = 2.0 * std::f64::consts::PI * k as f64 / len as f64;
            ((1.0 - w.cos()) / dt, w.sin() / dt)
        })
        .collect()
}

/// H's columns beside the searched lag, in the order of its coefficients: the static coupling,
/// the gain on the rate when `rate`, the lags at the τ `held` (the binned selection's).
fn columns(b: &Band, len: usize, dt: f64, rate: bool, held: &[f64]) -> Vec<Vec<(f64, f64)>> {
    let mut c = vec![vec![(1.0, 0.0); b.k.len()]];
    if rate {
        c.push(rate_shape(b, len, dt));
    }
    c.extend(held.iter().map(|&t| lag_shape(b, len, dt, t)));
    c
}

/// `g` on the band as the weighted fit's real rows: (re, im) of each bin times √w.
fn stacked(b: &Band, g: &[(f64, f64)]) -> Vec<f64> {
    g.iter()
        .zip(&b.w)
        .flat_map(|(&(r, i), &w)| [r * w.sqrt(), i * w.sqrt()])
        .collect()
}

/// χ² of the band with the columns `cols` and the lag beside them, as a function of τ: the
/// weighted columns' orthonormal basis and the transfer function's residual on it are made
/// once, each τ projects only the lag's column (χ² = |r|² − (g⊥·r)²/|g⊥|², the least squares of
/// [`fit`] without refactoring the fixed columns at every point of the τ search).
struct Profile<'a> {
    b: &'a Band,
    len: usize,
    dt: f64,
    basis: crate::numerics::linalg::OrthonormalBasis,
    resid: Vec<f64>,
    rss: f64,
}

impl<'a> Profile<'a> {
    fn new(b: &'a Band, cols: &[Vec<(f64, f64)>], len: usize, dt: f64) -> Self {
        let cs: Vec<Vec<f64>> = cols.iter().map(|c| stacked(b, c)).collect();
        let basis = crate::numerics::linalg::OrthonormalBasis::new(&cs);
        let resid = basis.residual(&stacked(b, &b.h));
        let rss = resid.iter().map(|v| v * v).sum();
        Self {
            b,
            len,
            dt,
            basis,
            resid,
            rss,
        }
    }

    fn chi(&self, tau: f64) -> f64 {
        let mut g = stacked(self.b, &lag_shape(self.b, self.len, self.dt, tau));
        crate::numerics::linalg::project_out(&self.basis.q, &mut g);
        let gg: f64 = g.iter().map(|v| v * v).sum();
        let gr: f64 = g.iter().zip(&self.resid).map(|(a, b)| a * b).sum();
        if gg > 0.0 && gg.is_finite() {
            self.rss - gr * gr / gg
        } else if gg == 0.0 {
            self.rss
        } else {
            f64::INFINITY
        }
    }
}

/// χ² on the τ grid and its best index.
fn chi_grid(p: &Profile, taus: &[f64]) -> (Vec<f64>, usize) {
    let grid: Vec<f64> = taus.iter().map(|&t| p.chi(t)).collect();
    let ib = (0..grid.len())
        .min_by(|&i, &j| grid[i].total_cmp(&grid[j]))
        .unwrap_or(0);
    (grid, ib)
}

/// ln τ of least χ² between the grid's neighbours of index `ib` (golden section).
fn refine(p: &Profile, taus: &[f64], ib: usize) -> f64 {
    let (lo, hi) = (ib.saturating_sub(1), (ib + 1).min(taus.len() - 1));
    golden(|l| p.chi(l.exp()), taus[lo].ln(), taus[hi].ln(), 40)
}

/// Weighted fit of H_k = Σ β_j g_j(k) (β real) to the band: (χ², β, covariance).
fn fit(b: &Band, shapes: &[Vec<(f64, f64)>]) -> Option<(f64, Vec<f64>, Vec<Vec<f64>>)> {
    let mut rows = Vec::with_capacity(2 * b.k.len());
    let mut rhs = Vec::with_capacity(2 * b.k.len());
    for (i, &w) in b.w.iter().enumerate() {
        let sw = w.sqrt();
        rows.push(shapes.iter().map(|g| g[i].0 * sw).collect::<Vec<f64>>());
        rhs.push(b.h[i].0 * sw);
        rows.push(shapes.iter().map(|g| g[i].1 * sw).collect::<Vec<f64>>());
        rhs.push(b.h[i].1 * sw);
    }
    let ls = least_squares(&rows, &rhs).ok()?;
    Some((ls.rss, ls.coeffs.clone(), ls.unscaled_covariance()))
}

/// The delete-one-group jackknife of the fit: with each of the G groups of segments left out
/// in turn, the spectra are re-averaged, the transfer function re-estimated on the record's
/// band `ks` (the floor re-measured) and the fit repeated with the same columns (the rate's
/// gain in or out as the record decided, τ searched on the grid and refined);
/// σ² = (G − 1)/G · Σ(θ_g − θ̄)² for θ = (τ, the coefficients in the fit's order). The band's
/// points are neither independent nor white (neighbouring bins, the residual spectrum's
/// estimate, what the model leaves in the band), so χ²'s curvature can understate σ; the groups
/// are contiguous in time and hold what the record's own variation does to the estimate.
/// `Err` says why it did not run.
fn jackknife(
    groups: &[Spectra],
    ks: &[usize],
    len: usize,
    dt: f64,
    rate: bool,
    held: &[f64],
    taus: &[f64],
) -> Result<Vec<f64>, String> {
    let g = groups.len();
    if g < MIN_JACKKNIFE_GROUPS {
        return Err(format!(
            "{g} segments, it needs at least {MIN_JACKKNIFE_GROUPS}"
        ));
    }
    let idx: Vec<usize> = (0..g).collect();
    let reps = crate::numerics::parallel::par_map(&idx, |&i| {
        let s = pooled(groups, Some(i));
        let b = band(&s, Some(ks))?;
        let cols = columns(&b, len, dt, rate, held);
        let p = Profile::new(&b, &cols, len, dt);
        let tau = refine(&p, taus, chi_grid(&p, taus).1).exp();
        let mut sh = cols;
        sh.push(lag_shape(&b, len, dt, tau));
        let (_, beta, _) = fit(&b, &sh)?;
        Some(std::iter::once(tau).chain(beta).collect::<Vec<f64>>())
    });
    let reps: Vec<Vec<f64>> = reps
        .into_iter()
        .collect::<Option<_>>()
        .ok_or_else(|| "a group left out leaves too few bins in the band".to_owned())?;
    let gf = g as f64;
    Ok((0..reps[0].len())
        .map(|j| {
            let mean = reps.iter().map(|r| r[j]).sum::<f64>() / gf;
            let ss = reps.iter().map(|r| (r[j] - mean).powi(2)).sum::<f64>();
            ((gf - 1.0) / gf * ss).sqrt()
        })
        .collect())
}

/// Why the stage could not run on a full-rate dataset (printed as `full rate: not run (…)` and
/// as the JSON `{"not_run": …}`).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FullRateError {
    /// Fewer than two rows: no row spacing.
    #[error("no rows")]
    NoRows,
    /// Too few gap-free segments of the length the bins call for to average the spectra over.
    #[error(
        "fewer than {min} gap-free segments of {segment_rows} rows ({segment_s:.0} s): {found}",
        min = MIN_SEGMENTS
    )]
    TooFewSegments {
        /// Rows per segment.
        segment_rows: usize,
        /// The segment's length, s.
        segment_s: f64,
        /// Gap-free segments found.
        found: usize,
    },
}

/// Runs the stage on the full-rate dataset `full` for the selection on `binned` (whose accepted
/// lags on a channel are kept in that channel's model at their τ). `Err` says why it did not run.
pub fn analyse(
    full: &Dataset,
    binned: &Dataset,
    accepted: &[Accepted],
) -> Result<FullRate, FullRateError> {
    let mut dts: Vec<f64> = full.t_s.windows(2).map(|w| w[1] - w[0]).collect();
    if dts.is_empty() {
        return Err(FullRateError::NoRows);
    }
    let mid = dts.len() / 2;
    let dt = *dts.select_nth_unstable_by(mid, f64::total_cmp).1;
    let bin = binned.dt_s;
    // Segments of SEGMENT_BINS bins, or of MIN_SEGMENT_BINS when the record holds too few of
    // those. Each starts one row into its run: its first difference takes the row before it.
    let cut = |bins: f64| {
        let len = ((bins * bin / dt).ceil() as usize).next_power_of_two();
        let mut segs = Vec::new();
        for (a, b) in uniform_runs(full, dt) {
            let mut s = a + 1;
            while s + len <= b {
                segs.push(s);
                s += len;
            }
        }
        (len, segs)
    };
    let (mut len, mut segs) = cut(SEGMENT_BINS);
    if segs.len() < MIN_SEGMENTS {
        (len, segs) = cut(MIN_SEGMENT_BINS);
    }
    if segs.len() < MIN_SEGMENTS {
        return Err(FullRateError::TooFewSegments {
            segment_rows: len,
            segment_s: len as f64 * dt,
            found: segs.len(),
        });
    }
    let mut out = FullRate {
        row_spacing_s: dt,
        bin_s: bin,
        segment_rows: len,
        segments: segs.len(),
        rows: segs.len() * len,
        terms: Vec::new(),
        refused: Vec::new(),
    };
    let rows_used = (segs.len() * len) as f64;
    let taus = log_grid(2.0 * dt, TAU_MAX_BINS * bin, TAU_GRID);
    let charge = rows_used.ln() + rows_used.ln().max(2.0 * (TAU_GRID as f64).ln());
    for ch in &full.channels {
        let name = match ch.kind {
            ChannelKind::Temperature => Effect::ThermalLag.name(),
            ChannelKind::Other => "ambient_coupling",
            _ => continue,
        };
        let n_groups = JACKKNIFE_GROUPS.min(segs.len());
        let groups = group_spectra(&full.y, &ch.values, &segs, len, n_groups);
        let s = pooled(&groups, None);
        let Some(b) = band(&s, None) else {
            out.refused.push((
                format!("{name} ({})", ch.name),
                "the channel's spectrum is at its reading-noise floor over the whole band".into(),
            ));
            continue;
        };
        // The lags the binned selection accepted on this channel stay in H at their τ.
        let held: Vec<f64> = accepted
            .iter()
            .filter(|a| match &a.effect {
                Effect::ThermalLag => ch.kind == ChannelKind::Temperature,
                Effect::AmbientCoupling(c) => *c == ch.name,
                _ => false,
            })
            .map(|a| a.theta.value)
            .filter(|t| t.is_finite() && *t > 0.0)
            .collect();
        // The channel's gain on its rate beside the lag: searched with it, kept when the band
        // shows it (χ² lower by more than ln n at the lag's τ), else the search is the lag's alone.
        let rate_in = {
            let cols = columns(&b, len, dt, true, &held);
            let p = Profile::new(&b, &cols, len, dt);
            let (grid, ib) = chi_grid(&p, &taus);
            ib > 0 && ib + 1 < grid.len() && {
                let t = refine(&p, &taus, ib).exp();
                let without = Profile::new(&b, &columns(&b, len, dt, false, &held), len, dt);
                without.chi(t) - p.chi(t) > rows_used.ln()
            }
        };
        let base = columns(&b, len, dt, rate_in, &held);
        let Some((chi0, _, _)) = fit(&b, &base) else {
            continue;
        };
        let profile = Profile::new(&b, &base, len, dt);
        let chi_at = |tau: f64| profile.chi(tau);
        let (grid, ib) = chi_grid(&profile, &taus);
        let delta_bic = grid[ib] - chi0 + charge;
        let label = format!("{name} ({})", ch.name);
        if delta_bic >= 0.0 {
            out.refused.push((
                label,
                format!("ΔBIC {delta_bic:.1} ≥ 0 (no lag shows in the band)"),
            ));
            continue;
        }
        if ib == 0 || ib + 1 == grid.len() {
            out.refused.push((
                label,
                format!(
                    "τ at the {} edge of its grid ({:.1} s; grid {:.1}–{:.0} s): {}",
                    if ib == 0 { "lower" } else { "upper" },
                    taus[ib],
                    taus[0],
                    taus[taus.len() - 1],
                    if ib == 0 {
                        "faster than two rows"
                    } else {
                        "slower than the full-rate band: the binned selection's range"
                    }
                ),
            ));
            continue;
        }
        let lt = refine(&profile, &taus, ib);
        let tau = lt.exp();
        let Some((chi, beta, cov)) = fit(&b, &{
            let mut sh = base.clone();
            sh.push(lag_shape(&b, len, dt, tau));
            sh
        }) else {
            continue;
        };
        let dof = (2 * b.k.len()).saturating_sub(beta.len() + 1).max(1) as f64;
        // Scale the uncertainties by the fit's χ²/dof when the model leaves more than noise.
        let scale = (chi / dof).max(1.0);
        // σ_τ from the curvature of χ² in ln τ: Δχ² = 1 at ±σ.
        let h = 0.05;
        let curv = (chi_at((lt + h).exp()) - 2.0 * chi + chi_at((lt - h).exp())) / (h * h);
        let curv_tau = if curv > 0.0 {
            tau * (2.0 * scale / curv).sqrt()
        } else {
            f64::INFINITY
        };
        // The curvature's σ: of τ, then of each coefficient in the fit's order.
        let curvature: Vec<f64> = std::iter::once(curv_tau)
            .chain((0..beta.len()).map(|j| (cov[j][j] * scale).sqrt()))
            .collect();
        let jk = jackknife(&groups, &b.k, len, dt, rate_in, &held, &taus);
        let last = beta.len() - 1;
        // Each parameter: (name, value, index into `curvature` and the jackknife's σ).
        let mut named = if name == "thermal_lag" {
            vec![("tau_s", tau, 0), ("coefficient", beta[last], last + 1)]
        } else {
            vec![("coefficient", beta[last], last + 1), ("lag_s", tau, 0)]
        };
        named.push(("static_coefficient", beta[0], 1));
        if rate_in {
            named.push(("rate_coefficient", beta[1], 2));
        }
        let sigmas: Vec<Sigma> = named
            .iter()
            .map(|&(n, _, j)| Sigma::new(n, curvature[j], jk.as_ref().ok().map(|s| s[j])))
            .collect();
        let sigma_method = match &jk {
            Ok(_) => format!("max(curvature, jackknife ({n_groups} groups))"),
            Err(why) => format!("curvature (no jackknife: {why})"),
        };
        let sd = |n: &str| {
            sigmas
                .iter()
                .find(|s| s.name == n)
                .map_or(f64::NAN, |s| s.used)
        };
        let sigma_tau = sd(if name == "thermal_lag" {
            "tau_s"
        } else {
            "lag_s"
        });
        if sigma_tau.is_nan() || sigma_tau >= tau {
            out.refused.push((
                label,
                format!(
                    "τ = {tau:.1} s is not determined by the band (σ {sigma_tau:.1} s, {}): the \
                     channel has too little power near 1/(2πτ)",
                    sigmas
                        .iter()
                        .find(|s| s.name.ends_with("_s"))
                        .map_or("curvature", |s| s.method)
                ),
            ));
            continue;
        }
        let params = named[..2]
            .iter()
            .map(|&(n, v, _)| (n.to_owned(), v, sd(n)))
            .collect();
        out.terms.push(FastTerm {
            name,
            channel: ch.name.clone(),
            params,
            static_coefficient: (beta[0], sd("static_coefficient")),
            delta_bic: chi - chi0 + charge,
            chi2_per_dof: chi / dof,
            band_hz: (
                b.k[0] as f64 / (len as f64 * dt),
                b.k[b.k.len() - 1] as f64 / (len as f64 * dt),
            ),
            bins: b.k.len(),
            rate_coefficient: rate_in.then(|| (beta[1], sd("rate_coefficient"))),
            sigma_method,
            sigmas,
        });
    }
    Ok(out)
}

/// A fast term carried into the binned model: its column on the bins, its τ held at the
/// full-rate value, its evidence from the full rate.
#[derive(Debug, Clone)]
pub struct InModel {
    /// The column, effect and τ (`Context::full_rate`).
    pub column: FastColumn,
    /// σ of τ from the full-rate fit, s.
    pub sigma_tau_s: f64,
    /// The term's parameters as the full-rate fit gave them (`params_at_acceptance`).
    pub params: Vec<(String, Param)>,
    /// Its ΔBIC at the full rate.
    pub delta_bic: f64,
    /// The full rate found a gain on the channel's rate beside the lag
    /// ([`FastTerm::rate_coefficient`]); it is in the column at the full rate's ratio.
    pub keeps_rate: bool,
}

/// The fast terms as columns of the binned model (`binned` from the same log as `full`): the
/// catalogue's column of each, computed on the full-rate rows at the found τ and averaged into
/// the bins. A term whose bins cannot be rebuilt is returned in the second list with why (it
/// then stays a full-rate finding only, and the report says so).
pub fn binned_columns(
    full: &Dataset,
    binned: &Dataset,
    f: &FullRate,
) -> (Vec<InModel>, Vec<(String, String)>) {
    let (mut out, mut left) = (Vec::new(), Vec::new());
    for t in &f.terms {
        let Some(ch) = full.channels.iter().find(|c| c.name == t.channel) else {
            continue;
        };
        let key = if t.name == "thermal_lag" {
            "tau_s"
        } else {
            "lag_s"
        };
        let Some(tau) = param(t, key) else { continue };
        let lagged = effects::lag_filter(&ch.values, &full.t_s, &full.segment_start, tau.value);
        let (effect, col) = if ch.kind == ChannelKind::Temperature {
            let mut e: Vec<f64> = lagged.iter().zip(&ch.values).map(|(l, x)| l - x).collect();
            // The channel's gain on its rate found beside the lag joins the lag's column at the
            // ratio the full rate found: on the bins the two are the same column (a lag of
            // τ ≪ a bin is −c·τ·dc/dt there), so their split is the full rate's, and the
            // coefficient fitted on the bins scales both.
            let c = param(t, "coefficient").map_or(f64::NAN, |p| p.value);
            if let Some((d, _)) = t.rate_coefficient.filter(|_| c.is_finite() && c != 0.0) {
                let r = effects::catalogue_rate(&ch.values, &full.t_s, &full.segment_start);
                e.iter_mut().zip(&r).for_each(|(v, r)| *v += d / c * r);
            }
            (Effect::ThermalLag, block_means_like(full, binned, &e))
        } else {
            let c = block_means_like(full, binned, &lagged).map(|mut c| {
                let m = c.iter().sum::<f64>() / c.len().max(1) as f64;
                c.iter_mut().for_each(|v| *v -= m);
                c
            });
            (Effect::AmbientCoupling(ch.name.clone()), c)
        };
        let label = format!("{} ({})", t.name, t.channel);
        match col {
            Some(column) => out.push(InModel {
                column: FastColumn {
                    effect,
                    tau_s: tau.value,
                    column,
                },
                sigma_tau_s: tau.sigma,
                params: t
                    .params
                    .iter()
                    .map(|(k, v, s)| {
                        (
                            k.clone(),
                            Param {
                                value: *v,
                                sigma: *s,
                            },
                        )
                    })
                    .collect(),
                delta_bic: t.delta_bic,
                keeps_rate: t.rate_coefficient.is_some(),
            }),
            None => left.push((
                label,
                "its column could not be averaged into the selection's bins (the bins rebuilt                  from the rows differ): reported at the full rate only, not in the final model"
                    .into(),
            )),
        }
    }
    (out, left)
}

/// The named parameters of a fast term as the report prints them.
pub fn param(t: &FastTerm, key: &str) -> Option<Param> {
    t.params.iter().find(|p| p.0 == key).map(|p| Param {
        value: p.1,
        sigma: p.2,
    })
}

/// The text report's section (empty when the stage did not apply).
pub fn text_of(r: &Option<Result<FullRate, FullRateError>>, unit: &str) -> String {
    use std::fmt::Write as _;
    let mut o = String::new();
    match r {
        None => {}
        Some(Err(why)) => {
            let _ = writeln!(o, "full rate: not run ({why})");
        }
        Some(Ok(f)) => {
            let _ = writeln!(
                o,
                "full rate: lags faster than the {:.1} s bins, fitted on {} rows at {} s in the \
                 frequency domain ({} segments of {:.0} s)",
                f.bin_s,
                f.rows,
                f.row_spacing_s,
                f.segments,
                f.segment_rows as f64 * f.row_spacing_s
            );
            if f.terms.is_empty() {
                let _ = writeln!(o, "  none");
            }
            for t in &f.terms {
                let FastTerm {
                    name,
                    channel,
                    static_coefficient: (a, a_sd),
                    delta_bic,
                    chi2_per_dof,
                    bins,
                    band_hz: (f_lo, f_hi),
                    ..
                } = t;
                let params = t
                    .params
                    .iter()
                    .map(|(k, v, s)| format!("{k} = {v:.5e} ± {s:.2e}"));
                let params = params.collect::<Vec<_>>().join(", ");
                let _ = writeln!(
                    o,
                    "  {name} ({channel}): {params}\n     static coupling {a:.4e} ± {a_sd:.2e} \
                     {unit}/channel unit; ΔBIC {delta_bic:.1}; χ²/dof {chi2_per_dof:.2} over \
                     {bins} bins, {f_lo:.3e}–{f_hi:.3e} Hz"
                );
                if let Some((d, sd)) = t.rate_coefficient {
                    let _ = writeln!(
                        o,
                        "     beside it a gain on the channel's rate {d:.4e} ± {sd:.2e} \
                         {unit}·s/channel unit"
                    );
                }
                let each = t.sigmas.iter().map(|s| match s.jackknife {
                    Some(j) => format!(
                        "{} {} (curvature {:.2e}, jackknife {j:.2e})",
                        s.name, s.method, s.curvature
                    ),
                    None => format!("{} curvature", s.name),
                });
                let _ = writeln!(
                    o,
                    "     σ: {}: {}",
                    t.sigma_method,
                    each.collect::<Vec<_>>().join("; ")
                );
            }
            for (n, why) in &f.refused {
                let _ = writeln!(o, "  refused: {n}: {why}");
            }
        }
    }
    o
}

/// The JSON `full_rate` value: null when the stage did not apply, `{"not_run": why}` when it
/// could not run.
pub fn json_of(r: &Option<Result<FullRate, FullRateError>>) -> serde_json::Value {
    match r {
        None => serde_json::Value::Null,
        Some(Err(why)) => serde_json::json!({ "not_run": why.to_string() }),
        Some(Ok(f)) => serde_json::json!({
            "row_spacing_s": f.row_spacing_s,
            "bin_s": f.bin_s,
            "segment_rows": f.segment_rows,
            "segments": f.segments,
            "rows": f.rows,
            "terms": f.terms.iter().map(|t| serde_json::json!({
                "name": t.name,
                "channel": t.channel,
                "parameters": t.params.iter().map(|p| (p.0.clone(), serde_json::json!(p.1))).collect::<serde_json::Map<_, _>>(),
                "uncertainties": t.params.iter().map(|p| (p.0.clone(), serde_json::json!(p.2))).collect::<serde_json::Map<_, _>>(),
                "static_coefficient": t.static_coefficient.0,
                "static_coefficient_sigma": t.static_coefficient.1,
                "delta_bic": t.delta_bic,
                "chi2_per_dof": t.chi2_per_dof,
                "band_hz": [t.band_hz.0, t.band_hz.1],
                "bins": t.bins,
                "rate_coefficient": t.rate_coefficient.map(|r| r.0),
                "rate_coefficient_sigma": t.rate_coefficient.map(|r| r.1),
                "sigma_method": t.sigma_method,
                "sigma_used": t.sigmas.iter().map(|s| (s.name.clone(), serde_json::json!(s.method))).collect::<serde_json::Map<_, _>>(),
                "uncertainties_curvature": t.sigmas.iter().map(|s| (s.name.clone(), serde_json::json!(s.curvature))).collect::<serde_json::Map<_, _>>(),
                "uncertainties_jackknife": t.sigmas.iter().map(|s| (s.name.clone(), serde_json::json!(s.jackknife))).collect::<serde_json::Map<_, _>>(),
            })).collect::<Vec<_>>(),
            "refused": f.refused.iter().map(|(n, w)| serde_json::json!({"name": n, "why": w})).collect::<Vec<_>>(),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The discrete lag's response is the lag filter's: a unit sinusoid through
    /// `effects::lag_filter` comes out with the gain and phase `lag_response` says.
    #[test]
    fn lag_response_is_the_lag_filters_transfer_function() {
        let (len, dt, tau, k) = (256usize, 1.0, 20.0, 5usize);
        let w = 2.0 * std::f64::consts::PI * k as f64 / len as f64;
        let n = 20 * len;
        let t: Vec<f64> = (0..n).map(|i| i as f64 * dt).collect();
        let u: Vec<f64> = (0..n).map(|i| (w * i as f64).cos()).collect();
        let seg: Vec<bool> = (0..n).map(|i| i == 0).collect();
        let x = super::super::effects::lag_filter(&u, &t, &seg, tau);
        let (hr, hi) = lag_response(k, len, dt, tau);
        // After the transient: x_i = Re(H e^{iωi}) = hr cos − hi sin.
        for (i, xi) in x.iter().enumerate().skip(n - 50) {
            let want = hr * (w * i as f64).cos() - hi * (w * i as f64).sin();
            assert!((xi - want).abs() < 1e-9, "{xi} vs {want}");
        }
    }

    /// The reasons the stage did not run read as they always have in the text and the JSON.
    #[test]
    fn why_the_stage_did_not_run_reads_as_before() {
        assert_eq!(FullRateError::NoRows.to_string(), "no rows");
        let few = FullRateError::TooFewSegments {
            segment_rows: 512,
            segment_s: 512.4,
            found: 3,
        };
        assert_eq!(
            few.to_string(),
            "fewer than 8 gap-free segments of 512 rows (512 s): 3"
        );
        assert_eq!(
            json_of(&Some(Err(few))),
            serde_json::json!({ "not_run": "fewer than 8 gap-free segments of 512 rows (512 s): 3" })
        );
        assert_eq!(
            text_of(&Some(Err(FullRateError::NoRows)), "g"),
            "full rate: not run (no rows)\n"
        );
    }

    /// Each parameter reports the larger of its two σ and names it; without the jackknife the
    /// curvature's stands, and the text and the JSON say which was used and why.
    #[test]
    fn the_larger_sigma_is_reported_and_named_and_a_missing_jackknife_is_announced() {
        let s = Sigma::new("tau_s", 0.3, Some(0.4));
        assert_eq!((s.used, s.method), (0.4, "jackknife"));
        let s = Sigma::new("static_coefficient", 2e-7, Some(1e-7));
        assert_eq!((s.used, s.method), (2e-7, "curvature"));
        let s = Sigma::new("tau_s", 0.3, None);
        assert_eq!((s.used, s.method), (0.3, "curvature"));
        // Fewer groups than the jackknife needs: it does not run, and says why.
        let few = vec![Spectra::zeros(16); MIN_JACKKNIFE_GROUPS - 1];
        let why = jackknife(&few, &[2, 3], 32, 1.0, false, &[], &[2.0, 4.0]).unwrap_err();
        assert_eq!(why, "7 segments, it needs at least 8");
        let term = FastTerm {
            name: "thermal_lag",
            channel: "temperature_c".into(),
            params: vec![
                ("tau_s".into(), 60.0, 0.3),
                ("coefficient".into(), 1e-4, 1e-6),
            ],
            static_coefficient: (1e-4, 1e-6),
            delta_bic: -100.0,
            chi2_per_dof: 1.0,
            band_hz: (1e-3, 0.5),
            bins: 100,
            rate_coefficient: None,
            sigma_method: format!("curvature (no jackknife: {why})"),
            sigmas: vec![s],
        };
        let f = FullRate {
            row_spacing_s: 1.0,
            bin_s: 70.0,
            segment_rows: 4096,
            segments: 7,
            rows: 7 * 4096,
            terms: vec![term],
            refused: Vec::new(),
        };
        let r = Some(Ok(f));
        assert!(text_of(&r, "v").contains(
            "σ: curvature (no jackknife: 7 segments, it needs at least 8): tau_s curvature"
        ));
        let j = json_of(&r);
        assert_eq!(
            j["terms"][0]["sigma_method"],
            "curvature (no jackknife: 7 segments, it needs at least 8)"
        );
        assert_eq!(j["terms"][0]["sigma_used"]["tau_s"], "curvature");
        assert!(j["terms"][0]["uncertainties_jackknife"]["tau_s"].is_null());
    }
}
