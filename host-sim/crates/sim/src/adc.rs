//! The board's converters: ADS1262 (32-bit ΔΣ, accelerometer output and tiltmeter) and AD7124-4
//! (24-bit, ratiometric Pt100), as they turn a physical input into a code.
//!
//! ADS1262: code = round((V + v_off + n)·G·(1 + ε_g) / V_ref(T_board) · 2³¹), with the reference
//! drifting with the board temperature, V_ref(T) = V_ref·(1 + α·(T − T_cal)), and n the
//! input-referred noise per sample. AD7124: code = round(R·G·(1 + ε_g) / R_ref · 2²⁴), the
//! reference resistor off its nominal value by ε_R. The board converts codes back with the
//! *nominal* scales (core `AdcScale`), exactly like the firmware, so every error above shows up
//! in the measured columns.

use accomp::adc::{AdcError, AdcScale};
use accomp::frontend::{ad7124_rtd_scale, ads1262_scale_with_vref};
use accomp::units::{Ohms, RtdOhms, Volts};
use serde::{Deserialize, Serialize};

use super::noise::{gauss, SimRng};

/// ADS1262 parameters (both inputs share the reference).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ads1262Params {
    /// Nominal reference, V.
    pub vref_v: f64,
    /// Reference temperature coefficient, ppm/°C of board temperature.
    pub vref_tempco_ppm_per_c: f64,
    /// Board temperature at which the reference is exactly nominal, °C.
    pub vref_calibrated_at_c: f64,
    /// PGA gain of the accelerometer input.
    pub accel_pga_gain: f64,
    /// PGA gain of the tiltmeter input.
    pub tilt_pga_gain: f64,
    /// Input-referred noise per sample, µV rms.
    pub noise_uv_rms: f64,
    /// Gain error, ppm.
    pub gain_error_ppm: f64,
    /// Input offset, µV.
    pub offset_uv: f64,
}

/// AD7124-4 parameters (RTD channel, ratiometric, unipolar).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ad7124Params {
    /// PGA gain.
    pub pga_gain: f64,
    /// Nominal reference resistor, Ω.
    pub reference_resistor_ohm: f64,
    /// Deviation of the actual reference resistor from nominal, ppm.
    pub reference_resistor_error_ppm: f64,
    /// Gain error, ppm.
    pub gain_error_ppm: f64,
}

/// Converters and the board they sit on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AdcParams {
    /// ADS1262.
    pub ads1262: Ads1262Params,
    /// AD7124-4.
    pub ad7124: Ad7124Params,
    /// Thermal time constant of the board following the room, minutes.
    pub board_lowpass_min: f64,
}

/// A voltage conversion: the code and what the board makes of it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VoltsConversion {
    /// Raw ADS1262 code (two's complement pattern).
    pub code: u32,
    /// Volts from the code with the nominal scale; `None` when the code is at a rail.
    pub volts: Option<Volts>,
}

/// A ratiometric conversion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OhmsConversion {
    /// Raw AD7124 code.
    pub code: u32,
    /// Ohms from the code with the nominal scale; `None` when the code is at a rail.
    pub ohms: Option<RtdOhms>,
}

/// The nominal ADS1262 scale the board converts with (the core's front-end scale, with the
/// scenario's reference voltage).
pub fn ads1262_nominal(p: &Ads1262Params, pga_gain: f64) -> AdcScale {
    ads1262_scale_with_vref(pga_gain, Volts(p.vref_v), 1.0, Volts(0.0))
}

/// The nominal AD7124 scale the board converts with (the core's ratiometric RTD scale).
pub fn ad7124_nominal(p: &Ad7124Params) -> AdcScale {
    ad7124_rtd_scale(p.pga_gain, 1.0)
}

/// Converts a voltage on an ADS1262 input at board temperature `board_c`.
pub fn ads1262_convert(
    p: &Ads1262Params,
    pga_gain: f64,
    v: Volts,
    board_c: f64,
    rng: &mut SimRng,
) -> Result<VoltsConversion, AdcError> {
    let vref =
        p.vref_v * (1.0 + p.vref_tempco_ppm_per_c * 1e-6 * (board_c - p.vref_calibrated_at_c));
    let actual = AdcScale {
        vref: Volts(vref),
        gain_correction: 1.0 / (1.0 + p.gain_error_ppm * 1e-6),
        offset: Volts(p.offset_uv * 1e-6),
        ..ads1262_nominal(p, pga_gain)
    };
    let noisy = Volts(v.0 + p.noise_uv_rms * 1e-6 * gauss(rng));
    let code = actual.code_for_volts(noisy)?;
    Ok(VoltsConversion {
        code,
        volts: ads1262_nominal(p, pga_gain).volts(code).ok(),
    })
}

/// Converts an RTD resistance on the AD7124 (noise is part of the RTD reading).
pub fn ad7124_convert(p: &Ad7124Params, r: RtdOhms) -> Result<OhmsConversion, AdcError> {
    let actual = AdcScale {
        gain_correction: 1.0 / (1.0 + p.gain_error_ppm * 1e-6),
        ..ad7124_nominal(p)
    };
    let r_ref = Ohms(p.reference_resistor_ohm * (1.0 + p.reference_resistor_error_ppm * 1e-6));
    let code = actual.code_for_ohms(r, r_ref)?;
    Ok(OhmsConversion {
        code,
        ohms: ad7124_nominal(p)
            .ratiometric_ohms(code, Ohms(p.reference_resistor_ohm))
            .ok(),
    })
}

#[cfg(test)]
mod tests {
    use super::super::noise::stream;
    use super::*;

    fn ads() -> Ads1262Params {
        Ads1262Params {
            vref_v: 2.5,
            vref_tempco_ppm_per_c: 2.0,
            vref_calibrated_at_c: 25.0,
            accel_pga_gain: 1.0,
            tilt_pga_gain: 8.0,
            noise_uv_rms: 0.0,
            gain_error_ppm: 0.0,
            offset_uv: 0.0,
        }
    }

    #[test]
    fn a_warmer_reference_reads_low_by_its_tempco() {
        let p = ads();
        let mut rng = stream(1, 7);
        let at_cal = ads1262_convert(&p, 1.0, Volts(1.3), 25.0, &mut rng).unwrap();
        let warm = ads1262_convert(&p, 1.0, Volts(1.3), 30.0, &mut rng).unwrap();
        // Quantization: 1 LSB = 1.16 nV. At 25 °C the reading is the input to within ½ LSB.
        assert!((at_cal.volts.unwrap().0 - 1.3).abs() < 0.6e-9);
        // +5 °C at 2 ppm/°C: V_ref 10 ppm high, so the reading is 10 ppm low (1.3 V → −13 µV).
        let rel = warm.volts.unwrap().0 / 1.3 - 1.0;
        assert!((rel + 10e-6 / (1.0 + 10e-6)).abs() < 1e-9, "{rel:e}");
    }

    #[test]
    fn the_rtd_code_reads_back_to_the_resistance_within_one_lsb() {
        let p = Ad7124Params {
            pga_gain: 16.0,
            reference_resistor_ohm: 5110.0,
            reference_resistor_error_ppm: 0.0,
            gain_error_ppm: 0.0,
        };
        let lsb = 5110.0 / 16.0 / 16_777_216.0;
        let c = ad7124_convert(&p, RtdOhms(123.24)).unwrap();
        assert!((c.ohms.unwrap().0 - 123.24).abs() <= 0.5 * lsb + 1e-12);
        // A reference resistor 100 ppm high makes the same RTD read 100 ppm low.
        let hi = ad7124_convert(
            &Ad7124Params {
                reference_resistor_error_ppm: 100.0,
                ..p
            },
            RtdOhms(123.24),
        )
        .unwrap();
        assert!((hi.ohms.unwrap().0 / 123.24 - 1.0 + 100e-6).abs() < 1e-7);
    }
}
