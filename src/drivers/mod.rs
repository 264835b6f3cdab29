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
//! bus and pin errors; where a chip sits and how it is used is not the driver's business, so
//! no driver names anything outside its chip. Nothing allocates and nothing panics: every
//! failure comes back as the chip's error, and every conversion comes back as the core's code
//! newtypes ([`crate::adc::Ads1262Code`], [`crate::adc::Ad7124Code`]) so the maths layer never
//! sees a bare integer.

/// Declares a converter driver's `Error<SpiE, PinE>`: the failures both converters share (bus,
/// pin, data-ready timeout, CRC, configuration, identity, read-back, unexpected reset) followed
/// by the chip's own variants given here, with `name()` for logs, the conversion from a
/// data-ready wait and the `DriverError<SPI, DRDY>` alias. Written once so that the two drivers
/// name their common failures alike.
macro_rules! converter_error {
    ($(
        $(#[$doc:meta])*
        $variant:ident $( { $($named:tt)* } )? $( ( $($tuple:tt)* ) )?
    ),* $(,)?) => {
        /// Error type of a driver built on bus `SPI` and data-ready pin `DRDY`.
        pub type DriverError<SPI, DRDY> = Error<
            <SPI as embedded_hal::spi::ErrorType>::Error,
            <DRDY as embedded_hal::digital::ErrorType>::Error,
        >;

        /// Everything a driver call can fail with.
        ///
        /// `SpiE` is the bus error of the [`embedded_hal::spi::SpiDevice`], `PinE` the error of
        /// the data-ready [`embedded_hal::digital::InputPin`]. The other variants say what the
        /// chip did wrong, so the firmware can report a precise status flag instead of a number
        /// it cannot trust.
        #[derive(Debug, Clone, Copy, PartialEq, Eq)]
        pub enum Error<SpiE, PinE> {
            /// The SPI transfer itself failed.
            Spi(SpiE),
            /// Reading the data-ready pin failed.
            Pin(PinE),
            /// Data-ready did not assert within the configured number of polls.
            DrdyTimeout,
            /// CRC-8 (x^8 + x^2 + x + 1) over the received bytes differs from the received CRC
            /// byte.
            CrcMismatch {
                /// CRC computed from the received bytes.
                expected: u8,
                /// CRC byte the converter sent.
                received: u8,
            },
            /// A configuration value does not fit its register field or contradicts another
            /// setting.
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
            /// The converter reports it has been reset since it was configured (brown-out or
            /// glitch on the reset line): its configuration is lost and must be re-initialised.
            UnexpectedReset,
            $( $(#[$doc])* $variant $( { $($named)* } )? $( ( $($tuple)* ) )? ),*
        }

        impl<SpiE, PinE> Error<SpiE, PinE> {
            /// The variant's name, for firmware logs: defmt prints it without pulling in
            /// `core::fmt` (whose Debug machinery would cost the front-end build ~3.5 KiB of
            /// flash).
            pub const fn name(&self) -> &'static str {
                match self {
                    Error::Spi(_) => "Spi",
                    Error::Pin(_) => "Pin",
                    Error::DrdyTimeout => "DrdyTimeout",
                    Error::CrcMismatch { .. } => "CrcMismatch",
                    Error::InvalidConfig => "InvalidConfig",
                    Error::DeviceId { .. } => "DeviceId",
                    Error::NotResponding { .. } => "NotResponding",
                    Error::ReadBack { .. } => "ReadBack",
                    Error::UnexpectedReset => "UnexpectedReset",
                    $( Error::$variant { .. } => stringify!($variant), )*
                }
            }
        }

        impl<SpiE, PinE> From<crate::drivers::WaitError<PinE>> for Error<SpiE, PinE> {
            fn from(e: crate::drivers::WaitError<PinE>) -> Self {
                match e {
                    crate::drivers::WaitError::Pin(p) => Error::Pin(p),
                    crate::drivers::WaitError::Timeout => Error::DrdyTimeout,
                }
            }
        }
    };
}

pub mod ad7124;
pub mod ads1262;
pub mod stm32f4_flash;

/// Chip-boundary test doubles shared by both drivers' tests.
#[cfg(test)]
pub(crate) mod test_support {
    use embedded_hal::spi::{ErrorKind, ErrorType, Operation, SpiDevice};
    use embedded_hal_mock::eh1::delay::NoopDelay;
    use embedded_hal_mock::eh1::digital::{Mock as PinMock, State, Transaction as PinT};
    use embedded_hal_mock::eh1::spi::{Mock as SpiMock, Transaction as SpiT};
    use embedded_hal_mock::eh1::MockError;

    use super::ad7124::{Ad7124, Ad7124Config};
    use super::ads1262::{Ads1262, Ads1262Config};

    /// What a converter driver runs on in its tests: the SPI device, the data-ready pin, a delay.
    pub(crate) type Mocks = (SpiMock<u8>, PinMock, NoopDelay);

    /// A converter's configuration, and its driver on the mocks.
    pub(crate) trait OnMocks {
        type Driver: ReleaseMocks;
        fn on_mocks(self, mocks: Mocks) -> Self::Driver;
        /// The same configuration, polling data-ready at most `polls` times.
        fn with_drdy_poll_limit(self, polls: u32) -> Self;
    }

    /// A converter driver on the mocks, which gives them back.
    pub(crate) trait ReleaseMocks {
        fn release_mocks(self) -> Mocks;
    }

    /// Both drivers take and give back the same three parts.
    macro_rules! on_mocks {
        ($($config:ty => $driver:ident),*) => {$(
            impl OnMocks for $config {
                type Driver = $driver<SpiMock<u8>, PinMock, NoopDelay>;
                fn on_mocks(self, (spi, pin, delay): Mocks) -> Self::Driver {
                    $driver::new(spi, pin, delay, self)
                }
                fn with_drdy_poll_limit(self, polls: u32) -> Self {
                    Self {
                        drdy_poll_limit: polls,
                        ..self
                    }
                }
            }

            impl ReleaseMocks for $driver<SpiMock<u8>, PinMock, NoopDelay> {
                fn release_mocks(self) -> Mocks {
                    self.release()
                }
            }
        )*};
    }
    on_mocks!(Ad7124Config => Ad7124, Ads1262Config => Ads1262);

    /// A driver with `config` on mocks expecting the SPI transactions `spi` and the pin reads
    /// `pin`.
    pub(crate) fn driver<C: OnMocks>(spi: &[SpiT<u8>], pin: &[PinT], config: C) -> C::Driver {
        config.on_mocks((SpiMock::new(spi), PinMock::new(pin), NoopDelay::new()))
    }

    /// Checks that the driver's mocks saw every transaction they expected.
    pub(crate) fn finish(d: impl ReleaseMocks) {
        let (mut spi, mut pin, _) = d.release_mocks();
        spi.done();
        pin.done();
    }

    /// `call` on a driver with `config` on mocks expecting `spi` and `pin`, the mocks then
    /// checked: what the call returned.
    pub(crate) fn run<C: OnMocks, R>(
        spi: &[SpiT<u8>],
        pin: &[PinT],
        config: C,
        call: impl FnOnce(&mut C::Driver) -> R,
    ) -> R {
        let mut d = driver(spi, pin, config);
        let result = call(&mut d);
        finish(d);
        result
    }

    /// The data-ready failures of either driver, through `wait` (a call that waits for
    /// data-ready first): a pin that stays high past the poll limit is `timeout`, a pin whose
    /// read fails is `pin_error` of the pin's error. Nothing goes over the bus.
    pub(crate) fn check_drdy_failures<C: OnMocks + Copy, E: PartialEq + core::fmt::Debug>(
        config: C,
        wait: impl Fn(&mut C::Driver) -> Result<(), E>,
        timeout: E,
        pin_error: impl FnOnce(MockError) -> E,
    ) {
        const POLLS: u32 = 3;
        let high = std::vec![PinT::get(State::High); POLLS as usize];
        let config = config.with_drdy_poll_limit(POLLS);
        let err = MockError::Io(std::io::ErrorKind::Other);
        let failing = [PinT::get(State::Low).with_error(err.clone())];
        let cases = [(&high[..], timeout), (&failing[..], pin_error(err))];
        for (pin, expected) in cases {
            assert_eq!(run(&[], pin, config, &wait), Err(expected));
        }
    }

    /// One chip-select frame writing `sent`.
    pub(crate) fn write_frame(sent: std::vec::Vec<u8>) -> std::vec::Vec<SpiT<u8>> {
        std::vec![
            SpiT::transaction_start(),
            SpiT::write_vec(sent),
            SpiT::transaction_end(),
        ]
    }

    /// One chip-select frame clocking `sent` out while `answer` comes in.
    pub(crate) fn transfer_frame(
        sent: std::vec::Vec<u8>,
        answer: std::vec::Vec<u8>,
    ) -> std::vec::Vec<SpiT<u8>> {
        std::vec![
            SpiT::transaction_start(),
            SpiT::transfer_in_place(sent, answer),
            SpiT::transaction_end(),
        ]
    }

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
