//! The station simulator's twin (`twin::Twin`) as the comparison's [`TwinModel`].
//!
//! The accepted effects become scenario entries through `scenario_effects_from_discovery`
//! (joint-fit parameters; `tidal_gravity` as wave-group corrections with the delay in their
//! phases when the wave-group analysis ran). One addition here: a pressure admittance fitted by
//! the wave-group analysis (jointly with the tide) that the greedy selection did not accept is
//! added when it is significant (|value| > [`ADMITTANCE_SIGMAS`] σ), named
//! `pressure_admittance (tidal analysis)` — the catalogue search alone leaves the barometric
//! signal in the residual when the tide's errors dominate its likelihood. Likewise the
//! wave-group tide when the selection did not accept `tidal_gravity` (its forward chaining can
//! refuse the in-phase factor of a tide whose error is mostly a phase) but a group's factor
//! against the twin's tide is significant (> [`TIDE_SIGMAS`] σ), named
//! `tidal_gravity (tidal analysis)`: left in the residual, the tide's lines are a mismatch of
//! ×20–40 at 1 and 2 cycles/day on each half of gMetrology.

use super::spectra::RegularGrid;
use super::{Refused, TwinModel};
use crate::discover::Discovery;
use crate::sim::effects::ScenarioEffect;
use crate::sim::twin::draw::{Drawn, EffectDraw, EffectDraws};
use crate::sim::twin::drift::Settling;
use crate::sim::twin::MemberModel;
use crate::twin::family::NoiseFamily;
use crate::twin::transients::Transients;
use crate::twin::{effect_draws, Twin, TwinError};

/// Significance a wave-group analysis admittance needs to be added.
pub const ADMITTANCE_SIGMAS: f64 = 3.0;

/// Significance a wave-group factor against the twin's tide needs for the groups to be added.
pub const TIDE_SIGMAS: f64 = 3.0;

/// The name of the wave-group tide added by [`TwinModel::effects_from`].
const TIDE_NAME: &str = "tidal_gravity (tidal analysis)";

/// Whether the twin takes the wave-group tide: the selection did not accept `tidal_gravity`
/// and some group's factor against the twin's tide is beyond [`TIDE_SIGMAS`] σ.
fn significant_tide(d: &Discovery) -> bool {
    let accepted = d
        .selection
        .accepted
        .iter()
        .any(|a| a.effect.name() == "tidal_gravity");
    let significant = d.tidal.as_ref().is_ok_and(|t| {
        t.groups.iter().any(|g| {
            let f = &g.amplitude_factor_vs_elastic_model;
            f.value.is_finite() && f.sigma.is_finite() && f.value.abs() > TIDE_SIGMAS * f.sigma
        })
    });
    !accepted && significant
}

impl TwinModel for Twin {
    type Effect = ScenarioEffect;
    type Error = TwinError;

    fn run(&self, seed: Option<u64>) -> Result<Vec<f64>, TwinError> {
        Twin::run(self, seed)
    }

    fn effects_from(&self, d: &Discovery) -> (Vec<(String, ScenarioEffect)>, Refused) {
        let draws = draws(d);
        let (effects, refused) = draws.nominal();
        let mut names: Vec<String> = effects.iter().map(|e| e.name().to_owned()).collect();
        if draws.admittance_per_hpa.is_some() {
            if let Some(last) = names.last_mut() {
                *last = "pressure_admittance (tidal analysis)".to_owned();
            }
        }
        // The wave-group tide is the only `tidal_gravity` when the selection refused it.
        if significant_tide(d) {
            if let Some(n) = names.iter_mut().find(|n| *n == "tidal_gravity") {
                *n = TIDE_NAME.to_owned();
            }
        }
        // Repeated kinds (steps, lines) get #2, #3 … in order.
        let mut seen: Vec<String> = Vec::new();
        let named = names
            .into_iter()
            .zip(effects)
            .map(|(n, e)| {
                let k = seen.iter().filter(|s| **s == n).count();
                seen.push(n.clone());
                let name = if k > 0 { format!("{n}#{}", k + 1) } else { n };
                (name, e)
            })
            .collect();
        (named, refused)
    }

    fn effects_drawn(&self, d: &Discovery, member: u64) -> Vec<ScenarioEffect> {
        draws(d).drawn(member)
    }

    fn written_twin(&self, d: &Discovery) -> Option<MemberModel> {
        self.grid_noise()
            .map(|g| Twin::member_model(self, g.clone(), Some(draws(d))))
    }

    fn extended(&self, effects: &[ScenarioEffect]) -> Self {
        Twin::extended(self, effects)
    }

    fn with_family(&self, family: &NoiseFamily, grid: &RegularGrid) -> Self {
        Twin::with_family(self, family, &grid.cell, grid.len)
    }

    fn with_transients(&self, found: &Transients) -> Self {
        Twin::with_transients(self, found)
    }

    fn with_drift(&self, coefficients: &[(f64, f64)], settling: Option<&Settling>) -> Self {
        Twin::with_drift(self, coefficients, settling)
    }

    fn provenance(&self) -> Vec<String> {
        let mut v = Twin::provenance(self).to_vec();
        let w = self.weather_drivers();
        v.push(if w.is_empty() {
            "ensemble members: the instrument noise only (no simulated driver enters the output; \
             measured channels are the record's in every member)"
                .to_owned()
        } else {
            format!(
                "ensemble members: the instrument noise and their own weather of the simulated \
                 driver(s) {} (the station re-run with the member's seed); measured channels are \
                 the record's in every member",
                w.join(", ")
            )
        });
        v
    }

    fn scenario_toml(&self) -> Option<String> {
        Some(self.scenario().to_toml())
    }

    fn is_simulator(&self) -> bool {
        true
    }
}

/// The accepted effects' draws with the wave-group tide and admittance that
/// [`TwinModel::effects_from`] adds (drawn like the rest, after them, in that order). The tide
/// is a `tidal_gravity` entry without parameters of its own: the rule writes it as the
/// wave-group analysis' groups, so the written twin carries it too.
fn draws(d: &Discovery) -> EffectDraws {
    let mut e = effect_draws(d);
    if significant_tide(d) && e.tide_groups.as_ref().is_some_and(|g| !g.is_empty()) {
        e.effects.push(EffectDraw {
            kind: "tidal_gravity".to_owned(),
            channel: None,
            params: Vec::new(),
            alternative: None,
            hysteresis: None,
        });
    }
    let accepted = e.effects.iter().any(|a| a.kind == "pressure_admittance");
    if !accepted {
        if let Ok(Some(a)) = d.tidal.as_ref().map(|t| t.pressure_admittance.as_ref()) {
            let p = &a.per_hpa;
            if p.value.is_finite()
                && p.sigma.is_finite()
                && p.value.abs() > ADMITTANCE_SIGMAS * p.sigma
            {
                e.admittance_per_hpa = Some(Drawn {
                    value: p.value,
                    sigma: p.sigma,
                });
            }
        }
    }
    e
}
