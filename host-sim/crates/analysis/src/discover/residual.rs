//! What the baseline gets wrong: the residual's spectrum (Lomb–Scargle, gaps handled), its
//! significant lines, its correlation with every auxiliary channel, with lagged and
//! differentiated temperature and the sign of the temperature rate, its trend and best single
//! step, and its Allan deviation.
//!
//! # Lomb–Scargle on long records
//!
//! The periodogram is computed on block means of at most `max_points` (4096) points, at most
//! one bin per original sample and never across a gap (unevenly spaced bin centres are fine for
//! Lomb–Scargle). Frequencies run from 1/span to the bins' Nyquist frequency with 4× oversampling;
//! sin/cos are advanced by rotation per frequency step, so the cost is O(points × frequencies)
//! multiply-adds ≈ 4096 × 8192 — milliseconds — whatever the record length. Lines shorter than
//! two bin widths are not resolved by this spectrum (the fitting itself uses all points).
//!
//! Significance: the normalised power z (Scargle 1982, variance-normalised) of a white residual
//! exceeds z with probability e^{−z} at one frequency; over M ≈ span·f_max independent
//! frequencies the false-alarm probability is 1 − (1 − e^{−z})^M (Horne & Baliunas 1986).

use super::effects::lag_filter;
use super::import::{ChannelKind, Dataset};

/// A periodogram line.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Line {
    /// Frequency, Hz.
    pub frequency_hz: f64,
    /// Period, s.
    pub period_s: f64,
    /// Normalised power.
    pub power: f64,
    /// Amplitude of the fitted sinusoid, input unit.
    pub amplitude: f64,
    /// False-alarm probability.
    pub fap: f64,
}

/// A periodogram with its local maxima.
#[derive(Debug, Clone, PartialEq)]
pub struct Spectrum {
    /// Frequencies, Hz.
    pub frequency_hz: Vec<f64>,
    /// Normalised power.
    pub power: Vec<f64>,
    /// Local maxima with FAP < 0.5, strongest first.
    pub lines: Vec<Line>,
}

/// Block means of at most `max_points` points: equal-width bins over the span (an empty bin
/// gives no point).
pub fn bin(t: &[f64], y: &[f64], max_points: usize) -> (Vec<f64>, Vec<f64>) {
    if t.len() <= max_points || t.len() < 2 {
        return (t.to_vec(), y.to_vec());
    }
    let span = t[t.len() - 1] - t[0];
    let w = span / max_points as f64;
    let mut cur = i64::MIN;
    let (bt, by, _) = crate::numerics::series::block_means(t, y, |_, ti| {
        let b = ((ti - t[0]) / w).floor() as i64;
        let opens = b != cur;
        cur = b;
        opens
    });
    (bt, by)
}

/// Lomb–Scargle periodogram of (t, y) binned to ≤ `max_points`.
pub fn periodogram(t: &[f64], y: &[f64], max_points: usize) -> Spectrum {
    let (t, y) = bin(t, y, max_points);
    let n = t.len();
    let empty = Spectrum {
        frequency_hz: Vec::new(),
        power: Vec::new(),
        lines: Vec::new(),
    };
    if n < 8 {
        return empty;
    }
    let mean = y.iter().sum::<f64>() / n as f64;
    let yc: Vec<f64> = y.iter().map(|v| v - mean).collect();
    let var = yc.iter().map(|v| v * v).sum::<f64>() / (n - 1) as f64;
    let span = t[n - 1] - t[0];
    if var <= 0.0 || span <= 0.0 {
        return empty;
    }
    let mut dts: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    dts.sort_by(f64::total_cmp);
    let dt_median = dts[dts.len() / 2];
    let f_max = 0.5 / dt_median;
    // A quarter of the resolution 1/span, unless the data cover less than a quarter of the span
    // (a record with a gap of years): then a quarter of the resolution of the time the data
    // cover, n × the median interval. Finer steps only sample the gap's fringes, and cost
    // n × 4·span·f_max products: 3·10¹⁰ for two days at 60 s ten years apart (minutes).
    let covered = n as f64 * dt_median;
    let df = if span > 4.0 * covered {
        1.0 / (4.0 * covered)
    } else {
        1.0 / (4.0 * span)
    };
    let nf = ((f_max - 1.0 / span) / df).floor().max(1.0) as usize;
    let tc: Vec<f64> = t.iter().map(|v| v - t[0]).collect();
    let two_pi = 2.0 * std::f64::consts::PI;
    // Per-point rotators: (cos, sin) of ω_k t_i advanced by (cos, sin) of 2π df t_i.
    let (mut c, mut s): (Vec<f64>, Vec<f64>) = tc
        .iter()
        .map(|&x| ((two_pi * x / span).cos(), (two_pi * x / span).sin()))
        .unzip();
    let (dc, ds): (Vec<f64>, Vec<f64>) = tc
        .iter()
        .map(|&x| ((two_pi * df * x).cos(), (two_pi * df * x).sin()))
        .unzip();
    let mut freqs = Vec::with_capacity(nf);
    let mut power = Vec::with_capacity(nf);
    let mut amps = Vec::with_capacity(nf);
    for k in 0..nf {
        let f = 1.0 / span + k as f64 * df;
        // One pass per frequency: advance the rotators and accumulate the five sums from which
        // τ (tan 2ωτ = Σ sin 2ωt / Σ cos 2ωt, by double angles) and the τ-rotated sums follow
        // algebraically.
        let (mut scc, mut sss, mut scs, mut syc, mut sys) = (0.0, 0.0, 0.0, 0.0, 0.0);
        let advance = k > 0;
        for (((ci, si), (dci, dsi)), yi) in c
            .iter_mut()
            .zip(s.iter_mut())
            .zip(dc.iter().zip(&ds))
            .zip(&yc)
        {
            if advance {
                let (c0, s0) = (*ci, *si);
                *ci = c0 * dci - s0 * dsi;
                *si = s0 * dci + c0 * dsi;
            }
            let (cv, sv) = (*ci, *si);
            scc += cv * cv;
            sss += sv * sv;
            scs += cv * sv;
            syc += yi * cv;
            sys += yi * sv;
        }
        let wt = 0.5 * (2.0 * scs).atan2(scc - sss);
        let (ct, st) = (wt.cos(), wt.sin());
        // cos(ω(t−τ)) = c·ct + s·st, sin(ω(t−τ)) = s·ct − c·st.
        let yc_c = ct * syc + st * sys;
        let yc_s = ct * sys - st * syc;
        let cc = ct * ct * scc + 2.0 * ct * st * scs + st * st * sss;
        let ss = ct * ct * sss - 2.0 * ct * st * scs + st * st * scc;
        let p = 0.5 * (yc_c * yc_c / cc.max(1e-300) + yc_s * yc_s / ss.max(1e-300)) / var;
        let a = ((yc_c / cc.max(1e-300)).powi(2) + (yc_s / ss.max(1e-300)).powi(2)).sqrt();
        freqs.push(f);
        power.push(p);
        amps.push(a);
    }
    let m_indep = (span * f_max).max(1.0);
    let mut lines: Vec<Line> = (0..nf)
        .filter(|&k| {
            (k == 0 || power[k] >= power[k - 1]) && (k + 1 == nf || power[k] >= power[k + 1])
        })
        .map(|k| {
            let single = (-power[k]).exp();
            // 1 − (1 − p)^M without cancellation for tiny p.
            let fap = -(m_indep * (-single).ln_1p()).exp_m1();
            Line {
                frequency_hz: freqs[k],
                period_s: 1.0 / freqs[k],
                power: power[k],
                amplitude: amps[k],
                fap,
            }
        })
        .filter(|l| l.fap < 0.5)
        .collect();
    lines.sort_by(|a, b| b.power.total_cmp(&a.power));
    lines.truncate(20);
    Spectrum {
        frequency_hz: freqs,
        power,
        lines,
    }
}

/// Pearson correlation (NaN if undefined).
pub fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len()) as f64;
    let ma = a.iter().sum::<f64>() / n;
    let mb = b.iter().sum::<f64>() / n;
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    sab / (saa * sbb).sqrt()
}

/// One correlation finding.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Correlation {
    /// What the residual was correlated with.
    pub with: String,
    /// Pearson r.
    pub r: f64,
}

/// Correlations of the residual with every channel, lagged temperature (first-order lags),
/// its rate, and the sign of its rate.
pub fn correlations(ds: &Dataset, resid: &[f64]) -> Vec<Correlation> {
    let mut out = Vec::new();
    for c in &ds.channels {
        out.push(Correlation {
            with: c.name.clone(),
            r: correlation(resid, &c.values),
        });
    }
    if let Some(temp) = ds.channel(ChannelKind::Temperature) {
        let span = ds.span_s();
        for tau in super::effects::log_grid((10.0 * ds.dt_s).max(1.0), span / 10.0, 5) {
            let l = lag_filter(&temp.values, &ds.t_s, &ds.segment_start, tau);
            out.push(Correlation {
                with: format!("{} lagged (tau {:.0} s)", temp.name, tau),
                r: correlation(resid, &l),
            });
        }
        let rate: Vec<f64> = (0..ds.len())
            .map(|i| {
                if i == 0 || ds.segment_start[i] {
                    0.0
                } else {
                    (temp.values[i] - temp.values[i - 1]) / (ds.t_s[i] - ds.t_s[i - 1])
                }
            })
            .collect();
        // Smooth the rate over ~20 points: differences of a noisy RTD are mostly noise.
        let smooth = lag_filter(&rate, &ds.t_s, &ds.segment_start, 20.0 * ds.dt_s);
        out.push(Correlation {
            with: format!("d({})/dt", temp.name),
            r: correlation(resid, &smooth),
        });
        let sign: Vec<f64> = smooth.iter().map(|v| v.signum()).collect();
        out.push(Correlation {
            with: format!("sign(d({})/dt)", temp.name),
            r: correlation(resid, &sign),
        });
    }
    out.retain(|c| c.r.is_finite());
    out
}

/// Trend and best single step of the residual.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Trend {
    /// Least-squares slope, output unit per day.
    pub slope_per_day: f64,
    /// Time of the best single step (max |CUSUM| of the centred residual), s.
    pub step_time_s: f64,
    /// Mean after minus mean before that time.
    pub step_size: f64,
}

/// Slope and CUSUM step of the residual.
pub fn trend(ds: &Dataset, resid: &[f64]) -> Trend {
    let n = resid.len();
    let mt = ds.t_s.iter().sum::<f64>() / n as f64;
    let mr = resid.iter().sum::<f64>() / n as f64;
    let (mut num, mut den) = (0.0, 0.0);
    for (t, r) in ds.t_s.iter().zip(resid) {
        num += (t - mt) * (r - mr);
        den += (t - mt) * (t - mt);
    }
    let mut cum = 0.0;
    let mut best = (0.0_f64, 0usize);
    for (i, r) in resid.iter().enumerate() {
        cum += r - mr;
        // Scaled CUSUM: |S_k| / sqrt(k (n − k)) peaks at the most likely single change point.
        let k = (i + 1) as f64;
        let sc = cum.abs() / (k * (n as f64 - k)).max(1.0).sqrt();
        if i + 1 < n && sc > best.0 {
            best = (sc, i + 1);
        }
    }
    let j = best.1.max(1);
    let before = resid[..j].iter().sum::<f64>() / j as f64;
    let after = resid[j..].iter().sum::<f64>() / (n - j).max(1) as f64;
    Trend {
        slope_per_day: if den > 0.0 { num / den * 86_400.0 } else { 0.0 },
        step_time_s: ds.t_s.get(j).copied().unwrap_or(f64::NAN),
        step_size: after - before,
    }
}

/// Overlapping Allan deviation (octave taus) of the residual placed on its time grid (gaps as
/// NaN, nothing interpolated), via the stability module.
pub fn adev(ds: &Dataset, resid: &[f64]) -> Vec<(f64, f64)> {
    adev_points(ds, resid)
        .iter()
        .map(|p| (p.tau_s, p.dev))
        .collect()
}

/// [`adev`] with the whole points (confidence interval, EDF) for the report's figure.
pub fn adev_points(ds: &Dataset, resid: &[f64]) -> Vec<crate::allan::AllanPoint> {
    let grid = match crate::stability::Grid::from_time(&ds.t_s) {
        Ok(g) => g,
        Err(_) => return Vec::new(),
    };
    let placed = grid.place(resid);
    crate::allan::oadev(&placed, ds.dt_s, crate::allan::TauSet::Octave).unwrap_or_default()
}

/// A measured regressor channel's own reading noise (kept at this path: the model is
/// [`super::eiv`]'s).
pub use super::eiv::ChannelNoise;

/// `ChannelNoise::method` of [`channel_noise`].
pub const METHOD_MAD_OF_DIFFERENCES: &str = "mad_of_first_differences";

/// Reading noise of every measured regressor channel (temperature, tilt, pressure, ambient):
/// 1.4826·MAD of the first differences inside segments, / √2 — white reading noise doubles
/// in a difference, a slow signal hardly moves between neighbours, and the median ignores the
/// few large differences of fast changes. On binned records it is the noise of a bin mean.
///
/// A quick robust estimate without a model (used by the simulator's recovery tests); the
/// discovery itself reports [`super::eiv`]'s maximum-likelihood levels.
pub fn channel_noise(ds: &Dataset) -> Vec<ChannelNoise> {
    use super::import::ChannelKind;
    ds.channels
        .iter()
        .filter(|c| c.kind != ChannelKind::Input)
        .filter_map(|c| {
            let mut d: Vec<f64> = (1..c.values.len())
                .filter(|&i| !ds.segment_start[i])
                .map(|i| (c.values[i] - c.values[i - 1]).abs())
                .collect();
            if d.len() < 10 {
                return None;
            }
            d.sort_by(f64::total_cmp);
            let mad = d[d.len() / 2];
            Some(ChannelNoise {
                channel: c.name.clone(),
                noise: 1.4826 * mad / std::f64::consts::SQRT_2,
                unit: match c.kind {
                    ChannelKind::Tilt => "rad",
                    ChannelKind::Pressure => "Pa",
                    ChannelKind::Temperature => "°C",
                    _ => "channel unit",
                },
                std: crate::numerics::stats::std(&c.values),
                diffusion_per_s: f64::NAN,
                slope_diffusion_per_s3: f64::NAN,
                smoothing_s: 0.0,
                resolved: false,
                smoothed: false,
                method: METHOD_MAD_OF_DIFFERENCES,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn periodogram_finds_a_line_through_a_gap_and_calls_it_significant() {
        // 1000 s period, amplitude 1, white-ish deterministic noise, a gap in the middle.
        let t: Vec<f64> = (0..6000)
            .map(f64::from)
            .filter(|x| !(2000.0..3000.0).contains(x))
            .collect();
        let y: Vec<f64> = t
            .iter()
            .enumerate()
            .map(|(i, x)| {
                (2.0 * std::f64::consts::PI * x / 1000.0).sin()
                    + 0.5 * (((i * 7919) % 101) as f64 / 50.0 - 1.0)
            })
            .collect();
        let s = periodogram(&t, &y, 4096);
        let top = s.lines[0];
        assert!((top.period_s - 1000.0).abs() < 10.0, "{top:?}");
        assert!(top.fap < 1e-10);
        assert!((top.amplitude - 1.0).abs() < 0.1);
    }

    #[test]
    fn cusum_places_a_step_where_it_is() {
        let t: Vec<f64> = (0..1000).map(f64::from).collect();
        let r: Vec<f64> = t
            .iter()
            .map(|&x| if x >= 700.0 { 1.0 } else { 0.0 })
            .collect();
        let ds = Dataset {
            input_g: None,
            ..Dataset::test_g(t, r.clone(), 1.0)
        };
        let tr = trend(&ds, &r);
        assert_eq!(tr.step_time_s, 700.0);
        assert!((tr.step_size - 1.0).abs() < 1e-12);
    }
}
