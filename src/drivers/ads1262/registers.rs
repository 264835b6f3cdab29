//! ADS1262 opcodes, register addresses and field encodings.
//!
//! Source: TI SBAS661C (ADS1262/ADS1263 datasheet, Feb 2015 – May 2021), "Programming"
//! (command opcodes) and "Register Map" (register tables).
//! Only what the driver uses is named here; the tests re-declare these numbers independently.

/// Command opcodes (SBAS661C "Commands"). RREG/WREG take the 5-bit register address in their low
/// bits and a second byte holding "number of registers − 1".
pub(crate) mod cmd {
    /// Reset the device to its power-on register values.
    pub const RESET: u8 = 0x06;
    /// Start (or restart) ADC1 conversions.
    pub const START1: u8 = 0x08;
    /// Stop ADC1 conversions.
    pub const STOP1: u8 = 0x0A;
    /// Read ADC1 data: status byte (if enabled), 4 data bytes, checksum/CRC byte (if enabled).
    pub const RDATA1: u8 = 0x12;
    /// Read registers, OR-ed with the start address (0x20 | rrrrr).
    pub const RREG: u8 = 0x20;
    /// Write registers, OR-ed with the start address (0x40 | rrrrr).
    pub const WREG: u8 = 0x40;
}

/// Register addresses (SBAS661C "Register Map").
pub(crate) mod reg {
    /// ID: DEV_ID[7:5] (000 = ADS1262, 001 = ADS1263), REV_ID[4:0].
    pub const ID: u8 = 0x00;
    /// POWER: RESET[4] (reads 1 after any reset, cleared by writing 0), VBIAS[1], INTREF[0].
    /// Reset value 0x11.
    pub const POWER: u8 = 0x01;
    /// INTERFACE: TIMEOUT[3], STATUS[2] (status byte before data), CRC[1:0]
    /// (00 off, 01 checksum, 10 CRC). Reset value 0x05.
    pub const INTERFACE: u8 = 0x02;
    /// MODE0: REFREV[7], RUNMODE[6] (0 continuous, 1 pulse), CHOP[5:4], DELAY[3:0]. Reset 0x00.
    pub const MODE0: u8 = 0x03;
    /// MODE1: FILTER[7:5], SBADC[4], SBPOL[3], SBMAG[2:0]. Reset 0x80 (FIR).
    pub const MODE1: u8 = 0x04;
    /// MODE2: BYPASS[7] (1 = PGA bypassed), GAIN[6:4], DR[3:0]. Reset 0x04 (gain 1, 20 SPS).
    pub const MODE2: u8 = 0x05;
    /// INPMUX: MUXP[7:4], MUXN[3:0]. Reset 0x01 (AIN0 − AIN1).
    pub const INPMUX: u8 = 0x06;
    /// REFMUX: RMUXP[5:3], RMUXN[2:0]. Reset 0x00 (internal 2.5 V reference).
    pub const REFMUX: u8 = 0x0F;
}

/// ID register: DEV_ID field position.
pub(crate) const ID_DEV_ID_SHIFT: u8 = 5;
/// POWER register: RESET flag.
pub(crate) const POWER_RESET: u8 = 1 << 4;
/// POWER register: internal 2.5 V reference enable.
pub(crate) const POWER_INTREF: u8 = 1 << 0;
/// INTERFACE register: status byte enable.
pub(crate) const INTERFACE_STATUS: u8 = 1 << 2;
/// MODE2 register: PGA bypass.
pub(crate) const MODE2_BYPASS: u8 = 1 << 7;

/// Status byte bits (SBAS661C "Status Byte").
pub(crate) mod status {
    /// ADC2 new data.
    pub const ADC2: u8 = 1 << 7;
    /// ADC1 new data since the last read.
    pub const ADC1: u8 = 1 << 6;
    /// External clock detected.
    pub const EXTCLK: u8 = 1 << 5;
    /// Low reference alarm (|V_REF| below ~0.4 V).
    pub const REF_ALM: u8 = 1 << 4;
    /// PGA output low alarm.
    pub const PGAL_ALM: u8 = 1 << 3;
    /// PGA output high alarm.
    pub const PGAH_ALM: u8 = 1 << 2;
    /// PGA differential output alarm (over-range).
    pub const PGAD_ALM: u8 = 1 << 1;
    /// Device reset since the POWER.RESET bit was last cleared.
    pub const RESET: u8 = 1 << 0;
}

/// Constant added to the sum of the data bytes in checksum mode (SBAS661C "Checksum").
pub(crate) const CHECKSUM_OFFSET: u8 = 0x9B;

/// Digital filter of ADC1 (MODE1.FILTER).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Filter {
    /// sinc1.
    Sinc1,
    /// sinc2.
    Sinc2,
    /// sinc3.
    Sinc3,
    /// sinc4: deepest notches at multiples of the data rate.
    Sinc4,
    /// FIR (only at 2.5, 5, 10 and 20 SPS): simultaneous 50/60 Hz rejection, single-cycle settling.
    Fir,
}

impl Filter {
    /// Conversion periods before the first settled result after a (re)start: the sinc order
    /// (SBAS661C "Conversion Latency"; FIR settles in one cycle). The data-sheet latency adds a
    /// small fixed delay on top, which callers allow for in their margins.
    pub const fn settling_conversions(self) -> u32 {
        match self {
            Filter::Sinc1 | Filter::Fir => 1,
            Filter::Sinc2 => 2,
            Filter::Sinc3 => 3,
            Filter::Sinc4 => 4,
        }
    }

    pub(crate) const fn bits(self) -> u8 {
        match self {
            Filter::Sinc1 => 0b000,
            Filter::Sinc2 => 0b001,
            Filter::Sinc3 => 0b010,
            Filter::Sinc4 => 0b011,
            Filter::Fir => 0b100,
        }
    }
}

/// ADC1 output data rate (MODE2.DR), in samples per second.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[allow(missing_docs)] // the names are the rates
pub enum DataRate {
    Sps2_5,
    Sps5,
    Sps10,
    Sps16_6,
    Sps20,
    Sps50,
    Sps60,
    Sps100,
    Sps400,
    Sps1200,
    Sps2400,
    Sps4800,
    Sps7200,
    Sps14400,
    Sps19200,
    Sps38400,
}

impl DataRate {
    pub(crate) const fn bits(self) -> u8 {
        self as u8
    }

    /// The rate for a whole number of samples per second, for the protocol's SetRate (2.5 and
    /// 16.6 SPS have no integer value and are not offered).
    pub const fn from_sps(sps: u32) -> Option<DataRate> {
        Some(match sps {
            5 => DataRate::Sps5,
            10 => DataRate::Sps10,
            20 => DataRate::Sps20,
            50 => DataRate::Sps50,
            60 => DataRate::Sps60,
            100 => DataRate::Sps100,
            400 => DataRate::Sps400,
            1200 => DataRate::Sps1200,
            2400 => DataRate::Sps2400,
            4800 => DataRate::Sps4800,
            7200 => DataRate::Sps7200,
            14400 => DataRate::Sps14400,
            19200 => DataRate::Sps19200,
            38400 => DataRate::Sps38400,
            _ => return None,
        })
    }

    /// Nominal conversion period in microseconds (1 / data rate).
    pub const fn period_us(self) -> u32 {
        match self {
            DataRate::Sps2_5 => 400_000,
            DataRate::Sps5 => 200_000,
            DataRate::Sps10 => 100_000,
            DataRate::Sps16_6 => 60_000,
            DataRate::Sps20 => 50_000,
            DataRate::Sps50 => 20_000,
            DataRate::Sps60 => 16_667,
            DataRate::Sps100 => 10_000,
            DataRate::Sps400 => 2_500,
            DataRate::Sps1200 => 834,
            DataRate::Sps2400 => 417,
            DataRate::Sps4800 => 209,
            DataRate::Sps7200 => 139,
            DataRate::Sps14400 => 70,
            DataRate::Sps19200 => 53,
            DataRate::Sps38400 => 27,
        }
    }

    /// Whether the FIR filter is defined at this rate (SBAS661C: 2.5, 5, 10, 20 SPS only).
    pub(crate) const fn supports_fir(self) -> bool {
        matches!(
            self,
            DataRate::Sps2_5 | DataRate::Sps5 | DataRate::Sps10 | DataRate::Sps20
        )
    }
}

/// PGA gain (MODE2.GAIN), V/V.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[allow(missing_docs)] // the names are the gains
pub enum Gain {
    G1,
    G2,
    G4,
    G8,
    G16,
    G32,
}

impl Gain {
    pub(crate) const fn bits(self) -> u8 {
        self as u8
    }

    /// The gain as a number, for [`crate::adc::AdcScale::pga_gain`].
    pub const fn factor(self) -> f64 {
        match self {
            Gain::G1 => 1.0,
            Gain::G2 => 2.0,
            Gain::G4 => 4.0,
            Gain::G8 => 8.0,
            Gain::G16 => 16.0,
            Gain::G32 => 32.0,
        }
    }
}

/// PGA setting of a channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pga {
    /// PGA in the signal path with this gain.
    Enabled(Gain),
    /// PGA bypassed (gain 1, wider input range to the rails, higher input current).
    Bypassed,
}

/// Analog input selection of INPMUX.MUXP / MUXN.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[allow(missing_docs)] // AIN0..AIN9 are the pin names
pub enum Input {
    Ain0,
    Ain1,
    Ain2,
    Ain3,
    Ain4,
    Ain5,
    Ain6,
    Ain7,
    Ain8,
    Ain9,
    /// AINCOM pin.
    AinCom,
    /// Internal temperature sensor.
    TempSensor,
    /// Analog power-supply monitor.
    AnalogSupply,
    /// Digital power-supply monitor.
    DigitalSupply,
    /// TDAC test signal.
    Tdac,
    /// Open (floating) input.
    Float,
}

impl Input {
    pub(crate) const fn bits(self) -> u8 {
        self as u8
    }
}

/// Positive reference selection (REFMUX.RMUXP).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RefPositive {
    /// Internal 2.5 V reference (needs POWER.INTREF).
    Internal,
    /// External reference on AIN0.
    Ain0,
    /// External reference on AIN2.
    Ain2,
    /// External reference on AIN4.
    Ain4,
    /// Analog supply VAVDD.
    Avdd,
}

impl RefPositive {
    pub(crate) const fn bits(self) -> u8 {
        self as u8
    }
    pub(crate) const fn pin(self) -> Option<Input> {
        match self {
            RefPositive::Ain0 => Some(Input::Ain0),
            RefPositive::Ain2 => Some(Input::Ain2),
            RefPositive::Ain4 => Some(Input::Ain4),
            RefPositive::Internal | RefPositive::Avdd => None,
        }
    }
}

/// Negative reference selection (REFMUX.RMUXN).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RefNegative {
    /// Internal 2.5 V reference (needs POWER.INTREF).
    Internal,
    /// External reference on AIN1.
    Ain1,
    /// External reference on AIN3.
    Ain3,
    /// External reference on AIN5.
    Ain5,
    /// Analog supply VAVSS.
    Avss,
}

impl RefNegative {
    pub(crate) const fn bits(self) -> u8 {
        self as u8
    }
    pub(crate) const fn pin(self) -> Option<Input> {
        match self {
            RefNegative::Ain1 => Some(Input::Ain1),
            RefNegative::Ain3 => Some(Input::Ain3),
            RefNegative::Ain5 => Some(Input::Ain5),
            RefNegative::Internal | RefNegative::Avss => None,
        }
    }
}

/// Chop / IDAC rotation (MODE0.CHOP).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Chop {
    /// No chopping.
    Off,
    /// Input chop: the ADC swaps the inputs on alternate conversions and averages, cancelling
    /// offset and offset drift at the cost of half the effective data rate.
    Input,
    /// IDAC rotation only.
    IdacRotation,
    /// Input chop and IDAC rotation.
    Both,
}

impl Chop {
    pub(crate) const fn bits(self) -> u8 {
        self as u8
    }
}

/// What follows the data bytes (INTERFACE.CRC).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Integrity {
    /// Nothing: no transmission check (not recommended on a long cable or a shared bus).
    None,
    /// Checksum byte = (sum of the 4 data bytes + 0x9B) mod 256.
    Checksum,
    /// CRC-8 (x^8 + x^2 + x + 1) over the 4 data bytes.
    Crc,
}

impl Integrity {
    pub(crate) const fn bits(self) -> u8 {
        match self {
            Integrity::None => 0b00,
            Integrity::Checksum => 0b01,
            Integrity::Crc => 0b10,
        }
    }
}
