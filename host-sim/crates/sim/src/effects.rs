//! The discovery catalogue's effects as simulator physics: the scenario's optional `[[effects]]`
//! array. Each entry is tagged by its catalogue name (`discover::effects::Effect::name`) and
//! carries the catalogue's parameters in the units `accomp discover` reports them, so that an
//! effect found on a record can be written back into a scenario and simulated as is.
//!
//! Where each enters the signal chain (docs/simulator.md, "Effects"):
//! - every effect but `channel_noise` is an **additive term in the output unit** (volts for the
//!   accelerometer — added to E before the ADC —, the record's gravity unit for the gravimeter),
//!   evaluated from the station's true state (mount temperature, input, foundation tilt, station
//!   pressure, room) — the physics, not the noisy readings;
//! - `tidal_gravity` adds a correction to the model tide: `amplitude_factor` × the model's tide
//!   delayed by `delay_s`, plus per wave group (`groups`) a factor and a phase against the model's
//!   elastic-Earth group tide (the discovery's tidal analysis reports both);
//! - `channel_noise` adds white reading noise to a measured channel (temperature, tilt, pressure)
//!   and nothing to the output.
//!
//! The effects draw from their own random stream (`channel_noise` only), so a scenario without
//! effects is simulated exactly as before.

use serde::{Deserialize, Serialize};

use accomp::tide::cte1973::CTE1973;
use accomp::tide::harmonic::{sin_cos, DoodsonArguments};
use accomp::tide::{Station, MAS_PER_RAD, NM_S2_PER_M_S2, STANDARD_GRAVITY_M_S2};

use super::noise::{gauss, SimRng};
use crate::catalogue::{aging, relay_step, step_fraction, warmup, EffectKind, FirstOrderLag, Play};

/// Channels whose reading `channel_noise` can disturb (log column names).
pub const NOISY_CHANNELS: [&str; 3] = ["temperature_c", "tilt_arcsec", "pressure_hpa"];

/// Ambient channels the station simulator itself provides to `ambient_coupling` (the room and
/// the board temperature, as deviations from the room's mean, °C).
pub const SIMULATED_AMBIENT: [&str; 2] = ["room_c", "board_c"];

/// A wave group's correction of the model tide: `factor`·(group tide advanced by `phase_deg`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TideGroupTerm {
    /// Group name as the tidal analysis reports it (`O1`, `M2`, merged groups joined with `+`,
    /// e.g. `P1K1+J1`); the band is the union of the groups' bands (`tide::GROUPS`).
    pub name: String,
    /// Amplitude factor against the model's elastic-Earth group tide (0: no correction).
    pub factor: f64,
    /// Phase, degrees, positive = leads the model.
    pub phase_deg: f64,
}

/// A relay hysteron of `thermal_hysteresis`: its state R is +1 once the mount temperature has
/// risen to `upper_c`, −1 once it has fallen to `lower_c`, unchanged in between (unknown, 0,
/// until the first of these); it adds `half_width`·(−R), so that between the thresholds the bias
/// is `half_width` higher on the heating branch than the mean of the branches — the sense of the
/// play term and of the discovery's relays (JSON `preisach.relays_c` = [[`lower_c`, `upper_c`]],
/// `relay_weights` × the reported `half_width` for a saturated loop).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Relay {
    /// Lower threshold β, °C.
    pub lower_c: f64,
    /// Upper threshold α > β, °C.
    pub upper_c: f64,
    /// Branch half-width between the thresholds, unit.
    pub half_width: f64,
}

/// One catalogue effect with its parameters (units as `accomp discover` reports them; "unit" is
/// the output unit of the instrument: V for the accelerometer, the gravity unit for the
/// gravimeter).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum ScenarioEffect {
    /// `coefficient`·(L_τ[T] − T): the proof mass lags the mount temperature (unit/°C, s).
    ThermalLag {
        /// Lag time constant, s.
        tau_s: f64,
        /// Output per °C of lag error, unit/°C.
        coefficient: f64,
    },
    /// `half_width`·(T − p_r[T])/r: a play operator of half-width r on the mount temperature,
    /// plus Σ h_j·(−R_j[T]) over `relays` (the Preisach model's switching elements, [`Relay`]),
    /// the sum reaching the output through a first-order lag of `lag_s` (0: at once).
    ThermalHysteresis {
        /// Bias half-difference between the heating and cooling branches, unit.
        half_width: f64,
        /// Play half-width r, °C.
        play_half_width_c: f64,
        /// Relay hysterons beside the play (none by default).
        #[serde(default, skip_serializing_if = "Vec::is_empty")]
        relays: Vec<Relay>,
        /// Time constant with which the loop's output reaches the sensor, s (a switching
        /// element's own switching time, or the thermal path from the hysteretic part to the
        /// proof mass); 0: at once.
        #[serde(default, skip_serializing_if = "is_zero")]
        lag_s: f64,
    },
    /// `coefficient`·(L_τ[a²] − a²): torquer self-heating after an input change (unit/g²).
    SelfHeating {
        /// Coil time constant, s.
        tau_s: f64,
        /// Output per g² of lag error, unit.
        coefficient: f64,
    },
    /// `amplitude`·exp(−t/τ) after power-on (t from the start of the run).
    Warmup {
        /// Time constant, s.
        tau_s: f64,
        /// Amplitude at t = 0, unit.
        amplitude: f64,
    },
    /// `amplitude`·ln(1 + t/τ): logarithmic aging.
    AgingDrift {
        /// Time scale, s.
        tau_s: f64,
        /// Amplitude, unit.
        amplitude: f64,
    },
    /// `size`·[`step_fraction`](crate::catalogue::step_fraction)(t, time_s, duration_s): a bias
    /// change, abrupt (duration 0) or over a linear ramp centred on `time_s`.
    Step {
        /// When (the middle of the ramp), seconds from the start of the run.
        time_s: f64,
        /// Jump, unit (`amplitude` is accepted as another name).
        #[serde(alias = "amplitude")]
        size: f64,
        /// Transition duration, s (0, the default: abrupt).
        #[serde(default, skip_serializing_if = "is_zero")]
        duration_s: f64,
    },
    /// A correction of the tide gravity: `amplitude_factor`·tide(t − delay_s) (the model tide
    /// projected on the input axis, in the output unit), plus the wave-group terms.
    TidalGravity {
        /// Extra factor on the model's tide (0: none; the discovery's `amplitude_factor` of the
        /// residual).
        amplitude_factor: f64,
        /// Delay of the `amplitude_factor` term, s (0 by default).
        #[serde(default)]
        delay_s: f64,
        /// Wave-group corrections (none by default).
        #[serde(default, skip_serializing_if = "Vec::is_empty")]
        groups: Vec<TideGroupTerm>,
    },
    /// `amplitude_factor`·(tide tilt along `azimuth_deg`) at the output's unit per g (0 g tests).
    TidalTilt {
        /// Factor on the model's tide tilt.
        amplitude_factor: f64,
        /// Azimuth of the sensitive direction, degrees from north towards east.
        azimuth_deg: f64,
    },
    /// `amplitude`·sin(2π·t_utc/1 d + phase_rad): diurnal building tilt seen by a 0 g test.
    BuildingTilt {
        /// Amplitude, unit.
        amplitude: f64,
        /// Phase, rad (against UTC midnight).
        phase_rad: f64,
    },
    /// `gain`·(eq. (5) tilt term of the true foundation tilt), in the output unit.
    TiltCoupling {
        /// Gain error of the tilt term (dimensionless).
        gain: f64,
    },
    /// `coefficient`·L_lag[c]: an auxiliary channel (deviation from its mean) through a lag.
    AmbientCoupling {
        /// Channel: `room_c` or `board_c` in the simulator; a twin also takes the record's
        /// auxiliary channels by their column name.
        channel: String,
        /// Output per channel unit.
        coefficient: f64,
        /// Lag time constant, s (0: none).
        lag_s: f64,
    },
    /// `coefficient`·(p − p̄): barometric admittance, unit per Pa.
    PressureAdmittance {
        /// Output per Pa.
        coefficient: f64,
    },
    /// `amplitude`·sin(2π·t/period_s + phase_rad), t from the start of the run.
    Periodic {
        /// Period, s.
        period_s: f64,
        /// Amplitude, unit.
        amplitude: f64,
        /// Phase, rad.
        phase_rad: f64,
    },
    /// `coefficient`·dc/dt: a channel through a gain on its rate of change
    /// ([`crate::catalogue::RateOfChange`]): the bias of a gradient across the sensor while the
    /// channel ramps.
    RateCoupling {
        /// `temperature_c` (the mount's), `pressure_hpa` (deviation, Pa) or an ambient channel.
        channel: String,
        /// Output per (channel unit per s).
        coefficient: f64,
    },
    /// `coefficient`·(L2_τ[c] − c): the lag error of a channel through two first-order stages
    /// of τ ([`crate::catalogue::SecondOrderLag`]), as `thermal_lag` is of one (the gain on the
    /// channel itself is the baseline's for the temperature, `pressure_admittance` or
    /// `ambient_coupling` for the others).
    Lag2Coupling {
        /// `temperature_c`, `pressure_hpa` (deviation, Pa) or an ambient channel.
        channel: String,
        /// Time constant of each stage, s.
        tau_s: f64,
        /// Output per channel unit.
        coefficient: f64,
    },
    /// `amplitude`·(t / 1 day)^`exponent` ([`crate::catalogue::creep`]), t from the start of the
    /// run: creep that accelerates (exponent > 1) or settles as a power law (< 1).
    CreepDrift {
        /// Exponent.
        exponent: f64,
        /// Drift after one day, unit.
        amplitude: f64,
    },
    /// White reading noise on a measured channel (`temperature_c` °C, `tilt_arcsec` in rad,
    /// `pressure_hpa` in Pa: the units the discovery stores them in).
    ChannelNoise {
        /// Log column.
        channel: String,
        /// Standard deviation per reading (°C, rad or Pa).
        noise: f64,
    },
}

/// A scenario effect out of its range: which entry, which field, why.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("effects[{index}] ({kind}): {field} {why}")]
pub struct InvalidEffect {
    /// Index in the scenario's `[[effects]]`.
    pub index: usize,
    /// The entry's kind.
    pub kind: &'static str,
    /// The field (or fields) at fault.
    pub field: String,
    /// What it must be.
    pub why: String,
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

impl ScenarioEffect {
    /// Its entry in the catalogue.
    pub fn kind(&self) -> EffectKind {
        match self {
            ScenarioEffect::ThermalLag { .. } => EffectKind::ThermalLag,
            ScenarioEffect::ThermalHysteresis { .. } => EffectKind::ThermalHysteresis,
            ScenarioEffect::SelfHeating { .. } => EffectKind::SelfHeating,
            ScenarioEffect::Warmup { .. } => EffectKind::Warmup,
            ScenarioEffect::AgingDrift { .. } => EffectKind::AgingDrift,
            ScenarioEffect::Step { .. } => EffectKind::Step,
            ScenarioEffect::TidalGravity { .. } => EffectKind::TidalGravity,
            ScenarioEffect::TidalTilt { .. } => EffectKind::TidalTilt,
            ScenarioEffect::BuildingTilt { .. } => EffectKind::BuildingTilt,
            ScenarioEffect::TiltCoupling { .. } => EffectKind::TiltCoupling,
            ScenarioEffect::AmbientCoupling { .. } => EffectKind::AmbientCoupling,
            ScenarioEffect::PressureAdmittance { .. } => EffectKind::PressureAdmittance,
            ScenarioEffect::Periodic { .. } => EffectKind::Periodic,
            ScenarioEffect::RateCoupling { .. } => EffectKind::RateCoupling,
            ScenarioEffect::Lag2Coupling { .. } => EffectKind::Lag2Coupling,
            ScenarioEffect::CreepDrift { .. } => EffectKind::CreepDrift,
            ScenarioEffect::ChannelNoise { .. } => EffectKind::ChannelNoise,
        }
    }

    /// The catalogue name.
    pub fn name(&self) -> &'static str {
        self.kind().name()
    }

    /// Checks the ranges; the error names the entry (`effects[i] (kind)`) and the field.
    pub fn validate(&self, index: usize) -> Result<(), InvalidEffect> {
        let at = |field: &str, why: &str| {
            Err(InvalidEffect {
                index,
                kind: self.name(),
                field: field.to_owned(),
                why: why.to_owned(),
            })
        };
        // One check per field: the condition, the field it names and what it must be.
        let check = |ok: bool, field: &str, why: &str| if ok { Ok(()) } else { at(field, why) };
        let finite = |field: &str, v: f64| check(v.is_finite(), field, "must be finite");
        let positive = |field: &str, v: f64| check(v.is_finite() && v > 0.0, field, "must be > 0");
        let non_negative =
            |field: &str, v: f64| check(v.is_finite() && v >= 0.0, field, "must be ≥ 0");
        let named =
            |channel: &str| check(!channel.trim().is_empty(), "channel", "must name a channel");
        match self {
            ScenarioEffect::ThermalLag { tau_s, coefficient }
            | ScenarioEffect::SelfHeating { tau_s, coefficient } => {
                positive("tau_s", *tau_s)?;
                finite("coefficient", *coefficient)
            }
            ScenarioEffect::ThermalHysteresis {
                half_width,
                play_half_width_c,
                relays,
                lag_s,
            } => {
                positive("play_half_width_c", *play_half_width_c)?;
                check(
                    lag_s.is_finite() && *lag_s >= 0.0,
                    "lag_s",
                    "must be finite and ≥ 0",
                )?;
                for r in relays {
                    finite("relays.half_width", r.half_width)?;
                    finite("relays.lower_c", r.lower_c)?;
                    check(
                        r.upper_c > r.lower_c && r.upper_c.is_finite(),
                        "relays.upper_c",
                        "must be finite and above lower_c",
                    )?;
                }
                finite("half_width", *half_width)
            }
            ScenarioEffect::Warmup { tau_s, amplitude }
            | ScenarioEffect::AgingDrift { tau_s, amplitude } => {
                positive("tau_s", *tau_s)?;
                finite("amplitude", *amplitude)
            }
            ScenarioEffect::Step {
                time_s,
                size,
                duration_s,
            } => {
                finite("time_s", *time_s)?;
                finite("size", *size)?;
                non_negative("duration_s", *duration_s)
            }
            ScenarioEffect::TidalGravity {
                amplitude_factor,
                delay_s,
                groups,
            } => {
                finite("amplitude_factor", *amplitude_factor)?;
                // A delay beyond a quarter of the shortest tidal period (M3, 8 h) is a phase
                // error of more than 90°: not a delay.
                check(
                    delay_s.is_finite() && delay_s.abs() <= 2.0 * 3600.0,
                    "delay_s",
                    "must be within ±7200 s",
                )?;
                for g in groups {
                    check(
                        group_band(&g.name).is_some(),
                        "groups",
                        &format!(
                            "has an unknown group {:?} (known: {})",
                            g.name,
                            group_names().join(", ")
                        ),
                    )?;
                    check(
                        g.factor.is_finite() && g.phase_deg.is_finite(),
                        "groups",
                        &format!("{}: factor and phase must be finite", g.name),
                    )?;
                }
                Ok(())
            }
            ScenarioEffect::TidalTilt {
                amplitude_factor,
                azimuth_deg,
            } => check(
                amplitude_factor.is_finite() && azimuth_deg.is_finite(),
                "amplitude_factor and azimuth_deg",
                "must be finite",
            ),
            ScenarioEffect::BuildingTilt {
                amplitude,
                phase_rad,
            } => check(
                amplitude.is_finite() && phase_rad.is_finite(),
                "amplitude and phase_rad",
                "must be finite",
            ),
            ScenarioEffect::TiltCoupling { gain } => finite("gain", *gain),
            ScenarioEffect::AmbientCoupling {
                channel,
                coefficient,
                lag_s,
            } => {
                named(channel)?;
                finite("coefficient", *coefficient)?;
                non_negative("lag_s", *lag_s)
            }
            ScenarioEffect::PressureAdmittance { coefficient } => {
                finite("coefficient", *coefficient)
            }
            ScenarioEffect::Periodic {
                period_s,
                amplitude,
                phase_rad,
            } => {
                positive("period_s", *period_s)?;
                check(
                    amplitude.is_finite() && phase_rad.is_finite(),
                    "amplitude and phase_rad",
                    "must be finite",
                )
            }
            ScenarioEffect::RateCoupling {
                channel,
                coefficient,
            } => {
                named(channel)?;
                finite("coefficient", *coefficient)
            }
            ScenarioEffect::Lag2Coupling {
                channel,
                tau_s,
                coefficient,
            } => {
                named(channel)?;
                positive("tau_s", *tau_s)?;
                finite("coefficient", *coefficient)
            }
            ScenarioEffect::CreepDrift {
                exponent,
                amplitude,
            } => {
                positive("exponent", *exponent)?;
                finite("amplitude", *amplitude)
            }
            ScenarioEffect::ChannelNoise { channel, noise } => {
                check(
                    NOISY_CHANNELS.contains(&channel.as_str()),
                    "channel",
                    &format!(
                        "{channel:?} is not a measured channel ({})",
                        NOISY_CHANNELS.join(", ")
                    ),
                )?;
                non_negative("noise", *noise)
            }
        }
    }
}

fn group_names() -> Vec<&'static str> {
    crate::tide::GROUPS.iter().map(|g| g.name).collect()
}

/// The frequency band (cpd) of a group name; merged names (`A+B`) take the union.
pub fn group_band(name: &str) -> Option<(f64, f64)> {
    let mut band: Option<(f64, f64)> = None;
    for part in name.split('+') {
        let g = crate::tide::GROUPS.iter().find(|g| g.name == part.trim())?;
        band = Some(match band {
            None => (g.from_cpd, g.to_cpd),
            Some((a, b)) => (a.min(g.from_cpd), b.max(g.to_cpd)),
        });
    }
    band
}

/// What the effects need to know about the run.
#[derive(Debug, Clone)]
pub struct ChainSetup {
    /// Unix seconds of t = 0.
    pub start_unix_s: f64,
    /// Site (latitude, longitude degrees, height m) for the tide corrections.
    pub site: (f64, f64, f64),
    /// First and last time the chain will be asked for, seconds from t = 0.
    pub span_s: (f64, f64),
    /// Output units per g (V/g: K1 at the set point; the gravity unit's per g).
    pub unit_per_g: f64,
    /// Nominal input of the test, g (its sign projects the tide on the input axis).
    pub input_g: f64,
    /// Names of the ambient channels the caller passes in [`Drive::ambient`], in order.
    pub ambient: Vec<String>,
}

/// The station's state at one instant, as the effects see it.
#[derive(Debug, Clone, Copy)]
pub struct Drive<'a> {
    /// Seconds from t = 0.
    pub t_s: f64,
    /// Temperature the thermal effects follow (the mount's, °C).
    pub temperature_c: f64,
    /// Nominal input acceleration, g.
    pub input_g: f64,
    /// Foundation tilt about the spindle, rad.
    pub tilt_rad: f64,
    /// Station pressure minus its mean, Pa.
    pub pressure_dev_pa: f64,
    /// Ambient channels (deviations from their means), in [`ChainSetup::ambient`] order.
    pub ambient: &'a [f64],
}

/// One effect's running state.
#[derive(Debug, Clone)]
enum State {
    /// First-order lag with the actual spacing.
    Lag {
        x: FirstOrderLag,
    },
    /// Play operator, the relays' states (+1, −1; 0 before the first switch) and the output
    /// lag.
    Play {
        p: Play,
        relays: Vec<f64>,
        lag: FirstOrderLag,
    },
    /// Index of the ambient channel and its lag.
    Ambient {
        index: usize,
        x: FirstOrderLag,
    },
    /// A channel coupling's source and transfer-function states.
    Coupling {
        source: Source,
        rate: crate::catalogue::RateOfChange,
        lag2: crate::catalogue::SecondOrderLag,
    },
    None,
}

/// Which drive a channel coupling reads.
#[derive(Debug, Clone, Copy)]
enum Source {
    Temperature,
    Pressure,
    Ambient(usize),
}

impl Source {
    fn value(self, d: &Drive) -> f64 {
        match self {
            Source::Temperature => d.temperature_c,
            Source::Pressure => d.pressure_dev_pa,
            Source::Ambient(i) => d.ambient.get(i).copied().unwrap_or(0.0),
        }
    }
}

/// The effects of a scenario, evaluated sample by sample.
#[derive(Debug, Clone)]
pub struct EffectChain {
    effects: Vec<ScenarioEffect>,
    states: Vec<State>,
    setup: ChainSetup,
    tide: Option<TideNodes>,
    groups: Option<Nodes>,
}

/// Why the chain cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EffectError {
    /// An ambient coupling names a channel nobody provides.
    #[error(
        "effects[{index}] (ambient_coupling): channel {channel:?} is not available (have: {have})"
    )]
    Channel {
        /// Entry.
        index: usize,
        /// Channel named.
        channel: String,
        /// Channels available.
        have: String,
    },
    /// The site is not on the Earth.
    #[error("effects: the tide corrections need a valid site: {0}")]
    Site(String),
}

impl EffectChain {
    /// The chain of `effects` (validated by the scenario) for a run described by `setup`.
    pub fn new(effects: &[ScenarioEffect], setup: ChainSetup) -> Result<Self, EffectError> {
        Self::with_kept_tides(effects, setup, &KeptTides::default())
    }

    /// The same, taking the model's tide and the wave groups' tides from `tides` (evaluating
    /// and keeping there those it does not hold yet): chains of one run built with the same
    /// `tides` evaluate the ephemeris and each group's waves once.
    pub fn with_kept_tides(
        effects: &[ScenarioEffect],
        setup: ChainSetup,
        tides: &KeptTides,
    ) -> Result<Self, EffectError> {
        let mut states = Vec::with_capacity(effects.len());
        let mut needs_tide = false;
        let mut group_terms: Vec<&TideGroupTerm> = Vec::new();
        for (index, e) in effects.iter().enumerate() {
            states.push(match e {
                ScenarioEffect::ThermalLag { .. } | ScenarioEffect::SelfHeating { .. } => {
                    State::Lag {
                        x: FirstOrderLag::default(),
                    }
                }
                ScenarioEffect::ThermalHysteresis { relays, .. } => State::Play {
                    p: Play::default(),
                    relays: vec![0.0; relays.len()],
                    lag: FirstOrderLag::default(),
                },
                ScenarioEffect::AmbientCoupling { channel, .. } => {
                    let i = setup
                        .ambient
                        .iter()
                        .position(|c| c == channel)
                        .ok_or_else(|| EffectError::Channel {
                            index,
                            channel: channel.clone(),
                            have: setup.ambient.join(", "),
                        })?;
                    State::Ambient {
                        index: i,
                        x: FirstOrderLag::default(),
                    }
                }
                ScenarioEffect::RateCoupling { channel, .. }
                | ScenarioEffect::Lag2Coupling { channel, .. } => {
                    let source = match channel.as_str() {
                        "temperature_c" => Source::Temperature,
                        c if c.starts_with("pressure") => Source::Pressure,
                        c => {
                            Source::Ambient(setup.ambient.iter().position(|a| a == c).ok_or_else(
                                || EffectError::Channel {
                                    index,
                                    channel: channel.clone(),
                                    have: setup.ambient.join(", "),
                                },
                            )?)
                        }
                    };
                    State::Coupling {
                        source,
                        rate: Default::default(),
                        lag2: Default::default(),
                    }
                }
                ScenarioEffect::TidalGravity {
                    amplitude_factor,
                    groups,
                    ..
                } => {
                    needs_tide |= *amplitude_factor != 0.0;
                    group_terms.extend(groups.iter());
                    State::None
                }
                ScenarioEffect::TidalTilt { .. } => {
                    needs_tide = true;
                    State::None
                }
                _ => State::None,
            });
        }
        let station = || {
            let (lat, lon, h) = setup.site;
            Station::new(lat, lon, h).map_err(|e| EffectError::Site(format!("{e:?}")))
        };
        let tide = if needs_tide {
            let st = station()?;
            let kept = tides.model(&st, &setup);
            Some(TideNodes::new(st, &setup, kept))
        } else {
            None
        };
        let groups = if group_terms.is_empty() {
            None
        } else {
            Some(group_nodes(&station()?, &setup, &group_terms, tides))
        };
        Ok(EffectChain {
            effects: effects.to_vec(),
            states,
            setup,
            tide,
            groups,
        })
    }

    /// Whether the chain adds anything to the output.
    pub fn is_empty(&self) -> bool {
        self.effects.is_empty()
    }

    /// The additive output term at one instant (output unit). Instants must come in increasing
    /// order (the lags and the play operator carry state).
    pub fn output_term(&mut self, d: &Drive) -> f64 {
        let u = self.setup.unit_per_g;
        let sign = if self.setup.input_g < 0.0 { -1.0 } else { 1.0 };
        let t = d.t_s;
        let mut sum = 0.0;
        for (e, st) in self.effects.iter().zip(self.states.iter_mut()) {
            sum += match (e, st) {
                (ScenarioEffect::ThermalLag { tau_s, coefficient }, State::Lag { x }) => {
                    coefficient * (x.step(t, d.temperature_c, *tau_s) - d.temperature_c)
                }
                (ScenarioEffect::SelfHeating { tau_s, coefficient }, State::Lag { x }) => {
                    let a2 = d.input_g * d.input_g;
                    coefficient * (x.step(t, a2, *tau_s) - a2)
                }
                (
                    ScenarioEffect::ThermalHysteresis {
                        half_width,
                        play_half_width_c,
                        relays,
                        lag_s,
                    },
                    State::Play {
                        p,
                        relays: states,
                        lag,
                    },
                ) => {
                    let r = *play_half_width_c;
                    let tc = d.temperature_c;
                    let q = p.step(tc, r);
                    let mut sum = half_width * (tc - q) / r;
                    for (rel, st) in relays.iter().zip(states.iter_mut()) {
                        *st = relay_step(*st, tc, rel.lower_c, rel.upper_c);
                        sum -= rel.half_width * *st;
                    }
                    lag.step(t, sum, *lag_s)
                }
                (ScenarioEffect::Warmup { tau_s, amplitude }, _) => amplitude * warmup(t, *tau_s),
                (ScenarioEffect::AgingDrift { tau_s, amplitude }, _) => {
                    amplitude * aging(t, *tau_s)
                }
                (
                    ScenarioEffect::Step {
                        time_s,
                        size,
                        duration_s,
                    },
                    _,
                ) => size * step_fraction(t, *time_s, *duration_s),
                (
                    ScenarioEffect::TidalGravity {
                        amplitude_factor,
                        delay_s,
                        ..
                    },
                    _,
                ) => match &mut self.tide {
                    Some(tn) if *amplitude_factor != 0.0 => {
                        amplitude_factor * tn.at(t - delay_s).0 * u * sign
                    }
                    _ => 0.0,
                },
                (
                    ScenarioEffect::TidalTilt {
                        amplitude_factor,
                        azimuth_deg,
                    },
                    _,
                ) => match &mut self.tide {
                    Some(tn) => {
                        let (_, n, e) = tn.at(t);
                        let (s, c) = azimuth_deg.to_radians().sin_cos();
                        amplitude_factor * (c * n + s * e) * u
                    }
                    None => 0.0,
                },
                (
                    ScenarioEffect::BuildingTilt {
                        amplitude,
                        phase_rad,
                    },
                    _,
                ) => {
                    let w = std::f64::consts::TAU / 86_400.0;
                    amplitude * (w * (self.setup.start_unix_s + t) + phase_rad).sin()
                }
                (ScenarioEffect::TiltCoupling { gain }, _) => {
                    // Eq. (5): sin(θ + φ) − sin θ at the nominal input a = sin θ (θ in ±90°).
                    let a = d.input_g.clamp(-1.0, 1.0);
                    let cos_head = (1.0 - a * a).max(0.0).sqrt();
                    let (s, c) = d.tilt_rad.sin_cos();
                    gain * u * (a * (c - 1.0) + cos_head * s)
                }
                (
                    ScenarioEffect::AmbientCoupling {
                        coefficient, lag_s, ..
                    },
                    State::Ambient { index, x },
                ) => {
                    let v = d.ambient.get(*index).copied().unwrap_or(0.0);
                    coefficient * x.step(t, v, *lag_s)
                }
                (ScenarioEffect::PressureAdmittance { coefficient }, _) => {
                    coefficient * d.pressure_dev_pa
                }
                (
                    ScenarioEffect::RateCoupling { coefficient, .. },
                    State::Coupling { source, rate, .. },
                ) => coefficient * rate.step(t, source.value(d)),
                (
                    ScenarioEffect::Lag2Coupling {
                        tau_s, coefficient, ..
                    },
                    State::Coupling { source, lag2, .. },
                ) => {
                    let v = source.value(d);
                    coefficient * (lag2.step(t, v, *tau_s) - v)
                }
                (
                    ScenarioEffect::CreepDrift {
                        exponent,
                        amplitude,
                    },
                    _,
                ) => amplitude * crate::catalogue::creep(t, *exponent),
                (
                    ScenarioEffect::Periodic {
                        period_s,
                        amplitude,
                        phase_rad,
                    },
                    _,
                ) => amplitude * (std::f64::consts::TAU * t / period_s + phase_rad).sin(),
                _ => 0.0,
            };
        }
        if let Some(g) = &self.groups {
            // The group terms are in nm/s² of gravity along the vertical.
            sum += g.at(t) * u / (STANDARD_GRAVITY_M_S2 * NM_S2_PER_M_S2) * sign;
        }
        sum
    }

    /// Reading noise of the `channel_noise` entries for one sample: (temperature °C, tilt rad,
    /// pressure Pa) to add to the readings.
    pub fn reading_noise(&self, rng: &mut SimRng) -> (f64, f64, f64) {
        let mut n = (0.0, 0.0, 0.0);
        for e in &self.effects {
            if let ScenarioEffect::ChannelNoise { channel, noise } = e {
                let x = noise * gauss(rng);
                match channel.as_str() {
                    "temperature_c" => n.0 += x,
                    "tilt_arcsec" => n.1 += x,
                    _ => n.2 += x,
                }
            }
        }
        n
    }

    /// Whether any entry is `channel_noise`.
    pub fn has_reading_noise(&self) -> bool {
        self.effects
            .iter()
            .any(|e| matches!(e, ScenarioEffect::ChannelNoise { .. }))
    }
}

/// Tide gravity (g) and tilt north/east (rad) from the ephemeris model every 60 s, linear in
/// between (as `discover::effects::tide_series` does, so the simulated term has the catalogue's
/// shape up to the interpolation, < 1e-5 of the range).
#[derive(Debug, Clone)]
struct TideNodes {
    station: Station,
    start_unix_s: f64,
    /// The nodes over the run's span (delays included), evaluated once per run.
    kept: std::sync::Arc<ModelTide>,
    k: i64,
    a: (f64, f64, f64),
    b: (f64, f64, f64),
}

const TIDE_NODE_S: f64 = 60.0;

impl TideNodes {
    fn new(station: Station, setup: &ChainSetup, kept: std::sync::Arc<ModelTide>) -> Self {
        TideNodes {
            station,
            start_unix_s: setup.start_unix_s,
            kept,
            k: i64::MIN,
            a: (0.0, 0.0, 0.0),
            b: (0.0, 0.0, 0.0),
        }
    }

    fn node(&self, k: i64) -> (f64, f64, f64) {
        let kept = usize::try_from(k - self.kept.first_node)
            .ok()
            .and_then(|i| self.kept.nodes.get(i));
        match kept {
            Some(v) => *v,
            None => model_node(&self.station, self.start_unix_s, k),
        }
    }

    fn at(&mut self, t: f64) -> (f64, f64, f64) {
        let x = t / TIDE_NODE_S;
        let k = x.floor() as i64;
        if k != self.k {
            self.a = if k == self.k.wrapping_add(1) {
                self.b
            } else {
                self.node(k)
            };
            self.b = self.node(k + 1);
            self.k = k;
        }
        let f = x - k as f64;
        (
            self.a.0 + f * (self.b.0 - self.a.0),
            self.a.1 + f * (self.b.1 - self.a.1),
            self.a.2 + f * (self.b.2 - self.a.2),
        )
    }
}

/// The model's tide (gravity g, tilt north and east rad) at node `k` of a run starting at
/// `start_unix_s`.
fn model_node(station: &Station, start_unix_s: f64, k: i64) -> (f64, f64, f64) {
    let s = station.tide_at_unix_seconds(start_unix_s + k as f64 * TIDE_NODE_S);
    (
        s.gravity_gs().0,
        s.tilt_north_mas / MAS_PER_RAD,
        s.tilt_east_mas / MAS_PER_RAD,
    )
}

/// The model's tide on the 60 s nodes of a run's span widened by the longest delay
/// (`tidal_gravity`'s ±7200 s) and one node each side: node `first_node + i` is `nodes[i]`.
#[derive(Debug)]
struct ModelTide {
    first_node: i64,
    nodes: Vec<(f64, f64, f64)>,
}

impl ModelTide {
    fn new(station: &Station, setup: &ChainSetup) -> Self {
        const LONGEST_DELAY_S: f64 = 7200.0;
        let first_node = ((setup.span_s.0 - LONGEST_DELAY_S) / TIDE_NODE_S).floor() as i64 - 1;
        let last_node = ((setup.span_s.1 + LONGEST_DELAY_S) / TIDE_NODE_S).floor() as i64 + 2;
        ModelTide {
            first_node,
            nodes: (first_node..=last_node)
                .map(|k| model_node(station, setup.start_unix_s, k))
                .collect(),
        }
    }
}

/// Node spacing of the wave-group corrections, s; with 4-point Lagrange interpolation the error
/// is ~(ωh)⁴/40 ≈ 5e-7 of an M3 wave at 300 s.
const GROUP_NODE_S: f64 = 300.0;

/// A precomputed series on a regular grid, interpolated by 4-point Lagrange.
#[derive(Debug, Clone)]
struct Nodes {
    t0: f64,
    v: Vec<f64>,
}

impl Nodes {
    fn at(&self, t: f64) -> f64 {
        let n = self.v.len();
        if n < 4 {
            return self.v.first().copied().unwrap_or(0.0);
        }
        let p = (t - self.t0) / GROUP_NODE_S;
        let k = (p.floor() as isize - 1).clamp(0, n as isize - 4) as usize;
        let u = p - k as f64;
        let l0 = -(u - 1.0) * (u - 2.0) * (u - 3.0) / 6.0;
        let l1 = u * (u - 2.0) * (u - 3.0) / 2.0;
        let l2 = -u * (u - 1.0) * (u - 3.0) / 2.0;
        let l3 = u * (u - 1.0) * (u - 2.0) / 6.0;
        self.v[k] * l0 + self.v[k + 1] * l1 + self.v[k + 2] * l2 + self.v[k + 3] * l3
    }
}

/// The run kept tides are of (start, span, site; bit patterns, a key) with the node grid of
/// its wave-group corrections: the first node (s from t = 0) and the node count.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct TideRun {
    start_unix_s: u64,
    span_end_s: u64,
    t0_s: u64,
    nodes: usize,
    site: [u64; 3],
}

impl TideRun {
    fn new(setup: &ChainSetup) -> Self {
        let t0 = setup.span_s.0 - 2.0 * GROUP_NODE_S;
        let t1 = setup.span_s.1 + 2.0 * GROUP_NODE_S;
        let nodes = ((t1 - t0) / GROUP_NODE_S).ceil().max(0.0) as usize + 1;
        let (lat, lon, h) = setup.site;
        TideRun {
            start_unix_s: setup.start_unix_s.to_bits(),
            span_end_s: setup.span_s.1.to_bits(),
            t0_s: t0.to_bits(),
            nodes,
            site: [lat.to_bits(), lon.to_bits(), h.to_bits()],
        }
    }

    fn t0_s(&self) -> f64 {
        f64::from_bits(self.t0_s)
    }
}

/// One wave group's elastic-Earth tide (Σ δ·rigid gravity of the catalogue waves in its band),
/// nm/s², on a [`TideRun`]: in phase (`in_phase[k]` = Σ δ·A·cos θ) and in quadrature
/// (`quadrature[k]` = Σ δ·A·sin θ). The group advanced by φ is cos φ·in_phase − sin φ·quadrature.
#[derive(Debug)]
struct GroupTide {
    in_phase: Vec<f64>,
    quadrature: Vec<f64>,
}

/// The tide series of one run that no effect parameter changes, kept for every chain built on
/// it: the model's tide on its 60 s nodes (`tidal_gravity`'s `amplitude_factor` term,
/// `tidal_tilt`) and the wave groups' tides on theirs (a group term's draw, factor and phase,
/// is a linear combination of its group's two series). The chains of a twin's members share
/// them, so no member evaluates the ephemeris or a wave. Chains of another run (start, span
/// or site) get their own series.
#[derive(Debug, Default)]
pub struct KeptTides {
    kept: std::sync::Mutex<Vec<(TideRun, String, std::sync::Arc<GroupTide>)>>,
    model: std::sync::Mutex<Vec<(TideRun, std::sync::Arc<ModelTide>)>>,
}

impl KeptTides {
    /// The model's tide on the nodes of the run `setup` describes (evaluated on first use).
    fn model(&self, st: &Station, setup: &ChainSetup) -> std::sync::Arc<ModelTide> {
        let run = TideRun::new(setup);
        let mut model = self
            .model
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some((_, m)) = model.iter().find(|(g, _)| *g == run) {
            return m.clone();
        }
        let m = std::sync::Arc::new(ModelTide::new(st, setup));
        model.push((run, m.clone()));
        m
    }

    /// The tides of the groups `names` on `grid`, those not kept yet evaluated (all in one pass
    /// over the nodes: the Doodson arguments once per node).
    fn of(
        &self,
        st: &Station,
        setup: &ChainSetup,
        grid: TideRun,
        names: &[&str],
    ) -> Vec<std::sync::Arc<GroupTide>> {
        // Held while evaluating: members that start together wait for one evaluation instead
        // of each making its own.
        let mut kept = self
            .kept
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let find = |kept: &[(TideRun, String, std::sync::Arc<GroupTide>)], name: &str| {
            kept.iter()
                .find(|(g, n, _)| *g == grid && n == name)
                .map(|(_, _, t)| t.clone())
        };
        let mut missing: Vec<&str> = Vec::new();
        for &name in names {
            if find(&kept, name).is_none() && !missing.contains(&name) {
                missing.push(name);
            }
        }
        for (name, tide) in missing.iter().zip(group_tides(st, setup, grid, &missing)) {
            kept.push((grid, (*name).to_owned(), std::sync::Arc::new(tide)));
        }
        names.iter().filter_map(|name| find(&kept, name)).collect()
    }
}

/// The elastic-Earth tides of the groups `names` on `grid`.
fn group_tides(st: &Station, setup: &ChainSetup, grid: TideRun, names: &[&str]) -> Vec<GroupTide> {
    // Per group: the catalogue waves in its band with their rigid gravity and the model's δ.
    let per_group: Vec<Vec<_>> = names
        .iter()
        .map(|name| {
            let (lo, hi) = group_band(name).unwrap_or((0.0, 0.0));
            CTE1973
                .iter()
                .filter(|w| (lo..hi).contains(&w.frequency_cpd()))
                .map(|w| (*w, st.wave_gravity(w), st.gravimetric_factor(w)))
                .collect()
        })
        .collect();
    let mut tides: Vec<GroupTide> = names
        .iter()
        .map(|_| GroupTide {
            in_phase: Vec::with_capacity(grid.nodes),
            quadrature: Vec::with_capacity(grid.nodes),
        })
        .collect();
    for k in 0..grid.nodes {
        let args = DoodsonArguments::at_unix_seconds(
            setup.start_unix_s + grid.t0_s() + k as f64 * GROUP_NODE_S,
        );
        for (waves, tide) in per_group.iter().zip(tides.iter_mut()) {
            let (mut cs, mut sn) = (0.0, 0.0);
            for (w, wg, delta) in waves {
                let (s, c) = sin_cos(w.argument_rad(&args) + wg.phase_rad);
                cs += delta * wg.amplitude_nm_s2 * c;
                sn += delta * wg.amplitude_nm_s2 * s;
            }
            tide.in_phase.push(cs);
            tide.quadrature.push(sn);
        }
    }
    tides
}

/// Σ over the terms of factor·(elastic group tide advanced by phase), nm/s², on the nodes,
/// from the groups' tides (`tides`: kept or evaluated now).
fn group_nodes(
    st: &Station,
    setup: &ChainSetup,
    terms: &[&TideGroupTerm],
    tides: &KeptTides,
) -> Nodes {
    let grid = TideRun::new(setup);
    let names: Vec<&str> = terms.iter().map(|g| g.name.as_str()).collect();
    let per_term = tides.of(st, setup, grid, &names);
    let mut v = vec![0.0; grid.nodes];
    for (g, tide) in terms.iter().zip(&per_term) {
        let (s, c) = g.phase_deg.to_radians().sin_cos();
        let (fc, fs) = (g.factor * c, g.factor * s);
        // cos(x + φ) = cos x·cos φ − sin x·sin φ.
        for ((v, cs), sn) in v.iter_mut().zip(&tide.in_phase).zip(&tide.quadrature) {
            *v += fc * cs - fs * sn;
        }
    }
    Nodes { t0: grid.t0_s(), v }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn setup() -> ChainSetup {
        ChainSetup {
            start_unix_s: 1.6e9,
            site: (34.0, 116.8, 50.0),
            span_s: (0.0, 86_400.0),
            unit_per_g: 1.0,
            input_g: 1.0,
            ambient: vec!["room_c".into()],
        }
    }

    fn drive(t_s: f64, temperature_c: f64) -> Drive<'static> {
        Drive {
            t_s,
            temperature_c,
            input_g: 1.0,
            tilt_rad: 0.0,
            pressure_dev_pa: 0.0,
            ambient: &[0.0],
        }
    }

    #[test]
    fn every_kind_parses_from_its_catalogue_name_and_validates() {
        let text = r#"
            [[effects]]
            kind = "step"
            time_s = 100.0
            amplitude = 2.0
            [[effects]]
            kind = "tidal_gravity"
            amplitude_factor = 0.1
            groups = [{ name = "M2", factor = 0.01, phase_deg = 2.0 }]
            [[effects]]
            kind = "channel_noise"
            channel = "temperature_c"
            noise = 0.003
        "#;
        #[derive(Deserialize)]
        struct W {
            effects: Vec<ScenarioEffect>,
        }
        let w: W = toml::from_str(text).unwrap();
        assert_eq!(
            w.effects[0],
            ScenarioEffect::Step {
                time_s: 100.0,
                size: 2.0,
                duration_s: 0.0,
            }
        );
        assert_eq!(w.effects[1].name(), "tidal_gravity");
        for (i, e) in w.effects.iter().enumerate() {
            e.validate(i).unwrap();
        }
    }

    #[test]
    fn validation_names_the_entry_and_the_field() {
        let e = ScenarioEffect::Warmup {
            tau_s: -1.0,
            amplitude: 1.0,
        };
        let m = e.validate(3).unwrap_err().to_string();
        assert!(m.contains("effects[3] (warmup): tau_s"), "{m}");
        let e = ScenarioEffect::TidalGravity {
            amplitude_factor: 0.0,
            delay_s: 0.0,
            groups: vec![TideGroupTerm {
                name: "X9".into(),
                factor: 1.0,
                phase_deg: 0.0,
            }],
        };
        assert!(e.validate(0).unwrap_err().to_string().contains("X9"));
        let e = ScenarioEffect::ChannelNoise {
            channel: "output_v".into(),
            noise: 1.0,
        };
        assert!(e.validate(0).unwrap_err().to_string().contains("output_v"));
        assert_eq!(group_band("P1K1+J1"), Some((0.986, 1.5)));
    }

    #[test]
    fn each_range_rule_names_its_field_and_what_it_must_be() {
        let cases = [
            (
                ScenarioEffect::ThermalLag {
                    tau_s: 0.0,
                    coefficient: 1.0,
                },
                "effects[1] (thermal_lag): tau_s must be > 0",
            ),
            (
                ScenarioEffect::SelfHeating {
                    tau_s: 1.0,
                    coefficient: f64::NAN,
                },
                "effects[1] (self_heating): coefficient must be finite",
            ),
            (
                ScenarioEffect::Step {
                    time_s: 0.0,
                    size: 1.0,
                    duration_s: -1.0,
                },
                "effects[1] (step): duration_s must be ≥ 0",
            ),
            (
                ScenarioEffect::TidalGravity {
                    amplitude_factor: 1.0,
                    delay_s: 7201.0,
                    groups: vec![],
                },
                "effects[1] (tidal_gravity): delay_s must be within ±7200 s",
            ),
            (
                ScenarioEffect::BuildingTilt {
                    amplitude: 1.0,
                    phase_rad: f64::INFINITY,
                },
                "effects[1] (building_tilt): amplitude and phase_rad must be finite",
            ),
            (
                ScenarioEffect::RateCoupling {
                    channel: " ".into(),
                    coefficient: 1.0,
                },
                "effects[1] (rate_coupling): channel must name a channel",
            ),
        ];
        for (e, want) in cases {
            assert_eq!(e.validate(1).unwrap_err().to_string(), want);
        }
    }

    #[test]
    fn lag_hysteresis_and_step_follow_their_definitions() {
        let mut c = EffectChain::new(
            &[
                ScenarioEffect::ThermalLag {
                    tau_s: 100.0,
                    coefficient: 2.0,
                },
                ScenarioEffect::ThermalHysteresis {
                    half_width: 1.0,
                    play_half_width_c: 0.5,
                    relays: Vec::new(),
                    lag_s: 0.0,
                },
            ],
            setup(),
        )
        .unwrap();
        // Temperature steps by 1 °C at t = 10 s: after one τ the lag error is −e^{−1}·2, and
        // the play has moved to T − r (heating branch, +1).
        assert_eq!(c.output_term(&drive(0.0, 0.0)), 0.0);
        let y1 = c.output_term(&drive(10.0, 1.0));
        assert!((y1 - (2.0 * ((1.0 - (-0.1f64).exp()) - 1.0) + 1.0)).abs() < 1e-12);
        let y = c.output_term(&drive(110.0, 1.0));
        let lag = 2.0 * ((1.0 - (-1.1f64).exp()) - 1.0);
        assert!((y - (lag + 1.0)).abs() < 1e-12, "{y}");
        let mut s = EffectChain::new(
            &[ScenarioEffect::Step {
                time_s: 50.0,
                size: 3.0,
                duration_s: 0.0,
            }],
            setup(),
        )
        .unwrap();
        assert_eq!(s.output_term(&drive(49.9, 0.0)), 0.0);
        assert_eq!(s.output_term(&drive(50.0, 0.0)), 3.0);
    }

    #[test]
    fn a_relay_switches_at_its_thresholds_and_holds_in_between() {
        // A play of zero weight and one relay, thresholds 0.2 and 0.6 °C, half-width 2.
        let mut c = EffectChain::new(&[one_relay(0.2, 0.6, 2.0, 0.0)], setup()).unwrap();
        // Virgin between the thresholds: no term until a threshold is reached.
        let up = [0.4, 0.5, 0.59, 0.6, 0.7, 0.5, 0.3, 0.21, 0.2, 0.1, 0.4];
        let want = [0.0, 0.0, 0.0, -2.0, -2.0, -2.0, -2.0, -2.0, 2.0, 2.0, 2.0];
        for (k, (t, w)) in up.iter().zip(want).enumerate() {
            let y = c.output_term(&drive(k as f64, *t));
            assert_eq!(y, w, "at {t} °C");
        }
        assert!(one_relay(0.6, 0.2, 1.0, 0.0).validate(0).is_err());
    }

    /// A `thermal_hysteresis` of one relay and a play of zero weight.
    fn one_relay(lower_c: f64, upper_c: f64, half_width: f64, lag_s: f64) -> ScenarioEffect {
        ScenarioEffect::ThermalHysteresis {
            half_width: 0.0,
            play_half_width_c: 0.1,
            relays: vec![Relay {
                lower_c,
                upper_c,
                half_width,
            }],
            lag_s,
        }
    }

    #[test]
    fn a_lagged_loop_reaches_its_branch_through_the_lag_and_a_negative_lag_is_refused() {
        // One relay (thresholds 0.2, 0.6 °C, half-width 2) whose output lags by 100 s: once
        // the temperature reaches 0.6 °C at t = 0 the term relaxes towards −2 as 1 − e^(−t/τ).
        let relay = |lag_s| one_relay(0.2, 0.6, 2.0, lag_s);
        let mut c = EffectChain::new(&[relay(100.0)], setup()).unwrap();
        assert_eq!(
            c.output_term(&drive(0.0, 0.6)),
            -2.0,
            "the lag starts settled"
        );
        assert_eq!(
            c.output_term(&drive(10.0, 0.1)),
            -2.0 + 4.0 * (1.0 - (-0.1f64).exp())
        );
        let y = c.output_term(&drive(110.0, 0.1));
        let want = 2.0 - 4.0 * (-1.1f64).exp();
        assert!((y - want).abs() < 1e-12, "{y} vs {want}");
        assert!(relay(-1.0).validate(0).is_err());
        assert!(relay(f64::NAN).validate(0).is_err());
    }

    #[test]
    fn an_unknown_ambient_channel_is_refused_by_name() {
        let e = [ScenarioEffect::AmbientCoupling {
            channel: "humidity".into(),
            coefficient: 1.0,
            lag_s: 0.0,
        }];
        let err = EffectChain::new(&e, setup()).unwrap_err();
        assert!(err.to_string().contains("humidity"), "{err}");
    }

    /// A member's draw of the ten groups rendered from the kept in-phase and quadrature series
    /// (kept by an earlier draw's chain) is each wave's δ·A·cos(θ + mλ + φ) summed directly
    /// with the core's per-wave evaluation, and bit for bit what a chain evaluating its own
    /// series renders.
    #[test]
    fn a_draw_from_the_kept_group_tides_is_the_direct_sum_of_its_waves() {
        let mut rng = crate::noise::stream(7, 11);
        let mut drawn = || -> Vec<TideGroupTerm> {
            crate::tide::GROUPS
                .iter()
                .map(|g| TideGroupTerm {
                    name: g.name.into(),
                    factor: 0.05 * gauss(&mut rng),
                    phase_deg: 5.0 * gauss(&mut rng),
                })
                .collect()
        };
        let tidal = |groups: Vec<TideGroupTerm>| ScenarioEffect::TidalGravity {
            amplitude_factor: 0.0,
            delay_s: 0.0,
            groups,
        };
        let kept = KeptTides::default();
        EffectChain::with_kept_tides(&[tidal(drawn())], setup(), &kept).unwrap();
        let member = drawn();
        let mut cached =
            EffectChain::with_kept_tides(&[tidal(member.clone())], setup(), &kept).unwrap();
        let mut own = EffectChain::new(&[tidal(member.clone())], setup()).unwrap();
        assert_eq!(
            kept.kept.lock().unwrap().len(),
            10,
            "one series pair per group"
        );
        let (lat, lon, h) = setup().site;
        let st = Station::new(lat, lon, h).unwrap();
        let nm_s2_per_g = STANDARD_GRAVITY_M_S2 * NM_S2_PER_M_S2;
        let (mut worst, mut peak) = (0.0f64, 0.0f64);
        // At the nodes (every 300 s from t = −600 s) the interpolation returns the node value.
        for i in 0..288 {
            let t = 300.0 * f64::from(i);
            let args = DoodsonArguments::at_unix_seconds(setup().start_unix_s + t);
            let direct: f64 = member
                .iter()
                .map(|g| {
                    let (lo, hi) = group_band(&g.name).unwrap();
                    let phase = g.phase_deg.to_radians();
                    CTE1973
                        .iter()
                        .filter(|w| (lo..hi).contains(&w.frequency_cpd()))
                        .map(|w| {
                            let mut wg = st.wave_gravity(w);
                            wg.phase_rad += phase;
                            g.factor * st.gravimetric_factor(w) * wg.at(w, &args)
                        })
                        .sum::<f64>()
                })
                .sum::<f64>()
                / nm_s2_per_g;
            let y = cached.output_term(&drive(t, 0.0));
            assert_eq!(y.to_bits(), own.output_term(&drive(t, 0.0)).to_bits());
            worst = worst.max((y - direct).abs());
            peak = peak.max(direct.abs());
        }
        assert!(peak > 1e-10, "the draw's correction is a tide: {peak}");
        assert!(worst <= 1e-12 * peak, "{worst} of {peak}");
    }

    /// A delayed `tidal_gravity` term from the kept model tide (kept by an earlier chain of
    /// the run) is the ephemeris tide at the 60 s nodes around t − delay, linear in between,
    /// inside the run's span and beyond it (where the chain evaluates the nodes itself).
    #[test]
    fn a_delayed_tide_term_from_the_kept_nodes_is_the_ephemeris_tide_interpolated() {
        let tidal = |amplitude_factor: f64| ScenarioEffect::TidalGravity {
            amplitude_factor,
            delay_s: 1234.0,
            groups: Vec::new(),
        };
        let kept = KeptTides::default();
        EffectChain::with_kept_tides(&[tidal(0.3)], setup(), &kept).unwrap();
        let mut c = EffectChain::with_kept_tides(&[tidal(0.07)], setup(), &kept).unwrap();
        assert_eq!(
            kept.model.lock().unwrap().len(),
            1,
            "one model tide for the run"
        );
        let (lat, lon, h) = setup().site;
        let st = Station::new(lat, lon, h).unwrap();
        let g = |k: f64| {
            st.tide_at_unix_seconds(setup().start_unix_s + k * TIDE_NODE_S)
                .gravity_gs()
                .0
        };
        // Inside the span, then two days past its end.
        for t in (0..144)
            .map(|i| 137.0 + 600.0 * f64::from(i))
            .chain([259_321.0])
        {
            let x = (t - 1234.0) / TIDE_NODE_S;
            let k = x.floor();
            let want = 0.07 * (g(k) + (x - k) * (g(k + 1.0) - g(k)));
            assert_eq!(c.output_term(&drive(t, 0.0)), want, "t = {t}");
        }
    }

    #[test]
    fn a_group_term_at_factor_one_is_the_models_group_tide() {
        // M2 alone at factor 1 against the model's full tide: the semidiurnal band dominates
        // at mid latitude, so the two correlate strongly and the M2 term is ~half the range.
        let mut c = EffectChain::new(
            &[ScenarioEffect::TidalGravity {
                amplitude_factor: 0.0,
                delay_s: 0.0,
                groups: vec![TideGroupTerm {
                    name: "M2".into(),
                    factor: 1.0,
                    phase_deg: 0.0,
                }],
            }],
            setup(),
        )
        .unwrap();
        let mut full = EffectChain::new(
            &[ScenarioEffect::TidalGravity {
                amplitude_factor: 1.0,
                delay_s: 0.0,
                groups: vec![],
            }],
            setup(),
        )
        .unwrap();
        let (mut a, mut b) = (Vec::new(), Vec::new());
        for i in 0..288 {
            let t = 300.0 * f64::from(i);
            a.push(c.output_term(&drive(t, 0.0)));
            b.push(full.output_term(&drive(t, 0.0)));
        }
        let ptp = |v: &[f64]| {
            v.iter().cloned().fold(f64::MIN, f64::max) - v.iter().cloned().fold(f64::MAX, f64::min)
        };
        // In g: the full tide spans ~1–3e-7 g, M2 alone a good part of it.
        assert!((0.5e-7..4e-7).contains(&ptp(&b)), "{}", ptp(&b));
        assert!(
            ptp(&a) > 0.2 * ptp(&b) && ptp(&a) < 1.2 * ptp(&b),
            "{}",
            ptp(&a)
        );
    }
}
