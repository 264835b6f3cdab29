//! One test: positions, the least-squares fit of equation (1) (numerics::linalg QR), standard
//! errors (noise and index error by the delta method), the paper's four-point values.

use super::*;
use crate::numerics::linalg::{least_squares_with, RankTolerance};

/// Resolved parameters of one log.
#[derive(Debug, Clone, Copy)]
pub(super) struct Params {
    pub(super) gravity_g: f64,
    pub(super) index_error_arcsec: f64,
    pub(super) axis: RotationAxis,
    pub(super) gap_s: f64,
}

/// `key` (a metadata key or CLI option) refused with its value and why.
fn bad_parameter(key: &str, value: impl ToString, reason: &'static str) -> TumbleError {
    TumbleError::BadParameter {
        key: key.into(),
        value: value.to_string(),
        reason,
    }
}

/// `value` of `key` is accepted when `ok`, else refused with `reason`.
fn require(ok: bool, key: &str, value: f64, reason: &'static str) -> Result<(), TumbleError> {
    if ok {
        Ok(())
    } else {
        Err(bad_parameter(key, value, reason))
    }
}

pub(super) fn meta_number(log: &TumbleLog, key: &str) -> Result<Option<f64>, TumbleError> {
    log.meta(key)
        .map(|v| {
            v.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| bad_parameter(key, v, "not a finite number"))
        })
        .transpose()
}

pub(super) fn resolve(
    log: &TumbleLog,
    opts: &TumbleOptions,
) -> Result<(Params, String), TumbleError> {
    let (gravity_g, source) = match (opts.gravity_g, meta_number(log, "local_gravity_m_s2")?) {
        (Some(g), _) => (g, "--gravity-g".to_string()),
        (None, Some(m)) => (
            m / STANDARD_GRAVITY_M_S2,
            format!("local_gravity_m_s2 {m} / {STANDARD_GRAVITY_M_S2}"),
        ),
        (None, None) => (1.0, "default 1 g".to_string()),
    };
    require(
        gravity_g.is_finite() && gravity_g > 0.5 && gravity_g < 1.5,
        "gravity",
        gravity_g,
        "expected 0.5..1.5 g",
    )?;
    let index = match opts.index_error_arcsec {
        Some(v) => v,
        None => meta_number(log, "index_error_arcsec")?.unwrap_or(DEFAULT_INDEX_ERROR_ARCSEC),
    };
    require(
        index.is_finite() && index >= 0.0,
        "index_error_arcsec",
        index,
        "must be ≥ 0",
    )?;
    let axis = match opts.rotation_axis {
        Some(a) => a,
        None => match log.meta("rotation_axis") {
            Some(v) => RotationAxis::parse(v)
                .ok_or_else(|| bad_parameter("rotation_axis", v, "expected output or pendulum"))?,
            None => return Err(TumbleError::MissingRotationAxis),
        },
    };
    let gap_s = opts.gap_s.unwrap_or(DEFAULT_TEST_GAP_S);
    require(
        gap_s.is_finite() && gap_s > 0.0,
        "gap_s",
        gap_s,
        "must be > 0",
    )?;
    Ok((
        Params {
            gravity_g,
            index_error_arcsec: index,
            axis,
            gap_s,
        },
        source,
    ))
}

pub(super) fn reduce_deg(a: f64) -> f64 {
    let r = a.rem_euclid(360.0);
    if 360.0 - r < ANGLE_TOLERANCE_DEG {
        0.0
    } else {
        r
    }
}

pub(super) fn same_angle(a: f64, b: f64) -> bool {
    let d = (reduce_deg(a) - reduce_deg(b)).abs();
    d < ANGLE_TOLERANCE_DEG || (360.0 - d) < ANGLE_TOLERANCE_DEG
}

/// Splits the rows into tests. With a `test` column: by id (rows with one id form one test,
/// wherever they are). Otherwise a new test starts when the head returns to an angle already
/// visited in the current test (the sequence restarted), or when two consecutive rows are more
/// than `gap_s` apart in `time_s`.
pub(super) fn split_tests(rows: &[Row], gap_s: f64) -> Vec<(String, Vec<&Row>)> {
    let mut tests: Vec<(String, Vec<&Row>)> = Vec::new();
    if rows.iter().all(|r| r.test.is_some()) {
        let mut index: BTreeMap<&str, usize> = BTreeMap::new();
        for r in rows {
            let id = r.test.as_deref().unwrap_or_default();
            let k = *index.entry(id).or_insert_with(|| {
                tests.push((id.to_string(), Vec::new()));
                tests.len() - 1
            });
            tests[k].1.push(r);
        }
        return tests;
    }
    let mut current: Vec<&Row> = Vec::new();
    let mut visited: Vec<f64> = Vec::new();
    let mut prev: Option<&Row> = None;
    for r in rows {
        let gap =
            matches!((prev.and_then(|p| p.time_s), r.time_s), (Some(a), Some(b)) if b - a > gap_s);
        let moved = prev.is_some_and(|p| !same_angle(p.angle_deg, r.angle_deg));
        let restart = moved && visited.iter().any(|&v| same_angle(v, r.angle_deg));
        if (gap || restart) && !current.is_empty() {
            tests.push(((tests.len() + 1).to_string(), std::mem::take(&mut current)));
            visited.clear();
        }
        if !visited.iter().any(|&v| same_angle(v, r.angle_deg)) {
            visited.push(r.angle_deg);
        }
        current.push(r);
        prev = Some(r);
    }
    if !current.is_empty() {
        tests.push(((tests.len() + 1).to_string(), current));
    }
    tests
}

pub(super) fn mean_sd(v: &[f64]) -> (f64, Option<f64>) {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    if v.len() < 2 {
        return (m, None);
    }
    let ss: f64 = v.iter().map(|x| (x - m) * (x - m)).sum();
    (m, Some((ss / (n - 1.0)).sqrt()))
}

/// Σ = A·diag(w)·Aᵀ for A (p × n).
pub(super) fn sandwich(a: &[Vec<f64>], w: &[f64]) -> Vec<Vec<f64>> {
    let p = a.len();
    let mut s = vec![vec![0.0; p]; p];
    for i in 0..p {
        for j in 0..p {
            s[i][j] = (0..w.len()).map(|k| a[i][k] * w[k] * a[j][k]).sum();
        }
    }
    s
}

/// Variance of c_j / c_1 by the delta method (j ≠ 1), or of c_1 itself (j = 1).
pub(super) fn ratio_var(c: &[f64], cov: &[Vec<f64>], j: usize) -> f64 {
    if j == 1 {
        return cov[1][1];
    }
    let (dj, d1) = (1.0 / c[1], -c[j] / (c[1] * c[1]));
    dj * dj * cov[j][j] + 2.0 * dj * d1 * cov[j][1] + d1 * d1 * cov[1][1]
}

/// The coefficients of equation (1) from the linear parameters c.
pub(super) fn coefficients(c: &[f64], axis: RotationAxis) -> StaticCoefficients {
    let delta = Radians(c[3] / c[1]);
    let (p, o) = match axis {
        RotationAxis::Output => (Radians(0.0), delta),
        RotationAxis::Pendulum => (delta, Radians(0.0)),
    };
    StaticCoefficients {
        bias_g: c[0] / c[1],
        scale_factor_v_per_g: c[1],
        nonlinearity_g_per_g2: c[2] / c[1],
        misalignment_p: p,
        misalignment_o: o,
    }
}

/// Equation (1) (core) plus the K3 term, at head angle θ (rad).
pub(super) fn model_v(
    k: &StaticCoefficients,
    k3: f64,
    axis: RotationAxis,
    g: f64,
    theta: f64,
) -> f64 {
    let a_i = g * theta.sin();
    k.output(Gs(a_i), axis.cross(g, theta)).0 + k.scale_factor_v_per_g * k3 * a_i * a_i * a_i
}

pub(super) fn four_point(pos: &[(f64, f64)], g: f64, axis: RotationAxis) -> Option<FourPoint> {
    let at = |deg: f64| {
        pos.iter()
            .find(|(a, _)| same_angle(*a, deg))
            .map(|(_, e)| *e)
    };
    let (e0, e90, e180, e270) = (at(0.0)?, at(90.0)?, at(180.0)?, at(270.0)?);
    let k1 = (e90 - e270) / (2.0 * g);
    let diff = e0 - e180;
    Some(FourPoint {
        k1_v_per_g: k1,
        k0_g: (e0 + e180) / (2.0 * k1),
        k2_g_per_g2: (e90 + e270 - e0 - e180) / (2.0 * k1 * g * g),
        misalignment_arcmin: axis.sign() * diff / (2.0 * k1 * g) / RAD_PER_ARCMIN,
        zero_difference_v: diff,
        zero_sum_v: e0 + e180,
    })
}

pub(super) fn solve_test(id: &str, rows: &[&Row], p: &Params) -> Result<TestSolution, TumbleError> {
    // Positions: every reading at one angle, wherever it is in the test.
    let mut groups: Vec<(f64, Vec<f64>)> = Vec::new();
    for r in rows {
        match groups.iter_mut().find(|(a, _)| same_angle(*a, r.angle_deg)) {
            Some((_, v)) => v.push(r.output_v),
            None => groups.push((reduce_deg(r.angle_deg), vec![r.output_v])),
        }
    }
    groups.sort_by(|a, b| a.0.total_cmp(&b.0));
    let n = groups.len();
    let with_k3 = n >= 8;
    let unknowns = if with_k3 { 5 } else { 4 };
    if n < unknowns {
        return Err(TumbleError::TooFewPositions {
            test: id.into(),
            positions: n,
            unknowns,
        });
    }
    let largest_gap_deg = (0..n)
        .map(|i| {
            let next = if i + 1 < n {
                groups[i + 1].0
            } else {
                groups[0].0 + 360.0
            };
            next - groups[i].0
        })
        .fold(0.0, f64::max);
    if largest_gap_deg >= 180.0 - ANGLE_TOLERANCE_DEG {
        return Err(TumbleError::AnglesDoNotCoverCircle {
            test: id.into(),
            largest_gap_deg,
        });
    }
    let g = p.gravity_g;
    let stats: Vec<(f64, f64, Option<f64>, usize)> = groups
        .iter()
        .map(|(a, v)| {
            let (m, sd) = mean_sd(v);
            (a.to_radians(), m, sd, v.len())
        })
        .collect();
    // Design matrix: E = c0 + c1·g·s + c2·g²·s² + c3·(±g·c) + c4·g³·s³.
    let x: Vec<Vec<f64>> = stats
        .iter()
        .map(|&(th, ..)| {
            let (s, c) = (th.sin(), th.cos());
            let mut row = vec![1.0, g * s, g * g * s * s, p.axis.sign() * g * c];
            if with_k3 {
                row.push(g * g * g * s * s * s);
            }
            row
        })
        .collect();
    let y: Vec<f64> = stats.iter().map(|s| s.1).collect();
    // Least squares by QR on the design itself (numerics::linalg), never on XᵀX. A pivot
    // |R_kk| ≤ 1e-5·max‖x_j‖ (what a 1e-10 pivot of XᵀX was) is a singular design.
    let ls = least_squares_with(&x, &y, RankTolerance::RelativeToColumnNorm(1e-5))
        .map_err(|_| TumbleError::Singular { test: id.into() })?;
    // (XᵀX)⁻¹ and the solution operator A = (XᵀX)⁻¹Xᵀ = R⁻¹Qᵀ (c = A·y).
    let inv = ls.unscaled_covariance();
    let a = ls.solution_operator();
    let c = ls.coeffs;
    if !(c[1].is_finite() && c[1] > 1e-12) {
        return Err(TumbleError::BadScaleFactor {
            test: id.into(),
            k1: c[1],
        });
    }
    let k = coefficients(&c, p.axis);
    let k3 = if with_k3 { c[4] / c[1] } else { 0.0 };
    let residuals: Vec<f64> = stats
        .iter()
        .map(|&(th, m, ..)| m - model_v(&k, k3, p.axis, g, th))
        .collect();
    let rss: f64 = residuals.iter().map(|r| r * r).sum();
    let dof = n - unknowns;
    let (noise_cov, basis) = if dof > 0 {
        let s2 = rss / dof as f64;
        let cov: Vec<Vec<f64>> = inv
            .iter()
            .map(|r| r.iter().map(|v| v * s2).collect())
            .collect();
        (Some(cov), NoiseBasis::Residuals)
    } else if stats.iter().all(|s| s.2.is_some()) {
        let w: Vec<f64> = stats
            .iter()
            .map(|s| s.2.map_or(0.0, |sd| sd * sd / s.3 as f64))
            .collect();
        (Some(sandwich(&a, &w)), NoiseBasis::ReadingScatter)
    } else {
        (None, NoiseBasis::None)
    };
    // Index error: each position's angle is off by δθ (σ given), which moves its mean by
    // dE/dθ·δθ; dE/dθ from the fitted model by a central difference (h = 1 mrad: truncation
    // 2e-7 relative, irrelevant for an uncertainty).
    let h = 1e-3;
    let w_index: Vec<f64> = stats
        .iter()
        .map(|&(th, ..)| {
            let d = (model_v(&k, k3, p.axis, g, th + h) - model_v(&k, k3, p.axis, g, th - h))
                / (2.0 * h);
            (d * p.index_error_arcsec * RAD_PER_ARCSEC).powi(2)
        })
        .collect();
    let index_cov = sandwich(&a, &w_index);
    let est = |j: usize, value: f64, unit: f64| {
        let vi = ratio_var(&c, &index_cov, j).max(0.0);
        let vn = noise_cov.as_ref().map(|cov| ratio_var(&c, cov, j).max(0.0));
        Estimate {
            value,
            se: (vi + vn.unwrap_or(0.0)).sqrt() * unit,
            se_noise: vn.map(|v| v.sqrt() * unit),
            se_index: vi.sqrt() * unit,
        }
    };
    let delta = c[3] / c[1];
    let temps: Vec<f64> = rows.iter().filter_map(|r| r.temperature_c).collect();
    let times: Vec<f64> = rows.iter().filter_map(|r| r.time_s).collect();
    let time_s = (!times.is_empty()).then(|| times.iter().sum::<f64>() / times.len() as f64);
    let means: Vec<(f64, f64)> = groups.iter().zip(&stats).map(|(g, s)| (g.0, s.1)).collect();
    Ok(TestSolution {
        id: id.into(),
        first_line: rows.first().map_or(0, |r| r.line),
        rotation_axis: p.axis,
        temperature: TemperatureSummary::of(&temps),
        time_s,
        positions: groups
            .iter()
            .zip(&stats)
            .zip(&residuals)
            .map(|((gr, s), r)| PositionResult {
                angle_deg: gr.0,
                readings: s.3,
                mean_v: s.1,
                scatter_v: s.2,
                residual_v: *r,
            })
            .collect(),
        fit: FitSummary {
            unknowns,
            dof,
            noise_basis: basis,
            rms_residual_v: (rss / n as f64).sqrt(),
        },
        coefficients: ModelCoefficients {
            k0_g: est(0, k.bias_g, 1.0),
            k1_v_per_g: est(1, k.scale_factor_v_per_g, 1.0),
            k2_g_per_g2: est(2, k.nonlinearity_g_per_g2, 1.0),
            misalignment_arcmin: est(3, delta / RAD_PER_ARCMIN, 1.0 / RAD_PER_ARCMIN),
            k3_g_per_g3: with_k3.then(|| est(4, k3, 1.0)),
        },
        four_point: four_point(&means, g, p.axis),
    })
}
