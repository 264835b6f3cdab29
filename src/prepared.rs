//! The active calibration prepared for the per-sample path: everything that depends only on the
//! table is computed once at activation, and the per-sample arithmetic is mixed precision.
//!
//! Recipe (docs/numerics.md, "Mixed precision on the firmware path"): base values, the output
//! sums and every quantity that needs more than ~1e-7 relative precision stay in f64 (software
//! double on the M4F); corrections whose magnitude is small against the value they correct are
//! evaluated in f32 (the M4F's hardware single precision), so their f32 rounding is scaled down
//! by their smallness. Whether a table's corrections are small enough is decided here, at
//! activation, from a worst-case error bound: a table whose bound exceeds the 1e-9 g budget is
//! compensated with the all-f64 reference code instead ([`Precision::Double`]).
//!
//! f32 basic operations, `sqrt` and the int/float conversions are IEEE-754 correctly rounded on
//! the M4F and on x86-64 alike and Rust never contracts to FMA, so the firmware and the host get
//! the same bits from this code.

use core::cell::Cell;

use crate::adc::AdcError;
use crate::adc::AdcScale;
use crate::compensation::ThermalCompensator;
use crate::fixed::{
    from_f32, from_f64, mul_code, sqrt_f32, to_f32, to_f64, CODE_FACTOR_BITS, G_BITS, VOLT_BITS,
};
use crate::frontend::{
    accel_scale, rtd_scale, tilt_scale, AD7124_FULL_SCALE, AD7124_MAX_CODE, ADS1262_HALF_SCALE,
};
use crate::model::CrossAxis;
use crate::poly::{TempPoly, N_COEFFS};
use crate::rtd::{CallendarVanDusen, RtdError};
use crate::table::{CalibrationTable, TableError, TiltAxis};
use crate::units::{Celsius, RtdOhms, RAD_PER_ARCSEC};

/// Unit roundoff of f32 (round to nearest): 2^-24.
const U32: f64 = 1.0 / 16_777_216.0;
/// The precision budget of the compensated a_i against an f64 reference.
pub const BUDGET_G: f64 = 1e-9;
/// The precision budget of the linearized output against an f64 reference (≈ 2.3e-9 g). Looser
/// than a_i's on purpose: the linearization itself departs from the exact model by ~6e-6 g
/// (docs/numerics.md), so its arithmetic does not need the exact path's 1e-9 g.
pub const BUDGET_LINEARIZED_V: f64 = 3e-9;
/// |a_i| up to which the error bounds are computed (the specified input range).
pub const MAX_INPUT_G: f64 = 1.5;
/// Largest |φ − φ0| (rad, ≈ 103") for which the tilt correction is evaluated in f32; larger tilts
/// take the f64 `sin` (slow, exact). Stability tests see a few arcseconds.
pub const MAX_F32_TILT_RAD: f32 = 5e-4;
/// Largest |4·K2·c| for which the root of equation (1) uses the f32 series (K2 ≤ 1e-4 g/g² at
/// 2 g gives 8e-4); beyond it the f64 square root.
const MAX_SERIES_W: f32 = 1e-2;

/// How the thermal compensation of this table is evaluated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Precision {
    /// f64 base values and sums, f32 corrections: the bound below is within the budget.
    Mixed,
    /// The all-f64 reference code ([`ThermalCompensator`]): the table's corrections are too large
    /// for f32 within the budget (or a temperature is outside the fast path's domain).
    Double,
}

/// Worst-case error bounds of the mixed-precision path against exact arithmetic, computed from the
/// table at activation (docs/numerics.md derives each term).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorBounds {
    /// a_i, in g, for |a_i| ≤ [`MAX_INPUT_G`] and |φ − φ0| ≤ [`MAX_F32_TILT_RAD`].
    pub a_i_g: f64,
    /// The linearized output, in volts, for inputs within the ADC's full scale.
    pub linearized_v: f64,
    /// The RTD temperature inside the calibrated range, in °C.
    pub temperature_c: f64,
}

/// A temperature polynomial split for mixed precision:
/// p(T) = lin0 + lin1·T (f64) + x²·(r0 + r1·x + r2·x²) (f32), x = (T − Tc)/Ts.
///
/// The constant and linear parts carry the value and must be f64; the curvature part is what is
/// left of the temperature dependence after the first order, small against p.
#[derive(Debug, Clone, Copy, PartialEq)]
struct SplitPoly {
    lin0: f64,
    lin1_per_c: f64,
    curvature: [f32; 3],
}

impl SplitPoly {
    fn new(p: &TempPoly, center_c: f64, half_span_c: f64) -> Self {
        let [c0, c1, c2, c3, c4] = p.coeffs;
        // c0 + c1·(T − Tc)/Ts = (c0 − c1/Ts·Tc) + c1/Ts·T: x itself is then only needed in f32.
        let lin1_per_c = c1 / half_span_c;
        SplitPoly {
            lin0: c0 - lin1_per_c * center_c,
            lin1_per_c,
            curvature: [c2 as f32, c3 as f32, c4 as f32],
        }
    }

    #[inline]
    fn eval(&self, t_c: f64, x: f32) -> f64 {
        let [r0, r1, r2] = self.curvature;
        let curvature = x * x * ((r2 * x + r1) * x + r0);
        self.lin0 + self.lin1_per_c * t_c + f64::from(curvature)
    }
}

/// Bound of |f32 evaluation − exact| for Σ_{k≥first} c_k·x^k with |x| ≤ 1 and x itself off by
/// at most `dx`. Each term passes through at most 7 roundings (its coefficient's conversion to
/// f32, ≤ 4 Horner operations, x² and the final product), so 8u·Σ|c_k| covers them with the
/// second-order terms; plus the derivative bound Σ k·|c_k| times dx.
fn f32_poly_bound(p: &TempPoly, first: usize, dx: f64) -> f64 {
    let mut sum = 0.0;
    let mut slope = 0.0;
    for (k, c) in p.coeffs.iter().enumerate().skip(first) {
        sum += libm::fabs(*c);
        slope += k as f64 * libm::fabs(*c);
    }
    8.0 * U32 * sum + slope * dx
}

/// Smallest |p(x)| over [−1, 1] guaranteed by |c0| − Σ_{k≥1}|c_k| (a lower bound).
fn lower_bound_abs(p: &TempPoly) -> f64 {
    let rest: f64 = p.coeffs.iter().skip(1).map(|c| libm::fabs(*c)).sum();
    libm::fabs(p.coeffs[0]) - rest
}

/// Largest |p(x)| over [−1, 1], bounded by Σ|c_k|.
fn upper_bound_abs(p: &TempPoly) -> f64 {
    p.coeffs.iter().map(|c| libm::fabs(*c)).sum()
}

/// The thermal compensation's table-only quantities for the mixed-precision path.
#[derive(Debug, Clone, Copy, PartialEq)]
struct FastThermal {
    t_min_c: f64,
    t_max_c: f64,
    center_c: f64,
    inv_half_span: f32,
    /// K0 + δo·a_p − δp·a_o with the table's fixed cross-axis inputs folded in, g.
    bias_g: SplitPoly,
    /// K1, V/g.
    k1_v_per_g: SplitPoly,
    /// K2 in f32 throughout: it only multiplies a², ≤ 2.25 g², and is ≤ 1e-4 g/g².
    k2: [f32; N_COEFFS],
    /// T0 of the linearized compensation.
    t0_c: f64,
    /// K1(T0)·(K0' + δo'·a_p − δp'·a_o)(T0), V/°C: the part of ΔE/ΔT independent of E.
    lin_offset_v_per_c: f64,
    /// K1'(T0)/K1(T0), 1/°C: ΔE/ΔT per volt of E.
    lin_gain_per_c: f32,
    /// K1(T0)·K2'(T0), V/(g²·°C).
    lin_k2_v_per_c: f32,
    /// 1/K1(T0) and K0(T0), for the a_i estimate of the K2 term only.
    inv_k1_t0: f32,
    k0_t0_g: f32,
    /// The accelerometer channel's code → volts map, in fixed point and in f64.
    accel: AccelFixed,
}

/// The accelerometer channel's code → volts map in fixed point: E = code·per_code − offset with
/// E in [`VOLT_BITS`] and per_code in [`VOLT_BITS`] + [`CODE_FACTOR_BITS`] fraction bits.
#[derive(Debug, Clone, Copy, PartialEq)]
struct AccelFixed {
    per_code: i64,
    offset: i64,
    /// The same map in f64, for the temperature terms (c0 and the per-code factor of c).
    linear: Ads1262Linear,
}

impl AccelFixed {
    fn new(linear: Ads1262Linear) -> Option<Self> {
        Some(AccelFixed {
            per_code: from_f64(linear.per_code, VOLT_BITS + CODE_FACTOR_BITS)?,
            offset: from_f64(linear.offset, VOLT_BITS)?,
            linear,
        })
    }

    /// E in volts ([`VOLT_BITS`]); cannot overflow (|code·per_code| < 2^60, |offset| < 2^61).
    #[inline]
    fn volts(&self, code: i32) -> i64 {
        mul_code(code, self.per_code) - self.offset
    }
}

/// What the compensation needs that depends only on the temperature sample, evaluated once per
/// RTD code ([`TemperatureCache`]) instead of once per accelerometer sample.
#[derive(Debug, Clone, Copy, PartialEq)]
struct ThermalTerms {
    /// The temperature was outside the calibrated range (terms evaluated at the edge).
    clamped: bool,
    /// c for accelerometer code 0 without tilt: K0(T) + cross-axis terms + offset/K1(T), g,
    /// [`G_BITS`].
    c0_g: i64,
    /// What c loses per accelerometer code: (volts per code)/K1(T), [`G_BITS`] +
    /// [`CODE_FACTOR_BITS`]. c = c0 − code·this + sign·sin(φ − φ0).
    c_per_code: i64,
    /// K1(T), V/g: the tilt correction in volts for the linearized output.
    k1_v_per_g: f64,
    k1_v_per_g32: f32,
    /// K2(T), g/g².
    k2: f32,
    /// K1(T0)·(K0' + δo'·a_p − δp'·a_o)(T0)·(T − T0): the E-independent part of ΔE, V,
    /// [`VOLT_BITS`].
    lin_offset_v: i64,
    /// T − T0, °C.
    dt: f32,
}

/// One RTD code's results: its conversion and the temperature terms of the compensation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Temperature {
    /// The AD7124 code these results are for (the cache key).
    code: u32,
    /// (R in Ω, T in °C), or why there is no temperature (with the ohms when known).
    pub(crate) rtd: Result<(f64, f64), (Option<f64>, RtdFault)>,
    /// The mixed-precision path's terms; None for an all-f64 table, or when a term does not fit
    /// the fixed-point range (that sample then takes the f64 path).
    terms: Option<ThermalTerms>,
}

/// The last RTD code's [`Temperature`]. The RTD is read far less often than the accelerometer
/// (and a slowly changing temperature repeats its code), so most samples find their terms here.
/// Transparent: a hit gives exactly the values a recomputation would (the terms are a function
/// of the table and the code only), hence it takes no part in equality.
#[derive(Debug, Clone, Default)]
struct TemperatureCache(Cell<Option<Temperature>>);

impl PartialEq for TemperatureCache {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

/// The RTD channel's table-only quantities: code thresholds and the CVD inverse's constants.
#[derive(Debug, Clone, Copy, PartialEq)]
struct PreparedRtd {
    cvd: CallendarVanDusen,
    ohms_per_code: f64,
    /// (ohms per code / R0) / A: T ≈ q/A = code·this − 1/A.
    q_over_a_per_code: f64,
    inv_a: f64,
    /// 4B/A: u = 4Bq/A² = (4B/A)·(q/A).
    u_per_q_over_a: f32,
    /// Codes below this read below the plausible minimum: shorted sensor.
    normal_from: u32,
    /// Codes from this one read above the plausible maximum: open sensor.
    open_from: u32,
    /// Codes from this one are at or above R0 (T ≥ 0 °C): closed-form inverse.
    closed_form_from: u32,
}

/// Smallest code in 0..=2^24 with `pred(code)`, for a predicate monotone in the code (binary
/// search: the thresholds then follow the very same f64 expressions the samples use).
fn first_code(pred: impl Fn(u32) -> bool) -> u32 {
    let (mut lo, mut hi) = (0u32, AD7124_FULL_SCALE as u32);
    if pred(lo) {
        return lo;
    }
    if !pred(hi) {
        return hi;
    }
    // Invariant: !pred(lo), pred(hi).
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        if pred(mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    hi
}

/// Why a sample's RTD code gave no temperature.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum RtdFault {
    /// A conversion-level fault (code wider than 24 bits, or at full scale).
    Adc(AdcError),
    /// The CVD inverse refused the resistance.
    Rtd(RtdError),
}

impl PreparedRtd {
    fn new(table: &CalibrationTable) -> Self {
        let cvd = table.rtd.cvd;
        let scale = rtd_scale(table);
        let ohms_per_code = table.rtd.reference_resistor.0 / AD7124_FULL_SCALE / scale.pga_gain
            * scale.gain_correction;
        let (r_min, r_max) = cvd.resistance_limits();
        let ohms = |code: u32| f64::from(code) * ohms_per_code;
        PreparedRtd {
            cvd,
            ohms_per_code,
            q_over_a_per_code: ohms_per_code / cvd.r0 / cvd.a,
            inv_a: 1.0 / cvd.a,
            u_per_q_over_a: (4.0 * cvd.b / cvd.a) as f32,
            normal_from: first_code(|c| ohms(c) >= r_min),
            open_from: first_code(|c| ohms(c) > r_max),
            closed_form_from: first_code(|c| ohms(c) >= cvd.r0),
        }
    }

    /// (R in Ω, T in °C) for a raw AD7124 code.
    ///
    /// T ≥ 0 °C: T = 2q/(A + √(A² + 4Bq)) = (q/A)·(1 + δ) with u = 4Bq/A² and
    /// δ = 2/(1 + √(1+u)) − 1 = −u/(1 + √(1+u))², no cancellation. q/A (≈ T) is f64; δ (≤ 0.014
    /// inside 0–100 °C) and the correction (q/A)·δ in f32: error ≤ 10u·|(q/A)·δ| (3e-7 °C at
    /// 65 °C). Below 0 °C the f64 Newton iteration of [`CallendarVanDusen::temperature`].
    #[inline]
    pub(crate) fn convert(&self, code: u32) -> Result<(f64, f64), (Option<f64>, RtdFault)> {
        if code > AD7124_MAX_CODE {
            return Err((None, RtdFault::Adc(AdcError::OutOfRange)));
        }
        if code == AD7124_MAX_CODE {
            return Err((None, RtdFault::Adc(AdcError::Saturated)));
        }
        let code_f = f64::from(code);
        let ohms = code_f * self.ohms_per_code;
        if code >= self.open_from {
            return Err((Some(ohms), RtdFault::Rtd(RtdError::Open)));
        }
        if code < self.normal_from {
            return Err((Some(ohms), RtdFault::Rtd(RtdError::Short)));
        }
        if code < self.closed_form_from {
            return match self.cvd.temperature(RtdOhms(ohms)) {
                Ok(t) => Ok((ohms, t.0)),
                Err(e) => Err((Some(ohms), RtdFault::Rtd(e))),
            };
        }
        let q_over_a = code_f * self.q_over_a_per_code - self.inv_a;
        let q_over_a32 = q_over_a as f32;
        // u itself, not 1 − (1 + u): the subtraction would cost 6e-8/|u| relative.
        let u = self.u_per_q_over_a * q_over_a32;
        let one_plus_u = 1.0 + u;
        if one_plus_u.is_nan() || one_plus_u <= 0.0 {
            // Cannot happen for validated constants inside the open threshold (u ≥ −0.8).
            return Err((Some(ohms), RtdFault::Rtd(RtdError::InvalidConstants)));
        }
        let root = 1.0 + sqrt_f32(one_plus_u);
        let delta = -u / (root * root);
        Ok((ohms, q_over_a + f64::from(q_over_a32 * delta)))
    }

    /// The correction (q/A)·δ at T (for the error bound).
    fn correction_c(&self, t: f64) -> f64 {
        let q = self.cvd.resistance(Celsius(t)).0 / self.cvd.r0 - 1.0;
        let u = 4.0 * self.cvd.b * q / (self.cvd.a * self.cvd.a);
        let root = 1.0 + libm::sqrt(1.0 + u);
        q / self.cvd.a * (-u) / (root * root)
    }
}

/// An ADS1262 channel's code → value map: value = code·per_code − offset.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Ads1262Linear {
    per_code: f64,
    offset: f64,
}

impl Ads1262Linear {
    /// The map of a front-end scale ([`crate::frontend`]), in `unit_per_v` units per volt.
    fn new(scale: &AdcScale, unit_per_v: f64) -> Self {
        Ads1262Linear {
            per_code: scale.vref.0 / ADS1262_HALF_SCALE / scale.pga_gain
                * scale.gain_correction
                * unit_per_v,
            offset: scale.offset.0 * unit_per_v,
        }
    }
}

/// An ADS1262 code at either rail reads as saturated, like [`crate::adc::AdcScale::fraction`].
#[inline]
pub(crate) fn ads1262_saturated(code: i32) -> bool {
    code == i32::MAX || code == i32::MIN
}

/// The tilt channel: the output value (f32, precise to ~1e-7 relative, far below the
/// tiltmeter's noise) and φ − φ0 in radians measured in codes from the reference, so that a large
/// common reference does not cancel in f32.
#[derive(Debug, Clone, Copy, PartialEq)]
struct PreparedTilt {
    arcsec_per_code: f32,
    offset_arcsec: f32,
    /// The reference φ0 as a code: integer part exact, fraction in f32.
    reference_code: i64,
    reference_fraction: f32,
    rad_per_code: f32,
    /// The same in f64 for tilts beyond [`MAX_F32_TILT_RAD`].
    reference_code_f64: f64,
    rad_per_code_f64: f64,
    sign: f64,
    sign32: f32,
}

impl PreparedTilt {
    fn new(table: &CalibrationTable) -> Self {
        let t = &table.tilt;
        let lin = Ads1262Linear::new(&tilt_scale(table), t.scale_arcsec_per_v);
        // φ − φ0 = code·k − offset − φ0 = k·(code − (offset + φ0)/k).
        let reference_code_f64 = (lin.offset + t.reference.0) / lin.per_code;
        let reference_code = libm::round(reference_code_f64).clamp(-4e18, 4e18) as i64;
        let sign = match t.axis {
            TiltAxis::Input => 1.0,
            TiltAxis::InputReversed => -1.0,
            TiltAxis::None => 0.0,
        };
        PreparedTilt {
            arcsec_per_code: lin.per_code as f32,
            offset_arcsec: lin.offset as f32,
            reference_code,
            reference_fraction: (reference_code_f64 - reference_code as f64) as f32,
            rad_per_code: (lin.per_code * RAD_PER_ARCSEC) as f32,
            reference_code_f64,
            rad_per_code_f64: lin.per_code * RAD_PER_ARCSEC,
            sign,
            sign32: sign as f32,
        }
    }

    #[inline]
    fn arcsec(&self, code: i32) -> f64 {
        f64::from(code as f32 * self.arcsec_per_code - self.offset_arcsec)
    }

    /// φ − φ0 in radians, f32; the code difference is exact below 2^24 codes.
    #[inline]
    fn phi_rad(&self, code: i32) -> f32 {
        // An i32 difference converts in one FPU instruction; a wider one means a tilt far beyond
        // the f32 path's range, which infinity sends to the f64 path.
        let d = match i32::try_from(i64::from(code) - self.reference_code) {
            Ok(d) => d as f32,
            Err(_) => f32::INFINITY,
        };
        (d - self.reference_fraction) * self.rad_per_code
    }

    #[inline]
    fn phi_rad_f64(&self, code: i32) -> f64 {
        (f64::from(code) - self.reference_code_f64) * self.rad_per_code_f64
    }
}

/// Largest |φ − φ0| the tilt correction is computed for: 0.5 rad (28.6°), far beyond any
/// tiltmeter's range; beyond it the sample is flagged COMPENSATION_FAILED.
pub const MAX_TILT_RAD: f64 = 0.5;

/// sin φ in f64 for |φ| ≤ [`MAX_TILT_RAD`], by its Taylor series to φ¹⁵ (the first omitted term
/// is < 5e-20 relative at 0.5 rad): a few ulp, like `libm::sin`, whose range reduction for any
/// argument would cost 4 KiB of flash on a path that only sees tilts of arcseconds. None beyond.
fn tilt_sin(phi: f64) -> Option<f64> {
    if phi.is_nan() || libm::fabs(phi) > MAX_TILT_RAD {
        return None;
    }
    let p2 = phi * phi;
    // φ·(1 − φ²/(2·3)·(1 − φ²/(4·5)·(1 − …))), innermost term φ²/(14·15).
    let mut acc = 1.0;
    for d in [210.0, 156.0, 110.0, 72.0, 42.0, 20.0, 6.0] {
        acc = 1.0 - p2 / d * acc;
    }
    Some(phi * acc)
}

/// sin φ for |φ| ≤ [`MAX_F32_TILT_RAD`]: φ − φ³/6 (the φ⁵ term is < 1e-15 relative there).
#[inline]
fn small_sin(phi: f32) -> f32 {
    phi - phi * phi * phi * (1.0 / 6.0)
}

/// 2/(1 + √(1 − w)) − 1 for |w| ≤ [`MAX_SERIES_W`]: the Catalan series
/// w/4 + w²/8 + 5w³/64 + 14w⁴/256; the first omitted term, 42w⁵/1024, is 0.164·w⁴ ≤ 1.7e-9
/// relative to the sum there, below f32's own rounding.
#[inline]
fn root_series(w: f32) -> f32 {
    let t1 = 0.25 * w;
    t1 * (1.0 + 0.5 * w * (1.0 + 0.625 * w * (1.0 + 0.7 * w)))
}

/// The calibration table prepared for the per-sample path. Built once when a table becomes
/// active; [`crate::pipeline::process_prepared`] uses it for every sample.
///
/// It remembers the last RTD code's temperature terms (a `Cell`: it is `Send` but not `Sync`,
/// each thread or task keeps its own).
#[derive(Debug, Clone, PartialEq)]
pub struct PreparedCalibration {
    accel: Ads1262Linear,
    tilt: PreparedTilt,
    rtd: PreparedRtd,
    thermal: ThermalCompensator,
    cross: CrossAxis,
    fast: Option<FastThermal>,
    bounds: ErrorBounds,
    cache: TemperatureCache,
}

/// What [`PreparedCalibration::compensate`] returns: (a_i in g, linearized E in V, clamped).
pub(crate) type Compensated = (f64, f64, bool);

/// Why a sample could not be compensated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum CompensateFault {
    /// The table asks for tilt correction but the tilt channel is invalid.
    TiltNeeded,
    /// No real root, non-finite intermediate, unusable temperature.
    Failed,
}

impl PreparedCalibration {
    /// Prepares a table; refuses one that does not pass [`CalibrationTable::validate`].
    pub fn new(table: &CalibrationTable) -> Result<Self, TableError> {
        table.validate()?;
        let thermal = table.thermal;
        let cross = table.orientation.cross;
        let accel = Ads1262Linear::new(&accel_scale(Some(table)), 1.0);
        let tilt = PreparedTilt::new(table);
        let rtd = PreparedRtd::new(table);
        let (fast, bounds) = FastThermal::new(&thermal, cross, &rtd, accel);
        let fast = (bounds.a_i_g <= BUDGET_G && bounds.linearized_v <= BUDGET_LINEARIZED_V)
            .then_some(fast)
            .flatten();
        Ok(PreparedCalibration {
            accel,
            tilt,
            rtd,
            thermal,
            cross,
            fast,
            bounds,
            cache: TemperatureCache::default(),
        })
    }

    /// Which arithmetic this table's compensation uses.
    pub fn precision(&self) -> Precision {
        if self.fast.is_some() {
            Precision::Mixed
        } else {
            Precision::Double
        }
    }

    /// The worst-case error bounds of the mixed-precision path for this table.
    pub fn error_bounds(&self) -> ErrorBounds {
        self.bounds
    }

    /// Accelerometer output E in volts, or saturation.
    #[inline]
    pub(crate) fn accel_volts(&self, code: i32) -> Result<f64, AdcError> {
        if ads1262_saturated(code) {
            return Err(AdcError::Saturated);
        }
        Ok(match &self.fast {
            Some(fast) => to_f64(fast.accel.volts(code), VOLT_BITS),
            None => f64::from(code) * self.accel.per_code - self.accel.offset,
        })
    }

    /// Tilt in arcseconds, or saturation.
    #[inline]
    pub(crate) fn tilt_arcsec(&self, code: i32) -> Result<f64, AdcError> {
        if ads1262_saturated(code) {
            return Err(AdcError::Saturated);
        }
        Ok(self.tilt.arcsec(code))
    }

    /// RTD (ohms, °C) for a code; on failure the ohms when they are known. Not cached.
    #[cfg(test)]
    pub(crate) fn rtd(&self, code: u32) -> Result<(f64, f64), (Option<f64>, RtdFault)> {
        self.rtd.convert(code)
    }

    /// The RTD conversion and the compensation's temperature terms for an RTD code: from the
    /// cache when the code is the previous one, else computed and remembered.
    #[inline]
    pub(crate) fn temperature(&self, code: u32) -> Temperature {
        match self.cache.0.get() {
            Some(hit) if hit.code == code => hit,
            _ => {
                let fresh = self.temperature_uncached(code);
                self.cache.0.set(Some(fresh));
                fresh
            }
        }
    }

    /// The RTD code whose terms are cached, if any (for the cache's tests).
    #[cfg(test)]
    pub(crate) fn cached_rtd_code(&self) -> Option<u32> {
        self.cache.0.get().map(|t| t.code)
    }

    #[inline(never)]
    fn temperature_uncached(&self, code: u32) -> Temperature {
        let rtd = self.rtd.convert(code);
        let terms = match (&self.fast, rtd) {
            (Some(fast), Ok((_, t_c))) => fast.terms(t_c),
            _ => None,
        };
        Temperature { code, rtd, terms }
    }

    /// Tilt correction (eq. 5) and both compensations for an accelerometer code (E = `e_v` volts)
    /// at a valid temperature. `tilt_code` is None when the tilt channel is invalid.
    #[inline]
    pub(crate) fn compensate(
        &self,
        accel_code: i32,
        e_v: f64,
        temperature: &Temperature,
        tilt_code: Option<i32>,
    ) -> Result<Compensated, CompensateFault> {
        // sign32: an f32 comparison is one FPU instruction, an f64 one a soft-float call.
        let phi = match (self.tilt.sign32 == 0.0, tilt_code) {
            (true, _) => None,
            (false, None) => return Err(CompensateFault::TiltNeeded),
            (false, Some(code)) => Some(code),
        };
        let Ok((_, t_c)) = temperature.rtd else {
            return Err(CompensateFault::Failed);
        };
        match (&self.fast, &temperature.terms) {
            (Some(fast), Some(terms)) => fast.compensate(terms, accel_code, phi, &self.tilt),
            _ => self.compensate_f64(e_v, t_c, phi),
        }
    }

    /// The all-f64 reference path (the core's [`ThermalCompensator`]).
    fn compensate_f64(
        &self,
        e_v: f64,
        t_c: f64,
        tilt_code: Option<i32>,
    ) -> Result<Compensated, CompensateFault> {
        let th = &self.thermal;
        let e = match tilt_code {
            None => e_v,
            Some(code) => {
                let (k, _) = th
                    .coefficients_at(Celsius(t_c))
                    .map_err(|_| CompensateFault::Failed)?;
                let sin = tilt_sin(self.tilt.phi_rad_f64(code)).ok_or(CompensateFault::Failed)?;
                let d = k.scale_factor_v_per_g * sin;
                e_v - self.tilt.sign * d
            }
        };
        let exact = th
            .exact(crate::units::Volts(e), Celsius(t_c), self.cross)
            .map_err(|_| CompensateFault::Failed)?;
        let lin = th
            .linearized(crate::units::Volts(e), Celsius(t_c), self.cross)
            .map_err(|_| CompensateFault::Failed)?;
        finite((exact.input.0, lin.output.0, exact.range.is_clamped()))
    }
}

fn finite(c: Compensated) -> Result<Compensated, CompensateFault> {
    if crate::fixed::is_finite(c.0) && crate::fixed::is_finite(c.1) {
        Ok(c)
    } else {
        Err(CompensateFault::Failed)
    }
}

impl FastThermal {
    /// The prepared quantities and the error bounds of evaluating them in mixed precision.
    fn new(
        th: &ThermalCompensator,
        cross: CrossAxis,
        rtd: &PreparedRtd,
        accel: Ads1262Linear,
    ) -> (Option<Self>, ErrorBounds) {
        let s = &th.scale;
        let m = &th.models;
        let (tc, ts) = (s.center.0, s.half_span_c);
        // The bias with the table's fixed cross-axis inputs folded in: one polynomial, in g.
        let mut bias = TempPoly::default();
        for (k, b) in bias.coeffs.iter_mut().enumerate() {
            let at = |p: &TempPoly| p.coeffs.get(k).copied().unwrap_or(0.0);
            *b = at(&m.bias_g) + at(&m.misalignment_o_rad) * cross.a_p.0
                - at(&m.misalignment_p_rad) * cross.a_o.0;
        }
        let k1 = m.scale_factor_v_per_g;
        let k2 = m.nonlinearity_g_per_g2;

        // x = (T − Tc)/Ts: the difference in f64, then f32: T − Tc, 1/Ts and the product each
        // rounded once, |x| ≤ 1: |Δx| ≤ 3u.
        let dx = 3.0 * U32;
        let k1_min = lower_bound_abs(&k1);
        let c_max = MAX_INPUT_G + upper_bound_abs(&bias);
        let k2_max = upper_bound_abs(&k2);
        // a = −c·(1 + g): ∂a/∂bias = −1, ∂a/∂K1 = −E/K1² ≈ −c/K1, ∂a/∂K2 ≈ −c².
        let bias_err = f32_poly_bound(&bias, 2, dx);
        let k1_err = f32_poly_bound(&k1, 2, dx) * c_max / k1_min;
        // Plain Horner: up to 9 roundings for c4, hence 10u = 1.25 × 8u.
        let k2_err = 1.25 * f32_poly_bound(&k2, 0, dx) * c_max * c_max;
        // The series: g ≈ w/4 with w = 4K2c in f32 (K2 and c rounded, one product, the series)
        // and c·g in f32 (one more rounding of c, one product): 10u·|c·g|; plus c's truncation
        // to 2^-24 before its conversion to f32, which moves c·g by K2·c·2^-24.
        let root_err = 10.0 * U32 * c_max * k2_max * c_max + c_max * k2_max * U32;
        // Tilt: sign·sin φ in f32, ≤ 6u relative (φ from the code 2u, the series 2u) of at most
        // MAX_F32_TILT_RAD, in g directly (c takes it without a division by K1).
        let tilt_err = 6.0 * U32 * f64::from(MAX_F32_TILT_RAD);
        // Fixed point (crate::fixed): two f32 → fixed truncations (tilt, c·g) of 2^-40 each, the
        // floor of code·(per code factor) and the rounding of c0 and of that factor (2^-48 and
        // below): 3·2^-40 covers them.
        let fixed_err = 3.0 / 1_099_511_627_776.0;
        // T: the RTD correction's f32 error, propagated through dB/dT and a·dK1/dT/K1.
        let t_err = 10.0 * U32 * libm::fabs(rtd.correction_c(libm::fmax(s.max.0, 0.0)));
        let slope = |p: &TempPoly| {
            p.coeffs
                .iter()
                .enumerate()
                .map(|(k, c)| k as f64 * libm::fabs(*c))
                .sum::<f64>()
                / ts
        };
        let t_err_g = t_err * (slope(&bias) + c_max * slope(&k1) / k1_min);
        let a_i_g = bias_err + k1_err + k2_err + root_err + tilt_err + t_err_g + fixed_err;

        // Linearized: ΔE = dt·(s0 + E·s1 + s2·a²); s0·dt in f64, the rest in f32 with ≤ 6u
        // relative error; |dt| ≤ span, |E| ≤ the ADC's full scale.
        let t0 = th.reference;
        let (Ok((k_t0, _)), Ok(d_t0)) = (th.coefficients_at(t0), th.sensitivities_at(t0)) else {
            return (None, unusable_bounds());
        };
        let k1_t0 = k_t0.scale_factor_v_per_g;
        if !(k1_t0.is_finite() && k1_t0 > 0.0 && k1_min > 0.0) {
            return (None, unusable_bounds());
        }
        let lin_gain = d_t0.scale_factor_v_per_g / k1_t0;
        let lin_k2 = k1_t0 * d_t0.nonlinearity_g_per_g2;
        // |E| ≤ K1·|c| for |a_i| ≤ MAX_INPUT_G, and never beyond the ADC's full scale.
        let e_max = libm::fmin(
            upper_bound_abs(&k1) * c_max,
            libm::fabs(accel.per_code) * ADS1262_HALF_SCALE + libm::fabs(accel.offset),
        );
        let span = s.max.0 - s.min.0;
        // E reaches f32 truncated to 2^-24 V (then rounded): through E·s1 and a_est² = (E/K1 − K0)².
        let e32_err = U32
            * span
            * (libm::fabs(lin_gain) + 2.0 * libm::fabs(lin_k2) * c_max / libm::fabs(k1_t0));
        // The tilt correction in volts: K1 (1u) times sign·sin φ (6u) in f32, then fixed.
        let tilt_v_err = 7.0 * U32 * upper_bound_abs(&k1) * f64::from(MAX_F32_TILT_RAD);
        let linearized_v =
            6.0 * U32 * span * (e_max * libm::fabs(lin_gain) + libm::fabs(lin_k2) * c_max * c_max)
                + t_err * libm::fabs(k1_t0 * slope(&bias) + e_max * libm::fabs(lin_gain))
                + e32_err
                + tilt_v_err
                + fixed_err;

        let Some(accel_fixed) = AccelFixed::new(accel) else {
            return (None, unusable_bounds());
        };
        let fast = FastThermal {
            accel: accel_fixed,
            t_min_c: s.min.0,
            t_max_c: s.max.0,
            center_c: tc,
            inv_half_span: (1.0 / ts) as f32,
            bias_g: SplitPoly::new(&bias, tc, ts),
            k1_v_per_g: SplitPoly::new(&k1, tc, ts),
            k2: k2.coeffs.map(|c| c as f32),
            t0_c: t0.0,
            lin_offset_v_per_c: k1_t0
                * (d_t0.bias_g + d_t0.misalignment_o.0 * cross.a_p.0
                    - d_t0.misalignment_p.0 * cross.a_o.0),
            lin_gain_per_c: lin_gain as f32,
            lin_k2_v_per_c: lin_k2 as f32,
            inv_k1_t0: (1.0 / k1_t0) as f32,
            k0_t0_g: k_t0.bias_g as f32,
        };
        let bounds = ErrorBounds {
            a_i_g,
            linearized_v,
            temperature_c: t_err,
        };
        let ok = a_i_g.is_finite() && linearized_v.is_finite();
        (ok.then_some(fast), bounds)
    }

    /// The temperature terms at `t_c` (clamped to the calibrated range); None when a term does
    /// not fit its fixed-point format (then the sample takes the f64 path).
    fn terms(&self, t_c: f64) -> Option<ThermalTerms> {
        if !t_c.is_finite() {
            return None;
        }
        let (t, clamped) = if t_c < self.t_min_c {
            (self.t_min_c, true)
        } else if t_c > self.t_max_c {
            (self.t_max_c, true)
        } else {
            (t_c, false)
        };
        let x = (t - self.center_c) as f32 * self.inv_half_span;
        let bias = self.bias_g.eval(t, x);
        let k1 = self.k1_v_per_g.eval(t, x);
        let [k2_0, k2_1, k2_2, k2_3, k2_4] = self.k2;
        let k2 = (((k2_4 * x + k2_3) * x + k2_2) * x + k2_1) * x + k2_0;
        let dt = t - self.t0_c;
        let linear = &self.accel.linear;
        // One division (≈ 200 instructions in software), two products.
        let inv_k1 = 1.0 / k1;
        Some(ThermalTerms {
            clamped,
            // c = K0 − E/K1 with E = code·per_code − offset.
            c0_g: from_f64(bias + linear.offset * inv_k1, G_BITS)?,
            c_per_code: from_f64(linear.per_code * inv_k1, G_BITS + CODE_FACTOR_BITS)?,
            k1_v_per_g: k1,
            k1_v_per_g32: k1 as f32,
            k2,
            lin_offset_v: from_f64(self.lin_offset_v_per_c * dt, VOLT_BITS)?,
            dt: dt as f32,
        })
    }

    /// Both compensations of one accelerometer code with the temperature's terms. Fixed point
    /// for the values (E, c, a_i, the linearized output), f32 for the corrections; no soft-float
    /// operation unless the tilt or the root leaves the f32 series' range.
    #[inline]
    fn compensate(
        &self,
        terms: &ThermalTerms,
        accel_code: i32,
        tilt_code: Option<i32>,
        tilt: &PreparedTilt,
    ) -> Result<Compensated, CompensateFault> {
        use CompensateFault::Failed;
        let e = self.accel.volts(accel_code);

        // Equation (5): E − sign·K1(T)·sin(φ − φ0). Divided by K1 the correction is sign·sin φ
        // itself, so c takes it in g and the linearized output in volts.
        let (tilt_g, tilt_v) = match tilt_code {
            None => (Some(0), Some(0)),
            Some(code) => {
                let phi = tilt.phi_rad(code);
                if phi.abs() <= MAX_F32_TILT_RAD {
                    // The sign (±1) is applied in f32, where it is exact.
                    let s = tilt.sign32 * small_sin(phi);
                    (
                        from_f32(s, G_BITS),
                        from_f32(terms.k1_v_per_g32 * s, VOLT_BITS),
                    )
                } else {
                    let Some(sin) = tilt_sin(tilt.phi_rad_f64(code)) else {
                        return Err(Failed);
                    };
                    let s = tilt.sign * sin;
                    (
                        from_f64(s, G_BITS),
                        from_f64(terms.k1_v_per_g * s, VOLT_BITS),
                    )
                }
            }
        };
        let (Some(tilt_g), Some(tilt_v)) = (tilt_g, tilt_v) else {
            return Err(Failed);
        };

        // Equation (1) inverted: a = −2c/(1 + √(1 − 4K2c)) = −c·(1 + g), c = K0 − E/K1.
        let c = terms
            .c0_g
            .checked_sub(mul_code(accel_code, terms.c_per_code))
            .and_then(|c| c.checked_add(tilt_g))
            .ok_or(Failed)?;
        let c32 = to_f32(c, G_BITS);
        let w = 4.0 * terms.k2 * c32;
        let a_i = if w.abs() <= MAX_SERIES_W {
            let cg = from_f32(c32 * root_series(w), G_BITS).ok_or(Failed)?;
            let a = c
                .checked_neg()
                .and_then(|a| a.checked_sub(cg))
                .ok_or(Failed)?;
            to_f64(a, G_BITS)
        } else {
            let c = to_f64(c, G_BITS);
            let disc = 1.0 - 4.0 * f64::from(terms.k2) * c;
            if disc.is_nan() || disc < 0.0 {
                return Err(Failed);
            }
            -2.0 * c / (1.0 + libm::sqrt(disc))
        };

        // Linearized (eq. 3/4): ΔE = dt·(s0 + E·s1 + s2·a²), a estimated at T0; dt·s0 is a
        // temperature term.
        let e = e.checked_sub(tilt_v).ok_or(Failed)?;
        let e32 = to_f32(e, VOLT_BITS);
        let a_est = e32 * self.inv_k1_t0 - self.k0_t0_g;
        let small = terms.dt * (e32 * self.lin_gain_per_c + self.lin_k2_v_per_c * a_est * a_est);
        let lin = e
            .checked_sub(terms.lin_offset_v)
            .zip(from_f32(small, VOLT_BITS))
            .and_then(|(e, small)| e.checked_sub(small))
            .ok_or(Failed)?;
        finite((a_i, to_f64(lin, VOLT_BITS), terms.clamped))
    }
}

fn unusable_bounds() -> ErrorBounds {
    ErrorBounds {
        a_i_g: f64::INFINITY,
        linearized_v: f64::INFINITY,
        temperature_c: f64::INFINITY,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::table::tests::paper_table;
    use crate::units::Volts;

    #[test]
    fn the_root_series_matches_the_closed_form_to_f32_precision() {
        for w in [-1e-2f64, -3e-3, -1e-5, 0.0, 2e-7, 4e-4, 1e-2] {
            // 2/(1 + √(1 − w)) − 1 in f64, written as w/(1 + √(1 − w))² (no cancellation).
            let s = (1.0 - w).sqrt();
            let exact = w / ((1.0 + s) * (1.0 + s));
            let got = f64::from(root_series(w as f32));
            assert!(
                (got - exact).abs() <= 4.0 * U32 * exact.abs(),
                "w={w}: {got:e} vs {exact:e}"
            );
        }
    }

    #[test]
    fn the_tilt_sine_series_matches_libm_to_a_few_ulp_and_refuses_beyond_half_a_radian() {
        let mut phi = -0.5;
        while phi <= 0.5 {
            let got = tilt_sin(phi).unwrap();
            let want = libm::sin(phi);
            assert!(
                (got - want).abs() <= 4.0 * f64::EPSILON * want.abs(),
                "{phi}"
            );
            phi += 0.000_731;
        }
        assert_eq!(tilt_sin(0.0), Some(0.0));
        assert_eq!(tilt_sin(0.500_001), None);
        assert_eq!(tilt_sin(f64::NAN), None);
    }

    #[test]
    fn the_small_angle_sine_is_within_one_f32_ulp() {
        for phi in [-5e-4f64, -1e-5, 3e-7, 2.4e-4, 5e-4] {
            let got = f64::from(small_sin(phi as f32));
            assert!((got - phi.sin()).abs() <= 2.0 * U32 * phi.abs(), "{phi}");
        }
    }

    #[test]
    fn rtd_temperature_matches_the_f64_cvd_inverse_from_minus_50_to_300_c() {
        let t = paper_table();
        let p = PreparedCalibration::new(&t).unwrap();
        let mut c = -50.0;
        while c <= 300.0 {
            let ohms = t.rtd.cvd.resistance(Celsius(c)).0;
            let code = libm::round(ohms / p.rtd.ohms_per_code) as u32;
            let (r, got) = p.rtd(code).unwrap();
            let want = t.rtd.cvd.temperature(RtdOhms(r)).unwrap().0;
            // The f32 correction's bound (1e-7 °C at 30 °C, 4e-7 °C at 65 °C, 3e-6 °C at 300 °C);
            // below 0 °C both take the f64 Newton path.
            let bound = 10.0 * U32 * p.rtd.correction_c(c.max(0.0)).abs() + 1e-10;
            assert!((got - want).abs() <= bound, "{c} °C: {got} vs {want}");
            c += 3.7;
        }
    }

    #[test]
    fn rtd_thresholds_split_short_normal_and_open_at_the_cvd_limits() {
        let mut t = paper_table();
        // Gain 8: full scale 638 Ω, so the open threshold (1.05·R(850 °C) = 410 Ω) is a code.
        t.rtd.pga_gain = 8.0;
        let p = PreparedCalibration::new(&t).unwrap();
        let (r_min, r_max) = t.rtd.cvd.resistance_limits();
        let k = p.rtd.ohms_per_code;
        let open = p.rtd.open_from;
        assert!(f64::from(open) * k > r_max && f64::from(open - 1) * k <= r_max);
        assert_eq!(
            p.rtd(open).map_err(|e| e.1),
            Err(RtdFault::Rtd(RtdError::Open))
        );
        assert!(p.rtd(open - 1).is_ok());
        let normal = p.rtd.normal_from;
        assert!(f64::from(normal) * k >= r_min && f64::from(normal - 1) * k < r_min);
        assert_eq!(
            p.rtd(normal - 1).map_err(|e| e.1),
            Err(RtdFault::Rtd(RtdError::Short))
        );
        assert!(p.rtd(normal).is_ok());
        assert_eq!(
            p.rtd(AD7124_MAX_CODE).map_err(|e| e.1),
            Err(RtdFault::Adc(AdcError::Saturated))
        );
        assert_eq!(
            p.rtd(AD7124_MAX_CODE + 1).map_err(|e| e.1),
            Err(RtdFault::Adc(AdcError::OutOfRange))
        );
    }

    #[test]
    fn the_papers_table_is_mixed_and_a_strongly_curved_one_falls_back_to_f64() {
        let t = paper_table();
        let p = PreparedCalibration::new(&t).unwrap();
        assert_eq!(p.precision(), Precision::Mixed);
        let b = p.error_bounds();
        // Hand figure: bias x² term 7.5e-5 g → 8u·7.5e-5 ≈ 3.6e-11 g, tilt 1.8e-10 g, K1 x² term
        // 9.4e-5 V/g ·8u·1.5/1.32 ≈ 5e-11 g, plus the x-rounding terms: a few 1e-10 g.
        assert!(b.a_i_g > 1e-10 && b.a_i_g < 1e-9, "{b:?}");
        assert!(b.linearized_v < BUDGET_LINEARIZED_V, "{b:?}");

        let mut curved = t;
        curved.thermal.models.bias_g.coeffs[4] = 5e-3;
        let p = PreparedCalibration::new(&curved).unwrap();
        assert_eq!(p.precision(), Precision::Double);
        assert!(p.error_bounds().a_i_g > BUDGET_G);
    }

    #[test]
    fn the_f64_fallback_gives_the_reference_compensation() {
        let mut t = paper_table();
        t.thermal.models.bias_g.coeffs[4] = 5e-3;
        let p = PreparedCalibration::new(&t).unwrap();
        let accel = crate::frontend::volts_to_ads1262(&accel_scale(Some(&t)), Volts(1.3))
            .unwrap()
            .0;
        let rtd = crate::frontend::celsius_to_ad7124(&t, Celsius(47.0))
            .unwrap()
            .0;
        let e = p.accel_volts(accel).unwrap();
        let temperature = p.temperature(rtd);
        let (_, t_c) = temperature.rtd.unwrap();
        let (a, lin, clamped) = p.compensate(accel, e, &temperature, Some(0)).unwrap();
        let tilt0 = p.tilt.phi_rad_f64(0);
        let (k, _) = t.thermal.coefficients_at(Celsius(t_c)).unwrap();
        let e_c = Volts(e - k.scale_factor_v_per_g * tilt_sin(tilt0).unwrap());
        let cross = t.orientation.cross;
        let want = t.thermal.exact(e_c, Celsius(t_c), cross).unwrap();
        let want_lin = t.thermal.linearized(e_c, Celsius(t_c), cross).unwrap();
        assert_eq!((a, lin, clamped), (want.input.0, want_lin.output.0, false));
    }
}
