//! Out-of-sample scores of a model with fixed columns: blocked cross-validation (held-out
//! blocks predicted from the others) and forward chaining (the rest of the record predicted from
//! its first part), both through the noise model's forecast.

use super::baseline::{gls, raw_residual, Rows};
use super::current_model::{fit_state, NoiseChoice};
use super::import::Dataset;
use super::noise::{blocked_forward_prediction, held_out_prediction, HeldOut, NoiseModel};
use super::select::Config;

/// Cross-validated errors of a model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CvScore {
    /// RMS of the held-out rows' prediction errors, output unit: the model fitted on the
    /// training rows plus the noise model's forecast from the training rows before each held-out
    /// row (with white noise alone, the raw held-out residual). Not the raw residual itself: with
    /// random-walk or flicker noise the raw held-out residual is mostly the unmodelled wander
    /// (its level is set by wherever the GLS puts the offset), and a real effect can raise it —
    /// on the gMetrology residual that refused steps of ΔBIC −512 (docs/discovery.md).
    pub raw: f64,
    /// RMS of the held-out residual's prediction errors from the training rows before them,
    /// each normalised by its predicted standard deviation (noise model; dimensionless, 1 for
    /// a residual that is exactly the modelled noise).
    pub prediction_z: f64,
}

/// Blocked cross-validation of a model (columns fixed).
pub fn cross_validate(
    ds: &Dataset,
    cols: &[Vec<f64>],
    y: &[f64],
    noise: &NoiseModel,
    cfg: &Config,
) -> CvScore {
    let n = y.len();
    let nb = (cfg.folds * cfg.blocks_per_fold).max(2);
    let fold_of = |i: usize| (i * nb / n) % cfg.folds;
    // The folds are independent: fitted on all cores, summed in fold order.
    let folds: Vec<usize> = (0..cfg.folds).collect();
    let held_out = crate::numerics::parallel::par_map(&folds, |&f| {
        let train: Vec<bool> = (0..n).map(|i| fold_of(i) != f).collect();
        let rows = Rows::with_noise(noise, &ds.t_s, Some(&train));
        if rows.idx.len() < cols.len() + 2 {
            return None;
        }
        let fit = gls(cols, y, 0.0, &rows);
        let r = raw_residual(cols, &fit.beta, y);
        Some(held_out_prediction(noise, &ds.t_s, &train, &r))
    });
    score(held_out.into_iter().flatten())
}

/// The score of the held-out predictions of all folds or splits, summed in their order.
fn score(held_out: impl Iterator<Item = HeldOut>) -> CvScore {
    let (mut s_raw, mut s_z, mut count) = (0.0, 0.0, 0usize);
    for h in held_out {
        s_raw += h.sum_sq;
        s_z += h.chi2;
        count += h.count;
    }
    CvScore {
        raw: (s_raw / count.max(1) as f64).sqrt(),
        prediction_z: (s_z / count.max(1) as f64).sqrt(),
    }
}

/// Times at which the record is cut for forward-chaining validation (fractions of the span).
pub const FORWARD_SPLITS: [f64; 5] = [0.5, 0.6, 0.7, 0.8, 0.9];

/// Forward-chaining validation: for each split, the model (columns fixed) is fitted on the
/// rows before it and the rows after it are predicted — the noise model's Kalman filter
/// carries the training residual's state forward, its predicted variance growing with the
/// distance — and scored like [`cross_validate`]: raw residual RMS over the predicted rows and
/// RMS of the normalised prediction errors.
pub fn forward_validate(ds: &Dataset, cols: &[Vec<f64>], y: &[f64], noise: &NoiseModel) -> CvScore {
    let splits = forward_residuals(ds, cols, y, noise);
    score(
        splits
            .iter()
            .map(|(train, r)| held_out_prediction(noise, &ds.t_s, train, r)),
    )
}

/// For each cut of [`FORWARD_SPLITS`] with enough rows on both sides, the training rows and
/// the residual of the model fitted on them (columns fixed).
fn forward_residuals(
    ds: &Dataset,
    cols: &[Vec<f64>],
    y: &[f64],
    noise: &NoiseModel,
) -> Vec<(Vec<bool>, Vec<f64>)> {
    let n = y.len();
    let t0 = ds.t_s.first().copied().unwrap_or(0.0);
    let span = ds.span_s();
    FORWARD_SPLITS
        .iter()
        .filter_map(|f| {
            let cut = t0 + f * span;
            let train: Vec<bool> = ds.t_s.iter().map(|&t| t < cut).collect();
            let rows = Rows::with_noise(noise, &ds.t_s, Some(&train));
            if rows.idx.len() < cols.len() + 2 || rows.idx.len() >= n {
                return None;
            }
            let fit = gls(cols, y, 0.0, &rows);
            Some((train, raw_residual(cols, &fit.beta, y)))
        })
        .collect()
}

/// Forward chaining judged block by block: for each split of [`FORWARD_SPLITS`], the model
/// (columns fixed) is fitted on the rows before it, and the rows after it are cut into the
/// blocked cross-validation's blocks (`folds × blocks_per_fold` over the record), each predicted
/// from every reading before it through the noise model ([`blocked_forward_prediction`]); scored
/// like [`cross_validate`]. The effect's coefficients are out of sample (from the part before
/// the cut), and every error is at the horizon of one block, not of the whole rest. The
/// selection judges every effect but a drift or a step by it; [`forward_validate`]'s single
/// forecast of the rest is what the report gives as the gain in predicting the rest.
pub fn forward_validate_blocked(
    ds: &Dataset,
    cols: &[Vec<f64>],
    y: &[f64],
    noise: &NoiseModel,
    cfg: &Config,
) -> CvScore {
    let block_rows = forward_block_rows(y.len(), cfg);
    score(
        forward_residuals(ds, cols, y, noise)
            .iter()
            .map(|(train, r)| blocked_forward_prediction(noise, &ds.t_s, train, r, block_rows)),
    )
}

/// The rows of a block of [`forward_validate_blocked`]: those of the blocked cross-validation's.
fn forward_block_rows(n: usize, cfg: &Config) -> usize {
    n.div_ceil((cfg.folds * cfg.blocks_per_fold).max(2))
}

/// [`forward_validate`] and [`forward_validate_blocked`] from one fit per split.
pub fn forward_validate_both(
    ds: &Dataset,
    cols: &[Vec<f64>],
    y: &[f64],
    noise: &NoiseModel,
    cfg: &Config,
) -> (CvScore, CvScore) {
    let block_rows = forward_block_rows(y.len(), cfg);
    let splits = forward_residuals(ds, cols, y, noise);
    (
        score(
            splits
                .iter()
                .map(|(train, r)| held_out_prediction(noise, &ds.t_s, train, r)),
        ),
        score(
            splits
                .iter()
                .map(|(train, r)| blocked_forward_prediction(noise, &ds.t_s, train, r, block_rows)),
        ),
    )
}

/// Whether any of `cols` still changes after the first forward cut (by more than 10⁻³ of its
/// range over the record): an effect that does not (a warm-up of hours in a record of days)
/// gives forward chaining nothing to predict.
pub fn supported_after_first_cut(ds: &Dataset, cols: &[Vec<f64>]) -> bool {
    let cut = ds.t_s.first().copied().unwrap_or(0.0) + FORWARD_SPLITS[0] * ds.span_s();
    let first = ds.t_s.partition_point(|&t| t < cut);
    let range = |v: &[f64]| {
        let (lo, hi) = v
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| {
                (l.min(x), h.max(x))
            });
        hi - lo
    };
    cols.iter()
        .any(|c| c.len() > first && range(&c[first..]) > 1e-3 * range(c))
}

/// Out-of-sample gain of the baseline extended by given effects at fixed nonlinear parameters
/// (used by the tests to compare with the discovered model): relative reduction of the
/// cross-validated residual std, with φ from the baseline.
pub fn gain_with(
    ds: &Dataset,
    target: &[f64],
    base_cols: &[Vec<f64>],
    extra: &[Vec<f64>],
    cfg: &Config,
) -> f64 {
    let (cur0, _, _) = fit_state(ds, base_cols, target, NoiseChoice::Fit(None));
    let before = cross_validate(ds, base_cols, target, &cur0.noise.model, cfg);
    let mut cols = base_cols.to_vec();
    cols.extend(extra.iter().cloned());
    let after = cross_validate(ds, &cols, target, &cur0.noise.model, cfg);
    1.0 - after.raw / before.raw
}
