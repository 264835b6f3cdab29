//! Speed of the solid-earth tide model (docs/tide.md, "Speed"): a 1 s series of 3.5 million
//! samples (what `accomp simulate` needs for 41 days at 1 Hz) and direct evaluations.
//!
//! `cargo run --release -p accomp-host --example tide_bench`

use accomp::tide::Station;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // Hannover, the ETERNA test-vector site.
    let st = Station::new(52.3868, 9.7144, 110.0).map_err(|e| format!("{e:?}"))?;
    let start = 1_700_000_000.0;
    let n = 3_500_000usize;
    let t0 = Instant::now();
    let mut acc = 0.0;
    for (_, s) in st.series(start, 1.0).map_err(|e| format!("{e:?}"))?.take(n) {
        acc += s.gravity_nm_s2 + s.tilt_north_mas;
    }
    let series_ns = t0.elapsed().as_nanos() as f64 / n as f64;
    let m = 200_000usize;
    let t1 = Instant::now();
    for i in 0..m {
        acc += st.tide_at_unix_seconds(start + i as f64).gravity_nm_s2;
    }
    let direct_ns = t1.elapsed().as_nanos() as f64 / m as f64;
    // The checksum keeps the loops from being optimised away.
    println!(
        "series (1 s step): {series_ns:.1} ns/sample; direct: {direct_ns:.1} ns/evaluation (checksum {acc:.1})"
    );
    Ok(())
}
