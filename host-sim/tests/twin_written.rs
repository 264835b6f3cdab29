//! The written scenario is the twin: `discover --simulate --write-scenario` writes the extended
//! twin, and `accomp simulate FILE --seed k` (the real binary) reproduces member k of the
//! extended ensemble bit for bit, its transients and drift polynomial included (the same file
//! without them gives other members); a missing driver file is a named error. A record whose
//! selection refuses `tidal_gravity` gets the wave-group tide as `tidal_gravity (tidal
//! analysis)`: the written twin carries it, and the same file without it gives other members.

use accomp_host::discover::import::Dataset;
use accomp_host::discover::select;
use accomp_host::discover::simulate::{simulate_dataset, write_scenario};
use accomp_host::sim::scenario::Scenario;
use std::path::Path;

#[path = "common/scratch.rs"]
mod scratch;

#[path = "common/real.rs"]
mod real;

use real::part;

/// Twelve days of the gMetrology record on 15 000 points (keeps the run to a few seconds), with
/// a knock added.
fn record() -> Dataset {
    let mut ds = real::first_days(12.0, 15_000);
    // A knock at day 6 like the record's largest (−0.055 mGal over a few samples; the twelve
    // days have none of their own), so that the twin has a transient to draw.
    let at = ds.t_s.iter().take_while(|&&t| t < 6.0 * 86_400.0).count();
    for (k, dy) in [-0.02, -0.055, -0.03].iter().enumerate() {
        ds.y[at + k] += dy;
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
    let dir = scratch::Scratch::new("twin-written");
    let toml = dir.join("ext.toml");
    write_scenario(&mut s, Some(&toml)).expect("write");
    assert!(dir.join("ext.drivers.csv").is_file());
    // The twelve days have transients and a drift curve beyond the linear: the file must
    // carry both for the members to match.
    assert!(!s.transients.events.is_empty(), "no transients found");
    assert!(s.drift.order >= 2, "drift order {}", s.drift.order);
    let text = std::fs::read_to_string(&toml).unwrap();
    assert!(
        text.contains("[[twin.transients.events]]") && text.contains("[[twin.drift.legendre]]"),
        "the written twin lacks its transients or drift"
    );
    // The family has a Gauss–Markov term here: it is a term of the written noise, so that the
    // members below are drawn with it.
    assert!(
        s.family.as_ref().is_some_and(|f| f.resolved(5)),
        "no Gauss–Markov term: {:?}",
        s.family.as_ref().map(|f| &f.gm_search)
    );
    assert!(text.contains("name = \"gauss_markov\""));
    let mut members = Vec::new();
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
        members.push(y);
    }
    // The same twin written without its drift: each member differs from the file's by the
    // polynomial, Σ c_k at the last instant (P_k(1) = 1) and Σ (−1)^k c_k at the first.
    let written = Scenario::from_toml(&text).expect("the written twin parses");
    let mut no_drift = written.clone();
    no_drift.twin.as_mut().unwrap().drift = None;
    let stripped = dir.join("no_drift.toml");
    std::fs::write(&stripped, no_drift.to_toml()).unwrap();
    let y = member_from_cli(&stripped, 1, &dir.join("m1_no_drift.csv")).expect("member");
    let c: Vec<f64> = s.drift_coefficients.iter().map(|c| c.0).collect();
    let at_last: f64 = c.iter().sum();
    let at_first: f64 = c
        .iter()
        .enumerate()
        .map(|(k, v)| v * (-1f64).powi(k as i32))
        .sum();
    let n = y.len() - 1;
    let scale = c.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    for (i, want) in [(0, at_first), (n, at_last)] {
        let got = members[0][i] - y[i];
        assert!(
            (got - want).abs() <= 1e-9 * scale,
            "point {i}: member − member without drift = {got}, the polynomial {want}"
        );
    }
    assert!(
        members[0].iter().zip(&y).any(|(a, b)| a != b),
        "dropping the drift changed nothing"
    );
    // Without the transients: the noise is the same draw, the events are missing — some member
    // differs, and only at the cells of its drawn events.
    let mut no_transients = written;
    no_transients.twin.as_mut().unwrap().transients = None;
    std::fs::write(&stripped, no_transients.to_toml()).unwrap();
    let event_cells: usize = s.transients.events.iter().map(|e| e.1.len()).sum();
    let mut differing = 0;
    for (k, with) in [1u64, 2].iter().zip(&members) {
        let y = member_from_cli(&stripped, *k, &dir.join("m_no_transients.csv")).expect("member");
        let d = with.iter().zip(&y).filter(|(a, b)| a != b).count();
        assert!(
            d <= 10 * event_cells.max(1),
            "member {k}: {d} points differ, more than its events"
        );
        differing += d;
    }
    assert!(differing > 0, "dropping the transients changed no member");
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
}

/// The first half of the record (25 000 points, 86 s): its selection does not accept
/// `tidal_gravity` (ΔBIC −23.4 in its last round, beside the refused settling), so the twin takes
/// the wave-group tide. (On the second half the selection accepts it, judged block by block.) The written twin must carry it: `accomp simulate` reproduces member k with
/// it, and the file without it gives members that differ by a tide.
#[test]
fn the_written_twin_carries_the_wave_group_tide_when_the_selection_refuses_tidal_gravity() {
    let ds = part(0.0, 0.5);
    let mut s = simulate_dataset(&ds, None, 2, &select::Config::default()).expect("simulate");
    assert!(
        s.written_twin.is_some(),
        "no noise family: {:?}",
        s.warnings
    );
    assert!(
        !s.cause
            .selection
            .accepted
            .iter()
            .any(|a| a.effect.name() == "tidal_gravity"),
        "the selection accepted tidal_gravity: not the case under test"
    );
    assert!(
        s.explained_by
            .iter()
            .any(|(n, _)| n == "tidal_gravity (tidal analysis)"),
        "the twin did not take the wave-group tide: {:?}",
        s.explained_by
    );
    let dir = scratch::Scratch::new("twin-written-tide");
    let toml = dir.join("ext.toml");
    write_scenario(&mut s, Some(&toml)).expect("write");
    let text = std::fs::read_to_string(&toml).unwrap();
    let written = Scenario::from_toml(&text).expect("the written twin parses");
    let spec = written.twin.as_ref().expect("[twin]");
    let groups = spec.draws.tide_groups.as_ref().map_or(0, Vec::len);
    assert!(groups > 0, "the written twin has no wave groups");
    assert!(
        spec.draws.effects.iter().any(|e| e.kind == "tidal_gravity"),
        "the written twin's draws lack the tide"
    );
    let mut with_tide = Vec::new();
    for k in [1u64, 2] {
        let y = member_from_cli(&toml, k, &dir.join(format!("m{k}.csv"))).expect("member");
        assert_eq!(y.len(), ds.len());
        assert_eq!(
            s.member_views(&ds, &y),
            s.members_after[k as usize - 1],
            "member {k}"
        );
        with_tide.push(y);
    }
    // The same file without the wave-group tide (its draw and its nominal entry): the noise is
    // the same draw, the tide is missing — every member differs, by a signal with the tide's
    // size (the groups' factors against the model tide are a few % of ≈ 0.1 mGal: ≈ 2e-3 mGal
    // RMS here).
    let mut no_tide = written.clone();
    let spec = no_tide.twin.as_mut().unwrap();
    let fixed = spec.fixed_effects;
    spec.draws.effects.retain(|e| e.kind != "tidal_gravity");
    spec.draws.tide_groups = None;
    let mut i = 0;
    no_tide.effects.retain(|e| {
        i += 1;
        i <= fixed || e.name() != "tidal_gravity"
    });
    assert!(no_tide.effects.len() < written.effects.len());
    let stripped = dir.join("no_tide.toml");
    std::fs::write(&stripped, no_tide.to_toml()).unwrap();
    for (k, with) in [1u64, 2].iter().zip(&with_tide) {
        let y = member_from_cli(&stripped, *k, &dir.join("m_no_tide.csv")).expect("member");
        let d: Vec<f64> = with.iter().zip(&y).map(|(a, b)| a - b).collect();
        let rms = (d.iter().map(|v| v * v).sum::<f64>() / d.len() as f64).sqrt();
        eprintln!("member {k}: the wave-group tide is {rms:.3e} RMS of the member");
        assert!(
            rms > 5e-4,
            "member {k}: dropping the tide changed it by {rms:e} RMS only"
        );
    }
}

/// The first half of the record (25 000 points, 86 s) starts with the spring's settling, which
/// the discovery refuses as a cause and the twin's drift carries in-sample: the written twin
/// holds it (`[twin.drift.settling]`), `accomp simulate` reproduces member k with it, and the
/// file without it gives members that differ by exactly one exponential each — A·exp(−t/τ)
/// at the member's own draw of A and τ, within a few σ of the fitted values, another draw in
/// another member.
#[test]
fn the_written_twin_carries_the_settling_at_the_records_start_drawn_per_member() {
    let ds = part(0.0, 0.5);
    let mut s = simulate_dataset(&ds, None, 2, &select::Config::default()).expect("simulate");
    let fitted = *s
        .settling
        .as_ref()
        .and_then(|f| f.kept())
        .expect("the first half's settling is in the twin");
    let dir = scratch::Scratch::new("twin-written-settling");
    let toml = dir.join("ext.toml");
    write_scenario(&mut s, Some(&toml)).expect("write");
    let text = std::fs::read_to_string(&toml).unwrap();
    assert!(text.contains("[twin.drift.settling"), "no settling written");
    let mut members = Vec::new();
    for k in [1u64, 2] {
        let y = member_from_cli(&toml, k, &dir.join(format!("m{k}.csv"))).expect("member");
        assert_eq!(
            s.member_views(&ds, &y),
            s.members_after[k as usize - 1],
            "member {k}"
        );
        members.push(y);
    }
    let mut stripped = Scenario::from_toml(&text).expect("the written twin parses");
    stripped
        .twin
        .as_mut()
        .unwrap()
        .drift
        .as_mut()
        .unwrap()
        .settling = None;
    let path = dir.join("no_settling.toml");
    std::fs::write(&path, stripped.to_toml()).unwrap();
    let t0 = ds.t_s[0];
    let (tau, a) = (fitted.tau_s, fitted.amplitude);
    let i1 = ds.t_s.partition_point(|&t| t - t0 < tau.value);
    let i2 = ds.t_s.partition_point(|&t| t - t0 < 2.5 * tau.value);
    let mut draws = Vec::new();
    for (k, with) in [1u64, 2].iter().zip(&members) {
        let y = member_from_cli(&path, *k, &dir.join("m_no_settling.csv")).expect("member");
        let d: Vec<f64> = with.iter().zip(&y).map(|(a, b)| a - b).collect();
        let tau_k = -(ds.t_s[i1] - t0) / (d[i1] / d[0]).ln();
        let want = d[0] * (-(ds.t_s[i2] - t0) / tau_k).exp();
        assert!(
            (d[i2] - want).abs() < 1e-6 * d[0].abs(),
            "member {k}: not one exponential ({} against {want})",
            d[i2]
        );
        assert!(
            (d[0] - a.value).abs() < 5.0 * a.sigma && (tau_k - tau.value).abs() < 5.0 * tau.sigma,
            "member {k}: A {} τ {tau_k} s against {a:?}, {tau:?}",
            d[0]
        );
        draws.push((d[0], tau_k));
    }
    assert!(draws[0] != draws[1], "both members drew the same settling");
}
