//! Hidden effects injected into the REAL residual of the gMetrology spring gravimeter (51 days
//! at 1 min), after the tide: the noise is what a real instrument makes, not a model of it.
//!
//! Preparation (written here, independent of the detector): one least-squares fit over the
//! whole record of an offset per segment, a linear drift, the core's tide model, sin/cos at the
//! nine main tidal frequencies (what the one-factor model misses: phase, group factors) and the
//! barometric pressure. Its residual is cut into 4-day windows. A window gets either nothing
//! (null) or one injected effect — a step, a periodic line (non-tidal period), a warm-up
//! transient — sized by its matched-filter SNR against that window's own noise, measured by
//! an AR(12) prediction-error filter fitted to the window's 5-min means (Levinson–Durbin; not
//! the detector's noise model). The tool runs blind on `gravity_mgal` (no site, so no tide candidate).
//!
//! Reported: detection rate against SNR with Wilson 95 % intervals (docs/discovery.md), and
//! the false discoveries on the uninjected windows with their exact binomial bound.

#[path = "common/hidden.rs"]
mod hidden;
#[path = "common/real.rs"]
mod real;
#[path = "common/synth.rs"]
mod synth;

use accomp_host::discover::import::{self, DatasetOptions};
use accomp_host::discover::{self, select};
use accomp_host::log::Log;
use rand::Rng;

use real::{residual_after_tide, snr, windows};

#[derive(Debug, Clone, Copy)]
enum Injected {
    Step { at: f64 },
    Periodic { period_s: f64, phase: f64 },
    Warmup { tau_s: f64 },
}

impl Injected {
    fn unit(&self, t: &[f64]) -> Vec<f64> {
        let t0 = t[0];
        t.iter()
            .map(|&x| match *self {
                Injected::Step { at } => f64::from(x >= at),
                Injected::Periodic { period_s, phase } => {
                    (std::f64::consts::TAU * x / period_s + phase).sin()
                }
                Injected::Warmup { tau_s } => (-(x - t0) / tau_s).exp(),
            })
            .collect()
    }

    /// The injected effect is among the accepted ones with parameters near the truth.
    fn found(&self, d: &discover::Discovery, size_mgal: f64) -> bool {
        d.selection.accepted.iter().any(|a| {
            let g = |k: &str| hidden::param_value(a, k);
            match (*self, a.effect.name()) {
                (Injected::Step { at }, "step") => {
                    (g("time_s") - at).abs() <= 1800.0
                        && (g("size") - size_mgal).abs() <= 0.5 * size_mgal.abs()
                }
                (Injected::Periodic { period_s, .. }, "periodic") => {
                    (g("period_s") / period_s - 1.0).abs() <= 0.05
                }
                (Injected::Warmup { tau_s }, "warmup") => (g("tau_s") / tau_s).ln().abs() <= 0.7,
                _ => false,
            }
        })
    }
}

fn run_window(t: &[f64], y: Vec<f64>) -> discover::Discovery {
    let mut log = Log::with_time(t.iter().map(|x| x - t[0]).collect()).expect("time");
    log.set_meta("input_g", "1").expect("meta");
    log.push_column("gravity_mgal", y).expect("column");
    let ds = import::dataset_from_log(&log, &DatasetOptions::default()).expect("dataset");
    discover::discover(ds, None, &select::Config::default()).expect("discover")
}

const WINDOW_ROWS: usize = 4 * 1440;
/// SNR bands of the curve.
const BANDS: [(f64, f64); 4] = [(2.0, 4.0), (4.0, 6.0), (6.0, 9.0), (9.0, 14.0)];
/// Injections per band.
const PER_BAND: usize = 6;

#[test]
fn effects_injected_into_the_real_gravimeter_residual_are_found_by_snr() {
    let res = residual_after_tide();
    let wins = windows(&res, WINDOW_ROWS);
    eprintln!(
        "residual after the tide: {} rows, std {:.4} mGal; {} windows of {WINDOW_ROWS} rows",
        res.r_mgal.len(),
        accomp_host::discover::baseline::std(&res.r_mgal),
        wins.len()
    );
    assert!(wins.len() >= 8, "only {} windows", wins.len());
    // Nulls: every window as it is.
    let mut false_disc = 0;
    for (k, w) in wins.iter().enumerate() {
        let d = run_window(&res.t_s[w.clone()], res.r_mgal[w.clone()].to_vec());
        let acc = hidden::accepted_names(&d);
        eprintln!("real null window {k}: accepted {acc:?}");
        false_disc += usize::from(!acc.is_empty());
    }
    let mut rng = synth::rng(0x6A11_2021);
    let mut curve = Vec::new();
    for (lo, hi) in BANDS {
        let mut hits = 0;
        for j in 0..PER_BAND {
            let w = wins[rng.random_range(0..wins.len())].clone();
            // Window time from its first row: the tool's `time_s` is on this clock.
            let t_rel: Vec<f64> = res.t_s[w.clone()]
                .iter()
                .map(|x| x - res.t_s[w.start])
                .collect();
            let t = &t_rel[..];
            let (t0, span) = (0.0, t[t.len() - 1]);
            let inj = match j % 3 {
                0 => Injected::Step {
                    at: t0 + rng.random_range(0.2..0.8) * span,
                },
                1 => Injected::Periodic {
                    // 2–9 h, away from the tidal bands (12 h, 24 h, 8 h).
                    period_s: 3600.0 * [2.5, 3.3, 4.4, 5.3, 7.1, 9.5][rng.random_range(0..6)],
                    phase: rng.random_range(0.0..std::f64::consts::TAU),
                },
                _ => Injected::Warmup {
                    tau_s: 3600.0 * rng.random_range(1.0..6.0),
                },
            };
            let x = &res.r_mgal[w.clone()];
            let unit = inj.unit(t);
            let target = rng.random_range(lo..hi);
            let sign = if rng.random::<bool>() { 1.0 } else { -1.0 };
            let size = sign * target / snr(&unit, x);
            let y: Vec<f64> = x.iter().zip(&unit).map(|(a, b)| a + size * b).collect();
            let d = run_window(t, y);
            let ok = inj.found(&d, size);
            let acc = hidden::accepted_names(&d);
            eprintln!(
                "real SNR {target:.1}: {inj:?} size {:.2} µGal: found={ok} accepted {acc:?}",
                size * 1e3
            );
            if !ok {
                eprintln!("    last round (ΔBIC): {:?}", d.selection.last_round);
                eprintln!("    refused: {:?}", d.selection.refused);
            }
            hits += usize::from(ok);
        }
        let (wl, wh) = synth::wilson(hits, PER_BAND);
        eprintln!(
            "REAL CURVE SNR {lo}–{hi}: {hits}/{PER_BAND} (Wilson 95 % {:.0}–{:.0} %)",
            100.0 * wl,
            100.0 * wh
        );
        curve.push(hits);
    }
    let upper = synth::binomial_upper(false_disc, wins.len(), 0.05);
    eprintln!(
        "REAL NULL windows: {false_disc}/{} accepted something (95 % upper bound {:.0} %)",
        wins.len(),
        100.0 * upper
    );
    // Stated before measuring: ≥ 5/6 found at SNR 9–14 and nothing accepted on ≥ 3/4 of the
    // uninjected windows (the real residual is not pure noise: the first window holds the
    // instrument's settling). Met since the out-of-sample score is the held-out prediction
    // error (select.rs): measured 5/6 at 9–14 and 10/12 at SNR ≥ 6, 2/12 uninjected windows
    // (docs/discovery.md, "Non-circular tests"); before, the raw held-out residual refused real
    // steps and lines of ΔBIC −190…−520 (3/6).
    assert!(
        curve[3] >= 5,
        "detection at SNR 9–14: {}/{PER_BAND}",
        curve[3]
    );
    let strong = curve[2] + curve[3];
    assert!(
        strong >= 9,
        "detection at SNR ≥ 6: {strong}/{}",
        2 * PER_BAND
    );
    assert!(
        false_disc * 4 <= wins.len(),
        "false discoveries on the real residual {false_disc}/{}",
        wins.len()
    );
}
