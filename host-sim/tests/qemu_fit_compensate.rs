//! Issue 4's closing path, through the CLI only: a table fitted by `accomp fit` from the paper's
//! Table 1 is loaded into the firmware in QEMU by `accomp compensate --target qemu`, and the
//! firmware's results are the ones the same core computes on the PC (`--target host`) and
//! recover the input the samples were made from.

use accomp::model::CrossAxis;
use accomp::table::CalibrationTable;
use accomp::units::{Celsius, Gs};
use accomp_host::device::firmware_path;
use std::path::Path;

#[path = "common/cli.rs"]
mod cli;
#[path = "common/scratch.rs"]
mod scratch;

const TABLE1: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../data/jn06_a12124_coefficients_vs_temperature.csv"
);

fn accomp(dir: &Path, args: &[&str]) -> String {
    // This test's own emulated board, not the user's persistent one.
    let board = dir.join("board");
    let out = cli::accomp_ok(args, &[(accomp_host::device::qemu::STATE_ENV, &board)]);
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Column `name` of a CSV written by `accomp compensate`.
fn column(text: &str, name: &str) -> Vec<String> {
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let i = header
        .iter()
        .position(|h| *h == name)
        .expect("column present");
    lines
        .map(|l| l.split(',').nth(i).unwrap_or("").to_owned())
        .collect()
}

#[test]
fn a_table_fitted_from_table_1_is_loaded_into_qemu_and_used_by_compensate() {
    assert!(Path::new(TABLE1).exists(), "Table 1 data missing: {TABLE1}");
    let elf = firmware_path(None);
    assert!(
        elf.exists(),
        "firmware ELF missing at {} (cargo xtask firmware)",
        elf.display()
    );

    let dir = scratch::Scratch::new("fit-compensate");
    let cal = dir.join("jn06.acal");
    accomp(
        &dir,
        &[
            "fit",
            TABLE1,
            "-o",
            cal.to_str().unwrap(),
            "--date",
            "2026-11-21",
        ],
    );
    let table =
        CalibrationTable::decode(&std::fs::read(&cal).unwrap()).expect("fit writes a valid table");

    // 1 g samples at temperatures across the calibrated range, made with the
    // fitted models (eq. (1) forward, which the firmware must invert).
    let temps: Vec<f64> = (0..40).map(|i| 31.0 + 0.8 * f64::from(i)).collect();
    let input = dir.join("samples.csv");
    let header = "# input_g: 1\ntime_s,output_v,temperature_c,tilt_arcsec\n";
    cli::write_csv(&input, header, temps.len(), |i| {
        let t = temps[i];
        let (k, _) = table.thermal.coefficients_at(Celsius(t)).unwrap();
        let e = k.output(Gs(1.0), CrossAxis::default());
        format!("{},{:.12},{t},0.0", i as f64 * 60.0, e.0)
    });

    let run = |target: &str, out: &Path| {
        let mut args = cli::compensate_args(
            target,
            cal.to_str().unwrap(),
            input.to_str().unwrap(),
            out.to_str().unwrap(),
        );
        args.extend(["--firmware", elf.to_str().unwrap()]);
        accomp(&dir, &args);
        std::fs::read_to_string(out).unwrap()
    };
    let qemu = run("qemu", &dir.join("qemu.csv"));
    let host = run("host", &dir.join("host.csv"));

    let a_qemu = column(&qemu, "a_i_exact_g");
    assert_eq!(a_qemu.len(), temps.len());
    assert_eq!(
        a_qemu,
        column(&host, "a_i_exact_g"),
        "firmware and host core differ"
    );
    assert_eq!(column(&qemu, "status"), column(&host, "status"));
    for (t, a) in temps.iter().zip(&a_qemu) {
        let a: f64 = a.parse().expect("a number, not a fault");
        // Quantization of the raw codes (ADS1262 1.2 nV, AD7124 RTD ≈ 5e-5 °C → ≈ 3e-9 g through
        // dK0/dT) bounds the round trip; 2e-8 g leaves room and still catches a wrong table
        // (the bias alone moves 5e-5 g per °C).
        assert!((a - 1.0).abs() < 2e-8, "T = {t} °C: a_i = {a}");
    }
}
