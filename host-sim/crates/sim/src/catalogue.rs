//! The catalogue of effects, once: every effect the discovery names and a scenario's
//! `[[effects]]` injects, with its parameters as both write them (the discovery's report and JSON,
//! the scenario's TOML keys) and their units. The discovery's `Effect` and the simulator's
//! [`ScenarioEffect`](crate::effects::ScenarioEffect) each say which entry they are (`kind()`),
//! and their tests check that the parameters they write are the ones listed here, in this order.
//!
//! "output" in a unit is the record's output unit (V, g, µGal, ...).

/// One entry of the catalogue.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum EffectKind {
    /// The proof mass lags the mount temperature.
    ThermalLag,
    /// Different bias on heating and cooling branches.
    ThermalHysteresis,
    /// Torquer self-heating after an input change.
    SelfHeating,
    /// Exponential transient after power-on.
    Warmup,
    /// Logarithmic aging.
    AgingDrift,
    /// A bias change, abrupt or over a linear ramp ([`step_fraction`]).
    Step,
    /// A correction of the solid-earth tide gravity.
    TidalGravity,
    /// The solid-earth tide tilt along the sensitive axis (0 g records).
    TidalTilt,
    /// Diurnal building tilt (0 g records).
    BuildingTilt,
    /// Gain error of the tiltmeter's eq. (5) tilt term.
    TiltCoupling,
    /// An auxiliary channel through a first-order lag.
    AmbientCoupling,
    /// Barometric admittance.
    PressureAdmittance,
    /// A line at a period matching no known cause.
    Periodic,
    /// Any channel through a gain on its rate of change (a gradient across the sensor while the
    /// channel ramps): [`RateOfChange`].
    RateCoupling,
    /// The lag error of any channel through a second-order lag (two equal first-order stages),
    /// L2_τ[c] − c: [`SecondOrderLag`].
    Lag2Coupling,
    /// A drift that is a power of the time since the start, [`creep`] (quadratic at exponent 2).
    CreepDrift,
    /// White reading noise on a measured channel: simulated, not a discovery candidate (the
    /// discovery reports a channel's noise with its channels, not as an effect).
    ChannelNoise,
}

/// A parameter: its name in the discovery's output and in the scenario, and its unit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ParamSpec {
    /// Name (report, JSON, scenario TOML key).
    pub name: &'static str,
    /// Unit ("output" = the record's output unit; "1" = dimensionless).
    pub unit: &'static str,
}

/// A `&'static [ParamSpec]` written as a table: `params!["tau_s": "s", "amplitude": "output"]`.
macro_rules! params {
    ($($name:literal: $unit:literal),* $(,)?) => {
        &[$(ParamSpec { name: $name, unit: $unit }),*]
    };
}

impl EffectKind {
    /// Every entry, in the catalogue's order.
    pub const ALL: [EffectKind; 17] = [
        EffectKind::ThermalLag,
        EffectKind::ThermalHysteresis,
        EffectKind::SelfHeating,
        EffectKind::Warmup,
        EffectKind::AgingDrift,
        EffectKind::Step,
        EffectKind::TidalGravity,
        EffectKind::TidalTilt,
        EffectKind::BuildingTilt,
        EffectKind::TiltCoupling,
        EffectKind::AmbientCoupling,
        EffectKind::PressureAdmittance,
        EffectKind::Periodic,
        EffectKind::RateCoupling,
        EffectKind::Lag2Coupling,
        EffectKind::CreepDrift,
        EffectKind::ChannelNoise,
    ];

    /// The name (the scenario's `kind`, the discovery's effect name).
    pub fn name(self) -> &'static str {
        match self {
            EffectKind::ThermalLag => "thermal_lag",
            EffectKind::ThermalHysteresis => "thermal_hysteresis",
            EffectKind::SelfHeating => "self_heating",
            EffectKind::Warmup => "warmup",
            EffectKind::AgingDrift => "aging_drift",
            EffectKind::Step => "step",
            EffectKind::TidalGravity => "tidal_gravity",
            EffectKind::TidalTilt => "tidal_tilt",
            EffectKind::BuildingTilt => "building_tilt",
            EffectKind::TiltCoupling => "tilt_coupling",
            EffectKind::AmbientCoupling => "ambient_coupling",
            EffectKind::PressureAdmittance => "pressure_admittance",
            EffectKind::Periodic => "periodic",
            EffectKind::RateCoupling => "rate_coupling",
            EffectKind::Lag2Coupling => "lag2_coupling",
            EffectKind::CreepDrift => "creep_drift",
            EffectKind::ChannelNoise => "channel_noise",
        }
    }

    /// The entry of a name.
    pub fn from_name(name: &str) -> Option<EffectKind> {
        EffectKind::ALL.into_iter().find(|k| k.name() == name)
    }

    /// Whether the discovery looks for it.
    pub fn discovered(self) -> bool {
        self != EffectKind::ChannelNoise
    }

    /// Whether the discovery can accept it more than once (at other parameters).
    pub fn repeatable(self) -> bool {
        matches!(self, EffectKind::Step | EffectKind::Periodic)
    }

    /// The parameters, in the order the discovery reports them. The scenario takes the same
    /// keys; a few entries bind a channel (`ambient_coupling`, `rate_coupling`, `lag2_coupling`,
    /// `channel_noise`: `channel`) and
    /// `tidal_gravity` also takes the tidal analysis's `delay_s` and wave `groups`.
    pub fn parameters(self) -> &'static [ParamSpec] {
        match self {
            EffectKind::ThermalLag => params!["tau_s": "s", "coefficient": "output/°C"],
            EffectKind::ThermalHysteresis => {
                params!["half_width": "output", "play_half_width_c": "°C"]
            }
            EffectKind::SelfHeating => params!["tau_s": "s", "coefficient": "output/g²"],
            EffectKind::Warmup | EffectKind::AgingDrift => {
                params!["tau_s": "s", "amplitude": "output"]
            }
            EffectKind::Step => params!["time_s": "s", "size": "output", "duration_s": "s"],
            EffectKind::TidalGravity => params!["amplitude_factor": "1"],
            EffectKind::TidalTilt => params!["amplitude_factor": "1", "azimuth_deg": "°"],
            EffectKind::BuildingTilt => params!["amplitude": "output", "phase_rad": "rad"],
            EffectKind::TiltCoupling => params!["gain": "1"],
            EffectKind::AmbientCoupling => {
                params!["coefficient": "output/channel unit", "lag_s": "s"]
            }
            EffectKind::PressureAdmittance => params!["coefficient": "output/Pa"],
            EffectKind::Periodic => {
                params!["period_s": "s", "amplitude": "output", "phase_rad": "rad"]
            }
            EffectKind::RateCoupling => params!["coefficient": "output·s/channel unit"],
            EffectKind::Lag2Coupling => {
                params!["tau_s": "s", "coefficient": "output/channel unit"]
            }
            EffectKind::CreepDrift => params!["exponent": "1", "amplitude": "output"],
            EffectKind::ChannelNoise => params!["noise": "channel unit (°C, rad, Pa)"],
        }
    }

    /// The parameter names, in order.
    pub fn parameter_names(self) -> Vec<&'static str> {
        self.parameters().iter().map(|p| p.name).collect()
    }
}

/// How far a `step` of `duration_s` centred on `time_s` has gone at `t`: 0 before, 1 after, a
/// linear ramp in between; `duration_s` 0 is the jump H(t − time_s). The discovery's step column
/// and the simulator's step are both this.
#[inline]
pub fn step_fraction(t: f64, time_s: f64, duration_s: f64) -> f64 {
    if duration_s > 0.0 {
        let start = time_s - 0.5 * duration_s;
        ((t - start) / duration_s).clamp(0.0, 1.0)
    } else {
        f64::from(t >= time_s)
    }
}

/// The transfer functions of the channel couplings, stepped one instant at a time: the
/// simulator steps them with the true channel, the discovery runs them over the measured one
/// (restarted per segment) to make its column — one definition for both.
///
/// Gain on the rate of change: (u − u_prev)/(t − t_prev), 0 at the first instant.
#[derive(Debug, Clone, Copy, Default)]
pub struct RateOfChange {
    prev: Option<(f64, f64)>,
}

impl RateOfChange {
    /// The channel's rate of change at `t` (channel unit per s).
    pub fn step(&mut self, t: f64, u: f64) -> f64 {
        let r = match self.prev {
            Some((t0, u0)) if t > t0 => (u - u0) / (t - t0),
            _ => 0.0,
        };
        self.prev = Some((t, u));
        r
    }
}

/// First-order lag τ dx/dt = u − x, exact for an input held at its new value over the interval
/// since the previous instant; settled at the first input (and passed through for τ ≤ 0). The
/// simulator's thermal lag, self-heating, ambient coupling and hysteresis output lag step it; the
/// discovery's lag columns run it over each segment.
#[derive(Debug, Clone, Copy, Default)]
pub struct FirstOrderLag {
    state: Option<(f64, f64)>,
}

impl FirstOrderLag {
    /// The lagged input at `t` (input unit).
    #[inline]
    pub fn step(&mut self, t: f64, u: f64, tau_s: f64) -> f64 {
        let x = match self.state {
            Some((t0, x0)) if tau_s > 0.0 => {
                let a = (-(t - t0).max(0.0) / tau_s).exp();
                a * x0 + (1.0 - a) * u
            }
            _ => u,
        };
        self.state = Some((t, x));
        x
    }
}

/// Play (backlash) operator of half-width r: its output p follows the input u only when u is
/// more than r away, p ← clamp(p, u − r, u + r); it starts at the first input (the virgin state:
/// no branch yet). `thermal_hysteresis`'s plays, simulated and fitted, are this.
#[derive(Debug, Clone, Copy, Default)]
pub struct Play {
    p: Option<f64>,
}

impl Play {
    /// The operator's output after input `u` (input unit).
    #[inline]
    pub fn step(&mut self, u: f64, r: f64) -> f64 {
        let p = self.p.unwrap_or(u).max(u - r).min(u + r);
        self.p = Some(p);
        p
    }
}

/// One step of a relay hysteron's state R at temperature `t_c`: +1 at or above `upper_c`, −1 at
/// or below `lower_c`, held in between (0 until the first switch). The simulator's injection and
/// the discovery's relay columns both step with it.
#[inline]
pub fn relay_step(state: f64, t_c: f64, lower_c: f64, upper_c: f64) -> f64 {
    if t_c >= upper_c {
        1.0
    } else if t_c <= lower_c {
        -1.0
    } else {
        state
    }
}

/// Second-order lag: two first-order stages of time constant τ in series (critically damped),
/// each exact for the interval since the previous instant; settled at the first input.
#[derive(Debug, Clone, Copy, Default)]
pub struct SecondOrderLag {
    state: Option<(f64, f64, f64)>,
}

impl SecondOrderLag {
    /// The lagged channel at `t` (channel unit).
    pub fn step(&mut self, t: f64, u: f64, tau_s: f64) -> f64 {
        let (x1, x2) = match self.state {
            Some((t0, x1, x2)) if tau_s > 0.0 => {
                // Exact for an input held over the interval: x₁ relaxes to u as e^{−s/τ}, and
                // x₂ follows it, x₂(h) = a·x₂ + (1 − a)·u + (x₁ − u)·(h/τ)·a.
                let h = (t - t0).max(0.0);
                let a = (-h / tau_s).exp();
                let x1n = a * x1 + (1.0 - a) * u;
                (x1n, a * x2 + (1.0 - a) * u + (x1 - u) * (h / tau_s) * a)
            }
            _ => (u, u),
        };
        self.state = Some((t, x1, x2));
        x2
    }
}

/// A relay's thresholds (`lower_c`, `upper_c`) with its gap scaled by `scale` about its centre:
/// how `thermal_hysteresis` widens or narrows (every play's half-width × `scale`, every relay's
/// gap so), in the discovery's width search and in a twin member's drawn width alike.
#[inline]
pub fn relay_scaled(lower_c: f64, upper_c: f64, scale: f64) -> (f64, f64) {
    let (centre, gap) = (0.5 * (lower_c + upper_c), 0.5 * (upper_c - lower_c) * scale);
    (centre - gap, centre + gap)
}

/// A warm-up transient's shape `since_start_s` after the start: exp(−t/τ) (1 at the start).
#[inline]
pub fn warmup(since_start_s: f64, tau_s: f64) -> f64 {
    (-since_start_s / tau_s).exp()
}

/// Logarithmic aging's shape `since_start_s` after the start: ln(1 + t/τ) (0 before the start).
#[inline]
pub fn aging(since_start_s: f64, tau_s: f64) -> f64 {
    (1.0 + since_start_s.max(0.0) / tau_s).ln()
}

/// Seconds of the time unit of [`creep`]: its amplitude is the drift after one day.
pub const CREEP_TIME_UNIT_S: f64 = 86_400.0;

/// A power-law drift's shape `since_start_s` after the start: (t / 1 day)^exponent (0 before
/// the start).
#[inline]
pub fn creep(since_start_s: f64, exponent: f64) -> f64 {
    (since_start_s.max(0.0) / CREEP_TIME_UNIT_S).powf(exponent)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effects::ScenarioEffect;

    #[test]
    fn names_are_unique_and_read_back() {
        for k in EffectKind::ALL {
            assert_eq!(EffectKind::from_name(k.name()), Some(k));
        }
        assert_eq!(EffectKind::from_name("no_such_effect"), None);
    }

    /// One scenario entry of each kind, every parameter set (non-zero, so none is skipped).
    fn one_of_each() -> Vec<ScenarioEffect> {
        use ScenarioEffect as S;
        vec![
            S::ThermalLag {
                tau_s: 1.0,
                coefficient: 1.0,
            },
            S::ThermalHysteresis {
                half_width: 1.0,
                play_half_width_c: 1.0,
                relays: Vec::new(),
                lag_s: 0.0,
            },
            S::SelfHeating {
                tau_s: 1.0,
                coefficient: 1.0,
            },
            S::Warmup {
                tau_s: 1.0,
                amplitude: 1.0,
            },
            S::AgingDrift {
                tau_s: 1.0,
                amplitude: 1.0,
            },
            S::Step {
                time_s: 1.0,
                size: 1.0,
                duration_s: 1.0,
            },
            S::TidalGravity {
                amplitude_factor: 1.0,
                delay_s: 1.0,
                groups: Vec::new(),
            },
            S::TidalTilt {
                amplitude_factor: 1.0,
                azimuth_deg: 1.0,
            },
            S::BuildingTilt {
                amplitude: 1.0,
                phase_rad: 1.0,
            },
            S::TiltCoupling { gain: 1.0 },
            S::AmbientCoupling {
                channel: "room_c".into(),
                coefficient: 1.0,
                lag_s: 1.0,
            },
            S::PressureAdmittance { coefficient: 1.0 },
            S::Periodic {
                period_s: 1.0,
                amplitude: 1.0,
                phase_rad: 1.0,
            },
            S::RateCoupling {
                channel: "temperature_c".into(),
                coefficient: 1.0,
            },
            S::Lag2Coupling {
                channel: "temperature_c".into(),
                tau_s: 1.0,
                coefficient: 1.0,
            },
            S::CreepDrift {
                exponent: 1.0,
                amplitude: 1.0,
            },
            S::ChannelNoise {
                channel: "temperature_c".into(),
                noise: 1.0,
            },
        ]
    }

    /// The scenario injects what the catalogue lists: its `kind` is the catalogue's name and its
    /// keys are the catalogue's parameters (plus the channel an entry binds and the tidal
    /// analysis's delay and groups, which are not fitted parameters).
    #[test]
    fn every_scenario_effect_writes_the_catalogue_name_and_parameters() {
        let all = one_of_each();
        let kinds: Vec<EffectKind> = all.iter().map(ScenarioEffect::kind).collect();
        assert_eq!(kinds, EffectKind::ALL);
        for e in &all {
            let toml::Value::Table(t) = toml::Value::try_from(e).unwrap() else {
                panic!("{e:?} is not a table")
            };
            assert_eq!(t["kind"].as_str(), Some(e.name()));
            let mut keys: Vec<&str> = t
                .keys()
                .map(String::as_str)
                .filter(|k| !matches!(*k, "kind" | "channel" | "delay_s" | "groups"))
                .collect();
            let mut expected = e.kind().parameter_names();
            keys.sort_unstable();
            expected.sort_unstable();
            assert_eq!(keys, expected, "{}", e.name());
        }
    }

    #[test]
    fn the_second_order_lag_of_a_step_rises_as_two_stages_and_the_rate_is_the_slope() {
        // Unit step at t = 0+, τ = 10 s, 1 s steps: 1 − e^{−t/τ}(1 + t/τ) at t = τ is 0.2642.
        let mut l = SecondOrderLag::default();
        let mut y = l.step(0.0, 0.0, 10.0);
        for k in 1..=10 {
            y = l.step(f64::from(k), 1.0, 10.0);
        }
        // Each input is held over the interval before it: exact for a step.
        assert!((y - (1.0 - (-1.0_f64).exp() * 2.0)).abs() < 1e-12, "{y}");
        let mut r = RateOfChange::default();
        assert_eq!(r.step(0.0, 1.0), 0.0);
        assert_eq!(r.step(2.0, 5.0), 2.0);
        assert_eq!(creep(2.0 * CREEP_TIME_UNIT_S, 2.0), 4.0);
        assert_eq!(creep(-1.0, 2.0), 0.0);
    }

    #[test]
    fn a_step_ramps_linearly_over_its_duration_and_jumps_without_one() {
        assert_eq!(step_fraction(9.9, 10.0, 0.0), 0.0);
        assert_eq!(step_fraction(10.0, 10.0, 0.0), 1.0);
        assert_eq!(step_fraction(4.0, 10.0, 10.0), 0.0);
        assert_eq!(step_fraction(10.0, 10.0, 10.0), 0.5);
        assert_eq!(step_fraction(12.5, 10.0, 10.0), 0.75);
        assert_eq!(step_fraction(16.0, 10.0, 10.0), 1.0);
    }

    #[test]
    fn the_first_order_lag_of_a_step_is_exact_for_any_spacing() {
        // Unit step after t = 0, τ = 10 s: 1 − e^{−t/τ} at t = 10 s, whether reached in one
        // interval or ten unequal ones; τ = 0 passes the input through.
        let mut one = FirstOrderLag::default();
        one.step(0.0, 0.0, 10.0);
        let y1 = one.step(10.0, 1.0, 10.0);
        let mut many = FirstOrderLag::default();
        many.step(0.0, 0.0, 10.0);
        let mut y = 0.0;
        for t in [0.5, 1.0, 3.0, 3.5, 6.0, 7.0, 9.9, 10.0] {
            y = many.step(t, 1.0, 10.0);
        }
        let want = 1.0 - (-1.0_f64).exp();
        assert!(
            (y1 - want).abs() < 1e-15 && (y - want).abs() < 1e-12,
            "{y1} {y}"
        );
        let mut through = FirstOrderLag::default();
        through.step(0.0, 0.0, 0.0);
        assert_eq!(through.step(1.0, 3.0, 0.0), 3.0);
    }

    #[test]
    fn a_play_moves_only_once_the_input_is_its_half_width_away() {
        // r = 1: starts at the first input, holds while the input reverses within 2r, follows
        // one r behind beyond it; a relay holds between its thresholds.
        let mut p = Play::default();
        let out: Vec<f64> = [0.0, 0.5, 2.0, 1.5, 0.2, -1.0]
            .iter()
            .map(|&u| p.step(u, 1.0))
            .collect();
        assert_eq!(out, [0.0, 0.0, 1.0, 1.0, 1.0, 0.0]);
        let states: Vec<f64> = [0.0, 0.6, 0.4, 0.2, 0.4]
            .iter()
            .scan(0.0, |r, &t| {
                *r = relay_step(*r, t, 0.2, 0.6);
                Some(*r)
            })
            .collect();
        assert_eq!(states, [-1.0, 1.0, 1.0, -1.0, -1.0]);
    }
}
