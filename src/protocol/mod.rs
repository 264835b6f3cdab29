//! The UART protocol between the lab PC and the board, in three files (docs/protocol.md has
//! the table of messages and codes):
//!
//! - [`messages`]: the requests and replies and what each carries — the protocol as one table;
//! - [`codes`]: every error reachable from the UART, with its number on the wire;
//! - [`framing`]: how a message becomes bytes (postcard, CRC-16, COBS, 0x00 delimiters);
//! - [`model`]: what a user expects the device to answer, the one reference model the tests,
//!   the fuzz targets and the host client's tests check the device against.

pub mod codes;
pub mod framing;
pub mod messages;
pub mod model;

pub use codes::*;
pub use framing::*;
pub use messages::*;
