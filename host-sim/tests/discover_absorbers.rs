//! The flexible effects must not absorb what is not theirs: 14-day logs at 120 s with a
//! thermostat programme (ramps of 2–6 h, what makes `thermal_hysteresis` a candidate) and NO
//! hidden effect, generated independently of the simulator and the detector
//! (`common/synth.rs`: 1/f flicker by spectral synthesis, white, random walk; an RTD with its
//! offset and reading noise; tilt and pressure channels), each in one of the ways real records
//! go wrong:
//!
//! - `Realistic`: white + 1/f flicker (0.3–1 µg) + random walk (2–8 ng/√s);
//! - `Gaps`: the same with three outages of 6–30 h cut out of the record;
//! - `Spikes`: the same with 30 single-sample spikes of ±20–100 µg;
//! - `Quake`: the same with 40 min of ground shaking (±30–80 µg, decaying), no offset after it;
//! - `RandomWalk`: white + a strong random walk (20–40 ng/√s), no flicker.
//!
//! Nothing is hidden, so every accepted effect is a false discovery; the hysteresis (a
//! 24-width Preisach distribution, the most flexible column of the catalogue) must never be
//! one of them. Measured rates: docs/discovery-causes.md.

#[path = "common/hidden.rs"]
mod hidden;
#[path = "common/synth.rs"]
mod synth;

use rand::Rng;

/// How the record goes wrong.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Trouble {
    Realistic,
    Gaps,
    Spikes,
    Quake,
    RandomWalk,
    /// Realistic noise plus a drift that accelerates, A·(t/span)^p, p 1.5–2.5, A 2–6 µg (no
    /// catalogue drift has this shape).
    AcceleratingDrift,
    /// Realistic noise plus a bias on the RATE of temperature change (a gradient across the
    /// sensor while the programme ramps): g·dT/dt of the true temperature, 1–3 µg at the
    /// programme's fastest ramp.
    RateCoupling,
}

const TROUBLES: [Trouble; 7] = [
    Trouble::Realistic,
    Trouble::Gaps,
    Trouble::Spikes,
    Trouble::Quake,
    Trouble::RandomWalk,
    Trouble::AcceleratingDrift,
    Trouble::RateCoupling,
];

const DT_S: f64 = 120.0;
const ROWS: usize = 14 * 720;

/// One null log of the given kind from `seed`: the accepted effects with their parameters.
fn accepted_on(trouble: Trouble, seed: u64) -> Vec<String> {
    let mut r = synth::rng(seed);
    let (st, mut noise) = synth::programme_station(ROWS, DT_S, &mut r);
    if trouble == Trouble::RandomWalk {
        noise.flicker_floor = 1e-12;
        noise.rw_per_sqrt_s = r.random_range(20.0e-9..40.0e-9);
    }
    let mut extra = vec![0.0; ROWS];
    match trouble {
        Trouble::Spikes => {
            for _ in 0..30 {
                let i = r.random_range(0..ROWS);
                extra[i] += hidden::sign(&mut r) * r.random_range(20.0e-6..100.0e-6);
            }
        }
        Trouble::Quake => {
            // Shaking sampled by a 120 s average: a random value per sample, decaying over 40 min.
            let i0 = r.random_range(ROWS / 10..9 * ROWS / 10);
            let a = r.random_range(30.0e-6..80.0e-6);
            for (k, e) in extra[i0..i0 + 20].iter_mut().enumerate() {
                *e = a * synth::gauss(&mut r) * (-(k as f64) / 6.0).exp();
            }
        }
        Trouble::AcceleratingDrift => {
            let p = r.random_range(1.5..2.5);
            let a = hidden::sign(&mut r) * r.random_range(2.0e-6..6.0e-6);
            let span = ROWS as f64 * DT_S;
            for (e, t) in extra.iter_mut().zip(&st.t_s) {
                *e = a * (t / span).powf(p);
            }
        }
        Trouble::RateCoupling => {
            // dT/dt by central differences of the true temperature, smoothed over 30 min (the
            // gradient builds up through the housing), scaled to `size` at its 99th percentile.
            let rate = synth::true_rate_c_per_s(&st);
            let smooth = synth::low_pass(&rate, DT_S, 1800.0);
            let mut mags: Vec<f64> = smooth.iter().map(|v| v.abs()).collect();
            mags.sort_by(f64::total_cmp);
            let top = mags[mags.len() * 99 / 100].max(1e-12);
            let size = hidden::sign(&mut r) * r.random_range(1.0e-6..3.0e-6);
            for (e, v) in extra.iter_mut().zip(&smooth) {
                *e = size * v / top;
            }
        }
        _ => {}
    }
    let y = synth::output_g(&st, &noise, &extra, &mut r);
    let mut log = synth::log_of(&st, y);
    if trouble == Trouble::Gaps {
        let mut keep = vec![true; ROWS];
        for _ in 0..3 {
            let len = r.random_range(180..900);
            let i0 = r.random_range(ROWS / 20..ROWS - len - ROWS / 20);
            keep[i0..i0 + len].iter_mut().for_each(|k| *k = false);
        }
        log = thinned(&log, &keep);
    }
    let (_, d) = hidden::discover_blind(&log);
    let j = accomp_host::discover::report::json(&d);
    if let Some(h) = j["effects"]
        .as_array()
        .and_then(|v| v.iter().find(|e| e["name"] == "thermal_hysteresis"))
    {
        eprintln!(
            "  the loop named: {}; refused {:?}; last round {:?}",
            h["preisach"], d.selection.refused, d.selection.last_round
        );
    }
    hidden::accepted_with_params(&d)
}

/// The log with only the rows marked `keep`.
fn thinned(log: &accomp_host::log::Log, keep: &[bool]) -> accomp_host::log::Log {
    let pick = |v: &[f64]| -> Vec<f64> {
        v.iter()
            .zip(keep)
            .filter(|(_, k)| **k)
            .map(|(x, _)| *x)
            .collect()
    };
    let mut out = accomp_host::log::Log::with_time(pick(log.time_s())).expect("time");
    out.set_meta("input_g", "1").expect("meta");
    for name in [
        "output_g",
        "temperature_c",
        "tilt_x_arcsec",
        "tilt_y_arcsec",
        "pressure_hpa",
    ] {
        let v = log.column(name).expect("column");
        out.push_column(name, pick(v)).expect("column");
    }
    out
}

/// Draws per kind of trouble (21 logs, ≈ 1.5 s each in the dev profile).
const DRAWS_PER_KIND: usize = 3;

#[test]
fn no_hysteresis_is_named_on_null_logs_with_gaps_spikes_a_quake_or_a_random_walk() {
    let mut rng = synth::rng(0x0AB5_0B3E);
    let mut hysteresis = 0;
    let mut extras = 0;
    let mut logs = 0;
    for trouble in TROUBLES {
        for i in 0..DRAWS_PER_KIND {
            let acc = accepted_on(trouble, rng.random::<u64>());
            eprintln!("{trouble:?} {i}: accepted {acc:?}");
            hysteresis += acc
                .iter()
                .filter(|a| a.starts_with("thermal_hysteresis"))
                .count();
            extras += acc.len();
            logs += 1;
        }
    }
    eprintln!("ABSORBERS: hysteresis named on {hysteresis} of {logs} null logs; {extras} effects accepted in all");
    assert_eq!(hysteresis, 0, "hysteresis named on null logs");
}

/// Logs of the lag-or-loop test (≈ 2 s each in the dev profile).
const ONE_RATE_LOGS: usize = 3;

#[test]
fn a_lag_on_a_cycling_programme_is_named_a_lag_not_a_loop_and_an_ambiguity_is_reported_in_full() {
    // A ±0.5 °C rounded triangle (8 h period, one ramp rate): after each reversal a
    // first-order lag's error relaxes exponentially in the temperature moved, close to a
    // Preisach distribution of play widths — the loop must not take the lag's place, and when
    // the two are reported as "ambiguous: A or B" the report must carry the other's parameters
    // and what would separate them (measured: the first-order lag in 3/3, twice said ambiguous
    // with a second-order lag, and no loop).
    // The lag: 20–40 min on the true temperature, 5–10 µg/°C (2–6 µg of offset on the ramps).
    let mut rng = synth::rng(0x0A3B_1601);
    let mut said = 0;
    let mut named = 0;
    let mut loops = 0;
    for i in 0..ONE_RATE_LOGS {
        let mut r = synth::rng(rng.random::<u64>());
        let st = synth::station(ROWS, DT_S, synth::EIGHT_HOUR_CYCLE, &mut r);
        let noise = synth::draw_noise(&mut r);
        let tau = r.random_range(1200.0..2400.0);
        let k = hidden::sign(&mut r) * r.random_range(5.0e-6..10.0e-6);
        let lag = synth::low_pass(&st.temp_true_c, DT_S, tau);
        let extra = synth::lag_error(&lag, &st.temp_true_c, k);
        let y = synth::output_g(&st, &noise, &extra, &mut r);
        let (_, d) = hidden::discover_blind(&synth::log_of(&st, y));
        let thermal = d.selection.accepted.iter().find(|a| {
            matches!(
                a.effect.name(),
                "thermal_lag" | "thermal_hysteresis" | "lag2_coupling" | "rate_coupling"
            )
        });
        let amb = thermal.and_then(|a| a.ambiguous_with.first());
        eprintln!(
            "one-rate lag {i}: τ {tau:.0} s, {:.1} µg/°C → {:?}; ambiguous with {:?}",
            k * 1e6,
            hidden::accepted_with_params(&d),
            amb.map(|a| (&a.other, a.other_delta_bic, a.overlap))
        );
        // The first-order lag, named as such or as one side of "ambiguous: A or B": on one ramp
        // rate a first-order lag, two stages and a gain on the rate differ only at the corners
        // (docs/discovery-causes.md), so another name is right only when it says the lag is the
        // equal alternative.
        named += usize::from(thermal.is_some_and(|a| {
            a.effect.name() == "thermal_lag"
                || a.ambiguous_with
                    .iter()
                    .any(|amb| amb.other == "thermal_lag")
        }));
        loops += usize::from(
            d.selection
                .accepted
                .iter()
                .any(|a| a.effect.name() == "thermal_hysteresis"),
        );
        if let Some(a) = amb {
            said += 1;
            let j = accomp_host::discover::report::json(&d);
            assert!(j.to_string().contains("ambiguous_with"), "JSON");
            assert!(accomp_host::discover::report::text(&d).contains("ambiguous: "));
            assert!(!a.other_parameters.is_empty() && !a.separates.is_empty());
        }
    }
    eprintln!(
        "ONE-RATE LAG: the first-order lag named {named}/{ONE_RATE_LOGS}, a loop on \
         {loops}, ambiguity \
         said {said}"
    );
    assert_eq!(named, ONE_RATE_LOGS);
    assert_eq!(loops, 0);
}
