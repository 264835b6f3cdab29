//! The front-end board's acquisition on the chip models: the real drivers and sequencers of the
//! core on the ADS1262 and AD7124-4 models, run in time order the way the firmware's interrupts
//! and tasks run them (`src/main.rs`): the ADS1262 DRDY interrupt (EXTI1, highest priority),
//! the ADS1262 supervisor tick every 20 ms, the RTD task at the AD7124's rate, and the worker's
//! sample assembler joining the latest RTD reading to each pair.
//!
//! One [`Board`] serves the timed tests (`tests/board_sim.rs`) and the virtual board behind
//! `accomp board-sim`: what the world puts on the chips' inputs and what becomes of a finished
//! pair are the caller's (an [`Inputs`] and a closure).

use std::cell::RefCell;
use std::rc::Rc;

use accomp::acquisition::{
    AdsReading, AdsSequencer, InterruptDrdy, RtdSequencer, SampleAssembler, SpiSettings,
};
use accomp::board;
use accomp::drivers::ad7124::Ad7124;
use accomp::drivers::ads1262::Ads1262;
use accomp::pipeline::RawSample;

use crate::{Ad7124Model, Ads1262Model, Clock, SimDelay, SimSpi};

/// The ADS1262 sequencer on its model.
pub type AdsSeq = AdsSequencer<SimSpi<Ads1262Model>, InterruptDrdy, SimDelay>;
/// The AD7124 sequencer on its model.
pub type RtdSeq = RtdSequencer<SimSpi<Ad7124Model>, InterruptDrdy, SimDelay>;

/// Supervisor tick of the ADS1262 sequencer (the firmware's `ADS_TICK_MS`).
pub const ADS_TICK_US: u64 = 20_000;
/// An RTD reading further than this from a pair is not joined to it (the firmware's
/// `RTD_MAX_AGE_US`).
pub const RTD_MAX_AGE_US: u64 = 1_000_000;

/// INPMUX of the accelerometer input (AIN0−AIN1), as the model latches it.
const ACCEL_INPMUX: u8 = 0x01;

/// What the world puts on the chips' analog inputs at a moment of the board's clock. Called
/// before every event, after the models have converted up to that moment.
pub trait Inputs {
    /// Sets the inputs for time `t_us` (board clock).
    fn apply(&mut self, t_us: u64, ads: &mut Ads1262Model, rtd: &mut Ad7124Model);
}

impl<F: FnMut(u64, &mut Ads1262Model, &mut Ad7124Model)> Inputs for F {
    fn apply(&mut self, t_us: u64, ads: &mut Ads1262Model, rtd: &mut Ad7124Model) {
        self(t_us, ads, rtd)
    }
}

/// A finished pair as the worker gets it: the sequencer's reading, the raw sample with the RTD
/// joined, and — from the model, not the firmware — when the accelerometer conversion it
/// carries really ended.
#[derive(Debug, Clone, Copy)]
pub struct Acquired {
    pub reading: AdsReading,
    pub raw: RawSample,
    /// DRDY time of the accelerometer conversion read into this pair, from the ADS1262 model
    /// (None for a timeout reading, which carries no conversion).
    pub true_accel_drdy_us: Option<u64>,
}

/// The acquisition half of the front-end board on the chip models.
pub struct Board {
    pub clock: Clock,
    pub ads: Rc<RefCell<Ads1262Model>>,
    pub rtd: Rc<RefCell<Ad7124Model>>,
    pub ads_seq: AdsSeq,
    pub rtd_seq: RtdSeq,
    pub assembler: SampleAssembler,
    next_ads_tick: u64,
    next_rtd_tick: u64,
    /// True end of the accelerometer conversion the DRDY handler last read.
    accel_true_us: Option<u64>,
}

impl Board {
    /// Powers the chips up on buses `ads_bus` and `rtd_bus` at the clock's present time; the
    /// sequencers bring them up in steps from their first ticks, as the firmware does.
    pub fn with_buses(clock: Clock, ads_bus: SpiSettings, rtd_bus: SpiSettings) -> Self {
        let ads = Rc::new(RefCell::new(Ads1262Model::new(clock.clone())));
        let rtd = Rc::new(RefCell::new(Ad7124Model::new(clock.clone())));
        let ads_driver = Ads1262::new(
            SimSpi::new(&ads, ads_bus),
            InterruptDrdy,
            SimDelay(clock.clone()),
            board::ads1262_config(),
        );
        let rtd_driver = Ad7124::new(
            SimSpi::new(&rtd, rtd_bus),
            InterruptDrdy,
            SimDelay(clock.clone()),
            board::ad7124_config(),
        );
        let rtd_seq = RtdSequencer::new(rtd_driver);
        let now = clock.now();
        Board {
            next_ads_tick: now + ADS_TICK_US,
            next_rtd_tick: now + rtd_seq.period_us(),
            clock,
            ads,
            rtd,
            ads_seq: AdsSequencer::new(ads_driver),
            rtd_seq,
            assembler: SampleAssembler::new(RTD_MAX_AGE_US),
            accel_true_us: None,
        }
    }

    /// The board as built: the buses of `accomp::board`.
    pub fn new(clock: Clock) -> Self {
        Self::with_buses(clock, board::ADS1262_BUS, board::AD7124_BUS)
    }

    /// The board's clock, µs.
    pub fn now(&self) -> u64 {
        self.clock.now()
    }

    /// When the next chip event (DRDY edge, supervisor tick, RTD tick) is due.
    pub fn next_event_us(&self) -> u64 {
        let drdy = self.ads.borrow().next_drdy().unwrap_or(u64::MAX);
        drdy.min(self.next_ads_tick).min(self.next_rtd_tick)
    }

    /// Lets the models convert up to now and sets their inputs.
    pub fn apply(&mut self, inputs: &mut impl Inputs) {
        let t = self.clock.now();
        let mut a = self.ads.borrow_mut();
        let mut r = self.rtd.borrow_mut();
        a.advance();
        r.advance();
        inputs.apply(t, &mut a, &mut r);
    }

    /// The DRDY interrupt at `t_us`.
    fn drdy(&mut self, t_us: u64, out: &mut impl FnMut(Acquired)) {
        let latched = self.ads.borrow().latched;
        if let Some(reading) = self.ads_seq.on_drdy(t_us) {
            let accel_true = self.accel_true_us.take();
            self.emit(reading, accel_true, out);
        } else if let Some((t, mux)) = latched {
            // The accelerometer half of a pair: remember when its conversion really ended.
            self.accel_true_us = (mux == ACCEL_INPMUX).then_some(t);
        }
    }

    fn emit(
        &mut self,
        reading: AdsReading,
        accel_true: Option<u64>,
        out: &mut impl FnMut(Acquired),
    ) {
        let raw = self.assembler.assemble(&reading);
        let conversion = reading.accel_flags.0 == 0;
        out(Acquired {
            reading,
            raw,
            true_accel_drdy_us: accel_true.filter(|_| conversion),
        });
    }

    /// Runs until the clock reads `end_us`: DRDY edges, the supervisor tick and the RTD tick in
    /// time order, each seeing the inputs of its moment; every finished pair goes to `out`.
    pub fn run_until(
        &mut self,
        end_us: u64,
        inputs: &mut impl Inputs,
        out: &mut impl FnMut(Acquired),
    ) {
        loop {
            let drdy = self.ads.borrow().next_drdy().unwrap_or(u64::MAX);
            let t = drdy.min(self.next_ads_tick).min(self.next_rtd_tick);
            if t > end_us {
                if end_us > self.clock.now() {
                    self.clock.set(end_us);
                }
                self.apply(inputs);
                return;
            }
            self.clock.set(t.max(self.clock.now()));
            self.apply(inputs);
            if t == drdy {
                self.drdy(t, out);
            }
            if t == self.next_rtd_tick {
                if let Some(r) = self.rtd_seq.on_tick(t) {
                    self.assembler.rtd(r);
                }
                self.next_rtd_tick = t + self.rtd_seq.period_us();
            }
            if t == self.next_ads_tick {
                if let Some(r) = self.ads_seq.on_tick(t) {
                    self.emit(r, None, out);
                }
                self.next_ads_tick = t + ADS_TICK_US;
            }
        }
    }

    /// The core stalls for `duration_us` (a flash erase or program: no instruction fetch, no
    /// handler runs, RM0090 §3.5) while the converters go on converting. Then the DRDY
    /// interrupt that became pending during the stall runs first (EXTI1 has the highest
    /// priority), then the overdue ticks (at their next event). The DRDY handler runs while
    /// the flash driver's operation is still in progress (it preempts the worker that waits for
    /// it): as in `src/main.rs`, it drops the conversion, whose time it does not know.
    pub fn stall(
        &mut self,
        duration_us: u64,
        inputs: &mut impl Inputs,
        out: &mut impl FnMut(Acquired),
    ) {
        let edges = self.ads.borrow().drdy_edges;
        let end = self.now() + duration_us;
        self.clock.set(end);
        self.apply(inputs);
        if self.ads.borrow().drdy_edges != edges {
            self.ads_seq.restart_pair();
            self.drdy(end, out);
        }
        self.next_ads_tick = self.next_ads_tick.max(end);
        self.next_rtd_tick = self.next_rtd_tick.max(end);
    }
}
