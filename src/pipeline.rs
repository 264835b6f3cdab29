//! Per-sample processing: raw ADC codes + the active calibration → one output frame.
//!
//! This is the whole per-sample computation of the firmware, and the host runs the very same
//! function (`accomp compensate --target host`, the QEMU end-to-end comparison), so a result
//! computed on the PC and one computed on the board differ only if the arithmetic differs.
//!
//! Sensor faults never produce a silent number: any value that cannot be trusted is NaN in the
//! frame *and* the reason is set in [`Status`]. Values that depend on a NaN are NaN as well.
//!
//! [`raw_from_physical`] builds the raw sample for physical values with the front-end's inverse
//! conversions ([`crate::frontend`]), so that the host can inject samples that the firmware
//! converts back to the same physics.

use serde::{Deserialize, Serialize};

use crate::adc::{Ad7124Code, AdcError, Ads1262Code};
use crate::fixed;
use crate::prepared::{CompensateFault, PreparedCalibration, RtdFault};
use crate::rtd::RtdError;
use crate::table::CalibrationTable;
use crate::units::{Celsius, TiltArcsec, Volts};

// The front-end's scales and value → code conversions, re-exported for the callers that build
// raw samples next to the pipeline (host injection, tests); they are defined once, in
// `crate::frontend`.
pub use crate::frontend::{
    accel_scale, arcsec_to_ads1262, celsius_to_ad7124, ohms_to_ad7124, tilt_scale, volts_to_ads1262,
};

/// Per-channel fault bits reported by the drivers together with a conversion.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct ChannelFlags(pub u8);

impl ChannelFlags {
    /// The conversion's checksum/CRC did not match: the code is garbage.
    pub const CHECKSUM: u8 = 1 << 0;
    /// DRDY did not come in time: the code is stale or absent.
    pub const DRDY_TIMEOUT: u8 = 1 << 1;
    /// The ADC itself reported an over-range (ADS1262 status byte, AD7124 error register).
    pub const SATURATION: u8 = 1 << 2;
    /// The converter reset itself since it was configured (brown-out, glitch): its settings were
    /// lost, the conversion is not the configured one; the sequencer re-initialises it.
    pub const RESET: u8 = 1 << 3;
    /// The converter did not answer (MISO idle: all ones or all zeros).
    pub const NOT_RESPONDING: u8 = 1 << 4;
    /// The AD7124 reports no reference (REF_DET): no excitation current flows, i.e. the RTD loop
    /// (or the reference resistor) is open.
    pub const OPEN_CIRCUIT: u8 = 1 << 5;

    /// True when any bit in `mask` is set.
    #[inline]
    pub const fn has(self, mask: u8) -> bool {
        self.0 & mask != 0
    }
}

/// One raw acquisition as the drivers deliver it (or as the host injects it in QEMU).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct RawSample {
    /// ADS1262 code of the sense-resistor voltage (accelerometer output E).
    pub accel: i32,
    /// AD7124 ratiometric code of the Pt100 against the reference resistor.
    pub rtd: u32,
    /// ADS1262 code of the tiltmeter output.
    pub tilt: i32,
    /// Driver fault bits of the accelerometer conversion.
    pub accel_flags: ChannelFlags,
    /// Driver fault bits of the RTD conversion.
    pub rtd_flags: ChannelFlags,
    /// Driver fault bits of the tilt conversion.
    pub tilt_flags: ChannelFlags,
}

impl RawSample {
    /// A sample of these codes without driver fault flags: what a clean acquisition delivers.
    pub const fn from_codes(accel: i32, rtd: u32, tilt: i32) -> Self {
        RawSample {
            accel,
            rtd,
            tilt,
            accel_flags: ChannelFlags(0),
            rtd_flags: ChannelFlags(0),
            tilt_flags: ChannelFlags(0),
        }
    }

    /// The accelerometer code as its typed newtype.
    pub const fn accel_code(&self) -> Ads1262Code {
        Ads1262Code(self.accel)
    }
    /// The RTD code as its typed newtype.
    pub const fn rtd_code(&self) -> Ad7124Code {
        Ad7124Code(self.rtd)
    }
    /// The tilt code as its typed newtype.
    pub const fn tilt_code(&self) -> Ads1262Code {
        Ads1262Code(self.tilt)
    }
}

/// Status bits of an output frame. Zero means every value in the frame is valid and inside the
/// calibrated range.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Status(pub u16);

impl Status {
    /// RTD resistance above the plausible maximum (open wire) or AD7124 code at full scale.
    pub const RTD_OPEN: u16 = 1 << 0;
    /// RTD resistance below the plausible minimum (shorted sensor).
    pub const RTD_SHORT: u16 = 1 << 1;
    /// A code at a rail, or an over-range reported by an ADC.
    pub const ADC_SATURATED: u16 = 1 << 2;
    /// A driver reported a checksum/CRC error on some conversion.
    pub const ADC_CHECKSUM: u16 = 1 << 3;
    /// A driver reported a DRDY timeout on some conversion.
    pub const DRDY_TIMEOUT: u16 = 1 << 4;
    /// Temperature outside the calibrated range: models evaluated at the clamped edge.
    pub const TEMP_OUT_OF_RANGE: u16 = 1 << 5;
    /// No active calibration table: only output_v is computed (ideal ADC scale).
    pub const NO_CALIBRATION: u16 = 1 << 6;
    /// The compensation itself failed (no real root, non-finite intermediate).
    pub const COMPENSATION_FAILED: u16 = 1 << 7;
    /// The tilt value is invalid (tilt channel fault); compensations needing it are NaN.
    pub const TILT_INVALID: u16 = 1 << 8;
    /// The accelerometer output value is invalid (its channel faulted).
    pub const OUTPUT_INVALID: u16 = 1 << 9;
    /// The RTD conversion failed for another reason (non-finite, invalid constants).
    pub const RTD_INVALID: u16 = 1 << 10;
    /// A converter reset itself mid-run (configuration lost); the acquisition re-initialised it.
    pub const ADC_RESET: u16 = 1 << 11;
    /// A converter did not answer on the bus (MISO idle high or low).
    pub const ADC_NOT_RESPONDING: u16 = 1 << 12;

    /// Names of the bits, in bit order, for logs and CSV output.
    pub const NAMES: [(u16, &'static str); 13] = [
        (Self::RTD_OPEN, "RTD_OPEN"),
        (Self::RTD_SHORT, "RTD_SHORT"),
        (Self::ADC_SATURATED, "ADC_SATURATED"),
        (Self::ADC_CHECKSUM, "ADC_CHECKSUM"),
        (Self::DRDY_TIMEOUT, "DRDY_TIMEOUT"),
        (Self::TEMP_OUT_OF_RANGE, "TEMP_OUT_OF_RANGE"),
        (Self::NO_CALIBRATION, "NO_CALIBRATION"),
        (Self::COMPENSATION_FAILED, "COMPENSATION_FAILED"),
        (Self::TILT_INVALID, "TILT_INVALID"),
        (Self::OUTPUT_INVALID, "OUTPUT_INVALID"),
        (Self::RTD_INVALID, "RTD_INVALID"),
        (Self::ADC_RESET, "ADC_RESET"),
        (Self::ADC_NOT_RESPONDING, "ADC_NOT_RESPONDING"),
    ];

    /// True when any bit in `mask` is set.
    #[inline]
    pub const fn has(self, mask: u16) -> bool {
        self.0 & mask != 0
    }

    #[inline]
    fn set(&mut self, mask: u16) {
        self.0 |= mask;
    }
}

/// Why readings are missing before a frame: the `seq` gap between it and the frame before is
/// explained by these bits (several may be set). Zero: nothing was lost since the last frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct LossFlags(pub u8);

impl LossFlags {
    /// Readings dropped because the worker's queue was full.
    pub const QUEUE_FULL: u8 = 1 << 0;
    /// Conversions the core could not serve in time (a flash erase or a long interrupt-off
    /// stretch): counted from the conversion clock, so the gap is the number missed.
    pub const STALL: u8 = 1 << 1;
    /// Frames the UART transmitter could not take (the link was full); their readings were
    /// acquired and processed but never sent.
    pub const TX_DROPPED: u8 = 1 << 2;

    /// Names of the bits, in bit order, for logs and CSV output.
    pub const NAMES: [(u8, &'static str); 3] = [
        (Self::QUEUE_FULL, "QUEUE_FULL"),
        (Self::STALL, "STALL"),
        (Self::TX_DROPPED, "TX_DROPPED"),
    ];

    /// True when any bit in `mask` is set.
    #[inline]
    pub const fn has(self, mask: u8) -> bool {
        self.0 & mask != 0
    }
}

/// The output of one sample: what the board streams and the host records.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Frame {
    /// Sequence number of the reading since boot: one per reading the acquisition produced
    /// (or per injected sample), whether it reached the host or not. A gap is readings lost;
    /// [`Frame::lost`] says why.
    pub seq: u32,
    /// Time of the reading in µs since boot, from the board's time base (the DRDY edge on the
    /// front-end, the arrival of the request on QEMU).
    pub time_us: u64,
    /// Why readings are missing between the previous frame and this one ([`LossFlags`]).
    pub lost: LossFlags,
    /// Accelerometer output E in volts, after the ADC gain/offset correction.
    pub output_v: f64,
    /// RTD temperature in °C (ITS-90, Callendar–Van Dusen).
    pub temperature_c: f64,
    /// RTD resistance in ohms.
    pub rtd_ohms: f64,
    /// Tilt in arcseconds.
    pub tilt_arcsec: f64,
    /// Input acceleration from the exact model inverse at the measured temperature, in g.
    pub a_i_exact_g: f64,
    /// The paper's linearized compensated output (eq. 3/4), in volts.
    pub output_linearized_v: f64,
    /// [`Status`] bits.
    pub status: Status,
}

/// Flags a channel's driver faults; returns true when the code must not be used.
#[inline]
fn driver_faults(flags: ChannelFlags, status: &mut Status) -> bool {
    // A clean conversion (every sample, as a rule) skips the six tests below: ≈ 60 instructions
    // per channel on the M4F.
    if flags.0 == 0 {
        return false;
    }
    if flags.has(ChannelFlags::CHECKSUM) {
        status.set(Status::ADC_CHECKSUM);
    }
    if flags.has(ChannelFlags::DRDY_TIMEOUT) {
        status.set(Status::DRDY_TIMEOUT);
    }
    if flags.has(ChannelFlags::SATURATION) {
        status.set(Status::ADC_SATURATED);
    }
    if flags.has(ChannelFlags::RESET) {
        status.set(Status::ADC_RESET);
    }
    if flags.has(ChannelFlags::NOT_RESPONDING) {
        status.set(Status::ADC_NOT_RESPONDING);
    }
    if flags.has(ChannelFlags::OPEN_CIRCUIT) {
        // Only the RTD channel reports it (AD7124 REF_DET); on another channel it still names
        // an open input rather than vanishing.
        status.set(Status::RTD_OPEN);
    }
    flags.0 != 0
}

fn adc_fault(e: AdcError, status: &mut Status) {
    match e {
        AdcError::Saturated | AdcError::OutOfRange => status.set(Status::ADC_SATURATED),
        AdcError::InvalidScale => status.set(Status::NO_CALIBRATION),
        // Only the physical → code direction (host-side injection) produces this; a code read
        // from a chip is always finite. Flag it as a conversion failure rather than guess.
        AdcError::NonFiniteInput => status.set(Status::ADC_SATURATED),
    }
}

/// Processes one raw sample with a table (if any) into an output frame: prepares the table,
/// then [`process_prepared`]. The host's reference path for one-off samples; the firmware keeps
/// the prepared table and calls [`process_prepared`] directly.
///
/// A table that does not validate is treated like no table (the device never activates one).
pub fn process(seq: u32, time_us: u64, raw: &RawSample, table: Option<&CalibrationTable>) -> Frame {
    let prepared = table.and_then(|t| PreparedCalibration::new(t).ok());
    process_prepared(seq, time_us, raw, prepared.as_ref())
}

/// Processes one raw sample with the prepared active table (if any) into an output frame.
///
/// Pure function of its arguments: the firmware and the host get the same bits.
pub fn process_prepared(
    seq: u32,
    time_us: u64,
    raw: &RawSample,
    table: Option<&PreparedCalibration>,
) -> Frame {
    let mut status = Status::default();
    let mut frame = Frame {
        seq,
        time_us,
        lost: LossFlags(0),
        output_v: f64::NAN,
        temperature_c: f64::NAN,
        rtd_ohms: f64::NAN,
        tilt_arcsec: f64::NAN,
        a_i_exact_g: f64::NAN,
        output_linearized_v: f64::NAN,
        status,
    };

    let Some(table) = table else {
        // Without a table only E, on the ideal scale.
        if driver_faults(raw.accel_flags, &mut status) {
            status.set(Status::OUTPUT_INVALID);
        } else {
            match accel_scale(None).volts(raw.accel_code().raw()) {
                Ok(v) => frame.output_v = v.0,
                Err(e) => {
                    adc_fault(e, &mut status);
                    status.set(Status::OUTPUT_INVALID);
                }
            }
        }
        status.set(Status::NO_CALIBRATION);
        frame.status = status;
        return frame;
    };

    // Accelerometer output E (and in fixed point for the compensation).
    let mut e_fixed = 0;
    if driver_faults(raw.accel_flags, &mut status) {
        status.set(Status::OUTPUT_INVALID);
    } else {
        match table.accel_volts(raw.accel) {
            Ok((v, fixed)) => {
                frame.output_v = v;
                e_fixed = fixed;
            }
            Err(e) => {
                adc_fault(e, &mut status);
                status.set(Status::OUTPUT_INVALID);
            }
        }
    }

    // RTD: ratiometric ohms → °C, with the compensation's temperature terms (cached per code).
    // (Held in place: a move of the 64-byte Temperature is ≈ 17 instructions.)
    let temperature = if driver_faults(raw.rtd_flags, &mut status) {
        status.set(Status::RTD_INVALID);
        None
    } else {
        Some(table.temperature(raw.rtd))
    };
    if let Some(temp) = &temperature {
        // NaN when unknown: the frame's value then stays NaN.
        frame.rtd_ohms = temp.ohms;
        match temp.fault {
            None => frame.temperature_c = temp.t_c,
            // A unipolar code at full scale means the excitation found no path: open.
            Some(RtdFault::Adc(AdcError::Saturated)) => {
                status.set(Status::RTD_OPEN | Status::ADC_SATURATED)
            }
            Some(RtdFault::Adc(e)) => {
                adc_fault(e, &mut status);
                status.set(Status::RTD_INVALID);
            }
            Some(RtdFault::Rtd(RtdError::Open)) => status.set(Status::RTD_OPEN),
            Some(RtdFault::Rtd(RtdError::Short)) => status.set(Status::RTD_SHORT),
            Some(RtdFault::Rtd(_)) => status.set(Status::RTD_INVALID),
        }
    }

    // Tiltmeter: volts → arcsec.
    let mut tilt_code = None;
    if driver_faults(raw.tilt_flags, &mut status) {
        status.set(Status::TILT_INVALID);
    } else {
        match table.tilt_arcsec(raw.tilt) {
            Ok(v) if fixed::is_finite(v) => {
                frame.tilt_arcsec = v;
                tilt_code = Some(raw.tilt);
            }
            // A non-finite tilt (an absurd table the validator should have refused) is invalid,
            // never a silent NaN next to status OK.
            Ok(_) => status.set(Status::TILT_INVALID),
            Err(e) => {
                adc_fault(e, &mut status);
                status.set(Status::TILT_INVALID);
            }
        }
    }

    // Same rule for E and T: a non-finite value is flagged invalid and stays NaN.
    // (Bit tests: `f64::is_finite`/`is_nan` are soft-float comparisons on the M4F.)
    if !fixed::is_finite(frame.output_v) && !status.has(Status::OUTPUT_INVALID) {
        frame.output_v = f64::NAN;
        status.set(Status::OUTPUT_INVALID);
    }
    if !fixed::is_finite(frame.temperature_c)
        && !status.has(Status::RTD_OPEN | Status::RTD_SHORT | Status::RTD_INVALID)
    {
        frame.temperature_c = f64::NAN;
        status.set(Status::RTD_INVALID);
    }
    let (e, t) = (frame.output_v, frame.temperature_c);
    let Some(temperature) = temperature
        .as_ref()
        .filter(|temp| temp.fault.is_none() && !(fixed::is_nan(e) || fixed::is_nan(t)))
    else {
        // Already flagged above; the compensated values stay NaN.
        frame.status = status;
        return frame;
    };
    // An Ok of `compensate` is finite (its contract; the f64 path checks, the fixed-point path
    // cannot produce anything else).
    match table.compensate(raw.accel, e, e_fixed, temperature, tilt_code) {
        Ok((a_i, lin, clamped)) => {
            frame.a_i_exact_g = a_i;
            frame.output_linearized_v = lin;
            if clamped {
                status.set(Status::TEMP_OUT_OF_RANGE);
            }
        }
        Err(CompensateFault::TiltNeeded) => status.set(Status::TILT_INVALID),
        Err(CompensateFault::Failed) => status.set(Status::COMPENSATION_FAILED),
    }
    frame.status = status;
    frame
}

/// Builds the raw sample the board would acquire for these physical values (host injection).
pub fn raw_from_physical(
    table: &CalibrationTable,
    output: Volts,
    t: Celsius,
    tilt: TiltArcsec,
) -> Result<RawSample, AdcError> {
    Ok(RawSample::from_codes(
        volts_to_ads1262(&accel_scale(Some(table)), output)?.0,
        celsius_to_ad7124(table, t)?.0,
        arcsec_to_ads1262(table, tilt)?.0,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::table::tests::paper_table;
    use crate::units::Gs;

    fn raw(table: &CalibrationTable, e: f64, t: f64, tilt: f64) -> RawSample {
        raw_from_physical(table, Volts(e), Celsius(t), TiltArcsec(tilt)).unwrap()
    }

    #[test]
    fn volts_round_trip_through_an_ads1262_code_within_half_an_lsb() {
        let s = accel_scale(None);
        let lsb = 2.5 / 2f64.powi(31);
        for v in [-2.4, -1.0, 0.0, 1e-9, 1.3267, 2.4] {
            let code = volts_to_ads1262(&s, Volts(v)).unwrap();
            let back = s.volts(code.raw()).unwrap().0;
            assert!((back - v).abs() <= 0.5 * lsb, "{v} → {back}");
        }
        assert_eq!(volts_to_ads1262(&s, Volts(2.6)), Err(AdcError::Saturated));
        assert_eq!(
            volts_to_ads1262(&s, Volts(f64::NAN)),
            Err(AdcError::NonFiniteInput)
        );
    }

    #[test]
    fn temperature_round_trips_through_the_rtd_code_to_a_tenth_of_a_millikelvin() {
        let t = paper_table();
        for c in [20.0, 30.5, 47.5, 64.5] {
            let code = celsius_to_ad7124(&t, Celsius(c)).unwrap();
            // Hand figure: 1 LSB = 5110 Ω / 16 / 2^24 = 1.9e-5 Ω ≈ 5e-5 °C for a Pt100.
            let f = process(0, 0, &raw(&t, 1.0, c, 0.0), Some(&t));
            let expected = if c < 30.0 {
                Status::TEMP_OUT_OF_RANGE
            } else {
                0
            };
            assert_eq!(f.status, Status(expected), "{c}");
            assert!(
                (f.temperature_c - c).abs() < 1e-4,
                "{c}: {}",
                f.temperature_c
            );
            assert_eq!(code.0, raw(&t, 1.0, c, 0.0).rtd);
        }
    }

    #[test]
    fn a_clean_sample_recovers_the_input_acceleration() {
        let t = paper_table();
        let (k, _) = t.thermal.coefficients_at(Celsius(50.0)).unwrap();
        let e = k.output(Gs(0.7), t.orientation.cross);
        let f = process(7, 123, &raw(&t, e.0, 50.0, 0.0), Some(&t));
        assert_eq!(f.status, Status(0));
        assert_eq!((f.seq, f.time_us), (7, 123));
        // Quantization: E to 1.2e-9 V (≈ 1e-9 g), T to 5e-5 °C (≈ 3e-9 g via dK0/dT).
        assert!((f.a_i_exact_g - 0.7).abs() < 2e-8, "{}", f.a_i_exact_g);
        assert!(f.output_linearized_v.is_finite());
    }

    #[test]
    fn tilt_is_removed_from_the_output_before_compensation() {
        let t = paper_table();
        let (k, _) = t.thermal.coefficients_at(Celsius(50.0)).unwrap();
        let e0 = k.output(Gs(0.0), t.orientation.cross).0;
        // 5 arcsec of tilt along the input axis adds K1·sin(5") to E.
        let d = k.scale_factor_v_per_g * libm::sin(5.0 * crate::units::RAD_PER_ARCSEC);
        let f = process(0, 0, &raw(&t, e0 + d, 50.0, 5.0), Some(&t));
        assert!((f.tilt_arcsec - 5.0).abs() < 1e-6);
        assert!(f.a_i_exact_g.abs() < 1e-8, "{}", f.a_i_exact_g);
        let no_tilt_correction = process(0, 0, &raw(&t, e0 + d, 50.0, 0.0), Some(&t));
        assert!((no_tilt_correction.a_i_exact_g - 24.2e-6).abs() < 0.1e-6);
    }

    #[test]
    fn open_and_shorted_rtd_are_flagged_and_nan() {
        let t = paper_table();
        let mut r = raw(&t, 1.0, 50.0, 0.0);
        r.rtd = 0x00FF_FFFF; // full scale: no excitation path
        let f = process(0, 0, &r, Some(&t));
        assert!(f.status.has(Status::RTD_OPEN));
        assert!(f.temperature_c.is_nan() && f.a_i_exact_g.is_nan());
        assert!(f.output_linearized_v.is_nan());
        assert!((f.output_v - 1.0).abs() < 1e-8, "E itself is still valid");

        r.rtd = 100; // ≈ 0.002 Ω
        let f = process(0, 0, &r, Some(&t));
        assert!(f.status.has(Status::RTD_SHORT));
        assert!(f.temperature_c.is_nan() && f.a_i_exact_g.is_nan());
        assert!(!f.status.has(Status::RTD_OPEN));
    }

    #[test]
    fn driver_faults_make_their_channel_nan_and_set_their_bit() {
        let t = paper_table();
        let mut r = raw(&t, 1.0, 50.0, 0.0);
        r.accel_flags = ChannelFlags(ChannelFlags::CHECKSUM);
        let f = process(0, 0, &r, Some(&t));
        assert!(f.status.has(Status::ADC_CHECKSUM) && f.status.has(Status::OUTPUT_INVALID));
        assert!(f.output_v.is_nan() && f.a_i_exact_g.is_nan());
        assert!(f.temperature_c.is_finite());

        let mut r = raw(&t, 1.0, 50.0, 0.0);
        r.rtd_flags = ChannelFlags(ChannelFlags::DRDY_TIMEOUT);
        let f = process(0, 0, &r, Some(&t));
        assert!(f.status.has(Status::DRDY_TIMEOUT) && f.status.has(Status::RTD_INVALID));
        assert!(f.temperature_c.is_nan() && f.a_i_exact_g.is_nan());

        let mut r = raw(&t, 1.0, 50.0, 0.0);
        r.tilt_flags = ChannelFlags(ChannelFlags::SATURATION);
        let f = process(0, 0, &r, Some(&t));
        assert!(f.status.has(Status::ADC_SATURATED) && f.status.has(Status::TILT_INVALID));
        assert!(f.tilt_arcsec.is_nan() && f.a_i_exact_g.is_nan());
    }

    #[test]
    fn accelerometer_code_at_the_rail_is_saturated_not_a_number() {
        let t = paper_table();
        let mut r = raw(&t, 1.0, 50.0, 0.0);
        r.accel = i32::MAX;
        let f = process(0, 0, &r, Some(&t));
        assert!(f.status.has(Status::ADC_SATURATED) && f.status.has(Status::OUTPUT_INVALID));
        assert!(f.output_v.is_nan() && f.a_i_exact_g.is_nan());
    }

    #[test]
    fn temperature_outside_the_calibrated_range_is_flagged_but_computed_at_the_edge() {
        let t = paper_table();
        let f = process(0, 0, &raw(&t, 1.0, 80.0, 0.0), Some(&t));
        assert!(f.status.has(Status::TEMP_OUT_OF_RANGE));
        assert!((f.temperature_c - 80.0).abs() < 1e-3);
        assert!(f.a_i_exact_g.is_finite());
    }

    #[test]
    fn without_a_table_only_the_output_voltage_is_given() {
        let t = paper_table();
        let f = process(0, 0, &raw(&t, 1.25, 50.0, 0.0), None);
        assert_eq!(f.status, Status(Status::NO_CALIBRATION));
        assert!((f.output_v - 1.25).abs() < 1e-9);
        assert!(f.temperature_c.is_nan() && f.a_i_exact_g.is_nan() && f.tilt_arcsec.is_nan());
    }

    /// Every f64 of a frame as bits (NaN compares equal to itself), plus seq and status.
    fn frame_bits(f: &Frame) -> [u64; 8] {
        [
            f.output_v.to_bits(),
            f.temperature_c.to_bits(),
            f.rtd_ohms.to_bits(),
            f.tilt_arcsec.to_bits(),
            f.a_i_exact_g.to_bits(),
            f.output_linearized_v.to_bits(),
            u64::from(f.status.0),
            u64::from(f.seq),
        ]
    }

    #[test]
    fn a_cached_temperature_gives_the_same_bits_as_a_fresh_preparation() {
        let mut t = paper_table();
        // ±250" at full scale, so that a tilt beyond the f32 range (103") is a valid code.
        t.tilt.scale_arcsec_per_v = 100.0;
        let warm = crate::prepared::PreparedCalibration::new(&t).unwrap();
        let cases = [
            (1.3, 45.0, 2.0),
            (-0.7, 45.0, 1.0),
            (0.9, 52.5, -3.0),
            (1.1, 45.0, 0.5),
            (0.2, 70.0, 0.0),
            (1.25, 20.0, 90.0),
            (0.2, 70.0, 200.0),
        ];
        // Twice through: hits (same code as the previous sample) and misses alternate.
        for (i, &(e, c, tilt)) in cases.iter().chain(cases.iter()).enumerate() {
            let raw = raw_from_physical(&t, Volts(e), Celsius(c), TiltArcsec(tilt)).unwrap();
            let cold = crate::prepared::PreparedCalibration::new(&t).unwrap();
            let from_warm = process_prepared(i as u32, 0, &raw, Some(&warm));
            let from_cold = process_prepared(i as u32, 0, &raw, Some(&cold));
            assert_eq!(frame_bits(&from_warm), frame_bits(&from_cold), "case {i}");
            assert!(from_warm.a_i_exact_g.is_finite(), "case {i}");
            assert_eq!(warm.cached_rtd_code(), Some(raw.rtd));
        }
    }

    #[test]
    fn every_status_bit_has_a_distinct_name() {
        let mut all = 0u16;
        for (bit, _) in Status::NAMES {
            assert_eq!(bit.count_ones(), 1);
            assert_eq!(all & bit, 0);
            all |= bit;
        }
    }
}
