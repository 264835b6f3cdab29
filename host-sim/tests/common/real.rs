//! The real residual of the gMetrology spring gravimeter (51 days at 1 min) with its known
//! effects removed, for tests that inject causes into a real instrument's noise. Preparation
//! (independent of the detector): one least-squares fit over the whole record of an offset per
//! segment, a linear drift, the core's tide model, sin/cos at the nine main tidal frequencies
//! and the barometric pressure.

// Each test crate uses a different subset of this module.
#![allow(dead_code)]

use accomp_host::discover::effects;
use accomp_host::discover::import::{self, Dataset, DatasetOptions, Format};
use std::path::PathBuf;

const FILE: &str = "gmetrology_relative_gravimeter_2021-06-08_51d.tsf";

/// The record, shipped in the repository's data/measured/ (MIT licence). Missing: the test
/// fails loudly (it did not run).
pub fn record() -> PathBuf {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../data/measured")
        .join(FILE);
    if !p.exists() {
        eprintln!(
            "\n!!!!!!!! REAL-RESIDUAL TEST DID NOT RUN: {} is missing !!!!!!!!\n",
            p.display()
        );
        panic!("measured record {} missing", p.display());
    }
    p
}

/// Solves the least squares y ≈ Σ β_j x_j by modified Gram–Schmidt; returns the residual.
pub fn ls_residual(cols: &[Vec<f64>], y: &[f64]) -> Vec<f64> {
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let mut q: Vec<Vec<f64>> = Vec::new();
    for c in cols {
        let mut v = c.clone();
        for _ in 0..2 {
            for b in &q {
                let k = dot(&v, b);
                v.iter_mut().zip(b).for_each(|(vi, bi)| *vi -= k * bi);
            }
        }
        let n = dot(&v, &v).sqrt();
        if n > 1e-9 * (v.len() as f64).sqrt() * c.iter().fold(0.0_f64, |m, x| m.max(x.abs())) {
            q.push(v.into_iter().map(|x| x / n).collect());
        }
    }
    let mut r = y.to_vec();
    for b in &q {
        let k = dot(&r, b);
        r.iter_mut().zip(b).for_each(|(ri, bi)| *ri -= k * bi);
    }
    r
}

/// The record's residual after the tide, in mGal, with its time (s) and segment starts.
pub struct Residual {
    /// Time, s.
    pub t_s: Vec<f64>,
    /// Residual, mGal.
    pub r_mgal: Vec<f64>,
    /// Segment starts.
    pub seg_start: Vec<bool>,
    /// The record's pressure, Pa (its admittance is removed from the residual).
    pub pressure_pa: Option<Vec<f64>>,
}

/// The record (every row good) reduced to a dataset as `accomp discover` reduces it with `opts`.
pub fn dataset(opts: &DatasetOptions) -> Dataset {
    let (log, bad) = import::load(&record(), Format::Auto).expect("record");
    assert!(bad.is_empty(), "{} bad rows in the record", bad.len());
    import::dataset_from_log(&log, opts).expect("dataset")
}

/// The record's first `days` days, binned to at most `max_points` over the whole record.
pub fn first_days(days: f64, max_points: usize) -> Dataset {
    let mut ds = dataset(&DatasetOptions::with_max_points(max_points));
    let n = ds.t_s.iter().take_while(|&&t| t < days * 86_400.0).count();
    ds.t_s.truncate(n);
    ds.y.truncate(n);
    ds.segment_start.truncate(n);
    for c in &mut ds.channels {
        c.values.truncate(n);
    }
    ds
}

/// The points [a·n, b·n) of the record's n points at the binning `accomp discover` uses, as a
/// record of its own (a new segment at its first point): a held-back part of the record.
pub fn part(a: f64, b: f64) -> Dataset {
    // The binning `accomp discover` uses (50 000 points, 86 s).
    let ds = dataset(&DatasetOptions::default());
    let n = ds.len() as f64;
    let keep: Vec<usize> = ((a * n) as usize..(b * n) as usize).collect();
    let pick = |v: &[f64]| keep.iter().map(|&i| v[i]).collect::<Vec<_>>();
    let mut out = ds.clone();
    out.t_s = pick(&ds.t_s);
    out.y = pick(&ds.y);
    out.segment_start = keep.iter().map(|&i| ds.segment_start[i]).collect();
    out.segment_start[0] = true;
    for (c, src) in out.channels.iter_mut().zip(&ds.channels) {
        c.values = pick(&src.values);
    }
    if !ds.samples_per_point.is_empty() {
        out.samples_per_point = pick(&ds.samples_per_point);
    }
    out
}

pub fn residual_after_tide() -> Residual {
    let ds = dataset(&DatasetOptions::with_max_points(import::MAX_MAX_POINTS));
    let (tide_g, _, _) = effects::tide_series(&ds).expect("tide (site and start known)");
    let u = ds.unit_per_g.expect("mGal per g");
    let n = ds.len();
    let mut cols: Vec<Vec<f64>> = Vec::new();
    // Offset per segment, a linear drift.
    let mut seg = 0usize;
    let seg_id: Vec<usize> = ds
        .segment_start
        .iter()
        .enumerate()
        .map(|(i, s)| {
            if *s && i > 0 {
                seg += 1;
            }
            seg
        })
        .collect();
    for s in 0..=seg {
        cols.push(seg_id.iter().map(|&k| f64::from(k == s)).collect());
    }
    let t0 = ds.t_s[0];
    let span = ds.span_s();
    cols.push(ds.t_s.iter().map(|t| (t - t0) / span).collect());
    cols.push(tide_g.iter().map(|g| g * u).collect());
    // Tidal lines, h: Q1, O1, P1, K1, N2, M2, S2, K2, M3.
    for p_h in [
        26.868_36, 25.819_34, 24.065_89, 23.934_47, 12.658_35, 12.420_60, 12.0, 11.967_24, 8.280_4,
    ] {
        let w = std::f64::consts::TAU / (p_h * 3600.0);
        cols.push(ds.t_s.iter().map(|t| (w * t).sin()).collect());
        cols.push(ds.t_s.iter().map(|t| (w * t).cos()).collect());
    }
    if let Some(p) = ds.channel(import::ChannelKind::Pressure) {
        let m = p.values.iter().sum::<f64>() / n as f64;
        cols.push(p.values.iter().map(|v| v - m).collect());
    }
    Residual {
        t_s: ds.t_s.clone(),
        r_mgal: ls_residual(&cols, &ds.y),
        seg_start: ds.segment_start.clone(),
        pressure_pa: ds
            .channel(import::ChannelKind::Pressure)
            .map(|p| p.values.clone()),
    }
}

/// Contiguous windows of `len` rows inside one segment with regular spacing.
pub fn windows(r: &Residual, len: usize) -> Vec<std::ops::Range<usize>> {
    let mut out = Vec::new();
    let mut i = 0;
    while i + len <= r.t_s.len() {
        let w = i..i + len;
        let regular =
            (w.start + 1..w.end).all(|k| !r.seg_start[k] && r.t_s[k] - r.t_s[k - 1] < 150.0);
        if regular {
            out.push(w.clone());
            i += len;
        } else {
            i += len / 8;
        }
    }
    out
}

/// AR(p) prediction-error whitening fitted to `x` (Levinson–Durbin on the biased
/// autocovariance): returns a function that whitens any series of the same length.
pub fn ar_whitener(x: &[f64], p: usize) -> impl Fn(&[f64]) -> Vec<f64> {
    let n = x.len();
    let m = x.iter().sum::<f64>() / n as f64;
    let r: Vec<f64> = (0..=p)
        .map(|k| (k..n).map(|i| (x[i] - m) * (x[i - k] - m)).sum::<f64>() / n as f64)
        .collect();
    let mut a = vec![0.0; p + 1];
    let mut e = r[0];
    for k in 1..=p {
        let acc: f64 = (1..k).map(|j| a[j] * r[k - j]).sum();
        let kk = (r[k] - acc) / e;
        let prev = a.clone();
        a[k] = kk;
        for j in 1..k {
            a[j] = prev[j] - kk * prev[k - j];
        }
        e *= 1.0 - kk * kk;
    }
    let sigma = e.max(1e-300).sqrt();
    move |s: &[f64]| {
        (p..s.len())
            .map(|i| (s[i] - (1..=p).map(|j| a[j] * s[i - j]).sum::<f64>()) / sigma)
            .collect()
    }
}

/// Rows per bin of the SNR yardstick (5 min): the record repeats readings (the instrument
/// updates more slowly than its 1-min log), which an AR fitted to the raw rows would predict
/// perfectly and so credit a step with far more SNR than any detector of the rows can use.
pub const SNR_BIN: usize = 5;

pub fn bin_means(x: &[f64]) -> Vec<f64> {
    x.chunks(SNR_BIN)
        .map(|c| c.iter().sum::<f64>() / c.len() as f64)
        .collect()
}

/// Matched-filter SNR of `shape` against the noise of `window` (both raw rows): 5-min means,
/// AR(12) prediction-error whitening fitted to the window, after offset and drift.
pub fn snr(shape: &[f64], window: &[f64]) -> f64 {
    let whiten = ar_whitener(&bin_means(window), 12);
    let s = bin_means(shape);
    let n = s.len();
    let nuisance = [
        vec![1.0; n],
        (0..n).map(|i| i as f64 / n as f64).collect::<Vec<_>>(),
    ];
    let cols: Vec<Vec<f64>> = nuisance.iter().map(|c| whiten(c)).collect();
    let r = ls_residual(&cols, &whiten(&s));
    r.iter().map(|v| v * v).sum::<f64>().sqrt()
}
