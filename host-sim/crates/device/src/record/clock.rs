//! The board-clock model of the recorder: which record time (seconds since the record's
//! `start_utc`) a frame gets from its board time stamp (µs since the board's boot) and the PC
//! time it arrived at.
//!
//! The board's clock is the time base: within one boot, record time advances with the board's
//! clock, corrected for its drift against the PC. So a PC clock step, or a burst of USB latency,
//! moves nothing. The drift is fitted continuously from the arrival times with a minimum-delay
//! filter: per block of [`BLOCK_S`] of board time only the earliest arrival relative to the
//! board clock counts (the frame that waited least in buffers), and a straight line through the
//! last [`BLOCKS_KEPT`] block minima gives the drift. A block minimum that jumps from the line
//! by more than [`STEP_S`] is a step of the PC's clock: reported, taken out of the fit, never
//! followed.
//!
//! A board clock running at more than [`MAX_CRYSTAL_DRIFT`] from the PC's is no crystal (the
//! virtual board at `--speed N`): it is announced once and no drift is applied; record time
//! then is the board's own clock.
//!
//! The first frame of a boot anchors the record time at its arrival, delay included; the
//! minimum-delay line then says where the board clock really sits, and the difference is slewed
//! in at most [`MAX_SLEW`] of the elapsed time (never a jump, never backwards).
//!
//! Only a new boot (or a new recorder on a board of unknown state) anchors the board clock
//! again: at the previous frame's record time plus the PC time since, scaled by the measured
//! rate of the board clock, and never at or before the previous frame.

use std::collections::VecDeque;

/// Board time covered by one minimum-delay block, seconds.
pub const BLOCK_S: f64 = 60.0;
/// Block minima kept for the drift fit (4 h at 60 s blocks).
pub const BLOCKS_KEPT: usize = 240;
/// A jump of a block minimum larger than this is a PC clock step, seconds.
pub const STEP_S: f64 = 0.5;
/// Largest drift of a board crystal against the PC's clock that is applied (1000 ppm).
pub const MAX_CRYSTAL_DRIFT: f64 = 1e-3;
/// Fastest slewing of the record time toward the minimum-delay line, as a fraction of the
/// elapsed time (500 ppm: a 0.1 s anchor error is absorbed in 200 s).
pub const MAX_SLEW: f64 = 5e-4;
/// A drift change that is reported as an event, ppm.
pub const DRIFT_REPORT_PPM: f64 = 1.0;

/// What the model noticed, for the record's event lines.
#[derive(Debug, Clone, PartialEq)]
pub enum ClockEvent {
    /// The fitted drift of the board clock against the PC's, and the fit's offset residual.
    Drift {
        /// Parts per million (positive: the board clock runs fast).
        ppm: f64,
        /// Block minima in the fit.
        blocks: usize,
    },
    /// The PC's clock stepped by this many seconds (not followed).
    PcStep {
        /// Seconds, positive forward.
        step_s: f64,
    },
    /// The board clock runs this many times the PC's: no crystal; drift not applied.
    NotACrystal {
        /// Board seconds per PC second.
        rate: f64,
    },
}

/// Where the previous frame of the record is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Last {
    /// Board time, µs.
    pub board_us: u64,
    /// Record time, s.
    pub record_s: f64,
    /// PC time it arrived at, Unix seconds (None: unknown, e.g. read from a file).
    pub pc_s: Option<f64>,
}

/// The model.
#[derive(Debug, Clone)]
pub struct ClockModel {
    /// Minima of (PC − board) per block: (board s, offset s, corrected for known PC steps).
    blocks: VecDeque<(f64, f64)>,
    /// The block being filled: its start (board s) and its minimum so far.
    current: Option<(f64, f64, f64)>,
    /// PC clock steps seen so far, summed (subtracted from later offsets).
    steps_s: f64,
    /// Fitted drift (board − PC rate, fraction) and whether the board is a crystal at all.
    drift: f64,
    crystal: bool,
    /// Board seconds per PC second, as measured (1 for a crystal board).
    rate: f64,
    reported_ppm: Option<f64>,
    /// A block minimum off the line, waiting for the next block to say step or rate:
    /// (board s, offset s, jump s).
    pending: Option<(f64, f64, f64)>,
    not_crystal_reported: bool,
    /// Record time still to be slewed in (s): the difference between where the minimum-delay
    /// line puts the board clock and where the record's anchor put it.
    correction_s: f64,
    start_unix_s: f64,
    last: Option<Last>,
    /// The board clock is anchored: frames of this boot follow it.
    anchored: bool,
}

impl Default for ClockModel {
    fn default() -> Self {
        ClockModel {
            blocks: VecDeque::new(),
            current: None,
            steps_s: 0.0,
            drift: 0.0,
            crystal: true,
            rate: 1.0,
            reported_ppm: None,
            pending: None,
            not_crystal_reported: false,
            correction_s: 0.0,
            start_unix_s: 0.0,
            last: None,
            anchored: false,
        }
    }
}

impl ClockModel {
    /// A model continuing a record whose last frame is `last` (None: a new record).
    pub fn new(last: Option<Last>) -> Self {
        ClockModel {
            last,
            ..ClockModel::default()
        }
    }

    /// The drift applied, ppm.
    pub fn drift_ppm(&self) -> f64 {
        self.drift * 1e6
    }

    /// The previous frame.
    pub fn last(&self) -> Option<Last> {
        self.last
    }

    /// The board rebooted (or its state is unknown): the next frame anchors its clock again.
    /// The fit's history stays (it is the same crystal), the block in progress is dropped.
    pub fn new_boot(&mut self) {
        self.anchored = false;
        self.current = None;
        self.pending = None;
        self.blocks.clear();
    }

    /// The frame of this boot continues the previous one (same boot, later board time): the
    /// board clock stays the base even if the recorder was not running meanwhile.
    pub fn continue_boot(&mut self) {
        self.anchored = self.last.is_some();
    }

    /// Record time of a frame stamped `board_us` that arrived at PC time `pc_s` (Unix seconds),
    /// for a record starting at `start_unix_s`; events noticed on the way go to `events`.
    /// `arrived_now`: false for a frame that waited in a buffer for an unknown time (read
    /// during the connection's handshake): its arrival says nothing about the board's clock.
    pub fn record_time(
        &mut self,
        board_us: u64,
        pc_s: f64,
        start_unix_s: f64,
        arrived_now: bool,
        events: &mut Vec<ClockEvent>,
    ) -> f64 {
        let b = board_us as f64 * 1e-6;
        self.start_unix_s = start_unix_s;
        if arrived_now {
            self.observe(b, pc_s, events);
        }
        let t = match (self.last, self.anchored) {
            (Some(l), true) if board_us > l.board_us => {
                let dt = (board_us - l.board_us) as f64 * 1e-6 * (1.0 - self.drift);
                // Slewed in at most MAX_SLEW of the elapsed time: never a jump, never back.
                let slew = self.correction_s.clamp(-MAX_SLEW * dt, MAX_SLEW * dt);
                self.correction_s -= slew;
                l.record_s + dt + slew
            }
            (Some(l), _) => {
                // A new anchor: the PC time since the previous frame at the board's rate, or
                // (previous frame from a file) the PC's time since the start.
                let since = match l.pc_s {
                    Some(p) => l.record_s + (pc_s - p).max(0.0) * self.rate,
                    None => pc_s - start_unix_s,
                };
                since.max(l.record_s + 1e-6)
            }
            (None, _) => pc_s - start_unix_s,
        };
        self.anchored = true;
        self.last = Some(Last {
            board_us,
            record_s: t,
            pc_s: Some(pc_s),
        });
        t
    }

    /// Feeds the minimum-delay filter and refits at each finished block.
    fn observe(&mut self, b: f64, pc_s: f64, events: &mut Vec<ClockEvent>) {
        if let Some((start, bmin, omin)) = self.current {
            if b < start || b >= start + BLOCK_S {
                self.current = None;
                self.finish_block(bmin, omin, events);
            }
        }
        // After a finished block: a step found there applies to this frame already.
        let offset = pc_s - b - self.steps_s;
        match &mut self.current {
            Some((_, bmin, omin)) => {
                if offset < *omin {
                    *bmin = b;
                    *omin = offset;
                }
            }
            None => self.current = Some((b, b, offset)),
        }
    }

    fn finish_block(&mut self, b: f64, offset: f64, events: &mut Vec<ClockEvent>) {
        let mut offset = offset;
        let mut placed = false;
        if let Some((pb, po, jump)) = self.pending.take() {
            // The block before jumped off the line. If this one goes on at the same slope the
            // board clock is no crystal; if it stays at the new level the PC's clock stepped;
            // if it is back on the line, the jumped block was a burst of delay (every frame of
            // it late): dropped, and this block is checked against the line as any other.
            let before = self.blocks.back().map_or(pb - BLOCK_S, |&(b0, _)| b0);
            let s_prev = jump / (pb - before).max(1e-9);
            let s_now = (offset - po) / (b - pb).max(1e-9);
            let stays = (offset - (po - self.drift * (b - pb))).abs() <= STEP_S;
            if s_now.abs() > MAX_CRYSTAL_DRIFT && (s_now - s_prev).abs() < 0.1 * s_prev.abs() {
                self.crystal = false;
                self.blocks.push_back((pb, po));
                placed = true;
            } else if stays {
                self.steps_s += jump;
                events.push(ClockEvent::PcStep { step_s: jump });
                self.blocks.push_back((pb, po - jump));
                offset -= jump;
                placed = true;
            }
        }
        if let (false, Some(&(pb, po))) = (placed, self.blocks.back()) {
            let jump = offset - (po - self.drift * (b - pb));
            if self.crystal && jump.abs() > STEP_S {
                self.pending = Some((b, offset, jump));
                return;
            }
        }
        self.blocks.push_back((b, offset));
        while self.blocks.len() > BLOCKS_KEPT {
            self.blocks.pop_front();
        }
        if self.blocks.len() < 2 {
            return;
        }
        // Least squares of offset (PC − board) against board time: slope = −drift.
        let n = self.blocks.len() as f64;
        let (mb, mo) = self
            .blocks
            .iter()
            .fold((0.0, 0.0), |(sb, so), (b, o)| (sb + b / n, so + o / n));
        let (sbo, sbb) = self.blocks.iter().fold((0.0, 0.0), |(sbo, sbb), (b, o)| {
            (sbo + (b - mb) * (o - mo), sbb + (b - mb) * (b - mb))
        });
        if sbb <= 0.0 {
            return;
        }
        let slope = sbo / sbb;
        if slope.abs() > MAX_CRYSTAL_DRIFT {
            // d(PC − board)/d(board) = 1/rate − 1.
            let rate = 1.0 / (1.0 + slope);
            if !self.not_crystal_reported {
                self.not_crystal_reported = true;
                events.push(ClockEvent::NotACrystal { rate });
            }
            self.crystal = false;
            self.drift = 0.0;
            self.rate = rate;
            return;
        }
        self.crystal = true;
        self.rate = 1.0;
        self.drift = -slope;
        // Where the block's least-delayed frame arrived against where the record put it: the
        // anchor (the first frame's arrival) carried that frame's delay, the line does not.
        if let (Some(l), true) = (self.last, self.anchored) {
            let mapped = l.record_s - (l.board_us as f64 * 1e-6 - b) * (1.0 - self.drift);
            // The offsets have the PC's steps taken out: the PC time as if it had not stepped.
            let arrived = offset + b - self.start_unix_s;
            self.correction_s = arrived - mapped;
        }
        let ppm = self.drift * 1e6;
        if self
            .reported_ppm
            .is_none_or(|r| (r - ppm).abs() >= DRIFT_REPORT_PPM)
        {
            self.reported_ppm = Some(ppm);
            events.push(ClockEvent::Drift {
                ppm,
                blocks: self.blocks.len(),
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A board at 1.25 frames/s whose crystal runs `ppm` fast, seen through a link that
    /// delays each frame by 2–12 ms, and sometimes by a 0.3 s burst.
    fn run(
        ppm: f64,
        seconds: f64,
        pc_step_at: Option<(f64, f64)>,
    ) -> (Vec<(u64, f64)>, Vec<ClockEvent>) {
        let mut m = ClockModel::new(None);
        let start = 1.7e9;
        let mut events = Vec::new();
        let mut out = Vec::new();
        let mut k = 0u64;
        loop {
            let true_s = k as f64 * 0.8;
            if true_s > seconds {
                break;
            }
            let board_us = (true_s * (1.0 + ppm * 1e-6) * 1e6) as u64;
            // Deterministic jitter; every 50th frame caught in a 0.3 s burst.
            let delay = 0.002
                + 0.01 * ((k * 7919 % 100) as f64 / 100.0)
                + if k % 50 == 7 { 0.3 } else { 0.0 };
            let step = pc_step_at.map_or(0.0, |(at, s)| if true_s >= at { s } else { 0.0 });
            let pc = start + true_s + delay + step;
            out.push((
                board_us,
                m.record_time(board_us, pc, start, true, &mut events),
            ));
            k += 1;
        }
        (out, events)
    }

    #[test]
    fn a_fast_crystal_is_measured_and_record_time_follows_true_time() {
        let (rows, events) = run(25.0, 6.0 * 3600.0, None);
        let Some(ClockEvent::Drift { ppm, .. }) = events
            .iter()
            .rev()
            .find(|e| matches!(e, ClockEvent::Drift { .. }))
        else {
            panic!("no drift event: {events:?}")
        };
        assert!((ppm - 25.0).abs() < 0.5, "fitted {ppm} ppm");
        // True time of the last frame is 0.8 s × index; the first frame's delay (≤ 12 ms) is
        // the anchor's error, the drift before the first fit adds at most 25 ppm × 2 blocks.
        let (i, t) = (rows.len() - 1, rows.last().unwrap().1);
        let truth = i as f64 * 0.8;
        assert!((t - truth).abs() < 0.02, "record {t} vs true {truth}");
        assert!(rows.windows(2).all(|w| w[1].1 > w[0].1));
    }

    /// Frames `0..frames` of a board at 1.25 frames/s with an exact crystal, frame k (true
    /// time `true_s`) reaching the PC `delay_s(k, true_s)` late: each frame's record time, and
    /// the events.
    fn record_times(frames: u64, delay_s: impl Fn(u64, f64) -> f64) -> (Vec<f64>, Vec<ClockEvent>) {
        let mut m = ClockModel::new(None);
        let start = 1.7e9;
        let mut events = Vec::new();
        let rows = (0..frames)
            .map(|k| {
                let true_s = k as f64 * 0.8;
                let pc = start + true_s + delay_s(k, true_s);
                m.record_time((true_s * 1e6) as u64, pc, start, true, &mut events)
            })
            .collect();
        (rows, events)
    }

    #[test]
    fn a_late_first_frame_is_slewed_out_without_a_jump() {
        // The first frame waited 0.4 s in a buffer (the record starts at its arrival); every
        // other one arrives within 1–3 ms.
        let (rows, _) = record_times(20_000, |k, _| {
            if k == 0 {
                0.4
            } else {
                0.001 + 0.002 * ((k % 7) as f64 / 7.0)
            }
        });
        // Record time of frame k should be its true time plus the 1 ms minimum delay; the
        // anchor put the first frame 0.4 s late.
        let err = |k: usize| rows[k] - (k as f64 * 0.8 + 0.001);
        assert!((err(0) - 0.399).abs() < 1e-6);
        assert!(err(rows.len() - 1).abs() < 2e-3, "{}", err(rows.len() - 1));
        for w in rows.windows(2) {
            let dt = w[1] - w[0];
            assert!((dt - 0.8).abs() <= 0.8 * MAX_SLEW + 1e-9, "step {dt}");
        }
    }

    #[test]
    fn a_pc_clock_step_is_reported_and_moves_nothing() {
        let (rows, events) = run(0.0, 3.0 * 3600.0, Some((3600.0, -30.0)));
        let steps: Vec<f64> = events
            .iter()
            .filter_map(|e| match e {
                ClockEvent::PcStep { step_s } => Some(*step_s),
                _ => None,
            })
            .collect();
        assert_eq!(steps.len(), 1, "{events:?}");
        assert!((steps[0] + 30.0).abs() < 0.02, "{steps:?}");
        for (i, (_, t)) in rows.iter().enumerate() {
            assert!((t - i as f64 * 0.8).abs() < 0.02, "frame {i}: {t}");
        }
    }

    #[test]
    fn a_burst_of_delay_over_a_whole_block_is_no_pc_clock_step() {
        let (rows, events) = record_times(9000, |k, true_s| {
            // Every frame between 1800 s and 1890 s (a whole 60 s block at least) waits 2 s
            // more: a PC that did not read the port for a minute and a half.
            let burst = if (1800.0..1890.0).contains(&true_s) {
                2.0
            } else {
                0.0
            };
            0.002 + 0.001 * ((k % 5) as f64) + burst
        });
        assert!(
            !events.iter().any(|e| matches!(
                e,
                ClockEvent::PcStep { .. } | ClockEvent::NotACrystal { .. }
            )),
            "{events:?}"
        );
        for (k, t) in rows.iter().enumerate() {
            assert!(
                (t - (k as f64 * 0.8 + 0.002)).abs() < 0.01,
                "frame {k}: {t}"
            );
        }
    }

    #[test]
    fn a_board_at_a_thousand_times_the_pc_clock_is_no_crystal_and_keeps_its_own_time() {
        let mut m = ClockModel::new(None);
        let mut events = Vec::new();
        let start = 1.7e9;
        let mut last = 0.0;
        for k in 0..2000u64 {
            let board_us = k * 800_000;
            let pc = start + k as f64 * 0.8e-3 + 0.001;
            last = m.record_time(board_us, pc, start, true, &mut events);
        }
        assert!(matches!(
            events.as_slice(),
            [ClockEvent::NotACrystal { rate }] if (rate - 1000.0).abs() < 5.0
        ));
        assert!((last - 1999.0 * 0.8).abs() < 0.01, "{last}");
        // A reboot 1 PC second later: the gap is 1000 board seconds.
        m.new_boot();
        let t = m.record_time(
            1_000,
            start + 1999.0 * 0.8e-3 + 1.001,
            start,
            true,
            &mut events,
        );
        assert!((t - (last + 1000.0)).abs() < 5.0, "{t}");
    }
}
