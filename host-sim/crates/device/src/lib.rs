//! Talking to the firmware: transports (serial port, QEMU's TCP serial), the QEMU launcher, a
//! request/response client with a pipelined sample stream, and `compensate` end to end.

pub mod board_sim;
pub mod client;
pub mod compensate;
mod error;
pub mod qemu;
pub mod record;
pub mod samples_csv;
pub mod transport;

/// Unit tests' scratch folders, removed on drop (the integration tests' own helper).
#[cfg(test)]
#[path = "../../../tests/common/scratch.rs"]
mod scratch;

pub use client::{Client, ClientError};
pub use error::DeviceError;
pub use qemu::{Qemu, QemuError};
pub use transport::Transport;

use std::path::{Path, PathBuf};

/// Environment variable naming the firmware ELF to boot in QEMU (set by `cargo xtask test`).
pub const FIRMWARE_ENV: &str = "ACCOMP_FIRMWARE_ELF";
/// Where `cargo xtask test|demo|firmware` leaves the QEMU-board firmware, relative to the
/// workspace root.
pub const DEFAULT_FIRMWARE: &str = "target/thumbv7em-none-eabihf/release/accomp-fw";

/// The firmware ELF to boot: `--firmware`, else `$ACCOMP_FIRMWARE_ELF`, else the default path
/// (relative to the current directory, then to this workspace).
pub fn firmware_path(explicit: Option<&Path>) -> PathBuf {
    if let Some(p) = explicit {
        return p.to_path_buf();
    }
    if let Some(p) = std::env::var_os(FIRMWARE_ENV) {
        return PathBuf::from(p);
    }
    let here = PathBuf::from(DEFAULT_FIRMWARE);
    if here.exists() {
        return here;
    }
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../..")
        .join(DEFAULT_FIRMWARE)
}

/// Where to talk to the firmware.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Target {
    /// The same core code on this PC.
    Host,
    /// The firmware ELF booted in QEMU.
    Qemu,
    /// A board on a serial port.
    Serial(String),
}

/// A `--target` that is none of host, qemu, serial:<port>.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown target `{0}`: use host, qemu or serial:<port>")]
pub struct UnknownTarget(pub String);

impl std::str::FromStr for Target {
    type Err = UnknownTarget;
    fn from_str(s: &str) -> Result<Self, UnknownTarget> {
        match s {
            "host" => Ok(Target::Host),
            "qemu" => Ok(Target::Qemu),
            _ => match s.strip_prefix("serial:") {
                Some(port) if !port.is_empty() => Ok(Target::Serial(port.to_string())),
                _ => Err(UnknownTarget(s.to_owned())),
            },
        }
    }
}

/// The (active, previous) calibration table ids of a flash image.
pub type TableIds = (Option<u32>, Option<u32>);

/// A connection to a device, keeping QEMU alive as long as the client is used.
pub struct Connection {
    /// The protocol client.
    pub client: Client,
    /// The QEMU instance behind the client, if any (shut down on drop).
    pub qemu: Option<Qemu>,
    /// The persistent board state QEMU runs on a working copy of (locked while this lives):
    /// [`Connection::close`] persists the image the board left, and so does a drop, best effort.
    board: Option<qemu::BoardState>,
}

impl Connection {
    /// Opens `target` (not `Host`): boots QEMU with `firmware` or opens the serial port, and
    /// waits for the device to answer. The QEMU board's state is taken as
    /// [`qemu::StateOptions::for_process`] says (by default: waits for another command using
    /// it, refuses a damaged image).
    pub fn open(target: &Target, firmware: Option<&Path>) -> Result<Connection, DeviceError> {
        Self::open_with(target, firmware, qemu::StateOptions::for_process())
    }

    /// As [`Connection::open`], with how to take the QEMU board's persistent state.
    pub fn open_with(
        target: &Target,
        firmware: Option<&Path>,
        state: qemu::StateOptions,
    ) -> Result<Connection, DeviceError> {
        match target {
            Target::Host => Err(DeviceError::HostTarget),
            Target::Qemu => {
                let elf = firmware_path(firmware);
                if !elf.is_file() {
                    return Err(QemuError::NoFirmware(elf).into());
                }
                // The CLI's board keeps its flash across commands, like a real board: one
                // command at a time, QEMU on a working copy, persisted when it is done.
                let board = qemu::BoardState::open(&qemu::board_state_dir(), state)?;
                let opts = qemu::QemuOptions {
                    initial_flash: board.image()?,
                    ..qemu::QemuOptions::default()
                };
                let (qemu, client) = Qemu::launch(&elf, &opts)?;
                Ok(Connection {
                    client,
                    qemu: Some(qemu),
                    board: Some(board),
                })
            }
            Target::Serial(port) => {
                let t =
                    transport::SerialTransport::open(port, 115_200).map_err(DeviceError::Serial)?;
                let mut client = Client::new(Box::new(t));
                // A board that is already running sent READY long ago: ask instead.
                client.ping()?;
                Ok(Connection {
                    client,
                    qemu: None,
                    board: None,
                })
            }
        }
    }

    /// Ends the session: for the QEMU board, cuts its power and persists the flash image it
    /// left (synced, renamed, read back), then releases the board. Returns the (active,
    /// previous) table ids of the image now on disk, None for a real board (its flash is its
    /// own).
    pub fn close(mut self) -> Result<Option<TableIds>, DeviceError> {
        self.persist()
    }

    fn persist(&mut self) -> Result<Option<TableIds>, DeviceError> {
        let Some(board) = self.board.take() else {
            if let Some(q) = self.qemu.take() {
                q.shutdown();
            }
            return Ok(None);
        };
        let Some(q) = self.qemu.take() else {
            return Err(DeviceError::QemuStopped {
                image: board.image_path(),
            });
        };
        let (_, image) = q.power_off();
        let image = image.map_err(|cause| DeviceError::NoImage {
            image: board.image_path(),
            cause,
        })?;
        let back = board.persist(&image)?;
        let tables = qemu::image_tables(&back).ok_or_else(|| DeviceError::NotAnImage {
            image: board.image_path(),
        })?;
        Ok(Some(tables))
    }

    /// The persistent board state's image path (QEMU target).
    pub fn state_image(&self) -> Option<PathBuf> {
        self.board.as_ref().map(|b| b.image_path())
    }
}

impl Drop for Connection {
    /// A command that ends early still persists what the board did (a real board would keep
    /// it); a failure is said on stderr.
    fn drop(&mut self) {
        if self.board.is_some() {
            if let Err(e) = self.persist() {
                eprintln!("warning: {e:#}");
            }
        }
    }
}

use accomp::model::CrossAxis;
use accomp::table::CalibrationTable;
use accomp::units::{Gs, TiltArcsec};

/// The paper's JN-06 A12124 second-order models over 30–65 °C (Table 2 coefficients).
pub fn paper_table() -> CalibrationTable {
    let mut t = accomp::reference::paper_order2_table();
    // Non-zero tilt reference and cross-axis input so that those paths are exercised.
    t.tilt.reference = TiltArcsec(0.5);
    t.orientation.cross = CrossAxis {
        a_p: Gs(0.0),
        a_o: Gs(0.3),
    };
    t
}
