//! Discovery on the two measured gravimeter records. Findings are written up in
//! docs/discovery.md.
//!
//! - gMetrology (MIT licence) ships in the repository's data/measured/ and always runs.
//! - The AQG record has no licence, so it is never copied into the project: its test is
//!   `#[ignore]`d with the reason (the default run lists it as *ignored*, never as passed) and
//!   `cargo xtask test` runs it with `--ignored` when the record is present — at
//!   `$ACCOMP_AQG_RECORD` or in the developers' `../shared/data/measured/` beside the clone. Run
//!   by hand without the record, it fails and says so.

use accomp_host::discover::import::{DatasetOptions, Format};
use accomp_host::discover::{discover_path, select};
use std::path::{Path, PathBuf};

const GMETROLOGY: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../data/measured/gmetrology_relative_gravimeter_2021-06-08_51d.tsf"
);
/// Where the developers' tree keeps the AQG record, beside the clone.
const AQG_BESIDE_CLONE: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../shared/data/measured/aqg_quantum_gravimeter_2020-07-31_12h.csv"
);

fn require(path: &Path) -> &Path {
    assert!(
        path.is_file(),
        "measured record {} missing: this test did not run",
        path.display()
    );
    path
}

/// The AQG record: `$ACCOMP_AQG_RECORD`, else the developers' tree beside the clone.
fn aqg_record() -> PathBuf {
    std::env::var_os("ACCOMP_AQG_RECORD")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(AQG_BESIDE_CLONE))
}

fn tidal_factor(d: &accomp_host::discover::Discovery) -> Option<(f64, f64)> {
    d.selection
        .accepted
        .iter()
        .find(|a| a.effect.name() == "tidal_gravity")
        .and_then(|a| a.params.iter().find(|(k, _)| k == "amplitude_factor"))
        .map(|(_, p)| (p.value, p.sigma))
}

#[test]
fn gmetrology_record_names_the_earth_tide_with_a_gravimetric_factor_near_one() {
    let (d, bad) = discover_path(
        require(Path::new(GMETROLOGY)),
        Format::Auto,
        &DatasetOptions::default(),
        None,
        &select::Config::default(),
    )
    .expect("discovery");
    eprintln!("{}", accomp_host::discover::report::text(&d));
    assert!(bad.is_empty(), "{bad:?}");
    // The wave-group analysis runs inside discover and reaches the JSON (its figures are
    // tested in tidal_gmetrology.rs).
    let j = accomp_host::discover::report::json(&d);
    let t = &j["tidal_analysis"];
    assert_eq!(t["groups"].as_array().map(Vec::len), Some(10), "{t}");
    assert!(t["groups"][6]["amplitude_factor_rigid_earth"]["value"].is_number());
    assert!(t["groups"][6]["amplitude_factor_vs_elastic_model"]["sigma"].is_number());
    assert!(t["delay"]["delay_s"]["value"].is_number());
    assert!(t["pressure_admittance"]["nm_s2_per_hpa"]["sigma"].is_number());
    // The Beijing-time stamps were moved to UTC: the tide only fits with the right clock.
    let (f, _) = tidal_factor(&d).expect("tidal_gravity not named on the gMetrology record");
    // The tide model already carries the elastic factor δ ≈ 1.16; a spring gravimeter's
    // calibration leaves the measured factor within ±15 % of 1.
    assert!((0.85..1.15).contains(&f), "amplitude_factor {f}");
    // The tide is ~2/3 of the baseline residual there: naming it must cut the held-out
    // residual by more than 30 % on its own.
    let tide = d
        .selection
        .accepted
        .iter()
        .find(|a| a.effect.name() == "tidal_gravity")
        .expect("tide");
    assert!(
        tide.gain_out_of_sample() > 0.3,
        "tide gain {}",
        tide.gain_out_of_sample()
    );
    assert!(d.selection.final_cv.raw < 0.6 * d.selection.baseline_cv.raw);
}

#[test]
#[ignore = "needs the unlicensed AQG record (not in the repository): set ACCOMP_AQG_RECORD or keep \
            ../shared beside the clone; `cargo xtask test` runs it when present"]
fn aqg_record_names_the_earth_tide() {
    let aqg = aqg_record();
    let (d, _) = discover_path(
        require(&aqg),
        Format::Auto,
        &DatasetOptions::default(),
        None,
        &select::Config::default(),
    )
    .expect("discovery");
    eprintln!("{}", accomp_host::discover::report::text(&d));
    let (f, s) = tidal_factor(&d).expect("tidal_gravity not named on the AQG record");
    assert!(
        (f - 1.0).abs() < 3.0 * s.max(0.05),
        "amplitude_factor {f} ± {s}"
    );
    assert!(d.selection.final_cv.raw < d.selection.baseline_cv.raw);
}
