//! The simulated twin of a measured record: the station simulator's instrument, at the record's
//! site and time, driven by the record's measured channels, predicting the record's output at
//! its own time stamps. The rules (what comes from the record, what from defaults) are in
//! docs/simulator.md, "Twin of a measured record", and each twin lists them for its record in
//! [`Twin::provenance`].
//!
//! Speed: everything that does not depend on the seed — the drivers, the tide, the instrument's
//! deterministic output and the effects — is computed once by [`Twin::new`] /
//! [`Twin::extended`]; [`Twin::run`] with a seed adds the instrument noise, drawn directly at
//! the record's (irregular) instants, and — only when a driver the record lacks enters the
//! output — re-runs the station with the member's seed so that the simulated drivers carry
//! their own weather (measured channels stay measured in every member).

mod build;
mod error;
pub mod family;
mod from_discovery;
mod noise;
#[cfg(test)]
pub(crate) mod tests;
/// The transient disturbances are the simulator's (a written twin's members draw them).
pub use crate::sim::twin::transients;

pub use error::TwinError;
pub use from_discovery::{effect_draws, scenario_effects_drawn, scenario_effects_from_discovery};

use noise::*;

use accomp::units::RAD_PER_ARCSEC;

use crate::discover::import::{unit_per_g_for_suffix, ChannelKind, Dataset};
use crate::discover::noise::NoiseModel;
use crate::sim::accelerometer::{DividingHead, HeadPosition};
use crate::sim::effects::{ScenarioEffect, SIMULATED_AMBIENT};
use crate::sim::gravimeter::{GravimeterParams, InstrumentParams, UNITS};
use crate::sim::noise::{gauss, stream, AllanParams};
use crate::sim::scenario::Scenario;
use crate::sim::tide::{TideModel, TideSampler};
use crate::sim::time::Utc;
use crate::sim::twin::draw::{Drawn, EffectDraws};
use crate::sim::twin::drift::{DriftPolynomial, Settling};
use crate::sim::twin::family::GridNoise;
pub use crate::sim::twin::record::quiet;
use crate::sim::twin::record::{
    interp, station_series, Drivers, Simulated, StationSeries, TwinRecord,
};
use crate::sim::twin::MemberModel;
use crate::sim::STANDARD_GRAVITY_M_S2;

/// The preset a derived twin starts from.
const BASE_PRESET: &str = "paper-1g";

/// The simulated twin of a measured record: the simulator's member model
/// ([`crate::sim::twin`]) with what the record said about it.
#[derive(Debug, Clone)]
pub struct Twin {
    /// The deterministic part at the record's instants (scenario, drivers, output).
    rec: TwinRecord,
    provenance: Vec<String>,
    dt_s: f64,
    /// Instrument noise in the record unit.
    noise: AllanParams,
    /// The record's fitted noise model, when given: the members draw from it exactly (its
    /// flicker slope included, which the scenario's three Allan levels cannot hold).
    noise_model: Option<NoiseModel>,
    /// The noise family fitted to the record, when given ([`Twin::with_family`]): members draw
    /// from it instead (each its own parameters, then the noise on the record's grid).
    family: Option<GridNoise>,
    /// The record's drift polynomial, when given ([`Twin::with_drift`]): every member carries
    /// it.
    drift: Option<DriftPolynomial>,
}

impl Twin {
    /// The scenario in use (to write with --write-scenario after `extended`).
    pub fn scenario(&self) -> &Scenario {
        &self.rec.scenario
    }

    /// What came from the record and what from defaults, one line each (printed by twin).
    pub fn provenance(&self) -> &[String] {
        &self.provenance
    }

    /// The record's time stamps `ds.t_s`; the output predicted at each, in the record's
    /// output unit. `seed: None` = the deterministic part (all noise off), `Some(s)` = one
    /// ensemble member with the simulator's noise. Measured temperature / pressure / tilt
    /// channels of the record drive the simulation where present (interpolated onto the
    /// simulator's steps), their simulated counterparts where absent.
    ///
    /// A member whose output depends on a simulated driver (see [`Twin::redraws_weather`])
    /// re-runs the station with its seed: the simulated drivers get that member's weather (room,
    /// thermostat, foundation, barometer), the measured channels stay the record's.
    pub fn run(&self, seed: Option<u64>) -> Result<Vec<f64>, TwinError> {
        let Some(seed) = seed else {
            return Ok(self.rec.det.clone());
        };
        match (&self.family, &self.noise_model) {
            (Some(g), _) => Ok(self.member_model(g.clone(), None).member(seed)?),
            (None, m) => {
                let mut out = self.rec.member_det(seed)?;
                match m {
                    Some(m) => add_model_noise(&mut out, &self.rec.t_s, m, seed),
                    None => add_noise(&mut out, &self.rec.t_s, self.dt_s, &self.noise, seed),
                }
                Ok(out)
            }
        }
    }

    /// The simulator's member model of this twin with the noise family `noise` and the
    /// effects' draws `draws`: what `--write-scenario` writes and the ensemble runs.
    pub fn member_model(&self, noise: GridNoise, draws: Option<EffectDraws>) -> MemberModel {
        MemberModel {
            record: self.rec.clone(),
            draws,
            noise,
            drift: self.drift.clone(),
        }
    }

    /// The noise family on the record's grid, if any.
    pub fn grid_noise(&self) -> Option<&GridNoise> {
        self.family.as_ref()
    }

    /// The same twin whose members draw their noise from `family`, laid on a regular grid of
    /// `len` cells where record point i falls in cell `cells[i]`.
    pub fn with_family(&self, family: &family::NoiseFamily, cells: &[usize], len: usize) -> Twin {
        let mut t = self.clone();
        t.family = Some(GridNoise {
            family: family.spec(),
            cells: cells.to_vec(),
            len,
            transients: None,
        });
        t
    }

    /// The same twin whose members also draw the record's transient disturbances (with a noise
    /// family only; nothing changes without one).
    pub fn with_transients(&self, found: &transients::Transients) -> Twin {
        let mut t = self.clone();
        if let Some(g) = &mut t.family {
            g.transients = (!found.events.is_empty()).then(|| found.clone());
        }
        t
    }

    /// The same twin whose members also carry the record's drift polynomial (Legendre
    /// coefficients of the record's time on [−1, 1] with their 1σ; empty: none) and the
    /// instrument's settling at the record's start, if any (each member draws its τ and
    /// amplitude).
    pub fn with_drift(&self, coefficients: &[(f64, f64)], settling: Option<&Settling>) -> Twin {
        let mut t = self.clone();
        t.drift = (!coefficients.is_empty() || settling.is_some()).then(|| DriftPolynomial {
            legendre: coefficients
                .iter()
                .map(|&(value, sigma)| Drawn { value, sigma })
                .collect(),
            settling: settling.copied(),
        });
        t
    }

    /// The same twin with the scenario's effects extended (appended) by `effects`.
    ///
    /// An effect that cannot be applied (out of range, an ambient channel the record does not
    /// have) is left out and said so in [`Twin::provenance`].
    pub fn extended(&self, effects: &[ScenarioEffect]) -> Twin {
        let mut t = self.clone();
        let (rec, refused) = self.rec.extended(effects);
        let added: Vec<&str> = rec.scenario.effects[self.rec.scenario.effects.len()..]
            .iter()
            .map(ScenarioEffect::name)
            .collect();
        for (name, why) in &refused {
            t.provenance
                .push(format!("effect {name} not applied: {why}"));
        }
        if !added.is_empty() {
            t.provenance
                .push(format!("effects added: {}", added.join(", ")));
        }
        t.rec = rec;
        t
    }

    /// Instrument noise levels of the ensemble members, record unit.
    pub fn noise_levels(&self) -> &AllanParams {
        &self.noise
    }

    /// The simulated drivers (channels the record lacks) that enter this twin's output (see
    /// [`TwinRecord::weather_drivers`]). Names as in the provenance.
    pub fn weather_drivers(&self) -> Vec<String> {
        self.rec.weather_drivers()
    }

    /// Whether seeded members re-run the station for their own weather (a simulated driver
    /// enters the output). When none does, a member is the deterministic part plus the
    /// instrument noise, and costs nothing more.
    pub fn redraws_weather(&self) -> bool {
        self.rec.redraws_weather()
    }
}
