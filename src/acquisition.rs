//! Acquisition sequencing of the front-end board, generic over embedded-hal 1.0.
//!
//! The board has two converters on two SPI buses (docs/drivers.md, "Bus"):
//!
//! - the **ADS1262** alternates between the accelerometer and the tiltmeter input. Its DRDY
//!   interrupt calls [`AdsSequencer::on_drdy`], which reads the conversion DRDY announced (one
//!   RDATA1 transaction), switches the mux to the other input (WREG, RREG, START1) and, after the
//!   tilt half, returns an [`AdsReading`] timestamped at the accelerometer's DRDY. It never waits.
//!   A supervisor tick ([`AdsSequencer::on_tick`]) notices a missing DRDY, emits readings flagged
//!   DRDY_TIMEOUT at the expected pair rate, diagnoses (reset? no answer?) and re-initialises
//!   the chip in steps — RESET, then [`ads1262::RESET_WAIT_US`] later the configuration — so
//!   nothing blocks for milliseconds.
//! - the **AD7124-4** converts the RTD continuously; its own task calls
//!   [`RtdSequencer::on_tick`] at the RTD data rate, which polls STATUS once and reads the result
//!   if ready. Transport errors are followed by a check of ADC_CONTROL (a reset part reads
//!   0x0000) and, if the configuration is gone, a stepped re-initialisation.
//!
//! The worker joins the two with [`SampleAssembler`]. Every driver error becomes a
//! [`ChannelFlags`] bit ([`flags_for`]), so a fault reaches the frame as a named status bit and
//! never as a number. The host runs all of this against register-level chip models
//! (host-sim/crates/chipsim/tests/board_sim.rs).

use embedded_hal::delay::DelayNs;
use embedded_hal::digital::InputPin;
use embedded_hal::spi::{Mode, Phase, Polarity, SpiDevice};

use crate::drivers::ad7124::{self, Ad7124};
use crate::drivers::ads1262::{self, registers::POWER_RESET, Ads1262, Channel, DataRate};
use crate::pipeline::{ChannelFlags, LossFlags, RawSample};

/// The SPI mode and clock a bus actually runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SpiSettings {
    /// Clock polarity and phase.
    pub mode: Mode,
    /// SCLK frequency in hertz.
    pub sclk_hz: u32,
}

/// What a chip's datasheet requires of its bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SpiRequirement {
    /// The only mode the chip's timing diagram allows.
    pub mode: Mode,
    /// Fastest SCLK in hertz.
    pub max_sclk_hz: u32,
}

const fn same_mode(a: Mode, b: Mode) -> bool {
    let pol = matches!(
        (a.polarity, b.polarity),
        (Polarity::IdleLow, Polarity::IdleLow) | (Polarity::IdleHigh, Polarity::IdleHigh)
    );
    let pha = matches!(
        (a.phase, b.phase),
        (
            Phase::CaptureOnFirstTransition,
            Phase::CaptureOnFirstTransition
        ) | (
            Phase::CaptureOnSecondTransition,
            Phase::CaptureOnSecondTransition
        )
    );
    pol && pha
}

impl SpiRequirement {
    /// True when a bus running `bus` meets this requirement.
    pub const fn accepts(&self, bus: &SpiSettings) -> bool {
        same_mode(self.mode, bus.mode) && bus.sclk_hz > 0 && bus.sclk_hz <= self.max_sclk_hz
    }
}

/// ADS1262: mode 1, ≤ 8 MHz ([`ads1262::SPI_MODE`], [`ads1262::MAX_SCLK_HZ`]).
pub const ADS1262_SPI: SpiRequirement = SpiRequirement {
    mode: ads1262::SPI_MODE,
    max_sclk_hz: ads1262::MAX_SCLK_HZ,
};

/// AD7124-4: mode 3, ≤ 5 MHz ([`ad7124::SPI_MODE`], [`ad7124::MAX_SCLK_HZ`]).
pub const AD7124_SPI: SpiRequirement = SpiRequirement {
    mode: ad7124::SPI_MODE,
    max_sclk_hz: ad7124::MAX_SCLK_HZ,
};

/// Fastest SCLK an STM32F4 SPI can make from `pclk_hz` without exceeding `max_hz`: the baud-rate
/// prescaler divides by 2, 4, …, 256 (RM0090, SPI_CR1.BR). None when even /256 is too fast.
pub const fn stm32_sclk_within(pclk_hz: u32, max_hz: u32) -> Option<u32> {
    let mut div = 2u32;
    while div <= 256 {
        if pclk_hz / div <= max_hz {
            return Some(pclk_hz / div);
        }
        div *= 2;
    }
    None
}

/// A converter error as the pipeline's channel flags: every error names at least one bit.
pub trait ChannelFault {
    /// The flags this error gives the channel it happened on.
    fn channel_flags(&self) -> ChannelFlags;
}

impl<S, P> ChannelFault for ads1262::Error<S, P> {
    fn channel_flags(&self) -> ChannelFlags {
        use ads1262::Error as E;
        ChannelFlags(match self {
            // The bytes arrived but cannot be trusted (or the bus itself failed).
            E::Checksum { .. } | E::CrcMismatch { .. } | E::Spi(_) => ChannelFlags::CHECKSUM,
            E::UnexpectedReset => ChannelFlags::RESET,
            E::NotResponding { .. } => ChannelFlags::NOT_RESPONDING,
            // No fresh, valid conversion: timeout, stale data, or a chip that does not take its
            // configuration.
            E::DrdyTimeout
            | E::StaleData
            | E::Pin(_)
            | E::InvalidConfig
            | E::DeviceId { .. }
            | E::ReadBack { .. } => ChannelFlags::DRDY_TIMEOUT,
        })
    }
}

impl<S, P> ChannelFault for ad7124::Error<S, P> {
    fn channel_flags(&self) -> ChannelFlags {
        use ad7124::Error as E;
        ChannelFlags(match self {
            E::CrcMismatch { .. } | E::Spi(_) => ChannelFlags::CHECKSUM,
            E::AdcError(f) => {
                let mut b = 0;
                if f.reference_missing() {
                    b |= ChannelFlags::OPEN_CIRCUIT;
                }
                if f.saturated() || f.input_out_of_range() || f.conversion() || b == 0 {
                    b |= ChannelFlags::SATURATION;
                }
                b
            }
            E::UnexpectedReset => ChannelFlags::RESET,
            E::NotResponding { .. } => ChannelFlags::NOT_RESPONDING,
            E::DrdyTimeout
            | E::Pin(_)
            | E::InvalidConfig
            | E::DeviceId { .. }
            | E::ReadBack { .. } => ChannelFlags::DRDY_TIMEOUT,
        })
    }
}

/// The pipeline's channel flags for a driver error of either converter.
pub fn flags_for<E: ChannelFault>(e: &E) -> ChannelFlags {
    e.channel_flags()
}

/// The drivers' data-ready input when the firmware does not poll a pin (the ADS1262's DRDY is
/// an interrupt, the AD7124's STATUS is polled over SPI). Reads "not ready", so a polled wait
/// on it times out instead of pretending data is there.
#[derive(Debug, Clone, Copy, Default)]
pub struct InterruptDrdy;

impl embedded_hal::digital::ErrorType for InterruptDrdy {
    type Error = core::convert::Infallible;
}

impl InputPin for InterruptDrdy {
    fn is_high(&mut self) -> Result<bool, Self::Error> {
        Ok(true)
    }
    fn is_low(&mut self) -> Result<bool, Self::Error> {
        Ok(false)
    }
}

/// Accelerometer and tilt conversions of one sample, timestamped at the accelerometer's DRDY.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AdsReading {
    /// ADS1262 code of the accelerometer input (0 when flagged).
    pub accel: i32,
    /// Its fault bits.
    pub accel_flags: ChannelFlags,
    /// ADS1262 code of the tiltmeter input (0 when flagged).
    pub tilt: i32,
    /// Its fault bits.
    pub tilt_flags: ChannelFlags,
    /// Firmware time of the accelerometer DRDY edge (or of the timeout), µs.
    pub time_us: u64,
    /// Sequence number: one per reading slot of the pair clock. Readings the core could not
    /// take in time (a stall longer than a pair period) leave a gap here.
    pub seq: u32,
    /// Why readings are missing before this one ([`LossFlags::STALL`] from the sequencer; the
    /// firmware adds the losses it sees later).
    pub lost: LossFlags,
}

/// Counters for Info and the logs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SequencerCounters {
    /// Readings emitted because no conversion came in time.
    pub timeouts: u32,
    /// Re-initialisations that completed.
    pub reinits: u32,
    /// Driver errors seen.
    pub errors: u32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Recovery {
    /// Not initialised yet: the first tick starts the stepped initialisation.
    Start,
    /// Configured and converting.
    Running,
    /// RESET sent at `since_us`; configure once the reset wait has passed.
    ResetWait { since_us: u64 },
    /// A re-initialisation failed; try again at `at_us`.
    Retry { at_us: u64 },
}

/// Extra margin on every DRDY deadline: the data-sheet latency adds a fixed delay to the
/// settling conversions, and the tick that checks the deadline has its own granularity.
const DEADLINE_MARGIN_US: u64 = 20_000;

/// The ADS1262 half of acquisition: DRDY-driven channel alternation, timeout, re-init, rate.
pub struct AdsSequencer<SPI, DRDY, D> {
    ads: Ads1262<SPI, DRDY, D>,
    recovery: Recovery,
    /// Channel whose conversion the next DRDY announces (None: unknown, restart the pair).
    converting: Option<Channel>,
    /// The accelerometer half of the pair in progress: code, flags, DRDY time.
    accel: Option<(i32, ChannelFlags, u64)>,
    /// Time of the last DRDY, of the last (re)start, or of the last timeout reading.
    last_progress_us: u64,
    /// When the next timeout reading is due while the chip is being recovered.
    next_timeout_us: u64,
    /// Why conversions stopped (RESET / NOT_RESPONDING bits), added to timeout readings.
    diagnosis: u8,
    pending_rate: Option<DataRate>,
    counters: SequencerCounters,
    /// Sequence number of the next reading.
    next_seq: u32,
    /// DRDY time of the previous pair's accelerometer half, while the pair clock is steady
    /// (None after a (re)start or a change of rate).
    last_pair_us: Option<u64>,
}

impl<SPI, DRDY, D> AdsSequencer<SPI, DRDY, D>
where
    SPI: SpiDevice,
    DRDY: InputPin,
    D: DelayNs,
{
    /// Wrap a driver. Nothing is sent until the first [`AdsSequencer::on_tick`], which starts
    /// the initialisation in steps (no blocking wait: what the firmware does), or until
    /// [`AdsSequencer::boot`] (blocking).
    pub const fn new(ads: Ads1262<SPI, DRDY, D>) -> Self {
        Self {
            ads,
            recovery: Recovery::Start,
            converting: None,
            accel: None,
            last_progress_us: 0,
            next_timeout_us: 0,
            diagnosis: 0,
            pending_rate: None,
            counters: SequencerCounters {
                timeouts: 0,
                reinits: 0,
                errors: 0,
            },
            next_seq: 0,
            last_pair_us: None,
        }
    }

    /// Initialise at boot (blocking reset wait: interrupts are not running yet). On failure the
    /// chip is retried from the supervisor tick, with timeout readings meanwhile.
    pub fn boot(
        &mut self,
        now_us: u64,
    ) -> Result<ads1262::DeviceInfo, ads1262::DriverError<SPI, DRDY>> {
        let result = self.ads.init();
        match result {
            Ok(_) => self.running(now_us),
            Err(ref e) => {
                self.diagnosis =
                    flags_for(e).0 & (ChannelFlags::NOT_RESPONDING | ChannelFlags::RESET);
                self.recovery = Recovery::Retry { at_us: now_us };
                self.next_timeout_us = now_us + self.pair_period_us();
            }
        }
        result
    }

    /// The driver (configuration, release).
    pub fn driver(&self) -> &Ads1262<SPI, DRDY, D> {
        &self.ads
    }

    /// Counters since boot.
    pub const fn counters(&self) -> SequencerCounters {
        self.counters
    }

    /// True while the chip is configured and converting.
    pub fn is_running(&self) -> bool {
        self.recovery == Recovery::Running
    }

    /// The core may have served this DRDY late: a flash erase or program stalled it (RM0090
    /// §3.5), so the conversion the DRDY announces may have ended at any time during the stall
    /// and the handler's time stamp would not be its time. Its result is read and dropped and
    /// the pair starts again from the accelerometer; the pairs this costs are the seq gap
    /// (flagged STALL) of the next pair.
    pub fn restart_pair(&mut self) {
        self.converting = None;
    }

    /// Change the data rate at the next channel switch (SetRate).
    pub fn request_rate(&mut self, rate: DataRate) {
        self.pending_rate = Some(rate);
    }

    /// Time from a (re)start to the first settled conversion of one channel, µs (nominal).
    pub fn channel_latency_us(&self) -> u64 {
        let c = self.ads.config();
        u64::from(c.filter.settling_conversions()) * u64::from(c.data_rate.period_us())
    }

    /// Expected time between two readings: both channels settle once per pair.
    pub fn pair_period_us(&self) -> u64 {
        2 * self.channel_latency_us()
    }

    /// How long without DRDY before the chip counts as stuck.
    fn overdue_us(&self) -> u64 {
        2 * self.channel_latency_us() + DEADLINE_MARGIN_US
    }

    fn running(&mut self, now_us: u64) {
        self.recovery = Recovery::Running;
        self.converting = Some(Channel::Accelerometer);
        self.accel = None;
        self.last_progress_us = now_us;
        self.last_pair_us = None;
    }

    /// Gives `reading` the next sequence number. A pair that comes more than half a pair
    /// period late (the core did not serve DRDY: a flash erase, interrupts off) skips the
    /// numbers of the pairs that would have come meanwhile and says STALL.
    fn numbered(&mut self, mut reading: AdsReading, pair: bool) -> AdsReading {
        if pair {
            if let Some(prev) = self.last_pair_us {
                // 32-bit arithmetic (one UDIV in the DRDY handler): pair periods are below
                // 2³² µs, and a stall of more than 71 minutes saturates to u32::MAX numbers.
                let period = u32::try_from(self.pair_period_us())
                    .unwrap_or(u32::MAX)
                    .max(1);
                let dt = u32::try_from(reading.time_us.saturating_sub(prev)).unwrap_or(u32::MAX);
                let missed = (dt.saturating_add(period / 2) / period).saturating_sub(1);
                if missed > 0 {
                    self.next_seq = self.next_seq.wrapping_add(missed);
                    reading.lost = LossFlags(reading.lost.0 | LossFlags::STALL);
                }
            }
            self.last_pair_us = Some(reading.time_us);
        } else {
            self.last_pair_us = None;
        }
        reading.seq = self.next_seq;
        self.next_seq = self.next_seq.wrapping_add(1);
        reading
    }

    /// DRDY fell at `now_us`: read what it announced, switch the mux, and return the pair when
    /// its tilt half is in. Bounded: one read, at most one mux write + read-back + START1.
    pub fn on_drdy(&mut self, now_us: u64) -> Option<AdsReading> {
        if self.recovery != Recovery::Running {
            return None;
        }
        self.last_progress_us = now_us;
        self.diagnosis = 0;
        let (code, flags) = match self.ads.read_conversion() {
            Ok(s) => {
                let alarm = s.status.is_some_and(|st| st.any_alarm());
                (
                    s.code.0,
                    ChannelFlags(if alarm { ChannelFlags::SATURATION } else { 0 }),
                )
            }
            Err(e) => {
                self.counters.errors = self.counters.errors.wrapping_add(1);
                let flags = flags_for(&e);
                if matches!(
                    e,
                    ads1262::Error::UnexpectedReset | ads1262::Error::NotResponding { .. }
                ) {
                    // The configuration is gone or nobody answers: the pair in progress is lost;
                    // say why in a reading and re-initialise in steps from the tick.
                    self.diagnosis = flags.0;
                    self.begin_reinit(now_us);
                    return Some(self.fault_reading(now_us, flags));
                }
                (0, flags)
            }
        };
        match self.converting {
            Some(Channel::Accelerometer) => {
                self.accel = Some((code, flags, now_us));
                self.switch_to(Channel::Tiltmeter);
                None
            }
            Some(Channel::Tiltmeter) => {
                // Without its accelerometer half (a failed switch lost it) the reading says so.
                let (accel, accel_flags, time_us) = self.accel.take().unwrap_or((
                    0,
                    ChannelFlags(ChannelFlags::DRDY_TIMEOUT),
                    now_us,
                ));
                let reading = AdsReading {
                    accel,
                    accel_flags,
                    tilt: code,
                    tilt_flags: flags,
                    time_us,
                    seq: 0,
                    lost: LossFlags(0),
                };
                // Numbered before the switch: a rate change the switch applies restarts the pair
                // clock after this pair, so the next pair (at the new rate) is not measured
                // against this one's period and does not claim a stall.
                let reading = self.numbered(reading, true);
                self.switch_to(Channel::Accelerometer);
                Some(reading)
            }
            None => {
                // A conversion of an input we cannot name: start the pair again.
                self.accel = None;
                self.switch_to(Channel::Accelerometer);
                None
            }
        }
    }

    /// Supervisor tick (call every few ms up to the channel latency): emits a DRDY_TIMEOUT
    /// reading when DRDY is overdue, then one per expected pair period while the chip is
    /// re-initialised; drives the re-initialisation steps.
    pub fn on_tick(&mut self, now_us: u64) -> Option<AdsReading> {
        match self.recovery {
            Recovery::Running => {
                if now_us.saturating_sub(self.last_progress_us) < self.overdue_us() {
                    return None;
                }
                self.diagnosis = self.diagnose();
                self.next_timeout_us = now_us + self.pair_period_us();
                self.begin_reinit(now_us);
                self.counters.timeouts = self.counters.timeouts.wrapping_add(1);
                Some(self.fault_reading(now_us, self.timeout_flags()))
            }
            Recovery::ResetWait { since_us } => {
                if now_us.saturating_sub(since_us) >= u64::from(ads1262::RESET_WAIT_US) {
                    match self.ads.configure() {
                        Ok(_) => {
                            self.counters.reinits = self.counters.reinits.wrapping_add(1);
                            self.running(now_us);
                            return None;
                        }
                        Err(e) => {
                            self.counters.errors = self.counters.errors.wrapping_add(1);
                            self.diagnosis |= flags_for(&e).0
                                & (ChannelFlags::NOT_RESPONDING | ChannelFlags::RESET);
                            self.recovery = Recovery::Retry {
                                at_us: now_us + self.pair_period_us(),
                            };
                        }
                    }
                }
                self.timeout_if_due(now_us)
            }
            Recovery::Retry { at_us } => {
                if now_us >= at_us {
                    self.begin_reinit(now_us);
                }
                self.timeout_if_due(now_us)
            }
            Recovery::Start => {
                self.next_timeout_us = now_us + self.overdue_us();
                self.begin_reinit(now_us);
                None
            }
        }
    }

    fn timeout_flags(&self) -> ChannelFlags {
        ChannelFlags(ChannelFlags::DRDY_TIMEOUT | self.diagnosis)
    }

    fn timeout_if_due(&mut self, now_us: u64) -> Option<AdsReading> {
        if now_us < self.next_timeout_us {
            return None;
        }
        self.next_timeout_us = now_us + self.pair_period_us();
        self.counters.timeouts = self.counters.timeouts.wrapping_add(1);
        Some(self.fault_reading(now_us, self.timeout_flags()))
    }

    fn fault_reading(&mut self, now_us: u64, flags: ChannelFlags) -> AdsReading {
        let reading = AdsReading {
            accel: 0,
            accel_flags: flags,
            tilt: 0,
            tilt_flags: flags,
            time_us: now_us,
            seq: 0,
            lost: LossFlags(0),
        };
        self.numbered(reading, false)
    }

    /// Why did DRDY stop? POWER.RESET = 1 means the chip reset (brown-out: START1 was lost with
    /// the configuration); an all-ones or all-zeros answer means nobody drives MISO.
    fn diagnose(&mut self) -> u8 {
        match self.ads.read_id_power() {
            Ok((id, power)) if id == 0xFF || (id == 0 && power == 0) => {
                ChannelFlags::NOT_RESPONDING
            }
            Ok((_, power)) if power & POWER_RESET != 0 => ChannelFlags::RESET,
            Ok(_) => 0,
            Err(e) => flags_for(&e).0 & ChannelFlags::NOT_RESPONDING,
        }
    }

    fn begin_reinit(&mut self, now_us: u64) {
        self.converting = None;
        self.accel = None;
        if self.next_timeout_us <= now_us {
            self.next_timeout_us = now_us + self.pair_period_us();
        }
        self.recovery = match self.ads.begin_reset() {
            Ok(()) => Recovery::ResetWait { since_us: now_us },
            Err(_) => Recovery::Retry {
                at_us: now_us + self.pair_period_us(),
            },
        };
    }

    fn switch_to(&mut self, channel: Channel) {
        if let Some(rate) = self.pending_rate.take() {
            // The pair clock changes: the next pair starts it afresh.
            self.last_pair_us = None;
            if self.ads.set_data_rate(rate).is_err() {
                self.counters.errors = self.counters.errors.wrapping_add(1);
            }
        }
        match self.ads.select_channel(channel) {
            Ok(()) => self.converting = Some(channel),
            Err(_) => {
                // The driver forgot the selection; the next DRDY (or the timeout) restarts.
                self.counters.errors = self.counters.errors.wrapping_add(1);
                self.converting = None;
            }
        }
    }
}

/// One RTD result (or why there is none), timestamped when it was read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RtdReading {
    /// AD7124 code (0 when flagged).
    pub code: u32,
    /// Fault bits.
    pub flags: ChannelFlags,
    /// Firmware time of the read, µs.
    pub time_us: u64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum RtdState {
    Recovery(Recovery),
    /// A transport error happened: check on the next tick whether the part kept its setup.
    Verify,
}

/// The AD7124-4 half of acquisition: one STATUS poll per tick, read when ready, verify after
/// a transport error, stepped re-initialisation after a reset or a timeout.
pub struct RtdSequencer<SPI, DRDY, D> {
    rtd: Ad7124<SPI, DRDY, D>,
    state: RtdState,
    last_result_us: u64,
    diagnosis: u8,
    counters: SequencerCounters,
}

impl<SPI, DRDY, D> RtdSequencer<SPI, DRDY, D>
where
    SPI: SpiDevice,
    DRDY: InputPin,
    D: DelayNs,
{
    /// Wrap a driver. Nothing is sent until the first [`RtdSequencer::on_tick`] (stepped
    /// initialisation) or [`RtdSequencer::boot`] (blocking).
    pub const fn new(rtd: Ad7124<SPI, DRDY, D>) -> Self {
        Self {
            rtd,
            state: RtdState::Recovery(Recovery::Start),
            last_result_us: 0,
            diagnosis: 0,
            counters: SequencerCounters {
                timeouts: 0,
                reinits: 0,
                errors: 0,
            },
        }
    }

    /// Initialise at boot (blocking reset wait); on failure retried from the tick.
    pub fn boot(
        &mut self,
        now_us: u64,
    ) -> Result<ad7124::DeviceInfo, ad7124::DriverError<SPI, DRDY>> {
        let result = self.rtd.init();
        match result {
            Ok(_) => {
                self.state = RtdState::Recovery(Recovery::Running);
                self.last_result_us = now_us;
            }
            Err(ref e) => {
                self.diagnosis = flags_for(e).0 & ChannelFlags::NOT_RESPONDING;
                self.state = RtdState::Recovery(Recovery::Retry { at_us: now_us });
            }
        }
        result
    }

    /// The driver.
    pub fn driver(&self) -> &Ad7124<SPI, DRDY, D> {
        &self.rtd
    }

    /// Counters since boot.
    pub const fn counters(&self) -> SequencerCounters {
        self.counters
    }

    /// Conversion period of the configured filter, µs: the tick period the task should use
    /// (1 / ODR = 32·FS / f_CLK; integer maths, no soft-float on the MCU).
    pub fn period_us(&self) -> u64 {
        let c = self.rtd.config();
        let clock_hz = u64::from(c.power_mode.clock_hz()).max(1);
        32 * u64::from(c.filter_fs.max(1)) * 1_000_000 / clock_hz
    }

    /// No result for this long (three periods plus margin) counts as a timeout.
    fn overdue_us(&self) -> u64 {
        3 * self.period_us() + DEADLINE_MARGIN_US
    }

    fn reading(&self, now_us: u64, code: u32, flags: u8) -> RtdReading {
        RtdReading {
            code,
            flags: ChannelFlags(flags),
            time_us: now_us,
        }
    }

    /// One tick at about the RTD data rate. Returns a reading when a result (or a fault) is
    /// there; None when the conversion is simply not finished yet.
    pub fn on_tick(&mut self, now_us: u64) -> Option<RtdReading> {
        match self.state {
            RtdState::Recovery(Recovery::Running) => self.poll(now_us),
            RtdState::Verify => {
                match self.rtd.read_control_unchecked() {
                    Ok(v) if v == self.rtd.configured_control() => {
                        // A transient transport error: the part kept its configuration.
                        self.state = RtdState::Recovery(Recovery::Running);
                        None
                    }
                    Ok(_) => {
                        // ADC_CONTROL lost its setting (0x0000 after a reset).
                        self.diagnosis = ChannelFlags::RESET;
                        self.begin_reinit(now_us);
                        Some(self.reading(now_us, 0, self.diagnosis))
                    }
                    Err(e) => {
                        self.diagnosis = flags_for(&e).0;
                        self.begin_reinit(now_us);
                        Some(self.reading(now_us, 0, self.diagnosis))
                    }
                }
            }
            RtdState::Recovery(Recovery::ResetWait { since_us }) => {
                if now_us.saturating_sub(since_us) < u64::from(ad7124::RESET_WAIT_US) {
                    return Some(self.reading(
                        now_us,
                        0,
                        ChannelFlags::DRDY_TIMEOUT | self.diagnosis,
                    ));
                }
                match self.rtd.configure() {
                    Ok(_) => {
                        self.counters.reinits = self.counters.reinits.wrapping_add(1);
                        self.state = RtdState::Recovery(Recovery::Running);
                        self.last_result_us = now_us;
                        // The first result settles over four periods: no reading yet.
                        None
                    }
                    Err(e) => {
                        self.counters.errors = self.counters.errors.wrapping_add(1);
                        self.diagnosis |= flags_for(&e).0 & ChannelFlags::NOT_RESPONDING;
                        self.state = RtdState::Recovery(Recovery::Retry {
                            at_us: now_us + 10 * self.period_us(),
                        });
                        Some(self.reading(now_us, 0, ChannelFlags::DRDY_TIMEOUT | self.diagnosis))
                    }
                }
            }
            RtdState::Recovery(Recovery::Retry { at_us }) => {
                if now_us >= at_us {
                    self.begin_reinit(now_us);
                }
                Some(self.reading(now_us, 0, ChannelFlags::DRDY_TIMEOUT | self.diagnosis))
            }
            RtdState::Recovery(Recovery::Start) => {
                self.begin_reinit(now_us);
                None
            }
        }
    }

    fn poll(&mut self, now_us: u64) -> Option<RtdReading> {
        let ready = match self.rtd.read_status() {
            Ok(st) => st.ready(),
            Err(e) => return Some(self.transport_error(now_us, &e)),
        };
        if !ready {
            if now_us.saturating_sub(self.last_result_us) < self.overdue_us() {
                return None;
            }
            // Conversions stopped: flag, then check whether the part kept its setup.
            self.counters.timeouts = self.counters.timeouts.wrapping_add(1);
            self.state = RtdState::Verify;
            self.last_result_us = now_us;
            return Some(self.reading(now_us, 0, ChannelFlags::DRDY_TIMEOUT));
        }
        match self.rtd.read_data() {
            Ok((code, _)) => {
                self.last_result_us = now_us;
                self.diagnosis = 0;
                Some(self.reading(now_us, code.0, 0))
            }
            Err(ad7124::Error::AdcError(f))
                if !(f.spi() || f.spi_crc() || f.register_map_crc() || f.supply()) =>
            {
                // An analog condition of the measurement (open RTD, saturation): the part works
                // and keeps converting; the reading carries the flag.
                self.last_result_us = now_us;
                Some(self.reading(
                    now_us,
                    0,
                    flags_for(&ad7124::Error::<(), ()>::AdcError(f)).0,
                ))
            }
            Err(e) => Some(self.transport_error(now_us, &e)),
        }
    }

    fn transport_error<S, P>(&mut self, now_us: u64, e: &ad7124::Error<S, P>) -> RtdReading {
        self.counters.errors = self.counters.errors.wrapping_add(1);
        let flags = flags_for(e).0;
        if flags & ChannelFlags::NOT_RESPONDING != 0 {
            self.diagnosis = flags;
            self.begin_reinit(now_us);
        } else {
            self.state = RtdState::Verify;
        }
        self.reading(now_us, 0, flags)
    }

    fn begin_reinit(&mut self, now_us: u64) {
        self.state = RtdState::Recovery(match self.rtd.begin_reset() {
            Ok(()) => Recovery::ResetWait { since_us: now_us },
            Err(_) => Recovery::Retry {
                at_us: now_us + 10 * self.period_us(),
            },
        });
    }
}

/// Joins the latest RTD reading to each ADS1262 pair (runs in the worker).
///
/// The RTD is read about eight times per pair at the default rates, so a transient RTD fault
/// (one bad CRC) is usually followed by a good reading before the next pair. So that no fault
/// goes unreported, a flagged reading is held until one pair has carried it; that pair's RTD
/// value is then invalid and says why.
#[derive(Debug, Clone, Copy)]
pub struct SampleAssembler {
    latest: Option<RtdReading>,
    unreported_fault: Option<RtdReading>,
    max_age_us: u64,
}

impl SampleAssembler {
    /// An RTD reading further than `max_age_us` from a pair's timestamp counts as missing
    /// (DRDY_TIMEOUT on the RTD channel).
    pub const fn new(max_age_us: u64) -> Self {
        Self {
            latest: None,
            unreported_fault: None,
            max_age_us,
        }
    }

    /// A new RTD reading from the RTD task.
    pub fn rtd(&mut self, reading: RtdReading) {
        if reading.flags.0 != 0 {
            let earlier = self.unreported_fault.map_or(0, |r| r.flags.0);
            self.unreported_fault = Some(RtdReading {
                flags: ChannelFlags(reading.flags.0 | earlier),
                ..reading
            });
        }
        self.latest = Some(reading);
    }

    /// The raw sample for one ADS1262 pair.
    pub fn assemble(&mut self, ads: &AdsReading) -> RawSample {
        let (rtd, rtd_flags) = match self.unreported_fault.take().or(self.latest) {
            Some(r) if r.time_us.abs_diff(ads.time_us) <= self.max_age_us => (r.code, r.flags),
            _ => (0, ChannelFlags(ChannelFlags::DRDY_TIMEOUT)),
        };
        RawSample {
            accel: ads.accel,
            rtd,
            tilt: ads.tilt,
            accel_flags: ads.accel_flags,
            rtd_flags,
            tilt_flags: ads.tilt_flags,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_hal::spi::{MODE_0, MODE_1, MODE_3};

    #[test]
    fn the_board_buses_meet_both_datasheets_and_the_old_shared_mode_1_bus_did_not() {
        assert_eq!(crate::board::ADS1262_BUS.sclk_hz, 5_250_000);
        assert_eq!(crate::board::AD7124_BUS.sclk_hz, 2_625_000);
        assert!(ADS1262_SPI.accepts(&crate::board::ADS1262_BUS));
        assert!(AD7124_SPI.accepts(&crate::board::AD7124_BUS));
        let old = SpiSettings {
            mode: MODE_1,
            sclk_hz: 5_250_000,
        };
        assert!(
            !AD7124_SPI.accepts(&old),
            "mode 1 and 5.25 MHz for the AD7124"
        );
        assert!(!AD7124_SPI.accepts(&SpiSettings {
            mode: MODE_3,
            sclk_hz: 5_250_000
        }));
        assert!(!ADS1262_SPI.accepts(&SpiSettings {
            mode: MODE_0,
            sclk_hz: 1_000_000
        }));
    }

    #[test]
    fn the_stm32_prescaler_never_exceeds_the_limit() {
        assert_eq!(stm32_sclk_within(84_000_000, 8_000_000), Some(5_250_000));
        assert_eq!(stm32_sclk_within(42_000_000, 5_000_000), Some(2_625_000));
        assert_eq!(stm32_sclk_within(84_000_000, 42_000_000), Some(42_000_000));
        assert_eq!(stm32_sclk_within(84_000_000, 100_000), None);
    }

    #[test]
    fn every_driver_error_names_a_flag() {
        // The variants both drivers' errors share (`converter_error!`), then the chip's own.
        macro_rules! every_error {
            ($E:ident: $($own:expr),*) => {
                [
                    $E::Spi(()),
                    $E::Pin(()),
                    $E::DrdyTimeout,
                    $E::CrcMismatch {
                        expected: 0,
                        received: 1,
                    },
                    $E::InvalidConfig,
                    $E::DeviceId { found: 3 },
                    $E::NotResponding { found: 0xFF },
                    $E::ReadBack {
                        register: 1,
                        written: 1,
                        read: 0,
                    },
                    $E::UnexpectedReset,
                    $($own),*
                ]
            };
        }
        use ads1262::Error as A;
        let ads: [A<(), ()>; 11] = every_error!(A: A::Checksum {
            expected: 0,
            received: 1,
        }, A::StaleData);
        for e in ads {
            assert_ne!(flags_for(&e).0, 0, "{e:?}");
        }
        use ad7124::Error as R;
        let rtd: [R<(), ()>; 10] = every_error!(R: R::AdcError(ad7124::ErrorFlags(0)));
        for e in rtd {
            assert_ne!(flags_for(&e).0, 0, "{e:?}");
        }
        let open = ad7124::ErrorFlags(1 << 11);
        assert_eq!(
            flags_for(&R::<(), ()>::AdcError(open)).0,
            ChannelFlags::OPEN_CIRCUIT
        );
    }

    #[test]
    fn a_stale_rtd_reading_is_not_joined_to_a_pair() {
        let mut a = SampleAssembler::new(1_000_000);
        let pair = AdsReading {
            accel: 5,
            accel_flags: ChannelFlags::default(),
            tilt: 6,
            tilt_flags: ChannelFlags::default(),
            time_us: 5_000_000,
            seq: 0,
            lost: LossFlags(0),
        };
        assert!(a.assemble(&pair).rtd_flags.has(ChannelFlags::DRDY_TIMEOUT));
        a.rtd(RtdReading {
            code: 77,
            flags: ChannelFlags::default(),
            time_us: 4_500_000,
        });
        let raw = a.assemble(&pair);
        assert_eq!(
            (raw.rtd, raw.rtd_flags.0, raw.accel, raw.tilt),
            (77, 0, 5, 6)
        );
        // A fault between two pairs is carried by the next pair even if a good reading followed.
        a.rtd(RtdReading {
            code: 0,
            flags: ChannelFlags(ChannelFlags::CHECKSUM),
            time_us: 4_600_000,
        });
        a.rtd(RtdReading {
            code: 78,
            flags: ChannelFlags::default(),
            time_us: 4_700_000,
        });
        assert!(a.assemble(&pair).rtd_flags.has(ChannelFlags::CHECKSUM));
        assert_eq!(a.assemble(&pair).rtd, 78);
        a.rtd(RtdReading {
            code: 77,
            flags: ChannelFlags::default(),
            time_us: 3_000_000,
        });
        assert!(a.assemble(&pair).rtd_flags.has(ChannelFlags::DRDY_TIMEOUT));
    }
}
