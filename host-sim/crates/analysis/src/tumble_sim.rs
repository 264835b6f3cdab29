//! A small generator of dividing-head tumble logs (docs/tumble.md), so that `accomp tumble` can be
//! exercised end to end: simulate at eight temperatures, tumble-solve, fit the temperature models.
//!
//! It is deliberately self-contained (the station simulator lives elsewhere): the instrument is the
//! core's equation (1) (`StaticCoefficients::output`) with every coefficient taken from true
//! temperature models (`ThermalCompensator::coefficients_at`), plus an optional K3·a_i³ term, a
//! constant foundation tilt, a random dividing-head index error per position and white output noise.

use std::fmt::Write as _;

use accomp::compensation::ThermalCompensator;
use accomp::model::StaticCoefficients;
use accomp::poly::{TempPoly, TemperatureScale};
use accomp::units::{Celsius, Gs, RAD_PER_ARCMIN, RAD_PER_ARCSEC};

use crate::tumble::RotationAxis;

/// A seeded SplitMix64 generator with Box–Muller normals: reproducible across platforms and
/// without a dependency, which is all a test-log generator needs.
#[derive(Debug, Clone)]
pub struct Rng {
    state: u64,
    spare: Option<f64>,
}

impl Rng {
    /// A generator from a seed.
    pub fn new(seed: u64) -> Self {
        Rng {
            state: seed,
            spare: None,
        }
    }

    fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in (0, 1], never 0 so that ln() below is finite.
    fn uniform(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 1.0) / (1u64 << 53) as f64
    }

    /// A standard normal deviate.
    pub fn normal(&mut self) -> f64 {
        if let Some(s) = self.spare.take() {
            return s;
        }
        let r = (-2.0 * self.uniform().ln()).sqrt();
        let phi = 2.0 * std::f64::consts::PI * self.uniform();
        self.spare = Some(r * phi.sin());
        r * phi.cos()
    }
}

/// Everything the generator varies.
#[derive(Debug, Clone)]
pub struct TumbleSimConfig {
    /// Seed of the noise.
    pub seed: u64,
    /// Number of equally spaced dividing-head positions, starting at 0°.
    pub positions: usize,
    /// Readings recorded at each position (the dwell).
    pub readings_per_position: usize,
    /// Seconds between readings.
    pub reading_interval_s: f64,
    /// Seconds to index the head to the next position and settle (no readings).
    pub index_time_s: f64,
    /// Test temperatures (thermostat set points), in order.
    pub temperatures_c: Vec<f64>,
    /// Tests per temperature (repeats back to back).
    pub repeats: usize,
    /// Seconds from the end of one test to the start of the next (temperature step and soak).
    pub test_gap_s: f64,
    /// White noise of each output reading (V, 1σ).
    pub output_noise_v: f64,
    /// White noise of each temperature reading (°C, 1σ); the true temperature is the set point.
    pub temperature_noise_c: f64,
    /// True dividing-head index error per position (arcsec, 1σ).
    pub index_error_arcsec: f64,
    /// Which accelerometer axis lies along the head's rotation axis.
    pub rotation_axis: RotationAxis,
    /// Local gravity in units of standard g.
    pub gravity_g: f64,
    /// Constant foundation tilt (arcsec) added to every head angle.
    pub tilt_arcsec: f64,
    /// True K3, g/g³ (not part of the core model; added here as K1·K3·a_i³).
    pub k3_g_per_g3: f64,
    /// Linear bias drift with time (g/day), for coefficient-stability tests.
    pub bias_drift_g_per_day: f64,
    /// The true temperature models.
    pub models: ThermalCompensator,
    /// Write a `test` column (otherwise tests are separated only by time and angle sequence).
    pub test_column: bool,
}

/// Why the simulated instrument's models cannot be built (the core refuses them).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ModelError {
    /// The core's temperature scale refuses the range.
    #[error("temperature scale: {0}")]
    Scale(String),
    /// A polynomial has more terms than the core's models take.
    #[error("polynomial order")]
    Order,
}

/// The paper's printed order-2 models (the core's [`accomp::reference::paper_order2_models_over`])
/// as the "true" instrument, T0 = 50 °C, with a δo model of our own (the paper prints none, and
/// a rotation about the output axis needs one to recover): 0.8′ at 30 °C falling 0.01′/°C. The
/// scale spans 20–75 °C so that temperature noise around the 30 and 65 °C set points is never
/// clamped.
pub fn paper_order2_models() -> Result<ThermalCompensator, ModelError> {
    let scale = TemperatureScale::for_range(Celsius(20.0), Celsius(75.0))
        .map_err(|e| ModelError::Scale(format!("{e:?}")))?;
    let mut m = accomp::reference::paper_order2_models_over(scale, Celsius(50.0));
    m.models.misalignment_o_rad = TempPoly::from_monomial_celsius(&[1.1, -0.01], &scale)
        .ok_or(ModelError::Order)?
        .scaled(RAD_PER_ARCMIN);
    Ok(m)
}

impl TumbleSimConfig {
    /// Table 1's eight temperatures (30..65 °C in 5 °C steps), four positions, 10 readings each,
    /// 2 µV (≈ 1.5 µg) reading noise, 0.2" index error, rotation about the pendulum axis (δp).
    pub fn table1_default(seed: u64) -> Result<Self, ModelError> {
        Ok(TumbleSimConfig {
            seed,
            positions: 4,
            readings_per_position: 10,
            reading_interval_s: 10.0,
            index_time_s: 60.0,
            temperatures_c: (0..8).map(|i| 30.0 + 5.0 * f64::from(i)).collect(),
            repeats: 1,
            test_gap_s: 4.0 * 3600.0,
            output_noise_v: 2e-6,
            temperature_noise_c: 0.01,
            index_error_arcsec: 0.2,
            rotation_axis: RotationAxis::Pendulum,
            gravity_g: 1.0,
            tilt_arcsec: 0.0,
            k3_g_per_g3: 0.0,
            bias_drift_g_per_day: 0.0,
            models: paper_order2_models()?,
            test_column: true,
        })
    }
}

/// One simulated test's true values, for tests that compare against the generator's truth.
#[derive(Debug, Clone, Copy)]
pub struct TrueTest {
    /// Set-point temperature.
    pub temperature_c: f64,
    /// Coefficients in force during the test (bias drift included).
    pub coefficients: StaticCoefficients,
    /// Time of the test's first reading.
    pub start_s: f64,
}

/// Generates a tumble log (docs/tumble.md format) and the true coefficients of each test.
pub fn simulate_tumble(cfg: &TumbleSimConfig) -> Result<(String, Vec<TrueTest>), String> {
    if cfg.positions < 1 || cfg.readings_per_position < 1 {
        return Err("need at least one position and one reading per position".into());
    }
    if !(cfg.gravity_g.is_finite() && cfg.gravity_g > 0.0) {
        return Err("gravity must be positive".into());
    }
    let mut rng = Rng::new(cfg.seed);
    let mut out = String::new();
    let axis = match cfg.rotation_axis {
        RotationAxis::Output => "output",
        RotationAxis::Pendulum => "pendulum",
    };
    let _ = writeln!(out, "# instrument: simulated (accomp simulate-tumble)");
    let _ = writeln!(out, "# seed: {}", cfg.seed);
    let _ = writeln!(out, "# rotation_axis: {axis}");
    let _ = writeln!(
        out,
        "# local_gravity_m_s2: {}",
        cfg.gravity_g * crate::tumble::STANDARD_GRAVITY_M_S2
    );
    let _ = writeln!(out, "# index_error_arcsec: {}", cfg.index_error_arcsec);
    if cfg.test_column {
        let _ = writeln!(out, "time_s,test,angle_deg,output_v,temperature_c");
    } else {
        let _ = writeln!(out, "time_s,angle_deg,output_v,temperature_c");
    }
    let g = cfg.gravity_g;
    let step_deg = 360.0 / cfg.positions as f64;
    let mut t_s = 0.0;
    let mut truth = Vec::new();
    let mut test_id = 0usize;
    for &temp in &cfg.temperatures_c {
        for _ in 0..cfg.repeats {
            test_id += 1;
            let (mut k, _) = cfg
                .models
                .coefficients_at(Celsius(temp))
                .map_err(|e| format!("true model at {temp} °C: {e:?}"))?;
            k.bias_g += cfg.bias_drift_g_per_day * t_s / 86_400.0;
            truth.push(TrueTest {
                temperature_c: temp,
                coefficients: k,
                start_s: t_s,
            });
            for p in 0..cfg.positions {
                let nominal_deg = step_deg * p as f64;
                let actual = nominal_deg.to_radians()
                    + (cfg.tilt_arcsec + cfg.index_error_arcsec * rng.normal()) * RAD_PER_ARCSEC;
                let a_i = g * actual.sin();
                // The solver's own convention for which cross axis the head turns through.
                let cross = cfg.rotation_axis.cross(g, actual);
                let e_true = k.output(Gs(a_i), cross).0
                    + k.scale_factor_v_per_g * cfg.k3_g_per_g3 * a_i * a_i * a_i;
                for _ in 0..cfg.readings_per_position {
                    let e = e_true + cfg.output_noise_v * rng.normal();
                    let tc = temp + cfg.temperature_noise_c * rng.normal();
                    if cfg.test_column {
                        let _ = writeln!(out, "{t_s:.1},{test_id},{nominal_deg},{e:.10},{tc:.4}");
                    } else {
                        let _ = writeln!(out, "{t_s:.1},{nominal_deg},{e:.10},{tc:.4}");
                    }
                    t_s += cfg.reading_interval_s;
                }
                t_s += cfg.index_time_s;
            }
            t_s += cfg.test_gap_s;
        }
    }
    Ok((out, truth))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tumble::{parse_log, solve_log, TumbleOptions};

    #[test]
    fn normal_deviates_have_zero_mean_and_unit_variance() {
        let mut r = Rng::new(42);
        let n = 100_000;
        let v: Vec<f64> = (0..n).map(|_| r.normal()).collect();
        let m = v.iter().sum::<f64>() / n as f64;
        let var = v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n as f64 - 1.0);
        // SE of the mean 0.003, of the variance 0.0045.
        assert!(m.abs() < 0.015, "{m}");
        assert!((var - 1.0).abs() < 0.025, "{var}");
    }

    #[test]
    fn the_log_has_one_row_per_reading_and_states_axis_and_gravity() {
        let cfg = TumbleSimConfig::table1_default(1).unwrap();
        let (text, truth) = simulate_tumble(&cfg).unwrap();
        let log = parse_log(&text).unwrap();
        assert_eq!(log.rows.len(), 8 * 4 * 10);
        assert_eq!(truth.len(), 8);
        assert_eq!(log.meta("rotation_axis"), Some("pendulum"));
        assert_eq!(log.meta("local_gravity_m_s2"), Some("9.80665"));
    }

    #[test]
    fn without_the_test_column_the_tests_are_found_from_time_gaps_and_restarts() {
        let mut cfg = TumbleSimConfig::table1_default(2).unwrap();
        cfg.test_column = false;
        let (text, _) = simulate_tumble(&cfg).unwrap();
        assert!(!text.contains(",test,"));
        let r = solve_log(&parse_log(&text).unwrap(), &TumbleOptions::default()).unwrap();
        assert_eq!(r.tests.len(), 8);
        let temps: Vec<f64> = r
            .tests
            .iter()
            .map(|t| t.temperature.mean_c.unwrap())
            .collect();
        for (t, want) in temps
            .iter()
            .zip([30.0, 35.0, 40.0, 45.0, 50.0, 55.0, 60.0, 65.0])
        {
            assert!((t - want).abs() < 0.01, "{t} vs {want}");
        }
    }

    #[test]
    fn noise_free_simulation_is_recovered_exactly_including_delta_o() {
        let mut cfg = TumbleSimConfig::table1_default(3).unwrap();
        cfg.output_noise_v = 0.0;
        cfg.index_error_arcsec = 0.0;
        cfg.temperature_noise_c = 0.0;
        cfg.rotation_axis = RotationAxis::Output;
        cfg.temperatures_c = vec![30.0];
        let (text, truth) = simulate_tumble(&cfg).unwrap();
        let r = solve_log(&parse_log(&text).unwrap(), &TumbleOptions::default()).unwrap();
        let t = &r.tests[0];
        let k = truth[0].coefficients;
        // Printed δo model: 1.1 − 0.01·30 = 0.8 arcmin.
        assert!((t.coefficients.misalignment_arcmin.value - 0.8).abs() < 1e-7);
        assert!((k.misalignment_o.0 / RAD_PER_ARCMIN - 0.8).abs() < 1e-12);
        // The log keeps 1e-10 V: K0 to ~1e-10 g.
        assert!((t.coefficients.k0_g.value - k.bias_g).abs() < 2e-10);
        assert!((t.coefficients.k1_v_per_g.value - k.scale_factor_v_per_g).abs() < 2e-10);
    }
}
