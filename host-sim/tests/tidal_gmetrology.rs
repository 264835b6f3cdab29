//! Tidal analysis (wave groups, delay, pressure admittance) of the measured gMetrology spring
//! gravimeter record in data/measured/ (George-Gou/gMetrology, MIT; 33.98° N, 116.79° E, 51 days
//! of 1-min data).
//! There is no truth for a real record: the test asserts that what comes out is physically sane
//! (δ of a mid-latitude station plus loading and calibration, a delay of minutes at most that
//! one value explains in all bands, a barometric admittance of the usual sign and size) and
//! that every figure carries an uncertainty. The figures are in docs/tide.md.

use accomp_host::discover::import::{dataset_from_log, load, DatasetOptions, Format};
use accomp_host::discover::tidal::{analyse, TidalAnalysis};
use std::path::Path;

const GMETROLOGY: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../data/measured/gmetrology_relative_gravimeter_2021-06-08_51d.tsf"
);

fn analysis() -> TidalAnalysis {
    let p = Path::new(GMETROLOGY);
    assert!(
        p.exists(),
        "measured record {GMETROLOGY} missing: this test did not run"
    );
    let (log, bad) = load(p, Format::Auto).expect("load");
    assert!(bad.is_empty());
    let ds = dataset_from_log(&log, &DatasetOptions::default()).expect("dataset");
    let a = analyse(&ds, &ds.y, &[]).expect("analysis");
    eprintln!("{}", a.text());
    a
}

#[test]
fn gmetrology_wave_groups_delay_and_admittance_are_physically_sane() {
    let a = analysis();
    assert_eq!(a.groups.len(), 10, "51 days resolve all ten groups");
    // (group, δ range, largest σ): body tide δ ≈ 1.155–1.16 at 34° N (DDW 1999); ocean loading
    // in eastern China and a spring gravimeter's calibration move it by a few per cent.
    for (name, lo, hi, sigma_max) in [
        ("O1", 1.10, 1.25, 0.01),
        ("P1K1", 1.08, 1.22, 0.01),
        ("M2", 1.10, 1.25, 0.005),
        ("N2", 1.05, 1.30, 0.02),
        ("S2K2", 1.05, 1.30, 0.02),
        ("Q1", 1.0, 1.35, 0.05),
    ] {
        let g = a.groups.iter().find(|g| g.name == name).expect(name);
        let d = g.amplitude_factor_rigid_earth;
        assert!((lo..hi).contains(&d.value), "{name}: δ {}", d.value);
        assert!(
            d.sigma > 0.0 && d.sigma < sigma_max,
            "{name}: σ {}",
            d.sigma
        );
        // Against the model's elastic tide: within the loading + calibration margin.
        let e = g.amplitude_factor_vs_elastic_model.value;
        assert!((0.95..1.06).contains(&e), "{name}: vs model {e}");
        assert!(g.phase_deg.sigma.is_finite() && g.phase_deg.value.abs() < 5.0);
    }
    // One delay for all bands: determined to better than 30 s, consistent (χ²/dof < 3), and a
    // few minutes at most (the instrument's output filter, not a clock error of hours).
    let d = &a.delay;
    assert!(
        d.delay_s.sigma > 0.0 && d.delay_s.sigma < 30.0,
        "{:?}",
        d.delay_s
    );
    assert!(d.delay_s.value.abs() < 600.0, "{:?}", d.delay_s);
    assert!(d.chi2_per_dof < 3.0, "χ²/dof {}", d.chi2_per_dof);
    // Barometric admittance: gravity falls when pressure rises, typically −3 nm/s² per hPa.
    let p = a
        .pressure_admittance
        .as_ref()
        .expect("pressure channel")
        .nm_s2_per_hpa;
    assert!((-8.0..0.0).contains(&p.value), "{p:?}");
    assert!(p.sigma > 0.0 && p.sigma < 3.0, "{p:?}");
}
