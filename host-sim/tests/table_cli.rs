//! `accomp table show|verify` on files written by the core encoder, good and corrupted.

use accomp::compensation::{CoefficientModels, ThermalCompensator};
use accomp::poly::{TempPoly, TemperatureScale};
use accomp::table::*;
use accomp::units::*;
use std::path::PathBuf;

#[path = "common/cli.rs"]
mod cli;
#[path = "common/scratch.rs"]
mod scratch;

use cli::{accomp, accomp_ok};
use scratch::Scratch;

fn table() -> CalibrationTable {
    let scale = TemperatureScale::for_range(Celsius(30.0), Celsius(65.0)).unwrap();
    CalibrationTable::with_board_defaults(
        "SNJ-103",
        CalibrationDate {
            year: 2026,
            month: 11,
            day: 21,
        },
        ThermalCompensator {
            scale,
            reference: Celsius(60.0),
            models: CoefficientModels {
                bias_g: TempPoly::from_coeffs(&[0.0056, 0.0009]).unwrap(),
                scale_factor_v_per_g: TempPoly::from_coeffs(&[1.3267, 4e-4, -1e-5]).unwrap(),
                nonlinearity_g_per_g2: TempPoly::constant(1e-6),
                misalignment_p_rad: TempPoly::constant(2.0 * RAD_PER_ARCMIN),
                misalignment_o_rad: TempPoly::constant(0.0),
            },
        },
    )
}

fn write(dir: &Scratch, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.path(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

#[test]
fn show_json_reports_the_tables_fields_in_lab_units() {
    let t = table();
    let dir = Scratch::new("table-cli");
    let p = write(&dir, "good.acal", &t.encode());
    let out = accomp_ok(&["table", "show", "--json", p.to_str().unwrap()], &[]);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["serial"], "SNJ-103");
    assert_eq!(v["id"], format!("{:08x}", t.id()));
    assert_eq!(v["k1_v_per_g"]["order"], 2);
    // δp stored in rad, shown in arcmin: 2.0 arcmin.
    let dp = v["delta_p_arcmin"]["at_reference"].as_f64().unwrap();
    assert!((dp - 2.0).abs() < 1e-12);
    // K0 at T0 = 60 °C: x = (60 − 47.5)/17.5, 0.0056 + 0.0009·x.
    let k0 = v["k0_g"]["at_reference"].as_f64().unwrap();
    assert!((k0 - (0.0056 + 0.0009 * 12.5 / 17.5)).abs() < 1e-15);
}

#[test]
fn verify_refuses_a_corrupted_file_with_the_named_error() {
    let mut b = table().encode();
    b[100] ^= 0x01;
    let dir = Scratch::new("table-cli");
    let p = write(&dir, "flipped.acal", &b);
    let out = accomp(&["table", "verify", p.to_str().unwrap()]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bad CRC"), "{err}");

    let p = write(&dir, "truncated.acal", &table().encode()[..200]);
    let out = accomp(&["table", "verify", p.to_str().unwrap()]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("bad length"));

    let p = write(&dir, "good2.acal", &table().encode());
    let out = accomp(&["table", "verify", p.to_str().unwrap()]);
    assert!(out.status.success());
}
