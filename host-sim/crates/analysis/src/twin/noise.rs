//! The instrument noise the members draw.

use super::*;

/// Adds one draw of the fitted noise model at the instants `t` (white per point, each flicker
/// component an OU process advanced over the actual spacing, the random walk).
pub(super) fn add_model_noise(out: &mut [f64], t: &[f64], m: &NoiseModel, seed: u64) {
    let mut rng = stream(seed, TWIN_NOISE_STREAM);
    let white = m.white_var.max(0.0).sqrt();
    let mut x: Vec<f64> = m
        .flicker
        .iter()
        .map(|&(_, v)| v.max(0.0).sqrt() * gauss(&mut rng))
        .collect();
    let mut walk = 0.0;
    let mut last = t.first().copied().unwrap_or(0.0);
    for (y, &ti) in out.iter_mut().zip(t) {
        let dt = (ti - last).max(0.0);
        last = ti;
        let mut f = 0.0;
        for (xc, &(tau, v)) in x.iter_mut().zip(&m.flicker) {
            if dt > 0.0 {
                let phi = (-dt / tau).exp();
                *xc = phi * *xc + (v.max(0.0) * (1.0 - phi * phi)).sqrt() * gauss(&mut rng);
            }
            f += *xc;
        }
        walk += (m.rw_per_s.max(0.0) * dt).sqrt() * gauss(&mut rng);
        *y += white * gauss(&mut rng) + f + walk;
    }
}

/// Ratio between successive flicker correlation times (as `noise::Flicker`).
const FLICKER_RATIO: f64 = 3.162_277_660_168_379_5;

/// Adds white + flicker + random-walk noise with the Allan levels `p` at the (irregular)
/// instants `t`: each flicker component and the walk are advanced exactly over the actual
/// spacing (an OU process sampled at any instants is an AR(1) with φ = e^{−Δ/τ}); the white
/// part is that of a sample averaged over the nominal spacing `dt_s`.
pub(super) fn add_noise(out: &mut [f64], t: &[f64], dt_s: f64, p: &AllanParams, seed: u64) {
    let mut rng = stream(seed, TWIN_NOISE_STREAM);
    let span = (t.last().copied().unwrap_or(0.0) - t.first().copied().unwrap_or(0.0)).max(dt_s);
    let white = p.white_adev_1s / dt_s.max(1e-9).sqrt();
    // Flicker components: correlation times from Δ to 10× the span, equal variances.
    let mut taus = Vec::new();
    if p.flicker_floor > 0.0 {
        let mut tau = dt_s;
        while tau <= 10.0 * span * FLICKER_RATIO {
            taus.push(tau);
            tau *= FLICKER_RATIO;
        }
    }
    let v = p.flicker_floor.powi(2) * FLICKER_RATIO.ln() / (2.0 * std::f64::consts::LN_2);
    let sd = v.sqrt();
    let mut x: Vec<f64> = taus.iter().map(|_| sd * gauss(&mut rng)).collect();
    let mut walk = 0.0;
    let mut last = t.first().copied().unwrap_or(0.0);
    for (y, &ti) in out.iter_mut().zip(t) {
        let dt = (ti - last).max(0.0);
        last = ti;
        let mut f = 0.0;
        for (xc, tau) in x.iter_mut().zip(&taus) {
            if dt > 0.0 {
                let phi = (-dt / tau).exp();
                *xc = phi * *xc + sd * (1.0 - phi * phi).sqrt() * gauss(&mut rng);
            }
            f += *xc;
        }
        walk += p.random_walk_per_sqrt_s * dt.sqrt() * gauss(&mut rng);
        *y += white * gauss(&mut rng) + f + walk;
    }
}
