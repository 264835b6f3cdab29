//! The written scenario is the twin: `discover --simulate --write-scenario` writes the extended
//! twin, and `accomp simulate FILE --seed k` (the real binary) reproduces member k of the
//! extended ensemble bit for bit; a missing driver file is a named error.

use accomp_host::discover::import::{self, Dataset, DatasetOptions, Format};
use accomp_host::discover::select;
use accomp_host::discover::simulate::{simulate_dataset, write_scenario};
use std::path::Path;

const GMETROLOGY: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../data/measured/gmetrology_relative_gravimeter_2021-06-08_51d.tsf"
);

/// Twelve days of the gMetrology record on 15 000 points (keeps the run to a few seconds).
fn record() -> Dataset {
    let path = Path::new(GMETROLOGY);
    assert!(path.is_file(), "{} missing", path.display());
    let (log, _) = import::load(path, Format::Auto).expect("record");
    let opts = DatasetOptions {
        max_points: 15_000,
        ..DatasetOptions::default()
    };
    let mut ds = import::dataset_from_log(&log, &opts).expect("dataset");
    let n = ds.t_s.iter().take_while(|&&t| t < 12.0 * 86_400.0).count();
    ds.t_s.truncate(n);
    ds.y.truncate(n);
    ds.segment_start.truncate(n);
    for c in &mut ds.channels {
        c.values.truncate(n);
    }
    ds
}

fn member_from_cli(toml: &Path, seed: u64, out: &Path) -> Result<Vec<f64>, String> {
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_accomp"))
        .args([
            "simulate",
            &toml.to_string_lossy(),
            "--seed",
            &seed.to_string(),
            "-o",
        ])
        .arg(out)
        .env("RUST_BACKTRACE", "0")
        .output()
        .expect("run accomp");
    if !o.status.success() {
        return Err(String::from_utf8_lossy(&o.stderr).into_owned());
    }
    let text = std::fs::read_to_string(out).expect("member file");
    Ok(text
        .lines()
        .filter(|l| !l.starts_with('#'))
        .skip(1)
        .map(|l| {
            l.split(',')
                .nth(1)
                .expect("value")
                .parse::<f64>()
                .expect("number")
        })
        .collect())
}

#[test]
fn accomp_simulate_of_the_written_scenario_reproduces_ensemble_member_k() {
    let ds = record();
    let mut s = simulate_dataset(&ds, None, 4, &select::Config::default()).expect("simulate");
    assert!(
        s.written_twin.is_some(),
        "no noise family: {:?}",
        s.warnings
    );
    let dir = std::env::temp_dir().join(format!("accomp-twin-written-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let toml = dir.join("ext.toml");
    write_scenario(&mut s, Some(&toml)).expect("write");
    assert!(dir.join("ext.drivers.csv").is_file());
    for k in [1u64, 2] {
        let y = member_from_cli(&toml, k, &dir.join(format!("m{k}.csv"))).expect("member");
        assert_eq!(y.len(), ds.len());
        let v = s.member_views(&ds, &y);
        // Bit-identical to the ensemble's member k, and not member k + 1.
        assert_eq!(v, s.members_after[k as usize - 1], "member {k}");
        assert_ne!(
            v,
            s.members_after[k as usize],
            "member {k} equals member {}",
            k + 1
        );
    }
    // The driver file missing: a named error.
    std::fs::rename(dir.join("ext.drivers.csv"), dir.join("moved.csv")).unwrap();
    let err = member_from_cli(&toml, 1, &dir.join("m9.csv")).unwrap_err();
    assert!(
        err.contains("twin driver file") && err.contains("is missing"),
        "{err}"
    );
    // A malformed [twin] section: a named error.
    let text = std::fs::read_to_string(&toml).unwrap();
    std::fs::write(
        &toml,
        text.replacen("fixed_effects = ", "fixed_effects = 99 #", 1),
    )
    .unwrap();
    let err = member_from_cli(&toml, 1, &dir.join("m9.csv")).unwrap_err();
    assert!(
        err.contains("[twin]") && err.contains("fixed_effects"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
