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
}
