//! A NOR flash that passes every operation on to another one and lets a [`Watcher`] act around
//! each erase and program: the QEMU board writes its RAM flash through to a host file, the
//! virtual board mirrors its image to a file and stalls on erases, the service's tests count
//! erases and fail programs — each says only what it adds, the pass-through is written once.

use embedded_storage::nor_flash::{ErrorType, NorFlash, ReadNorFlash};

/// What acts around the erases and programs a [`Watched`] flash passes on. Every method does
/// nothing by default.
pub trait Watcher<F: ErrorType> {
    /// Before `from..to` is erased; an error refuses the erase (nothing changes).
    fn before_erase(&mut self, _from: u32, _to: u32) -> Result<(), F::Error> {
        Ok(())
    }

    /// Before `bytes` are programmed at `offset`; an error refuses the program.
    fn before_write(&mut self, _offset: u32, _bytes: &[u8]) -> Result<(), F::Error> {
        Ok(())
    }

    /// After `from..to` was erased or programmed, with the flash as it now is.
    fn changed(&mut self, _flash: &F, _from: u32, _to: u32) {}
}

/// `flash`, with `watcher` acting around each erase and program.
pub struct Watched<F, W> {
    /// Where the operations go.
    pub flash: F,
    /// What acts around them.
    pub watcher: W,
}

impl<F: ErrorType, W> ErrorType for Watched<F, W> {
    type Error = F::Error;
}

impl<F: ReadNorFlash, W> ReadNorFlash for Watched<F, W> {
    const READ_SIZE: usize = F::READ_SIZE;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        self.flash.read(offset, bytes)
    }

    fn capacity(&self) -> usize {
        self.flash.capacity()
    }
}

impl<F: NorFlash, W: Watcher<F>> NorFlash for Watched<F, W> {
    const WRITE_SIZE: usize = F::WRITE_SIZE;
    const ERASE_SIZE: usize = F::ERASE_SIZE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        self.watcher.before_erase(from, to)?;
        self.flash.erase(from, to)?;
        self.watcher.changed(&self.flash, from, to);
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        self.watcher.before_write(offset, bytes)?;
        self.flash.write(offset, bytes)?;
        let to = offset.saturating_add(bytes.len() as u32);
        self.watcher.changed(&self.flash, offset, to);
        Ok(())
    }
}
