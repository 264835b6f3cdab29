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
use crate::sim::noise::{gauss, stream};
use crate::twin::family::NoiseFamily;
use crate::twin::transients::Transients;
use crate::twin::{
    scenario_effects_drawn, scenario_effects_from_discovery, tide_from_groups, Twin, TwinError,
};

/// Random stream of a member's draw of the effects' parameters (not the noise's stream).
const EFFECT_DRAW_STREAM: u64 = 5;

/// Significance a wave-group analysis admittance needs to be added.
pub const ADMITTANCE_SIGMAS: f64 = 3.0;

/// Significance a wave-group factor against the twin's tide needs for the groups to be added.
pub const TIDE_SIGMAS: f64 = 3.0;

/// The name of the wave-group tide added by [`TwinModel::effects_from`].
const TIDE_NAME: &str = "tidal_gravity (tidal analysis)";

/// The discovery's wave-group analysis, when the selection did not accept `tidal_gravity` and
/// some group's factor against the twin's tide is beyond [`TIDE_SIGMAS`] σ.
fn significant_tide(d: &Discovery) -> Option<&crate::discover::tidal::TidalAnalysis> {
    let accepted = d
        .selection
        .accepted
        .iter()
        .any(|a| a.effect.name() == "tidal_gravity");
    let t = d.tidal.as_ref().ok()?;
    let significant = t.groups.iter().any(|g| {
        let f = &g.amplitude_factor_vs_elastic_model;
        f.value.is_finite() && f.sigma.is_finite() && f.value.abs() > TIDE_SIGMAS * f.sigma
    });
    (!accepted && significant).then_some(t)
}

/// Pascals per hectopascal.
const PA_PER_HPA: f64 = 100.0;

impl TwinModel for Twin {
    type Effect = ScenarioEffect;
    type Error = TwinError;

    fn run(&self, seed: Option<u64>) -> Result<Vec<f64>, TwinError> {
        Twin::run(self, seed)
    }

    fn effects_from(&self, d: &Discovery) -> (Vec<(String, ScenarioEffect)>, Refused) {
        let (mut effects, refused) = scenario_effects_from_discovery(d);
        let mut names: Vec<String> = effects.iter().map(|e| e.name().to_owned()).collect();
        if let Some(t) = significant_tide(d) {
            effects.push(tide_from_groups(t, |p| p.value));
            names.push(TIDE_NAME.to_owned());
        }
        if !names.iter().any(|n| n == "pressure_admittance") {
            if let Ok(Some(a)) = d.tidal.as_ref().map(|t| t.pressure_admittance.as_ref()) {
                let p = &a.per_hpa;
                if p.value.is_finite()
                    && p.sigma.is_finite()
                    && p.value.abs() > ADMITTANCE_SIGMAS * p.sigma
                {
                    effects.push(ScenarioEffect::PressureAdmittance {
                        coefficient: p.value / PA_PER_HPA,
                    });
                    names.push("pressure_admittance (tidal analysis)".to_owned());
                }
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
        let mut rng = stream(member, EFFECT_DRAW_STREAM);
        let mut effects = scenario_effects_drawn(d, &mut rng, member);
        // The wave-group tide, drawn like the rest, when `effects_from` adds it.
        if let Some(t) = significant_tide(d) {
            let rng = std::cell::RefCell::new(&mut rng);
            effects.push(tide_from_groups(t, |p| {
                if p.sigma.is_finite() && p.sigma > 0.0 {
                    p.value + p.sigma * gauss(&mut rng.borrow_mut())
                } else {
                    p.value
                }
            }));
        }
        // The wave-group admittance, drawn like the rest, when `effects_from` adds it.
        let (nominal, _) = self.effects_from(d);
        if nominal
            .iter()
            .any(|(n, _)| n == "pressure_admittance (tidal analysis)")
        {
            if let Ok(Some(a)) = d.tidal.as_ref().map(|t| t.pressure_admittance.as_ref()) {
                let p = &a.per_hpa;
                effects.push(ScenarioEffect::PressureAdmittance {
                    coefficient: (p.value + p.sigma * gauss(&mut rng)) / PA_PER_HPA,
                });
            }
        }
        effects
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
