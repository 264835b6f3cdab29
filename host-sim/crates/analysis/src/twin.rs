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
use crate::sim::{SimError, Simulator, STANDARD_GRAVITY_M_S2};

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
}

fn is_gravity_record(ds: &Dataset) -> bool {
    let unit = ds.output_unit.to_ascii_lowercase();
    UNITS.contains(&unit.as_str()) || ds.output_name.to_ascii_lowercase().starts_with("gravity")
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

/// Least-squares line `a + b·t` through (t, y).
fn line_fit(t: &[f64], y: &[f64]) -> (f64, f64) {
    let n = t.len().max(1) as f64;
    let mt = t.iter().sum::<f64>() / n;
    let my = y.iter().sum::<f64>() / n;
    let (mut sty, mut stt) = (0.0, 0.0);
    for (a, b) in t.iter().zip(y) {
        sty += (a - mt) * (b - my);
        stt += (a - mt) * (a - mt);
    }
    let b = if stt > 0.0 { sty / stt } else { 0.0 };
    (my - b * mt, b)
}

/// Allan levels of a fitted noise model (its unit) for points spaced `dt_s`.
fn levels_of(m: &NoiseModel, dt_s: f64) -> AllanParams {
    AllanParams {
        // White variance σ² per point of spacing Δ: h_w = σ²·Δ, ADEV(τ) = √(h_w/τ), so at
        // 1 s √h_w.
        white_adev_1s: (m.white_var.max(0.0) * dt_s).sqrt(),
        flicker_floor: m.flicker_floor(),
        // Allan variance of the walk q·τ/3 = K²·τ/3.
        random_walk_per_sqrt_s: m.rw_per_s.max(0.0).sqrt(),
    }
}

fn scaled(p: &AllanParams, k: f64) -> AllanParams {
    AllanParams {
        white_adev_1s: p.white_adev_1s * k.abs(),
        flicker_floor: p.flicker_floor * k.abs(),
        random_walk_per_sqrt_s: p.random_walk_per_sqrt_s * k.abs(),
    }
}

/// Linear interpolation of a regular series (first value at t = 0, spacing `h`) at `t`.
fn interp(v: &[f64], h: f64, t: f64) -> f64 {
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

fn centred(v: &[f64]) -> Vec<f64> {
    let m = v.iter().sum::<f64>() / v.len().max(1) as f64;
    v.iter().map(|x| x - m).collect()
}

impl Twin {
    /// Base scenario derived from the record when `base` is None (documented rules in
    /// docs/simulator.md "Twin of a measured record": start time, site, interval, duration,
    /// instrument kind and unit, input_g, from the record; noise levels from the record's
    /// fitted noise model when given; everything else the preset defaults, each listed).
    pub fn new(
        ds: &Dataset,
        base: Option<Scenario>,
        noise: Option<&NoiseModel>,
    ) -> Result<Twin, SimError> {
        if ds.len() < 2 {
            return Err(SimError::Twin(
                "the record has fewer than two points".into(),
            ));
        }
        let mut prov: Vec<String> = Vec::new();
        let derived = base.is_none();
        let mut s = match base {
            Some(b) => {
                prov.push(format!("base scenario {:?} (given)", b.name));
                b
            }
            None => {
                prov.push(format!(
                    "base scenario: preset {BASE_PRESET} (room, thermostat, RTD, foundation, \
                     tiltmeter, ADC, barometer, calibration models: preset defaults)"
                ));
                Scenario::preset(BASE_PRESET)
                    .ok_or_else(|| SimError::Twin("preset missing".into()))?
            }
        };
        s.name = format!("twin of {}", ds.output_name);
        s.description = format!(
            "Simulated twin of a measured record ({}, {} points)",
            ds.output_name,
            ds.len()
        );
        // Time and place.
        match ds.start_unix_s {
            Some(u) => {
                s.run.start_utc = Utc(u).to_string();
                prov.push(format!("start_utc {}: from the record", s.run.start_utc));
            }
            None => prov.push(format!(
                "start_utc {}: scenario default (the record has no start time; the tide is \
                 placed at that date)",
                s.run.start_utc
            )),
        }
        match ds.site {
            Some((lat, lon, h)) => {
                s.site.latitude_deg = lat;
                s.site.longitude_deg = lon;
                s.site.height_m = h;
                prov.push(format!(
                    "site {lat:.4}° N, {lon:.4}° E, {h} m: from the record"
                ));
            }
            None => prov.push(format!(
                "site {:.4}° N, {:.4}° E: scenario default (the record has no site)",
                s.site.latitude_deg, s.site.longitude_deg
            )),
        }
        let t_s = ds.t_s.clone();
        let t_last = t_s.last().copied().unwrap_or(0.0);
        s.run.interval_s = ds.dt_s;
        s.run.duration_s = (t_last + ds.dt_s).max(ds.dt_s);
        prov.push(format!(
            "interval {} s, duration {:.3} d: from the record ({} points, the twin predicts at \
             its own time stamps)",
            s.run.interval_s,
            s.run.duration_s / 86_400.0,
            ds.len()
        ));
        // The instrument.
        let rec_unit = ds.output_unit.to_ascii_lowercase();
        let gravity = is_gravity_record(ds);
        if derived && gravity {
            let unit = if UNITS.contains(&rec_unit.as_str()) {
                rec_unit.clone()
            } else {
                return Err(SimError::Twin(format!(
                    "gravity record in an unknown unit {:?} (known: {})",
                    ds.output_unit,
                    UNITS.join(", ")
                )));
            };
            let (a, b) = line_fit(&t_s, &ds.y);
            let per_nm =
                unit_per_g_for_suffix(&unit).unwrap_or(1.0) / (STANDARD_GRAVITY_M_S2 * 1e9);
            let g = GravimeterParams {
                name: format!("twin of {}", ds.output_name),
                unit: unit.clone(),
                offset: a,
                drift_per_day: b * 86_400.0,
                tide_factor: 1.0,
                tide_delay_s: 0.0,
                pressure_admittance_per_hpa: 0.0,
                // A spring gravimeter's reading noise: ≈ 1 µGal (10 nm/s²) at 1 s, flicker floor
                // 0.05 µGal.
                noise: AllanParams {
                    white_adev_1s: 10.0 * per_nm,
                    flicker_floor: 0.5 * per_nm,
                    random_walk_per_sqrt_s: 0.0,
                },
            };
            prov.push(format!(
                "instrument: gravimeter, unit {unit}: from the record's output column {}",
                ds.output_name
            ));
            prov.push(format!(
                "offset {a:.6} {unit} and drift {:.6} {unit}/day: least-squares line of the record",
                b * 86_400.0
            ));
            prov.push(
                "tide factor 1 (the model's elastic Earth), delay 0 s, pressure admittance 0: \
                 defaults (what the simulation does not know)"
                    .into(),
            );
            s.instrument = Some(InstrumentParams::Gravimeter(g));
        } else if derived {
            let input = ds.input_g.unwrap_or(1.0).clamp(-1.0, 1.0);
            s.accelerometer.orientation.positions = vec![HeadPosition {
                angle_deg: input.asin().to_degrees(),
                dwell_s: 0.0,
            }];
            prov.push(format!(
                "instrument: accelerometer (output {}), head at input {input} g: {}",
                ds.output_name,
                if ds.input_g.is_some() {
                    "input_g from the record"
                } else {
                    "input_g default 1 g (the record does not say)"
                }
            ));
            s.instrument = None;
        } else {
            prov.push(format!(
                "instrument: {} (base scenario)",
                if s.gravimeter().is_some() {
                    "gravimeter"
                } else {
                    "accelerometer"
                }
            ));
        }
        // Output units of the record per instrument unit, and per g.
        let inst_per_g = crate::sim::unit_per_g(&s)?;
        let rec_per_g = if rec_unit == "v" {
            if s.gravimeter().is_some() {
                return Err(SimError::Twin(
                    "a gravimeter cannot predict a record in volts".into(),
                ));
            }
            inst_per_g
        } else {
            match ds.unit_per_g.or_else(|| unit_per_g_for_suffix(&rec_unit)) {
                Some(u) => u,
                None => {
                    prov.push(format!(
                        "output unit {:?} unknown: the instrument's unit is taken as the record's",
                        ds.output_unit
                    ));
                    inst_per_g
                }
            }
        };
        let out_scale = rec_per_g / inst_per_g;
        // Noise levels.
        let inst_noise = match (noise, s.gravimeter()) {
            (Some(m), g) => {
                let rec = levels_of(m, ds.dt_s);
                prov.push(format!(
                    "noise from the fitted noise model: white {:.3e}/√Hz, flicker floor {:.3e}, \
                     random walk {:.3e}/√s ({})",
                    rec.white_adev_1s,
                    rec.flicker_floor,
                    rec.random_walk_per_sqrt_s,
                    ds.output_unit
                ));
                let inst = scaled(&rec, 1.0 / out_scale);
                match g {
                    Some(_) => {
                        if let Some(InstrumentParams::Gravimeter(gp)) = &mut s.instrument {
                            gp.noise = inst;
                        }
                    }
                    None => s.accelerometer.noise_g = scaled(&inst, 1.0 / inst_per_g),
                }
                inst
            }
            (None, Some(g)) => {
                prov.push("noise: the gravimeter's default levels (no noise model given)".into());
                g.noise
            }
            (None, None) => {
                prov.push("noise: the preset's accelerometer levels (no noise model given)".into());
                scaled(&s.accelerometer.noise_g, inst_per_g)
            }
        };
        s.validate()?;
        let drivers = drivers(ds, &s, &mut prov)?;
        let start = Utc::parse(&s.run.start_utc).map_err(|e| SimError::Twin(e.to_string()))?;
        let base = instrument_output(&s, start, &t_s, &drivers, out_scale)?;
        let mut twin = Twin {
            noise: scaled(&inst_noise, out_scale),
            noise_model: noise.cloned(),
            out_scale,
            unit_per_g: rec_per_g,
            dt_s: ds.dt_s,
            det: Vec::new(),
            base,
            drivers,
            t_s,
            provenance: prov,
            scenario: s,
        };
        let effects = std::mem::take(&mut twin.scenario.effects);
        twin.det = twin.base.clone();
        Ok(twin.extended(&effects))
    }

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
    pub fn run(&self, seed: Option<u64>) -> Result<Vec<f64>, SimError> {
        let mut out = match seed {
            Some(k) if self.redraws_weather() => self.output(&self.redrawn_drivers(k)?)?,
            _ => self.det.clone(),
        };
        match (seed, &self.noise_model) {
            (Some(seed), Some(m)) => add_model_noise(&mut out, &self.t_s, m, seed),
            (Some(seed), None) => add_noise(&mut out, &self.t_s, self.dt_s, &self.noise, seed),
            (None, _) => {}
        }
        Ok(out)
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
    fn output(&self, d: &Drivers) -> Result<Vec<f64>, SimError> {
        let start =
            Utc::parse(&self.scenario.run.start_utc).map_err(|e| SimError::Twin(e.to_string()))?;
        let mut y = instrument_output(&self.scenario, start, &self.t_s, d, self.out_scale)?;
        if !self.scenario.effects.is_empty() {
            let chain = EffectChain::new(&self.scenario.effects, self.chain_setup())
                .map_err(|e| SimError::Twin(e.to_string()))?;
            add_effects(&mut y, chain, &self.t_s, d);
        }
        Ok(y)
    }

    /// The drivers with the simulated ones drawn from the station run with `seed` (its weather:
    /// room, doors, thermostat, foundation creep, barometric weather; instrument and sensor
    /// noise do not enter, the truth values are taken). The station's streams (room, thermostat,
    /// foundation, barometer) are not the instrument noise's stream, so one seed serves both.
    fn redrawn_drivers(&self, seed: u64) -> Result<Drivers, SimError> {
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

/// The station's drivers from a run of `s` (tide off, no effects, accelerometer instrument) with
/// `seed`, at its own steps.
fn station_series(s: &Scenario, seed: u64) -> Result<StationSeries, SimError> {
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
    let p_mean =
        crate::sim::barometer::mean_pressure_hpa(s.barometer.sea_level_hpa, s.site.height_m);
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

/// The drivers at the record's instants: measured channels where present, the quiet
/// simulation's counterparts where absent.
fn drivers(ds: &Dataset, s: &Scenario, prov: &mut Vec<String>) -> Result<Drivers, SimError> {
    let n = ds.len();
    let start = Utc::parse(&s.run.start_utc).map_err(|e| SimError::Twin(e.to_string()))?;
    // The tide at the record's instants (and its tilt along the configured azimuth).
    let model = if s.tide.enabled {
        Some(TideModel::new(&s.site, s.tide.tilt_azimuth_deg)?)
    } else {
        prov.push("tide: disabled in the scenario".into());
        None
    };
    let mut sampler = TideSampler::new(model, start, s.tide.step_s);
    let (mut tide_nm_s2, mut tide_tilt_rad) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for &t in &ds.t_s {
        let x = sampler.at(t);
        tide_nm_s2.push(x.gravity_nm_s2);
        tide_tilt_rad.push(x.tilt_arcsec * RAD_PER_ARCSEC);
    }
    // The quiet station without its tide (added above), at the scenario's own steps.
    let mut q = quiet(s);
    q.tide.enabled = false;
    q.effects.clear();
    q.instrument = None;
    let StationSeries {
        temperature_c: sim_t,
        tilt_rad: sim_tilt,
        pressure_dev_pa: sim_p,
        room_c: sim_room,
        board_c: sim_board,
    } = station_series(&q, 0)?;
    let mut simulated = Simulated::default();
    let h = s.run.interval_s;
    let at = |v: &[f64]| -> Vec<f64> { ds.t_s.iter().map(|&t| interp(v, h, t)).collect() };
    let mut say = |what: &str, from: Option<&str>| {
        prov.push(match from {
            Some(c) => format!("{what}: the record's measured channel {c}"),
            None => format!(
                "{what}: simulated (the quiet station of the scenario; the record has none)"
            ),
        })
    };
    let temperature_c = match ds.channel(ChannelKind::Temperature) {
        Some(c) => {
            say("temperature", Some(&c.name));
            c.values.clone()
        }
        None => {
            say("temperature", None);
            simulated.temperature = true;
            at(&sim_t)
        }
    };
    let tilt_rad = match ds.channel(ChannelKind::Tilt) {
        Some(c) => {
            say("tilt", Some(&c.name));
            c.values.clone()
        }
        None => {
            say("tilt (tide tilt added)", None);
            simulated.tilt = true;
            at(&sim_tilt)
                .iter()
                .zip(&tide_tilt_rad)
                .map(|(a, b)| a + b)
                .collect()
        }
    };
    let pressure_dev_pa = match ds.channel(ChannelKind::Pressure) {
        Some(c) => {
            say("pressure (centred on its mean)", Some(&c.name));
            centred(&c.values)
        }
        None => {
            say("pressure", None);
            simulated.pressure = true;
            at(&sim_p)
        }
    };
    let head = DividingHead::new(&s.accelerometer.orientation)?;
    let input_g = match (ds.changing_input(), s.gravimeter()) {
        (_, Some(_)) => vec![1.0; n],
        (Some(a), None) => {
            say("input", Some("input_g"));
            a.to_vec()
        }
        (None, None) => {
            // The head programme of the scenario (its nominal angle, no indexing error).
            let mut head = head;
            let mut rng = stream(0, 0);
            ds.t_s
                .iter()
                .map(|&t| head.angle_rad(t, &mut rng).sin())
                .collect()
        }
    };
    let mut ambient_names = Vec::new();
    let mut ambient = Vec::new();
    for c in ds.channels.iter().filter(|c| c.kind == ChannelKind::Other) {
        ambient_names.push(c.name.clone());
        ambient.push(centred(&c.values));
        simulated.ambient.push(false);
    }
    for (name, v) in SIMULATED_AMBIENT.iter().zip([&sim_room, &sim_board]) {
        if !ambient_names.iter().any(|a| a == name) {
            ambient_names.push((*name).to_owned());
            ambient.push(at(v));
            simulated.ambient.push(true);
        }
    }
    Ok(Drivers {
        temperature_c,
        tilt_rad,
        pressure_dev_pa,
        input_g,
        ambient_names,
        ambient,
        tide_nm_s2,
        tide_tilt_rad,
        simulated,
    })
}

/// The instrument's deterministic output at the record's instants, record unit.
fn instrument_output(
    s: &Scenario,
    start: Utc,
    t_s: &[f64],
    d: &Drivers,
    out_scale: f64,
) -> Result<Vec<f64>, SimError> {
    if let Some(g) = s.gravimeter() {
        let per_nm = g
            .unit_per_nm_s2()
            .ok_or_else(|| SimError::Twin(format!("unknown gravity unit {:?}", g.unit)))?;
        // The delayed tide: its own sampler (the undelayed series is in the drivers).
        let tide = if g.tide_delay_s != 0.0 && s.tide.enabled {
            let mut sm = TideSampler::new(
                Some(TideModel::new(&s.site, s.tide.tilt_azimuth_deg)?),
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
    let models = s.accelerometer.calibration.load(s.thermostat.setpoint_c)?;
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

/// Adds one draw of the fitted noise model at the instants `t` (white per point, each flicker
/// component an OU process advanced over the actual spacing, the random walk).
fn add_model_noise(out: &mut [f64], t: &[f64], m: &NoiseModel, seed: u64) {
    let mut rng = stream(seed, TWIN_NOISE_STREAM);
    let white = m.white_var.max(0.0).sqrt();
    let mut x: Vec<f64> = m
        .flicker
        .iter()
        .map(|&(_, v)| v.max(0.0).sqrt() * gauss(&mut rng))
        .collect();
    let mut walk = 0.0;
    let mut last = t.first().copied().unwrap_or(0.0);
    for (y, &ti) in out.iter_mut().zip(t) {
        let dt = (ti - last).max(0.0);
        last = ti;
        let mut f = 0.0;
        for (xc, &(tau, v)) in x.iter_mut().zip(&m.flicker) {
            if dt > 0.0 {
                let phi = (-dt / tau).exp();
                *xc = phi * *xc + (v.max(0.0) * (1.0 - phi * phi)).sqrt() * gauss(&mut rng);
            }
            f += *xc;
        }
        walk += (m.rw_per_s.max(0.0) * dt).sqrt() * gauss(&mut rng);
        *y += white * gauss(&mut rng) + f + walk;
    }
}

/// Ratio between successive flicker correlation times (as `noise::Flicker`).
const FLICKER_RATIO: f64 = 3.162_277_660_168_379_5;

/// Adds white + flicker + random-walk noise with the Allan levels `p` at the (irregular)
/// instants `t`: each flicker component and the walk are advanced exactly over the actual
/// spacing (an OU process sampled at any instants is an AR(1) with φ = e^{−Δ/τ}); the white
/// part is that of a sample averaged over the nominal spacing `dt_s`.
fn add_noise(out: &mut [f64], t: &[f64], dt_s: f64, p: &AllanParams, seed: u64) {
    let mut rng = stream(seed, TWIN_NOISE_STREAM);
    let span = (t.last().copied().unwrap_or(0.0) - t.first().copied().unwrap_or(0.0)).max(dt_s);
    let white = p.white_adev_1s / dt_s.max(1e-9).sqrt();
    // Flicker components: correlation times from Δ to 10× the span, equal variances.
    let mut taus = Vec::new();
    if p.flicker_floor > 0.0 {
        let mut tau = dt_s;
        while tau <= 10.0 * span * FLICKER_RATIO {
            taus.push(tau);
            tau *= FLICKER_RATIO;
        }
    }
    let v = p.flicker_floor.powi(2) * FLICKER_RATIO.ln() / (2.0 * std::f64::consts::LN_2);
    let sd = v.sqrt();
    let mut x: Vec<f64> = taus.iter().map(|_| sd * gauss(&mut rng)).collect();
    let mut walk = 0.0;
    let mut last = t.first().copied().unwrap_or(0.0);
    for (y, &ti) in out.iter_mut().zip(t) {
        let dt = (ti - last).max(0.0);
        last = ti;
        let mut f = 0.0;
        for (xc, tau) in x.iter_mut().zip(&taus) {
            if dt > 0.0 {
                let phi = (-dt / tau).exp();
                *xc = phi * *xc + sd * (1.0 - phi * phi).sqrt() * gauss(&mut rng);
            }
            f += *xc;
        }
        walk += p.random_walk_per_sqrt_s * dt.sqrt() * gauss(&mut rng);
        *y += white * gauss(&mut rng) + f + walk;
    }
}

/// The accepted effects of a discovery as scenario entries, with their joint-fit parameters
/// (`select::Accepted::params`, which the final joint fit wrote), and the effects that cannot
/// be expressed, each with why.
///
/// `tidal_gravity` is written from the wave-group analysis when the discovery has one (a
/// factor and a phase per group against the model's elastic tide: the delay is in the phases),
/// else as its single `amplitude_factor`. `warmup`'s amplitude is moved from the record's first
/// instant to t = 0 (exactly: A·e^{−(t−t₀)/τ} = A·e^{t₀/τ}·e^{−t/τ}).
pub fn scenario_effects_from_discovery(
    d: &crate::discover::Discovery,
) -> (Vec<ScenarioEffect>, Vec<(String, String)>) {
    let mut out = Vec::new();
    let mut refused = Vec::new();
    let t0 = d.dataset.t_s.first().copied().unwrap_or(0.0);
    for a in &d.selection.accepted {
        let name = a.effect.name();
        let p = |key: &str| -> Option<f64> {
            a.params
                .iter()
                .find(|(k, _)| k == key)
                .map(|(_, v)| v.value)
                .filter(|v| v.is_finite())
        };
        let need =
            |key: &str| p(key).ok_or_else(|| format!("parameter {key} missing or not finite"));
        let e: Result<ScenarioEffect, String> = (|| {
            Ok(match a.effect.kind() {
                EffectKind::ThermalLag => ScenarioEffect::ThermalLag {
                    tau_s: need("tau_s")?,
                    coefficient: need("coefficient")?,
                },
                EffectKind::ThermalHysteresis => ScenarioEffect::ThermalHysteresis {
                    half_width: need("half_width")?,
                    play_half_width_c: need("play_half_width_c")?,
                },
                EffectKind::SelfHeating => ScenarioEffect::SelfHeating {
                    tau_s: need("tau_s")?,
                    coefficient: need("coefficient")?,
                },
                EffectKind::Warmup => {
                    let tau_s = need("tau_s")?;
                    ScenarioEffect::Warmup {
                        tau_s,
                        amplitude: need("amplitude")? * (t0 / tau_s).exp(),
                    }
                }
                EffectKind::AgingDrift => ScenarioEffect::AgingDrift {
                    tau_s: need("tau_s")?,
                    amplitude: need("amplitude")?,
                },
                EffectKind::Step => ScenarioEffect::Step {
                    time_s: need("time_s")?,
                    size: need("size")?,
                    duration_s: p("duration_s").unwrap_or(0.0),
                },
                EffectKind::TidalGravity => match &d.tidal {
                    Ok(t) if !t.groups.is_empty() => ScenarioEffect::TidalGravity {
                        amplitude_factor: 0.0,
                        delay_s: 0.0,
                        groups: t
                            .groups
                            .iter()
                            .filter(|g| {
                                g.amplitude_factor_vs_elastic_model.value.is_finite()
                                    && g.phase_vs_elastic_model_deg.value.is_finite()
                            })
                            .map(|g| crate::sim::effects::TideGroupTerm {
                                name: g.name.clone(),
                                factor: g.amplitude_factor_vs_elastic_model.value,
                                phase_deg: g.phase_vs_elastic_model_deg.value,
                            })
                            .collect(),
                    },
                    _ => ScenarioEffect::TidalGravity {
                        amplitude_factor: need("amplitude_factor")?,
                        delay_s: 0.0,
                        groups: Vec::new(),
                    },
                },
                EffectKind::TidalTilt => ScenarioEffect::TidalTilt {
                    amplitude_factor: need("amplitude_factor")?,
                    azimuth_deg: need("azimuth_deg")?,
                },
                EffectKind::BuildingTilt => ScenarioEffect::BuildingTilt {
                    amplitude: need("amplitude")?,
                    phase_rad: need("phase_rad")?,
                },
                EffectKind::TiltCoupling => ScenarioEffect::TiltCoupling {
                    gain: need("gain")?,
                },
                EffectKind::AmbientCoupling => {
                    let channel = a.effect.channel().unwrap_or_default().to_owned();
                    let in_record = d.dataset.channels.iter().any(|c| c.name == channel);
                    if !in_record && !SIMULATED_AMBIENT.contains(&channel.as_str()) {
                        return Err(format!(
                            "channel {channel:?} is neither in the record nor simulated"
                        ));
                    }
                    ScenarioEffect::AmbientCoupling {
                        channel,
                        coefficient: need("coefficient")?,
                        lag_s: p("lag_s").unwrap_or(0.0).max(0.0),
                    }
                }
                EffectKind::PressureAdmittance => ScenarioEffect::PressureAdmittance {
                    coefficient: need("coefficient")?,
                },
                EffectKind::Periodic => ScenarioEffect::Periodic {
                    period_s: need("period_s")?,
                    amplitude: need("amplitude")?,
                    phase_rad: need("phase_rad")?,
                },
                EffectKind::RateCoupling | EffectKind::Lag2Coupling => {
                    let channel = a.effect.channel().unwrap_or_default().to_owned();
                    let drives = channel == "temperature_c"
                        || channel.starts_with("pressure")
                        || d.dataset.channels.iter().any(|c| c.name == channel)
                        || SIMULATED_AMBIENT.contains(&channel.as_str());
                    if !drives {
                        return Err(format!("channel {channel:?} is not a driver of the twin"));
                    }
                    if a.effect.kind() == EffectKind::RateCoupling {
                        ScenarioEffect::RateCoupling {
                            channel,
                            coefficient: need("coefficient")?,
                        }
                    } else {
                        ScenarioEffect::Lag2Coupling {
                            channel,
                            tau_s: need("tau_s")?,
                            coefficient: need("coefficient")?,
                        }
                    }
                }
                // The discovery's creep starts at the record's first instant, the scenario's at
                // t = 0: the same curve only when they coincide.
                EffectKind::CreepDrift if t0.abs() > d.dataset.dt_s => {
                    return Err(format!(
                        "the record starts at t = {t0:.0} s and a power law cannot be moved to \
                         t = 0 exactly"
                    ))
                }
                EffectKind::CreepDrift => ScenarioEffect::CreepDrift {
                    exponent: need("exponent")?,
                    amplitude: need("amplitude")?,
                },
                EffectKind::ChannelNoise => {
                    let channel = a.effect.channel().unwrap_or_default().to_owned();
                    ScenarioEffect::ChannelNoise {
                        channel,
                        noise: p("noise")
                            .or_else(|| p("level"))
                            .ok_or("parameter noise missing")?,
                    }
                }
            })
        })();
        match e.and_then(|e| {
            let i = out.len();
            e.validate(i).map(|()| e).map_err(|x| x.to_string())
        }) {
            Ok(e) => out.push(e),
            Err(why) => refused.push((name.to_owned(), why)),
        }
    }
    (out, refused)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::discover::import::{dataset_from_log, DatasetOptions};
    use crate::log::Log;
    use crate::sim::{simulate, Options};

    /// A 2-day gravimeter log at 5 min from the simulator itself (tide, drift, admittance,
    /// noise), read back as the discovery reads records.
    fn gravimeter_scenario() -> Scenario {
        let mut s = Scenario::preset("paper-1g").unwrap();
        s.run.duration_s = 2.0 * 86_400.0;
        s.run.interval_s = 300.0;
        s.tide.step_s = 300.0;
        s.instrument = Some(InstrumentParams::Gravimeter(GravimeterParams {
            name: "test gravimeter".into(),
            unit: "ugal".into(),
            offset: 1000.0,
            drift_per_day: 50.0,
            tide_factor: 1.0,
            tide_delay_s: 0.0,
            pressure_admittance_per_hpa: -0.3,
            noise: AllanParams {
                white_adev_1s: 2.0,
                flicker_floor: 0.0,
                random_walk_per_sqrt_s: 0.0,
            },
        }));
        s
    }

    fn dataset(s: &Scenario, seed: u64) -> Dataset {
        let bytes = simulate(s, seed, &Options::default(), Vec::new(), &mut |_, _| {})
            .unwrap()
            .1;
        let log = Log::read(&bytes[..]).unwrap();
        dataset_from_log(
            &log,
            &DatasetOptions {
                output: None,
                max_points: 1_000_000,
                unit_per_g_from_calibration: None,
            },
        )
        .unwrap()
    }

    /// Standard deviation about a least-squares line in time (the derived twin's offset and
    /// drift come from a line through the record, which also takes the linear part of what the
    /// twin does not know).
    fn detrended_std(t: &[f64], v: &[f64]) -> f64 {
        let (a, b) = line_fit(t, v);
        let r: Vec<f64> = t.iter().zip(v).map(|(t, y)| y - a - b * t).collect();
        std(&r)
    }

    fn std(v: &[f64]) -> f64 {
        let n = v.len() as f64;
        let m = v.iter().sum::<f64>() / n;
        (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / n).sqrt()
    }

    #[test]
    fn a_gravimeter_log_is_written_in_its_unit_and_its_twin_predicts_the_tide() {
        let s = gravimeter_scenario();
        let ds = dataset(&s, 4);
        assert_eq!(ds.output_name, "gravity_ugal");
        assert_eq!(ds.output_unit, "ugal");
        let twin = Twin::new(&ds, None, None).unwrap();
        assert!(twin.scenario().gravimeter().is_some());
        assert!(twin.provenance().iter().any(|l| l.contains("pressure")));
        let det = twin.run(None).unwrap();
        assert_eq!(det.len(), ds.len());
        let resid: Vec<f64> = ds.y.iter().zip(&det).map(|(a, b)| a - b).collect();
        // The record: tide (~±100 µGal) + pressure·(−0.3 µGal/hPa) + white 2/√300 µGal. The
        // twin knows the tide and the line, not the admittance: what is left is the pressure
        // term (weather of a few hPa over 2 days) and the noise — far below the tide.
        assert!(std(&ds.y) > 20.0, "{}", std(&ds.y));
        let p = ds.channel(ChannelKind::Pressure).unwrap();
        let pstd_hpa = std(&p.values) / 100.0;
        assert!(
            std(&resid) < 0.3 * pstd_hpa + 0.5,
            "residual {} vs pressure {pstd_hpa} hPa",
            std(&resid)
        );
        // Extended by the true admittance (µGal per Pa), the residual falls to the noise.
        let ext = twin.extended(&[ScenarioEffect::PressureAdmittance {
            coefficient: -0.3 / 100.0,
        }]);
        let det2 = ext.run(None).unwrap();
        let r2: Vec<f64> = ds.y.iter().zip(&det2).map(|(a, b)| a - b).collect();
        let (before, after) = (detrended_std(&ds.t_s, &resid), detrended_std(&ds.t_s, &r2));
        assert!(after < 0.2 && after < 0.3 * before, "{after} vs {before}");
        assert_eq!(ext.scenario().effects.len(), 1);
    }

    #[test]
    fn an_accelerometer_twin_follows_the_measured_temperature_and_tilt() {
        let mut s = Scenario::preset("paper-1g").unwrap();
        s.run.duration_s = 86_400.0;
        s.run.interval_s = 120.0;
        let ds = dataset(&s, 2);
        let twin = Twin::new(&ds, None, None).unwrap();
        assert!(twin.scenario().gravimeter().is_none());
        let det = twin.run(None).unwrap();
        let resid: Vec<f64> = ds.y.iter().zip(&det).map(|(a, b)| a - b).collect();
        // Same models, the RTD's offset (≤ 0.1 °C, a constant) and the noise are what differ:
        // the residual's spread is far below the record's.
        assert!(
            std(&resid) < 0.3 * std(&ds.y),
            "{} vs {}",
            std(&resid),
            std(&ds.y)
        );
    }

    #[test]
    fn members_are_seeded_and_carry_the_noise_level() {
        let s = gravimeter_scenario();
        let ds = dataset(&s, 4);
        let twin = Twin::new(&ds, None, None).unwrap();
        let det = twin.run(None).unwrap();
        let a = twin.run(Some(1)).unwrap();
        assert_eq!(a, twin.run(Some(1)).unwrap());
        assert_ne!(a, twin.run(Some(2)).unwrap());
        let n: Vec<f64> = a.iter().zip(&det).map(|(x, y)| x - y).collect();
        // Default gravimeter noise: 10 nm/s² = 1 µGal at 1 s, white: 1/√300 µGal per point,
        // seen in the first differences (/√2), where the 0.05 µGal flicker floor adds ~20 %.
        let d: Vec<f64> = n.windows(2).map(|w| (w[1] - w[0]) / 2f64.sqrt()).collect();
        let want = 1.0 / 300f64.sqrt();
        assert!((std(&d) / want - 1.1).abs() < 0.2, "{} vs {want}", std(&d));
    }

    #[test]
    fn members_draw_from_a_given_noise_model_and_the_scenario_gets_its_levels() {
        let s = gravimeter_scenario();
        let ds = dataset(&s, 4);
        // White noise of 0.5 µGal per point (at the record's 300 s spacing).
        let m = NoiseModel::white(0.25);
        let twin = Twin::new(&ds, None, Some(&m)).unwrap();
        let det = twin.run(None).unwrap();
        let n: Vec<f64> = twin
            .run(Some(3))
            .unwrap()
            .iter()
            .zip(&det)
            .map(|(a, b)| a - b)
            .collect();
        assert!((std(&n) / 0.5 - 1.0).abs() < 0.1, "{}", std(&n));
        let g = twin.scenario().gravimeter().unwrap();
        // √h_w with h_w = 0.25 µGal²·300 s.
        assert!((g.noise.white_adev_1s / (0.25f64 * 300.0).sqrt() - 1.0).abs() < 1e-9);
        assert!(twin
            .provenance()
            .iter()
            .any(|l| l.contains("fitted noise model")));
    }

    #[test]
    fn members_redraw_the_weather_of_simulated_drivers_only() {
        let mut s = Scenario::preset("paper-1g").unwrap();
        s.run.duration_s = 86_400.0;
        s.run.interval_s = 300.0;
        let full = dataset(&s, 2);
        let m = NoiseModel::white(1e-14);
        // Every driver the accelerometer follows is measured: members are the deterministic
        // part plus the instrument noise.
        let twin = Twin::new(&full, None, Some(&m)).unwrap();
        assert!(
            twin.weather_drivers().is_empty(),
            "{:?}",
            twin.weather_drivers()
        );
        let det = twin.run(None).unwrap();
        let d1: Vec<f64> = twin
            .run(Some(1))
            .unwrap()
            .iter()
            .zip(&det)
            .map(|(a, b)| a - b)
            .collect();
        assert!((std(&d1) / 1e-7 - 1.0).abs() < 0.2, "{}", std(&d1));
        // Without a temperature channel the twin simulates it; each member draws its own
        // weather: member − deterministic part is far above the instrument noise, differs
        // between seeds and is reproducible.
        let mut no_t = full.clone();
        no_t.channels.retain(|c| c.kind != ChannelKind::Temperature);
        let twin = Twin::new(&no_t, None, Some(&m)).unwrap();
        assert_eq!(twin.weather_drivers(), vec!["temperature".to_owned()]);
        let det = twin.run(None).unwrap();
        let r = |k| -> Vec<f64> {
            twin.run(Some(k))
                .unwrap()
                .iter()
                .zip(&det)
                .map(|(a, b)| a - b)
                .collect()
        };
        let (a, b) = (r(1), r(2));
        assert_eq!(a, r(1));
        assert!(
            std(&a) > 10.0 * 1e-7 && std(&b) > 10.0 * 1e-7,
            "{} {}",
            std(&a),
            std(&b)
        );
        let diff: Vec<f64> = a.iter().zip(&b).map(|(x, y)| x - y).collect();
        assert!(std(&diff) > 10.0 * 1e-7, "{}", std(&diff));
        // A gravimeter without admittance follows no simulated driver until an effect uses one.
        let g = dataset(&gravimeter_scenario(), 4);
        let mut g_no_t = g.clone();
        g_no_t
            .channels
            .retain(|c| c.kind != ChannelKind::Temperature);
        let gt = Twin::new(&g_no_t, None, None).unwrap();
        assert!(gt.weather_drivers().is_empty());
        let ext = gt.extended(&[ScenarioEffect::ThermalLag {
            tau_s: 3600.0,
            coefficient: 1.0,
        }]);
        assert_eq!(ext.weather_drivers(), vec!["temperature".to_owned()]);
        let det = ext.run(None).unwrap();
        assert_ne!(ext.run(Some(1)).unwrap(), ext.run(Some(2)).unwrap());
        assert_eq!(det, ext.run(None).unwrap());
    }

    #[test]
    fn scenario_toml_with_effects_and_a_gravimeter_round_trips() {
        let mut s = gravimeter_scenario();
        s.effects = vec![
            ScenarioEffect::Step {
                time_s: 3600.0,
                size: 5.0,
                duration_s: 0.0,
            },
            ScenarioEffect::TidalGravity {
                amplitude_factor: 0.0,
                delay_s: 0.0,
                groups: vec![crate::sim::effects::TideGroupTerm {
                    name: "M2".into(),
                    factor: 0.02,
                    phase_deg: 1.5,
                }],
            },
        ];
        let text = s.to_toml();
        assert!(
            text.contains("[[effects]]") && text.contains("kind = \"gravimeter\""),
            "{text}"
        );
        assert_eq!(Scenario::from_toml(&text).unwrap(), s);
    }
}

#[cfg(test)]
mod from_discovery_tests {
    use super::*;
    use crate::discover::import::{dataset_from_log, DatasetOptions};
    use crate::log::Log;
    use crate::sim::{simulate, Options};

    #[test]
    fn a_discovered_step_becomes_a_scenario_effect_that_simulates() {
        // A 3-day paper-1g log at 5 min with its noise and a 15 µg step at 1.4 d.
        let mut s = Scenario::preset("paper-1g").unwrap();
        s.run.duration_s = 3.0 * 86_400.0;
        s.run.interval_s = 300.0;
        let mut hidden = s.clone();
        hidden.effects = vec![ScenarioEffect::Step {
            time_s: 1.4 * 86_400.0 + 150.0,
            size: 2e-5,
            duration_s: 0.0,
        }];
        let bytes = simulate(&hidden, 5, &Options::default(), Vec::new(), &mut |_, _| {})
            .unwrap()
            .1;
        let ds = dataset_from_log(
            &Log::read(&bytes[..]).unwrap(),
            &DatasetOptions {
                output: None,
                max_points: 1_000_000,
                unit_per_g_from_calibration: None,
            },
        )
        .unwrap();
        let d = crate::discover::discover(ds, None, &crate::discover::select::Config::default())
            .unwrap();
        let (effects, refused) = scenario_effects_from_discovery(&d);
        let step = effects
            .iter()
            .find_map(|e| match e {
                ScenarioEffect::Step { time_s, size, .. } => Some((*time_s, *size)),
                _ => None,
            })
            .unwrap_or_else(|| panic!("no step among {effects:?} (refused {refused:?})"));
        assert!(
            (step.0 - (1.4 * 86_400.0 + 150.0)).abs() <= 300.0,
            "{step:?}"
        );
        assert!((step.1 / 2e-5 - 1.0).abs() < 0.1, "{step:?}");
        // Written into the scenario, every converted effect validates and runs.
        let mut ext = s.clone();
        ext.effects = effects;
        let back = Scenario::from_toml(&ext.to_toml()).unwrap();
        assert_eq!(back, ext);
        let mut short = back;
        short.run.duration_s = 3600.0;
        simulate(&short, 1, &Options::default(), Vec::new(), &mut |_, _| {}).unwrap();
    }
}
