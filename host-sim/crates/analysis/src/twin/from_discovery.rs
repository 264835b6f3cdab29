//! The accepted effects of a discovery as the twin's scenario entries.

use super::*;

use crate::sim::twin::draw::{
    Alternative, Drawn, EffectDraw, EffectDraws, NamedParam, TideGroupDraw,
};

/// A fitted parameter as the simulator's [`Drawn`]; a σ that is not a finite number is 0
/// (the rule does not draw either: the scenario holds finite numbers only).
fn drawn_of(p: &crate::discover::effects::Param) -> Drawn {
    Drawn {
        value: p.value,
        sigma: if p.sigma.is_finite() { p.sigma } else { 0.0 },
    }
}

/// Named fitted parameters as the simulator's; a parameter whose value is not finite is left
/// out (the rule treats both as missing).
fn named(params: &[(String, crate::discover::effects::Param)]) -> Vec<NamedParam> {
    params
        .iter()
        .filter(|(_, p)| p.value.is_finite())
        .map(|(name, p)| NamedParam {
            name: name.clone(),
            drawn: drawn_of(p),
        })
        .collect()
}

/// The accepted effects of a discovery with their joint-fit parameters
/// (`select::Accepted::params`, which the final joint fit wrote) and σ, the other cause of each
/// ambiguous pair, the wave-group analysis' groups and what the rule needs of the record: the
/// simulator's description, from which it makes the nominal scenario entries and each member's
/// draw (`accomp-sim`, `twin::draw`).
pub fn effect_draws(d: &crate::discover::Discovery) -> EffectDraws {
    EffectDraws {
        record_start_s: d.dataset.t_s.first().copied().unwrap_or(0.0),
        record_interval_s: d.dataset.dt_s,
        record_channels: d.dataset.channels.iter().map(|c| c.name.clone()).collect(),
        tide_groups: match &d.tidal {
            Ok(t) if !t.groups.is_empty() => Some(
                t.groups
                    .iter()
                    .filter(|g| {
                        g.amplitude_factor_vs_elastic_model.value.is_finite()
                            && g.phase_vs_elastic_model_deg.value.is_finite()
                    })
                    .map(|g| TideGroupDraw {
                        name: g.name.clone(),
                        factor: drawn_of(&g.amplitude_factor_vs_elastic_model),
                        phase_deg: drawn_of(&g.phase_vs_elastic_model_deg),
                    })
                    .collect(),
            ),
            _ => None,
        },
        effects: d
            .selection
            .accepted
            .iter()
            .map(|a| EffectDraw {
                kind: a.effect.name().to_owned(),
                channel: a.effect.channel().map(str::to_owned),
                params: named(&a.params),
                alternative: a.ambiguous_with.as_ref().map(|amb| Alternative {
                    kind: amb.other.clone(),
                    params: named(&amb.other_parameters),
                }),
            })
            .collect(),
        admittance_per_hpa: None,
    }
}

/// The accepted effects of a discovery as scenario entries, with their joint-fit parameters,
/// and the effects that cannot be expressed, each with why.
///
/// `tidal_gravity` is written from the wave-group analysis when the discovery has one (a
/// factor and a phase per group against the model's elastic tide: the delay is in the phases),
/// else as its single `amplitude_factor`. `warmup`'s amplitude is moved from the record's first
/// instant to t = 0 (exactly: A·e^{−(t−t₀)/τ} = A·e^{t₀/τ}·e^{−t/τ}).
pub fn scenario_effects_from_discovery(
    d: &crate::discover::Discovery,
) -> (Vec<ScenarioEffect>, Vec<(String, String)>) {
    effect_draws(d).nominal()
}

/// One ensemble member's version of [`scenario_effects_from_discovery`]: every parameter drawn
/// from its fitted value and σ, the other cause of an ambiguous pair in odd members
/// (`accomp-sim`, `twin::draw::EffectDraws::drawn`, stream `EFFECT_DRAW_STREAM`).
pub fn scenario_effects_drawn(d: &crate::discover::Discovery, member: u64) -> Vec<ScenarioEffect> {
    effect_draws(d).drawn(member)
}

#[cfg(test)]
mod from_discovery_tests {
    use super::*;
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
        let ds = crate::twin::tests::dataset(&hidden, 5);
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
