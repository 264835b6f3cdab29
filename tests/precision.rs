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

/// K0, K1, K2, δp, δo from their coefficient rows.
fn coefficient_models(m: &[[f64; 5]; 5]) -> CoefficientModels {
    CoefficientModels {
        bias_g: poly(m[0]),
        scale_factor_v_per_g: poly(m[1]),
        nonlinearity_g_per_g2: poly(m[2]),
        misalignment_p_rad: poly(m[3]),
        misalignment_o_rad: poly(m[4]),
    }
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

/// Where in the calibrated range a sample is taken and what the accelerometer feels.
#[derive(Debug, Clone, Copy)]
struct Sample {
    /// Position in the range, 0 at its low end, 1 at its high end.
    t_frac: f64,
    a_i: f64,
    a_p: f64,
    a_o: f64,
    tilt_arcsec: f64,
    /// Low end of the calibrated range, °C.
    lo: f64,
    /// Width of the calibrated range, °C.
    span: f64,
}

impl Sample {
    /// The temperature, °C.
    fn t(&self) -> f64 {
        self.lo + self.t_frac * self.span
    }

    /// The output eq. (1) gives for models `m` (coefficients in x = (T − Tc)/Ts), V.
    fn output_v(&self, m: &[[f64; 5]; 5]) -> f64 {
        let x = (self.t() - (self.lo + 0.5 * self.span)) / (0.5 * self.span);
        let [k0, k1, k2, dp, d_o] = m.map(|c| reference_eval(&c, x));
        let a_i = self.a_i;
        k1 * (k0 + a_i + k2 * a_i * a_i + d_o * self.a_p - dp * self.a_o)
    }
}

prop_compose! {
    /// Samples anywhere in a range of width `spans` starting at 20..40 °C, |a_i| ≤ 1.5 g, cross
    /// accelerations up to 1 g, tilt up to ±60".
    fn samples(spans: std::ops::Range<f64>)(
        t_frac in 0.0..=1.0f64,
        a_i in -1.5..=1.5f64,
        a_p in -1.0..=1.0f64,
        a_o in -1.0..=1.0f64,
        tilt_arcsec in -60.0..60.0f64,
        lo in 20.0..40.0f64,
        span in spans,
    ) -> Sample {
        Sample { t_frac, a_i, a_p, a_o, tilt_arcsec, lo, span }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 20_000, ..ProptestConfig::default() })]

    #[test]
    fn exact_a_i_agrees_with_an_f64_reference_within_1e_9_g(
        m in models(),
        s in samples(5.0..60.0),
    ) {
        let Sample { a_i, a_p, a_o, lo, span, .. } = s;
        let scale = TemperatureScale::for_range(Celsius(lo), Celsius(lo + span)).unwrap();
        let comp = ThermalCompensator {
            scale,
            reference: Celsius(lo + 0.5 * span),
            models: coefficient_models(&m),
        };
        let cross = CrossAxis { a_p: Gs(a_p), a_o: Gs(a_o) };
        let got = comp.exact(Volts(s.output_v(&m)), Celsius(s.t()), cross).unwrap();
        prop_assert!((got.input.0 - a_i).abs() <= BUDGET_G,
            "a_i={a_i} got={} err={:e}", got.input.0, got.input.0 - a_i);
    }
}

// ---------------------------------------------------------------------------------------------
// The path the firmware runs: raw codes → pipeline::process_prepared (PreparedCalibration, mixed
// precision) against an f64 reference written here from the physics.

mod firmware_path {
    use super::*;
    use accomp::pipeline::{process_prepared, RawSample, Status};
    use accomp::prepared::{Precision, PreparedCalibration, BUDGET_LINEARIZED_V};
    use accomp::rtd::CallendarVanDusen;
    use accomp::table::{
        AccelChannel, CalibrationDate, CalibrationTable, Orientation, RtdConfig, TiltAxis,
        TiltConfig,
    };
    use accomp::units::{Ohms, TiltArcsec, RAD_PER_ARCSEC};

    /// Reference CVD inverse for T ≥ 0 °C: the textbook quadratic root in f64.
    fn reference_temperature(cvd: &CallendarVanDusen, ohms: f64) -> f64 {
        let q = ohms / cvd.r0 - 1.0;
        (-cvd.a + (cvd.a * cvd.a + 4.0 * cvd.b * q).sqrt()) / (2.0 * cvd.b)
    }

    /// Reference: tilt-corrected E, then a_i from equation (1) by Newton's method, and the paper's linearized ΔE with derivatives by explicit powers.
    struct Reference {
        a_i: f64,
        linearized: f64,
    }

    fn reference(table: &CalibrationTable, e: f64, t: f64, tilt_arcsec: f64) -> Reference {
        let th = &table.thermal;
        let (lo, hi) = (th.scale.min.0, th.scale.max.0);
        let t = t.clamp(lo, hi);
        let x_of = |t: f64| (t - th.scale.center.0) / th.scale.half_span_c;
        let m = &th.models;
        let polys = [
            m.bias_g.coeffs,
            m.scale_factor_v_per_g.coeffs,
            m.nonlinearity_g_per_g2.coeffs,
            m.misalignment_p_rad.coeffs,
            m.misalignment_o_rad.coeffs,
        ];
        let x = x_of(t);
        let [k0, k1, k2, dp, d_o] = polys.map(|c| reference_eval(&c, x));
        let (a_p, a_o) = (table.orientation.cross.a_p.0, table.orientation.cross.a_o.0);
        let sign = match table.tilt.axis {
            TiltAxis::Input => 1.0,
            TiltAxis::InputReversed => -1.0,
            TiltAxis::None => 0.0,
        };
        let phi = (tilt_arcsec - table.tilt.reference.0) * RAD_PER_ARCSEC;
        let e = e - sign * k1 * phi.sin();
        let c = k0 + d_o * a_p - dp * a_o - e / k1;
        // Newton on K2·a² + a + c = 0 from −c (the textbook root formula loses eps/K2).
        let mut a_i = -c;
        for _ in 0..6 {
            a_i -= (k2 * a_i * a_i + a_i + c) / (2.0 * k2 * a_i + 1.0);
        }
        // d/dT of Σ c_k x^k = Σ k c_k x^(k−1) / Ts, at T0.
        let x0 = x_of(th.reference.0);
        let d = |c: &[f64; 5]| {
            (1..5)
                .map(|k| k as f64 * c[k] * x0.powi(k as i32 - 1))
                .sum::<f64>()
                / th.scale.half_span_c
        };
        let [s_k0, s_k1, s_k2, s_dp, s_do] = polys.map(|c| d(&c));
        let [k0_0, k1_0, ..] = polys.map(|c| reference_eval(&c, x0));
        let dt = t - th.reference.0;
        let a_est = e / k1_0 - k0_0;
        let delta_e = e * s_k1 * dt / k1_0
            + k1_0 * (s_k0 * dt + s_k2 * dt * a_est * a_est + s_do * dt * a_p - s_dp * dt * a_o);
        Reference {
            a_i,
            linearized: e - delta_e,
        }
    }

    fn table(m: [[f64; 5]; 5], lo: f64, span: f64, a_p: f64, a_o: f64) -> CalibrationTable {
        let scale = TemperatureScale::for_range(Celsius(lo), Celsius(lo + span)).unwrap();
        CalibrationTable {
            serial: CalibrationTable::serial_from_str("PROPTEST"),
            date: CalibrationDate {
                year: 2026,
                month: 1,
                day: 1,
            },
            thermal: ThermalCompensator {
                scale,
                reference: Celsius(lo + 0.7 * span),
                models: coefficient_models(&m),
            },
            tilt: TiltConfig {
                reference: TiltArcsec(1.5),
                scale_arcsec_per_v: 20.0,
                axis: TiltAxis::Input,
                adc_gain_correction: 1.0003,
                adc_offset: Volts(2e-5),
            },
            rtd: RtdConfig {
                cvd: CallendarVanDusen::IEC_60751_PT100,
                reference_resistor: Ohms(5110.0),
                adc_gain_correction: 0.9998,
                pga_gain: 16.0,
            },
            accel: AccelChannel {
                adc_gain_correction: 1.0001,
                adc_offset: Volts(-3e-6),
                sense_resistor: Ohms(1000.0),
            },
            orientation: Orientation {
                cross: CrossAxis {
                    a_p: Gs(a_p),
                    a_o: Gs(a_o),
                },
                nominal_input: Gs(1.0),
            },
        }
    }

    prop_compose! {
        /// Fitted JN-06-like models: first-order temperature terms as in the paper (bias
        /// ≈ 1e-3 g, K1 ≈ 5e-4 relative over the range), x² terms up to 1e-4 (the paper's are
        /// 7.5e-5 g and 9.4e-5 V/g), x³ and x⁴ up to 3e-5.
        fn realistic()(
            k0 in prop::array::uniform5(-3e-5..3e-5f64),
            k1 in prop::array::uniform5(-3e-5..3e-5f64),
            k0_curv in -1e-4..1e-4f64,
            k1_curv in -1e-4..1e-4f64,
            k2 in prop_oneof![Just([0.0; 5]), prop::array::uniform5(-4e-6..4e-6f64)],
            dp in prop::array::uniform5(-2e-5..2e-5f64),
            dq in prop::array::uniform5(-2e-5..2e-5f64),
            k0_lin in -1e-3..1e-3f64,
            k1_lin in -7e-4..7e-4f64,
            k0_base in 0.0..0.01f64,
            k1_base in 0.8..1.6f64,
            dp_base in -2e-3..2e-3f64,
        ) -> [[f64; 5]; 5] {
            let (mut k0, mut k1, mut dp) = (k0, k1, dp);
            k0[0] = k0_base; k0[1] = k0_lin; k0[2] = k0_curv;
            k1[0] = k1_base; k1[1] = k1_lin; k1[2] = k1_curv;
            dp[0] = dp_base;
            [k0, k1, k2, dp, dq]
        }
    }

    /// Runs one sample through the firmware path and checks it against the reference.
    fn check(m: [[f64; 5]; 5], s: Sample, expect_mixed: bool) -> Result<(), TestCaseError> {
        let table = table(m, s.lo, s.span, s.a_p, s.a_o);
        let prepared = PreparedCalibration::new(&table).unwrap();
        if expect_mixed {
            prop_assert_eq!(
                prepared.precision(),
                Precision::Mixed,
                "{:?}",
                prepared.error_bounds()
            );
        }
        // Codes for a sample near a_i (the reference works from what the codes say).
        let (e, t, tilt) = (
            Volts(s.output_v(&m)),
            Celsius(s.t()),
            TiltArcsec(s.tilt_arcsec),
        );
        // Outputs beyond the ADC's ±2.5 V cannot be measured: not a case for this property.
        let Ok(raw) = accomp::pipeline::raw_from_physical(&table, e, t, tilt) else {
            return Ok(());
        };
        let f = process_prepared(0, 0, &raw, Some(&prepared));
        // Only the range flag may be set: at the range ends the RTD quantization can fall outside.
        prop_assert_eq!(f.status.0 & !Status::TEMP_OUT_OF_RANGE, 0);

        // Physical inputs from the codes, f64 from the ADC definitions.
        let accel = accomp::board::accel_scale(Some(&table));
        let e_ref = accel.volts(raw.accel as u32).unwrap().0;
        prop_assert!(
            (f.output_v - e_ref).abs() <= 1e-15,
            "E {} vs {}",
            f.output_v,
            e_ref
        );
        let ohms_ref = accomp::board::rtd_scale(&table)
            .ratiometric_ohms(raw.rtd, table.rtd.reference_resistor)
            .unwrap()
            .0;
        prop_assert!((f.rtd_ohms - ohms_ref).abs() <= 1e-12);
        let t_ref = reference_temperature(&table.rtd.cvd, ohms_ref);
        prop_assert!(
            (f.temperature_c - t_ref).abs() <= 1e-6,
            "T {} vs {} ({:e})",
            f.temperature_c,
            t_ref,
            f.temperature_c - t_ref
        );
        let tilt_ref = accomp::board::tilt_scale(&table)
            .volts(raw.tilt as u32)
            .unwrap()
            .0
            * table.tilt.scale_arcsec_per_v;
        prop_assert!((f.tilt_arcsec - tilt_ref).abs() <= 1e-6 * tilt_ref.abs().max(1.0));

        let r = reference(&table, e_ref, t_ref, tilt_ref);
        prop_assert!(
            (f.a_i_exact_g - r.a_i).abs() <= BUDGET_G,
            "a_i {} vs {} err {:e}",
            f.a_i_exact_g,
            r.a_i,
            f.a_i_exact_g - r.a_i
        );
        prop_assert!(
            (f.output_linearized_v - r.linearized).abs() <= BUDGET_LINEARIZED_V,
            "lin {} vs {} err {:e}",
            f.output_linearized_v,
            r.linearized,
            f.output_linearized_v - r.linearized
        );
        Ok(())
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 20_000, ..ProptestConfig::default() })]

        /// Realistic tables take the mixed-precision path and stay within 1e-9 g (and 3e-9 V for
        /// the linearized output) of the f64 reference, tilt up to ±60".
        #[test]
        fn firmware_path_agrees_with_an_f64_reference_within_1e_9_g(
            m in realistic(),
            s in samples(20.0..45.0),
        ) {
            check(m, s, true)?;
        }

        /// Tables with large curvature terms fall back to f64 and stay within budget too.
        #[test]
        fn firmware_path_with_large_curvature_stays_within_1e_9_g(
            m in models(),
            s in samples(5.0..45.0),
        ) {
            prop_assume!(m[1][0] - m[1][1..].iter().map(|c| c.abs()).sum::<f64>() > 0.01);
            check(m, s, false)?;
        }
    }

    #[test]
    fn the_papers_table_takes_the_mixed_precision_path() {
        let scale = TemperatureScale::for_range(Celsius(30.0), Celsius(65.0)).unwrap();
        let mono = |m: &[f64]| TempPoly::from_monomial_celsius(m, &scale).unwrap();
        let mut t = table([[0.0; 5]; 5], 30.0, 35.0, 0.0, 0.0);
        t.thermal.models = CoefficientModels {
            bias_g: mono(&[0.003554, 2.97e-5, 2.46e-7]),
            scale_factor_v_per_g: mono(&[1.324489, 5.99e-5, -3.07e-7]),
            nonlinearity_g_per_g2: mono(&[-1.06e-5, 2.89e-7, -1.1e-9]),
            misalignment_p_rad: mono(&[4.30, -0.0716, 5.16e-4])
                .scaled(accomp::units::RAD_PER_ARCMIN),
            misalignment_o_rad: TempPoly::constant(0.0),
        };
        let p = PreparedCalibration::new(&t).unwrap();
        assert_eq!(p.precision(), Precision::Mixed);
        let b = p.error_bounds();
        assert!(
            b.a_i_g < 1e-9 && b.linearized_v < BUDGET_LINEARIZED_V,
            "{b:?}"
        );
        // And a code at the rail is still refused, not computed.
        let raw = RawSample {
            accel: i32::MAX,
            ..accomp::pipeline::raw_from_physical(&t, Volts(1.0), Celsius(50.0), TiltArcsec(0.0))
                .unwrap()
        };
        let f = process_prepared(0, 0, &raw, Some(&p));
        assert!(f.status.has(Status::ADC_SATURATED) && f.a_i_exact_g.is_nan());
    }
}
