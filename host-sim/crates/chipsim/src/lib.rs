//! The front-end board's chips on the host, at register level, written from their datasheets:
//! the TI ADS1262 ([`ads1262`]), the ADI AD7124-4 ([`ad7124`]) and the SPI buses they sit on
//! ([`bus`]: a virtual clock, a delay that advances it and an `embedded_hal` `SpiDevice` that
//! lets a chip refuse a transaction in the wrong mode or too fast).
//!
//! The real drivers and the real acquisition code of the `accomp` core run against these
//! models on one [`Board`] ([`board`]: the firmware's interrupts and tasks in time order): in
//! this crate's integration test (`tests/board_sim.rs`) and in the virtual board.

pub mod ad7124;
pub mod ads1262;
pub mod board;
pub mod bus;
pub mod flash;
pub mod usart;

pub use ad7124::Ad7124Model;
pub use ads1262::Ads1262Model;
pub use board::{Acquired, Board, Inputs};
pub use bus::{BusRefusal, Chip, Clock, Port, SimDelay, SimSpi};
pub use flash::{timed, FlashClock, FlashTiming, TimedFlash};
pub use usart::UsartRx;
