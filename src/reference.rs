//! Published reference data as values: the paper's printed order-2 temperature models of
//! JN-06 A12124 (Tables 2–5), and the board's nominal channel settings. One place, used by the
//! simulator's default instrument, the firmware examples and the tests.

use crate::compensation::{CoefficientModels, ThermalCompensator};
use crate::model::CrossAxis;
use crate::poly::{TempPoly, TemperatureScale};
use crate::rtd::CallendarVanDusen;
use crate::table::{
    AccelChannel, CalibrationDate, CalibrationTable, Orientation, RtdConfig, TiltAxis, TiltConfig,
};
use crate::units::{Celsius, Gs, Ohms, TiltArcsec, Volts, RAD_PER_ARCMIN};

/// Nominal values of the front-end board's channels: those of [`crate::board`], named here
/// for the tables built from them.
pub mod board {
    pub use crate::board::{
        RTD_PGA_GAIN, RTD_REFERENCE_OHMS, SENSE_RESISTOR_OHMS, TILT_SCALE_ARCSEC_PER_V,
    };
}

/// The calibrated range of Table 1, 30–65 °C, with its natural normalization.
pub const TABLE1_SCALE: TemperatureScale = TemperatureScale {
    min: Celsius(30.0),
    max: Celsius(65.0),
    center: Celsius(47.5),
    half_span_c: 17.5,
};

/// The paper's printed order-2 models (raw-°C monomials, as printed in Tables 2–5): K0, K1, K2
/// and δp (arcmin). δo is not in the paper.
pub const PAPER_ORDER2_MONOMIALS: [[f64; 3]; 4] = [
    [0.003554, 2.97e-5, 2.46e-7],
    [1.324489, 5.99e-5, -3.07e-7],
    [-1.06e-5, 2.89e-7, -1.1e-9],
    [4.30, -0.0716, 5.16e-4],
];

/// The paper's printed order-2 models as a compensator over 30–65 °C with T0 = `reference`.
pub fn paper_order2_models(reference: Celsius) -> ThermalCompensator {
    paper_order2_models_over(TABLE1_SCALE, reference)
}

/// The paper's printed order-2 models on `scale` (a simulator's instrument spans more than the
/// calibrated range, so that its coefficients are never clamped), δo = 0 (the paper prints
/// none).
pub fn paper_order2_models_over(scale: TemperatureScale, reference: Celsius) -> ThermalCompensator {
    // from_monomial_celsius only refuses more than five coefficients; three always convert.
    let mono = |m: &[f64; 3]| TempPoly::from_monomial_celsius(m, &scale).unwrap_or_default();
    let [k0, k1, k2, dp] = &PAPER_ORDER2_MONOMIALS;
    ThermalCompensator {
        scale,
        reference,
        models: CoefficientModels {
            bias_g: mono(k0),
            scale_factor_v_per_g: mono(k1),
            nonlinearity_g_per_g2: mono(k2),
            misalignment_p_rad: mono(dp).scaled(RAD_PER_ARCMIN),
            misalignment_o_rad: TempPoly::constant(0.0),
        },
    }
}

impl CalibrationTable {
    /// A table with the given identity and temperature models and the board's nominal channel
    /// settings: IEC 60751 Pt100 against 5.11 kΩ at PGA 16, 1 kΩ sense resistor, tiltmeter
    /// 10 "/V on the input axis with φ0 = 0, ideal ADC corrections, 1 g input, no cross-axis
    /// input.
    pub fn with_board_defaults(
        serial: &str,
        date: CalibrationDate,
        thermal: ThermalCompensator,
    ) -> Self {
        CalibrationTable {
            serial: CalibrationTable::serial_from_str(serial),
            date,
            thermal,
            tilt: TiltConfig {
                reference: TiltArcsec(0.0),
                scale_arcsec_per_v: board::TILT_SCALE_ARCSEC_PER_V,
                axis: TiltAxis::Input,
                adc_gain_correction: 1.0,
                adc_offset: Volts(0.0),
            },
            rtd: RtdConfig {
                cvd: CallendarVanDusen::IEC_60751_PT100,
                reference_resistor: Ohms(board::RTD_REFERENCE_OHMS),
                adc_gain_correction: 1.0,
                pga_gain: board::RTD_PGA_GAIN,
            },
            accel: AccelChannel {
                adc_gain_correction: 1.0,
                adc_offset: Volts(0.0),
                sense_resistor: Ohms(board::SENSE_RESISTOR_OHMS),
            },
            orientation: Orientation {
                cross: CrossAxis::default(),
                nominal_input: Gs(1.0),
            },
        }
    }
}

/// The paper's printed order-2 models in a table with the board defaults, T0 = 60 °C (the
/// paper's 41-day test temperature).
pub fn paper_order2_table() -> CalibrationTable {
    CalibrationTable::with_board_defaults(
        "JN-06 A12124",
        CalibrationDate {
            year: 2017,
            month: 4,
            day: 1,
        },
        paper_order2_models(Celsius(60.0)),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table1_scale_is_the_natural_scale_of_30_to_65_c() {
        assert_eq!(
            TemperatureScale::for_range(Celsius(30.0), Celsius(65.0)).unwrap(),
            TABLE1_SCALE
        );
    }

    #[test]
    fn paper_models_reproduce_the_printed_polynomials() {
        let c = paper_order2_models(Celsius(60.0));
        let x = TABLE1_SCALE.x_unclamped(Celsius(50.0));
        let bias = 0.003554 + 2.97e-5 * 50.0 + 2.46e-7 * 2500.0;
        assert!((c.models.bias_g.eval(x) - bias).abs() < 1e-15);
        let dp_rad = (4.30 - 0.0716 * 50.0 + 5.16e-4 * 2500.0) * core::f64::consts::PI / 10_800.0;
        assert!((c.models.misalignment_p_rad.eval(x) - dp_rad).abs() < 1e-15);
    }

    #[test]
    fn paper_table_is_accepted_by_the_validator() {
        let t = paper_order2_table();
        assert_eq!(CalibrationTable::decode(&t.encode()), Ok(t));
    }
}
