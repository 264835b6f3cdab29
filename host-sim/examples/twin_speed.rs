//! Wall time of the simulated twin on a measured record (docs/benchmarks.md, "Twin"):
//! `cargo run -p accomp-host --example twin_speed [--release] -- [RECORD] [MAX_POINTS]`
//! (default: the gMetrology record of data/measured, binned as `accomp discover` does).

use std::time::Instant;

use accomp_host::discover::import::{dataset_from_log, load, DatasetOptions, Format};
use accomp_host::twin::Twin;

#[path = "common/record.rs"]
mod record;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let path = record::path_arg(&args);
    let max_points = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(50_000);
    let t = Instant::now();
    let (log, _) = load(std::path::Path::new(&path), Format::Auto)?;
    let ds = dataset_from_log(
        &log,
        &DatasetOptions {
            max_points,
            ..DatasetOptions::default()
        },
    )?;
    let import = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let twin = Twin::new(&ds, None, None)?;
    let new = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let det = twin.run(None)?;
    let det_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let mut sum = 0.0;
    for seed in 0..20 {
        sum += twin.run(Some(seed))?.iter().sum::<f64>();
    }
    let members = t.elapsed().as_secs_f64();
    println!(
        "{} points ({} s spacing): import {import:.3} s, Twin::new {new:.3} s, run(None) {:.4} s, \
         20 seeded members {members:.3} s ({:.4} s each) [checksum {:.3e}, {}]",
        det.len(),
        ds.dt_s,
        det_s,
        members / 20.0,
        sum,
        twin.provenance().len()
    );
    for line in twin.provenance() {
        println!("  {line}");
    }
    let r: Vec<f64> = ds.y.iter().zip(&det).map(|(a, b)| a - b).collect();
    let n = r.len() as f64;
    let m = r.iter().sum::<f64>() / n;
    let sd = (r.iter().map(|x| (x - m).powi(2)).sum::<f64>() / n).sqrt();
    let m_y = ds.y.iter().sum::<f64>() / n;
    let sd_y = (ds.y.iter().map(|x| (x - m_y).powi(2)).sum::<f64>() / n).sqrt();
    println!(
        "record std {sd_y:.6} {u}, record − twin std {sd:.6} {u}",
        u = ds.output_unit
    );
    Ok(())
}
