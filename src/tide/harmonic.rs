//! Harmonic tide: the tide-generating potential as a catalogue of waves with Doodson arguments,
//! for tidal analysis (a record's response per wave group) beside the direct ephemeris tide of
//! the parent module.
//!
//! Each wave of degree l and order m (m = the multiplier of τ) contributes a potential
//! V = g₀ H (r/a)ˡ Nₗₘ Pₗₘ(sin φ′) cos(θ + mλ), θ = Σ kᵢ·(τ, s, h, p, N′, pₛ) − 90° when l + m is
//! odd (Cartwright & Tayler 1971: sines for l + m odd), with Nₗₘ the Cartwright–Tayler
//! normalisation √((2l+1)/4π)·√((l−m)!/(l+m)!) and Pₗₘ without the Condon–Shortley sign. The
//! gravity change it causes is the radial gradient l·V/r (plus the tiny north-gradient part that
//! the ellipsoid normal picks up, as in the ephemeris tide), with the sign of `TideSample`:
//! positive = the gravity felt increases.
//!
//! The catalogue is [`super::cte1973::CTE1973`]; `docs/tide.md` says how it compares with the
//! ephemeris tide and with ETERNA.

use super::{
    julian_date_from_unix_seconds, Station, DAYS_PER_CENTURY, DEG, J2000_JD, NM_S2_PER_M_S2,
    SECONDS_PER_DAY, TT_MINUS_UTC_S,
};
use libm::{cos, floor, sin, sqrt};

/// Geocentric gravitational constant of the Earth, m³/s² (IERS 2010).
pub const GM_EARTH_M3_S2: f64 = 3.986_004_418e14;
/// Radius to which the Cartwright–Tayler amplitudes are normalised, m: the Earth's equatorial
/// radius (IAU 1964 system, 6378.160 km), with g₀ = GM/a². Since H ∝ a⁴/d³ and the degree-2
/// gravity ∝ H/a⁴, the radius must be theirs: with the mean radius (6371 km) every degree-2
/// wave comes out 0.45 % too large against the ephemeris tide, which involves no such
/// convention (test `catalogue_matches_the_ephemeris_tide`).
pub const CATALOGUE_RADIUS_M: f64 = 6_378_160.0;

/// Rates of the Doodson arguments (τ, s, h, p, N′, pₛ), degrees per hour, from the time
/// derivatives of the mean longitudes below (Meeus ch. 47 / 25) at J2000.
pub const DOODSON_RATES_DEG_H: [f64; 6] = [
    15.0 - 481_267.881_234_21 / HOURS_PER_CENTURY + 36_000.769_83 / HOURS_PER_CENTURY,
    481_267.881_234_21 / HOURS_PER_CENTURY,
    36_000.769_83 / HOURS_PER_CENTURY,
    4_069.013_728_7 / HOURS_PER_CENTURY,
    1_934.136_261 / HOURS_PER_CENTURY,
    1.719_46 / HOURS_PER_CENTURY,
];
const HOURS_PER_CENTURY: f64 = DAYS_PER_CENTURY * 24.0;

/// One wave of a tidal-potential catalogue.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wave {
    /// Degree l of the spherical harmonic (2 or 3).
    pub degree: u8,
    /// Multipliers of (τ, s, h, p, N′, pₛ); the first is the order m (the species).
    pub doodson: [i8; 6],
    /// Amplitude H, metres of equilibrium tide (Cartwright–Tayler normalisation), signed.
    pub amplitude_m: f64,
}

impl Wave {
    /// A catalogue entry.
    pub const fn new(degree: u8, doodson: [i8; 6], amplitude_m: f64) -> Self {
        Self {
            degree,
            doodson,
            amplitude_m,
        }
    }

    /// Order m: 0 long-period, 1 diurnal, 2 semidiurnal, 3 terdiurnal.
    pub fn order(&self) -> u8 {
        self.doodson[0].unsigned_abs()
    }

    /// Angular speed, degrees per hour.
    pub fn speed_deg_h(&self) -> f64 {
        self.doodson
            .iter()
            .zip(DOODSON_RATES_DEG_H)
            .map(|(&k, r)| f64::from(k) * r)
            .sum()
    }

    /// Frequency, cycles per day.
    pub fn frequency_cpd(&self) -> f64 {
        self.speed_deg_h() * 24.0 / 360.0
    }

    /// Astronomical argument θ at Greenwich (radians), including the −90° of the l + m odd
    /// waves; the station adds mλ.
    pub fn argument_rad(&self, args: &DoodsonArguments) -> f64 {
        let mut a = 0.0;
        for (&k, x) in self.doodson.iter().zip(args.angles_rad) {
            a += f64::from(k) * x;
        }
        if (u16::from(self.degree) + u16::from(self.order())) % 2 == 1 {
            a -= 0.5 * core::f64::consts::PI;
        }
        a
    }
}

/// The six Doodson arguments at an instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DoodsonArguments {
    /// τ (mean lunar time at Greenwich, from lower transit), s (Moon's mean longitude), h (Sun's
    /// mean longitude), p (lunar perigee), N′ (= −N, node), pₛ (solar perigee), radians.
    pub angles_rad: [f64; 6],
}

impl DoodsonArguments {
    /// Arguments at a UTC Julian date (mean longitudes in TT, Earth rotation in UT1 = UTC).
    pub fn at_julian_date_utc(jd_utc: f64) -> Self {
        let t = (jd_utc + TT_MINUS_UTC_S / SECONDS_PER_DAY - J2000_JD) / DAYS_PER_CENTURY;
        let (t2, t3, t4) = (t * t, t * t * t, t * t * t * t);
        // Meeus eq. 47.1 (s), 25.2 (h), ch. 47 (p = Π, N = Ω), ch. 25 (pₛ), degrees.
        let s = 218.316_447_7 + 481_267.881_234_21 * t - 0.001_578_6 * t2 + t3 / 538_841.0
            - t4 / 65_194_000.0;
        let h = 280.466_46 + 36_000.769_83 * t + 0.000_303_2 * t2;
        let p = 83.353_246_5 + 4_069.013_728_7 * t - 0.010_320_0 * t2 - t3 / 80_053.0
            + t4 / 18_999_000.0;
        let n = 125.044_52 - 1_934.136_261 * t + 0.002_070_8 * t2 + t3 / 450_000.0;
        let ps = 282.937_35 + 1.719_46 * t + 0.000_46 * t2;
        // Hours of the UTC day (the Julian day starts at noon).
        let day = jd_utc + 0.5;
        let hours = (day - floor(day)) * 24.0;
        let tau = 15.0 * hours - s + h;
        let wrap = |x: f64| (x % 360.0) * DEG;
        Self {
            angles_rad: [wrap(tau), wrap(s), wrap(h), wrap(p), wrap(-n), wrap(ps)],
        }
    }

    /// Arguments at a Unix time (seconds).
    pub fn at_unix_seconds(unix_s: f64) -> Self {
        Self::at_julian_date_utc(julian_date_from_unix_seconds(unix_s))
    }
}

/// A wave's gravity at one station: `amplitude_nm_s2 · cos(θ + phase_rad)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WaveGravity {
    /// Rigid-Earth (δ = 1) amplitude, nm/s², signed like the catalogue's H.
    pub amplitude_nm_s2: f64,
    /// mλ, radians.
    pub phase_rad: f64,
}

impl WaveGravity {
    /// Value at the given arguments, nm/s² (rigid Earth).
    pub fn at(&self, wave: &Wave, args: &DoodsonArguments) -> f64 {
        self.amplitude_nm_s2 * cos(wave.argument_rad(args) + self.phase_rad)
    }
}

/// Pₗₘ(x) and dPₗₘ/dθ for x = cos θ, u = sin θ (θ colatitude), l ≤ 3, no Condon–Shortley
/// sign. Returns zeros for other (l, m).
fn legendre(l: u8, m: u8, x: f64, u: f64) -> (f64, f64) {
    match (l, m) {
        (2, 0) => (0.5 * (3.0 * x * x - 1.0), -3.0 * x * u),
        (2, 1) => (3.0 * x * u, 3.0 * (x * x - u * u)),
        (2, 2) => (3.0 * u * u, 6.0 * u * x),
        (3, 0) => (
            0.5 * (5.0 * x * x * x - 3.0 * x),
            -1.5 * (5.0 * x * x - 1.0) * u,
        ),
        (3, 1) => (
            1.5 * u * (5.0 * x * x - 1.0),
            1.5 * x * (5.0 * x * x - 1.0 - 10.0 * u * u),
        ),
        (3, 2) => (15.0 * x * u * u, 15.0 * u * (2.0 * x * x - u * u)),
        (3, 3) => (15.0 * u * u * u, 45.0 * u * u * x),
        _ => (0.0, 0.0),
    }
}

/// √((2l+1)/4π · (l−m)!/(l+m)!) for l ≤ 3.
fn normalisation(l: u8, m: u8) -> f64 {
    let fact = |n: u8| (1..=u32::from(n)).fold(1.0, |p, k| p * f64::from(k));
    let l_f = f64::from(l);
    sqrt((2.0 * l_f + 1.0) / (4.0 * core::f64::consts::PI) * fact(l - m.min(l)) / fact(l + m))
}

impl Station {
    /// The rigid-Earth gravity of one catalogue wave at this station.
    pub fn wave_gravity(&self, wave: &Wave) -> WaveGravity {
        let (l, m) = (wave.degree, wave.order());
        // Colatitude θ: cos θ = sin φ′.
        let (x, u) = (self.sin_gc, self.cos_gc);
        let (p, dp) = legendre(l, m, x, u);
        // Cartwright & Tayler's harmonics carry the Condon–Shortley sign (−1)ᵐ: without it the
        // odd orders (diurnal, M3) come out inverted against the ephemeris tide.
        let nrm = if m % 2 == 1 { -1.0 } else { 1.0 } * normalisation(l, m);
        let ratio = self.radius_m / CATALOGUE_RADIUS_M;
        let mut scale =
            GM_EARTH_M3_S2 / (CATALOGUE_RADIUS_M * CATALOGUE_RADIUS_M) * wave.amplitude_m * nrm
                / self.radius_m;
        for _ in 0..l {
            scale *= ratio;
        }
        // Upward gradient l·V/r and north gradient −(1/r)∂V/∂θ, per unit cos(θ + mλ).
        let up = f64::from(l) * scale * p;
        let north = -scale * dp;
        WaveGravity {
            amplitude_nm_s2: -(self.cos_dev * up + self.sin_dev * north) * NM_S2_PER_M_S2,
            phase_rad: f64::from(m) * self.longitude_rad,
        }
    }

    /// The model's gravimetric factor δ for a wave (the elastic Earth of the ephemeris tide:
    /// DDW 1999 with the latitude terms; the diurnal band follows the free-core-nutation
    /// resonance formula at the wave's own frequency).
    pub fn gravimetric_factor(&self, wave: &Wave) -> f64 {
        let f = &self.factors;
        match (wave.degree, wave.order()) {
            (2, 0) => f.delta_20,
            (2, 1) => {
                let w = wave.speed_deg_h();
                f.delta_21
                    + super::DELTA_FCN * (w - super::OMEGA_O1_DEG_H) / (super::OMEGA_FCN_DEG_H - w)
            }
            (2, _) => f.delta_22,
            _ => f.delta_3,
        }
    }

    /// Sum of the elastic (δ-weighted) gravity of `waves` at a Unix time, nm/s².
    pub fn harmonic_gravity_nm_s2(&self, waves: &[Wave], unix_s: f64) -> f64 {
        let args = DoodsonArguments::at_unix_seconds(unix_s);
        waves
            .iter()
            .map(|w| self.gravimetric_factor(w) * self.wave_gravity(w).at(w, &args))
            .sum()
    }
}

/// Sine and cosine of one angle (libm), for callers that sum many waves.
#[inline]
pub fn sin_cos(x: f64) -> (f64, f64) {
    (sin(x), cos(x))
}

#[cfg(test)]
mod tests;
