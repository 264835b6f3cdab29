//! Station pressure and the barometer that measures it.
//!
//! ```text
//! p(t)      = p_h + A2·cos(2π·2·(t_solar − t2)/24 h) + A1·cos(2π·(t_solar − t1)/24 h) + w(t)
//! p_h       = p0·(1 − L·h/T0)^(g·M/(R·L))                     (ISA troposphere, h = site height)
//! p_meas    = Q_r(p + n),  n ~ N(0, σ_n²),  Q_r: rounding to the barometer's resolution r
//! ```
//! - p_h: the mean pressure at the site height from the International Standard Atmosphere
//!   barometric formula (lapse rate L = 6.5 K/km, T0 = 288.15 K): 1013.25 hPa at sea level,
//!   1006.1 hPa at 60 m, 898.7 hPa at 1000 m.
//! - The atmospheric tide, forced by solar heating of ozone and water vapour: the semidiurnal S2
//!   has a surface amplitude of about 1.16·cos³(latitude) hPa (Haurwitz & Cowley 1973; 1.2–1.3
//!   hPa in the tropics, ≈ 0.5 hPa at 40° N) with maxima near 10 and 22 local solar time
//!   (Dai & Wang 1999, J. Atmos. Sci. 56, 3874); the diurnal S1 is smaller and more variable
//!   over land, typically 0.2–0.6 hPa with the maximum in the early morning (≈ 6–8 LST).
//! - w(t): synoptic weather (passing highs and lows), an AR(1) process with a standard deviation
//!   of a few hPa (5–10 hPa at mid latitudes over a year, less inside a season) and a
//!   correlation time of 1–3 days.
//! - The barometer (e.g. a Vaisala PTB110/PTB330-class or a MEMS sensor such as the BMP388)
//!   adds white noise of a few Pa and reports at a finite resolution (0.01–0.1 hPa).
//!
//! The barometer draws from its own random stream, so adding it changed no other channel of a
//! given seed.

use serde::{Deserialize, Serialize};

use super::noise::{gauss, Ar1, SimRng};

/// The station's barometric environment and the barometer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BarometerParams {
    /// Mean sea-level pressure, hPa (1013.25: the standard atmosphere); the station's mean is
    /// this reduced to the site height by the barometric formula.
    pub sea_level_hpa: f64,
    /// Amplitude of the semidiurnal atmospheric tide S2, hPa (≈ 1.16·cos³ latitude).
    pub s2_amplitude_hpa: f64,
    /// Local solar hour of the first S2 maximum (0–12; the second is 12 h later), ≈ 10.
    pub s2_peak_solar_h: f64,
    /// Amplitude of the diurnal atmospheric tide S1, hPa.
    pub s1_amplitude_hpa: f64,
    /// Local solar hour of the S1 maximum (0–24).
    pub s1_peak_solar_h: f64,
    /// Standard deviation of the synoptic weather component (AR(1)), hPa.
    pub weather_std_hpa: f64,
    /// Correlation time of the weather component, hours.
    pub weather_tau_h: f64,
    /// White noise of the barometer per sample, hPa rms.
    pub noise_hpa: f64,
    /// Resolution (output step) of the barometer, hPa; 0 for a continuous output.
    pub resolution_hpa: f64,
}

/// ISA sea-level temperature, K.
const ISA_T0_K: f64 = 288.15;
/// ISA tropospheric lapse rate, K/m.
const ISA_LAPSE_K_PER_M: f64 = 0.0065;
/// g·M/(R·L) of the ISA troposphere (g0 standard gravity, M = 0.028 964 4 kg/mol,
/// R = 8.314 462 6 J/(mol·K), L = 0.0065 K/m).
const ISA_EXPONENT: f64 =
    crate::STANDARD_GRAVITY_M_S2 * 0.028_964_4 / (8.314_462_6 * ISA_LAPSE_K_PER_M);

/// Earth radius of the geopotential-height conversion (US Standard Atmosphere 1976), m.
const GEOPOTENTIAL_RADIUS_M: f64 = 6_356_766.0;

/// Mean pressure at `height_m` above sea level for `sea_level_hpa` at sea level, hPa
/// (ISA barometric formula of the troposphere, valid below 11 km). The formula is in
/// geopotential height H = r·h/(r + h); using h directly would be 0.3 hPa low at 5 km.
pub fn mean_pressure_hpa(sea_level_hpa: f64, height_m: f64) -> f64 {
    let geopotential_m = GEOPOTENTIAL_RADIUS_M * height_m / (GEOPOTENTIAL_RADIUS_M + height_m);
    sea_level_hpa * (1.0 - ISA_LAPSE_K_PER_M * geopotential_m / ISA_T0_K).powf(ISA_EXPONENT)
}

/// Pressure of one sample, hPa.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PressureSample {
    /// True station pressure.
    pub truth_hpa: f64,
    /// What the barometer reports (noise, then rounding to the resolution).
    pub measured_hpa: f64,
}

/// The barometric environment with its weather state.
#[derive(Debug, Clone)]
pub struct Barometer {
    p: BarometerParams,
    mean_hpa: f64,
    weather: Ar1,
}

impl Barometer {
    /// A barometer at `height_m`, sampled every `interval_s`; the weather starts in its
    /// stationary distribution.
    pub fn new(p: &BarometerParams, height_m: f64, interval_s: f64, rng: &mut SimRng) -> Self {
        Barometer {
            p: p.clone(),
            mean_hpa: mean_pressure_hpa(p.sea_level_hpa, height_m),
            weather: Ar1::new(p.weather_std_hpa, p.weather_tau_h * 3600.0, interval_s, rng),
        }
    }

    /// Mean station pressure, hPa.
    pub fn mean_hpa(&self) -> f64 {
        self.mean_hpa
    }

    /// Advances one interval at local solar hour `solar_h`.
    pub fn step(&mut self, solar_h: f64, rng: &mut SimRng) -> PressureSample {
        let w = std::f64::consts::TAU / 24.0;
        let tide = self.p.s2_amplitude_hpa * (2.0 * w * (solar_h - self.p.s2_peak_solar_h)).cos()
            + self.p.s1_amplitude_hpa * (w * (solar_h - self.p.s1_peak_solar_h)).cos();
        let truth_hpa = self.mean_hpa + tide + self.weather.step(rng);
        let noisy = truth_hpa + self.p.noise_hpa * gauss(rng);
        let measured_hpa = if self.p.resolution_hpa > 0.0 {
            (noisy / self.p.resolution_hpa).round() * self.p.resolution_hpa
        } else {
            noisy
        };
        PressureSample {
            truth_hpa,
            measured_hpa,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::noise::stream;
    use super::*;

    /// The presets' Beijing barometric environment.
    fn params() -> BarometerParams {
        super::super::scenario::barometer()
    }

    #[test]
    fn the_mean_at_height_matches_the_standard_atmosphere_table() {
        // US Standard Atmosphere 1976 table, by geometric altitude: 1013.25 hPa at 0 m,
        // 898.76 hPa at 1000 m, 795.01 hPa at 2000 m, 540.48 hPa at 5000 m.
        assert!((mean_pressure_hpa(1013.25, 0.0) - 1013.25).abs() < 1e-9);
        assert!((mean_pressure_hpa(1013.25, 1000.0) - 898.76).abs() < 0.05);
        assert!((mean_pressure_hpa(1013.25, 2000.0) - 795.01).abs() < 0.05);
        assert!((mean_pressure_hpa(1013.25, 5000.0) - 540.48).abs() < 0.05);
    }

    /// Least-squares amplitude and phase (radians) of cos/sin at angular frequency `w` rad/h.
    #[allow(clippy::needless_range_loop)] // Gaussian elimination: indices are the algorithm
    fn fit_line(h: &[f64], y: &[f64], w: f64) -> (f64, f64) {
        // Normal equations of [1, cos, sin] written out (the design is near-orthogonal over
        // whole days, but the exact 3×3 solve keeps it honest).
        let cols: Vec<[f64; 3]> = h
            .iter()
            .map(|t| [1.0, (w * t).cos(), (w * t).sin()])
            .collect();
        let mut a = [[0.0; 4]; 3];
        for (c, yi) in cols.iter().zip(y) {
            for i in 0..3 {
                for j in 0..3 {
                    a[i][j] += c[i] * c[j];
                }
                a[i][3] += c[i] * yi;
            }
        }
        for k in 0..3 {
            for i in k + 1..3 {
                let f = a[i][k] / a[k][k];
                for j in k..4 {
                    a[i][j] -= f * a[k][j];
                }
            }
        }
        let mut x = [0.0; 3];
        for i in (0..3).rev() {
            let s: f64 = (i + 1..3).map(|j| a[i][j] * x[j]).sum();
            x[i] = (a[i][3] - s) / a[i][i];
        }
        (x[1].hypot(x[2]), x[2].atan2(x[1]))
    }

    #[test]
    fn the_semidiurnal_tide_appears_with_its_amplitude_and_peak_hour() {
        // No weather: a 10-day series at 10 min, S2 peaking at 10 and 22 LST, S1 beside it.
        let mut p = params();
        p.weather_std_hpa = 0.0;
        let mut b = Barometer::new(&p, 60.0, 600.0, &mut stream(3, 9));
        let mut rng = stream(3, 9);
        let hours: Vec<f64> = (0..1440).map(|i| f64::from(i) / 6.0).collect();
        let y: Vec<f64> = hours
            .iter()
            .map(|h| b.step(h.rem_euclid(24.0), &mut rng).measured_hpa)
            .collect();
        let w2 = std::f64::consts::TAU / 12.0;
        let (amp, phase) = fit_line(&hours, &y, w2);
        assert!((amp - 0.5).abs() < 0.005, "S2 amplitude {amp}");
        // Peak of cos(w2·(t − t2)) at phase w2·t2: t2 = 10 h (mod 12).
        let peak_h = (phase / w2).rem_euclid(12.0);
        assert!((peak_h - 10.0).abs() < 0.05, "S2 peak at {peak_h} h");
        let (a1, p1) = fit_line(&hours, &y, w2 / 2.0);
        assert!((a1 - 0.3).abs() < 0.005, "S1 amplitude {a1}");
        let peak1 = (p1 / (w2 / 2.0)).rem_euclid(24.0);
        assert!((peak1 - 7.0).abs() < 0.1, "S1 peak at {peak1} h");
    }

    #[test]
    fn weather_has_the_configured_spread_and_correlation_time() {
        // No tide, no sensor noise: the truth minus the mean is the AR(1) weather alone.
        let mut p = params();
        p.s2_amplitude_hpa = 0.0;
        p.s1_amplitude_hpa = 0.0;
        p.noise_hpa = 0.0;
        let dt_s = 3600.0;
        let mut rng = stream(11, 9);
        let mut b = Barometer::new(&p, 0.0, dt_s, &mut rng);
        // 20 000 days at 1 h: ≈ 10 000 correlation times, so the std is within ~1.5 %.
        let x: Vec<f64> = (0..480_000)
            .map(|_| b.step(0.0, &mut rng).truth_hpa - 1013.25)
            .collect();
        let n = x.len() as f64;
        let m = x.iter().sum::<f64>() / n;
        let var = x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / n;
        assert!((var.sqrt() - 4.0).abs() < 0.15, "std {}", var.sqrt());
        let lag1 = x.windows(2).map(|w| (w[0] - m) * (w[1] - m)).sum::<f64>() / (n - 1.0) / var;
        // φ = exp(−1 h / 48 h) = 0.979 382.
        let tau_h = -1.0 / lag1.ln();
        assert!((tau_h - 48.0).abs() < 3.0, "tau {tau_h} h");
    }

    #[test]
    fn readings_fall_on_the_resolution_grid() {
        let mut p = params();
        p.resolution_hpa = 0.1;
        let mut rng = stream(5, 9);
        let mut b = Barometer::new(&p, 60.0, 60.0, &mut rng);
        for i in 0..1000 {
            let s = b.step(f64::from(i) / 60.0, &mut rng);
            let steps = s.measured_hpa / 0.1;
            assert!((steps - steps.round()).abs() < 1e-6, "{}", s.measured_hpa);
            assert!((s.measured_hpa - s.truth_hpa).abs() < 0.05 + 5.0 * 0.01);
        }
    }
}
