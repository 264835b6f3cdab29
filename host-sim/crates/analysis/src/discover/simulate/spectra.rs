//! The three views of a residual the comparison uses — Allan deviation at octave τ, Welch power
//! spectral density in log-spaced bands, and magnitude-squared coherence with each measured
//! channel in the same bands — computed the same way for the measured record and for every
//! ensemble member, so that an envelope of the members is a fair yardstick for the record.
//!
//! Records have gaps and (after binning) slightly irregular time stamps, so each series is first
//! laid on a regular grid of the record's spacing ([`RegularGrid`]): samples falling in one cell
//! are averaged, holes of at most [`MAX_FILLED_CELLS`] cells inside a segment are filled
//! linearly (binning leaves isolated empty cells), longer holes stay gaps (NaN). The ADEV skips
//! the gaps (the project's Allan code, `allan.rs`); the Welch segments lie wholly inside
//! gap-free stretches.

use crate::discover::import::Dataset;
use crate::numerics::fft;

/// Interior holes up to this many cells are filled by linear interpolation.
pub const MAX_FILLED_CELLS: usize = 3;
/// Welch segment length: the largest power of two ≤ the longest gap-free stretch / 2, at most
/// this many cells, at least [`MIN_SEGMENT`].
pub const MAX_SEGMENT: usize = 8192;
/// Shortest Welch segment.
pub const MIN_SEGMENT: usize = 64;
/// Log-spaced bands per decade of frequency (PSD and coherence).
pub const BANDS_PER_DECADE: f64 = 8.0;
/// ADEV points beyond span / this are left out (too few averages to compare).
pub const ADEV_MAX_TAU_FRACTION: f64 = 4.0;

/// Where each sample of a record falls on a regular grid.
#[derive(Debug, Clone, PartialEq)]
pub struct RegularGrid {
    /// Cell width, s.
    pub dt_s: f64,
    /// Cell of each sample.
    pub cell: Vec<usize>,
    /// Number of cells.
    pub len: usize,
    /// Cells that are filled from neighbours when a series is placed (short interior holes).
    fill: Vec<bool>,
}

impl RegularGrid {
    /// The grid of a dataset: its nominal spacing, origin at its first sample.
    pub fn new(ds: &Dataset) -> Self {
        let dt = if ds.dt_s.is_finite() && ds.dt_s > 0.0 {
            ds.dt_s
        } else {
            1.0
        };
        let t0 = ds.t_s.first().copied().unwrap_or(0.0);
        let mut cell = Vec::with_capacity(ds.len());
        let mut prev: Option<usize> = None;
        for &t in &ds.t_s {
            let mut k = ((t - t0) / dt).round().max(0.0) as usize;
            if let Some(p) = prev {
                // Time stamps are strictly increasing; two in one cell are averaged.
                k = k.max(p);
            }
            cell.push(k);
            prev = Some(k);
        }
        let len = prev.map_or(0, |p| p + 1);
        let mut occupied = vec![false; len];
        for &k in &cell {
            occupied[k] = true;
        }
        // Holes inside a segment (not across a segment start) of ≤ MAX_FILLED_CELLS are filled.
        let mut fill = vec![false; len];
        for i in 1..ds.len() {
            let (a, b) = (cell[i - 1], cell[i]);
            if !ds.segment_start[i] && b > a + 1 && b - a - 1 <= MAX_FILLED_CELLS {
                for f in fill.iter_mut().take(b).skip(a + 1) {
                    *f = true;
                }
            }
        }
        RegularGrid {
            dt_s: dt,
            cell,
            len,
            fill,
        }
    }

    /// `x` (one value per sample) on the grid: cell means, short holes filled, gaps NaN.
    pub fn place(&self, x: &[f64]) -> Vec<f64> {
        let mut sum = vec![0.0; self.len];
        let mut n = vec![0u32; self.len];
        for (&k, &v) in self.cell.iter().zip(x) {
            sum[k] += v;
            n[k] += 1;
        }
        let mut out: Vec<f64> = sum
            .iter()
            .zip(&n)
            .map(|(s, &c)| if c > 0 { s / c as f64 } else { f64::NAN })
            .collect();
        let mut i = 0;
        while i < self.len {
            if self.fill[i] {
                let a = i - 1; // a filled cell always follows an occupied one
                let mut b = i;
                while b < self.len && self.fill[b] {
                    b += 1;
                }
                if b < self.len {
                    let (ya, yb) = (out[a], out[b]);
                    for (j, o) in out.iter_mut().enumerate().take(b).skip(i) {
                        let f = (j - a) as f64 / (b - a) as f64;
                        *o = ya + (yb - ya) * f;
                    }
                }
                i = b;
            } else {
                i += 1;
            }
        }
        out
    }

    /// Gap-free stretches (start, end exclusive) of a placed series.
    pub fn runs(placed: &[f64]) -> Vec<(usize, usize)> {
        let mut v = Vec::new();
        let mut start = None;
        for (i, x) in placed.iter().enumerate() {
            match (x.is_finite(), start) {
                (true, None) => start = Some(i),
                (false, Some(s)) => {
                    v.push((s, i));
                    start = None;
                }
                _ => {}
            }
        }
        if let Some(s) = start {
            v.push((s, placed.len()));
        }
        v
    }
}

/// The Welch set-up shared by every series of one comparison: segment length, the segments'
/// positions and the log-spaced bands (so measured and members are binned identically).
#[derive(Debug, Clone, PartialEq)]
pub struct Welch {
    /// Segment length, cells (a power of two).
    pub seg: usize,
    /// Segment starts (Hann window, 50 % overlap, each wholly inside a gap-free stretch).
    pub starts: Vec<usize>,
    /// Bands: (lowest FFT bin, highest bin exclusive, centre frequency Hz).
    pub bands: Vec<(usize, usize, f64)>,
    /// Cell width, s.
    pub dt_s: f64,
}

impl Welch {
    /// Set-up for the gap pattern of `placed` (any placed series of the record: gaps are the
    /// record's). `None` when no stretch holds a minimal segment.
    pub fn new(placed: &[f64], dt_s: f64) -> Option<Self> {
        let runs = RegularGrid::runs(placed);
        let longest = runs.iter().map(|(a, b)| b - a).max()?;
        let mut seg = MIN_SEGMENT;
        while seg * 2 <= longest / 2 && seg * 2 <= MAX_SEGMENT {
            seg *= 2;
        }
        if seg > longest {
            return None;
        }
        let mut starts = Vec::new();
        for &(a, b) in &runs {
            let mut s = a;
            while s + seg <= b {
                starts.push(s);
                s += seg / 2;
            }
        }
        // Bins 1..seg/2 (DC left out), grouped in log-spaced bands; the lowest bins of a Hann
        // window are leaky, so the first band starts at bin 2.
        let df = 1.0 / (seg as f64 * dt_s);
        let mut bands = Vec::new();
        let mut lo = 2usize;
        let ratio = 10f64.powf(1.0 / BANDS_PER_DECADE);
        while lo < seg / 2 {
            let hi = ((lo as f64 * ratio).ceil() as usize)
                .max(lo + 1)
                .min(seg / 2);
            let centre = ((lo as f64) * (hi - 1) as f64).sqrt().max(lo as f64) * df;
            bands.push((lo, hi, centre));
            lo = hi;
        }
        Some(Welch {
            seg,
            starts,
            bands,
            dt_s,
        })
    }

    /// Band frequencies, Hz.
    pub fn frequencies(&self) -> Vec<f64> {
        self.bands.iter().map(|b| b.2).collect()
    }

    /// Per-segment spectra of a placed series (mean removed per segment, Hann window).
    fn spectra(&self, placed: &[f64]) -> Vec<Vec<(f64, f64)>> {
        let w: Vec<f64> = (0..self.seg)
            .map(|i| {
                let x = std::f64::consts::PI * i as f64 / self.seg as f64;
                x.sin().powi(2)
            })
            .collect();
        self.starts
            .iter()
            .map(|&s| {
                let x = &placed[s..s + self.seg];
                let m = x.iter().sum::<f64>() / self.seg as f64;
                let mut buf: Vec<f64> = x.iter().zip(&w).map(|(v, wi)| (v - m) * wi).collect();
                fft::half_spectrum(&mut buf)
            })
            .collect()
    }

    /// One-sided PSD (unit²/Hz) in each band.
    pub fn psd(&self, placed: &[f64]) -> Vec<f64> {
        let sp = self.spectra(placed);
        // Hann: Σw² = 3N/8; one-sided PSD = 2 |X|² dt / Σw².
        let norm = 2.0 * self.dt_s / (3.0 * self.seg as f64 / 8.0);
        self.bands
            .iter()
            .map(|&(lo, hi, _)| {
                let mut s = 0.0;
                let mut n = 0usize;
                for seg in &sp {
                    for c in &seg[lo..hi] {
                        s += c.0 * c.0 + c.1 * c.1;
                        n += 1;
                    }
                }
                if n == 0 {
                    f64::NAN
                } else {
                    norm * s / n as f64
                }
            })
            .collect()
    }

    /// Magnitude-squared coherence of `a` and `b` in each band (cross and auto spectra
    /// averaged over segments and the band's bins).
    pub fn coherence(&self, a: &[f64], b: &[f64]) -> Vec<f64> {
        self.coherence_with(&self.spectra(a), &self.spectra(b))
    }

    /// Spectra of a channel, to reuse across the members.
    pub fn channel_spectra(&self, placed: &[f64]) -> ChannelSpectra {
        ChannelSpectra(self.spectra(placed))
    }

    /// Coherence of a placed series with a channel's precomputed spectra.
    pub fn coherence_to(&self, a: &[f64], ch: &ChannelSpectra) -> Vec<f64> {
        self.coherence_with(&self.spectra(a), &ch.0)
    }

    fn coherence_with(&self, sa: &[Vec<(f64, f64)>], sb: &[Vec<(f64, f64)>]) -> Vec<f64> {
        self.bands
            .iter()
            .map(|&(lo, hi, _)| {
                let (mut re, mut im, mut aa, mut bb) = (0.0, 0.0, 0.0, 0.0);
                for (x, y) in sa.iter().zip(sb) {
                    for k in lo..hi {
                        let (p, q) = (x[k], y[k]);
                        // X·conj(Y)
                        re += p.0 * q.0 + p.1 * q.1;
                        im += p.1 * q.0 - p.0 * q.1;
                        aa += p.0 * p.0 + p.1 * p.1;
                        bb += q.0 * q.0 + q.1 * q.1;
                    }
                }
                if aa > 0.0 && bb > 0.0 {
                    (re * re + im * im) / (aa * bb)
                } else {
                    f64::NAN
                }
            })
            .collect()
    }
}

/// Precomputed segment spectra of a measured channel.
#[derive(Debug, Clone)]
pub struct ChannelSpectra(Vec<Vec<(f64, f64)>>);

/// Overlapping ADEV at octave τ of a placed series (gaps skipped by the Allan code), τ up to
/// span / [`ADEV_MAX_TAU_FRACTION`]: (τ s, deviation).
pub fn adev(placed: &[f64], dt_s: f64) -> Vec<(f64, f64)> {
    let span = placed.len() as f64 * dt_s;
    crate::allan::oadev(placed, dt_s, crate::allan::TauSet::Octave)
        .unwrap_or_default()
        .iter()
        .filter(|p| p.tau_s <= span / ADEV_MAX_TAU_FRACTION && p.dev.is_finite())
        .map(|p| (p.tau_s, p.dev))
        .collect()
}

/// The views of one residual.
#[derive(Debug, Clone, PartialEq)]
pub struct Views {
    /// ADEV (τ, dev).
    pub adev: Vec<(f64, f64)>,
    /// PSD per band.
    pub psd: Vec<f64>,
    /// Coherence per band with each measured channel (same order as the channels).
    pub coherence: Vec<Vec<f64>>,
}

/// 5 %, 50 % and 95 % of `v` as prediction limits: the p-quantile at rank p·(n + 1) between
/// order statistics (linear interpolation, clamped to the smallest and largest; NaN dropped).
/// A new draw from the members' distribution lies above the rank-r member with probability
/// (n + 1 − r)/(n + 1), so these limits hold a new member 90 % of the time whatever n; the
/// rank p·(n − 1) + 1 rule holds it only ≈ 81 % of the time with 20 members.
pub fn percentiles(v: &mut Vec<f64>) -> (f64, f64, f64) {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return (f64::NAN, f64::NAN, f64::NAN);
    }
    v.sort_by(f64::total_cmp);
    let q = |p: f64| {
        let x = (p * (v.len() + 1) as f64 - 1.0).clamp(0.0, (v.len() - 1) as f64);
        let i = x.floor() as usize;
        let j = (i + 1).min(v.len() - 1);
        v[i] + (v[j] - v[i]) * (x - i as f64)
    };
    (q(0.05), q(0.5), q(0.95))
}

/// 5–95 % envelope (and median) of one quantity over the members: one entry per point.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Envelope {
    /// Abscissa (τ s or frequency Hz).
    pub x: Vec<f64>,
    /// 5 %.
    pub low: Vec<f64>,
    /// Median.
    pub median: Vec<f64>,
    /// 95 %.
    pub high: Vec<f64>,
}

impl Envelope {
    /// Envelope of member curves `ys` (each aligned with `x`; shorter ones count where present).
    pub fn of(x: &[f64], ys: &[Vec<f64>]) -> Self {
        let mut e = Envelope {
            x: x.to_vec(),
            low: Vec::new(),
            median: Vec::new(),
            high: Vec::new(),
        };
        for i in 0..x.len() {
            let mut v: Vec<f64> = ys.iter().filter_map(|y| y.get(i).copied()).collect();
            let (l, m, h) = percentiles(&mut v);
            e.low.push(l);
            e.median.push(m);
            e.high.push(h);
        }
        e
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn welch_psd_of_white_noise_is_its_variance_times_twice_the_spacing() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        // Uniform(−1, 1): variance 1/3; one-sided PSD of white noise = 2σ²dt.
        let x: Vec<f64> = (0..40_000).map(|_| rng.random_range(-1.0..1.0)).collect();
        let w = Welch::new(&x, 10.0).unwrap();
        let p = w.psd(&x);
        // Mean over all bins (bands weighted by their bin count).
        let bins: Vec<f64> = w.bands.iter().map(|b| (b.1 - b.0) as f64).collect();
        let mean = p.iter().zip(&bins).map(|(p, n)| p * n).sum::<f64>() / bins.iter().sum::<f64>();
        assert!((mean / (2.0 / 3.0 * 10.0) - 1.0).abs() < 0.02, "{mean}");
        // Coherence of a series with itself is one, with independent noise small.
        let y: Vec<f64> = (0..40_000).map(|_| rng.random_range(-1.0..1.0)).collect();
        assert!(w.coherence(&x, &x).iter().all(|c| (c - 1.0).abs() < 1e-9));
        let c = w.coherence(&x, &y);
        assert!(c.iter().all(|c| *c < 0.5), "{c:?}");
    }

    #[test]
    fn short_holes_are_filled_and_long_ones_stay_gaps() {
        let t: Vec<f64> = [0, 1, 2, 4, 5, 10, 11, 12]
            .iter()
            .map(|&k| 60.0 * k as f64)
            .collect();
        let n = t.len();
        let ds = Dataset {
            output_name: "y".into(),
            output_unit: "v".into(),
            unit_per_g: None,
            input_g: None,
            ..Dataset::test_g(t, (0..n).map(|i| i as f64).collect(), 60.0)
        };
        let g = RegularGrid::new(&ds);
        let p = g.place(&ds.y);
        assert_eq!(p.len(), 13);
        assert!((p[3] - 2.5).abs() < 1e-12);
        assert!(p[6..10].iter().all(|v| v.is_nan()));
        assert_eq!(RegularGrid::runs(&p), vec![(0, 6), (10, 13)]);
    }
}
