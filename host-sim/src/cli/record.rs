//! `accomp record`: record the board's sample stream into a log (the recorder is
//! [`crate::device::record`]).

use std::io::{IsTerminal as _, Write as _};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use anyhow::Context as _;

use super::record_tui::LiveView;
use crate::device::record::{self, Link, Options, Progress};
use crate::device::Target;
use ratatui::crossterm;

/// Record the board's samples into a log (flushed to disk every second).
#[derive(clap::Args, Debug)]
pub struct RecordArgs {
    /// serial:<port>
    #[arg(long)]
    pub target: Target,
    /// Output file (.csv), or directory with --rotate daily / daily-gz.
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
    /// Stop after this many samples written.
    #[arg(long, conflicts_with = "duration")]
    pub samples: Option<u64>,
    /// Stop after this much board time: 6w, 3d, 12h, 30m, 90s.
    #[arg(long, value_parser = record::parse_duration)]
    pub duration: Option<f64>,
    /// Continue an existing record (the header must name the same board and table).
    #[arg(long)]
    pub append: bool,
    /// Write over an existing record, or append to one of another board or table.
    #[arg(long)]
    pub force: bool,
    /// `daily`: one file per UTC day in the output directory; `daily-gz`: the same, and every day
    /// older than yesterday gzip-compressed (`YYYY-MM-DD.csv.gz`, a third of the size).
    #[arg(long, value_enum)]
    pub rotate: Option<Rotate>,
    /// Where the test runs (written into the header).
    #[arg(long)]
    pub site: Option<String>,
    /// A note for the header.
    #[arg(long)]
    pub note: Option<String>,
    /// Set the ADS1262 data rate first (samples/s; frames come at rate / 8).
    #[arg(long)]
    pub rate: Option<u32>,
    /// Full-screen live view: output, temperature and tilt over the last hours, the Allan
    /// deviation so far, the counters, the events (q or Ctrl-C stops the record).
    #[arg(long)]
    pub tui: bool,
}

/// `--rotate` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Rotate {
    /// One file per UTC day.
    Daily,
    /// One file per UTC day, the days before yesterday gzip-compressed.
    DailyGz,
}

fn pc_clock() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

fn status_text(p: &Progress) -> String {
    format!(
        "{} samples, {:.0} s recorded, {} lost, {} events, device dropped {}, link {}, drift \
         {:.2} ppm{}",
        p.samples,
        p.record_s,
        p.lost,
        p.events,
        p.frames_dropped,
        match p.link {
            Link::Up => "up",
            Link::Down => "DOWN (reopening)",
        },
        p.drift_ppm,
        p.to_go
            .as_ref()
            .map_or_else(String::new, |t| format!(", {t}"))
    )
}

/// Runs `accomp record`.
pub fn run(args: &RecordArgs) -> anyhow::Result<()> {
    let Target::Serial(port) = &args.target else {
        anyhow::bail!("record needs --target serial:<port> (a board or `accomp board-sim`)");
    };
    let tui = args.tui && std::io::stdout().is_terminal();
    if args.tui && !tui {
        eprintln!("record: --tui needs a terminal on stdout; showing the status line instead");
    }
    let opts = Options {
        port: port.clone(),
        output: args.output.clone(),
        samples: args.samples,
        duration_s: args.duration,
        append: args.append,
        force: args.force,
        daily: args.rotate.is_some(),
        compress_days: args.rotate == Some(Rotate::DailyGz),
        site: args.site.clone(),
        note: args.note.clone(),
        rate_hz: args.rate,
        live_rows: tui,
    };
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        ctrlc::set_handler(move || stop.store(true, Ordering::Relaxed))
            .context("cannot install the Ctrl-C handler")?;
    }
    if tui {
        return run_tui(&opts, &stop);
    }
    let tty = std::io::stderr().is_terminal();
    let mut last_line = Instant::now();
    let mut show = |p: &Progress| {
        if tty {
            eprint!("\r\x1b[2K{}", status_text(p));
            let _ = std::io::stderr().flush();
        } else if last_line.elapsed() >= Duration::from_secs(60) {
            last_line = Instant::now();
            eprintln!("record: {}", status_text(p));
        }
    };
    let summary = record::record(&opts, &pc_clock, &stop, &mut show)?;
    if tty {
        eprintln!();
    }
    print_summary(&summary);
    Ok(())
}

fn print_summary(summary: &record::Summary) {
    eprintln!(
        "record: {} samples written to {} ({}), {} lost, {} events, {} reconnects, {} resets",
        summary.samples,
        summary.path.display(),
        summary.reason,
        summary.lost,
        summary.events,
        summary.reconnects,
        summary.resets
    );
}

/// Puts the terminal back (raw mode off, main screen) however the record ends.
struct TerminalGuard;

impl Drop for TerminalGuard {
    fn drop(&mut self) {
        let _ = crossterm::terminal::disable_raw_mode();
        let _ = crossterm::execute!(
            std::io::stdout(),
            crossterm::terminal::LeaveAlternateScreen,
            crossterm::cursor::Show
        );
    }
}

/// The record with the full-screen view: drawn at most 5 times a second, the Allan deviation
/// recomputed every 2 s; `q` or Ctrl-C (a key in raw mode, not a signal) sets `stop`, so the
/// record ends as without the view (stream stopped, closing event, file synced).
fn run_tui(opts: &Options, stop: &Arc<AtomicBool>) -> anyhow::Result<()> {
    use crossterm::event::{self, Event, KeyCode, KeyEventKind, KeyModifiers};
    crossterm::terminal::enable_raw_mode().context("--tui: cannot set the terminal raw")?;
    let guard = TerminalGuard;
    crossterm::execute!(std::io::stdout(), crossterm::terminal::EnterAlternateScreen)?;
    let mut terminal =
        ratatui::Terminal::new(ratatui::backend::CrosstermBackend::new(std::io::stdout()))?;
    let mut view = LiveView::new();
    let mut last_allan: Option<Instant> = None;
    let mut draw_error: Option<std::io::Error> = None;
    let mut show = |p: &Progress| {
        view.update(p);
        if last_allan.is_none_or(|t| t.elapsed() >= Duration::from_secs(2)) {
            last_allan = Some(Instant::now());
            view.refresh_allan();
        }
        if let Err(e) = terminal.draw(|f| view.draw(f)) {
            // The record goes on; the error is said when the screen is back.
            draw_error.get_or_insert(e);
        }
        while event::poll(Duration::ZERO).unwrap_or(false) {
            if let Ok(Event::Key(k)) = event::read() {
                let ctrl_c =
                    k.code == KeyCode::Char('c') && k.modifiers.contains(KeyModifiers::CONTROL);
                if k.kind == KeyEventKind::Press && (ctrl_c || k.code == KeyCode::Char('q')) {
                    stop.store(true, Ordering::Relaxed);
                }
            }
        }
    };
    let result = record::record(opts, &pc_clock, stop, &mut show);
    drop(terminal);
    drop(guard);
    if let Some(e) = draw_error {
        eprintln!("record: the live view could not be drawn: {e}");
    }
    print_summary(&result?);
    Ok(())
}
