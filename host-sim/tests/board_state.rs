//! The QEMU board's persistent state under careless or unlucky use: one command at a time
//! (concurrent `load`s and a `table get` racing them lose no table), "verified" only once the
//! image on disk holds the table, a damaged image refused and never overwritten, a folder that
//! cannot take the image refused by name before anything is sent, and no emulator or temporary
//! folder left behind by an `accomp` killed with SIGKILL.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use accomp::table::CalibrationTable;
use accomp_host::device::paper_table;
use accomp_host::device::qemu::{image_tables, FLASH_IMAGE, STATE_ENV};

#[path = "common/cli.rs"]
mod cli;
#[path = "common/qemu.rs"]
mod qemu;
#[path = "common/scratch.rs"]
mod scratch;
use cli::stderr;
use qemu::elf;
use scratch::Scratch;

/// A table told apart by its date (its id is its CRC).
fn table(n: u32) -> CalibrationTable {
    let mut t = paper_table();
    t.date.year = 2000 + (n / 300) as u16;
    t.date.month = 1 + ((n / 28) % 12) as u8;
    t.date.day = 1 + (n % 28) as u8;
    t
}

fn accomp_cmd(state: &Path, args: &[&str]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_accomp"));
    c.args(args)
        .env(STATE_ENV, state)
        .env("ACCOMP_FIRMWARE_ELF", elf())
        .stdin(Stdio::null());
    c
}

fn accomp(state: &Path, args: &[&str]) -> Output {
    accomp_cmd(state, args).output().expect("accomp runs")
}

fn write_table(dir: &Path, n: u32) -> (PathBuf, u32) {
    let t = table(n);
    let p = dir.join(format!("t{n}.acal"));
    std::fs::write(&p, t.encode()).unwrap();
    (p, t.id())
}

/// `accomp table get --target qemu` and `extra`.
fn table_get<'a>(extra: &[&'a str]) -> Vec<&'a str> {
    let mut args = vec!["table", "get", "--target", "qemu"];
    args.extend_from_slice(extra);
    args
}

/// A board's state folder and a folder for the test's files: `board-state-<name>[-files]`.
fn board(name: &str) -> (Scratch, Scratch) {
    (
        Scratch::new(&format!("board-state-{name}")),
        Scratch::new(&format!("board-state-{name}-files")),
    )
}

/// Writes table `n` into `work` and loads it onto the QEMU board of `state` (asserted to
/// succeed): the table's file and id.
fn load_table(state: &Path, work: &Path, n: u32) -> (PathBuf, u32) {
    let (t, id) = write_table(work, n);
    let o = accomp(state, &["load", "--target", "qemu", t.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    (t, id)
}

/// (active, previous) as the firmware finds them when it boots on a copy of the state.
fn tables_after_boot(state: &Path) -> (Option<u32>, Option<u32>) {
    let copy = Scratch::new("board-state-boot");
    std::fs::copy(state.join(FLASH_IMAGE), copy.join(FLASH_IMAGE)).expect("image");
    qemu::tables_after_boot(&copy)
}

fn on_disk(state: &Path) -> (Option<u32>, Option<u32>) {
    let image = std::fs::read(state.join(FLASH_IMAGE)).expect("image");
    image_tables(&image).expect("the image scans")
}

fn hex(id: u32) -> String {
    format!("{id:#010x}")
}

#[test]
fn concurrent_loads_and_a_racing_table_get_lose_no_table_in_30_rounds() {
    let (state, work) = board("race");
    let (_, first_id) = load_table(&state, &work, 0);
    let mut active = first_id;
    let mut waited = 0;
    for round in 0..30u32 {
        let (a, a_id) = write_table(&work, 1 + 2 * round);
        let (b, b_id) = write_table(&work, 2 + 2 * round);
        let got = work.join(format!("got{round}.acal"));
        let spawn = |args: &[&str]| {
            accomp_cmd(&state, args)
                .stdout(Stdio::piped())
                .stderr(Stdio::piped())
                .spawn()
                .expect("spawn")
        };
        let la = spawn(&["load", "--target", "qemu", a.to_str().unwrap()]);
        let get = spawn(&table_get(&["-o", got.to_str().unwrap()]));
        let lb = spawn(&["load", "--target", "qemu", b.to_str().unwrap()]);
        let (oa, og, ob) = (
            la.wait_with_output().unwrap(),
            get.wait_with_output().unwrap(),
            lb.wait_with_output().unwrap(),
        );
        for (what, o) in [("load a", &oa), ("table get", &og), ("load b", &ob)] {
            assert!(
                o.status.success(),
                "round {round}: {what} failed: {}",
                stderr(o)
            );
            waited += stderr(o).contains("in use by pid") as usize;
        }
        // Each load says which table it left as the rollback: the one before it.
        let (ea, eb) = (stderr(&oa), stderr(&ob));
        let (later, earlier, earlier_id, later_id) =
            if eb.contains(&format!("rollback table {}", hex(a_id))) {
                (eb, ea, a_id, b_id)
            } else {
                (ea, eb, b_id, a_id)
            };
        assert!(
            later.contains(&format!(
                "active table {} (read back and verified",
                hex(later_id)
            )) && later.contains(&format!("rollback table {}", hex(earlier_id))),
            "round {round}: later load says {later}"
        );
        assert!(
            earlier.contains(&format!("rollback table {}", hex(active))),
            "round {round}: earlier load (of {}) says {earlier}, expected rollback {}",
            hex(earlier_id),
            hex(active)
        );
        assert_eq!(
            on_disk(&state),
            (Some(later_id), Some(earlier_id)),
            "round {round}: the image on disk"
        );
        // The get saw the board before, between or after the loads: always a whole table.
        let got_id = CalibrationTable::decode(&std::fs::read(&got).unwrap())
            .expect("get wrote a valid table")
            .id();
        assert!(
            [active, a_id, b_id].contains(&got_id),
            "round {round}: get returned {}",
            hex(got_id)
        );
        active = later_id;
    }
    // The firmware itself, booting on the final image, agrees with the host's reading of it.
    assert_eq!(tables_after_boot(&state), on_disk(&state));
    eprintln!("30 rounds: {waited} of 90 commands waited for the board");
    assert!(waited > 0, "no command ever waited: the race was not run");
}

#[test]
fn no_wait_refuses_a_busy_board_naming_the_holder() {
    let state = Scratch::new("board-state-nowait");
    std::fs::create_dir_all(&*state).unwrap();
    // This test holds the lock as another accomp would.
    let lock = std::fs::OpenOptions::new()
        .create(true)
        .truncate(true)
        .write(true)
        .open(state.join("accomp-board.lock"))
        .unwrap();
    lock.lock().unwrap();
    std::fs::write(state.join("accomp-board.lock"), "4242\n").unwrap();
    let out = state.join("got.acal");
    let started = Instant::now();
    let o = accomp(
        &state,
        &table_get(&["--no-wait", "-o", out.to_str().unwrap()]),
    );
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains("in use by pid 4242") && e.contains("--no-wait"),
        "{e}"
    );
    assert!(started.elapsed() < Duration::from_secs(10));
    // Without --no-wait it waits, says so, and goes on once the lock is released.
    let child = accomp_cmd(&state, &table_get(&["-o", out.to_str().unwrap()]))
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(500));
    drop(lock);
    let o = child.wait_with_output().unwrap();
    let e = stderr(&o);
    assert!(e.contains("in use by pid 4242, waiting"), "{e}");
    // A blank board has no table to get: the refusal is the firmware's, after the wait.
    assert!(!e.contains("--no-wait"), "{e}");
}

#[test]
fn a_short_flash_image_is_refused_with_its_size_kept_intact_and_reset_state_moves_it_aside() {
    let (state, work) = board("short");
    let (t, _) = load_table(&state, &work, 7);
    let image = state.join(FLASH_IMAGE);
    let full = std::fs::read(&image).unwrap();
    let cut = full[..1000].to_vec();
    std::fs::write(&image, &cut).unwrap();
    let got = work.join("got.acal");
    for args in [
        vec![
            "table",
            "get",
            "--target",
            "qemu",
            "-o",
            got.to_str().unwrap(),
        ],
        vec!["load", "--target", "qemu", t.to_str().unwrap()],
    ] {
        let o = accomp(&state, &args);
        assert!(!o.status.success(), "{args:?} accepted a 1000-byte image");
        let e = stderr(&o);
        assert!(
            e.contains(&image.display().to_string())
                && e.contains("1000 bytes")
                && e.contains("expected 3072"),
            "{args:?}: {e}"
        );
        assert_eq!(
            std::fs::read(&image).unwrap(),
            cut,
            "{args:?} touched the image"
        );
    }
    let o = accomp(
        &state,
        &table_get(&["--reset-state", "-o", got.to_str().unwrap()]),
    );
    let e = stderr(&o);
    assert!(e.contains("moved to"), "{e}");
    let aside: Vec<PathBuf> = std::fs::read_dir(&*state)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.to_string_lossy().contains(".damaged-"))
        .collect();
    assert_eq!(aside.len(), 1, "{aside:?}");
    assert_eq!(
        std::fs::read(&aside[0]).unwrap(),
        cut,
        "the damaged image was not kept"
    );
    assert_eq!(std::fs::metadata(&image).unwrap().len(), 3072);
    // The board starts blank after the reset (so the get finds no table).
    assert!(!o.status.success());
    assert_eq!(on_disk(&state), (None, None));
}

#[test]
fn an_immutable_state_folder_is_refused_by_name_before_anything_is_sent() {
    let (state, work) = board("immutable");
    let (_, id1) = load_table(&state, &work, 11);
    let (t2, _) = write_table(&work, 12);
    let before = std::fs::read(state.join(FLASH_IMAGE)).unwrap();
    // Root writes through permission bits; the immutable attribute stops root too.
    let chattr = Command::new("chattr").arg("+i").arg(&*state).status();
    assert!(
        chattr.is_ok_and(|s| s.success()),
        "chattr +i is needed for this test (e2fsprogs, a file system with attributes)"
    );
    let o = accomp(&state, &["load", "--target", "qemu", t2.to_str().unwrap()]);
    let _ = Command::new("chattr").arg("-i").arg(&*state).status();
    assert_refused_before_sending(&o, &state, "load into an immutable folder");
    assert_eq!(std::fs::read(state.join(FLASH_IMAGE)).unwrap(), before);
    assert_eq!(on_disk(&state), (Some(id1), None));
}

#[test]
fn a_full_state_file_system_is_refused_before_anything_is_sent() {
    // 64 KiB of tmpfs, filled to less than one image.
    let mnt = Scratch::tmpfs_64k("board-state-full");
    let work = Scratch::new("board-state-full-files");
    let (t, _) = write_table(&work, 21);
    let state = mnt.join("state");
    std::fs::create_dir_all(&state).unwrap();
    let filler = mnt.join("filler");
    {
        use std::io::Write as _;
        let mut f = std::fs::File::create(&filler).unwrap();
        while f.write_all(&[0u8; 512]).and_then(|()| f.sync_all()).is_ok() {}
    }
    let o = accomp(&state, &["load", "--target", "qemu", t.to_str().unwrap()]);
    let _ = std::fs::remove_file(&filler);
    mnt.unmount();
    assert_refused_before_sending(&o, &state, "load onto a full file system");
}

/// `what` failed, its error naming the state folder and saying nothing was sent (nor verified).
fn assert_refused_before_sending(o: &Output, state: &Path, what: &str) {
    assert!(!o.status.success(), "{what} succeeded");
    let e = stderr(o);
    assert!(
        e.contains(&state.display().to_string()) && e.contains("nothing sent"),
        "{e}"
    );
    assert!(!e.contains("verified"), "{e}");
}

#[test]
fn a_state_path_under_a_regular_file_is_named_and_leaves_no_temporary_folder() {
    let work = Scratch::new("board-state-badpath");
    let file = work.join("a-file");
    std::fs::write(&file, "not a folder").unwrap();
    let state = file.join("state");
    let tmp = Scratch::new("board-state-badpath-tmp");
    let child = accomp_cmd(&state, &table_get(&["-o"]))
        .arg(work.join("got.acal"))
        .env("TMPDIR", &*tmp)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let pid = child.id();
    let o = child.wait_with_output().unwrap();
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains(&state.display().to_string()) && e.contains("cannot create the folder"),
        "{e}"
    );
    assert!(
        !e.contains("qemu-system-arm"),
        "blamed on the emulator: {e}"
    );
    assert!(
        qemu::temp_dirs_of(&tmp, pid).is_empty(),
        "{:?} left",
        qemu::temp_dirs_of(&tmp, pid)
    );
}

/// Direct children of `pid`.
fn children_of(pid: u32) -> Vec<u32> {
    let mut out = Vec::new();
    for e in std::fs::read_dir("/proc").unwrap().flatten() {
        let Ok(p) = e.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        if let Ok(stat) = std::fs::read_to_string(format!("/proc/{p}/stat")) {
            let after = stat.rsplit(')').next().unwrap_or("");
            if after.split_whitespace().nth(1).and_then(|s| s.parse().ok()) == Some(pid) {
                out.push(p);
            }
        }
    }
    out
}

fn running(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat")).is_ok_and(|s| {
        !s.rsplit(')')
            .next()
            .unwrap_or("")
            .trim_start()
            .starts_with('Z')
    })
}

#[test]
fn kill_9_of_accomp_leaves_no_emulator_and_the_next_run_reclaims_its_folder() {
    let (state, work) = board("kill9");
    let csv = work.join("in.csv");
    cli::write_csv(&csv, "time_s,output_v,temperature_c\n", 200_000, |i| {
        format!("{},1.3,50", i as f64 * 0.1)
    });
    let (cal, _) = write_table(&work, 31);
    load_table(&state, &work, 32);
    // Its own temp dir: a launch by a parallel test would reclaim the folder of the killed
    // process before this test looks for it.
    let tmp = Scratch::new("board-state-kill9-tmp");
    let mut child = accomp_cmd(&state, &["compensate", "--target", "qemu", "--calibration"])
        .env("TMPDIR", &*tmp)
        .arg(&cal)
        .arg("--input")
        .arg(&csv)
        .arg("--output")
        .arg(work.join("out.csv"))
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let pid = child.id();
    let deadline = Instant::now() + Duration::from_secs(60);
    let qemu = loop {
        let kids = children_of(pid);
        if let Some(&q) = kids.first() {
            break q;
        }
        assert!(Instant::now() < deadline, "QEMU never started");
        std::thread::sleep(Duration::from_millis(20));
    };
    // Let it boot and stream a little.
    std::thread::sleep(Duration::from_millis(500));
    assert!(
        child.try_wait().unwrap().is_none(),
        "compensate ended before the kill"
    );
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    let deadline = Instant::now() + Duration::from_secs(10);
    while running(qemu) && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(
        !running(qemu),
        "QEMU {qemu} still running after its parent was killed"
    );
    // SIGKILL leaves no chance to remove the folder: the next launch reclaims it, and the
    // board's lock died with the process.
    assert!(
        !qemu::temp_dirs_of(&tmp, pid).is_empty(),
        "no folder left: nothing to reclaim was tested"
    );
    let o = accomp_cmd(
        &state,
        &table_get(&["--no-wait", "-o", work.join("g.acal").to_str().unwrap()]),
    )
    .env("TMPDIR", &*tmp)
    .output()
    .expect("accomp runs");
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        qemu::temp_dirs_of(&tmp, pid).is_empty(),
        "{:?} not reclaimed",
        qemu::temp_dirs_of(&tmp, pid)
    );
}

#[test]
fn compensate_says_that_it_activates_its_table_and_the_board_keeps_it() {
    let (state, work) = board("compensate");
    let (_, old_id) = load_table(&state, &work, 41);
    let (cal, cal_id) = write_table(&work, 42);
    let csv = work.join("in.csv");
    std::fs::write(&csv, "time_s,output_v,temperature_c\n0,1.3,50\n1,1.3,50\n").unwrap();
    let out = work.join("out.csv");
    let o = accomp(
        &state,
        &cli::compensate_args(
            "qemu",
            cal.to_str().unwrap(),
            csv.to_str().unwrap(),
            out.to_str().unwrap(),
        ),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(
        e.contains(&format!("activating table {} on the device", hex(cal_id))),
        "{e}"
    );
    assert_eq!(on_disk(&state), (Some(cal_id), Some(old_id)));
}
