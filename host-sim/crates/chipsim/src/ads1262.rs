//! Register-level model of the TI ADS1262 (ADC1 only), written from SBAS661C:
//! "Commands" (opcodes), "Register Map" (addresses, reset values), "Read Data by Command"
//! (status byte, 4 data bytes, checksum/CRC byte; the data field repeats while SCLK continues),
//! "Status Byte", "Checksum" (Σ data + 0x9B), "Conversion Latency" (first data after a start
//! takes the sinc order's number of periods) and "Serial Interface" (mode 1, tc(SC) ≥ 125 ns).
//!
//! The harness drives the analog inputs (volts) and time; faults are switches on the model.

use accomp::acquisition::{SpiRequirement, ADS1262_SPI};

use crate::bus::{crc8, Chip, Clock, Port};

const ID: usize = 0x00;
const POWER: usize = 0x01;
const INTERFACE: usize = 0x02;
const MODE0: usize = 0x03;
const MODE1: usize = 0x04;
const MODE2: usize = 0x05;
const INPMUX: usize = 0x06;
const REFMUX: usize = 0x0F;
const N_REGS: usize = 0x1B;

/// Power-on register values (SBAS661C register map; ID: DEV_ID 000, REV_ID 2 here).
const RESET_VALUES: [u8; N_REGS] = [
    0x02, 0x11, 0x05, 0x00, 0x80, 0x04, 0x01, 0x00, 0x00, 0x00, 0x00, 0x00, 0x40, 0xBB, 0x00, 0x00,
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x01, 0x00, 0x00, 0x40,
];

/// MODE2.DR → samples per second.
const SPS: [f64; 16] = [
    2.5, 5.0, 10.0, 16.6, 20.0, 50.0, 60.0, 100.0, 400.0, 1200.0, 2400.0, 4800.0, 7200.0, 14400.0,
    19200.0, 38400.0,
];

enum Frame {
    Command,
    RregCount(usize),
    WregCount(usize),
    Wreg {
        addr: usize,
        left: usize,
    },
    Output {
        bytes: Vec<u8>,
        pos: usize,
        repeat: bool,
    },
    Ignore,
}

pub struct Ads1262Model {
    clock: Clock,
    regs: [u8; N_REGS],
    running: bool,
    next_conversion_us: Option<u64>,
    code: i32,
    alarms: u8,
    new_data: bool,
    frame: Frame,
    /// Differential input on AIN0−AIN1 (accelerometer sense voltage), volts.
    pub accel_v: f64,
    /// Differential input on AIN2−AIN3 (tiltmeter), volts.
    pub tilt_v: f64,
    /// Fault: the modulator stops, DRDY never falls again ([`Self::set_stuck_drdy`]).
    stuck_drdy: bool,
    /// The SPI port's faults and refusals; `corrupt_reads` here are conversion reads, the last
    /// data byte's low bit flipped after the checksum or CRC.
    pub port: Port,
    /// Conversions completed (DRDY falling edges).
    pub drdy_edges: u64,
    /// The result in the output register: the time its conversion ended (its DRDY edge) and
    /// the INPMUX it converted. What a test compares the firmware's time stamps with.
    pub latched: Option<(u64, u8)>,
}

impl Ads1262Model {
    pub fn new(clock: Clock) -> Self {
        Self {
            clock,
            regs: RESET_VALUES,
            running: false,
            next_conversion_us: None,
            code: 0,
            alarms: 0,
            new_data: false,
            frame: Frame::Ignore,
            accel_v: 0.0,
            tilt_v: 0.0,
            stuck_drdy: false,
            port: Port::default(),
            drdy_edges: 0,
            latched: None,
        }
    }

    fn period_us(&self) -> f64 {
        1e6 / SPS[usize::from(self.regs[MODE2] & 0x0F)]
    }

    /// Periods from a start to the first settled result: sinc1..sinc4 → 1..4, FIR → 1; plus
    /// the programmable start delay and a fixed 0.3 ms.
    fn first_latency_us(&self) -> u64 {
        let order = match self.regs[MODE1] >> 5 {
            0 => 1.0,
            1 => 2.0,
            2 => 3.0,
            3 => 4.0,
            _ => 1.0,
        };
        (order * self.period_us() + 300.0) as u64
    }

    fn restart(&mut self) {
        self.running = true;
        self.new_data = false;
        self.next_conversion_us = Some(self.clock.now() + self.first_latency_us());
    }

    /// Fault switch: the modulator stops (DRDY never falls) or runs again. A modulator that
    /// runs again starts its conversion cycle at that moment ("Conversion Latency": the first
    /// result after a start takes the filter's settling), so no DRDY edge falls in the past:
    /// the conversions the stopped modulator never made are not delivered late.
    pub fn set_stuck_drdy(&mut self, stuck: bool) {
        if self.stuck_drdy && !stuck && self.running {
            self.restart();
        }
        self.stuck_drdy = stuck;
    }

    /// When DRDY will next fall, if it will.
    pub fn next_drdy(&self) -> Option<u64> {
        if self.stuck_drdy || !self.running {
            return None;
        }
        self.next_conversion_us
    }

    /// Let time pass up to now: every conversion that ends latches a result and drops DRDY.
    pub fn advance(&mut self) {
        let now = self.clock.now();
        while let Some(t) = self.next_drdy() {
            if t > now {
                break;
            }
            self.convert();
            self.latched = Some((t, self.regs[INPMUX]));
            self.drdy_edges += 1;
            self.next_conversion_us = Some(t + self.period_us() as u64);
        }
    }

    fn convert(&mut self) {
        let mux = self.regs[INPMUX];
        let v = match (mux >> 4, mux & 0x0F) {
            (0, 1) => self.accel_v,
            (2, 3) => self.tilt_v,
            _ => 0.0,
        };
        let gain = if self.regs[MODE2] & 0x80 != 0 {
            1.0
        } else {
            f64::from(1u32 << ((self.regs[MODE2] >> 4) & 0x07))
        };
        let internal_ref = self.regs[REFMUX] == 0;
        let vref = if internal_ref && self.regs[POWER] & 0x01 != 0 {
            2.5
        } else {
            0.0
        };
        self.alarms = 0;
        if vref < 0.4 {
            self.alarms |= 1 << 4; // REF_ALM
            self.code = 0x7FFF_FFFF;
        } else {
            let x = v * gain / vref * 2_147_483_648.0;
            if x >= 2_147_483_647.0 || x <= -2_147_483_648.0 {
                self.alarms |= 1 << 1; // PGAD_ALM: differential over-range
            }
            self.code = x.round().clamp(-2_147_483_648.0, 2_147_483_647.0) as i32;
        }
        self.new_data = true;
    }

    fn data_frame(&mut self) -> Vec<u8> {
        let mut out = Vec::new();
        if self.regs[INTERFACE] & 0x04 != 0 {
            let mut status = self.alarms;
            if self.new_data {
                status |= 1 << 6;
            }
            if self.regs[POWER] & 0x10 != 0 {
                status |= 1;
            }
            out.push(status);
        }
        let mut data = self.code.to_be_bytes();
        let check = match self.regs[INTERFACE] & 0x03 {
            0b01 => Some(data.iter().fold(0x9Bu8, |a, b| a.wrapping_add(*b))),
            0b10 => Some(crc8(&data)),
            _ => None,
        };
        if self.port.corrupt_reads > 0 {
            self.port.corrupt_reads -= 1;
            data[3] ^= 0x01;
        }
        out.extend_from_slice(&data);
        out.extend(check);
        self.new_data = false;
        out
    }

    fn write_register(&mut self, addr: usize, value: u8) {
        match addr {
            ID => {}
            // RESET can only be cleared by writing 0 (writing 1 keeps it as it is).
            POWER => self.regs[POWER] = (value & 0x03) | (self.regs[POWER] & value & 0x10),
            a if a < N_REGS => self.regs[a] = value,
            _ => {}
        }
        // "Writing new data to certain registers results in a conversion-cycle restart."
        if self.running && ((MODE0..=INPMUX).contains(&addr) || addr == REFMUX) {
            self.restart();
        }
    }
}

impl Chip for Ads1262Model {
    const REQUIRED: SpiRequirement = ADS1262_SPI;

    fn begin_frame(&mut self) {
        self.advance();
        self.frame = Frame::Command;
    }

    fn exchange(&mut self, mosi: u8) -> u8 {
        match std::mem::replace(&mut self.frame, Frame::Ignore) {
            Frame::Command => {
                match mosi {
                    0x06 => {
                        // RESET: registers to power-on values; conversions stop (START low).
                        self.power_glitch();
                    }
                    0x08 => self.restart(),
                    0x0A => {
                        self.running = false;
                        self.next_conversion_us = None;
                    }
                    0x12 => {
                        let bytes = self.data_frame();
                        self.frame = Frame::Output {
                            bytes,
                            pos: 0,
                            repeat: true,
                        };
                    }
                    op if op & 0xE0 == 0x20 => {
                        self.frame = Frame::RregCount(usize::from(op & 0x1F))
                    }
                    op if op & 0xE0 == 0x40 => {
                        self.frame = Frame::WregCount(usize::from(op & 0x1F))
                    }
                    _ => {}
                }
                0xFF
            }
            Frame::RregCount(start) => {
                let n = usize::from(mosi & 0x1F) + 1;
                // Past the last register the device outputs zeros (no wrap).
                let bytes = (start..start + n)
                    .map(|a| self.regs.get(a).copied().unwrap_or(0))
                    .collect();
                self.frame = Frame::Output {
                    bytes,
                    pos: 0,
                    repeat: false,
                };
                0xFF
            }
            Frame::WregCount(start) => {
                self.frame = Frame::Wreg {
                    addr: start,
                    left: usize::from(mosi & 0x1F) + 1,
                };
                0xFF
            }
            Frame::Wreg { addr, left } => {
                self.write_register(addr, mosi);
                if left > 1 {
                    self.frame = Frame::Wreg {
                        addr: addr + 1,
                        left: left - 1,
                    };
                }
                0xFF
            }
            Frame::Output { bytes, pos, repeat } => {
                let b = if repeat {
                    bytes[pos % bytes.len()]
                } else {
                    bytes.get(pos).copied().unwrap_or(0)
                };
                self.frame = Frame::Output {
                    bytes,
                    pos: pos + 1,
                    repeat,
                };
                b
            }
            Frame::Ignore => 0xFF,
        }
    }

    fn end_frame(&mut self) {
        self.frame = Frame::Ignore;
    }

    /// A supply glitch: every register back to its power-on value, conversions stopped (the
    /// START pin is held low, so only a START1 command restarts them).
    fn power_glitch(&mut self) {
        self.regs = RESET_VALUES;
        self.running = false;
        self.next_conversion_us = None;
        self.new_data = false;
    }

    fn port(&mut self) -> &mut Port {
        &mut self.port
    }
}
