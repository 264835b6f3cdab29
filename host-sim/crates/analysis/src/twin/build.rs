//! Building a twin from a record: the scenario derived from the record, its drivers at the
//! record's instants and the instrument's deterministic output.

use super::*;
use crate::sim::SimError;

pub(super) fn is_gravity_record(ds: &Dataset) -> bool {
    let unit = ds.output_unit.to_ascii_lowercase();
    UNITS.contains(&unit.as_str()) || ds.output_name.to_ascii_lowercase().starts_with("gravity")
}

/// Least-squares line `a + b·t` through (t, y).
pub(super) fn line_fit(t: &[f64], y: &[f64]) -> (f64, f64) {
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
pub(super) fn levels_of(m: &NoiseModel, dt_s: f64) -> AllanParams {
    AllanParams {
        // White variance σ² per point of spacing Δ: h_w = σ²·Δ, ADEV(τ) = √(h_w/τ), so at
        // 1 s √h_w.
        white_adev_1s: (m.white_var.max(0.0) * dt_s).sqrt(),
        flicker_floor: m.flicker_floor(),
        // Allan variance of the walk q·τ/3 = K²·τ/3.
        random_walk_per_sqrt_s: m.rw_per_s.max(0.0).sqrt(),
    }
}

pub(super) fn scaled(p: &AllanParams, k: f64) -> AllanParams {
    AllanParams {
        white_adev_1s: p.white_adev_1s * k.abs(),
        flicker_floor: p.flicker_floor * k.abs(),
        random_walk_per_sqrt_s: p.random_walk_per_sqrt_s * k.abs(),
    }
}

pub(super) fn centred(v: &[f64]) -> Vec<f64> {
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
    ) -> Result<Twin, TwinError> {
        if ds.len() < 2 {
            return Err(TwinError::TooShort { points: ds.len() });
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
                Scenario::preset(BASE_PRESET).ok_or(TwinError::PresetMissing(BASE_PRESET))?
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
                return Err(TwinError::UnknownGravityUnit {
                    unit: ds.output_unit.clone(),
                    known: UNITS.join(", "),
                });
            };
            let (a, b) = line_fit(&t_s, &ds.y);
            let per_nm =
                unit_per_g_for_suffix(&unit).unwrap_or(1.0) / (STANDARD_GRAVITY_M_S2 * 1e9);
            let g = GravimeterParams {
                offset: a,
                drift_per_day: b * 86_400.0,
                // A spring gravimeter's reading noise: ≈ 1 µGal (10 nm/s²) at 1 s, flicker floor
                // 0.05 µGal.
                noise: AllanParams {
                    white_adev_1s: 10.0 * per_nm,
                    flicker_floor: 0.5 * per_nm,
                    random_walk_per_sqrt_s: 0.0,
                },
                ..GravimeterParams::ideal(format!("twin of {}", ds.output_name), unit.clone())
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
                return Err(TwinError::GravimeterInVolts);
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
        s.validate().map_err(SimError::from)?;
        let drivers = drivers(ds, &s, &mut prov)?;
        let effects = std::mem::take(&mut s.effects);
        let (rec, _) = TwinRecord::new(s, t_s, drivers, rec_per_g, out_scale)?;
        let twin = Twin {
            noise: scaled(&inst_noise, out_scale),
            noise_model: noise.cloned(),
            family: None,
            drift: None,
            dt_s: ds.dt_s,
            rec,
            provenance: prov,
        };
        Ok(twin.extended(&effects))
    }
}

/// The drivers at the record's instants: measured channels where present, the quiet
/// simulation's counterparts where absent.
pub(super) fn drivers(
    ds: &Dataset,
    s: &Scenario,
    prov: &mut Vec<String>,
) -> Result<Drivers, TwinError> {
    let n = ds.len();
    let start = Utc::parse(&s.run.start_utc)?;
    // The tide at the record's instants (and its tilt along the configured azimuth).
    let model = if s.tide.enabled {
        Some(TideModel::new(&s.site, s.tide.tilt_azimuth_deg).map_err(SimError::from)?)
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
    // Each channel the record's own when it has it (named in the provenance), else the quiet
    // station's: (series, simulated?).
    let mut measured_or = |kind: ChannelKind,
                           measured_what: &str,
                           measured: fn(&[f64]) -> Vec<f64>,
                           simulated_what: &str,
                           simulated: &dyn Fn() -> Vec<f64>|
     -> (Vec<f64>, bool) {
        match ds.channel(kind) {
            Some(c) => {
                say(measured_what, Some(&c.name));
                (measured(&c.values), false)
            }
            None => {
                say(simulated_what, None);
                (simulated(), true)
            }
        }
    };
    let (temperature_c, sim_temperature) = measured_or(
        ChannelKind::Temperature,
        "temperature",
        <[f64]>::to_vec,
        "temperature",
        &|| at(&sim_t),
    );
    let (tilt_rad, sim_tilt_used) = measured_or(
        ChannelKind::Tilt,
        "tilt",
        <[f64]>::to_vec,
        "tilt (tide tilt added)",
        &|| {
            at(&sim_tilt)
                .iter()
                .zip(&tide_tilt_rad)
                .map(|(a, b)| a + b)
                .collect()
        },
    );
    let (pressure_dev_pa, sim_pressure) = measured_or(
        ChannelKind::Pressure,
        "pressure (centred on its mean)",
        centred,
        "pressure",
        &|| at(&sim_p),
    );
    simulated.temperature = sim_temperature;
    simulated.tilt = sim_tilt_used;
    simulated.pressure = sim_pressure;
    let head = DividingHead::new(&s.accelerometer.orientation).map_err(SimError::from)?;
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
