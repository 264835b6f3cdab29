//! Drivers of the board's chips: the two converters over embedded-hal 1.0 SPI, and the MCU's
//! own flash controller behind embedded-storage.
//!
//! - [`ads1262`]: TI ADS1262 32-bit ΔΣ ADC (accelerometer torquer-current sense and tiltmeter).
//! - [`ad7124`]: ADI AD7124-4 24-bit ΔΣ ADC (4-wire Pt100, ratiometric, as in ADI CN-0381).
//! - [`stm32f4_flash`]: the STM32F405 flash controller (calibration slots), register-level.
//!
//! Both take an [`embedded_hal::spi::SpiDevice`] (so the bus can be shared and chip select is
//! the bus manager's business), an [`embedded_hal::digital::InputPin`] for data-ready and an
//! [`embedded_hal::delay::DelayNs`] for the reset waits. Nothing allocates and nothing panics: every
//! failure comes back as an [`Error`], and every conversion comes back as the core's code
//! newtypes ([`crate::adc::Ads1262Code`], [`crate::adc::Ad7124Code`]) so the maths layer never
//! sees a bare integer.

pub mod ad7124;
pub mod ads1262;
pub mod stm32f4_flash;

/// Chip-boundary test doubles shared by both drivers' tests.
#[cfg(test)]
pub(crate) mod test_support {
    use embedded_hal::spi::{ErrorKind, ErrorType, Operation, SpiDevice};

    /// An SPI device whose every transaction fails (embedded-hal-mock cannot inject bus errors).
    pub(crate) struct BrokenBus;

    impl ErrorType for BrokenBus {
        type Error = ErrorKind;
    }

    impl SpiDevice for BrokenBus {
        fn transaction(&mut self, _: &mut [Operation<'_, u8>]) -> Result<(), ErrorKind> {
            Err(ErrorKind::Other)
        }
    }

    /// Bitwise CRC-8, polynomial x^8 + x^2 + x + 1, initial 0, written from the definition (both
    /// datasheets' CRC), independently of the drivers' table-driven `crc` crate.
    pub(crate) fn crc8_reference(bytes: &[u8]) -> u8 {
        let mut crc = 0u8;
        for &b in bytes {
            for bit in (0..8).rev() {
                let input = (b >> bit) & 1;
                let top = crc >> 7;
                crc <<= 1;
                if top ^ input == 1 {
                    crc ^= 0x07;
                }
            }
        }
        crc
    }

    #[test]
    fn reference_crc_matches_the_catalogue_check_value() {
        // CRC-8/SMBUS (poly 0x07, init 0) check value over "123456789" is 0xF4.
        assert_eq!(crc8_reference(b"123456789"), 0xF4);
    }
}

/// Everything a driver call can fail with.
///
/// `SpiE` is the bus error of the [`embedded_hal::spi::SpiDevice`], `PinE` the error of the
/// data-ready [`embedded_hal::digital::InputPin`]. The other variants say what the chip did wrong,
/// so the firmware can report a precise status flag instead of a number it cannot trust.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Error<SpiE, PinE> {
    /// The SPI transfer itself failed.
    Spi(SpiE),
    /// Reading the data-ready pin failed.
    Pin(PinE),
    /// Data-ready did not assert within the configured number of polls.
    DrdyTimeout,
    /// ADS1262 checksum mode: the received checksum byte differs from the sum of the data
    /// bytes + 0x9B.
    Checksum {
        /// Checksum computed from the received data bytes.
        expected: u8,
        /// Checksum byte the converter sent.
        received: u8,
    },
    /// CRC-8 (x^8 + x^2 + x + 1) over the received bytes differs from the received CRC byte.
    CrcMismatch {
        /// CRC computed from the received bytes.
        expected: u8,
        /// CRC byte the converter sent.
        received: u8,
    },
    /// A configuration value does not fit its register field or contradicts another setting.
    InvalidConfig,
    /// The ID register names another device.
    DeviceId {
        /// The ID register content read.
        found: u8,
    },
    /// The ID register reads as an idle bus (all zeros or all ones): no device answered.
    NotResponding {
        /// The byte read where the ID was expected.
        found: u8,
    },
    /// A register read back after writing holds another value than written.
    ReadBack {
        /// Register address.
        register: u8,
        /// Value written.
        written: u32,
        /// Value read back.
        read: u32,
    },
    /// ADS1262: the status byte says no new conversion since the last read (stale data).
    StaleData,
    /// The converter reports it has been reset since it was configured (brown-out or glitch on
    /// the reset line): its configuration is lost and must be re-initialised.
    UnexpectedReset,
    /// AD7124: the ERROR register reports the listed conditions (see [`ad7124::ErrorFlags`]).
    AdcError(ad7124::ErrorFlags),
}

impl<SpiE, PinE> Error<SpiE, PinE> {
    /// The variant's name, for firmware logs: defmt prints it without pulling in `core::fmt`
    /// (whose Debug machinery would cost the front-end build ~3.5 KiB of flash).
    pub const fn name(&self) -> &'static str {
        match self {
            Error::Spi(_) => "Spi",
            Error::Pin(_) => "Pin",
            Error::DrdyTimeout => "DrdyTimeout",
            Error::Checksum { .. } => "Checksum",
            Error::CrcMismatch { .. } => "CrcMismatch",
            Error::InvalidConfig => "InvalidConfig",
            Error::DeviceId { .. } => "DeviceId",
            Error::NotResponding { .. } => "NotResponding",
            Error::ReadBack { .. } => "ReadBack",
            Error::StaleData => "StaleData",
            Error::UnexpectedReset => "UnexpectedReset",
            Error::AdcError(_) => "AdcError",
        }
    }
}

/// Polls an active-low data-ready pin at most `limit` times, `interval_us` apart: both converters
/// pull their DRDY output low when a conversion result is ready.
pub(crate) fn wait_low<
    SpiE,
    P: embedded_hal::digital::InputPin,
    D: embedded_hal::delay::DelayNs,
>(
    pin: &mut P,
    delay: &mut D,
    limit: u32,
    interval_us: u32,
) -> Result<(), Error<SpiE, P::Error>> {
    for _ in 0..limit {
        if pin.is_low().map_err(Error::Pin)? {
            return Ok(());
        }
        delay.delay_us(interval_us);
    }
    Err(Error::DrdyTimeout)
}

/// CRC-8 with polynomial x^8 + x^2 + x + 1 (0x07), initial value 0, no reflection, no final XOR
/// (the CRC-8/SMBUS parameter set): the AD7124 SPI CRC and the ADS1262 CRC mode both use it.
pub(crate) const CRC8_ATM: crc::Crc<u8> = crc::Crc::<u8>::new(&crc::CRC_8_SMBUS);
