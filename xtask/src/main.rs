//! Build, test and demo orchestration: `cargo xtask test | demo | firmware | qemu-check`.
//!
//! Everything CI runs goes through here, so that the README's two commands are the whole set-up on
//! a fresh Debian machine with only rustup: the toolchain comes from rust-toolchain.toml; the thumb
//! target and the components the checks use are added with rustup when the active toolchain lacks
//! them (rust-toolchain.toml only adds them when rustup installs the toolchain itself);
//! qemu-system-arm is installed with apt-get when running as root.

use std::{
    env,
    path::{Path, PathBuf},
    process::{Command, ExitCode},
};

const FIRMWARE_TARGET: &str = "thumbv7em-none-eabihf";
const FIRMWARE_BIN: &str = "accomp-fw";
/// Components `cargo xtask test` runs (fmt and clippy steps).
const COMPONENTS: [&str; 2] = ["rustfmt", "clippy"];

fn main() -> ExitCode {
    let args: Vec<String> = env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("test") => test(),
        Some("demo") => demo(&args[1..]),
        Some("firmware") => build_firmware().map(|elf| println!("{}", elf.display())),
        Some("qemu-check") => ensure_qemu(),
        Some("toolchain") => ensure_toolchain(),
        _ => {
            eprintln!(
                "usage: cargo xtask <command>\n\n\
                 commands:\n  \
                 demo        build the firmware, boot it in QEMU and run the simulated stability test\n  \
                 test        every test: fmt, clippy, host tests, firmware build, QEMU end-to-end\n  \
                 firmware    build the QEMU-board firmware ELF and print its path\n  \
                 qemu-check  make sure qemu-system-arm is installed\n  \
                 toolchain   add the thumb target and the rustfmt/clippy components when missing"
            );
            Err("no command".into())
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: error: {e}");
            ExitCode::FAILURE
        }
    }
}

type Result<T> = std::result::Result<T, String>;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."))
}

fn cargo() -> Command {
    let mut c = Command::new(env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
    c.current_dir(root());
    c
}

fn run(step: &str, mut cmd: Command) -> Result<()> {
    eprintln!("\n==> {step}");
    let status = cmd
        .status()
        .map_err(|e| format!("{step}: could not start: {e}"))?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("{step} failed ({status})"))
    }
}

/// Path of the firmware ELF that the host tools boot in QEMU (documented in the README).
fn firmware_elf() -> PathBuf {
    let target_dir = env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| root().join("target"));
    target_dir
        .join(FIRMWARE_TARGET)
        .join("release")
        .join(FIRMWARE_BIN)
}

/// `rustup <args>` run from the workspace root, so that it answers for the toolchain pinned by
/// rust-toolchain.toml (or the one `RUSTUP_TOOLCHAIN` names when cargo was started through rustup).
fn rustup() -> Command {
    let mut c = Command::new("rustup");
    c.current_dir(root());
    c
}

/// The first word of each line of `rustup <list...> --installed` (`clippy-x86_64-…` stays whole).
fn rustup_installed(what: &str) -> Result<Vec<String>> {
    let out = rustup()
        .args([what, "list", "--installed"])
        .output()
        .map_err(|e| {
            format!(
                "rustup {what} list: could not start rustup ({e}); install the \
                 {FIRMWARE_TARGET} target and the {} components by hand",
                COMPONENTS.join("/")
            )
        })?;
    if !out.status.success() {
        return Err(format!(
            "rustup {what} list --installed failed: {}",
            String::from_utf8_lossy(&out.stderr).trim()
        ));
    }
    Ok(String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| l.split_whitespace().next().map(str::to_owned))
        .collect())
}

/// A component line (`clippy-x86_64-unknown-linux-gnu`, `rustfmt`, `clippy-preview`) names `name`.
fn component_installed(installed: &[String], name: &str) -> bool {
    installed.iter().any(|c| {
        c == name
            || c.strip_prefix(name)
                .is_some_and(|rest| rest.starts_with('-'))
    })
}

/// The thumb target and the components must be in the *active* toolchain: rust-toolchain.toml
/// only installs them when rustup installs the toolchain itself, so a machine that already had
/// the pinned version fails with "can't find crate for `core`" (#11). Added with rustup when
/// missing, like qemu and flip-link.
fn ensure_toolchain() -> Result<()> {
    let targets = rustup_installed("target")?;
    if !targets.iter().any(|t| t == FIRMWARE_TARGET) {
        let mut add = rustup();
        add.args(["target", "add", FIRMWARE_TARGET]);
        run(
            &format!("rustup target add {FIRMWARE_TARGET} (missing from the active toolchain)"),
            add,
        )?;
    }
    let components = rustup_installed("component")?;
    let missing: Vec<&str> = COMPONENTS
        .into_iter()
        .filter(|c| !component_installed(&components, c))
        .collect();
    if !missing.is_empty() {
        let mut add = rustup();
        add.args(["component", "add"]).args(&missing);
        run(
            &format!(
                "rustup component add {} (missing from the active toolchain)",
                missing.join(" ")
            ),
            add,
        )?;
    }
    Ok(())
}

/// flip-link is the firmware's linker (.cargo/config.toml); installed with cargo when missing.
fn ensure_flip_link() -> Result<()> {
    let have = Command::new("flip-link")
        .arg("--version")
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    if have {
        return Ok(());
    }
    let mut c = Command::new(env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
    c.args(["install", "flip-link", "--locked"]);
    run("cargo install flip-link (firmware linker)", c)
}

/// `cargo build --release` of the firmware binary for the thumb target, plus board features.
fn firmware_build(board_args: &[&str]) -> Result<Command> {
    ensure_toolchain()?;
    ensure_flip_link()?;
    let mut c = cargo();
    c.args([
        "build",
        "--release",
        "--package",
        "accomp",
        "--bin",
        FIRMWARE_BIN,
        "--target",
        FIRMWARE_TARGET,
    ])
    .args(board_args);
    Ok(c)
}

/// Builds the front-end board firmware (it cannot run here, but it must build) and keeps its ELF
/// next to the QEMU one as `accomp-fw-frontend`.
fn build_frontend_firmware() -> Result<PathBuf> {
    let c = firmware_build(&["--no-default-features", "--features", "board-frontend"])?;
    run("firmware release build, board-frontend", c)?;
    let elf = firmware_elf();
    let kept = elf.with_file_name(format!("{FIRMWARE_BIN}-frontend"));
    std::fs::copy(&elf, &kept).map_err(|e| format!("keeping the frontend ELF: {e}"))?;
    Ok(kept)
}

fn build_firmware() -> Result<PathBuf> {
    let c = firmware_build(&[])?;
    run(
        "firmware release build, board-qemu (thumbv7em-none-eabihf)",
        c,
    )?;
    Ok(firmware_elf())
}

/// Mangled-name prefix of portable-atomic's lock-based fallback (its global seqlock spin locks).
/// Those locks are not interrupt-safe: an interrupt that preempts their holder and takes the same
/// lock spins forever. The firmware froze so in QEMU (SysTick's 64-bit tick counter, about one
/// run in 50) until the 64-bit atomics were switched to masking interrupts (Cargo.toml,
/// `portable-atomic` features). This keeps any dependency from bringing them back.
const INTERRUPT_UNSAFE_ATOMICS: &[u8] = b"portable_atomic3imp8fallback";

/// Whether an ELF image holds a symbol of the lock-based atomic fallback.
fn has_interrupt_unsafe_atomics(image: &[u8]) -> bool {
    image
        .windows(INTERRUPT_UNSAFE_ATOMICS.len())
        .any(|w| w == INTERRUPT_UNSAFE_ATOMICS)
}

/// Refuses a firmware ELF that uses lock-based atomics (see [`INTERRUPT_UNSAFE_ATOMICS`]).
fn check_firmware_atomics(elf: &Path) -> Result<()> {
    let image = std::fs::read(elf).map_err(|e| format!("reading {}: {e}", elf.display()))?;
    if has_interrupt_unsafe_atomics(&image) {
        return Err(format!(
            "{} links portable-atomic's lock-based fallback (a spin lock an interrupt can \
             deadlock on); enable its `unsafe-assume-single-core` feature for the firmware",
            elf.display()
        ));
    }
    eprintln!(
        "==> {}: no lock-based atomics (interrupt-safe)",
        elf.display()
    );
    Ok(())
}

fn is_root() -> bool {
    Command::new("id")
        .arg("-u")
        .output()
        .map(|o| String::from_utf8_lossy(&o.stdout).trim() == "0")
        .unwrap_or(false)
}

fn have_qemu() -> bool {
    Command::new("qemu-system-arm")
        .arg("--version")
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false)
}

/// qemu-system-arm is required: installed when we are root, otherwise a loud failure with the
/// one line that fixes it. Never a silent skip.
fn ensure_qemu() -> Result<()> {
    if have_qemu() {
        return Ok(());
    }
    if !is_root() {
        return Err("qemu-system-arm is missing; install it with: \
                    sudo apt-get install -y --no-install-recommends qemu-system-arm"
            .into());
    }
    eprintln!("==> installing qemu-system-arm with apt-get");
    let mut update = Command::new("apt-get");
    update.args(["update", "-qq"]);
    run("apt-get update", update)?;
    let mut install = Command::new("apt-get");
    install
        .args([
            "install",
            "-y",
            "-qq",
            "--no-install-recommends",
            "qemu-system-arm",
        ])
        .env("DEBIAN_FRONTEND", "noninteractive");
    run("apt-get install qemu-system-arm", install)?;
    if have_qemu() {
        Ok(())
    } else {
        Err("qemu-system-arm still not runnable after apt-get install".into())
    }
}

/// Cargo for the test run's builds. A test run compiles each crate once, so incremental
/// compilation only costs: its caches were 780 MB of a clean run's 2.4 GB target folder, and CI's
/// disk ran out (docs/benchmarks.md, "Build footprint").
fn cargo_once() -> Command {
    let mut c = cargo();
    c.env("CARGO_INCREMENTAL", "0");
    c
}

/// `cargo clippy <what> -- -D warnings`: every lint is an error.
fn clippy(step: &str, what: &[&str]) -> Result<()> {
    let mut c = cargo_once();
    c.arg("clippy").args(what).args(["--", "-D", "warnings"]);
    run(step, c)
}

fn test() -> Result<()> {
    ensure_toolchain()?;
    ensure_qemu()?;
    let mut fmt = cargo();
    fmt.args(["fmt", "--all", "--check"]);
    run("cargo fmt --check", fmt)?;

    clippy(
        "clippy (host, all targets)",
        &["--workspace", "--all-targets"],
    )?;
    clippy(
        "clippy (firmware)",
        &[
            "--package",
            "accomp",
            "--target",
            FIRMWARE_TARGET,
            "--release",
        ],
    )?;

    // Frontend first: both builds write the same ELF path, and the QEMU one must be left there.
    let frontend = build_frontend_firmware()?;
    check_firmware_atomics(&frontend)?;
    let elf = build_firmware()?;
    check_firmware_atomics(&elf)?;

    let mut tests = cargo_once();
    tests
        .args(["test", "--workspace"])
        .env("ACCOMP_FIRMWARE_ELF", &elf);
    run("host tests (workspace)", tests)?;
    aqg_record_test()?;
    eprintln!("\nxtask: all checks passed");
    Ok(())
}

/// The AQG gravimeter record has no licence, so it is not in the repository and its discovery
/// test is `#[ignore]`d (listed as ignored above). It runs here when the record is present: at
/// the path `$ACCOMP_AQG_RECORD` names (data/README.md says where to get it).
/// Otherwise this says plainly that it did not run.
fn aqg_record_test() -> Result<()> {
    const FILE: &str = "aqg_quantum_gravimeter_2020-07-31_12h.csv";
    let record = env::var_os("ACCOMP_AQG_RECORD")
        .map(PathBuf::from)
        .filter(|p| p.is_file());
    let Some(record) = record else {
        eprintln!(
            "\n==> SKIPPED (did not run): discover_measured::aqg_record_names_the_earth_tide — \
             the AQG record {FILE} is not in the repository (no licence) and was not found at \
             $ACCOMP_AQG_RECORD (set it to the record's path)"
        );
        return Ok(());
    };
    let mut c = cargo_once();
    c.args([
        "test",
        "--package",
        "accomp-host",
        "--test",
        "discover_measured",
        "--",
        "--ignored",
        "aqg_record_names_the_earth_tide",
    ])
    .env("ACCOMP_AQG_RECORD", &record);
    run(
        &format!(
            "measured-data test on the AQG record ({})",
            record.display()
        ),
        c,
    )
}

/// `cargo xtask demo [accomp demo options]`: builds the firmware, then `accomp demo` boots it in
/// QEMU, fits Table 1, streams the simulated paper-1g and paper-0g tests through it and prints the
/// report (log, figures and report files under target/demo/).
fn demo(args: &[String]) -> Result<()> {
    ensure_qemu()?;
    let elf = build_firmware()?;
    eprintln!("firmware ELF: {}", elf.display());
    let table1 = root().join("data/jn06_a12124_coefficients_vs_temperature.csv");
    if !table1.is_file() {
        return Err(format!(
            "{} not found: the repository's data/ folder is incomplete",
            table1.display()
        ));
    }
    let mut run_demo = cargo();
    run_demo
        .args([
            "run",
            "--release",
            "--quiet",
            "--package",
            "accomp-host",
            "--",
            "demo",
            "--table1",
        ])
        .arg(&table1)
        .arg("--firmware")
        .arg(&elf)
        .args(args);
    run(
        "accomp demo (firmware in QEMU, paper-1g and paper-0g)",
        run_demo,
    )
}

#[cfg(test)]
mod tests {
    use super::{component_installed, has_interrupt_unsafe_atomics};

    #[test]
    fn a_firmware_image_with_the_lock_based_atomic_fallback_is_refused() {
        // The symbol as rustc's legacy mangling writes it into the ELF's string table.
        let mut image = vec![0u8; 64];
        image.extend_from_slice(b"_ZN15portable_atomic3imp8fallback4lock5LOCKS17h0123E");
        assert!(has_interrupt_unsafe_atomics(&image));
        // The interrupt-masking implementation lives in `imp::interrupt`: allowed.
        let ok = b"_ZN15portable_atomic3imp9interrupt8AtomicU649fetch_add17h0E";
        assert!(!has_interrupt_unsafe_atomics(ok));
    }

    #[test]
    fn a_component_is_found_by_its_name_before_the_host_triple() {
        let listed: Vec<String> = [
            "cargo-x86_64-unknown-linux-gnu",
            "rustfmt-x86_64-unknown-linux-gnu",
        ]
        .map(String::from)
        .to_vec();
        assert!(component_installed(&listed, "rustfmt"));
        assert!(!component_installed(&listed, "clippy"));
        // `rust` must not match `rust-docs…`/`rustfmt…` by prefix alone.
        assert!(!component_installed(&listed, "rustf"));
    }
}
