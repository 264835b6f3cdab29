//! Register-level model of the ADI AD7124-4, written from the Rev. B datasheet: "On-chip
//! registers" (communications byte WEN/R/W/RS, register sizes and reset values), "Reset"
//! (64 ones on DIN), "CRC" (CRC-8 over the communications byte and the data, on writes and
//! reads once ERROR_EN.SPI_CRC_ERR_EN is set; a write with a bad CRC is ignored and flagged),
//! "Data Register" (DATA_STATUS appends STATUS), the ERROR register, continuous conversion with
//! ODR = f_CLK / (32·FS) and sinc4 settling of four periods, and the timing characteristics
//! (mode 3, SCLK pulse widths ≥ 100 ns).
//!
//! The analog side is the board's ratiometric Pt100 (ADI CN-0381): IOUT0 through the RTD and
//! the reference resistor, so the code is R_rtd·gain/R_ref·2²⁴ (unipolar). An open loop carries
//! no current: the reference collapses (REF_DET) and AINP is pulled to the rail.

use accomp::acquisition::{SpiRequirement, AD7124_SPI};

use crate::bus::{crc8, Chip, Clock, Port};

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

const SPI_CRC_ERR: u32 = 1 << 2;
const REF_DET_ERR: u32 = 1 << 11;
const AINP_OV_ERR: u32 = 1 << 15;
const ADC_SAT_ERR: u32 = 1 << 16;

/// Register size in bytes (0 = no such register in this model).
fn size(addr: u8) -> usize {
    match addr {
        STATUS | ID => 1,
        ADC_CONTROL => 2,
        DATA | IO_CONTROL_1 | ERROR | ERROR_EN => 3,
        0x04 => 2,        // IO_CONTROL_2
        0x08 => 1,        // MCLK_COUNT
        0x09..=0x18 => 2, // CHANNEL_0..15
        0x19..=0x20 => 2, // CONFIG_0..7
        0x21..=0x28 => 3, // FILTER_0..7
        0x29..=0x38 => 3, // OFFSET_x, GAIN_x
        _ => 0,
    }
}

fn reset_value(addr: u8) -> u32 {
    match addr {
        ID => 0x04, // AD7124-4, DEVICE_ID 0, silicon revision 4
        ERROR_EN => 0x00_0040,
        0x09 => 0x8001,
        0x0A..=0x18 => 0x0001,
        0x19..=0x20 => 0x0860,
        0x21..=0x28 => 0x06_0180,
        0x29..=0x30 => 0x80_0000,
        0x31..=0x38 => 0x50_0000,
        _ => 0,
    }
}

enum Frame {
    Comms,
    Read { bytes: Vec<u8>, pos: usize },
    Write { comms: u8, data: Vec<u8> },
    Ignore,
}

pub struct Ad7124Model {
    clock: Clock,
    regs: [u32; 0x39],
    por: bool,
    ready: bool,
    errors: u32,
    next_conversion_us: Option<u64>,
    frame: Frame,
    ones: u32,
    /// RTD resistance, ohms; infinite = open loop.
    pub rtd_ohms: f64,
    /// Reference resistor on REFIN1, ohms.
    pub reference_ohms: f64,
    /// Fault: conversions stop (RDY never comes).
    pub stuck: bool,
    /// The SPI port's faults and refusals; `corrupt_reads` here are register reads, the first
    /// byte's low bit flipped after the CRC.
    pub port: Port,
    pub conversions: u64,
}

impl Ad7124Model {
    pub fn new(clock: Clock) -> Self {
        let mut m = Self {
            clock,
            regs: [0; 0x39],
            por: true,
            ready: false,
            errors: 0,
            next_conversion_us: None,
            frame: Frame::Ignore,
            ones: 0,
            rtd_ohms: 100.0,
            reference_ohms: 5110.0,
            stuck: false,
            port: Port::default(),
            conversions: 0,
        };
        m.power_glitch();
        m
    }

    fn crc_on(&self) -> bool {
        self.regs[usize::from(ERROR_EN)] & SPI_CRC_ERR != 0
    }

    fn odr_hz(&self) -> f64 {
        let clk = match (self.regs[usize::from(ADC_CONTROL)] >> 6) & 0x3 {
            0 => 76_800.0,
            1 => 153_600.0,
            _ => 614_400.0,
        };
        let fs = (self.regs[usize::from(FILTER_0)] & 0x7FF).max(1);
        clk / (32.0 * f64::from(fs))
    }

    fn converting(&self) -> bool {
        let mode = (self.regs[usize::from(ADC_CONTROL)] >> 2) & 0xF;
        mode == 0 && self.regs[usize::from(CHANNEL_0)] & 0x8000 != 0
    }

    fn restart(&mut self) {
        self.ready = false;
        self.next_conversion_us = self
            .converting()
            .then(|| self.clock.now() + (4.0 * 1e6 / self.odr_hz()) as u64);
    }

    /// Let time pass: each finished conversion latches DATA and clears RDY (active low).
    pub fn advance(&mut self) {
        let now = self.clock.now();
        while let Some(t) = self.next_conversion_us {
            if t > now || self.stuck {
                break;
            }
            self.convert();
            self.conversions += 1;
            self.next_conversion_us = Some(t + (1e6 / self.odr_hz()) as u64);
        }
    }

    fn convert(&mut self) {
        let io = self.regs[usize::from(IO_CONTROL_1)];
        let current_a = match (io >> 8) & 0x7 {
            1 => 50e-6,
            2 => 100e-6,
            3 => 250e-6,
            4 => 500e-6,
            5 => 750e-6,
            6 => 1e-3,
            _ => 0.0,
        };
        let config = self.regs[usize::from(CONFIG_0)];
        let gain = f64::from(1u32 << (config & 0x7));
        let bipolar = config & (1 << 11) != 0;
        let mut errors = 0;
        let open = !self.rtd_ohms.is_finite();
        let vref = if open {
            0.0
        } else {
            current_a * self.reference_ohms
        };
        let code = if vref < 0.7 {
            // No excitation current: reference below the REF_DET threshold, AINP at the rail.
            errors |= REF_DET_ERR | AINP_OV_ERR | ADC_SAT_ERR;
            0xFF_FFFF
        } else {
            let ratio = self.rtd_ohms * current_a * gain / vref;
            let x = if bipolar {
                8_388_608.0 * (1.0 + ratio)
            } else {
                16_777_216.0 * ratio
            };
            if x >= 16_777_215.0 {
                errors |= ADC_SAT_ERR;
            }
            x.round().clamp(0.0, 16_777_215.0) as u32
        };
        self.regs[usize::from(DATA)] = code;
        // Conversion error flags follow the latest conversion; SPI flags stay until ERROR is read.
        self.errors = (self.errors & 0x7F) | errors;
        self.ready = true;
    }

    fn status(&self) -> u8 {
        let mut s = 0u8;
        if !self.ready {
            s |= 0x80;
        }
        if self.errors & self.regs[usize::from(ERROR_EN)] != 0 {
            s |= 0x40;
        }
        if self.por {
            s |= 0x10;
        }
        s
    }

    fn read_register(&mut self, comms: u8, addr: u8) -> Vec<u8> {
        let n = size(addr);
        let value = match addr {
            STATUS => u32::from(self.status()),
            ERROR => self.errors,
            _ => self.regs.get(usize::from(addr)).copied().unwrap_or(0),
        };
        let mut out: Vec<u8> = value.to_be_bytes()[4 - n..].to_vec();
        if addr == DATA && self.regs[usize::from(ADC_CONTROL)] & (1 << 10) != 0 {
            out.push(self.status());
        }
        // Side effects of the read.
        match addr {
            STATUS => self.por = false,
            DATA => self.ready = false,
            ERROR => self.errors &= !0x7F,
            _ => {}
        }
        if self.crc_on() {
            let mut covered = vec![comms];
            covered.extend_from_slice(&out);
            out.push(crc8(&covered));
        }
        if self.port.corrupt_reads > 0 {
            self.port.corrupt_reads -= 1;
            out[0] ^= 0x01;
        }
        out
    }

    fn write_register(&mut self, comms: u8, data: &[u8]) {
        let addr = comms & 0x3F;
        let n = size(addr);
        let (value, crc) = data.split_at(n);
        if self.crc_on() {
            let mut covered = vec![comms];
            covered.extend_from_slice(value);
            if crc.first() != Some(&crc8(&covered)) {
                self.errors |= SPI_CRC_ERR;
                return;
            }
        }
        if matches!(addr, STATUS | DATA | ID | ERROR) {
            return;
        }
        let v = value.iter().fold(0u32, |a, b| (a << 8) | u32::from(*b));
        self.regs[usize::from(addr)] = v;
        if matches!(addr, ADC_CONTROL | CHANNEL_0 | CONFIG_0 | FILTER_0) {
            self.restart();
        }
    }
}

impl Chip for Ad7124Model {
    const REQUIRED: SpiRequirement = AD7124_SPI;

    fn begin_frame(&mut self) {
        self.advance();
        self.frame = Frame::Comms;
        self.ones = 0;
    }

    fn exchange(&mut self, mosi: u8) -> u8 {
        // 64 consecutive ones reset the part whatever the interface state.
        if mosi == 0xFF {
            self.ones += 8;
            if self.ones >= 64 {
                self.power_glitch();
                self.frame = Frame::Ignore;
                return 0xFF;
            }
        } else {
            self.ones = 0;
        }
        match std::mem::replace(&mut self.frame, Frame::Ignore) {
            Frame::Comms => {
                let addr = mosi & 0x3F;
                if mosi & 0x80 != 0 || size(addr) == 0 {
                    // WEN = 1: not a communication; unknown register: ignored.
                } else if mosi & 0x40 != 0 {
                    let bytes = self.read_register(mosi, addr);
                    self.frame = Frame::Read { bytes, pos: 0 };
                } else {
                    self.frame = Frame::Write {
                        comms: mosi,
                        data: Vec::new(),
                    };
                }
                0xFF
            }
            // Beyond the register (and its CRC) DOUT/RDY idles high.
            Frame::Read { bytes, pos } => {
                let b = bytes.get(pos).copied().unwrap_or(0xFF);
                self.frame = Frame::Read {
                    bytes,
                    pos: pos + 1,
                };
                b
            }
            Frame::Write { comms, mut data } => {
                data.push(mosi);
                let need = size(comms & 0x3F) + usize::from(self.crc_on());
                if data.len() == need {
                    self.write_register(comms, &data);
                } else {
                    self.frame = Frame::Write { comms, data };
                }
                0xFF
            }
            Frame::Ignore => 0xFF,
        }
    }

    fn end_frame(&mut self) {
        // CS high resets the interface: a half-sent write is dropped.
        self.frame = Frame::Ignore;
    }

    /// Reset (serial reset or supply glitch): registers to reset values, CRC off, POR flag set.
    /// The reset value of ADC_CONTROL is continuous conversion of CHANNEL_0 at low power, so
    /// the part keeps converting — with the wrong settings.
    fn power_glitch(&mut self) {
        for a in 0..0x39u8 {
            self.regs[usize::from(a)] = reset_value(a);
        }
        self.por = true;
        self.ready = false;
        self.errors = 0;
        self.restart();
    }

    fn port(&mut self) -> &mut Port {
        &mut self.port
    }
}
