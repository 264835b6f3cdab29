//! Min/max envelope decimation of long series for plotting.
//!
//! A 41-day log at 1 Hz has 3.5 M samples; a figure is about a thousand pixels wide. Drawing
//! every sample is slow (and makes SVG files of hundreds of MB); taking every k-th sample hides
//! spikes. Instead the x range is cut into `buckets` equal columns (one per pixel column) and each
//! column keeps only its smallest and largest reading, in their original order and at their own
//! x. A line through those points covers exactly the vertical extent the full series would paint
//! in that column, so the picture is the same and every extreme survives.
//!
//! Gaps (NaN readings) are not interpolated: a column that holds a NaN ends the current polyline
//! after its own points, so a gap shows as a break of at least one pixel column.

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

/// Extremes of one pixel column: indices and values of its minimum and maximum.
#[derive(Clone, Copy)]
struct Column {
    min: (usize, f64),
    max: (usize, f64),
}

/// Min/max envelope of `(x, y)` over `buckets` equal columns of the x range.
///
/// `x` must be non-decreasing (a log's time axis is strictly increasing). Series with at most
/// `2 * buckets` points are only split at gaps: decimation would not save anything.
pub fn envelope(x: &[f64], y: &[f64], buckets: usize) -> Vec<Segment> {
    let n = x.len().min(y.len());
    let (x, y) = (&x[..n], &y[..n]);
    if buckets == 0 || n <= 2 * buckets {
        return split_at_gaps(x, y);
    }
    let (Some(&x0), Some(&x1)) = (
        x.iter().find(|v| v.is_finite()),
        x.iter().rev().find(|v| v.is_finite()),
    ) else {
        return Vec::new();
    };
    let span = x1 - x0;
    if span <= 0.0 {
        return split_at_gaps(x, y);
    }
    let scale = buckets as f64 / span;
    let mut out = Vec::new();
    let mut cur: Segment = Vec::new();
    let mut col: Option<Column> = None;
    let mut col_has_gap = false;
    let mut col_index = 0usize;
    // Emits the finished column's extremes in sample order, then breaks the line if the column
    // held a gap.
    let flush = |col: &mut Option<Column>, gap: bool, cur: &mut Segment, out: &mut Vec<Segment>| {
        if let Some(c) = col.take() {
            let (a, b) = if c.min.0 <= c.max.0 {
                (c.min, c.max)
            } else {
                (c.max, c.min)
            };
            cur.push((x[a.0], a.1));
            if b.0 != a.0 {
                cur.push((x[b.0], b.1));
            }
        }
        if gap && !cur.is_empty() {
            out.push(std::mem::take(cur));
        }
    };
    for i in 0..n {
        let xi = x[i];
        if !xi.is_finite() {
            col_has_gap = true;
            continue;
        }
        let k = (((xi - x0) * scale) as usize).min(buckets - 1);
        if k != col_index {
            flush(&mut col, col_has_gap, &mut cur, &mut out);
            col_has_gap = false;
            col_index = k;
        }
        let yi = y[i];
        if !yi.is_finite() {
            col_has_gap = true;
            continue;
        }
        match &mut col {
            None => {
                col = Some(Column {
                    min: (i, yi),
                    max: (i, yi),
                })
            }
            Some(c) => {
                if yi < c.min.1 {
                    c.min = (i, yi);
                }
                if yi > c.max.1 {
                    c.max = (i, yi);
                }
            }
        }
    }
    flush(&mut col, col_has_gap, &mut cur, &mut out);
    if !cur.is_empty() {
        out.push(cur);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn all_points(s: &[Segment]) -> Vec<(f64, f64)> {
        s.iter().flatten().copied().collect()
    }

    #[test]
    fn a_single_spike_in_a_million_samples_survives() {
        let n: usize = 1_000_000;
        let x: Vec<f64> = (0..n).map(|i| i as f64).collect();
        // Small deterministic wiggle plus one positive and one negative spike.
        let mut y: Vec<f64> = (0..n).map(|i| ((i * 7919) % 1000) as f64 * 1e-3).collect();
        y[123_457] = 50.0;
        y[876_543] = -40.0;
        let s = envelope(&x, &y, 1000);
        let p = all_points(&s);
        assert!(p.len() <= 2000, "{} points", p.len());
        assert!(p.contains(&(123_457.0, 50.0)));
        assert!(p.contains(&(876_543.0, -40.0)));
        let ymax = p.iter().map(|q| q.1).fold(f64::MIN, f64::max);
        let ymin = p.iter().map(|q| q.1).fold(f64::MAX, f64::min);
        assert_eq!((ymin, ymax), (-40.0, 50.0));
    }

    #[test]
    fn every_pixel_column_keeps_its_own_min_and_max() {
        // 10 columns of 100 samples; column c ramps from c to c + 0.99 going down then up.
        let x: Vec<f64> = (0..1000).map(|i| i as f64).collect();
        let y: Vec<f64> = (0..1000)
            .map(|i| {
                let c = (i / 100) as f64;
                let j = (i % 100) as f64;
                c + (j - 50.0).abs() / 100.0
            })
            .collect();
        let p = all_points(&envelope(&x, &y, 10));
        assert_eq!(p.len(), 20);
        for c in 0..10 {
            let inside: Vec<f64> = p
                .iter()
                .filter(|q| (q.0 as usize) / 100 == c)
                .map(|q| q.1)
                .collect();
            let lo = inside.iter().copied().fold(f64::MAX, f64::min);
            let hi = inside.iter().copied().fold(f64::MIN, f64::max);
            assert_eq!(lo, c as f64, "column {c}");
            assert_eq!(hi, c as f64 + 0.5, "column {c}");
        }
    }

    #[test]
    fn points_stay_in_time_order() {
        let x: Vec<f64> = (0..10_000).map(|i| i as f64 * 0.5).collect();
        let y: Vec<f64> = (0..10_000).map(|i| ((i as f64) * 0.37).sin()).collect();
        let p = all_points(&envelope(&x, &y, 100));
        assert!(p.windows(2).all(|w| w[0].0 < w[1].0));
    }

    #[test]
    fn gaps_break_the_line_and_are_not_bridged() {
        let x: Vec<f64> = (0..10_000).map(|i| i as f64).collect();
        let mut y = vec![1.0; 10_000];
        for v in &mut y[4000..4500] {
            *v = f64::NAN;
        }
        let s = envelope(&x, &y, 100);
        assert_eq!(s.len(), 2);
        let last_before = s[0].last().map(|p| p.0).unwrap_or(f64::NAN);
        let first_after = s[1].first().map(|p| p.0).unwrap_or(f64::NAN);
        assert!(last_before < 4000.0 && first_after >= 4500.0);
    }

    #[test]
    fn short_series_are_only_split_at_gaps() {
        let x = [0.0, 1.0, 2.0, 3.0, 4.0];
        let y = [1.0, f64::NAN, 3.0, 4.0, 5.0];
        let s = envelope(&x, &y, 1000);
        assert_eq!(
            s,
            vec![vec![(0.0, 1.0)], vec![(2.0, 3.0), (3.0, 4.0), (4.0, 5.0)]]
        );
    }
}
