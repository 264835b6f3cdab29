//! The analog front-end board in one place: references, PGA gains, resistors, full scales, and
//! the conversions between physical values and ADC codes (docs/drivers.md, "Front-end").
//!
//! Every user reads the board from here: the per-sample pipeline and the prepared calibration
//! (code → value), the host's injection and the simulator's converters (value → code), the
//! reference tables' nominal channel settings and the drivers' scales. A value that differs
//! between two of them is a bug this module exists to rule out.
//!
//! **The ADS1262's PGA is enabled, at gain 1, on both channels** (the driver's
//! `Ads1262Config::board_default`, MODE2 BYPASS = 0). An older comment said "bypassed"; the
//! driver is what runs, and enabled is what the board needs: the PGA's high input impedance keeps
//! the source resistance of the inputs (the accelerometer's sense resistor, the tiltmeter's
//! output stage) from loading the modulator's switched-capacitor input, which in bypass would
//! draw input current through them and turn it into a gain error. At gain 1 the PGA's
//! absolute-input headroom (a few hundred mV inside the supplies) still takes E ≈ 1.33 V/g ×
//! 1.5 g ≈ 2 V. The maths only sees the gain, 1 either way, so no result depended on the
//! contradiction; `tests::the_drivers_board_settings_are_the_front_end_constants` now pins it.

use crate::adc::{Ad7124Code, AdcError, AdcScale, Ads1262Code};
use crate::drivers::{ad7124, ads1262};
use crate::table::CalibrationTable;
use crate::units::{Celsius, Ohms, RtdOhms, TiltArcsec, Volts};

/// ADS1262 reference: the internal 2.5 V reference.
pub const ADS1262_VREF: Volts = Volts(2.5);
/// ADS1262 result width (ADC1, 32-bit two's complement).
pub const ADS1262_BITS: u8 = ads1262::CODE_BITS;
/// Full-scale magnitude of the ADS1262 code, 2^31: ±Vref/gain ↔ ±2^31.
pub const ADS1262_HALF_SCALE: f64 = 2_147_483_648.0;
/// ADS1262 PGA gain of the accelerometer channel (PGA enabled; see the module text).
pub const ACCEL_PGA_GAIN: f64 = 1.0;
/// ADS1262 PGA gain of the tiltmeter channel (PGA enabled; volts-level output as well).
pub const TILT_PGA_GAIN: f64 = 1.0;

/// AD7124-4 result width (24-bit, unipolar on the RTD channel).
pub const AD7124_BITS: u8 = ad7124::CODE_BITS;
/// Full scale of the unipolar AD7124 code, 2^24: R_ref/gain ↔ 2^24.
pub const AD7124_FULL_SCALE: f64 = 16_777_216.0;
/// Largest AD7124 code (all ones): reads as saturated (an open RTD).
pub const AD7124_MAX_CODE: u32 = 0x00FF_FFFF;
/// AD7124 PGA gain of the RTD channel (nominal; a table carries its own).
pub const RTD_PGA_GAIN: f64 = 16.0;
/// Reference resistor of the ratiometric RTD measurement, Ω (nominal; a table carries its own).
pub const RTD_REFERENCE_OHMS: f64 = 5110.0;
/// Sense resistor of the torquer current, Ω.
pub const SENSE_RESISTOR_OHMS: f64 = 1000.0;
/// Tiltmeter sensitivity, arcsec per volt (nominal; a table carries its own).
pub const TILT_SCALE_ARCSEC_PER_V: f64 = 10.0;

/// How an ADS1262 channel's codes read: 32-bit two's complement, the internal reference, the
/// channel's PGA gain and the calibration's gain correction and offset.
pub fn ads1262_scale(pga_gain: f64, gain_correction: f64, offset: Volts) -> AdcScale {
    ads1262_scale_with_vref(pga_gain, ADS1262_VREF, gain_correction, offset)
}

/// [`ads1262_scale`] with another reference voltage (the simulator's drifting reference, a
/// driver configured for an external one).
pub fn ads1262_scale_with_vref(
    pga_gain: f64,
    vref: Volts,
    gain_correction: f64,
    offset: Volts,
) -> AdcScale {
    ads1262::code_scale(pga_gain, vref, gain_correction, offset)
}

/// How AD7124 codes read: 24 bits, unipolar or offset binary (bipolar), the PGA gain, the
/// reference voltage (for volt readings) and the gain correction.
pub fn ad7124_scale(bipolar: bool, pga_gain: f64, vref: Volts, gain_correction: f64) -> AdcScale {
    ad7124::code_scale(bipolar, pga_gain, vref, gain_correction)
}

/// How the AD7124's ratiometric RTD codes read: unipolar, the PGA gain and the gain correction.
/// The reference voltage cancels in a ratiometric reading; 1 V stands for it.
pub fn ad7124_rtd_scale(pga_gain: f64, gain_correction: f64) -> AdcScale {
    ad7124_scale(false, pga_gain, Volts(1.0), gain_correction)
}

/// The accelerometer channel, with the table's correction when there is one.
pub fn accel_scale(table: Option<&CalibrationTable>) -> AdcScale {
    let (gain_correction, offset) = match table {
        Some(t) => (t.accel.adc_gain_correction, t.accel.adc_offset),
        None => (1.0, Volts(0.0)),
    };
    ads1262_scale(ACCEL_PGA_GAIN, gain_correction, offset)
}

/// The tiltmeter channel with the table's correction.
pub fn tilt_scale(table: &CalibrationTable) -> AdcScale {
    ads1262_scale(
        TILT_PGA_GAIN,
        table.tilt.adc_gain_correction,
        table.tilt.adc_offset,
    )
}

/// The RTD channel with the table's gain and correction.
pub fn rtd_scale(table: &CalibrationTable) -> AdcScale {
    ad7124_rtd_scale(table.rtd.pga_gain, table.rtd.adc_gain_correction)
}

/// The code a measurable value gives: [`AdcScale`]'s inverse, refusing what the converter cannot
/// represent. `Err(Saturated)` when the code would be a rail (the chip would report an
/// over-range; the forward conversion reads rails as saturated), `Err(NonFiniteInput)` for NaN
/// or ±∞, `Err(InvalidScale)` for an unusable scale.
fn measurable(scale: &AdcScale, code: Result<u32, AdcError>) -> Result<u32, AdcError> {
    let code = code?;
    match scale.fraction(code) {
        Ok(_) => Ok(code),
        Err(e) => Err(e),
    }
}

/// Volts at an ADS1262 input → code.
pub fn volts_to_ads1262(scale: &AdcScale, v: Volts) -> Result<Ads1262Code, AdcError> {
    measurable(scale, scale.code_for_volts(v)).map(|c| Ads1262Code(c as i32))
}

/// RTD ohms → AD7124 ratiometric code (the reference resistor sets full scale).
pub fn ohms_to_ad7124(
    scale: &AdcScale,
    r: RtdOhms,
    reference: Ohms,
) -> Result<Ad7124Code, AdcError> {
    measurable(scale, scale.code_for_ohms(r, reference)).map(Ad7124Code)
}

/// Temperature → RTD ohms → AD7124 code with the table's RTD constants.
pub fn celsius_to_ad7124(table: &CalibrationTable, t: Celsius) -> Result<Ad7124Code, AdcError> {
    if !t.0.is_finite() {
        return Err(AdcError::NonFiniteInput);
    }
    let r = table.rtd.cvd.resistance(t);
    ohms_to_ad7124(&rtd_scale(table), r, table.rtd.reference_resistor)
}

/// Tilt → tiltmeter volts → ADS1262 code with the table's tilt scale.
pub fn arcsec_to_ads1262(
    table: &CalibrationTable,
    tilt: TiltArcsec,
) -> Result<Ads1262Code, AdcError> {
    volts_to_ads1262(
        &tilt_scale(table),
        Volts(tilt.0 / table.tilt.scale_arcsec_per_v),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::drivers::ad7124::Ad7124Config;
    use crate::drivers::ads1262::{Ads1262Config, Channel, Pga};

    #[test]
    fn the_drivers_board_settings_are_the_front_end_constants() {
        let ads = Ads1262Config::board_default();
        // Enabled, not bypassed, at the gains the maths uses.
        assert!(matches!(ads.channels.accelerometer.pga, Pga::Enabled(_)));
        assert!(matches!(ads.channels.tiltmeter.pga, Pga::Enabled(_)));
        let accel = ads.scale(Channel::Accelerometer, ADS1262_VREF);
        assert_eq!(accel, accel_scale(None));
        let tilt = ads.scale(Channel::Tiltmeter, ADS1262_VREF);
        assert_eq!(tilt, ads1262_scale(TILT_PGA_GAIN, 1.0, Volts(0.0)));
        let rtd = Ad7124Config::board_default().scale(Volts(1.0));
        assert_eq!(rtd, ad7124_rtd_scale(RTD_PGA_GAIN, 1.0));
    }

    #[test]
    fn values_beyond_full_scale_are_refused_as_saturated_and_nan_as_non_finite() {
        let s = accel_scale(None);
        let lsb = 2.5 / ADS1262_HALF_SCALE;
        assert_eq!(volts_to_ads1262(&s, Volts(2.6)), Err(AdcError::Saturated));
        assert_eq!(volts_to_ads1262(&s, Volts(-2.5)), Err(AdcError::Saturated));
        assert_eq!(
            volts_to_ads1262(&s, Volts(2.5 - 2.0 * lsb)),
            Ok(Ads1262Code(i32::MAX - 1))
        );
        assert_eq!(
            volts_to_ads1262(&s, Volts(f64::NAN)),
            Err(AdcError::NonFiniteInput)
        );
        let r = ad7124_rtd_scale(RTD_PGA_GAIN, 1.0);
        let full = RtdOhms(RTD_REFERENCE_OHMS / RTD_PGA_GAIN);
        assert_eq!(
            ohms_to_ad7124(&r, full, Ohms(RTD_REFERENCE_OHMS)),
            Err(AdcError::Saturated)
        );
        assert_eq!(
            ohms_to_ad7124(&r, RtdOhms(0.0), Ohms(RTD_REFERENCE_OHMS)),
            Ok(Ad7124Code(0))
        );
    }
}
