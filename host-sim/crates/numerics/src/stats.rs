//! Descriptive statistics shared by the host's analyses (mean, sample standard deviation).
//! Here rather than inside one analysis so that no module imports another only for these
//! (`discover::import` used to reach into `discover::baseline` for its standard deviation while
//! the baseline imports the dataset: an import circle).

/// Arithmetic mean (NaN for an empty slice).
pub fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

/// Sample standard deviation (n − 1 in the denominator; 0 for fewer than two values).
pub fn std(v: &[f64]) -> f64 {
    let n = v.len() as f64;
    if n < 2.0 {
        return 0.0;
    }
    let m = mean(v);
    (v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1.0)).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sample_standard_deviation_uses_n_minus_one() {
        // 1, 2, 3, 4: mean 2.5, Σ(x − m)² = 5, s = √(5/3).
        assert_eq!(mean(&[1.0, 2.0, 3.0, 4.0]), 2.5);
        assert!((std(&[1.0, 2.0, 3.0, 4.0]) - (5.0f64 / 3.0).sqrt()).abs() < 1e-15);
        assert_eq!(std(&[7.0]), 0.0);
    }
}
