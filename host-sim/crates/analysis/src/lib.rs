//! The analyses of a log: Allan deviation (`allan`), stability (`stability`), Table 1's fit
//! (`fit`), the tumble calibration (`tumble`, `tumble_sim`), the discovery of hidden effects
//! (`discover`), the simulated twin of a measured record (`twin`) and the figures (`plot`).

// The crates below, under the module names the analyses use (`crate::numerics::linalg`, ...).
use accomp_log as log;
use accomp_numerics as numerics;
use accomp_sim as sim;

pub mod allan;
pub mod discover;
pub mod fit;
pub mod plot;
pub mod stability;
mod text_table;
pub mod tumble;
pub mod tumble_sim;
pub mod twin;

#[cfg(test)]
mod recovery_tests;
