//! Foundation tilt about the dividing head's spindle and the tiltmeter that measures it.
//!
//! ```text
//! φ(t) = φ0 + k_b · LP_τb[room − mean](t) + drift(t) + tide_tilt(t, azimuth)
//! φ_meas = Q_r(φ + n),  n ~ N(0, σ_n²),  Q_r: rounding to the tiltmeter's resolution r
//! ```
//! The building deforms with the room (outside) temperature with a lag of hours: a first-order
//! low pass τb of the room deviation, scaled by k_b (arcsec/°C). The foundation also creeps (a
//! random walk), and the solid-earth tide tilts the crust (see `tide.rs`). The tiltmeter's axis
//! is aligned with the spindle normal, so it measures the tilt that turns the input axis.

use serde::{Deserialize, Serialize};

use super::noise::{gauss, RandomWalk, SimRng};
use super::thermostat::LowPass;

/// The foundation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FoundationParams {
    /// Tilt at the start, arcsec.
    pub initial_arcsec: f64,
    /// Building thermal tilt per °C of room deviation, arcsec/°C.
    pub building_arcsec_per_c: f64,
    /// Lag of the building's thermal tilt behind the room temperature (low-pass τ), hours.
    pub building_lag_h: f64,
    /// Random-walk creep of the foundation, arcsec per √day.
    pub creep_arcsec_per_sqrt_day: f64,
}

/// The tiltmeter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TiltmeterParams {
    /// White noise per sample, arcsec rms.
    pub noise_arcsec: f64,
    /// Resolution (output step), arcsec; 0 for a continuous output.
    pub resolution_arcsec: f64,
    /// Analog output scale, arcsec per volt (the board's tilt ADC input).
    pub scale_arcsec_per_v: f64,
}

/// Foundation tilt state.
#[derive(Debug, Clone)]
pub struct Foundation {
    p: FoundationParams,
    building: LowPass,
    creep: RandomWalk,
}

impl Foundation {
    /// A foundation sampled every `interval_s`, starting with the building in equilibrium.
    pub fn new(p: &FoundationParams, interval_s: f64) -> Self {
        Foundation {
            p: p.clone(),
            building: LowPass::new(p.building_lag_h * 3600.0, interval_s, 0.0),
            creep: RandomWalk::new(p.creep_arcsec_per_sqrt_day / 86_400f64.sqrt(), interval_s),
        }
    }

    /// Tilt (arcsec) without the tide, for the room deviation from its mean.
    pub fn step(&mut self, room_deviation_c: f64, rng: &mut SimRng) -> f64 {
        self.p.initial_arcsec
            + self.p.building_arcsec_per_c * self.building.step(room_deviation_c)
            + self.creep.step(rng)
    }
}

/// Reads the tilt like the instrument: noise, then rounding to the resolution.
pub fn tiltmeter_reading(p: &TiltmeterParams, tilt_arcsec: f64, rng: &mut SimRng) -> f64 {
    let noisy = tilt_arcsec + p.noise_arcsec * gauss(rng);
    if p.resolution_arcsec > 0.0 {
        (noisy / p.resolution_arcsec).round() * p.resolution_arcsec
    } else {
        noisy
    }
}

#[cfg(test)]
mod tests {
    use super::super::noise::stream;
    use super::*;

    #[test]
    fn readings_fall_on_the_resolution_grid_and_average_to_the_tilt() {
        let p = TiltmeterParams {
            noise_arcsec: 0.05,
            resolution_arcsec: 0.1,
            scale_arcsec_per_v: 10.0,
        };
        let mut rng = stream(1, 6);
        let n = 20_000;
        let mut sum = 0.0;
        for _ in 0..n {
            let r = tiltmeter_reading(&p, 0.234, &mut rng);
            assert!(((r / 0.1) - (r / 0.1).round()).abs() < 1e-9, "{r}");
            sum += r;
        }
        // Noise of 0.05" dithers the 0.1" steps: the mean recovers the tilt to ~1e-3".
        assert!((sum / n as f64 - 0.234).abs() < 2e-3);
    }

    #[test]
    fn building_tilt_follows_a_room_step_with_the_configured_lag() {
        let p = FoundationParams {
            initial_arcsec: 1.0,
            building_arcsec_per_c: 0.2,
            building_lag_h: 4.0,
            creep_arcsec_per_sqrt_day: 0.0,
        };
        let mut f = Foundation::new(&p, 60.0);
        let mut rng = stream(1, 6);
        let mut tilt = 0.0;
        for _ in 0..240 {
            tilt = f.step(1.0, &mut rng);
        }
        // After one time constant (4 h) of a 1 °C step: 1 + 0.2·(1 − e^−1).
        assert!(
            (tilt - (1.0 + 0.2 * (1.0 - (-1f64).exp()))).abs() < 1e-9,
            "{tilt}"
        );
    }
}
