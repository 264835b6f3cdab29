//! The accepted effects of a discovery as the twin's scenario entries.

use super::*;

use crate::sim::twin::draw::{
    Alternative, Drawn, EffectDraw, EffectDraws, HysteresisShape, NamedParam, TideGroupDraw,
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

/// A fitted Preisach distribution as the simulator's [`HysteresisShape`]: each operator's
/// weight over the distribution's `reach` (the column is Σ weight × operator / reach, times the
/// effect's `half_width`), the relays by their thresholds, the output lag.
pub fn hysteresis_shape(p: &crate::discover::hysteresis::Preisach) -> Option<HysteresisShape> {
    if !(p.reach > 0.0 && p.reach.is_finite()) {
        return None;
    }
    Some(HysteresisShape {
        width_c: p.width_c(),
        plays: p
            .widths_c
            .iter()
            .zip(&p.weights)
            .map(|(&r, &w)| [r, w / p.reach])
            .collect(),
        relays: p
            .relays_c
            .iter()
            .zip(&p.relay_weights)
            .map(|(&[lo, hi], &w)| [lo, hi, w / p.reach])
            .collect(),
        lag_s: p.lag_s,
    })
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
                alternative: a.ambiguous_with.first().map(|amb| Alternative {
                    kind: amb.other.clone(),
                    params: named(&amb.other_parameters),
                }),
                hysteresis: match a.effect {
                    crate::discover::effects::Effect::ThermalHysteresis => {
                        d.selection.hysteresis.as_ref().and_then(hysteresis_shape)
                    }
                    _ => None,
                },
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
    fn a_fitted_preisach_distribution_is_simulated_as_its_column() {
        use crate::discover::hysteresis::Preisach;
        use crate::sim::effects::{ChainSetup, Drive, EffectChain};
        // A ±0.5 °C programme of uneven ramps with minor loops, at 60 s.
        let temp: Vec<f64> = (0..6000)
            .map(|i| {
                let x = i as f64 / 400.0;
                0.5 * x.sin() * (0.3 * x).cos() + 0.1 * (2.7 * x).sin()
            })
            .collect();
        let p = Preisach {
            widths_c: vec![0.03, 0.4],
            weights: vec![0.25, 0.45],
            relays_c: vec![[-0.2, 0.15], [0.05, 0.3]],
            relay_weights: vec![0.2, 0.1],
            reach: 1.0,
            loop_area_c: 0.0,
            lag_s: 0.0,
            record_loop_area_c: 0.0,
        }
        .on_record(&temp);
        // The wide play is not saturated on the programme: the column is scaled by its reach.
        assert!((p.reach - 1.0).abs() > 0.05, "reach {}", p.reach);
        // A member's draw: the coefficient and the width off their fitted values.
        let (half_width, theta) = (3e-6, 1.2 * p.width_c());
        let want: Vec<f64> = p
            .column(&temp, theta)
            .iter()
            .map(|c| half_width * c)
            .collect();
        let simulated = |shape: Option<HysteresisShape>| {
            let draws = EffectDraws {
                record_start_s: 0.0,
                record_interval_s: 60.0,
                record_channels: vec!["temperature_c".into()],
                tide_groups: None,
                effects: vec![EffectDraw {
                    kind: "thermal_hysteresis".into(),
                    channel: None,
                    params: vec![
                        NamedParam {
                            name: "half_width".into(),
                            drawn: Drawn {
                                value: half_width,
                                sigma: 0.0,
                            },
                        },
                        NamedParam {
                            name: "play_half_width_c".into(),
                            drawn: Drawn {
                                value: theta,
                                sigma: 0.0,
                            },
                        },
                    ],
                    alternative: None,
                    hysteresis: shape,
                }],
                admittance_per_hpa: None,
            };
            let (entries, refused) = draws.nominal();
            assert!(refused.is_empty(), "{refused:?}");
            let setup = ChainSetup {
                start_unix_s: 1.6e9,
                site: (34.0, 116.8, 50.0),
                span_s: (0.0, 60.0 * temp.len() as f64),
                unit_per_g: 1.0,
                input_g: 1.0,
                ambient: Vec::new(),
            };
            let mut chain = EffectChain::new(&entries, setup).unwrap();
            let out: Vec<f64> = temp
                .iter()
                .enumerate()
                .map(|(i, &t)| {
                    chain.output_term(&Drive {
                        t_s: 60.0 * i as f64,
                        temperature_c: t,
                        input_g: 1.0,
                        tilt_rad: 0.0,
                        pressure_dev_pa: 0.0,
                        ambient: &[],
                    })
                })
                .collect();
            (entries.len(), out)
        };
        let worst = |got: &[f64]| {
            got.iter()
                .zip(&want)
                .map(|(g, w)| (g - w).abs())
                .fold(0.0, f64::max)
        };
        // Two plays: two entries, the relays on the first; the column to rounding.
        let (n, got) = simulated(hysteresis_shape(&p));
        assert_eq!(n, 2);
        assert!(worst(&got) < 1e-12 * half_width, "{:e}", worst(&got));
        // One play of the fitted width is another loop (what the twin simulated without it).
        let (_, one_play) = simulated(None);
        assert!(
            worst(&one_play) > 0.1 * half_width,
            "{:e}",
            worst(&one_play)
        );
        // The output lag travels with the shape.
        let lagged = Preisach {
            lag_s: 960.0,
            ..p.clone()
        };
        let shape = hysteresis_shape(&lagged).unwrap();
        assert!(shape.entries(half_width, theta).iter().all(
            |e| matches!(e, ScenarioEffect::ThermalHysteresis { lag_s, .. } if *lag_s == 960.0)
        ));
    }

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
