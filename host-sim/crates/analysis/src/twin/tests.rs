//! The twin against the simulator: its prediction, members and scenario.

use super::build::line_fit;
use super::*;
use crate::discover::import::{dataset_from_log, DatasetOptions};
use crate::sim::simulate_log;

/// A 2-day gravimeter log at 5 min from the simulator itself (tide, drift, admittance,
/// noise), read back as the discovery reads records.
fn gravimeter_scenario() -> Scenario {
    let mut s = Scenario::preset("paper-1g").unwrap();
    s.run.duration_s = 2.0 * 86_400.0;
    s.run.interval_s = 300.0;
    s.tide.step_s = 300.0;
    s.instrument = Some(InstrumentParams::Gravimeter(GravimeterParams {
        offset: 1000.0,
        drift_per_day: 50.0,
        pressure_admittance_per_hpa: -0.3,
        noise: AllanParams {
            white_adev_1s: 2.0,
            ..AllanParams::NONE
        },
        ..GravimeterParams::ideal("test gravimeter", "ugal")
    }));
    s
}

/// The log the simulator writes for `s` with `seed`, read back as the discovery reads records
/// (every point kept).
pub(crate) fn dataset(s: &Scenario, seed: u64) -> Dataset {
    let log = simulate_log(s, seed).unwrap();
    dataset_from_log(&log, &DatasetOptions::with_max_points(1_000_000)).unwrap()
}

/// One day of paper-1g at `interval_s` (seed 2), read back as the discovery reads it.
fn paper_1g_day(interval_s: f64) -> Dataset {
    let mut s = Scenario::preset("paper-1g").unwrap();
    s.run.duration_s = 86_400.0;
    s.run.interval_s = interval_s;
    dataset(&s, 2)
}

/// Member `seed` of `twin` less its deterministic part `det`: what the member draws.
fn member_less(twin: &Twin, det: &[f64], seed: u64) -> Vec<f64> {
    twin.run(Some(seed))
        .unwrap()
        .iter()
        .zip(det)
        .map(|(a, b)| a - b)
        .collect()
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
    let ds = paper_1g_day(120.0);
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
    let n = member_less(&twin, &det, 3);
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
    let full = paper_1g_day(300.0);
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
    let d1 = member_less(&twin, &det, 1);
    assert!((std(&d1) / 1e-7 - 1.0).abs() < 0.2, "{}", std(&d1));
    // Without a temperature channel the twin simulates it; each member draws its own
    // weather: member − deterministic part is far above the instrument noise, differs
    // between seeds and is reproducible.
    let mut no_t = full.clone();
    no_t.channels.retain(|c| c.kind != ChannelKind::Temperature);
    let twin = Twin::new(&no_t, None, Some(&m)).unwrap();
    assert_eq!(twin.weather_drivers(), vec!["temperature".to_owned()]);
    let det = twin.run(None).unwrap();
    let r = |k| member_less(&twin, &det, k);
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
