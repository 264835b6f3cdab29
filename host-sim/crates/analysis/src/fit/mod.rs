//! `accomp fit`: temperature models of the calibration coefficients (the paper's equation (2)),
//! fitted at every order 0–4 in the conditioned variable x = (T − Tc)/Ts ∈ [−1, 1], compared by
//! residual standard deviation, AICc, leave-one-out RMS and the F test, set beside the paper's
//! printed models, and turned into a calibration table. Method and findings: docs/fitting.md.
//!
//! Files: `table.rs` reads the coefficient-vs-temperature table and the printed models;
//! `orders.rs` fits every order (QR least squares), compares them and picks one; `calibration.rs`
//! turns the chosen models into a calibration table; `text.rs` the human report; `tests.rs`. The
//! command's arguments and file handling: `accomp_host::cli::fit`.

mod calibration;
mod orders;
mod table;
#[cfg(test)]
mod tests;

pub use calibration::*;
pub use orders::*;
pub use table::*;
pub use text::render_text;

mod text;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use accomp::compensation::{CoefficientModels, ThermalCompensator};
use accomp::poly::{TempPoly, TemperatureScale, MAX_ORDER};
use accomp::rtd;
use accomp::table::{CalibrationDate, CalibrationTable, TableError};
use accomp::units::{Celsius, RAD_PER_ARCMIN};
use serde::Serialize;
use thiserror::Error;

use crate::log::reader::{ReadError, Records};

use crate::numerics::distributions::{f_upper_tail, SpecialError};
use crate::numerics::linalg::{least_squares, LinalgError};

/// Why a fit or a report fails.
#[derive(Debug, Error)]
pub enum FitError {
    /// Reading a file failed.
    #[error("cannot read {path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        error: std::io::Error,
    },
    /// The coefficient table is malformed.
    #[error("{path}: {error}")]
    Csv {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        error: CsvError,
    },
    /// The least-squares problem is degenerate.
    #[error("column `{column}`, order {order}: {error}")]
    Linalg {
        /// Column.
        column: String,
        /// Polynomial order.
        order: usize,
        /// Why.
        error: LinalgError,
    },
    /// A p value could not be computed.
    #[error("column `{column}`, order {order}: {error}")]
    Special {
        /// Column.
        column: String,
        /// Polynomial order.
        order: usize,
        /// Why.
        error: SpecialError,
    },
    /// No order has a defined AICc (too few rows).
    #[error("column `{0}`: no model order has a defined AICc")]
    NoSelectableOrder(String),
    /// `--at` is NaN or infinite.
    #[error("--at must be a finite temperature")]
    BadAt,
}
