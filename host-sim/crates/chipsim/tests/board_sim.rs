//! The front-end board on the host: the real drivers, the real acquisition sequencer and the
//! real pipeline, wired to register-level models of the ADS1262 and the AD7124-4 that answer
//! SPI the way their datasheets say (this crate's `ads1262` and `ad7124` modules) and refuse a bus in the wrong
//! mode or too fast. A compact physical station (thermostat cycle, tide-like tilt, the core's
//! own accelerometer model equation) drives the analog inputs over simulated days while faults
//! are switched on and off; every fault must come out as a named status bit, every clean frame
//! must be right, and the stream must go on.
//!
//! The station is generated here from the core (the chip models and this test need nothing
//! above it). Run: `cargo test -p accomp-chipsim --test board_sim`.

use std::cell::RefCell;
use std::rc::Rc;

use accomp::acquisition::SpiSettings;
use accomp::board;
use accomp::drivers::ad7124;
use accomp::drivers::ads1262::{self, DataRate};
use accomp::model::StaticCoefficients;
use accomp::pipeline::{process_prepared, Frame, Status};
use accomp::prepared::PreparedCalibration;
use accomp::reference::paper_order2_table;
use accomp::table::CalibrationTable;
use accomp::units::{Celsius, Gs, RAD_PER_ARCSEC};
use embedded_hal::spi::{MODE_1, MODE_3};

use accomp_chipsim::{Acquired, Ad7124Model, Ads1262Model, Board, BusRefusal, Chip, Clock};

const S: u64 = 1_000_000;
const H: u64 = 3600 * S;

/// The thermostat, the foundation and the accelerometer: physical values at time t.
struct Station {
    table: CalibrationTable,
}

impl Station {
    /// Thermostat: 45 °C set point, a daily ±0.2 °C cycle of the room leaking through and a
    /// 30-minute ±0.02 °C controller limit cycle.
    fn temperature_c(&self, t_us: u64) -> f64 {
        let t = t_us as f64 / 1e6;
        45.0 + 0.2 * (2.0 * std::f64::consts::PI * t / 86_400.0).sin()
            + 0.02 * (2.0 * std::f64::consts::PI * t / 1_800.0).sin()
    }

    /// Foundation tilt about the input axis: a semidiurnal tide (M2, 12.42 h, ±1.5") and a
    /// slow settlement drift of 0.3"/day.
    fn tilt_arcsec(&self, t_us: u64) -> f64 {
        let t = t_us as f64 / 1e6;
        1.5 * (2.0 * std::f64::consts::PI * t / 44_712.0).sin() + 0.3 * t / 86_400.0
    }

    /// The accelerometer's output with 1 g on its input axis, tilted by φ: equation (1) at the
    /// temperature with the core's own coefficient models, plus K1·sin φ along the input axis.
    fn output_v(&self, t_us: u64) -> f64 {
        let (k, _) = self
            .table
            .thermal
            .coefficients_at(Celsius(self.temperature_c(t_us)))
            .expect("inside the table range");
        let k: StaticCoefficients = k;
        let phi = self.tilt_arcsec(t_us) * RAD_PER_ARCSEC;
        k.output(Gs(1.0), self.table.orientation.cross).0 + k.scale_factor_v_per_g * phi.sin()
    }

    fn rtd_ohms(&self, t_us: u64) -> f64 {
        self.table
            .rtd
            .cvd
            .resistance(Celsius(self.temperature_c(t_us)))
            .0
    }

    /// The station on the chips' analog inputs at `t_us`.
    fn put_on(&self, t_us: u64, ads: &mut Ads1262Model, rtd: &mut Ad7124Model) {
        ads.accel_v = self.output_v(t_us);
        ads.tilt_v = self.tilt_arcsec(t_us) / self.table.tilt.scale_arcsec_per_v;
        rtd.rtd_ohms = self.rtd_ohms(t_us);
    }
}

/// The board on the bench: the chip models, sequencers and assembler ([`Board`]), the station
/// on their inputs, and the pipeline.
struct Bench {
    board: Board,
    prepared: PreparedCalibration,
    station: Station,
    frames: Vec<Frame>,
    /// Physics overrides while a fault is on.
    accel_override_v: Option<f64>,
    rtd_override_ohms: Option<f64>,
}

impl Bench {
    fn with_buses(ads_bus: SpiSettings, rtd_bus: SpiSettings) -> Self {
        let clock = Clock::default();
        clock.set(1_000);
        let table = paper_order2_table();
        let prepared = PreparedCalibration::new(&table).expect("the paper table prepares");
        Bench {
            board: Board::with_buses(clock, ads_bus, rtd_bus),
            prepared,
            station: Station { table },
            frames: Vec::new(),
            accel_override_v: None,
            rtd_override_ohms: None,
        }
    }

    fn new() -> Self {
        Self::with_buses(board::ADS1262_BUS, board::AD7124_BUS)
    }

    fn now(&self) -> u64 {
        self.board.now()
    }

    /// Transactions the two chips refused (wrong mode or clock).
    fn refusals(&self) -> u32 {
        self.board.ads.borrow_mut().port().refusals + self.board.rtd.borrow_mut().port().refusals
    }

    /// Power-up as the firmware does it: no blocking init, the sequencers bring their chips up
    /// in steps from their first ticks. Runs 1.5 s and says whether both are running.
    fn boot(&mut self) -> (bool, bool) {
        self.run_until(self.now() + 1_500_000);
        (
            self.board.ads_seq.is_running(),
            self.board.rtd_seq.counters().reinits == 1,
        )
    }

    /// Runs the board with the station (and the fault overrides) on its inputs and the
    /// pipeline behind it.
    fn drive(&mut self, run: Run) {
        let Bench {
            board,
            prepared,
            station,
            frames,
            accel_override_v,
            rtd_override_ohms,
        } = self;
        let inputs = |t: u64, a: &mut Ads1262Model, r: &mut Ad7124Model| {
            station.put_on(t, a, r);
            if let Some(v) = *accel_override_v {
                a.accel_v = v;
            }
            if let Some(ohms) = *rtd_override_ohms {
                r.rtd_ohms = ohms;
            }
        };
        let out = |acq: Acquired| {
            let mut frame = process_prepared(
                acq.reading.seq,
                acq.reading.time_us,
                &acq.raw,
                Some(prepared),
            );
            frame.lost = acq.reading.lost;
            frames.push(frame);
        };
        run.on(board, inputs, out);
    }

    /// The core stalls for `duration_us` (a flash erase: no instruction fetch, no handler runs)
    /// while the converters go on converting ([`Board::stall`]).
    fn stall(&mut self, duration_us: u64) {
        self.drive(Run::Stall(duration_us));
    }

    /// Event-driven run to `end_us` ([`Board::run_until`]).
    fn run_until(&mut self, end_us: u64) {
        self.drive(Run::Until(end_us));
    }
}

/// How a harness runs the board: event-driven to a time, or through a stall of the core.
#[derive(Clone, Copy)]
enum Run {
    /// [`Board::run_until`] this time, µs.
    Until(u64),
    /// [`Board::stall`] for this long, µs.
    Stall(u64),
}

impl Run {
    fn on(
        self,
        board: &mut Board,
        mut inputs: impl FnMut(u64, &mut Ads1262Model, &mut Ad7124Model),
        mut out: impl FnMut(Acquired),
    ) {
        match self {
            Run::Until(end_us) => board.run_until(end_us, &mut inputs, &mut out),
            Run::Stall(us) => board.stall(us, &mut inputs, &mut out),
        }
    }
}

/// What a clean frame must say about the station at its timestamp.
fn check_clean_frame(station: &Station, f: &Frame) -> Result<(), String> {
    let t = f.time_us;
    let dt = (f.temperature_c - station.temperature_c(t)).abs();
    let dtilt = (f.tilt_arcsec - station.tilt_arcsec(t)).abs();
    let da = (f.a_i_exact_g - 1.0).abs();
    // The tilt is converted one channel latency (0.4 s) after the accelerometer, and the RTD up
    // to a few tenths of a second away from it: the station moves < 1e-4 °C and < 1e-4" in that
    // time. Quantisation: 49 µK (RTD), 0.9 ng and 1e-8" (ADS1262).
    if dt > 2e-3 || dtilt > 1e-3 || da > 2e-7 || f.output_v.is_nan() {
        return Err(format!(
            "frame {} at {:.1} s: ΔT {dt:.2e} °C, Δtilt {dtilt:.2e}\", Δa {da:.2e} g",
            f.seq,
            t as f64 / 1e6
        ));
    }
    Ok(())
}

fn names(status: Status) -> String {
    Status::NAMES
        .iter()
        .filter(|(bit, _)| status.has(*bit))
        .map(|(_, n)| *n)
        .collect::<Vec<_>>()
        .join("|")
}

#[test]
fn both_chips_come_up_on_the_board_buses_in_their_own_modes() {
    let mut b = Bench::new();
    assert_eq!(b.boot(), (true, true));
    assert_eq!(board::ADS1262_BUS.mode, MODE_1);
    assert_eq!(board::AD7124_BUS.mode, MODE_3);
    let at_boot = b.frames.len();
    b.run_until(b.now() + 10 * S);
    assert_eq!(b.refusals(), 0);
    // sinc4 at 10 SPS: each channel settles in 4 periods, a pair every 0.8 s.
    let n = b.frames.len() - at_boot;
    assert!((12..=13).contains(&n), "{n} frames in 10 s");
    // From the very first frame on (the RTD is up before the first pair).
    for f in &b.frames {
        assert_eq!(f.status, Status::default(), "{}", names(f.status));
        check_clean_frame(&b.station, f).unwrap();
    }
}

#[test]
fn a_wrong_spi_mode_or_clock_is_refused_and_every_frame_says_so() {
    // The old shared bus: mode 1 at 5.25 MHz for both chips.
    let old = SpiSettings {
        mode: MODE_1,
        sclk_hz: 5_250_000,
    };
    let mut b = Bench::with_buses(board::ADS1262_BUS, old);
    let boot_result = {
        let now = b.now();
        b.board.rtd_seq.boot(now)
    };
    assert_eq!(
        boot_result.err(),
        Some(ad7124::Error::Spi(BusRefusal::WrongMode))
    );
    assert!(b.board.rtd.borrow_mut().port().refusals > 0);
    // The right mode, but faster than the AD7124's 100 ns SCLK pulse widths allow.
    let fast = SpiSettings {
        mode: MODE_3,
        sclk_hz: 5_250_000,
    };
    let mut c = Bench::with_buses(board::ADS1262_BUS, fast);
    let now = c.now();
    assert_eq!(
        c.board.rtd_seq.boot(now).err(),
        Some(ad7124::Error::Spi(BusRefusal::ClockTooFast))
    );
    // The ADS1262 in mode 3.
    let mut d = Bench::with_buses(old_with(MODE_3), board::AD7124_BUS);
    let now = d.now();
    assert_eq!(
        d.board.ads_seq.boot(now).err(),
        Some(ads1262::Error::Spi(BusRefusal::WrongMode))
    );

    // Running anyway with the AD7124 on the wrong bus: the ADS1262 half streams, every frame
    // flags the RTD channel, no temperature or acceleration is ever given.
    b.boot();
    b.run_until(b.now() + 20 * S);
    assert!(b.frames.len() >= 20);
    for f in &b.frames {
        assert!(f.status.has(Status::RTD_INVALID), "{}", names(f.status));
        assert!(f.temperature_c.is_nan() && f.a_i_exact_g.is_nan());
    }
}

fn old_with(mode: embedded_hal::spi::Mode) -> SpiSettings {
    SpiSettings {
        mode,
        sclk_hz: board::ADS1262_BUS.sclk_hz,
    }
}

#[test]
fn set_rate_reprograms_the_ads1262_data_rate_and_claims_no_stall() {
    let mut b = Bench::new();
    b.boot();
    b.run_until(b.now() + 5 * S);
    // Requested while the tilt input converts, so the rate is applied at the switch back to the
    // accelerometer, between two pairs: the last pair's accelerometer DRDY was at `t`, the
    // next one comes at t + 2 latencies and its tilt half at t + 3.
    let latency = b.board.ads_seq.channel_latency_us();
    let t = b.frames.last().unwrap().time_us;
    b.run_until(t + 2 * latency + latency / 2);
    b.board.ads_seq.request_rate(DataRate::Sps50);
    let from = b.now() + 2 * S;
    b.run_until(b.now() + 12 * S);
    // sinc4 at 50 SPS: 4 × 20 ms per channel, a pair every 160 ms.
    let times: Vec<u64> = b
        .frames
        .iter()
        .filter(|f| f.time_us > from)
        .map(|f| f.time_us)
        .collect();
    let gaps: Vec<u64> = times.windows(2).map(|w| w[1] - w[0]).collect();
    assert!(gaps.len() > 50, "{} frames", gaps.len());
    for g in gaps {
        assert!((155_000..=165_000).contains(&g), "pair interval {g} µs");
    }
    assert!(b.frames.iter().all(|f| f.status == Status::default()));
    // The change of rate loses no reading and claims no stall: the pair clock starts again.
    for w in b.frames.windows(2) {
        assert_eq!(w[1].seq, w[0].seq + 1);
        assert_eq!(
            w[1].lost,
            accomp::pipeline::LossFlags(0),
            "frame {}",
            w[1].seq
        );
    }
}

/// A fault switched on for a while; frames between `on` and `off + RECOVERY` must show `bit`.
struct Injected {
    name: String,
    on: u64,
    off: u64,
    bit: u16,
}

/// Time after a fault is cleared within which the stream must be clean again.
const RECOVERY_US: u64 = 6 * S;

/// Switches a fault on (`true`) or off on the bench.
type Switch = fn(&mut Bench, bool);
/// A fault of the schedule: its name, when it is switched on, for how long, the status bit
/// that must name it, and its switch.
type ScheduledFault = (String, u64, u64, u16, Switch);

/// A chip model on the bench, for the faults of its SPI port.
trait OnBench: Chip {
    fn on(b: &Bench) -> &Rc<RefCell<Self>>;
}

impl OnBench for Ads1262Model {
    fn on(b: &Bench) -> &Rc<RefCell<Self>> {
        &b.board.ads
    }
}

impl OnBench for Ad7124Model {
    fn on(b: &Bench) -> &Rc<RefCell<Self>> {
        &b.board.rtd
    }
}

fn miso_high<C: OnBench>(b: &mut Bench, on: bool) {
    C::on(b).borrow_mut().port().miso_high = on;
}

fn corrupt_one_read<C: OnBench>(b: &mut Bench, on: bool) {
    if on {
        C::on(b).borrow_mut().port().corrupt_reads = 1;
    }
}

fn reset_mid_run<C: OnBench>(b: &mut Bench, on: bool) {
    if on {
        C::on(b).borrow_mut().power_glitch();
    }
}

/// The faults of a chip's SPI port, the same on either chip, two hours apart from `at`: MISO
/// reading 0xFF, one read corrupted (caught by the chip's `check`), a reset mid-run.
fn port_faults<C: OnBench>(chip: &str, check: &str, at: u64) -> [ScheduledFault; 3] {
    [
        (
            format!("{chip} MISO 0xFF"),
            at,
            4 * S,
            Status::ADC_NOT_RESPONDING,
            miso_high::<C>,
        ),
        (
            format!("{chip} {check} error"),
            at + 2 * H,
            S,
            Status::ADC_CHECKSUM,
            corrupt_one_read::<C>,
        ),
        (
            format!("{chip} reset mid-run"),
            at + 4 * H,
            S,
            Status::ADC_RESET,
            reset_mid_run::<C>,
        ),
    ]
}

#[test]
fn a_multi_day_stability_run_names_every_fault_and_recovers() {
    let mut b = Bench::new();
    assert_eq!(b.boot(), (true, true));
    let mut faults: Vec<Injected> = Vec::new();
    let start = b.now();
    let days = 2;

    // Each fault: switch on at `at`, off after `dur`.
    let schedule: Vec<ScheduledFault> = [
        vec![(
            "ADS1262 DRDY stuck".to_string(),
            2 * H,
            5 * S,
            Status::DRDY_TIMEOUT,
            (|b, on| b.board.ads.borrow_mut().set_stuck_drdy(on)) as Switch,
        )],
        port_faults::<Ads1262Model>("ADS1262", "checksum", 4 * H).into(),
        vec![
            (
                "accelerometer input saturated".to_string(),
                10 * H,
                3 * S,
                Status::ADC_SATURATED,
                |b, on| b.accel_override_v = on.then_some(3.1),
            ),
            (
                "RTD open".to_string(),
                12 * H,
                5 * S,
                Status::RTD_OPEN,
                |b, on| b.rtd_override_ohms = on.then_some(f64::INFINITY),
            ),
            (
                "RTD shorted".to_string(),
                14 * H,
                5 * S,
                Status::RTD_SHORT,
                |b, on| b.rtd_override_ohms = on.then_some(0.0),
            ),
        ],
        port_faults::<Ad7124Model>("AD7124", "CRC", 16 * H).into(),
        vec![
            (
                "AD7124 conversions stuck".to_string(),
                22 * H,
                4 * S,
                Status::DRDY_TIMEOUT,
                |b, on| b.board.rtd.borrow_mut().stuck = on,
            ),
            // The second day again at a faster ADS1262 rate (SetRate 20 SPS), with a DRDY stall.
            (
                "ADS1262 DRDY stuck at 20 SPS".to_string(),
                30 * H,
                3 * S,
                Status::DRDY_TIMEOUT,
                |b, on| b.board.ads.borrow_mut().set_stuck_drdy(on),
            ),
        ],
    ]
    .concat();
    let rate_change_at = start + 26 * H;
    let mut rate_changed = false;
    for (name, at, dur, bit, switch) in schedule {
        let on = start + at;
        if !rate_changed && on > rate_change_at {
            b.run_until(rate_change_at);
            b.board.ads_seq.request_rate(DataRate::Sps20);
            rate_changed = true;
        }
        b.run_until(on);
        switch(&mut b, true);
        b.run_until(on + dur);
        switch(&mut b, false);
        faults.push(Injected {
            name,
            on,
            off: on + dur,
            bit,
        });
    }
    let end = start + days * 24 * H;
    b.run_until(end);

    let frames = &b.frames;
    // 0.8 s pairs the first 26 h, 0.4 s after SetRate 20 (the model adds 0.3 ms of fixed
    // latency per channel, −0.1 %; the fault windows lose a few more).
    let expected = (26 * H) as f64 / 0.8e6 + ((days * 24 - 26) * H) as f64 / 0.4e6;
    assert!(
        (frames.len() as f64 - expected).abs() < 0.003 * expected,
        "{} frames, expected ≈ {expected:.0}",
        frames.len()
    );
    assert_eq!(b.refusals(), 0);

    // 1. Never a silent number: every frame without a status bit is right.
    let mut clean = 0;
    for f in frames.iter().filter(|f| f.status == Status::default()) {
        check_clean_frame(&b.station, f).unwrap();
        clean += 1;
    }
    // 2. Outside the fault windows every frame is clean, the first one after power-up included.
    let in_window = |t: u64| {
        faults
            .iter()
            .any(|w| t + S >= w.on && t <= w.off + RECOVERY_US)
    };
    for f in frames.iter().filter(|f| !in_window(f.time_us)) {
        assert_eq!(
            f.status,
            Status::default(),
            "frame {} at {:.1} h: {}",
            f.seq,
            f.time_us as f64 / H as f64,
            names(f.status)
        );
    }
    // 3. Each fault is named in its window, and clean frames come back after it.
    for w in &faults {
        let window: Vec<&Frame> = frames
            .iter()
            .filter(|f| f.time_us + S >= w.on && f.time_us <= w.off + RECOVERY_US)
            .collect();
        let named = window.iter().filter(|f| f.status.has(w.bit)).count();
        assert!(
            named > 0,
            "{}: no frame flagged {}; seen: {:?}",
            w.name,
            names(Status(w.bit)),
            window.iter().map(|f| names(f.status)).collect::<Vec<_>>()
        );
        let recovered = frames.iter().any(|f| {
            f.time_us > w.off && f.time_us <= w.off + RECOVERY_US && f.status == Status::default()
        });
        assert!(
            recovered,
            "{}: no clean frame within {} s",
            w.name,
            RECOVERY_US / S
        );
    }
    // 4. The stream never stops: during a fault, readings flagged DRDY_TIMEOUT keep coming at
    //    about the pair rate (0.8 s), re-initialisation included.
    let max_gap = frames
        .windows(2)
        .map(|p| p[1].time_us - p[0].time_us)
        .max()
        .unwrap_or(0);
    assert!(max_gap <= 2 * S, "longest gap {max_gap} µs");
    assert!(clean as f64 > 0.999 * frames.len() as f64);
    let c = b.board.ads_seq.counters();
    assert!(c.reinits >= 4 && c.timeouts >= 4, "{c:?}");
}

/// A 2 s stall of the core (the worst-case 128 KiB sector erase at x32, DS8626) in the middle of
/// a stream at the default rate: every pair slot of the ADC's conversion clock is either a frame
/// or a number skipped in `seq`, the gap sits on the first frame after the stall and says STALL,
/// and no frame before or after says so.
#[test]
fn a_core_stall_longer_than_a_pair_leaves_a_seq_gap_flagged_stall_and_nothing_else_is_lost() {
    use accomp::pipeline::LossFlags;
    let mut b = Bench::new();
    assert_eq!(b.boot(), (true, true));
    b.run_until(b.now() + 20 * S);
    let pair_us = b.board.ads_seq.pair_period_us();
    let first = b.frames.len();
    b.stall(2 * S);
    b.run_until(b.now() + 20 * S);
    let frames = &b.frames[first.saturating_sub(5)..];
    let mut gaps = Vec::new();
    for w in frames.windows(2) {
        assert!(w[1].seq > w[0].seq, "seq runs forward");
        let gap = w[1].seq - w[0].seq - 1;
        assert_eq!(
            gap > 0,
            w[1].lost.has(LossFlags::STALL),
            "frame {}: gap {gap}, lost {:?}",
            w[1].seq,
            w[1].lost
        );
        if gap > 0 {
            gaps.push((gap, w[1].time_us - w[0].time_us));
        }
    }
    assert_eq!(gaps.len(), 1, "one gap, at the stall: {gaps:?}");
    let (gap, dt) = gaps[0];
    // The slots the pair clock had between the two frames, all accounted for.
    let slots = (dt + pair_us / 2) / pair_us;
    assert_eq!(
        u64::from(gap) + 1,
        slots,
        "gap {gap} over {dt} µs of {pair_us} µs pairs"
    );
    assert!(
        gap >= 2,
        "a 2 s stall at {pair_us} µs per pair loses at least 2 pairs"
    );
    // Every frame is clean: the stall cost readings, not values.
    for f in frames {
        check_clean_frame(&b.station, f).unwrap();
    }
}

/// A DRDY stall ends at whatever moment of the sequencer's recovery cycle (RESET, reset wait,
/// configuration, waiting for the first DRDY): the chip's conversions start again from that
/// moment, so the first pair after the stall is stamped after its end, the pairs then follow at
/// the pair rate, and the timeout readings took every number meanwhile: no gap in seq, no STALL.
#[test]
fn a_drdy_stall_ending_at_any_moment_of_the_recovery_leaves_no_seq_gap() {
    use accomp::pipeline::LossFlags;
    // One recovery cycle is 2 × 0.4 s + 20 ms of overdue and a 20 ms tick of reset wait: the
    // stall's end is swept across it in 5 ms steps.
    let mut wrong = Vec::new();
    for phase_ms in (0..880).step_by(5) {
        let mut b = Bench::new();
        assert_eq!(b.boot(), (true, true));
        let on = b.now() + 5 * S;
        b.run_until(on);
        b.board.ads.borrow_mut().set_stuck_drdy(true);
        let off = on + 10 * S + phase_ms * 1000;
        b.run_until(off);
        b.board.ads.borrow_mut().set_stuck_drdy(false);
        b.run_until(off + 10 * S);
        let frames = &b.frames;
        for w in frames.windows(2) {
            if w[1].seq != w[0].seq + 1 || w[1].lost.has(LossFlags::STALL) {
                wrong.push(format!(
                    "{phase_ms} ms: seq {} at {} µs then {} at {} µs ({:?})",
                    w[0].seq, w[0].time_us, w[1].seq, w[1].time_us, w[1].lost
                ));
            }
            if w[1].time_us <= w[0].time_us {
                wrong.push(format!("{phase_ms} ms: time goes back at seq {}", w[1].seq));
            }
        }
        let first_clean = frames
            .iter()
            .find(|f| f.time_us > on && f.status == Status::default())
            .expect("clean frames after the stall");
        if first_clean.time_us < off {
            wrong.push(format!(
                "{phase_ms} ms: a conversion stamped {} µs, before the stall ended at {off} µs",
                first_clean.time_us
            ));
        }
    }
    assert!(
        wrong.is_empty(),
        "{} wrong:\n{}",
        wrong.len(),
        wrong.join("\n")
    );
}

/// Only the erases stall here (2 s each, DS8626 worst case at x32); the whole front-end test
/// below adds the programming time.
const ERASES_ONLY: accomp_chipsim::FlashTiming = accomp_chipsim::FlashTiming {
    sector_erase_us: 2 * S,
    byte_program_us: 0,
};

/// The device side around the simulated board: the real `Service` on a flash whose erases
/// stall the simulated core, called as the firmware's worker calls it.
struct Device {
    service: accomp::service::Service<BoardFlash>,
    busy_us: Rc<std::cell::Cell<u64>>,
    next_id: u32,
}

/// Worst-case sector erase (128 KiB at x32, DS8626 "Flash memory programming").
const ERASE_STALL_US: u64 = ERASES_ONLY.sector_erase_us;

impl Device {
    /// The device's clock during a flash operation: the core stalls for it.
    fn clock(&self, b: &Bench) -> impl Fn() -> u64 {
        let (clock, busy, before) = (
            b.board.clock.clone(),
            self.busy_us.clone(),
            self.busy_us.get(),
        );
        move || clock.now() + (busy.get() - before)
    }

    fn request(&mut self, b: &mut Bench, request: accomp::protocol::Request) {
        use accomp::protocol::{DeviceMessage, HostFrame};
        self.next_id += 1;
        let before = self.busy_us.get();
        let now = self.clock(b);
        let answer = self.service.handle(
            HostFrame {
                id: self.next_id,
                request,
            },
            &now,
        );
        assert!(
            matches!(answer, DeviceMessage::Response { .. }),
            "{answer:?}"
        );
        self.stall_for_flash(b, before);
        // The worker's erase ahead once the answer is out.
        self.erase_ahead(b);
    }

    /// The worker's erase ahead; true when it erased.
    fn erase_ahead(&mut self, b: &mut Bench) -> bool {
        let before = self.busy_us.get();
        let now = self.clock(b);
        let erased = self.service.erase_ahead(&now) == Ok(true);
        self.stall_for_flash(b, before);
        erased
    }

    fn stall_for_flash(&self, b: &mut Bench, before: u64) {
        let us = self.busy_us.get() - before;
        if us > 0 {
            b.stall(us);
        }
    }

    fn upload(&mut self, b: &mut Bench, table: &CalibrationTable) {
        let bytes = table.encode();
        for request in accomp::protocol::upload_requests(self.next_id + 1000, &bytes) {
            self.request(b, request);
        }
    }
}

/// Tables changed while streaming, on a board booted with an old table in the spare slot: the
/// erase ahead runs at boot, before the stream; during the stream the first change writes into
/// the erased spare and costs no reading, its own erase ahead waits for the stream to stop; a
/// second change must erase and stalls the core — its lost pairs are a seq gap flagged STALL,
/// and Info counts the stall. Every pair slot of the ADC's clock is a frame or a counted gap.
#[test]
fn tables_changed_while_streaming_lose_readings_only_to_counted_flagged_erase_stalls() {
    use accomp::pipeline::LossFlags;
    use accomp::protocol::{Board, Request};
    let flash = accomp_chipsim::timed(accomp::storage::RamFlash::new(), ERASES_ONLY);
    let erases = flash.watcher.erases.clone();
    let layout = accomp::storage::SlotLayout::consecutive(1024);
    let mut b = Bench::new();
    let mut dev = Device {
        busy_us: flash.watcher.busy_us.clone(),
        service: accomp::service::Service::new(Board::Frontend, flash, layout),
        next_id: 0,
    };
    let tables: Vec<CalibrationTable> = (1..=5u8)
        .map(|d| {
            let mut t = paper_order2_table();
            t.date.day = d;
            t
        })
        .collect();
    // Loaded while a stream runs, so no erase ahead ran after the last one.
    dev.request(&mut b, Request::StreamStart);
    for t in &tables[..3] {
        dev.upload(&mut b, t);
    }
    assert_eq!(erases.get(), 0, "three blank slots");
    // Power off and on: slots A, B, C hold tables 1, 2, 3; the spare (A) holds an old table.
    let flash = dev.service.into_flash().unwrap();
    dev.service = accomp::service::Service::new(Board::Frontend, flash, layout);
    assert_eq!(b.boot(), (true, true));
    // The worker's erase ahead after boot, before any host streams.
    assert!(dev.erase_ahead(&mut b));

    dev.request(&mut b, Request::StreamStart);
    let first = b.frames.len();
    b.run_until(b.now() + 10 * S);
    let erases_at_start = erases.get();
    dev.upload(&mut b, &tables[3]); // into the erased spare: no erase
    assert_eq!(erases.get(), erases_at_start, "the first change erased");
    b.run_until(b.now() + 10 * S);
    dev.request(&mut b, Request::Rollback); // the spare holds table 2: erased now
    assert_eq!(erases.get(), erases_at_start + 1);
    b.run_until(b.now() + 10 * S);

    let frames = b.frames[first..].to_vec();
    let pair_us = b.board.ads_seq.pair_period_us();
    let mut lost = 0u64;
    let mut stalls = 0;
    for w in frames.windows(2) {
        let gap = u64::from(w[1].seq - w[0].seq - 1);
        let slots = (w[1].time_us - w[0].time_us + pair_us / 2) / pair_us;
        assert_eq!(
            gap + 1,
            slots,
            "frame {}: every pair slot accounted",
            w[1].seq
        );
        assert_eq!(
            gap > 0,
            w[1].lost.has(LossFlags::STALL),
            "frame {}",
            w[1].seq
        );
        lost += gap;
        stalls += usize::from(gap > 0);
    }
    assert_eq!(stalls, 1, "one stall: the rollback's erase");
    assert!(lost >= ERASE_STALL_US / pair_us - 1, "{lost} pairs lost");
    let accomp::protocol::DeviceMessage::Response {
        body: accomp::protocol::Response::Info(info),
        ..
    } = dev.service.handle(
        accomp::protocol::HostFrame {
            id: 1,
            request: Request::Info,
        },
        &|| 0,
    )
    else {
        panic!("Info");
    };
    // Both erases stalled the core (the one at boot before the stream), both are counted.
    assert_eq!(info.losses.erase_stalls, 2);
    assert_eq!(info.losses.erase_stall_us, 2 * ERASE_STALL_US);
    // The stream stops: the pending erase ahead runs now.
    let before = erases.get();
    dev.request(&mut b, Request::StreamStop);
    assert_eq!(erases.get(), before + 1);
    for f in &frames {
        check_clean_frame(&b.station, f).unwrap();
    }
}

/// The firmware's UART receive ring (`RX_RING_LEN` in src/bsp/frontend.rs).
const RX_RING_LEN: usize = 2048;
/// The firmware's inbound queue (`INBOUND_CAPACITY` in src/main.rs).
const INBOUND_CAPACITY: usize = 16;

/// What the interrupts hand the worker (src/main.rs `Inbound`; RTD readings go straight to the
/// assembler inside [`Board`]).
enum Inbound {
    Frame(Result<Vec<u8>, accomp::protocol::FrameError>),
    Ads(Acquired),
}

/// A message on its way to the host: when its last byte is out, and for a sample the model's
/// true DRDY time of its accelerometer conversion.
struct ToHost {
    at_us: u64,
    msg: accomp::protocol::DeviceMessage,
    true_drdy_us: Option<u64>,
}

/// A flash stall of the core: when, how long, and whether the stream was on.
#[derive(Debug, Clone, Copy)]
struct Stall {
    at_us: u64,
    us: u64,
    streaming: bool,
    /// Caused by a request (a commit), not by the worker's erase ahead.
    by_request: bool,
}

type BoardFlash = accomp_chipsim::TimedFlash<accomp::storage::RamFlash<3072, 1024, 4>>;

/// The whole front-end in time: the [`Board`] on the chip models, USART1 with its DMA ring
/// (RM0090 §30, §10) receiving the host's bytes at 115,200 Bd, the firmware's receive path (the
/// core's `RxRing` and `FrameDecoder`, read as `bsp::frontend::read_byte` does), the worker's
/// `Service` on a flash whose erases and programs take their datasheet time and stall the core
/// meanwhile, the transmit line back to the host, and the host.
struct Rig {
    board: Board,
    station: Station,
    usart: accomp_chipsim::UsartRx<RX_RING_LEN>,
    ring: accomp::rx_ring::RxRing<RX_RING_LEN>,
    /// Ring position when a line error was last counted (as in `read_byte`).
    error_head: usize,
    uart_overruns: u32,
    decoder: accomp::protocol::FrameDecoder<{ accomp::protocol::MAX_FRAME_LEN }>,
    /// Host → device bytes with the time each one's stop bit is sampled.
    line: std::collections::VecDeque<(u64, u8)>,
    line_free_us: u64,
    bytes_sent: u64,
    /// Bytes the firmware's reader took out of the ring.
    bytes_read: u64,
    inbound: std::collections::VecDeque<Inbound>,
    readings_dropped: u32,
    service: accomp::service::Service<BoardFlash>,
    busy_us: Rc<std::cell::Cell<u64>>,
    tx_free_us: u64,
    to_host: Vec<ToHost>,
    stalls: Vec<Stall>,
    next_id: u32,
    /// The rate last handed to the sequencer (None: the board's default).
    rate: Option<DataRate>,
}

impl Rig {
    /// Powers the board up on `flash` (its clock from 1 ms).
    fn boot(flash: BoardFlash) -> Rig {
        let clock = Clock::default();
        clock.set(1_000);
        let busy_us = flash.watcher.busy_us.clone();
        let mut usart = accomp_chipsim::UsartRx::new();
        // start_rx_dma: the circular stream enabled, then USART_CR3.DMAR.
        usart.dmar = true;
        let service = accomp::service::Service::new(
            accomp::protocol::Board::Frontend,
            flash,
            accomp::storage::SlotLayout::consecutive(1024),
        );
        Rig {
            board: Board::new(clock),
            station: Station {
                table: paper_order2_table(),
            },
            usart,
            ring: accomp::rx_ring::RxRing::new(),
            error_head: 0,
            uart_overruns: 0,
            decoder: accomp::protocol::FrameDecoder::new(),
            line: Default::default(),
            line_free_us: 0,
            bytes_sent: 0,
            bytes_read: 0,
            inbound: Default::default(),
            readings_dropped: 0,
            service,
            busy_us,
            tx_free_us: 0,
            to_host: Vec::new(),
            stalls: Vec::new(),
            next_id: 0,
            rate: None,
        }
    }

    fn now(&self) -> u64 {
        self.board.now()
    }

    /// Runs the board with the station on its inputs and the finished pairs queued for the
    /// worker.
    fn drive(&mut self, run: Run) {
        let Rig {
            board,
            station,
            inbound,
            readings_dropped,
            ..
        } = self;
        run.on(
            board,
            |t, a, r| station.put_on(t, a, r),
            |acq| push_reading(inbound, readings_dropped, acq),
        );
    }

    /// The chips up to `t_us`: handlers run, finished pairs queue for the worker.
    fn chips_until(&mut self, t_us: u64) {
        self.drive(Run::Until(t_us));
    }

    /// Runs everything until `end_us`, the worker after every event.
    fn run_until(&mut self, end_us: u64) {
        loop {
            let byte_at = self.line.front().map_or(u64::MAX, |b| b.0);
            let t = self.board.next_event_us().min(byte_at).min(end_us);
            self.chips_until(t);
            self.worker();
            if t < byte_at {
                if t >= end_us {
                    return;
                }
                continue;
            }
            let (_, b) = self.line.pop_front().unwrap();
            self.usart.byte_received(b);
            // The USART1 interrupt (priority 2) runs: the core is not stalled here.
            self.uart_rx();
            self.worker();
        }
    }

    /// The firmware's `uart_rx` task: drains the DMA ring into the frame decoder (what
    /// `bsp::frontend::read_byte` does with the registers, on the models').
    fn uart_rx(&mut self) {
        use accomp::rx_ring::RxRing;
        use accomp_chipsim::usart::sr;
        loop {
            let status = self.usart.read_sr();
            let ndtr = self.usart.ndtr();
            let head = RxRing::<RX_RING_LEN>::head(ndtr);
            if status & sr::ORE != 0 && head != self.error_head {
                self.error_head = head;
                self.uart_overruns += 1;
            }
            let ring = &self.usart.ring;
            let Some(byte) = self.ring.next(ndtr, |i| ring[i]) else {
                return;
            };
            self.bytes_read += 1;
            if let Some(frame) = self.decoder.push(byte) {
                if self.inbound.len() < INBOUND_CAPACITY {
                    self.inbound
                        .push_back(Inbound::Frame(frame.map(<[u8]>::to_vec)));
                } else {
                    self.service.count_dropped();
                }
            }
        }
    }

    /// The core stalls `us` for the flash: the chips convert, the USART and its DMA receive,
    /// no handler or task runs. Afterwards the pending interrupts run.
    fn stall(&mut self, us: u64, by_request: bool) {
        let at_us = self.now();
        self.stalls.push(Stall {
            at_us,
            us,
            streaming: self.service.streaming(),
            by_request,
        });
        let end = at_us + us;
        while self.line.front().is_some_and(|b| b.0 <= end) {
            let (_, b) = self.line.pop_front().unwrap();
            self.usart.byte_received(b);
        }
        self.drive(Run::Stall(us));
        self.uart_rx();
    }

    /// The worker: every queued item in order, the answer sent after any flash stall, then the
    /// erase ahead when nothing waits (src/main.rs `worker`).
    fn worker(&mut self) {
        use accomp::pipeline::LossFlags;
        use accomp::protocol::{decode_message, HostFrame, Request};
        while let Some(item) = self.inbound.pop_front() {
            self.service.losses_mut().uart_rx_overrun = self.uart_overruns;
            let busy_before = self.busy_us.get();
            let (clock, busy) = (self.board.clock.clone(), self.busy_us.clone());
            let now = move || clock.now() + (busy.get() - busy_before);
            let (reply, true_drdy_us) = match item {
                Inbound::Frame(frame) => {
                    let is_commit = frame.as_ref().is_ok_and(|body| {
                        matches!(
                            decode_message::<HostFrame>(body).map(|f| f.request),
                            Ok(Request::UploadCommit { .. }
                                | Request::Rollback
                                | Request::Activate { .. })
                        )
                    });
                    let reply = self
                        .service
                        .handle_frame(frame.as_deref().map_err(|e| *e), &now);
                    let stalled = self.busy_us.get() - busy_before;
                    if stalled > 0 {
                        assert!(is_commit, "only a commit touches the flash");
                        self.stall(stalled, true);
                    }
                    (reply, None)
                }
                Inbound::Ads(acq) => {
                    let mut lost = acq.reading.lost;
                    let dropped = std::mem::take(&mut self.readings_dropped);
                    if dropped > 0 {
                        lost.0 |= LossFlags::QUEUE_FULL;
                        let l = self.service.losses_mut();
                        l.queue_full = l.queue_full.wrapping_add(dropped);
                    }
                    let r = acq.reading;
                    (
                        self.service.acquired(r.seq, lost, &acq.raw, r.time_us),
                        acq.true_accel_drdy_us,
                    )
                }
            };
            if let Some(msg) = reply {
                self.transmit(msg, true_drdy_us);
            }
            // SetRate: the worker hands the rate to the supervisor, which requests it.
            if let Some(rate) = DataRate::from_sps(self.service.rate_hz()) {
                if Some(rate) != self.rate {
                    self.rate = Some(rate);
                    self.board.ads_seq.request_rate(rate);
                }
            }
            if self.service.erase_pending() && self.inbound.is_empty() {
                let busy_before = self.busy_us.get();
                let (clock, busy) = (self.board.clock.clone(), self.busy_us.clone());
                let now = move || clock.now() + (busy.get() - busy_before);
                let _ = self.service.erase_ahead(&now);
                let stalled = self.busy_us.get() - busy_before;
                if stalled > 0 {
                    self.stall(stalled, false);
                }
            }
        }
    }

    /// The transmitter (blocking, byte after byte at the baud rate).
    fn transmit(&mut self, msg: accomp::protocol::DeviceMessage, true_drdy_us: Option<u64>) {
        let mut buf = [0u8; accomp::protocol::MAX_FRAME_LEN];
        let n = accomp::protocol::encode_frame(&msg, &mut buf).expect("every message encodes");
        let start = self.tx_free_us.max(self.now());
        self.tx_free_us = accomp_chipsim::usart::byte_done_us(start, n as u64 - 1);
        self.to_host.push(ToHost {
            at_us: self.tx_free_us,
            msg,
            true_drdy_us,
        });
    }

    /// The host sends a request: its bytes go on the line back to back after what is already
    /// on it.
    fn send(&mut self, request: accomp::protocol::Request) -> u32 {
        use accomp::protocol::{encode_frame, HostFrame, MAX_FRAME_LEN};
        self.next_id += 1;
        let id = self.next_id;
        let mut buf = [0u8; MAX_FRAME_LEN];
        let n = encode_frame(&HostFrame { id, request }, &mut buf).unwrap();
        let start = self.line_free_us.max(self.now());
        for (k, &b) in buf[..n].iter().enumerate() {
            self.line
                .push_back((accomp_chipsim::usart::byte_done_us(start, k as u64), b));
        }
        self.line_free_us = self.line.back().map_or(start, |b| b.0);
        self.bytes_sent += n as u64;
        id
    }

    /// Sends a request and runs until its answer has reached the host.
    fn call(&mut self, request: accomp::protocol::Request) -> accomp::protocol::Response {
        use accomp::protocol::DeviceMessage;
        let id = self.send(request.clone());
        let deadline = self.now() + 10 * S;
        loop {
            let now = self.now();
            if let Some(m) = self.to_host.iter().find(|m| {
                m.at_us <= now
                    && matches!(m.msg, DeviceMessage::Response { id: i, .. }
                        | DeviceMessage::Error { id: i, .. } if i == id)
            }) {
                match &m.msg {
                    DeviceMessage::Response { body, .. } => return body.clone(),
                    other => panic!("{request:?}: {other:?}"),
                }
            }
            assert!(now < deadline, "{request:?} unanswered");
            self.run_until(now + 500);
        }
    }

    /// The answer to request `id` that has reached the host (panics if none has).
    fn answer(&self, id: u32) -> Result<accomp::protocol::Response, accomp::protocol::ErrorReply> {
        use accomp::protocol::DeviceMessage;
        let now = self.now();
        let m = self.to_host.iter().filter(|m| m.at_us <= now);
        match m.map(|m| &m.msg).find(|msg| {
            matches!(msg, DeviceMessage::Response { id: i, .. }
                | DeviceMessage::Error { id: i, .. } if *i == id)
        }) {
            Some(DeviceMessage::Response { body, .. }) => Ok(body.clone()),
            Some(DeviceMessage::Error { error, .. }) => Err(*error),
            _ => panic!("request {id} unanswered"),
        }
    }

    fn info(&mut self) -> accomp::protocol::DeviceInfo {
        match self.call(accomp::protocol::Request::Info) {
            accomp::protocol::Response::Info(i) => i,
            other => panic!("{other:?}"),
        }
    }

    /// Uploads `table` over the line as the host client does, chunk by chunk, and commits.
    fn upload(&mut self, table: &CalibrationTable) {
        let bytes = table.encode();
        let answers: Vec<_> = accomp::protocol::upload_requests(7000 + self.next_id, &bytes)
            .map(|request| self.call(request))
            .collect();
        assert_eq!(
            answers.last(),
            Some(&accomp::protocol::Response::Committed {
                table_id: table.id()
            })
        );
    }

    /// The sample frames sent after the first `from` messages that reached the host so far,
    /// with their true DRDY times.
    fn delivered(&self, from: usize) -> Vec<(Frame, Option<u64>)> {
        let now = self.now();
        self.to_host[from..]
            .iter()
            .filter(|m| m.at_us <= now)
            .filter_map(|m| match &m.msg {
                accomp::protocol::DeviceMessage::Sample { id: 0, frame } => {
                    Some((*frame, m.true_drdy_us))
                }
                _ => None,
            })
            .collect()
    }

    /// Info now, and the stream that reached the host after its first `from` messages checked
    /// ([`check_stream`]) against the conversions lost since `lost_before`: the gaps in it.
    fn check_stream_since(
        &mut self,
        name: &str,
        from: usize,
        lost_before: u32,
    ) -> (accomp::protocol::DeviceInfo, usize) {
        let info = self.info();
        let frames = self.delivered(from);
        let gaps = check_stream(
            name,
            &frames,
            self.board.ads_seq.pair_period_us(),
            info.losses.conversions_lost - lost_before,
            &self.station,
        );
        (info, gaps)
    }

    /// `lead_us` into the stream, `table` uploaded and committed, 2 s more: the stream since the
    /// host's first `from` messages has exactly one gap, the commit's. Info afterwards.
    fn commit_mid_stream(
        &mut self,
        name: &str,
        table: &CalibrationTable,
        lead_us: u64,
        from: usize,
        before: &accomp::protocol::DeviceInfo,
    ) -> accomp::protocol::DeviceInfo {
        self.run_until(self.now() + lead_us);
        self.upload(table);
        self.run_until(self.now() + 2 * S);
        let (info, gaps) = self.check_stream_since(name, from, before.losses.conversions_lost);
        assert_eq!(gaps, 1, "{name}: one gap, the commit's");
        info
    }

    /// No byte from the host lost: every byte sent received, none overrun, all read from the
    /// ring, and the device (`info`) counted no overrun and dropped no frame.
    fn assert_no_byte_lost(&self, info: &accomp::protocol::DeviceInfo) {
        let uart = (
            self.usart.received,
            self.usart.overrun_bytes,
            self.bytes_read,
        );
        let sent = self.bytes_sent;
        assert_eq!(
            uart,
            (sent, 0, sent),
            "received, overrun, read from the ring"
        );
        assert_eq!((info.losses.uart_rx_overrun, info.frames_dropped), (0, 0));
    }
}

/// The DRDY interrupt's `try_send`: a full queue loses the reading, counted for the next one.
fn push_reading(
    inbound: &mut std::collections::VecDeque<Inbound>,
    dropped: &mut u32,
    acq: Acquired,
) {
    if inbound.len() < INBOUND_CAPACITY {
        inbound.push_back(Inbound::Ads(acq));
    } else {
        *dropped += 1;
    }
}

/// Checks one stream as the host received it: every pair slot of the ADC's conversion clock is
/// a delivered frame or a number skipped in `seq`, each gap is flagged on the frame after it,
/// the gaps add up to the device's `conversions_lost`, and every time stamp is within 50 µs of
/// the model's true DRDY time. Returns the number of gaps.
fn check_stream(
    name: &str,
    frames: &[(Frame, Option<u64>)],
    pair_us: u64,
    conversions_lost: u32,
    station: &Station,
) -> usize {
    use accomp::pipeline::LossFlags;
    assert!(frames.len() > 100, "{name}: {} frames", frames.len());
    let mut lost = 0u64;
    let mut gaps = 0;
    // The first pair of a stream may still be of the rate before SetRate: slots from the second.
    for (k, w) in frames.windows(2).enumerate() {
        let (a, b) = (&w[0].0, &w[1].0);
        assert!(b.seq > a.seq, "{name}: seq runs forward");
        let gap = u64::from(b.seq - a.seq - 1);
        let flagged = b.lost.0 & (LossFlags::STALL | LossFlags::QUEUE_FULL) != 0;
        if gap > 0 {
            eprintln!(
                "{name}: gap {gap} before {} at {} {:?} (prev at {})",
                b.seq, b.time_us, b.lost, a.time_us
            );
        }
        assert_eq!(
            gap > 0,
            flagged,
            "{name}: frame {} gap {gap} lost {:?}",
            b.seq,
            b.lost
        );
        if k > 0 {
            let slots = (b.time_us - a.time_us + pair_us / 2) / pair_us;
            assert_eq!(
                gap + 1,
                slots,
                "{name}: frame {}: every pair slot accounted",
                b.seq
            );
        }
        lost += gap;
        gaps += usize::from(gap > 0);
    }
    assert_eq!(
        lost,
        u64::from(conversions_lost),
        "{name}: gaps = conversions_lost"
    );
    let mut worst = 0;
    for (f, true_us) in frames {
        let t = true_us.unwrap_or_else(|| panic!("{name}: frame {} carries no conversion", f.seq));
        worst = worst.max(f.time_us.abs_diff(t));
        // Before the first upload of a factory-blank board the frames say NO_CALIBRATION.
        if f.status == Status::default() {
            check_clean_frame(station, f).unwrap();
        } else {
            assert_eq!(
                f.status,
                Status(Status::NO_CALIBRATION),
                "{name}: frame {}",
                f.seq
            );
        }
    }
    eprintln!(
        "{name}: {} frames, {gaps} gaps, {lost} pairs lost, worst stamp {worst} µs off",
        frames.len()
    );
    assert!(
        worst <= 50,
        "{name}: a time stamp {worst} µs off the true DRDY time"
    );
    gaps
}

/// The timed simulation of the whole front-end: streaming at the highest data rate the firmware
/// configures (400 SPS: a pair every 20 ms), tables uploaded over the modelled UART (USART1 →
/// circular DMA → the firmware's ring, bytes every 86.8 µs at 115,200 Bd, ORE when a byte is not
/// taken in time) and committed and rolled back in the middle, a reboot with an old table in the
/// spare slot and the host starting its stream at once, and every flash erase (2 s) and program
/// (100 µs a byte) stalling the core meanwhile (RM0090 §3.5, DS8626 worst case).
///
/// Asserted: no UART byte lost (ORE never set, every byte sent received); every conversion pair
/// delivered or accounted for by a seq gap, a flag and `conversions_lost`; time stamps within
/// 50 µs of the model's true DRDY times across every stall; the only stalls while streaming are
/// the commits the host asked for (the erase ahead waits for the stream to stop), each counted in
/// Info when it erased.
#[test]
fn a_400_sps_stream_through_uploads_rollback_and_reboot_loses_no_byte_and_accounts_for_every_conversion(
) {
    use accomp::protocol::{Request, Response, CHUNK_LEN, MAX_RATE_HZ};
    let tables: Vec<CalibrationTable> = (1..=5u8)
        .map(|d| {
            let mut t = paper_order2_table();
            t.date.day = d;
            t
        })
        .collect();
    let flash = accomp_chipsim::timed(
        accomp::storage::RamFlash::new(),
        accomp_chipsim::FlashTiming::MAX,
    );
    let erases = flash.watcher.erases.clone();

    // First boot, a factory-blank flash: three uploads (each into a blank slot: programming
    // only) and a rollback (into the slot of table 1: an erase) while streaming.
    let mut rig = Rig::boot(flash);
    rig.run_until(rig.now() + 1_500_000);
    assert_eq!(rig.call(Request::SetRate { hz: MAX_RATE_HZ }), Response::Ok);
    assert_eq!(rig.call(Request::StreamStart), Response::Ok);
    let before = rig.info().losses;
    let from = rig.to_host.len();
    rig.run_until(rig.now() + S);
    for t in &tables[..3] {
        rig.upload(t);
        rig.run_until(rig.now() + S);
    }
    // The rollback, and behind it a host's window of 8 requests in flight (`accomp compensate`
    // keeps 8): 8 full-size chunk frames (of no upload: each is refused with NoUpload and
    // changes nothing) arrive during the rollback's 2 s erase stall and wait in the DMA ring.
    let rollback = rig.send(Request::Rollback);
    let window: Vec<u32> = (0..8)
        .map(|_| {
            rig.send(Request::UploadChunk {
                upload_id: 1,
                offset: 0,
                data: heapless::Vec::from_slice(&[0x55; CHUNK_LEN]).unwrap(),
            })
        })
        .collect();
    rig.run_until(rig.now() + 3 * S);
    assert_eq!(rig.answer(rollback), Ok(Response::Ok));
    for id in window {
        let code = rig.answer(id).unwrap_err().code;
        assert_eq!(code, accomp::protocol::ErrorCode::NoUpload as u16);
    }
    let pair_us = rig.board.ads_seq.pair_period_us();
    assert_eq!(pair_us, 20_000, "400 SPS, sinc4: 4 × 2.5 ms per input");
    let (info, gaps) = rig.check_stream_since("first boot", from, before.conversions_lost);
    assert_eq!(info.active_table, Some(tables[1].id()));
    assert_eq!(
        gaps, 4,
        "one gap per commit (the programming alone is > half a pair)"
    );
    assert_eq!(
        info.losses.erase_stalls - before.erase_stalls,
        1,
        "the rollback's erase"
    );
    assert!(info.losses.erase_stall_us - before.erase_stall_us >= 2 * S);
    rig.assert_no_byte_lost(&info);
    let stalls = rig.stalls.clone();

    // Power cut while streaming: the erase ahead after the rollback never ran, the spare holds
    // table 2's old copy. The host starts its stream as soon as the board is up.
    let flash = rig.service.into_flash().unwrap();
    let mut rig = Rig::boot(flash);
    rig.send(Request::StreamStart);
    rig.send(Request::SetRate { hz: MAX_RATE_HZ });
    rig.run_until(rig.now() + 1_500_000);
    let before = rig.info();
    let from = rig.to_host.len();
    assert_eq!(
        (before.active_table, before.previous_table),
        (Some(tables[1].id()), Some(tables[2].id()))
    );
    // The spare still holds an old table: this commit erases.
    let info = rig.commit_mid_stream("after the reboot", &tables[3], 3 * S, from, &before);
    assert_eq!(info.losses.erase_stalls - before.losses.erase_stalls, 1);
    // Stopped, the erase ahead runs; the next stream's upload only programs.
    let erased = erases.get();
    assert_eq!(rig.call(Request::StreamStop), Response::Ok);
    rig.run_until(rig.now() + 3 * S);
    assert_eq!(
        erases.get(),
        erased + 1,
        "the erase ahead once the stream stopped"
    );
    let before = rig.info();
    assert_eq!(rig.call(Request::StreamStart), Response::Ok);
    let from = rig.to_host.len();
    let info = rig.commit_mid_stream("upload into the erased spare", &tables[4], S, from, &before);
    assert_eq!(
        info.losses.erase_stalls, before.losses.erase_stalls,
        "no erase"
    );
    assert_eq!(info.active_table, Some(tables[4].id()));
    rig.assert_no_byte_lost(&info);

    // Every stall during a stream was a commit the host asked for.
    for s in stalls.iter().chain(&rig.stalls) {
        assert!(
            !s.streaming || s.by_request,
            "the erase ahead stalled the core {} µs at {} µs while streaming",
            s.us,
            s.at_us
        );
    }
}
