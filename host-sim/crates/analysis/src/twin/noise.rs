//! The instrument noise the members draw.

use super::*;

/// Random stream of the twin's instrument noise (the simulator's member noise stream).
const TWIN_NOISE_STREAM: u64 = crate::sim::twin::NOISE_STREAM;

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
    let taus: Vec<f64> = m.flicker.iter().map(|&(tau, _)| tau).collect();
    add_ou_sum(
        out,
        t,
        &mut rng,
        white,
        (&mut x, &taus),
        |c, phi| (m.flicker[c].1.max(0.0) * (1.0 - phi * phi)).sqrt(),
        |dt| (m.rw_per_s.max(0.0) * dt).sqrt(),
    );
}

/// Adds white noise (σ `white` per point), the OU components `x` (initial states, correlation
/// times `taus`) and a random walk at the instants `t`: each component advances exactly over
/// the actual spacing, x ← φx + innovation(c, φ)·N(0,1) with φ = e^{−Δ/τ} (an OU process
/// sampled at any instants is an AR(1)), the walk by walk_sd(Δ)·N(0,1).
fn add_ou_sum(
    out: &mut [f64],
    t: &[f64],
    rng: &mut crate::sim::noise::SimRng,
    white: f64,
    (x, taus): (&mut [f64], &[f64]),
    innovation: impl Fn(usize, f64) -> f64,
    walk_sd: impl Fn(f64) -> f64,
) {
    let mut walk = 0.0;
    let mut last = t.first().copied().unwrap_or(0.0);
    for (y, &ti) in out.iter_mut().zip(t) {
        let dt = (ti - last).max(0.0);
        last = ti;
        let mut f = 0.0;
        for (c, (xc, &tau)) in x.iter_mut().zip(taus).enumerate() {
            if dt > 0.0 {
                let phi = (-dt / tau).exp();
                *xc = phi * *xc + innovation(c, phi) * gauss(rng);
            }
            f += *xc;
        }
        walk += walk_sd(dt) * gauss(rng);
        *y += white * gauss(rng) + f + walk;
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
    add_ou_sum(
        out,
        t,
        &mut rng,
        white,
        (&mut x, &taus),
        |_, phi| sd * (1.0 - phi * phi).sqrt(),
        |dt| p.random_walk_per_sqrt_s * dt.sqrt(),
    );
}
