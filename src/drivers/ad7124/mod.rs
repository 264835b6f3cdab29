//! ADI AD7124-4 (24-bit ΔΣ) driver: 4-wire Pt100 measured ratiometrically (ADI CN-0381 scheme).
//!
//! IOUT0 drives the excitation current through the RTD and, in series, the reference resistor
//! across REFIN1±; the ADC measures the RTD sense leads against that reference, so the code is
//! R_rtd · gain / R_ref · 2^24 whatever the exact current (see [`crate::adc::AdcScale::ratiometric_ohms`]).
//!
//! Every access starts with the communications byte (WEN = 0, R/W, 6-bit address) followed by
//! the register bytes MSB first; with SPI_CRC_ERR_EN set, a CRC-8 (x^8 + x^2 + x + 1) over the
//! communications byte and the data follows each write and each read.
//!
//! Data-ready: [`Ad7124::read_rtd`] polls a DRDY GPIO wired to DOUT/RDY, which only shows RDY
//! while the AD7124's chip select is low, so it needs the AD7124 alone on its bus with CS held
//! low. On a shared bus use [`Ad7124::read_rtd_polled`], which polls the STATUS register instead.
//! Register-level choices and their reasons: `docs/drivers.md`.

pub mod registers;
#[cfg(test)]
mod tests;

use embedded_hal::delay::DelayNs;
use embedded_hal::digital::InputPin;
use embedded_hal::spi::{Mode, SpiDevice, MODE_3};

use crate::adc::{Ad7124Code, AdcScale, Coding};
use crate::drivers::{wait_low, CRC8_ATM};
use crate::units::Volts;
use registers::{adc_control, config, err, status, Reg};
pub use registers::{AnalogInput, Excitation, FilterType, Gain, IoutPin, PowerMode, Reference};

/// SPI mode the AD7124-4 requires: CPOL = 1, CPHA = 1. Datasheet Rev. B, "Timing
/// Characteristics" (Figures 2 and 3, read and write cycle timing): SCLK idles high, DOUT/RDY
/// changes on the falling edge and DIN is sampled on the rising edge. Mode 1 (idle low) would
/// put the first data bit one edge off: ID and read-back fail.
pub const SPI_MODE: Mode = MODE_3;

/// Fastest SCLK the AD7124-4 accepts, in hertz: t3/t4 (SCLK high and low pulse widths) ≥ 100 ns
/// in the Rev. B timing table, i.e. 5 MHz.
pub const MAX_SCLK_HZ: u32 = 5_000_000;

/// Wait after the 64-ones reset before the first access, in microseconds. ADI's reference code
/// waits 4 ms (the datasheet's power-up/reset time is shorter; the margin costs nothing once).
pub const RESET_WAIT_US: u32 = 4_000;

/// Content of the ERROR register (datasheet Rev. B, ERROR register table).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ErrorFlags(pub u32);

impl ErrorFlags {
    const fn has(self, bit: u32) -> bool {
        self.0 & bit != 0
    }
    /// Calibration failed (ADC_CAL_ERR).
    pub const fn calibration(self) -> bool {
        self.has(err::ADC_CAL)
    }
    /// Conversion error / overflow in the modulator or filter (ADC_CONV_ERR).
    pub const fn conversion(self) -> bool {
        self.has(err::ADC_CONV)
    }
    /// The result is clamped at full scale (ADC_SAT_ERR).
    pub const fn saturated(self) -> bool {
        self.has(err::ADC_SAT)
    }
    /// AINP or AINM outside the supply rails (AINx_OV/UV_ERR): broken or shorted lead.
    pub const fn input_out_of_range(self) -> bool {
        self.0 & (err::AINP_OV | err::AINP_UV | err::AINM_OV | err::AINM_UV) != 0
    }
    /// Reference below ~0.7 V (REF_DET_ERR): for the RTD this means no excitation current flows,
    /// i.e. an open RTD loop or reference resistor.
    pub const fn reference_missing(self) -> bool {
        self.has(err::REF_DET)
    }
    /// Analog or digital LDO out of regulation (ALDO/DLDO_PSM_ERR).
    pub const fn supply(self) -> bool {
        self.0 & (err::ALDO_PSM | err::DLDO_PSM) != 0
    }
    /// The ADC saw a bad CRC on a write (SPI_CRC_ERR): that write was ignored.
    pub const fn spi_crc(self) -> bool {
        self.has(err::SPI_CRC)
    }
    /// Any SPI framing problem (SCLK count, read, write, ignored access).
    pub const fn spi(self) -> bool {
        self.0 & (err::SPI_IGNORE | err::SPI_SCLK_CNT | err::SPI_READ | err::SPI_WRITE) != 0
    }
    /// Register-map CRC changed (MM_CRC_ERR): the configuration was corrupted.
    pub const fn register_map_crc(self) -> bool {
        self.has(err::MM_CRC)
    }
}

/// The STATUS byte appended to the data (DATA_STATUS = 1) or read from STATUS.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Status(pub u8);

impl Status {
    /// A new conversion is ready (RDY bit low).
    pub const fn ready(self) -> bool {
        self.0 & status::RDY_N == 0
    }
    /// An enabled error condition is present (read ERROR for which).
    pub const fn error(self) -> bool {
        self.0 & status::ERROR_FLAG != 0
    }
    /// Power-on/reset flag.
    pub const fn power_on_reset(self) -> bool {
        self.0 & status::POR_FLAG != 0
    }
    /// Channel the result belongs to.
    pub const fn channel(self) -> u8 {
        self.0 & status::CH_ACTIVE_MASK
    }
}

/// Complete AD7124-4 configuration: power mode, reference, excitation current and pin, the
/// channel's inputs, coding, buffers and gain, filter, SPI CRC, and how long to poll data-ready.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ad7124Config {
    /// Power mode (ADC_CONTROL.POWER_MODE).
    pub power_mode: PowerMode,
    /// Internal 2.5 V reference enabled (ADC_CONTROL.REF_EN).
    pub internal_reference: bool,
    /// Append STATUS to every DATA read (ADC_CONTROL.DATA_STATUS): each result then carries its
    /// error flag, so a broken RTD cannot pass as a temperature.
    pub data_status: bool,
    /// ADC_CONTROL.CS_EN.
    pub cs_en: bool,
    /// IOUT0 current (IO_CONTROL_1.IOUT0).
    pub excitation: Excitation,
    /// IOUT0 output pin (IO_CONTROL_1.IOUT0_CH).
    pub excitation_pin: IoutPin,
    /// RTD sense, positive input (CHANNEL_0.AINP).
    pub positive: AnalogInput,
    /// RTD sense, negative input (CHANNEL_0.AINM).
    pub negative: AnalogInput,
    /// Bipolar (offset-binary) coding instead of unipolar (CONFIG_0.Bipolar).
    pub bipolar: bool,
    /// Reference (CONFIG_0.REF_SEL).
    pub reference: Reference,
    /// Reference buffers REF_BUFP/REF_BUFM.
    pub reference_buffers: bool,
    /// Analog input buffers AIN_BUFP/AIN_BUFM.
    pub input_buffers: bool,
    /// PGA gain (CONFIG_0.PGA).
    pub gain: Gain,
    /// Filter type (FILTER_0.Filter).
    pub filter: FilterType,
    /// Filter word FS (1..=2047): ODR = f_CLK / (32 · FS).
    pub filter_fs: u16,
    /// SPI CRC on every access (ERROR_EN.SPI_CRC_ERR_EN).
    pub crc: bool,
    /// Maximum number of data-ready polls before [`Error::DrdyTimeout`].
    pub drdy_poll_limit: u32,
    /// Wait between two polls, in microseconds.
    pub drdy_poll_interval_us: u32,
}

impl Ad7124Config {
    /// Output data rate in hertz for this power mode and filter word (sinc3/sinc4, no post filter).
    pub fn output_data_rate_hz(&self) -> f64 {
        f64::from(self.power_mode.clock_hz()) / (32.0 * f64::from(self.filter_fs.max(1)))
    }

    /// How [`crate::adc::AdcScale`] must read this configuration's codes: 24 bits, unipolar or
    /// offset binary, the PGA gain. `vref` is the reference voltage for volt conversions; the
    /// ratiometric RTD path ([`crate::adc::AdcScale::ratiometric_ohms`]) does not depend on it.
    pub fn scale(&self, vref: Volts) -> AdcScale {
        code_scale(self.bipolar, self.gain.factor(), vref, 1.0)
    }

    fn validate(&self) -> bool {
        (1..=registers::FILTER_FS_MAX).contains(&self.filter_fs)
            && (self.reference != Reference::Internal || self.internal_reference)
            && self.positive != self.negative
            && self.drdy_poll_limit > 0
    }

    const fn adc_control(&self) -> u32 {
        let mut v = (self.power_mode.bits() << adc_control::POWER_MODE_SHIFT)
            | (adc_control::MODE_CONTINUOUS << adc_control::MODE_SHIFT);
        if self.data_status {
            v |= adc_control::DATA_STATUS;
        }
        if self.cs_en {
            v |= adc_control::CS_EN;
        }
        if self.internal_reference {
            v |= adc_control::REF_EN;
        }
        v as u32
    }

    const fn io_control_1(&self) -> u32 {
        (self.excitation.bits() << 8) | self.excitation_pin.bits()
    }

    const fn error_en(&self) -> u32 {
        // Every analog and SPI check the part offers except the LDO-capacitor and MCLK tests
        // (they need a test sequence of their own).
        let base = err::ADC_CAL
            | err::ADC_CONV
            | err::ADC_SAT
            | err::AINP_OV
            | err::AINP_UV
            | err::AINM_OV
            | err::AINM_UV
            | err::REF_DET
            | err::DLDO_PSM
            | err::ALDO_PSM
            | err::SPI_IGNORE
            | err::SPI_SCLK_CNT
            | err::SPI_READ
            | err::SPI_WRITE
            | err::MM_CRC;
        if self.crc {
            base | err::SPI_CRC
        } else {
            base
        }
    }

    const fn channel_0(&self) -> u32 {
        // Setup 0, this channel only.
        (registers::CHANNEL_ENABLE | (self.positive.bits() << 5) | self.negative.bits()) as u32
    }

    const fn config_0(&self) -> u32 {
        let mut v = (self.reference.bits() << config::REF_SEL_SHIFT) | self.gain.bits();
        if self.bipolar {
            v |= config::BIPOLAR;
        }
        if self.reference_buffers {
            v |= config::REF_BUFP | config::REF_BUFM;
        }
        if self.input_buffers {
            v |= config::AIN_BUFP | config::AIN_BUFM;
        }
        v as u32
    }

    const fn filter_0(&self) -> u32 {
        (self.filter.bits() << registers::FILTER_TYPE_SHIFT) | self.filter_fs as u32
    }
}

/// Identity read during [`Ad7124::init`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DeviceInfo {
    /// SILICON_REVISION (ID[3:0]).
    pub silicon_revision: u8,
}

converter_error! {
    /// The ERROR register reports the listed conditions (see [`ErrorFlags`]).
    AdcError(ErrorFlags),
}

/// Result width (Rev. B "Data Register": 24 bits).
pub const CODE_BITS: u8 = 24;

/// How codes read: 24 bits, unipolar or offset binary (`bipolar`), full scale `vref`/`pga_gain`,
/// then the calibration's `gain_correction` (the board decides these; the chip only its coding).
pub const fn code_scale(
    bipolar: bool,
    pga_gain: f64,
    vref: Volts,
    gain_correction: f64,
) -> AdcScale {
    AdcScale {
        bits: CODE_BITS,
        coding: if bipolar {
            Coding::OffsetBinary
        } else {
            Coding::Unipolar
        },
        pga_gain,
        vref,
        gain_correction,
        offset: Volts(0.0),
    }
}

/// The AD7124-4 on an SPI device, with a data-ready pin and a delay source.
pub struct Ad7124<SPI, DRDY, D> {
    spi: SPI,
    drdy: DRDY,
    delay: D,
    config: Ad7124Config,
    /// Whether the device currently expects and sends CRC bytes.
    crc_active: bool,
}

impl<SPI, DRDY, D> Ad7124<SPI, DRDY, D>
where
    SPI: SpiDevice,
    DRDY: InputPin,
    D: DelayNs,
{
    /// Wrap the bus, pin and delay. Nothing is sent until [`Ad7124::init`].
    pub const fn new(spi: SPI, drdy: DRDY, delay: D, config: Ad7124Config) -> Self {
        Self {
            spi,
            drdy,
            delay,
            config,
            crc_active: false,
        }
    }

    /// Give the bus, pin and delay back.
    pub fn release(self) -> (SPI, DRDY, D) {
        (self.spi, self.drdy, self.delay)
    }

    /// The configuration in use.
    pub const fn config(&self) -> &Ad7124Config {
        &self.config
    }

    /// Serial reset: 64 consecutive ones on DIN, then the reset wait. CRC is off afterwards.
    pub fn reset(&mut self) -> Result<(), DriverError<SPI, DRDY>> {
        self.begin_reset()?;
        self.delay.delay_us(RESET_WAIT_US);
        Ok(())
    }

    /// The 64 ones of [`Ad7124::reset`] without the wait: the caller leaves the part alone for
    /// [`RESET_WAIT_US`] before [`Ad7124::configure`] (interrupt-driven re-initialisation).
    pub fn begin_reset(&mut self) -> Result<(), DriverError<SPI, DRDY>> {
        self.crc_active = false;
        self.spi.write(&[0xFF; 8]).map_err(Error::Spi)
    }

    /// Reset, check the ID, write and read back every configuration register, and start
    /// continuous conversion. Blocks [`RESET_WAIT_US`]; see [`Ad7124::configure`].
    pub fn init(&mut self) -> Result<DeviceInfo, DriverError<SPI, DRDY>> {
        if !self.config.validate() {
            return Err(Error::InvalidConfig);
        }
        self.reset()?;
        self.configure()
    }

    /// ADC_CONTROL as configured (what [`Ad7124::read_control_unchecked`] shows while the part
    /// keeps its configuration; 0x0000 after a reset).
    pub const fn configured_control(&self) -> u32 {
        self.config.adc_control()
    }

    /// Read ADC_CONTROL without a CRC byte whatever the CRC state: how to ask a part whose CRC
    /// state is unknown (after a reset its CRC is off, so every CRC-checked read fails) whether
    /// it still holds its configuration. With CRC on, the part's CRC byte is simply not clocked;
    /// CS rising ends the frame.
    pub fn read_control_unchecked(&mut self) -> Result<u32, DriverError<SPI, DRDY>> {
        let comms =
            registers::COMMS_READ | (registers::ADC_CONTROL.addr & registers::COMMS_ADDR_MASK);
        let mut buf = [comms, 0, 0];
        self.spi.transfer_in_place(&mut buf).map_err(Error::Spi)?;
        let [_, hi, lo] = buf;
        if hi == 0xFF && lo == 0xFF {
            return Err(Error::NotResponding { found: 0xFF });
        }
        Ok(u32::from(u16::from_be_bytes([hi, lo])))
    }

    /// Second half of [`Ad7124::init`], [`RESET_WAIT_US`] after [`Ad7124::begin_reset`].
    pub fn configure(&mut self) -> Result<DeviceInfo, DriverError<SPI, DRDY>> {
        if !self.config.validate() {
            return Err(Error::InvalidConfig);
        }
        self.crc_active = false;
        let id = self.read_register(registers::ID)? as u8;
        if id == 0x00 || id == 0xFF {
            return Err(Error::NotResponding { found: id });
        }
        if id >> 4 != 0 {
            // DEVICE_ID 0 is the AD7124-4 (1 would be the AD7124-8).
            return Err(Error::DeviceId { found: id });
        }

        let cfg = self.config;
        // ERROR_EN first: the write that sets SPI_CRC_ERR_EN is itself sent without CRC, every
        // access after it carries one (including the read-back of ERROR_EN).
        self.write_register(registers::ERROR_EN, cfg.error_en())?;
        self.crc_active = cfg.crc;
        self.verify(registers::ERROR_EN, cfg.error_en())?;
        self.write_verified(registers::IO_CONTROL_1, cfg.io_control_1())?;
        self.write_verified(registers::CONFIG_0, cfg.config_0())?;
        self.write_verified(registers::FILTER_0, cfg.filter_0())?;
        self.write_verified(registers::CHANNEL_0, cfg.channel_0())?;
        // ADC_CONTROL last: its write (re)starts continuous conversion with everything in place.
        self.write_verified(registers::ADC_CONTROL, cfg.adc_control())?;
        Ok(DeviceInfo {
            silicon_revision: id & 0x0F,
        })
    }

    /// Read the ERROR register (CRC-checked when CRC is on); reading clears the SPI flags.
    pub fn read_error_flags(&mut self) -> Result<ErrorFlags, DriverError<SPI, DRDY>> {
        self.read_register(registers::ERROR).map(ErrorFlags)
    }

    /// Read the STATUS register (clears POR_FLAG).
    pub fn read_status(&mut self) -> Result<Status, DriverError<SPI, DRDY>> {
        self.read_register(registers::STATUS)
            .map(|v| Status(v as u8))
    }

    /// Poll the DRDY pin (DOUT/RDY, active low) at most `drdy_poll_limit` times.
    pub fn wait_drdy(&mut self) -> Result<(), DriverError<SPI, DRDY>> {
        let (limit, interval_us) = (
            self.config.drdy_poll_limit,
            self.config.drdy_poll_interval_us,
        );
        wait_low(&mut self.drdy, &mut self.delay, limit, interval_us).map_err(Error::from)
    }

    /// Poll the STATUS register's RDY bit at most `drdy_poll_limit` times (shared-bus path).
    pub fn wait_ready_polled(&mut self) -> Result<(), DriverError<SPI, DRDY>> {
        for _ in 0..self.config.drdy_poll_limit {
            if self.read_status()?.ready() {
                return Ok(());
            }
            self.delay.delay_us(self.config.drdy_poll_interval_us);
        }
        Err(Error::DrdyTimeout)
    }

    /// Read DATA (and the appended STATUS if enabled), check the CRC and, when STATUS shows
    /// the error flag, read ERROR and fail with [`Error::AdcError`].
    pub fn read_data(&mut self) -> Result<(Ad7124Code, Option<Status>), DriverError<SPI, DRDY>> {
        let len = registers::DATA.len + usize::from(self.config.data_status);
        let mut raw = [0u8; 4];
        let bytes = raw.get_mut(..len).ok_or(Error::InvalidConfig)?;
        self.read_raw(registers::DATA.addr, bytes)?;
        let (data, rest) = bytes.split_first_chunk::<3>().ok_or(Error::InvalidConfig)?;
        let [hi, mid, lo] = *data;
        let code = Ad7124Code(u32::from_be_bytes([0, hi, mid, lo]));
        let status = rest.first().map(|s| Status(*s));
        if let Some(s) = status {
            if s.error() {
                let flags = self.read_error_flags()?;
                return Err(Error::AdcError(flags));
            }
        }
        Ok((code, status))
    }

    /// Wait for DRDY (bounded), then read and check one RTD conversion.
    pub fn read_rtd(&mut self) -> Result<Ad7124Code, DriverError<SPI, DRDY>> {
        self.wait_drdy()?;
        self.read_data().map(|(code, _)| code)
    }

    /// Like [`Ad7124::read_rtd`] but waits by polling STATUS, for a shared SPI bus.
    pub fn read_rtd_polled(&mut self) -> Result<Ad7124Code, DriverError<SPI, DRDY>> {
        self.wait_ready_polled()?;
        self.read_data().map(|(code, _)| code)
    }

    fn read_register(&mut self, reg: Reg) -> Result<u32, DriverError<SPI, DRDY>> {
        let mut raw = [0u8; 3];
        let bytes = raw.get_mut(..reg.len).ok_or(Error::InvalidConfig)?;
        self.read_raw(reg.addr, bytes)?;
        Ok(bytes.iter().fold(0u32, |acc, b| (acc << 8) | u32::from(*b)))
    }

    /// Comms byte with R/W = 1, then `out.len()` bytes (+ CRC when active). Zeros are clocked
    /// out meanwhile: a run of 64 ones would reset the part.
    fn read_raw(&mut self, addr: u8, out: &mut [u8]) -> Result<(), DriverError<SPI, DRDY>> {
        let comms = registers::COMMS_READ | (addr & registers::COMMS_ADDR_MASK);
        let total = 1 + out.len() + usize::from(self.crc_active);
        let mut frame = [0u8; 6];
        let buf = frame.get_mut(..total).ok_or(Error::InvalidConfig)?;
        if let Some(first) = buf.first_mut() {
            *first = comms;
        }
        self.spi.transfer_in_place(buf).map_err(Error::Spi)?;
        // An idle MISO (pulled high) reads all ones: no AD7124 register or STATUS byte can be
        // all ones (STATUS bit 5 and the top bits of ERROR are always 0), so name it.
        if buf.get(1..).is_some_and(|b| b.iter().all(|x| *x == 0xFF)) {
            return Err(Error::NotResponding { found: 0xFF });
        }
        let (data, crc) = buf
            .get(1..)
            .and_then(|b| b.split_at_checked(out.len()))
            .ok_or(Error::InvalidConfig)?;
        if self.crc_active {
            let received = *crc.first().ok_or(Error::InvalidConfig)?;
            // The CRC covers the communications byte as sent plus the data as received.
            let mut digest = CRC8_ATM.digest();
            digest.update(&[comms]);
            digest.update(data);
            let expected = digest.finalize();
            if expected != received {
                return Err(Error::CrcMismatch { expected, received });
            }
        }
        out.copy_from_slice(data);
        Ok(())
    }

    fn write_register(&mut self, reg: Reg, value: u32) -> Result<(), DriverError<SPI, DRDY>> {
        let mut frame = [0u8; 5];
        let total = 1 + reg.len + usize::from(self.crc_active);
        let be = value.to_be_bytes();
        let payload = be
            .get(be.len().saturating_sub(reg.len)..)
            .ok_or(Error::InvalidConfig)?;
        let width_bits = u32::try_from(8 * reg.len).map_err(|_| Error::InvalidConfig)?;
        if value.checked_shr(width_bits).unwrap_or(0) != 0 {
            return Err(Error::InvalidConfig);
        }
        let buf = frame.get_mut(..total).ok_or(Error::InvalidConfig)?;
        let (head, tail) = buf.split_at_mut(1 + reg.len);
        if let Some((comms, data)) = head.split_first_mut() {
            *comms = reg.addr & registers::COMMS_ADDR_MASK;
            data.copy_from_slice(payload);
        }
        if let Some(crc) = tail.first_mut() {
            *crc = CRC8_ATM.checksum(head);
        }
        self.spi.write(buf).map_err(Error::Spi)
    }

    fn verify(&mut self, reg: Reg, written: u32) -> Result<(), DriverError<SPI, DRDY>> {
        let read = self.read_register(reg)?;
        if read == written {
            Ok(())
        } else {
            Err(Error::ReadBack {
                register: reg.addr,
                written,
                read,
            })
        }
    }

    fn write_verified(&mut self, reg: Reg, value: u32) -> Result<(), DriverError<SPI, DRDY>> {
        self.write_register(reg, value)?;
        self.verify(reg, value)
    }
}
