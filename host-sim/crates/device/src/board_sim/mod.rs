//! The virtual front-end board behind `accomp board-sim`: the firmware's real core — the
//! protocol [`Service`] with its calibration store, the acquisition sequencers, the sample
//! assembler and the pipeline — running on the register-level models of the ADS1262 and the
//! AD7124-4 (the `accomp-chipsim` crate, which the core's board tests use too), whose analog inputs follow the station
//! simulator's physics for a scenario: the accelerometer's output voltage, the RTD's resistance
//! and the tiltmeter's voltage.
//!
//! Time: the board's clock (µs since its boot) is virtual and advanced by the caller; the world
//! (the scenario) keeps running across board resets. The simulator steps at the scenario's
//! interval and the inputs are interpolated linearly between its steps.
//!
//! What the firmware's `main.rs` does with RTIC tasks is done by the chip simulator's
//! [`Board`] in one event loop, in time order: ADS1262 DRDY edges, the supervisor tick, the RTD
//! task's tick; requests are handled between events, as the worker does.

pub mod flash;
pub mod pty;

use accomp::drivers::ads1262::DataRate;
use accomp::protocol::{
    encode_frame, Board, BootReport, DeviceMessage, FrameDecoder, MAX_FRAME_LEN, PROTOCOL_VERSION,
};
use accomp::service::Service;

use accomp_chipsim::{Acquired, Ad7124Model, Ads1262Model, Clock};
use accomp_sim::{scenario::Scenario, Sample, SimError, Simulator};
use flash::BoardFlash;

/// The physical inputs at a moment of the world's time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Physics {
    /// Accelerometer output across the sense resistor, V.
    pub accel_v: f64,
    /// RTD resistance as wired, Ω.
    pub rtd_ohms: f64,
    /// Tiltmeter output, V.
    pub tilt_v: f64,
}

/// The station simulator sampled at any time: linear interpolation between its steps.
pub struct Station {
    sim: Simulator,
    tilt_arcsec_per_v: f64,
    prev: Sample,
    next: Sample,
}

impl Station {
    /// The station of `scenario` with `seed`, at world time 0.
    pub fn new(scenario: &Scenario, seed: u64) -> Result<Self, SimError> {
        let mut sim = Simulator::new(scenario, seed)?;
        let prev = sim.step()?;
        let next = sim.step()?;
        Ok(Station {
            sim,
            tilt_arcsec_per_v: scenario.tiltmeter.scale_arcsec_per_v,
            prev,
            next,
        })
    }

    /// The inputs at world time `t_s` (never earlier than the last call's; past the scenario's
    /// end the last step holds).
    pub fn at(&mut self, t_s: f64) -> Physics {
        while self.next.time_s < t_s {
            match self.sim.step() {
                Ok(s) => {
                    self.prev = self.next;
                    self.next = s;
                }
                Err(_) => break,
            }
        }
        let span = self.next.time_s - self.prev.time_s;
        let w = if span > 0.0 {
            ((t_s - self.prev.time_s) / span).clamp(0.0, 1.0)
        } else {
            1.0
        };
        let lerp = |a: f64, b: f64| a + (b - a) * w;
        Physics {
            accel_v: lerp(self.prev.truth_output_v, self.next.truth_output_v),
            rtd_ohms: lerp(self.prev.truth_rtd_ohms, self.next.truth_rtd_ohms),
            tilt_v: lerp(self.prev.truth_tilt_arcsec, self.next.truth_tilt_arcsec)
                / self.tilt_arcsec_per_v,
        }
    }
}

/// Faults switched on and off from outside.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Faults {
    /// The RTD loop is open (infinite resistance).
    pub rtd_open: bool,
    /// The ADS1262 stops converting (DRDY never falls).
    pub drdy_stall: bool,
}

/// One board: chips, sequencers, the service, and the bytes it has to send.
pub struct VirtualBoard {
    board: accomp_chipsim::Board,
    service: Service<BoardFlash>,
    decoder: FrameDecoder<MAX_FRAME_LEN>,
    rate_hz: u32,
    /// World time at this board's boot, µs.
    boot_world_us: u64,
    /// Bytes waiting for the UART.
    pub tx: Vec<u8>,
    /// Faults in force.
    pub faults: Faults,
    /// Frames streamed since boot.
    pub frames_sent: u64,
}

impl VirtualBoard {
    /// Powers a board up at world time `world_us` on `flash` (the tables survive in it).
    pub fn boot(flash: BoardFlash, world_us: u64, reset_cause: u8) -> Self {
        let clock = Clock::default();
        // The board's clock starts at its power-up; 1 ms for the reset sequence.
        clock.set(1_000);
        let layout = flash::SLOT_LAYOUT;
        let mut service = Service::new(Board::Frontend, flash, layout);
        service.set_boot_report(BootReport {
            reset_cause,
            clock_fallback: false,
        });
        let mut b = VirtualBoard {
            board: accomp_chipsim::Board::new(clock),
            rate_hz: service.rate_hz(),
            service,
            decoder: FrameDecoder::new(),
            boot_world_us: world_us,
            tx: Vec::new(),
            faults: Faults::default(),
            frames_sent: 0,
        };
        // READY once the receiver is live.
        send(
            &mut b.tx,
            &DeviceMessage::Ready {
                board: Board::Frontend,
                protocol: PROTOCOL_VERSION,
            },
        );
        b
    }

    /// The board's own time, µs since boot.
    pub fn now_us(&self) -> u64 {
        self.board.now()
    }

    /// World time at the board's boot, µs.
    pub fn boot_world_us(&self) -> u64 {
        self.boot_world_us
    }

    /// A reset at world time `world_us`: a new boot on the same flash (tables kept), the
    /// faults still in force (they are outside the MCU).
    pub fn reset(self, world_us: u64, reset_cause: u8) -> std::io::Result<Self> {
        let faults = self.faults;
        let flash = self
            .service
            .into_flash()
            .ok_or_else(|| std::io::Error::other("the board's flash store was unusable"))?;
        let mut b = VirtualBoard::boot(flash, world_us, reset_cause);
        b.faults = faults;
        Ok(b)
    }

    /// Bytes from the PC: requests are answered in order (the worker's part).
    pub fn receive(&mut self, bytes: &[u8]) {
        for &b in bytes {
            let Some(frame) = self.decoder.push(b) else {
                continue;
            };
            let frame = frame.map(<[u8]>::to_vec);
            let now = self.board.now();
            if let Some(reply) = self
                .service
                .handle_frame(frame.as_deref().map_err(|e| *e), &|| now)
            {
                send(&mut self.tx, &reply);
            }
        }
        if self.service.rate_hz() != self.rate_hz {
            self.rate_hz = self.service.rate_hz();
            if let Some(r) = DataRate::from_sps(self.rate_hz) {
                self.board.ads_seq.request_rate(r);
            }
        }
    }

    /// Erases the spare slot when the firmware would (after an answer, no request waiting).
    pub fn idle(&mut self) {
        if self.service.erase_pending() {
            // The board's clock stands still during the call (the stall of an `erase-stall`
            // fault is wall time: the board's clock jumps after it, the sequencer sees the
            // missed conversions), so the erase-stall time counted here is 0 µs.
            let now = self.board.now();
            let _ = self.service.erase_ahead(&|| now);
        }
    }

    /// Runs the board until its clock reads `end_us`: DRDY edges, supervisor and RTD ticks in
    /// time order, each seeing the physics of its moment; finished pairs go through the
    /// service (seq, losses, pipeline) and out on the UART while streaming.
    pub fn run_until(&mut self, end_us: u64, station: &mut Station) {
        let VirtualBoard {
            board,
            service,
            boot_world_us,
            tx,
            faults,
            frames_sent,
            ..
        } = self;
        let mut inputs = |t: u64, a: &mut Ads1262Model, r: &mut Ad7124Model| {
            let p = station.at((*boot_world_us + t) as f64 * 1e-6);
            a.accel_v = p.accel_v;
            a.tilt_v = p.tilt_v;
            a.stuck_drdy = faults.drdy_stall;
            r.rtd_ohms = if faults.rtd_open {
                f64::INFINITY
            } else {
                p.rtd_ohms
            };
        };
        // The firmware's worker: seq and STALL losses from the sequencer.
        let mut out = |acq: Acquired| {
            let r = acq.reading;
            if let Some(msg) = service.acquired(r.seq, r.lost, &acq.raw, r.time_us) {
                send(tx, &msg);
                *frames_sent += 1;
            }
        };
        board.run_until(end_us, &mut inputs, &mut out);
    }
}

/// Appends `msg` as a frame to the UART's outgoing bytes.
fn send(tx: &mut Vec<u8>, msg: &DeviceMessage) {
    let mut out = [0u8; MAX_FRAME_LEN];
    if let Ok(n) = encode_frame(msg, &mut out) {
        tx.extend_from_slice(&out[..n]);
    }
}
