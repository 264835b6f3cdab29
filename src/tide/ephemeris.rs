//! Ephemeris: the Moon (Meeus ch. 47) and the Sun (Meeus ch. 25) in the equatorial frame of
//! date.

use super::*;

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
pub(super) type LrTerm = (i8, i8, i8, i8, i32, i32);
/// One periodic term of Meeus Table 47.B: multipliers of D, M, M′, F, then Σb (1e-6°).
pub(super) type BTerm = (i8, i8, i8, i8, i32);

/// ELP-2000/82 as truncated by Meeus (Table 47.A), further cut to |Σl| ≥ 0.0005° or
/// |Σr| ≥ 2 km: the dropped terms sum to < 0.005° and < 10 km (2.6e-5 relative), both far
/// below what the tide needs (docs/tide.md).
pub(super) const MOON_LR: [LrTerm; 44] = [
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
pub(super) const MOON_B: [BTerm; 28] = [
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

pub(super) fn ecliptic_to_equatorial(p: &EclipticPosition, sin_eps: f64, cos_eps: f64) -> [f64; 3] {
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
pub(super) const MOON_ORBIT_A_M: f64 = 384_399.0e3;
pub(super) const MOON_ORBIT_E: f64 = 0.0549;
pub(super) const MOON_ORBIT_INCLINATION_RAD: f64 = 5.145 * DEG;
/// Earth's orbit eccentricity (for the Sun's mean 1/d³).
pub(super) const SUN_ORBIT_E: f64 = 0.0167;

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

    pub(super) fn lerp(a: &Self, b: &Self, w: f64) -> Self {
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
pub(super) fn mean_inverse_cube(a_m: f64, e: f64) -> f64 {
    let q = 1.0 - e * e;
    a_m * a_m * a_m * q * sqrt(q)
}
