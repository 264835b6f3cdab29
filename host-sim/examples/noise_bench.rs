//! Benchmark of the noise model's likelihood (the discovery's inner loop): one pass of the
//! Kalman innovations over 49 893 evenly spaced bins (the 41-day 1 Hz log's 71 s bins) with the
//! flicker comb of that record (12 states), on the regular rows (the rank-2 recursion) and on
//! the same rows with one removed (a gap: the full O(k²) update on every step).
//!
//! ```text
//! cargo run --release -p accomp-host --example noise_bench
//! ```
//!
//! Timings are the minimum of 30 runs; the load average is printed before and after (the
//! machine may be shared). Results go into docs/benchmarks.md ("Discovery").

use std::time::Instant;

use accomp_host::discover::noise::{neg2_loglik, NoiseModel};

fn load() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|_| "unknown".into())
}

fn best_of(runs: usize, f: impl Fn() -> f64) -> (f64, f64) {
    let mut best = f64::INFINITY;
    let mut v = 0.0;
    for _ in 0..runs {
        let t0 = Instant::now();
        v = f();
        best = best.min(t0.elapsed().as_secs_f64());
    }
    (best, v)
}

fn main() {
    let (n, dt) = (49_893usize, 71.0);
    let t: Vec<f64> = (0..n).map(|i| i as f64 * dt).collect();
    let x: Vec<f64> = (0..n).map(|i| ((i * 7919) % 1000) as f64 * 1e-6).collect();
    // The final model's levels on that record (white 8.8e-10 V² a bin, flicker 1.4 µV at τ_mid,
    // nearly flat, random walk 4.9e-14 V²/s).
    let m = NoiseModel::from_levels(
        8.8e-10,
        1.4e-6_f64.powi(2),
        -0.016,
        4.9e-14,
        dt,
        n as f64 * dt,
    );
    let regular: Vec<usize> = (0..n).collect();
    let mut gapped = regular.clone();
    gapped.remove(n / 2);
    println!("load before: {}", load());
    let (a, _) = best_of(30, || neg2_loglik(&m, &t, &regular, &x));
    let (b, _) = best_of(30, || neg2_loglik(&m, &t, &gapped, &x));
    println!(
        "{} states, {n} bins: regular pass {:.2} ms (rank-2), with one gap {:.2} ms (full update)",
        m.flicker.len() + 1,
        a * 1e3,
        b * 1e3
    );
    println!("load after: {}", load());
}
