//! `discover --simulate` on a record with a hidden effect: the mismatch between the record and
//! its simulated twin must appear in the band where the hidden effect lives, and vanish once the
//! twin is extended by what the catalogue search names.
//!
//! Non-circular: the effect is injected into the **real** gMetrology record (its own noise,
//! drift and tide errors — not the simulator's noise), with a shape the catalogue does not
//! parametrise (a non-sinusoidal, slowly amplitude-modulated 5.3 h wave: `periodic` is one
//! sinusoid of constant amplitude). The tool is not told what was hidden. Cheap: the first
//! 12 days binned to ~5 min, 8 members.

use accomp_host::discover::import::{self, Dataset, DatasetOptions, Format};
use accomp_host::discover::select;
use accomp_host::discover::simulate::cli::{simulate_dataset, write_scenario};
use accomp_host::discover::simulate::mismatch::Quantity;
use accomp_host::discover::simulate::Simulation;
use std::path::Path;

const GMETROLOGY: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../data/measured/gmetrology_relative_gravimeter_2021-06-08_51d.tsf"
);

/// Hidden period (s) and amplitude (mGal): 5.3 h ≈ 4.5 cycles/day, between the ter- and
/// quarter-diurnal tides; 6 µGal, a few times the residual's noise in that band.
const HIDDEN_PERIOD_S: f64 = 5.3 * 3600.0;
const HIDDEN_AMPLITUDE: f64 = 0.006;
const DAYS: f64 = 12.0;

fn record() -> Dataset {
    let path = Path::new(GMETROLOGY);
    assert!(
        path.is_file(),
        "{} missing: this test did not run",
        path.display()
    );
    let (log, bad) = import::load(path, Format::Auto).expect("record");
    assert!(bad.is_empty());
    let opts = DatasetOptions {
        max_points: 15_000,
        ..DatasetOptions::default()
    };
    let mut ds = import::dataset_from_log(&log, &opts).expect("dataset");
    let n = ds.t_s.iter().take_while(|&&t| t < DAYS * 86_400.0).count();
    ds.t_s.truncate(n);
    ds.y.truncate(n);
    ds.segment_start.truncate(n);
    for c in &mut ds.channels {
        c.values.truncate(n);
    }
    ds
}

/// A rounded, skewed wave (fundamental + 2nd harmonic) whose amplitude drifts by ±25 % over the
/// record.
fn hidden(t: f64) -> f64 {
    let w = 2.0 * std::f64::consts::PI / HIDDEN_PERIOD_S;
    let env = 1.0 + 0.25 * (2.0 * std::f64::consts::PI * t / (DAYS * 86_400.0 * 1.7)).sin();
    HIDDEN_AMPLITUDE * env * ((w * t).sin() + 0.3 * (2.0 * w * t + 1.0).sin())
}

/// PSD mismatches above the envelope that contain the frequency f (cycles/day).
fn psd_above_at(s: &Simulation, after: bool, f_cpd: f64) -> usize {
    let c = if after { &s.after } else { &s.before };
    c.mismatches
        .iter()
        .filter(|m| m.quantity == Quantity::Psd && m.direction == "above")
        .filter(|m| {
            // The range is given by band centres: widen by half a band either side.
            let half = 10f64.powf(0.5 / 8.0);
            m.from / half <= f_cpd && f_cpd <= m.to * half
        })
        .count()
}

#[test]
fn hidden_wave_in_the_real_record_is_a_mismatch_in_its_band_that_the_extension_removes() {
    let mut ds = record();
    for (y, &t) in ds.y.iter_mut().zip(&ds.t_s) {
        *y += hidden(t);
    }
    let s = simulate_dataset(&ds, None, 8, &select::Config::default()).expect("simulate");
    let unit = ds.output_unit.clone();
    eprintln!(
        "{}",
        accomp_host::discover::simulate::output::text(&s, &unit)
    );
    let f_hidden = 86_400.0 / HIDDEN_PERIOD_S;
    assert_eq!(
        psd_above_at(&s, false, f_hidden),
        1,
        "no PSD mismatch at the hidden {f_hidden:.2} cycles/day before the extension"
    );
    assert_eq!(
        psd_above_at(&s, true, f_hidden),
        0,
        "the mismatch at {f_hidden:.2} cycles/day is still there after the extension"
    );
    // The cause: the mismatch at the hidden band is explained by an accepted periodic line at
    // its period (within 2 %).
    let idx = s
        .before
        .mismatches
        .iter()
        .position(|m| {
            m.quantity == Quantity::Psd
                && m.direction == "above"
                && m.from / 1.2 <= f_hidden
                && f_hidden <= m.to * 1.2
        })
        .expect("the mismatch");
    let line = s
        .cause
        .selection
        .accepted
        .iter()
        .find(|a| {
            a.effect.name() == "periodic" && (a.theta.value / HIDDEN_PERIOD_S - 1.0).abs() < 0.02
        })
        .expect("a periodic line at the hidden period");
    assert!(line.theta.value > 0.0);
    assert!(
        s.explained_by
            .iter()
            .any(|(n, idxs)| n.starts_with("periodic") && idxs.contains(&idx)),
        "{:?}",
        s.explained_by
    );
    // The gain: lower out-of-sample residual after.
    assert!(s.after_scores.residual_std_out_of_sample < s.before_scores.residual_std_out_of_sample);
    // The extended scenario is written and `accomp simulate` runs it as is; it holds the line.
    let dir = std::env::temp_dir().join(format!("accomp-discover-simulate-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let toml = dir.join("extended.toml");
    let mut s = s;
    write_scenario(&mut s, Some(&toml)).expect("write scenario");
    let text = std::fs::read_to_string(&toml).unwrap();
    let sc = accomp_host::sim::scenario::Scenario::from_toml(&text).expect("scenario parses");
    assert!(sc.effects.iter().any(|e| matches!(e,
        accomp_host::sim::effects::ScenarioEffect::Periodic { period_s, .. }
            if (period_s / HIDDEN_PERIOD_S - 1.0).abs() < 0.02)));
    let out = dir.join("extended.csv");
    let st = std::process::Command::new(env!("CARGO_BIN_EXE_accomp"))
        .args(["simulate", toml.to_str().unwrap(), "--days", "0.5", "-o"])
        .arg(&out)
        .status()
        .expect("accomp simulate");
    assert!(st.success(), "accomp simulate refused the written scenario");
    let log = std::fs::read_to_string(&out).unwrap();
    assert!(
        log.lines().any(|l| l.starts_with("time_s,gravity_mgal")),
        "no gravity column"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn without_the_hidden_wave_there_is_no_mismatch_in_that_band() {
    let ds = record();
    let s = simulate_dataset(&ds, None, 8, &select::Config::default()).expect("simulate");
    let f_hidden = 86_400.0 / HIDDEN_PERIOD_S;
    assert_eq!(
        psd_above_at(&s, false, f_hidden),
        0,
        "{}",
        accomp_host::discover::simulate::output::text(&s, &ds.output_unit)
    );
}
