//! Issue #15.3: the emulated board keeps its state across QEMU runs (its flash image lives in
//! the board's state directory, written through by the firmware), so `accomp load` then
//! `accomp table get` round-trip through two separate QEMU runs; and a system-level power cut —
//! the real firmware in QEMU killed at each step of an upload, commit and erase-ahead — leaves
//! the old or the new table active at the next boot, never neither, with the right rollback
//! table. Also #15.8: no `/tmp/accomp-qemu-*` folder is left after a QEMU launch.

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use accomp::protocol::model::TableHistory;
use accomp::protocol::upload_requests;
use accomp::table::CalibrationTable;
use accomp_host::device::paper_table;
use accomp_host::device::qemu::{FLASH_IMAGE, STATE_ENV};

#[path = "common/cli.rs"]
mod cli;
#[path = "common/qemu.rs"]
mod qemu;
#[path = "common/scratch.rs"]
mod scratch;
use qemu::{boot_on as boot, elf, tables_after_boot};
use scratch::Scratch;

fn table(day: u8) -> CalibrationTable {
    let mut t = paper_table();
    t.date.day = day;
    t
}

/// A fresh folder, removed when the test passes.
fn fresh_dir(name: &str) -> Scratch {
    Scratch::new(&format!("persist-test-{name}"))
}

fn accomp(state: &Path, args: &[&str]) -> std::process::Output {
    cli::accomp_ok(args, &[(STATE_ENV, state), ("ACCOMP_FIRMWARE_ELF", &elf())])
}

#[test]
fn load_then_table_get_round_trip_across_two_qemu_runs_and_leave_no_temp_folder() {
    let state = fresh_dir("cli");
    let work = fresh_dir("cli-files");
    let file = work.join("t.acal");
    let back = work.join("back.acal");
    std::fs::write(&file, table(5).encode()).expect("write table");
    accomp(
        &state,
        &["load", "--target", "qemu", file.to_str().unwrap()],
    );
    assert!(state.join(FLASH_IMAGE).exists(), "no flash image kept");
    // A second, separate QEMU run reads back what the first one stored.
    accomp(
        &state,
        &[
            "table",
            "get",
            "--target",
            "qemu",
            "-o",
            back.to_str().unwrap(),
        ],
    );
    assert_eq!(std::fs::read(&back).unwrap(), table(5).encode().to_vec());
    // Loading it again is a no-op on the board (the rollback table stays empty).
    accomp(
        &state,
        &["load", "--target", "qemu", file.to_str().unwrap()],
    );
    assert_eq!(tables_after_boot(&state), (Some(table(5).id()), None));
    // Each `accomp` process removed its QEMU's temporary folder (its own temp dir, where no
    // parallel test's launch reclaims it for it).
    let tmp = fresh_dir("cli-tmp");
    let out = Command::new(env!("CARGO_BIN_EXE_accomp"))
        .args(["table", "get", "--target", "qemu", "-o"])
        .arg(&back)
        .env("TMPDIR", &*tmp)
        .env(STATE_ENV, &*state)
        .env("ACCOMP_FIRMWARE_ELF", elf())
        .spawn()
        .expect("spawn");
    let pid = out.id();
    let status = out.wait_with_output().expect("wait").status;
    assert!(status.success());
    assert!(
        qemu::temp_dirs_of(&tmp, pid).is_empty(),
        "{:?} left",
        qemu::temp_dirs_of(&tmp, pid)
    );
    // And a launch in this process: its temporary folder goes with the Qemu.
    let (q, _c) = qemu::boot();
    let dir = q.log_dir.clone();
    assert!(dir.exists());
    drop(q);
    assert!(!dir.exists(), "{} left", dir.display());
}

#[test]
fn sigterm_stops_qemu_and_removes_its_temporary_folder() {
    let state = fresh_dir("sigterm");
    let work = fresh_dir("sigterm-files");
    // A long compensate through QEMU, interrupted while it streams.
    let csv = work.join("in.csv");
    cli::write_csv(&csv, "time_s,output_v,temperature_c\n", 200_000, |i| {
        format!("{},{},50", i as f64 * 0.1, 1.3)
    });
    let cal = work.join("t.acal");
    std::fs::write(&cal, table(6).encode()).unwrap();
    let tmp = fresh_dir("sigterm-tmp");
    let mut child = Command::new(env!("CARGO_BIN_EXE_accomp"))
        .env("TMPDIR", &*tmp)
        .args(["compensate", "--target", "qemu", "--calibration"])
        .arg(&cal)
        .arg("--input")
        .arg(&csv)
        .arg("--output")
        .arg(work.join("out.csv"))
        .env(STATE_ENV, &*state)
        .env("ACCOMP_FIRMWARE_ELF", elf())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("spawn");
    let pid = child.id();
    // Wait until its QEMU runs (its temp folder exists), then a little longer.
    let deadline = std::time::Instant::now() + Duration::from_secs(60);
    while qemu::temp_dirs_of(&tmp, pid).is_empty() && std::time::Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(50));
    }
    assert!(
        !qemu::temp_dirs_of(&tmp, pid).is_empty(),
        "QEMU never started"
    );
    // Streaming (#15.8): rows are on disk while the run goes on.
    let out_csv = work.join("out.csv");
    let deadline = std::time::Instant::now() + Duration::from_secs(60);
    let rows_on_disk = || {
        std::fs::read_to_string(&out_csv)
            .map(|t| {
                t.lines()
                    .filter(|l| l.starts_with(|c: char| c.is_ascii_digit()))
                    .count()
            })
            .unwrap_or(0)
    };
    while rows_on_disk() < 10 && std::time::Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(100));
    }
    assert!(
        rows_on_disk() >= 10,
        "no rows on disk while compensate runs"
    );
    assert!(
        child.try_wait().unwrap().is_none(),
        "compensate ended before the signal"
    );
    let qemu_pids = children_of(pid);
    assert!(!qemu_pids.is_empty(), "no QEMU child");
    Command::new("kill")
        .args(["-TERM", &pid.to_string()])
        .status()
        .unwrap();
    let status = child.wait().unwrap();
    assert!(!status.success());
    assert!(qemu::temp_dirs_of(&tmp, pid).is_empty(), "temp folder left");
    for q in qemu_pids {
        assert!(
            !Path::new(&format!("/proc/{q}")).exists()
                || std::fs::read_to_string(format!("/proc/{q}/stat"))
                    .map(|s| s.contains(") Z"))
                    .unwrap_or(true),
            "QEMU {q} still running"
        );
    }
}

/// Direct children of `pid` (from /proc).
fn children_of(pid: u32) -> Vec<u32> {
    let mut out = Vec::new();
    if let Ok(dir) = std::fs::read_dir("/proc") {
        for e in dir.flatten() {
            let Ok(p) = e.file_name().to_string_lossy().parse::<u32>() else {
                continue;
            };
            if let Ok(stat) = std::fs::read_to_string(format!("/proc/{p}/stat")) {
                let after = stat.rsplit(')').next().unwrap_or("");
                let ppid = after.split_whitespace().nth(1).and_then(|s| s.parse().ok());
                if ppid == Some(pid) {
                    out.push(p);
                }
            }
        }
    }
    out
}

#[test]
fn power_cut_at_every_step_of_an_upload_commit_and_erase_ahead_leaves_old_or_new() {
    let (t1, t2, t3) = (table(1), table(2), table(3));
    let template = fresh_dir("cut-template");
    {
        let (q, mut c) = boot(&template);
        c.load(&t1.encode(), |_, _| {}).unwrap();
        c.load(&t2.encode(), |_, _| {}).unwrap();
        c.ping().unwrap();
        q.shutdown();
    }
    let image = std::fs::read(template.join(FLASH_IMAGE)).expect("image");
    let state = fresh_dir("cut");
    let reset = || {
        std::fs::write(state.join(FLASH_IMAGE), &image).unwrap();
        let _ = std::fs::remove_file(state.join("accomp-power-cut.txt"));
    };
    // What the user expects, from the protocol's reference model: t1 then t2 loaded (old),
    // and t3 on top of them (new).
    let mut model = TableHistory::default();
    model.load(&t1.encode());
    model.load(&t2.encode());
    let old = model.ids();
    model.load(&t3.encode());
    let new = model.ids();
    let check = |what: &str| {
        let _ = std::fs::remove_file(state.join("accomp-power-cut.txt"));
        let after = tables_after_boot(&state);
        assert!(
            after == old || after == new,
            "{what}: (active, previous) = {after:?}, expected {old:?} or {new:?}"
        );
        after
    };

    // 1. Killed between requests: after Begin, mid-transfer, with all chunks in, right after
    //    the Commit request was sent.
    let bytes = t3.encode();
    for stop_after in [1usize, 4, 8, 9] {
        reset();
        let (q, mut c) = boot(&state);
        let uid = c.new_upload_id();
        let reqs = upload_requests(uid, &bytes);
        for (k, r) in reqs.enumerate() {
            if k + 1 == stop_after && k + 1 == 9 {
                // The commit is sent but its answer not awaited: the kill races the commit.
                c.send(r).unwrap();
                break;
            }
            c.call(r).unwrap();
            if k + 1 == stop_after {
                break;
            }
        }
        q.shutdown(); // SIGKILL: the power goes
        check(&format!("killed after request {stop_after}"));
    }

    // 2. Power cut inside every flash operation the upload causes (the image program, the
    //    commit marker, the erase ahead after the commit; the boot's erase ahead finds the
    //    spare blank), with none and half of the operation reaching the cells.
    let mut cut_points = 0;
    let mut saw_new_after_cut = false;
    for op in 0.. {
        let mut completed = true;
        for quarters in [0, 2] {
            reset();
            std::fs::write(
                state.join("accomp-power-cut.txt"),
                format!("{op} {quarters}"),
            )
            .unwrap();
            let (mut q, mut c) = boot(&state);
            c.timeout = Duration::from_secs(3);
            let loaded = c.load(&bytes, |_, _| {});
            // Give the erase ahead after the commit its chance.
            let _ = c.ping();
            let code = q.wait_exit(Duration::from_secs(2));
            q.shutdown();
            if code == Some(120) {
                completed = false;
                cut_points += 1;
                let after = check(&format!("cut in flash operation {op} ({quarters}/4)"));
                saw_new_after_cut |= after == new;
            } else {
                assert!(loaded.is_ok(), "uncut upload failed: {loaded:?}");
                assert_eq!(check("uncut"), new);
            }
        }
        if completed {
            break;
        }
        assert!(op < 20, "the upload never completes");
    }
    eprintln!("system-level power cuts: {cut_points} cut points + 4 request-level kills");
    // At least: image, marker, erase ahead after the commit (× 2 tears). The spare at boot
    // (C, never written) reads blank, so the boot's erase ahead erases nothing.
    assert!(cut_points >= 6, "only {cut_points} cut points");
    assert!(saw_new_after_cut, "no cut fell after the commit marker");
}
