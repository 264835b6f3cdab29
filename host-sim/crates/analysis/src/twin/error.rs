//! Why a twin cannot be built or run: each refusal named, with what the user can change.

use crate::sim::time::UtcParseError;
use crate::sim::SimError;

/// A twin refused or failed.
#[derive(Debug, thiserror::Error)]
pub enum TwinError {
    /// Fewer than two points: no spacing, no span.
    #[error("the record has {points} point(s): a twin needs at least two")]
    TooShort {
        /// Points in the record.
        points: usize,
    },
    /// The preset a derived twin starts from is not in the simulator.
    #[error("the base preset {0:?} is missing from the simulator")]
    PresetMissing(&'static str),
    /// A gravity record whose unit the gravimeter model does not know.
    #[error("gravity record in an unknown unit {unit:?} (known: {known})")]
    UnknownGravityUnit {
        /// The record's (or scenario's) unit.
        unit: String,
        /// The units the gravimeter model takes.
        known: String,
    },
    /// A gravimeter scenario cannot predict an output in volts.
    #[error("a gravimeter cannot predict a record in volts")]
    GravimeterInVolts,
    /// The scenario's start time does not parse.
    #[error("the scenario's start time: {0}")]
    Start(#[from] UtcParseError),
    /// The simulator refused the scenario or failed while running it.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// The simulator's member model failed.
    #[error(transparent)]
    Run(#[from] crate::sim::twin::TwinRunError),
    /// An effect the scenario holds cannot be built into the chain.
    #[error(transparent)]
    Effect(#[from] crate::sim::effects::EffectError),
}
