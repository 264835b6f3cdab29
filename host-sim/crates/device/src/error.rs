//! The error type of the device side's entry points ([`crate::Connection`],
//! [`crate::compensate`], [`crate::record`]): each variant names the port, file or image it is
//! about, as the CLI prints it.

use std::path::PathBuf;

use accomp_log::calibration_file::TableFileError;
use accomp_log::outputs::OutputError;
use accomp_log::reader::ReadError;

use crate::qemu::{QemuError, StateError};
use crate::record::file::RecordFileError;
use crate::samples_csv::CsvError;
use crate::ClientError;

/// Why talking to a device, compensating through it or recording from it failed.
#[derive(Debug, thiserror::Error)]
pub enum DeviceError {
    /// `--target host` where a device is needed.
    #[error("the host target has no device to connect to")]
    HostTarget,
    /// QEMU could not boot the firmware.
    #[error(transparent)]
    Qemu(#[from] QemuError),
    /// The QEMU board's persistent state could not be taken or saved.
    #[error(transparent)]
    State(#[from] StateError),
    /// The serial port could not be opened (the message names the port).
    #[error(transparent)]
    Serial(std::io::Error),
    /// The protocol client failed.
    #[error(transparent)]
    Client(#[from] ClientError),
    /// The protocol client failed on the first connection to `port`.
    #[error("{port}: {cause}")]
    Port {
        /// The serial port.
        port: String,
        /// What the client said.
        cause: ClientError,
    },
    /// QEMU stopped before the board's image was saved.
    #[error("the board's QEMU was stopped before its image was saved: {} left as it was", image.display())]
    QemuStopped {
        /// The persistent image, unchanged.
        image: PathBuf,
    },
    /// QEMU left no readable flash image.
    #[error("the board left no readable flash image ({cause}): {} left as it was", image.display())]
    NoImage {
        /// The persistent image, unchanged.
        image: PathBuf,
        /// Why the image could not be read.
        cause: std::io::Error,
    },
    /// The image persisted does not scan as a flash image.
    #[error("{}: the persisted image does not scan as a flash image", image.display())]
    NotAnImage {
        /// The persistent image.
        image: PathBuf,
    },
    /// The calibration table does not decode on the host.
    #[error("calibration refused locally: {0:?}")]
    TableRefused(accomp::table::TableError),
    /// The calibration file could not be read.
    #[error(transparent)]
    TableFile(#[from] TableFileError),
    /// The samples file could not be read.
    #[error("reading {}", path.display())]
    Read {
        /// The samples file.
        path: PathBuf,
        /// Cause.
        #[source]
        source: ReadError,
    },
    /// The samples file is malformed (the error names the line).
    #[error(transparent)]
    Csv(#[from] CsvError),
    /// A samples file is malformed: the file, and the line the error names.
    // `error`, not `source`: the message holds it already, no "Caused by" repeating it.
    #[error("{}: {error}", path.display())]
    Samples {
        /// The samples file.
        path: PathBuf,
        /// What is wrong, with its line.
        error: CsvError,
    },
    /// An output file could not be created or written.
    #[error(transparent)]
    Output(#[from] OutputError),
    /// Creating an output file failed.
    #[error("creating {}", path.display())]
    Create {
        /// The output file.
        path: PathBuf,
        /// Cause.
        #[source]
        source: std::io::Error,
    },
    /// Writing an output file failed.
    #[error("writing {}", path.display())]
    Write {
        /// The output file.
        path: PathBuf,
        /// Cause.
        #[source]
        source: std::io::Error,
    },
    /// The record file failed.
    #[error(transparent)]
    RecordFile(#[from] RecordFileError),
    /// `--daily --append` on a directory with no daily file.
    #[error("no daily file to append to")]
    NoDailyFile,
    /// `--append` on an output that holds no record.
    #[error("--append: {} holds no record to continue", output.display())]
    NothingToAppend {
        /// The output asked for.
        output: PathBuf,
    },
}
