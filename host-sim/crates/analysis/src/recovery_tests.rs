//! Every `[[effects]]` kind, simulated alone into a quiet station, is recovered by the discovery
//! catalogue's own columns (`discover::effects::columns` / `parameters`) with its parameters in
//! the units the discovery reports them — the round trip `discover → scenario → simulate →
//! discover` that `accomp discover --simulate --write-scenario` relies on.
//!
//! Each case: a 3-day log at 5 min from a scenario whose instrument and sensor noise are off
//! (the room's weather stays: it gives the temperature and pressure their structure); the twin
//! of that log from the same scenario *without* the effect; the catalogue column fitted to the
//! log minus the twin (with an offset and a slope) over the catalogue's grid of its nonlinear
//! parameter, refined by golden section. Tolerances are stated per case.
//!
//! The simulator's log carries the nominal input and the room temperature only as truth
//! columns, which the importer never takes as regressors; for `self_heating` and
//! `ambient_coupling` the test adds them as the observables a record would have (`input_g`,
//! `room_c`), as a station with a head programme and a room sensor writes them.

use crate::discover::effects::{self, columns, Context, Effect, Param};
use crate::discover::import::{dataset_from_log, Dataset, DatasetOptions};
use crate::log::Log;
use crate::numerics::linalg::least_squares;
use crate::sim::effects::ScenarioEffect;
use crate::sim::scenario::Scenario;
use crate::sim::simulate_log;
use crate::sim::twin::record::silence_readings;
use crate::twin::Twin;

const DAY: f64 = 86_400.0;

/// paper-1g (or paper-0g) for 3 days at 5 min, noise off but for the room's weather.
fn quiet_station(preset: &str) -> Scenario {
    let mut s = Scenario::preset(preset).unwrap();
    s.run.duration_s = 3.0 * DAY;
    s.run.interval_s = 300.0;
    s.tide.step_s = 300.0;
    silence_readings(&mut s);
    s.tiltmeter.resolution_arcsec = 0.0;
    s.barometer.resolution_hpa = 0.0;
    // What the twin does not model (it predicts the instrument, not the converter, and reads the
    // RTD as the true temperature): the ADC reference's temperature drift and the RTD's offset
    // (the latter silenced with the readings).
    s.adc.ads1262.vref_tempco_ppm_per_c = 0.0;
    // The twin reads the RTD as the proof-mass temperature: no lag between them, and a room
    // coupling strong enough that the temperature moves by a good fraction of a degree.
    s.thermostat.proof_mass_lag_s = 0.0;
    s.thermostat.room_coupling = 0.5;
    s
}

fn dataset(s: &Scenario) -> Dataset {
    dataset_with(s, &[])
}

/// The log of `s` read back as the discovery reads records, with `extra` columns added, each
/// computed from the log's own columns.
#[allow(clippy::type_complexity)]
fn dataset_with(s: &Scenario, extra: &[(&str, &dyn Fn(&Log) -> Vec<f64>)]) -> Dataset {
    let mut log = simulate_log(s, 11).unwrap();
    for (name, f) in extra {
        let v = f(&log);
        log.push_column(name, v).unwrap();
    }
    dataset_from_log(&log, &DatasetOptions::with_max_points(1_000_000)).unwrap()
}

/// Log with `e`, and the log minus the twin without it.
fn residual(s: &Scenario, e: ScenarioEffect) -> (Dataset, Vec<f64>) {
    residual_with(s, e, &[])
}

/// [`residual`] with columns added to the log (see [`dataset_with`]).
#[allow(clippy::type_complexity)]
fn residual_with(
    s: &Scenario,
    e: ScenarioEffect,
    extra: &[(&str, &dyn Fn(&Log) -> Vec<f64>)],
) -> (Dataset, Vec<f64>) {
    let mut with = s.clone();
    with.effects = vec![e];
    let ds = dataset_with(&with, extra);
    let twin = Twin::new(&ds, Some(s.clone()), None).unwrap();
    let det = twin.run(None).unwrap();
    let r = ds.y.iter().zip(&det).map(|(a, b)| a - b).collect();
    (ds, r)
}

fn context(ds: &Dataset) -> Context {
    let tide = effects::tide_series(ds);
    let u = ds.unit_per_g.unwrap_or(1.0);
    Context {
        tide_gravity_g: tide.as_ref().map(|t| t.0.clone()),
        tide_tilt_rad: tide.map(|t| (t.1, t.2)),
        tilt_term: crate::discover::baseline::tilt_term_g(ds)
            .map(|v| v.iter().map(|x| x * u).collect()),
        hysteresis: None,
        full_rate: Vec::new(),
        rate_columns: Vec::new(),
    }
}

/// RSS and coefficients of [1, t, columns(θ)] fitted to `r`.
fn fit_at(e: &Effect, ds: &Dataset, ctx: &Context, r: &[f64], theta: f64) -> (f64, Vec<f64>) {
    let cols = columns(e, ds, ctx, theta);
    let rows: Vec<Vec<f64>> = (0..ds.len())
        .map(|i| {
            let mut row = vec![1.0, ds.t_s[i] / DAY];
            row.extend(cols.iter().map(|c| c[i]));
            row
        })
        .collect();
    match least_squares(&rows, r) {
        Ok(ls) => (ls.rss, ls.coeffs[2..].to_vec()),
        Err(_) => (f64::INFINITY, Vec::new()),
    }
}

/// [`recover`] over the catalogue's own grid of the effect's time scale.
fn recover_on_grid(e: &Effect, ds: &Dataset, r: &[f64]) -> Vec<(String, f64)> {
    recover(e, ds, r, &effects::grid(e, ds))
}

/// The best θ on `grid` refined by golden section between its neighbours (in ln θ for a
/// positive grid), and the named parameters there.
fn recover(e: &Effect, ds: &Dataset, r: &[f64], grid: &[f64]) -> Vec<(String, f64)> {
    let ctx = context(ds);
    let theta = if grid.is_empty() {
        f64::NAN
    } else {
        let k = (0..grid.len())
            .min_by(|&a, &b| {
                fit_at(e, ds, &ctx, r, grid[a])
                    .0
                    .total_cmp(&fit_at(e, ds, &ctx, r, grid[b]).0)
            })
            .unwrap_or(0);
        let positive = grid.iter().all(|g| *g > 0.0);
        type Map = fn(f64) -> f64;
        let (to, from): (Map, Map) = if positive {
            (f64::ln, f64::exp)
        } else {
            (|x| x, |x| x)
        };
        let (mut a, mut b) = (
            to(grid[k.saturating_sub(1)]),
            to(grid[(k + 1).min(grid.len() - 1)]),
        );
        let g = 0.618_033_988_749_895;
        for _ in 0..40 {
            let (c, d) = (b - g * (b - a), a + g * (b - a));
            if fit_at(e, ds, &ctx, r, from(c)).0 < fit_at(e, ds, &ctx, r, from(d)).0 {
                b = d;
            } else {
                a = c;
            }
        }
        from(0.5 * (a + b))
    };
    let (_, beta) = fit_at(e, ds, &ctx, r, theta);
    let se = vec![0.0; beta.len()];
    effects::parameters(
        e,
        ds,
        Param {
            value: theta,
            sigma: f64::NAN,
        },
        &beta,
        &se,
    )
    .into_iter()
    .map(|(k, v)| (k, v.value))
    .collect()
}

fn param(p: &[(String, f64)], key: &str) -> f64 {
    p.iter()
        .find(|(k, _)| k == key)
        .map_or(f64::NAN, |(_, v)| *v)
}

/// |got/want − 1| ≤ tol.
fn close(p: &[(String, f64)], key: &str, want: f64, tol: f64) {
    let got = param(p, key);
    assert!(
        (got / want - 1.0).abs() <= tol,
        "{key}: recovered {got:e}, simulated {want:e} (tolerance {tol}) — all: {p:?}"
    );
}

#[test]
fn thermal_effects_are_recovered_with_their_time_constant_and_size() {
    let s = quiet_station("paper-1g");
    let (ds, r) = residual(
        &s,
        ScenarioEffect::ThermalLag {
            tau_s: 1800.0,
            coefficient: 1e-3,
        },
    );
    let p = recover_on_grid(&Effect::ThermalLag, &ds, &r);
    close(&p, "tau_s", 1800.0, 0.05);
    close(&p, "coefficient", 1e-3, 0.02);

    let (ds, r) = residual(
        &s,
        ScenarioEffect::ThermalHysteresis {
            half_width: 5e-5,
            play_half_width_c: 0.1,
            relays: Vec::new(),
            lag_s: 0.0,
        },
    );
    // The catalogue's play grid starts at 3× the reading noise; the quiet RTD has none, so the
    // grid is taken over 0.01–1 °C here.
    let p = recover(
        &Effect::ThermalHysteresis,
        &ds,
        &r,
        &effects::log_grid(0.01, 1.0, 24),
    );
    close(&p, "play_half_width_c", 0.1, 0.05);
    close(&p, "half_width", 5e-5, 0.05);
}

#[test]
fn transients_steps_and_lines_are_recovered_where_they_were_put() {
    let s = quiet_station("paper-1g");
    let cases: [(ScenarioEffect, Effect, &str, f64, &str, f64); 3] = [
        (
            ScenarioEffect::Warmup {
                tau_s: 6.0 * 3600.0,
                amplitude: 1e-4,
            },
            Effect::Warmup,
            "tau_s",
            6.0 * 3600.0,
            "amplitude",
            1e-4,
        ),
        (
            ScenarioEffect::AgingDrift {
                tau_s: DAY,
                amplitude: 5e-5,
            },
            Effect::AgingDrift,
            "tau_s",
            DAY,
            "amplitude",
            5e-5,
        ),
        (
            ScenarioEffect::Step {
                time_s: 1.3 * DAY,
                size: 2e-5,
                duration_s: 0.0,
            },
            Effect::Step { duration_s: 0.0 },
            "time_s",
            1.3 * DAY,
            "size",
            2e-5,
        ),
    ];
    for (inject, kind, k1, v1, k2, v2) in cases {
        let (ds, r) = residual(&s, inject);
        let grid = match kind {
            // The step's time: every sample time (the selection scans them the same way).
            Effect::Step { .. } => ds.t_s.clone(),
            _ => effects::grid(&kind, &ds),
        };
        let p = recover(&kind, &ds, &r, &grid);
        // Aging's time scale is weakly determined beside an offset and a slope over 3 days.
        let tol = if matches!(kind, Effect::AgingDrift) {
            0.15
        } else {
            0.02
        };
        close(&p, k1, v1, tol);
        close(&p, k2, v2, tol);
    }
    let (ds, r) = residual(
        &s,
        ScenarioEffect::Periodic {
            period_s: 5.0 * 3600.0,
            amplitude: 1e-5,
            phase_rad: 0.7,
        },
    );
    let p = recover(
        &Effect::Periodic,
        &ds,
        &r,
        &effects::log_grid(3600.0, DAY, 400),
    );
    close(&p, "period_s", 5.0 * 3600.0, 0.002);
    close(&p, "amplitude", 1e-5, 0.02);
    close(&p, "phase_rad", 0.7, 0.02);
}

#[test]
fn tide_building_tilt_and_pressure_terms_are_recovered_in_the_catalogues_units() {
    let s = quiet_station("paper-1g");
    // Each injected term, the catalogue's effect that describes it (no time scale to search)
    // and the parameters it must return, within 2 %.
    type Case = (ScenarioEffect, Effect, &'static [(&'static str, f64)]);
    let cases: [Case; 4] = [
        (
            ScenarioEffect::TidalGravity {
                amplitude_factor: 2.0,
                delay_s: 0.0,
                groups: Vec::new(),
            },
            Effect::TidalGravity,
            &[("amplitude_factor", 2.0)],
        ),
        (
            ScenarioEffect::TidalTilt {
                amplitude_factor: 50.0,
                azimuth_deg: 30.0,
            },
            Effect::TidalTilt,
            &[("amplitude_factor", 50.0), ("azimuth_deg", 30.0)],
        ),
        (
            ScenarioEffect::BuildingTilt {
                amplitude: 1e-5,
                phase_rad: 1.0,
            },
            Effect::BuildingTilt,
            &[("amplitude", 1e-5), ("phase_rad", 1.0)],
        ),
        (
            ScenarioEffect::PressureAdmittance { coefficient: 1e-8 },
            Effect::PressureAdmittance,
            &[("coefficient", 1e-8)],
        ),
    ];
    for (inject, kind, want) in cases {
        let (ds, r) = residual(&s, inject);
        let p = recover(&kind, &ds, &r, &[]);
        for &(key, value) in want {
            close(&p, key, value, 0.02);
        }
    }
}

#[test]
fn tilt_coupling_is_recovered_at_zero_g() {
    let s = quiet_station("paper-0g");
    let (ds, r) = residual(&s, ScenarioEffect::TiltCoupling { gain: 0.3 });
    let p = recover(&Effect::TiltCoupling, &ds, &r, &[]);
    // The catalogue's column is the measured tilt averaged over ±15 min; the simulated term
    // follows the true tilt sample by sample.
    close(&p, "gain", 0.3, 0.05);
}

#[test]
fn self_heating_is_recovered_from_the_head_programme() {
    use crate::sim::accelerometer::HeadPosition;
    let mut s = quiet_station("paper-1g");
    // 1 g and 0 g for 6 h each: the torquer's power (∝ a²) steps at every move.
    s.accelerometer.orientation.positions = vec![
        HeadPosition {
            angle_deg: 90.0,
            dwell_s: 6.0 * 3600.0,
        },
        HeadPosition {
            angle_deg: 0.0,
            dwell_s: 6.0 * 3600.0,
        },
    ];
    // The nominal input of each row, as a record with a head programme logs it.
    let input = |log: &Log| -> Vec<f64> {
        log.column("truth_head_angle_deg")
            .unwrap()
            .iter()
            .map(|a| a.to_radians().sin())
            .collect()
    };
    let (ds, r) = residual_with(
        &s,
        ScenarioEffect::SelfHeating {
            tau_s: 1800.0,
            coefficient: 2e-4,
        },
        &[("input_g", &input)],
    );
    assert!(
        ds.changing_input().is_some(),
        "the input_g column is not taken"
    );
    let p = recover_on_grid(&Effect::SelfHeating, &ds, &r);
    close(&p, "tau_s", 1800.0, 0.05);
    close(&p, "coefficient", 2e-4, 0.02);
}

#[test]
fn ambient_coupling_is_recovered_from_the_room_channel() {
    let s = quiet_station("paper-1g");
    // The room temperature as a record's auxiliary sensor logs it.
    let room = |log: &Log| -> Vec<f64> { log.column("truth_room_c").unwrap().to_vec() };
    let (ds, r) = residual_with(
        &s,
        ScenarioEffect::AmbientCoupling {
            channel: "room_c".into(),
            coefficient: 5e-5,
            lag_s: 2.0 * 3600.0,
        },
        &[("room_c", &room)],
    );
    // The importer takes room_c as an auxiliary channel, not as the temperature.
    assert_eq!(
        ds.channel(crate::discover::import::ChannelKind::Temperature)
            .map(|c| c.name.as_str()),
        Some("temperature_c")
    );
    let e = Effect::AmbientCoupling("room_c".into());
    let p = recover_on_grid(&e, &ds, &r);
    close(&p, "lag_s", 2.0 * 3600.0, 0.05);
    close(&p, "coefficient", 5e-5, 0.02);
}

#[test]
fn channel_noise_is_the_reading_noise_the_discovery_measures() {
    let mut s = quiet_station("paper-1g");
    // The thermostat's own fluctuation (0.165 °C, 15 min) moves the temperature between
    // 5-min samples by far more than 5 mK: a calm thermostat here.
    s.thermostat.controller_std_c = 0.0;
    s.thermostat.room_coupling = 0.03;
    let mut with = s.clone();
    with.effects = vec![ScenarioEffect::ChannelNoise {
        channel: "temperature_c".into(),
        noise: 0.005,
    }];
    let ds = dataset(&with);
    let n = crate::discover::residual::channel_noise(&ds);
    let t = n.iter().find(|c| c.channel == "temperature_c").unwrap();
    assert!((t.noise / 0.005 - 1.0).abs() < 0.15, "{}", t.noise);
}

#[test]
fn tide_group_corrections_of_a_gravimeter_are_what_the_tidal_analysis_reports() {
    use crate::sim::effects::TideGroupTerm;
    use crate::sim::gravimeter::{GravimeterParams, InstrumentParams};
    let mut s = quiet_station("paper-1g");
    // 30 days: every group is resolved from its neighbours (Rayleigh), none is merged.
    s.run.duration_s = 30.0 * DAY;
    s.run.interval_s = 1800.0;
    s.tide.step_s = 1800.0;
    s.instrument = Some(InstrumentParams::Gravimeter(GravimeterParams::ideal(
        "quiet gravimeter",
        "nm_s2",
    )));
    let (ds, r) = residual(
        &s,
        ScenarioEffect::TidalGravity {
            amplitude_factor: 0.0,
            delay_s: 0.0,
            groups: vec![
                TideGroupTerm {
                    name: "M2".into(),
                    factor: 0.05,
                    phase_deg: 10.0,
                },
                TideGroupTerm {
                    name: "O1".into(),
                    factor: -0.03,
                    phase_deg: 0.0,
                },
            ],
        },
    );
    let t = crate::discover::tidal::analyse(&ds, &r, &[]).unwrap();
    let names: Vec<&str> = t.groups.iter().map(|g| g.name.as_str()).collect();
    let group = |n: &str| {
        t.groups
            .iter()
            .find(|g| g.name == n)
            .unwrap_or_else(|| panic!("{}", names.join(",")))
    };
    let m2 = group("M2");
    assert!(
        (m2.amplitude_factor_vs_elastic_model.value - 0.05).abs() < 0.002,
        "{m2:?}"
    );
    assert!(
        (m2.phase_vs_elastic_model_deg.value - 10.0).abs() < 1.0,
        "{m2:?}"
    );
    // A negative factor is a factor of 0.03 at 180°.
    let o1 = group("O1");
    assert!(
        (o1.amplitude_factor_vs_elastic_model.value - 0.03).abs() < 0.002,
        "{o1:?}"
    );
    let ph = o1.phase_vs_elastic_model_deg.value.rem_euclid(360.0);
    assert!((ph - 180.0).abs() < 2.0, "{o1:?}");
    // Groups left alone stay near zero.
    let s2 = t.groups.iter().find(|g| g.name.contains("S2")).unwrap();
    assert!(s2.amplitude_factor_vs_elastic_model.value < 0.005, "{s2:?}");
}
