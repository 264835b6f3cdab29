//! `accomp board-sim`: the virtual front-end board on a pseudo-terminal (see
//! [`crate::device::board_sim`]), with faults on demand.

use std::io::{BufRead as _, Write as _};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::time::{Duration, Instant};

use anyhow::Context as _;

use crate::device::board_sim::flash;
use crate::device::board_sim::pty::{self, Pty};
use crate::device::board_sim::{Station, VirtualBoard};

/// Run the virtual board on a pseudo-terminal.
#[derive(clap::Args, Debug)]
pub struct BoardSimArgs {
    /// Scenario: a preset (paper-1g, paper-0g) or a scenario TOML file.
    pub scenario: String,
    /// The board's clock runs this many times faster than the wall clock.
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// Seed of the station's noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Make this path a symbolic link to the pseudo-terminal (`--target serial:PATH`).
    #[arg(long)]
    pub link: Option<PathBuf>,
    /// Directory of the board's flash image (default: `<link>.state`; without --link the flash
    /// lives in memory only).
    #[arg(long)]
    pub state: Option<PathBuf>,
    /// A fault at a time after start: KIND[=ARG]@SECONDS (wall clock), e.g. `reset@5`,
    /// `unplug=2@10`, `rtd-open=on@3`, `drdy-stall=off@8`, `garbage=100@4`,
    /// `erase-stall=3000@0`. The same commands (without @) are read from stdin, one a line.
    #[arg(long = "fault")]
    pub faults: Vec<String>,
}

/// A fault command.
#[derive(Debug, Clone, PartialEq)]
pub enum Fault {
    /// The cable is pulled for this long: the port disappears, the board runs on.
    Unplug(Duration),
    /// The board resets (reset pin): new boot, the tables stay in flash.
    Reset,
    /// RTD loop open or closed again.
    RtdOpen(bool),
    /// ADS1262 DRDY stops or comes back.
    DrdyStall(bool),
    /// This many bytes of noise on the line toward the PC.
    Garbage(usize),
    /// The next flash erase stalls the board this long.
    EraseStall(Duration),
}

impl std::str::FromStr for Fault {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let (kind, arg) = match s.trim().split_once('=') {
            Some((k, a)) => (k.trim(), Some(a.trim())),
            None => (s.trim(), None),
        };
        let on = |a: Option<&str>| match a {
            None | Some("on") => Ok(true),
            Some("off") => Ok(false),
            Some(x) => Err(format!("{kind}: `{x}` is neither on nor off")),
        };
        let num = |a: Option<&str>, default: f64| -> Result<f64, String> {
            a.map_or(Ok(default), |x| {
                x.parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite() && *v >= 0.0)
                    .ok_or_else(|| format!("{kind}: `{x}` is not a non-negative number"))
            })
        };
        Ok(match kind {
            "unplug" => Fault::Unplug(Duration::from_secs_f64(num(arg, 2.0)?)),
            "reset" => Fault::Reset,
            "rtd-open" => Fault::RtdOpen(on(arg)?),
            "drdy-stall" => Fault::DrdyStall(on(arg)?),
            "garbage" => Fault::Garbage(num(arg, 64.0)? as usize),
            "erase-stall" => Fault::EraseStall(Duration::from_millis(num(arg, 3000.0)? as u64)),
            _ => {
                return Err(format!(
                    "unknown fault `{kind}` (unplug[=s], reset, rtd-open[=on|off], \
                     drdy-stall[=on|off], garbage[=bytes], erase-stall[=ms])"
                ))
            }
        })
    }
}

/// `KIND[=ARG]@SECONDS`.
fn scheduled(s: &str) -> anyhow::Result<(Duration, Fault)> {
    let (f, at) = s
        .rsplit_once('@')
        .ok_or_else(|| anyhow::anyhow!("--fault {s:?}: expected KIND[=ARG]@SECONDS"))?;
    let at: f64 = at
        .parse()
        .ok()
        .filter(|v: &f64| v.is_finite() && *v >= 0.0)
        .ok_or_else(|| anyhow::anyhow!("--fault {s:?}: `{at}` is not a time in seconds"))?;
    Ok((
        Duration::from_secs_f64(at),
        f.parse().map_err(|e: String| anyhow::anyhow!(e))?,
    ))
}

/// The state directory: `--state`, else beside the link.
fn state_dir(args: &BoardSimArgs) -> Option<PathBuf> {
    args.state.clone().or_else(|| {
        args.link.as_ref().map(|l| {
            let mut s = l.as_os_str().to_owned();
            s.push(".state");
            PathBuf::from(s)
        })
    })
}

fn open_line(link: Option<&Path>) -> anyhow::Result<Pty> {
    let p = Pty::open()?;
    if let Some(l) = link {
        pty::link(&p.path, l).with_context(|| format!("link {}", l.display()))?;
    }
    Ok(p)
}

/// Reset cause bits (RCC_CSR, see `BootReport`).
const POWER_ON: u8 = accomp::protocol::BootReport::POR | accomp::protocol::BootReport::PIN;
const PIN_RESET: u8 = accomp::protocol::BootReport::PIN;

/// Runs `accomp board-sim` until Ctrl-C or SIGTERM.
pub fn run(args: &BoardSimArgs) -> anyhow::Result<()> {
    if !(args.speed.is_finite() && args.speed > 0.0) {
        anyhow::bail!("--speed must be a positive number");
    }
    let scenario = crate::sim::scenario::load(&args.scenario)?;
    let mut station = Station::new(&scenario, args.seed)?;
    let mut schedule: Vec<(Duration, Fault)> = args
        .faults
        .iter()
        .map(|s| scheduled(s))
        .collect::<anyhow::Result<_>>()?;
    schedule.sort_by_key(|(t, _)| *t);
    let state = state_dir(args);
    if let Some(d) = &state {
        std::fs::create_dir_all(d).with_context(|| format!("state directory {}", d.display()))?;
    }
    let flash = flash::open(state.as_deref())?;
    let erase_stall = flash.watcher.erase_stall_ms.clone();

    let mut line = Some(open_line(args.link.as_deref())?);
    {
        let mut out = std::io::stdout().lock();
        if let Some(l) = &line {
            writeln!(out, "port: {}", l.path.display())?;
        }
        out.flush()?;
    }
    eprintln!(
        "board-sim: scenario {} at {}× the wall clock, flash {}",
        scenario.name,
        args.speed,
        state
            .as_ref()
            .map_or("in memory only".to_string(), |d| d.display().to_string())
    );

    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        ctrlc::set_handler(move || stop.store(true, Ordering::Relaxed))
            .context("cannot install the Ctrl-C handler")?;
    }
    // Commands on stdin, one a line.
    let (cmd_tx, cmd_rx) = mpsc::channel::<String>();
    std::thread::spawn(move || {
        for l in std::io::stdin().lock().lines() {
            let Ok(l) = l else { break };
            if cmd_tx.send(l).is_err() {
                break;
            }
        }
    });

    let start = Instant::now();
    let world_us = |at: Instant| (at.duration_since(start).as_secs_f64() * args.speed * 1e6) as u64;
    let mut board = VirtualBoard::boot(flash, 0, POWER_ON);
    let mut plugged_again: Option<Instant> = None;
    let mut rx = [0u8; 1024];
    // What the PC side holds of the board's output when its program does not read (the bytes
    // beyond the pseudo-terminal's own 20 KiB): 64 KiB of the stream at the real rate, i.e.
    // the same stretch of wall clock at any speed. A PC's stalls (scheduling, a disk sync) last
    // as long in wall clock whatever the speed, and so does this process's own catching up
    // after it was not scheduled; a fixed 64 KiB would shrink the PC's margin `--speed` times
    // (3.5 s at 250×) and lose frames no real board would lose.
    let pc_buffer = ((1usize << 16) as f64 * args.speed.max(1.0)) as usize;
    let mut noise = 0x1234_5678u32;
    while !stop.load(Ordering::Relaxed) {
        let now = Instant::now();
        let mut faults: Vec<Fault> = Vec::new();
        while schedule.first().is_some_and(|(t, _)| *t <= now - start) {
            faults.push(schedule.remove(0).1);
        }
        while let Ok(cmd) = cmd_rx.try_recv() {
            if cmd.trim().is_empty() {
                continue;
            }
            match cmd.parse::<Fault>() {
                Ok(f) => faults.push(f),
                Err(e) => {
                    let _ = writeln!(std::io::stderr(), "board-sim: {e}");
                }
            }
        }
        for f in faults {
            let _ = writeln!(std::io::stderr(), "board-sim: fault {f:?}");
            match f {
                Fault::Unplug(d) => {
                    line = None;
                    if let Some(l) = &args.link {
                        let _ = std::fs::remove_file(l);
                    }
                    plugged_again = Some(now + d);
                }
                Fault::Reset => board = board.reset(world_us(now), PIN_RESET)?,
                Fault::RtdOpen(on) => board.faults.rtd_open = on,
                Fault::DrdyStall(on) => board.faults.drdy_stall = on,
                Fault::Garbage(n) => {
                    for _ in 0..n {
                        // xorshift: reproducible noise, no zero bytes (which would only
                        // delimit empty frames).
                        noise ^= noise << 13;
                        noise ^= noise >> 17;
                        noise ^= noise << 5;
                        board.tx.push((noise as u8).max(1));
                    }
                }
                Fault::EraseStall(d) => {
                    erase_stall.store(d.as_millis() as u64, Ordering::Relaxed);
                }
            }
        }
        if plugged_again.is_some_and(|t| now >= t) {
            plugged_again = None;
            let l = open_line(args.link.as_deref())?;
            // Whoever started us may have stopped reading stdout after the first line: a closed
            // pipe must not end the board.
            let mut out = std::io::stdout().lock();
            let _ = writeln!(out, "port: {}", l.path.display());
            let _ = out.flush();
            line = Some(l);
        }

        let board_end = world_us(now).saturating_sub(board.boot_world_us());
        board.run_until(board_end, &mut station);
        match &mut line {
            Some(l) => {
                let client_open = loop {
                    match l.read(&mut rx) {
                        Ok(0) => break true,
                        Ok(n) => board.receive(&rx[..n]),
                        Err(_) => break false,
                    }
                };
                if client_open {
                    let sent = l.write(&board.tx);
                    board.tx.drain(..sent);
                } else {
                    // The PC's driver drops what arrives at a port no program has open.
                    board.tx.clear();
                }
                // A UART never waits for the PC: what the PC side does not take in time is lost
                // there (the recorder sees the gap in seq). Whole frames: the one being
                // written stays.
                if board.tx.len() > pc_buffer {
                    let keep = board.tx.iter().position(|&b| b == 0).map_or(0, |i| i + 1);
                    board.tx.truncate(keep);
                }
            }
            // Unplugged: the board talks into the void.
            None => board.tx.clear(),
        }
        board.idle();
        std::thread::sleep(Duration::from_millis(1));
    }
    if let (Some(l), Some(_)) = (&args.link, &line) {
        let _ = std::fs::remove_file(l);
    }
    let _ = writeln!(
        std::io::stderr(),
        "board-sim: stopped after {} frames",
        board.frames_sent
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fault_commands_parse_with_defaults_and_refuse_nonsense() {
        assert_eq!("reset".parse::<Fault>(), Ok(Fault::Reset));
        assert_eq!(
            "unplug".parse::<Fault>(),
            Ok(Fault::Unplug(Duration::from_secs(2)))
        );
        assert_eq!("rtd-open=off".parse::<Fault>(), Ok(Fault::RtdOpen(false)));
        assert_eq!("garbage=10".parse::<Fault>(), Ok(Fault::Garbage(10)));
        assert!("rtd-open=maybe".parse::<Fault>().is_err());
        assert!("melt".parse::<Fault>().is_err());
        let (t, f) = scheduled("unplug=1.5@10").unwrap();
        assert_eq!(
            (t, f),
            (
                Duration::from_secs(10),
                Fault::Unplug(Duration::from_secs_f64(1.5))
            )
        );
        assert!(scheduled("reset").is_err());
    }
}
