//! Overlapping Allan deviation (OADEV) and modified Allan deviation (MDEV) of "frequency-like"
//! readings, with chi-squared confidence intervals and lag-1 autocorrelation noise identification.
//!
//! # Data and definitions (NIST SP 1065, eqs. (11) and (14))
//!
//! The input is a series of readings `y_i` (any unit: g for an accelerometer output) taken every
//! `tau0_s` seconds, i.e. frequency data in the time-and-frequency sense. They are integrated to
//! "phase" `x_0 = 0, x_k = tau0 * sum_{i<k} (y_i - mean(y))` (`N + 1` points for `N` readings,
//! exactly as allantools' `frequency2phase`; subtracting the mean changes nothing mathematically
//! and keeps the integral small, which protects the second differences from cancellation).
//!
//! - OADEV at `tau = m tau0`: `sigma^2 = sum_n (x_{n+2m} - 2 x_{n+m} + x_n)^2 / (2 tau^2 n_terms)`
//!   over `n = 0 .. N+1-2m`.
//! - MDEV: `sigma^2 = sum_j (sum_{i=j}^{j+m-1} (x_{i+2m} - 2x_{i+m} + x_i))^2 / (2 m^2 tau^2 n_terms)`
//!   over `j = 0 .. N+2-3m`.
//!
//! Both cost O(N) per tau. OADEV is one vectorisable pass; MDEV updates the inner sum by a
//! recurrence (`v_{j+1} = v_j + x_{j+3m} - 3x_{j+2m} + 3x_{j+m} - x_j`), run as several
//! independent chains started from directly summed values, so the adds pipeline and the rounding
//! error of the recurrence stays a short random walk.
//!
//! # Tau sets
//!
//! [`TauSet::Octave`]: `m = 1, 2, 4, ...` up to `2^floor(log2(N+1))`; [`TauSet::All`]: every
//! `m`. As in allantools, a tau is reported only if it has at least 2 terms. `All` is O(N^2):
//! meant for short records.
//!
//! # Gaps (NaN readings)
//!
//! Nothing is interpolated. A NaN reading is excluded from the mean and contributes zero to the
//! integral, and **every term whose window touches a NaN reading is skipped** (an OADEV term at `n`
//! uses readings `n .. n+2m-1`; an MDEV term at `j` uses `j .. j+3m-2`). The divisor is the number
//! of terms actually used, reported as `n_terms`. The EDF is then computed as if the record were
//! contiguous with `n_terms` terms (i.e. with `N_eff = n_terms + 2m` phase points for OADEV),
//! which is an approximation when gaps are many.
//!
//! # Confidence intervals
//!
//! The interval is the chi-squared one of SP 1065 eq. (45) at the 1-sigma (68.27 %) level:
//! `sigma * sqrt(edf / chi2_{0.8413}(edf)) .. sigma * sqrt(edf / chi2_{0.1587}(edf))`.
//! The EDF is the Howe/Allan/Barnes ("Stein") simple approximation of SP 1065 Table 5 for the
//! overlapping Allan variance, for the power-law noise type `alpha` identified at that tau by the
//! lag-1 autocorrelation method of Riley & Greenhall (2004). When identification is impossible
//! (fewer than 30 non-overlapping averages at that tau) the type identified at the nearest
//! shorter tau is carried over (white FM, `alpha = 0`, if none was) and the point says so
//! (`alpha_identified: None`). On gapless records the identification uses at most the first
//! [`NOISE_ID_MAX_POINTS`] block means (a cost cap; allantools uses all of them).
//!
//! **MDEV intervals use the same OADEV EDF formula** at the same `m` and `alpha`. That is an
//! approximation (Greenhall's general EDF algorithm for the modified variance is not implemented);
//! treat MDEV intervals as indicative.
//!
//! allantools' own `ade` error is simply `dev / sqrt(n_terms)`; [`AllanPoint::simple_err`]
//! reproduces it for comparison.
//!
//! # Files
//!
//! `mod.rs` the types, the phase integral and the per-tau driver; `overlapping.rs` the OADEV sums
//! (the vectorised multi-tau kernel); `modified.rs` the MDEV sums; `noise_id.rs` the lag-1
//! noise identification; `confidence.rs` the EDF and the χ² interval; `tests.rs` the checks
//! against allantools and brute force.

mod confidence;
mod modified;
mod noise_id;
mod overlapping;
#[cfg(test)]
mod tests;

pub use confidence::{chi2_interval, chi2_quantile, edf_oadev_simple, ONE_SIGMA_TAIL};
pub use noise_id::{detrend_linear, lag1_autocorrelation, noise_id_lag1};
use overlapping::oadev_sums_gapless;

/// Noise identification uses at most this many block means (the first ones of the record).
pub const NOISE_ID_MAX_POINTS: usize = 1 << 17;

/// Which averaging factors to evaluate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TauSet {
    /// `m = 1, 2, 4, 8, ...`
    Octave,
    /// Every `m` (O(N^2): short records only).
    All,
}

/// Which statistic.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Statistic {
    /// Overlapping Allan deviation.
    Oadev,
    /// Modified Allan deviation.
    Mdev,
}

/// Errors of the Allan computations.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AllanError {
    /// The sample spacing is not a positive finite number.
    #[error("sample spacing tau0 = {0} s is not positive and finite")]
    BadTau0(f64),
    /// Too few readings for any tau (need at least 3 finite readings).
    #[error("too few readings for an Allan deviation: {0}")]
    TooShort(usize),
    /// A reading is infinite.
    #[error("reading {0} is infinite")]
    Infinite(usize),
}

/// One point of an Allan-type deviation curve.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct AllanPoint {
    /// Averaging time, s.
    pub tau_s: f64,
    /// Averaging factor `tau / tau0`.
    pub m: usize,
    /// The deviation, in the unit of the readings.
    pub dev: f64,
    /// Number of terms summed (allantools' `n`).
    pub n_terms: usize,
    /// Equivalent degrees of freedom used for the interval.
    pub edf: f64,
    /// Lower end of the 68.27 % chi-squared interval.
    pub ci_low: f64,
    /// Upper end of the 68.27 % chi-squared interval.
    pub ci_high: f64,
    /// Noise exponent `alpha` (frequency PSD ~ f^alpha) identified at this tau, if possible.
    pub alpha_identified: Option<i32>,
    /// The `alpha` the EDF was computed for (identified here, else carried from a shorter tau,
    /// else 0 = white FM).
    pub alpha_used: i32,
}

impl AllanPoint {
    /// allantools' simple error bar `dev / sqrt(n_terms)`.
    pub fn simple_err(&self) -> f64 {
        self.dev / (self.n_terms as f64).sqrt()
    }
}

/// Readings integrated to phase, with the gap bookkeeping both statistics need.
#[derive(Debug, Clone)]
pub struct Phase {
    /// `x_0 .. x_N` (N + 1 points), unit of readings times seconds.
    x: Vec<f64>,
    /// `nan_before[k]` = number of NaN readings among `y_0 .. y_{k-1}`; `None` if there are none.
    nan_before: Option<Vec<u32>>,
    /// `x_0, x_DEC, x_2DEC, ...` (bit-identical copies), gapless records only: noise
    /// identification at long taus reads these instead of striding through all of `x`.
    dec: Vec<f64>,
    tau0_s: f64,
    finite: usize,
}

/// Stride of [`Phase::dec`].
const DEC: usize = 32;

impl Phase {
    /// Integrates readings spaced `tau0_s` seconds apart (NaN = gap, see module docs).
    pub fn from_readings(y: &[f64], tau0_s: f64) -> Result<Self, AllanError> {
        if !(tau0_s.is_finite() && tau0_s > 0.0) {
            return Err(AllanError::BadTau0(tau0_s));
        }
        let (mut finite, mut sum) = (0usize, 0.0);
        for (i, &v) in y.iter().enumerate() {
            if v.is_finite() {
                finite += 1;
                sum += v;
            } else if v.is_infinite() {
                return Err(AllanError::Infinite(i));
            }
        }
        if finite < 3 {
            return Err(AllanError::TooShort(finite));
        }
        let mean = sum / finite as f64;
        let gapless = finite == y.len();
        let mut x = Vec::with_capacity(y.len() + 1);
        let mut dec = Vec::with_capacity(if gapless { y.len() / DEC + 2 } else { 0 });
        x.push(0.0);
        let mut acc = 0.0;
        for chunk in y.chunks(DEC) {
            if gapless {
                dec.push(acc * tau0_s);
            }
            x.extend(chunk.iter().map(|&v| {
                if v.is_finite() {
                    acc += v - mean;
                }
                acc * tau0_s
            }));
        }
        if gapless && y.len().is_multiple_of(DEC) {
            dec.push(acc * tau0_s);
        }
        let nan_before = (finite < y.len()).then(|| {
            let mut c = Vec::with_capacity(y.len() + 1);
            let mut k = 0u32;
            c.push(0);
            for v in y {
                k += u32::from(v.is_nan());
                c.push(k);
            }
            c
        });
        Ok(Phase {
            x,
            nan_before,
            dec,
            tau0_s,
            finite,
        })
    }

    /// Number of phase points (readings + 1).
    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// Always false: a `Phase` holds at least 4 points.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// Number of finite readings.
    pub fn finite_readings(&self) -> usize {
        self.finite
    }

    /// Averaging factors for a tau set (before dropping those with < 2 terms).
    pub fn factors(&self, set: TauSet, stat: Statistic) -> Vec<usize> {
        let np = self.x.len();
        let max_m = match stat {
            // OADEV needs np - 2m >= 2 terms; MDEV np - 3m + 1 >= 2.
            Statistic::Oadev => np.saturating_sub(2) / 2,
            Statistic::Mdev => np.saturating_sub(1) / 3,
        };
        match set {
            TauSet::All => (1..=max_m).collect(),
            TauSet::Octave => {
                let mut v = Vec::new();
                let mut m = 1usize;
                while m <= max_m {
                    v.push(m);
                    m *= 2;
                }
                v
            }
        }
    }
}

impl Phase {
    /// One deviation curve.
    ///
    /// Where the noise cannot be identified (long tau, too few averages) the EDF uses the
    /// noise type identified at the nearest shorter tau, white FM if there is none.
    pub fn deviation(&self, stat: Statistic, set: TauSet) -> Vec<AllanPoint> {
        let ms = self.factors(set, stat);
        let sums = self.sums_and_ids(stat, &ms);
        let mut out = Vec::new();
        let mut last_alpha = 0;
        for (&m, (s, n, alpha_identified)) in ms.iter().zip(sums) {
            if let Some(p) = self.make_point(stat, m, s, n, alpha_identified, last_alpha) {
                last_alpha = p.alpha_used;
                out.push(p);
            }
        }
        out
    }

    /// Sum, term count and identified noise type at every factor in `ms`. On long records the
    /// taus are shared between two threads; each sum is computed exactly as on one thread.
    fn sums_and_ids(&self, stat: Statistic, ms: &[usize]) -> Vec<(f64, usize, Option<i32>)> {
        let work = |group: &[usize]| -> Vec<(f64, usize, Option<i32>)> {
            let sums: Vec<(f64, usize)> = match (stat, &self.nan_before) {
                (Statistic::Oadev, None) => oadev_sums_gapless(&self.x, group),
                (Statistic::Oadev, Some(_)) => group.iter().map(|&m| self.oadev_sum(m)).collect(),
                (Statistic::Mdev, _) => group.iter().map(|&m| self.mdev_sum(m)).collect(),
            };
            let mut scratch = Vec::new();
            sums.into_iter()
                .zip(group)
                .map(|((s, n), &m)| {
                    let id = if n >= 2 {
                        self.noise_id(m, &mut scratch)
                    } else {
                        None
                    };
                    (s, n, id)
                })
                .collect()
        };
        // Work of one tau: one term per phase point, minus the window.
        let np = self.x.len();
        on_two_threads(ms, |m| np.saturating_sub(2 * m), work)
    }

    /// One point at averaging factor `m`; `None` if it has fewer than 2 terms. White FM is
    /// assumed for the EDF if the noise cannot be identified at this tau.
    pub fn point(&self, stat: Statistic, m: usize) -> Option<AllanPoint> {
        self.point_with_default_alpha(stat, m, 0)
    }

    /// [`Phase::point`] with the `alpha` to assume when identification is impossible.
    pub fn point_with_default_alpha(
        &self,
        stat: Statistic,
        m: usize,
        default_alpha: i32,
    ) -> Option<AllanPoint> {
        if m == 0 {
            return None;
        }
        let (s, n) = match stat {
            Statistic::Oadev => self.oadev_sum(m),
            Statistic::Mdev => self.mdev_sum(m),
        };
        if n < 2 {
            return None;
        }
        let alpha_identified = self.noise_id(m, &mut Vec::new());
        self.make_point(stat, m, s, n, alpha_identified, default_alpha)
    }

    /// The point from its sum `s` over `n` terms; `None` below 2 terms.
    fn make_point(
        &self,
        stat: Statistic,
        m: usize,
        s: f64,
        n: usize,
        alpha_identified: Option<i32>,
        default_alpha: i32,
    ) -> Option<AllanPoint> {
        if m == 0 || n < 2 {
            return None;
        }
        let tau = m as f64 * self.tau0_s;
        let mf = m as f64;
        let var = match stat {
            Statistic::Oadev => s / (2.0 * tau * tau * n as f64),
            Statistic::Mdev => s / (2.0 * mf * mf * tau * tau * n as f64),
        };
        let dev = var.sqrt();
        let alpha_used = alpha_identified.unwrap_or(default_alpha);
        // Phase points of an equivalent contiguous record (equal to len() without gaps).
        let n_phase = match stat {
            Statistic::Oadev => n + 2 * m,
            Statistic::Mdev => n + 3 * m - 1,
        };
        let edf = edf_oadev_simple(n_phase as f64, mf, alpha_used);
        let (ci_low, ci_high) = chi2_interval(dev, edf);
        Some(AllanPoint {
            tau_s: tau,
            m,
            dev,
            n_terms: n,
            edf,
            ci_low,
            ci_high,
            alpha_identified,
            alpha_used,
        })
    }
}

/// OADEV of readings `y` spaced `tau0_s` (convenience over [`Phase`]).
pub fn oadev(y: &[f64], tau0_s: f64, set: TauSet) -> Result<Vec<AllanPoint>, AllanError> {
    Ok(Phase::from_readings(y, tau0_s)?.deviation(Statistic::Oadev, set))
}

/// MDEV of readings `y` spaced `tau0_s` (convenience over [`Phase`]).
pub fn mdev(y: &[f64], tau0_s: f64, set: TauSet) -> Result<Vec<AllanPoint>, AllanError> {
    Ok(Phase::from_readings(y, tau0_s)?.deviation(Statistic::Mdev, set))
}

/// Below this much work (terms summed over all taus) a second thread costs more than it saves.
const PARALLEL_MIN_WORK: usize = 1 << 20;

/// Runs `work` on `items` split into two groups of about equal `cost`, one of them on a scoped
/// thread, and returns the results in the order of `items`. `work` returns one result per item
/// of the group it is given, in order. One group only when the machine has one core, the work
/// is small or the thread cannot be started.
fn on_two_threads<T: Send>(
    items: &[usize],
    cost: impl Fn(usize) -> usize,
    work: impl Fn(&[usize]) -> Vec<T> + Sync,
) -> Vec<T> {
    let total: usize = items.iter().map(|&m| cost(m)).sum();
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    if cores < 2 || items.len() < 2 || total < PARALLEL_MIN_WORK {
        return work(items);
    }
    // Largest first, each to the lighter group.
    let mut order: Vec<usize> = (0..items.len()).collect();
    order.sort_by_key(|&i| std::cmp::Reverse(cost(items[i])));
    let (mut ga, mut gb) = (Vec::new(), Vec::new());
    let (mut ca, mut cb) = (0usize, 0usize);
    for i in order {
        if ca <= cb {
            ca += cost(items[i]);
            ga.push(i);
        } else {
            cb += cost(items[i]);
            gb.push(i);
        }
    }
    ga.sort_unstable();
    gb.sort_unstable();
    let ma: Vec<usize> = ga.iter().map(|&i| items[i]).collect();
    let mb: Vec<usize> = gb.iter().map(|&i| items[i]).collect();
    let (ra, rb) = std::thread::scope(|s| {
        let work = &work;
        let spawned = std::thread::Builder::new().spawn_scoped(s, || work(&mb));
        let ra = work(&ma);
        let rb = match spawned {
            Ok(h) => match h.join() {
                Ok(r) => r,
                Err(panic) => std::panic::resume_unwind(panic),
            },
            Err(_) => work(&mb),
        };
        (ra, rb)
    });
    let mut out: Vec<Option<T>> = (0..items.len()).map(|_| None).collect();
    for (i, r) in ga.into_iter().zip(ra).chain(gb.into_iter().zip(rb)) {
        if let Some(slot) = out.get_mut(i) {
            *slot = Some(r);
        }
    }
    out.into_iter().flatten().collect()
}
