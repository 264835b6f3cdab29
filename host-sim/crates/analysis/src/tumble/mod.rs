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

use crate::sim::accelerometer::SpindleAxis;

/// Standard gravity g_n (m/s²), the unit `local_gravity_m_s2` is divided by: the core's.
pub use accomp::tide::STANDARD_GRAVITY_M_S2;
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

    /// The cross-axis inputs of equation (1) at head angle θ with gravity g (in g): the
    /// simulator's dividing-head geometry ([`crate::sim::accelerometer::axes`]), the same axis
    /// along the spindle.
    pub fn cross(self, g: f64, theta: f64) -> CrossAxis {
        let spindle = match self {
            RotationAxis::Output => SpindleAxis::Output,
            RotationAxis::Pendulum => SpindleAxis::Pendulum,
        };
        crate::sim::accelerometer::axes(spindle, 1.0, theta, g).1
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

mod parse;
mod solve;
mod stability;
mod table;
#[cfg(test)]
mod tests;
mod text;

pub use parse::{parse_log, Row, TumbleLog};
use solve::*;
pub use stability::regress_on_time;
use stability::*;
pub use table::{coefficient_table, table_csv, TableRow};
pub use text::render_text;

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

/// The operating temperature over one test's readings.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct TemperatureSummary {
    /// Mean temperature (°C), when logged.
    #[serde(rename = "temperature_c")]
    pub mean_c: Option<f64>,
    /// Standard deviation of the temperature readings (°C), when more than one.
    #[serde(rename = "temperature_sd_c")]
    pub sd_c: Option<f64>,
}

impl TemperatureSummary {
    /// Mean and standard deviation of the logged readings (none logged: both `None`).
    pub fn of(readings_c: &[f64]) -> Self {
        if readings_c.is_empty() {
            return Self::default();
        }
        let (mean_c, sd_c) = mean_sd(readings_c);
        Self {
            mean_c: Some(mean_c),
            sd_c,
        }
    }
}

/// The least squares fit of one test: its size and how its noise was estimated.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FitSummary {
    /// Unknowns fitted (4, or 5 with K3).
    pub unknowns: usize,
    /// Degrees of freedom n − p.
    pub dof: usize,
    /// Where the noise part of the SE comes from.
    pub noise_basis: NoiseBasis,
    /// RMS of the position residuals (V).
    pub rms_residual_v: f64,
}

/// The model equation's coefficients as least squares fits them for one test, each with its
/// uncertainty.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ModelCoefficients {
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
    /// The operating temperature over the test (flattened: `temperature_c` and
    /// `temperature_sd_c` stay fields of the test in the JSON).
    #[serde(flatten)]
    pub temperature: TemperatureSummary,
    /// Mean time of the test's readings (s), when logged.
    pub time_s: Option<f64>,
    /// The positions.
    pub positions: Vec<PositionResult>,
    /// How well determined the least squares fit is (flattened: `unknowns` … `rms_residual_v`
    /// stay fields of the test in the JSON).
    #[serde(flatten)]
    pub fit: FitSummary,
    /// The model equation's coefficients (flattened: the JSON keeps `k0_g` … `k3_g_per_g3` as
    /// fields of the test).
    #[serde(flatten)]
    pub coefficients: ModelCoefficients,
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
