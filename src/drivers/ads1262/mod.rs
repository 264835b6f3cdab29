//! TI ADS1262 (32-bit ΔΣ, ADC1 only) driver: accelerometer torquer-current sense and tiltmeter.
//!
//! The board wires the accelerometer's sense resistor and the tiltmeter's analog output to two
//! differential input pairs; [`Ads1262::read_channel`] switches INPMUX between them, restarts the
//! conversion so the first result is fully settled on the new input, waits for DRDY (bounded),
//! reads the frame with RDATA1 and checks its checksum/CRC and status byte.
//!
//! Register-level choices and their reasons: `docs/drivers.md`. Register map: [`registers`].

pub mod registers;
#[cfg(test)]
mod tests;

use embedded_hal::delay::DelayNs;
use embedded_hal::digital::InputPin;
use embedded_hal::spi::{Mode, SpiDevice, MODE_1};

use crate::adc::{AdcScale, Ads1262Code, Coding};
use crate::drivers::{wait_low, CRC8_ATM};
use crate::units::Volts;
use registers::{cmd, reg, status};
pub use registers::{
    Chop, DataRate, Filter, Gain, Input, Integrity, Pga, RefNegative, RefPositive,
};

/// Time to wait after the RESET command before talking to the device, in microseconds.
///
/// SBAS661C gives the reset time as 2^16 f_CLK periods after power-up (8.9 ms at the internal
/// 7.3728 MHz oscillator); we wait 10 ms after the command too, since init runs once and a short
/// wait would make the ID read race the internal reset.
pub const RESET_WAIT_US: u32 = 10_000;

/// SPI mode the ADS1262 requires: CPOL = 0, CPHA = 1 (SBAS661C, "Serial Interface" and the
/// serial-interface timing figure: SCLK idles low, DIN is latched and DOUT updated so that data
/// are valid on the SCLK falling edge).
pub const SPI_MODE: Mode = MODE_1;

/// Fastest SCLK the ADS1262 accepts, in hertz: tc(SC) ≥ 125 ns in SBAS661C "Timing
/// Requirements: Serial Interface" (8 MHz). The board runs it well below (docs/drivers.md).
pub const MAX_SCLK_HZ: u32 = 8_000_000;

/// One of the two signals the board feeds to the ADS1262.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Channel {
    /// Accelerometer torquer current across the precision sense resistor.
    Accelerometer,
    /// Tiltmeter analog output.
    Tiltmeter,
}

/// Input pair and PGA of one channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ChannelConfig {
    /// Positive input (INPMUX.MUXP).
    pub positive: Input,
    /// Negative input (INPMUX.MUXN).
    pub negative: Input,
    /// PGA gain or bypass (MODE2).
    pub pga: Pga,
}

impl ChannelConfig {
    const fn inpmux(&self) -> u8 {
        (self.positive.bits() << 4) | self.negative.bits()
    }
}

/// Where the board's two signals are wired.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BoardChannels {
    /// Accelerometer sense-resistor voltage.
    pub accelerometer: ChannelConfig,
    /// Tiltmeter output.
    pub tiltmeter: ChannelConfig,
}

impl BoardChannels {
    const fn get(&self, channel: Channel) -> &ChannelConfig {
        match channel {
            Channel::Accelerometer => &self.accelerometer,
            Channel::Tiltmeter => &self.tiltmeter,
        }
    }
}

/// Complete ADS1262 configuration: filter, data rate, chop, start delay, reference, status and
/// check bytes, the two input channels, and how long to poll DRDY.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ads1262Config {
    /// Digital filter (MODE1).
    pub filter: Filter,
    /// Output data rate (MODE2).
    pub data_rate: DataRate,
    /// Chop mode (MODE0).
    pub chop: Chop,
    /// Conversion start delay code (MODE0.DELAY, 0 = none … 11 = 8.8 ms).
    pub delay_code: u8,
    /// Positive reference (REFMUX).
    pub ref_positive: RefPositive,
    /// Negative reference (REFMUX).
    pub ref_negative: RefNegative,
    /// Internal 2.5 V reference enabled (POWER.INTREF); required when a reference is internal.
    pub internal_reference: bool,
    /// Status byte before the data (INTERFACE.STATUS).
    pub status_byte: bool,
    /// Checksum or CRC byte after the data (INTERFACE.CRC).
    pub integrity: Integrity,
    /// The two board channels.
    pub channels: BoardChannels,
    /// Maximum number of DRDY polls before [`Error::DrdyTimeout`].
    pub drdy_poll_limit: u32,
    /// Wait between two DRDY polls, in microseconds.
    pub drdy_poll_interval_us: u32,
}

impl Ads1262Config {
    /// How [`crate::adc::AdcScale`] must read a channel's codes: 32-bit two's complement, the
    /// channel's PGA gain (1 when bypassed) and `vref` (2.5 V for the internal reference).
    pub fn scale(&self, channel: Channel, vref: Volts) -> AdcScale {
        let pga_gain = match self.channels.get(channel).pga {
            Pga::Enabled(g) => g.factor(),
            Pga::Bypassed => 1.0,
        };
        code_scale(pga_gain, vref, 1.0, Volts(0.0))
    }

    /// Refuse settings the chip would accept but that cannot work on purpose.
    fn validate(&self) -> bool {
        let channels = [self.channels.accelerometer, self.channels.tiltmeter];
        let ref_pins = [self.ref_positive.pin(), self.ref_negative.pin()];
        let needs_intref = matches!(self.ref_positive, RefPositive::Internal)
            || matches!(self.ref_negative, RefNegative::Internal);
        let pins_distinct = channels.iter().all(|c| {
            c.positive != c.negative
                && ref_pins
                    .iter()
                    .flatten()
                    .all(|p| *p != c.positive && *p != c.negative)
        });
        self.delay_code <= 11
            && (self.filter != Filter::Fir || self.data_rate.supports_fir())
            && (!needs_intref || self.internal_reference)
            && self.drdy_poll_limit > 0
            && pins_distinct
    }

    const fn power(&self) -> u8 {
        // RESET bit written 0: clears the "device was reset" flag, so a later 1 means a new reset.
        if self.internal_reference {
            registers::POWER_INTREF
        } else {
            0
        }
    }

    const fn interface(&self) -> u8 {
        let status = if self.status_byte {
            registers::INTERFACE_STATUS
        } else {
            0
        };
        status | self.integrity.bits()
    }

    const fn mode0(&self) -> u8 {
        // REFREV = 0, RUNMODE = 0 (continuous): read_channel restarts with START1 after a switch.
        (self.chop.bits() << 4) | (self.delay_code & 0x0F)
    }

    const fn mode1(&self) -> u8 {
        // Sensor-bias current source off (SBADC/SBPOL/SBMAG = 0): it would load the sense resistor.
        self.filter.bits() << 5
    }

    const fn mode2(&self, channel: &ChannelConfig) -> u8 {
        let pga = match channel.pga {
            Pga::Enabled(g) => g.bits() << 4,
            Pga::Bypassed => registers::MODE2_BYPASS,
        };
        pga | self.data_rate.bits()
    }

    const fn refmux(&self) -> u8 {
        (self.ref_positive.bits() << 3) | self.ref_negative.bits()
    }
}

/// Which part answered the ID read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Part {
    /// ADS1262 (DEV_ID 000).
    Ads1262,
    /// ADS1263 (DEV_ID 001): same ADC1, plus ADC2 the driver leaves off.
    Ads1263,
}

/// Identity read during [`Ads1262::init`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DeviceInfo {
    /// Part from DEV_ID.
    pub part: Part,
    /// Silicon revision REV_ID[4:0].
    pub revision: u8,
}

/// The status byte that precedes the data (SBAS661C "Status Byte").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Status(pub u8);

impl Status {
    /// ADC1 has produced a new conversion since the last read.
    pub const fn adc1_new_data(self) -> bool {
        self.0 & status::ADC1 != 0
    }
    /// Low-reference alarm: the reference voltage collapsed (open or shorted reference).
    pub const fn reference_alarm(self) -> bool {
        self.0 & status::REF_ALM != 0
    }
    /// PGA output below its low limit (input below the common-mode range).
    pub const fn pga_low_alarm(self) -> bool {
        self.0 & status::PGAL_ALM != 0
    }
    /// PGA output above its high limit (input above the common-mode range).
    pub const fn pga_high_alarm(self) -> bool {
        self.0 & status::PGAH_ALM != 0
    }
    /// PGA differential output over range.
    pub const fn pga_differential_alarm(self) -> bool {
        self.0 & status::PGAD_ALM != 0
    }
    /// Any analog alarm: the code must not be trusted as a measurement.
    pub const fn any_alarm(self) -> bool {
        self.0 & (status::REF_ALM | status::PGAL_ALM | status::PGAH_ALM | status::PGAD_ALM) != 0
    }
    /// The device reset since its POWER.RESET bit was last cleared.
    pub const fn reset(self) -> bool {
        self.0 & status::RESET != 0
    }
    /// An external clock is in use.
    pub const fn external_clock(self) -> bool {
        self.0 & status::EXTCLK != 0
    }
    /// ADC2 new data (ADS1263 only; ADC2 stays off here).
    pub const fn adc2_new_data(self) -> bool {
        self.0 & status::ADC2 != 0
    }
}

/// One checked ADC1 conversion.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sample {
    /// The conversion result.
    pub code: Ads1262Code,
    /// The status byte, if enabled (analog alarms are reported here, not as errors, so the
    /// stream can carry the raw code with a flag).
    pub status: Option<Status>,
}

/// A conversion read on one of the board channels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ChannelSample {
    /// Which input pair was converted.
    pub channel: Channel,
    /// The checked conversion.
    pub sample: Sample,
}

converter_error! {
    /// Checksum mode: the received checksum byte differs from the sum of the data bytes + 0x9B.
    Checksum {
        /// Checksum computed from the received data bytes.
        expected: u8,
        /// Checksum byte the converter sent.
        received: u8,
    },
    /// The status byte says no new conversion since the last read (stale data).
    StaleData,
}

/// ADC1 result width (SBAS661C "Data Format": 32-bit two's complement).
pub const CODE_BITS: u8 = 32;

/// How ADC1 codes read: 32-bit two's complement, ±`vref`/`pga_gain` at full scale, then the
/// calibration's `gain_correction` and `offset` (the board decides these; the chip only its
/// coding).
pub const fn code_scale(
    pga_gain: f64,
    vref: Volts,
    gain_correction: f64,
    offset: Volts,
) -> AdcScale {
    AdcScale {
        bits: CODE_BITS,
        coding: Coding::TwosComplement,
        pga_gain,
        vref,
        gain_correction,
        offset,
    }
}

/// The ADS1262 on an SPI device, with its DRDY pin and a delay source.
pub struct Ads1262<SPI, DRDY, D> {
    spi: SPI,
    drdy: DRDY,
    delay: D,
    config: Ads1262Config,
    /// Channel whose INPMUX/MODE2 the device holds, `None` before init.
    selected: Option<Channel>,
}

impl<SPI, DRDY, D> Ads1262<SPI, DRDY, D>
where
    SPI: SpiDevice,
    DRDY: InputPin,
    D: DelayNs,
{
    /// Wrap the bus, pin and delay. Nothing is sent until [`Ads1262::init`].
    pub const fn new(spi: SPI, drdy: DRDY, delay: D, config: Ads1262Config) -> Self {
        Self {
            spi,
            drdy,
            delay,
            config,
            selected: None,
        }
    }

    /// Give the bus, pin and delay back.
    pub fn release(self) -> (SPI, DRDY, D) {
        (self.spi, self.drdy, self.delay)
    }

    /// The configuration in use.
    pub const fn config(&self) -> &Ads1262Config {
        &self.config
    }

    /// Reset, identify, configure (with read-back) and start ADC1 on the accelerometer channel.
    /// Blocks [`RESET_WAIT_US`] in the middle; interrupt-driven code uses
    /// [`Ads1262::begin_reset`] and, [`RESET_WAIT_US`] later, [`Ads1262::configure`] instead.
    pub fn init(&mut self) -> Result<DeviceInfo, DriverError<SPI, DRDY>> {
        self.begin_reset()?;
        self.delay.delay_us(RESET_WAIT_US);
        self.configure()
    }

    /// First half of [`Ads1262::init`]: check the configuration and send RESET. The device must
    /// be left alone for [`RESET_WAIT_US`] before [`Ads1262::configure`].
    pub fn begin_reset(&mut self) -> Result<(), DriverError<SPI, DRDY>> {
        if !self.config.validate() {
            return Err(Error::InvalidConfig);
        }
        self.selected = None;
        self.command(cmd::RESET)
    }

    /// ID and POWER in one RREG (diagnosis: POWER.RESET = 1 means the device reset since it
    /// was configured; an idle bus reads all ones or all zeros).
    pub fn read_id_power(&mut self) -> Result<(u8, u8), DriverError<SPI, DRDY>> {
        let mut id_power = [0u8; 2];
        self.read_registers(reg::ID, &mut id_power)?;
        let [id, power] = id_power;
        Ok((id, power))
    }

    /// Second half of [`Ads1262::init`], after the reset wait: identify, write and verify the
    /// configuration, start ADC1 on the accelerometer channel.
    pub fn configure(&mut self) -> Result<DeviceInfo, DriverError<SPI, DRDY>> {
        if !self.config.validate() {
            return Err(Error::InvalidConfig);
        }
        self.selected = None;
        // ID and POWER in one RREG: POWER must show the RESET flag the command just set.
        let (id, power) = self.read_id_power()?;
        if id == 0xFF || (id == 0x00 && power == 0x00) {
            return Err(Error::NotResponding { found: id });
        }
        let part = match id >> registers::ID_DEV_ID_SHIFT {
            0b000 => Part::Ads1262,
            0b001 => Part::Ads1263,
            _ => return Err(Error::DeviceId { found: id }),
        };
        if power & registers::POWER_RESET == 0 {
            // A live ADS1262 always reports RESET = 1 right after a reset: the command was lost.
            return Err(Error::NotResponding { found: power });
        }

        let cfg = self.config;
        let first = cfg.channels.accelerometer;
        // POWER..INPMUX are consecutive (0x01..0x06): one WREG, one RREG to verify.
        let block = [
            cfg.power(),
            cfg.interface(),
            cfg.mode0(),
            cfg.mode1(),
            cfg.mode2(&first),
            first.inpmux(),
        ];
        self.write_verified(reg::POWER, &block)?;
        self.write_verified(reg::REFMUX, &[cfg.refmux()])?;
        self.selected = Some(Channel::Accelerometer);
        self.command(cmd::START1)?;
        Ok(DeviceInfo {
            part,
            revision: id & 0x1F,
        })
    }

    /// Change the output data rate (MODE2.DR). Takes effect at the next channel selection,
    /// which then rewrites MODE2 with the new rate (and restarts the conversion).
    pub fn set_data_rate(&mut self, rate: DataRate) -> Result<(), DriverError<SPI, DRDY>> {
        let mut next = self.config;
        next.data_rate = rate;
        if !next.validate() {
            return Err(Error::InvalidConfig);
        }
        self.config = next;
        // Forgetting the selection makes the next select write MODE2 and INPMUX together.
        self.selected = None;
        Ok(())
    }

    /// Start (or restart) ADC1 conversions (START1).
    pub fn start(&mut self) -> Result<(), DriverError<SPI, DRDY>> {
        self.command(cmd::START1)
    }

    /// Stop ADC1 conversions (STOP1).
    pub fn stop(&mut self) -> Result<(), DriverError<SPI, DRDY>> {
        self.command(cmd::STOP1)
    }

    /// Poll DRDY (active low) at most `drdy_poll_limit` times.
    pub fn wait_drdy(&mut self) -> Result<(), DriverError<SPI, DRDY>> {
        let (limit, interval_us) = (
            self.config.drdy_poll_limit,
            self.config.drdy_poll_interval_us,
        );
        wait_low(&mut self.drdy, &mut self.delay, limit, interval_us).map_err(Error::from)
    }

    /// Read the latest ADC1 conversion with RDATA1 and check it (no DRDY wait).
    ///
    /// Fails with [`Error::Checksum`]/[`Error::CrcMismatch`] on a corrupted frame,
    /// [`Error::UnexpectedReset`] if the device lost its configuration, and
    /// [`Error::StaleData`] if the status byte says this conversion was already read.
    pub fn read_conversion(&mut self) -> Result<Sample, DriverError<SPI, DRDY>> {
        // Opcode, then status, 4 data bytes, check byte; 0x00 (NOP) clocked out meanwhile so
        // nothing the ADC reads on DIN during the data phase can be taken for a command.
        let mut frame = [0u8; 7];
        let len = 1
            + usize::from(self.config.status_byte)
            + 4
            + usize::from(self.config.integrity != Integrity::None);
        let buf = frame.get_mut(..len).ok_or(Error::InvalidConfig)?;
        if let Some(first) = buf.first_mut() {
            *first = cmd::RDATA1;
        }
        self.spi.transfer_in_place(buf).map_err(Error::Spi)?;
        let rest = buf.get(1..).ok_or(Error::InvalidConfig)?;
        parse_frame(rest, self.config.status_byte, self.config.integrity)
    }

    /// Convert one board channel: switch the input mux (and PGA) if needed, restart the
    /// conversion so the result is settled on the new input, wait for DRDY, read and check.
    pub fn read_channel(
        &mut self,
        channel: Channel,
    ) -> Result<ChannelSample, DriverError<SPI, DRDY>> {
        if self.selected != Some(channel) {
            self.select(channel)?;
        }
        self.wait_drdy()?;
        let sample = self.read_conversion()?;
        Ok(ChannelSample { channel, sample })
    }

    /// The channel the device converts, `None` before init or after a failed switch.
    pub const fn selected(&self) -> Option<Channel> {
        self.selected
    }

    /// Switch to `channel` (if not already there) and restart the conversion, without waiting:
    /// for DRDY-interrupt-driven acquisition, where the next DRDY edge announces the settled
    /// conversion of the new input. [`Ads1262::read_channel`] is the polled equivalent.
    pub fn select_channel(&mut self, channel: Channel) -> Result<(), DriverError<SPI, DRDY>> {
        if self.selected == Some(channel) {
            return Ok(());
        }
        self.select(channel)
    }

    fn select(&mut self, channel: Channel) -> Result<(), DriverError<SPI, DRDY>> {
        let cfg = self.config;
        let next = *cfg.channels.get(channel);
        let previous = self.selected.map(|c| *cfg.channels.get(c));
        // Forget the selection until the write is verified: a failed switch must not leave the
        // driver believing the mux points where it does not.
        self.selected = None;
        if previous.map(|p| cfg.mode2(&p)) == Some(cfg.mode2(&next)) {
            self.write_verified(reg::INPMUX, &[next.inpmux()])?;
        } else {
            // MODE2 and INPMUX are consecutive (0x05, 0x06).
            self.write_verified(reg::MODE2, &[cfg.mode2(&next), next.inpmux()])?;
        }
        self.selected = Some(channel);
        // START1 while running restarts the conversion: the next DRDY is a full, settled
        // conversion of the new input, never a result straddling the switch.
        self.command(cmd::START1)
    }

    fn command(&mut self, opcode: u8) -> Result<(), DriverError<SPI, DRDY>> {
        self.spi.write(&[opcode]).map_err(Error::Spi)
    }

    /// RREG: opcode | address, count − 1, then the register bytes (≤ 8 at a time here).
    fn read_registers(&mut self, start: u8, out: &mut [u8]) -> Result<(), DriverError<SPI, DRDY>> {
        let mut frame = [0u8; 2 + MAX_BLOCK];
        let count = u8::try_from(out.len())
            .ok()
            .filter(|n| (1..=MAX_BLOCK as u8).contains(n))
            .ok_or(Error::InvalidConfig)?;
        let buf = frame.get_mut(..2 + out.len()).ok_or(Error::InvalidConfig)?;
        if let [op, n, ..] = buf {
            *op = cmd::RREG | (start & 0x1F);
            *n = count - 1;
        }
        self.spi.transfer_in_place(buf).map_err(Error::Spi)?;
        let data = buf.get(2..).ok_or(Error::InvalidConfig)?;
        out.copy_from_slice(data);
        Ok(())
    }

    /// WREG then RREG the same block; report the first register that differs.
    fn write_verified(&mut self, start: u8, values: &[u8]) -> Result<(), DriverError<SPI, DRDY>> {
        let count = u8::try_from(values.len())
            .ok()
            .filter(|n| (1..=MAX_BLOCK as u8).contains(n))
            .ok_or(Error::InvalidConfig)?;
        let mut frame = [0u8; 2 + MAX_BLOCK];
        let buf = frame
            .get_mut(..2 + values.len())
            .ok_or(Error::InvalidConfig)?;
        if let [op, n, data @ ..] = buf {
            *op = cmd::WREG | (start & 0x1F);
            *n = count - 1;
            data.copy_from_slice(values);
        }
        self.spi.write(buf).map_err(Error::Spi)?;

        let mut back = [0u8; MAX_BLOCK];
        let back = back.get_mut(..values.len()).ok_or(Error::InvalidConfig)?;
        self.read_registers(start, back)?;
        for (offset, (w, r)) in (0u8..).zip(values.iter().zip(back.iter())) {
            if w != r {
                return Err(Error::ReadBack {
                    register: start + offset,
                    written: u32::from(*w),
                    read: u32::from(*r),
                });
            }
        }
        Ok(())
    }
}

/// Longest register block the driver reads or writes in one command.
const MAX_BLOCK: usize = 8;

// `init` writes POWER..INPMUX as one block and `select` writes MODE2, INPMUX as one: both rely on
// these registers being consecutive in the map.
const _: () = assert!(
    reg::INTERFACE == reg::POWER + 1
        && reg::MODE0 == reg::POWER + 2
        && reg::MODE1 == reg::POWER + 3
        && reg::MODE2 == reg::POWER + 4
        && reg::INPMUX == reg::MODE2 + 1
);

/// Check and decode the bytes after the RDATA1 opcode.
fn parse_frame<SpiE, PinE>(
    bytes: &[u8],
    has_status: bool,
    integrity: Integrity,
) -> Result<Sample, Error<SpiE, PinE>> {
    // Every byte 0xFF (MISO pulled high, chip unpowered) or 0x00 (MISO stuck low) can never be
    // a valid frame: such a status byte would claim a reset (0xFF) or no data (0x00), and the
    // checksum of four equal bytes is never that byte. Name it instead of calling it corrupt.
    if let Some(&first) = bytes.first() {
        if (first == 0xFF || first == 0x00) && bytes.iter().all(|b| *b == first) {
            return Err(Error::NotResponding { found: first });
        }
    }
    let (status, rest) = if has_status {
        let (s, rest) = bytes.split_first().ok_or(Error::InvalidConfig)?;
        (Some(Status(*s)), rest)
    } else {
        (None, bytes)
    };
    let (data, rest) = rest.split_first_chunk::<4>().ok_or(Error::InvalidConfig)?;
    match integrity {
        Integrity::None => {}
        Integrity::Checksum => {
            let received = *rest.first().ok_or(Error::InvalidConfig)?;
            let expected = data
                .iter()
                .fold(registers::CHECKSUM_OFFSET, |acc, b| acc.wrapping_add(*b));
            if expected != received {
                return Err(Error::Checksum { expected, received });
            }
        }
        Integrity::Crc => {
            let received = *rest.first().ok_or(Error::InvalidConfig)?;
            let expected = CRC8_ATM.checksum(data);
            if expected != received {
                return Err(Error::CrcMismatch { expected, received });
            }
        }
    }
    if let Some(s) = status {
        if s.reset() {
            return Err(Error::UnexpectedReset);
        }
        if !s.adc1_new_data() {
            return Err(Error::StaleData);
        }
    }
    Ok(Sample {
        code: Ads1262Code(i32::from_be_bytes(*data)),
        status,
    })
}
