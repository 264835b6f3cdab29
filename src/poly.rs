//! Temperature polynomials of order ≤ 4, stored in the normalized variable x = (T − Tc)/Ts.
//!
//! In raw °C a 4th-order fit over 30–65 °C has a Vandermonde condition number of ~5e9 and the
//! paper's 3-digit printing of such coefficients wrecks the model (see docs/fitting.md). With
//! x ∈ [−1, 1] over the calibrated range, the monomials 1, x, …, x⁴ are well conditioned, so
//! the coefficients can be stored and evaluated (Horner) without loss.

use crate::units::Celsius;

/// Highest supported polynomial order.
pub const MAX_ORDER: usize = 4;
/// Number of stored coefficients (orders 0..=MAX_ORDER).
pub const N_COEFFS: usize = MAX_ORDER + 1;

/// A polynomial p(x) = c0 + c1·x + … + c4·x⁴ in the normalized temperature x.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TempPoly {
    /// Coefficients c0..c4 in ascending powers of x; those above `order` are zero.
    pub coeffs: [f64; N_COEFFS],
}

/// Whether a temperature was inside the calibrated range or had to be clamped to it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RangeStatus {
    /// Inside [min, max].
    Inside,
    /// Below the range: evaluated at the minimum.
    ClampedLow,
    /// Above the range: evaluated at the maximum.
    ClampedHigh,
}

impl RangeStatus {
    /// True when the temperature was outside the calibrated range.
    #[inline]
    pub fn is_clamped(self) -> bool {
        self != RangeStatus::Inside
    }
}

/// Why a temperature scale or an evaluation is refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ScaleError {
    /// The temperature (or a scale parameter) is NaN or infinite.
    NonFinite,
    /// The calibrated range is empty or inverted (max ≤ min).
    EmptyRange,
    /// Ts is zero or negative.
    InvalidSpan,
}

/// The calibrated temperature range and the normalization x = (T − Tc)/Ts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TemperatureScale {
    /// Lowest calibrated temperature.
    pub min: Celsius,
    /// Highest calibrated temperature.
    pub max: Celsius,
    /// Tc, the centre of the normalization.
    pub center: Celsius,
    /// Ts, the half-span of the normalization (°C per unit of x).
    pub half_span_c: f64,
}

/// A temperature mapped into the normalized variable, with its range status.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Normalized {
    /// x = (T_clamped − Tc)/Ts.
    pub x: f64,
    /// The temperature actually used (clamped into the range).
    pub used: Celsius,
    /// Whether clamping happened.
    pub status: RangeStatus,
}

impl TemperatureScale {
    /// The natural scale for a calibrated range: Tc at the middle, Ts the half-width, so
    /// x ∈ [−1, 1] exactly over the range.
    pub fn for_range(min: Celsius, max: Celsius) -> Result<Self, ScaleError> {
        let s = TemperatureScale {
            min,
            max,
            center: Celsius(0.5 * (min.0 + max.0)),
            half_span_c: 0.5 * (max.0 - min.0),
        };
        s.validate()?;
        Ok(s)
    }

    /// Checks that the scale is usable.
    pub fn validate(&self) -> Result<(), ScaleError> {
        if !(self.min.0.is_finite()
            && self.max.0.is_finite()
            && self.center.0.is_finite()
            && self.half_span_c.is_finite())
        {
            return Err(ScaleError::NonFinite);
        }
        if self.max.0 <= self.min.0 {
            return Err(ScaleError::EmptyRange);
        }
        if self.half_span_c <= 0.0 {
            return Err(ScaleError::InvalidSpan);
        }
        Ok(())
    }

    /// Maps T to x, clamping to the calibrated range: a model is never extrapolated silently.
    #[inline]
    pub fn normalize(&self, t: Celsius) -> Result<Normalized, ScaleError> {
        if !t.0.is_finite() {
            return Err(ScaleError::NonFinite);
        }
        let (used, status) = if t.0 < self.min.0 {
            (self.min, RangeStatus::ClampedLow)
        } else if t.0 > self.max.0 {
            (self.max, RangeStatus::ClampedHigh)
        } else {
            (t, RangeStatus::Inside)
        };
        Ok(Normalized {
            x: (used.0 - self.center.0) / self.half_span_c,
            used,
            status,
        })
    }

    /// x for a temperature without clamping (for fitting and reporting, never for compensation).
    #[inline]
    pub fn x_unclamped(&self, t: Celsius) -> f64 {
        (t.0 - self.center.0) / self.half_span_c
    }
}

impl TempPoly {
    /// A polynomial from coefficients in ascending powers of x (at most five).
    pub fn from_coeffs(c: &[f64]) -> Option<Self> {
        if c.len() > N_COEFFS {
            return None;
        }
        let mut coeffs = [0.0; N_COEFFS];
        for (dst, src) in coeffs.iter_mut().zip(c) {
            *dst = *src;
        }
        Some(TempPoly { coeffs })
    }

    /// A constant.
    pub const fn constant(c0: f64) -> Self {
        TempPoly {
            coeffs: [c0, 0.0, 0.0, 0.0, 0.0],
        }
    }

    /// Highest power with a non-zero coefficient (0 for a constant or zero polynomial).
    pub fn order(&self) -> usize {
        self.coeffs.iter().rposition(|c| *c != 0.0).unwrap_or(0)
    }

    /// p(x) by Horner's rule.
    #[inline]
    pub fn eval(&self, x: f64) -> f64 {
        let c = &self.coeffs;
        (((c[4] * x + c[3]) * x + c[2]) * x + c[1]) * x + c[0]
    }

    /// dp/dx by Horner's rule.
    #[inline]
    pub fn derivative_x(&self, x: f64) -> f64 {
        let c = &self.coeffs;
        ((4.0 * c[4] * x + 3.0 * c[3]) * x + 2.0 * c[2]) * x + c[1]
    }

    /// All coefficients multiplied by `k` (a unit change such as arcmin → rad).
    pub fn scaled(&self, k: f64) -> Self {
        let mut out = *self;
        for c in out.coeffs.iter_mut() {
            *c *= k;
        }
        out
    }

    /// True when every coefficient is finite.
    pub fn is_finite(&self) -> bool {
        self.coeffs.iter().all(|c| c.is_finite())
    }
}

/// A temperature model: a polynomial together with the scale it is expressed in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TemperatureModel<'a> {
    /// The polynomial in x.
    pub poly: &'a TempPoly,
    /// Range and normalization.
    pub scale: &'a TemperatureScale,
}

/// A model value at a temperature, with the range status of that temperature.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Evaluated {
    /// The model value.
    pub value: f64,
    /// Whether the temperature was clamped.
    pub status: RangeStatus,
}

impl TemperatureModel<'_> {
    /// K(T), clamping T to the calibrated range and reporting it.
    pub fn at(&self, t: Celsius) -> Result<Evaluated, ScaleError> {
        let n = self.scale.normalize(t)?;
        Ok(Evaluated {
            value: self.poly.eval(n.x),
            status: n.status,
        })
    }

    /// dK/dT (per °C) at T, clamped like [`TemperatureModel::at`]; zero slope is *not*
    /// substituted outside the range: the slope at the range edge is returned with the status.
    pub fn slope_per_c(&self, t: Celsius) -> Result<Evaluated, ScaleError> {
        let n = self.scale.normalize(t)?;
        Ok(Evaluated {
            value: self.poly.derivative_x(n.x) / self.scale.half_span_c,
            status: n.status,
        })
    }
}

/// Binomial coefficient C(n, k) for n ≤ 4, exact in f64.
const fn binomial(n: usize, k: usize) -> f64 {
    const TABLE: [[f64; N_COEFFS]; N_COEFFS] = [
        [1.0, 0.0, 0.0, 0.0, 0.0],
        [1.0, 1.0, 0.0, 0.0, 0.0],
        [1.0, 2.0, 1.0, 0.0, 0.0],
        [1.0, 3.0, 3.0, 1.0, 0.0],
        [1.0, 4.0, 6.0, 4.0, 1.0],
    ];
    if n < N_COEFFS && k < N_COEFFS {
        TABLE[n][k]
    } else {
        0.0
    }
}

fn powi(base: f64, n: usize) -> f64 {
    let mut r = 1.0;
    for _ in 0..n {
        r *= base;
    }
    r
}

impl TempPoly {
    /// The same polynomial as monomial coefficients in raw °C, K(T) = Σ m_j·T^j, for comparison
    /// with printed models. Exact algebra, but the result is ill-conditioned to *use*: it is for
    /// display, never for evaluation.
    pub fn to_monomial_celsius(&self, scale: &TemperatureScale) -> [f64; N_COEFFS] {
        // x = (T − Tc)/Ts = a·T + b with a = 1/Ts, b = −Tc/Ts; expand c_k·(a·T + b)^k.
        let a = 1.0 / scale.half_span_c;
        let b = -scale.center.0 / scale.half_span_c;
        let mut m = [0.0; N_COEFFS];
        for (k, ck) in self.coeffs.iter().enumerate() {
            for (j, mj) in m.iter_mut().enumerate().take(k + 1) {
                *mj += ck * binomial(k, j) * powi(a, j) * powi(b, k - j);
            }
        }
        m
    }

    /// A polynomial in x from monomial coefficients in raw °C (ascending powers, ≤ 5 terms).
    pub fn from_monomial_celsius(m: &[f64], scale: &TemperatureScale) -> Option<Self> {
        if m.len() > N_COEFFS {
            return None;
        }
        // T = Tc + Ts·x; expand m_k·(Tc + Ts·x)^k.
        let mut c = [0.0; N_COEFFS];
        for (k, mk) in m.iter().enumerate() {
            for (j, cj) in c.iter_mut().enumerate().take(k + 1) {
                *cj +=
                    mk * binomial(k, j) * powi(scale.half_span_c, j) * powi(scale.center.0, k - j);
            }
        }
        Some(TempPoly { coeffs: c })
    }
}

#[cfg(test)]
mod basis_tests {
    use super::*;

    #[test]
    fn monomial_round_trip_preserves_the_function() {
        let s = TemperatureScale::for_range(Celsius(30.0), Celsius(65.0)).unwrap();
        // The paper's printed order-2 bias model (Table 2): 0.003554 + 2.97e-5·T + 2.46e-7·T².
        let printed = [0.003554, 2.97e-5, 2.46e-7];
        let p = TempPoly::from_monomial_celsius(&printed, &s).unwrap();
        for t in [30.0, 41.3, 65.0] {
            let direct = 0.003554 + 2.97e-5 * t + 2.46e-7 * t * t;
            assert!((p.eval(s.x_unclamped(Celsius(t))) - direct).abs() < 1e-17);
        }
        let back = p.to_monomial_celsius(&s);
        for (a, b) in back.iter().zip([0.003554, 2.97e-5, 2.46e-7, 0.0, 0.0]) {
            assert!((a - b).abs() <= 1e-15 * b.abs().max(1e-12), "{a} vs {b}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scale_30_65() -> TemperatureScale {
        TemperatureScale::for_range(Celsius(30.0), Celsius(65.0)).unwrap()
    }

    #[test]
    fn for_range_maps_the_range_onto_minus_one_to_one() {
        let s = scale_30_65();
        assert_eq!(s.normalize(Celsius(30.0)).unwrap().x, -1.0);
        assert_eq!(s.normalize(Celsius(65.0)).unwrap().x, 1.0);
        assert_eq!(s.normalize(Celsius(47.5)).unwrap().x, 0.0);
    }

    #[test]
    fn horner_matches_explicit_powers() {
        let p = TempPoly::from_coeffs(&[1.5, -0.25, 3.0, 0.125, -2.0]).unwrap();
        for x in [-1.0, -0.3, 0.0, 0.7, 1.0] {
            let explicit = 1.5 - 0.25 * x + 3.0 * x * x + 0.125 * x * x * x - 2.0 * x * x * x * x;
            assert!((p.eval(x) - explicit).abs() < 1e-14);
            let d = -0.25 + 6.0 * x + 0.375 * x * x - 8.0 * x * x * x;
            assert!((p.derivative_x(x) - d).abs() < 1e-14);
        }
    }

    #[test]
    fn slope_per_c_is_the_derivative_in_celsius() {
        // K(T) = 2 + 3·x with x = (T − 47.5)/17.5 → dK/dT = 3/17.5.
        let s = scale_30_65();
        let p = TempPoly::from_coeffs(&[2.0, 3.0]).unwrap();
        let m = TemperatureModel {
            poly: &p,
            scale: &s,
        };
        let d = m.slope_per_c(Celsius(40.0)).unwrap();
        assert!((d.value - 3.0 / 17.5).abs() < 1e-15);
        // Numerical check against a central difference.
        let h = 1e-4;
        let num = (m.at(Celsius(40.0 + h)).unwrap().value - m.at(Celsius(40.0 - h)).unwrap().value)
            / (2.0 * h);
        assert!((num - d.value).abs() < 1e-9);
    }

    #[test]
    fn temperatures_outside_the_range_are_clamped_and_reported() {
        let s = scale_30_65();
        let p = TempPoly::from_coeffs(&[0.0, 1.0, 1.0]).unwrap();
        let m = TemperatureModel {
            poly: &p,
            scale: &s,
        };
        let hi = m.at(Celsius(80.0)).unwrap();
        assert_eq!(hi.status, RangeStatus::ClampedHigh);
        assert_eq!(hi.value, p.eval(1.0));
        let lo = m.at(Celsius(-5.0)).unwrap();
        assert_eq!(lo.status, RangeStatus::ClampedLow);
        assert_eq!(lo.value, p.eval(-1.0));
        assert_eq!(m.at(Celsius(50.0)).unwrap().status, RangeStatus::Inside);
    }

    #[test]
    fn nan_temperature_and_inverted_range_are_refused() {
        let s = scale_30_65();
        assert_eq!(s.normalize(Celsius(f64::NAN)), Err(ScaleError::NonFinite));
        assert_eq!(
            TemperatureScale::for_range(Celsius(65.0), Celsius(30.0)),
            Err(ScaleError::EmptyRange)
        );
        assert_eq!(
            TemperatureScale::for_range(Celsius(30.0), Celsius(30.0)),
            Err(ScaleError::EmptyRange)
        );
    }

    #[test]
    fn order_is_the_highest_non_zero_power() {
        assert_eq!(TempPoly::from_coeffs(&[1.0, 0.0, 2.0]).unwrap().order(), 2);
        assert_eq!(TempPoly::constant(0.0).order(), 0);
        assert!(TempPoly::from_coeffs(&[0.0; 6]).is_none());
    }
}
