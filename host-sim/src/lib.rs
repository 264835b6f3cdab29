//! The `accomp` CLI (`cli`) and the demo on top of the host crates. The crates below are
//! re-exported under the module names the commands, the examples and the integration tests use:
//! `accomp_host::discover` is `accomp_analysis::discover`, `accomp_host::sim` is `accomp_sim`.
//!
//! Layers (a crate only uses the ones above it in this list):
//! - `accomp` (the no_std core: maths, types, protocol, tide);
//! - `accomp-numerics` (linear algebra, statistics, minimisation, parallel map);
//! - `accomp-log` (the log format read and written, column units, UTC, the calibration file);
//! - `accomp-sim` (the station simulator, its effects and scenarios);
//! - `accomp-analysis` (Allan, stability, fit, tumble, discovery, the twin, plots);
//! - `accomp-device` (transport, firmware client, QEMU, compensation through the firmware);
//! - `accomp-host` (this crate: the CLI and the demo).

pub mod cli;
pub mod demo;

pub use accomp_analysis::{allan, discover, fit, plot, stability, tumble, tumble_sim, twin};
pub use accomp_device as device;
pub use accomp_log as log;
pub use accomp_log::calibration_file;
pub use accomp_log::outputs;
pub use accomp_numerics as numerics;
pub use accomp_sim as sim;
