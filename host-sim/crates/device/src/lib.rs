//! Talking to the firmware: transports (serial port, QEMU's TCP serial), the QEMU launcher, a
//! request/response client with a pipelined sample stream, and `compensate` end to end.

pub mod client;
pub mod compensate;
pub mod qemu;
pub mod samples_csv;
pub mod transport;

pub use client::{Client, ClientError};
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

impl std::str::FromStr for Target {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "host" => Ok(Target::Host),
            "qemu" => Ok(Target::Qemu),
            _ => match s.strip_prefix("serial:") {
                Some(port) if !port.is_empty() => Ok(Target::Serial(port.to_string())),
                _ => Err(format!(
                    "unknown target `{s}`: use host, qemu or serial:<port>"
                )),
            },
        }
    }
}

/// A connection to a device, keeping QEMU alive as long as the client is used.
pub struct Connection {
    /// The protocol client.
    pub client: Client,
    /// The QEMU instance behind the client, if any (shut down on drop).
    pub qemu: Option<Qemu>,
}

impl Connection {
    /// Opens `target` (not `Host`): boots QEMU with `firmware` or opens the serial port, and
    /// waits for the device to answer.
    pub fn open(target: &Target, firmware: Option<&Path>) -> anyhow::Result<Connection> {
        match target {
            Target::Host => anyhow::bail!("the host target has no device to connect to"),
            Target::Qemu => {
                let elf = firmware_path(firmware);
                // The CLI's board keeps its flash across commands, like a real board.
                let opts = qemu::QemuOptions {
                    state_dir: Some(qemu::board_state_dir()),
                    ..qemu::QemuOptions::default()
                };
                let (qemu, client) = Qemu::launch(&elf, &opts)?;
                Ok(Connection {
                    client,
                    qemu: Some(qemu),
                })
            }
            Target::Serial(port) => {
                let t = transport::SerialTransport::open(port, 115_200)?;
                let mut client = Client::new(Box::new(t));
                // A board that is already running sent READY long ago: ask instead.
                client.ping()?;
                Ok(Connection { client, qemu: None })
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
