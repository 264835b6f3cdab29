//! Multipoint tumble analysis (issue 7, docs/tumble.md): from a log of outputs at known
//! dividing-head angles to K0, K1, K2, δo or δp (and K3) per test, with standard errors, the
//! paper's 0 g / 1 g four-point definitions beside them, the coefficient table that `accomp fit`
//! reads, and the stability of each coefficient over repeated tests.
//!
//! Angle convention (docs/tumble.md): the head's axis is horizontal; at head angle θ the input
//! axis sees a_i = g·sin θ and the accelerometer axis that is *not* along the head axis sees
//! g·cos θ — the pendulum axis (a_p, identifies δo) when the head turns about the output axis, the
//! output axis (a_o, identifies δp) when it turns about the pendulum axis.
//!
//! Equation (1) is linear in c = (K1·K0, K1, K1·K2, K1·δ, K1·K3), so each test is an ordinary
//! least-squares problem in c; the physical coefficients are ratios c_j / c_1, their covariance
//! follows by the delta method. The model itself (fitted outputs, residuals, dE/dθ) is evaluated
//! with the core's `StaticCoefficients::output`, so the tool and the firmware share equation (1).

use std::collections::BTreeMap;
use std::fmt::Write as _;

use accomp::model::{CrossAxis, StaticCoefficients};
use accomp::units::{Gs, Radians, RAD_PER_ARCMIN, RAD_PER_ARCSEC};
use serde::Serialize;

use crate::log::reader::{ReadError, Records};
use crate::numerics::linalg::{least_squares_with, RankTolerance};

/// Standard gravity g_n (m/s²), the unit `local_gravity_m_s2` is divided by.
pub const STANDARD_GRAVITY_M_S2: f64 = 9.80665;
/// Default dividing-head index error (arcsec, 1σ): the paper's head indexes to 0.2".
pub const DEFAULT_INDEX_ERROR_ARCSEC: f64 = 0.2;
/// Default gap (s) between rows that starts a new test when the log has no `test` column.
pub const DEFAULT_TEST_GAP_S: f64 = 3600.0;
/// Two head angles closer than this (degrees) are the same position.
const ANGLE_TOLERANCE_DEG: f64 = 1e-6;
/// Tests whose mean temperatures differ by less than this (°C) share a coefficient-table row
/// and a stability group.
pub const TEMPERATURE_GROUP_TOLERANCE_C: f64 = 0.5;

/// Which accelerometer axis lies along the dividing head's (horizontal) rotation axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum RotationAxis {
    /// Head axis along the output axis: a_i = g·sin θ, a_p = g·cos θ, a_o = 0 → δo.
    Output,
    /// Head axis along the pendulum axis: a_i = g·sin θ, a_o = g·cos θ, a_p = 0 → δp.
    Pendulum,
}

impl RotationAxis {
    /// Parses the metadata / CLI spelling.
    pub fn parse(s: &str) -> Option<Self> {
        match s.trim().to_ascii_lowercase().as_str() {
            "output" => Some(RotationAxis::Output),
            "pendulum" => Some(RotationAxis::Pendulum),
            _ => None,
        }
    }

    /// The name of the misalignment this axis identifies, as a table column.
    pub fn misalignment_column(self) -> &'static str {
        match self {
            RotationAxis::Output => "delta_o_arcmin",
            RotationAxis::Pendulum => "delta_p_arcmin",
        }
    }

    /// The cross-axis inputs of equation (1) at head angle θ with gravity g (in g).
    pub fn cross(self, g: f64, theta: f64) -> CrossAxis {
        let c = g * theta.cos();
        match self {
            RotationAxis::Output => CrossAxis {
                a_p: Gs(c),
                a_o: Gs(0.0),
            },
            RotationAxis::Pendulum => CrossAxis {
                a_p: Gs(0.0),
                a_o: Gs(c),
            },
        }
    }

    /// Sign with which K1·δ·g·cos θ enters E: +δo·a_p, −δp·a_o.
    fn sign(self) -> f64 {
        match self {
            RotationAxis::Output => 1.0,
            RotationAxis::Pendulum => -1.0,
        }
    }
}

/// Why a tumble log could not be read or solved. Line numbers are 1-based lines of the file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TumbleError {
    /// No header row.
    #[error("the log has no header row")]
    NoHeader,
    /// A required column is missing from the header.
    #[error("the header has no `{0}` column")]
    MissingColumn(&'static str),
    /// A data row cannot be read.
    #[error("line {line}: {reason}")]
    Malformed {
        /// Line of the file.
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// A number is NaN or infinite.
    #[error("line {line}: `{column}` is not finite")]
    NonFinite {
        /// Line of the file.
        line: usize,
        /// Column name.
        column: String,
    },
    /// A metadata value or option is unusable.
    #[error("bad `{key}`: {value:?} ({reason})")]
    BadParameter {
        /// Metadata key or CLI option.
        key: String,
        /// Its value.
        value: String,
        /// Why.
        reason: &'static str,
    },
    /// Neither the metadata nor the command line says which axis the head turns about.
    #[error(
        "rotation axis unknown: add `# rotation_axis: output|pendulum` or pass --rotation-axis"
    )]
    MissingRotationAxis,
    /// The log has no data rows.
    #[error("the log has no data rows")]
    Empty,
    /// Fewer distinct positions than unknowns.
    #[error("test {test}: {positions} distinct positions for {unknowns} unknowns (K0, K1, K2, δ need at least 4)")]
    TooFewPositions {
        /// Test id.
        test: String,
        /// Distinct head angles in the test.
        positions: usize,
        /// Unknowns of the fitted model.
        unknowns: usize,
    },
    /// All positions lie within a half circle: the design is singular.
    #[error("test {test}: the angles do not cover the circle (largest gap {largest_gap_deg:.3}° ≥ 180°); K2 and δ cannot be separated")]
    AnglesDoNotCoverCircle {
        /// Test id.
        test: String,
        /// Largest circular gap between consecutive positions.
        largest_gap_deg: f64,
    },
    /// The normal matrix is singular for another reason (aliased positions).
    #[error("test {test}: the positions do not identify every coefficient (singular design)")]
    Singular {
        /// Test id.
        test: String,
    },
    /// The fitted scale factor is not positive or not finite: the ratios are meaningless, and a
    /// negative K1 means the angle sense (θ increasing towards input axis up) is reversed.
    #[error("test {test}: fitted K1 is {k1} V/g (negative: is the head angle sense reversed? see docs/tumble.md)")]
    BadScaleFactor {
        /// Test id.
        test: String,
        /// Fitted K1.
        k1: f64,
    },
    /// The coefficient table needs a temperature per test.
    #[error("test {0} has no temperature_c: the coefficient table needs one")]
    NoTemperature(String),
}

/// One data row.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    /// 1-based line in the file.
    pub line: usize,
    /// Nominal dividing-head angle (°).
    pub angle_deg: f64,
    /// Accelerometer output (V).
    pub output_v: f64,
    /// Operating temperature (°C), when logged.
    pub temperature_c: Option<f64>,
    /// Seconds since start, when logged.
    pub time_s: Option<f64>,
    /// Test id, when logged.
    pub test: Option<String>,
}

/// A parsed tumble log.
#[derive(Debug, Clone, PartialEq)]
pub struct TumbleLog {
    /// `# key: value` metadata in file order.
    pub metadata: Vec<(String, String)>,
    /// Data rows in file order.
    pub rows: Vec<Row>,
}

impl TumbleLog {
    /// The value of a metadata key (keys are unique: the reader refuses a repeated one).
    pub fn meta(&self, key: &str) -> Option<&str> {
        self.metadata
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }
}

fn parse_number(line: usize, column: &str, cell: &str) -> Result<f64, TumbleError> {
    let v: f64 = cell.trim().parse().map_err(|_| TumbleError::Malformed {
        line,
        reason: format!("`{column}` = {:?} is not a number", cell.trim()),
    })?;
    if !v.is_finite() {
        return Err(TumbleError::NonFinite {
            line,
            column: column.to_string(),
        });
    }
    Ok(v)
}

impl From<ReadError> for TumbleError {
    fn from(e: ReadError) -> Self {
        match e {
            ReadError::NoHeader => TumbleError::NoHeader,
            other => TumbleError::Malformed {
                line: other.line().unwrap_or(0),
                reason: other.what(),
            },
        }
    }
}

/// Reads a tumble log through the project's CSV reader (`log::reader`: `# key: value` lines,
/// one header row, then comma-separated rows). Required columns `angle_deg`, `output_v`;
/// optional `temperature_c`, `time_s`, `test`; other columns are ignored.
pub fn parse_log(text: &str) -> Result<TumbleLog, TumbleError> {
    let mut records = Records::from_text(text)?;
    let find = |n: &'static str| records.column(n).ok_or(TumbleError::MissingColumn(n));
    let (ia, io) = (find("angle_deg")?, find("output_v")?);
    let (it, its, itest) = (
        records.column("temperature_c"),
        records.column("time_s"),
        records.column("test"),
    );
    let metadata = records.take_meta();
    let mut rows = Vec::new();
    while let Some(row) = records.next_row()? {
        let line = row.line;
        let cell = |j: usize| row.text(j);
        let opt = |j: Option<usize>, name: &str| -> Result<Option<f64>, TumbleError> {
            j.map(|j| parse_number(line, name, cell(j)?)).transpose()
        };
        let test = match itest {
            Some(j) if cell(j)?.is_empty() => {
                return Err(TumbleError::Malformed {
                    line,
                    reason: "empty `test` id".into(),
                })
            }
            Some(j) => Some(cell(j)?.to_string()),
            None => None,
        };
        rows.push(Row {
            line,
            angle_deg: parse_number(line, "angle_deg", cell(ia)?)?,
            output_v: parse_number(line, "output_v", cell(io)?)?,
            temperature_c: opt(it, "temperature_c")?,
            time_s: opt(its, "time_s")?,
            test,
        });
    }
    if rows.is_empty() {
        return Err(TumbleError::Empty);
    }
    Ok(TumbleLog { metadata, rows })
}

/// Analysis options; `None` means "from the metadata, else the default".
#[derive(Debug, Clone, Default)]
pub struct TumbleOptions {
    /// Local gravity in units of standard g (`--gravity-g`).
    pub gravity_g: Option<f64>,
    /// Dividing-head index error, arcsec 1σ (`--index-error-arcsec`).
    pub index_error_arcsec: Option<f64>,
    /// Rotation axis (`--rotation-axis`).
    pub rotation_axis: Option<RotationAxis>,
    /// Time gap (s) that starts a new test when there is no `test` column.
    pub gap_s: Option<f64>,
}

/// A coefficient with its standard uncertainty.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Estimate {
    /// Value.
    pub value: f64,
    /// Total standard uncertainty: noise and index parts in quadrature.
    pub se: f64,
    /// Part from the output noise (residuals or reading scatter), when estimable.
    pub se_noise: Option<f64>,
    /// Part from the dividing-head index error.
    pub se_index: f64,
}

/// Where the noise part of the standard errors comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum NoiseBasis {
    /// s² = RSS/(n − p) of the position means (n > p).
    Residuals,
    /// n = p: the scatter of the repeated readings at each position, σ/√m per mean.
    ReadingScatter,
    /// n = p and one reading per position: not estimable; only the index part is stated.
    None,
}

/// One dividing-head position of a test.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PositionResult {
    /// Head angle (°, reduced to [0, 360)).
    pub angle_deg: f64,
    /// Readings averaged.
    pub readings: usize,
    /// Mean output (V).
    pub mean_v: f64,
    /// Sample standard deviation of the readings (V), when more than one.
    pub scatter_v: Option<f64>,
    /// Measured mean minus the fitted model (V).
    pub residual_v: f64,
}

/// The paper's definitions from the four cardinal positions 0°, 90°, 180°, 270°.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FourPoint {
    /// K1 = (E90 − E270)/(2g): absorbs K3·g² when K3 ≠ 0.
    pub k1_v_per_g: f64,
    /// K0 = (E0 + E180)/(2·K1): foundation tilt cancels in the sum.
    pub k0_g: f64,
    /// K2 = (E90 + E270 − E0 − E180)/(2·K1·g²).
    pub k2_g_per_g2: f64,
    /// δ = ±(E0 − E180)/(2·K1·g): a foundation tilt φ enters the difference twice (2φ), so δ
    /// carries the full tilt φ.
    pub misalignment_arcmin: f64,
    /// E0 − E180 (V), the horizontal-zero difference.
    pub zero_difference_v: f64,
    /// E0 + E180 (V), the horizontal-zero sum.
    pub zero_sum_v: f64,
}

/// The solution of one test.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TestSolution {
    /// Test id (from the `test` column, else 1, 2, … in file order).
    pub id: String,
    /// First line of the test in the file.
    pub first_line: usize,
    /// Which misalignment this test identifies.
    pub rotation_axis: RotationAxis,
    /// Mean temperature over the test, when logged.
    pub temperature_c: Option<f64>,
    /// Standard deviation of the temperature readings.
    pub temperature_sd_c: Option<f64>,
    /// Mean time of the test's readings (s), when logged.
    pub time_s: Option<f64>,
    /// The positions.
    pub positions: Vec<PositionResult>,
    /// Unknowns fitted (4, or 5 with K3).
    pub unknowns: usize,
    /// Degrees of freedom n − p.
    pub dof: usize,
    /// Where the noise part of the SE comes from.
    pub noise_basis: NoiseBasis,
    /// RMS of the position residuals (V).
    pub rms_residual_v: f64,
    /// K0 (g).
    pub k0_g: Estimate,
    /// K1 (V/g).
    pub k1_v_per_g: Estimate,
    /// K2 (g/g²).
    pub k2_g_per_g2: Estimate,
    /// δo (output axis) or δp (pendulum axis), arcmin.
    pub misalignment_arcmin: Estimate,
    /// K3 (g/g³), fitted when there are at least 8 positions.
    pub k3_g_per_g3: Option<Estimate>,
    /// The four-point definitions, when 0/90/180/270° are all present.
    pub four_point: Option<FourPoint>,
}

/// Linear regression of one coefficient against time over repeated tests.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CoefficientStability {
    /// Coefficient name with unit (`k0_g`, …).
    pub coefficient: String,
    /// Mean value.
    pub mean: f64,
    /// Slope per day.
    pub slope_per_day: f64,
    /// Standard error of the slope per day.
    pub slope_se_per_day: f64,
    /// Regression standard deviation sqrt(RSS/(n − 2)) — the paper's coefficient stability.
    pub regression_sd: f64,
}

/// Stability over the repeated tests at one temperature.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StabilityGroup {
    /// Mean temperature of the group, when logged.
    pub temperature_c: Option<f64>,
    /// Which misalignment the group's tests identify.
    pub rotation_axis: RotationAxis,
    /// Number of tests.
    pub tests: usize,
    /// Time from the first to the last test (days).
    pub span_days: f64,
    /// Per coefficient.
    pub coefficients: Vec<CoefficientStability>,
}

/// The whole analysis of one or more logs.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TumbleReport {
    /// Local gravity used, in standard g (g_n = 9.80665 m/s²).
    pub gravity_g: f64,
    /// Where it came from.
    pub gravity_source: String,
    /// Dividing-head index error used (arcsec, 1σ).
    pub index_error_arcsec: f64,
    /// Every test.
    pub tests: Vec<TestSolution>,
    /// Stability groups (temperatures with at least three timed tests).
    pub stability: Vec<StabilityGroup>,
}

/// Resolved parameters of one log.
#[derive(Debug, Clone, Copy)]
struct Params {
    gravity_g: f64,
    index_error_arcsec: f64,
    axis: RotationAxis,
    gap_s: f64,
}

fn meta_number(log: &TumbleLog, key: &str) -> Result<Option<f64>, TumbleError> {
    log.meta(key)
        .map(|v| {
            v.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| TumbleError::BadParameter {
                    key: key.into(),
                    value: v.into(),
                    reason: "not a finite number",
                })
        })
        .transpose()
}

fn resolve(log: &TumbleLog, opts: &TumbleOptions) -> Result<(Params, String), TumbleError> {
    let (gravity_g, source) = match (opts.gravity_g, meta_number(log, "local_gravity_m_s2")?) {
        (Some(g), _) => (g, "--gravity-g".to_string()),
        (None, Some(m)) => (
            m / STANDARD_GRAVITY_M_S2,
            format!("local_gravity_m_s2 {m} / {STANDARD_GRAVITY_M_S2}"),
        ),
        (None, None) => (1.0, "default 1 g".to_string()),
    };
    if !(gravity_g.is_finite() && gravity_g > 0.5 && gravity_g < 1.5) {
        return Err(TumbleError::BadParameter {
            key: "gravity".into(),
            value: gravity_g.to_string(),
            reason: "expected 0.5..1.5 g",
        });
    }
    let index = match opts.index_error_arcsec {
        Some(v) => v,
        None => meta_number(log, "index_error_arcsec")?.unwrap_or(DEFAULT_INDEX_ERROR_ARCSEC),
    };
    if !(index.is_finite() && index >= 0.0) {
        return Err(TumbleError::BadParameter {
            key: "index_error_arcsec".into(),
            value: index.to_string(),
            reason: "must be ≥ 0",
        });
    }
    let axis = match opts.rotation_axis {
        Some(a) => a,
        None => match log.meta("rotation_axis") {
            Some(v) => RotationAxis::parse(v).ok_or_else(|| TumbleError::BadParameter {
                key: "rotation_axis".into(),
                value: v.into(),
                reason: "expected output or pendulum",
            })?,
            None => return Err(TumbleError::MissingRotationAxis),
        },
    };
    let gap_s = opts.gap_s.unwrap_or(DEFAULT_TEST_GAP_S);
    if !(gap_s.is_finite() && gap_s > 0.0) {
        return Err(TumbleError::BadParameter {
            key: "gap_s".into(),
            value: gap_s.to_string(),
            reason: "must be > 0",
        });
    }
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

fn reduce_deg(a: f64) -> f64 {
    let r = a.rem_euclid(360.0);
    if 360.0 - r < ANGLE_TOLERANCE_DEG {
        0.0
    } else {
        r
    }
}

fn same_angle(a: f64, b: f64) -> bool {
    let d = (reduce_deg(a) - reduce_deg(b)).abs();
    d < ANGLE_TOLERANCE_DEG || (360.0 - d) < ANGLE_TOLERANCE_DEG
}

/// Splits the rows into tests. With a `test` column: by id (rows with one id form one test,
/// wherever they are). Otherwise a new test starts when the head returns to an angle already
/// visited in the current test (the sequence restarted), or when two consecutive rows are more
/// than `gap_s` apart in `time_s`.
fn split_tests(rows: &[Row], gap_s: f64) -> Vec<(String, Vec<&Row>)> {
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

fn mean_sd(v: &[f64]) -> (f64, Option<f64>) {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    if v.len() < 2 {
        return (m, None);
    }
    let ss: f64 = v.iter().map(|x| (x - m) * (x - m)).sum();
    (m, Some((ss / (n - 1.0)).sqrt()))
}

/// Σ = A·diag(w)·Aᵀ for A (p × n).
fn sandwich(a: &[Vec<f64>], w: &[f64]) -> Vec<Vec<f64>> {
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
fn ratio_var(c: &[f64], cov: &[Vec<f64>], j: usize) -> f64 {
    if j == 1 {
        return cov[1][1];
    }
    let (dj, d1) = (1.0 / c[1], -c[j] / (c[1] * c[1]));
    dj * dj * cov[j][j] + 2.0 * dj * d1 * cov[j][1] + d1 * d1 * cov[1][1]
}

/// The coefficients of equation (1) from the linear parameters c.
fn coefficients(c: &[f64], axis: RotationAxis) -> StaticCoefficients {
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
fn model_v(k: &StaticCoefficients, k3: f64, axis: RotationAxis, g: f64, theta: f64) -> f64 {
    let a_i = g * theta.sin();
    k.output(Gs(a_i), axis.cross(g, theta)).0 + k.scale_factor_v_per_g * k3 * a_i * a_i * a_i
}

fn four_point(pos: &[(f64, f64)], g: f64, axis: RotationAxis) -> Option<FourPoint> {
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

fn solve_test(id: &str, rows: &[&Row], p: &Params) -> Result<TestSolution, TumbleError> {
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
    let (temperature_c, temperature_sd_c) = if temps.is_empty() {
        (None, None)
    } else {
        let (m, sd) = mean_sd(&temps);
        (Some(m), sd)
    };
    let times: Vec<f64> = rows.iter().filter_map(|r| r.time_s).collect();
    let time_s = (!times.is_empty()).then(|| times.iter().sum::<f64>() / times.len() as f64);
    let means: Vec<(f64, f64)> = groups.iter().zip(&stats).map(|(g, s)| (g.0, s.1)).collect();
    Ok(TestSolution {
        id: id.into(),
        first_line: rows.first().map_or(0, |r| r.line),
        rotation_axis: p.axis,
        temperature_c,
        temperature_sd_c,
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
        unknowns,
        dof,
        noise_basis: basis,
        rms_residual_v: (rss / n as f64).sqrt(),
        k0_g: est(0, k.bias_g, 1.0),
        k1_v_per_g: est(1, k.scale_factor_v_per_g, 1.0),
        k2_g_per_g2: est(2, k.nonlinearity_g_per_g2, 1.0),
        misalignment_arcmin: est(3, delta / RAD_PER_ARCMIN, 1.0 / RAD_PER_ARCMIN),
        k3_g_per_g3: with_k3.then(|| est(4, k3, 1.0)),
        four_point: four_point(&means, g, p.axis),
    })
}

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
fn temperature_groups(tests: &[TestSolution]) -> Vec<Vec<&TestSolution>> {
    let mut groups: Vec<Vec<&TestSolution>> = Vec::new();
    for t in tests {
        let found = groups.iter_mut().find(|g| {
            g[0].rotation_axis == t.rotation_axis
                && match (g[0].temperature_c, t.temperature_c) {
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

fn stability(tests: &[TestSolution]) -> Vec<StabilityGroup> {
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
            ("k0_g", |t| t.k0_g.value),
            ("k1_v_per_g", |t| t.k1_v_per_g.value),
            ("k2_g_per_g2", |t| t.k2_g_per_g2.value),
            ("misalignment_arcmin", |t| t.misalignment_arcmin.value),
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
        let temps: Vec<f64> = timed.iter().filter_map(|t| t.temperature_c).collect();
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

/// Solves every test of a log.
pub fn solve_log(log: &TumbleLog, opts: &TumbleOptions) -> Result<TumbleReport, TumbleError> {
    analyse(&[log], opts)
}

/// Solves every test of one or more logs (e.g. one turned about the pendulum axis for δp and one
/// about the output axis for δo) and the coefficient stability. Gravity and index error must
/// agree across logs; the first log's values are reported.
pub fn analyse(logs: &[&TumbleLog], opts: &TumbleOptions) -> Result<TumbleReport, TumbleError> {
    let mut tests = Vec::new();
    let mut head: Option<(Params, String)> = None;
    for log in logs {
        let (p, src) = resolve(log, opts)?;
        for (id, rows) in split_tests(&log.rows, p.gap_s) {
            let id = if logs.len() > 1 {
                format!("{}:{id}", tests.len() + 1)
            } else {
                id
            };
            tests.push(solve_test(&id, &rows, &p)?);
        }
        head.get_or_insert((p, src));
    }
    let (p, src) = head.ok_or(TumbleError::Empty)?;
    Ok(TumbleReport {
        gravity_g: p.gravity_g,
        gravity_source: src,
        index_error_arcsec: p.index_error_arcsec,
        stability: stability(&tests),
        tests,
    })
}

/// Inverse-variance weighted mean of estimates and its standard error.
fn weighted(es: &[Estimate]) -> Option<(f64, f64)> {
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

/// One row of the coefficient table: a temperature and the weighted means (value, SE) of the
/// tests there.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TableRow {
    /// Mean temperature of the tests.
    pub temperature_c: f64,
    /// Tests combined.
    pub tests: usize,
    /// K0 (g), SE.
    pub k0_g: (f64, f64),
    /// K1 (V/g), SE.
    pub k1_v_per_g: (f64, f64),
    /// K2 (g/g²), SE.
    pub k2_g_per_g2: (f64, f64),
    /// δp (arcmin), SE, when a pendulum-axis test exists at this temperature.
    pub delta_p_arcmin: Option<(f64, f64)>,
    /// δo (arcmin), SE, when an output-axis test exists at this temperature.
    pub delta_o_arcmin: Option<(f64, f64)>,
}

/// The coefficient table: one row per test temperature (tests within
/// [`TEMPERATURE_GROUP_TOLERANCE_C`] combined by inverse-variance weighted means; K0, K1, K2
/// from every test, δp from pendulum-axis tests, δo from output-axis tests), sorted by
/// temperature.
pub fn coefficient_table(report: &TumbleReport) -> Result<Vec<TableRow>, TumbleError> {
    let mut groups: Vec<Vec<&TestSolution>> = Vec::new();
    for t in &report.tests {
        let temp = t
            .temperature_c
            .ok_or_else(|| TumbleError::NoTemperature(t.id.clone()))?;
        match groups.iter_mut().find(|g| {
            g[0].temperature_c
                .is_some_and(|a| (a - temp).abs() < TEMPERATURE_GROUP_TOLERANCE_C)
        }) {
            Some(g) => g.push(t),
            None => groups.push(vec![t]),
        }
    }
    let mut rows = Vec::new();
    for g in groups {
        let pick = |f: fn(&TestSolution) -> Estimate| g.iter().map(|t| f(t)).collect::<Vec<_>>();
        let axis = |a: RotationAxis| {
            g.iter()
                .filter(|t| t.rotation_axis == a)
                .map(|t| t.misalignment_arcmin)
                .collect::<Vec<_>>()
        };
        let temps: Vec<f64> = g.iter().filter_map(|t| t.temperature_c).collect();
        let (Some(k0), Some(k1), Some(k2)) = (
            weighted(&pick(|t| t.k0_g)),
            weighted(&pick(|t| t.k1_v_per_g)),
            weighted(&pick(|t| t.k2_g_per_g2)),
        ) else {
            continue;
        };
        rows.push(TableRow {
            temperature_c: temps.iter().sum::<f64>() / temps.len() as f64,
            tests: g.len(),
            k0_g: k0,
            k1_v_per_g: k1,
            k2_g_per_g2: k2,
            delta_p_arcmin: weighted(&axis(RotationAxis::Pendulum)),
            delta_o_arcmin: weighted(&axis(RotationAxis::Output)),
        });
    }
    rows.sort_by(|a, b| a.temperature_c.total_cmp(&b.temperature_c));
    Ok(rows)
}

/// The coefficient table as CSV in the format of the shared Table 1 file
/// (`temperature_c,k0_g,k1_v_per_g,k2_g_per_g2,delta_p_arcmin` [`,delta_o_arcmin`]); with
/// `with_se`, one `<column>_se` column per coefficient is appended. A column is written when at
/// least one row has it; a row without it leaves the cell empty.
pub fn table_csv(report: &TumbleReport, with_se: bool) -> Result<String, TumbleError> {
    let rows = coefficient_table(report)?;
    let has_p = rows.iter().any(|r| r.delta_p_arcmin.is_some());
    let has_o = rows.iter().any(|r| r.delta_o_arcmin.is_some());
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# Static model coefficients from dividing-head tumble tests (accomp tumble)."
    );
    let _ = writeln!(
        s,
        "# Local gravity {} g_n ({}), g_n = {STANDARD_GRAVITY_M_S2} m/s^2; index error {} arcsec (1 sigma).",
        report.gravity_g, report.gravity_source, report.index_error_arcsec
    );
    let _ = writeln!(
        s,
        "# Columns: temperature (degC); K0 bias (g); K1 scale factor (V/g); K2 second-order nonlinearity (g/g^2);"
    );
    let _ = writeln!(
        s,
        "# delta_p / delta_o misalignments (arcmin). One row per test temperature (weighted mean of its tests)."
    );
    let mut cols = vec!["temperature_c", "k0_g", "k1_v_per_g", "k2_g_per_g2"];
    if has_p {
        cols.push("delta_p_arcmin");
    }
    if has_o {
        cols.push("delta_o_arcmin");
    }
    let mut header = cols.join(",");
    if with_se {
        for c in &cols[1..] {
            let _ = write!(header, ",{c}_se");
        }
    }
    let _ = writeln!(s, "{header}");
    let opt = |v: Option<(f64, f64)>, se: bool| {
        v.map_or(String::new(), |(m, e)| {
            format!("{}", if se { e } else { m })
        })
    };
    for r in rows {
        let mut vals = vec![Some(r.k0_g), Some(r.k1_v_per_g), Some(r.k2_g_per_g2)];
        if has_p {
            vals.push(r.delta_p_arcmin);
        }
        if has_o {
            vals.push(r.delta_o_arcmin);
        }
        let mut line = format!("{}", round_temperature(r.temperature_c));
        for v in &vals {
            let _ = write!(line, ",{}", opt(*v, false));
        }
        if with_se {
            for v in &vals {
                let _ = write!(line, ",{}", opt(*v, true));
            }
        }
        let _ = writeln!(s, "{line}");
    }
    Ok(s)
}

/// Temperatures to 0.001 °C: the RTD is good to 0.1 °C, more digits are noise.
fn round_temperature(t: f64) -> f64 {
    (t * 1000.0).round() / 1000.0
}

fn fmt_est(e: &Estimate) -> String {
    format!("{:>16.9e} ± {:.2e}", e.value, e.se)
}

/// A human-readable report.
pub fn render_text(r: &TumbleReport) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "local gravity {} g_n ({}); index error {} arcsec (1σ)",
        r.gravity_g, r.gravity_source, r.index_error_arcsec
    );
    for t in &r.tests {
        let _ = writeln!(
            s,
            "\ntest {} (line {}), rotation about the {} axis{}{}",
            t.id,
            t.first_line,
            match t.rotation_axis {
                RotationAxis::Output => "output",
                RotationAxis::Pendulum => "pendulum",
            },
            t.temperature_c
                .map_or(String::new(), |c| format!(", {c:.3} °C")),
            t.time_s
                .map_or(String::new(), |x| format!(", t = {x:.0} s")),
        );
        let _ = writeln!(
            s,
            "  {:>10} {:>4} {:>16} {:>11} {:>12}",
            "angle_deg", "n", "mean_v", "scatter_v", "residual_v"
        );
        for p in &t.positions {
            let _ = writeln!(
                s,
                "  {:>10.4} {:>4} {:>16.10} {:>11} {:>12.3e}",
                p.angle_deg,
                p.readings,
                p.mean_v,
                p.scatter_v.map_or("-".into(), |v| format!("{v:.2e}")),
                p.residual_v
            );
        }
        let _ = writeln!(
            s,
            "  least squares ({} unknowns, {} dof, noise from {:?}, rms residual {:.2e} V):",
            t.unknowns, t.dof, t.noise_basis, t.rms_residual_v
        );
        let _ = writeln!(s, "    K0 (g)       {}", fmt_est(&t.k0_g));
        let _ = writeln!(s, "    K1 (V/g)     {}", fmt_est(&t.k1_v_per_g));
        let _ = writeln!(s, "    K2 (g/g²)    {}", fmt_est(&t.k2_g_per_g2));
        let _ = writeln!(
            s,
            "    {} {}",
            match t.rotation_axis {
                RotationAxis::Output => "δo (arcmin) ",
                RotationAxis::Pendulum => "δp (arcmin) ",
            },
            fmt_est(&t.misalignment_arcmin)
        );
        if let Some(k3) = &t.k3_g_per_g3 {
            let _ = writeln!(s, "    K3 (g/g³)    {}", fmt_est(k3));
        }
        if let Some(f) = &t.four_point {
            let _ = writeln!(
                s,
                "  four-point (paper): K0 {:.9e} g, K1 {:.9e} V/g, K2 {:.3e} g/g², δ {:.5} arcmin",
                f.k0_g, f.k1_v_per_g, f.k2_g_per_g2, f.misalignment_arcmin
            );
        }
    }
    for g in &r.stability {
        let _ = writeln!(
            s,
            "\nstability over {} tests, {:.2} days{}:",
            g.tests,
            g.span_days,
            g.temperature_c
                .map_or(String::new(), |c| format!(" at {c:.2} °C"))
        );
        for c in &g.coefficients {
            let _ = writeln!(
                s,
                "  {:<20} mean {:>15.9e}  slope {:>10.3e} ± {:.2e} /day  regression sd {:.3e}",
                c.coefficient, c.mean, c.slope_per_day, c.slope_se_per_day, c.regression_sd
            );
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    const K1: f64 = 1.3;
    const K0: f64 = 0.005;
    const K2: f64 = 2e-5;
    /// 2 arcmin in rad, written out: 2·π/10800.
    const DELTA_RAD: f64 = 2.0 * std::f64::consts::PI / 10_800.0;

    /// A log whose outputs are equation (1) written out by hand (not through the core), with the
    /// head at `angle + tilt` and one row per entry of `readings` (offsets added to E).
    fn hand_log(
        axis: &str,
        angles_deg: &[f64],
        g: f64,
        k3: f64,
        tilt_rad: f64,
        readings: &[f64],
        extra_meta: &str,
    ) -> String {
        let mut s = format!("# rotation_axis: {axis}\n{extra_meta}angle_deg,output_v\n");
        for &a in angles_deg {
            let th = a.to_radians() + tilt_rad;
            let ai = g * th.sin();
            let cross = g * th.cos();
            let mis = if axis == "output" {
                DELTA_RAD * cross
            } else {
                -DELTA_RAD * cross
            };
            let e = K1 * (K0 + ai + K2 * ai * ai + k3 * ai * ai * ai + mis);
            for d in readings {
                s.push_str(&format!("{a},{}\n", e + d));
            }
        }
        s
    }

    fn solve(text: &str) -> Result<TumbleReport, TumbleError> {
        solve_log(&parse_log(text)?, &TumbleOptions::default())
    }

    fn zero_index() -> TumbleOptions {
        TumbleOptions {
            index_error_arcsec: Some(0.0),
            ..TumbleOptions::default()
        }
    }

    #[test]
    fn four_noise_free_positions_recover_k0_k1_k2_and_delta_p_exactly() {
        let r = solve(&hand_log(
            "pendulum",
            &[0.0, 90.0, 180.0, 270.0],
            1.0,
            0.0,
            0.0,
            &[0.0],
            "",
        ))
        .unwrap();
        let t = &r.tests[0];
        assert_eq!((t.unknowns, t.dof, t.noise_basis), (4, 0, NoiseBasis::None));
        assert!((t.k1_v_per_g.value - K1).abs() < 1e-14);
        assert!((t.k0_g.value - K0).abs() < 1e-15);
        assert!((t.k2_g_per_g2.value - K2).abs() < 1e-14);
        assert!((t.misalignment_arcmin.value - 2.0).abs() < 1e-10);
        assert!(t.k3_g_per_g3.is_none());
        let f = t.four_point.unwrap();
        assert!((f.k0_g - K0).abs() < 1e-15 && (f.k1_v_per_g - K1).abs() < 1e-14);
        assert!((f.k2_g_per_g2 - K2).abs() < 1e-14);
        assert!((f.misalignment_arcmin - 2.0).abs() < 1e-10);
    }

    #[test]
    fn rotation_about_the_output_axis_identifies_delta_o_with_its_own_sign() {
        let r = solve(&hand_log(
            "output",
            &[0.0, 90.0, 180.0, 270.0],
            1.0,
            0.0,
            0.0,
            &[0.0],
            "",
        ))
        .unwrap();
        let t = &r.tests[0];
        assert_eq!(t.rotation_axis, RotationAxis::Output);
        assert!((t.misalignment_arcmin.value - 2.0).abs() < 1e-10);
        // E0 − E180 = +2·K1·δo·g for the output axis.
        let f = t.four_point.unwrap();
        assert!((f.zero_difference_v - 2.0 * K1 * DELTA_RAD).abs() < 1e-15);
        assert!((f.misalignment_arcmin - 2.0).abs() < 1e-10);
    }

    #[test]
    fn eight_positions_add_k3_and_recover_it() {
        let angles: Vec<f64> = (0..8).map(|i| 45.0 * f64::from(i)).collect();
        let r = solve(&hand_log("pendulum", &angles, 1.0, 3e-5, 0.0, &[0.0], "")).unwrap();
        let t = &r.tests[0];
        assert_eq!((t.unknowns, t.dof), (5, 3));
        assert!((t.k3_g_per_g3.unwrap().value - 3e-5).abs() < 1e-13);
        assert!((t.k1_v_per_g.value - K1).abs() < 1e-13);
        // The four-point K1 absorbs K3: (E90 − E270)/2 = K1·(1 + K3).
        let f = t.four_point.unwrap();
        assert!((f.k1_v_per_g - K1 * (1.0 + 3e-5)).abs() < 1e-13);
    }

    #[test]
    fn local_gravity_from_metadata_is_divided_by_standard_gravity() {
        let g = 9.7940 / 9.80665;
        let text = hand_log(
            "pendulum",
            &[0.0, 90.0, 180.0, 270.0],
            g,
            0.0,
            0.0,
            &[0.0],
            "# local_gravity_m_s2: 9.7940\n",
        );
        let r = solve(&text).unwrap();
        assert!((r.gravity_g - g).abs() < 1e-15);
        assert!((r.tests[0].k1_v_per_g.value - K1).abs() < 1e-13);
        // Ignoring local gravity (1 g forced) makes K1 wrong by the gravity ratio.
        let forced = solve_log(
            &parse_log(&text).unwrap(),
            &TumbleOptions {
                gravity_g: Some(1.0),
                ..TumbleOptions::default()
            },
        )
        .unwrap();
        assert!((forced.tests[0].k1_v_per_g.value - K1 * g).abs() < 1e-13);
    }

    #[test]
    fn index_error_propagates_to_half_the_angle_variance_at_four_points() {
        // Hand propagation for 0/90/180/270 with σθ = 0.2": K0 and δ are half-sum and
        // half-difference of E0 and E180, where dE/dθ = ±K1·g, so σ(K0) = σθ·g/√2 and
        // σ(δ) = σθ/√2; K2 also gets σθ/√2 (E0, E180 enter it with weight 1/(2K1)).
        let r = solve(&hand_log(
            "pendulum",
            &[0.0, 90.0, 180.0, 270.0],
            1.0,
            0.0,
            0.0,
            &[0.0],
            "",
        ))
        .unwrap();
        let t = &r.tests[0];
        let sigma_rad = 0.2 * 4.848_136_811e-6;
        let half = sigma_rad / std::f64::consts::SQRT_2;
        assert!(t.k0_g.se_noise.is_none());
        assert!(
            (t.k0_g.se_index / half - 1.0).abs() < 1e-3,
            "{}",
            t.k0_g.se_index
        );
        assert!((t.k2_g_per_g2.se / half - 1.0).abs() < 1e-3);
        let delta_arcmin = 0.2 / 60.0 / std::f64::consts::SQRT_2;
        assert!((t.misalignment_arcmin.se / delta_arcmin - 1.0).abs() < 1e-3);
        // K1 only sees dE/dθ = ±K1·δ at 90°/270°: σ = K1·δ·σθ/√2 ≈ 1e-9 V/g.
        assert!((t.k1_v_per_g.se / (K1 * DELTA_RAD * half) - 1.0).abs() < 1e-2);
    }

    #[test]
    fn reading_scatter_gives_the_noise_se_when_the_design_is_exactly_determined() {
        // Two readings ±d per position: sample sd d·√2, SE of each mean d. K0 = c0/c1 with
        // c0 = (E0+E180)/2 and c1 = (E90−E270)/2 independent, each of variance d²/2, so
        // σ²(K0) = (d²/2)·(1 + K0²)/K1².
        let d = 1e-6;
        let log = parse_log(&hand_log(
            "pendulum",
            &[0.0, 90.0, 180.0, 270.0],
            1.0,
            0.0,
            0.0,
            &[-d, d],
            "",
        ))
        .unwrap();
        let r = solve_log(&log, &zero_index()).unwrap();
        let t = &r.tests[0];
        assert_eq!(t.noise_basis, NoiseBasis::ReadingScatter);
        assert_eq!(t.positions[0].readings, 2);
        assert!((t.positions[0].scatter_v.unwrap() - d * std::f64::consts::SQRT_2).abs() < 1e-12);
        let expect = d * ((1.0 + K0 * K0) / 2.0).sqrt() / K1;
        assert!((t.k0_g.se / expect - 1.0).abs() < 1e-6, "{}", t.k0_g.se);
        assert_eq!(t.k0_g.se_index, 0.0);
    }

    #[test]
    fn residual_se_is_used_when_there_are_more_positions_than_unknowns() {
        // Twelve positions, one reading each, one output off by ε: the residuals are non-zero
        // and sum to zero (the constant column), and the SE basis is the residuals.
        let angles: Vec<f64> = (0..12).map(|i| 30.0 * f64::from(i)).collect();
        let mut text = hand_log("pendulum", &angles, 1.0, 0.0, 0.0, &[0.0], "");
        text = text.replacen("\n30,", "\n30,1e-6+", 1);
        // "1e-6+x" is not a number: this checks the malformed-row path on the way.
        assert!(matches!(
            solve(&text),
            Err(TumbleError::Malformed { line: 4, .. })
        ));
        let mut lines: Vec<String> = hand_log("pendulum", &angles, 1.0, 0.0, 0.0, &[0.0], "")
            .lines()
            .map(String::from)
            .collect();
        let (a, e) = lines[3].split_once(',').unwrap();
        lines[3] = format!("{a},{}", e.parse::<f64>().unwrap() + 1e-6);
        let r = solve_log(&parse_log(&lines.join("\n")).unwrap(), &zero_index()).unwrap();
        let t = &r.tests[0];
        assert_eq!(
            (t.unknowns, t.dof, t.noise_basis),
            (5, 7, NoiseBasis::Residuals)
        );
        let sum: f64 = t.positions.iter().map(|p| p.residual_v).sum();
        assert!(sum.abs() < 1e-15);
        assert!(t.rms_residual_v > 1e-8 && t.k0_g.se_noise.unwrap() > 0.0);
    }

    #[test]
    fn foundation_tilt_cancels_in_the_bias_and_enters_the_misalignment_fully() {
        // Tilt φ = 1": the zero difference E0 − E180 grows by 2·K1·φ (tilt counted twice), so
        // δ = difference/(2·K1·g) is off by φ = 1/60 arcmin; the sum (bias) is unchanged.
        let phi = 4.848_136_811e-6;
        let r = solve(&hand_log(
            "output",
            &[0.0, 90.0, 180.0, 270.0],
            1.0,
            0.0,
            phi,
            &[0.0],
            "",
        ))
        .unwrap();
        let f = r.tests[0].four_point.unwrap();
        // Sum: 2·K1·(K0 + K2·sin²φ); K2·φ² is 5e-16 g, the rest is rounding of π in the
        // head angle — nine orders below the 2·K1·φ = 1.3e-5 V the tilt puts into the difference.
        assert!((f.zero_sum_v - 2.0 * K1 * K0).abs() < 1e-14);
        // The four-point K1 carries (1 − δo·φ) from the 90°/270° pair, hence 1e-10 on K0.
        assert!((f.k0_g - K0).abs() < 1e-10);
        assert!((f.zero_difference_v - 2.0 * K1 * (DELTA_RAD + phi)).abs() < 1e-12);
        assert!((f.misalignment_arcmin - (2.0 + 1.0 / 60.0)).abs() < 1e-6);
        assert!((r.tests[0].misalignment_arcmin.value - (2.0 + 1.0 / 60.0)).abs() < 1e-6);
    }

    #[test]
    fn fewer_positions_than_unknowns_is_refused_with_counts() {
        let e = solve(&hand_log(
            "pendulum",
            &[0.0, 120.0, 240.0],
            1.0,
            0.0,
            0.0,
            &[0.0],
            "",
        ));
        assert_eq!(
            e,
            Err(TumbleError::TooFewPositions {
                test: "1".into(),
                positions: 3,
                unknowns: 4
            })
        );
    }

    #[test]
    fn positions_within_half_a_circle_are_refused() {
        let e = solve(&hand_log(
            "pendulum",
            &[0.0, 45.0, 90.0, 135.0, 180.0],
            1.0,
            0.0,
            0.0,
            &[0.0],
            "",
        ));
        assert!(matches!(
            e,
            Err(TumbleError::AnglesDoNotCoverCircle { largest_gap_deg, .. }) if (largest_gap_deg - 180.0).abs() < 1e-9
        ));
    }

    #[test]
    fn six_equally_spaced_positions_fit_four_unknowns_but_would_alias_k3() {
        // At multiples of 60°, sin 3θ = 0, so sin³θ = ¾·sin θ: K3 is not separable from K1.
        // Below 8 positions K3 is not fitted, so six positions solve with 2 dof.
        let angles: Vec<f64> = (0..6).map(|i| 60.0 * f64::from(i)).collect();
        let r = solve(&hand_log("pendulum", &angles, 1.0, 0.0, 0.0, &[0.0], "")).unwrap();
        assert_eq!((r.tests[0].unknowns, r.tests[0].dof), (4, 2));
        for th in &angles {
            let s = th.to_radians().sin();
            assert!((s.powi(3) - 0.75 * s).abs() < 1e-15);
        }
    }

    #[test]
    fn nan_output_is_refused_with_its_line() {
        let text = "# rotation_axis: output\nangle_deg,output_v\n0,0.1\n90,NaN\n";
        assert_eq!(
            parse_log(text),
            Err(TumbleError::NonFinite {
                line: 4,
                column: "output_v".into()
            })
        );
    }

    #[test]
    fn malformed_rows_and_missing_columns_are_named() {
        assert!(matches!(
            parse_log("angle_deg,output_v\n0,0.1\n90\n"),
            Err(TumbleError::Malformed { line: 3, .. })
        ));
        assert!(matches!(
            parse_log("angle_deg,output_v\n0,abc\n"),
            Err(TumbleError::Malformed { line: 2, .. })
        ));
        assert_eq!(
            parse_log("angle_deg,volts\n0,1\n"),
            Err(TumbleError::MissingColumn("output_v"))
        );
        assert_eq!(parse_log("# only: comments\n"), Err(TumbleError::NoHeader));
        assert_eq!(parse_log("angle_deg,output_v\n"), Err(TumbleError::Empty));
    }

    #[test]
    fn the_rotation_axis_must_be_stated() {
        let text = hand_log(
            "pendulum",
            &[0.0, 90.0, 180.0, 270.0],
            1.0,
            0.0,
            0.0,
            &[0.0],
            "",
        )
        .replace("# rotation_axis: pendulum\n", "");
        assert_eq!(solve(&text), Err(TumbleError::MissingRotationAxis));
        let bad = hand_log(
            "pendulum",
            &[0.0, 90.0, 180.0, 270.0],
            1.0,
            0.0,
            0.0,
            &[0.0],
            "",
        )
        .replace("pendulum", "input");
        assert!(matches!(solve(&bad), Err(TumbleError::BadParameter { .. })));
    }

    #[test]
    fn without_a_test_column_a_restarted_sequence_or_a_time_gap_starts_a_new_test() {
        let rows = |t0: f64| -> String {
            [0.0, 90.0, 180.0, 270.0]
                .iter()
                .enumerate()
                .map(|(i, a)| {
                    let th: f64 = f64::to_radians(*a);
                    let e = K1 * (K0 + th.sin());
                    format!("{},{a},{e}\n", t0 + 10.0 * i as f64)
                })
                .collect()
        };
        // Two sequences back to back: the return to 0° starts test 2 at line 7.
        let text = format!(
            "# rotation_axis: pendulum\ntime_s,angle_deg,output_v\n{}{}",
            rows(0.0),
            rows(40.0)
        );
        let r = solve(&text).unwrap();
        assert_eq!(r.tests.len(), 2);
        assert_eq!(r.tests[1].first_line, 7);
        // A gap alone: 0, 90 | gap | 180, 270, … must split even though no angle repeats.
        let log = parse_log(
            "# rotation_axis: pendulum\ntime_s,angle_deg,output_v\n0,0,1\n10,90,1\n9000,180,1\n9010,270,1\n",
        )
        .unwrap();
        let tests = split_tests(&log.rows, DEFAULT_TEST_GAP_S);
        assert_eq!(tests.len(), 2);
        assert_eq!(tests[1].1[0].line, 5);
    }

    #[test]
    fn regression_on_time_matches_a_hand_computed_example() {
        // t = 0..3, y = 1, 3, 2, 5: slope 5.5/5 = 1.1, RSS 2.7, s = √1.35, SE(slope) = s/√5.
        let (mean, b, bse, s) =
            regress_on_time(&[0.0, 1.0, 2.0, 3.0], &[1.0, 3.0, 2.0, 5.0]).unwrap();
        assert!((mean - 2.75).abs() < 1e-15);
        assert!((b - 1.1).abs() < 1e-14);
        assert!((s - 1.35f64.sqrt()).abs() < 1e-14);
        assert!((bse - 1.35f64.sqrt() / 5f64.sqrt()).abs() < 1e-14);
        assert!(regress_on_time(&[0.0, 1.0], &[1.0, 2.0]).is_none());
    }

    #[test]
    fn table_combines_a_pendulum_and_an_output_log_into_both_misalignment_columns() {
        let with_t = |axis: &str| {
            hand_log(
                axis,
                &[0.0, 90.0, 180.0, 270.0],
                1.0,
                0.0,
                0.0,
                &[-1e-6, 1e-6],
                "",
            )
            .replace("angle_deg,output_v\n", "angle_deg,output_v,temperature_c\n")
            .lines()
            .map(|l| {
                if l.starts_with('#') || l.starts_with("angle") {
                    l.to_string()
                } else {
                    format!("{l},50.0")
                }
            })
            .collect::<Vec<_>>()
            .join("\n")
        };
        let a = parse_log(&with_t("pendulum")).unwrap();
        let b = parse_log(&with_t("output")).unwrap();
        let r = analyse(&[&a, &b], &TumbleOptions::default()).unwrap();
        let csv = table_csv(&r, false).unwrap();
        let mut data = csv.lines().filter(|l| !l.starts_with('#'));
        assert_eq!(
            data.next(),
            Some("temperature_c,k0_g,k1_v_per_g,k2_g_per_g2,delta_p_arcmin,delta_o_arcmin")
        );
        let row: Vec<f64> = data
            .next()
            .unwrap()
            .split(',')
            .map(|c| c.parse().unwrap())
            .collect();
        assert_eq!(row[0], 50.0);
        assert!((row[1] - K0).abs() < 1e-12 && (row[2] - K1).abs() < 1e-12);
        assert!((row[4] - 2.0).abs() < 1e-6 && (row[5] - 2.0).abs() < 1e-6);
        assert!(data.next().is_none());
    }

    #[test]
    fn a_reversed_angle_sense_is_refused_as_a_negative_scale_factor() {
        // θ → −θ: the 90° and 270° readings swap.
        let text = hand_log(
            "pendulum",
            &[0.0, 90.0, 180.0, 270.0],
            1.0,
            0.0,
            0.0,
            &[0.0],
            "",
        )
        .replace("\n90,", "\nX,")
        .replace("\n270,", "\n90,")
        .replace("\nX,", "\n270,");
        assert!(matches!(
            solve(&text),
            Err(TumbleError::BadScaleFactor { k1, .. }) if (k1 + K1).abs() < 1e-12
        ));
    }

    #[test]
    fn table_needs_a_temperature_per_test() {
        let r = solve(&hand_log(
            "pendulum",
            &[0.0, 90.0, 180.0, 270.0],
            1.0,
            0.0,
            0.0,
            &[0.0],
            "",
        ))
        .unwrap();
        assert_eq!(
            table_csv(&r, false),
            Err(TumbleError::NoTemperature("1".into()))
        );
    }
}
