//! Many change points at once: a bistable sensor, repeated tares.
//!
//! The greedy selection adds one effect per round and validates it alone; a bias that flips up
//! and back down every few days is refused step by step (one flip alone does not predict the
//! rest of the record, where the level has come back). Here the residual is segmented first
//! and the set of change points is then validated together (ΔBIC with every step's charge,
//! blocked cross-validation and forward prediction, in `select`).
//!
//! Segmentation: a moving-sum (MOSUM) scan at several bandwidths w ∈ [`WINDOWS`]: at every
//! row j the jump J_w(j) = mean(r[j..j+w]) − mean(r[j−w..j]) is compared with its noise under
//! the fitted noise model — white + flicker + random walk, not white: the difference of two
//! adjacent w-point means has variance 2·σ²_A(w·Δt), the model's Allan variance — so
//! z = J/σ_J. A row is a change point when z² exceeds the look-elsewhere threshold for
//! [`FALSE_ALARM`] over n·(bandwidths) trials (Bonferroni over every row and bandwidth; over
//! n/w effectively independent positions per bandwidth instead, white noise of 3000 rows gave a
//! point in 50 of 200 records, with every row 7 of 200) and no larger |z| lies within the
//! bandwidth; the points are taken greedily by |z|, each excluding its ± w neighbourhood.

use super::import::Dataset;
use super::noise::NoiseModel;

/// Bandwidths of the scan, points.
pub const WINDOWS: [usize; 4] = [4, 12, 36, 108];

/// Probability that the scan finds any point in a record of pure modelled noise (the set is
/// then validated again, so the scan may be a little liberal).
pub const FALSE_ALARM: f64 = 0.05;

/// At most this many change points in a set.
pub const MAX_POINTS: usize = 24;

/// One change point found by the scan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChangePoint {
    /// First row of the new level.
    pub index: usize,
    /// Time of the change (midway between the rows either side), s.
    pub time_s: f64,
    /// Local jump (mean after − mean before over `window` points), output unit.
    pub jump: f64,
    /// The jump over its noise σ_J.
    pub z: f64,
    /// Bandwidth it was found at, points.
    pub window: usize,
}

/// The change points of `resid` under `noise` (sorted by time).
pub fn segment(ds: &Dataset, resid: &[f64], noise: &NoiseModel) -> Vec<ChangePoint> {
    let n = resid.len();
    let mut cum = vec![0.0; n + 1];
    for (i, r) in resid.iter().enumerate() {
        cum[i + 1] = cum[i] + r;
    }
    let mean = |a: usize, b: usize| (cum[b] - cum[a]) / (b - a) as f64;
    let windows: Vec<usize> = WINDOWS.iter().copied().filter(|&w| 4 * w <= n).collect();
    let trials: f64 = (n * windows.len()) as f64;
    if windows.is_empty() || trials < 2.0 {
        return Vec::new();
    }
    // z² above x has probability ≈ √(2/(πx))·e^(−x/2) (χ²₁ tail): x with `trials` of them
    // summing to FALSE_ALARM.
    let a = 2.0 * (trials / FALSE_ALARM).ln();
    let threshold = a - (std::f64::consts::PI * a / 2.0).ln();
    let mut hits: Vec<ChangePoint> = Vec::new();
    for &w in &windows {
        let sigma = (2.0 * super::plausibility::model_avar(noise, ds.dt_s, w as f64 * ds.dt_s))
            .max(0.0)
            .sqrt();
        if sigma <= 0.0 || !sigma.is_finite() {
            continue;
        }
        let z: Vec<f64> = (0..n)
            .map(|j| {
                if j < w || j + w > n {
                    0.0
                } else {
                    (mean(j, j + w) - mean(j - w, j)) / sigma
                }
            })
            .collect();
        for j in w..=n - w {
            let zj = z[j].abs();
            // A local maximum of |z| over ± w, above the threshold.
            if zj * zj > threshold && z[j - w..(j + w).min(n)].iter().all(|v| v.abs() <= zj) {
                hits.push(ChangePoint {
                    index: j,
                    time_s: 0.5 * (ds.t_s[j - 1] + ds.t_s[j]),
                    jump: z[j] * sigma,
                    z: z[j],
                    window: w,
                });
            }
        }
    }
    hits.sort_by(|a, b| b.z.abs().total_cmp(&a.z.abs()));
    let mut out: Vec<ChangePoint> = Vec::new();
    for h in hits {
        if out.len() >= MAX_POINTS {
            break;
        }
        if out
            .iter()
            .all(|o| o.index.abs_diff(h.index) > o.window.max(h.window))
        {
            out.push(h);
        }
    }
    out.sort_by_key(|c| c.index);
    out
}

/// A set of change points proposed as steps, with its evidence.
pub(super) struct StepSet {
    /// The steps' times, s.
    pub times_s: Vec<f64>,
    /// Their columns (abrupt steps).
    pub cols: Vec<Vec<f64>>,
    /// ΔBIC of the whole set under the noise model re-fitted with it, against the same re-fit
    /// without it.
    pub delta_bic: f64,
    /// Penalty of the set (size and position of every step).
    pub penalty: f64,
}

/// The set of change points of the current residual, pruned and scored together: the scan's
/// points as abrupt steps, fitted jointly (GLS under the current noise model); the step with
/// the smallest t² is dropped while that t² is below one step's charge (ln n for its size,
/// max(ln n, 2 ln n) for its position searched over every row — the single step's charge), and
/// first any point `is_step(time, size)` refuses;
/// then the full likelihood with the noise re-fitted. `None` with fewer than two points left
/// (one step is the greedy selection's own candidate).
pub(super) fn propose(
    cur: &super::current_model::Current,
    cols: &[Vec<f64>],
    target: &[f64],
    cur_raw: &[f64],
    is_step: impl Fn(f64, f64) -> bool,
) -> Option<StepSet> {
    use super::baseline::{gls, Rows};
    use super::current_model::{fit_state, NoiseChoice};
    let ds = cur.ds;
    let n = target.len() as f64;
    let per_step = n.ln() + n.ln().max(2.0 * n.ln());
    let step_cols = |times: &[f64]| -> Vec<Vec<f64>> {
        times
            .iter()
            .map(|&t| super::effects::step_column(&ds.t_s, t, 0.0))
            .collect()
    };
    let scan = |noise: &NoiseModel| -> Vec<f64> {
        segment(ds, cur_raw, noise)
            .iter()
            .map(|c| c.time_s)
            .collect()
    };
    // The current noise model was fitted to a residual that still holds the jumps (its random
    // walk took them in), which hides them: the noise is re-fitted with the points found in
    // the model and the residual scanned again (twice at most, or until the set stands).
    let mut noise = cur.noise.model.clone();
    let mut times = scan(&noise);
    for _ in 0..2 {
        if times.is_empty() {
            break;
        }
        let mut trial = cols.to_vec();
        trial.extend(step_cols(&times));
        noise = fit_state(ds, &trial, target, NoiseChoice::Fit(Some(&noise)))
            .0
            .noise
            .model;
        let again = scan(&noise);
        if again == times {
            break;
        }
        times = again;
    }
    let rows = Rows::with_noise(&noise, &ds.t_s, None);
    while times.len() >= 2 {
        let mut trial = cols.to_vec();
        trial.extend(step_cols(&times));
        let fit = gls(&trial, target, 0.0, &rows);
        let k0 = cols.len();
        let (worst, t2) = (0..times.len())
            .map(|i| (i, (fit.beta[k0 + i] / fit.se[k0 + i]).powi(2)))
            .min_by(|a, b| a.1.total_cmp(&b.1))?;
        // A point whose record does not jump there (a glitch that comes back, a smooth change
        // cut into steps: `select`'s local-jump test of a single step) goes first.
        let glitch = (0..times.len()).find(|&i| !is_step(times[i], fit.beta[k0 + i]));
        if let Some(g) = glitch {
            times.remove(g);
            continue;
        }
        if t2.is_finite() && t2 >= per_step {
            break;
        }
        times.remove(worst);
    }
    if times.len() < 2 {
        return None;
    }
    let set_cols = step_cols(&times);
    let mut trial = cols.to_vec();
    trial.extend(set_cols.iter().cloned());
    let warm = NoiseChoice::Fit(Some(&noise));
    let with = fit_state(ds, &trial, target, warm).0.neg2_loglik();
    let without = fit_state(ds, cols, target, warm).0.neg2_loglik();
    let penalty = times.len() as f64 * per_step;
    Some(StepSet {
        delta_bic: with - without + penalty,
        penalty,
        times_s: times,
        cols: set_cols,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};

    #[test]
    fn three_unequal_jumps_in_white_noise_are_found_where_they_are_and_nothing_else() {
        let n = 3000;
        let t: Vec<f64> = (0..n).map(|i| 60.0 * i as f64).collect();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let steps = [(700, 2.0), (1500, -3.5), (2300, 1.2)];
        let r: Vec<f64> = (0..n)
            .map(|i| {
                let e: f64 = StandardNormal.sample(&mut rng);
                e * 0.3
                    + steps
                        .iter()
                        .filter(|(k, _)| i >= *k)
                        .map(|(_, s)| s)
                        .sum::<f64>()
            })
            .collect();
        let ds = Dataset::test_g(t, r.clone(), 60.0);
        let cps = segment(&ds, &r, &NoiseModel::white(0.09));
        for (k, size) in steps {
            assert!(
                cps.iter()
                    .any(|c| c.index.abs_diff(k) <= 2 && (c.jump - size).abs() < 0.4),
                "{k}: {cps:?}"
            );
        }
        assert_eq!(cps.len(), 3, "{cps:?}");
        // Pure noise: nothing above the threshold (|z| ≈ 4.6 for 12 000 trials).
        let e: Vec<f64> = (0..n)
            .map(|_| {
                let e: f64 = StandardNormal.sample(&mut rng);
                0.3 * e
            })
            .collect();
        assert!(segment(&ds, &e, &NoiseModel::white(0.09)).is_empty());
    }
}
