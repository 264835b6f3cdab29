//! The accepted effects of a discovery as the twin's scenario entries.

use super::*;

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
    for a in &d.selection.accepted {
        let name = a.effect.name();
        let e = scenario_effect(a.effect.kind(), a.effect.channel(), &a.params, d, None);
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

/// One ensemble member's version of [`scenario_effects_from_discovery`]: every parameter drawn
/// from its fitted value and σ (Gaussian; a draw the scenario refuses, such as a negative time
/// constant, falls back to the fitted value), and for an effect the discovery called ambiguous
/// ("A or B"), odd members take the other cause with its own fitted parameters, so the
/// ensemble draws from both. Effects the scenario cannot express are left out, as there.
pub fn scenario_effects_drawn(
    d: &crate::discover::Discovery,
    rng: &mut crate::sim::noise::SimRng,
    member: u64,
) -> Vec<ScenarioEffect> {
    let mut out = Vec::new();
    for a in &d.selection.accepted {
        let other = a.ambiguous_with.as_ref().and_then(|amb| {
            EffectKind::from_name(&amb.other).map(|k| (k, amb.other_parameters.as_slice()))
        });
        let (kind, params) = match other {
            Some(o) if member % 2 == 1 => o,
            _ => (a.effect.kind(), a.params.as_slice()),
        };
        let drawn = scenario_effect(kind, a.effect.channel(), params, d, Some(rng));
        let i = out.len();
        let ok = |e: Result<ScenarioEffect, String>| e.ok().filter(|e| e.validate(i).is_ok());
        if let Some(e) =
            ok(drawn).or_else(|| ok(scenario_effect(kind, a.effect.channel(), params, d, None)))
        {
            out.push(e);
        }
    }
    out
}

/// One effect as a scenario entry from its kind, channel and fitted parameters; with `draw`,
/// each parameter is drawn as value + σ·N(0, 1).
fn scenario_effect(
    kind: EffectKind,
    channel: Option<&str>,
    params: &[(String, crate::discover::effects::Param)],
    d: &crate::discover::Discovery,
    draw: Option<&mut crate::sim::noise::SimRng>,
) -> Result<ScenarioEffect, String> {
    let t0 = d.dataset.t_s.first().copied().unwrap_or(0.0);
    let draw = std::cell::RefCell::new(draw);
    let drawn = |v: &crate::discover::effects::Param| -> f64 {
        match draw.borrow_mut().as_mut() {
            Some(rng) if v.sigma.is_finite() && v.sigma > 0.0 => v.value + v.sigma * gauss(rng),
            _ => v.value,
        }
    };
    {
        let a = Accepted { params, channel };
        let p = |key: &str| -> Option<f64> {
            a.params
                .iter()
                .find(|(k, _)| k == key)
                .map(|(_, v)| drawn(v))
                .filter(|v| v.is_finite())
        };
        let need =
            |key: &str| p(key).ok_or_else(|| format!("parameter {key} missing or not finite"));
        let e: Result<ScenarioEffect, String> = (|| {
            Ok(match kind {
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
                    Ok(t) if !t.groups.is_empty() => tide_from_groups(t, drawn),
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
                    let channel = a.channel.unwrap_or_default().to_owned();
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
                    let channel = a.channel.unwrap_or_default().to_owned();
                    let drives = channel == "temperature_c"
                        || channel.starts_with("pressure")
                        || d.dataset.channels.iter().any(|c| c.name == channel)
                        || SIMULATED_AMBIENT.contains(&channel.as_str());
                    if !drives {
                        return Err(format!("channel {channel:?} is not a driver of the twin"));
                    }
                    if kind == EffectKind::RateCoupling {
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
                    let channel = a.channel.unwrap_or_default().to_owned();
                    ScenarioEffect::ChannelNoise {
                        channel,
                        noise: p("noise")
                            .or_else(|| p("level"))
                            .ok_or("parameter noise missing")?,
                    }
                }
            })
        })();
        e
    }
}

/// What [`scenario_effect`] reads of an accepted effect.
struct Accepted<'a> {
    params: &'a [(String, crate::discover::effects::Param)],
    channel: Option<&'a str>,
}

/// The wave-group analysis' tide as a `tidal_gravity` entry: a factor and a phase per group
/// against the model's elastic tide (the delay is in the phases), each value through `value`
/// (the fitted value, or a member's draw).
pub fn tide_from_groups(
    t: &crate::discover::tidal::TidalAnalysis,
    value: impl Fn(&crate::discover::effects::Param) -> f64,
) -> ScenarioEffect {
    ScenarioEffect::TidalGravity {
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
                factor: value(&g.amplitude_factor_vs_elastic_model),
                phase_deg: value(&g.phase_vs_elastic_model_deg),
            })
            .collect(),
    }
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
