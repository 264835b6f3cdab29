//! The error codes: every failure reachable from the UART, its number on the wire and the
//! meaning of its detail.

use serde::{Deserialize, Serialize};

use embedded_storage::nor_flash::{NorFlashError, NorFlashErrorKind};

use crate::table::{Coefficient, Field, TableError};

/// A failure: a stable numeric code plus one number of detail (documented per code).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ErrorReply {
    /// [`ErrorCode`] as a number.
    pub code: u16,
    /// Code-specific detail (expected offset, computed CRC, field, …), 0 when none.
    pub detail: u32,
}

/// Every failure reachable from the UART, with its number on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u16)]
pub enum ErrorCode {
    /// The frame decoded (CRC good) but is not a known request. Detail: 0.
    Malformed = 1,
    /// Frame CRC mismatch (counted; not answered since the id is untrusted). Detail: computed CRC.
    FrameCrc = 2,
    /// Frame longer than the receive buffer (counted; not answered). Detail: buffer size.
    FrameTooLong = 3,
    /// COBS structure broken (counted; not answered). Detail: 0.
    FrameCobs = 4,
    /// Chunk or commit without an UploadBegin. Detail: 0.
    NoUpload = 10,
    /// Chunk offset is not the next expected one. Detail: expected offset.
    ChunkOutOfOrder = 11,
    /// Upload longer than a table can be. Detail: maximum length.
    UploadTooLong = 12,
    /// Commit before all announced bytes arrived. Detail: bytes received.
    UploadIncomplete = 13,
    /// Bytes received do not match UploadBegin's CRC-32. Detail: computed CRC.
    UploadCrcMismatch = 14,
    /// Chunk or commit of an upload other than the one in progress (a later UploadBegin
    /// replaced it). Detail: the id of the upload in progress.
    UploadIdMismatch = 15,
    /// Table: wrong magic. Detail: 0.
    TableBadMagic = 20,
    /// Table: unsupported format version. Detail: version found.
    TableUnsupportedVersion = 21,
    /// Table: wrong length. Detail: length found.
    TableBadLength = 22,
    /// Table: stored CRC wrong. Detail: computed CRC.
    TableBadCrc = 23,
    /// Table: NaN or infinite number. Detail: field code (see docs/protocol.md).
    TableNonFinite = 24,
    /// Table: polynomial order above 4. Detail: coefficient code.
    TableOrderTooHigh = 25,
    /// Table: empty or inverted temperature range. Detail: 0.
    TableEmptyRange = 26,
    /// Table: T0 outside the calibrated range. Detail: 0.
    TableReferenceOutsideRange = 27,
    /// Table: K1 implausible. Detail: 0.
    TableScaleFactorImplausible = 28,
    /// Table: RTD constants out of range. Detail: 0.
    TableRtdConstants = 29,
    /// Table: ADC constants out of range. Detail: 0.
    TableAdcConstants = 30,
    /// Table: serial not UTF-8. Detail: 0.
    TableSerial = 31,
    /// Table: date invalid. Detail: 0.
    TableDate = 32,
    /// Table: tilt axis code invalid. Detail: 0.
    TableTiltAxis = 33,
    /// Table: reserved header field not zero. Detail: its value.
    TableReserved = 34,
    /// Table: a finite value outside its physical bounds. Detail: field code.
    TableOutOfBounds = 35,
    /// ReadTable with no active table. Detail: 0.
    NoTable = 40,
    /// ReadTable offset beyond the table. Detail: table length.
    OffsetOutOfRange = 41,
    /// Rollback with no previous table. Detail: 0.
    NoPreviousTable = 42,
    /// Activate with an id that is neither active nor previous. Detail: 0.
    TableNotFound = 43,
    /// The device could not queue the answer or the sample. Detail: 0.
    Busy = 50,
    /// The request does not exist on this board (InjectSample on the front-end). Detail: 0.
    NotSupported = 51,
    /// SetRate with a rate not in [`SET_RATES_SPS`]. Detail: MAX_RATE_HZ.
    InvalidRate = 52,
    /// Bench count outside 1..=MAX_BENCH_COUNT. Detail: MAX_BENCH_COUNT.
    InvalidCount = 53,
    /// The flash driver failed to erase, program or read. Detail: 0 not aligned, 1 out of
    /// bounds, 2 other (embedded-storage `NorFlashErrorKind`). The active table is unchanged.
    FlashFailed = 60,
    /// What was read back from the slot differs from what was written; the slot was left
    /// uncommitted and the active table is unchanged. Detail: slot (0 = A, 1 = B).
    FlashVerify = 61,
    /// The calibration store could not be opened at boot (slot layout does not fit the flash),
    /// so nothing can be committed. Detail: 0.
    StorageUnavailable = 62,
    /// STM32 flash controller PGSERR (programming sequence error, RM0090 §3.8.4). Detail: 0.
    /// Like every flash error: the active table is unchanged, the flag is cleared, the next
    /// operation runs normally.
    FlashProgramSequence = 63,
    /// STM32 flash controller PGPERR (programming parallelism error). Detail: 0.
    FlashProgramParallelism = 64,
    /// STM32 flash controller PGAERR (programming alignment error). Detail: 0.
    FlashProgramAlignment = 65,
    /// STM32 flash controller WRPERR: the calibration sector is write-protected (option bytes
    /// nWRP). Detail: 0.
    FlashWriteProtected = 66,
    /// STM32 flash controller OPERR (operation error). Detail: 0.
    FlashOperation = 67,
    /// FLASH_CR stayed locked after the unlock keys (a wrong key sequence locks it until
    /// reset, RM0090 §3.5.1). Detail: 0.
    FlashLocked = 68,
}

impl ErrorCode {
    /// Every code, for documentation and exhaustive tests.
    pub const ALL: [ErrorCode; 43] = [
        ErrorCode::Malformed,
        ErrorCode::FrameCrc,
        ErrorCode::FrameTooLong,
        ErrorCode::FrameCobs,
        ErrorCode::NoUpload,
        ErrorCode::ChunkOutOfOrder,
        ErrorCode::UploadTooLong,
        ErrorCode::UploadIncomplete,
        ErrorCode::UploadCrcMismatch,
        ErrorCode::UploadIdMismatch,
        ErrorCode::TableBadMagic,
        ErrorCode::TableUnsupportedVersion,
        ErrorCode::TableBadLength,
        ErrorCode::TableBadCrc,
        ErrorCode::TableNonFinite,
        ErrorCode::TableOrderTooHigh,
        ErrorCode::TableEmptyRange,
        ErrorCode::TableReferenceOutsideRange,
        ErrorCode::TableScaleFactorImplausible,
        ErrorCode::TableRtdConstants,
        ErrorCode::TableAdcConstants,
        ErrorCode::TableSerial,
        ErrorCode::TableDate,
        ErrorCode::TableTiltAxis,
        ErrorCode::TableReserved,
        ErrorCode::TableOutOfBounds,
        ErrorCode::NoTable,
        ErrorCode::OffsetOutOfRange,
        ErrorCode::NoPreviousTable,
        ErrorCode::TableNotFound,
        ErrorCode::Busy,
        ErrorCode::NotSupported,
        ErrorCode::InvalidRate,
        ErrorCode::InvalidCount,
        ErrorCode::FlashFailed,
        ErrorCode::FlashVerify,
        ErrorCode::StorageUnavailable,
        ErrorCode::FlashProgramSequence,
        ErrorCode::FlashProgramParallelism,
        ErrorCode::FlashProgramAlignment,
        ErrorCode::FlashWriteProtected,
        ErrorCode::FlashOperation,
        ErrorCode::FlashLocked,
    ];

    /// The code for a number from the wire.
    pub fn from_u16(n: u16) -> Option<ErrorCode> {
        ErrorCode::ALL.iter().copied().find(|c| *c as u16 == n)
    }

    /// A reply with this code and detail.
    pub const fn reply(self, detail: u32) -> ErrorReply {
        ErrorReply {
            code: self as u16,
            detail,
        }
    }
}

const fn coefficient_code(c: Coefficient) -> u32 {
    match c {
        Coefficient::Bias => 0,
        Coefficient::ScaleFactor => 1,
        Coefficient::Nonlinearity => 2,
        Coefficient::MisalignmentP => 3,
        Coefficient::MisalignmentO => 4,
    }
}

/// Field codes of TableNonFinite's detail.
pub const fn field_code(f: Field) -> u32 {
    match f {
        Field::TemperatureScale => 0,
        Field::ReferenceTemperature => 1,
        Field::Polynomial(c) => 10 + coefficient_code(c),
        Field::Tilt => 2,
        Field::Rtd => 3,
        Field::Adc => 4,
        Field::Orientation => 5,
        Field::Serial => 6,
        Field::Date => 7,
    }
}

impl From<TableError> for ErrorReply {
    fn from(e: TableError) -> Self {
        use ErrorCode as C;
        match e {
            TableError::BadMagic => C::TableBadMagic.reply(0),
            TableError::UnsupportedVersion(v) => C::TableUnsupportedVersion.reply(u32::from(v)),
            TableError::BadLength { found, .. } => C::TableBadLength.reply(found),
            TableError::BadCrc { computed, .. } => C::TableBadCrc.reply(computed),
            TableError::NonFinite(f) => C::TableNonFinite.reply(field_code(f)),
            TableError::OrderTooHigh(c) => C::TableOrderTooHigh.reply(coefficient_code(c)),
            TableError::EmptyRange => C::TableEmptyRange.reply(0),
            TableError::ReferenceOutsideRange => C::TableReferenceOutsideRange.reply(0),
            TableError::ScaleFactorImplausible => C::TableScaleFactorImplausible.reply(0),
            TableError::RtdConstants => C::TableRtdConstants.reply(0),
            TableError::AdcConstants => C::TableAdcConstants.reply(0),
            TableError::Serial => C::TableSerial.reply(0),
            TableError::Date => C::TableDate.reply(0),
            TableError::TiltAxis => C::TableTiltAxis.reply(0),
            TableError::Reserved(v) => C::TableReserved.reply(u32::from(v)),
            TableError::OutOfBounds(f) => C::TableOutOfBounds.reply(field_code(f)),
        }
    }
}

/// A flash driver's error as the protocol reports it. The default is FlashFailed with the
/// embedded-storage kind as detail (0 not aligned, 1 out of bounds, 2 other); a driver that can
/// say more (the STM32 flash controller's FLASH_SR flags, codes 63–68) overrides it.
pub trait FlashErrorReply: NorFlashError {
    /// The reply for this error.
    fn reply(&self) -> ErrorReply {
        ErrorCode::FlashFailed.reply(match self.kind() {
            NorFlashErrorKind::NotAligned => 0,
            NorFlashErrorKind::OutOfBounds => 1,
            _ => 2,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_errors_map_to_distinct_documented_codes() {
        let mut seen = std::collections::BTreeSet::new();
        for c in ErrorCode::ALL {
            assert!(seen.insert(c as u16), "duplicate {c:?}");
            assert_eq!(ErrorCode::from_u16(c as u16), Some(c));
        }
        assert_eq!(ErrorCode::from_u16(999), None);
        let e: ErrorReply = TableError::UnsupportedVersion(2).into();
        assert_eq!((e.code, e.detail), (21, 2));
        let e: ErrorReply = TableError::NonFinite(Field::Polynomial(Coefficient::Bias)).into();
        assert_eq!((e.code, e.detail), (24, 10));
    }
}
