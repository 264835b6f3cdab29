//! The STM32F405's internal flash as the calibration store's NOR flash (sectors 9, 10, 11):
//! the core's register-level driver ([`accomp::drivers::stm32f4_flash`], RM0090 §3.5/§3.8) on
//! the PAC's FLASH registers. The driver unlocks FLASH_CR only for one erase or program, clears
//! the sticky FLASH_SR error flags before each and names the ones an operation raises (the
//! HAL's `UnlockedFlash` never cleared them: after one error every later write failed).

use accomp::drivers::stm32f4_flash::{FlashRegisters, Stm32f4Flash, FLASH_BYTES};
use accomp::storage::SlotLayout;
use stm32f4xx_hal::pac;

/// The calibration flash of this board.
pub type Flash = Stm32f4Flash<PacFlash>;

/// Sectors 9 (0x080A_0000), 10 and 11; memory.x keeps the program below them.
pub const SLOT_LAYOUT: SlotLayout = SlotLayout::STM32F405_SECTORS_9_11;

/// Base of the main flash memory on the AHB (RM0090 §3.3, Table 5).
const FLASH_BASE: usize = 0x0800_0000;

/// The FLASH peripheral's registers and the flash memory bus.
pub struct PacFlash {
    flash: pac::FLASH,
}

/// Takes the flash controller (locked until an operation).
pub fn new(flash: pac::FLASH) -> Flash {
    Stm32f4Flash::new(PacFlash { flash })
}

impl FlashRegisters for PacFlash {
    fn sr(&mut self) -> u32 {
        self.flash.sr().read().bits()
    }
    fn clear_sr(&mut self, bits: u32) {
        // rc_w1 flags: writing 1 clears, 0 leaves; BSY is read-only.
        self.flash.sr().write(|w| unsafe { w.bits(bits) });
    }
    fn cr(&mut self) -> u32 {
        self.flash.cr().read().bits()
    }
    fn set_cr(&mut self, value: u32) {
        self.flash.cr().write(|w| unsafe { w.bits(value) });
    }
    fn key(&mut self, key: u32) {
        self.flash.keyr().write(|w| unsafe { w.bits(key) });
    }
    fn write_byte(&mut self, offset: u32, byte: u8) {
        // The driver checked `offset` against FLASH_BYTES (embedded-storage check_write).
        let at = FLASH_BASE + offset as usize;
        // SAFETY: inside the 1 MiB main memory; with PG set the controller turns this byte
        // access into a program operation (RM0090 §3.5.4), it is never a plain RAM store.
        unsafe { core::ptr::write_volatile(at as *mut u8, byte) };
    }
    fn acr(&mut self) -> u32 {
        self.flash.acr().read().bits()
    }
    fn set_acr(&mut self, value: u32) {
        // SAFETY: the driver writes back what it read with only the cache bits changed (the
        // latency and prefetch fields stay as clock setup left them).
        self.flash.acr().write(|w| unsafe { w.bits(value) });
    }
    fn read(&mut self, offset: u32, bytes: &mut [u8]) {
        let start = offset as usize;
        if start + bytes.len() > FLASH_BYTES {
            return; // unreachable: the driver checks bounds first
        }
        for (k, b) in bytes.iter_mut().enumerate() {
            // SAFETY: inside the main memory (checked above); flash reads have no side effects.
            *b = unsafe { core::ptr::read_volatile((FLASH_BASE + start + k) as *const u8) };
        }
    }
}
