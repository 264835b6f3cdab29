//! The residual's noise model (white + flicker + random walk) and the exact whitening it implies.
//!
//! # Why
//!
//! An AR(1) whitening does not whiten flicker + random-walk noise: the likelihood then sees
//! far more independent information than the record holds, and slow effects, steps and lines
//! are "found" in pure noise. Here the residual's Allan variance is fitted with
//! σ²(τ) = h_w/τ + h_f·F(τ) + h_rw·τ, where F is the Allan variance of a sum of equal-variance
//! Ornstein–Uhlenbeck processes with correlation times spaced by √10 (a flicker of flat Allan
//! deviation between the shortest and longest correlation time). That noise is a linear
//! state-space model (one state per OU component, one random-walk state, white measurement
//! noise), so the exact GLS whitening is the Kalman filter's normalised innovation sequence:
//! O(n·k²) once for the gains, O(n·k) per whitened column, gaps and irregular sampling handled
//! by propagating the state over the actual time step (nothing interpolated).

/// Ratio between successive flicker correlation times (two per decade).
const FLICKER_RATIO: f64 = 3.162_277_660_168_379_5;

/// White + flicker + random-walk noise in the output unit.
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseModel {
    /// Variance of one white sample at the record's spacing, unit².
    pub white_var: f64,
    /// Flicker components: (correlation time s, variance unit²).
    pub flicker: Vec<(f64, f64)>,
    /// Random-walk diffusion, unit² per second.
    pub rw_per_s: f64,
    /// Fitted Allan coefficients (h_w unit²·s, flicker floor unit², h_rw unit²/s).
    pub h: [f64; 3],
    /// Per row of the record: the factor on `white_var` of that point (a bin mean of n
    /// samples has white variance σ²/n: the factor is the record's mean count over n, so
    /// `white_var` stays the variance of a point of average count). `None`: every point alike.
    pub white_scale: Option<Arc<[f64]>>,
}

use std::sync::Arc;

/// Per-row white-variance factors of a record whose points hold `counts` samples each
/// (mean count / count), or `None` when they are all equal (or not known).
pub fn white_scale_from_counts(counts: &[f64]) -> Option<Arc<[f64]>> {
    let first = *counts.first()?;
    if counts.iter().all(|&c| c == first) || counts.iter().any(|&c| c.is_nan() || c <= 0.0) {
        return None;
    }
    let mean = counts.iter().sum::<f64>() / counts.len() as f64;
    Some(counts.iter().map(|&c| mean / c).collect())
}

/// Allan variance of an OU process of unit variance and correlation time `t_c` at averaging
/// time `tau` (exact for continuous averaging): Var(mean) − Cov(adjacent means).
pub fn ou_avar(tau: f64, t_c: f64) -> f64 {
    let x = tau / t_c;
    let e = (-x).exp();
    let var_mean = 2.0 / (x * x) * (x - (1.0 - e));
    let cov = (1.0 - e).powi(2) / (x * x);
    (var_mean - cov).max(0.0)
}

/// Correlation times of the flicker components for spacing `dt_s` and span `span_s`.
fn flicker_times(dt_s: f64, span_s: f64) -> Vec<f64> {
    let mut v = Vec::new();
    let mut t = dt_s.max(1e-9);
    while t < 3.0 * span_s.max(dt_s) {
        v.push(t);
        t *= FLICKER_RATIO;
    }
    v
}

/// Flicker basis: Allan variance of the equal-variance OU sum (unit variance each).
fn flicker_avar(tau: f64, times: &[f64]) -> f64 {
    times.iter().map(|&t| ou_avar(tau, t)).sum()
}

impl NoiseModel {
    /// Model Allan variance at `tau`.
    pub fn avar(&self, tau: f64) -> f64 {
        let f: f64 = self.flicker.iter().map(|&(t, v)| v * ou_avar(tau, t)).sum();
        self.h[0] / tau + f + self.h[2] * tau
    }

    /// Fits the model to Allan points `(tau_s, adev)` of a residual sampled every `dt_s` over
    /// `span_s`: non-negative weighted least squares on the Allan variance, each point weighted
    /// by the number of independent averages it holds (span/τ) and relative to its value. The
    /// three-term NNLS is solved exactly by trying every subset of active terms.
    pub fn fit(points: &[(f64, f64)], dt_s: f64, span_s: f64) -> Option<Self> {
        let times = flicker_times(dt_s, span_s);
        let pts: Vec<(f64, f64, f64)> = points
            .iter()
            .filter(|(t, a)| *t > 0.0 && *t <= span_s / 3.0 && a.is_finite() && *a > 0.0)
            .map(|&(t, a)| (t, a * a, (span_s / t).sqrt()))
            .collect();
        if pts.is_empty() {
            return None;
        }
        // Rows: basis values / measured, target 1, weight sqrt(span/τ).
        let basis = |t: f64| [1.0 / t, flicker_avar(t, &times), t];
        let mut best: Option<(f64, [f64; 3])> = None;
        for mask in 1u8..8 {
            let act: Vec<usize> = (0..3).filter(|j| mask & (1 << j) != 0).collect();
            let Some(h) = active_terms_fit(&pts, basis, &act) else {
                continue;
            };
            let cost: f64 = pts
                .iter()
                .map(|&(t, m, w)| {
                    let f = basis(t);
                    let model = h[0] * f[0] + h[1] * f[1] + h[2] * f[2];
                    (w * (model / m - 1.0)).powi(2)
                })
                .sum();
            if best.is_none_or(|(c, _)| cost < c) {
                best = Some((cost, h));
            }
        }
        let (_, h) = best?;
        Some(NoiseModel {
            white_var: h[0] / dt_s,
            flicker: times.iter().map(|&t| (t, h[1])).collect(),
            rw_per_s: 3.0 * h[2],
            h,
            white_scale: None,
        })
    }

    /// Pure white noise of the given per-sample variance (fallback, tests).
    pub fn white(var: f64) -> Self {
        NoiseModel {
            white_var: var,
            flicker: Vec::new(),
            rw_per_s: 0.0,
            h: [0.0; 3],
            white_scale: None,
        }
    }

    /// The same model with per-row white-variance factors (see [`white_scale_from_counts`]).
    pub fn with_white_scale(mut self, scale: Option<Arc<[f64]>>) -> Self {
        self.white_scale = scale;
        self
    }

    /// White variance of row `i`.
    fn white_var_at(&self, i: usize) -> f64 {
        let f = self
            .white_scale
            .as_ref()
            .and_then(|s| s.get(i).copied())
            .unwrap_or(1.0);
        (self.white_var * f).max(1e-300)
    }
}

/// How a noise model was obtained (reported in the JSON `noise.method` and the text).
pub const METHOD_KALMAN_ML: &str = "kalman_innovations_ml";
/// The fallback when the likelihood fit failed (always announced as a warning).
pub const METHOD_WHITE_FALLBACK: &str = "white_fallback";

/// Lower bound of the flicker and random-walk levels relative to the white level (ln units):
/// a component this small is "off" (its contribution is far below the white noise on any
/// time scale the record resolves).
const LN_RATIO_MIN: f64 = -30.0;
/// Upper bound (the white part is then negligible; kept finite for the numerics).
const LN_RATIO_MAX: f64 = 25.0;

/// A noise model fitted by maximum likelihood, with how it went.
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseFit {
    /// The model.
    pub model: NoiseModel,
    /// [`METHOD_KALMAN_ML`] or [`METHOD_WHITE_FALLBACK`].
    pub method: &'static str,
    /// −2 ln L of the residual under the model (constant dropped).
    pub neg2_loglik: f64,
    /// Likelihood evaluations used.
    pub evaluations: usize,
    /// Why the likelihood fit failed (then `model` is a white fallback).
    pub failure: Option<String>,
}

/// −2 ln L (constant 2π dropped) of `x` on the rows `idx` (increasing) under `model`:
/// Σ e²/S + Σ ln S over the Kalman innovations e with variances S. One pass, O(n·k²), nothing
/// stored; irregular spacing and gaps are propagated over at their true length.
pub fn neg2_loglik(model: &NoiseModel, t_s: &[f64], idx: &[usize], x: &[f64]) -> f64 {
    let (q, ld) = innovation_sums(model, t_s, idx, x);
    q + ld
}

/// (Σ e²/S, Σ ln S) of the Kalman innovations.
fn innovation_sums(model: &NoiseModel, t_s: &[f64], idx: &[usize], x: &[f64]) -> (f64, f64) {
    let mut ric = Riccati::for_rows(model, t_s, idx);
    let mut state = vec![0.0; ric.k];
    let mut prev_t: Option<f64> = None;
    let (mut chi2, mut log_det) = (0.0, 0.0);
    for &i in idx {
        let dt = prev_t.map_or(0.0, |pt| (t_s[i] - pt).max(0.0));
        prev_t = Some(t_s[i]);
        ric.step(dt, i, true);
        let pred = predict_state(&mut state, &ric.a);
        let s = ric.s;
        let e = x[i] - pred;
        for (st, h) in state.iter_mut().zip(&ric.ph) {
            *st += h / s * e;
        }
        chi2 += e * e / s;
        log_det += ric.ln_s;
    }
    (chi2, log_det)
}

/// Change of the Kalman gains (absolute: a gain is the fraction of an innovation a state takes)
/// and relative change of the innovation variance between two consecutive steps of the same
/// length below which the covariance is taken as converged (the steady-state filter). The
/// Riccati recursion converges geometrically, so what is left after this is far below the
/// likelihood's rounding: the remaining steps skip the O(k²) covariance update.
const STEADY_TOL: f64 = 1e-12;

/// Distinct step lengths whose transitions a [`Riccati`] keeps.
const TRANSITIONS_KEPT: usize = 4;

/// The covariance side of the Kalman filter of a [`NoiseModel`] (H = [1 … 1]), shared by the
/// likelihood, the whitening and the held-out prediction. Once the gain has converged for a
/// repeated step length it is held (steady state) until the step length changes or a row is
/// not observed.
#[derive(Clone)]
struct Riccati<'m> {
    model: &'m NoiseModel,
    k: usize,
    r_var: f64,
    p: Vec<f64>,
    /// Transition factors of the last step.
    a: Vec<f64>,
    q: Vec<f64>,
    /// The transitions of the last few distinct step lengths (length, a, q), most recent
    /// first: bin means of a regular record are a few step lengths alternating (70, 70.5 and
    /// 71 s on the 41-day 1 Hz log binned to 50 000 points), and the k exponentials of a
    /// transition were a quarter of a Riccati step. Exact: a hit has the same length to the bit.
    transitions: Vec<(f64, Vec<f64>, Vec<f64>)>,
    /// P Hᵀ of the step before (the steady-state test compares it with the new one).
    old_ph: Vec<f64>,
    /// P Hᵀ of the last prediction (before the update).
    ph: Vec<f64>,
    /// Innovation variance of the last prediction, and its log.
    s: f64,
    ln_s: f64,
    last_dt: f64,
    last_observed: bool,
    steady: bool,
    /// The rank-2 increments of a regular pass ([`Riccati::for_rows`]); `None`: the full
    /// update on every step.
    low_rank: Option<LowRank>,
}

/// The covariance's increment δₙ = Pₙ₊₁ − Pₙ = L S Lᵀ of a time-invariant filter (one step
/// length, one white variance, every row observed) started from the stationary prior.
///
/// Why: the slowest flicker states (correlation times up to 3× the span) keep P changing to
/// the record's end, so the steady state is seldom reached and the O(k²) update is the
/// discovery's inner loop on long records. For a time-invariant filter the difference of two
/// Riccati iterates obeys δₙ₊₁ = F̄ₙ (δₙ − δₙHᵀHδₙ/Sₙ₊₁) F̄ₙᵀ with F̄ₙ = A − A PₙHᵀH/Sₙ (the
/// Chandrasekhar recursions, Morf, Sidhu & Kailath 1974), so δ keeps the rank of δ₀; from
/// P₀ = the stationary OU variances and a random walk at 0, δ₀ = Q_rw e eᵀ − (A P₀Hᵀ)(A P₀Hᵀ)ᵀ/S₀
/// is rank 2, and each step costs O(k) instead of O(k²). P itself is not kept.
#[derive(Debug, Clone)]
struct LowRank {
    /// L, k × 2, column-major (`l[c * k + j]`).
    l: Vec<f64>,
    /// S, 2 × 2 symmetric.
    s: [[f64; 2]; 2],
    /// Steps taken in this mode (the first one sets δ₀ up).
    steps: usize,
    /// The pass's last row when its step or white variance differs from the others'.
    tail: Option<Tail>,
}

/// The last row of a [`LowRank`] pass, of another step length or white variance: its
/// prediction needs P only through P·a_tail, which is carried along (z = Pₙ a_tail, moved by
/// δₙ a_tail = L S Lᵀ a_tail each step), so P is never formed.
#[derive(Debug, Clone)]
struct Tail {
    /// The last step's transition factors and process noise.
    a: Vec<f64>,
    q: Vec<f64>,
    /// Pₙ a (the current prediction's covariance times `a`).
    z: Vec<f64>,
}

impl<'m> Riccati<'m> {
    /// The filter for one pass over the rows `idx` of `t_s`, all observed. When the pass is
    /// time-invariant after its first row (one step length within the `step`'s tolerance, one
    /// white variance) up to its last row, which may differ in both (a record's last bin holds
    /// fewer samples), the covariance moves by rank-2 increments ([`LowRank`]).
    fn for_rows(model: &'m NoiseModel, t_s: &[f64], idx: &[usize]) -> Self {
        let mut ric = Self::new(model);
        let (Some(&i0), Some(&i1), Some(body)) = (
            idx.first(),
            idx.get(1),
            idx.get(..idx.len().saturating_sub(1)),
        ) else {
            return ric;
        };
        let dt = t_s[i1] - t_s[i0];
        let r = model.white_var_at(i0);
        let regular = |w: &[usize]| {
            let d = t_s[w[1]] - t_s[w[0]];
            (d - dt).abs() <= 1e-9 * dt && model.white_var_at(w[1]) == r
        };
        if idx.len() < 3 || dt.is_nan() || dt <= 0.0 || !body.windows(2).all(regular) {
            return ric;
        }
        let k = ric.k;
        let last = &idx[idx.len() - 2..];
        let tail = (!regular(last)).then(|| {
            let (mut a, mut q) = (vec![0.0; k], vec![0.0; k]);
            transition(
                model,
                (t_s[last[1]] - t_s[last[0]]).max(0.0),
                &mut a,
                &mut q,
            );
            Tail {
                z: vec![0.0; k],
                a,
                q,
            }
        });
        ric.low_rank = Some(LowRank {
            l: vec![0.0; 2 * k],
            s: [[0.0; 2]; 2],
            steps: 0,
            tail,
        });
        ric
    }

    fn new(model: &'m NoiseModel) -> Self {
        let k = model.flicker.len() + 1;
        // Initial covariance: stationary OU states, random walk at zero (offset is a column).
        let mut p = vec![0.0; k * k];
        for (j, &(_, v)) in model.flicker.iter().enumerate() {
            p[j * k + j] = v;
        }
        Riccati {
            model,
            k,
            r_var: f64::NAN,
            p,
            a: vec![1.0; k],
            q: vec![0.0; k],
            transitions: Vec::with_capacity(TRANSITIONS_KEPT),
            old_ph: vec![0.0; k],
            ph: vec![0.0; k],
            s: 0.0,
            ln_s: 0.0,
            last_dt: f64::NAN,
            last_observed: false,
            steady: false,
            low_rank: None,
        }
    }

    /// `a` and `q` for a step of `dt_s`: from the kept transitions when one has this length,
    /// else computed (and kept, the oldest dropped).
    fn set_transition(&mut self, dt_s: f64) {
        if let Some(i) = self
            .transitions
            .iter()
            .position(|(len, ..)| len.to_bits() == dt_s.to_bits())
        {
            let (_, a, q) = &self.transitions[i];
            self.a.copy_from_slice(a);
            self.q.copy_from_slice(q);
            return;
        }
        transition(self.model, dt_s, &mut self.a, &mut self.q);
        if self.transitions.len() == TRANSITIONS_KEPT {
            self.transitions.pop();
        }
        self.transitions
            .insert(0, (dt_s, self.a.clone(), self.q.clone()));
    }

    /// Predicts over `dt_s` (fills `a`, `ph`, `s`) and, if `observed`, applies the measurement
    /// update to the covariance.
    fn step(&mut self, dt_s: f64, row: usize, observed: bool) {
        let same_dt = (dt_s - self.last_dt).abs() <= 1e-9 * dt_s.abs().max(1e-300);
        let r_var = self.model.white_var_at(row);
        let same_r = r_var == self.r_var;
        self.r_var = r_var;
        if self.steady && same_dt && same_r && observed && self.last_observed {
            return;
        }
        let k = self.k;
        let (old_s, was_observed) = (self.s, self.last_observed);
        let compare = same_dt && same_r && observed && was_observed;
        if compare {
            self.old_ph.copy_from_slice(&self.ph);
        }
        if was_observed && self.low_rank.is_some() {
            self.low_rank_step(dt_s, same_dt, same_r && observed, old_s);
            self.finish_step(compare, old_s, dt_s, observed);
            return;
        }
        if !same_dt {
            self.set_transition(dt_s);
        }
        // P ← A P A + Q and P Hᵀ (row sums) in one pass.
        for (r, (row, ph)) in self
            .p
            .chunks_exact_mut(k)
            .zip(self.ph.iter_mut())
            .enumerate()
        {
            let ar = self.a[r];
            for (pc, ac) in row.iter_mut().zip(&self.a) {
                *pc *= ar * ac;
            }
            // The row sum apart, on independent partial sums: summed in the loop above, every
            // element would wait on the addition before it (this is the discovery's inner loop).
            let sum = sum_unchained(row);
            row[r] += self.q[r];
            *ph = sum + self.q[r];
        }
        self.s = self.ph.iter().sum::<f64>() + self.r_var;
        self.ln_s = self.s.ln();
        if observed {
            let s = self.s;
            for (row, &phr) in self.p.chunks_exact_mut(k).zip(self.ph.iter()) {
                let f = phr / s;
                for (pc, phc) in row.iter_mut().zip(&self.ph) {
                    *pc -= f * phc;
                }
            }
        }
        self.finish_step(compare, old_s, dt_s, observed);
    }

    /// After a step's prediction: whether the filter has reached its steady state (`compare`:
    /// this step and the one before are of the same length and white variance, both observed;
    /// then S and PHᵀ moved by less than [`STEADY_TOL`]), and what the next step compares with.
    fn finish_step(&mut self, compare: bool, old_s: f64, dt_s: f64, observed: bool) {
        self.steady = compare
            && (self.s - old_s).abs() <= STEADY_TOL * self.s
            && self
                .old_ph
                .iter()
                .zip(&self.ph)
                .all(|(o, n)| (n - o).abs() <= STEADY_TOL * self.s);
        self.last_dt = dt_s;
        self.last_observed = observed;
    }

    /// One step of the [`LowRank`] mode: from Pₙ's PHᵀ and S (in `ph`, `s` = `old_s`) and
    /// δₙ = L S Lᵀ to Pₙ₊₁'s, and δₙ₊₁. The first step after the first row sets δ₀ up.
    fn low_rank_step(&mut self, dt_s: f64, same_dt: bool, invariant: bool, old_s: f64) {
        let k = self.k;
        let Some(lr) = self.low_rank.as_mut() else {
            return;
        };
        if !(invariant && (same_dt || lr.steps == 0)) {
            // `for_rows` proved the pass time-invariant after its first row but for its last:
            // this is the last row. Pₙ⁺ a = z − PHᵀ (PHᵀ·a)/S, and the prediction's PHᵀ is
            // a ∘ (Pₙ⁺ a) + q.
            debug_assert!(lr.tail.is_some(), "an irregular row inside a low-rank pass");
            if let Some(t) = &lr.tail {
                let c = self.ph.iter().zip(&t.a).map(|(p, a)| p * a).sum::<f64>() / old_s;
                for ((ph, (z, a)), q) in self.ph.iter_mut().zip(t.z.iter().zip(&t.a)).zip(&t.q) {
                    *ph = a * (z - *ph * c) + q;
                }
                self.a.copy_from_slice(&t.a);
                self.q.copy_from_slice(&t.q);
                self.s = self.ph.iter().sum::<f64>() + self.r_var;
                self.ln_s = self.s.ln();
            }
            self.low_rank = None;
            return;
        }
        if lr.steps == 0 {
            transition(self.model, dt_s, &mut self.a, &mut self.q);
            // δ₀ = Φ(P₀) − P₀ with P₀ diagonal and stationary for the OU states: the random
            // walk's diffusion, less the update's (A P₀Hᵀ)(A P₀Hᵀ)ᵀ/S₀.
            lr.l.iter_mut().for_each(|v| *v = 0.0);
            lr.l[k - 1] = 1.0;
            for (l, (a, ph)) in lr.l[k..].iter_mut().zip(self.a.iter().zip(&self.ph)) {
                *l = a * ph;
            }
            lr.s = [[self.q[k - 1], 0.0], [0.0, -1.0 / old_s]];
            if let Some(t) = lr.tail.as_mut() {
                // z₀ = P₀ a: the stationary OU variances, the random walk at 0.
                t.z.iter_mut().for_each(|z| *z = 0.0);
                for (z, (&(_, v), a)) in t.z.iter_mut().zip(self.model.flicker.iter().zip(&t.a)) {
                    *z = v * a;
                }
            }
        }
        lr.steps += 1;
        let (l0, l1) = lr.l.split_at_mut(k);
        // u = Lᵀ Hᵀ (column sums), w = S u, v = L w = δₙ Hᵀ.
        let u = [sum_unchained(l0), sum_unchained(l1)];
        let w = [
            lr.s[0][0] * u[0] + lr.s[0][1] * u[1],
            lr.s[1][0] * u[0] + lr.s[1][1] * u[1],
        ];
        let s_new = old_s + u[0] * w[0] + u[1] * w[1];
        if let Some(t) = lr.tail.as_mut() {
            // z ← z + L S (Lᵀ a_tail), with this step's L.
            let dot = |l: &[f64]| l.iter().zip(&t.a).map(|(x, a)| x * a).sum::<f64>();
            let (g0, g1) = (dot(l0), dot(l1));
            let (h0, h1) = (
                lr.s[0][0] * g0 + lr.s[0][1] * g1,
                lr.s[1][0] * g0 + lr.s[1][1] * g1,
            );
            for ((z, x0), x1) in t.z.iter_mut().zip(l0.iter()).zip(l1.iter()) {
                *z += x0 * h0 + x1 * h1;
            }
        }
        // L ← F̄ₙ L = A L − (A PₙHᵀ) uᵀ/Sₙ, with Pₙ's PHᵀ; then PHᵀ ← PHᵀ + L w.
        let (c0, c1) = (u[0] / old_s, u[1] / old_s);
        for (((x0, x1), a), ph) in l0
            .iter_mut()
            .zip(l1.iter_mut())
            .zip(&self.a)
            .zip(&mut self.ph)
        {
            let v = *x0 * w[0] + *x1 * w[1];
            let aph = a * *ph;
            *x0 = a * *x0 - aph * c0;
            *x1 = a * *x1 - aph * c1;
            *ph += v;
        }
        // S ← S − (S u)(S u)ᵀ/Sₙ₊₁.
        for (r, wr) in lr.s.iter_mut().zip(w) {
            for (sc, wc) in r.iter_mut().zip(w) {
                *sc -= wr * wc / s_new;
            }
        }
        self.s = s_new;
        self.ln_s = s_new.ln();
    }
}

/// The state moved by the transition factors `a`, and the prediction H x (the states' sum).
/// The sum apart from the products, on independent partial sums: it is the whitening's inner
/// loop (one pass per column per noise model), and a running sum waits on every addition.
fn predict_state(state: &mut [f64], a: &[f64]) -> f64 {
    state.iter_mut().zip(a).for_each(|(s, f)| *s *= f);
    sum_unchained(state)
}

/// Σ `x` on four independent partial sums (the additions do not wait on each other).
fn sum_unchained(x: &[f64]) -> f64 {
    let mut acc = [0.0; 4];
    let mut chunks = x.chunks_exact(4);
    for c in &mut chunks {
        for (a, v) in acc.iter_mut().zip(c) {
            *a += v;
        }
    }
    let tail: f64 = chunks.remainder().iter().sum();
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

/// Range of the flicker slope β (component variance ∝ (τ_c/τ_mid)^β): 0 is a flat Allan
/// deviation (1/f), negative values put the variance into the fast components (a low-passed
/// white noise, as a gravimeter's output filter makes), positive into the slow ones.
pub const FLICKER_SLOPE_RANGE: (f64, f64) = (-2.0, 1.0);
/// Upper bound of ln(shortest flicker correlation time / spacing): the comb may start up to
/// 100 spacings (an instrument's output filter of a few samples is the usual case).
const LN_T_MIN_MAX: f64 = 4.605_170_185_988_091;
/// Dimensions of the likelihood search: ln(f/w), ln(q·dt/w), β, ln(t_min/dt).
const D: usize = 4;
type P = [f64; D];

impl NoiseModel {
    /// The model with white variance `w` (per point), flicker level `f` (variance of the OU
    /// component at the middle correlation time) and slope `beta` (component variances
    /// f·(τ_c/τ_mid)^β), random-walk diffusion `q` (unit²/s); flicker times for `dt_s`/`span_s`.
    pub fn from_levels(w: f64, f: f64, beta: f64, q: f64, dt_s: f64, span_s: f64) -> Self {
        Self::from_levels_from(w, f, beta, q, dt_s, dt_s, span_s)
    }

    /// [`NoiseModel::from_levels`] with the shortest flicker correlation time `t_min_s`.
    pub fn from_levels_from(
        w: f64,
        f: f64,
        beta: f64,
        q: f64,
        t_min_s: f64,
        dt_s: f64,
        span_s: f64,
    ) -> Self {
        let times = flicker_times(t_min_s, span_s);
        let mid = match (times.first(), times.last()) {
            (Some(a), Some(b)) => (a * b).sqrt(),
            _ => 1.0,
        };
        NoiseModel {
            white_var: w,
            flicker: if f > 0.0 {
                times
                    .iter()
                    .map(|&t| (t, f * (t / mid).powf(beta)))
                    .collect()
            } else {
                Vec::new()
            },
            rw_per_s: q,
            h: [w * dt_s, f, q / 3.0],
            white_scale: None,
        }
    }

    /// Slope β of the flicker components' variances (0 when flat or absent).
    pub fn flicker_slope(&self) -> f64 {
        match (self.flicker.first(), self.flicker.last()) {
            (Some(a), Some(b)) if self.flicker.len() > 1 && a.1 > 0.0 && b.1 > 0.0 => {
                (b.1 / a.1).ln() / (b.0 / a.0).ln()
            }
            _ => 0.0,
        }
    }

    /// Allan deviation of the flicker part at the geometric middle of its correlation times
    /// (its floor when flat), output unit.
    pub fn flicker_floor(&self) -> f64 {
        let (Some(a), Some(b)) = (self.flicker.first(), self.flicker.last()) else {
            return 0.0;
        };
        let tau = (a.0 * b.0).sqrt();
        self.flicker
            .iter()
            .map(|&(t, v)| v * ou_avar(tau, t))
            .sum::<f64>()
            .sqrt()
    }

    /// Fits the noise levels of the residual `x` on rows `idx` by maximum likelihood of its
    /// Kalman innovations (the exact Gaussian likelihood of the state-space model, irregular
    /// spacing and gaps included — no Allan deviation, no grid).
    ///
    /// The overall scale is concentrated out analytically (for levels c·(w, f, q),
    /// −2 ln L = Σe²/(cS) + Σ ln S + n ln c is least at c = Σ(e²/S)/n), so the search is over
    /// ln(f/w) and ln(q·dt/w) in [−30, 25] and the flicker slope β in
    /// [`FLICKER_SLOPE_RANGE`]: a start grid (or the given `start` models: the previous round's,
    /// an Allan fit), then Nelder–Mead; `max_evals` bounds the work.
    ///
    /// For a record whose points have different white variances (bins of unequal counts),
    /// `white_scale` as in [`white_scale_from_counts`]; the fitted model carries it.
    #[allow(clippy::too_many_arguments, clippy::needless_range_loop)] // Nelder–Mead: indices over the D coordinates
    pub fn fit_ml(
        t_s: &[f64],
        idx: &[usize],
        x: &[f64],
        dt_s: f64,
        span_s: f64,
        start: &[&NoiseModel],
        max_evals: usize,
        white_scale: Option<Arc<[f64]>>,
    ) -> NoiseFit {
        let n = idx.len();
        let values: Vec<f64> = idx.iter().map(|&i| x[i]).collect();
        let fail = |why: String| {
            let var = if n > 1 {
                crate::numerics::stats::std(&values).powi(2)
            } else {
                0.0
            };
            NoiseFit {
                model: NoiseModel::white(if var.is_finite() {
                    var.max(1e-300)
                } else {
                    1.0
                }),
                method: METHOD_WHITE_FALLBACK,
                neg2_loglik: f64::NAN,
                evaluations: 0,
                failure: Some(why),
            }
        };
        if n < 8 {
            return fail(format!("only {n} points: too few to fit a noise model"));
        }
        if values.iter().any(|v| !v.is_finite()) {
            return fail("the residual has non-finite values".into());
        }
        let var = crate::numerics::stats::std(&values).powi(2);
        if !(var > 0.0 && var.is_finite()) {
            return fail(format!(
                "the residual's variance is {var:e}: nothing to model"
            ));
        }
        let dt = dt_s.max(1e-9);
        let (b_lo, b_hi) = FLICKER_SLOPE_RANGE;
        let lo = [LN_RATIO_MIN, LN_RATIO_MIN, b_lo, 0.0];
        let hi = [LN_RATIO_MAX, LN_RATIO_MAX, b_hi, LN_T_MIN_MAX];
        let clamp = |p: P| {
            let mut o = p;
            for d in 0..D {
                o[d] = p[d].clamp(lo[d], hi[d]);
            }
            o
        };
        let model_at = |p: P, w: f64| {
            let p = clamp(p);
            let f = if p[0] <= LN_RATIO_MIN + 0.5 {
                0.0
            } else {
                w * p[0].exp()
            };
            let q = if p[1] <= LN_RATIO_MIN + 0.5 {
                0.0
            } else {
                w * p[1].exp() / dt
            };
            NoiseModel::from_levels_from(w, f, p[2], q, dt * p[3].exp(), dt, span_s)
                .with_white_scale(white_scale.clone())
        };
        let mut evals = 0usize;
        // Concentrated −2 ln L at p = (ln f/w, ln q·dt/w, β), and the scale c.
        let likelihood = |p: &P| -> (f64, f64) {
            let m = model_at(*p, var);
            let (q, ld) = innovation_sums(&m, t_s, idx, x);
            let c = q / n as f64;
            let v = n as f64 * (1.0 + c.ln()) + ld;
            (if v.is_finite() { v } else { f64::INFINITY }, c)
        };
        let eval = |p: P, evals: &mut usize| -> (f64, f64) {
            *evals += 1;
            likelihood(&p)
        };
        // Points that do not depend on each other (the start grid, the first simplex, a
        // shrink) are evaluated on all cores: the same numbers, sooner.
        let eval_all = |ps: &[P], evals: &mut usize| -> Vec<f64> {
            *evals += ps.len();
            crate::numerics::parallel::par_map(ps, |p| likelihood(p).0)
        };
        let to_p = |m: &NoiseModel| -> Option<P> {
            let w = m.white_var;
            if w.is_nan() || w <= 0.0 {
                return None;
            }
            let q = if m.rw_per_s > 0.0 {
                (m.rw_per_s * dt / w).ln()
            } else {
                LN_RATIO_MIN
            };
            let (Some(a), Some(b)) = (m.flicker.first(), m.flicker.last()) else {
                return Some(clamp([LN_RATIO_MIN, q, 0.0, 0.0]));
            };
            let beta = m.flicker_slope();
            let mid = (a.0 * b.0).sqrt();
            let f = a.1 / (a.0 / mid).powf(beta);
            Some(clamp([(f / w).ln(), q, beta, (a.0 / dt).ln()]))
        };
        let mut starts: Vec<P> = start.iter().filter_map(|m| to_p(m)).collect();
        let warm = !starts.is_empty();
        if !warm {
            for a in [-12.0, -5.0, 1.0] {
                for b in [-16.0, -8.0, 0.0] {
                    starts.push([a, b, 0.0, 0.0]);
                }
            }
            // A low-passed white noise (a filtered instrument output): one strong fast
            // component at a few spacings.
            for a in [0.0, 4.0] {
                for tm in [1.0, 2.5] {
                    starts.push([a, -16.0, -2.0, tm]);
                }
            }
        }
        let mut best: Option<(P, f64)> = None;
        for (s, v) in starts.iter().zip(eval_all(&starts, &mut evals)) {
            if best.is_none_or(|(_, bv)| v < bv) {
                best = Some((*s, v));
            }
        }
        let Some((x0, f0)) = best else {
            return fail("no starting point".into());
        };
        if !f0.is_finite() {
            return fail("the likelihood is not finite at any starting point".into());
        }
        // Nelder–Mead in D dimensions. Written here rather than taken from argmin on purpose:
        // every trial point is clamped to the box [lo, hi] (argmin's NelderMead is unbounded);
        // the first simplex and each shrink are evaluated as one parallel batch (par_map over
        // Kalman filters, the cost of the discovery); and the budget is a count of likelihood
        // evaluations (ML_EVALS_WARM/COLD in select.rs, 36/110), which is what bounds the
        // discovery's run time, where argmin counts iterations of varying cost. Its result is
        // the discovery's published figures (docs/discovery.md): another minimiser's path would
        // change them.
        let steps: P = if warm {
            [0.7, 0.7, 0.25, 0.3]
        } else {
            [2.0, 2.0, 0.5, 0.7]
        };
        let mut simplex = vec![(x0, f0)];
        let vertices: Vec<P> = (0..D)
            .map(|d| {
                let mut p = x0;
                p[d] += if p[d] + steps[d] > hi[d] {
                    -steps[d]
                } else {
                    steps[d]
                };
                p
            })
            .collect();
        for (p, v) in vertices.iter().zip(eval_all(&vertices, &mut evals)) {
            simplex.push((*p, v));
        }
        while evals < max_evals {
            simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
            let spread = (simplex[D].1 - simplex[0].1).abs();
            let size = (1..=D)
                .flat_map(|i| (0..D).map(move |d| (i, d)))
                .map(|(i, d)| (simplex[i].0[d] - simplex[0].0[d]).abs())
                .fold(0.0, f64::max);
            if spread < 0.05 && size < 0.05 {
                break;
            }
            let mut c = [0.0; D];
            for v in &simplex[..D] {
                for d in 0..D {
                    c[d] += v.0[d] / D as f64;
                }
            }
            let w = simplex[D];
            let along = |t: f64| {
                let mut p = [0.0; D];
                for d in 0..D {
                    p[d] = c[d] + t * (w.0[d] - c[d]);
                }
                clamp(p)
            };
            let r = along(-1.0);
            let fr = eval(r, &mut evals).0;
            if fr < simplex[0].1 {
                let e = along(-2.0);
                let fe = eval(e, &mut evals).0;
                simplex[D] = if fe < fr { (e, fe) } else { (r, fr) };
            } else if fr < simplex[D - 1].1 {
                simplex[D] = (r, fr);
            } else {
                let k = along(if fr < w.1 { -0.5 } else { 0.5 });
                let fk = eval(k, &mut evals).0;
                if fk < w.1.min(fr) {
                    simplex[D] = (k, fk);
                } else {
                    let b = simplex[0].0;
                    for s in simplex.iter_mut().skip(1) {
                        for d in 0..D {
                            s.0[d] = 0.5 * (s.0[d] + b[d]);
                        }
                    }
                    let shrunk: Vec<P> = simplex[1..].iter().map(|s| s.0).collect();
                    for (s, v) in simplex[1..].iter_mut().zip(eval_all(&shrunk, &mut evals)) {
                        s.1 = v;
                    }
                }
            }
        }
        simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
        let (p, v) = simplex[0];
        let (_, c) = eval(p, &mut evals);
        let w = var * c;
        if !(w > 0.0 && w.is_finite() && v.is_finite()) {
            return fail(format!(
                "the likelihood search ended at a non-finite point ({v:e})"
            ));
        }
        NoiseFit {
            model: model_at(p, w),
            method: METHOD_KALMAN_ML,
            neg2_loglik: v,
            evaluations: evals,
            failure: None,
        }
    }
}

/// One subset of the three-term NNLS of [`NoiseModel::fit`]: the weighted least-squares
/// coefficients of the basis terms `active` alone (the others zero) for the points `(τ, measured
/// Allan variance, weight)`, solved through the host's one linear-algebra module
/// (`numerics::linalg::solve_square`, LU with partial pivoting). None when singular, or when a
/// coefficient is negative or not finite: that subset is then no solution of the NNLS.
fn active_terms_fit(
    pts: &[(f64, f64, f64)],
    basis: impl Fn(f64) -> [f64; 3],
    active: &[usize],
) -> Option<[f64; 3]> {
    // Normal equations (k ≤ 3, well scaled by the relative weighting).
    let k = active.len();
    let mut a = vec![vec![0.0f64; k]; k];
    let mut b = vec![0.0f64; k];
    for &(t, m, w) in pts {
        let f = basis(t);
        for (p, &jp) in active.iter().enumerate() {
            let xp = w * f[jp] / m;
            b[p] += xp * w;
            for (q, &jq) in active.iter().enumerate() {
                a[p][q] += xp * w * f[jq] / m;
            }
        }
    }
    let sol = crate::numerics::linalg::solve_square(&a, &b)?;
    if sol.iter().any(|v| *v < 0.0 || !v.is_finite()) {
        return None;
    }
    let mut h = [0.0; 3];
    for (&j, v) in active.iter().zip(sol) {
        h[j] = v;
    }
    Some(h)
}

/// Transition factors `a` and process noise `q` of the model's states over `dt_s` (flicker OU
/// components, then the random walk).
fn transition(model: &NoiseModel, dt_s: f64, a: &mut [f64], q: &mut [f64]) {
    let nf = model.flicker.len();
    for (j, &(tc, v)) in model.flicker.iter().enumerate() {
        a[j] = (-dt_s / tc).exp();
        q[j] = v * (1.0 - a[j] * a[j]);
    }
    a[nf] = 1.0;
    q[nf] = model.rw_per_s * dt_s;
}

/// The Kalman whitening of a noise model on a set of observed rows.
#[derive(Debug, Clone)]
pub struct Whitener {
    /// Observed row indices (increasing).
    pub idx: Vec<usize>,
    /// Number of states.
    k: usize,
    /// The distinct state transitions (k factors each): a regular record has two or three (its
    /// first row, its step, a shorter last bin), and reading one per row would double what the
    /// whitening of each column streams from memory.
    a: Vec<f64>,
    /// Per observed row: which of `a` it takes.
    a_of_row: Vec<u32>,
    /// Per observed row: Kalman gains (k each).
    gain: Vec<f64>,
    /// Per observed row: innovation standard deviation.
    s_sqrt: Vec<f64>,
}

impl Whitener {
    /// Gains of `model` for observations at `t_s[i]` for the rows in `idx`.
    pub fn new(model: &NoiseModel, t_s: &[f64], idx: Vec<usize>) -> Self {
        let mut ric = Riccati::for_rows(model, t_s, &idx);
        let k = ric.k;
        let mut a_all: Vec<f64> = Vec::new();
        let mut a_of_row = Vec::with_capacity(idx.len());
        let mut g_all = Vec::with_capacity(idx.len() * k);
        let mut s_all = Vec::with_capacity(idx.len());
        let mut prev_t: Option<f64> = None;
        for &i in &idx {
            let dt = prev_t.map_or(0.0, |pt| (t_s[i] - pt).max(0.0));
            prev_t = Some(t_s[i]);
            ric.step(dt, i, true);
            // The same transition as one of the last few kept (an irregular record's step
            // lengths alternate), else a new one.
            let kept = a_all.len() / k.max(1);
            let found = (kept.saturating_sub(TRANSITIONS_KEPT)..kept)
                .rev()
                .find(|&j| a_all[j * k..(j + 1) * k] == ric.a[..]);
            a_of_row.push(match found {
                Some(j) => j as u32,
                None => {
                    a_all.extend_from_slice(&ric.a);
                    kept as u32
                }
            });
            let s = ric.s;
            g_all.extend(ric.ph.iter().map(|v| v / s));
            s_all.push(s.sqrt());
        }
        Whitener {
            idx,
            k,
            a: a_all,
            a_of_row,
            gain: g_all,
            s_sqrt: s_all,
        }
    }

    /// Innovations (one-step-ahead prediction errors) of `x` on the observed rows; normalised
    /// by their standard deviation when `normalise`.
    pub fn filter(&self, x: &[f64], normalise: bool) -> Vec<f64> {
        let k = self.k;
        let mut s = vec![0.0; k];
        let mut out = Vec::with_capacity(self.idx.len());
        for (r, (&i, &ai)) in self.idx.iter().zip(&self.a_of_row).enumerate() {
            let ai = ai as usize;
            let a = &self.a[ai * k..(ai + 1) * k];
            let g = &self.gain[r * k..(r + 1) * k];
            let pred = predict_state(&mut s, a);
            let e = x[i] - pred;
            for j in 0..k {
                s[j] += g[j] * e;
            }
            out.push(if normalise { e / self.s_sqrt[r] } else { e });
        }
        out
    }

    /// ln det of the noise covariance on these rows (Σ ln S_t): with the sum of squared
    /// normalised innovations it makes −2 ln L, comparable between noise models.
    pub fn log_det(&self) -> f64 {
        self.s_sqrt.iter().map(|s| 2.0 * s.ln()).sum()
    }

    /// Normalised innovations: the GLS-whitened series.
    pub fn whiten(&self, x: &[f64]) -> Vec<f64> {
        self.filter(x, true)
    }
}

/// Held-out prediction of `x` by the noise model: a Kalman filter over every row that updates
/// its state only on the `observed` rows; at each other row it records the prediction error
/// from the observed rows before it and that prediction's variance. Returns the sum of the
/// squared normalised errors over the held-out rows and their number.
///
/// This is the out-of-sample score that long-memory noise needs: a held-out block is predicted
/// from the training data before it (the further into the block, the larger the predicted
/// variance), so an effect that is smooth — a transient, a slow line — improves it, where a
/// one-step-ahead error computed with every row observed tracks the effect and hardly moves.
pub fn held_out_chi2(
    model: &NoiseModel,
    t_s: &[f64],
    observed: &[bool],
    x: &[f64],
) -> (f64, usize) {
    let h = held_out_prediction(model, t_s, observed, x);
    (h.chi2, h.count)
}

/// Prediction errors of the held-out rows (see [`held_out_chi2`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeldOut {
    /// Σ e²/S over the held-out rows (normalised by the predicted variance).
    pub chi2: f64,
    /// Σ e² over the held-out rows, output unit²: the errors of predicting them from the model
    /// and the training rows before them (with white noise only, the raw residual).
    pub sum_sq: f64,
    /// Held-out rows.
    pub count: usize,
}

/// [`held_out_chi2`] with the unnormalised errors too.
pub fn held_out_prediction(
    model: &NoiseModel,
    t_s: &[f64],
    observed: &[bool],
    x: &[f64],
) -> HeldOut {
    let mut ric = Riccati::new(model);
    let mut state = vec![0.0; ric.k];
    let mut prev_t: Option<f64> = None;
    let (mut chi2, mut sum_sq, mut count) = (0.0, 0.0, 0usize);
    for (i, ((&t, &obs), &xi)) in t_s.iter().zip(observed).zip(x).enumerate() {
        let dt = prev_t.map_or(0.0, |pt| (t - pt).max(0.0));
        prev_t = Some(t);
        ric.step(dt, i, obs);
        let pred = predict_state(&mut state, &ric.a);
        let s = ric.s;
        let e = xi - pred;
        if obs {
            for (st, h) in state.iter_mut().zip(&ric.ph) {
                *st += h / s * e;
            }
        } else {
            chi2 += e * e / s;
            sum_sq += e * e;
            count += 1;
        }
    }
    HeldOut {
        chi2,
        sum_sq,
        count,
    }
}

/// Prediction errors of the rows after the `observed` (training) rows, block by block: the
/// rows not observed are cut into blocks of `block_rows`, and each block is predicted from
/// every row before it — the training rows and the earlier blocks, whose readings the filter
/// then takes in — its predicted variance growing through the block, as in
/// [`held_out_chi2`]. Returns the errors of all blocks.
///
/// Why not the whole rest from the training rows alone ([`held_out_prediction`]): with a random
/// walk or flicker in the noise, the forecast's variance grows with the distance from the last
/// training row, and on the far rows the forecast error is the noise's own wander since then,
/// which a deterministic effect correlates with by chance. Those rows add to the score without
/// judging the effect (measured on the real gravimeter residual: a relay loop of ΔBIC −451,
/// injected, made the single-forecast score worse even with the injected column itself, 0.677 →
/// 0.690, better at 4 of its 5 cuts). Predicting each block from the readings before it keeps
/// every row's error at the block's horizon, as the blocked cross-validation does, while the
/// effect's coefficients still come from the training part only.
pub fn blocked_forward_prediction(
    model: &NoiseModel,
    t_s: &[f64],
    observed: &[bool],
    x: &[f64],
    block_rows: usize,
) -> HeldOut {
    let block_rows = block_rows.max(1);
    let mut ric = Riccati::new(model);
    let mut state = vec![0.0; ric.k];
    let mut prev_t: Option<f64> = None;
    let (mut chi2, mut sum_sq, mut count) = (0.0, 0.0, 0usize);
    // Rows of the current block still to come; at 0 the next unobserved row starts a block.
    let mut left = 0usize;
    let n = t_s.len().min(observed.len()).min(x.len());
    for i in 0..n {
        if !observed[i] && left == 0 {
            // The block predicted from here without its readings.
            let (mut r2, mut st2, mut pt2) = (ric.clone(), state.clone(), prev_t);
            let end = (i + block_rows).min(n);
            for j in (i..end).filter(|&j| !observed[j]) {
                let dt = pt2.map_or(0.0, |pt| (t_s[j] - pt).max(0.0));
                pt2 = Some(t_s[j]);
                r2.step(dt, j, false);
                let e = x[j] - predict_state(&mut st2, &r2.a);
                chi2 += e * e / r2.s;
                sum_sq += e * e;
                count += 1;
            }
            left = end - i;
        }
        // Every row's reading is then taken in: the next block is predicted from it.
        let dt = prev_t.map_or(0.0, |pt| (t_s[i] - pt).max(0.0));
        prev_t = Some(t_s[i]);
        ric.step(dt, i, true);
        let e = x[i] - predict_state(&mut state, &ric.a);
        for (st, h) in state.iter_mut().zip(&ric.ph) {
            *st += h / ric.s * e;
        }
        left = left.saturating_sub(1);
    }
    HeldOut {
        chi2,
        sum_sq,
        count,
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A deterministic standard normal sequence (Box–Muller on a 64-bit LCG); eiv's tests use it
    /// too.
    pub(crate) fn normals(n: usize, mut seed: u64) -> Vec<f64> {
        let mut u = move || {
            seed = seed
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            ((seed >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        (0..n)
            .map(|_| (-2.0 * u().ln()).sqrt() * (2.0 * std::f64::consts::PI * u()).cos())
            .collect()
    }

    /// (PHᵀ, S) of every step and −2 ln L of `x` through the filter `ric` over `idx`.
    fn filter_trace(mut ric: Riccati, t: &[f64], idx: &[usize], x: &[f64]) -> (Vec<f64>, f64) {
        let mut st = vec![0.0; ric.k];
        let (mut trace, mut n2ll) = (Vec::new(), 0.0);
        let mut prev: Option<f64> = None;
        for &i in idx {
            ric.step(prev.map_or(0.0, |p| t[i] - p), i, true);
            prev = Some(t[i]);
            let mut pred = 0.0;
            for (s, f) in st.iter_mut().zip(&ric.a) {
                *s *= f;
                pred += *s;
            }
            let e = x[i] - pred;
            for (s, h) in st.iter_mut().zip(&ric.ph) {
                *s += h / ric.s * e;
            }
            n2ll += e * e / ric.s + ric.ln_s;
            trace.extend_from_slice(&ric.ph);
            trace.push(ric.s);
        }
        (trace, n2ll)
    }

    #[test]
    fn the_rank_two_recursion_of_a_regular_pass_is_the_full_riccati_recursion() {
        // 20 000 rows at 71 s (a regular binned record): flicker from 71 s to 3× the span, with
        // and without a random walk, and white alone; each also with a last bin of 68 samples
        // (its mean 69.5 s after the one before, its white variance 71/68 of the others').
        // Every step's PHᵀ and S of the low-rank mode against the full O(k²) update, and the
        // likelihood of a series through both.
        let (n, dt) = (20_000, 71.0);
        let regular: Vec<f64> = (0..n).map(|i| i as f64 * dt).collect();
        let mut short_last = regular.clone();
        short_last[n - 1] -= 1.5;
        let idx: Vec<usize> = (0..n).collect();
        let x = normals(n, 7);
        let mut scale = vec![1.0; n];
        scale[n - 1] = 71.0 / 68.0;
        let scale: Arc<[f64]> = scale.into();
        for base in [
            NoiseModel::from_levels(1.0, 0.3, -0.2, 1e-6, dt, n as f64 * dt),
            NoiseModel::from_levels(1.0, 2.0, 0.5, 0.0, dt, n as f64 * dt),
            NoiseModel::from_levels(1.0, 0.0, 0.0, 1e-5, dt, n as f64 * dt),
        ] {
            for (t, m) in [
                (&regular, base.clone()),
                (
                    &short_last,
                    base.clone().with_white_scale(Some(scale.clone())),
                ),
            ] {
                let fast = Riccati::for_rows(&m, t, &idx);
                assert!(fast.low_rank.is_some());
                let (a, la) = filter_trace(fast, t, &idx, &x);
                let (b, lb) = filter_trace(Riccati::new(&m), t, &idx, &x);
                let worst = a
                    .chunks(m.flicker.len() + 2)
                    .zip(b.chunks(m.flicker.len() + 2))
                    .flat_map(|(p, q)| {
                        let s = q[q.len() - 1];
                        p.iter().zip(q).map(move |(u, v)| (u - v).abs() / s)
                    })
                    .fold(0.0, f64::max);
                assert!(worst < 1e-9, "largest relative difference {worst:e}");
                assert!((la - lb).abs() < 1e-9 * lb.abs(), "{la} against {lb}");
                // The likelihood goes through the low-rank mode (sums in another order).
                assert!((neg2_loglik(&m, t, &idx, &x) - la).abs() < 1e-12 * la.abs());
            }
        }
        // A gap or a row of another white variance before the last keeps the full update.
        let mut gapped = idx.clone();
        gapped.remove(500);
        let m = NoiseModel::from_levels(1.0, 0.3, -0.2, 1e-6, dt, n as f64 * dt);
        assert!(Riccati::for_rows(&m, &regular, &gapped).low_rank.is_none());
        let mut scale = vec![1.0; n];
        scale[700] = 0.5;
        let scaled = m.clone().with_white_scale(Some(scale.into()));
        assert!(Riccati::for_rows(&scaled, &regular, &idx)
            .low_rank
            .is_none());
    }

    #[test]
    fn likelihood_fit_recovers_white_and_random_walk_levels_on_an_irregular_record() {
        // White σ = 1 and a random walk of 0.01²/s, sampled at alternating 60/90 s (the binned
        // records that the Allan-deviation fit could not place on a grid).
        let n = 4000;
        let mut t = Vec::with_capacity(n);
        let mut now = 0.0;
        for i in 0..n {
            t.push(now);
            now += if i % 2 == 0 { 60.0 } else { 90.0 };
        }
        let (w, rw) = (normals(n, 1), normals(n, 2));
        let q: f64 = 1e-4;
        let mut walk = 0.0;
        let x: Vec<f64> = (0..n)
            .map(|i| {
                if i > 0 {
                    walk += (q * (t[i] - t[i - 1])).sqrt() * rw[i];
                }
                walk + w[i]
            })
            .collect();
        let idx: Vec<usize> = (0..n).collect();
        let f = NoiseModel::fit_ml(&t, &idx, &x, 75.0, t[n - 1], &[], 110, None);
        assert_eq!(f.method, METHOD_KALMAN_ML, "{:?}", f.failure);
        let m = &f.model;
        assert!((m.white_var.sqrt() - 1.0).abs() < 0.1, "{m:?}");
        assert!((m.rw_per_s / q - 1.0).abs() < 0.5, "{m:?}");
        // The flicker part is negligible against both on every time scale of the record.
        assert!(m.flicker_floor() < 0.3, "{m:?}");
    }

    #[test]
    fn bins_of_unequal_counts_get_the_white_variance_of_their_count() {
        // Bin means of 1 and 2 samples alternately (72 000 one-minute rows binned to 50 000
        // points), white noise σ = 1 per sample: a bin of n samples has variance 1/n.
        let n = 6000;
        let counts: Vec<f64> = (0..n).map(|i| if i % 2 == 0 { 1.0 } else { 2.0 }).collect();
        let t: Vec<f64> = (0..n).map(|i| 86.4 * i as f64).collect();
        let x: Vec<f64> = normals(n, 9)
            .iter()
            .zip(&counts)
            .map(|(z, c)| z / c.sqrt())
            .collect();
        let idx: Vec<usize> = (0..n).collect();
        let scale = white_scale_from_counts(&counts);
        assert!(scale.is_some());
        let scaled = NoiseModel::fit_ml(&t, &idx, &x, 86.4, t[n - 1], &[], 110, scale);
        let plain = NoiseModel::fit_ml(&t, &idx, &x, 86.4, t[n - 1], &[], 110, None);
        assert_eq!(scaled.method, METHOD_KALMAN_ML, "{:?}", scaled.failure);
        // The white level is that of a bin of the mean count (1.5 samples): 1/1.5.
        let w = scaled.model.white_var;
        assert!((w * 1.5 - 1.0).abs() < 0.1, "{w}");
        // The likelihood tells the two apart: Δ(−2 ln L) ≈ n·(ln 0.75 − ½ ln 0.5) ≈ 350
        // expected (its spread ≈ 40).
        assert!(
            plain.neg2_loglik - scaled.neg2_loglik > 200.0,
            "{} vs {}",
            plain.neg2_loglik,
            scaled.neg2_loglik
        );
        // Whitened with the scaled model, both kinds of bin have unit variance.
        let e = Whitener::new(&scaled.model, &t, idx.clone()).whiten(&x);
        let var_of = |parity: usize| {
            let v: Vec<f64> = e.iter().skip(parity).step_by(2).copied().collect();
            v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64
        };
        assert!((var_of(0) - 1.0).abs() < 0.1, "{}", var_of(0));
        assert!((var_of(1) - 1.0).abs() < 0.1, "{}", var_of(1));
        // Equal counts: no factors at all (the steady-state filter stays exact and fast).
        assert!(white_scale_from_counts(&[3.0; 10]).is_none());
    }

    #[test]
    fn likelihood_fit_of_a_residual_with_no_variance_fails_loudly() {
        let t: Vec<f64> = (0..100).map(f64::from).collect();
        let f = NoiseModel::fit_ml(
            &t,
            &(0..100).collect::<Vec<_>>(),
            &[3.0; 100],
            1.0,
            99.0,
            &[],
            50,
            None,
        );
        assert_eq!(f.method, METHOD_WHITE_FALLBACK);
        assert!(f.failure.is_some());
    }

    #[test]
    fn the_steady_state_gain_gives_the_likelihood_of_the_full_riccati_recursion() {
        // Regular spacing (the gain converges and is then held) against the same record with
        // spacings jittered by 1e-7 (never equal: every step runs the full recursion).
        let n = 6000;
        let x = normals(n, 5);
        let t: Vec<f64> = (0..n).map(|i| 10.0 * i as f64).collect();
        let tj: Vec<f64> = t
            .iter()
            .enumerate()
            .map(|(i, v)| v * (1.0 + 1e-7 * ((i % 3) as f64 - 1.0) / (i as f64 + 1.0)))
            .collect();
        let m = NoiseModel::from_levels_from(1.0, 0.3, -0.5, 1e-5, 10.0, 10.0, 6e4);
        let idx: Vec<usize> = (0..n).collect();
        let (a, b) = (
            neg2_loglik(&m, &t, &idx, &x),
            neg2_loglik(&m, &tj, &idx, &x),
        );
        assert!((a - b).abs() < 1e-6 * a.abs(), "{a} vs {b}");
        let (wa, wb) = (
            Whitener::new(&m, &t, idx.clone()).whiten(&x),
            Whitener::new(&m, &tj, idx.clone()).whiten(&x),
        );
        let d = wa
            .iter()
            .zip(&wb)
            .map(|(p, q)| (p - q).abs())
            .fold(0.0, f64::max);
        assert!(d < 1e-5, "{d}");
    }

    #[test]
    fn held_out_rows_of_a_random_walk_are_predicted_by_the_last_observed_value() {
        // Pure random walk, white noise negligible: the prediction at a held-out row is the last
        // observed value, its variance q·(time since it).
        let model = NoiseModel {
            rw_per_s: 1.0,
            ..NoiseModel::white(1e-20)
        };
        let t: Vec<f64> = (0..6).map(f64::from).collect();
        let x = [0.0, 1.0, 3.0, 7.0, 2.0, 2.0];
        let observed = [true, true, false, false, true, true];
        let (chi2, n) = held_out_chi2(&model, &t, &observed, &x);
        // Row 2: (3 − 1)²/1, row 3: (7 − 1)²/2.
        assert_eq!(n, 2);
        assert!((chi2 - (4.0 + 18.0)).abs() < 1e-9, "{chi2}");
    }

    #[test]
    fn each_forward_block_is_predicted_from_every_reading_before_it() {
        // Pure random walk, white noise negligible: a row of a block is predicted by the last
        // reading before the block (a training row or the earlier block's last), its variance
        // q·(time since that reading).
        let model = NoiseModel {
            rw_per_s: 1.0,
            ..NoiseModel::white(1e-20)
        };
        let t: Vec<f64> = (0..7).map(f64::from).collect();
        let x = [0.0, 1.0, 3.0, 7.0, 2.0, 5.0, 4.0];
        let training = [true, true, false, false, false, false, false];
        let h = blocked_forward_prediction(&model, &t, &training, &x, 2);
        // Block 2–3 from row 1 (1): (3 − 1)²/1 + (7 − 1)²/2; block 4–5 from row 3 (7):
        // (2 − 7)²/1 + (5 − 7)²/2; block 6 from row 5 (5): (4 − 5)²/1.
        assert_eq!(h.count, 5);
        assert!(
            (h.chi2 - (4.0 + 18.0 + 25.0 + 2.0 + 1.0)).abs() < 1e-9,
            "{}",
            h.chi2
        );
        assert!(
            (h.sum_sq - (4.0 + 36.0 + 25.0 + 4.0 + 1.0)).abs() < 1e-9,
            "{}",
            h.sum_sq
        );
    }

    #[test]
    fn one_block_of_the_whole_rest_is_the_single_forecast_of_the_rest() {
        // White + flicker + random walk on an irregular grid: with blocks longer than the rest,
        // the block-by-block prediction is the one forecast of the rest from the training rows.
        let model = NoiseModel::from_levels_from(1.0, 0.3, -0.5, 1e-5, 10.0, 10.0, 6e4);
        let n = 300;
        let t: Vec<f64> = (0..n).map(|i| 10.0 * i as f64 + (i % 3) as f64).collect();
        let x = normals(n, 7);
        let training: Vec<bool> = (0..n).map(|i| i < 180).collect();
        let single = held_out_prediction(&model, &t, &training, &x);
        let blocked = blocked_forward_prediction(&model, &t, &training, &x, n);
        assert_eq!(blocked.count, single.count);
        assert!(
            (blocked.chi2 - single.chi2).abs() <= 1e-9 * single.chi2,
            "{} vs {}",
            blocked.chi2,
            single.chi2
        );
        // Shorter blocks take the later readings in: the far rows are no longer predicted from
        // row 179 alone, and the score changes.
        let short = blocked_forward_prediction(&model, &t, &training, &x, 10);
        assert_eq!(short.count, single.count);
        assert!((short.chi2 - single.chi2).abs() > 1e-3 * single.chi2);
    }

    #[test]
    fn ou_allan_variance_has_the_random_walk_and_white_limits() {
        // τ ≪ T: like a random walk of diffusion 2v/T → σ² = 2τ/(3T).
        let t_c = 1.0e4;
        assert!((ou_avar(1.0, t_c) / (2.0 / (3.0 * t_c)) - 1.0).abs() < 1e-3);
        // τ ≫ T: like white noise with h_w = 2vT → σ² = 2T/τ.
        assert!((ou_avar(1.0e8, 10.0) / (2.0 * 10.0 / 1.0e8) - 1.0).abs() < 1e-3);
    }

    #[test]
    fn fit_recovers_the_three_allan_coefficients_of_a_synthetic_curve() {
        let (dt, span) = (10.0, 2.0e5);
        let times = flicker_times(dt, span);
        let truth = [4e-12, 1e-13, 2e-17];
        let pts: Vec<(f64, f64)> = (0..13)
            .map(|e| {
                let t = dt * 2f64.powi(e);
                let v = truth[0] / t + truth[1] * flicker_avar(t, &times) + truth[2] * t;
                (t, v.sqrt())
            })
            .collect();
        let m = NoiseModel::fit(&pts, dt, span).expect("fit");
        for (h, want) in m.h.iter().zip(truth) {
            assert!((h / want - 1.0).abs() < 1e-6, "{:?}", m.h);
        }
    }

    #[test]
    fn white_noise_whitening_is_a_scaling_and_a_random_walk_is_differenced() {
        let t: Vec<f64> = (0..5).map(f64::from).collect();
        let w = Whitener::new(&NoiseModel::white(4.0), &t, (0..5).collect());
        assert_eq!(
            w.whiten(&[2.0, 4.0, 6.0, 0.0, -2.0]),
            vec![1.0, 2.0, 3.0, 0.0, -1.0]
        );
        // A strong random walk with a tiny white part: innovations → first differences (the
        // walk starts at 0 with no uncertainty: the level is the regression's offset column).
        let rw = NoiseModel {
            rw_per_s: 1.0,
            ..NoiseModel::white(1e-12)
        };
        let w = Whitener::new(&rw, &t, (0..5).collect());
        let e = w.filter(&[0.0, 2.0, 5.0, 9.0, 14.0], false);
        let want = [0.0, 2.0, 3.0, 4.0, 5.0];
        for (a, b) in e.iter().zip(want) {
            assert!((a - b).abs() < 1e-6, "{e:?}");
        }
    }
}
