//! `accomp record` against the virtual board, through a real pseudo-terminal: `accomp
//! board-sim` runs as its own process (killed and restarted like a board that loses power),
//! the recorder as a process (killed like a PC that crashes) or in this process (when the test
//! needs to step the PC's clock). Every test checks the rows against the scenario's physics and
//! the event lines against what was done to the link.

use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use accomp::table::CalibrationTable;
use accomp_host::device::board_sim::Station;
use accomp_host::device::record::{self, Options};
use accomp_host::log::Log;
use accomp_host::sim::scenario::Scenario;

const BIN: &str = env!("CARGO_BIN_EXE_accomp");

#[path = "common/scratch.rs"]
mod scratch;
use scratch::Scratch;

/// The test's own folder (the board's pty link, the table, the record), removed on drop.
fn temp_dir(name: &str) -> Scratch {
    Scratch::new(&format!("record-{name}"))
}

/// A running `accomp board-sim`, killed on drop.
struct BoardSim {
    child: Child,
    stdin: ChildStdin,
    /// When the process was started (its board's clock runs from about then).
    started: Instant,
}

impl BoardSim {
    fn start(dir: &Path, speed: u32, seed: u64) -> BoardSim {
        let started = Instant::now();
        let mut child = Command::new(BIN)
            .args(["board-sim", "paper-1g", "--speed", &speed.to_string()])
            .args(["--seed", &seed.to_string()])
            .arg("--link")
            .arg(dir.join("board"))
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let stdout = child.stdout.take().unwrap();
        let mut first = String::new();
        BufReader::new(stdout).read_line(&mut first).unwrap();
        assert!(first.starts_with("port: /dev/"), "first line {first:?}");
        let stdin = child.stdin.take().unwrap();
        BoardSim {
            child,
            stdin,
            started,
        }
    }

    fn command(&mut self, c: &str) {
        writeln!(self.stdin, "{c}").unwrap();
        self.stdin.flush().unwrap();
    }

    /// Raises the fault `name` for `ms` of wall clock, then clears it.
    fn fault_for(&mut self, name: &str, ms: u64) {
        self.command(name);
        std::thread::sleep(Duration::from_millis(ms));
        self.command(&format!("{name}=off"));
    }

    fn kill(mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for BoardSim {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A recorder process, killed on drop (a failed assertion must not leave it running).
struct Recorder(Child);

impl Recorder {
    fn spawn(mut c: Command) -> Recorder {
        Recorder(c.spawn().unwrap())
    }
    fn wait_success(&mut self) -> bool {
        self.0.wait().unwrap().success()
    }
    /// The record at `out` once the recorder has exited, asserted to have succeeded.
    fn finished_record(&mut self, out: &Path) -> Rec {
        assert!(self.wait_success(), "the recorder failed");
        read_rec(out)
    }
    fn kill(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
    /// Ctrl-C: the recorder stops the stream, writes its stop event and exits with success.
    fn interrupt(&mut self) {
        let ok = Command::new("kill")
            .args(["-INT", &self.0.id().to_string()])
            .status()
            .unwrap();
        assert!(ok.success());
    }
}

impl Drop for Recorder {
    fn drop(&mut self) {
        self.kill();
    }
}

fn port(dir: &Path) -> String {
    format!("serial:{}", dir.join("board").display())
}

/// Writes `table` to `dir/file` and loads it into the board with `accomp load`.
fn load(dir: &Path, table: &CalibrationTable, file: &str) {
    let path = dir.join(file);
    std::fs::write(&path, table.encode()).unwrap();
    let ok = Command::new(BIN)
        .args(["load", "--target", &port(dir)])
        .arg(&path)
        .stderr(Stdio::null())
        .status()
        .unwrap();
    assert!(ok.success());
}

/// Loads the paper's table into the board (a table makes temperature and a_i valid).
fn load_table(dir: &Path) {
    load(dir, &accomp_host::device::paper_table(), "table.acal");
}

/// A fresh directory `name`, a board in it at `speed`× with the paper's table loaded, and the
/// path the record goes to.
fn board_with_table(name: &str, speed: u32, seed: u64) -> (Scratch, BoardSim, PathBuf) {
    let dir = temp_dir(name);
    let board = BoardSim::start(&dir, speed, seed);
    load_table(&dir);
    let out = dir.join("rec.csv");
    (dir, board, out)
}

/// A recorder process writing `samples` rows to `out`, once it has written `rows` of them.
fn recording(dir: &Path, out: &Path, samples: &str, rows: usize) -> Recorder {
    let rec = Recorder::spawn(record_cmd(dir, out, &["--samples", samples]));
    wait_rows(out, rows);
    rec
}

fn record_cmd(dir: &Path, out: &Path, extra: &[&str]) -> Command {
    let mut c = Command::new(BIN);
    c.args(["record", "--target", &port(dir), "-o"])
        .arg(out)
        .args(extra)
        .stderr(Stdio::null());
    c
}

/// The rows of a record: (time_s, seq, board_time_us, output_v, rtd_ohms, tilt_arcsec,
/// status) and its event lines (kind, details).
/// A row of the record: time_s, seq, board µs, the columns 4, 6 and 7 as numbers, status.
type Row = (f64, u32, u64, f64, f64, f64, String);

struct Rec {
    rows: Vec<Row>,
    events: Vec<(String, String)>,
    headers: usize,
}

impl Rec {
    /// The rows either side of the first place where seq does not grow by one.
    fn around_seq_jump(&self) -> (&Row, &Row) {
        let at = self
            .rows
            .windows(2)
            .position(|w| w[1].1 != w[0].1 + 1)
            .expect("a jump in seq");
        (&self.rows[at], &self.rows[at + 1])
    }
}

fn read_rec(path: &Path) -> Rec {
    let text = std::fs::read_to_string(path).unwrap();
    let mut rows = Vec::new();
    let mut events = Vec::new();
    let mut headers = 0;
    for l in text.lines() {
        if let Some(e) = l.strip_prefix("# event: ") {
            let mut w = e.splitn(3, ' ');
            let _utc = w.next();
            events.push((
                w.next().unwrap_or("").to_string(),
                w.next().unwrap_or("").to_string(),
            ));
        } else if l.starts_with("time_s,") {
            headers += 1;
        } else if !l.starts_with('#') && !l.is_empty() {
            let f: Vec<&str> = l.split(',').collect();
            let num = |i: usize| f[i].parse::<f64>().unwrap_or(f64::NAN);
            rows.push((
                num(0),
                f[1].parse().unwrap(),
                f[2].parse().unwrap(),
                num(4),
                num(6),
                num(7),
                f[11].to_string(),
            ));
        }
    }
    // The project's reader takes the record as it is.
    Log::read_path(path).unwrap();
    Rec {
        rows,
        events,
        headers,
    }
}

fn kinds(r: &Rec) -> Vec<&str> {
    r.events.iter().map(|(k, _)| k.as_str()).collect()
}

/// The details of every event of `kind`, in file order.
fn details<'a>(r: &'a Rec, kind: &str) -> Vec<&'a str> {
    r.events
        .iter()
        .filter(|(k, _)| k == kind)
        .map(|(_, d)| d.as_str())
        .collect()
}

/// The record has an event of each kind in `present` and none of any kind in `absent`.
fn assert_events(r: &Rec, present: &[&str], absent: &[&str]) {
    let k = kinds(r);
    for kind in present {
        assert!(k.contains(kind), "no {kind} event in {k:?}");
    }
    for kind in absent {
        assert!(!k.contains(kind), "a {kind} event in {k:?}");
    }
}

/// The first status event raises `flag` from OK, and a later one returns to OK.
fn assert_status_raised_and_cleared(r: &Rec, flag: &str) {
    let status = details(r, "status");
    assert!(
        status
            .first()
            .is_some_and(|d| d.starts_with("OK -> ") && d.contains(flag)),
        "{status:?}"
    );
    assert!(status.iter().any(|d| d.ends_with("-> OK")), "{status:?}");
}

/// The board booted again during the record: its clock and seq start again (seq counts its
/// readings since boot).
fn assert_a_new_boot(r: &Rec) {
    let restart = r.rows.windows(2).position(|w| w[1].1 < w[0].1).unwrap();
    assert!(r.rows[restart + 1].2 < r.rows[restart].2);
}

fn assert_time_increases(r: &Rec) {
    for w in r.rows.windows(2) {
        assert!(w[1].0 > w[0].0, "time_s {} then {}", w[0].0, w[1].0);
    }
}

fn wait_rows(path: &Path, n: usize) {
    let t = Instant::now();
    while t.elapsed() < Duration::from_secs(20) {
        if let Ok(s) = std::fs::read_to_string(path) {
            if s.lines()
                .filter(|l| l.starts_with(|c: char| c.is_ascii_digit()))
                .count()
                >= n
            {
                return;
            }
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    panic!("{} never reached {n} rows", path.display());
}

/// Waits until the record has a line containing both `a` and `b`.
fn wait_text(path: &Path, a: &str, b: &str) {
    let t = Instant::now();
    while t.elapsed() < Duration::from_secs(20) {
        if let Ok(s) = std::fs::read_to_string(path) {
            if s.split_inclusive('\n')
                .any(|l| l.contains(a) && l.contains(b))
            {
                return;
            }
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    panic!("{} never had a line with {a:?} and {b:?}", path.display());
}

/// Waits until the record has `n` rows after the first line containing `marker`.
fn wait_rows_after(path: &Path, marker: &str, n: usize) {
    let t = Instant::now();
    while t.elapsed() < Duration::from_secs(20) {
        if let Ok(s) = std::fs::read_to_string(path) {
            if let Some(at) = s.find(marker) {
                let rows = s[at..]
                    .lines()
                    .filter(|l| l.starts_with(|c: char| c.is_ascii_digit()))
                    .count();
                if rows >= n {
                    return;
                }
            }
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    panic!("{} never had {n} rows after {marker:?}", path.display());
}

#[test]
fn recorded_samples_are_the_scenarios_physics_in_seq_and_board_time() {
    let (dir, _board, out) = board_with_table("truth", 1000, 7);
    let ok = record_cmd(
        &dir,
        &out,
        &["--samples", "500", "--site", "lab B", "--note", "t"],
    )
    .status()
    .unwrap();
    assert!(ok.success());
    let r = read_rec(&out);
    assert_eq!(r.rows.len(), 500);
    assert_eq!(r.headers, 1);
    assert_eq!(kinds(&r).first(), Some(&"start"));
    assert_eq!(kinds(&r).last(), Some(&"stop"));
    let log = Log::read_path(&out).unwrap();
    assert_eq!(log.meta("site"), Some("lab B"));
    assert!(log
        .meta("calibration_id")
        .is_some_and(|v| v.starts_with("0x")));

    // seq without a gap (it counts readings since boot, streamed or not: the first row's is
    // the readings before the stream started), time_s following the board clock exactly
    // (virtual board: no drift applied; µs stamps printed with 6 decimals).
    let (t0, seq0, b0, ..) = r.rows[0];
    for (i, row) in r.rows.iter().enumerate() {
        assert_eq!(row.1, seq0 + i as u32);
        let board_s = (row.2 - b0) as f64 * 1e-6;
        assert!((row.0 - t0 - board_s).abs() < 2e-6, "row {i}");
    }
    // Values: the station's physics at the frame's board time (the board booted at world
    // time 0), within the converters' resolution and the 0.4 s the tilt half lags.
    let scenario = Scenario::preset("paper-1g").unwrap();
    let mut station = Station::new(&scenario, 7).unwrap();
    let k_tilt = scenario.tiltmeter.scale_arcsec_per_v;
    let table = accomp_host::device::paper_table();
    for row in &r.rows {
        let p = station.at(row.2 as f64 * 1e-6);
        assert!(
            (row.3 - p.accel_v).abs() < 2e-6,
            "output {} vs {}",
            row.3,
            p.accel_v
        );
        assert!(
            (row.4 - p.rtd_ohms).abs() < 5e-3,
            "rtd {} vs {}",
            row.4,
            p.rtd_ohms
        );
        // The table's tilt scale converts the code back; the scenario's made the voltage.
        let tilt = p.tilt_v * k_tilt;
        let got = row.5 * k_tilt / table.tilt.scale_arcsec_per_v;
        assert!((got - tilt).abs() < 0.05, "tilt {got} vs {tilt}");
        assert_eq!(row.6, "OK");
    }
    // Writing over it needs --force.
    let again = record_cmd(&dir, &out, &["--samples", "5"])
        .status()
        .unwrap();
    assert!(!again.success());
    assert_eq!(read_rec(&out).rows.len(), 500);
}

#[test]
fn the_record_goes_on_when_the_board_is_killed_and_restarted_on_the_same_link() {
    let (dir, board, out) = board_with_table("restart", 1000, 1);
    let mut rec = recording(&dir, &out, "3000", 800);
    board.kill();
    std::thread::sleep(Duration::from_millis(800));
    let _board = BoardSim::start(&dir, 1000, 1);
    let r = rec.finished_record(&out);
    assert_eq!(r.rows.len(), 3000);
    assert_events(&r, &["link_lost", "reconnected", "board_reset"], &[]);
    assert_a_new_boot(&r);
    assert_time_increases(&r);
    // The table survived in the board's flash: the frames are still compensated.
    assert_eq!(r.rows.last().unwrap().6, "OK");
}

#[test]
fn a_killed_recorder_is_continued_with_append() {
    let (dir, _board, out) = board_with_table("append", 1000, 2);
    let mut rec = Recorder::spawn(record_cmd(&dir, &out, &[]));
    wait_rows(&out, 400);
    rec.kill();
    let before = read_rec(&out);
    // A crash cuts the last line on top of it.
    {
        let mut f = std::fs::OpenOptions::new().append(true).open(&out).unwrap();
        f.write_all(b"123.4,99").unwrap();
    }
    std::thread::sleep(Duration::from_millis(300));
    let ok = record_cmd(&dir, &out, &["--append", "--samples", "300"])
        .status()
        .unwrap();
    assert!(ok.success());
    let r = read_rec(&out);
    assert_eq!(r.headers, 1, "one header: the same record goes on");
    assert_eq!(r.rows.len(), before.rows.len() + 300);
    assert_events(&r, &["trimmed", "append", "seq_gap"], &[]);
    // The frames streamed while no recorder ran are counted in the gap.
    let last_before = before.rows.last().unwrap().1;
    let first_after = r.rows[before.rows.len()].1;
    let gap = details(&r, "seq_gap")[0];
    let lost = first_after - last_before - 1;
    assert!(gap.starts_with(&format!("lost={lost} ")), "{gap:?}");
    assert_time_increases(&r);
    // Same boot: time_s follows the board clock across the recorder's absence.
    let (a, b) = (&r.rows[before.rows.len() - 1], &r.rows[before.rows.len()]);
    assert!(((b.0 - a.0) - (b.2 - a.2) as f64 * 1e-6).abs() < 2e-6);
}

#[test]
fn a_board_reset_and_garbage_on_the_line_are_events_and_lose_nothing_else() {
    let (dir, mut board, out) = board_with_table("reset", 1000, 3);
    let mut rec = recording(&dir, &out, "2500", 500);
    board.command("garbage=300");
    wait_rows(&out, 1000);
    board.command("reset");
    let r = rec.finished_record(&out);
    assert_events(&r, &["line_noise", "board_reset"], &["link_lost"]);
    assert_time_increases(&r);
    assert_a_new_boot(&r);
}

#[test]
fn an_unplugged_link_keeps_the_boot_and_flag_changes_are_events() {
    let (dir, mut board, out) = board_with_table("unplug", 1000, 5);
    // No sample count: the recorder loses nothing, so under load it may still be writing rows
    // from before the faults when a count would be reached. It is stopped (Ctrl-C) once the
    // record holds rows from after the link came back, which it reads in order.
    let mut rec = Recorder::spawn(record_cmd(&dir, &out, &[]));
    wait_rows(&out, 400);
    // The loop opened until the record has the status event raising RTD_OPEN, then closed
    // until it has the one back to OK (event lines are synced at once; rows may show half a
    // second late), then the link pulled: each step seen before the next, however late
    // board-sim or the recorder are scheduled.
    board.command("rtd-open");
    wait_text(&out, "status OK -> ", "RTD_OPEN");
    board.command("rtd-open=off");
    wait_text(&out, " status ", "-> OK\n");
    board.command("unplug=1");
    wait_rows_after(&out, " reconnected ", 300);
    rec.interrupt();
    let r = rec.finished_record(&out);
    assert_events(
        &r,
        &["link_lost", "reconnected", "seq_gap"],
        &["board_reset"],
    );
    assert_status_raised_and_cleared(&r, "RTD_OPEN");
    // The open loop's rows are flagged and carry no resistance.
    assert!(r
        .rows
        .iter()
        .any(|row| row.6.contains("RTD_OPEN") && row.4.is_nan()));
    // One boot: seq only grows, and across the gap time_s follows the board clock.
    let (a, b) = r.around_seq_jump();
    assert!(b.1 > a.1);
    assert!(((b.0 - a.0) - (b.2 - a.2) as f64 * 1e-6).abs() < 1e-3);
    let lost = details(&r, "seq_gap")[0];
    assert!(
        lost.starts_with(&format!("lost={} ", b.1 - a.1 - 1)),
        "{lost:?}"
    );
    assert_time_increases(&r);
}

#[test]
fn a_reset_while_unplugged_is_a_new_boot_though_its_clock_and_seq_passed_the_old_boots() {
    let (dir, mut board, out) = board_with_table("unplugreset", 1000, 9);
    let mut rec = recording(&dir, &out, "3000", 400);
    // Unplugged and reset at once (one write: board-sim takes both in the same turn, however
    // late it is scheduled): READY goes into the void. The link stays down 1 s longer than the
    // old boot has lived (1000 s of the board's clock), so when it is back the new boot's
    // uptime and seq are far past the old boot's last frame whatever the load made of the old
    // boot's life. Only Info's boot id tells it is a new boot.
    let unplug_s = board.started.elapsed().as_secs_f64() + 1.0;
    board.command(&format!("unplug={unplug_s:.3}\nreset"));
    let r = rec.finished_record(&out);
    // A new boot's seq is no gap.
    assert_events(
        &r,
        &["link_lost", "reconnected", "board_reset"],
        &["seq_gap"],
    );
    let reset = details(&r, "board_reset")[0];
    assert!(reset.contains("boot id 0x"), "{reset:?}");
    // The jump in seq is where the new boot starts, and the new boot's rows really are far
    // past the old boot in seq and board time (what made the uptime test alone fail).
    let (a, b) = r.around_seq_jump();
    assert!(
        b.1 > a.1 && b.2 > a.2,
        "seq {} → {}, board µs {} → {}",
        a.1,
        b.1,
        a.2,
        b.2
    );
    assert_time_increases(&r);
}

/// The virtual board in this process, on a pseudo-terminal linked at `dir/board`, whose world
/// clock is virtual and advanced in lockstep with the recorder: [`STEP_US`] per turn, and after a
/// turn that sent frames only once the recorder has read the PC clock again (it does so for every
/// frame it takes). So the recorder sees every frame within about one step of its board time, as
/// a real PC sees a real board's within milliseconds, however late the test's threads are
/// scheduled: the PC clock made from this virtual clock carries no scheduling noise multiplied by
/// a board's speed.
struct LockstepBoard {
    /// World time the board has run to, µs.
    world_us: std::sync::Arc<std::sync::atomic::AtomicU64>,
    /// Reads of the PC clock by the recorder.
    pc_reads: std::sync::Arc<std::sync::atomic::AtomicU64>,
    stop: std::sync::Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

/// Virtual time per turn of [`LockstepBoard`], µs: the most a frame waits for the recorder in
/// virtual time, so the minimum-delay blocks of the recorder's clock model scatter by less
/// than 10 ms per 60 s (170 ppm of apparent drift at most).
const STEP_US: u64 = 10_000;

impl LockstepBoard {
    fn start(dir: &Path, seed: u64) -> LockstepBoard {
        use accomp_host::device::board_sim::{flash, pty, VirtualBoard};
        use std::sync::atomic::{AtomicU64, Ordering::SeqCst};
        use std::sync::Arc;
        let mut line = pty::Pty::open().unwrap();
        pty::link(&line.path, &dir.join("board")).unwrap();
        let world_us = Arc::new(AtomicU64::new(0));
        let pc_reads = Arc::new(AtomicU64::new(0));
        let stop = Arc::new(AtomicBool::new(false));
        let (w, reads, halt) = (world_us.clone(), pc_reads.clone(), stop.clone());
        let thread = std::thread::spawn(move || {
            // The chip models share state through Rc: the board is built on its own thread.
            let scenario = Scenario::preset("paper-1g").unwrap();
            let mut station = Station::new(&scenario, seed).unwrap();
            let power_on = accomp::protocol::BootReport::POR | accomp::protocol::BootReport::PIN;
            let mut board = VirtualBoard::boot(flash::open(None).unwrap(), 0, power_on);
            let mut rx = [0u8; 1024];
            let mut world = 0u64;
            while !halt.load(SeqCst) {
                world += STEP_US;
                let frames = board.frames_sent;
                board.run_until(world.saturating_sub(board.boot_world_us()), &mut station);
                let client_open = loop {
                    match line.read(&mut rx) {
                        Ok(0) => break true,
                        Ok(n) => board.receive(&rx[..n]),
                        Err(_) => break false,
                    }
                };
                let reads_before = reads.load(SeqCst);
                if client_open {
                    while !board.tx.is_empty() && !halt.load(SeqCst) {
                        let sent = line.write(&board.tx);
                        board.tx.drain(..sent);
                        if sent == 0 {
                            std::thread::sleep(Duration::from_micros(200));
                        }
                    }
                } else {
                    board.tx.clear();
                }
                board.idle();
                w.store(world, SeqCst);
                // Frames went out this turn: the world waits until the recorder has taken one
                // (10 s of wall clock at most: a recorder that stopped reading does not hang
                // the test).
                let sent_frames = client_open && board.frames_sent > frames;
                let t = Instant::now();
                while sent_frames
                    && reads.load(SeqCst) == reads_before
                    && !halt.load(SeqCst)
                    && t.elapsed() < Duration::from_secs(10)
                {
                    std::thread::sleep(Duration::from_micros(200));
                }
                // A breath of wall clock every 100 ms of the world's (the turns are cheap).
                if world.is_multiple_of(100_000) {
                    std::thread::sleep(Duration::from_micros(300));
                }
            }
        });
        LockstepBoard {
            world_us,
            pc_reads,
            stop,
            thread: Some(thread),
        }
    }
}

impl Drop for LockstepBoard {
    fn drop(&mut self) {
        self.stop.store(true, std::sync::atomic::Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

#[test]
fn a_pc_clock_step_is_an_event_and_moves_no_row() {
    use std::sync::atomic::Ordering::SeqCst;
    let dir = temp_dir("pcstep");
    // The PC's clock is the board's virtual world clock (the board's clock plus its boot time)
    // from a Unix epoch, and steps 300 s back once the world is 500 s old: a crystal board
    // without drift, read without scheduling noise, and one real step of the PC's clock.
    let board = LockstepBoard::start(&dir, 4);
    let opts = Options {
        port: dir.join("board").display().to_string(),
        output: dir.join("rec.csv"),
        samples: Some(800),
        duration_s: None,
        append: false,
        force: false,
        rotate: None,
        site: None,
        note: None,
        rate_hz: None,
        live_rows: false,
    };
    let unix0 = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_secs_f64();
    let (world_us, reads) = (board.world_us.clone(), board.pc_reads.clone());
    let pc = move || {
        reads.fetch_add(1, SeqCst);
        let world_s = world_us.load(SeqCst) as f64 * 1e-6;
        unix0 + world_s - if world_s > 500.0 { 300.0 } else { 0.0 }
    };
    let stop = AtomicBool::new(false);
    let summary = record::record(&opts, &pc, &stop, &mut |_| {}).unwrap();
    drop(board);
    assert_eq!(summary.samples, 800);
    let r = read_rec(&opts.output);
    let steps: Vec<f64> = details(&r, "pc_clock_step")
        .iter()
        .filter_map(|d| d.strip_prefix("step_s=")?.split(' ').next()?.parse().ok())
        .collect();
    // The one step, within the frames' delay of at most a turn or two.
    assert!(
        steps.len() == 1 && (steps[0] + 300.0).abs() < 0.3,
        "steps {steps:?}, events {:?}",
        r.events
    );
    // Every interval of time_s is the board's interval (drift < 1000 ppm applied at most).
    for w in r.rows.windows(2) {
        let board = (w[1].2 - w[0].2) as f64 * 1e-6;
        assert!(
            ((w[1].0 - w[0].0) - board).abs() < 1e-3 * board + 2e-6,
            "seq {} → {}: time_s {} → {}, board {board} s; events {:?}",
            w[0].1,
            w[1].1,
            w[0].0,
            w[1].0,
            r.events
        );
    }
}

#[test]
fn a_drdy_stall_is_flagged_in_rows_and_status_events_and_takes_no_number_from_seq() {
    let (dir, mut board, out) = board_with_table("drdystall", 250, 6);
    let mut rec = recording(&dir, &out, "2500", 400);
    // 1.2 s of wall clock: 300 s of the board's, ≈ 375 pair periods without a conversion.
    board.fault_for("drdy-stall", 1200);
    let r = rec.finished_record(&out);
    assert_events(&r, &[], &["seq_gap", "board_reset"]);
    // The timeout readings keep coming at the pair rate and take the numbers: no gap in seq.
    for w in r.rows.windows(2) {
        assert_eq!(w[1].1, w[0].1 + 1, "seq {} then {}", w[0].1, w[1].1);
    }
    let flagged: Vec<_> = r
        .rows
        .iter()
        .filter(|row| row.6.contains("DRDY_TIMEOUT"))
        .collect();
    assert!(flagged.len() > 100, "{} rows flagged", flagged.len());
    // A timeout reading carries no conversion: no output value.
    assert!(flagged.iter().all(|row| row.3.is_nan()));
    assert_status_raised_and_cleared(&r, "DRDY_TIMEOUT");
    assert_eq!(r.rows.last().unwrap().6, "OK");
    assert_time_increases(&r);
}

/// Loads a copy of the paper's table dated `day` (a different table for each day).
fn load_dated_table(dir: &Path, day: u8) {
    let mut t = accomp_host::device::paper_table();
    t.date.day = day;
    load(dir, &t, &format!("table{day}.acal"));
}

#[test]
fn an_erase_stall_while_streaming_loses_pairs_that_info_counts_with_the_stall_length() {
    let dir = temp_dir("erasestall");
    // 100×: the 2 s stall is 20 ms of wall clock, the record's frames come 12.5 a second.
    let mut board = BoardSim::start(&dir, 100, 8);
    // Three tables fill the three slots; the erase ahead after the third empties the spare.
    for day in 1..=3 {
        load_dated_table(&dir, day);
    }
    // A recorder started and gone: the board streams on.
    let out = dir.join("rec.csv");
    let mut rec = Recorder::spawn(record_cmd(&dir, &out, &[]));
    wait_rows(&out, 5);
    rec.kill();
    // Loaded while streaming: the first into the emptied spare (no erase, the next erase ahead
    // waits for the stream to stop), the second onto a spare holding an old table: its commit
    // erases, and the fault makes that erase stall the board 2 s.
    load_dated_table(&dir, 4);
    board.command("erase-stall=2000");
    std::thread::sleep(Duration::from_millis(100));
    load_dated_table(&dir, 5);
    let info = Command::new(BIN)
        .args(["device", "info", "--json", "--target", &port(&dir)])
        .stderr(Stdio::null())
        .output()
        .unwrap();
    assert!(info.status.success());
    let info: serde_json::Value = serde_json::from_slice(&info.stdout).unwrap();
    // Two erases: the erase ahead after the third load (not streaming, no fault: 0 µs) and
    // the fifth load's.
    assert_eq!(info["losses"]["erase_stalls"], 2, "{info}");
    assert_eq!(info["losses"]["erase_stall_us"], 2_000_000, "{info}");
    let lost = info["losses"]["conversions_lost"].as_u64().unwrap();
    // 2 s of 0.8 s pairs: two pairs, or three with the conversion dropped after the stall.
    assert!((2..=3).contains(&lost), "{info}");
}
