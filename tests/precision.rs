//! Precision property: the exact compensated a_i agrees with an f64 reference to ≤ 1e-9 g over
//! the whole calibrated range and |a_i| ≤ 1.5 g, for randomized JN-06-like models.
//!
//! The reference is written independently of the core: coefficients by explicit powers, the
//! forward equation (1) by hand, and a_i as the value the output was generated from.

use accomp::compensation::{CoefficientModels, ThermalCompensator};
use accomp::model::CrossAxis;
use accomp::poly::{TempPoly, TemperatureScale};
use accomp::units::{Celsius, Gs, Volts};
use proptest::prelude::*;

const BUDGET_G: f64 = 1e-9;

fn poly(c: [f64; 5]) -> TempPoly {
    TempPoly { coeffs: c }
}

/// Σ c_k·x^k with powi, not Horner: a different evaluation order from the core.
fn reference_eval(c: &[f64; 5], x: f64) -> f64 {
    c.iter()
        .enumerate()
        .map(|(k, ck)| ck * x.powi(k as i32))
        .sum()
}

prop_compose! {
    /// Models around JN-06 A12124 (Table 1 magnitudes), every coefficient order 4, with K2
    /// anywhere from −1e-4 to 1e-4 g/g² including exactly zero.
    fn models()(
        k0 in prop::array::uniform5(-1e-3..1e-3f64),
        k1 in prop::array::uniform5(-1e-3..1e-3f64),
        k2 in prop_oneof![Just([0.0; 5]), prop::array::uniform5(-2e-5..2e-5f64)],
        dp in prop::array::uniform5(-1e-3..1e-3f64),
        dq in prop::array::uniform5(-1e-3..1e-3f64),
        k0_base in 0.0..0.01f64,
        k1_base in 0.5..2.0f64,
    ) -> [[f64; 5]; 5] {
        let mut k0 = k0; k0[0] += k0_base;
        let mut k1 = k1; k1[0] += k1_base;
        [k0, k1, k2, dp, dq]
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 20_000, ..ProptestConfig::default() })]

    #[test]
    fn exact_a_i_agrees_with_an_f64_reference_within_1e_9_g(
        m in models(),
        t_frac in 0.0..=1.0f64,
        a_i in -1.5..=1.5f64,
        a_p in -1.0..=1.0f64,
        a_o in -1.0..=1.0f64,
        lo in 20.0..40.0f64,
        span in 5.0..60.0f64,
    ) {
        let scale = TemperatureScale::for_range(Celsius(lo), Celsius(lo + span)).unwrap();
        let comp = ThermalCompensator {
            scale,
            reference: Celsius(lo + 0.5 * span),
            models: CoefficientModels {
                bias_g: poly(m[0]),
                scale_factor_v_per_g: poly(m[1]),
                nonlinearity_g_per_g2: poly(m[2]),
                misalignment_p_rad: poly(m[3]),
                misalignment_o_rad: poly(m[4]),
            },
        };
        let t = lo + t_frac * span;
        let x = (t - (lo + 0.5 * span)) / (0.5 * span);
        let [k0, k1, k2, dp, d_o] = m.map(|c| reference_eval(&c, x));
        let e = k1 * (k0 + a_i + k2 * a_i * a_i + d_o * a_p - dp * a_o);
        let cross = CrossAxis { a_p: Gs(a_p), a_o: Gs(a_o) };
        let got = comp.exact(Volts(e), Celsius(t), cross).unwrap();
        prop_assert!((got.input.0 - a_i).abs() <= BUDGET_G,
            "a_i={a_i} got={} err={:e}", got.input.0, got.input.0 - a_i);
    }
}
