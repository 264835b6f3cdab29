//! The active calibration prepared for the per-sample path: everything that depends only on the
//! table is computed once at activation, and the per-sample arithmetic is mixed precision.
//!
//! Recipe (docs/numerics.md, "Mixed precision on the firmware path"): base values, the output
//! sums and every quantity that needs more than ~1e-7 relative precision are fixed point (i64
//! with a binary point, [`crate::fixed`]: the M4F has no double precision, every f64 operation is
//! a software routine); corrections whose magnitude is small against the value they correct are
//! evaluated in f32 (the M4F's hardware single precision), so their f32 rounding is scaled down
//! by their smallness. A clean sample, a new RTD code included, calls no soft-float routine. Whether a table's corrections are small enough is decided here, at
//! activation, from a worst-case error bound: a table whose bound exceeds the 1e-9 g budget is
//! compensated with the all-f64 reference code instead ([`Precision::Double`]).
//!
//! f32 basic operations, `sqrt` and the int/float conversions are IEEE-754 correctly rounded on
//! the M4F and on x86-64 alike and Rust never contracts to FMA, so the firmware and the host get
//! the same bits from this code.

use core::cell::Cell;

use crate::adc::AdcError;
use crate::adc::AdcScale;
use crate::board::{
    accel_scale, rtd_scale, tilt_scale, AD7124_FULL_SCALE, AD7124_MAX_CODE, ADS1262_HALF_SCALE,
};
use crate::compensation::ThermalCompensator;
use crate::fixed::{
    from_f32, from_f32_small, from_f32_truncated, from_f64, mul_code, mul_hi, sqrt_f32, to_f32,
    to_f64, CODE_FACTOR_BITS, G_BITS, VOLT_BITS,
};
use crate::model::CrossAxis;
use crate::poly::{TempPoly, N_COEFFS};
use crate::rtd::{CallendarVanDusen, RtdError};
use crate::table::{CalibrationTable, TableError, TiltAxis};
use crate::units::{Celsius, RAD_PER_ARCSEC};

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
/// Largest |φ − φ0| (rad, ≈ 103") for which the tilt correction is evaluated in f32; a sample with
/// a larger tilt takes the all-f64 path (slow, exact). Stability tests see a few arcseconds.
pub const MAX_F32_TILT_RAD: f32 = 5e-4;
/// Largest |4·K2·c| for which the root of equation (1) uses the f32 series (K2 ≤ 1e-4 g/g² at
/// 2 g gives 8e-4); beyond it the sample takes the all-f64 path.
const MAX_SERIES_W: f32 = 1e-2;

/// How the thermal compensation of this table is evaluated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Precision {
    /// Fixed-point base values and sums, f32 corrections: the bound below is within the budget.
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

/// A temperature polynomial for Horner's rule in fixed point: x = (T − Tc)/Ts is an i32 with
/// [`X_BITS`] fraction bits, and the coefficients are stored as c_k·4^k, so that each step is one
/// [`mul_code`] (code·factor/2^32 multiplies by x/4) and one add: p(x) = Σ (c_k·4^k)·(x/4)^k.
#[derive(Debug, Clone, Copy, PartialEq)]
struct FixedPoly([i64; N_COEFFS]);

impl FixedPoly {
    /// The polynomial with `bits` fraction bits; None when a coefficient, or the sum of their
    /// magnitudes (which bounds every partial Horner sum for |x| ≤ 1), reaches 2^62.
    fn new(p: &TempPoly, bits: u32) -> Option<Self> {
        let mut c = [0i64; N_COEFFS];
        let mut sum = 0.0;
        let mut four_k = 1.0;
        for (dst, src) in c.iter_mut().zip(p.coeffs) {
            *dst = from_f64(src * four_k, bits)?;
            sum += libm::fabs(src * four_k);
            four_k *= 4.0;
        }
        (sum < ulp(bits as i32 - 62)).then_some(FixedPoly(c))
    }

    /// p(x) for x with [`X_BITS`] fraction bits, |x| ≤ 1 (+2^-20): within
    /// [`FixedPoly::ROUNDING_ULPS`] units of the last place of the exact value at that x.
    #[inline]
    fn eval(&self, x: i32) -> i64 {
        let [c0, c1, c2, c3, c4] = self.0;
        let mut acc = c3 + mul_code(x, c4);
        acc = c2 + mul_code(x, acc);
        acc = c1 + mul_code(x, acc);
        c0 + mul_code(x, acc)
    }

    /// Five coefficient roundings (½ ulp each, times |x|^k ≤ 1) and four floors (1 ulp each,
    /// times |x/4|^j ≤ 1).
    const ROUNDING_ULPS: f64 = 6.5;
}

/// Fraction bits of x = (T − Tc)/Ts in the fixed-point temperature terms.
const X_BITS: u32 = 30;
/// Fraction bits of T − Tc on its way to x (an i32: |T − Tc| < 128 °C, 6e-8 °C).
const DIFF_BITS: u32 = 24;
/// Fraction bits of a ratio near 1 (K1(Tc)/K1(T)) and of η = K1(T)/K1(Tc) − 1.
const RATIO_BITS: u32 = 62;

/// 2^-n as f64 (|n| ≤ 1022), built in the exponent field (no libm call).
const fn ulp(n: i32) -> f64 {
    f64::from_bits(((1023 - n) as u64) << 52)
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
#[inline(never)]
fn lower_bound_abs(p: &TempPoly) -> f64 {
    let rest: f64 = p.coeffs.iter().skip(1).map(|c| libm::fabs(*c)).sum();
    libm::fabs(p.coeffs[0]) - rest
}

/// Largest |dp/dx| over [−1, 1], bounded by Σ k·|c_k|. Activation only (flash: not inlined).
#[inline(never)]
fn slope_x(p: &TempPoly) -> f64 {
    p.coeffs
        .iter()
        .enumerate()
        .map(|(k, c)| k as f64 * libm::fabs(*c))
        .sum::<f64>()
}

/// Largest |p(x)| over [−1, 1], bounded by Σ|c_k|.
#[inline(never)]
fn upper_bound_abs(p: &TempPoly) -> f64 {
    p.coeffs.iter().map(|c| libm::fabs(*c)).sum()
}

/// The thermal compensation's table-only quantities for the mixed-precision path.
#[derive(Debug, Clone, Copy, PartialEq)]
struct FastThermal {
    /// The first RTD code at or above the calibrated range's minimum, and the first above its
    /// maximum: the range check is two u32 comparisons (T is monotone in the code).
    in_range_from: u32,
    above_range_from: u32,
    /// The calibrated range, its centre Tc and T0, [`CELSIUS_BITS`].
    t_min: i64,
    t_max: i64,
    center: i64,
    t0: i64,
    /// 1/Ts, [`X_BITS`] + [`CODE_FACTOR_BITS`] − [`DIFF_BITS`].
    inv_half_span: i64,
    /// K0 + δo·a_p − δp·a_o with the table's fixed cross-axis inputs folded in, g, [`G_BITS`].
    bias_g: FixedPoly,
    /// η(x) = K1(T)/K1(Tc) − 1, [`RATIO_BITS`]; |η| ≤ 1/32 (checked at activation).
    k1_ratio: FixedPoly,
    /// K1(Tc), V/g.
    k1_center32: f32,
    /// (volts per code)/K1(Tc), [`G_BITS`] + [`CODE_FACTOR_BITS`] + 2 (a [`mul_hi`] by a
    /// [`RATIO_BITS`] ratio gives [`G_BITS`] + [`CODE_FACTOR_BITS`]).
    c_per_code_center: i64,
    /// ADC offset/K1(Tc), g, [`G_BITS`].
    offset_g_center: i64,
    /// K2 in f32 throughout: it only multiplies a², ≤ 2.25 g², and is ≤ 1e-4 g/g².
    k2: [f32; N_COEFFS],
    /// K1(T0)·(K0' + δo'·a_p − δp'·a_o)(T0), V/°C: the part of ΔE/ΔT independent of E,
    /// [`VOLT_BITS`] + [`CODE_FACTOR_BITS`] − [`DIFF_BITS`] (a [`mul_code`] by T − T0 at
    /// 2^-24 °C).
    lin_offset_v_per_c: i64,
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
    k1_v_per_g32: f32,
    /// K2(T), g/g².
    k2: f32,
    /// K1(T0)·(K0' + δo'·a_p − δp'·a_o)(T0)·(T − T0): the E-independent part of ΔE, V,
    /// [`VOLT_BITS`].
    lin_offset_v: i64,
    /// T − T0, °C.
    dt: f32,
}

/// One RTD code's results: its conversion and the temperature terms of the compensation. Kept
/// to 64 bytes: copied in and out of the cache, a larger one costs a library `memcpy` (≈ 80
/// instructions) instead of a few load/store-multiples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Temperature {
    /// The AD7124 code these results are for (the cache key).
    code: u32,
    /// Why there is no temperature; None when `ohms` and `t_c` hold one.
    pub(crate) fault: Option<RtdFault>,
    /// R in Ω; NaN when unknown (a conversion-level fault).
    pub(crate) ohms: f64,
    /// T in °C; NaN with a fault.
    pub(crate) t_c: f64,
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
    /// The fixed-point constants of the closed-form inverse; None when a table's constants do
    /// not fit their formats (then every code takes the f64 inverse of [`CallendarVanDusen`]).
    fixed: Option<FixedRtd>,
    /// Codes below this read below the plausible minimum: shorted sensor.
    normal_from: u32,
    /// Codes from this one read above the plausible maximum: open sensor.
    open_from: u32,
    /// Codes from this one are at or above R0 (T ≥ 0 °C): closed-form inverse.
    closed_form_from: u32,
}

/// The closed-form CVD inverse (T ≥ 0 °C) in fixed point: q/A = code·(ohms per code/R0/A) − 1/A
/// is linear in the code, so it is one [`mul_code`] and one subtraction, exact to 2^-40 °C.
#[derive(Debug, Clone, Copy, PartialEq)]
struct FixedRtd {
    /// Ohms per code, [`OHM_BITS`] + [`CODE_FACTOR_BITS`].
    ohms_per_code: i64,
    /// (ohms per code / R0) / A, [`CELSIUS_BITS`] + [`CODE_FACTOR_BITS`].
    q_over_a_per_code: i64,
    /// 1/A, [`CELSIUS_BITS`].
    inv_a: i64,
    /// 4B/A: u = 4Bq/A² = (4B/A)·(q/A).
    u_per_q_over_a: f32,
}

impl FixedRtd {
    fn new(cvd: &CallendarVanDusen, ohms_per_code: f64) -> Option<Self> {
        Some(FixedRtd {
            ohms_per_code: from_f64(ohms_per_code, OHM_BITS + CODE_FACTOR_BITS)?,
            q_over_a_per_code: from_f64(
                ohms_per_code / cvd.r0 / cvd.a,
                CELSIUS_BITS + CODE_FACTOR_BITS,
            )?,
            inv_a: from_f64(1.0 / cvd.a, CELSIUS_BITS)?,
            u_per_q_over_a: (4.0 * cvd.b / cvd.a) as f32,
        })
    }
}

/// Fraction bits of a fixed-point temperature (°C): 9.1e-13 °C, ±2^21 °C.
const CELSIUS_BITS: u32 = 40;
/// Fraction bits of a fixed-point resistance (Ω): 2.3e-13 Ω.
const OHM_BITS: u32 = 42;
/// Fraction bits of q/A on its way to f32 (`(q/A)·2^20` as an i32: ±2048 °C, 9.5e-7 °C).
const Q_OVER_A_F32_BITS: u32 = 20;

/// Smallest code in 0..=2^24 with `pred(code)`, for a predicate monotone in the code (binary
/// search: the thresholds then follow the very same expressions the samples use). Activation
/// only: one copy for its five predicates (flash).
#[inline(never)]
fn first_code(pred: &dyn Fn(u32) -> bool) -> u32 {
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
            fixed: FixedRtd::new(&cvd, ohms_per_code),
            normal_from: first_code(&|c| ohms(c) >= r_min),
            open_from: first_code(&|c| ohms(c) > r_max),
            closed_form_from: first_code(&|c| ohms(c) >= cvd.r0),
        }
    }

    /// (R in Ω, T in °C) for a raw AD7124 code, and T in fixed point ([`CELSIUS_BITS`]) when the
    /// closed form gave it.
    ///
    /// T ≥ 0 °C: T = 2q/(A + √(A² + 4Bq)) = (q/A)·(1 + δ) with u = 4Bq/A² and
    /// δ = 2/(1 + √(1+u)) − 1 = −u/(1 + √(1+u))², no cancellation. q/A (≈ T) is fixed point,
    /// exact to 2^-40 °C; δ (≤ 0.014 inside 0–100 °C) and the correction (q/A)·δ in f32 from
    /// q/A truncated to 2^-20 °C: error ≤ 10u·|(q/A)·δ| + 2^-19·|δ| ([`Self::error_bound_c`];
    /// 5e-7 °C at 65 °C). Below 0 °C the f64 Newton iteration of
    /// [`CallendarVanDusen::temperature`].
    #[inline]
    pub(crate) fn convert(&self, code: u32) -> (RtdResult, Option<i64>) {
        if code > AD7124_MAX_CODE {
            return (Err((None, RtdFault::Adc(AdcError::OutOfRange))), None);
        }
        if code == AD7124_MAX_CODE {
            return (Err((None, RtdFault::Adc(AdcError::Saturated))), None);
        }
        match self.convert_fixed(code) {
            Some((ohms, t)) => (Ok((ohms, to_f64(t, CELSIUS_BITS))), Some(t)),
            None => (self.convert_f64(code), None),
        }
    }

    /// (R in Ω, T in fixed point) on the closed form's fixed path (see [`Self::convert`]);
    /// None outside it: below 0 °C, at the fault thresholds, for constants that do not fit.
    #[inline]
    fn convert_fixed(&self, code: u32) -> Option<(f64, i64)> {
        let fixed = self.fixed.as_ref()?;
        if code < self.closed_form_from || code >= self.open_from || code >= AD7124_MAX_CODE {
            return None;
        }
        // code < 2^24: the i32 is exact.
        let code = code as i32;
        let ohms = to_f64(mul_code(code, fixed.ohms_per_code), OHM_BITS);
        let q_over_a = mul_code(code, fixed.q_over_a_per_code) - fixed.inv_a;
        // q/A ∈ [0, 1000) °C here (R0 ≤ R ≤ the open threshold): the i32 cannot overflow.
        let q_over_a32 = (q_over_a >> (CELSIUS_BITS - Q_OVER_A_F32_BITS)) as i32 as f32
            * (1.0 / (1u32 << Q_OVER_A_F32_BITS) as f32);
        // u itself, not 1 − (1 + u): the subtraction would cost 6e-8/|u| relative.
        let u = fixed.u_per_q_over_a * q_over_a32;
        let one_plus_u = 1.0 + u;
        // Cannot fail for validated constants inside the open threshold (u ≥ −0.8); the f64
        // path names what went wrong if it does.
        if one_plus_u.is_nan() || one_plus_u <= 0.0 {
            return None;
        }
        let root = 1.0 + sqrt_f32(one_plus_u);
        let delta = -u / (root * root);
        // (q/A)·δ ≈ 1.5e-4·T² °C: below 4 °C up to ≈ 160 °C, one VCVT truncating to 2^-29 °C;
        // exact beyond.
        let correction = from_f32_truncated(q_over_a32 * delta, 29, CELSIUS_BITS)?;
        Some((ohms, q_over_a + correction))
    }

    /// T of a code in fixed point as the temperature terms get it, or for a code without a
    /// temperature whether it lies above the valid codes (open, saturated: true) or below
    /// (short: false): a predicate on it is monotone in the code.
    fn t_fixed_or_side(&self, code: u32) -> Result<i64, bool> {
        match self.convert(code) {
            (_, Some(t)) => Ok(t),
            (Ok((_, t_c)), None) => from_f64(t_c, CELSIUS_BITS).ok_or(true),
            (Err((_, RtdFault::Rtd(RtdError::Short))), _) => Err(false),
            (Err(_), _) => Err(true),
        }
    }

    /// The conversion in f64: below 0 °C, at the fault thresholds, and for tables whose
    /// constants do not fit the fixed-point formats.
    #[inline(never)]
    fn convert_f64(&self, code: u32) -> RtdResult {
        let ohms = f64::from(code) * self.ohms_per_code;
        if code >= self.open_from {
            return Err((Some(ohms), RtdFault::Rtd(RtdError::Open)));
        }
        if code < self.normal_from {
            return Err((Some(ohms), RtdFault::Rtd(RtdError::Short)));
        }
        // The table's constants were validated at activation and R lies inside the fault
        // thresholds (the code checks above): the inverse without its own checks.
        if !crate::fixed::is_finite(ohms) {
            return Err((Some(ohms), RtdFault::Rtd(RtdError::NonFinite)));
        }
        match self.cvd.temperature_of_ratio(ohms / self.cvd.r0 - 1.0) {
            Ok(t) => Ok((ohms, t)),
            Err(e) => Err((Some(ohms), RtdFault::Rtd(e))),
        }
    }

    /// (q/A, (q/A)·δ) at T, in f64 (for the error bound).
    fn correction_c(&self, t: f64) -> (f64, f64) {
        let q = self.cvd.resistance(Celsius(t)).0 / self.cvd.r0 - 1.0;
        let u = 4.0 * self.cvd.b * q / (self.cvd.a * self.cvd.a);
        let root = 1.0 + libm::sqrt(1.0 + u);
        let q_over_a = q / self.cvd.a;
        (q_over_a, q_over_a * (-u) / (root * root))
    }

    /// Bound of |T − the exact CVD inverse of the code's resistance| at T ≥ 0 °C on the fixed
    /// path: the f32 correction's 10 roundings (10u·|(q/A)·δ|), q/A's truncation to 2^-20 °C
    /// before it (through d((q/A)·δ)/d(q/A) ≈ 2δ: 2^-19·|δ|), the correction's truncation to
    /// 2^-29 °C, and the fixed-point q/A (its floor, the per-code factor's rounding times 2^24
    /// codes, 1/A's rounding: < 2^-38 °C).
    fn error_bound_c(&self, t: f64) -> f64 {
        let (q_over_a, correction) = self.correction_c(libm::fmax(t, 0.0));
        let delta = if q_over_a > 0.0 {
            libm::fabs(correction / q_over_a)
        } else {
            0.0
        };
        10.0 * U32 * libm::fabs(correction)
            + 2.0 * delta * ulp(Q_OVER_A_F32_BITS as i32)
            + ulp(29)
            + ulp(38)
    }
}

/// (R in Ω, T in °C) of an RTD code, or why there is none (with the ohms when known).
pub(crate) type RtdResult = Result<(f64, f64), (Option<f64>, RtdFault)>;

/// An ADS1262 channel's code → value map: value = code·per_code − offset.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Ads1262Linear {
    per_code: f64,
    offset: f64,
}

impl Ads1262Linear {
    /// The map of a front-end scale ([`crate::board`]), in `unit_per_v` units per volt.
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
        crate::fixed::f32_to_f64(code as f32 * self.arcsec_per_code - self.offset_arcsec)
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

/// Why the fixed-point compensation did not give a result.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum FastFault {
    /// Overflow of a fixed-point format.
    Failed,
    /// Outside what its error bound covers (a tilt beyond [`MAX_F32_TILT_RAD`], a nonlinearity
    /// beyond the root's series): this sample takes the all-f64 path.
    Double,
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

    /// Accelerometer output E in volts and in fixed point ([`VOLT_BITS`]; 0 for an all-f64
    /// table), or saturation. The fixed value goes back into [`Self::compensate`].
    #[inline]
    pub(crate) fn accel_volts(&self, code: i32) -> Result<(f64, i64), AdcError> {
        if ads1262_saturated(code) {
            return Err(AdcError::Saturated);
        }
        Ok(match &self.fast {
            Some(fast) => {
                let e = fast.accel.volts(code);
                (to_f64(e, VOLT_BITS), e)
            }
            None => (f64::from(code) * self.accel.per_code - self.accel.offset, 0),
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
    pub(crate) fn rtd(&self, code: u32) -> RtdResult {
        self.rtd.convert(code).0
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

    /// A new RTD code: the closed form and the terms in fixed point, straight through.
    #[inline(never)]
    fn temperature_uncached(&self, code: u32) -> Temperature {
        if let (Some(fast), Some((ohms, t))) = (&self.fast, self.rtd.convert_fixed(code)) {
            return Temperature {
                code,
                fault: None,
                ohms,
                t_c: to_f64(t, CELSIUS_BITS),
                terms: fast.terms_for_code(code, t),
            };
        }
        self.temperature_general(code)
    }

    /// A new RTD code off the fixed path: faults, below 0 °C, all-f64 tables.
    #[inline(never)]
    fn temperature_general(&self, code: u32) -> Temperature {
        let (rtd, t_fixed) = self.rtd.convert(code);
        let (ohms, t_c, fault) = match rtd {
            Ok((ohms, t_c)) => (ohms, t_c, None),
            Err((ohms, fault)) => (ohms.unwrap_or(f64::NAN), f64::NAN, Some(fault)),
        };
        let terms = match &self.fast {
            // Below 0 °C (the f64 inverse) T reaches the fixed-point terms rounded to 2^-40 °C.
            Some(fast) if fault.is_none() => t_fixed
                .or_else(|| from_f64(t_c, CELSIUS_BITS))
                .and_then(|t| fast.terms_for_code(code, t)),
            _ => None,
        };
        Temperature {
            code,
            fault,
            ohms,
            t_c,
            terms,
        }
    }

    /// Tilt correction (eq. 5) and both compensations for an accelerometer code (E = `e_v` volts)
    /// at a valid temperature. `tilt_code` is None when the tilt channel is invalid. Both values
    /// of an `Ok` are finite (a non-finite result is `Failed`).
    #[inline]
    pub(crate) fn compensate(
        &self,
        accel_code: i32,
        e_v: f64,
        e_fixed: i64,
        temperature: &Temperature,
        tilt_code: Option<i32>,
    ) -> Result<Compensated, CompensateFault> {
        // sign32: an f32 comparison is one FPU instruction, an f64 one a soft-float call.
        let phi = match (self.tilt.sign32 == 0.0, tilt_code) {
            (true, _) => None,
            (false, None) => return Err(CompensateFault::TiltNeeded),
            (false, Some(code)) => Some(code),
        };
        if temperature.fault.is_some() {
            return Err(CompensateFault::Failed);
        }
        let t_c = temperature.t_c;
        match (&self.fast, &temperature.terms) {
            (Some(fast), Some(terms)) => {
                match fast.compensate(terms, accel_code, e_fixed, phi, &self.tilt) {
                    Ok(c) => Ok(c),
                    Err(FastFault::Failed) => Err(CompensateFault::Failed),
                    Err(FastFault::Double) => self.compensate_f64(e_v, t_c, phi),
                }
            }
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

        // x = (T − Tc)/Ts in fixed point: T − Tc truncated to 2^-24 °C, 1/Ts rounded to 2^-38,
        // the product floored to 2^-30 (|T − Tc| ≤ Ts, so 1/Ts's rounding adds < 2^-38·Ts).
        let dx = ulp(DIFF_BITS as i32) / ts + ulp(X_BITS as i32) + ulp(38) * ts;
        // The f32 copy of x (K2's Horner) adds its conversion's rounding.
        let dx32 = dx + U32;
        let k1_min = lower_bound_abs(&k1);
        let c_max = MAX_INPUT_G + upper_bound_abs(&bias);
        let k2_max = upper_bound_abs(&k2);
        // K1(T) = K1(Tc)·(1 + η(x)); 1/(1 + η) = 1 − η + η²·(1 − η) + η⁴/(1 + η).
        let k1_center = k1.coeffs[0];
        let mut eta_poly = TempPoly::default();
        for (e, c) in eta_poly.coeffs.iter_mut().zip(k1.coeffs).skip(1) {
            *e = c / k1_center;
        }
        let eps = upper_bound_abs(&eta_poly);
        // a = −c·(1 + g): ∂a/∂bias = −1, ∂a/∂(1/K1) = −E·… : a relative error ρ of 1/K1 moves c
        // by ρ·|E/K1| ≤ ρ·(c_max + |bias|) ≤ 2ρ·c_max; ∂a/∂K2 ≈ −c².
        let bias_err = FixedPoly::ROUNDING_ULPS * ulp(G_BITS as i32) + slope_x(&bias) * dx;
        // ρ: the series' truncation; η's own rounding (Horner) and its x error; the f32 second
        // order η²(1 − η) (η truncated to 2^-32 and rounded: 2|η|·(2^-32 + u|η|); three
        // roundings: 4u·η²; its conversion's truncation 2^-40).
        let ratio_err = eps * eps * eps * eps / (1.0 - eps)
            + (FixedPoly::ROUNDING_ULPS + 2.0) * ulp(RATIO_BITS as i32)
            + slope_x(&eta_poly) * dx
            + 2.0 * eps * (ulp(32) + U32 * eps)
            + 4.0 * U32 * eps * eps
            + ulp(40);
        let k1_err = 2.0 * ratio_err * c_max;
        // Plain Horner: up to 9 roundings for c4, hence 10u = 1.25 × 8u.
        let k2_err = 1.25 * f32_poly_bound(&k2, 0, dx32) * c_max * c_max;
        // The series: g ≈ w/4 with w = 4K2c in f32 (K2 and c rounded, one product, the series)
        // and c·g in f32 (one more rounding of c, one product): 10u·|c·g|; plus c's conversion
        // to f32 ([`to_f32`]: 2u·|c| + 2^-40), which moves c·g by K2·c times as much.
        let root_err =
            10.0 * U32 * c_max * k2_max * c_max + c_max * k2_max * (2.0 * U32 * c_max + ulp(40));
        // Tilt: sign·sin φ in f32, ≤ 6u relative (φ from the code 2u, the series 2u) of at most
        // MAX_F32_TILT_RAD, in g directly (c takes it without a division by K1).
        let tilt_err = 6.0 * U32 * f64::from(MAX_F32_TILT_RAD);
        // Fixed point (crate::fixed): two f32 → fixed truncations (tilt, c·g) of 2^-40 each, the
        // floor of code·(per code factor), of the two products by the ratio and the rounding of
        // the constants (2^-48 and below): 4·2^-40 covers them.
        let fixed_err = 4.0 * ulp(40);
        // T: the RTD conversion's error at the top of the range (it grows with T), plus the
        // truncation of T − Tc (in dx already), through dB/dT and a·dK1/dT/K1.
        let t_err = rtd.error_bound_c(s.max.0);
        let slope = |p: &TempPoly| slope_x(p) / ts;
        let t_err_g = t_err * (slope(&bias) + c_max * slope(&k1) / k1_min);
        // offset/K1 through ratio − 1 at 2^-32 (the rest of its error is in k1_err's ρ).
        let offset_err = libm::fabs(accel.offset / k1_center) * ulp(32);
        let a_i_g =
            bias_err + k1_err + k2_err + root_err + tilt_err + t_err_g + offset_err + fixed_err;

        // Linearized: ΔE = dt·(s0 + E·s1 + s2·a²); s0·dt in fixed point, the rest in f32 with
        // ≤ 6u relative error; |dt| ≤ span, |E| ≤ the ADC's full scale.
        let t0 = th.reference;
        let (Ok((k_t0, _)), Ok(d_t0)) = (th.coefficients_at(t0), th.sensitivities_at(t0)) else {
            return (None, unusable_bounds());
        };
        let k1_t0 = k_t0.scale_factor_v_per_g;
        if !(k1_t0.is_finite() && k1_t0 > 0.0 && k1_min > 0.0 && k1_center > 0.0) {
            return (None, unusable_bounds());
        }
        let lin_gain = d_t0.scale_factor_v_per_g / k1_t0;
        let lin_k2 = k1_t0 * d_t0.nonlinearity_g_per_g2;
        let lin_offset_v_per_c = k1_t0
            * (d_t0.bias_g + d_t0.misalignment_o.0 * cross.a_p.0
                - d_t0.misalignment_p.0 * cross.a_o.0);
        // |E| ≤ K1·|c| for |a_i| ≤ MAX_INPUT_G, and never beyond the ADC's full scale.
        let e_max = libm::fmin(
            upper_bound_abs(&k1) * c_max,
            libm::fabs(accel.per_code) * ADS1262_HALF_SCALE + libm::fabs(accel.offset),
        );
        let span = s.max.0 - s.min.0;
        // E reaches f32 within 2u·|E| + 2^-44 V ([`to_f32`]): through E·s1 and
        // a_est² = (E/K1 − K0)².
        let e32_err = (2.0 * U32 * e_max + ulp(VOLT_BITS as i32 - 8))
            * span
            * (libm::fabs(lin_gain) + 2.0 * libm::fabs(lin_k2) * c_max / libm::fabs(k1_t0));
        // dt is truncated to 2^-24 °C (for the offset term's product and for f32).
        let dt32_err = U32
            * (libm::fabs(lin_offset_v_per_c)
                + e_max * libm::fabs(lin_gain)
                + libm::fabs(lin_k2) * c_max * c_max);
        // The tilt correction in volts: K1 (3u: K1(Tc) and 1 + η rounded, η truncated) times
        // sign·sin φ (6u) in f32, then fixed.
        let tilt_v_err = 9.0 * U32 * upper_bound_abs(&k1) * f64::from(MAX_F32_TILT_RAD);
        let linearized_v =
            6.0 * U32 * span * (e_max * libm::fabs(lin_gain) + libm::fabs(lin_k2) * c_max * c_max)
                + t_err * libm::fabs(libm::fabs(lin_offset_v_per_c) + e_max * libm::fabs(lin_gain))
                + e32_err
                + dt32_err
                + tilt_v_err
                + fixed_err;
        let bounds = ErrorBounds {
            a_i_g,
            linearized_v,
            temperature_c: t_err,
        };

        // The formats' ranges: |T − Tc| ≤ Ts < 64 °C (an i32 at 2^-24), |T − T0| < 128 °C (the
        // same for dt), |η| ≤ 1/32 (an i32 at 2^-32, its second order below 2^-9, and the series
        // converging fast; the bound refuses far smaller ε anyway: ε⁴ must stay below 1e-10).
        let t_fixed = |t: f64| from_f64(t, CELSIUS_BITS);
        // And the sums of the compensation (no checked arithmetic there): |c| < 2^60 in G_BITS
        // (4096 g), |E| and the linearized offset < 2^60 in VOLT_BITS (256 V); K1 < 3.5 V/g keeps
        // the tilt in volts below 2^-9 ([`from_f32_small`]).
        let full_scale_codes = 2_147_483_648.0;
        let c_range = upper_bound_abs(&bias)
            + (libm::fabs(accel.per_code) * full_scale_codes + libm::fabs(accel.offset)) / k1_min;
        let e_range = libm::fabs(accel.per_code) * full_scale_codes
            + libm::fabs(accel.offset)
            + 128.0 * libm::fabs(lin_offset_v_per_c);
        let in_formats = ts < 64.0
            && libm::fabs(s.max.0 - t0.0) < 128.0
            && libm::fabs(s.min.0 - t0.0) < 128.0
            && eps <= 1.0 / 32.0
            && c_range < 4000.0
            && e_range < 250.0
            && upper_bound_abs(&k1) < 3.5;
        let fast = || -> Option<FastThermal> {
            let (t_min, t_max) = (t_fixed(s.min.0)?, t_fixed(s.max.0)?);
            Some(FastThermal {
                in_range_from: first_code(&|c| {
                    rtd.t_fixed_or_side(c).map_or_else(|a| a, |t| t >= t_min)
                }),
                above_range_from: first_code(&|c| {
                    rtd.t_fixed_or_side(c).map_or_else(|a| a, |t| t > t_max)
                }),
                t_min,
                t_max,
                center: t_fixed(tc)?,
                t0: t_fixed(t0.0)?,
                inv_half_span: from_f64(1.0 / ts, X_BITS + CODE_FACTOR_BITS - DIFF_BITS)?,
                bias_g: FixedPoly::new(&bias, G_BITS)?,
                k1_ratio: FixedPoly::new(&eta_poly, RATIO_BITS)?,
                k1_center32: k1_center as f32,
                c_per_code_center: from_f64(
                    accel.per_code / k1_center,
                    G_BITS + CODE_FACTOR_BITS + 2,
                )?,
                offset_g_center: from_f64(accel.offset / k1_center, G_BITS)?,
                k2: k2.coeffs.map(|c| c as f32),
                lin_offset_v_per_c: from_f64(
                    lin_offset_v_per_c,
                    VOLT_BITS + CODE_FACTOR_BITS - DIFF_BITS,
                )?,
                lin_gain_per_c: lin_gain as f32,
                lin_k2_v_per_c: lin_k2 as f32,
                inv_k1_t0: (1.0 / k1_t0) as f32,
                k0_t0_g: k_t0.bias_g as f32,
                accel: AccelFixed::new(accel)?,
            })
        };
        let ok = in_formats && a_i_g.is_finite() && linearized_v.is_finite();
        (if ok { fast() } else { None }, bounds)
    }

    /// The temperature terms for an RTD code of temperature T ([`CELSIUS_BITS`]), clamped to the
    /// calibrated range: integer arithmetic and a few f32 operations, no soft-float call. None
    /// when a term does not fit its fixed-point format (then the sample takes the f64 path).
    #[inline]
    fn terms_for_code(&self, code: u32, t: i64) -> Option<ThermalTerms> {
        let (t, clamped) = if code < self.in_range_from {
            (self.t_min, true)
        } else if code >= self.above_range_from {
            (self.t_max, true)
        } else {
            (t, false)
        };
        // |T − Tc| ≤ Ts < 64 °C: the i32 holds it; |x| ≤ 1 (+ 1/Ts's rounding): so does x's.
        let diff = ((t - self.center) >> (CELSIUS_BITS - DIFF_BITS)) as i32;
        let x = mul_code(diff, self.inv_half_span) as i32;
        let bias = self.bias_g.eval(x);
        // K1(T) = K1(Tc)·(1 + η), |η| ≤ 1/32: K1(Tc)/K1(T) = 1 − η + η²(1 − η) + O(η⁴), η in
        // fixed point, the second order in f32 (for a fitted K1, η ≈ 1e-3: its f32 rounding is
        // ≈ 1e-13 of the ratio; the activation's bound has the general case).
        let eta = self.k1_ratio.eval(x);
        let eta32 = ((eta >> (RATIO_BITS - 32)) as i32) as f32 * (1.0 / 4_294_967_296.0);
        // η²(1 − η) ≤ (1/32)²·(33/32) < 2^-9 (|η| ≤ 1/32 at activation): one VCVT, to 2^-40.
        let second = from_f32_small(eta32 * eta32 * (1.0 - eta32), RATIO_BITS);
        let ratio = (1i64 << RATIO_BITS) - eta + second;
        let x32 = x as f32 * (1.0 / (1u32 << X_BITS) as f32);
        let [k2_0, k2_1, k2_2, k2_3, k2_4] = self.k2;
        let k2 = (((k2_4 * x32 + k2_3) * x32 + k2_2) * x32 + k2_1) * x32 + k2_0;
        // |T − T0| < 128 °C (checked at activation): the i32 holds it at 2^-24 °C.
        let dt = ((t - self.t0) >> (CELSIUS_BITS - DIFF_BITS)) as i32;
        // ratio − 1 = −η + η²(1 − η), |·| < 1/16: an i32 at 2^-32 for the offset term (offset/K1
        // is small: its product needs no more).
        let ratio_minus_one = ((ratio - (1i64 << RATIO_BITS)) >> (RATIO_BITS - 32)) as i32;
        Some(ThermalTerms {
            clamped,
            // c = K0 − E/K1 with E = code·per_code − offset: offset/K1 = (offset/K1(Tc))·ratio.
            c0_g: bias + self.offset_g_center + mul_code(ratio_minus_one, self.offset_g_center),
            c_per_code: mul_hi(self.c_per_code_center, ratio),
            k1_v_per_g32: self.k1_center32 * (1.0 + eta32),
            k2,
            lin_offset_v: mul_code(dt, self.lin_offset_v_per_c),
            dt: dt as f32 * (U32 as f32),
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
        e: i64,
        tilt_code: Option<i32>,
        tilt: &PreparedTilt,
    ) -> Result<Compensated, FastFault> {
        use FastFault::Failed;

        // Equation (5): E − sign·K1(T)·sin(φ − φ0). Divided by K1 the correction is sign·sin φ
        // itself, so c takes it in g and the linearized output in volts.
        let (tilt_g, tilt_v) = match tilt_code {
            None => (0, 0),
            Some(code) => {
                let phi = tilt.phi_rad(code);
                if phi.is_nan() || phi.abs() > MAX_F32_TILT_RAD {
                    // Beyond ≈ 103" (or a code far off): the whole sample in f64.
                    return Err(FastFault::Double);
                }
                // The sign (±1) is applied in f32, where it is exact. |sin φ| ≤ 5e-4 and
                // K1 < 3.5 V/g (activation): both below 2^-9.
                let s = tilt.sign32 * small_sin(phi);
                (
                    from_f32_small(s, G_BITS),
                    from_f32_small(terms.k1_v_per_g32 * s, VOLT_BITS),
                )
            }
        };

        // Equation (1) inverted: a = −2c/(1 + √(1 − 4K2c)) = −c·(1 + g), c = K0 − E/K1.
        // |c0| and |code·c_per_code| < 2^60, the tilt and c·g below 2^-9 g (activation, and the
        // series' range): the sums cannot overflow, hence no checked arithmetic.
        let c = terms
            .c0_g
            .wrapping_sub(mul_code(accel_code, terms.c_per_code))
            .wrapping_add(tilt_g);
        let c32 = to_f32(c, G_BITS);
        let w = 4.0 * terms.k2 * c32;
        if w.is_nan() || w.abs() > MAX_SERIES_W {
            // A nonlinearity the series does not cover (|4·K2·c| > 1e-2): the sample in f64.
            return Err(FastFault::Double);
        }
        let cg = from_f32(c32 * root_series(w), G_BITS).ok_or(Failed)?;
        let a_i = to_f64(c.wrapping_neg().wrapping_sub(cg), G_BITS);

        // Linearized (eq. 3/4): ΔE = dt·(s0 + E·s1 + s2·a²), a estimated at T0; dt·s0 is a
        // temperature term. |E|, |dt·s0| < 2^60 (activation): no overflow either.
        let e = e.wrapping_sub(tilt_v);
        let e32 = to_f32(e, VOLT_BITS);
        let a_est = e32 * self.inv_k1_t0 - self.k0_t0_g;
        let small = terms.dt * (e32 * self.lin_gain_per_c + self.lin_k2_v_per_c * a_est * a_est);
        let lin = e
            .wrapping_sub(terms.lin_offset_v)
            .wrapping_sub(from_f32(small, VOLT_BITS).ok_or(Failed)?);
        // Finite by construction (fixed point converted): no check needed.
        Ok((a_i, to_f64(lin, VOLT_BITS), terms.clamped))
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
    use crate::table::CalibrationTable;
    use crate::units::{RtdOhms, Volts};

    /// The table prepared, on the mixed-precision path (asserted), and its error bounds.
    fn prepared_mixed(t: &CalibrationTable) -> (PreparedCalibration, ErrorBounds) {
        let p = PreparedCalibration::new(t).unwrap();
        assert_eq!(p.precision(), Precision::Mixed);
        let bounds = p.error_bounds();
        (p, bounds)
    }

    /// The paper's table with everything the prepared path folds in made non-trivial: ADC gain
    /// and offset corrections, cross-axis inputs, x³ and x⁴ terms, T0 off the centre.
    fn busy_table() -> CalibrationTable {
        let mut t = paper_table();
        t.accel.adc_gain_correction = 1.0001;
        t.accel.adc_offset = Volts(-3e-6);
        t.rtd.adc_gain_correction = 0.9998;
        t.orientation.cross = CrossAxis {
            a_p: crate::units::Gs(0.3),
            a_o: crate::units::Gs(-0.2),
        };
        let m = &mut t.thermal.models;
        m.bias_g.coeffs[3] = 2e-5;
        m.bias_g.coeffs[4] = -1e-5;
        m.scale_factor_v_per_g.coeffs[3] = -2e-5;
        m.scale_factor_v_per_g.coeffs[4] = 1.5e-5;
        m.misalignment_o_rad.coeffs = [3e-4, 2e-5, -1e-5, 0.0, 0.0];
        t.thermal.reference = Celsius(41.0);
        t
    }

    /// The f64 reference of the RTD inverse: R = code·(ohms per code), T from the quadratic root.
    fn reference_t(p: &PreparedCalibration, code: u32) -> (f64, f64) {
        let ohms = f64::from(code) * p.rtd.ohms_per_code;
        (ohms, p.rtd.cvd.temperature(RtdOhms(ohms)).unwrap().0)
    }

    #[test]
    fn the_fixed_rtd_inverse_is_within_its_bound_for_every_code_from_0_to_300_c() {
        let t = busy_table();
        let p = PreparedCalibration::new(&t).unwrap();
        let code_at = |c: f64| (t.rtd.cvd.resistance(Celsius(c)).0 / p.rtd.ohms_per_code) as u32;
        let (lo, hi) = (code_at(30.0), code_at(65.0));
        let mut worst = 0.0f64; // error / bound
                                // Every code of the calibrated range, every 7th from 0 °C to 300 °C.
        let codes = (lo..=hi).chain((p.rtd.closed_form_from..code_at(300.0)).step_by(7));
        for code in codes {
            let (ohms_ref, t_ref) = reference_t(&p, code);
            let (ohms, t_c) = p.rtd(code).unwrap();
            // The product's floor at 2^-42 Ω and two f64 roundings.
            assert!(
                (ohms - ohms_ref).abs() <= 2.3e-13 + 4.5e-16 * ohms_ref,
                "{code}"
            );
            let bound = p.rtd.error_bound_c(t_ref);
            worst = worst.max((t_c - t_ref).abs() / bound);
        }
        assert!(worst <= 1.0, "worst error/bound {worst}");
        // The bound itself at the top of the calibrated range, as documented.
        assert!(p.rtd.error_bound_c(65.0) < 6e-7);
    }

    #[test]
    fn the_fixed_point_terms_are_within_the_a_i_bound_for_every_code_of_the_range() {
        let t = busy_table();
        let (p, bounds) = prepared_mixed(&t);
        let fast = p.fast.as_ref().unwrap();
        let th = &t.thermal;
        let cross = t.orientation.cross;
        let accel = &p.accel;
        let accel_codes: [i32; 5] = [
            -2_000_000_000,
            -900_000_000,
            0,
            1_100_000_000,
            2_000_000_000,
        ];
        let (mut worst_c, mut worst_lin) = (0.0f64, 0.0f64);
        // Every code of the range and 2000 beyond each end (clamped).
        for code in fast.in_range_from - 2000..fast.above_range_from + 2000 {
            let temperature = p.temperature_uncached(code);
            let terms = temperature.terms.unwrap();
            let (_, t_ref) = reference_t(&p, code);
            let t_used = t_ref.clamp(th.scale.min.0, th.scale.max.0);
            let (k, _) = th.coefficients_at(Celsius(t_used)).unwrap();
            let bias =
                k.bias_g + k.misalignment_o.0 * cross.a_p.0 - k.misalignment_p.0 * cross.a_o.0;
            for code_a in accel_codes {
                let e = f64::from(code_a) * accel.per_code - accel.offset;
                let c_ref = bias - e / k.scale_factor_v_per_g;
                let c = to_f64(terms.c0_g - mul_code(code_a, terms.c_per_code), G_BITS);
                worst_c = worst_c.max((c - c_ref).abs());
            }
            let s0 = fast.lin_offset_v_per_c as f64
                / libm::ldexp(1.0, (VOLT_BITS + CODE_FACTOR_BITS - DIFF_BITS) as i32);
            let lin_ref = s0 * (t_used - th.reference.0);
            let lin = to_f64(terms.lin_offset_v, VOLT_BITS);
            worst_lin = worst_lin.max((lin - lin_ref).abs());
            let k2_err = (f64::from(terms.k2) - k.nonlinearity_g_per_g2).abs();
            assert!(k2_err <= 1e-12, "{code}: K2 off by {k2_err:e}");
            let k1_rel = (f64::from(terms.k1_v_per_g32) / k.scale_factor_v_per_g - 1.0).abs();
            assert!(k1_rel <= 4.0 * U32, "{code}: K1 off by {k1_rel:e}");
        }
        // c carries every temperature term of a_i; the linearized offset those of ΔE.
        assert!(
            worst_c <= bounds.a_i_g,
            "c off by {worst_c:e}, bound {bounds:?}"
        );
        assert!(
            worst_lin <= bounds.linearized_v,
            "ΔE off by {worst_lin:e}, bound {bounds:?}"
        );
        // What the sweep measures, far inside the bound (which also covers E's, the tilt's and
        // the root's f32 errors): T's 5e-7 °C through the slopes, a few 1e-11 g.
        assert!(worst_c < 1e-10, "c off by {worst_c:e}");
    }

    #[test]
    fn the_range_check_by_code_agrees_with_comparing_the_temperature() {
        let t = paper_table();
        let p = PreparedCalibration::new(&t).unwrap();
        let fast = p.fast.as_ref().unwrap();
        for edge in [fast.in_range_from, fast.above_range_from] {
            for code in edge - 300..edge + 300 {
                let temperature = p.temperature(code);
                let t_c = temperature.t_c;
                let outside = t_c < t.thermal.scale.min.0 || t_c > t.thermal.scale.max.0;
                assert_eq!(temperature.terms.unwrap().clamped, outside, "{code}: {t_c}");
            }
        }
        // The edges are where they should be: 30 °C and 65 °C are a code apart from them.
        let t_at = |code: u32| p.temperature(code).t_c;
        assert!(t_at(fast.in_range_from - 1) < 30.0 && t_at(fast.in_range_from) >= 30.0);
        assert!(t_at(fast.above_range_from - 1) <= 65.0 && t_at(fast.above_range_from) > 65.0);
    }

    #[test]
    fn a_temperature_fits_in_64_bytes_so_the_cache_copies_it_inline() {
        assert!(core::mem::size_of::<Option<Temperature>>() <= 64);
    }

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
            // The fixed path's bound (2e-7 °C at 30 °C, 5e-7 °C at 65 °C, 4e-6 °C at 300 °C);
            // below 0 °C both take the f64 Newton path.
            let bound = p.rtd.error_bound_c(c) + 1e-10;
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
    fn the_papers_table_is_mixed_and_a_strongly_varying_scale_factor_falls_back_to_f64() {
        let t = paper_table();
        let (_, b) = prepared_mixed(&t);
        // Hand figure: tilt 6u·5e-4 ≈ 1.8e-10 g; K1 varies by ε ≈ 4.8e-4 of K1(Tc) over the
        // range, so 1/K1's series and f32 second order cost ≈ 3e-13 of c; T's 5e-7 °C at 65 °C
        // through the bias and K1 slopes ≈ 4e-11 g: a few 1e-10 g.
        assert!(b.a_i_g > 1e-10 && b.a_i_g < 1e-9, "{b:?}");
        assert!(b.linearized_v < BUDGET_LINEARIZED_V, "{b:?}");

        // K1 varying by 15 % over the range: 1/K1's series (ε⁴ ≈ 5e-4) is far over the budget.
        // (A strongly curved bias alone no longer is: it is evaluated in fixed point.)
        let mut curved = t;
        curved.thermal.models.scale_factor_v_per_g.coeffs[2] = 0.2;
        let p = PreparedCalibration::new(&curved).unwrap();
        assert_eq!(p.precision(), Precision::Double);
        assert!(p.error_bounds().a_i_g > BUDGET_G);
    }

    #[test]
    fn the_f64_fallback_gives_the_reference_compensation() {
        let mut t = paper_table();
        t.thermal.models.scale_factor_v_per_g.coeffs[2] = 0.2;
        let p = PreparedCalibration::new(&t).unwrap();
        let accel = crate::board::volts_to_ads1262(&accel_scale(Some(&t)), Volts(1.3))
            .unwrap()
            .0;
        let rtd = crate::board::celsius_to_ad7124(&t, Celsius(47.0))
            .unwrap()
            .0;
        let (e, e_fixed) = p.accel_volts(accel).unwrap();
        let temperature = p.temperature(rtd);
        let t_c = temperature.t_c;
        let (a, lin, clamped) = p
            .compensate(accel, e, e_fixed, &temperature, Some(0))
            .unwrap();
        let tilt0 = p.tilt.phi_rad_f64(0);
        let (k, _) = t.thermal.coefficients_at(Celsius(t_c)).unwrap();
        let e_c = Volts(e - k.scale_factor_v_per_g * tilt_sin(tilt0).unwrap());
        let cross = t.orientation.cross;
        let want = t.thermal.exact(e_c, Celsius(t_c), cross).unwrap();
        let want_lin = t.thermal.linearized(e_c, Celsius(t_c), cross).unwrap();
        assert_eq!((a, lin, clamped), (want.input.0, want_lin.output.0, false));
    }
}
