//! Host-side library behind the `accomp` CLI: fitting, simulation, analysis, firmware client.

pub mod allan;
pub mod discover;
pub mod fit;
pub mod log;
pub mod sim;
pub mod stability;
pub mod table_cli;
