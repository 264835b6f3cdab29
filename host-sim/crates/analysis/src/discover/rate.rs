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
//! without biasing the gain. The floor is the white level N of the fit N + A·(2 sin(ω/2))^(−α)
//! to the periodogram's upper three quarters ([`reading_floor`]): white reading noise under a
//! power law, which is what a sampled thermostat's controller noise (an AR(1), α = 2 above its
//! corner) or a programme's slow ramps (A ≈ 0) look like there. On controller noise of tens of
//! mK/min read with ≈ 1 mK the lowest band mean of that part is still signal, and a floor taken
//! there would stop the band at a fifth of the frequencies. A white signal component at the top
//! of the spectrum is not told from reading noise by any spectrum: the floor is then taken too
//! high, and the band stops early.
//!
//! # The timing within a row
//!
//! A rate taken on rows has a position in its row: a backward difference (u_i − u_{i−1})/Δt
//! dates it half a row early against the centred one, and their difference (1 − cos ωΔt)/Δt
//! is even in time and as large as the rate itself near the Nyquist frequency (a simulator that
//! steps its coupling with the previous row, a logger that averages over the interval before
//! its time stamp). So the rate comes with a second column, that even part band-limited the
//! same way ([`RateColumns::timing`]): b·(rate + p·timing) is the gain b at position p in the
//! row (p = 1 backward, 0 centred, −1 forward), and the two columns are orthogonal (odd and even
//! in time), so p's error is the ratio of the two gains' errors.

/// How far above its white floor the channel's smoothed periodogram must stand for a frequency
/// to be kept: the gain is attenuated by at most 1/(1 + margin) there.
pub const BAND_MARGIN: f64 = 10.0;

/// Shortest segment whose rate is band-limited; a shorter one contributes its mean slope.
pub const MIN_SEGMENT: usize = 32;

/// The timing column is fitted only when its rms is at least this fraction of the rate's: below
/// that a position of one row moves the coupling's contribution by less than this, which the
/// gain's own error on such a channel (slow ramps: the timing column is ≈ ωΔt/2 of the rate)
/// holds, and a second column would be charged ln n for nothing.
pub const TIMING_MIN_RATIO: f64 = 0.1;

/// The band-limited rate of a channel (unit per second) and its timing column (module
/// description), per contiguous segment, each with its mean removed.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RateColumns {
    /// The centred rate.
    pub rate: Vec<f64>,
    /// The even part (1 − cos ωΔt)/Δt of the same band: backward − centred rate.
    pub timing: Vec<f64>,
}

impl RateColumns {
    /// rms of the timing column over rms of the rate (0 for a rate of 0).
    pub fn timing_ratio(&self) -> f64 {
        let ss = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>();
        let r = ss(&self.rate);
        if r > 0.0 {
            (ss(&self.timing) / r).sqrt()
        } else {
            0.0
        }
    }
}

/// The rate of `v` (unit per second) band-limited as in the module's description, per
/// contiguous segment (`seg_start` true at each segment's first sample), centred.
pub fn band_limited_rate(v: &[f64], t: &[f64], seg_start: &[bool]) -> Vec<f64> {
    band_limited_rates(v, t, seg_start).rate
}

/// [`band_limited_rate`] and its timing column.
pub fn band_limited_rates(v: &[f64], t: &[f64], seg_start: &[bool]) -> RateColumns {
    let n = v.len();
    let mut out = RateColumns {
        rate: vec![0.0; n],
        timing: vec![0.0; n],
    };
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
            let (r, e) = segment_rates(&v[a..b], dt);
            out.rate[a..b].copy_from_slice(&r);
            out.timing[a..b].copy_from_slice(&e);
        }
        a = b;
    }
    let centre = |v: &mut Vec<f64>| {
        let m = v.iter().sum::<f64>() / n.max(1) as f64;
        v.iter_mut().for_each(|x| *x -= m);
    };
    centre(&mut out.rate);
    centre(&mut out.timing);
    out
}

/// One evenly spaced segment, the band kept (weight 1 where the smoothed periodogram stands
/// above [`BAND_MARGIN`] × the reading floor, 0 elsewhere): (rate, timing).
fn segment_rates(w: &[f64], dt: f64) -> (Vec<f64>, Vec<f64>) {
    filtered_rates(w, dt, |p| {
        let floor = reading_floor(p);
        move |ps| if ps <= BAND_MARGIN * floor { 0.0 } else { 1.0 }
    })
}

/// The rate (unit per second) of one evenly spaced segment `w`, `dt` s apart, weighted per
/// frequency: [`filtered_rates`]' rate.
pub fn filtered_rate<W, G>(w: &[f64], dt: f64, weights: W) -> Vec<f64>
where
    W: FnOnce(&[f64]) -> G,
    G: Fn(f64) -> f64,
{
    filtered_rates(w, dt, weights).0
}

/// The rate (unit per second) of one evenly spaced segment `w`, `dt` s apart, and its timing
/// column, weighted per frequency: linear trend out (its slope is a constant rate, added back to
/// the rate; its timing part is 0), even extension (the periodic FFT sees no jump at the ends),
/// the per-bin periodogram (E = σ² for white noise of variance σ²) handed to `weights`, which
/// returns the weight of a bin from its periodogram smoothed over ±max(j/10, 2) bins; then the
/// central difference's transfer function i·sin(ωΔt)/Δt and the timing's (1 − cos ωΔt)/Δt. A
/// segment shorter than [`MIN_SEGMENT`] gives its mean slope and no timing.
pub fn filtered_rates<W, G>(w: &[f64], dt: f64, weights: W) -> (Vec<f64>, Vec<f64>)
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
        return (vec![slope / dt; n], vec![0.0; n]);
    }
    let d: Vec<f64> = w
        .iter()
        .enumerate()
        .map(|(i, v)| v - m - slope * (i as f64 - tm))
        .collect();
    let (x, p) = even_periodogram(&d);
    let big = 2 * n;
    let k = p.len();
    let weight = weights(&p);
    let mut rate = Vec::with_capacity(k + 1);
    let mut timing = Vec::with_capacity(k + 1);
    for (j, &(re, im)) in x.iter().enumerate().take(k) {
        let band = (j / 10).max(2);
        let (a, b) = (j.saturating_sub(band).max(1), (j + band + 1).min(k));
        let ps = p[a..b].iter().sum::<f64>() / (b - a).max(1) as f64;
        let g = if j == 0 { 0.0 } else { weight(ps) };
        if g == 0.0 {
            rate.push((0.0, 0.0));
            timing.push((0.0, 0.0));
            continue;
        }
        let om = std::f64::consts::TAU * j as f64 / (big as f64 * dt);
        let s = (om * dt).sin() / dt * g;
        let c = (1.0 - (om * dt).cos()) / dt * g;
        rate.push((-im * s, re * s));
        timing.push((re * c, im * c));
    }
    rate.push((0.0, 0.0));
    timing.push((0.0, 0.0));
    let back = |half: &[(f64, f64)], add: f64| -> Vec<f64> {
        crate::numerics::fft::real_from_half_spectrum(half)
            .iter()
            .take(n)
            .map(|v| v / big as f64 + add)
            .collect()
    };
    (back(&rate, slope / dt), back(&timing, 0.0))
}

/// The spectrum of the even extension of `d` (length 2n, bins 0..n) and its per-bin
/// periodogram (E = σ² for white noise of variance σ²).
fn even_periodogram(d: &[f64]) -> (Vec<(f64, f64)>, Vec<f64>) {
    let mut z: Vec<f64> = d.iter().chain(d.iter().rev()).copied().collect();
    let big = z.len() as f64;
    let x = crate::numerics::fft::half_spectrum(&mut z);
    let p = x.iter().map(|(a, b)| (a * a + b * b) / big).collect();
    (x, p)
}

/// A band of 10 % of the frequency in the upper three quarters of a periodogram.
struct Band {
    /// 2 sin(ω/2) at its centre.
    x: f64,
    /// Its mean.
    mean: f64,
    /// Its bins.
    bins: f64,
}

/// The bands of 10 % of the frequency in the upper three quarters of a periodogram `p` (bins
/// 0..k, bin j at ω = πj/k).
fn upper_bands(p: &[f64]) -> Vec<Band> {
    let k = p.len();
    let mut bands = Vec::new();
    let mut j = (k / 4).max(1);
    while j < k {
        let e = (j + (j / 10).max(1)).min(k);
        let om = std::f64::consts::PI * (j + e - 1) as f64 / 2.0 / k as f64;
        bands.push(Band {
            x: 2.0 * (om / 2.0).sin(),
            mean: p[j..e].iter().sum::<f64>() / (e - j) as f64,
            bins: (e - j) as f64,
        });
        j = e;
    }
    bands
}

/// The lowest of [`upper_bands`]' means (0 for a periodogram too short to have one).
fn lowest_band_mean(p: &[f64]) -> f64 {
    let m = upper_bands(p)
        .iter()
        .map(|b| b.mean)
        .fold(f64::INFINITY, f64::min);
    if m.is_finite() {
        m.max(0.0)
    } else {
        0.0
    }
}

/// Exponents α of the power law in [`reading_floor`]'s fit: from 0.5 (flatter is white over the
/// two octaves fitted, and would trade with N) to 4 (the steepest a sampled smooth process shows
/// below the Nyquist frequency), in steps of 0.05.
const FLOOR_ALPHAS: std::ops::RangeInclusive<u32> = 10..=80;

/// The fit of N + A·x^(−α) (`alpha` None: N alone) to the bands by iteratively reweighted least
/// squares, each band mean's variance 2·model²/bins (a periodogram bin of the even extension is
/// a χ²₁ of its expectation): (N, χ²); N and A ≥ 0.
fn floor_fit(bands: &[Band], alpha: Option<f64>) -> Option<(f64, f64)> {
    let g: Vec<f64> = bands
        .iter()
        .map(|b| alpha.map_or(0.0, |a| b.x.powf(-a)))
        .collect();
    let mut model: Vec<f64> = bands.iter().map(|b| b.mean).collect();
    let mut best = None;
    for _ in 0..4 {
        let (mut s11, mut s12, mut s22, mut b1, mut b2) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for ((b, &gi), &mi) in bands.iter().zip(&g).zip(&model) {
            let w = b.bins / (2.0 * mi * mi);
            s11 += w;
            s12 += w * gi;
            s22 += w * gi * gi;
            b1 += w * b.mean;
            b2 += w * b.mean * gi;
        }
        let det = s11 * s22 - s12 * s12;
        let mut cands = vec![(b1 / s11, 0.0)];
        if alpha.is_some() {
            cands.push((0.0, b2 / s22));
            if det > 1e-12 * s11 * s22 {
                cands.push(((b1 * s22 - b2 * s12) / det, (s11 * b2 - s12 * b1) / det));
            }
        }
        let cost = |(n0, a0): (f64, f64)| -> f64 {
            bands
                .iter()
                .zip(&g)
                .zip(&model)
                .map(|((b, &gi), &mi)| b.bins * (b.mean - n0 - a0 * gi).powi(2) / (2.0 * mi * mi))
                .sum()
        };
        let (n0, a0) = cands
            .into_iter()
            .filter(|&(n0, a0)| n0 >= 0.0 && a0 >= 0.0 && (n0 > 0.0 || a0 > 0.0))
            .min_by(|&u, &v| cost(u).total_cmp(&cost(v)))?;
        model = g.iter().map(|gi| n0 + a0 * gi).collect();
        let chi2: f64 = bands
            .iter()
            .zip(&model)
            .map(|(b, mi)| b.bins * (b.mean - mi).powi(2) / (2.0 * mi * mi))
            .sum();
        best = Some((n0, chi2));
    }
    best
}

/// The white reading-noise level of a periodogram `p` (per-bin power E = σ² for white noise,
/// bins 0..k of a length-2k FFT, bin j at ω = πj/k), from its means over bands of 10 % of the
/// frequency in its upper three quarters: the white level N of N + A·(2 sin(ω/2))^(−α) (white
/// reading noise under a power law; α on a grid, N, A ≥ 0 by iteratively reweighted least
/// squares, ≈ a fit of the log-periodogram), or of N alone when the power law does not improve
/// the fit's χ² by more than its charge (its two parameters, ln of the bands each, and the α
/// grid's look-elsewhere 2 ln 71): a power law with A > 0 fitted to white noise takes part of
/// its level and biases N low. The one estimate of that floor: the band limit here and the
/// full-rate stage's ([`super::fullrate`]) use it.
pub fn reading_floor(p: &[f64]) -> f64 {
    let bands = upper_bands(p);
    if bands.len() < 4 || bands.iter().any(|b| !(b.mean > 0.0 && b.mean.is_finite())) {
        return lowest_band_mean(p);
    }
    let Some((white, chi2_white)) = floor_fit(&bands, None) else {
        return lowest_band_mean(p);
    };
    let law: Vec<(f64, f64)> = FLOOR_ALPHAS
        .filter_map(|ai| floor_fit(&bands, Some(f64::from(ai) * 0.05)))
        .collect();
    let chi2_law = law.iter().map(|f| f.1).fold(f64::INFINITY, f64::min);
    let charge = 2.0 * (bands.len() as f64).ln() + 2.0 * (FLOOR_ALPHAS.count() as f64).ln();
    if chi2_white - chi2_law <= charge {
        return white;
    }
    // The best fit's N. It trades with α (a steeper law leaves more of the top to the white
    // level), and the upper end of its profile interval was tried: on the simulator's
    // thermostat it stopped the band before the Nyquist frequency on some records, and the
    // coupling's part above the band was then named a lag and a hysteresis at their grid edges.
    law.iter()
        .min_by(|u, v| u.1.total_cmp(&v.1))
        .map_or(white, |f| f.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A thermostat's controller noise at 60 s (AR(1) of `sd` °C over `tau_s`, through the
    /// mount's thermal lag of `lag_s`: with a lag, not the floor fit's power law), and its RTD
    /// reading with white noise of `rtd_c`: (true, read).
    fn controller(n: usize, lag_s: f64, rtd_c: f64, seed: u64) -> (Vec<f64>, Vec<f64>) {
        let (dt, sd, tau_s) = (60.0_f64, 0.165_f64, 900.0_f64);
        let mut lcg = crate::numerics::lcg::Lcg(seed);
        let a = (-dt / tau_s).exp();
        let b = if lag_s > 0.0 {
            (-dt / lag_s).exp()
        } else {
            0.0
        };
        let (mut x, mut m) = (0.0, 0.0);
        let truth: Vec<f64> = (0..n + 200)
            .map(|_| {
                x = a * x + sd * (1.0 - a * a).sqrt() * lcg.normal();
                m = b * m + (1.0 - b) * x;
                20.0 + m
            })
            .skip(200)
            .collect();
        let read = truth.iter().map(|v| v + rtd_c * lcg.normal()).collect();
        (truth, read)
    }

    /// Least-squares gains of `y` on the columns `x` (no intercept: all have mean ≈ 0).
    fn gains(x: &[&[f64]], y: &[f64]) -> Vec<f64> {
        let rows: Vec<Vec<f64>> = (0..y.len())
            .map(|i| x.iter().map(|c| c[i]).collect())
            .collect();
        crate::numerics::linalg::least_squares(&rows, y)
            .expect("fit")
            .coeffs
    }

    /// On controller noise of 0.165 °C over 15 min read with 2 mK, the upper three quarters of
    /// the reading's spectrum are still signal (the reading noise is 1/10–1/200 of it at the
    /// Nyquist frequency): their lowest band mean is far above the noise, the fitted floor is
    /// well below that mean (so the band reaches further) and not above the noise; white noise
    /// alone gives its variance.
    #[test]
    fn the_reading_floor_is_the_white_noise_under_controller_noise() {
        for (lag_s, rtd_c) in [(0.0, 2e-3), (120.0, 2e-3), (0.0, 15e-3)] {
            let noise = rtd_c * rtd_c;
            let (_, read) = controller(5760, lag_s, rtd_c, 0x51);
            let (_, p) = even_periodogram(&read);
            let floor = reading_floor(&p);
            let lowest = lowest_band_mean(&p);
            eprintln!(
                "lag {lag_s} s, RTD {rtd_c} °C: floor {floor:e}, lowest band mean {lowest:e}"
            );
            assert!(
                floor < 2.0 * noise,
                "floor {floor:e} above the noise {noise:e}"
            );
            assert!(
                floor < lowest / 4.0,
                "floor {floor:e}, lowest band mean {lowest:e}"
            );
        }
        // White noise alone: the floor is its variance.
        let mut lcg = crate::numerics::lcg::Lcg(7);
        let white: Vec<f64> = (0..4096).map(|_| 3e-3 * lcg.normal()).collect();
        let f = reading_floor(&even_periodogram(&white).1);
        assert!((f / 9e-6 - 1.0).abs() < 0.1, "white floor {f:e}");
    }

    /// The rate of that reading keeps its gain (a regression of the true rate's coupling on it)
    /// and most of the true rate: the band reaches the frequencies where the rate lives. Read
    /// with 15 mK (the noise a fifth of the power at the Nyquist frequency) too.
    #[test]
    fn the_rate_of_controller_noise_keeps_its_gain_and_its_band() {
        for (rtd_c, tol, min_corr) in [(2e-3, 0.03, 0.95), (15e-3, 0.05, 0.8)] {
            rate_against_truth(rtd_c, tol, min_corr);
        }
    }

    fn rate_against_truth(rtd_c: f64, tol: f64, min_corr: f64) {
        let n = 5760;
        let (truth, read) = controller(n, 120.0, rtd_c, 0x52);
        let t: Vec<f64> = (0..n).map(|i| i as f64 * 60.0).collect();
        let seg: Vec<bool> = (0..n).map(|i| i == 0).collect();
        let r = band_limited_rate(&read, &t, &seg);
        let centred: Vec<f64> = (0..n)
            .map(|i| {
                let (a, b) = (i.saturating_sub(1), (i + 1).min(n - 1));
                (truth[b] - truth[a]) / ((b - a) as f64 * 60.0)
            })
            .collect();
        let g = gains(&[&r], &centred)[0];
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let corr = dot(&r, &centred) / (dot(&r, &r) * dot(&centred, &centred)).sqrt();
        eprintln!("RTD {rtd_c} °C: gain {g}, correlation with the true rate {corr}");
        assert!((g - 1.0).abs() < tol, "gain {g}");
        assert!(corr > min_corr, "correlation with the true rate {corr}");
    }

    /// A backward difference of the true temperature is the rate at position 1 in its row, a
    /// centred one at 0; on controller noise the timing column is as large as the rate.
    #[test]
    fn the_timing_column_dates_a_backward_difference_to_the_end_of_its_row() {
        let n = 5760;
        let (truth, read) = controller(n, 120.0, 2e-3, 0x53);
        let t: Vec<f64> = (0..n).map(|i| i as f64 * 60.0).collect();
        let seg: Vec<bool> = (0..n).map(|i| i == 0).collect();
        let c = band_limited_rates(&read, &t, &seg);
        assert!(
            c.timing_ratio() > 2.0 * TIMING_MIN_RATIO,
            "timing ratio {}",
            c.timing_ratio()
        );
        // Rows 1..n−1: both differences defined.
        let backward: Vec<f64> = (1..n - 1)
            .map(|i| (truth[i] - truth[i - 1]) / 60.0)
            .collect();
        let centred: Vec<f64> = (1..n - 1)
            .map(|i| (truth[i + 1] - truth[i - 1]) / 120.0)
            .collect();
        let (rate, timing) = (&c.rate[1..n - 1], &c.timing[1..n - 1]);
        for (y, want) in [(backward, 1.0), (centred, 0.0)] {
            let g = gains(&[rate, timing], &y);
            let pos = g[1] / g[0];
            assert!((g[0] - 1.0).abs() < 0.03, "gain {}", g[0]);
            assert!((pos - want).abs() < 0.05, "position {pos} against {want}");
        }
    }

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
        let c = band_limited_rates(&v, &t, &seg);
        assert!(c.timing_ratio() < TIMING_MIN_RATIO, "{}", c.timing_ratio());
        let r = c.rate;
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
