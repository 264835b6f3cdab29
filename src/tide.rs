//! Solid-earth tide: the change of gravity and the tilt of the ground at a station, from a
//! low-precision analytic ephemeris of the Moon and the Sun.
//!
//! Used by the station simulator (tilt disturbs the 0 g position, gravity the 1 g logs) and by
//! the model discovery (`tidal_gravity`, `tidal_tilt` effects). The model, its constants, the
//! sign conventions and the agreement reached against ETERNA are written up in `docs/tide.md`.
//!
//! The computation is direct rather than harmonic: the Moon (Meeus ch. 47, ELP-2000/82 truncated)
//! and the Sun (Meeus ch. 25) are placed in the equatorial frame of date, the Earth is turned by
//! the mean sidereal time, and the gradient of the degree-2 (Moon and Sun) and degree-3 (Moon)
//! tide-generating potential is taken at the station's geocentric position. The elastic Earth
//! enters through the gravimetric factor δ = 1 + h − 3k/2 and the tilt factor γ = 1 + k − h,
//! split by tidal species so that each band gets its own Love numbers, with the free-core-nutation
//! resonance applied to the K1 line. No catalogue is stored, so the model is small enough for the
//! MCU and fast on the host.
//!
//! Everything is f64: the potential is a difference of large numbers only in the ephemeris
//! arguments (centuries × 481 267 °), and f32 would lose the Moon's position there.

use crate::units::{Gs, Radians, TiltArcsec, RAD_PER_ARCSEC};
use libm::{atan2, cos, fabs, floor, sin, sqrt};

// ---------------------------------------------------------------------------------------------
// Constants
// ---------------------------------------------------------------------------------------------

/// Julian date of the Unix epoch, 1970-01-01 00:00 UTC.
pub const UNIX_EPOCH_JD: f64 = 2_440_587.5;
/// Julian date of J2000.0 (2000-01-01 12:00 TT), the epoch of the ephemeris series.
pub const J2000_JD: f64 = 2_451_545.0;
/// Seconds in a (UTC calendar) day; Unix time has no leap seconds.
pub const SECONDS_PER_DAY: f64 = 86_400.0;
/// Days in a Julian century, the time unit of the ephemeris series.
pub const DAYS_PER_CENTURY: f64 = 36_525.0;
/// TT − UTC used to enter the ephemeris, seconds (37 leap seconds + 32.184 s, valid since 2017).
///
/// Why a constant is enough: before 2017 it is too large by at most 37 s, during which the Moon
/// moves < 20″; the tide changes by < 0.01 % (see `docs/tide.md`).
pub const TT_MINUS_UTC_S: f64 = 69.184;

/// Milliarcseconds per radian (648 000 000 / π).
pub const MAS_PER_RAD: f64 = 1.0e3 / RAD_PER_ARCSEC;
/// Standard gravity (m/s²), the unit behind [`Gs`].
pub const STANDARD_GRAVITY_M_S2: f64 = 9.806_65;
/// Nanometres per second squared in one m/s².
pub const NM_S2_PER_M_S2: f64 = 1.0e9;

/// Geocentric gravitational constant of the Moon, m³/s² (DE430: 4902.800066 km³/s²).
pub const GM_MOON_M3_S2: f64 = 4.902_800_066e12;
/// Heliocentric gravitational constant, m³/s² (IERS 2010).
pub const GM_SUN_M3_S2: f64 = 1.327_124_420_99e20;
/// Astronomical unit, m (IAU 2012).
pub const AU_M: f64 = 1.495_978_707e11;

/// GRS80 semi-major axis, m.
pub const GRS80_A_M: f64 = 6_378_137.0;
/// GRS80 first eccentricity squared.
pub const GRS80_E2: f64 = 0.006_694_380_022_90;
/// GRS80 normal gravity at the equator, m/s² (Somigliana).
const GRS80_GAMMA_E_M_S2: f64 = 9.780_326_771_5;
/// GRS80 Somigliana constant k = (b γ_p − a γ_e) / (a γ_e).
const GRS80_SOMIGLIANA_K: f64 = 0.001_931_851_353;
/// Free-air gradient of normal gravity, (m/s²)/m.
const FREE_AIR_GRADIENT_PER_M: f64 = 3.086e-6;

const DEG: f64 = core::f64::consts::PI / 180.0;
const TWO_PI: f64 = 2.0 * core::f64::consts::PI;

// ---------------------------------------------------------------------------------------------
// Love numbers (body tide, Dehant–Defraigne–Wahr 1999 inelastic non-hydrostatic, the values
// ETERNA 3.4 uses). Index by species: long-period (2,0), diurnal (2,1), semidiurnal (2,2).
// ---------------------------------------------------------------------------------------------

/// Gravimetric factor δ = 1 + h − 3k/2 at the equator-free reference, per degree-2 species.
pub const DELTA_2: [f64; 3] = [1.1576, 1.1542, 1.1600];
/// Gravimetric factor for degree 3 (all orders).
pub const DELTA_3: f64 = 1.0728;
/// Love number h per degree-2 species.
pub const LOVE_H_2: [f64; 3] = [0.6165, 0.6069, 0.6133];
/// Love number k per degree-2 species.
pub const LOVE_K_2: [f64; 3] = [0.3068, 0.3009, 0.3034];
/// Love numbers h and k for degree 3.
pub const LOVE_HK_3: (f64, f64) = (0.2946, 0.0942);
/// Latitude coefficients of δ: (2,0) "+" and "−" terms, (2,1) "+", (2,2) "+".
const DELTA_20_PLUS: f64 = -0.0016;
const DELTA_20_MINUS: f64 = 0.0054;
const DELTA_21_PLUS: f64 = -0.0018;
const DELTA_22_PLUS: f64 = -0.0010;
/// Latitude coefficients of γ = 1 + k − h: (k+ − h+) for (2,1) and (2,2).
const GAMMA_21_PLUS: f64 = 0.0014 - 0.0007;
const GAMMA_22_PLUS: f64 = 0.0009 - 0.0005;
/// Free-core-nutation resonance: δ(ω) = δ(O1) + DELTA_FCN·(ω − ω_O1)/(ω_FCN − ω), ω in °/h.
const DELTA_FCN: f64 = -0.000_625;
/// Same for γ (k_r − h_r = −0.001261 + 0.002505).
const GAMMA_FCN: f64 = -0.001_261 + 0.002_505;
/// Angular frequencies, °/h: O1 (reference of the resonance), K1, FCN (space-fixed).
const OMEGA_O1_DEG_H: f64 = 13.943_036;
const OMEGA_K1_DEG_H: f64 = 15.041_069;
const OMEGA_FCN_DEG_H: f64 = 15.073_729;

// ---------------------------------------------------------------------------------------------
// Errors
// ---------------------------------------------------------------------------------------------

/// What was wrong with an input to the tide model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TideError {
    /// Month outside 1..=12.
    MonthOutOfRange,
    /// Day outside the month (leap years are known).
    DayOutOfRange,
    /// Hour ≥ 24, minute ≥ 60 or second outside 0 ≤ s < 61 (61 allows a leap second).
    TimeOfDayOutOfRange,
    /// Year outside 1600..=2400, where the Gregorian calendar and the ephemeris both hold.
    YearOutOfRange,
    /// Latitude outside −90..=90°.
    LatitudeOutOfRange,
    /// Height outside −11 000..=100 000 m (a typo, not a station).
    HeightOutOfRange,
    /// A NaN or infinite input.
    NotFinite,
    /// Series sample interval not strictly positive.
    IntervalNotPositive,
}

// ---------------------------------------------------------------------------------------------
// Time
// ---------------------------------------------------------------------------------------------

/// A UTC calendar instant (Gregorian calendar), without a parser: fill the fields.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UtcTime {
    /// Year, e.g. 2024.
    pub year: i32,
    /// Month 1..=12.
    pub month: u8,
    /// Day of month 1..=31.
    pub day: u8,
    /// Hour 0..=23.
    pub hour: u8,
    /// Minute 0..=59.
    pub minute: u8,
    /// Seconds, 0 ≤ s < 61.
    pub second: f64,
}

fn is_leap_year(year: i32) -> bool {
    (year % 4 == 0 && year % 100 != 0) || year % 400 == 0
}

fn days_in_month(year: i32, month: u8) -> u8 {
    match month {
        1 | 3 | 5 | 7 | 8 | 10 | 12 => 31,
        4 | 6 | 9 | 11 => 30,
        2 if is_leap_year(year) => 29,
        2 => 28,
        _ => 0,
    }
}

impl UtcTime {
    /// A checked calendar instant.
    pub fn new(
        year: i32,
        month: u8,
        day: u8,
        hour: u8,
        minute: u8,
        second: f64,
    ) -> Result<Self, TideError> {
        if !second.is_finite() {
            return Err(TideError::NotFinite);
        }
        if !(1600..=2400).contains(&year) {
            return Err(TideError::YearOutOfRange);
        }
        if !(1..=12).contains(&month) {
            return Err(TideError::MonthOutOfRange);
        }
        if day == 0 || day > days_in_month(year, month) {
            return Err(TideError::DayOutOfRange);
        }
        if hour > 23 || minute > 59 || !(0.0..61.0).contains(&second) {
            return Err(TideError::TimeOfDayOutOfRange);
        }
        Ok(Self {
            year,
            month,
            day,
            hour,
            minute,
            second,
        })
    }

    /// Julian date (UTC-based) of this instant.
    ///
    /// Integer day number by the Fliegel–Van Flandern formula (all quotients are of positive
    /// numbers for years after −4800, so Rust's truncating division is the floor it needs).
    pub fn julian_date(&self) -> f64 {
        let a = (14 - i64::from(self.month)) / 12;
        let y = i64::from(self.year) + 4800 - a;
        let m = i64::from(self.month) + 12 * a - 3;
        let jdn =
            i64::from(self.day) + (153 * m + 2) / 5 + 365 * y + y / 4 - y / 100 + y / 400 - 32_045;
        let day_fraction =
            (f64::from(self.hour) * 3600.0 + f64::from(self.minute) * 60.0 + self.second)
                / SECONDS_PER_DAY;
        jdn as f64 - 0.5 + day_fraction
    }

    /// Seconds since 1970-01-01 00:00 UTC (Unix time, no leap seconds).
    pub fn unix_seconds(&self) -> f64 {
        unix_seconds_from_julian_date(self.julian_date())
    }
}

/// Julian date (UTC-based) of a Unix time in seconds.
#[inline]
pub fn julian_date_from_unix_seconds(unix_s: f64) -> f64 {
    UNIX_EPOCH_JD + unix_s / SECONDS_PER_DAY
}

/// Unix time in seconds of a Julian date (UTC-based).
#[inline]
pub fn unix_seconds_from_julian_date(jd: f64) -> f64 {
    (jd - UNIX_EPOCH_JD) * SECONDS_PER_DAY
}

/// Greenwich mean sidereal time (IAU 1982, Meeus eq. 12.4) in radians, 0..2π.
///
/// UT1 is taken equal to UTC: |UT1 − UTC| < 0.9 s turns the Earth by < 0.004°, a < 0.02 %
/// change of the semidiurnal tide.
pub fn gmst_rad(jd_ut1: f64) -> f64 {
    // Split whole days from the fraction so that 360.98…° × days keeps its precision.
    let d = jd_ut1 - J2000_JD;
    let whole = floor(d);
    let frac = d - whole;
    let t = d / DAYS_PER_CENTURY;
    let deg = 280.460_618_37 + 360.0 * frac + 0.985_647_366_29 * d + 0.000_387_933 * t * t
        - t * t * t / 38_710_000.0;
    let rad = (deg % 360.0) * DEG;
    if rad < 0.0 {
        rad + TWO_PI
    } else {
        rad
    }
}

// ---------------------------------------------------------------------------------------------
// Ephemeris
// ---------------------------------------------------------------------------------------------

/// Ecliptic coordinates of a body, mean equinox of date.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EclipticPosition {
    /// Longitude, radians.
    pub longitude_rad: f64,
    /// Latitude, radians.
    pub latitude_rad: f64,
    /// Geocentric distance, metres.
    pub distance_m: f64,
}

/// One periodic term of Meeus Table 47.A: multipliers of D, M, M′, F, then Σl (1e-6°) and
/// Σr (1e-3 km).
type LrTerm = (i8, i8, i8, i8, i32, i32);
/// One periodic term of Meeus Table 47.B: multipliers of D, M, M′, F, then Σb (1e-6°).
type BTerm = (i8, i8, i8, i8, i32);

/// ELP-2000/82 as truncated by Meeus (Table 47.A), further cut to |Σl| ≥ 0.0005° or
/// |Σr| ≥ 2 km: the dropped terms sum to < 0.005° and < 10 km (2.6e-5 relative), both far
/// below what the tide needs (docs/tide.md).
const MOON_LR: [LrTerm; 44] = [
    (0, 0, 1, 0, 6_288_774, -20_905_355),
    (2, 0, -1, 0, 1_274_027, -3_699_111),
    (2, 0, 0, 0, 658_314, -2_955_968),
    (0, 0, 2, 0, 213_618, -569_925),
    (0, 1, 0, 0, -185_116, 48_888),
    (0, 0, 0, 2, -114_332, -3_149),
    (2, 0, -2, 0, 58_793, 246_158),
    (2, -1, -1, 0, 57_066, -152_138),
    (2, 0, 1, 0, 53_322, -170_733),
    (2, -1, 0, 0, 45_758, -204_586),
    (0, 1, -1, 0, -40_923, -129_620),
    (1, 0, 0, 0, -34_720, 108_743),
    (0, 1, 1, 0, -30_383, 104_755),
    (2, 0, 0, -2, 15_327, 10_321),
    (0, 0, 1, 2, -12_528, 0),
    (0, 0, 1, -2, 10_980, 79_661),
    (4, 0, -1, 0, 10_675, -34_782),
    (0, 0, 3, 0, 10_034, -23_210),
    (4, 0, -2, 0, 8_548, -21_636),
    (2, 1, -1, 0, -7_888, 24_208),
    (2, 1, 0, 0, -6_766, 30_824),
    (1, 0, -1, 0, -5_163, -8_379),
    (1, 1, 0, 0, 4_987, -16_675),
    (2, -1, 1, 0, 4_036, -12_831),
    (2, 0, 2, 0, 3_994, -10_445),
    (4, 0, 0, 0, 3_861, -11_650),
    (2, 0, -3, 0, 3_665, 14_403),
    (0, 1, -2, 0, -2_689, -7_003),
    (2, 0, -1, 2, -2_602, 0),
    (2, -1, -2, 0, 2_390, 10_056),
    (1, 0, 1, 0, -2_348, 6_322),
    (2, -2, 0, 0, 2_236, -9_884),
    (0, 1, 2, 0, -2_120, 5_751),
    (0, 2, 0, 0, -2_069, 0),
    (2, -2, -1, 0, 2_048, -4_950),
    (2, 0, 1, -2, -1_773, 4_130),
    (2, 0, 0, 2, -1_595, 0),
    (4, -1, -1, 0, 1_215, -3_958),
    (0, 0, 2, 2, -1_110, 0),
    (3, 0, -1, 0, -892, 3_258),
    (2, 1, 1, 0, -810, 2_616),
    (4, -1, -2, 0, 759, -1_897),
    (0, 2, -1, 0, -713, -2_117),
    (2, 0, -1, -2, 0, 8_752),
];

/// Meeus Table 47.B cut to |Σb| ≥ 0.001° (dropped terms sum to < 0.005°).
const MOON_B: [BTerm; 28] = [
    (0, 0, 0, 1, 5_128_122),
    (0, 0, 1, 1, 280_602),
    (0, 0, 1, -1, 277_693),
    (2, 0, 0, -1, 173_237),
    (2, 0, -1, 1, 55_413),
    (2, 0, -1, -1, 46_271),
    (2, 0, 0, 1, 32_573),
    (0, 0, 2, 1, 17_198),
    (2, 0, 1, -1, 9_266),
    (0, 0, 2, -1, 8_822),
    (2, -1, 0, -1, 8_216),
    (2, 0, -2, -1, 4_324),
    (2, 0, 1, 1, 4_200),
    (2, 1, 0, -1, -3_359),
    (2, -1, -1, 1, 2_463),
    (2, -1, 0, 1, 2_211),
    (2, -1, -1, -1, 2_065),
    (0, 1, -1, -1, -1_870),
    (4, 0, -1, -1, 1_828),
    (0, 1, 0, 1, -1_794),
    (0, 0, 0, 3, -1_749),
    (0, 1, -1, 1, -1_565),
    (1, 0, 0, 1, -1_491),
    (0, 1, 1, 1, -1_475),
    (0, 1, 1, -1, -1_410),
    (0, 1, 0, -1, -1_344),
    (1, 0, 0, -1, -1_335),
    (0, 0, 3, 1, 1_107),
];

/// Geocentric ecliptic position of the Moon (Meeus ch. 47), `t` in Julian centuries of TT
/// from J2000.0.
pub fn moon_position(t: f64) -> EclipticPosition {
    let t2 = t * t;
    let t3 = t2 * t;
    let t4 = t3 * t;
    // Mean arguments in degrees (Meeus 47.1–47.5).
    let l_mean = 218.316_447_7 + 481_267.881_234_21 * t - 0.001_578_6 * t2 + t3 / 538_841.0
        - t4 / 65_194_000.0;
    let d = 297.850_192_1 + 445_267.111_403_4 * t - 0.001_881_9 * t2 + t3 / 545_868.0
        - t4 / 113_065_000.0;
    let m = 357.529_109_2 + 35_999.050_290_9 * t - 0.000_153_6 * t2 + t3 / 24_490_000.0;
    let mp = 134.963_396_4 + 477_198.867_505_5 * t + 0.008_741_4 * t2 + t3 / 69_699.0
        - t4 / 14_712_000.0;
    let f = 93.272_095_0 + 483_202.017_523_3 * t - 0.003_653_9 * t2 - t3 / 3_526_000.0
        + t4 / 863_310_000.0;
    let a1 = (119.75 + 131.849 * t) * DEG;
    let a2 = (53.09 + 479_264.290 * t) * DEG;
    let a3 = (313.45 + 481_266.484 * t) * DEG;
    // Earth's orbit eccentricity shrinks the terms in M (Meeus 47.6).
    let e = 1.0 - 0.002_516 * t - 0.000_007_4 * t2;
    let (l_r, d_r, m_r, mp_r, f_r) = (
        (l_mean % 360.0) * DEG,
        (d % 360.0) * DEG,
        (m % 360.0) * DEG,
        (mp % 360.0) * DEG,
        (f % 360.0) * DEG,
    );
    let e_factor = |mult_m: i8| match mult_m {
        1 | -1 => e,
        2 | -2 => e * e,
        _ => 1.0,
    };
    let arg = |cd: i8, cm: i8, cmp: i8, cf: i8| {
        f64::from(cd) * d_r + f64::from(cm) * m_r + f64::from(cmp) * mp_r + f64::from(cf) * f_r
    };

    let mut sum_l = 0.0;
    let mut sum_r = 0.0;
    for &(cd, cm, cmp, cf, sl, sr) in MOON_LR.iter() {
        let x = arg(cd, cm, cmp, cf);
        let k = e_factor(cm);
        sum_l += k * f64::from(sl) * sin(x);
        sum_r += k * f64::from(sr) * cos(x);
    }
    sum_l += 3958.0 * sin(a1) + 1962.0 * sin(l_r - f_r) + 318.0 * sin(a2);

    let mut sum_b = 0.0;
    for &(cd, cm, cmp, cf, sb) in MOON_B.iter() {
        sum_b += e_factor(cm) * f64::from(sb) * sin(arg(cd, cm, cmp, cf));
    }
    sum_b += -2235.0 * sin(l_r)
        + 382.0 * sin(a3)
        + 175.0 * sin(a1 - f_r)
        + 175.0 * sin(a1 + f_r)
        + 127.0 * sin(l_r - mp_r)
        - 115.0 * sin(l_r + mp_r);

    EclipticPosition {
        longitude_rad: l_r + sum_l * 1.0e-6 * DEG,
        latitude_rad: sum_b * 1.0e-6 * DEG,
        distance_m: (385_000.56 + sum_r * 1.0e-3) * 1.0e3,
    }
}

/// Geocentric ecliptic position of the Sun (Meeus ch. 25, low accuracy: 0.01°), `t` in Julian
/// centuries of TT from J2000.0. Latitude is zero at this accuracy.
pub fn sun_position(t: f64) -> EclipticPosition {
    let l0 = 280.466_46 + 36_000.769_83 * t + 0.000_303_2 * t * t;
    let m = (357.529_11 + 35_999.050_29 * t - 0.000_153_7 * t * t) * DEG;
    let e = 0.016_708_634 - 0.000_042_037 * t - 0.000_000_126_7 * t * t;
    let c = (1.914_602 - 0.004_817 * t - 0.000_014 * t * t) * sin(m)
        + (0.019_993 - 0.000_101 * t) * sin(2.0 * m)
        + 0.000_289 * sin(3.0 * m);
    let nu = m + c * DEG;
    let r_au = 1.000_001_018 * (1.0 - e * e) / (1.0 + e * cos(nu));
    EclipticPosition {
        longitude_rad: ((l0 + c) % 360.0) * DEG,
        latitude_rad: 0.0,
        distance_m: r_au * AU_M,
    }
}

/// Mean obliquity of the ecliptic (IAU 1980 linear term), radians.
pub fn mean_obliquity_rad(t: f64) -> f64 {
    (23.439_291_111 - 0.013_004_2 * t) * DEG
}

fn ecliptic_to_equatorial(p: &EclipticPosition, sin_eps: f64, cos_eps: f64) -> [f64; 3] {
    let cb = cos(p.latitude_rad);
    let x = cb * cos(p.longitude_rad);
    let y = cb * sin(p.longitude_rad);
    let z = sin(p.latitude_rad);
    [
        p.distance_m * x,
        p.distance_m * (y * cos_eps - z * sin_eps),
        p.distance_m * (y * sin_eps + z * cos_eps),
    ]
}

/// Moon's mean orbit: semi-major axis (m), eccentricity, inclination to the ecliptic (rad).
const MOON_ORBIT_A_M: f64 = 384_399.0e3;
const MOON_ORBIT_E: f64 = 0.0549;
const MOON_ORBIT_INCLINATION_RAD: f64 = 5.145 * DEG;
/// Earth's orbit eccentricity (for the Sun's mean 1/d³).
const SUN_ORBIT_E: f64 = 0.0167;

/// Where the Moon and the Sun are, in the geocentric equatorial frame of the mean equinox of
/// date, plus the slowly varying moments that make up the K1 line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bodies {
    /// Moon position (x to the equinox, z to the pole), metres.
    pub moon_m: [f64; 3],
    /// Sun position, metres.
    pub sun_m: [f64; 3],
    /// Orbit-averaged Σ GM·⟨x z / d⁵⟩ and Σ GM·⟨y z / d⁵⟩ of Moon and Sun, 1/s².
    ///
    /// Why: the K1 line is the part of the diurnal tide at exactly sidereal frequency, i.e. the
    /// orbit average of the diurnal moment; it gets the FCN-resonant Love numbers.
    pub k1_moment: [f64; 2],
}

impl Bodies {
    /// Positions at a UTC Julian date.
    pub fn at_julian_date_utc(jd_utc: f64) -> Self {
        let t = (jd_utc + TT_MINUS_UTC_S / SECONDS_PER_DAY - J2000_JD) / DAYS_PER_CENTURY;
        let eps = mean_obliquity_rad(t);
        let (se, ce) = (sin(eps), cos(eps));
        let moon_m = ecliptic_to_equatorial(&moon_position(t), se, ce);
        let sun_m = ecliptic_to_equatorial(&sun_position(t), se, ce);

        // Orbit average of u uᵀ/d³ for a Kepler orbit with pole n: (I − n nᵀ)/(2 a³ (1−e²)^1.5),
        // so ⟨x z⟩ = −n_x n_z/2 and ⟨y z⟩ = −n_y n_z/2 times GM/(a³(1−e²)^1.5).
        let node = (125.044_52 - 1_934.136_261 * t) * DEG;
        let (si, ci) = (
            sin(MOON_ORBIT_INCLINATION_RAD),
            cos(MOON_ORBIT_INCLINATION_RAD),
        );
        let n_ecl = [si * sin(node), -si * cos(node), ci];
        let n_x = n_ecl[0];
        let n_y = n_ecl[1] * ce - n_ecl[2] * se;
        let n_z = n_ecl[1] * se + n_ecl[2] * ce;
        let moon_scale = GM_MOON_M3_S2 / mean_inverse_cube(MOON_ORBIT_A_M, MOON_ORBIT_E);
        // Sun: the pole of its apparent orbit is the ecliptic pole (0, −sin ε, cos ε).
        let sun_scale = GM_SUN_M3_S2 / mean_inverse_cube(AU_M, SUN_ORBIT_E);
        let k1_moment = [
            -0.5 * moon_scale * n_x * n_z,
            -0.5 * moon_scale * n_y * n_z + 0.5 * sun_scale * se * ce,
        ];
        Self {
            moon_m,
            sun_m,
            k1_moment,
        }
    }

    fn lerp(a: &Self, b: &Self, w: f64) -> Self {
        let mix = |x: f64, y: f64| x + (y - x) * w;
        Self {
            moon_m: [
                mix(a.moon_m[0], b.moon_m[0]),
                mix(a.moon_m[1], b.moon_m[1]),
                mix(a.moon_m[2], b.moon_m[2]),
            ],
            sun_m: [
                mix(a.sun_m[0], b.sun_m[0]),
                mix(a.sun_m[1], b.sun_m[1]),
                mix(a.sun_m[2], b.sun_m[2]),
            ],
            k1_moment: [
                mix(a.k1_moment[0], b.k1_moment[0]),
                mix(a.k1_moment[1], b.k1_moment[1]),
            ],
        }
    }
}

/// a³ (1 − e²)^1.5, the denominator of the orbit-averaged 1/d³.
fn mean_inverse_cube(a_m: f64, e: f64) -> f64 {
    let q = 1.0 - e * e;
    a_m * a_m * a_m * q * sqrt(q)
}

// ---------------------------------------------------------------------------------------------
// Station
// ---------------------------------------------------------------------------------------------

/// Elastic factors of one station: gravimetric δ and tilt γ per species.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ElasticFactors {
    /// δ for the degree-2 long-period (2,0) band, latitude corrected.
    pub delta_20: f64,
    /// δ for the degree-2 diurnal band at O1 (the resonance reference).
    pub delta_21: f64,
    /// δ at K1, after the free-core-nutation resonance.
    pub delta_k1: f64,
    /// δ for the degree-2 semidiurnal band.
    pub delta_22: f64,
    /// δ for degree 3.
    pub delta_3: f64,
    /// γ for the long-period band (no latitude term: it is singular where P20 vanishes).
    pub gamma_20: f64,
    /// γ for the diurnal band at O1.
    pub gamma_21: f64,
    /// γ at K1.
    pub gamma_k1: f64,
    /// γ for the semidiurnal band.
    pub gamma_22: f64,
    /// γ for degree 3.
    pub gamma_3: f64,
}

/// A station: where the tide is evaluated, with all position-only quantities precomputed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Station {
    latitude_deg: f64,
    longitude_rad: f64,
    height_m: f64,
    /// sin and cos of the geocentric latitude.
    sin_gc: f64,
    cos_gc: f64,
    /// Geocentric radius, m.
    radius_m: f64,
    /// sin and cos of (geodetic − geocentric latitude): rotates radial/north into up/north.
    sin_dev: f64,
    cos_dev: f64,
    /// Normal gravity at the station (GRS80 + free air), m/s².
    gravity_m_s2: f64,
    /// δ(2,0)·(3 s² − 1) with the latitude terms multiplied out (finite where P20 = 0).
    delta20_p20: f64,
    factors: ElasticFactors,
}

/// Tide at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TideSample {
    /// Change of gravity, nm/s², positive when the gravity the station feels increases
    /// (ETERNA / earthtide convention: about −δ × the upward tidal acceleration).
    pub gravity_nm_s2: f64,
    /// Tilt towards north, milliarcseconds: γ × (northward tidal acceleration) / g.
    ///
    /// Positive when the tide pulls north, which is what a horizontal accelerometer whose
    /// sensitive axis points north reads (in units of g × angle). Same sign as ETERNA's /
    /// earthtide's `tidal_tilt` at azimuth 0 (checked by the test vectors).
    pub tilt_north_mas: f64,
    /// Tilt towards east, milliarcseconds, same convention.
    pub tilt_east_mas: f64,
}

impl TideSample {
    /// Tilt along an azimuth (0° = north, 90° = east, clockwise), milliarcseconds.
    #[inline]
    pub fn tilt_mas(&self, azimuth_deg: f64) -> f64 {
        let az = azimuth_deg * DEG;
        self.tilt_north_mas * cos(az) + self.tilt_east_mas * sin(az)
    }
    /// Tilt along an azimuth, arcseconds.
    #[inline]
    pub fn tilt_arcsec(&self, azimuth_deg: f64) -> TiltArcsec {
        TiltArcsec(self.tilt_mas(azimuth_deg) * 1.0e-3)
    }
    /// Tilt along an azimuth, radians.
    #[inline]
    pub fn tilt_radians(&self, azimuth_deg: f64) -> Radians {
        Radians(self.tilt_mas(azimuth_deg) / MAS_PER_RAD)
    }
    /// Gravity change in m/s².
    #[inline]
    pub fn gravity_m_s2(&self) -> f64 {
        self.gravity_nm_s2 / NM_S2_PER_M_S2
    }
    /// Gravity change in units of standard gravity.
    #[inline]
    pub fn gravity_gs(&self) -> Gs {
        Gs(self.gravity_m_s2() / STANDARD_GRAVITY_M_S2)
    }
}

/// Gravity of the elastic model split by tidal band, nm/s² (same sign as
/// [`TideSample::gravity_nm_s2`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GravitySpecies {
    /// Degree 2, order 0 (long-period, including the permanent tide).
    pub long_period_nm_s2: f64,
    /// Degree 2, order 1 (diurnal, K1 with its resonant factor).
    pub diurnal_nm_s2: f64,
    /// Degree 2, order 2 (semidiurnal).
    pub semidiurnal_nm_s2: f64,
    /// Degree 3, all orders (the Moon's; terdiurnal M3 and small parts of the other bands).
    pub degree3_nm_s2: f64,
}

/// Radial, north and east gradient of one piece of the potential (m/s², up/north/east).
#[derive(Clone, Copy, Default)]
struct Gradient {
    up: f64,
    north: f64,
    east: f64,
}

impl Station {
    /// A station at geodetic (GRS80/WGS84) latitude, east longitude (degrees) and ellipsoidal
    /// height (metres).
    pub fn new(latitude_deg: f64, longitude_deg: f64, height_m: f64) -> Result<Self, TideError> {
        if !(latitude_deg.is_finite() && longitude_deg.is_finite() && height_m.is_finite()) {
            return Err(TideError::NotFinite);
        }
        if !(-90.0..=90.0).contains(&latitude_deg) {
            return Err(TideError::LatitudeOutOfRange);
        }
        if !(-11_000.0..=100_000.0).contains(&height_m) {
            return Err(TideError::HeightOutOfRange);
        }
        let phi = latitude_deg * DEG;
        let (sp, cp) = (sin(phi), cos(phi));
        let n = GRS80_A_M / sqrt(1.0 - GRS80_E2 * sp * sp);
        let p = (n + height_m) * cp;
        let z = (n * (1.0 - GRS80_E2) + height_m) * sp;
        let radius_m = sqrt(p * p + z * z);
        let gc = atan2(z, p);
        let dev = phi - gc;
        let (sin_gc, cos_gc) = (sin(gc), cos(gc));

        let gravity_m_s2 = GRS80_GAMMA_E_M_S2 * (1.0 + GRS80_SOMIGLIANA_K * sp * sp)
            / sqrt(1.0 - GRS80_E2 * sp * sp)
            - FREE_AIR_GRADIENT_PER_M * height_m;

        // Latitude dependence (DDW 1999 as tabulated for ETERNA), in ct = cos(colatitude).
        let ct2 = sin_gc * sin_gc;
        let p20 = 3.0 * ct2 - 1.0;
        // 0.335410 = 3/(4√5), 0.894427 = 2/√5: normalisation of the "+"/"−" terms.
        let delta20_p20 = DELTA_2[0] * p20
            + DELTA_20_PLUS * 0.335_410 * (35.0 * ct2 * ct2 - 30.0 * ct2 + 3.0)
            + DELTA_20_MINUS * 0.894_427;
        let lat21 = 0.612_372 * (7.0 * ct2 - 3.0);
        let lat22 = 0.866_025 * (7.0 * ct2 - 1.0);
        let delta_21 = DELTA_2[1] + DELTA_21_PLUS * lat21;
        let delta_22 = DELTA_2[2] + DELTA_22_PLUS * lat22;
        let gamma_21 = 1.0 + LOVE_K_2[1] - LOVE_H_2[1] + GAMMA_21_PLUS * lat21;
        let gamma_22 = 1.0 + LOVE_K_2[2] - LOVE_H_2[2] + GAMMA_22_PLUS * lat22;
        let resonance = (OMEGA_K1_DEG_H - OMEGA_O1_DEG_H) / (OMEGA_FCN_DEG_H - OMEGA_K1_DEG_H);
        let factors = ElasticFactors {
            // Reported value at this latitude; where P20 ≈ 0 the ratio is meaningless and the
            // plain DDW value is shown instead (the computation uses delta20_p20).
            delta_20: if fabs(p20) > 1e-3 {
                delta20_p20 / p20
            } else {
                DELTA_2[0]
            },
            delta_21,
            delta_k1: delta_21 + DELTA_FCN * resonance,
            delta_22,
            delta_3: DELTA_3,
            gamma_20: 1.0 + LOVE_K_2[0] - LOVE_H_2[0],
            gamma_21,
            gamma_k1: gamma_21 + GAMMA_FCN * resonance,
            gamma_22,
            gamma_3: 1.0 + LOVE_HK_3.1 - LOVE_HK_3.0,
        };
        Ok(Self {
            latitude_deg,
            longitude_rad: longitude_deg * DEG,
            height_m,
            sin_gc,
            cos_gc,
            radius_m,
            sin_dev: sin(dev),
            cos_dev: cos(dev),
            gravity_m_s2,
            delta20_p20,
            factors,
        })
    }

    /// Geodetic latitude, degrees.
    pub fn latitude_deg(&self) -> f64 {
        self.latitude_deg
    }
    /// Ellipsoidal height, metres.
    pub fn height_m(&self) -> f64 {
        self.height_m
    }
    /// Geocentric latitude, degrees.
    pub fn geocentric_latitude_deg(&self) -> f64 {
        atan2(self.sin_gc, self.cos_gc) / DEG
    }
    /// Geocentric radius, metres.
    pub fn geocentric_radius_m(&self) -> f64 {
        self.radius_m
    }
    /// Normal gravity used to turn horizontal acceleration into tilt, m/s².
    pub fn normal_gravity_m_s2(&self) -> f64 {
        self.gravity_m_s2
    }
    /// The elastic factors in use at this station.
    pub fn elastic_factors(&self) -> ElasticFactors {
        self.factors
    }

    /// Tide at a Unix time (seconds since 1970-01-01 UTC).
    pub fn tide_at_unix_seconds(&self, unix_s: f64) -> TideSample {
        self.tide_at_julian_date(julian_date_from_unix_seconds(unix_s))
    }

    /// Tide at a UTC calendar instant.
    pub fn tide_at_utc(&self, time: &UtcTime) -> TideSample {
        self.tide_at_julian_date(time.julian_date())
    }

    /// Tide at a UTC Julian date.
    pub fn tide_at_julian_date(&self, jd_utc: f64) -> TideSample {
        self.tide_from_bodies(&Bodies::at_julian_date_utc(jd_utc), gmst_rad(jd_utc))
    }

    /// Tide from given body positions and Greenwich sidereal time (the series path).
    pub fn tide_from_bodies(&self, bodies: &Bodies, gmst: f64) -> TideSample {
        self.tide_parts(bodies, gmst).0
    }

    /// Gravity split by band at a Unix time: what the elastic model puts into each species.
    /// The parts sum to [`TideSample::gravity_nm_s2`].
    pub fn gravity_species_at_unix_seconds(&self, unix_s: f64) -> GravitySpecies {
        let jd = julian_date_from_unix_seconds(unix_s);
        self.tide_parts(&Bodies::at_julian_date_utc(jd), gmst_rad(jd))
            .1
    }

    /// The tide and its gravity split by species.
    fn tide_parts(&self, bodies: &Bodies, gmst: f64) -> (TideSample, GravitySpecies) {
        let lst = gmst + self.longitude_rad;
        let (s_lst, c_lst) = (sin(lst), cos(lst));
        let (s, c, r) = (self.sin_gc, self.cos_gc, self.radius_m);
        let f = &self.factors;

        // δ-weighted upward and north gradients per species: long-period, diurnal,
        // semidiurnal, degree 3 (the north part enters gravity through the deviation).
        let mut g_up = [0.0; 4];
        let mut g_north = [0.0; 4];
        let mut t_up = 0.0; // γ-weighted
        let mut t_north = 0.0;
        let mut t_east = 0.0;

        for (pos, gm, degree3) in [
            (&bodies.moon_m, GM_MOON_M3_S2, true),
            (&bodies.sun_m, GM_SUN_M3_S2, false),
        ] {
            let d2 = pos[0] * pos[0] + pos[1] * pos[1] + pos[2] * pos[2];
            let d = sqrt(d2);
            let inv_d = 1.0 / d;
            // Direction cosines of the body seen from the local meridian: p = sin dec,
            // q = cos dec cos H, w = cos dec sin H (H = local hour angle).
            let p = pos[2] * inv_d;
            let q = (pos[0] * c_lst + pos[1] * s_lst) * inv_d;
            let w = (pos[0] * s_lst - pos[1] * c_lst) * inv_d;
            // GM r / d³: scale of the degree-2 gradient.
            let k2 = gm * r * inv_d * inv_d * inv_d;

            let (g20, g21, g22) = degree2_gradients(s, c, p, q, w, k2);
            // Long-period band: the latitude-corrected δ·P20 replaces δ·(3s²−1) in the radial term.
            g_up[0] += 0.5 * k2 * self.delta20_p20 * (3.0 * p * p - 1.0);
            g_up[1] += f.delta_21 * g21.up;
            g_up[2] += f.delta_22 * g22.up;
            g_north[0] += f.delta_20 * g20.north;
            g_north[1] += f.delta_21 * g21.north;
            g_north[2] += f.delta_22 * g22.north;
            t_up += f.gamma_20 * g20.up + f.gamma_21 * g21.up + f.gamma_22 * g22.up;
            t_north += f.gamma_20 * g20.north + f.gamma_21 * g21.north + f.gamma_22 * g22.north;
            t_east += f.gamma_21 * g21.east + f.gamma_22 * g22.east;

            if degree3 {
                // Degree 3 (Moon only; for the Sun r/d ≈ 4e-5 makes it < 0.01 nm/s²).
                let x = s * p + c * q; // cos of the zenith angle of the body
                let k3 = k2 * r * inv_d;
                let p3 = 0.5 * (5.0 * x * x * x - 3.0 * x);
                let dp3 = 0.5 * (15.0 * x * x - 3.0);
                let g3 = Gradient {
                    up: 3.0 * k3 * p3,
                    north: k3 * dp3 * (c * p - s * q),
                    east: -k3 * dp3 * w,
                };
                g_up[3] += f.delta_3 * g3.up;
                g_north[3] += f.delta_3 * g3.north;
                t_up += f.gamma_3 * g3.up;
                t_north += f.gamma_3 * g3.north;
                t_east += f.gamma_3 * g3.east;
            }
        }

        // K1 line: the orbit-averaged diurnal moment gets the FCN-resonant factors on top of
        // the O1-referenced ones already applied above.
        let mx = bodies.k1_moment[0] * r;
        let my = bodies.k1_moment[1] * r;
        let pq = mx * c_lst + my * s_lst; // ⟨p q⟩ × GM r / d³ equivalent
        let pw = mx * s_lst - my * c_lst;
        let k1 = Gradient {
            up: 6.0 * s * c * pq,
            north: 3.0 * (c * c - s * s) * pq,
            east: -3.0 * s * pw,
        };
        let dd = f.delta_k1 - f.delta_21;
        let dg = f.gamma_k1 - f.gamma_21;
        g_up[1] += dd * k1.up;
        g_north[1] += dd * k1.north;
        t_up += dg * k1.up;
        t_north += dg * k1.north;
        t_east += dg * k1.east;

        // Radial/geocentric-north → ellipsoid normal/geodetic-north; upward tidal acceleration
        // lowers the gravity the station feels.
        let band =
            |i: usize| -(self.cos_dev * g_up[i] + self.sin_dev * g_north[i]) * NM_S2_PER_M_S2;
        let species = GravitySpecies {
            long_period_nm_s2: band(0),
            diurnal_nm_s2: band(1),
            semidiurnal_nm_s2: band(2),
            degree3_nm_s2: band(3),
        };
        let north = self.cos_dev * t_north - self.sin_dev * t_up;
        let to_mas = MAS_PER_RAD / self.gravity_m_s2;
        (
            TideSample {
                gravity_nm_s2: species.long_period_nm_s2
                    + species.diurnal_nm_s2
                    + species.semidiurnal_nm_s2
                    + species.degree3_nm_s2,
                tilt_north_mas: north * to_mas,
                tilt_east_mas: t_east * to_mas,
            },
            species,
        )
    }

    /// Tide at `start_unix_s + i × interval_s`, i = 0, 1, …, without allocation.
    ///
    /// The Moon and Sun are computed at nodes [`SERIES_NODE_STEP_S`] apart and interpolated
    /// linearly in Cartesian coordinates; the Earth's rotation is exact at every sample. The
    /// interpolation error is < 1e-6 of the tide (docs/tide.md, test
    /// `series_matches_direct_evaluation`).
    pub fn series(&self, start_unix_s: f64, interval_s: f64) -> Result<TideSeries<'_>, TideError> {
        if !(start_unix_s.is_finite() && interval_s.is_finite()) {
            return Err(TideError::NotFinite);
        }
        if interval_s <= 0.0 {
            return Err(TideError::IntervalNotPositive);
        }
        Ok(TideSeries {
            station: self,
            start_unix_s,
            interval_s,
            index: 0,
            nodes: None,
        })
    }
}

/// Degree-2 gradients (up, north, east) for the three species, before any Love numbers.
///
/// From the addition theorem P2(cos ψ) = ¼(3s²−1)(3p²−1) + 3 s c p q + ¾ c² (q² − w²), with
/// s, c the sine and cosine of the geocentric latitude; V2 = (GM r²/d³)·P2, so ∂V/∂r = 2V/r,
/// north = (1/r) ∂V/∂φ, east = (1/(r cos φ)) ∂V/∂λ with ∂q/∂λ = −w, ∂w/∂λ = q.
#[inline]
fn degree2_gradients(
    s: f64,
    c: f64,
    p: f64,
    q: f64,
    w: f64,
    k2: f64,
) -> (Gradient, Gradient, Gradient) {
    let p2 = 3.0 * p * p - 1.0;
    let pq = p * q;
    let qq_ww = q * q - w * w;
    let g20 = Gradient {
        up: 0.5 * k2 * (3.0 * s * s - 1.0) * p2,
        north: 1.5 * k2 * s * c * p2,
        east: 0.0,
    };
    let g21 = Gradient {
        up: 6.0 * k2 * s * c * pq,
        north: 3.0 * k2 * (c * c - s * s) * pq,
        east: -3.0 * k2 * s * p * w,
    };
    let g22 = Gradient {
        up: 1.5 * k2 * c * c * qq_ww,
        north: -1.5 * k2 * s * c * qq_ww,
        east: -3.0 * k2 * c * q * w,
    };
    (g20, g21, g22)
}

/// Spacing of the ephemeris nodes of [`TideSeries`], seconds.
///
/// Why 600 s: the Moon moves 0.09° in that time, so the chord of linear interpolation sags by
/// 3e-7 of its distance, a 1e-6 change of the tide (< 0.002 nm/s²); the ephemeris then costs
/// one evaluation per 600 samples at 1 Hz.
pub const SERIES_NODE_STEP_S: f64 = 600.0;

/// Iterator over a regularly sampled tide series: yields (Unix seconds, tide).
#[derive(Debug, Clone)]
pub struct TideSeries<'a> {
    station: &'a Station,
    start_unix_s: f64,
    interval_s: f64,
    index: u64,
    /// Cached ephemeris nodes: (node index k, bodies at k, bodies at k+1).
    nodes: Option<(i64, Bodies, Bodies)>,
}

impl TideSeries<'_> {
    fn bodies_at_node(&self, k: i64) -> Bodies {
        let t = self.start_unix_s + k as f64 * SERIES_NODE_STEP_S;
        Bodies::at_julian_date_utc(julian_date_from_unix_seconds(t))
    }
}

impl Iterator for TideSeries<'_> {
    type Item = (f64, TideSample);

    fn next(&mut self) -> Option<Self::Item> {
        // Time from the index, not by accumulation, so a 3.5-million-sample run does not drift.
        let offset_s = self.index as f64 * self.interval_s;
        let unix_s = self.start_unix_s + offset_s;
        self.index = self.index.checked_add(1)?;
        let jd = julian_date_from_unix_seconds(unix_s);
        let gmst = gmst_rad(jd);
        if self.interval_s >= SERIES_NODE_STEP_S {
            let bodies = Bodies::at_julian_date_utc(jd);
            return Some((unix_s, self.station.tide_from_bodies(&bodies, gmst)));
        }
        let pos = offset_s / SERIES_NODE_STEP_S;
        let k = floor(pos) as i64;
        let w = pos - k as f64;
        let (a, b) = match self.nodes {
            Some((kk, a, b)) if kk == k => (a, b),
            Some((kk, _, b)) if kk + 1 == k => {
                let next = self.bodies_at_node(k + 1);
                self.nodes = Some((k, b, next));
                (b, next)
            }
            _ => {
                let a = self.bodies_at_node(k);
                let b = self.bodies_at_node(k + 1);
                self.nodes = Some((k, a, b));
                (a, b)
            }
        };
        let bodies = Bodies::lerp(&a, &b, w);
        Some((unix_s, self.station.tide_from_bodies(&bodies, gmst)))
    }
}

pub mod cte1973;
pub mod harmonic;

#[cfg(test)]
mod tests;
