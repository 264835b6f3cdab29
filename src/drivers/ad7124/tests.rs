//! Host tests against embedded-hal-mock. Register addresses, field values and the CRC are
//! re-declared here from the AD7124-4 datasheet (Rev. B), not imported from the driver.

use super::*;
use crate::drivers::test_support::{
    check_drdy_failures, crc8_reference, driver, finish, run, transfer_frame, write_frame,
    BrokenBus,
};
use embedded_hal::spi::ErrorKind;
use embedded_hal_mock::eh1::delay::NoopDelay;
use embedded_hal_mock::eh1::digital::{Mock as PinMock, State, Transaction as PinT};
use embedded_hal_mock::eh1::spi::{Mock as SpiMock, Transaction as SpiT};

/// The configuration the register values below are worked out for (the front-end board's,
/// re-declared here: the driver does not know the board).
fn config() -> Ad7124Config {
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
        gain: Gain::G16,
        filter: FilterType::Sinc4,
        filter_fs: 1920,
        crc: true,
        drdy_poll_limit: 20_000,
        drdy_poll_interval_us: 50,
    }
}

// Addresses (communications byte RS[5:0]); R/W is bit 6.
const READ: u8 = 0x40;
const STATUS: u8 = 0x00;
const ADC_CONTROL: u8 = 0x01;
const DATA: u8 = 0x02;
const IO_CONTROL_1: u8 = 0x03;
const ID: u8 = 0x05;
const ERROR: u8 = 0x06;
const ERROR_EN: u8 = 0x07;
const CHANNEL_0: u8 = 0x09;
const CONFIG_0: u8 = 0x19;
const FILTER_0: u8 = 0x21;

// Board register values, worked out by hand from the register tables.
// ERROR_EN: bits 18..12 (cal, conv, sat, AINP OV/UV, AINM OV/UV) = 0x07F000, REF_DET bit 11
// = 0x800, DLDO_PSM bit 9 = 0x200, ALDO_PSM bit 7 = 0x80, SPI_IGNORE/SCLK/READ/WRITE bits 6..3
// = 0x78, SPI_CRC bit 2 = 0x04, MM_CRC bit 1 = 0x02 → 0x07FAFE (0x07FAFA without CRC).
const ERROR_EN_CRC: [u8; 3] = [0x07, 0xFA, 0xFE];
const ERROR_EN_NO_CRC: [u8; 3] = [0x07, 0xFA, 0xFA];
// IO_CONTROL_1: IOUT0 = 011 (250 µA) at [10:8], IOUT0_CH = 0000 (AIN0) → 0x000300.
const IOCON1: [u8; 3] = [0x00, 0x03, 0x00];
// CONFIG_0: unipolar, REF_BUFP|REF_BUFM|AIN_BUFP|AIN_BUFM = 0x1E0, REFIN1 = 00, PGA 16 = 100.
const CONFIG: [u8; 2] = [0x01, 0xE4];
// FILTER_0: sinc4 = 000 at [23:21], FS = 1920 = 0x780.
const FILTER: [u8; 3] = [0x00, 0x07, 0x80];
// CHANNEL_0: enable bit 15, setup 0, AINP = AIN1 (1 << 5), AINM = AIN2 → 0x8022.
const CHANNEL: [u8; 2] = [0x80, 0x22];
// ADC_CONTROL: DATA_STATUS bit 10, POWER_MODE = 10 (full) at [7:6], continuous → 0x0480.
const ADC_CTRL: [u8; 2] = [0x04, 0x80];
const ID_AD7124_4_REV4: u8 = 0x04;

fn wr(addr: u8, value: &[u8], crc: bool) -> Vec<SpiT<u8>> {
    let mut sent = vec![addr];
    sent.extend_from_slice(value);
    if crc {
        sent.push(crc8_reference(&sent));
    }
    write_frame(sent)
}

/// A read whose CRC byte (if any) is `crc_override` or else the correct one.
fn rd_with(addr: u8, value: &[u8], crc: bool, crc_override: Option<u8>) -> Vec<SpiT<u8>> {
    let comms = READ | addr;
    let extra = usize::from(crc);
    let mut sent = vec![0u8; 1 + value.len() + extra];
    sent[0] = comms;
    let mut answer = vec![0xFF];
    answer.extend_from_slice(value);
    if crc {
        let mut covered = vec![comms];
        covered.extend_from_slice(value);
        answer.push(crc_override.unwrap_or_else(|| crc8_reference(&covered)));
    }
    transfer_frame(sent, answer)
}

fn rd(addr: u8, value: &[u8], crc: bool) -> Vec<SpiT<u8>> {
    rd_with(addr, value, crc, None)
}

/// A register write and its read-back, as `init` verifies every register it writes.
fn written(addr: u8, value: &[u8], crc: bool) -> Vec<SpiT<u8>> {
    [wr(addr, value, crc), rd(addr, value, crc)].concat()
}

fn reset() -> Vec<SpiT<u8>> {
    write_frame(vec![0xFF; 8])
}

fn board_init() -> Vec<SpiT<u8>> {
    board_init_with(true)
}

/// `init` of the board configuration with or without CRC: reset, ID, ERROR_EN (switching the
/// CRC on, it is written without CRC and read back with it), then every register written and
/// read back.
fn board_init_with(crc: bool) -> Vec<SpiT<u8>> {
    let error_en = if crc {
        [
            wr(ERROR_EN, &ERROR_EN_CRC, false),
            rd(ERROR_EN, &ERROR_EN_CRC, true),
        ]
        .concat()
    } else {
        written(ERROR_EN, &ERROR_EN_NO_CRC, false)
    };
    [
        reset(),
        rd(ID, &[ID_AD7124_4_REV4], false),
        error_en,
        written(IO_CONTROL_1, &IOCON1, crc),
        written(CONFIG_0, &CONFIG, crc),
        written(FILTER_0, &FILTER, crc),
        written(CHANNEL_0, &CHANNEL, crc),
        written(ADC_CONTROL, &ADC_CTRL, crc),
    ]
    .concat()
}

type Driver = Ad7124<SpiMock<u8>, PinMock, NoopDelay>;

/// A board-default driver already through `init`, expecting `then` afterwards.
fn initialised(then: &[SpiT<u8>], pin: &[PinT]) -> Driver {
    let spi = [board_init(), then.to_vec()].concat();
    let mut d = driver(&spi, pin, config());
    assert!(d.init().is_ok(), "board-default init failed");
    d
}

#[test]
fn the_board_configuration_converts_at_10_sps() {
    // Full power f_CLK = 614.4 kHz, sinc4: 614400 / (32 · 1920) = 10 Hz.
    assert_eq!(config().output_data_rate_hz(), 10.0);
}

#[test]
fn init_resets_checks_id_and_writes_every_register_with_crc_and_read_back() {
    assert_eq!(
        run(&board_init(), &[], config(), |d| d.init()),
        Ok(DeviceInfo {
            silicon_revision: 4
        })
    );
}

#[test]
fn init_without_crc_sends_no_crc_bytes() {
    let cfg = Ad7124Config {
        crc: false,
        ..config()
    };
    let mut d = driver(&board_init_with(false), &[], cfg);
    assert!(d.init().is_ok());
    finish(d);
}

#[test]
fn init_reports_a_register_that_did_not_read_back() {
    let spi = [
        reset(),
        rd(ID, &[ID_AD7124_4_REV4], false),
        wr(ERROR_EN, &ERROR_EN_CRC, false),
        rd(ERROR_EN, &ERROR_EN_CRC, true),
        written(IO_CONTROL_1, &IOCON1, true),
        wr(CONFIG_0, &CONFIG, true),
        rd(CONFIG_0, &[0x08, 0x60], true), // still the reset value
    ]
    .concat();
    assert_eq!(
        run(&spi, &[], config(), |d| d.init()),
        Err(Error::ReadBack {
            register: CONFIG_0,
            written: 0x01E4,
            read: 0x0860
        })
    );
}

#[test]
fn init_rejects_the_ad7124_8_and_an_idle_bus() {
    for (id, expected) in [
        (0x14u8, Error::DeviceId { found: 0x14 }),
        (0x00, Error::NotResponding { found: 0x00 }),
        (0xFF, Error::NotResponding { found: 0xFF }),
    ] {
        let spi = [reset(), rd(ID, &[id], false)].concat();
        assert_eq!(run(&spi, &[], config(), |d| d.init()), Err(expected));
    }
}

#[test]
fn corrupted_read_back_fails_the_crc() {
    let good = {
        let mut c = vec![READ | ERROR_EN];
        c.extend_from_slice(&ERROR_EN_CRC);
        crc8_reference(&c)
    };
    let spi = [
        reset(),
        rd(ID, &[ID_AD7124_4_REV4], false),
        wr(ERROR_EN, &ERROR_EN_CRC, false),
        rd_with(ERROR_EN, &ERROR_EN_CRC, true, Some(good ^ 0x80)),
    ]
    .concat();
    assert_eq!(
        run(&spi, &[], config(), |d| d.init()),
        Err(Error::CrcMismatch {
            expected: good,
            received: good ^ 0x80
        })
    );
}

#[test]
fn init_refuses_impossible_configurations_without_touching_the_bus() {
    let base = config();
    for cfg in [
        Ad7124Config {
            filter_fs: 0,
            ..base
        },
        Ad7124Config {
            filter_fs: 2048,
            ..base
        },
        Ad7124Config {
            reference: Reference::Internal,
            ..base
        },
        Ad7124Config {
            negative: AnalogInput::Ain1,
            ..base
        },
    ] {
        assert_eq!(run(&[], &[], cfg, |d| d.init()), Err(Error::InvalidConfig));
    }
}

#[test]
fn read_rtd_waits_for_drdy_and_returns_the_checked_code() {
    // Data 0x123456, STATUS 0x00 (ready, no error, channel 0), CRC over 0x42 + data + status.
    let then = rd(DATA, &[0x12, 0x34, 0x56, 0x00], true);
    let pin = [PinT::get(State::High), PinT::get(State::Low)];
    let mut d = initialised(&then, &pin);
    assert_eq!(d.read_rtd(), Ok(Ad7124Code(0x12_3456)));
    finish(d);
}

#[test]
fn read_rtd_with_a_bad_crc_is_a_crc_mismatch() {
    let good = crc8_reference(&[READ | DATA, 0x12, 0x34, 0x56, 0x00]);
    let then = rd_with(DATA, &[0x12, 0x34, 0x56, 0x00], true, Some(good ^ 0x01));
    let mut d = initialised(&then, &[PinT::get(State::Low)]);
    assert_eq!(
        d.read_rtd(),
        Err(Error::CrcMismatch {
            expected: good,
            received: good ^ 0x01
        })
    );
    finish(d);
}

#[test]
fn error_flag_in_status_reads_and_reports_the_error_register() {
    // STATUS 0x40: ERROR_FLAG. ERROR = REF_DET (bit 11) | ADC_SAT (bit 16) = 0x010800:
    // an open RTD loop leaves no reference and a saturated result.
    let then = [
        rd(DATA, &[0xFF, 0xFF, 0xFF, 0x40], true),
        rd(ERROR, &[0x01, 0x08, 0x00], true),
    ]
    .concat();
    let mut d = initialised(&then, &[PinT::get(State::Low)]);
    let e = d.read_rtd();
    assert_eq!(e, Err(Error::AdcError(ErrorFlags(0x01_0800))));
    if let Err(Error::AdcError(flags)) = e {
        assert!(flags.reference_missing() && flags.saturated());
        assert!(!flags.spi_crc() && !flags.input_out_of_range() && !flags.conversion());
    }
    finish(d);
}

#[test]
fn error_flag_decoding_follows_the_register_bits() {
    assert!(ErrorFlags(1 << 2).spi_crc());
    assert!(ErrorFlags(1 << 15).input_out_of_range());
    assert!(ErrorFlags(1 << 12).input_out_of_range());
    assert!(ErrorFlags(1 << 17).conversion());
    assert!(ErrorFlags(1 << 18).calibration());
    assert!(ErrorFlags(1 << 1).register_map_crc());
    assert!(ErrorFlags(1 << 7).supply() && ErrorFlags(1 << 9).supply());
    assert!(ErrorFlags(1 << 6).spi() && !ErrorFlags(1 << 2).spi());
}

#[test]
fn read_rtd_polled_polls_status_until_ready() {
    let then = [
        rd(STATUS, &[0x80], true), // RDY high: not yet
        rd(STATUS, &[0x00], true),
        rd(DATA, &[0x00, 0x01, 0x00, 0x00], true),
    ]
    .concat();
    let mut d = initialised(&then, &[]);
    assert_eq!(d.read_rtd_polled(), Ok(Ad7124Code(0x00_0100)));
    finish(d);
}

/// Data-ready that never falls times out after the poll limit; a failing pin is a pin error.
#[test]
fn drdy_failures_are_named() {
    check_drdy_failures(
        config(),
        |d| d.read_rtd().map(drop),
        Error::DrdyTimeout,
        Error::Pin,
    );
}

#[test]
fn status_that_never_shows_ready_times_out() {
    let cfg = Ad7124Config {
        drdy_poll_limit: 2,
        crc: false,
        ..config()
    };
    let spi = [rd(STATUS, &[0x80], false), rd(STATUS, &[0x80], false)].concat();
    assert_eq!(
        run(&spi, &[], cfg, |d| d.read_rtd_polled()),
        Err(Error::DrdyTimeout)
    );
}

#[test]
fn bus_failure_is_reported_as_spi_error() {
    let mut d = Ad7124::new(BrokenBus, PinMock::new(&[]), NoopDelay::new(), config());
    assert_eq!(d.init(), Err(Error::Spi(ErrorKind::Other)));
    assert_eq!(d.read_data(), Err(Error::Spi(ErrorKind::Other)));
    let (_, mut pin, _) = d.release();
    pin.done();
}

#[test]
fn scale_reads_the_board_code_for_100_ohm_back_as_100_ohm() {
    let scale = config().scale(crate::units::Volts(1.2775));
    // 2^24 · 100 Ω · 16 / 5110 Ω = 5 253 140.04 → code 5 253 140; 1 LSB = 19.0 µΩ.
    let r = scale.ratiometric_ohms(Ad7124Code(5_253_140).raw(), crate::units::Ohms(5110.0));
    assert!(r.is_ok_and(|r| (r.0 - 100.0).abs() < 2e-5), "{r:?}");
    let bipolar = Ad7124Config {
        bipolar: true,
        ..config()
    };
    assert_eq!(
        bipolar.scale(crate::units::Volts(1.0)).coding,
        crate::adc::Coding::OffsetBinary
    );
}
