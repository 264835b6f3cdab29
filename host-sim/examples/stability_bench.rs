//! Benchmark of the stability analysis on a 41-day, 1 Hz log (3 542 400 samples): log write and
//! read, stability (std + drift regression), OADEV and MDEV at octave taus.
//!
//! ```text
//! cargo run --release -p accomp-host --example stability_bench -- /tmp/accomp_41d.csv
//! python3 host-sim/benches/allantools_bench.py /tmp/accomp_41d.csv
//! ```
//!
//! The log is written to the given path (so allantools can time the same data); timings are the
//! best of 5 runs (the first, cold OADEV run is printed too: it pays the first touch of the phase
//! buffer). The load average is printed before and after, the machine being shared. Results go
//! into docs/benchmarks.md.

use std::time::Instant;

use accomp_host::allan::{Phase, Statistic, TauSet};
use accomp_host::log::Log;
// The test fixture's generator.
use accomp_host::stability::{analyse, mean_std, regression, Options};
use accomp_numerics::lcg::Lcg;

const SAMPLES: usize = 41 * 86_400;
const K1_V_PER_G: f64 = 1.3301;

const RUNS: usize = 5;

/// Best time of `runs` calls, the first call's time, and the last result.
fn best_of<T>(runs: usize, mut f: impl FnMut() -> T) -> (f64, f64, T) {
    let t0 = Instant::now();
    let mut last = f();
    let first = t0.elapsed().as_secs_f64();
    let mut best = first;
    for _ in 1..runs {
        let t0 = Instant::now();
        last = f();
        best = best.min(t0.elapsed().as_secs_f64());
    }
    (best, first, last)
}

fn loadavg() -> String {
    std::fs::read_to_string("/proc/loadavg").unwrap_or_default()
}

fn main() -> anyhow::Result<()> {
    let path = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "/tmp/accomp_41d.csv".into());

    // 1 g output: white noise 2 µg, random walk 5 ng/√s, drift 1e-12 g/s, plus a daily
    // temperature wiggle, read as volts through K1.
    let mut g = Lcg(41);
    let mut rw = 0.0;
    let mut t = Vec::with_capacity(SAMPLES);
    let mut out_v = Vec::with_capacity(SAMPLES);
    let mut temp_c = Vec::with_capacity(SAMPLES);
    for i in 0..SAMPLES {
        let s = i as f64;
        rw += 5e-9 * g.normal();
        let day = (s * std::f64::consts::TAU / 86_400.0).sin();
        let a_g = 1.0 + 2e-6 * g.normal() + rw + 1e-12 * s + 1e-6 * day;
        t.push(s);
        out_v.push(a_g * K1_V_PER_G);
        temp_c.push(60.0 + 0.01 * day);
    }
    let mut log = Log::with_time(t)?;
    log.set_meta("instrument", "synthetic (stability_bench)")?;
    log.set_meta("scale_factor_v_per_g", &K1_V_PER_G.to_string())?;
    log.push_column("output_v", out_v)?;
    log.push_column("temperature_c", temp_c)?;

    print!("load average before: {}", loadavg());
    let t0 = Instant::now();
    log.write_path(&path)?;
    let write_s = t0.elapsed().as_secs_f64();
    let size_mb = std::fs::metadata(&path)?.len() as f64 / 1e6;
    let (read_s, _, back) = best_of(3, || Log::read_path(&path));
    let back = back?;
    assert_eq!(back.len(), SAMPLES);

    let y_g: Vec<f64> = back
        .column("output_v")
        .unwrap_or(&[])
        .iter()
        .map(|v| v / K1_V_PER_G)
        .collect();
    let time = back.time_s();

    let (stab_s, _, (ms, reg)) = best_of(RUNS, || (mean_std(&y_g), regression(time, &y_g)));
    let (oadev_s, oadev_cold_s, ad) = best_of(RUNS, || {
        Phase::from_readings(&y_g, 1.0).map(|p| p.deviation(Statistic::Oadev, TauSet::Octave))
    });
    let (mdev_s, _, md) = best_of(RUNS, || {
        Phase::from_readings(&y_g, 1.0).map(|p| p.deviation(Statistic::Mdev, TauSet::Octave))
    });
    let opts = Options {
        columns: vec!["output_v".into()],
        ..Options::default()
    };
    let (full_s, _, rep) = best_of(RUNS, || analyse(&back, &opts));
    let (ad, md, rep) = (ad?, md?, rep?);

    println!("samples                  {SAMPLES}");
    println!("log write                {write_s:.3} s ({size_mb:.0} MB)");
    println!("log read                 {read_s:.3} s");
    println!("stability (std + regr.)  {:.4} s", stab_s);
    println!(
        "OADEV octave (+CI, ID)   {:.4} s  ({} taus; first, cold run {:.4} s)",
        oadev_s,
        ad.len(),
        oadev_cold_s
    );
    println!("OADEV + stability        {:.4} s", oadev_s + stab_s);
    println!(
        "MDEV octave (+CI, ID)    {:.4} s  ({} taus)",
        mdev_s,
        md.len()
    );
    println!("analyse(): all of these  {:.4} s", full_s);
    if let (Some((_, std, _)), Some(r)) = (ms, reg) {
        println!(
            "std = {std:.6e} g, slope = {:.6e} g/s, residual std = {:.6e} g",
            r.slope_per_s, r.residual_std
        );
    }
    for p in ad.iter().step_by(4) {
        println!("  oadev tau {:>8} s  {:.6e}", p.tau_s, p.dev);
    }
    println!("columns analysed: {}", rep.columns.len());
    print!("load average after: {}", loadavg());
    Ok(())
}
