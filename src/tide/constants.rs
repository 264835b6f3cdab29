//! Physical and astronomical constants, and the Earth's tidal response (Love numbers).

use super::*;

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
pub(super) const GRS80_GAMMA_E_M_S2: f64 = 9.780_326_771_5;
/// GRS80 Somigliana constant k = (b γ_p − a γ_e) / (a γ_e).
pub(super) const GRS80_SOMIGLIANA_K: f64 = 0.001_931_851_353;
/// Free-air gradient of normal gravity, (m/s²)/m.
pub(super) const FREE_AIR_GRADIENT_PER_M: f64 = 3.086e-6;

pub(super) const DEG: f64 = core::f64::consts::PI / 180.0;
pub(super) const TWO_PI: f64 = 2.0 * core::f64::consts::PI;

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
pub(super) const DELTA_20_PLUS: f64 = -0.0016;
pub(super) const DELTA_20_MINUS: f64 = 0.0054;
pub(super) const DELTA_21_PLUS: f64 = -0.0018;
pub(super) const DELTA_22_PLUS: f64 = -0.0010;
/// Latitude coefficients of γ = 1 + k − h: (k+ − h+) for (2,1) and (2,2).
pub(super) const GAMMA_21_PLUS: f64 = 0.0014 - 0.0007;
pub(super) const GAMMA_22_PLUS: f64 = 0.0009 - 0.0005;
/// Free-core-nutation resonance: δ(ω) = δ(O1) + DELTA_FCN·(ω − ω_O1)/(ω_FCN − ω), ω in °/h.
pub(super) const DELTA_FCN: f64 = -0.000_625;
/// Same for γ (k_r − h_r = −0.001261 + 0.002505).
pub(super) const GAMMA_FCN: f64 = -0.001_261 + 0.002_505;
/// Angular frequencies, °/h: O1 (reference of the resonance), K1, FCN (space-fixed).
pub(super) const OMEGA_O1_DEG_H: f64 = 13.943_036;
pub(super) const OMEGA_K1_DEG_H: f64 = 15.041_069;
pub(super) const OMEGA_FCN_DEG_H: f64 = 15.073_729;
