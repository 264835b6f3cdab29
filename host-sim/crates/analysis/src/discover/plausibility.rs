//! Whether a flexible effect is physically plausible, beyond buying likelihood.
//!
//! A flexible column (the 24-width Preisach distribution of `thermal_hysteresis`) can take the
//! shape of almost any leftover that correlates with the temperature programme: in null logs
//! with white + 1/f flicker + random-walk noise it was accepted at 0.04–0.26 µg with ΔBIC
//! −50 … −600, far below the noise at the time scale it acts on. Two checks that do not depend
//! on the likelihood's charge for freedom:
//!
//! 1. **Above the noise floor at its own time scale** ([`noise_floor`]): the fitted
//!    contribution's Allan deviation must exceed the noise model's at some averaging time τ
//!    of the record's octave grid. A bias that never stands above the noise at any τ is not
//!    a cause the record shows, whatever a many-parameter fit makes of it: a loop of branch
//!    half-width h switching every T has σ_A(T) ≈ √2·h, so a 1 µg loop on a 0.5–1 µg flicker
//!    floor passes, a 0.2 µg one does not.
//! 2. **Better than the simpler explanation out of sample** ([`simpler_than`]): a loop must
//!    predict held-out blocks better than a first-order thermal lag (two parameters, one
//!    mechanism). When it does not, the lag is the explanation the record supports.

use super::effects::Effect;
use super::import::Dataset;
use super::noise::NoiseModel;

/// The contribution's Allan deviation against the noise model's, at the τ where it stands
/// highest above it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Floor {
    /// Averaging time, s.
    pub tau_s: f64,
    /// The contribution's Allan deviation there, output unit.
    pub effect_adev: f64,
    /// The noise model's Allan deviation there, output unit.
    pub noise_adev: f64,
}

impl Floor {
    /// The contribution over the noise (≥ 1: above the floor).
    pub fn ratio(&self) -> f64 {
        self.effect_adev / self.noise_adev.max(f64::MIN_POSITIVE)
    }
}

/// Least ratio of a flexible effect's Allan deviation to the noise model's at its best τ.
pub const FLOOR_RATIO_MIN: f64 = 1.0;

/// The effects whose freedom is large enough to absorb noise, so they must pass [`noise_floor`].
/// A gain on a channel's rate is not one: its column is fixed by the channel as read (the rate
/// band-limited to where the channel stands above its reading noise, `rate`), one linear gain
/// and no width to tune, so its ΔBIC charges all its freedom; and on a thermostat's controller
/// noise its contribution is as broadband as the output's noise (0.99× its Allan deviation at
/// best for ≈ 3 µg rms, ΔBIC −870), which this check would refuse whatever the evidence.
pub fn is_flexible(e: &Effect) -> bool {
    matches!(e, Effect::ThermalHysteresis)
}

/// The simpler physical explanations a flexible effect, or a higher-order transfer function,
/// must beat out of sample: a loop the first-order lag; a second-order lag of a channel that
/// channel's first-order lag (measured: a first-order lag of 24 min on a one-rate programme was
/// named `lag2_coupling` with τ 1253 s and a coefficient 0.58 × the true one without it).
pub fn simpler_than(e: &Effect, ds: &super::import::Dataset) -> Vec<Effect> {
    match e {
        Effect::ThermalHysteresis => vec![Effect::ThermalLag],
        Effect::Lag2Coupling(c) => {
            use super::import::ChannelKind;
            let is = |k: ChannelKind| ds.channel(k).is_some_and(|ch| &ch.name == c);
            if is(ChannelKind::Temperature) {
                vec![Effect::ThermalLag]
            } else if is(ChannelKind::Pressure) {
                vec![Effect::PressureAdmittance]
            } else {
                vec![Effect::AmbientCoupling(c.clone())]
            }
        }
        // A gain on the rate is the limit of the channel's first-order lag as τ → 0 (L_τ[c] − c
        // ≈ −τ·dc/dt): on a slow cycle the lag at its own τ must not predict the held-out blocks
        // as well (measured: a 24-min lag on a one-rate cycle named a rate coupling without it).
        Effect::RateCoupling(c) => {
            use super::import::ChannelKind;
            if ds
                .channel(ChannelKind::Temperature)
                .is_some_and(|ch| &ch.name == c)
            {
                vec![Effect::ThermalLag]
            } else if ds
                .channel(ChannelKind::Pressure)
                .is_some_and(|ch| &ch.name == c)
            {
                Vec::new()
            } else {
                vec![Effect::AmbientCoupling(c.clone())]
            }
        }
        _ => Vec::new(),
    }
}

/// The contribution's Allan deviation against `noise`'s on the record's octave τ grid (the
/// same estimator as the residual's: gaps placed on the time grid); `None` when no τ fits.
pub fn noise_floor(ds: &Dataset, contribution: &[f64], noise: &NoiseModel) -> Option<Floor> {
    super::residual::adev(ds, contribution)
        .into_iter()
        .filter(|(tau, dev)| *tau > 0.0 && dev.is_finite())
        .map(|(tau_s, effect_adev)| Floor {
            tau_s,
            effect_adev,
            noise_adev: model_avar(noise, ds.dt_s, tau_s).max(0.0).sqrt(),
        })
        .max_by(|a, b| a.ratio().total_cmp(&b.ratio()))
}

/// The noise model's Allan variance at `tau_s` from its state-space levels (white of variance
/// `white_var` per point of spacing `dt_s`, the flicker components, the random walk), so that a
/// model without fitted Allan coefficients (the white fallback) has its floor too.
pub fn model_avar(noise: &NoiseModel, dt_s: f64, tau_s: f64) -> f64 {
    let f: f64 = noise
        .flicker
        .iter()
        .map(|&(t, v)| v * super::noise::ou_avar(tau_s, t))
        .sum();
    noise.white_var * dt_s / tau_s + f + noise.rw_per_s * tau_s / 3.0
}

/// Why a flexible effect's fitted contribution is not above the noise, if it is not.
pub fn below_floor(ds: &Dataset, contribution: &[f64], noise: &NoiseModel) -> Option<String> {
    let f = noise_floor(ds, contribution, noise)?;
    (f.ratio() < FLOOR_RATIO_MIN).then(|| {
        format!(
            "its contribution never stands above the noise: at best (τ = {:.0} s) its Allan \
             deviation is {:.3e} against the noise model's {:.3e} ({:.2}×, at least \
             {FLOOR_RATIO_MIN} needed) — a flexible column fitting the noise, not a cause",
            f.tau_s,
            f.effect_adev,
            f.noise_adev,
            f.ratio()
        )
    })
}

/// Contiguous blocks of the record for [`jackknife_gain`]: a variance from 19 degrees of freedom
/// (its square root known to about ±16 %), each block 5 % of the record, long against the memory
/// the noise model's whitening leaves (the decisions measured with 10, 40 and 100 blocks were the
/// same: docs/discovery-causes.md).
pub const JACKKNIFE_BLOCKS: usize = 20;

/// A gain's significance measured by its scatter over the record's time blocks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JackknifeGain {
    /// The gain on the whole record (GLS under the noise model).
    pub gain: f64,
    /// Its standard error from the noise model (whitened residual scale).
    pub se_model: f64,
    /// Its delete-one-block jackknife standard error over [`JACKKNIFE_BLOCKS`] blocks.
    pub se_jackknife: f64,
}

impl JackknifeGain {
    /// (gain / jackknife standard error)²: the gain's χ² measured off the record itself.
    pub fn chi2(&self) -> f64 {
        (self.gain / self.se_jackknife.max(f64::MIN_POSITIVE)).powi(2)
    }
}

/// The gain of the last column of `cols` (the others beside it) and its delete-one-block
/// jackknife standard error: the record cut into [`JACKKNIFE_BLOCKS`] contiguous blocks, the
/// GLS under `noise` repeated with each block left out (its rows unobserved in the Kalman
/// whitening), var = (G − 1)/G · Σ(β₍ᵦ₎ − β̄)². It does not rest on the noise model being right:
/// where the model under-describes the noise in the column's band, or the gain rests on a few
/// events, the blocks' gains scatter more than the model's standard error says. `None` when a
/// block leaves too few rows.
pub fn jackknife_gain(
    ds: &Dataset,
    cols: &[Vec<f64>],
    target: &[f64],
    noise: &NoiseModel,
) -> Option<JackknifeGain> {
    jackknife_gain_of(ds, cols, target, noise, cols.len().checked_sub(1)?)
}

/// [`jackknife_gain`] of the gain of column `at` (a coupling with columns after its gain: a
/// rate's timing within the row).
pub fn jackknife_gain_of(
    ds: &Dataset,
    cols: &[Vec<f64>],
    target: &[f64],
    noise: &NoiseModel,
    at: usize,
) -> Option<JackknifeGain> {
    use super::baseline::{gls, Rows};
    let n = target.len();
    let k = cols.len();
    if at >= k || n < JACKKNIFE_BLOCKS * (k + 2) {
        return None;
    }
    let full = gls(cols, target, 0.0, &Rows::with_noise(noise, &ds.t_s, None));
    let blocks: Vec<usize> = (0..JACKKNIFE_BLOCKS).collect();
    let gains = crate::numerics::parallel::par_map(&blocks, |&b| {
        let keep: Vec<bool> = (0..n).map(|i| i * JACKKNIFE_BLOCKS / n != b).collect();
        gls(
            cols,
            target,
            0.0,
            &Rows::with_noise(noise, &ds.t_s, Some(&keep)),
        )
        .beta[at]
    });
    let g = JACKKNIFE_BLOCKS as f64;
    let mean = gains.iter().sum::<f64>() / g;
    let var = (g - 1.0) / g * gains.iter().map(|x| (x - mean).powi(2)).sum::<f64>();
    Some(JackknifeGain {
        gain: full.beta[at],
        se_model: full.se[at],
        se_jackknife: var.sqrt(),
    })
}

/// Two candidates of one round whose ΔBIC differ by less than this explain the data equally
/// (the lag-or-loop margin of `hysteresis`).
pub const AMBIGUOUS_DBIC: f64 = super::hysteresis::LAG_OR_LOOP_DBIC;

/// ... when their fitted shapes (projections of the whitened residual on each, off the current
/// model) overlap by at least this (cosine): they explain the same part of the residual.
pub const AMBIGUOUS_OVERLAP: f64 = 0.8;

/// An accepted effect that another cause explains equally: reported as "ambiguous: A or B".
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Ambiguity {
    /// The other cause.
    pub other: String,
    /// Its ΔBIC in the round the effect was accepted in.
    pub other_delta_bic: f64,
    /// Its parameters fitted in the effect's place.
    pub other_parameters: Vec<(String, super::effects::Param)>,
    /// Cosine between the two fitted shapes (whitened, off the current model).
    pub overlap: f64,
    /// What measurement would separate them.
    pub separates: String,
}

/// The fitted shape of `cols` (whitened and off the current model) in the whitened residual
/// `r_w`: the residual's projection on their span (Gram–Schmidt).
pub fn fitted_shape(cols: &[Vec<f64>], r_w: &[f64]) -> Vec<f64> {
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let mut q: Vec<Vec<f64>> = Vec::new();
    for c in cols {
        let mut v = c.clone();
        for b in &q {
            let k = dot(&v, b);
            v.iter_mut().zip(b).for_each(|(x, y)| *x -= k * y);
        }
        let nv = dot(&v, &v).sqrt();
        if nv > 0.0 && nv.is_finite() {
            q.push(v.into_iter().map(|x| x / nv).collect());
        }
    }
    let mut p = vec![0.0; r_w.len()];
    for b in &q {
        let k = dot(r_w, b);
        p.iter_mut().zip(b).for_each(|(x, y)| *x += k * y);
    }
    p
}

/// Cosine between two fitted shapes (0 when either is zero).
pub fn overlap(a: &[f64], b: &[f64]) -> f64 {
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let d = (dot(a, a) * dot(b, b)).sqrt();
    if d > 0.0 {
        dot(a, b) / d
    } else {
        0.0
    }
}

/// What measurement would tell two causes apart.
pub fn separating_measurement(a: &Effect, b: &Effect) -> String {
    use Effect::*;
    let pair = |x: &Effect, y: &Effect| {
        (std::mem::discriminant(a) == std::mem::discriminant(x)
            && std::mem::discriminant(b) == std::mem::discriminant(y))
            || (std::mem::discriminant(a) == std::mem::discriminant(y)
                && std::mem::discriminant(b) == std::mem::discriminant(x))
    };
    if pair(&ThermalLag, &ThermalHysteresis) {
        "temperature ramps of different rates (a lag's offset scales with the rate, a loop's \
         does not) or a hold after a ramp (a lag settles, a loop stays on its branch)"
            .into()
    } else if pair(&ThermalLag, &RateCoupling(String::new()))
        || pair(
            &AmbientCoupling(String::new()),
            &RateCoupling(String::new()),
        )
        || pair(&Lag2Coupling(String::new()), &RateCoupling(String::new()))
    {
        "a change of the channel's rate held for longer than the lag (a step in the ramp rate, or \
         a ramp that stops and holds): a rate coupling follows the new rate at once and vanishes \
         on the hold, a lag settles over its τ"
            .into()
    } else if pair(&ThermalLag, &Lag2Coupling(String::new()))
        || pair(
            &AmbientCoupling(String::new()),
            &Lag2Coupling(String::new()),
        )
    {
        "a step of the channel (a first-order lag responds at once, a second-order one starts \
         with zero slope)"
            .into()
    } else if pair(&Warmup, &AgingDrift)
        || pair(&Warmup, &CreepDrift)
        || pair(&AgingDrift, &CreepDrift)
    {
        "a longer record (an exponential settles, a logarithm keeps growing, a power law \
         accelerates or settles as t^p)"
            .into()
    } else if pair(&TiltCoupling, &BuildingTilt) || pair(&TiltCoupling, &TidalTilt) {
        "a tilt excursion off the solar day (a deliberate tilt of the pier or the mount)".into()
    } else if pair(&Step { duration_s: 0.0 }, &Warmup)
        || pair(&Step { duration_s: 0.0 }, &AgingDrift)
    {
        "a record that continues past the change (a step holds its level, a drift goes on)".into()
    } else {
        format!(
            "a record in which the {} and {} columns differ more than here",
            a.name(),
            b.name()
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::lcg::Lcg;

    /// `n` standard normal deviates (sum of 12 uniforms) from the LCG seeded with `state`.
    fn normals(n: usize, state: u64) -> Vec<f64> {
        let mut g = Lcg(state);
        (0..n).map(|_| g.normal()).collect()
    }

    fn white(var: f64) -> NoiseModel {
        NoiseModel::white(var)
    }

    #[test]
    fn two_columns_fitting_the_same_leftover_overlap_and_an_orthogonal_one_does_not() {
        let n = 400;
        let r: Vec<f64> = (0..n).map(|i| (i as f64 * 0.05).sin()).collect();
        let a = vec![r.clone()];
        // Nearly the same shape (a small phase shift): overlap near 1.
        let b = vec![(0..n)
            .map(|i| (i as f64 * 0.05 + 0.1).sin())
            .collect::<Vec<_>>()];
        // An orthogonal one (a cosine over whole cycles would be; a constant here) explains little.
        let c = vec![vec![1.0; n]];
        let (pa, pb, pc) = (
            fitted_shape(&a, &r),
            fitted_shape(&b, &r),
            fitted_shape(&c, &r),
        );
        assert!(overlap(&pa, &pb) > 0.99, "{}", overlap(&pa, &pb));
        assert!(overlap(&pa, &pc) > 0.0 && overlap(&pa, &pc) < AMBIGUOUS_OVERLAP);
        assert!(
            separating_measurement(&Effect::ThermalHysteresis, &Effect::ThermalLag)
                .contains("different rates")
        );
    }

    #[test]
    fn the_jackknife_agrees_with_the_model_on_a_spread_gain_and_not_on_one_resting_on_a_block() {
        let n = 4000;
        let t: Vec<f64> = (0..n).map(|i| 60.0 * i as f64).collect();
        let e = normals(n, 0x5EED);
        let x = normals(n, 0xBEEF);
        // A gain of 0.1 on a column spread over the record, in white noise the model describes:
        // the blocks' scatter is the model's standard error (within the ±16 % of 19 degrees of
        // freedom, ×2 for a margin).
        let y: Vec<f64> = x.iter().zip(&e).map(|(x, e)| 0.1 * x + e).collect();
        let ds = Dataset::test_g(t.clone(), y.clone(), 60.0);
        let j = jackknife_gain(&ds, &[vec![1.0; n], x.clone()], &y, &white(1.0)).expect("fit");
        let ratio = j.se_jackknife / j.se_model;
        assert!((0.68..1.32).contains(&ratio), "{j:?}");
        assert!(j.chi2() > 20.0, "{j:?}");
        // A column that is small except in one short stretch, where the output follows it: the
        // model's standard error sees n rows, the gain rests on the one block, and leaving that
        // block out leaves a gain of ≈ 0 — its jackknife error is far above the model's.
        let (a, b) = (1000, 1010);
        let mut z: Vec<f64> = x.iter().map(|v| 0.05 * v).collect();
        for (i, v) in z.iter_mut().enumerate().take(b).skip(a) {
            *v = if i % 2 == 0 { 1.0 } else { -1.0 };
        }
        let mut y2 = e.clone();
        for i in a..b {
            y2[i] += 3.0 * z[i];
        }
        let ds2 = Dataset::test_g(t, y2.clone(), 60.0);
        let j2 = jackknife_gain(&ds2, &[vec![1.0; n], z], &y2, &white(1.0)).expect("fit");
        assert!(j2.se_jackknife > 3.0 * j2.se_model, "{j2:?}");
    }

    #[test]
    fn a_square_wave_stands_above_white_noise_of_its_size_but_not_one_tenth_of_it() {
        // ±1 switching every 100 samples, 60 s spacing; white noise σ = 1 per sample has
        // σ_A(6000 s) = 1/√100 = 0.1, the wave's σ_A(6000 s) = √2.
        let n = 4000;
        let t: Vec<f64> = (0..n).map(|i| 60.0 * i as f64).collect();
        let sq: Vec<f64> = (0..n)
            .map(|i| if (i / 100) % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let ds = Dataset::test_g(t, vec![0.0; n], 60.0);
        let f = noise_floor(&ds, &sq, &white(1.0)).expect("floor");
        assert!(f.ratio() > 5.0, "{f:?}");
        assert!(below_floor(&ds, &sq, &white(1.0)).is_none());
        // The same wave at 1 % against white noise of σ 1 is nowhere above it (σ_A of the
        // noise at the longest τ ≈ 1/√(n/2) ≈ 0.022, the wave's ≤ 0.014).
        let small: Vec<f64> = sq.iter().map(|v| 0.01 * v).collect();
        let why = below_floor(&ds, &small, &white(1.0)).expect("refused");
        assert!(why.contains("never stands above the noise"), "{why}");
    }
}
