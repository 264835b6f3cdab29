//! Host-side library behind the `accomp` CLI: fitting, simulation, analysis, firmware client.

pub mod fit;
pub mod tumble;
pub mod tumble_sim;
