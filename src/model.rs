//! The accelerometer's static model, the paper's equation (1), and its exact inverse.
//!
//! ```text
//! E = K1 · (K0 + a_i + K2·a_i² + δo·a_p − δp·a_o)
//! ```
//!
//! E output (V), a_i / a_p / a_o acceleration along the input, pendulum and output axes (g),
//! K1 scale factor (V/g), K0 bias (g), K2 second-order nonlinearity (g/g²), δp and δo
//! misalignments (rad, small angles: δ·a is an acceleration in g).

use crate::units::{Gs, Radians, Volts};

/// The five static coefficients of equation (1) at one temperature.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StaticCoefficients {
    /// K0, bias in g.
    pub bias_g: f64,
    /// K1, scale factor in V/g.
    pub scale_factor_v_per_g: f64,
    /// K2, second-order nonlinearity in g/g².
    pub nonlinearity_g_per_g2: f64,
    /// δp, misalignment about the pendulum axis (couples a_o).
    pub misalignment_p: Radians,
    /// δo, misalignment about the output axis (couples a_p).
    pub misalignment_o: Radians,
}

/// Accelerations along the pendulum and output axes: the test orientation's cross-axis inputs.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CrossAxis {
    /// a_p, acceleration along the pendulum axis (g).
    pub a_p: Gs,
    /// a_o, acceleration along the output axis (g).
    pub a_o: Gs,
}

/// Why equation (1) cannot be inverted for a given output.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InverseError {
    /// K1 is zero, negative or not finite.
    InvalidScaleFactor,
    /// An input or coefficient is NaN or infinite.
    NonFinite,
    /// The output lies beyond the fold of the quadratic (1 − 4·K2·c < 0): no real a_i.
    NoRealRoot,
}

impl StaticCoefficients {
    /// The cross-axis part δo·a_p − δp·a_o, in g.
    #[inline]
    fn cross_axis_g(&self, cross: CrossAxis) -> f64 {
        self.misalignment_o.0 * cross.a_p.0 - self.misalignment_p.0 * cross.a_o.0
    }

    /// Equation (1) forward: the output for an input acceleration a_i.
    #[inline]
    pub fn output(&self, a_i: Gs, cross: CrossAxis) -> Volts {
        let a = a_i.0;
        Volts(
            self.scale_factor_v_per_g
                * (self.bias_g + a + self.nonlinearity_g_per_g2 * a * a + self.cross_axis_g(cross)),
        )
    }

    /// Equation (1) inverted exactly for a_i: the root of K2·a² + a + c = 0 with
    /// c = K0 + δo·a_p − δp·a_o − E/K1 that tends to −c as K2 → 0.
    ///
    /// Written as a = −2c / (1 + √(1 − 4·K2·c)) so that nothing cancels: the textbook
    /// (−1 + √…)/(2·K2) loses about eps/K2 (5e-11 g at K2 = 1e-6, 5e-8 g at K2 = 1e-9) and is
    /// undefined at K2 = 0, where this form is exact.
    #[inline]
    pub fn input(&self, e: Volts, cross: CrossAxis) -> Result<Gs, InverseError> {
        let k1 = self.scale_factor_v_per_g;
        if !k1.is_finite() || k1 <= 0.0 {
            return Err(InverseError::InvalidScaleFactor);
        }
        let c = self.bias_g + self.cross_axis_g(cross) - e.0 / k1;
        let k2 = self.nonlinearity_g_per_g2;
        if !c.is_finite() || !k2.is_finite() {
            return Err(InverseError::NonFinite);
        }
        let discriminant = 1.0 - 4.0 * k2 * c;
        if discriminant < 0.0 {
            return Err(InverseError::NoRealRoot);
        }
        Ok(Gs(-2.0 * c / (1.0 + libm::sqrt(discriminant))))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::units::Arcmin;

    /// JN-06 A12124 at 50 °C, Table 1 of the paper.
    fn jn06_at_50c() -> StaticCoefficients {
        StaticCoefficients {
            bias_g: 0.0056442,
            scale_factor_v_per_g: 1.3267168,
            nonlinearity_g_per_g2: -6.1e-8,
            misalignment_p: Arcmin(2.01).to_radians(),
            misalignment_o: Arcmin(0.5).to_radians(),
        }
    }

    #[test]
    fn output_at_one_g_with_no_cross_axis_is_k1_times_one_plus_bias_plus_k2() {
        let k = jn06_at_50c();
        let e = k.output(Gs(1.0), CrossAxis::default());
        // Hand-evaluated: 1.3267168 · (0.0056442 + 1 − 6.1e-8).
        assert!((e.0 - 1.3267168 * 1.005_644_139).abs() < 1e-15);
    }

    #[test]
    fn inverse_recovers_the_input_across_plus_minus_one_and_a_half_g() {
        let k = jn06_at_50c();
        let cross = CrossAxis {
            a_p: Gs(0.3),
            a_o: Gs(-0.2),
        };
        for i in -150..=150 {
            let a = f64::from(i) * 0.01;
            let back = k.input(k.output(Gs(a), cross), cross).unwrap();
            assert!((back.0 - a).abs() < 1e-14, "a={a} back={}", back.0);
        }
    }

    #[test]
    fn inverse_is_exact_when_k2_is_zero_and_stable_when_k2_is_tiny() {
        for k2 in [0.0, 1e-12, -1e-12, 1e-9, 5e-5] {
            let k = StaticCoefficients {
                nonlinearity_g_per_g2: k2,
                ..jn06_at_50c()
            };
            let back = k.input(
                k.output(Gs(1.2), CrossAxis::default()),
                CrossAxis::default(),
            );
            assert!((back.unwrap().0 - 1.2).abs() < 1e-14, "k2={k2}");
        }
    }

    #[test]
    fn misalignments_enter_with_the_paper_signs() {
        // δo·a_p adds, δp·a_o subtracts.
        let k = StaticCoefficients {
            bias_g: 0.0,
            scale_factor_v_per_g: 1.0,
            nonlinearity_g_per_g2: 0.0,
            misalignment_p: Radians(1e-3),
            misalignment_o: Radians(2e-3),
        };
        let e = k.output(
            Gs(0.0),
            CrossAxis {
                a_p: Gs(1.0),
                a_o: Gs(1.0),
            },
        );
        assert!((e.0 - (2e-3 - 1e-3)).abs() < 1e-18);
    }

    #[test]
    fn inverse_refuses_bad_scale_factor_nan_and_beyond_the_fold() {
        let mut k = jn06_at_50c();
        let x = CrossAxis::default();
        k.scale_factor_v_per_g = 0.0;
        assert_eq!(
            k.input(Volts(1.0), x),
            Err(InverseError::InvalidScaleFactor)
        );
        k = jn06_at_50c();
        assert_eq!(k.input(Volts(f64::NAN), x), Err(InverseError::NonFinite));
        // K2 = −0.1: the parabola's vertex is at a = 5 g, E_max = K1·(K0 + 2.5); beyond it no root.
        k.nonlinearity_g_per_g2 = -0.1;
        assert_eq!(
            k.input(Volts(1.3267168 * 3.0), x),
            Err(InverseError::NoRealRoot)
        );
    }
}
