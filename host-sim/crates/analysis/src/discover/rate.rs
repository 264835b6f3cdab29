//! The rate of a measured channel for `rate_coupling`, band-limited to where the channel stands
//! above its own reading noise.
//!
//! # Why
//!
//! A coupling to the rate of a channel is fitted on the rate of its reading, and the reading
//! carries white reading noise: differencing multiplies it by 1/Δt, and a regression on a noisy
//! regressor attenuates the gain by S_signal/(S_signal + S_noise) (errors in variables). A moving
//! average cuts the noise but also the signal: on a thermostat's controller noise (correlation
//! ≈ 15 min) a ±15 min average keeps 0.1–0.3 of the gain. A Wiener filter
//! S_signal/(S_signal + S_noise) is exact only with the true noise level; with the level
//! estimated from the record its error passes into the gain.
//!
//! So the rate is kept only at the frequencies where the reading's smoothed periodogram stands
//! above [`BAND_MARGIN`] × its white floor, with gain 1 there and 0 elsewhere. Inside that band
//! the reading noise is at most 1/[`BAND_MARGIN`] of the power, so it attenuates the gain by at
//! most that; outside it the regressor is 0, which removes those frequencies from the fit
//! without biasing the gain. The floor is taken from the channel itself as the lowest mean of
//! the periodogram over bands of 10 % of the frequency in the upper three quarters of the spectrum: a mean
//! of signal + noise is never below the noise, so the floor errs high (a narrower band: more
//! variance, no bias), not low (noise let into the band: bias).

/// How far above its white floor the channel's smoothed periodogram must stand for a frequency
/// to be kept: the gain is attenuated by at most 1/(1 + margin) there.
pub const BAND_MARGIN: f64 = 10.0;

/// Shortest segment whose rate is band-limited; a shorter one contributes its mean slope.
pub const MIN_SEGMENT: usize = 32;

/// The rate of `v` (unit per second) band-limited as in the module's description, per
/// contiguous segment (`seg_start` true at each segment's first sample), centred.
pub fn band_limited_rate(v: &[f64], t: &[f64], seg_start: &[bool]) -> Vec<f64> {
    let n = v.len();
    let mut out = vec![0.0; n];
    let mut a = 0;
    while a < n {
        let mut b = a + 1;
        while b < n && !seg_start[b] {
            b += 1;
        }
        let dt = if b - a > 1 {
            (t[b - 1] - t[a]) / (b - a - 1) as f64
        } else {
            0.0
        };
        if dt > 0.0 {
            out[a..b].copy_from_slice(&segment_rate(&v[a..b], dt));
        }
        a = b;
    }
    let m = out.iter().sum::<f64>() / n.max(1) as f64;
    out.into_iter().map(|x| x - m).collect()
}

/// One evenly spaced segment, the band kept (weight 1 where the smoothed periodogram stands
/// above [`BAND_MARGIN`] × the white floor, 0 elsewhere).
fn segment_rate(w: &[f64], dt: f64) -> Vec<f64> {
    filtered_rate(w, dt, |p| {
        let floor = white_floor(p);
        move |ps| if ps <= BAND_MARGIN * floor { 0.0 } else { 1.0 }
    })
}

/// The rate (unit per second) of one evenly spaced segment `w`, `dt` s apart, weighted per
/// frequency: linear trend out (its slope is a constant rate, added back), even extension (the
/// periodic FFT sees no jump at the ends), the per-bin periodogram (E = σ² for white noise of
/// variance σ²) handed to `weights`, which returns the weight of a bin from its periodogram
/// smoothed over ±max(j/10, 2) bins; then the central difference's transfer function
/// i·sin(ωΔt)/Δt. A segment shorter than [`MIN_SEGMENT`] gives its mean slope.
pub fn filtered_rate<W, G>(w: &[f64], dt: f64, weights: W) -> Vec<f64>
where
    W: FnOnce(&[f64]) -> G,
    G: Fn(f64) -> f64,
{
    let n = w.len();
    let tm = (n as f64 - 1.0) / 2.0;
    let m = w.iter().sum::<f64>() / n as f64;
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for (i, v) in w.iter().enumerate() {
        sxy += (i as f64 - tm) * (v - m);
        sxx += (i as f64 - tm).powi(2);
    }
    let slope = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    if n < MIN_SEGMENT {
        return vec![slope / dt; n];
    }
    let d: Vec<f64> = w
        .iter()
        .enumerate()
        .map(|(i, v)| v - m - slope * (i as f64 - tm))
        .collect();
    let mut z: Vec<f64> = d.iter().chain(d.iter().rev()).copied().collect();
    let big = z.len();
    let x = crate::numerics::fft::half_spectrum(&mut z);
    let p: Vec<f64> = x
        .iter()
        .map(|(a, b)| (a * a + b * b) / big as f64)
        .collect();
    let k = p.len();
    let weight = weights(&p);
    let mut half: Vec<(f64, f64)> = (0..k)
        .map(|j| {
            let band = (j / 10).max(2);
            let (a, b) = (j.saturating_sub(band).max(1), (j + band + 1).min(k));
            let ps = p[a..b].iter().sum::<f64>() / (b - a).max(1) as f64;
            let g = if j == 0 { 0.0 } else { weight(ps) };
            if g == 0.0 {
                return (0.0, 0.0);
            }
            let om = std::f64::consts::TAU * j as f64 / (big as f64 * dt);
            let s = (om * dt).sin() / dt * g;
            let (re, im) = x[j];
            (-im * s, re * s)
        })
        .collect();
    half.push((0.0, 0.0));
    let r = crate::numerics::fft::real_from_half_spectrum(&half);
    r.iter()
        .take(n)
        .map(|v| v / big as f64 + slope / dt)
        .collect()
}

/// The white floor of a periodogram `p` (per-bin power, bins 0..k): the lowest mean over bands
/// of 10 % of the frequency in its upper three quarters (see the module's description: it errs high).
pub fn white_floor(p: &[f64]) -> f64 {
    let k = p.len();
    let mut best = f64::INFINITY;
    let mut j = (k / 4).max(1);
    while j < k {
        let e = (j + (j / 10).max(1)).min(k);
        let m = p[j..e].iter().sum::<f64>() / (e - j) as f64;
        best = best.min(m);
        j = e;
    }
    if best.is_finite() {
        best
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sine well above white reading noise: its rate comes back with its amplitude (the band
    /// holds it), and the noise's rate does not (the band leaves it out).
    #[test]
    fn a_slow_sine_under_reading_noise_keeps_its_rate_amplitude() {
        let (n, dt) = (4096, 60.0);
        let period = 86_400.0 / 4.0;
        let w = std::f64::consts::TAU / period;
        let mut lcg = crate::numerics::lcg::Lcg(0x1234_5678);
        let t: Vec<f64> = (0..n).map(|i| i as f64 * dt).collect();
        let v: Vec<f64> = t
            .iter()
            .map(|x| 0.5 * (w * x).sin() + 0.005 * lcg.normal())
            .collect();
        let seg: Vec<bool> = (0..n).map(|i| i == 0).collect();
        let r = band_limited_rate(&v, &t, &seg);
        let truth: Vec<f64> = t.iter().map(|x| 0.5 * w * (w * x).cos()).collect();
        let num: f64 = r.iter().zip(&truth).map(|(a, b)| a * b).sum();
        let den: f64 = truth.iter().map(|b| b * b).sum();
        let gain = num / den;
        assert!((gain - 1.0).abs() < 0.02, "gain {gain}");
        let resid: f64 = r
            .iter()
            .zip(&truth)
            .map(|(a, b)| (a - gain * b).powi(2))
            .sum();
        // The raw central difference's noise: 0.005·√2/(2Δt) per sample.
        let raw_noise = 0.005 * 2f64.sqrt() / (2.0 * dt);
        assert!((resid / n as f64).sqrt() < 0.2 * raw_noise);
    }
}
