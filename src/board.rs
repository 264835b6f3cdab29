//! The front-end board in one place: which chip is where (pins, buses, the channel map), the
//! drivers' configurations, references, PGA gains, resistors, full scales, and the conversions
//! between physical values and ADC codes (docs/drivers.md, "The board").
//!
//! The chip drivers (`crate::drivers`) know only their chip; what this board makes of them —
//! [`ads1262_config`], [`ad7124_config`], the SPI buses, the pin map — is here, and the firmware's
//! per-board glue (`src/bsp/`, the binary's board support package: HAL types, clocks,
//! interrupts) builds the hardware from it. The name `board` belongs to this description rather
//! than to the glue because the description is what the host shares with the firmware (the
//! simulator's converters, the chip-model tests, `accomp compensate`'s injection); the glue is
//! target-only code, and "BSP" is what embedded Rust calls it.
//!
//! Every user reads the board from here: the per-sample pipeline and the prepared calibration
//! (code → value), the host's injection and the simulator's converters (value → code), the
//! reference tables' nominal channel settings and the firmware's driver set-up. A value that
//! differs between two of them is a bug this module exists to rule out.
//!
//! **The ADS1262's PGA is enabled, at gain 1, on both channels** ([`ads1262_config`], MODE2
//! BYPASS = 0): the PGA's high input impedance keeps the source resistance of the inputs (the
//! accelerometer's sense resistor, the tiltmeter's output stage) from loading the modulator's
//! switched-capacitor input, which in bypass would draw input current through them and turn it
//! into a gain error. At gain 1 the PGA's absolute-input headroom (a few hundred mV inside the
//! supplies) still takes E ≈ 1.33 V/g × 1.5 g ≈ 2 V.
//! `tests::the_drivers_board_settings_are_the_front_end_constants` pins it.

use crate::acquisition::{stm32_sclk_within, SpiSettings, AD7124_SPI, ADS1262_SPI};
use crate::adc::{Ad7124Code, AdcError, AdcScale, Ads1262Code};
use crate::drivers::ad7124::{
    self, Ad7124Config, AnalogInput, Excitation, FilterType, IoutPin, PowerMode, Reference,
};
use crate::drivers::ads1262::{
    self, Ads1262Config, BoardChannels, ChannelConfig, Chop, DataRate, Filter, Gain, Input,
    Integrity, Pga, RefNegative, RefPositive,
};
use crate::table::CalibrationTable;
use crate::units::{Celsius, Ohms, RtdOhms, TiltArcsec, Volts};

/// ADS1262 reference: the internal 2.5 V reference.
pub const ADS1262_VREF: Volts = Volts(2.5);
/// ADS1262 result width (ADC1, 32-bit two's complement).
pub const ADS1262_BITS: u8 = ads1262::CODE_BITS;
/// Full-scale magnitude of the ADS1262 code, 2^31: ±Vref/gain ↔ ±2^31.
pub const ADS1262_HALF_SCALE: f64 = 2_147_483_648.0;
/// ADS1262 PGA gain of the accelerometer channel (PGA enabled; see the module text).
pub const ACCEL_PGA_GAIN: f64 = 1.0;
/// ADS1262 PGA gain of the tiltmeter channel (PGA enabled; volts-level output as well).
pub const TILT_PGA_GAIN: f64 = 1.0;

/// AD7124-4 result width (24-bit, unipolar on the RTD channel).
pub const AD7124_BITS: u8 = ad7124::CODE_BITS;
/// Full scale of the unipolar AD7124 code, 2^24: R_ref/gain ↔ 2^24.
pub const AD7124_FULL_SCALE: f64 = 16_777_216.0;
/// Largest AD7124 code (all ones): reads as saturated (an open RTD).
pub const AD7124_MAX_CODE: u32 = 0x00FF_FFFF;
/// AD7124 PGA gain of the RTD channel (nominal; a table carries its own).
pub const RTD_PGA_GAIN: f64 = 16.0;
/// Reference resistor of the ratiometric RTD measurement, Ω (nominal; a table carries its own).
pub const RTD_REFERENCE_OHMS: f64 = 5110.0;
/// Sense resistor of the torquer current, Ω.
pub const SENSE_RESISTOR_OHMS: f64 = 1000.0;
/// Tiltmeter sensitivity, arcsec per volt (nominal; a table carries its own).
pub const TILT_SCALE_ARCSEC_PER_V: f64 = 10.0;

/// The ADS1262 on this board (reasons in docs/drivers.md): sinc4 at 10 SPS (notches on every
/// multiple of 10 Hz, so 50 and 60 Hz both fall in one), chop off (it would halve the throughput
/// of the two multiplexed channels; at gain 1 and 1.33 V/g even 100 nV/°C of offset drift is
/// 75 ng/°C), internal 2.5 V reference, status byte + checksum, accelerometer on AIN0−AIN1 and
/// tiltmeter on AIN2−AIN3, both at gain 1 with the PGA enabled. The DRDY bound is 1 s (20 000
/// polls of 50 µs): the first sinc4 conversion at 10 SPS after a restart takes about 4 data
/// periods (≈ 400 ms). Both configurations are functions, not `const` items: built in place
/// with immediate stores they cost 56 B less flash than a copy out of .rodata.
pub const fn ads1262_config() -> Ads1262Config {
    Ads1262Config {
        filter: Filter::Sinc4,
        data_rate: DataRate::Sps10,
        chop: Chop::Off,
        delay_code: 0,
        ref_positive: RefPositive::Internal,
        ref_negative: RefNegative::Internal,
        internal_reference: true,
        status_byte: true,
        integrity: Integrity::Checksum,
        channels: BoardChannels {
            accelerometer: ChannelConfig {
                positive: Input::Ain0,
                negative: Input::Ain1,
                pga: Pga::Enabled(Gain::G1),
            },
            tiltmeter: ChannelConfig {
                positive: Input::Ain2,
                negative: Input::Ain3,
                pga: Pga::Enabled(Gain::G1),
            },
        },
        drdy_poll_limit: 20_000,
        drdy_poll_interval_us: 50,
    }
}

/// The AD7124-4 on this board: 4-wire Pt100, 250 µA from IOUT0 on AIN0, sense leads on
/// AIN1(+)/AIN2(−), 5.11 kΩ reference resistor on REFIN1 with buffers, gain 16, unipolar, full
/// power, sinc4 at FS = 1920 (10 SPS, notches at every multiple of 10 Hz), STATUS appended, CRC
/// on. Reasons in docs/drivers.md. The DRDY bound is 1 s (20 000 × 50 µs), well above the
/// 400 ms sinc4 settling at 10 SPS.
pub const fn ad7124_config() -> Ad7124Config {
    Ad7124Config {
        power_mode: PowerMode::Full,
        internal_reference: false,
        data_status: true,
        cs_en: false,
        excitation: Excitation::Ua250,
        excitation_pin: IoutPin::Ain0,
        positive: AnalogInput::Ain1,
        negative: AnalogInput::Ain2,
        bipolar: false,
        reference: Reference::Refin1,
        reference_buffers: true,
        input_buffers: true,
        gain: ad7124::Gain::G16,
        filter: FilterType::Sinc4,
        filter_fs: 1920,
        crc: true,
        drdy_poll_limit: 20_000,
        drdy_poll_interval_us: 50,
    }
}

/// APB2 clock (SPI1) with the PLL at 168 MHz, from the crystal or from the HSI fallback.
pub const APB2_HZ: u32 = 84_000_000;
/// APB1 clock (SPI2, USART… ; TIM2 runs at twice it).
pub const APB1_HZ: u32 = 42_000_000;

const fn sclk(pclk: u32, max: u32) -> u32 {
    match stm32_sclk_within(pclk, max) {
        Some(f) => f,
        None => 0,
    }
}

/// SPI1 → ADS1262 alone: mode 1, 84 MHz / 16 = 5.25 MHz (≤ 8 MHz).
pub const ADS1262_BUS: SpiSettings = SpiSettings {
    mode: ADS1262_SPI.mode,
    sclk_hz: sclk(APB2_HZ, ADS1262_SPI.max_sclk_hz),
};

/// SPI2 → AD7124-4 alone: mode 3, 42 MHz / 16 = 2.625 MHz (/8 would be 5.25 MHz > 5 MHz).
pub const AD7124_BUS: SpiSettings = SpiSettings {
    mode: AD7124_SPI.mode,
    sclk_hz: sclk(APB1_HZ, AD7124_SPI.max_sclk_hz),
};

// The board configuration meets both datasheets, or the firmware does not build.
const _: () = assert!(ADS1262_SPI.accepts(&ADS1262_BUS) && AD7124_SPI.accepts(&AD7124_BUS));

/// An STM32F405 GPIO pin: port letter and number. The firmware's glue names its HAL pins by
/// these constants (`gpio::Pin<{ P.port }, { P.number }, _>`), so a pin moved here moves there
/// or the firmware does not build.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Pin {
    /// Port letter, 'A'…'I'.
    pub port: char,
    /// Pin number in the port, 0…15.
    pub number: u8,
}

const fn pin(port: char, number: u8) -> Pin {
    Pin { port, number }
}

/// USART1 TX (AF7) to the lab PC.
pub const UART_TX: Pin = pin('A', 9);
/// USART1 RX (AF7) from the lab PC.
pub const UART_RX: Pin = pin('A', 10);
/// SPI1 SCK (AF5), ADS1262.
pub const ADS1262_SCK: Pin = pin('A', 5);
/// SPI1 MISO (AF5), ADS1262 DOUT.
pub const ADS1262_MISO: Pin = pin('A', 6);
/// SPI1 MOSI (AF5), ADS1262 DIN.
pub const ADS1262_MOSI: Pin = pin('A', 7);
/// ADS1262 chip select, push-pull, high when idle.
pub const ADS1262_CS: Pin = pin('A', 4);
/// ADS1262 DRDY, falling edge, pull-up; EXTI line = pin number (the firmware binds EXTI1).
/// PA1 in alternate function 1 is TIM2_CH2 (DS8626 Table 9, "Alternate function mapping"):
/// TIM2, the time base, latches its count at the DRDY edge by input capture, so a reading is
/// stamped with the time its conversion ended, not when the handler got to run. The pin's input
/// path still feeds EXTI in alternate-function mode (RM0090 §8.3.11), which runs the handler.
/// A plain EXTI pin such as PC4 has no timer function. Of the TIM2 channel pins (PA0–PA3, PA5,
/// PA15, PB3, PB10, PB11), PA5 is SPI1's clock, PA15/PB3 are JTAG, PA0 is the wake-up pin,
/// PA2/PA3 are USART2, and PB10/PB11 would share the EXTI15_10 vector; PA1 has EXTI1 alone.
pub const ADS1262_DRDY: Pin = pin('A', 1);
/// Alternate function of [`ADS1262_DRDY`] that connects it to TIM2_CH2.
pub const ADS1262_DRDY_AF: u8 = 1;
/// SPI2 SCK (AF5), AD7124-4.
pub const AD7124_SCK: Pin = pin('B', 13);
/// SPI2 MISO (AF5), AD7124-4 DOUT/RDY.
pub const AD7124_MISO: Pin = pin('B', 14);
/// SPI2 MOSI (AF5), AD7124-4 DIN.
pub const AD7124_MOSI: Pin = pin('B', 15);
/// AD7124-4 chip select, push-pull, high when idle.
pub const AD7124_CS: Pin = pin('B', 12);
/// ADS1262 START, push-pull, held low: conversions are started by the START1 command, which
/// SBAS661C ("Conversion Control", START pin) requires the pin low for; a floating START could
/// start and stop conversions at random.
pub const ADS1262_START: Pin = pin('C', 5);
/// ADS1262 XTAL1/CLKIN, push-pull, held low: the ADC runs on its internal 7.3728 MHz oscillator,
/// for which SBAS661C ("Clock Operation") wants CLKIN at DGND; a floating CLKIN could be taken
/// for an external clock. PA8 is MCO1, so the MCU could later clock the ADC from here.
pub const ADS1262_CLKIN: Pin = pin('A', 8);

/// How an ADS1262 channel's codes read: 32-bit two's complement, the internal reference, the
/// channel's PGA gain and the calibration's gain correction and offset.
pub fn ads1262_scale(pga_gain: f64, gain_correction: f64, offset: Volts) -> AdcScale {
    ads1262_scale_with_vref(pga_gain, ADS1262_VREF, gain_correction, offset)
}

/// [`ads1262_scale`] with another reference voltage (the simulator's drifting reference, a
/// driver configured for an external one).
pub fn ads1262_scale_with_vref(
    pga_gain: f64,
    vref: Volts,
    gain_correction: f64,
    offset: Volts,
) -> AdcScale {
    ads1262::code_scale(pga_gain, vref, gain_correction, offset)
}

/// How AD7124 codes read: 24 bits, unipolar or offset binary (bipolar), the PGA gain, the
/// reference voltage (for volt readings) and the gain correction.
pub fn ad7124_scale(bipolar: bool, pga_gain: f64, vref: Volts, gain_correction: f64) -> AdcScale {
    ad7124::code_scale(bipolar, pga_gain, vref, gain_correction)
}

/// How the AD7124's ratiometric RTD codes read: unipolar, the PGA gain and the gain correction.
/// The reference voltage cancels in a ratiometric reading; 1 V stands for it.
pub fn ad7124_rtd_scale(pga_gain: f64, gain_correction: f64) -> AdcScale {
    ad7124_scale(false, pga_gain, Volts(1.0), gain_correction)
}

/// The accelerometer channel, with the table's correction when there is one.
pub fn accel_scale(table: Option<&CalibrationTable>) -> AdcScale {
    let (gain_correction, offset) = match table {
        Some(t) => (t.accel.adc_gain_correction, t.accel.adc_offset),
        None => (1.0, Volts(0.0)),
    };
    ads1262_scale(ACCEL_PGA_GAIN, gain_correction, offset)
}

/// The tiltmeter channel with the table's correction.
pub fn tilt_scale(table: &CalibrationTable) -> AdcScale {
    ads1262_scale(
        TILT_PGA_GAIN,
        table.tilt.adc_gain_correction,
        table.tilt.adc_offset,
    )
}

/// The RTD channel with the table's gain and correction.
pub fn rtd_scale(table: &CalibrationTable) -> AdcScale {
    ad7124_rtd_scale(table.rtd.pga_gain, table.rtd.adc_gain_correction)
}

/// The code a measurable value gives: [`AdcScale`]'s inverse, refusing what the converter cannot
/// represent. `Err(Saturated)` when the code would be a rail (the chip would report an
/// over-range; the forward conversion reads rails as saturated), `Err(NonFiniteInput)` for NaN
/// or ±∞, `Err(InvalidScale)` for an unusable scale.
fn measurable(scale: &AdcScale, code: Result<u32, AdcError>) -> Result<u32, AdcError> {
    let code = code?;
    match scale.fraction(code) {
        Ok(_) => Ok(code),
        Err(e) => Err(e),
    }
}

/// Volts at an ADS1262 input → code.
pub fn volts_to_ads1262(scale: &AdcScale, v: Volts) -> Result<Ads1262Code, AdcError> {
    measurable(scale, scale.code_for_volts(v)).map(|c| Ads1262Code(c as i32))
}

/// RTD ohms → AD7124 ratiometric code (the reference resistor sets full scale).
pub fn ohms_to_ad7124(
    scale: &AdcScale,
    r: RtdOhms,
    reference: Ohms,
) -> Result<Ad7124Code, AdcError> {
    measurable(scale, scale.code_for_ohms(r, reference)).map(Ad7124Code)
}

/// Temperature → RTD ohms → AD7124 code with the table's RTD constants.
pub fn celsius_to_ad7124(table: &CalibrationTable, t: Celsius) -> Result<Ad7124Code, AdcError> {
    if !t.0.is_finite() {
        return Err(AdcError::NonFiniteInput);
    }
    let r = table.rtd.cvd.resistance(t);
    ohms_to_ad7124(&rtd_scale(table), r, table.rtd.reference_resistor)
}

/// Tilt → tiltmeter volts → ADS1262 code with the table's tilt scale.
pub fn arcsec_to_ads1262(
    table: &CalibrationTable,
    tilt: TiltArcsec,
) -> Result<Ads1262Code, AdcError> {
    volts_to_ads1262(
        &tilt_scale(table),
        Volts(tilt.0 / table.tilt.scale_arcsec_per_v),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::drivers::ads1262::Channel;

    #[test]
    fn the_drivers_board_settings_are_the_front_end_constants() {
        let ads = ads1262_config();
        // Enabled, not bypassed, at the gains the maths uses.
        assert!(matches!(ads.channels.accelerometer.pga, Pga::Enabled(_)));
        assert!(matches!(ads.channels.tiltmeter.pga, Pga::Enabled(_)));
        let accel = ads.scale(Channel::Accelerometer, ADS1262_VREF);
        assert_eq!(accel, accel_scale(None));
        let tilt = ads.scale(Channel::Tiltmeter, ADS1262_VREF);
        assert_eq!(tilt, ads1262_scale(TILT_PGA_GAIN, 1.0, Volts(0.0)));
        let rtd = ad7124_config().scale(Volts(1.0));
        assert_eq!(rtd, ad7124_rtd_scale(RTD_PGA_GAIN, 1.0));
    }

    #[test]
    fn values_beyond_full_scale_are_refused_as_saturated_and_nan_as_non_finite() {
        let s = accel_scale(None);
        let lsb = 2.5 / ADS1262_HALF_SCALE;
        assert_eq!(volts_to_ads1262(&s, Volts(2.6)), Err(AdcError::Saturated));
        assert_eq!(volts_to_ads1262(&s, Volts(-2.5)), Err(AdcError::Saturated));
        assert_eq!(
            volts_to_ads1262(&s, Volts(2.5 - 2.0 * lsb)),
            Ok(Ads1262Code(i32::MAX - 1))
        );
        assert_eq!(
            volts_to_ads1262(&s, Volts(f64::NAN)),
            Err(AdcError::NonFiniteInput)
        );
        let r = ad7124_rtd_scale(RTD_PGA_GAIN, 1.0);
        let full = RtdOhms(RTD_REFERENCE_OHMS / RTD_PGA_GAIN);
        assert_eq!(
            ohms_to_ad7124(&r, full, Ohms(RTD_REFERENCE_OHMS)),
            Err(AdcError::Saturated)
        );
        assert_eq!(
            ohms_to_ad7124(&r, RtdOhms(0.0), Ohms(RTD_REFERENCE_OHMS)),
            Ok(Ad7124Code(0))
        );
    }
}
