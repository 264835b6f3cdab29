//! The one error type of `discover`'s library entry points ([`super::discover_path`], the
//! report writers, `simulate`'s entry points): each variant names the file, option or stage it
//! is about, as the CLI prints it.

use std::path::PathBuf;

/// Why a discovery entry point failed.
#[derive(Debug, thiserror::Error)]
pub enum DiscoverError {
    /// The record could not be loaded or turned into a dataset.
    #[error(transparent)]
    Import(#[from] super::import::ImportError),
    /// The baseline could not be built.
    #[error(transparent)]
    Baseline(#[from] super::baseline::BaselineError),
    /// A report directory could not be created.
    #[error("cannot create directory {}: {source}", dir.display())]
    CreateDir {
        /// The directory.
        dir: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// An output file could not be written (the error names the file).
    #[error(transparent)]
    Output(#[from] crate::log::outputs::OutputError),
    /// `--scenario <file>` could not be loaded.
    #[error("--scenario {}: {source}", path.display())]
    Scenario {
        /// The scenario file or preset given.
        path: PathBuf,
        /// Cause.
        source: crate::sim::scenario::ScenarioError,
    },
    /// The simulation in the loop failed (the error names the stage).
    #[error(transparent)]
    Simulate(#[from] super::simulate::SimulateError),
    /// `--write-scenario <file>` on a twin that has no scenario to write.
    #[error("--write-scenario {}: this twin has no scenario to write ({why})", path.display())]
    NoScenario {
        /// The file asked for.
        path: PathBuf,
        /// The twin's warnings, joined.
        why: String,
    },
}
