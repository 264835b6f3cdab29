//! Operations on a uniformly sampled series.

/// The rate of change of `x` sampled every `dt_s` seconds, per second: central differences,
/// one-sided at the two ends (an empty series gives an empty one).
pub fn central_difference(x: &[f64], dt_s: f64) -> Vec<f64> {
    let n = x.len();
    (0..n)
        .map(|i| {
            let (a, b) = (i.saturating_sub(1), (i + 1).min(n - 1));
            (x[b] - x[a]) / ((b - a) as f64 * dt_s)
        })
        .collect()
}

/// Block means of the series `v` sampled at `t`: a block opens at the first point and wherever
/// `opens(i, t[i])` says so (the caller's binning rule). Per block: the mean time, the mean value
/// and the number of points (as f64, the divisor of both means).
pub fn block_means(
    t: &[f64],
    v: &[f64],
    mut opens: impl FnMut(usize, f64) -> bool,
) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let (mut ts, mut vs, mut counts) = (Vec::new(), Vec::new(), Vec::new());
    for (i, (&ti, &vi)) in t.iter().zip(v).enumerate() {
        if opens(i, ti) || counts.is_empty() {
            ts.push(0.0);
            vs.push(0.0);
            counts.push(0.0);
        }
        let k = counts.len() - 1;
        ts[k] += ti;
        vs[k] += vi;
        counts[k] += 1.0;
    }
    for ((tk, vk), c) in ts.iter_mut().zip(&mut vs).zip(&counts) {
        *tk /= c;
        *vk /= c;
    }
    (ts, vs, counts)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_quadratic_has_its_exact_slope_inside_and_the_chord_slope_at_the_ends() {
        // x = t² at t = 0, 2, 4, 6: inside (x[i+1] − x[i−1]) / 4 = t exactly·2; ends one-sided.
        let x = [0.0, 4.0, 16.0, 36.0];
        assert_eq!(central_difference(&x, 2.0), vec![2.0, 4.0, 8.0, 10.0]);
        assert!(central_difference(&[], 1.0).is_empty());
    }

    #[test]
    fn block_means_average_time_and_value_over_each_block_the_rule_opens() {
        let t = [0.0, 1.0, 2.0, 3.0, 4.0];
        let v = [1.0, 3.0, 10.0, 20.0, 30.0];
        // Blocks open at index 2 (and at the first point, whatever the rule says).
        let (tm, vm, n) = block_means(&t, &v, |i, _| i == 2);
        assert_eq!(tm, vec![0.5, 3.0]);
        assert_eq!(vm, vec![2.0, 20.0]);
        assert_eq!(n, vec![2.0, 3.0]);
        assert_eq!(block_means(&[], &[], |_, _| true), (vec![], vec![], vec![]));
    }
}
