//! The simulated twin of a measured record: the station simulator's instrument, at the record's
//! site and time, driven by the record's measured channels, predicting the record's output at
//! its own time stamps. The rules (what comes from the record, what from defaults) are in
//! docs/simulator.md, "Twin of a measured record", and each twin lists them for its record in
//! [`Twin::provenance`].
//!
//! Speed: everything that does not depend on the seed — the drivers, the tide, the instrument's
//! deterministic output and the effects — is computed once by [`Twin::new`] /
//! [`Twin::extended`]; [`Twin::run`] with a seed adds the instrument noise, drawn directly at
//! the record's (irregular) instants, and — only when a driver the record lacks enters the
//! output — re-runs the station with the member's seed so that the simulated drivers carry
//! their own weather (measured channels stay measured in every member).

mod build;
mod error;
pub mod family;
mod from_discovery;
mod noise;
#[cfg(test)]
mod tests;
pub mod transients;

pub use error::TwinError;
pub use from_discovery::{
    scenario_effects_drawn, scenario_effects_from_discovery, tide_from_groups,
};

use build::*;
use noise::*;

use accomp::units::RAD_PER_ARCSEC;

use crate::discover::import::{unit_per_g_for_suffix, ChannelKind, Dataset};
use crate::discover::noise::NoiseModel;
use crate::sim::accelerometer::{axes, true_coefficients, DividingHead, HeadPosition};
use crate::sim::catalogue::EffectKind;
use crate::sim::effects::{ChainSetup, Drive, EffectChain, ScenarioEffect, SIMULATED_AMBIENT};
use crate::sim::gravimeter::{GravimeterParams, InstrumentParams, UNITS};
use crate::sim::noise::{gauss, stream, AllanParams};
use crate::sim::scenario::Scenario;
use crate::sim::tide::{TideModel, TideSampler};
use crate::sim::time::Utc;
use crate::sim::{Simulator, STANDARD_GRAVITY_M_S2};

/// Random stream of the twin's instrument noise.
const TWIN_NOISE_STREAM: u64 = 3;

/// The preset a derived twin starts from.
const BASE_PRESET: &str = "paper-1g";

/// The record's drivers at its own instants.
#[derive(Debug, Clone)]
struct Drivers {
    /// Temperature the instrument and the thermal effects follow, °C.
    temperature_c: Vec<f64>,
    /// Foundation tilt about the spindle, tide included, rad.
    tilt_rad: Vec<f64>,
    /// Station pressure minus its mean, Pa.
    pressure_dev_pa: Vec<f64>,
    /// Nominal input, g.
    input_g: Vec<f64>,
    /// Ambient channels (centred), by name.
    ambient_names: Vec<String>,
    ambient: Vec<Vec<f64>>,
    /// Tide gravity, nm/s² (at the instant, no delay).
    tide_nm_s2: Vec<f64>,
    /// Tide tilt along the spindle, rad (added to a simulated tilt).
    tide_tilt_rad: Vec<f64>,
    /// Which drivers are simulated (the record lacks them).
    simulated: Simulated,
}

/// Which drivers the twin simulates because the record has no such channel.
#[derive(Debug, Clone, Default, PartialEq)]
struct Simulated {
    temperature: bool,
    tilt: bool,
    pressure: bool,
    /// Per ambient channel (same order as `Drivers::ambient_names`).
    ambient: Vec<bool>,
}

/// The station's own driver series at the scenario's steps (tide excluded): mount temperature
/// °C, tilt rad, pressure − mean Pa, room and board temperature − room mean °C.
struct StationSeries {
    temperature_c: Vec<f64>,
    tilt_rad: Vec<f64>,
    pressure_dev_pa: Vec<f64>,
    room_c: Vec<f64>,
    board_c: Vec<f64>,
}

/// The simulated twin of a measured record.
#[derive(Debug, Clone)]
pub struct Twin {
    scenario: Scenario,
    provenance: Vec<String>,
    t_s: Vec<f64>,
    dt_s: f64,
    drivers: Drivers,
    /// Record output units per g (what the effects' amplitudes are in).
    unit_per_g: f64,
    /// Record output units per instrument unit.
    out_scale: f64,
    /// Deterministic instrument output without the effects, record unit.
    base: Vec<f64>,
    /// `base` plus the effects.
    det: Vec<f64>,
    /// Instrument noise in the record unit.
    noise: AllanParams,
    /// The record's fitted noise model, when given: the members draw from it exactly (its
    /// flicker slope included, which the scenario's three Allan levels cannot hold).
    noise_model: Option<NoiseModel>,
    /// The noise family fitted to the record, when given ([`Twin::with_family`]): members draw
    /// from it instead (each its own parameters, then the noise on the record's grid).
    family: Option<GridNoise>,
}

/// The noise family with where the record's points fall on its grid.
#[derive(Debug, Clone)]
struct GridNoise {
    family: family::NoiseFamily,
    /// Grid cell of each record point.
    cells: Vec<usize>,
    /// Cells in the grid.
    len: usize,
    /// The record's transient disturbances, when found: members draw them too.
    transients: Option<transients::Transients>,
}

/// The scenario with every random process silenced: the deterministic part.
pub fn quiet(s: &Scenario) -> Scenario {
    let mut q = s.clone();
    q.room.weather_std_c = 0.0;
    q.room.door_rate_per_day = 0.0;
    q.thermostat.controller_std_c = 0.0;
    q.thermostat.setpoint_walk_c_per_sqrt_day = 0.0;
    q.accelerometer.noise_g = AllanParams::NONE;
    q.accelerometer.orientation.indexing_std_arcsec = 0.0;
    q.rtd.accuracy_c = 0.0;
    q.rtd.noise_uv_rms = 0.0;
    q.foundation.creep_arcsec_per_sqrt_day = 0.0;
    q.tiltmeter.noise_arcsec = 0.0;
    q.adc.ads1262.noise_uv_rms = 0.0;
    q.barometer.weather_std_hpa = 0.0;
    q.barometer.noise_hpa = 0.0;
    if let Some(InstrumentParams::Gravimeter(g)) = &mut q.instrument {
        g.noise = AllanParams::NONE;
    }
    q.effects
        .retain(|e| !matches!(e, ScenarioEffect::ChannelNoise { .. }));
    q
}

impl Twin {
    /// The scenario in use (to write with --write-scenario after `extended`).
    pub fn scenario(&self) -> &Scenario {
        &self.scenario
    }

    /// What came from the record and what from defaults, one line each (printed by twin).
    pub fn provenance(&self) -> &[String] {
        &self.provenance
    }

    /// The record's time stamps `ds.t_s`; the output predicted at each, in the record's
    /// output unit. `seed: None` = the deterministic part (all noise off), `Some(s)` = one
    /// ensemble member with the simulator's noise. Measured temperature / pressure / tilt
    /// channels of the record drive the simulation where present (interpolated onto the
    /// simulator's steps), their simulated counterparts where absent.
    ///
    /// A member whose output depends on a simulated driver (see [`Twin::redraws_weather`])
    /// re-runs the station with its seed: the simulated drivers get that member's weather (room,
    /// thermostat, foundation, barometer), the measured channels stay the record's.
    pub fn run(&self, seed: Option<u64>) -> Result<Vec<f64>, TwinError> {
        let mut out = match seed {
            Some(k) if self.redraws_weather() => self.output(&self.redrawn_drivers(k)?)?,
            _ => self.det.clone(),
        };
        match (seed, &self.noise_model) {
            (Some(seed), _) if self.family.is_some() => {
                if let Some(g) = &self.family {
                    let mut rng = stream(seed, TWIN_NOISE_STREAM);
                    let f = g.family.drawn(&mut rng);
                    let mut x = f.synthesise(g.len, &mut rng);
                    if let Some(t) = &g.transients {
                        t.add_drawn(&mut x, &mut rng);
                    }
                    for (y, &c) in out.iter_mut().zip(&g.cells) {
                        *y += x.get(c).copied().unwrap_or(f64::NAN);
                    }
                }
            }
            (Some(seed), Some(m)) => add_model_noise(&mut out, &self.t_s, m, seed),
            (Some(seed), None) => add_noise(&mut out, &self.t_s, self.dt_s, &self.noise, seed),
            (None, _) => {}
        }
        Ok(out)
    }

    /// The same twin whose members draw their noise from `family`, laid on a regular grid of
    /// `len` cells where record point i falls in cell `cells[i]`.
    pub fn with_family(&self, family: &family::NoiseFamily, cells: &[usize], len: usize) -> Twin {
        let mut t = self.clone();
        t.family = Some(GridNoise {
            family: family.clone(),
            cells: cells.to_vec(),
            len,
            transients: None,
        });
        t
    }

    /// The same twin whose members also draw the record's transient disturbances (with a noise
    /// family only; nothing changes without one).
    pub fn with_transients(&self, found: &transients::Transients) -> Twin {
        let mut t = self.clone();
        if let Some(g) = &mut t.family {
            g.transients = (!found.events.is_empty()).then(|| found.clone());
        }
        t
    }

    /// The noise family the members draw from, if any.
    pub fn family(&self) -> Option<&family::NoiseFamily> {
        self.family.as_ref().map(|g| &g.family)
    }

    /// The same twin with the scenario's effects extended (appended) by `effects`.
    ///
    /// An effect that cannot be applied (out of range, an ambient channel the record does not
    /// have) is left out and said so in [`Twin::provenance`].
    pub fn extended(&self, effects: &[ScenarioEffect]) -> Twin {
        let mut t = self.clone();
        let setup = t.chain_setup();
        let offset = t.scenario.effects.len();
        let mut accepted = Vec::new();
        for (i, e) in effects.iter().enumerate() {
            let ok = e
                .validate(offset + i)
                .map_err(|x| x.to_string())
                .and_then(|()| {
                    EffectChain::new(std::slice::from_ref(e), setup.clone())
                        .map(|_| ())
                        .map_err(|x| x.to_string())
                });
            match ok {
                Ok(()) => accepted.push(e.clone()),
                Err(why) => t
                    .provenance
                    .push(format!("effect {} not applied: {why}", e.name())),
            }
        }
        if accepted.is_empty() {
            return t;
        }
        t.scenario.effects.extend(accepted.iter().cloned());
        if let Ok(chain) = EffectChain::new(&accepted, setup) {
            add_effects(&mut t.det, chain, &t.t_s, &t.drivers);
        }
        let names: Vec<&str> = accepted.iter().map(ScenarioEffect::name).collect();
        t.provenance
            .push(format!("effects added: {}", names.join(", ")));
        t
    }

    /// Instrument noise levels of the ensemble members, record unit.
    pub fn noise_levels(&self) -> &AllanParams {
        &self.noise
    }

    /// The simulated drivers (channels the record lacks) that enter this twin's output: the
    /// accelerometer follows the temperature and the tilt, a gravimeter the pressure through its
    /// admittance; effects their own drivers (thermal: temperature, tilt coupling: tilt, pressure
    /// admittance: pressure, ambient coupling: its channel). Names as in the provenance.
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

    /// Whether seeded members re-run the station for their own weather (a simulated driver
    /// enters the output). When none does, a member is the deterministic part plus the
    /// instrument noise, and costs nothing more.
    pub fn redraws_weather(&self) -> bool {
        !self.weather_drivers().is_empty()
    }

    fn chain_setup(&self) -> ChainSetup {
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
    fn output(&self, d: &Drivers) -> Result<Vec<f64>, TwinError> {
        let start = Utc::parse(&self.scenario.run.start_utc)?;
        let mut y = instrument_output(&self.scenario, start, &self.t_s, d, self.out_scale)?;
        if !self.scenario.effects.is_empty() {
            let chain = EffectChain::new(&self.scenario.effects, self.chain_setup())?;
            add_effects(&mut y, chain, &self.t_s, d);
        }
        Ok(y)
    }

    /// The drivers with the simulated ones drawn from the station run with `seed` (its weather:
    /// room, doors, thermostat, foundation creep, barometric weather; instrument and sensor
    /// noise do not enter, the truth values are taken). The station's streams (room, thermostat,
    /// foundation, barometer) are not the instrument noise's stream, so one seed serves both.
    fn redrawn_drivers(&self, seed: u64) -> Result<Drivers, TwinError> {
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

/// Adds the chain's output terms at the record's instants to `y`.
fn add_effects(y: &mut [f64], mut chain: EffectChain, t_s: &[f64], d: &Drivers) {
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
