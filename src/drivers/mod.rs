//! Drivers of the board's chips: the two converters over embedded-hal 1.0 SPI, and the MCU's
//! own flash controller behind embedded-storage.
//!
//! - [`ads1262`]: TI ADS1262 32-bit ΔΣ ADC (accelerometer torquer-current sense and tiltmeter).
//! - [`ad7124`]: ADI AD7124-4 24-bit ΔΣ ADC (4-wire Pt100, ratiometric, as in ADI CN-0381).
//! - [`stm32f4_flash`]: the STM32F405 flash controller (calibration slots), register-level.
//!
//! Both take an [`embedded_hal::spi::SpiDevice`] (so the bus can be shared and chip select is
//! the bus manager's business), an [`embedded_hal::digital::InputPin`] for data-ready and an
//! [`embedded_hal::delay::DelayNs`] for the reset waits. Each knows only its chip: its registers,
//! its coding, and its own error type ([`ads1262::Error`], [`ad7124::Error`]) generic over the
//! bus and pin errors; where a chip sits and how the board uses it is the board's business
//! ([`crate::frontend`], [`crate::acquisition`]). Nothing allocates and nothing panics: every
//! failure comes back as the chip's error, and every conversion comes back as the core's code
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

/// Why a wait for data-ready ended without it; each driver turns this into its own error.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum WaitError<PinE> {
    /// Reading the pin failed.
    Pin(PinE),
    /// Data-ready did not assert within the polls allowed.
    Timeout,
}

/// Polls an active-low data-ready pin at most `limit` times, `interval_us` apart: both converters
/// pull their DRDY output low when a conversion result is ready.
pub(crate) fn wait_low<P: embedded_hal::digital::InputPin, D: embedded_hal::delay::DelayNs>(
    pin: &mut P,
    delay: &mut D,
    limit: u32,
    interval_us: u32,
) -> Result<(), WaitError<P::Error>> {
    for _ in 0..limit {
        if pin.is_low().map_err(WaitError::Pin)? {
            return Ok(());
        }
        delay.delay_us(interval_us);
    }
    Err(WaitError::Timeout)
}

/// CRC-8 with polynomial x^8 + x^2 + x + 1 (0x07), initial value 0, no reflection, no final XOR
/// (the CRC-8/SMBUS parameter set): the AD7124 SPI CRC and the ADS1262 CRC mode both use it.
pub(crate) const CRC8_ATM: crc::Crc<u8> = crc::Crc::<u8>::new(&crc::CRC_8_SMBUS);
