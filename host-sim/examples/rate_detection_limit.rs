//! Where a `rate_coupling` is named: the discovery run blind (selection included) on synthetic
//! logs with a gain on the rate of the TRUE temperature scaled to a given ideal SNR, and on the
//! same logs with nothing injected.
//!
//! The **ideal SNR** of a hidden coupling g·dT/dt is what a detector that knew its column
//! exactly (the true rate, no reading noise) and the output's noise exactly would have: the
//! matched-filter SNR (`hidden::matched_filter_snr`) of g·dT/dt under the true white,
//! flicker and random-walk noise, after an offset, a linear drift and the true temperature took
//! what they can. One linear column is charged ln n by the criterion, so with everything known it would be
//! named from SNR √(ln n) ≈ 2.9–3.0.
//!
//! Two stations (`tests/common/synth.rs`), the noise of the hidden-effect tests (white 2 µg·√s,
//! 1/f flicker 0.3–1 µg, random walk 2–8 ng/√s):
//!
//! - `controller`: a regulated station plus controller noise AR(1) of 0.1–0.2 °C over 10–20 min,
//!   RTD 1–5 mK, 4 days at 60 s (`discover_transfer.rs`' controller-noise test);
//! - `ramps`: a lab's programmed chamber, ±0.5 °C ramps of 2–6 h, 14 days at 120 s.
//!
//! Prints one line per log (what was named, the gain found / true, why a rate coupling was
//! refused) and a summary per station and SNR.
//!
//! `cargo run --release -p accomp-host --example rate_detection_limit [records] [snr,snr,…]`

#[path = "../tests/common/hidden.rs"]
mod hidden;
#[path = "../tests/common/synth.rs"]
mod synth;

use accomp_host::sim::noise::AllanParams;

/// One station of `case` drawn from `seed`, and its sensor noise.
fn station(case: &str, seed: u64) -> (synth::Station, synth::SensorNoise, rand_chacha::ChaCha8Rng) {
    let mut r = synth::rng(seed);
    if case == "ramps" {
        let (st, noise) = synth::programme_station(14 * 720, 120.0, &mut r);
        return (st, noise, r);
    }
    let (st, noise, _) = synth::controller_noise_station(4 * 1440, 60.0, &mut r);
    (st, noise, r)
}

fn main() {
    let records: u64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(6);
    let snrs: Vec<f64> = std::env::args()
        .nth(2)
        .map(|s| s.split(',').filter_map(|x| x.parse().ok()).collect())
        .unwrap_or_else(|| vec![0.0, 3.0, 4.0, 5.0, 6.0, 8.0]);
    let mut summary: Vec<String> = Vec::new();
    for case in ["controller", "ramps"] {
        for &snr in &snrs {
            let (mut named, mut extras, mut gains) = (0, 0, Vec::new());
            for rec in 0..records {
                let seed = 0x5A7E_0000 + rec + if case == "ramps" { 1000 } else { 0 };
                let (st, noise, mut r) = station(case, seed);
                let n = st.t_s.len();
                let rate = synth::true_rate_c_per_s(&st);
                let allan = AllanParams {
                    white_adev_1s: noise.white_1s,
                    flicker_floor: noise.flicker_floor,
                    random_walk_per_sqrt_s: noise.rw_per_sqrt_s,
                };
                let nuisance = vec![
                    vec![1.0; n],
                    (0..n).map(|i| i as f64 / n as f64).collect(),
                    st.temp_true_c.clone(),
                ];
                let span = n as f64 * st.dt_s;
                let unit = hidden::matched_filter_snr(&rate, &nuisance, &allan, st.dt_s, span);
                let g = hidden::sign(&mut r) * snr / unit;
                let extra: Vec<f64> = rate.iter().map(|v| g * v).collect();
                let mut ro = synth::rng(seed ^ 0xF00D);
                let y = synth::output_g(&st, &noise, &extra, &mut ro);
                let (_, d) = hidden::discover_blind(&synth::log_of(&st, y));
                let acc = hidden::accepted_with_params(&d);
                let found = hidden::accepted(&d, "rate_coupling")
                    .filter(|a| a.effect.channel() == Some("temperature_c"))
                    .map(|a| hidden::param_value(a, "coefficient"));
                let other = acc
                    .iter()
                    .filter(|a| !a.starts_with("rate_coupling"))
                    .count();
                extras += other;
                let refusal = hidden::refusal(&d, "rate_coupling");
                match found {
                    Some(k) => {
                        named += 1;
                        if snr > 0.0 {
                            gains.push(k / g);
                        }
                        println!(
                            "{case} snr {snr} rec {rec}: named, gain {:.3} ({k:.3e}); {acc:?}",
                            if snr > 0.0 { k / g } else { f64::NAN }
                        );
                    }
                    None => println!(
                        "{case} snr {snr} rec {rec}: not named; {acc:?}; refused: {refusal}"
                    ),
                }
            }
            let (lo, hi) = gains
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| {
                    (l.min(x), h.max(x))
                });
            summary.push(format!(
                "{case}, ideal SNR {snr}: rate_coupling named {named}/{records}, gain found/true {lo:.2}–{hi:.2}, other effects {extras}"
            ));
        }
    }
    println!("\nsummary:");
    for s in summary {
        println!("{s}");
    }
}
