//! A NOR flash in RAM for the QEMU board, whose flash model is not worth trusting, and for
//! tests. It enforces what real NOR flash does, so code that works on it does not rely on
//! anything the STM32F405's flash would not do: erase sets whole ERASE_SIZE blocks to 0xFF,
//! programming can only clear bits, and every offset and length is checked for alignment.

use embedded_storage::nor_flash::{
    check_erase, check_read, check_write, ErrorType, NorFlash, NorFlashError, NorFlashErrorKind,
    ReadNorFlash,
};

/// Why a [`RamFlash`] operation was refused. Nothing is changed by a refused operation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RamFlashError {
    /// Offset or length not a multiple of READ_SIZE, WRITE_SIZE or ERASE_SIZE.
    NotAligned,
    /// Range outside the flash.
    OutOfBounds,
    /// Programming would have to turn a 0 bit into 1, which NOR flash cannot do without an
    /// erase. Refused rather than silently ANDed, so a missing erase shows up in tests.
    WouldSetBits {
        /// Offset of the first byte that would need an erase.
        offset: u32,
    },
}

impl NorFlashError for RamFlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            RamFlashError::NotAligned => NorFlashErrorKind::NotAligned,
            RamFlashError::OutOfBounds => NorFlashErrorKind::OutOfBounds,
            RamFlashError::WouldSetBits { .. } => NorFlashErrorKind::Other,
        }
    }
}

impl From<NorFlashErrorKind> for RamFlashError {
    fn from(kind: NorFlashErrorKind) -> Self {
        match kind {
            NorFlashErrorKind::NotAligned => RamFlashError::NotAligned,
            _ => RamFlashError::OutOfBounds,
        }
    }
}

/// `N` bytes of RAM behaving as NOR flash with erase blocks of `ERASE` bytes and a program unit
/// of `WRITE` bytes (reads are byte-granular). Starts erased, like a factory-new part.
#[derive(Clone)]
pub struct RamFlash<const N: usize, const ERASE: usize = 1024, const WRITE: usize = 4> {
    bytes: [u8; N],
}

impl<const N: usize, const ERASE: usize, const WRITE: usize> RamFlash<N, ERASE, WRITE> {
    /// Erased flash (all 0xFF).
    pub const fn new() -> Self {
        const {
            assert!(
                ERASE > 0 && WRITE > 0,
                "erase and write sizes must be non-zero"
            );
            assert!(
                N.is_multiple_of(ERASE),
                "capacity must be whole erase blocks"
            );
            assert!(
                ERASE.is_multiple_of(WRITE),
                "erase blocks must be whole write units"
            );
        }
        RamFlash { bytes: [0xFF; N] }
    }

    /// Flash holding `bytes` (e.g. a snapshot taken with [`Self::as_bytes`]).
    pub const fn from_bytes(bytes: [u8; N]) -> Self {
        RamFlash { bytes }
    }

    /// The raw contents.
    pub fn as_bytes(&self) -> &[u8; N] {
        &self.bytes
    }

    /// The raw contents, for fault injection (bit flips) in tests.
    pub fn as_bytes_mut(&mut self) -> &mut [u8; N] {
        &mut self.bytes
    }

    /// The `len` cells from `offset`, if they are inside the flash.
    fn cells(&mut self, offset: u32, len: usize) -> Result<&mut [u8], RamFlashError> {
        let start = offset as usize;
        self.bytes
            .get_mut(start..start + len)
            .ok_or(RamFlashError::OutOfBounds)
    }
}

impl<const N: usize, const ERASE: usize, const WRITE: usize> Default for RamFlash<N, ERASE, WRITE> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize, const ERASE: usize, const WRITE: usize> ErrorType
    for RamFlash<N, ERASE, WRITE>
{
    type Error = RamFlashError;
}

impl<const N: usize, const ERASE: usize, const WRITE: usize> ReadNorFlash
    for RamFlash<N, ERASE, WRITE>
{
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        check_read(self, offset, bytes.len())?;
        bytes.copy_from_slice(self.cells(offset, bytes.len())?);
        Ok(())
    }

    fn capacity(&self) -> usize {
        N
    }
}

impl<const N: usize, const ERASE: usize, const WRITE: usize> NorFlash
    for RamFlash<N, ERASE, WRITE>
{
    const WRITE_SIZE: usize = WRITE;
    const ERASE_SIZE: usize = ERASE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        check_erase(self, from, to)?;
        self.bytes
            .get_mut(from as usize..to as usize)
            .ok_or(RamFlashError::OutOfBounds)?
            .fill(0xFF);
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        check_write(self, offset, bytes.len())?;
        let dst = self.cells(offset, bytes.len())?;
        // Check everything first so a refused write changes nothing.
        if let Some(i) = dst.iter().zip(bytes).position(|(old, new)| new & !old != 0) {
            return Err(RamFlashError::WouldSetBits {
                offset: offset + i as u32,
            });
        }
        for (old, new) in dst.iter_mut().zip(bytes) {
            *old &= *new;
        }
        Ok(())
    }
}

/// FlashFailed with the error's kind.
impl crate::protocol::FlashErrorReply for RamFlashError {}

#[cfg(test)]
mod tests {
    use super::*;

    type Flash = RamFlash<64, 16, 4>;

    #[test]
    fn new_flash_reads_erased() {
        let mut f = Flash::new();
        let mut buf = [0u8; 64];
        f.read(0, &mut buf).unwrap();
        assert!(buf.iter().all(|b| *b == 0xFF));
        assert_eq!(f.capacity(), 64);
    }

    #[test]
    fn program_clears_bits_and_erase_sets_the_whole_block() {
        let mut f = Flash::new();
        f.write(16, &[0x0F, 0xF0, 0x00, 0x5A]).unwrap();
        f.write(28, &[0x00; 4]).unwrap();
        // Clearing further bits of a programmed word is allowed (NOR semantics).
        f.write(16, &[0x0E, 0x70, 0x00, 0x50]).unwrap();
        assert_eq!(&f.as_bytes()[16..20], &[0x0E, 0x70, 0x00, 0x50]);
        f.erase(16, 32).unwrap();
        assert!(f.as_bytes()[16..32].iter().all(|b| *b == 0xFF));
    }

    #[test]
    fn erase_leaves_other_blocks_alone() {
        let mut f = Flash::new();
        f.write(0, &[0; 4]).unwrap();
        f.write(32, &[0; 4]).unwrap();
        f.erase(16, 32).unwrap();
        assert_eq!(&f.as_bytes()[0..4], &[0; 4]);
        assert_eq!(&f.as_bytes()[32..36], &[0; 4]);
    }

    #[test]
    fn program_that_would_set_bits_is_refused_and_changes_nothing() {
        let mut f = Flash::new();
        f.write(8, &[0x00, 0xFF, 0xFF, 0xFF]).unwrap();
        let before = *f.as_bytes();
        assert_eq!(
            f.write(4, &[0x00, 0x00, 0x00, 0x00, 0x01, 0x00, 0x00, 0x00]),
            Err(RamFlashError::WouldSetBits { offset: 8 })
        );
        assert_eq!(f.as_bytes(), &before);
    }

    #[test]
    fn misaligned_or_out_of_range_operations_are_refused() {
        let mut f = Flash::new();
        assert_eq!(f.write(2, &[0; 4]), Err(RamFlashError::NotAligned));
        assert_eq!(f.write(0, &[0; 3]), Err(RamFlashError::NotAligned));
        assert_eq!(f.write(64, &[0; 4]), Err(RamFlashError::OutOfBounds));
        assert_eq!(f.erase(8, 16), Err(RamFlashError::NotAligned));
        assert_eq!(f.erase(0, 80), Err(RamFlashError::OutOfBounds));
        assert_eq!(f.erase(32, 16), Err(RamFlashError::OutOfBounds));
        let mut buf = [0u8; 2];
        assert_eq!(f.read(63, &mut buf), Err(RamFlashError::OutOfBounds));
        assert!(f.as_bytes().iter().all(|b| *b == 0xFF));
    }

    #[test]
    fn error_kinds_map_to_the_embedded_storage_kinds() {
        assert_eq!(
            RamFlashError::NotAligned.kind(),
            NorFlashErrorKind::NotAligned
        );
        assert_eq!(
            RamFlashError::OutOfBounds.kind(),
            NorFlashErrorKind::OutOfBounds
        );
        assert_eq!(
            RamFlashError::WouldSetBits { offset: 0 }.kind(),
            NorFlashErrorKind::Other
        );
    }
}
