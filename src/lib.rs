//! accomp core: the maths and types shared by the STM32F405 firmware and the host tools.
//!
//! `no_std`, no allocation, no I/O. Everything here is compiled for the MCU and unit-tested on
//! the host with plain `cargo test`, so the lab PC runs exactly the code the board runs.
#![cfg_attr(not(test), no_std)]
#![deny(missing_docs)]
// One exception, allowed where it is: the VSQRT instruction in `fixed::sqrt_f32`.
#![deny(unsafe_code)]

pub mod acquisition;
pub mod adc;
pub mod compensation;
pub mod drivers;
mod fixed;
pub mod frontend;
pub mod model;
pub mod pipeline;
pub mod poly;
pub mod prepared;
pub mod protocol;
pub mod reference;
pub mod rtd;
pub mod service;
pub mod storage;
pub mod table;
pub mod tide;
pub mod timebase;
pub mod units;
