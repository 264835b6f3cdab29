//! ADC codes and their conversion to volts and ratios: where drivers and maths meet in types.
//!
//! The drivers return these code newtypes exactly as the chips deliver them; converting to
//! physical units needs the reference and gain, carried in [`AdcScale`].

use crate::units::{Ohms, RtdOhms, Volts};

/// A 32-bit two's-complement conversion result of the ADS1262 (ADC1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ads1262Code(pub i32);

/// A 24-bit conversion result of the AD7124-4, right-aligned in a `u32` (bits 31..24 are zero).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ad7124Code(pub u32);

/// Coding of a conversion result.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Coding {
    /// Two's complement, full scale ±Vref/gain (ADS1262).
    TwosComplement,
    /// Offset binary: 0 ↔ −Vref/gain, 2^(N−1) ↔ 0 V, 2^N − 1 ↔ +Vref/gain (AD7124 bipolar).
    OffsetBinary,
    /// Straight binary: 0 ↔ 0 V, 2^N − 1 ↔ +Vref/gain (AD7124 unipolar).
    Unipolar,
}

/// How a code maps to volts: resolution, coding, PGA gain and reference voltage, plus a
/// calibration correction (gain factor and offset in volts) from the calibration table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdcScale {
    /// Number of bits of the result (32 for the ADS1262, 24 for the AD7124).
    pub bits: u8,
    /// Coding of the result.
    pub coding: Coding,
    /// Programmable gain (1, 2, 4, … 128).
    pub pga_gain: f64,
    /// Reference voltage in volts.
    pub vref: Volts,
    /// Multiplicative correction of the conversion (1.0 = ideal).
    pub gain_correction: f64,
    /// Offset in volts subtracted after scaling (0.0 = ideal).
    pub offset: Volts,
}

/// Conversion failures that must never turn into a number.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AdcError {
    /// The code sits at the positive or negative full-scale limit: the input is saturated.
    Saturated,
    /// The code has bits set above the converter's resolution.
    OutOfRange,
    /// The scale is not usable (zero/negative gain or reference, bits not in 8..=32).
    InvalidScale,
    /// The input to an inverse conversion (volts or ohms → code) is NaN or infinite.
    NonFiniteInput,
}

impl AdcScale {
    fn check(&self) -> Result<(), AdcError> {
        let ok = (8..=32).contains(&self.bits)
            && self.pga_gain.is_finite()
            && self.pga_gain > 0.0
            && self.vref.0.is_finite()
            && self.vref.0 > 0.0
            && self.gain_correction.is_finite()
            && self.gain_correction > 0.0
            && self.offset.0.is_finite();
        if ok {
            Ok(())
        } else {
            Err(AdcError::InvalidScale)
        }
    }

    /// Signed fraction of full scale in [−1, 1) for a raw code of `self.bits` bits, or an error
    /// when the code is at a rail (saturated) or wider than the converter.
    pub fn fraction(&self, raw: u32) -> Result<f64, AdcError> {
        self.check()?;
        let bits = u32::from(self.bits);
        let max: u64 = (1u64 << bits) - 1;
        if u64::from(raw) > max {
            return Err(AdcError::OutOfRange);
        }
        let half = (1u64 << (bits - 1)) as f64;
        let (value, full_scale, at_rail) = match self.coding {
            Coding::TwosComplement => {
                // Sign-extend from `bits`.
                let shift = 64 - bits;
                let signed = ((u64::from(raw) << shift) as i64) >> shift;
                let at_rail = signed == (half as i64) - 1 || signed == -(half as i64);
                (signed as f64, half, at_rail)
            }
            Coding::OffsetBinary => {
                let v = u64::from(raw) as f64 - half;
                (v, half, u64::from(raw) == 0 || u64::from(raw) == max)
            }
            Coding::Unipolar => (
                u64::from(raw) as f64,
                (max + 1) as f64,
                u64::from(raw) == max,
            ),
        };
        if at_rail {
            return Err(AdcError::Saturated);
        }
        Ok(value / full_scale)
    }

    /// Input voltage at the ADC pins for a raw code.
    pub fn volts(&self, raw: u32) -> Result<Volts, AdcError> {
        let f = self.fraction(raw)?;
        Ok(Volts(
            f * self.vref.0 / self.pga_gain * self.gain_correction - self.offset.0,
        ))
    }

    /// Ratiometric resistance: the RTD and the reference resistor carry the same excitation
    /// current, and the reference resistor's voltage is the ADC reference, so
    /// R_rtd = R_ref · fraction / gain, independent of the current and of Vref.
    pub fn ratiometric_ohms(&self, raw: u32, reference: Ohms) -> Result<RtdOhms, AdcError> {
        let f = self.fraction(raw)?;
        if !(reference.0.is_finite() && reference.0 > 0.0) {
            return Err(AdcError::InvalidScale);
        }
        Ok(RtdOhms(
            reference.0 * f / self.pga_gain * self.gain_correction,
        ))
    }
}

impl AdcScale {
    /// The inverse of [`AdcScale::fraction`]: the code a converter of this scale outputs for a
    /// signed fraction of full scale, rounded to the nearest code. Like the chip, an input beyond
    /// full scale gives the rail code (which the forward conversion then reports as saturated).
    pub fn code_for_fraction(&self, fraction: f64) -> Result<u32, AdcError> {
        self.check()?;
        if !fraction.is_finite() {
            return Err(AdcError::NonFiniteInput);
        }
        let bits = u32::from(self.bits);
        let half = (1u64 << (bits - 1)) as f64;
        let max = ((1u64 << bits) - 1) as f64;
        let code = match self.coding {
            Coding::TwosComplement => {
                let signed = libm::round(fraction * half).clamp(-half, half - 1.0) as i64;
                // Two's complement pattern truncated to `bits`.
                (signed as u64 & ((1u64 << bits) - 1)) as u32
            }
            Coding::OffsetBinary => libm::round(fraction * half + half).clamp(0.0, max) as u32,
            Coding::Unipolar => libm::round(fraction * (max + 1.0)).clamp(0.0, max) as u32,
        };
        Ok(code)
    }

    /// The inverse of [`AdcScale::volts`]: the code for an input voltage at the ADC pins.
    pub fn code_for_volts(&self, v: Volts) -> Result<u32, AdcError> {
        self.check()?;
        if !v.0.is_finite() {
            return Err(AdcError::NonFiniteInput);
        }
        self.code_for_fraction(
            (v.0 + self.offset.0) * self.pga_gain / (self.vref.0 * self.gain_correction),
        )
    }

    /// The inverse of [`AdcScale::ratiometric_ohms`]: the code for an RTD resistance measured
    /// against `reference`.
    pub fn code_for_ohms(&self, r: RtdOhms, reference: Ohms) -> Result<u32, AdcError> {
        self.check()?;
        if !(reference.0.is_finite() && reference.0 > 0.0) {
            return Err(AdcError::InvalidScale);
        }
        if !r.0.is_finite() {
            return Err(AdcError::NonFiniteInput);
        }
        self.code_for_fraction(r.0 * self.pga_gain / (reference.0 * self.gain_correction))
    }
}

impl Ads1262Code {
    /// The code as the raw 32-bit pattern for [`AdcScale::fraction`].
    #[inline]
    pub const fn raw(self) -> u32 {
        self.0 as u32
    }
}

impl Ad7124Code {
    /// The code as the raw 24-bit pattern for [`AdcScale::fraction`].
    #[inline]
    pub const fn raw(self) -> u32 {
        self.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ads1262(gain: f64) -> AdcScale {
        AdcScale {
            bits: 32,
            coding: Coding::TwosComplement,
            pga_gain: gain,
            vref: Volts(2.5),
            gain_correction: 1.0,
            offset: Volts(0.0),
        }
    }

    /// AD7124 unipolar at gain 16 (the board's RTD channel), 2.5 V reference.
    fn ad7124_gain_16() -> AdcScale {
        AdcScale {
            bits: 24,
            coding: Coding::Unipolar,
            pga_gain: 16.0,
            vref: Volts(2.5),
            gain_correction: 1.0,
            offset: Volts(0.0),
        }
    }

    #[test]
    fn ads1262_code_to_volts_follows_the_datasheet_lsb() {
        // ADS1262 datasheet: 1 LSB = 2·Vref / (gain · 2^32); 0x4000_0000 = +Vref/2 at gain 1.
        let s = ads1262(1.0);
        assert_eq!(s.volts(0x4000_0000).unwrap(), Volts(1.25));
        assert_eq!(
            s.volts(Ads1262Code(-0x4000_0000).raw()).unwrap(),
            Volts(-1.25)
        );
        let lsb = s.volts(1).unwrap().0;
        assert!((lsb - 2.5 / 2f64.powi(31)).abs() < 1e-24);
    }

    #[test]
    fn full_scale_codes_are_reported_as_saturated() {
        let s = ads1262(1.0);
        assert_eq!(s.volts(0x7FFF_FFFF), Err(AdcError::Saturated));
        assert_eq!(s.volts(0x8000_0000), Err(AdcError::Saturated));
    }

    #[test]
    fn ratiometric_resistance_is_independent_of_reference_voltage() {
        // AD7124 unipolar, gain 16, Rref 5.11 kΩ: code for 100 Ω is 2^24·100·16/5110.
        let mut s = ad7124_gain_16();
        let code = (16_777_216.0 * 100.0 * 16.0 / 5110.0_f64).round() as u32;
        let r1 = s.ratiometric_ohms(code, Ohms(5110.0)).unwrap();
        s.vref = Volts(1.0);
        let r2 = s.ratiometric_ohms(code, Ohms(5110.0)).unwrap();
        assert_eq!(r1, r2);
        assert!((r1.0 - 100.0).abs() < 5110.0 / 16.0 / 16_777_216.0);
    }

    #[test]
    fn codes_wider_than_the_converter_are_refused() {
        let s = AdcScale {
            bits: 24,
            coding: Coding::OffsetBinary,
            pga_gain: 1.0,
            vref: Volts(2.5),
            gain_correction: 1.0,
            offset: Volts(0.0),
        };
        assert_eq!(s.volts(0x0100_0000), Err(AdcError::OutOfRange));
        assert_eq!(s.volts(0x80_0000).unwrap(), Volts(0.0));
    }

    #[test]
    fn volts_to_code_follows_the_datasheet_lsb_and_rounds_to_nearest() {
        let s = ads1262(1.0);
        // +Vref/2 at gain 1 is 0x4000_0000; −Vref/2 is its two's complement 0xC000_0000.
        assert_eq!(s.code_for_volts(Volts(1.25)), Ok(0x4000_0000));
        assert_eq!(s.code_for_volts(Volts(-1.25)), Ok(0xC000_0000));
        // 0.6 LSB rounds up to 1, 0.4 LSB down to 0 (1 LSB = 2.5 V / 2^31 at gain 1).
        let lsb = 2.5 / 2_147_483_648.0;
        assert_eq!(s.code_for_volts(Volts(0.6 * lsb)), Ok(1));
        assert_eq!(s.code_for_volts(Volts(0.4 * lsb)), Ok(0));
        assert_eq!(s.code_for_volts(Volts(-lsb)), Ok(0xFFFF_FFFF));
        // Gain 32 divides the full scale by 32.
        assert_eq!(
            ads1262(32.0).code_for_volts(Volts(1.25 / 32.0)),
            Ok(0x4000_0000)
        );
    }

    #[test]
    fn volts_to_code_inverts_code_to_volts_for_every_coding() {
        let scales = [
            ads1262(4.0),
            AdcScale {
                bits: 24,
                coding: Coding::OffsetBinary,
                pga_gain: 2.0,
                vref: Volts(2.5),
                gain_correction: 1.0003,
                offset: Volts(1e-4),
            },
            AdcScale {
                bits: 24,
                coding: Coding::Unipolar,
                pga_gain: 16.0,
                vref: Volts(2.5),
                gain_correction: 0.9998,
                offset: Volts(0.0),
            },
        ];
        for s in scales {
            let max = ((1u64 << s.bits) - 1) as u32;
            for raw in [1u32, 12_345, max / 3, max / 2 + 7, max - 2] {
                let raw = raw & max;
                let Ok(v) = s.volts(raw) else { continue };
                assert_eq!(s.code_for_volts(v), Ok(raw), "{s:?} raw={raw:#x}");
            }
        }
    }

    #[test]
    fn inputs_beyond_full_scale_give_the_rail_code_which_reads_back_as_saturated() {
        let s = ads1262(1.0);
        let hi = s.code_for_volts(Volts(3.0)).unwrap();
        let lo = s.code_for_volts(Volts(-3.0)).unwrap();
        assert_eq!((hi, lo), (0x7FFF_FFFF, 0x8000_0000));
        assert_eq!(s.volts(hi), Err(AdcError::Saturated));
        assert_eq!(
            s.code_for_volts(Volts(f64::NAN)),
            Err(AdcError::NonFiniteInput)
        );
    }

    #[test]
    fn ohms_to_code_matches_the_ratiometric_formula() {
        // AD7124 unipolar, gain 16, Rref 5.11 kΩ: 100 Ω ↔ round(2^24·100·16/5110) = 5 253 140 (computed independently).
        let s = ad7124_gain_16();
        assert_eq!(s.code_for_ohms(RtdOhms(100.0), Ohms(5110.0)), Ok(5_253_140));
        assert_eq!(
            s.code_for_ohms(RtdOhms(100.0), Ohms(0.0)),
            Err(AdcError::InvalidScale)
        );
    }
}
