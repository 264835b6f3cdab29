//! Host tests against embedded-hal-mock. The register map, opcodes and expected bytes are
//! re-declared here from SBAS661C, not imported, so a wrong constant in the driver cannot agree
//! with itself; checksums and CRCs are hand-computed or computed by the tiny bitwise CRC of
//! `drivers::test_support`.

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
fn config() -> Ads1262Config {
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

// SBAS661C opcodes and addresses, written out again.
const RESET: u8 = 0x06;
const START1: u8 = 0x08;
const STOP1: u8 = 0x0A;
const RDATA1: u8 = 0x12;
const RREG: u8 = 0x20;
const WREG: u8 = 0x40;
const ID: u8 = 0x00;
const POWER: u8 = 0x01;
const MODE1: u8 = 0x04;
const MODE2: u8 = 0x05;
const INPMUX: u8 = 0x06;
const REFMUX: u8 = 0x0F;

// Board default register values, worked out by hand from the register tables:
// POWER: INTREF=1, RESET=0 → 0x01. INTERFACE: STATUS=1, CRC=01 (checksum) → 0x05.
// MODE0: CHOP=00, DELAY=0000 → 0x00. MODE1: FILTER=011 (sinc4) at [7:5] → 0x60.
// MODE2: BYPASS=0, GAIN=000 (1), DR=0010 (10 SPS) → 0x02. INPMUX: AIN0(0000)/AIN1(0001) → 0x01.
// REFMUX: internal/internal → 0x00.
const BOARD_BLOCK: [u8; 6] = [0x01, 0x05, 0x00, 0x60, 0x02, 0x01];
const ID_ADS1262_REV3: u8 = 0b000_00011;
const POWER_AFTER_RESET: u8 = 0x11;

fn command(op: u8) -> Vec<SpiT<u8>> {
    write_frame(vec![op])
}

fn rreg(addr: u8, values: &[u8]) -> Vec<SpiT<u8>> {
    let mut sent = vec![RREG | addr, values.len() as u8 - 1];
    sent.extend(std::iter::repeat_n(0u8, values.len()));
    let mut answer = vec![0xFF, 0xFF];
    answer.extend_from_slice(values);
    transfer_frame(sent, answer)
}

fn wreg(addr: u8, values: &[u8]) -> Vec<SpiT<u8>> {
    let mut sent = vec![WREG | addr, values.len() as u8 - 1];
    sent.extend_from_slice(values);
    write_frame(sent)
}

fn rdata1(answer: &[u8]) -> Vec<SpiT<u8>> {
    let mut sent = vec![RDATA1];
    sent.extend(std::iter::repeat_n(0u8, answer.len()));
    let mut resp = vec![0xFF];
    resp.extend_from_slice(answer);
    transfer_frame(sent, resp)
}

fn board_init() -> Vec<SpiT<u8>> {
    init_writing(&BOARD_BLOCK, 0x00)
}

/// `init` of a configuration whose POWER..INPMUX block is `block` and REFMUX `refmux`: reset,
/// ID, the block written and read back, REFMUX written and read back, START1.
fn init_writing(block: &[u8], refmux: u8) -> Vec<SpiT<u8>> {
    [
        command(RESET),
        rreg(ID, &[ID_ADS1262_REV3, POWER_AFTER_RESET]),
        wreg(POWER, block),
        rreg(POWER, block),
        wreg(REFMUX, &[refmux]),
        rreg(REFMUX, &[refmux]),
        command(START1),
    ]
    .concat()
}

/// `read_conversion` of the board configuration on one RDATA1 answer (status, four data bytes,
/// check byte), the mock then checked done.
fn conversion_of(answer: &[u8]) -> Result<Sample, DriverError<SpiMock<u8>, PinMock>> {
    let mut d = driver(&rdata1(answer), &[], config());
    let r = d.read_conversion();
    finish(d);
    r
}

#[test]
fn init_resets_identifies_writes_verifies_and_starts() {
    assert_eq!(
        run(&board_init(), &[], config(), |d| d.init()),
        Ok(DeviceInfo {
            part: Part::Ads1262,
            revision: 3
        })
    );
}

#[test]
fn chop_delay_fir_and_external_reference_are_encoded_as_the_datasheet_says() {
    let cfg = Ads1262Config {
        chop: Chop::Input,
        delay_code: 3,
        filter: Filter::Fir,
        data_rate: DataRate::Sps20,
        ref_positive: RefPositive::Ain4,
        ref_negative: RefNegative::Ain5,
        internal_reference: false,
        integrity: Integrity::Crc,
        ..config()
    };
    // POWER 0x00 (INTREF off); INTERFACE STATUS | CRC=10 → 0x06; MODE0 CHOP=01, DELAY=0011 →
    // 0x13; MODE1 FILTER=100 → 0x80; MODE2 gain 1, DR=0100 (20 SPS) → 0x04; INPMUX 0x01.
    // REFMUX RMUXP=011 (AIN4) at [5:3], RMUXN=011 (AIN5) → 0x1B.
    let block = [0x00, 0x06, 0x13, 0x80, 0x04, 0x01];
    let mut d = driver(&init_writing(&block, 0x1B), &[], cfg);
    assert!(d.init().is_ok());
    finish(d);
}

#[test]
fn init_reports_the_register_that_did_not_read_back() {
    let mut back = BOARD_BLOCK;
    back[3] = 0x80; // MODE1 still at its reset value (FIR)
    let spi = [
        command(RESET),
        rreg(ID, &[ID_ADS1262_REV3, POWER_AFTER_RESET]),
        wreg(POWER, &BOARD_BLOCK),
        rreg(POWER, &back),
    ]
    .concat();
    assert_eq!(
        run(&spi, &[], config(), |d| d.init()),
        Err(Error::ReadBack {
            register: MODE1,
            written: 0x60,
            read: 0x80
        })
    );
}

#[test]
fn init_rejects_a_foreign_device_id() {
    let spi = [command(RESET), rreg(ID, &[0b010_00001, 0x11])].concat();
    assert_eq!(
        run(&spi, &[], config(), |d| d.init()),
        Err(Error::DeviceId { found: 0x41 })
    );
}

#[test]
fn init_accepts_the_ads1263() {
    let mut spi = board_init();
    spi.splice(3..6, rreg(ID, &[0b001_00010, POWER_AFTER_RESET]));
    let mut d = driver(&spi, &[], config());
    assert_eq!(d.init().map(|i| i.part), Ok(Part::Ads1263));
    finish(d);
}

#[test]
fn init_reports_an_idle_bus_as_not_responding() {
    for idle in [0x00u8, 0xFF] {
        let spi = [command(RESET), rreg(ID, &[idle, idle])].concat();
        assert_eq!(
            run(&spi, &[], config(), |d| d.init()),
            Err(Error::NotResponding { found: idle })
        );
    }
}

#[test]
fn init_notices_a_reset_command_that_did_not_arrive() {
    // POWER without its RESET flag right after RESET: the command was lost.
    let spi = [command(RESET), rreg(ID, &[ID_ADS1262_REV3, 0x01])].concat();
    assert_eq!(
        run(&spi, &[], config(), |d| d.init()),
        Err(Error::NotResponding { found: 0x01 })
    );
}

#[test]
fn init_refuses_impossible_configurations_without_touching_the_bus() {
    let base = config();
    let fir_fast = Ads1262Config {
        filter: Filter::Fir,
        data_rate: DataRate::Sps100,
        ..base
    };
    let no_intref = Ads1262Config {
        internal_reference: false,
        ..base
    };
    let ref_on_signal_pin = Ads1262Config {
        ref_positive: RefPositive::Ain2,
        ..base
    };
    let bad_delay = Ads1262Config {
        delay_code: 12,
        ..base
    };
    for cfg in [fir_fast, no_intref, ref_on_signal_pin, bad_delay] {
        assert_eq!(run(&[], &[], cfg, |d| d.init()), Err(Error::InvalidConfig));
    }
}

#[test]
fn conversion_with_good_checksum_is_decoded() {
    // 0x12+0x34+0x56+0x78 = 0x114; + 0x9B = 0x1AF → checksum 0xAF.
    assert_eq!(
        conversion_of(&[0x40, 0x12, 0x34, 0x56, 0x78, 0xAF]).map(|s| (s.code, s.status)),
        Ok((Ads1262Code(0x1234_5678), Some(Status(0x40))))
    );
}

#[test]
fn negative_conversion_is_sign_extended() {
    // 0xFF+0xFF+0xFF+0xFE = 0x3FB; + 0x9B = 0x496 → 0x96.
    assert_eq!(
        conversion_of(&[0x40, 0xFF, 0xFF, 0xFF, 0xFE, 0x96]).map(|s| s.code),
        Ok(Ads1262Code(-2))
    );
}

#[test]
fn corrupted_frame_fails_the_checksum() {
    assert_eq!(
        conversion_of(&[0x40, 0x12, 0x34, 0x56, 0x78, 0xAE]),
        Err(Error::Checksum {
            expected: 0xAF,
            received: 0xAE
        })
    );
}

#[test]
fn crc_mode_accepts_a_good_crc_and_rejects_a_bad_one() {
    let cfg = Ads1262Config {
        integrity: Integrity::Crc,
        ..config()
    };
    let data = [0x00, 0x80, 0x00, 0x01];
    let crc = crc8_reference(&data);
    let good = [&[0x40][..], &data, &[crc]].concat();
    let bad = [&[0x40][..], &data, &[crc ^ 0x01]].concat();
    let spi = [rdata1(&good), rdata1(&bad)].concat();
    let mut d = driver(&spi, &[], cfg);
    assert_eq!(
        d.read_conversion().map(|s| s.code),
        Ok(Ads1262Code(0x0080_0001))
    );
    assert_eq!(
        d.read_conversion(),
        Err(Error::CrcMismatch {
            expected: crc,
            received: crc ^ 0x01
        })
    );
    finish(d);
}

#[test]
fn frame_without_status_and_check_byte_is_four_bytes() {
    let cfg = Ads1262Config {
        status_byte: false,
        integrity: Integrity::None,
        ..config()
    };
    let spi = rdata1(&[0x7F, 0x00, 0x00, 0x00]);
    let mut d = driver(&spi, &[], cfg);
    assert_eq!(
        d.read_conversion().map(|s| (s.code, s.status)),
        Ok((Ads1262Code(0x7F00_0000), None))
    );
    finish(d);
}

#[test]
fn status_alarms_are_reported_with_the_code() {
    // ADC1 new data + REF_ALM + PGAD_ALM; checksum of 00 00 01 00 = 0x01 + 0x9B = 0x9C.
    let status =
        conversion_of(&[0x40 | 0x10 | 0x02, 0x00, 0x00, 0x01, 0x00, 0x9C]).map(|s| s.status);
    let Ok(Some(st)) = status else {
        panic!("no status byte decoded: {status:?}");
    };
    assert!(st.reference_alarm() && st.pga_differential_alarm() && st.any_alarm());
    assert!(!st.pga_low_alarm() && !st.pga_high_alarm());
}

#[test]
fn status_reset_flag_is_an_unexpected_reset() {
    assert_eq!(
        conversion_of(&[0x41, 0x00, 0x00, 0x00, 0x00, 0x9B]),
        Err(Error::UnexpectedReset)
    );
}

#[test]
fn conversion_without_new_data_flag_is_stale() {
    assert_eq!(
        conversion_of(&[0x00, 0x00, 0x00, 0x00, 0x00, 0x9B]),
        Err(Error::StaleData)
    );
}

#[test]
fn read_channel_switches_the_mux_restarts_and_waits_for_drdy() {
    // Tiltmeter on AIN2/AIN3 at gain 1: only INPMUX changes → 0x23.
    let spi = [
        board_init(),
        wreg(INPMUX, &[0x23]),
        rreg(INPMUX, &[0x23]),
        command(START1),
        rdata1(&[0x40, 0x00, 0x00, 0x00, 0x10, 0xAB]),
        // Same channel again: no mux traffic, just the next conversion.
        rdata1(&[0x40, 0x00, 0x00, 0x00, 0x11, 0xAC]),
    ]
    .concat();
    let pin = [
        PinT::get(State::High),
        PinT::get(State::Low),
        PinT::get(State::Low),
    ];
    let mut d = driver(&spi, &pin, config());
    assert!(d.init().is_ok());
    assert_eq!(
        d.read_channel(Channel::Tiltmeter)
            .map(|a| (a.channel, a.sample.code)),
        Ok((Channel::Tiltmeter, Ads1262Code(0x10)))
    );
    assert_eq!(
        d.read_channel(Channel::Tiltmeter).map(|b| b.sample.code),
        Ok(Ads1262Code(0x11))
    );
    finish(d);
}

#[test]
fn read_channel_rewrites_the_gain_when_channels_differ() {
    let mut cfg = config();
    cfg.channels.tiltmeter.pga = Pga::Enabled(Gain::G8);
    // MODE2 gain 8 = GAIN 011 at [6:4], DR 10 SPS → 0x32; accelerometer back at gain 1 → 0x02.
    let spi = [
        board_init(),
        wreg(MODE2, &[0x32, 0x23]),
        rreg(MODE2, &[0x32, 0x23]),
        command(START1),
        rdata1(&[0x40, 0x00, 0x00, 0x00, 0x00, 0x9B]),
        wreg(MODE2, &[0x02, 0x01]),
        rreg(MODE2, &[0x02, 0x01]),
        command(START1),
        rdata1(&[0x40, 0x00, 0x00, 0x00, 0x00, 0x9B]),
    ]
    .concat();
    let pin = [PinT::get(State::Low), PinT::get(State::Low)];
    let mut d = driver(&spi, &pin, cfg);
    assert!(d.init().is_ok());
    assert!(d.read_channel(Channel::Tiltmeter).is_ok());
    assert!(d.read_channel(Channel::Accelerometer).is_ok());
    finish(d);
}

#[test]
fn failed_mux_switch_is_retried_on_the_next_read() {
    let spi = [
        board_init(),
        wreg(INPMUX, &[0x23]),
        rreg(INPMUX, &[0x01]), // did not take
        // State unknown after the failure: the retry rewrites MODE2 (gain 1, 10 SPS) as well.
        wreg(MODE2, &[0x02, 0x23]),
        rreg(MODE2, &[0x02, 0x23]),
        command(START1),
        rdata1(&[0x40, 0x00, 0x00, 0x00, 0x00, 0x9B]),
    ]
    .concat();
    let mut d = driver(&spi, &[PinT::get(State::Low)], config());
    assert!(d.init().is_ok());
    assert_eq!(
        d.read_channel(Channel::Tiltmeter),
        Err(Error::ReadBack {
            register: INPMUX,
            written: 0x23,
            read: 0x01
        })
    );
    assert!(d.read_channel(Channel::Tiltmeter).is_ok());
    finish(d);
}

/// DRDY that never falls times out after the poll limit; a failing pin is a pin error.
#[test]
fn drdy_failures_are_named() {
    check_drdy_failures(config(), |d| d.wait_drdy(), Error::DrdyTimeout, Error::Pin);
}

#[test]
fn start_and_stop_send_their_opcodes() {
    let spi = [command(START1), command(STOP1)].concat();
    let mut d = driver(&spi, &[], config());
    assert_eq!(d.start(), Ok(()));
    assert_eq!(d.stop(), Ok(()));
    finish(d);
}

/// An SPI device whose every transfer fails, as a broken bus would.
#[test]
fn bus_failure_is_reported_as_spi_error() {
    let mut d = Ads1262::new(BrokenBus, PinMock::new(&[]), NoopDelay::new(), config());
    assert_eq!(d.init(), Err(Error::Spi(ErrorKind::Other)));
    assert_eq!(d.read_conversion(), Err(Error::Spi(ErrorKind::Other)));
    let (_, mut pin, _) = d.release();
    pin.done();
}

#[test]
fn scale_uses_the_channel_gain_and_reads_one_g_as_1_33_volts() {
    let mut cfg = config();
    cfg.channels.tiltmeter.pga = Pga::Enabled(Gain::G8);
    let acc = cfg.scale(Channel::Accelerometer, crate::units::Volts(2.5));
    let tilt = cfg.scale(Channel::Tiltmeter, crate::units::Volts(2.5));
    assert_eq!((acc.bits, acc.pga_gain, tilt.pga_gain), (32, 1.0, 8.0));
    // 1.33 V at gain 1, Vref 2.5 V: code = 1.33 / 2.5 · 2^31 = 1 142 461 300.7 → 1 142 461 301.
    let v = acc.volts(Ads1262Code(1_142_461_301).raw());
    assert!(v.is_ok_and(|v| (v.0 - 1.33).abs() < 2e-9), "{v:?}");
}
