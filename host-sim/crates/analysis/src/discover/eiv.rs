//! Errors in variables: every measured regressor channel (temperature, tilt, pressure, any
//! ambient channel) is a noisy reading of a slower true value.
//!
//! # Why
//!
//! A regression on a noisy reading puts the reading noise, times the coefficient, into the
//! model: smoothing the reading then always improves the fit, whatever the physics. Fitted on
//! the raw RTD reading, a `thermal_lag` of a few samples (or any low-pass of the temperature)
//! "explains" the reading noise and is named as physics. So each channel is modelled as a state:
//! a local linear trend model — the true value a level that diffuses and moves with a slope that
//! diffuses (a smooth thermostat swing is a slowly turning slope, a jump is level diffusion),
//! the reading that value plus white reading noise of variance `r` — whose three levels are
//! fitted by maximum likelihood of the channel's own Kalman innovations (two ratios by a grid
//! and golden sections, the scale concentrated out), and the model sees the Rauch–Tung–Striebel
//! smoothed level: zero phase (no lag is introduced), its width fitted, nothing when the
//! reading has no white part. The reading noise is reported as its own cause (`channel_noise`, with the channel,
//! its level and the smoothing width) and is part of the model the effects are fitted on.

use super::import::{ChannelKind, Dataset};

/// What the errors-in-variables model found for one channel.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ChannelNoise {
    /// Column name.
    pub channel: String,
    /// Standard deviation of one reading's white noise (maximum likelihood of the local linear
    /// trend model), in the channel's stored unit (`unit`); reported also when not `resolved`
    /// (until session 4 it was then given as 0, which read as "no reading noise").
    pub noise: f64,
    /// The stored unit (°C and other channels: the log's; tilt: rad; pressure: Pa).
    pub unit: &'static str,
    /// Standard deviation of the channel itself (signal + noise).
    pub std: f64,
    /// Diffusion of the true value, unit² per second.
    pub diffusion_per_s: f64,
    /// Diffusion of the true value's slope, unit² per second³.
    pub slope_diffusion_per_s3: f64,
    /// Effective width of the smoother, seconds: the shorter of the times over which the level's
    /// and the slope's diffusion move the true value by one reading noise (0 = not smoothed).
    pub smoothing_s: f64,
    /// Whether the reading noise is resolved (the smoother averages over at least a spacing).
    pub resolved: bool,
    /// Whether the model was fitted on the smoothed state (false: the channel as read).
    pub smoothed: bool,
    /// How the levels were obtained.
    pub method: &'static str,
}

/// `ChannelNoise::method`.
pub const METHOD_LOCAL_TREND_ML: &str = "local_linear_trend_kalman_ml_rts";

/// Search range of ln(q·dt/r) for the level's and ln(q_slope·dt³/r) for the slope's diffusion:
/// from a reading noise 10⁵ times the per-sample change of the true value (an extremely smooth
/// channel) to the reverse (no reading noise to speak of).
const LN_LAMBDA: (f64, f64) = (-23.0, 23.0);

/// 2×2 symmetric matrix [a b; b c].
#[derive(Clone, Copy, Default)]
struct Sym {
    a: f64,
    b: f64,
    c: f64,
}

/// Stored forward pass for the smoother: filtered state and covariance, predicted covariance,
/// step length into each row.
#[derive(Default)]
struct Pass {
    m_f: Vec<[f64; 2]>,
    p_f: Vec<Sym>,
    p_pred: Vec<Sym>,
    h: Vec<f64>,
}

/// Kalman filter of the local linear trend model — the true value a level that diffuses by
/// `l1`·r/dt per second and moves with a slope that diffuses by `l2`·r/dt³ per second, read
/// with white noise of variance r = 1 (scale concentrated out). The first two readings set the
/// state (exact diffuse start); returns (Σ e²/S, Σ ln S) over the rest.
fn filter(
    t_s: &[f64],
    x: &[f64],
    dt: f64,
    l1: f64,
    l2: f64,
    keep: Option<&mut Pass>,
) -> (f64, f64) {
    let (q1, q2) = (l1 / dt, l2 / (dt * dt * dt));
    let h0 = (t_s[1] - t_s[0]).max(1e-9);
    let mut m = [x[1], (x[1] - x[0]) / h0];
    let mut p = Sym {
        a: 1.0,
        b: 1.0 / h0,
        c: 2.0 / (h0 * h0),
    };
    let (mut chi2, mut log_det) = (0.0, 0.0);
    let mut keep = keep;
    if let Some(k) = keep.as_deref_mut() {
        // Row 0 is smoothed from row 1's state (it only set the start).
        for _ in 0..2 {
            k.m_f.push(m);
            k.p_f.push(p);
            k.p_pred.push(p);
            k.h.push(h0);
        }
    }
    for i in 2..x.len() {
        let h = (t_s[i] - t_s[i - 1]).max(0.0);
        // Predict: F = [1 h; 0 1], Q = q1·[h 0; 0 0] + q2·[h³/3 h²/2; h²/2 h].
        let mp = [m[0] + h * m[1], m[1]];
        let pp = Sym {
            a: p.a + 2.0 * h * p.b + h * h * p.c + q1 * h + q2 * h * h * h / 3.0,
            b: p.b + h * p.c + q2 * h * h / 2.0,
            c: p.c + q2 * h,
        };
        let sv = pp.a + 1.0;
        let e = x[i] - mp[0];
        chi2 += e * e / sv;
        log_det += sv.ln();
        let (g0, g1) = (pp.a / sv, pp.b / sv);
        m = [mp[0] + g0 * e, mp[1] + g1 * e];
        p = Sym {
            a: pp.a - g0 * pp.a,
            b: pp.b - g0 * pp.b,
            c: pp.c - g1 * pp.b,
        };
        if let Some(k) = keep.as_deref_mut() {
            k.m_f.push(m);
            k.p_f.push(p);
            k.p_pred.push(pp);
            k.h.push(h);
        }
    }
    (chi2, log_det)
}

/// Concentrated −2 ln L of the model at (ln l1, ln l2), and the reading-noise variance.
fn neg2_loglik(t_s: &[f64], x: &[f64], dt: f64, ll: [f64; 2]) -> (f64, f64) {
    let (chi2, ld) = filter(t_s, x, dt, ll[0].exp(), ll[1].exp(), None);
    let m = (x.len() - 2) as f64;
    let c = chi2 / m;
    let v = m * (1.0 + c.ln()) + ld;
    (if v.is_finite() { v } else { f64::INFINITY }, c)
}

/// Fitted model of one channel: (ln l1, ln l2, r) with r the reading-noise variance, or None
/// when the channel is constant or too short. A coarse grid over both ratios, then coordinate
/// golden-section refinements.
fn fit(t_s: &[f64], x: &[f64], dt: f64) -> Option<([f64; 2], f64)> {
    if x.len() < 10 || crate::numerics::stats::std(x) <= 0.0 {
        return None;
    }
    let f = |p: [f64; 2]| neg2_loglik(t_s, x, dt, p).0;
    let (lo, hi) = LN_LAMBDA;
    let steps = 11;
    let at = |i: usize| lo + (hi - lo) * i as f64 / steps as f64;
    let mut best: Option<([f64; 2], f64)> = None;
    for i in 0..=steps {
        for j in 0..=steps {
            let p = [at(i), at(j)];
            let v = f(p);
            if v.is_finite() && best.is_none_or(|(_, b)| v < b) {
                best = Some((p, v));
            }
        }
    }
    let (mut p, mut v) = best?;
    let half = (hi - lo) / steps as f64;
    for width in [half, half / 4.0] {
        for d in 0..2 {
            let (a, b) = ((p[d] - width).max(lo), (p[d] + width).min(hi));
            let g = crate::numerics::optimize::golden_section_min(
                |u| {
                    let mut q = p;
                    q[d] = u;
                    f(q)
                },
                a,
                b,
                24,
            );
            let mut q = p;
            q[d] = g;
            let fq = f(q);
            if fq < v {
                (p, v) = (q, fq);
            }
        }
    }
    let (_, c) = neg2_loglik(t_s, x, dt, p);
    Some((p, c))
}

/// Rauch–Tung–Striebel smoothed level of the local linear trend model.
fn smooth(t_s: &[f64], x: &[f64], dt: f64, ll: [f64; 2]) -> Vec<f64> {
    let mut pass = Pass::default();
    filter(t_s, x, dt, ll[0].exp(), ll[1].exp(), Some(&mut pass));
    let n = x.len();
    let mut ms = pass.m_f.clone();
    for i in (1..n.saturating_sub(1)).rev() {
        let h = pass.h[i + 1];
        let (pf, pp) = (pass.p_f[i], pass.p_pred[i + 1]);
        // J = P_f Fᵀ P_pred⁻¹ with F = [1 h; 0 1].
        let (fa, fb, fc) = (pf.a + h * pf.b, pf.b, pf.b + h * pf.c);
        // P_f Fᵀ = [pf.a + h pf.b, pf.b; pf.b + h pf.c, pf.c] (rows).
        let det = pp.a * pp.c - pp.b * pp.b;
        if !(det.abs() > 0.0 && det.is_finite()) {
            continue;
        }
        let (ia, ib, ic) = (pp.c / det, -pp.b / det, pp.a / det);
        let j = [
            [fa * ia + fb * ib, fa * ib + fb * ic],
            [fc * ia + pf.c * ib, fc * ib + pf.c * ic],
        ];
        let mp = [pass.m_f[i][0] + h * pass.m_f[i][1], pass.m_f[i][1]];
        let d = [ms[i + 1][0] - mp[0], ms[i + 1][1] - mp[1]];
        ms[i] = [
            pass.m_f[i][0] + j[0][0] * d[0] + j[0][1] * d[1],
            pass.m_f[i][1] + j[1][0] * d[0] + j[1][1] * d[1],
        ];
    }
    // Row 0 only set the start: its smoothed value is row 1's level moved back one step.
    if n >= 2 {
        ms[0] = [ms[1][0] - pass.h[1] * ms[1][1], ms[1][1]];
    }
    ms.iter().map(|m| m[0]).collect()
}

/// Splits the rows into the dataset's contiguous segments (the smoother restarts after a gap
/// longer than the record's own spacing would allow: the true value is not carried across).
fn segments(ds: &Dataset) -> Vec<std::ops::Range<usize>> {
    let mut out = Vec::new();
    let mut start = 0;
    for i in 1..ds.len() {
        if ds.segment_start[i] {
            out.push(start..i);
            start = i;
        }
    }
    if !ds.is_empty() {
        out.push(start..ds.len());
    }
    out
}

/// Time scale over which the smoother averages: where the reading noise equals the true value's
/// change by level diffusion (r/q1) or by slope diffusion ((r/q2)^⅓), the shorter.
fn smoothing_width_s(dt: f64, ll: [f64; 2]) -> f64 {
    let level = dt * (-ll[0]).exp();
    let slope = dt * (-ll[1] / 3.0).exp();
    level.min(slope)
}

/// Fits the errors-in-variables model of every regressor channel of `ds` and returns the
/// dataset the effects are fitted on — with `apply`, resolved channels replaced by their
/// smoothed states (the output and the input channel untouched); without, the channels as
/// read — with what was found per channel.
pub fn denoise(ds: &Dataset, apply: bool) -> (Dataset, Vec<ChannelNoise>) {
    let dt = ds.dt_s.max(1e-9);
    let segs = segments(ds);
    // One model per channel, the channels on all cores: its levels are fitted on the longest
    // segment (the levels are a property of the sensor, not of the segment), then every segment
    // is smoothed with them. `None`: not modelled (the input, too short a record, no fit).
    let one = |c: &super::import::Channel| -> Option<(Option<Vec<f64>>, ChannelNoise)> {
        if c.kind == ChannelKind::Input {
            return None;
        }
        let raw_std = crate::numerics::stats::std(&c.values);
        let longest = segs.iter().max_by_key(|r| r.len()).cloned()?;
        if longest.len() < 10 {
            return None;
        }
        let (ll, r) = fit(&ds.t_s[longest.clone()], &c.values[longest], dt)?;
        // When the reading noise is below the true value's change over one spacing (the
        // smoother would average over less than a spacing) the white part is not resolved: the
        // channel is used as read.
        let resolved = r > 0.0 && smoothing_width_s(dt, ll) >= dt;
        let smoothed = (resolved && apply).then(|| {
            let mut v = c.values.clone();
            for s in &segs {
                if s.len() >= 3 {
                    let sm = smooth(&ds.t_s[s.clone()], &c.values[s.clone()], dt, ll);
                    v[s.clone()].copy_from_slice(&sm);
                }
            }
            v
        });
        let noise = ChannelNoise {
            channel: c.name.clone(),
            noise: r.max(0.0).sqrt(),
            unit: match c.kind {
                ChannelKind::Tilt => "rad",
                ChannelKind::Pressure => "Pa",
                ChannelKind::Temperature => "°C",
                _ => "channel unit",
            },
            std: raw_std,
            diffusion_per_s: r * ll[0].exp() / dt,
            slope_diffusion_per_s3: r * ll[1].exp() / (dt * dt * dt),
            smoothing_s: if resolved {
                smoothing_width_s(dt, ll)
            } else {
                0.0
            },
            resolved,
            smoothed: resolved && apply,
            method: METHOD_LOCAL_TREND_ML,
        };
        Some((smoothed, noise))
    };
    let found = crate::numerics::parallel::par_map_balanced(&ds.channels, one);
    let mut model = ds.clone();
    let mut report = Vec::new();
    for (c, f) in model.channels.iter_mut().zip(found) {
        if let Some((smoothed, noise)) = f {
            if let Some(v) = smoothed {
                c.values = v;
            }
            report.push(noise);
        }
    }
    (model, report)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::discover::import::Channel;
    use crate::discover::noise::tests::normals;

    fn dataset(values: Vec<f64>, dt: f64) -> Dataset {
        let n = values.len();
        let t_s = (0..n).map(|i| i as f64 * dt).collect();
        Dataset {
            channels: vec![Channel {
                name: "temperature_c".into(),
                kind: ChannelKind::Temperature,
                values,
            }],
            input_g: None,
            ..Dataset::test_g(t_s, vec![0.0; n], dt)
        }
    }

    #[test]
    fn reading_noise_of_an_rtd_is_fitted_and_smoothed_away_without_a_lag() {
        // A slow 0.5 °C, 6 h sine read with 3 mK white noise every 60 s for 3 days.
        let (n, dt) = (4320, 60.0);
        let w = normals(n, 7);
        let truth: Vec<f64> = (0..n)
            .map(|i| 25.0 + 0.5 * (2.0 * std::f64::consts::PI * i as f64 * dt / 21_600.0).sin())
            .collect();
        let read: Vec<f64> = truth.iter().zip(&w).map(|(t, e)| t + 0.003 * e).collect();
        let (m, rep) = denoise(&dataset(read.clone(), dt), true);
        assert_eq!(rep.len(), 1);
        let c = &rep[0];
        assert!(c.smoothed, "{c:?}");
        assert!((c.noise / 0.003 - 1.0).abs() < 0.15, "{c:?}");
        let err = |v: &[f64]| {
            (v.iter()
                .zip(&truth)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
                / n as f64)
                .sqrt()
        };
        let sm = &m.channels[0].values;
        // Most of the reading noise is gone …
        assert!(err(sm) < 0.4 * err(&read), "{} vs {}", err(sm), err(&read));
        // … and no lag was introduced: the smoothed series is as close to the truth shifted
        // back as forward (a causal low-pass would be closer to the truth one sample late).
        let shifted = |k: i64| {
            (100..n - 100)
                .map(|i| (sm[i] - truth[(i as i64 + k) as usize]).powi(2))
                .sum::<f64>()
        };
        let (back, fwd) = (shifted(-1), shifted(1));
        assert!((back / fwd - 1.0).abs() < 0.05, "{back} {fwd}");
    }

    #[test]
    fn a_channel_without_reading_noise_is_used_as_read() {
        // A pure random walk: no white part to remove.
        let w = normals(3000, 3);
        let mut acc = 20.0;
        let v: Vec<f64> = w
            .iter()
            .map(|e| {
                acc += 0.01 * e;
                acc
            })
            .collect();
        let (m, rep) = denoise(&dataset(v.clone(), 10.0), true);
        assert!(!rep[0].smoothed, "{:?}", rep[0]);
        assert_eq!(m.channels[0].values, v);
    }
}
