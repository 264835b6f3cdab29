//! Host-side library behind the `accomp` CLI: fitting, simulation, analysis, firmware client.

pub mod allan;
pub mod calibration_file;
pub mod cli;
pub mod demo;
pub mod device;
pub mod discover;
pub mod fit;
pub mod log;
pub mod numerics;
pub mod outputs;
pub mod plot;
pub mod sim;
pub mod stability;
pub mod tumble;
pub mod tumble_sim;
