//! Many change points: a bistable sensor flipping between two levels about every three days,
//! the jumps unequal (the two levels wander), in logs the detector did not generate:
//!
//! - 14-day 1 g logs at 120 s from `common/synth.rs` (white + 1/f flicker by spectral
//!   synthesis + random walk, a regulated thermostat, tilt and pressure channels);
//! - the real gMetrology gravimeter record (51 days at 1 min, tide, pressure, its own noise)
//!   with the flips added to its gravity column.
//!
//! The tool runs blind; a flip is found when an accepted `step` lies within 10 min of it with
//! its size within 30 % (or 3 σ). Accepted effects that are neither a flip nor (on gMetrology)
//! what the record is known to hold are counted as extras. Measured rates:
//! docs/discovery-causes.md.

#[path = "common/hidden.rs"]
mod hidden;
#[path = "common/synth.rs"]
mod synth;

use accomp_host::discover::import::{self, DatasetOptions, Format};
use accomp_host::discover::{self, select, Discovery};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// Flip times (s) and sizes: spacing exponential with mean 3 days, at least 12 h; the sensor
/// alternates between its two levels, each jump `base`·(1 ± 0.4) with the sign alternating.
fn flips(span_s: f64, base: f64, rng: &mut ChaCha8Rng) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    let mut t = rng.random_range(0.3..1.0) * 86_400.0;
    let mut up = rng.random::<bool>();
    while t < span_s - 0.5 * 86_400.0 {
        let size = base * rng.random_range(0.6..1.4) * if up { 1.0 } else { -1.0 };
        out.push((t, size));
        up = !up;
        t += (0.5 * 86_400.0_f64).max(-(rng.random::<f64>().max(1e-12)).ln() * 3.0 * 86_400.0);
    }
    out
}

fn flip_series(t_s: &[f64], fl: &[(f64, f64)]) -> Vec<f64> {
    t_s.iter()
        .map(|&t| fl.iter().filter(|f| t >= f.0).map(|f| f.1).sum())
        .collect()
}

/// (flips found, accepted effects that are not a found flip nor in `known`).
fn score(d: &Discovery, fl: &[(f64, f64)], known: &[&str]) -> (usize, usize) {
    let steps = hidden::accepted_steps(d);
    let mut used = vec![false; steps.len()];
    let mut found = 0;
    for &(t, s) in fl {
        if let Some(k) = steps.iter().enumerate().position(|(k, st)| {
            !used[k]
                && (st.0 - t).abs() <= 600.0
                && (st.1 - s).abs() <= (0.3 * s.abs()).max(3.0 * st.2)
        }) {
            used[k] = true;
            found += 1;
        }
    }
    let other = d
        .selection
        .accepted
        .iter()
        .filter(|a| a.effect.name() != "step" && !known.contains(&a.effect.name()))
        .count();
    (found, other + used.iter().filter(|u| !**u).count())
}

/// Logs of the synthetic test (≈ 3 s each in the dev profile).
const SYNTH_LOGS: usize = 6;

#[test]
fn a_bistable_sensor_flipping_every_three_days_is_named_as_its_steps() {
    let mut rng = synth::rng(0x0B15_7AB1);
    let (mut flips_total, mut flips_found, mut extras) = (0, 0, 0);
    for i in 0..SYNTH_LOGS {
        let mut r = synth::rng(rng.random::<u64>());
        let n = 14 * 720;
        let st = synth::station(n, 120.0, synth::Thermal::Regulated, &mut r);
        let noise = synth::draw_noise(&mut r);
        // Jumps of 8–16 × the flicker floor (× 0.6–1.4 each): a flip the eye sees in the record.
        let base = noise.flicker_floor * r.random_range(8.0..16.0);
        // A sensor that flips: at least twice in the record (one flip is a single step).
        let fl = loop {
            let fl = flips(n as f64 * 120.0, base, &mut r);
            if fl.len() >= 2 {
                break fl;
            }
        };
        let y = synth::output_g(&st, &noise, &flip_series(&st.t_s, &fl), &mut r);
        let (_, d) = hidden::discover_blind(&synth::log_of(&st, y));
        let (found, extra) = score(&d, &fl, &[]);
        eprintln!(
            "bistable {i}: flips {:?} µg → found {found}/{}, extras {extra}; accepted {:?}; \
             refused {:?}",
            fl.iter()
                .map(|f| ((f.0 / 3600.0).round(), (f.1 * 1e7).round() / 10.0))
                .collect::<Vec<_>>(),
            fl.len(),
            hidden::accepted_with_params(&d),
            d.selection.refused
        );
        flips_total += fl.len();
        flips_found += found;
        extras += extra;
    }
    eprintln!("BISTABLE synthetic: flips found {flips_found}/{flips_total}, extras {extras}");
    assert!(
        flips_found * 10 >= flips_total * 8,
        "flips found {flips_found}/{flips_total}"
    );
    assert!(extras <= 2, "extras {extras}");
}

const GMETROLOGY: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../data/measured/gmetrology_relative_gravimeter_2021-06-08_51d.tsf"
);

#[test]
fn flips_added_to_the_real_gravimeter_record_are_named_as_its_steps() {
    let (orig, _) = import::load(std::path::Path::new(GMETROLOGY), Format::Auto)
        .expect("gMetrology record (data/measured)");
    let t = orig.time_s().to_vec();
    let span = t[t.len() - 1] - t[0];
    let mut r = synth::rng(0x6_F11B);
    // 0.005–0.01 mGal (50–100 nm/s²): a few times the record's minute-scale noise.
    let fl: Vec<(f64, f64)> = flips(span, r.random_range(0.005..0.01), &mut r)
        .into_iter()
        .map(|(x, s)| (x + t[0], s))
        .collect();
    let add = flip_series(&t, &fl);
    // The same record with the flips in its gravity column.
    let mut log = accomp_host::log::Log::with_time(t.clone()).expect("time");
    for (k, v) in orig.metadata() {
        log.set_meta(k, v).expect("meta");
    }
    for name in orig.column_names().iter().filter(|c| *c != "time_s") {
        let v = orig.column(name).expect("column");
        let v = if name.starts_with("gravity") {
            v.iter().zip(&add).map(|(a, b)| a + b).collect()
        } else {
            v.to_vec()
        };
        log.push_column(name, v).expect("column");
    }
    let ds = import::dataset_from_log(&log, &DatasetOptions::default()).expect("dataset");
    let d = discover::discover(ds, None, &select::Config::default()).expect("discover");
    let (found, extra) = score(
        &d,
        &fl,
        &[
            "tidal_gravity",
            "pressure_admittance",
            "warmup",
            "aging_drift",
        ],
    );
    eprintln!(
        "gMetrology + flips {:?} mGal → found {found}/{}, extras {extra}; accepted {:?}; refused {:?}",
        fl.iter()
            .map(|f| (((f.0 - t[0]) / 3600.0).round(), (f.1 * 1e4).round() / 1e4))
            .collect::<Vec<_>>(),
        fl.len(),
        hidden::accepted_with_params(&d),
        d.selection.refused
    );
    assert!(found * 10 >= fl.len() * 8, "found {found}/{}", fl.len());
    assert!(extra <= 1, "extras {extra}");
}
