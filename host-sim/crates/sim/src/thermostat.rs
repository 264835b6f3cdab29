//! The thermal environment: the laboratory room, the Peltier thermostat around the instrument,
//! and the lag between the thermostat's mounting block (where the RTD sits) and the proof mass.
//!
//! ```text
//! room(t)   = mean + A·cos(2π(t_solar − t_peak)/24 h) + weather(t) + doors(t)
//! mount(t)  = setpoint + controller(t) + drift(t) + k_room · LP_τth[room − mean](t)
//! proof(t)  = LP_τpm[mount](t)
//! ```
//! weather: AR(1) (a bounded random walk over days); doors: Poisson-timed steps of the room
//! temperature that decay exponentially; controller: AR(1) of the regulation loop; drift: random
//! walk of the set point; LP_τ: first-order low pass with time constant τ. Physics and default
//! magnitudes: docs/simulator.md.

use super::noise::{gauss, Ar1, RandomWalk, SimRng};
use rand::Rng;
use serde::{Deserialize, Serialize};

/// Laboratory room temperature.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RoomParams {
    /// Mean room temperature, °C.
    pub mean_c: f64,
    /// Amplitude of the daily cycle, °C.
    pub diurnal_amplitude_c: f64,
    /// Local solar hour of the daily maximum (0–24).
    pub diurnal_peak_solar_h: f64,
    /// Standard deviation of the weather component, °C.
    pub weather_std_c: f64,
    /// Correlation time of the weather component, hours.
    pub weather_tau_h: f64,
    /// Mean number of door openings per day (Poisson).
    pub door_rate_per_day: f64,
    /// Room temperature step at a door opening, °C (sign included).
    pub door_step_c: f64,
    /// Time constant with which a door step decays, minutes.
    pub door_decay_min: f64,
}

/// The thermostat around the instrument.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ThermostatParams {
    /// Set point, °C.
    pub setpoint_c: f64,
    /// Standard deviation of the regulation fluctuation (AR(1)), °C.
    pub controller_std_c: f64,
    /// Correlation time of the regulation fluctuation, seconds.
    pub controller_tau_s: f64,
    /// Random walk of the set point (sensor/electronics ageing), °C per √day.
    pub setpoint_walk_c_per_sqrt_day: f64,
    /// Fraction of a room temperature change that reaches the mounting block (1/rejection).
    pub room_coupling: f64,
    /// Thermal time constant of the thermostat enclosure for room changes, hours.
    pub room_lowpass_h: f64,
    /// Time constant from the mounting block (RTD) to the proof mass, seconds (0: no lag).
    pub proof_mass_lag_s: f64,
}

/// Temperatures of one sample, °C.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Temperatures {
    /// Room.
    pub room_c: f64,
    /// Thermostat mounting block, where the RTD is.
    pub mount_c: f64,
    /// Proof mass: the temperature the accelerometer's coefficients follow.
    pub proof_mass_c: f64,
}

/// First-order low pass, exact for an input held constant over each interval.
#[derive(Debug, Clone)]
pub struct LowPass {
    alpha: f64,
    y: f64,
}

impl LowPass {
    /// Time constant `tau_s` (0: pass-through), sampled every `interval_s`, starting at `y0`.
    pub fn new(tau_s: f64, interval_s: f64, y0: f64) -> Self {
        let alpha = if tau_s > 0.0 {
            1.0 - (-interval_s / tau_s).exp()
        } else {
            1.0
        };
        LowPass { alpha, y: y0 }
    }

    /// Feeds one input and returns the output.
    #[inline]
    pub fn step(&mut self, x: f64) -> f64 {
        self.y += self.alpha * (x - self.y);
        self.y
    }

    /// Current output.
    #[inline]
    pub fn value(&self) -> f64 {
        self.y
    }
}

/// The room: daily cycle, weather, door openings.
#[derive(Debug, Clone)]
pub struct Room {
    p: RoomParams,
    weather: Ar1,
    door: f64,
    door_decay: f64,
    next_door_s: f64,
    interval_s: f64,
}

const DAY_S: f64 = 86_400.0;

impl Room {
    /// A room sampled every `interval_s`.
    pub fn new(p: &RoomParams, interval_s: f64, rng: &mut SimRng) -> Self {
        let mut room = Room {
            p: p.clone(),
            weather: Ar1::new(p.weather_std_c, p.weather_tau_h * 3600.0, interval_s, rng),
            door: 0.0,
            door_decay: if p.door_decay_min > 0.0 {
                (-interval_s / (p.door_decay_min * 60.0)).exp()
            } else {
                0.0
            },
            next_door_s: f64::INFINITY,
            interval_s,
        };
        room.next_door_s = room.waiting_time_s(rng);
        room
    }

    fn waiting_time_s(&self, rng: &mut SimRng) -> f64 {
        if self.p.door_rate_per_day <= 0.0 {
            return f64::INFINITY;
        }
        // Exponential waiting time of a Poisson process: −ln(U)/λ with U in (0, 1].
        let u: f64 = 1.0 - rng.random::<f64>();
        -u.ln() * DAY_S / self.p.door_rate_per_day
    }

    /// Room temperature at elapsed time `t_s`, with `solar_h` the local solar hour then.
    /// Call once per sample, in order.
    pub fn step(&mut self, t_s: f64, solar_h: f64, rng: &mut SimRng) -> f64 {
        let weather = self.weather.step(rng);
        self.door *= self.door_decay;
        while t_s >= self.next_door_s {
            self.door += self.p.door_step_c;
            let w = self.waiting_time_s(rng);
            self.next_door_s += w.max(self.interval_s * 1e-3);
        }
        let phase = 2.0 * std::f64::consts::PI * (solar_h - self.p.diurnal_peak_solar_h) / 24.0;
        self.p.mean_c + self.p.diurnal_amplitude_c * phase.cos() + weather + self.door
    }

    /// Mean room temperature, °C.
    pub fn mean_c(&self) -> f64 {
        self.p.mean_c
    }
}

/// The thermostat and the proof-mass lag.
#[derive(Debug, Clone)]
pub struct Thermostat {
    p: ThermostatParams,
    controller: Ar1,
    walk: RandomWalk,
    enclosure: LowPass,
    proof: LowPass,
}

impl Thermostat {
    /// A thermostat sampled every `interval_s`, starting in equilibrium at the set point.
    pub fn new(p: &ThermostatParams, interval_s: f64, rng: &mut SimRng) -> Self {
        let controller = Ar1::new(p.controller_std_c, p.controller_tau_s, interval_s, rng);
        // Start the proof mass near the mounting block (as after a long warm-up) with a small
        // draw, rather than exactly on it.
        let start = p.setpoint_c + controller.value();
        let lag_spread = p.controller_std_c
            * (p.proof_mass_lag_s / (p.proof_mass_lag_s + p.controller_tau_s.max(1e-9))).sqrt();
        Thermostat {
            p: p.clone(),
            walk: RandomWalk::new(p.setpoint_walk_c_per_sqrt_day / DAY_S.sqrt(), interval_s),
            enclosure: LowPass::new(p.room_lowpass_h * 3600.0, interval_s, 0.0),
            proof: LowPass::new(
                p.proof_mass_lag_s,
                interval_s,
                start + lag_spread * gauss(rng),
            ),
            controller,
        }
    }

    /// Mounting-block and proof-mass temperatures for the room deviation from its mean.
    pub fn step(&mut self, room_deviation_c: f64, rng: &mut SimRng) -> (f64, f64) {
        let c = self.controller.step(rng);
        let w = self.walk.step(rng);
        let r = self.enclosure.step(room_deviation_c);
        let mount = self.p.setpoint_c + c + w + self.p.room_coupling * r;
        (mount, self.proof.step(mount))
    }
}

#[cfg(test)]
mod tests {
    use super::super::noise::stream;
    use super::*;

    fn quiet_room() -> RoomParams {
        RoomParams {
            mean_c: 22.0,
            diurnal_amplitude_c: 2.0,
            diurnal_peak_solar_h: 15.0,
            weather_std_c: 0.0,
            weather_tau_h: 48.0,
            door_rate_per_day: 0.0,
            door_step_c: 1.0,
            door_decay_min: 20.0,
        }
    }

    #[test]
    fn the_daily_cycle_peaks_at_the_configured_solar_hour() {
        let mut rng = stream(1, 1);
        let mut room = Room::new(&quiet_room(), 60.0, &mut rng);
        assert!((room.step(0.0, 15.0, &mut rng) - 24.0).abs() < 1e-12);
        assert!((room.step(60.0, 3.0, &mut rng) - 20.0).abs() < 1e-12);
    }

    #[test]
    fn door_openings_arrive_at_the_configured_poisson_rate() {
        let p = RoomParams {
            diurnal_amplitude_c: 0.0,
            door_rate_per_day: 4.0,
            door_decay_min: 0.0, // each step lasts one sample: count the samples above the mean
            ..quiet_room()
        };
        let mut rng = stream(2, 1);
        let mut room = Room::new(&p, 60.0, &mut rng);
        let days = 200.0;
        let n = (days * DAY_S / 60.0) as usize;
        let mut count = 0.0;
        for i in 0..n {
            let t = room.step(i as f64 * 60.0, 0.0, &mut rng);
            count += (t - 22.0).round();
        }
        // Poisson: 800 expected, σ ≈ 28; allow 4σ.
        assert!((count - 4.0 * days).abs() < 115.0, "{count} openings");
    }

    #[test]
    fn the_enclosure_attenuates_and_delays_a_daily_room_cycle_as_a_first_order_low_pass() {
        let p = ThermostatParams {
            setpoint_c: 60.0,
            controller_std_c: 0.0,
            controller_tau_s: 600.0,
            setpoint_walk_c_per_sqrt_day: 0.0,
            room_coupling: 0.1,
            room_lowpass_h: 3.0,
            proof_mass_lag_s: 0.0,
        };
        let dt = 60.0;
        let mut rng = stream(3, 1);
        let mut th = Thermostat::new(&p, dt, &mut rng);
        let w = 2.0 * std::f64::consts::PI / DAY_S;
        let (mut max, mut t_max) = (f64::MIN, 0.0);
        for i in 0..(10.0 * DAY_S / dt) as usize {
            let t = i as f64 * dt;
            let (mount, proof) = th.step((w * t).sin(), &mut rng);
            assert_eq!(mount, proof);
            if t > 9.0 * DAY_S && mount > max {
                (max, t_max) = (mount, t);
            }
        }
        // |H| = 1/√(1 + (ωτ)²), lag = atan(ωτ)/ω for τ = 3 h: 0.0538 °C above 60, 4.4 h late.
        let wt = w * 3.0 * 3600.0;
        let gain = 0.1 / (1.0 + wt * wt).sqrt();
        assert!(
            (max - 60.0 - gain).abs() < 0.002 * gain.max(1.0),
            "amp {}",
            max - 60.0
        );
        let lag_h = ((t_max - 9.0 * DAY_S) - DAY_S / 4.0) / 3600.0;
        let expect_h = wt.atan() / w / 3600.0;
        assert!(
            (lag_h - expect_h).abs() < 0.1,
            "lag {lag_h} h vs {expect_h} h"
        );
    }
}
