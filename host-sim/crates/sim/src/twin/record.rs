//! The deterministic part of a twin at a record's instants: the instrument's output and the
//! scenario's effects driven by the record's drivers, and the member's own weather for the
//! drivers the record lacks.

use serde::{Deserialize, Serialize};

use accomp::units::RAD_PER_ARCSEC;

use super::TwinRunError;
use crate::accelerometer::{axes, true_coefficients};
use crate::effects::{ChainSetup, Drive, EffectChain, KeptTides, ScenarioEffect};
use crate::gravimeter::{InstrumentParams, UNITS};
use crate::noise::AllanParams;
use crate::scenario::Scenario;
use crate::tide::{TideModel, TideSampler};
use crate::time::Utc;
use crate::{SimError, Simulator, STANDARD_GRAVITY_M_S2};

/// The drivers at the record's instants.
#[derive(Debug, Clone, PartialEq)]
pub struct Drivers {
    /// Temperature the instrument and the thermal effects follow, °C.
    pub temperature_c: Vec<f64>,
    /// Foundation tilt about the spindle, tide included, rad.
    pub tilt_rad: Vec<f64>,
    /// Station pressure minus its mean, Pa.
    pub pressure_dev_pa: Vec<f64>,
    /// Nominal input, g.
    pub input_g: Vec<f64>,
    /// Ambient channels (centred), by name.
    pub ambient_names: Vec<String>,
    /// Their series, same order.
    pub ambient: Vec<Vec<f64>>,
    /// Tide gravity, nm/s² (at the instant, no delay).
    pub tide_nm_s2: Vec<f64>,
    /// Tide tilt along the spindle, rad (added to a simulated tilt).
    pub tide_tilt_rad: Vec<f64>,
    /// Which drivers are simulated (the record lacks them).
    pub simulated: Simulated,
}

/// Which drivers the twin simulates because the record has no such channel.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Simulated {
    /// Temperature.
    pub temperature: bool,
    /// Tilt.
    pub tilt: bool,
    /// Pressure.
    pub pressure: bool,
    /// Per ambient channel (same order as `Drivers::ambient_names`).
    pub ambient: Vec<bool>,
}

/// The station's own driver series at the scenario's steps (tide excluded): mount temperature
/// °C, tilt rad, pressure − mean Pa, room and board temperature − room mean °C.
pub struct StationSeries {
    /// Mount temperature, °C.
    pub temperature_c: Vec<f64>,
    /// Tilt, rad.
    pub tilt_rad: Vec<f64>,
    /// Pressure − mean, Pa.
    pub pressure_dev_pa: Vec<f64>,
    /// Room − room mean, °C.
    pub room_c: Vec<f64>,
    /// Board − room mean, °C.
    pub board_c: Vec<f64>,
}

/// Silences the accelerometer's and the sensors' random errors (accelerometer noise, head
/// indexing, RTD offset and noise, tiltmeter, ADC and barometer noise); the station's
/// environment (room, thermostat, foundation, weather) is left as it is.
pub fn silence_readings(s: &mut Scenario) {
    s.accelerometer.noise_g = AllanParams::NONE;
    s.accelerometer.orientation.indexing_std_arcsec = 0.0;
    s.rtd.accuracy_c = 0.0;
    s.rtd.noise_uv_rms = 0.0;
    s.tiltmeter.noise_arcsec = 0.0;
    s.adc.ads1262.noise_uv_rms = 0.0;
    s.barometer.noise_hpa = 0.0;
}

/// The scenario with every random process silenced: the deterministic part.
pub fn quiet(s: &Scenario) -> Scenario {
    let mut q = s.clone();
    silence_readings(&mut q);
    q.room.weather_std_c = 0.0;
    q.room.door_rate_per_day = 0.0;
    q.thermostat.controller_std_c = 0.0;
    q.thermostat.setpoint_walk_c_per_sqrt_day = 0.0;
    q.foundation.creep_arcsec_per_sqrt_day = 0.0;
    q.barometer.weather_std_hpa = 0.0;
    if let Some(InstrumentParams::Gravimeter(g)) = &mut q.instrument {
        g.noise = AllanParams::NONE;
    }
    q.effects
        .retain(|e| !matches!(e, ScenarioEffect::ChannelNoise { .. }));
    q
}

/// Linear interpolation of a regular series (first value at t = 0, spacing `h`) at `t`.
pub fn interp(v: &[f64], h: f64, t: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let x = (t / h).max(0.0);
    let k = (x.floor() as usize).min(v.len() - 1);
    let f = x - k as f64;
    match v.get(k + 1) {
        Some(b) => v[k] + f.min(1.0) * (b - v[k]),
        None => v[k],
    }
}

/// The station's drivers from a run of `s` (tide off, no effects, accelerometer instrument) with
/// `seed`, at its own steps.
pub fn station_series(s: &Scenario, seed: u64) -> Result<StationSeries, SimError> {
    let mut sim = Simulator::new(s, seed)?;
    let steps = sim.samples() as usize + 1;
    let mut o = StationSeries {
        temperature_c: Vec::with_capacity(steps),
        tilt_rad: Vec::with_capacity(steps),
        pressure_dev_pa: Vec::with_capacity(steps),
        room_c: Vec::with_capacity(steps),
        board_c: Vec::with_capacity(steps),
    };
    let room_mean = s.room.mean_c;
    let p_mean = crate::barometer::mean_pressure_hpa(s.barometer.sea_level_hpa, s.site.height_m);
    for _ in 0..steps {
        let x = sim.step()?;
        o.temperature_c.push(x.truth_mount_temperature_c);
        o.tilt_rad.push(x.truth_tilt_arcsec * RAD_PER_ARCSEC);
        o.pressure_dev_pa
            .push((x.truth_pressure_hpa - p_mean) * 100.0);
        o.room_c.push(x.truth_room_c - room_mean);
        o.board_c.push(x.truth_board_c - room_mean);
    }
    Ok(o)
}

/// The instrument's deterministic output at the record's instants, record unit.
pub fn instrument_output(
    s: &Scenario,
    start: Utc,
    t_s: &[f64],
    d: &Drivers,
    out_scale: f64,
) -> Result<Vec<f64>, TwinRunError> {
    if let Some(g) = s.gravimeter() {
        let per_nm = g
            .unit_per_nm_s2()
            .ok_or_else(|| TwinRunError::UnknownGravityUnit {
                unit: g.unit.clone(),
                known: UNITS.join(", "),
            })?;
        // The delayed tide: its own sampler (the undelayed series is in the drivers).
        let tide = if g.tide_delay_s != 0.0 && s.tide.enabled {
            let mut sm = TideSampler::new(
                Some(TideModel::new(&s.site, s.tide.tilt_azimuth_deg).map_err(SimError::from)?),
                start,
                s.tide.step_s,
            );
            t_s.iter()
                .map(|&t| sm.at(t - g.tide_delay_s).gravity_nm_s2)
                .collect()
        } else {
            d.tide_nm_s2.clone()
        };
        return Ok(t_s
            .iter()
            .enumerate()
            .map(|(i, &t)| {
                out_scale
                    * (g.offset
                        + g.drift_per_day * t / 86_400.0
                        + g.tide_factor * tide[i] * per_nm
                        + g.pressure_admittance_per_hpa * d.pressure_dev_pa[i] / 100.0)
            })
            .collect());
    }
    let models = s
        .accelerometer
        .calibration
        .load(s.thermostat.setpoint_c)
        .map_err(SimError::from)?;
    let o = &s.accelerometer.orientation;
    Ok((0..t_s.len())
        .map(|i| {
            let a = d.input_g[i].clamp(-1.0, 1.0);
            let g = 1.0 + d.tide_nm_s2[i] * 1e-9 / STANDARD_GRAVITY_M_S2;
            let (a_i, cross) = axes(o.spindle_axis, o.cross_sign, a.asin() + d.tilt_rad[i], g);
            let k = true_coefficients(&models, d.temperature_c[i]);
            k.output(a_i, cross).0 * out_scale
        })
        .collect())
}

/// Adds the chain's output terms at the record's instants to `y`.
pub fn add_effects(y: &mut [f64], mut chain: EffectChain, t_s: &[f64], d: &Drivers) {
    let mut amb = vec![0.0; d.ambient.len()];
    for (i, y) in y.iter_mut().enumerate() {
        for (a, c) in amb.iter_mut().zip(&d.ambient) {
            *a = c[i];
        }
        *y += chain.output_term(&Drive {
            t_s: t_s[i],
            temperature_c: d.temperature_c[i],
            input_g: d.input_g[i],
            tilt_rad: d.tilt_rad[i],
            pressure_dev_pa: d.pressure_dev_pa[i],
            ambient: &amb,
        });
    }
}

/// The deterministic part of a twin at a record's instants.
#[derive(Debug, Clone)]
pub struct TwinRecord {
    /// The scenario (its effects are in `det`).
    pub scenario: Scenario,
    /// The record's time stamps, s.
    pub t_s: Vec<f64>,
    /// The drivers at those instants.
    pub drivers: Drivers,
    /// Record output units per g (what the effects' amplitudes are in).
    pub unit_per_g: f64,
    /// Record output units per instrument unit.
    pub out_scale: f64,
    /// The instrument's output without the effects, record unit.
    pub base: Vec<f64>,
    /// `base` plus the effects.
    pub det: Vec<f64>,
    /// The model's tide and the wave groups' tides over the record's span, evaluated once for
    /// the record and its extensions (shared by the clones: a member's draw of the tide
    /// effects only combines them).
    pub kept_tides: std::sync::Arc<KeptTides>,
}

impl TwinRecord {
    /// The deterministic part of `scenario` (its effects included, each that cannot be applied
    /// left out and returned as (name, why)).
    pub fn new(
        mut scenario: Scenario,
        t_s: Vec<f64>,
        drivers: Drivers,
        unit_per_g: f64,
        out_scale: f64,
    ) -> Result<(TwinRecord, Vec<(String, String)>), TwinRunError> {
        let start = Utc::parse(&scenario.run.start_utc)?;
        let base = instrument_output(&scenario, start, &t_s, &drivers, out_scale)?;
        let effects = std::mem::take(&mut scenario.effects);
        let r = TwinRecord {
            det: base.clone(),
            base,
            scenario,
            t_s,
            drivers,
            unit_per_g,
            out_scale,
            kept_tides: Default::default(),
        };
        Ok(r.extended(&effects))
    }

    /// The same with the scenario's effects extended (appended) by `effects`; an effect that
    /// cannot be applied (out of range, an ambient channel the record does not have) is left
    /// out and returned as (name, why).
    pub fn extended(&self, effects: &[ScenarioEffect]) -> (TwinRecord, Vec<(String, String)>) {
        let mut t = self.clone();
        let setup = t.chain_setup();
        let offset = t.scenario.effects.len();
        let mut valid = Vec::new();
        let mut refused = Vec::new();
        for (i, e) in effects.iter().enumerate() {
            match e.validate(offset + i) {
                Ok(()) => valid.push(e.clone()),
                Err(why) => refused.push((e.name().to_owned(), why.to_string())),
            }
        }
        // The chain of every valid effect at once: when it builds, each effect's own chain
        // would (a chain's set-up per effect is independent), so the effects are accepted
        // without building each one's again — a wave-group tide renders its groups' waves at
        // every node, the largest part of a member's draw. When it fails, each effect is
        // tried alone and the ones that cannot be built are refused.
        let tides = &*self.kept_tides;
        let chain = match EffectChain::with_kept_tides(&valid, setup.clone(), tides) {
            Ok(chain) => Some(chain),
            Err(_) => {
                let mut accepted = Vec::new();
                for e in valid {
                    match EffectChain::with_kept_tides(
                        std::slice::from_ref(&e),
                        setup.clone(),
                        tides,
                    ) {
                        Ok(_) => accepted.push(e),
                        Err(why) => refused.push((e.name().to_owned(), why.to_string())),
                    }
                }
                valid = accepted;
                EffectChain::with_kept_tides(&valid, setup, tides).ok()
            }
        };
        if valid.is_empty() {
            return (t, refused);
        }
        t.scenario.effects.extend(valid.iter().cloned());
        if let Some(chain) = chain {
            add_effects(&mut t.det, chain, &t.t_s, &t.drivers);
        }
        (t, refused)
    }

    /// The simulated drivers (channels the record lacks) that enter the output: the
    /// accelerometer follows the temperature and the tilt, a gravimeter the pressure through its
    /// admittance; effects their own drivers (thermal: temperature, tilt coupling: tilt, pressure
    /// admittance: pressure, ambient coupling: its channel).
    pub fn weather_drivers(&self) -> Vec<String> {
        let sim = &self.drivers.simulated;
        let grav = self.scenario.gravimeter();
        let (mut temp, mut tilt, mut press) = (
            grav.is_none(),
            grav.is_none(),
            grav.is_some_and(|g| g.pressure_admittance_per_hpa != 0.0),
        );
        let mut amb = vec![false; sim.ambient.len()];
        for e in &self.scenario.effects {
            match e {
                ScenarioEffect::ThermalLag { .. } | ScenarioEffect::ThermalHysteresis { .. } => {
                    temp = true;
                }
                ScenarioEffect::TiltCoupling { .. } => tilt = true,
                ScenarioEffect::PressureAdmittance { .. } => press = true,
                ScenarioEffect::AmbientCoupling { channel, .. } => {
                    if let Some(i) = self.drivers.ambient_names.iter().position(|n| n == channel) {
                        amb[i] = true;
                    }
                }
                _ => {}
            }
        }
        let mut v = Vec::new();
        for (used, simulated, name) in [
            (temp, sim.temperature, "temperature"),
            (tilt, sim.tilt, "tilt"),
            (press, sim.pressure, "pressure"),
        ] {
            if used && simulated {
                v.push(name.to_owned());
            }
        }
        for ((used, simulated), name) in amb
            .iter()
            .zip(&sim.ambient)
            .zip(&self.drivers.ambient_names)
        {
            if *used && *simulated {
                v.push(name.clone());
            }
        }
        v
    }

    /// Whether seeded members re-run the station for their own weather.
    pub fn redraws_weather(&self) -> bool {
        !self.weather_drivers().is_empty()
    }

    /// The deterministic part of member `seed`: `det`, or, when a simulated driver enters the
    /// output, the output for that member's weather.
    pub fn member_det(&self, seed: u64) -> Result<Vec<f64>, TwinRunError> {
        if self.redraws_weather() {
            self.output(&self.redrawn_drivers(seed)?)
        } else {
            Ok(self.det.clone())
        }
    }

    /// The effect chain's set-up for this record.
    pub fn chain_setup(&self) -> ChainSetup {
        let start = Utc::parse(&self.scenario.run.start_utc).map_or(0.0, |u| u.0);
        ChainSetup {
            start_unix_s: start,
            site: (
                self.scenario.site.latitude_deg,
                self.scenario.site.longitude_deg,
                self.scenario.site.height_m,
            ),
            span_s: (
                self.t_s.first().copied().unwrap_or(0.0),
                self.t_s.last().copied().unwrap_or(0.0),
            ),
            unit_per_g: self.unit_per_g,
            input_g: self.drivers.input_g.first().copied().unwrap_or(1.0),
            ambient: self.drivers.ambient_names.clone(),
        }
    }

    /// The deterministic output (instrument and effects) for other drivers, record unit.
    fn output(&self, d: &Drivers) -> Result<Vec<f64>, TwinRunError> {
        let start = Utc::parse(&self.scenario.run.start_utc)?;
        let mut y = instrument_output(&self.scenario, start, &self.t_s, d, self.out_scale)?;
        if !self.scenario.effects.is_empty() {
            let chain = EffectChain::with_kept_tides(
                &self.scenario.effects,
                self.chain_setup(),
                &self.kept_tides,
            )?;
            add_effects(&mut y, chain, &self.t_s, d);
        }
        Ok(y)
    }

    /// The drivers with the simulated ones drawn from the station run with `seed` (its weather:
    /// room, doors, thermostat, foundation creep, barometric weather; instrument and sensor
    /// noise do not enter, the truth values are taken). The station's streams are not the
    /// instrument noise's stream, so one seed serves both.
    fn redrawn_drivers(&self, seed: u64) -> Result<Drivers, TwinRunError> {
        let mut w = self.scenario.clone();
        w.tide.enabled = false;
        w.effects.clear();
        w.instrument = None;
        let st = station_series(&w, seed)?;
        let h = w.run.interval_s;
        let at = |v: &[f64]| -> Vec<f64> { self.t_s.iter().map(|&t| interp(v, h, t)).collect() };
        let mut d = self.drivers.clone();
        let sim = &self.drivers.simulated;
        if sim.temperature {
            d.temperature_c = at(&st.temperature_c);
        }
        if sim.tilt {
            d.tilt_rad = at(&st.tilt_rad)
                .iter()
                .zip(&d.tide_tilt_rad)
                .map(|(a, b)| a + b)
                .collect();
        }
        if sim.pressure {
            d.pressure_dev_pa = at(&st.pressure_dev_pa);
        }
        for ((name, v), simulated) in d
            .ambient_names
            .iter()
            .zip(d.ambient.iter_mut())
            .zip(&sim.ambient)
        {
            if *simulated {
                match name.as_str() {
                    "room_c" => *v = at(&st.room_c),
                    "board_c" => *v = at(&st.board_c),
                    _ => {}
                }
            }
        }
        Ok(d)
    }
}
