//! The simulated SPI buses: a virtual clock, a delay that advances it, and an
//! `embedded_hal::spi::SpiDevice` per chip that knows the mode and clock its bus runs and lets
//! the chip model refuse a transaction its datasheet does not allow.

use std::cell::{Cell, RefCell};
use std::rc::Rc;

use accomp::acquisition::{SpiRequirement, SpiSettings};
use embedded_hal::spi::{ErrorKind, ErrorType, Operation, SpiDevice};

/// Virtual firmware time in µs, shared by the harness, the delays and the chip models.
#[derive(Clone, Default)]
pub struct Clock(Rc<Cell<u64>>);

impl Clock {
    pub fn now(&self) -> u64 {
        self.0.get()
    }
    pub fn set(&self, t: u64) {
        assert!(t >= self.0.get(), "time runs forward");
        self.0.set(t);
    }
}

/// `DelayNs` that lets virtual time pass (the boot-time reset waits).
pub struct SimDelay(pub Clock);

impl embedded_hal::delay::DelayNs for SimDelay {
    fn delay_ns(&mut self, ns: u32) {
        let c = &self.0;
        c.set(c.now() + u64::from(ns).div_ceil(1000));
    }
}

/// A chip at byte level: one frame per chip-select assertion.
pub trait Chip {
    /// What the datasheet allows on the bus.
    const REQUIRED: SpiRequirement;
    /// CS fell.
    fn begin_frame(&mut self);
    /// One byte each way, MSB first, in the chip's own SPI mode.
    fn exchange(&mut self, mosi: u8) -> u8;
    /// CS rose.
    fn end_frame(&mut self);
    /// A supply glitch: the chip back to its power-on state.
    fn power_glitch(&mut self);
    /// The port's faults and count, which the bus applies the same way to every chip.
    fn port(&mut self) -> &mut Port;
}

/// A chip's SPI port as the harness sees it: the faults it switches on the wire and the count
/// of transactions the chip refused. The same on every chip model.
#[derive(Debug, Default)]
pub struct Port {
    /// Fault: MISO reads all ones (chip unpowered or line open with a pull-up).
    pub miso_high: bool,
    /// Fault: corrupt this many upcoming reads, one bit flipped on the wire after the chip
    /// computed its check byte (which reads count, and which bit, is the chip model's).
    pub corrupt_reads: u32,
    /// Transactions refused (wrong mode or clock).
    pub refusals: u32,
}

/// Why the model refused a transaction.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BusRefusal {
    /// CPOL/CPHA differ from the chip's timing diagram: on a real board the chip would shift
    /// one edge off and every byte would be wrong.
    WrongMode,
    /// SCLK faster than the datasheet's minimum period allows.
    ClockTooFast,
}

impl embedded_hal::spi::Error for BusRefusal {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Other
    }
}

/// The SpiDevice a driver gets: the chip model plus the settings its bus runs.
pub struct SimSpi<M> {
    pub chip: Rc<RefCell<M>>,
    pub bus: SpiSettings,
}

impl<M> SimSpi<M> {
    /// A driver's handle on `chip`, over a bus run with `bus`.
    pub fn new(chip: &Rc<RefCell<M>>, bus: SpiSettings) -> Self {
        SimSpi {
            chip: chip.clone(),
            bus,
        }
    }
}

impl<M> ErrorType for SimSpi<M> {
    type Error = BusRefusal;
}

impl<M: Chip> SpiDevice for SimSpi<M> {
    fn transaction(&mut self, operations: &mut [Operation<'_, u8>]) -> Result<(), BusRefusal> {
        let mut chip = self.chip.borrow_mut();
        let req = M::REQUIRED;
        if !req.accepts(&self.bus) {
            chip.port().refusals += 1;
            let same_mode = SpiRequirement {
                mode: self.bus.mode,
                max_sclk_hz: u32::MAX,
            }
            .accepts(&SpiSettings {
                mode: req.mode,
                sclk_hz: 1,
            });
            return Err(if same_mode {
                BusRefusal::ClockTooFast
            } else {
                BusRefusal::WrongMode
            });
        }
        chip.begin_frame();
        let chip = &mut *chip;
        // One byte each way, with the MISO fault on the wire after the chip.
        let mut exchange = |mosi: u8| {
            let miso = chip.exchange(mosi);
            if chip.port().miso_high {
                0xFF
            } else {
                miso
            }
        };
        for op in operations.iter_mut() {
            match op {
                Operation::Write(w) => {
                    for b in w.iter() {
                        exchange(*b);
                    }
                }
                Operation::Read(r) => {
                    for b in r.iter_mut() {
                        *b = exchange(0x00);
                    }
                }
                Operation::Transfer(r, w) => {
                    let n = r.len().max(w.len());
                    for i in 0..n {
                        let out = exchange(w.get(i).copied().unwrap_or(0x00));
                        if let Some(x) = r.get_mut(i) {
                            *x = out;
                        }
                    }
                }
                Operation::TransferInPlace(buf) => {
                    for b in buf.iter_mut() {
                        *b = exchange(*b);
                    }
                }
                Operation::DelayNs(_) => {}
            }
        }
        chip.end_frame();
        Ok(())
    }
}

/// CRC-8, polynomial x⁸ + x² + x + 1, initial 0, bit by bit — written here from the two
/// datasheets' descriptions, independently of the drivers' table-driven `crc` crate use.
pub fn crc8(bytes: &[u8]) -> u8 {
    let mut crc = 0u8;
    for &b in bytes {
        crc ^= b;
        for _ in 0..8 {
            crc = if crc & 0x80 != 0 {
                (crc << 1) ^ 0x07
            } else {
                crc << 1
            };
        }
    }
    crc
}

#[test]
fn crc8_matches_the_catalogue_check_value() {
    // CRC-8/SMBUS check value for "123456789".
    assert_eq!(crc8(b"123456789"), 0xF4);
}
