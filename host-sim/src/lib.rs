//! Host-side library behind the `accomp` CLI: fitting, simulation, analysis, firmware client.

pub mod device;
