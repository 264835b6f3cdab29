//! Power-law noise identification by the lag-1 autocorrelation (Riley & Greenhall 2004), on
//! the block means of the phase.

use super::{Phase, DEC, NOISE_ID_MAX_POINTS};

impl Phase {
    /// Non-overlapping averages of the readings over `m`, from the phase (blocks touching a gap
    /// are dropped), for noise identification.
    pub(super) fn block_means(&self, m: usize) -> Vec<f64> {
        let nblocks = (self.x.len() - 1) / m;
        let mut out = Vec::with_capacity(nblocks);
        for k in 0..nblocks {
            let (i0, i1) = (k * m, (k + 1) * m);
            if let Some(nb) = &self.nan_before {
                if nb[i1] != nb[i0] {
                    continue;
                }
            }
            out.push((self.x[i1] - self.x[i0]) / (m as f64 * self.tau0_s));
        }
        out
    }

    /// Noise type at factor `m` (see [`noise_id_lag1`]); `scratch` is reused between taus.
    pub(super) fn noise_id(&self, m: usize, scratch: &mut Vec<f64>) -> Option<i32> {
        if self.nan_before.is_none() {
            self.noise_id_gapless(m, scratch)
        } else {
            noise_id_lag1(&self.block_means(m))
        }
    }

    /// [`noise_id_lag1`] of the block means over `m` of a gapless record, with the detrending
    /// of [`lag1_id_detrending`]. The block means are differences of phase points `m` apart,
    /// gathered into `scratch` (at most [`NOISE_ID_MAX_POINTS`] + 1 of them, read from the
    /// decimated copy of the phase when `m` allows, so a long tau does not stride through all of
    /// `x`): O(min(N/m, cap)) work per tau.
    pub(super) fn noise_id_gapless(&self, m: usize, scratch: &mut Vec<f64>) -> Option<i32> {
        // At most NOISE_ID_MAX_POINTS block means (the first ones): lag-1 ACF from 131 072
        // points is already good to ~0.003, and at m = 1 on a 41-day log the full 3.5 M points
        // cost more than the whole OADEV pass.
        let k_len = ((self.x.len() - 1) / m).min(NOISE_ID_MAX_POINTS);
        if k_len < 30 {
            return None;
        }
        let scale = 1.0 / (m as f64 * self.tau0_s);
        scratch.clear();
        if m.is_multiple_of(DEC) && !self.dec.is_empty() {
            scratch.extend(self.dec.iter().step_by(m / DEC).take(k_len + 1));
        } else {
            scratch.extend(self.x.iter().step_by(m).take(k_len + 1));
        }
        if scratch.len() != k_len + 1 {
            return None;
        }
        // Phase points -> block means, in place: z_k = (x_{(k+1)m} - x_{km}) / (m tau0).
        for k in 0..k_len {
            scratch[k] = (scratch[k + 1] - scratch[k]) * scale;
        }
        scratch.truncate(k_len);
        lag1_id_detrending(scratch)
    }
}

/// Lag-1 noise identification of block means `z` (overwritten with their detrended values):
/// linear detrend with the closed-form `sum (k - mean k)^2`, then differencing on the fly, as
/// [`noise_id_lag1`] does with explicit copies. At least 30 points, else `None`.
fn lag1_id_detrending(z: &mut [f64]) -> Option<i32> {
    let k_len = z.len();
    if k_len < 30 {
        return None;
    }
    let kf = k_len as f64;
    let tm = (kf - 1.0) / 2.0;
    let sz = lane_sum(k_len, |k| z[k]);
    let stz = lane_sum(k_len, |k| (k as f64 - tm) * z[k]);
    let zm = sz / kf;
    let sxx = kf * (kf * kf - 1.0) / 12.0;
    let b = stz / sxx;
    for (k, v) in z.iter_mut().enumerate() {
        *v = *v - zm - b * (k as f64 - tm);
    }
    let r: &[f64] = z;
    let mut d = 0usize;
    loop {
        // d-th difference of the residuals, on the fly.
        let w = |k: usize| match d {
            0 => r[k],
            1 => r[k + 1] - r[k],
            _ => r[k + 2] - 2.0 * r[k + 1] + r[k],
        };
        let n = k_len - d;
        let mu = lane_sum(n, w) / n as f64;
        let den = lane_sum(n, |k| (w(k) - mu) * (w(k) - mu));
        let num = lane_sum(n - 1, |k| (w(k) - mu) * (w(k + 1) - mu));
        if den <= 0.0 || !den.is_finite() {
            return None;
        }
        let r1 = num / den;
        let delta = r1 / (1.0 + r1);
        if delta < 0.25 || d >= 2 {
            let alpha = -(2.0 * delta).round() as i32 - 2 * d as i32;
            return Some(alpha.clamp(-2, 2));
        }
        d += 1;
    }
}

/// `sum_{k<n} f(k)` in four interleaved partial sums (independent add chains, 4x the
/// throughput of one running sum).
fn lane_sum(n: usize, f: impl Fn(usize) -> f64) -> f64 {
    let mut acc = [0.0f64; 4];
    for j in 0..n / 4 {
        for (l, a) in acc.iter_mut().enumerate() {
            *a += f(4 * j + l);
        }
    }
    let mut s = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    for k in n / 4 * 4..n {
        s += f(k);
    }
    s
}

/// Lag-1 autocorrelation noise identification (Riley & Greenhall 2004) for frequency data
/// already averaged over the tau of interest: returns the power-law exponent `alpha`
/// (2 white PM, 1 flicker PM, 0 white FM, -1 flicker FM, -2 random-walk FM), or `None` with
/// fewer than 30 points. The series is first detrended (linear fit removed: frequency drift
/// would otherwise read as random walk), then differenced until `delta = r1 / (1 + r1) < 0.25`
/// or twice; `alpha = -round(2 delta) - 2 d`, clamped to [-2, 2].
pub fn noise_id_lag1(z: &[f64]) -> Option<i32> {
    if z.len() < 30 {
        return None;
    }
    let mut z = detrend_linear(z);
    let mut d = 0i32;
    loop {
        let r1 = lag1_autocorrelation(&z)?;
        let delta = r1 / (1.0 + r1);
        if delta < 0.25 || d >= 2 {
            let alpha = -(2.0 * delta).round() as i32 - 2 * d;
            return Some(alpha.clamp(-2, 2));
        }
        z = z.windows(2).map(|w| w[1] - w[0]).collect();
        d += 1;
    }
}

/// `sum (z_n - mean)(z_{n+1} - mean) / sum (z_n - mean)^2`; `None` for a constant series.
pub fn lag1_autocorrelation(z: &[f64]) -> Option<f64> {
    let n = z.len();
    if n < 2 {
        return None;
    }
    let mean = z.iter().sum::<f64>() / n as f64;
    let den: f64 = z.iter().map(|v| (v - mean) * (v - mean)).sum();
    if den <= 0.0 || !den.is_finite() {
        return None;
    }
    let num: f64 = z.windows(2).map(|w| (w[0] - mean) * (w[1] - mean)).sum();
    Some(num / den)
}

/// `z` less its least-squares line in the index (what a baseline of an offset and a linear drift
/// leaves).
pub fn detrend_linear(z: &[f64]) -> Vec<f64> {
    let n = z.len() as f64;
    let tm = (n - 1.0) / 2.0;
    let zm = z.iter().sum::<f64>() / n;
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for (i, v) in z.iter().enumerate() {
        let dt = i as f64 - tm;
        sxy += dt * (v - zm);
        sxx += dt * dt;
    }
    let b = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    z.iter()
        .enumerate()
        .map(|(i, v)| v - zm - b * (i as f64 - tm))
        .collect()
}
