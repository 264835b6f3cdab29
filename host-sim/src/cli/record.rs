//! `accomp record`: record the board's sample stream into a log (the recorder is
//! [`crate::device::record`]).

use std::io::{IsTerminal as _, Write as _};
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
    /// The recorder's options (all but the port, from `--target`, and the live rows, `--tui`).
    #[command(flatten)]
    pub options: Options,
    /// Full-screen live view: output, temperature and tilt over the last hours, the Allan
    /// deviation so far, the counters, the events (q or Ctrl-C stops the record).
    #[arg(long)]
    pub tui: bool,
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
        live_rows: tui,
        ..args.options.clone()
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
