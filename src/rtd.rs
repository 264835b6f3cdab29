//! Platinum resistance thermometer: Callendar–Van Dusen (IEC 60751 / ITS-90 practical form).
//!
//! ```text
//! T ≥ 0 °C: R(T) = R0·(1 + A·T + B·T²)
//! T < 0 °C: R(T) = R0·(1 + A·T + B·T² + C·(T − 100)·T³)
//! ```
//!
//! Each sensor carries its own R0, A, B, C (from its calibration certificate); the IEC 60751
//! standard values are [`CallendarVanDusen::IEC_60751_PT100`].

use crate::units::{Celsius, RtdOhms};

/// Per-sensor Callendar–Van Dusen constants.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CallendarVanDusen {
    /// Resistance at 0 °C, Ω.
    pub r0: f64,
    /// A, 1/°C.
    pub a: f64,
    /// B, 1/°C².
    pub b: f64,
    /// C, 1/°C⁴ (used below 0 °C only).
    pub c: f64,
}

/// A resistance that cannot be a working sensor, or constants that cannot be a platinum RTD.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RtdError {
    /// Resistance above the −200…850 °C span: broken wire or open connection.
    Open,
    /// Resistance below the span: shorted sensor or leads.
    Short,
    /// Resistance is NaN or infinite.
    NonFinite,
    /// R0, A, B or C out of the plausible range for platinum.
    InvalidConstants,
    /// The iteration for T < 0 °C did not converge (cannot happen for valid constants).
    NoConvergence,
}

/// IEC 60751 span of validity, °C: the temperatures a platinum RTD reading can stand for (the
/// fault thresholds below are set from it; `accomp fit` refuses calibration temperatures outside).
pub const T_MIN_C: f64 = -200.0;
/// Upper end of the IEC 60751 span, °C.
pub const T_MAX_C: f64 = 850.0;

impl CallendarVanDusen {
    /// IEC 60751 Pt100: A = 3.9083e-3, B = −5.775e-7, C = −4.183e-12.
    pub const IEC_60751_PT100: CallendarVanDusen = CallendarVanDusen {
        r0: 100.0,
        a: 3.9083e-3,
        b: -5.775e-7,
        c: -4.183e-12,
    };

    /// Checks the constants against what platinum can be (α between 0.0036 and 0.0040 /°C,
    /// B and C negative and small, R0 from 10 Ω to 10 kΩ).
    pub fn validate(&self) -> Result<(), RtdError> {
        let finite =
            self.r0.is_finite() && self.a.is_finite() && self.b.is_finite() && self.c.is_finite();
        let ok = finite
            && (10.0..=10_000.0).contains(&self.r0)
            && (3.5e-3..=4.1e-3).contains(&self.a)
            && (-1e-6..=0.0).contains(&self.b)
            && (-1e-11..=0.0).contains(&self.c);
        if ok {
            Ok(())
        } else {
            Err(RtdError::InvalidConstants)
        }
    }

    /// R(T).
    pub fn resistance(&self, t: Celsius) -> RtdOhms {
        let t = t.0;
        let mut ratio = 1.0 + self.a * t + self.b * t * t;
        if t < 0.0 {
            ratio += self.c * (t - 100.0) * t * t * t;
        }
        RtdOhms(self.r0 * ratio)
    }

    /// Fault thresholds: 10 % below R(−200 °C) and 5 % above R(850 °C). The margins keep a
    /// healthy sensor at the span's edge (and table values rounded down) out of the fault path.
    pub(crate) fn resistance_limits(&self) -> (f64, f64) {
        (
            0.90 * self.resistance(Celsius(T_MIN_C)).0,
            1.05 * self.resistance(Celsius(T_MAX_C)).0,
        )
    }

    /// T(R) for both branches: closed form at and above R0, Newton iteration below.
    pub fn temperature(&self, r: RtdOhms) -> Result<Celsius, RtdError> {
        self.validate()?;
        if !r.0.is_finite() {
            return Err(RtdError::NonFinite);
        }
        let (r_min, r_max) = self.resistance_limits();
        if r.0 > r_max {
            return Err(RtdError::Open);
        }
        if r.0 < r_min {
            return Err(RtdError::Short);
        }
        Ok(Celsius(self.temperature_of_ratio(r.0 / self.r0 - 1.0)?))
    }

    /// T for q = R/R0 − 1, without the checks of [`Self::temperature`] (validated constants, R
    /// inside the fault thresholds): for a caller that made them once (the firmware's prepared
    /// table, which checks R by code thresholds).
    pub(crate) fn temperature_of_ratio(&self, q: f64) -> Result<f64, RtdError> {
        // Root of B·T² + A·T − q = 0 that tends to q/A as B → 0, written without cancellation.
        let quadratic = 2.0 * q / (self.a + libm::sqrt(self.a * self.a + 4.0 * self.b * q));
        if q >= 0.0 {
            return Ok(quadratic);
        }
        // Below 0 °C the C term (at most 0.1 °C at −200 °C) makes it a quartic: Newton from the
        // quadratic root converges in 2–3 steps; 20 are allowed before declaring failure.
        let mut t = quadratic;
        for _ in 0..20 {
            let f = self.resistance(Celsius(t)).0 / self.r0 - 1.0 - q;
            let df = self.a + 2.0 * self.b * t + self.c * (4.0 * t * t * t - 300.0 * t * t);
            let step = f / df;
            t -= step;
            if libm::fabs(step) < 1e-10 {
                return Ok(t);
            }
        }
        Err(RtdError::NoConvergence)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// IEC 60751 Pt100 table, resistance in Ω printed to 0.01 Ω.
    const IEC_TABLE: [(f64, f64); 12] = [
        (-200.0, 18.52),
        (-100.0, 60.26),
        (-50.0, 80.31),
        (-20.0, 92.16),
        (0.0, 100.00),
        (25.0, 109.73),
        (50.0, 119.40),
        (60.0, 123.24),
        (100.0, 138.51),
        (200.0, 175.86),
        (500.0, 280.98),
        (850.0, 390.48),
    ];

    #[test]
    fn resistance_matches_the_iec_60751_table_to_its_printed_digits() {
        let pt = CallendarVanDusen::IEC_60751_PT100;
        for (t, r) in IEC_TABLE {
            let got = pt.resistance(Celsius(t)).0;
            assert!((got - r).abs() <= 0.005 + 1e-9, "R({t}) = {got}, table {r}");
        }
    }

    #[test]
    fn temperature_from_table_resistance_is_within_the_tables_rounding() {
        // ±0.005 Ω of table rounding is at most 0.005/0.39 ≈ 0.013 °C at the steepest point.
        let pt = CallendarVanDusen::IEC_60751_PT100;
        for (t, r) in IEC_TABLE {
            let got = pt.temperature(RtdOhms(r)).unwrap().0;
            assert!((got - t).abs() < 0.014, "T({r}) = {got}, table {t}");
        }
    }

    #[test]
    fn both_branches_invert_the_forward_model_to_sub_microkelvin() {
        let pt = CallendarVanDusen {
            r0: 100.012,
            a: 3.9080e-3,
            b: -5.80e-7,
            c: -4.3e-12,
        };
        let mut t = -199.5;
        while t < 849.0 {
            let back = pt.temperature(pt.resistance(Celsius(t))).unwrap().0;
            assert!((back - t).abs() < 1e-6, "t={t} back={back}");
            t += 7.25;
        }
    }

    #[test]
    fn open_and_shorted_sensors_are_named_not_converted() {
        let pt = CallendarVanDusen::IEC_60751_PT100;
        assert_eq!(pt.temperature(RtdOhms(1e6)), Err(RtdError::Open));
        assert_eq!(pt.temperature(RtdOhms(0.3)), Err(RtdError::Short));
        assert_eq!(pt.temperature(RtdOhms(f64::NAN)), Err(RtdError::NonFinite));
        let bad = CallendarVanDusen { a: 0.0, ..pt };
        assert_eq!(
            bad.temperature(RtdOhms(100.0)),
            Err(RtdError::InvalidConstants)
        );
    }
}
