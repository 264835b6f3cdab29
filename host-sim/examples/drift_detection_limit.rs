//! Measures where `discover` starts naming a drift family, against the ideal detector's χ²
//! (docs/discovery-causes.md, "Drift families"): 14-day synthetic logs at 120 s
//! (`tests/common/drift.rs`), each family at ideal χ² 20 to 1280 (doubling) on the same records
//! (the drift scaled, the noise the same), several seeds. Prints one line per run and, per
//! family and χ², how often a drift was named and how often with the right family.
//!
//! `cargo run -p accomp-host --example drift_detection_limit [seeds]` (the dev profile builds
//! the host crates at opt-level 3)

#[path = "../tests/common/drift.rs"]
mod drift;
#[path = "../tests/common/hidden.rs"]
mod hidden;
#[path = "../tests/common/synth.rs"]
mod synth;

use drift::Family;

fn main() {
    let seeds: u64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(3);
    let levels = [20.0, 40.0, 80.0, 160.0, 320.0, 640.0, 1280.0];
    let families = [
        Family::Exponential,
        Family::Logarithmic,
        Family::PowerLaw,
        Family::Logistic,
        Family::TwoExponentials,
    ];
    println!(
        "family, chi2, named any drift / right family (of {seeds} seeds), likelihood recovered"
    );
    for family in families {
        for &chi2 in &levels {
            let (mut any, mut right) = (0, 0);
            let mut recovered = Vec::new();
            for seed in 0..seeds {
                let x = drift::synthetic(family, 0xD41F_7000 + seed, chi2);
                let (_, d) = hidden::discover_blind(&x.log);
                let v = drift::verdict(&d, &x.t_s, &x.shape_g, family);
                let ok = drift::named_right(&v, family, &x.truth, 0.3);
                // The best drift family's ΔBIC: accepted, else the last round's score.
                let best = d
                    .selection
                    .accepted
                    .iter()
                    .filter(|a| a.effect.drift_family().is_some())
                    .map(|a| a.delta_bic)
                    .chain(
                        d.selection
                            .last_round
                            .iter()
                            .filter(|(n, _)| {
                                matches!(n.as_str(), "warmup" | "aging_drift" | "creep_drift")
                            })
                            .map(|(_, b)| *b),
                    )
                    .fold(f64::INFINITY, f64::min);
                // What the likelihood recovered of the ideal χ²: ΔBIC less the family's charge
                // (one column, ln n, and its 24-point shape grid, max(ln n, 2 ln 24)).
                let n = x.t_s.len() as f64;
                let charge = n.ln() + n.ln().max(2.0 * 24f64.ln());
                recovered.push((charge - best) / chi2);
                any += usize::from(v.named.is_some());
                right += usize::from(ok);
                println!(
                    "  {family:?} chi2 {chi2} (random-walk form {:.0}) seed {seed}: A {:.1} µg \
                     truth {:?} → {:?} or {:?}, param {:?}, mismatch {:.2}, others {:?}, best drift ΔBIC \
                     {best:.1}, right {ok}",
                    x.chi2_random_walk,
                    x.amplitude_g * 1e6,
                    x.truth,
                    v.named,
                    v.or,
                    v.shape_param,
                    v.mismatch,
                    v.others
                );
            }
            println!(
                "{family:?}, {chi2}, {any}/{seeds} / {right}/{seeds}, recovered Δ(−2 ln L) / χ² {:?}",
                recovered
                    .iter()
                    .map(|r| (r * 100.0).round() / 100.0)
                    .collect::<Vec<_>>()
            );
        }
    }
}
