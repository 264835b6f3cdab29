//! Coefficient stability over repeated tests: regression on time per temperature group, and the
//! inverse-variance weighted means the coefficient table uses.

use super::*;

/// Linear regression y = a + b·t: (mean, slope, slope SE, sqrt(RSS/(n−2))). Needs n ≥ 3 and
/// distinct times.
pub fn regress_on_time(t: &[f64], y: &[f64]) -> Option<(f64, f64, f64, f64)> {
    let n = t.len();
    if n < 3 || y.len() != n {
        return None;
    }
    let nf = n as f64;
    let tm = t.iter().sum::<f64>() / nf;
    let ym = y.iter().sum::<f64>() / nf;
    let stt: f64 = t.iter().map(|v| (v - tm) * (v - tm)).sum();
    if stt <= 0.0 {
        return None;
    }
    let sty: f64 = t.iter().zip(y).map(|(a, b)| (a - tm) * (b - ym)).sum();
    let b = sty / stt;
    let rss: f64 = t
        .iter()
        .zip(y)
        .map(|(a, v)| {
            let r = v - ym - b * (a - tm);
            r * r
        })
        .sum();
    let s = (rss / (nf - 2.0)).sqrt();
    Some((ym, b, s / stt.sqrt(), s))
}

/// Groups tests by axis and temperature (within [`TEMPERATURE_GROUP_TOLERANCE_C`]; tests without
/// a temperature form one group per axis), in order of first appearance.
pub(super) fn temperature_groups(tests: &[TestSolution]) -> Vec<Vec<&TestSolution>> {
    let mut groups: Vec<Vec<&TestSolution>> = Vec::new();
    for t in tests {
        let found = groups.iter_mut().find(|g| {
            g[0].rotation_axis == t.rotation_axis
                && match (g[0].temperature.mean_c, t.temperature.mean_c) {
                    (Some(a), Some(b)) => (a - b).abs() < TEMPERATURE_GROUP_TOLERANCE_C,
                    (None, None) => true,
                    _ => false,
                }
        });
        match found {
            Some(g) => g.push(t),
            None => groups.push(vec![t]),
        }
    }
    groups
}

/// Reads one coefficient of a test.
type Getter = fn(&TestSolution) -> f64;

pub(super) fn stability(tests: &[TestSolution]) -> Vec<StabilityGroup> {
    let mut out = Vec::new();
    for g in temperature_groups(tests) {
        let timed: Vec<&&TestSolution> = g.iter().filter(|t| t.time_s.is_some()).collect();
        if timed.len() < 3 {
            continue;
        }
        let days: Vec<f64> = timed
            .iter()
            .map(|t| t.time_s.unwrap_or(0.0) / 86_400.0)
            .collect();
        let series: [(&str, Getter); 4] = [
            ("k0_g", |t| t.coefficients.k0_g.value),
            ("k1_v_per_g", |t| t.coefficients.k1_v_per_g.value),
            ("k2_g_per_g2", |t| t.coefficients.k2_g_per_g2.value),
            ("misalignment_arcmin", |t| {
                t.coefficients.misalignment_arcmin.value
            }),
        ];
        let coefficients = series
            .iter()
            .filter_map(|(name, f)| {
                let y: Vec<f64> = timed.iter().map(|t| f(t)).collect();
                regress_on_time(&days, &y).map(|(mean, b, bse, s)| CoefficientStability {
                    coefficient: name.to_string(),
                    mean,
                    slope_per_day: b,
                    slope_se_per_day: bse,
                    regression_sd: s,
                })
            })
            .collect::<Vec<_>>();
        if coefficients.is_empty() {
            continue;
        }
        let temps: Vec<f64> = timed.iter().filter_map(|t| t.temperature.mean_c).collect();
        out.push(StabilityGroup {
            temperature_c: (!temps.is_empty())
                .then(|| temps.iter().sum::<f64>() / temps.len() as f64),
            rotation_axis: timed[0].rotation_axis,
            tests: timed.len(),
            span_days: days.iter().copied().fold(f64::MIN, f64::max)
                - days.iter().copied().fold(f64::MAX, f64::min),
            coefficients,
        });
    }
    out
}

/// Inverse-variance weighted mean of estimates and its standard error.
pub(super) fn weighted(es: &[Estimate]) -> Option<(f64, f64)> {
    if es.is_empty() {
        return None;
    }
    if es.iter().any(|e| e.se.is_nan() || e.se <= 0.0) {
        // An estimate without a usable SE: plain mean, SE of the mean unknown → largest SE.
        let m = es.iter().map(|e| e.value).sum::<f64>() / es.len() as f64;
        return Some((m, es.iter().map(|e| e.se).fold(0.0, f64::max)));
    }
    let w: f64 = es.iter().map(|e| 1.0 / (e.se * e.se)).sum();
    let m = es.iter().map(|e| e.value / (e.se * e.se)).sum::<f64>() / w;
    Some((m, (1.0 / w).sqrt()))
}
