//! `accomp record`: a weeks-long stability record from the board's sample stream.
//!
//! The recorder opens the serial port, reads the device's info and active table (for the
//! header), starts the stream and writes every frame as a row ([`file`]) with a record time from
//! the board-clock model ([`clock`]). Nothing is lost silently: a seq gap, a change of the
//! frame's status bits, a rise of a device counter, line noise, a lost link, a reconnection, a
//! board reset and the clock's drift and steps are each written as a `# event:` line where they
//! happened. When the port disappears or stops answering the recorder keeps reopening the same
//! path; a board that comes back after a reset is recognised (READY, seq or uptime restarting)
//! and its clock anchored again.

pub mod clock;
pub mod file;

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use accomp::pipeline::{Frame, LossFlags, Status};
use accomp::protocol::{DeviceInfo, DeviceMessage, Request, Response};
use accomp::table::CalibrationTable;

use crate::samples_csv::status_names;
use crate::transport::SerialTransport;
use crate::{Client, ClientError, DeviceError};
use accomp_log::time::Utc;
use clock::{ClockEvent, ClockModel, Last};
use file::{Layout, RecordFile, RecordFileError};

/// What to record and where. With the `clap` feature these are also the flags of
/// `accomp record` (the doc comments are their help), except `port` (the CLI's `--target
/// serial:<port>`) and `live_rows` (its `--tui`).
#[derive(Debug, Clone)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct Options {
    /// Serial port path.
    #[cfg_attr(feature = "clap", arg(skip))]
    pub port: String,
    /// Output file (.csv), or directory with --rotate daily / daily-gz.
    #[cfg_attr(feature = "clap", arg(short = 'o', long = "output"))]
    pub output: PathBuf,
    /// Stop after this many samples written.
    #[cfg_attr(feature = "clap", arg(long, conflicts_with = "duration_s"))]
    pub samples: Option<u64>,
    /// Stop after this much board time: 6w, 3d, 12h, 30m, 90s.
    #[cfg_attr(
        feature = "clap",
        arg(long = "duration", value_name = "DURATION", value_parser = parse_duration)
    )]
    pub duration_s: Option<f64>,
    /// Continue an existing record (the header must name the same board and table).
    #[cfg_attr(feature = "clap", arg(long))]
    pub append: bool,
    /// Write over an existing record, or append to one of another board or table.
    #[cfg_attr(feature = "clap", arg(long))]
    pub force: bool,
    /// `daily`: one file per UTC day in the output directory; `daily-gz`: the same, and every day
    /// older than yesterday gzip-compressed (`YYYY-MM-DD.csv.gz`, a third of the size).
    #[cfg_attr(feature = "clap", arg(long, value_enum))]
    pub rotate: Option<Rotate>,
    /// Where the test runs (written into the header).
    #[cfg_attr(feature = "clap", arg(long))]
    pub site: Option<String>,
    /// A note for the header.
    #[cfg_attr(feature = "clap", arg(long))]
    pub note: Option<String>,
    /// Set the ADS1262 data rate first (samples/s; frames come at rate / 8).
    #[cfg_attr(feature = "clap", arg(long = "rate", value_name = "RATE"))]
    pub rate_hz: Option<u32>,
    /// Hand the rows to the progress callback ([`Progress::rows`]) for a live view; off, no
    /// row is kept (the recorder's memory does not depend on the frame rate).
    #[cfg_attr(feature = "clap", arg(skip))]
    pub live_rows: bool,
}

/// How a record is split into files (`--rotate`); without it, one file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum Rotate {
    /// One file per UTC day.
    Daily,
    /// One file per UTC day, the days before yesterday gzip-compressed.
    DailyGz,
}

/// State of the link, for the status line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Link {
    /// Streaming.
    Up,
    /// Port gone or silent: reopening.
    Down,
}

/// Progress for the status line.
#[derive(Debug, Clone, PartialEq)]
pub struct Progress {
    /// Rows written by this run.
    pub samples: u64,
    /// Record time of the last row, s.
    pub record_s: f64,
    /// Frames lost (seq gaps) so far.
    pub lost: u64,
    /// Event lines written.
    pub events: u64,
    /// The device's dropped-frame counter (last read).
    pub frames_dropped: u32,
    /// Link state.
    pub link: Link,
    /// Fitted drift of the board clock, ppm.
    pub drift_ppm: f64,
    /// Rows still to write, or record seconds still to go, when a stop is set.
    pub to_go: Option<String>,
    /// The device's counters as last read, by name (empty before the first read).
    pub counters: Vec<(&'static str, u64)>,
    /// With [`Options::live_rows`]: rows written since the previous call, with their record
    /// time (s), for a live view;
    /// at most [`LIVE_ROWS_MAX`] (the oldest beyond are not kept, `live_rows_skipped` counts them).
    pub rows: Vec<(f64, Frame)>,
    /// Rows not kept in `rows` since the previous call (more than [`LIVE_ROWS_MAX`] came).
    pub live_rows_skipped: u64,
    /// Event lines written since the previous call: (Unix s, kind, details).
    pub new_events: Vec<(f64, String, String)>,
}

/// The most rows one [`Progress`] carries (bounds the recorder's memory if nobody drains it).
pub const LIVE_ROWS_MAX: usize = 65_536;

/// How the record ended.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// Rows written by this run.
    pub samples: u64,
    /// Frames lost (seq gaps).
    pub lost: u64,
    /// Event lines written.
    pub events: u64,
    /// Reconnections.
    pub reconnects: u64,
    /// Board resets seen.
    pub resets: u64,
    /// Why it stopped.
    pub reason: String,
    /// The file written last.
    pub path: PathBuf,
}

/// Every counter of Info, by name (the recorder writes an event for any rise).
pub fn counter_values(i: &DeviceInfo) -> Vec<(&'static str, u64)> {
    let l = &i.losses;
    vec![
        ("frames_dropped", u64::from(i.frames_dropped)),
        ("conversions_lost", u64::from(l.conversions_lost)),
        ("queue_full", u64::from(l.queue_full)),
        ("uart_rx_overrun", u64::from(l.uart_rx_overrun)),
        ("uart_framing_noise", u64::from(l.uart_framing_noise)),
        ("tx_frames_dropped", u64::from(l.tx_frames_dropped)),
        ("erase_stalls", u64::from(l.erase_stalls)),
        ("erase_stall_us", l.erase_stall_us),
        ("watchdog_resets", u64::from(l.watchdog_resets)),
        ("brownout_resets", u64::from(l.brownout_resets)),
    ]
}

/// How often the device's counters are read while streaming.
const INFO_INTERVAL: Duration = Duration::from_secs(10);
/// Silence after which the board is pinged.
const SILENCE: Duration = Duration::from_secs(3);
/// Pause between attempts to reopen the port.
const REOPEN_PAUSE: Duration = Duration::from_millis(300);

/// The device as the recorder found it.
struct Device {
    client: Client,
    info: DeviceInfo,
    table: Option<CalibrationTable>,
}

fn connect(port: &str, rate_hz: Option<u32>) -> Result<Device, ClientError> {
    let mut t = SerialTransport::open(port, 115_200)?;
    // Whatever the line held from before (a previous run, an unplugged stretch) is old.
    t.clear_input();
    // Read by a thread of its own: a stalled write or sync of the record must not stop the
    // port from being read (the line would lose what overflows the kernel's buffer).
    let mut client = Client::new(Box::new(t.drained()?));
    client.timeout = Duration::from_secs(2);
    client.ping()?;
    // Stop first so the table read-back is not interleaved with samples.
    client.call(Request::StreamStop)?;
    let table = match client.read_table() {
        Ok(bytes) => CalibrationTable::decode(&bytes).ok(),
        Err(ClientError::Device(_)) => None,
        Err(e) => return Err(e),
    };
    if let Some(hz) = rate_hz {
        client.call(Request::SetRate { hz })?;
    }
    let info = client.info()?;
    match client.call(Request::StreamStart)? {
        Response::Ok => {}
        other => return Err(ClientError::Unexpected(format!("{other:?}"))),
    }
    Ok(Device {
        client,
        info,
        table,
    })
}

/// The header's metadata for a device.
fn metadata(opts: &Options, dev: &Device, start_unix_s: f64) -> Vec<(String, String)> {
    let i = &dev.info;
    let mut m: Vec<(String, String)> = vec![
        ("start_utc".into(), Utc(start_unix_s).to_string()),
        (
            "recorder".into(),
            format!("accomp record {}", env!("CARGO_PKG_VERSION")),
        ),
        ("port".into(), opts.port.clone()),
        ("site".into(), opts.site.clone().unwrap_or_default()),
        ("note".into(), opts.note.clone().unwrap_or_default()),
        ("device_board".into(), format!("{:?}", i.board)),
        ("device_firmware".into(), i.firmware.to_string()),
        ("device_protocol".into(), i.protocol.to_string()),
        ("device_rate_hz".into(), i.rate_hz.to_string()),
        (
            "device_reset_cause".into(),
            format!("{:#04x}", i.boot.reset_cause),
        ),
        (
            "calibration_id".into(),
            i.active_table
                .map_or_else(|| "none".into(), |id| format!("{id:#010x}")),
        ),
    ];
    if let Some(t) = &dev.table {
        m.push((
            "calibration_serial".into(),
            t.serial_str().unwrap_or("").to_string(),
        ));
        m.push((
            "calibration_date".into(),
            format!("{:04}-{:02}-{:02}", t.date.year, t.date.month, t.date.day),
        ));
        m.push(("input_g".into(), t.orientation.nominal_input.0.to_string()));
        m.push(("reference_c".into(), t.thermal.reference.0.to_string()));
        if let Ok((k, _)) = t.thermal.coefficients_at(t.thermal.reference) {
            m.push((
                "scale_factor_v_per_g".into(),
                format!("{:.9}", k.scale_factor_v_per_g),
            ));
        }
    } else {
        m.push(("calibration_serial".into(), String::new()));
    }
    m.push(("tilt_axis".into(), "input".into()));
    m.push((
        "time_base".into(),
        "time_s: the board's clock since start_utc, corrected for its drift against the PC \
         (clock event lines); unix_time_s = start_utc + time_s"
            .into(),
    ));
    m
}

/// The recorder's state between frames.
struct Recorder<'a> {
    opts: &'a Options,
    pc: &'a dyn Fn() -> f64,
    file: Option<RecordFile>,
    /// Events before the header could be written (no frame yet).
    queued: Vec<(f64, String, String)>,
    start_unix_s: Option<f64>,
    clock: ClockModel,
    last_seq: Option<u32>,
    /// Info's boot id of the boot the last frames came from (None: not known, as when a
    /// recording is appended to: then only the board's uptime tells a new boot).
    last_boot_id: Option<u32>,
    last_status: Option<Status>,
    frames_dropped: Option<u32>,
    /// The device's counters as last read (None: not yet on this connection).
    counters: Option<Vec<(&'static str, u64)>>,
    bad_frames: u64,
    first_record_s: Option<f64>,
    summary: Summary,
    meta: Vec<(String, String)>,
    existing: Option<file::Existing>,
    /// Rows and events since the last progress call (for a live view).
    live_rows: Vec<(f64, Frame)>,
    live_rows_skipped: u64,
    live_events: Vec<(f64, String, String)>,
}

impl Recorder<'_> {
    fn event(&mut self, unix_s: f64, kind: &str, details: String) -> Result<(), RecordFileError> {
        self.summary.events += 1;
        if self.live_events.len() < LIVE_ROWS_MAX {
            self.live_events
                .push((unix_s, kind.to_owned(), details.clone()));
        }
        match &mut self.file {
            Some(f) => f.event(unix_s, kind, &details),
            None => {
                self.queued.push((unix_s, kind.to_owned(), details));
                Ok(())
            }
        }
    }

    fn clock_events(&mut self, evs: Vec<ClockEvent>, unix_s: f64) -> Result<(), RecordFileError> {
        for e in evs {
            let (kind, d) = match e {
                ClockEvent::Drift { ppm, blocks } => (
                    "clock_drift",
                    format!("drift_ppm={ppm:.3} fitted over {blocks} minimum-delay blocks"),
                ),
                ClockEvent::PcStep { step_s } => (
                    "pc_clock_step",
                    format!("step_s={step_s:.3} (not followed: time_s keeps the board clock)"),
                ),
                ClockEvent::NotACrystal { rate } => (
                    "clock_rate",
                    format!(
                        "board clock runs {rate:.1}x the PC's (a virtual board at --speed?): \
                         no drift applied, time_s is the board's own clock"
                    ),
                ),
            };
            self.event(unix_s, kind, d)?;
        }
        Ok(())
    }

    /// Opens the file at the first frame (its UTC is the record's start).
    fn open_file(&mut self, dev: &Device, pc_s: f64) -> Result<(), DeviceError> {
        let layout = if self.opts.rotate.is_some() {
            Layout::Daily(self.opts.output.clone())
        } else {
            Layout::File(self.opts.output.clone())
        };
        let file = match self.existing.take() {
            Some(e) => {
                let path = if self.opts.rotate.is_some() {
                    file::newest_daily(&self.opts.output).ok_or(DeviceError::NoDailyFile)?
                } else {
                    self.opts.output.clone()
                };
                let f = RecordFile::append(layout, path, e.meta.clone(), e.start_unix_s)?;
                self.start_unix_s = Some(e.start_unix_s);
                f
            }
            None => {
                let meta = metadata(self.opts, dev, pc_s);
                self.meta = meta.clone();
                self.start_unix_s = Some(pc_s);
                RecordFile::create(layout, meta, pc_s, self.opts.force)?
            }
        };
        let mut file = file;
        file.compress_finished_days(self.opts.rotate == Some(Rotate::DailyGz));
        self.file = Some(file);
        for (t, k, d) in std::mem::take(&mut self.queued) {
            if let Some(f) = &mut self.file {
                f.event(t, &k, &d)?;
            }
        }
        Ok(())
    }

    fn frame(&mut self, dev: &Device, frame: &Frame, arrived_now: bool) -> Result<(), DeviceError> {
        let pc = (self.pc)();
        if self.file.is_none() {
            self.open_file(dev, pc)?;
        }
        let start = self.start_unix_s.unwrap_or(pc);
        if let Some(last) = self.last_seq {
            let expected = last.wrapping_add(1);
            if frame.seq != expected {
                let lost = frame.seq.wrapping_sub(expected);
                if frame.seq > last && lost < u32::MAX / 2 {
                    self.summary.lost += u64::from(lost);
                    let t = start + self.clock.last().map_or(0.0, |l| l.record_s);
                    let why: Vec<&str> = LossFlags::NAMES
                        .iter()
                        .filter(|(bit, _)| frame.lost.has(*bit))
                        .map(|(_, n)| *n)
                        .collect();
                    let why = if why.is_empty() {
                        "not flagged by the board: lost on the link or in the PC".to_string()
                    } else {
                        format!("board: {}", why.join("|"))
                    };
                    self.event(
                        t,
                        "seq_gap",
                        format!(
                            "lost={lost} seq {}..={} missing ({why})",
                            expected,
                            frame.seq - 1
                        ),
                    )?;
                } else {
                    // seq went back without a READY: the board restarted unseen.
                    self.summary.resets += 1;
                    self.clock.new_boot();
                    self.event(
                        pc,
                        accomp_log::event_kind::BOARD_RESET,
                        format!(
                            "seq restarted at {} after {last} (no READY seen)",
                            frame.seq
                        ),
                    )?;
                }
            }
        }
        let mut evs = Vec::new();
        let t = self
            .clock
            .record_time(frame.time_us, pc, start, arrived_now, &mut evs);
        self.clock_events(evs, start + t)?;
        if self.last_status != Some(frame.status) {
            if let Some(old) = self.last_status {
                self.event(
                    start + t,
                    "status",
                    format!("{} -> {}", status_names(old), status_names(frame.status)),
                )?;
            }
            self.last_status = Some(frame.status);
        }
        self.last_seq = Some(frame.seq);
        if let Some(f) = &mut self.file {
            f.row(t, frame)?;
        }
        if self.opts.live_rows {
            if self.live_rows.len() < LIVE_ROWS_MAX {
                self.live_rows.push((t, *frame));
            } else {
                self.live_rows_skipped += 1;
            }
        }
        self.summary.samples += 1;
        self.first_record_s.get_or_insert(t);
        Ok(())
    }

    /// Device counters: any rise is an event.
    fn counters(&mut self, info: &DeviceInfo) -> Result<(), RecordFileError> {
        let pc = (self.pc)();
        let now = counter_values(info);
        if let Some(old) = self.counters.take() {
            for ((name, was), (_, is)) in old.iter().zip(&now) {
                if is > was {
                    let d = is - was;
                    self.event(pc, "counter", format!("{name} +{d} (total {is})"))?;
                }
            }
        }
        self.frames_dropped = Some(info.frames_dropped);
        self.counters = Some(now);
        Ok(())
    }

    fn line_noise(&mut self, client: &Client) -> Result<(), RecordFileError> {
        if client.bad_frames > self.bad_frames {
            let n = client.bad_frames - self.bad_frames;
            self.bad_frames = client.bad_frames;
            let pc = (self.pc)();
            self.event(
                pc,
                "line_noise",
                format!("{n} frame(s) from the board refused (CRC/COBS), nothing written for them"),
            )?;
        }
        Ok(())
    }

    fn progress(&mut self, link: Link) -> Progress {
        let record_s = self.clock.last().map_or(0.0, |l| l.record_s);
        let to_go = match (self.opts.samples, self.opts.duration_s) {
            (Some(n), _) => Some(format!(
                "{} samples to go",
                n.saturating_sub(self.summary.samples)
            )),
            (None, Some(d)) => Some(format!(
                "{:.0} s to go",
                (d - (record_s - self.first_record_s.unwrap_or(record_s))).max(0.0)
            )),
            _ => None,
        };
        Progress {
            samples: self.summary.samples,
            record_s,
            lost: self.summary.lost,
            events: self.summary.events,
            frames_dropped: self.frames_dropped.unwrap_or(0),
            link,
            drift_ppm: self.clock.drift_ppm(),
            to_go,
            counters: self.counters.clone().unwrap_or_default(),
            rows: std::mem::take(&mut self.live_rows),
            live_rows_skipped: std::mem::take(&mut self.live_rows_skipped),
            new_events: std::mem::take(&mut self.live_events),
        }
    }

    fn done(&self) -> bool {
        if self.opts.samples.is_some_and(|n| self.summary.samples >= n) {
            return true;
        }
        match (self.opts.duration_s, self.first_record_s, self.clock.last()) {
            (Some(d), Some(first), Some(l)) => l.record_s - first >= d,
            _ => false,
        }
    }
}

/// Prepares the output: refuses to overwrite without `force`, checks and trims a record to
/// append to.
fn prepare_output(opts: &Options) -> Result<Option<file::Existing>, DeviceError> {
    let target = if opts.rotate.is_some() {
        file::newest_daily(&opts.output)
    } else {
        opts.output.exists().then(|| opts.output.clone())
    };
    match (target, opts.append) {
        (Some(p), true) => Ok(Some(file::open_existing(&p)?)),
        (None, true) => Err(DeviceError::NothingToAppend {
            output: opts.output.clone(),
        }),
        (Some(p), false) if !opts.force => Err(RecordFileError::Exists(p).into()),
        _ => Ok(None),
    }
}

/// Records until the stop condition, `stop` (Ctrl-C) or an error of the file. `pc` is the PC's
/// clock in Unix seconds (tests step it). `progress` is called a few times a second.
pub fn record(
    opts: &Options,
    pc: &dyn Fn() -> f64,
    stop: &AtomicBool,
    progress: &mut dyn FnMut(&Progress),
) -> Result<Summary, DeviceError> {
    let existing = prepare_output(opts)?;
    let last = existing.as_ref().and_then(|e| {
        e.last.map(|(t, _, b)| Last {
            board_us: b,
            record_s: t,
            pc_s: None,
        })
    });
    let mut r = Recorder {
        opts,
        pc,
        file: None,
        queued: Vec::new(),
        start_unix_s: existing.as_ref().map(|e| e.start_unix_s),
        clock: ClockModel::new(last),
        last_seq: existing.as_ref().and_then(|e| e.last.map(|l| l.1)),
        last_boot_id: None,
        last_status: None,
        frames_dropped: None,
        counters: None,
        bad_frames: 0,
        first_record_s: None,
        summary: Summary {
            samples: 0,
            lost: 0,
            events: 0,
            reconnects: 0,
            resets: 0,
            reason: String::new(),
            path: opts.output.clone(),
        },
        meta: existing
            .as_ref()
            .map(|e| e.meta.clone())
            .unwrap_or_default(),
        existing,
        live_rows: Vec::new(),
        live_rows_skipped: 0,
        live_events: Vec::new(),
    };
    if let Some(e) = &r.existing {
        if e.trimmed > 0 {
            let t = pc();
            r.event(
                t,
                "trimmed",
                format!(
                    "{} bytes of a cut last line removed (the previous run was killed mid-line)",
                    e.trimmed
                ),
            )?;
        }
    }
    let mut dev: Option<Device> = None;
    let mut down_since: Option<Instant> = None;
    let mut last_msg = Instant::now();
    let mut last_info = Instant::now();
    let mut last_progress = Instant::now();
    let mut first_connect = true;
    let reason = loop {
        if stop.load(Ordering::Relaxed) {
            break "interrupted".to_string();
        }
        if r.done() {
            break if opts.samples.is_some() {
                "samples"
            } else {
                "duration"
            }
            .to_string();
        }
        if last_progress.elapsed() >= Duration::from_millis(200) {
            last_progress = Instant::now();
            let link = if dev.is_some() { Link::Up } else { Link::Down };
            progress(&r.progress(link));
        }
        let Some(d) = dev.as_mut() else {
            match connect(&opts.port, opts.rate_hz) {
                Ok(newdev) => {
                    let t = pc();
                    let uptime_us = newdev.info.uptime_us;
                    if first_connect {
                        if let Some(e) = &r.existing {
                            let now_meta = metadata(opts, &newdev, e.start_unix_s);
                            if let Some((key, old, new)) =
                                file::identity_difference(&e.meta, &now_meta)
                            {
                                if !opts.force {
                                    return Err(file::RecordFileError::HeaderMismatch {
                                        path: opts.output.clone(),
                                        key,
                                        old,
                                        new,
                                    }
                                    .into());
                                }
                                r.event(
                                    t,
                                    "header_mismatch",
                                    format!("{key}: {old:?} in the header, {new:?} now (--force)"),
                                )?;
                            }
                            r.event(t, "append", format!("recording continues on {}", opts.port))?;
                        } else {
                            r.event(t, "start", format!("recording from {}", opts.port))?;
                        }
                    } else {
                        let secs = down_since.map_or(0.0, |s| s.elapsed().as_secs_f64());
                        r.summary.reconnects += 1;
                        r.event(t, "reconnected", format!("after {secs:.1} s"))?;
                    }
                    // Same boot when the boot id is the last frames' and the board's clock is
                    // past the last frame's. The id decides: a new boot's clock may well have
                    // passed the old boot's last time stamp by the time the link is back.
                    let boot_id = newdev.info.boot.boot_id;
                    let same_boot = r.clock.last().is_some_and(|l| {
                        r.last_seq.is_some()
                            && uptime_us >= l.board_us
                            && r.last_boot_id.is_none_or(|id| id == boot_id)
                    });
                    r.last_boot_id = Some(boot_id);
                    if same_boot {
                        r.clock.continue_boot();
                    } else if r.clock.last().is_some() {
                        r.summary.resets += 1;
                        r.clock.new_boot();
                        r.last_seq = None;
                        r.event(
                            t,
                            accomp_log::event_kind::BOARD_RESET,
                            format!(
                                "uptime {:.3} s, reset cause {:#04x}, boot id {boot_id:#010x}: \
                                 a new boot",
                                newdev.info.uptime_us as f64 / 1e6,
                                newdev.info.boot.reset_cause
                            ),
                        )?;
                    }
                    if !first_connect {
                        if let Some(old) = r.meta.iter().find(|(k, _)| k == "calibration_id") {
                            let now = newdev
                                .info
                                .active_table
                                .map_or_else(|| "none".into(), |id| format!("{id:#010x}"));
                            if old.1 != now {
                                let old = old.1.clone();
                                r.event(
                                    t,
                                    accomp_log::event_kind::TABLE_CHANGED,
                                    format!("{old} -> {now}"),
                                )?;
                            }
                        }
                    }
                    r.counters = None;
                    r.counters(&newdev.info)?;
                    first_connect = false;
                    down_since = None;
                    last_msg = Instant::now();
                    last_info = Instant::now();
                    r.bad_frames = newdev.client.bad_frames;
                    let mut newdev = newdev;
                    // Frames that streamed in during the handshake (a stream left running by
                    // an earlier recorder): recorded, but their arrival times are not clock
                    // information.
                    for m in newdev.client.take_inbox() {
                        if r.done() {
                            break;
                        }
                        if let DeviceMessage::Sample { id: 0, frame } = m {
                            r.frame(&newdev, &frame, false)?;
                        }
                    }
                    dev = Some(newdev);
                }
                Err(e) => {
                    if first_connect && down_since.is_none() {
                        // Nothing recorded yet: a wrong port is an error, not a wait.
                        return Err(DeviceError::Port {
                            port: opts.port.clone(),
                            cause: e,
                        });
                    }
                    if let Some(f) = &mut r.file {
                        f.sync_if_due()?;
                    }
                    std::thread::sleep(REOPEN_PAUSE);
                }
            }
            continue;
        };
        let msg = d.client.recv(Duration::from_millis(100));
        let lost_link = match msg {
            Ok(DeviceMessage::Sample { id: 0, frame }) => {
                last_msg = Instant::now();
                let dref = &*d;
                r.frame(dref, &frame, true)?;
                None
            }
            Ok(DeviceMessage::Ready { .. }) => {
                last_msg = Instant::now();
                let t = pc();
                r.summary.resets += 1;
                r.clock.new_boot();
                r.last_seq = None;
                // The new boot streams nothing until asked again.
                let restart = (|| -> Result<DeviceInfo, ClientError> {
                    if let Some(hz) = opts.rate_hz {
                        d.client.call(Request::SetRate { hz })?;
                    }
                    d.client.call(Request::StreamStart)?;
                    d.client.info()
                })();
                match restart {
                    Ok(info) => {
                        r.last_boot_id = Some(info.boot.boot_id);
                        r.event(
                            t,
                            accomp_log::event_kind::BOARD_RESET,
                            format!(
                                "READY: a new boot, reset cause {:#04x}, boot id {:#010x}; \
                                 stream restarted",
                                info.boot.reset_cause, info.boot.boot_id
                            ),
                        )?;
                        r.counters = None;
                        r.counters(&info)?;
                        None
                    }
                    Err(e) => Some(format!("after the board's reset: {e}")),
                }
            }
            Ok(DeviceMessage::Error { id, error }) => {
                let t = pc();
                r.event(
                    t,
                    "device_error",
                    format!("id {id} code {} detail {}", error.code, error.detail),
                )?;
                None
            }
            Ok(_) => None,
            Err(ClientError::Timeout(..)) => {
                if last_msg.elapsed() >= SILENCE {
                    match d.client.ping() {
                        Ok(()) => {
                            last_msg = Instant::now();
                            None
                        }
                        Err(e) => Some(format!(
                            "no frame for {:.0} s and no answer to a ping ({e})",
                            SILENCE.as_secs_f64()
                        )),
                    }
                } else {
                    None
                }
            }
            Err(e) => Some(e.to_string()),
        };
        let lost_link = match lost_link {
            Some(why) => Some(why),
            None if last_info.elapsed() >= INFO_INTERVAL => {
                last_info = Instant::now();
                match d.client.info() {
                    Ok(info) => {
                        r.counters(&info)?;
                        None
                    }
                    Err(e) => Some(format!("info: {e}")),
                }
            }
            None => None,
        };
        if let Some(d) = &dev {
            r.line_noise(&d.client)?;
        }
        if let Some(why) = lost_link {
            let t = pc();
            r.event(t, "link_lost", format!("{why}; reopening {}", opts.port))?;
            dev = None;
            down_since = Some(Instant::now());
        }
        if let Some(f) = &mut r.file {
            f.sync_if_due()?;
        }
    };
    if let Some(d) = &mut dev {
        let _ = d.client.call(Request::StreamStop);
    }
    let t = pc();
    // A day being compressed is finished before the record ends (no stale .tmp left).
    let compressed = r
        .file
        .as_mut()
        .map(|f| f.finish_compression())
        .unwrap_or_default();
    for (kind, details) in compressed {
        r.event(t, &kind, details)?;
    }
    r.summary.reason = reason.clone();
    let (n, lost) = (r.summary.samples, r.summary.lost);
    r.event(
        t,
        "stop",
        format!("{reason}: {n} samples written by this run, {lost} lost to seq gaps"),
    )?;
    if let Some(f) = &mut r.file {
        f.sync()?;
        r.summary.path = f.path().to_owned();
    }
    progress(&r.progress(if dev.is_some() { Link::Up } else { Link::Down }));
    Ok(r.summary)
}

/// `6w`, `3d`, `12h`, `30m`, `90s` or plain seconds.
pub fn parse_duration(s: &str) -> Result<f64, String> {
    let s = s.trim();
    let (num, unit) = match s.find(|c: char| c.is_ascii_alphabetic()) {
        Some(i) => s.split_at(i),
        None => (s, "s"),
    };
    let v: f64 = num
        .trim()
        .parse()
        .map_err(|_| format!("duration {s:?}: expected a number and w, d, h, m or s"))?;
    let k = match unit {
        "w" => 7.0 * 86_400.0,
        "d" => 86_400.0,
        "h" => 3600.0,
        "m" => 60.0,
        "s" => 1.0,
        _ => {
            return Err(format!(
                "duration {s:?}: unit {unit:?} is not w, d, h, m or s"
            ))
        }
    };
    if !(v.is_finite() && v > 0.0) {
        return Err(format!("duration {s:?} must be positive"));
    }
    Ok(v * k)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_take_weeks_days_hours_minutes_seconds() {
        assert_eq!(parse_duration("6w"), Ok(6.0 * 7.0 * 86_400.0));
        assert_eq!(parse_duration("1.5h"), Ok(5400.0));
        assert_eq!(parse_duration("90"), Ok(90.0));
        assert!(parse_duration("3y").is_err());
        assert!(parse_duration("-1d").is_err());
    }
}
