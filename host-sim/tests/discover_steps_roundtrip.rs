//! Change points through the one catalogue, both ways: a scenario's `[[effects]]` with several
//! jumps of unequal sizes is simulated, `discover` reports them as `step`
//! with the scenario's parameter names and units (`time_s` s, `size` in the output unit,
//! `duration_s` s), and the discovered steps, turned back into scenario effects, are the
//! injected ones within the stated tolerances.

#[path = "common/hidden.rs"]
mod hidden;

use accomp_host::discover::import::{dataset_from_log, DatasetOptions};
use accomp_host::discover::{self as disc, select};
use accomp_host::log::Log;
use accomp_host::sim::catalogue::EffectKind;
use accomp_host::sim::effects::ScenarioEffect;
use accomp_host::sim::scenario::Scenario;
use accomp_host::sim::{simulate, Options};

/// Four days at five minutes.
const DAYS: f64 = 4.0;
const INTERVAL_S: f64 = 300.0;
/// Tolerances (those of the change-point tests, docs/discovery-causes.md): time ±2 samples,
/// size ±30 % or 3σ.
const TIME_TOL_S: f64 = 2.0 * INTERVAL_S;
const SIZE_TOL: f64 = 0.3;

#[test]
fn several_unequal_steps_injected_from_a_scenario_are_reported_and_written_back() {
    let mut sc = Scenario::preset("paper-1g").expect("preset");
    sc.run.duration_s = DAYS * 86_400.0;
    sc.run.interval_s = INTERVAL_S;
    // Unequal sizes, alternating sign (V, the output unit; ≈ 15, −9, 23 µg at the preset's
    // scale factor). Abrupt: the change-point set fits its steps as jumps (a 40-minute ramp
    // under this station's random walk is measured at about a third of its size, see
    // docs/discovery-causes.md).
    let injected = [
        (0.8 * 86_400.0 + 150.0, 2.0e-5, 0.0),
        (1.9 * 86_400.0 + 150.0, -1.2e-5, 0.0),
        (3.1 * 86_400.0 + 150.0, 3.0e-5, 0.0),
    ];
    let mut hidden = sc.clone();
    hidden.effects = injected
        .iter()
        .map(|&(time_s, size, duration_s)| ScenarioEffect::Step {
            time_s,
            size,
            duration_s,
        })
        .collect();
    // As a scenario file writes and reads them.
    let hidden = Scenario::from_toml(&hidden.to_toml()).expect("the scenario with its steps");
    assert_eq!(
        hidden
            .effects
            .iter()
            .filter(|e| e.kind() == EffectKind::Step)
            .count(),
        3
    );
    let bytes = simulate(&hidden, 9, &Options::default(), Vec::new(), &mut |_, _| {})
        .expect("simulate")
        .1;
    let ds = dataset_from_log(
        &Log::read(&bytes[..]).expect("log"),
        &DatasetOptions::default(),
    )
    .expect("dataset");
    assert_eq!(ds.output_unit, "v");
    let d = disc::discover(ds, None, &select::Config::default()).expect("discover");
    let (effects, refused) = accomp_host::twin::scenario_effects_from_discovery(&d);
    let found: Vec<(f64, f64, f64)> = effects
        .iter()
        .filter_map(|e| match e {
            ScenarioEffect::Step {
                time_s,
                size,
                duration_s,
            } => Some((*time_s, *size, *duration_s)),
            _ => None,
        })
        .collect();
    println!("injected {injected:?}\nfound {found:?}\nrefused {refused:?}");
    // The discovery's parameters are the catalogue's, in its order.
    for a in d
        .selection
        .accepted
        .iter()
        .filter(|a| a.effect.name() == "step")
    {
        // (`size_g` beside `size`: the same amplitude in g, when the unit per g is known.)
        let keys: Vec<&str> = a
            .params
            .iter()
            .map(|(k, _)| k.as_str())
            .filter(|k| !k.ends_with("_g"))
            .collect();
        assert_eq!(keys, EffectKind::Step.parameter_names());
    }
    // Each injected step among the reported ones, with the reported σ of its size.
    let reported = hidden::accepted_steps(&d);
    for (t, s, _) in injected {
        let hit = reported.iter().find(|f| {
            (f.0 - t).abs() <= TIME_TOL_S
                && ((f.1 / s - 1.0).abs() <= SIZE_TOL || (f.1 - s).abs() <= 3.0 * f.2)
        });
        assert!(
            hit.is_some(),
            "step at {t} s of {s:e} V not found in {reported:?}"
        );
    }
    // The scenario effects made of them are the same steps.
    assert_eq!(found.len(), reported.len());
    assert!(found.len() <= 4, "extra steps: {found:?}");
    // Written back, the found steps are a scenario the simulator runs.
    let mut back = sc.clone();
    back.effects = effects;
    let again = Scenario::from_toml(&back.to_toml()).expect("round trip");
    assert_eq!(again, back);
}
