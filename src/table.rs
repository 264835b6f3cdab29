//! Calibration table: the versioned, CRC-protected binary encoding the lab PC fits and uploads
//! and the board keeps in flash, and its validator. The layout is specified in
//! docs/calibration-format.md; every refusal has its own [`TableError`].
//!
//! Fixed-size little-endian layout (no allocation, no serde on the MCU): a 12-byte header
//! (magic, version, payload length), the payload, and a CRC-32/ISO-HDLC over everything before
//! it. The CRC value doubles as the table id that the firmware reports.

use crate::compensation::{CoefficientModels, ThermalCompensator};
use crate::model::CrossAxis;
use crate::poly::{TempPoly, TemperatureScale, N_COEFFS};
use crate::rtd::CallendarVanDusen;
use crate::units::{Celsius, Gs, Ohms, TiltArcsec, Volts};

/// First four bytes of every table.
pub const MAGIC: [u8; 4] = *b"ACAL";
/// Format version written by this code; the only one it reads.
pub const FORMAT_VERSION: u16 = 1;
/// Bytes of the accelerometer serial-number field (UTF-8, NUL padded).
pub const SERIAL_LEN: usize = 24;
/// Header: magic (4), version (2), reserved (2), payload length (4).
pub const HEADER_LEN: usize = 12;
const POLY_LEN: usize = 1 + 8 * N_COEFFS;
/// Payload length of format version 1.
pub const PAYLOAD_LEN: usize = SERIAL_LEN
    + 4 // calibration date
    + 8 * 5 // range min/max, centre, half-span, T0
    + 5 * POLY_LEN
    + 8 * 2 + 1 // tilt reference, tilt scale, tilt axis
    + 8 * 5 // RTD R0, A, B, C, reference resistor
    + 8 * 2 // RTD ADC gain correction, PGA gain
    + 8 * 3 // accel ADC gain correction, offset, sense resistor
    + 8 * 2 // tilt ADC gain correction, offset
    + 8 * 3; // orientation a_p, a_o, nominal input
/// Total encoded length: header, payload, CRC-32.
pub const ENCODED_LEN: usize = HEADER_LEN + PAYLOAD_LEN + 4;

/// CRC-32/ISO-HDLC (the zlib/Ethernet CRC), so that any tool can check a table file.
// Bitwise (no 1 KiB table in flash): it runs only on uploads, commits and at boot.
pub const CRC32: crc::Crc<u32, crc::NoTable> =
    crc::Crc::<u32, crc::NoTable>::new(&crc::CRC_32_ISO_HDLC);

/// Which coefficient a polynomial belongs to (for error messages and the format's order).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Coefficient {
    /// K0.
    Bias,
    /// K1.
    ScaleFactor,
    /// K2.
    Nonlinearity,
    /// δp.
    MisalignmentP,
    /// δo.
    MisalignmentO,
}

/// A named field of the table (for [`TableError::NonFinite`] and friends).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Field {
    /// Calibrated range or normalization.
    TemperatureScale,
    /// T0.
    ReferenceTemperature,
    /// A coefficient polynomial.
    Polynomial(Coefficient),
    /// Tilt reference, scale or axis.
    Tilt,
    /// RTD constants or reference resistor.
    Rtd,
    /// ADC corrections or sense resistor.
    Adc,
    /// Default orientation.
    Orientation,
    /// Serial number text.
    Serial,
    /// Calibration date.
    Date,
}

/// Why a table is refused. The active table is never touched by a refused one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TableError {
    /// Not an accomp table: the first four bytes are not `ACAL`.
    BadMagic,
    /// A format version this firmware does not read.
    UnsupportedVersion(u16),
    /// The reserved header field is not zero: a format this firmware does not read. Refused so
    /// that every accepted table re-encodes to exactly the bytes received (its id, read-back).
    Reserved(u16),
    /// The length field or the byte count is wrong.
    BadLength {
        /// Bytes expected.
        expected: u32,
        /// Bytes found.
        found: u32,
    },
    /// The CRC does not match: corrupted in transit or in storage.
    BadCrc {
        /// CRC stored in the table.
        stored: u32,
        /// CRC computed over the bytes.
        computed: u32,
    },
    /// A number is NaN or infinite.
    NonFinite(Field),
    /// A polynomial order above 4, non-zero coefficients above the stated order, or a stated
    /// order above the highest non-zero coefficient.
    OrderTooHigh(Coefficient),
    /// The calibrated temperature range is empty or inverted, or Ts ≤ 0.
    EmptyRange,
    /// T0 lies outside the calibrated range.
    ReferenceOutsideRange,
    /// K1 is ≤ 0 or outside 0.01–100 V/g somewhere in the calibrated range.
    ScaleFactorImplausible,
    /// RTD constants or reference resistor are not those of a platinum sensor.
    RtdConstants,
    /// An ADC correction, sense resistor or tilt scale is zero, negative or absurd.
    AdcConstants,
    /// The serial number is not UTF-8.
    Serial,
    /// The calibration date is not a calendar date.
    Date,
    /// The tilt axis code is unknown.
    TiltAxis,
    /// A finite value outside its physical bounds (docs/calibration-format.md lists them with
    /// the reasoning): temperature range outside the platinum RTD's, a coefficient model that
    /// leaves its bound somewhere in the calibrated range, an absurd tilt scale or reference.
    OutOfBounds(Field),
}

/// Physical bounds of the table's fields (docs/calibration-format.md gives the reasoning).
pub mod bounds {
    /// Lowest and highest temperature of the Callendar–Van Dusen equation (IEC 60751), °C.
    pub const RTD_RANGE_C: (f64, f64) = (-200.0, 850.0);
    /// |K0| over the calibrated range, g: ten times a navigation-grade bias budget.
    pub const MAX_BIAS_G: f64 = 0.1;
    /// |K2| over the calibrated range, g/g²: about 100 times a servo accelerometer's.
    pub const MAX_NONLINEARITY_G_PER_G2: f64 = 1e-2;
    /// |δp|, |δo| over the calibrated range, rad (≈ 69 arcmin): far above any case alignment.
    pub const MAX_MISALIGNMENT_RAD: f64 = 0.02;
    /// Tiltmeter sensitivity magnitude, arcsec/V.
    pub const TILT_SCALE_ARCSEC_PER_V: (f64, f64) = (1e-3, 1e5);
    /// |φ0|, arcsec (10°): beyond any tiltmeter's range.
    pub const MAX_TILT_REFERENCE_ARCSEC: f64 = 36_000.0;
}

/// Calibration date.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CalibrationDate {
    /// Year (e.g. 2026).
    pub year: u16,
    /// Month 1–12.
    pub month: u8,
    /// Day 1–31.
    pub day: u8,
}

/// Which accelerometer axis the tiltmeter axis is aligned with (sign included).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TiltAxis {
    /// Tilt turns the input axis (0 g test with the input axis horizontal): eq. (5) applies.
    Input = 0,
    /// Tilt turns the input axis, tiltmeter mounted reversed.
    InputReversed = 1,
    /// Tilt about the input axis: no first-order effect on the output.
    None = 2,
}

/// Tiltmeter configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TiltConfig {
    /// φ0, the tilt at the start of the test.
    pub reference: TiltArcsec,
    /// Tiltmeter sensitivity, arcsec per volt.
    pub scale_arcsec_per_v: f64,
    /// Axis alignment.
    pub axis: TiltAxis,
    /// ADC gain correction of the tilt channel.
    pub adc_gain_correction: f64,
    /// ADC offset of the tilt channel.
    pub adc_offset: Volts,
}

/// RTD measurement configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RtdConfig {
    /// Callendar–Van Dusen constants of this sensor.
    pub cvd: CallendarVanDusen,
    /// Reference resistor of the ratiometric measurement.
    pub reference_resistor: Ohms,
    /// ADC gain correction of the RTD channel.
    pub adc_gain_correction: f64,
    /// PGA gain of the RTD channel.
    pub pga_gain: f64,
}

/// Accelerometer channel configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AccelChannel {
    /// ADC gain correction.
    pub adc_gain_correction: f64,
    /// ADC offset.
    pub adc_offset: Volts,
    /// Precision sense resistor the torquer current flows through (E = I·R).
    pub sense_resistor: Ohms,
}

/// Default test orientation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Orientation {
    /// Cross-axis inputs a_p, a_o.
    pub cross: CrossAxis,
    /// Nominal input a_i of the test (1 g, 0 g, −1 g …).
    pub nominal_input: Gs,
}

/// A complete calibration table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationTable {
    /// Accelerometer serial number, UTF-8, NUL padded.
    pub serial: [u8; SERIAL_LEN],
    /// When it was calibrated.
    pub date: CalibrationDate,
    /// Temperature models, range, normalization and T0.
    pub thermal: ThermalCompensator,
    /// Tiltmeter.
    pub tilt: TiltConfig,
    /// RTD.
    pub rtd: RtdConfig,
    /// Accelerometer channel.
    pub accel: AccelChannel,
    /// Default orientation.
    pub orientation: Orientation,
}

struct Writer<'a> {
    buf: &'a mut [u8; ENCODED_LEN],
    pos: usize,
}

impl Writer<'_> {
    fn bytes(&mut self, b: &[u8]) {
        // Lengths are compile-time constants of the layout; `get_mut` keeps this panic-free.
        if let Some(dst) = self.buf.get_mut(self.pos..self.pos + b.len()) {
            dst.copy_from_slice(b);
        }
        self.pos += b.len();
    }
    fn f64(&mut self, v: f64) {
        self.bytes(&v.to_le_bytes());
    }
    fn poly(&mut self, p: &TempPoly) {
        self.bytes(&[p.order() as u8]);
        for c in p.coeffs {
            self.f64(c);
        }
    }
}

struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl Reader<'_> {
    fn take<const N: usize>(&mut self) -> Result<[u8; N], TableError> {
        let mut out = [0u8; N];
        let src = self
            .buf
            .get(self.pos..self.pos + N)
            .ok_or(TableError::BadLength {
                expected: ENCODED_LEN as u32,
                found: self.buf.len() as u32,
            })?;
        out.copy_from_slice(src);
        self.pos += N;
        Ok(out)
    }
    fn u8(&mut self) -> Result<u8, TableError> {
        Ok(self.take::<1>()?[0])
    }
    fn u16(&mut self) -> Result<u16, TableError> {
        Ok(u16::from_le_bytes(self.take()?))
    }
    fn u32(&mut self) -> Result<u32, TableError> {
        Ok(u32::from_le_bytes(self.take()?))
    }
    fn f64(&mut self, field: Field) -> Result<f64, TableError> {
        let v = f64::from_le_bytes(self.take()?);
        if v.is_finite() {
            Ok(v)
        } else {
            Err(TableError::NonFinite(field))
        }
    }
    fn poly(&mut self, which: Coefficient) -> Result<TempPoly, TableError> {
        let order = usize::from(self.u8()?);
        let mut coeffs = [0.0; N_COEFFS];
        for c in coeffs.iter_mut() {
            *c = self.f64(Field::Polynomial(which))?;
        }
        if order >= N_COEFFS || coeffs.iter().skip(order + 1).any(|c| *c != 0.0) {
            return Err(TableError::OrderTooHigh(which));
        }
        let poly = TempPoly { coeffs };
        // The order byte is derived data (the encoder writes the highest non-zero power): one
        // that claims more than the coefficients hold would not re-encode to the same bytes.
        if poly.order() != order {
            return Err(TableError::OrderTooHigh(which));
        }
        Ok(poly)
    }
}

impl CalibrationTable {
    /// The serial number as text (up to the first NUL).
    pub fn serial_str(&self) -> Result<&str, TableError> {
        let end = self
            .serial
            .iter()
            .position(|b| *b == 0)
            .unwrap_or(SERIAL_LEN);
        let bytes = self.serial.get(..end).ok_or(TableError::Serial)?;
        core::str::from_utf8(bytes).map_err(|_| TableError::Serial)
    }

    /// A serial-number field from text, truncated at a character boundary to fit.
    pub fn serial_from_str(s: &str) -> [u8; SERIAL_LEN] {
        let mut out = [0u8; SERIAL_LEN];
        let mut end = s.len().min(SERIAL_LEN);
        while !s.is_char_boundary(end) {
            end -= 1;
        }
        if let (Some(dst), Some(src)) = (out.get_mut(..end), s.as_bytes().get(..end)) {
            dst.copy_from_slice(src);
        }
        out
    }

    /// Encodes the table; the result carries its CRC in the last four bytes.
    pub fn encode(&self) -> [u8; ENCODED_LEN] {
        let mut buf = [0u8; ENCODED_LEN];
        let mut w = Writer {
            buf: &mut buf,
            pos: 0,
        };
        w.bytes(&MAGIC);
        w.bytes(&FORMAT_VERSION.to_le_bytes());
        w.bytes(&[0, 0]);
        w.bytes(&(PAYLOAD_LEN as u32).to_le_bytes());
        w.bytes(&self.serial);
        w.bytes(&self.date.year.to_le_bytes());
        w.bytes(&[self.date.month, self.date.day]);
        let t = &self.thermal;
        w.f64(t.scale.min.0);
        w.f64(t.scale.max.0);
        w.f64(t.scale.center.0);
        w.f64(t.scale.half_span_c);
        w.f64(t.reference.0);
        let m = &t.models;
        for p in [
            &m.bias_g,
            &m.scale_factor_v_per_g,
            &m.nonlinearity_g_per_g2,
            &m.misalignment_p_rad,
            &m.misalignment_o_rad,
        ] {
            w.poly(p);
        }
        w.f64(self.tilt.reference.0);
        w.f64(self.tilt.scale_arcsec_per_v);
        w.bytes(&[self.tilt.axis as u8]);
        w.f64(self.rtd.cvd.r0);
        w.f64(self.rtd.cvd.a);
        w.f64(self.rtd.cvd.b);
        w.f64(self.rtd.cvd.c);
        w.f64(self.rtd.reference_resistor.0);
        w.f64(self.rtd.adc_gain_correction);
        w.f64(self.rtd.pga_gain);
        w.f64(self.accel.adc_gain_correction);
        w.f64(self.accel.adc_offset.0);
        w.f64(self.accel.sense_resistor.0);
        w.f64(self.tilt.adc_gain_correction);
        w.f64(self.tilt.adc_offset.0);
        w.f64(self.orientation.cross.a_p.0);
        w.f64(self.orientation.cross.a_o.0);
        w.f64(self.orientation.nominal_input.0);
        let crc_at = w.pos;
        let crc = CRC32.checksum(buf.get(..crc_at).unwrap_or(&[]));
        if let Some(dst) = buf.get_mut(crc_at..crc_at + 4) {
            dst.copy_from_slice(&crc.to_le_bytes());
        }
        buf
    }

    /// The table id: the CRC-32 of its encoding.
    pub fn id(&self) -> u32 {
        table_id(&self.encode())
    }

    /// Decodes and validates a table. Checks, in order: magic, version, length, CRC, then every
    /// field (finite numbers, orders, ranges, plausibility).
    pub fn decode(bytes: &[u8]) -> Result<Self, TableError> {
        let mut r = Reader { buf: bytes, pos: 0 };
        if r.take::<4>()? != MAGIC {
            return Err(TableError::BadMagic);
        }
        let version = r.u16()?;
        if version != FORMAT_VERSION {
            return Err(TableError::UnsupportedVersion(version));
        }
        let reserved = r.u16()?;
        if reserved != 0 {
            return Err(TableError::Reserved(reserved));
        }
        let payload_len = r.u32()?;
        if payload_len != PAYLOAD_LEN as u32 || bytes.len() != ENCODED_LEN {
            // The length that is wrong: the byte count when the header is right (a truncated
            // or padded file), else what the header claims.
            let found = if payload_len == PAYLOAD_LEN as u32 {
                bytes.len()
            } else {
                (payload_len as usize).saturating_add(HEADER_LEN + 4)
            };
            return Err(TableError::BadLength {
                expected: ENCODED_LEN as u32,
                found: found.min(u32::MAX as usize) as u32,
            });
        }
        let body = bytes.get(..ENCODED_LEN - 4).ok_or(TableError::BadLength {
            expected: ENCODED_LEN as u32,
            found: bytes.len() as u32,
        })?;
        let mut crc_bytes = [0u8; 4];
        if let Some(src) = bytes.get(ENCODED_LEN - 4..ENCODED_LEN) {
            crc_bytes.copy_from_slice(src);
        }
        let stored = u32::from_le_bytes(crc_bytes);
        let computed = CRC32.checksum(body);
        if stored != computed {
            return Err(TableError::BadCrc { stored, computed });
        }
        let serial = r.take::<SERIAL_LEN>()?;
        let date = CalibrationDate {
            year: r.u16()?,
            month: r.u8()?,
            day: r.u8()?,
        };
        let min = Celsius(r.f64(Field::TemperatureScale)?);
        let max = Celsius(r.f64(Field::TemperatureScale)?);
        let center = Celsius(r.f64(Field::TemperatureScale)?);
        let half_span_c = r.f64(Field::TemperatureScale)?;
        let reference = Celsius(r.f64(Field::ReferenceTemperature)?);
        let models = CoefficientModels {
            bias_g: r.poly(Coefficient::Bias)?,
            scale_factor_v_per_g: r.poly(Coefficient::ScaleFactor)?,
            nonlinearity_g_per_g2: r.poly(Coefficient::Nonlinearity)?,
            misalignment_p_rad: r.poly(Coefficient::MisalignmentP)?,
            misalignment_o_rad: r.poly(Coefficient::MisalignmentO)?,
        };
        let tilt_reference = TiltArcsec(r.f64(Field::Tilt)?);
        let tilt_scale = r.f64(Field::Tilt)?;
        let axis = match r.u8()? {
            0 => TiltAxis::Input,
            1 => TiltAxis::InputReversed,
            2 => TiltAxis::None,
            _ => return Err(TableError::TiltAxis),
        };
        let cvd = CallendarVanDusen {
            r0: r.f64(Field::Rtd)?,
            a: r.f64(Field::Rtd)?,
            b: r.f64(Field::Rtd)?,
            c: r.f64(Field::Rtd)?,
        };
        let rtd = RtdConfig {
            cvd,
            reference_resistor: Ohms(r.f64(Field::Rtd)?),
            adc_gain_correction: r.f64(Field::Adc)?,
            pga_gain: r.f64(Field::Adc)?,
        };
        let accel = AccelChannel {
            adc_gain_correction: r.f64(Field::Adc)?,
            adc_offset: Volts(r.f64(Field::Adc)?),
            sense_resistor: Ohms(r.f64(Field::Adc)?),
        };
        let tilt = TiltConfig {
            reference: tilt_reference,
            scale_arcsec_per_v: tilt_scale,
            axis,
            adc_gain_correction: r.f64(Field::Adc)?,
            adc_offset: Volts(r.f64(Field::Adc)?),
        };
        let orientation = Orientation {
            cross: CrossAxis {
                a_p: Gs(r.f64(Field::Orientation)?),
                a_o: Gs(r.f64(Field::Orientation)?),
            },
            nominal_input: Gs(r.f64(Field::Orientation)?),
        };
        let table = CalibrationTable {
            serial,
            date,
            thermal: ThermalCompensator {
                scale: TemperatureScale {
                    min,
                    max,
                    center,
                    half_span_c,
                },
                reference,
                models,
            },
            tilt,
            rtd,
            accel,
            orientation,
        };
        table.validate()?;
        Ok(table)
    }

    /// Checks every field for plausibility (also run by [`CalibrationTable::decode`]).
    pub fn validate(&self) -> Result<(), TableError> {
        self.serial_str()?;
        let d = self.date;
        if !(2000..=2200).contains(&d.year)
            || !(1..=12).contains(&d.month)
            || !(1..=31).contains(&d.day)
        {
            return Err(TableError::Date);
        }
        let s = &self.thermal.scale;
        for v in [s.min.0, s.max.0, s.center.0, s.half_span_c] {
            if !v.is_finite() {
                return Err(TableError::NonFinite(Field::TemperatureScale));
            }
        }
        if s.max.0 <= s.min.0 || s.half_span_c <= 0.0 {
            return Err(TableError::EmptyRange);
        }
        let (rtd_lo, rtd_hi) = bounds::RTD_RANGE_C;
        if s.min.0 < rtd_lo
            || s.max.0 > rtd_hi
            || s.center.0 < s.min.0
            || s.center.0 > s.max.0
            || s.half_span_c > rtd_hi - rtd_lo
        {
            return Err(TableError::OutOfBounds(Field::TemperatureScale));
        }
        let t0 = self.thermal.reference.0;
        if !t0.is_finite() {
            return Err(TableError::NonFinite(Field::ReferenceTemperature));
        }
        if t0 < s.min.0 || t0 > s.max.0 {
            return Err(TableError::ReferenceOutsideRange);
        }
        let m = &self.thermal.models;
        for (which, p) in [
            (Coefficient::Bias, &m.bias_g),
            (Coefficient::ScaleFactor, &m.scale_factor_v_per_g),
            (Coefficient::Nonlinearity, &m.nonlinearity_g_per_g2),
            (Coefficient::MisalignmentP, &m.misalignment_p_rad),
            (Coefficient::MisalignmentO, &m.misalignment_o_rad),
        ] {
            if !p.is_finite() {
                return Err(TableError::NonFinite(Field::Polynomial(which)));
            }
        }
        // Every model must stay inside its bounds over the whole range, not only at its ends:
        // sample densely (a quartic has at most three extrema; 65 points also bound it between
        // samples to well within the margins of the bounds).
        for i in 0..=64 {
            let t = s.min.0 + (s.max.0 - s.min.0) * f64::from(i) / 64.0;
            let x = s.x_unclamped(Celsius(t));
            let k1 = m.scale_factor_v_per_g.eval(x);
            if !(0.01..=100.0).contains(&k1) {
                return Err(TableError::ScaleFactorImplausible);
            }
            for (which, p, bound) in [
                (Coefficient::Bias, &m.bias_g, bounds::MAX_BIAS_G),
                (
                    Coefficient::Nonlinearity,
                    &m.nonlinearity_g_per_g2,
                    bounds::MAX_NONLINEARITY_G_PER_G2,
                ),
                (
                    Coefficient::MisalignmentP,
                    &m.misalignment_p_rad,
                    bounds::MAX_MISALIGNMENT_RAD,
                ),
                (
                    Coefficient::MisalignmentO,
                    &m.misalignment_o_rad,
                    bounds::MAX_MISALIGNMENT_RAD,
                ),
            ] {
                // Also refuses a NaN from an overflowing evaluation.
                let v = libm::fabs(p.eval(x));
                if v.is_nan() || v > bound {
                    return Err(TableError::OutOfBounds(Field::Polynomial(which)));
                }
            }
        }
        if self.rtd.cvd.validate().is_err()
            || !(self.rtd.reference_resistor.0.is_finite()
                && (10.0..=1e6).contains(&self.rtd.reference_resistor.0))
        {
            return Err(TableError::RtdConstants);
        }
        let near_one = |g: f64| g.is_finite() && (0.5..=2.0).contains(&g);
        let small = |v: f64| v.is_finite() && libm::fabs(v) <= 1.0;
        let pga_ok = [1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0, 128.0].contains(&self.rtd.pga_gain);
        if !(near_one(self.rtd.adc_gain_correction)
            && pga_ok
            && near_one(self.accel.adc_gain_correction)
            && small(self.accel.adc_offset.0)
            && self.accel.sense_resistor.0.is_finite()
            && (1.0..=1e6).contains(&self.accel.sense_resistor.0)
            && near_one(self.tilt.adc_gain_correction)
            && small(self.tilt.adc_offset.0)
            && self.tilt.scale_arcsec_per_v.is_finite()
            && self.tilt.scale_arcsec_per_v != 0.0)
        {
            return Err(TableError::AdcConstants);
        }
        if !self.tilt.reference.0.is_finite() {
            return Err(TableError::NonFinite(Field::Tilt));
        }
        let (tilt_lo, tilt_hi) = bounds::TILT_SCALE_ARCSEC_PER_V;
        let tilt_scale = libm::fabs(self.tilt.scale_arcsec_per_v);
        if !(tilt_lo..=tilt_hi).contains(&tilt_scale)
            || libm::fabs(self.tilt.reference.0) > bounds::MAX_TILT_REFERENCE_ARCSEC
        {
            return Err(TableError::OutOfBounds(Field::Tilt));
        }
        let o = &self.orientation;
        for v in [o.cross.a_p.0, o.cross.a_o.0, o.nominal_input.0] {
            if !v.is_finite() || libm::fabs(v) > 2.0 {
                return Err(TableError::NonFinite(Field::Orientation));
            }
        }
        Ok(())
    }
}

/// The id (CRC-32) of an encoded table, read from its last four bytes.
pub fn table_id(encoded: &[u8; ENCODED_LEN]) -> u32 {
    let mut b = [0u8; 4];
    if let Some(src) = encoded.get(ENCODED_LEN - 4..) {
        b.copy_from_slice(src);
    }
    u32::from_le_bytes(b)
}

impl core::fmt::Display for Coefficient {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Coefficient::Bias => "K0 (bias)",
            Coefficient::ScaleFactor => "K1 (scale factor)",
            Coefficient::Nonlinearity => "K2 (nonlinearity)",
            Coefficient::MisalignmentP => "δp (misalignment about the pendulum axis)",
            Coefficient::MisalignmentO => "δo (misalignment about the output axis)",
        })
    }
}

impl core::fmt::Display for TableError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            TableError::BadMagic => f.write_str("bad magic: not an accomp calibration table"),
            TableError::UnsupportedVersion(v) => write!(f, "unsupported format version {v}"),
            TableError::BadLength { expected, found } => {
                write!(f, "bad length: expected {expected} bytes, found {found}")
            }
            TableError::BadCrc { stored, computed } => {
                write!(
                    f,
                    "bad CRC: stored {stored:#010x}, computed {computed:#010x}"
                )
            }
            TableError::NonFinite(field) => write!(f, "non-finite number in {field:?}"),
            TableError::OrderTooHigh(c) => write!(f, "polynomial order above 4 in {c}"),
            TableError::EmptyRange => f.write_str("empty or inverted calibrated temperature range"),
            TableError::ReferenceOutsideRange => {
                f.write_str("reference temperature T0 outside the calibrated range")
            }
            TableError::ScaleFactorImplausible => {
                f.write_str("scale factor K1 not within 0.01–100 V/g over the calibrated range")
            }
            TableError::RtdConstants => f.write_str("RTD constants out of range for platinum"),
            TableError::AdcConstants => {
                f.write_str("ADC corrections or resistor values out of range")
            }
            TableError::Serial => f.write_str("serial number is not UTF-8"),
            TableError::Date => f.write_str("calibration date is not a calendar date"),
            TableError::TiltAxis => f.write_str("unknown tilt axis code"),
            TableError::Reserved(v) => write!(f, "reserved header field is {v:#06x}, not 0"),
            TableError::OutOfBounds(field) => write!(
                f,
                "{field:?} outside its physical bounds (docs/calibration-format.md)"
            ),
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A table with the paper's printed order-2 models, as a fixture for tests.
    pub(crate) fn paper_table() -> CalibrationTable {
        crate::reference::paper_order2_table()
    }

    fn reseal(b: &mut [u8; ENCODED_LEN]) {
        let crc = CRC32.checksum(&b[..ENCODED_LEN - 4]);
        b[ENCODED_LEN - 4..].copy_from_slice(&crc.to_le_bytes());
    }

    #[test]
    fn encode_decode_round_trip_is_bit_exact() {
        let t = paper_table();
        let b = t.encode();
        assert_eq!(&b[..4], b"ACAL");
        assert_eq!(CalibrationTable::decode(&b), Ok(t));
        assert_eq!(t.serial_str(), Ok("JN-06 A12124"));
        // The id is the standard CRC-32 of the body: check with the published check value
        // algorithm on a known string first, then against the trailer.
        assert_eq!(CRC32.checksum(b"123456789"), 0xCBF4_3926);
        assert_eq!(
            t.id(),
            u32::from_le_bytes(b[ENCODED_LEN - 4..].try_into().unwrap())
        );
    }

    #[test]
    fn every_single_bit_flip_is_refused() {
        let b = paper_table().encode();
        for byte in 0..ENCODED_LEN {
            for bit in 0..8 {
                let mut c = b;
                c[byte] ^= 1 << bit;
                assert!(
                    CalibrationTable::decode(&c).is_err(),
                    "flip at {byte}:{bit} accepted"
                );
            }
        }
    }

    #[test]
    fn header_errors_are_named() {
        let b = paper_table().encode();
        let mut c = b;
        c[0] = b'X';
        assert_eq!(CalibrationTable::decode(&c), Err(TableError::BadMagic));
        let mut c = b;
        c[4] = 2;
        assert_eq!(
            CalibrationTable::decode(&c),
            Err(TableError::UnsupportedVersion(2))
        );
        assert!(matches!(
            CalibrationTable::decode(&b[..ENCODED_LEN - 1]),
            Err(TableError::BadLength { .. })
        ));
        let mut c = b;
        c[40] ^= 0x10;
        assert!(matches!(
            CalibrationTable::decode(&c),
            Err(TableError::BadCrc { .. })
        ));
    }

    #[test]
    fn nan_coefficient_with_a_valid_crc_is_refused_by_name() {
        let mut t = paper_table();
        t.thermal.models.bias_g.coeffs[1] = f64::NAN;
        let b = t.encode();
        assert_eq!(
            CalibrationTable::decode(&b),
            Err(TableError::NonFinite(Field::Polynomial(Coefficient::Bias)))
        );
    }

    #[test]
    fn implausible_content_is_refused_by_name() {
        let mut t = paper_table();
        t.thermal.scale.max = Celsius(20.0);
        assert_eq!(
            CalibrationTable::decode(&t.encode()),
            Err(TableError::EmptyRange)
        );
        let mut t = paper_table();
        t.thermal.models.scale_factor_v_per_g = TempPoly::constant(-1.3);
        assert_eq!(
            CalibrationTable::decode(&t.encode()),
            Err(TableError::ScaleFactorImplausible)
        );
        let mut t = paper_table();
        t.rtd.cvd.a = 0.05;
        assert_eq!(
            CalibrationTable::decode(&t.encode()),
            Err(TableError::RtdConstants)
        );
        let mut t = paper_table();
        t.thermal.reference = Celsius(70.0);
        assert_eq!(
            CalibrationTable::decode(&t.encode()),
            Err(TableError::ReferenceOutsideRange)
        );
    }

    #[test]
    fn order_byte_above_four_or_hidden_high_coefficients_are_refused() {
        let mut b = paper_table().encode();
        // The bias polynomial's order byte follows serial, date and the five scale f64s.
        let at = HEADER_LEN + SERIAL_LEN + 4 + 40;
        assert_eq!(b[at], 2);
        b[at] = 5;
        reseal(&mut b);
        assert_eq!(
            CalibrationTable::decode(&b),
            Err(TableError::OrderTooHigh(Coefficient::Bias))
        );
        b[at] = 1; // says order 1 but c2 is non-zero
        reseal(&mut b);
        assert_eq!(
            CalibrationTable::decode(&b),
            Err(TableError::OrderTooHigh(Coefficient::Bias))
        );
    }
}

/// Bounded fuzzing of the validator inside `cargo test` (and so `cargo xtask test`): the
/// cargo-fuzz target `fuzz/fuzz_targets/table_decode.rs` runs the same properties unbounded.
#[cfg(test)]
mod robustness {
    use super::tests::paper_table;
    use super::*;
    use core::sync::atomic::{AtomicU64, Ordering};
    use proptest::prelude::*;
    use proptest::test_runner::{Config, TestRunner};

    /// Cases per property: the issue asks for at least 100 000.
    const CASES: u32 = 100_000;

    fn runner() -> TestRunner {
        // Explicit case count: PROPTEST_CASES in the environment cannot lower it.
        TestRunner::new(Config {
            cases: CASES,
            failure_persistence: None,
            ..Config::default()
        })
    }

    /// Rewrites the CRC so that a mutation reaches the field checks behind it.
    fn fix_crc(bytes: &mut [u8; ENCODED_LEN]) {
        let crc = CRC32.checksum(&bytes[..ENCODED_LEN - 4]);
        bytes[ENCODED_LEN - 4..].copy_from_slice(&crc.to_le_bytes());
    }

    /// The property every input must satisfy: refused with a `TableError` (a named error by
    /// construction), or decoded to a table whose encoding is exactly the input, so nothing
    /// the device accepts differs from what it will store, read back and report as its id.
    fn check(bytes: &[u8]) -> Result<Option<CalibrationTable>, TestCaseError> {
        match CalibrationTable::decode(bytes) {
            Ok(t) => {
                prop_assert_eq!(
                    &t.encode()[..],
                    bytes,
                    "accepted but re-encodes differently"
                );
                Ok(Some(t))
            }
            Err(_) => Ok(None),
        }
    }

    #[test]
    fn random_bytes_are_refused_without_panicking() {
        let count = AtomicU64::new(0);
        let accepted = AtomicU64::new(0);
        // Half the inputs carry a valid header and CRC so they reach the field checks.
        let strategy = (
            proptest::collection::vec(any::<u8>(), 0..2 * ENCODED_LEN),
            any::<bool>(),
        );
        runner()
            .run(&strategy, |(mut bytes, framed)| {
                count.fetch_add(1, Ordering::Relaxed);
                if framed {
                    bytes.resize(ENCODED_LEN, 0);
                    let mut b = [0u8; ENCODED_LEN];
                    b.copy_from_slice(&bytes);
                    b[..4].copy_from_slice(&MAGIC);
                    b[4..6].copy_from_slice(&FORMAT_VERSION.to_le_bytes());
                    b[6..8].copy_from_slice(&[0, 0]);
                    b[8..12].copy_from_slice(&(PAYLOAD_LEN as u32).to_le_bytes());
                    fix_crc(&mut b);
                    bytes = b.to_vec();
                }
                if check(&bytes)?.is_some() {
                    accepted.fetch_add(1, Ordering::Relaxed);
                }
                Ok(())
            })
            .unwrap();
        assert_eq!(count.load(Ordering::Relaxed), u64::from(CASES));
        // Random doubles are never a plausible calibration.
        assert_eq!(accepted.load(Ordering::Relaxed), 0);
    }

    #[test]
    fn every_mutation_of_a_valid_table_is_identical_or_refused() {
        let original = paper_table().encode();
        let count = AtomicU64::new(0);
        let reached_fields = AtomicU64::new(0);
        let strategy = (
            proptest::collection::vec((0..ENCODED_LEN, any::<u8>(), any::<bool>()), 1..6),
            any::<bool>(),
            0..=ENCODED_LEN + 8,
        );
        runner()
            .run(&strategy, |(edits, recrc, len)| {
                count.fetch_add(1, Ordering::Relaxed);
                let mut b = original;
                for (at, value, flip_one_bit) in edits {
                    // Single-bit flips (line noise) and whole-byte overwrites.
                    b[at] = if flip_one_bit {
                        b[at] ^ (1 << (value % 8))
                    } else {
                        value
                    };
                }
                if recrc {
                    fix_crc(&mut b);
                }
                let mut bytes = b.to_vec();
                // One case in ~ENCODED_LEN keeps the length; the others truncate or extend.
                if len != ENCODED_LEN && len % 4 == 0 {
                    bytes.resize(len, 0xA5);
                }
                let decoded = check(&bytes)?;
                match CalibrationTable::decode(&bytes) {
                    Err(TableError::BadCrc { .. } | TableError::BadLength { .. }) => {}
                    Err(_) => {
                        reached_fields.fetch_add(1, Ordering::Relaxed);
                    }
                    Ok(_) => {
                        reached_fields.fetch_add(1, Ordering::Relaxed);
                    }
                }
                if !recrc && bytes.len() == ENCODED_LEN {
                    // Without a CRC fix only a no-op mutation may pass.
                    if let Some(t) = decoded {
                        prop_assert_eq!(t.encode(), original);
                    }
                }
                Ok(())
            })
            .unwrap();
        assert_eq!(count.load(Ordering::Relaxed), u64::from(CASES));
        // The CRC-fixed half must exercise the field checks, not stop at the CRC.
        assert!(reached_fields.load(Ordering::Relaxed) > u64::from(CASES) / 4);
    }
}
