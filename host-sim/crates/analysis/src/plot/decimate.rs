//! Decimation of long series for plotting: mean and min/max envelope per pixel column.
//!
//! A 41-day log at 1 Hz has 3.5 M samples; a figure is about a thousand pixels wide. Drawing
//! every sample is slow (and makes SVG files of hundreds of MB); taking every k-th sample hides
//! spikes. Instead the x range is cut into equal columns (one per pixel column) and each column
//! keeps its mean, smallest and largest reading. The figures shade min..max (so every spike stays
//! visible, exactly as tall as in the full series) and draw the mean as the line: with ~3000
//! white-noise readings per column a min/max polyline alone would be a solid band that hides the
//! drift and the temperature effect the figures are about.
//!
//! Gaps (NaN readings) are not interpolated: a column that holds a NaN ends the current run after
//! its own bucket, so a gap shows as a break of at least one pixel column.

/// One unbroken polyline, as (x, y) points.
pub type Segment = Vec<(f64, f64)>;

/// Splits a series into polylines at NaN readings, without decimating.
pub fn split_at_gaps(x: &[f64], y: &[f64]) -> Vec<Segment> {
    let mut out = Vec::new();
    let mut cur: Segment = Vec::new();
    for (&xi, &yi) in x.iter().zip(y) {
        if xi.is_finite() && yi.is_finite() {
            cur.push((xi, yi));
        } else if !cur.is_empty() {
            out.push(std::mem::take(&mut cur));
        }
    }
    if !cur.is_empty() {
        out.push(cur);
    }
    out
}

/// One pixel column of a decimated series.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bucket {
    /// Mean x of the column's finite readings.
    pub x: f64,
    /// Mean reading: the line drawn, which shows drift and slow effects through the noise.
    pub mean: f64,
    /// Smallest reading: lower edge of the shaded envelope.
    pub min: f64,
    /// Largest reading: upper edge of the shaded envelope.
    pub max: f64,
}

/// An unbroken run of pixel columns (runs are separated by gaps).
pub type Run = Vec<Bucket>;

/// Running sums of one column.
#[derive(Clone, Copy)]
struct Acc {
    n: usize,
    sx: f64,
    sy: f64,
    min: f64,
    max: f64,
}

impl Acc {
    fn new(x: f64, y: f64) -> Self {
        Acc {
            n: 1,
            sx: x,
            sy: y,
            min: y,
            max: y,
        }
    }
    fn add(&mut self, x: f64, y: f64) {
        self.n += 1;
        self.sx += x;
        self.sy += y;
        self.min = self.min.min(y);
        self.max = self.max.max(y);
    }
    fn bucket(&self) -> Bucket {
        let n = self.n as f64;
        Bucket {
            x: self.sx / n,
            mean: self.sy / n,
            min: self.min,
            max: self.max,
        }
    }
}

/// Mean, min and max of `(x, y)` in each of `buckets` equal columns of the x range.
///
/// `x` must be non-decreasing (a log's time axis is strictly increasing). Series with at most
/// `2 * buckets` points are not decimated: each reading is its own bucket (min = max = mean), and
/// only split at gaps.
pub fn buckets(x: &[f64], y: &[f64], buckets: usize) -> Vec<Run> {
    buckets_broken(x, y, buckets, &[])
}

/// As [`buckets`], with the runs also broken before each row index in `breaks` (ascending): the
/// first rows of a recorder's continuous segments, so no line joins the readings of two boots.
pub fn buckets_broken(x: &[f64], y: &[f64], buckets: usize, breaks: &[usize]) -> Vec<Run> {
    let n = x.len().min(y.len());
    let (x, y) = (&x[..n], &y[..n]);
    let single = |seg: Segment| -> Run {
        seg.into_iter()
            .map(|(x, y)| Bucket {
                x,
                mean: y,
                min: y,
                max: y,
            })
            .collect()
    };
    if buckets == 0 || n <= 2 * buckets {
        let mut bounds = vec![0];
        bounds.extend(breaks.iter().copied().filter(|&b| b > 0 && b < n));
        bounds.push(n);
        return bounds
            .windows(2)
            .flat_map(|w| split_at_gaps(&x[w[0]..w[1]], &y[w[0]..w[1]]))
            .map(single)
            .collect();
    }
    let (Some(&x0), Some(&x1)) = (
        x.iter().find(|v| v.is_finite()),
        x.iter().rev().find(|v| v.is_finite()),
    ) else {
        return Vec::new();
    };
    let span = x1 - x0;
    if span <= 0.0 {
        return split_at_gaps(x, y).into_iter().map(single).collect();
    }
    let scale = buckets as f64 / span;
    let mut out = Vec::new();
    let mut cur: Run = Vec::new();
    let mut acc: Option<Acc> = None;
    let mut col_has_gap = false;
    let mut col_index = 0usize;
    // Ends a column: its bucket joins the run, and a gap inside it ends the run.
    let flush = |acc: &mut Option<Acc>, gap: bool, cur: &mut Run, out: &mut Vec<Run>| {
        if let Some(a) = acc.take() {
            cur.push(a.bucket());
        }
        if gap && !cur.is_empty() {
            out.push(std::mem::take(cur));
        }
    };
    let mut next_break = breaks.iter().copied().peekable();
    for (i, (&xi, &yi)) in x.iter().zip(y).enumerate() {
        let at_break = next_break.next_if(|&b| b <= i).is_some();
        if !xi.is_finite() {
            col_has_gap = true;
            continue;
        }
        let k = (((xi - x0) * scale) as usize).min(buckets - 1);
        if k != col_index || at_break {
            flush(&mut acc, col_has_gap || at_break, &mut cur, &mut out);
            col_has_gap = false;
            col_index = k;
        }
        if !yi.is_finite() {
            col_has_gap = true;
            continue;
        }
        match &mut acc {
            None => acc = Some(Acc::new(xi, yi)),
            Some(a) => a.add(xi, yi),
        }
    }
    flush(&mut acc, col_has_gap, &mut cur, &mut out);
    if !cur.is_empty() {
        out.push(cur);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn all(r: &[Run]) -> Vec<Bucket> {
        r.iter().flatten().copied().collect()
    }

    #[test]
    fn a_single_spike_in_a_million_samples_survives() {
        let n: usize = 1_000_000;
        let x: Vec<f64> = (0..n).map(|i| i as f64).collect();
        // Small deterministic wiggle plus one positive and one negative spike.
        let mut y: Vec<f64> = (0..n).map(|i| ((i * 7919) % 1000) as f64 * 1e-3).collect();
        y[123_457] = 50.0;
        y[876_543] = -40.0;
        let b = all(&buckets(&x, &y, 1000));
        assert_eq!(b.len(), 1000);
        let top = b.iter().map(|q| q.max).fold(f64::MIN, f64::max);
        let bottom = b.iter().map(|q| q.min).fold(f64::MAX, f64::min);
        assert_eq!((bottom, top), (-40.0, 50.0));
        // ... in the pixel columns where they happened (1000 samples per column).
        assert_eq!(b[123].max, 50.0);
        assert_eq!(b[876].min, -40.0);
    }

    #[test]
    fn every_pixel_column_keeps_its_own_min_max_and_mean() {
        // 10 columns of 100 samples; column c is c + |j - 50| / 100 for j = 0..100, whose
        // minimum is c, maximum c + 0.5 and mean c + 2500 / 10000 = c + 0.25.
        let x: Vec<f64> = (0..1000).map(|i| i as f64).collect();
        let y: Vec<f64> = (0..1000)
            .map(|i| {
                let c = (i / 100) as f64;
                let j = (i % 100) as f64;
                c + (j - 50.0).abs() / 100.0
            })
            .collect();
        let b = all(&buckets(&x, &y, 10));
        assert_eq!(b.len(), 10);
        for (c, q) in b.iter().enumerate() {
            let c = c as f64;
            assert_eq!(q.min, c, "column {c}");
            assert_eq!(q.max, c + 0.5, "column {c}");
            assert!(
                (q.mean - (c + 0.25)).abs() < 1e-12,
                "column {c}: {}",
                q.mean
            );
            assert!((q.x - (100.0 * c + 49.5)).abs() < 1e-9);
        }
    }

    #[test]
    fn buckets_stay_in_time_order() {
        let x: Vec<f64> = (0..10_000).map(|i| i as f64 * 0.5).collect();
        let y: Vec<f64> = (0..10_000).map(|i| ((i as f64) * 0.37).sin()).collect();
        let b = all(&buckets(&x, &y, 100));
        assert!(b.windows(2).all(|w| w[0].x < w[1].x));
    }

    #[test]
    fn gaps_break_the_run_and_are_not_bridged() {
        let x: Vec<f64> = (0..10_000).map(|i| i as f64).collect();
        let mut y = vec![1.0; 10_000];
        for v in &mut y[4000..4500] {
            *v = f64::NAN;
        }
        let r = buckets(&x, &y, 100);
        assert_eq!(r.len(), 2);
        let last_before = r[0].last().map_or(f64::NAN, |b| b.x);
        let first_after = r[1].first().map_or(f64::NAN, |b| b.x);
        assert!(last_before < 4000.0 && first_after >= 4500.0);
    }

    #[test]
    fn a_break_ends_the_run_even_inside_a_pixel_column() {
        // 10 columns of 100 samples, a break at row 450 (mid column 4): two runs, columns 0..=4
        // and 4..=9, column 4 cut in two buckets, each with the mean of its own side.
        let x: Vec<f64> = (0..1000).map(|i| i as f64).collect();
        let y: Vec<f64> = (0..1000).map(|i| if i < 450 { 1.0 } else { 2.0 }).collect();
        let r = buckets_broken(&x, &y, 10, &[450]);
        assert_eq!(r.len(), 2);
        assert_eq!((r[0].len(), r[1].len()), (5, 6));
        assert_eq!(r[0][4].mean, 1.0);
        assert_eq!(r[1][0].mean, 2.0);
        assert!(r[0][4].x < 450.0 && r[1][0].x >= 450.0);
        // Not decimated (short): split there as at a gap.
        let r = buckets_broken(&x[..10], &y[..10], 1000, &[4]);
        assert_eq!((r.len(), r[0].len(), r[1].len()), (2, 4, 6));
    }

    #[test]
    fn short_series_are_only_split_at_gaps() {
        let x = [0.0, 1.0, 2.0, 3.0, 4.0];
        let y = [1.0, f64::NAN, 3.0, 4.0, 5.0];
        let s = split_at_gaps(&x, &y);
        assert_eq!(
            s,
            vec![vec![(0.0, 1.0)], vec![(2.0, 3.0), (3.0, 4.0), (4.0, 5.0)]]
        );
        let r = buckets(&x, &y, 1000);
        assert_eq!(r.len(), 2);
        assert_eq!(
            r[1][0],
            Bucket {
                x: 2.0,
                mean: 3.0,
                min: 3.0,
                max: 3.0
            }
        );
    }
}
