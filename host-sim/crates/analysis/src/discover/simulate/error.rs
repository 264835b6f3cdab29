//! Why `--simulate` stopped: each failure named.

use crate::discover::baseline::BaselineError;

/// A failed comparison with the twin.
#[derive(Debug, thiserror::Error)]
pub enum SimulateError {
    /// `--ensemble` outside [`super::ENSEMBLE_RANGE`].
    #[error("ensemble of {members} members: {}..={} are taken", super::ENSEMBLE_RANGE.start(), super::ENSEMBLE_RANGE.end())]
    EnsembleSize {
        /// Members asked for.
        members: usize,
    },
    /// The twin refused to be built or to run.
    #[error("{0}")]
    Twin(#[source] Box<dyn std::error::Error + Send + Sync>),
    /// The twin's output does not have one value per record point.
    #[error("the twin returned {got} values for a record of {points} points")]
    Length {
        /// Values returned.
        got: usize,
        /// Points in the record.
        points: usize,
    },
    /// The twin's prediction is NaN or infinite somewhere.
    #[error("the twin's prediction is not finite at point {index} (t = {t_s} s)")]
    NotFinite {
        /// Point index.
        index: usize,
        /// Its time, s.
        t_s: f64,
    },
    /// The catalogue search on the measured − twin residual failed.
    #[error(transparent)]
    Discover(#[from] BaselineError),
    /// A worker thread of the ensemble ended without its member.
    #[error("ensemble member {0} did not finish")]
    MemberLost(usize),
}

impl SimulateError {
    /// Wraps a twin's own error.
    pub fn twin<E: std::error::Error + Send + Sync + 'static>(e: E) -> Self {
        SimulateError::Twin(Box::new(e))
    }
}
