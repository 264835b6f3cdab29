//! Where the extended twin leaves the record (docs/discovery.md, "`--simulate` on gMetrology"):
//! `cargo run -p accomp-host --release --example twin_fidelity -- [RECORD] [MEMBERS]` prints,
//! for every ADEV τ and PSD band after the extension, the measured value, the members' 5/50/95 %
//! and the ratio to the median, the noise family, and the residual's noise level per tenth of
//! the record (a noise level that changes shows there).

use accomp_host::discover::import::{dataset_from_log, load, DatasetOptions, Format};
use accomp_host::discover::select;
use accomp_host::discover::simulate::simulate_dataset;
use accomp_host::discover::simulate::spectra::RegularGrid;

#[path = "common/record.rs"]
mod record;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let path = record::path_arg(&args);
    let (log, _) = load(std::path::Path::new(&path), Format::Auto)?;
    let mut ds = dataset_from_log(&log, &DatasetOptions::default())?;
    // TWIN_FIDELITY_KEEP=a,b keeps the fraction a..b of the record (to see where a mismatch
    // comes from).
    if let Ok(v) = std::env::var("TWIN_FIDELITY_KEEP") {
        let f: Vec<f64> = v.split(',').filter_map(|x| x.parse().ok()).collect();
        let n = ds.len() as f64;
        let (a, b) = ((f[0] * n) as usize, (f[1] * n) as usize);
        ds.t_s = ds.t_s[a..b].to_vec();
        ds.y = ds.y[a..b].to_vec();
        ds.segment_start = ds.segment_start[a..b].to_vec();
        ds.segment_start[0] = true;
        for c in &mut ds.channels {
            c.values = c.values[a..b].to_vec();
        }
        if !ds.samples_per_point.is_empty() {
            ds.samples_per_point = ds.samples_per_point[a..b].to_vec();
        }
    }
    let members = args
        .get(2)
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| accomp_host::discover::simulate::default_ensemble(ds.len()));
    let s = simulate_dataset(&ds, None, members, &select::Config::default())?;
    // TWIN_FIDELITY_TEXT=1 prints the command's text report first.
    if std::env::var_os("TWIN_FIDELITY_TEXT").is_some() {
        println!(
            "{}",
            accomp_host::discover::simulate::output::text(&s, &ds.output_unit)
        );
        println!("{}", accomp_host::discover::report::text(&s.cause));
    }
    for (label, c) in [("before", &s.before), ("after", &s.after)] {
        println!(
            "{label}: ADEV outside {:.1} %, PSD outside {:.1} % (member {:.1} % / {:.1} %)",
            100.0 * c.adev_outside_fraction,
            100.0 * c.psd_outside_fraction,
            100.0 * c.member_adev_outside_fraction,
            100.0 * c.member_psd_outside_fraction
        );
    }
    println!(
        "drift order {} (−ℓ per order {:?}), coefficients {:?}",
        s.drift.order, s.drift.neg_loglik, s.drift_coefficients
    );
    println!(
        "transients: {} ({:.3} per day), peaks {:?}",
        s.transients.events.len(),
        s.transients.rate_per_day(),
        s.transients.peaks()
    );
    let a = &s.after;
    let row = |x: f64, m: f64, lo: f64, med: f64, hi: f64| {
        let out = if m > hi || m < lo { "OUT" } else { "" };
        println!(
            "{x:>12.4e} {m:>11.3e} {lo:>11.3e} {med:>11.3e} {hi:>11.3e} {:>6.2} {out}",
            m / med
        );
    };
    println!("ADEV: tau_s measured p5 p50 p95 ratio");
    for i in 0..a.adev.x.len() {
        row(
            a.adev.x[i],
            a.measured.adev[i].1,
            a.adev.low[i],
            a.adev.median[i],
            a.adev.high[i],
        );
    }
    println!("PSD: cycles/day measured p5 p50 p95 ratio");
    for i in 0..a.psd.x.len() {
        row(
            a.psd.x[i] * 86_400.0,
            a.measured.psd[i],
            a.psd.low[i],
            a.psd.median[i],
            a.psd.high[i],
        );
    }
    if let Some(f) = &s.family {
        for c in f.components(&ds.output_unit) {
            println!("{c:?}");
        }
    }
    // The residual's first-difference RMS per tenth of the grid.
    let grid = RegularGrid::new(&ds);
    let placed = grid.place(&s.residual_after);
    let n = placed.len();
    print!("first-difference RMS per tenth:");
    for k in 0..10 {
        let part = &placed[k * n / 10..(k + 1) * n / 10];
        let d: Vec<f64> = part
            .windows(2)
            .map(|w| w[1] - w[0])
            .filter(|v| v.is_finite())
            .collect();
        let rms = (d.iter().map(|v| v * v).sum::<f64>() / d.len().max(1) as f64).sqrt();
        print!(" {rms:.2e}");
    }
    println!();
    let mut big: Vec<(f64, usize)> = placed
        .windows(2)
        .enumerate()
        .map(|(i, w)| ((w[1] - w[0]).abs(), i))
        .filter(|v| v.0.is_finite())
        .collect();
    big.sort_by(|a, b| b.0.total_cmp(&a.0));
    println!(
        "largest first differences (value, day): {:?}",
        big.iter()
            .take(12)
            .map(|(v, i)| (
                format!("{v:.2e}"),
                format!("{:.2}", *i as f64 * grid.dt_s / 86_400.0)
            ))
            .collect::<Vec<_>>()
    );
    // Half-day means of the residual (the slow drift the members must carry).
    print!("half-day means:");
    let cells_per = (43_200.0 / grid.dt_s).round() as usize;
    for chunk in placed.chunks(cells_per.max(1)) {
        let v: Vec<f64> = chunk.iter().copied().filter(|v| v.is_finite()).collect();
        if v.is_empty() {
            print!(" gap");
        } else {
            print!(" {:.4}", v.iter().sum::<f64>() / v.len() as f64);
        }
    }
    println!();
    // The slow residual against each channel: 6-hour means, both with the drift polynomial's
    // order removed, correlation and slope.
    let u = accomp_host::discover::simulate::drift::unit_time(&ds.t_s);
    for ch in &ds.channels {
        let c = accomp_host::discover::simulate::drift::remove(&u, &ch.values, s.drift.order).1;
        let cp = grid.place(&c);
        let per = (21_600.0 / grid.dt_s).round() as usize;
        let mut pairs = Vec::new();
        for (a, b) in placed.chunks(per).zip(cp.chunks(per)) {
            let v: Vec<(f64, f64)> = a
                .iter()
                .zip(b)
                .filter(|(x, y)| x.is_finite() && y.is_finite())
                .map(|(x, y)| (*x, *y))
                .collect();
            if v.len() > per / 2 {
                let n = v.len() as f64;
                pairs.push((
                    v.iter().map(|p| p.0).sum::<f64>() / n,
                    v.iter().map(|p| p.1).sum::<f64>() / n,
                ));
            }
        }
        let n = pairs.len() as f64;
        let (mx, my) = (
            pairs.iter().map(|p| p.0).sum::<f64>() / n,
            pairs.iter().map(|p| p.1).sum::<f64>() / n,
        );
        let sxy: f64 = pairs.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
        let sxx: f64 = pairs.iter().map(|p| (p.0 - mx).powi(2)).sum();
        let syy: f64 = pairs.iter().map(|p| (p.1 - my).powi(2)).sum();
        println!(
            "6-hour means vs {}: correlation {:.2}, slope {:.3e} per channel unit ({} means)",
            ch.name,
            sxy / (sxx * syy).sqrt(),
            sxy / syy,
            pairs.len()
        );
    }
    let gaps: Vec<(usize, usize)> = RegularGrid::runs(&placed);
    println!("gap-free runs (cells): {gaps:?} of {n}");
    let mut counts = std::collections::BTreeMap::new();
    for c in &ds.samples_per_point {
        *counts.entry(format!("{c}")).or_insert(0) += 1;
    }
    println!("samples per point: {counts:?}");
    for m in &a.mismatches {
        println!(
            "{} | {}",
            accomp_host::discover::simulate::mismatch::sentence(m),
            m.unmodelled.as_deref().unwrap_or("")
        );
    }
    for (st, t) in &s.timing_s {
        println!("{st}: {t:.2} s");
    }
    // TWIN_FIDELITY_SIZES=10,20,50 measures the envelope's own sampling error: envelopes of
    // that many members drawn (without replacement) from this run's extended ensemble, against
    // the envelope of all of them.
    if let Ok(v) = std::env::var("TWIN_FIDELITY_SIZES") {
        let sizes: Vec<usize> = v.split(',').filter_map(|x| x.parse().ok()).collect();
        envelope_sampling_error(&s, &sizes);
    }
    Ok(())
}

/// For each size m: over [`SUBSETS`] random m-member subsets of the extended ensemble, the rms
/// error of the 5 % and 95 % lines (ln units, against the whole ensemble's) relative to the
/// envelope's half-width ln(p95/p50), and the mean and spread of the record's outside
/// fractions and of the leave-one-member-out figure.
fn envelope_sampling_error(s: &accomp_host::discover::simulate::Simulation, sizes: &[usize]) {
    use accomp_host::discover::simulate::mismatch::{leave_one_out, sides};
    use accomp_host::discover::simulate::spectra::Envelope;
    use rand::seq::SliceRandom;
    use rand::SeedableRng;
    const SUBSETS: usize = 100;
    let all = &s.members_after;
    let taus: Vec<f64> = s.after.adev.x.clone();
    let adev: Vec<Vec<f64>> = all
        .iter()
        .map(|m| m.adev.iter().map(|p| p.1).collect())
        .collect();
    let psd: Vec<Vec<f64>> = all.iter().map(|m| m.psd.clone()).collect();
    let meas_adev: Vec<f64> = s.after.measured.adev.iter().map(|p| p.1).collect();
    let meas_psd = s.after.measured.psd.clone();
    let full = [
        Envelope::of(&taus, &adev),
        Envelope::of(&s.frequencies_hz, &psd),
    ];
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    println!(
        "envelope sampling error against all {} members (ln-rms error of the 5/95 % lines / \
         half-width; record outside mean ± sd; leave-one-out mean ± sd), {SUBSETS} subsets:",
        all.len()
    );
    for &m in sizes.iter().filter(|&&m| m >= 3 && m <= all.len()) {
        let mut err = [0.0f64; 2];
        let mut cnt = [0usize; 2];
        let mut out = [Vec::new(), Vec::new()];
        let mut loo = [Vec::new(), Vec::new()];
        for _ in 0..SUBSETS {
            let mut idx: Vec<usize> = (0..all.len()).collect();
            idx.shuffle(&mut rng);
            idx.truncate(m);
            for (q, (x, curves, meas)) in [
                (&taus, &adev, &meas_adev),
                (&s.frequencies_hz, &psd, &meas_psd),
            ]
            .into_iter()
            .enumerate()
            {
                let sub: Vec<Vec<f64>> = idx.iter().map(|&i| curves[i].clone()).collect();
                let e = Envelope::of(x, &sub);
                let f = &full[q];
                for i in 0..x.len() {
                    let half = (f.high[i] / f.median[i]).ln();
                    let a = (e.high[i] / f.high[i]).ln() / half;
                    let b = (e.low[i] / f.low[i]).ln() / half;
                    if a.is_finite() && b.is_finite() {
                        err[q] += a * a + b * b;
                        cnt[q] += 2;
                    }
                }
                let sd = sides(meas, &e);
                out[q].push(sd.iter().filter(|v| **v != 0).count() as f64 / sd.len() as f64);
                if loo[q].len() < 20 {
                    loo[q].push(leave_one_out(x, &sub));
                }
            }
        }
        let ms = |v: &[f64]| {
            let n = v.len() as f64;
            let mean = v.iter().sum::<f64>() / n;
            let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
            format!("{:.1} ± {:.1} %", 100.0 * mean, 100.0 * sd)
        };
        println!(
            "  {m:>4} members: edge error ADEV {:.2}, PSD {:.2}; record outside ADEV {}, PSD {}; \
             leave-one-out ADEV {}, PSD {}",
            (err[0] / cnt[0].max(1) as f64).sqrt(),
            (err[1] / cnt[1].max(1) as f64).sqrt(),
            ms(&out[0]),
            ms(&out[1]),
            ms(&loo[0]),
            ms(&loo[1])
        );
    }
}
