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
    /// The flash's count of erase-stall time, µs.
    stalled_us: std::sync::Arc<std::sync::atomic::AtomicU64>,
    /// Stall time of erases run by the service that the chips have not lived through yet.
    pending_stall_us: u64,
    /// The time the board was last run to ([`Self::run_until`]).
    run_end_us: u64,
    /// Received bytes not handled yet (held during a stall).
    held: Vec<u8>,
}

impl VirtualBoard {
    /// Powers a board up at world time `world_us` on `flash` (the tables survive in it).
    pub fn boot(flash: BoardFlash, world_us: u64, reset_cause: u8) -> Self {
        Self::boot_after(flash, world_us, reset_cause, None)
    }

    /// A boot, given the boot id the board's reset-surviving RAM kept (None: a power-on).
    fn boot_after(
        flash: BoardFlash,
        world_us: u64,
        reset_cause: u8,
        kept_boot_id: Option<u32>,
    ) -> Self {
        let clock = Clock::default();
        // The board's clock starts at its power-up; 1 ms for the reset sequence.
        clock.set(1_000);
        let run_end_us = clock.now();
        let layout = flash::SLOT_LAYOUT;
        let stalled_us = flash.watcher.stalled_us.clone();
        let mut service = Service::new(Board::Frontend, flash, layout);
        let report = BootReport {
            reset_cause,
            clock_fallback: false,
            boot_id: 0,
        };
        // The power-on nonce: a freshly seeded hasher differs in every process and every call,
        // as the SRAM's power-up state differs between a real board's power-ons.
        let nonce = || {
            use std::hash::BuildHasher;
            std::collections::hash_map::RandomState::new().hash_one(world_us) as u32
        };
        service.set_boot_report(BootReport {
            boot_id: report.next_boot_id(kept_boot_id, nonce),
            ..report
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
            stalled_us,
            pending_stall_us: 0,
            run_end_us,
            held: Vec::new(),
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
        let boot_id = self.service.boot_report().boot_id;
        let flash = self
            .service
            .into_flash()
            .ok_or_else(|| std::io::Error::other("the board's flash store was unusable"))?;
        let mut b = VirtualBoard::boot_after(flash, world_us, reset_cause, Some(boot_id));
        b.faults = faults;
        Ok(b)
    }

    /// Bytes from the PC: requests are answered in order (the worker's part). While the core
    /// is stalled by a flash erase the bytes wait (the UART's DMA ring keeps them) and are
    /// answered once the board has run past the stall.
    pub fn receive(&mut self, bytes: &[u8]) {
        self.held.extend_from_slice(bytes);
        self.take_held();
    }

    /// True while a flash erase stalls the core: one ran and the chips have not lived through
    /// it yet, or the board's clock is still ahead of the time it was last run to.
    fn stalled(&self) -> bool {
        self.pending_stall_us > 0 || self.board.now() > self.run_end_us
    }

    fn take_held(&mut self) {
        let mut used = 0;
        while used < self.held.len() && !self.stalled() {
            let b = self.held[used];
            used += 1;
            let Some(frame) = self.decoder.push(b) else {
                continue;
            };
            let frame = frame.map(<[u8]>::to_vec);
            let clock = self.flash_clock();
            if let Some(reply) = self
                .service
                .handle_frame(frame.as_deref().map_err(|e| *e), &|| clock.now())
            {
                send(&mut self.tx, &reply);
            }
            self.pending_stall_us += clock.stalled();
        }
        self.held.drain(..used);
        if self.service.rate_hz() != self.rate_hz {
            self.rate_hz = self.service.rate_hz();
            if let Some(r) = DataRate::from_sps(self.rate_hz) {
                self.board.ads_seq.request_rate(r);
            }
        }
    }

    /// Erases the spare slot when the firmware would (after an answer, no request waiting).
    pub fn idle(&mut self) {
        if self.service.erase_pending() && self.held.is_empty() && !self.stalled() {
            let clock = self.flash_clock();
            let _ = self.service.erase_ahead(&|| clock.now());
            self.pending_stall_us += clock.stalled();
        }
    }

    /// The board's clock as the service sees it during a flash operation: an erase stall of
    /// the `erase-stall` fault moves it on (the time base counts through the stall), so Info
    /// counts the stall's length.
    fn flash_clock(&self) -> FlashClock {
        FlashClock {
            now_us: self.board.now(),
            stalled_us: self.stalled_us.clone(),
            before_us: self.stalled_us.load(std::sync::atomic::Ordering::Relaxed),
        }
    }

    /// Runs the board until its clock reads `end_us`: DRDY edges, supervisor and RTD ticks in
    /// time order, each seeing the physics of its moment; finished pairs go through the
    /// service (seq, losses, pipeline) and out on the UART while streaming.
    pub fn run_until(&mut self, end_us: u64, station: &mut Station) {
        let stall_us = std::mem::take(&mut self.pending_stall_us);
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
            a.set_stuck_drdy(faults.drdy_stall);
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
        // An erase stalled the core: the chips converted meanwhile, no handler ran; the DRDY
        // served after it finds the sequencer's pair clock behind (a STALL gap in seq).
        if stall_us > 0 {
            board.stall(stall_us, &mut inputs, &mut out);
        }
        board.run_until(end_us, &mut inputs, &mut out);
        self.run_end_us = end_us;
        self.take_held();
    }
}

/// The service's clock during a flash operation ([`VirtualBoard::flash_clock`]).
struct FlashClock {
    now_us: u64,
    stalled_us: std::sync::Arc<std::sync::atomic::AtomicU64>,
    before_us: u64,
}

impl FlashClock {
    /// Stall time since the clock was taken, µs.
    fn stalled(&self) -> u64 {
        self.stalled_us.load(std::sync::atomic::Ordering::Relaxed) - self.before_us
    }

    fn now(&self) -> u64 {
        self.now_us + self.stalled()
    }
}

/// Appends `msg` as a frame to the UART's outgoing bytes.
fn send(tx: &mut Vec<u8>, msg: &DeviceMessage) {
    let mut out = [0u8; MAX_FRAME_LEN];
    if let Ok(n) = encode_frame(msg, &mut out) {
        tx.extend_from_slice(&out[..n]);
    }
}

#[cfg(test)]
mod tests {
    use std::sync::atomic::Ordering;

    use accomp::pipeline::{Frame, LossFlags};
    use accomp::protocol::{decode_message, upload_requests, HostFrame, Request, Response};

    use super::*;

    /// A host on the board's line: requests in, every message out decoded.
    struct Host {
        board: VirtualBoard,
        station: Station,
        decoder: FrameDecoder<MAX_FRAME_LEN>,
        frames: Vec<Frame>,
        next_id: u32,
    }

    impl Host {
        /// Sends a request and runs the board in 10 ms steps until its answer is out.
        fn call(&mut self, request: Request) -> Response {
            self.next_id += 1;
            let id = self.next_id;
            let mut buf = [0u8; MAX_FRAME_LEN];
            let n = encode_frame(&HostFrame { id, request }, &mut buf).unwrap();
            self.board.receive(&buf[..n]);
            self.board.idle();
            for _ in 0..1000 {
                let tx = std::mem::take(&mut self.board.tx);
                let mut answer = None;
                for b in tx {
                    if let Some(Ok(body)) = self.decoder.push(b) {
                        match decode_message::<DeviceMessage>(body).unwrap() {
                            DeviceMessage::Sample { frame, .. } => self.frames.push(frame),
                            DeviceMessage::Response { id: i, body } if i == id => {
                                answer = Some(body)
                            }
                            other => panic!("{other:?}"),
                        }
                    }
                }
                if let Some(a) = answer {
                    return a;
                }
                self.run(10_000);
            }
            panic!("request {id} unanswered");
        }

        fn run(&mut self, us: u64) {
            let end = self.board.now_us() + us;
            self.board.run_until(end, &mut self.station);
            self.board.idle();
        }

        fn upload(&mut self, day: u8) {
            let mut t = crate::paper_table();
            t.date.day = day;
            let bytes = t.encode();
            let answers: Vec<_> = upload_requests(100 + u32::from(day), &bytes)
                .map(|request| self.call(request))
                .collect();
            assert_eq!(
                answers.last(),
                Some(&Response::Committed { table_id: t.id() })
            );
        }
    }

    /// `erase-stall=2000` and a table loaded while streaming onto a spare that holds an old
    /// table: the commit's erase stalls the board 2 s of its clock — the pairs it missed are a
    /// seq gap flagged STALL, and Info counts the stall with its 2,000,000 µs.
    #[test]
    fn an_erase_stall_fault_stalls_the_board_clock_and_info_counts_its_length() {
        let scenario = accomp_sim::scenario::Scenario::preset("paper-1g").unwrap();
        let flash = flash::open(None).unwrap();
        // The fault control's switch, as `board-sim`'s `erase-stall=2000` sets it.
        let flash_stall = flash.watcher.erase_stall_ms.clone();
        let mut host = Host {
            board: VirtualBoard::boot(flash, 0, 0),
            station: Station::new(&scenario, 1).unwrap(),
            decoder: FrameDecoder::new(),
            frames: Vec::new(),
            next_id: 0,
        };
        host.board.tx.clear();
        host.run(2_000_000);
        assert_eq!(host.call(Request::StreamStart), Response::Ok);
        for day in 1..=3 {
            host.upload(day); // blank slots: no erase
        }
        host.run(5_000_000);
        let stall = host.board.stalled_us.clone();
        flash_stall.store(2000, Ordering::Relaxed);
        host.upload(4); // the spare holds table 1: this commit erases
        host.run(5_000_000);
        assert_eq!(stall.load(Ordering::Relaxed), 2_000_000);
        let Response::Info(info) = host.call(Request::Info) else {
            panic!("Info")
        };
        assert_eq!(info.losses.erase_stalls, 1);
        assert_eq!(info.losses.erase_stall_us, 2_000_000);
        let gaps: Vec<(u32, LossFlags)> = host
            .frames
            .windows(2)
            .filter(|w| w[1].seq != w[0].seq + 1)
            .map(|w| (w[1].seq - w[0].seq - 1, w[1].lost))
            .collect();
        // 2 s at 10 SPS (0.8 s pairs): two pairs missed, or three with the dropped one.
        assert_eq!(gaps.len(), 1, "{gaps:?}");
        assert!((2..=3).contains(&gaps[0].0), "{gaps:?}");
        assert!(gaps[0].1.has(LossFlags::STALL));
        assert_eq!(
            u64::from(gaps[0].0),
            u64::from(info.losses.conversions_lost)
        );
    }
}
