//! The effects a twin's members draw: each accepted effect with its fitted parameters and their
//! σ, in the catalogue's own parameters, and the rule that makes a member's scenario entries of
//! them (the same rule makes the nominal entries, without drawing).

use serde::{Deserialize, Serialize};

use crate::catalogue::EffectKind;
use crate::effects::{InvalidEffect, Relay, ScenarioEffect, TideGroupTerm, SIMULATED_AMBIENT};
use crate::noise::{gauss, stream, SimRng};

/// Random stream of a member's draw of the effects' parameters (not the noise's stream).
pub const EFFECT_DRAW_STREAM: u64 = 5;

/// Pascals per hectopascal.
const PA_PER_HPA: f64 = 100.0;

/// Why an accepted effect cannot be written as a scenario entry (said beside its name in
/// [`EffectDraws::nominal`]'s refusals).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Unexpressible {
    /// The name is no catalogue effect.
    #[error("{0:?} is not in the catalogue")]
    NotInCatalogue(String),
    /// A parameter the entry needs is not among the fitted ones, or not a finite number.
    #[error("parameter {0} missing or not finite")]
    MissingParameter(&'static str),
    /// The channel noise's level is missing.
    #[error("parameter noise missing")]
    MissingNoise,
    /// An ambient coupling's channel is neither recorded nor simulated.
    #[error("channel {0:?} is neither in the record nor simulated")]
    ChannelNotDriven(String),
    /// A rate or second-order coupling's channel drives nothing in the twin.
    #[error("channel {0:?} is not a driver of the twin")]
    NotADriver(String),
    /// A creep fitted from a record that starts after t = 0.
    #[error(
        "the record starts at t = {record_start_s:.0} s and a power law cannot be moved to t = 0 \
         exactly"
    )]
    CreepNotAtZero {
        /// The record's first instant, s.
        record_start_s: f64,
    },
    /// The entry is out of the scenario's range.
    #[error(transparent)]
    Invalid(#[from] InvalidEffect),
}

/// A fitted value and its 1σ.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Drawn {
    /// Fitted value.
    pub value: f64,
    /// 1σ (0 or not finite: not drawn).
    pub sigma: f64,
}

/// One catalogue parameter by name.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NamedParam {
    /// The catalogue's parameter name (`tau_s`, `amplitude`, …).
    pub name: String,
    /// Value and σ.
    #[serde(flatten)]
    pub drawn: Drawn,
}

/// The other cause of an ambiguous pair, with its own fitted parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Alternative {
    /// Catalogue name.
    pub kind: String,
    /// Its parameters.
    pub params: Vec<NamedParam>,
}

/// One accepted effect.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EffectDraw {
    /// Catalogue name.
    pub kind: String,
    /// The channel it acts through, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub channel: Option<String>,
    /// Its fitted parameters.
    pub params: Vec<NamedParam>,
    /// The other cause of an ambiguous pair: odd members take it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alternative: Option<Alternative>,
    /// A `thermal_hysteresis`'s fitted Preisach distribution; absent: one play of the fitted
    /// half-width.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hysteresis: Option<HysteresisShape>,
}

/// A fitted Preisach distribution of a `thermal_hysteresis`: plays and relays with their weights
/// per unit of the effect's `half_width`, at the fitted width `width_c` (a member's drawn width
/// scales every play's half-width and every relay's gap about its centre by the same factor),
/// reaching the output through a first-order lag of `lag_s`. The simulator writes it as one
/// scenario entry per play, the relays and the lag with the first (the lag is linear, so the
/// entries' lagged sum is the lagged sum).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HysteresisShape {
    /// The width the shape is given at, °C (the effect's `play_half_width_c` as fitted).
    pub width_c: f64,
    /// Plays: half-width °C, weight per unit `half_width`.
    pub plays: Vec<[f64; 2]>,
    /// Relays: lower and upper threshold °C, weight per unit `half_width`.
    pub relays: Vec<[f64; 3]>,
    /// Output lag, s (0: at once).
    pub lag_s: f64,
}

impl HysteresisShape {
    /// The scenario entries of the distribution at coefficient `half_width` and width
    /// `width_c`.
    pub fn entries(&self, half_width: f64, width_c: f64) -> Vec<ScenarioEffect> {
        let scale = width_c / self.width_c;
        let mut relays: Vec<Relay> = self
            .relays
            .iter()
            .map(|&[lower, upper, weight]| {
                let (lower_c, upper_c) = crate::catalogue::relay_scaled(lower, upper, scale);
                Relay {
                    lower_c,
                    upper_c,
                    half_width: half_width * weight,
                }
            })
            .collect();
        let mut plays: Vec<(f64, f64)> = self
            .plays
            .iter()
            .map(|&[r, weight]| (r * scale, half_width * weight))
            .collect();
        if plays.is_empty() {
            // Relays alone: they ride on a play of no weight (the entry needs one).
            plays.push((width_c, 0.0));
        }
        plays
            .into_iter()
            .map(|(r, h)| ScenarioEffect::ThermalHysteresis {
                half_width: h,
                play_half_width_c: r,
                // All on the first entry.
                relays: std::mem::take(&mut relays),
                lag_s: self.lag_s,
            })
            .collect()
    }
}

/// One tidal wave group's factor and phase against the model's elastic tide.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TideGroupDraw {
    /// Group name.
    pub name: String,
    /// Amplitude factor.
    pub factor: Drawn,
    /// Phase, degrees.
    pub phase_deg: Drawn,
}

/// Every accepted effect with what the rule needs of the record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EffectDraws {
    /// The record's first instant, s (a warm-up's amplitude is moved from there to t = 0).
    pub record_start_s: f64,
    /// The record's spacing, s.
    pub record_interval_s: f64,
    /// The record's channels (an ambient coupling or a transfer function needs its channel).
    pub record_channels: Vec<String>,
    /// The wave-group analysis' groups (finite ones), when it ran: `tidal_gravity` is written
    /// as them; absent: as its single `amplitude_factor`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tide_groups: Option<Vec<TideGroupDraw>>,
    /// The accepted effects, in order.
    pub effects: Vec<EffectDraw>,
    /// A pressure admittance per hPa from the wave-group analysis, added after the effects.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub admittance_per_hpa: Option<Drawn>,
}

/// A hysteresis entry with its fitted distribution as the distribution's entries at the entry's
/// coefficient and width; any other entry as itself.
fn shaped(e: ScenarioEffect, shape: Option<&HysteresisShape>) -> Vec<ScenarioEffect> {
    match (&e, shape) {
        (
            ScenarioEffect::ThermalHysteresis {
                half_width,
                play_half_width_c,
                ..
            },
            Some(shape),
        ) => shape.entries(*half_width, *play_half_width_c),
        _ => vec![e],
    }
}

/// The entries if each passes the scenario's checks (numbered from `first`).
fn valid(entries: Vec<ScenarioEffect>, first: usize) -> Result<Vec<ScenarioEffect>, Unexpressible> {
    for (k, e) in entries.iter().enumerate() {
        e.validate(first + k)?;
    }
    Ok(entries)
}

impl EffectDraws {
    /// The nominal entries (fitted values) and the effects that cannot be expressed, each with
    /// why.
    pub fn nominal(&self) -> (Vec<ScenarioEffect>, Vec<(String, String)>) {
        let mut out = Vec::new();
        let mut refused = Vec::new();
        for a in &self.effects {
            let kind = EffectKind::from_name(&a.kind);
            let e = kind
                .ok_or_else(|| Unexpressible::NotInCatalogue(a.kind.clone()))
                .and_then(|k| self.entry(k, a.channel.as_deref(), &a.params, None));
            match e.and_then(|e| valid(shaped(e, a.hysteresis.as_ref()), out.len())) {
                Ok(e) => out.extend(e),
                Err(why) => refused.push((a.kind.clone(), why.to_string())),
            }
        }
        if let Some(p) = &self.admittance_per_hpa {
            out.push(ScenarioEffect::PressureAdmittance {
                coefficient: p.value / PA_PER_HPA,
            });
        }
        (out, refused)
    }

    /// Member `member`'s entries: every parameter drawn from its value and σ (Gaussian, stream
    /// [`EFFECT_DRAW_STREAM`]; a draw the scenario refuses, such as a negative time constant,
    /// falls back to the fitted value); for an ambiguous effect odd members take the other
    /// cause with its own parameters. Effects that cannot be expressed are left out.
    pub fn drawn(&self, member: u64) -> Vec<ScenarioEffect> {
        let mut rng = stream(member, EFFECT_DRAW_STREAM);
        let mut out = Vec::new();
        for a in &self.effects {
            let other = a
                .alternative
                .as_ref()
                .and_then(|o| EffectKind::from_name(&o.kind).map(|k| (k, o.params.as_slice())));
            let (kind, params, shape) = match other {
                Some((k, p)) if member % 2 == 1 => (k, p, None),
                _ => match EffectKind::from_name(&a.kind) {
                    Some(k) => (k, a.params.as_slice(), a.hysteresis.as_ref()),
                    None => continue,
                },
            };
            let ch = a.channel.as_deref();
            let drawn = self.entry(kind, ch, params, Some(&mut rng));
            let i = out.len();
            let ok = |e: Result<ScenarioEffect, Unexpressible>| {
                e.and_then(|e| valid(shaped(e, shape), i)).ok()
            };
            if let Some(e) = ok(drawn).or_else(|| ok(self.entry(kind, ch, params, None))) {
                out.extend(e);
            }
        }
        if let Some(p) = &self.admittance_per_hpa {
            out.push(ScenarioEffect::PressureAdmittance {
                coefficient: (p.value + p.sigma * gauss(&mut rng)) / PA_PER_HPA,
            });
        }
        out
    }

    /// One effect as a scenario entry; with `draw`, each parameter drawn as value + σ·N(0, 1).
    fn entry(
        &self,
        kind: EffectKind,
        channel: Option<&str>,
        params: &[NamedParam],
        draw: Option<&mut SimRng>,
    ) -> Result<ScenarioEffect, Unexpressible> {
        let t0 = self.record_start_s;
        let draw = std::cell::RefCell::new(draw);
        let drawn = |v: &Drawn| -> f64 {
            match draw.borrow_mut().as_mut() {
                Some(rng) if v.sigma.is_finite() && v.sigma > 0.0 => v.value + v.sigma * gauss(rng),
                _ => v.value,
            }
        };
        let p = |key: &str| -> Option<f64> {
            params
                .iter()
                .find(|q| q.name == key)
                .map(|q| drawn(&q.drawn))
                .filter(|v| v.is_finite())
        };
        let need = |key: &'static str| p(key).ok_or(Unexpressible::MissingParameter(key));
        let in_record = |c: &str| self.record_channels.iter().any(|n| n == c);
        Ok(match kind {
            EffectKind::ThermalLag => ScenarioEffect::ThermalLag {
                tau_s: need("tau_s")?,
                coefficient: need("coefficient")?,
            },
            EffectKind::ThermalHysteresis => ScenarioEffect::ThermalHysteresis {
                half_width: need("half_width")?,
                play_half_width_c: need("play_half_width_c")?,
                relays: Vec::new(),
                lag_s: 0.0,
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
            EffectKind::TidalGravity => match &self.tide_groups {
                Some(groups) => ScenarioEffect::TidalGravity {
                    amplitude_factor: 0.0,
                    delay_s: 0.0,
                    groups: groups
                        .iter()
                        .map(|g| TideGroupTerm {
                            name: g.name.clone(),
                            factor: drawn(&g.factor),
                            phase_deg: drawn(&g.phase_deg),
                        })
                        .collect(),
                },
                None => ScenarioEffect::TidalGravity {
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
                let channel = channel.unwrap_or_default().to_owned();
                if !in_record(&channel) && !SIMULATED_AMBIENT.contains(&channel.as_str()) {
                    return Err(Unexpressible::ChannelNotDriven(channel));
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
                let channel = channel.unwrap_or_default().to_owned();
                let drives = channel == "temperature_c"
                    || channel.starts_with("pressure")
                    || in_record(&channel)
                    || SIMULATED_AMBIENT.contains(&channel.as_str());
                if !drives {
                    return Err(Unexpressible::NotADriver(channel));
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
            EffectKind::CreepDrift if t0.abs() > self.record_interval_s => {
                return Err(Unexpressible::CreepNotAtZero { record_start_s: t0 })
            }
            EffectKind::CreepDrift => ScenarioEffect::CreepDrift {
                exponent: need("exponent")?,
                amplitude: need("amplitude")?,
            },
            EffectKind::ChannelNoise => {
                let channel = channel.unwrap_or_default().to_owned();
                ScenarioEffect::ChannelNoise {
                    channel,
                    noise: p("noise")
                        .or_else(|| p("level"))
                        .ok_or(Unexpressible::MissingNoise)?,
                }
            }
        })
    }
}
