//! AD7124-4 communication byte, register addresses/sizes and field encodings.
//!
//! Source: Analog Devices AD7124-4 datasheet Rev. B, "On-chip registers" (register summary and
//! the per-register tables). Only what the driver uses is named; the tests re-declare these
//! numbers independently.

/// A register: address in the communications byte and size in bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Reg {
    pub addr: u8,
    pub len: usize,
}

/// Communications register (write-only, the first byte of every access):
/// WEN[7] must be 0, R/W[6] (1 = read), RS[5:0] register address.
pub(crate) const COMMS_READ: u8 = 1 << 6;
/// Register-select mask of the communications byte.
pub(crate) const COMMS_ADDR_MASK: u8 = 0x3F;

/// STATUS, 8 bit, read-only: RDY[7] (0 = new result), ERROR_FLAG[6], POR_FLAG[4], CH_ACTIVE[3:0].
pub(crate) const STATUS: Reg = Reg { addr: 0x00, len: 1 };
/// ADC_CONTROL, 16 bit: DOUT_RDY_DEL[12], CONT_READ[11], DATA_STATUS[10], CS_EN[9], REF_EN[8],
/// POWER_MODE[7:6], MODE[5:2], CLK_SEL[1:0]. Reset 0x0000.
pub(crate) const ADC_CONTROL: Reg = Reg { addr: 0x01, len: 2 };
/// DATA, 24 bit, read-only (+ STATUS appended when DATA_STATUS = 1).
pub(crate) const DATA: Reg = Reg { addr: 0x02, len: 3 };
/// IO_CONTROL_1, 24 bit: PDSW[15], IOUT1[13:11], IOUT0[10:8], IOUT1_CH[7:4], IOUT0_CH[3:0].
pub(crate) const IO_CONTROL_1: Reg = Reg { addr: 0x03, len: 3 };
/// ID, 8 bit, read-only: DEVICE_ID[7:4] (0 = AD7124-4), SILICON_REVISION[3:0].
pub(crate) const ID: Reg = Reg { addr: 0x05, len: 1 };
/// ERROR, 24 bit, read-only; the flag positions match their enables in ERROR_EN.
pub(crate) const ERROR: Reg = Reg { addr: 0x06, len: 3 };
/// ERROR_EN, 24 bit. Reset 0x000040 (SPI_IGNORE_ERR_EN).
pub(crate) const ERROR_EN: Reg = Reg { addr: 0x07, len: 3 };
/// CHANNEL_0, 16 bit: Enable[15], Setup[14:12], AINP[9:5], AINM[4:0]. Reset 0x8001.
pub(crate) const CHANNEL_0: Reg = Reg { addr: 0x09, len: 2 };
/// CONFIG_0, 16 bit: Bipolar[11], Burnout[10:9], REF_BUFP[8], REF_BUFM[7], AIN_BUFP[6],
/// AIN_BUFM[5], REF_SEL[4:3], PGA[2:0]. Reset 0x0860.
pub(crate) const CONFIG_0: Reg = Reg { addr: 0x19, len: 2 };
/// FILTER_0, 24 bit: Filter[23:21], REJ60[20], POST_FILTER[19:17], SINGLE_CYCLE[16], FS[10:0].
/// Reset 0x060180.
pub(crate) const FILTER_0: Reg = Reg { addr: 0x21, len: 3 };

/// STATUS bits.
pub(crate) mod status {
    /// 0 when a new conversion result is ready (active low, like DOUT/RDY).
    pub const RDY_N: u8 = 1 << 7;
    /// One of the enabled ERROR flags is set.
    pub const ERROR_FLAG: u8 = 1 << 6;
    /// Power-on (or reset) flag, cleared by reading STATUS.
    pub const POR_FLAG: u8 = 1 << 4;
    /// Channel the result belongs to.
    pub const CH_ACTIVE_MASK: u8 = 0x0F;
}

/// ADC_CONTROL bits.
pub(crate) mod adc_control {
    pub const DATA_STATUS: u16 = 1 << 10;
    pub const CS_EN: u16 = 1 << 9;
    pub const REF_EN: u16 = 1 << 8;
    pub const POWER_MODE_SHIFT: u16 = 6;
    pub const MODE_SHIFT: u16 = 2;
    /// MODE = 0000: continuous conversion.
    pub const MODE_CONTINUOUS: u16 = 0b0000;
}

/// ERROR / ERROR_EN bit positions (identical in both registers).
pub(crate) mod err {
    pub const ADC_CAL: u32 = 1 << 18;
    pub const ADC_CONV: u32 = 1 << 17;
    pub const ADC_SAT: u32 = 1 << 16;
    pub const AINP_OV: u32 = 1 << 15;
    pub const AINP_UV: u32 = 1 << 14;
    pub const AINM_OV: u32 = 1 << 13;
    pub const AINM_UV: u32 = 1 << 12;
    pub const REF_DET: u32 = 1 << 11;
    pub const DLDO_PSM: u32 = 1 << 9;
    pub const ALDO_PSM: u32 = 1 << 7;
    pub const SPI_IGNORE: u32 = 1 << 6;
    pub const SPI_SCLK_CNT: u32 = 1 << 5;
    pub const SPI_READ: u32 = 1 << 4;
    pub const SPI_WRITE: u32 = 1 << 3;
    pub const SPI_CRC: u32 = 1 << 2;
    pub const MM_CRC: u32 = 1 << 1;
}

/// CHANNEL_x bits.
pub(crate) const CHANNEL_ENABLE: u16 = 1 << 15;
/// CONFIG_x bits.
pub(crate) mod config {
    pub const BIPOLAR: u16 = 1 << 11;
    pub const REF_BUFP: u16 = 1 << 8;
    pub const REF_BUFM: u16 = 1 << 7;
    pub const AIN_BUFP: u16 = 1 << 6;
    pub const AIN_BUFM: u16 = 1 << 5;
    pub const REF_SEL_SHIFT: u16 = 3;
}
/// FILTER_x: filter-type field position and FS mask.
pub(crate) const FILTER_TYPE_SHIFT: u32 = 21;
pub(crate) const FILTER_FS_MAX: u16 = 2047;

/// ADC power mode (ADC_CONTROL.POWER_MODE); sets the modulator clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PowerMode {
    /// Low power, f_CLK = 76.8 kHz.
    Low,
    /// Mid power, f_CLK = 153.6 kHz.
    Mid,
    /// Full power, f_CLK = 614.4 kHz: lowest noise.
    Full,
}

impl PowerMode {
    pub(crate) const fn bits(self) -> u16 {
        match self {
            PowerMode::Low => 0b00,
            PowerMode::Mid => 0b01,
            PowerMode::Full => 0b10,
        }
    }

    /// Master clock in hertz, for the output-data-rate formula.
    pub const fn clock_hz(self) -> u32 {
        match self {
            PowerMode::Low => 76_800,
            PowerMode::Mid => 153_600,
            PowerMode::Full => 614_400,
        }
    }
}

/// Excitation current of IOUT0 (IO_CONTROL_1.IOUT0).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Excitation {
    /// Off.
    Off,
    /// 50 µA.
    Ua50,
    /// 100 µA.
    Ua100,
    /// 250 µA.
    Ua250,
    /// 500 µA.
    Ua500,
    /// 750 µA.
    Ua750,
    /// 1 mA.
    Ma1,
}

impl Excitation {
    pub(crate) const fn bits(self) -> u32 {
        self as u32
    }
}

/// Pin that IOUT0 drives (IO_CONTROL_1.IOUT0_CH). On the AD7124-4 the codes are not the pin
/// numbers (the 4-channel part keeps the AD7124-8 code points of its bonded pins).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[allow(missing_docs)] // AINx are the pin names
pub enum IoutPin {
    Ain0,
    Ain1,
    Ain2,
    Ain3,
    Ain4,
    Ain5,
    Ain6,
    Ain7,
}

impl IoutPin {
    pub(crate) const fn bits(self) -> u32 {
        match self {
            IoutPin::Ain0 => 0b0000,
            IoutPin::Ain1 => 0b0001,
            IoutPin::Ain2 => 0b0100,
            IoutPin::Ain3 => 0b0101,
            IoutPin::Ain4 => 0b1010,
            IoutPin::Ain5 => 0b1011,
            IoutPin::Ain6 => 0b1110,
            IoutPin::Ain7 => 0b1111,
        }
    }
}

/// Analog input of a channel (CHANNEL_x.AINP / AINM).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[allow(missing_docs)] // AINx are the pin names
pub enum AnalogInput {
    Ain0,
    Ain1,
    Ain2,
    Ain3,
    Ain4,
    Ain5,
    Ain6,
    Ain7,
    /// Internal temperature sensor (code 16).
    TempSensor,
    /// AVSS (code 17).
    Avss,
}

impl AnalogInput {
    pub(crate) const fn bits(self) -> u16 {
        match self {
            AnalogInput::TempSensor => 16,
            AnalogInput::Avss => 17,
            pin => pin as u16,
        }
    }
}

/// Reference of a setup (CONFIG_x.REF_SEL).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reference {
    /// REFIN1(+)/REFIN1(−): the reference resistor in the ratiometric RTD circuit.
    Refin1,
    /// REFIN2(+)/REFIN2(−).
    Refin2,
    /// Internal 2.5 V reference (needs ADC_CONTROL.REF_EN).
    Internal,
    /// AVDD − AVSS.
    Avdd,
}

impl Reference {
    pub(crate) const fn bits(self) -> u16 {
        self as u16
    }
}

/// PGA gain (CONFIG_x.PGA).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[allow(missing_docs)] // the names are the gains
pub enum Gain {
    G1,
    G2,
    G4,
    G8,
    G16,
    G32,
    G64,
    G128,
}

impl Gain {
    pub(crate) const fn bits(self) -> u16 {
        self as u16
    }

    /// The gain as a number, for [`crate::adc::AdcScale::pga_gain`].
    pub const fn factor(self) -> f64 {
        (1u32 << (self as u32)) as f64
    }
}

/// Digital filter of a setup (FILTER_x.Filter).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FilterType {
    /// sinc4 (code 000): ODR = f_CLK / (32 · FS), settling 4 / ODR.
    Sinc4,
    /// sinc3 (code 010): ODR = f_CLK / (32 · FS), settling 3 / ODR.
    Sinc3,
}

impl FilterType {
    pub(crate) const fn bits(self) -> u32 {
        match self {
            FilterType::Sinc4 => 0b000,
            FilterType::Sinc3 => 0b010,
        }
    }
}
