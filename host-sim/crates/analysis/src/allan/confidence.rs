//! Confidence intervals: the equivalent degrees of freedom (SP 1065 Table 5) and the χ²
//! interval of eq. (45).

/// Equivalent degrees of freedom of the overlapping Allan variance, simple approximations of
/// NIST SP 1065 Table 5 (Howe, Allan & Barnes 1981): `n` phase points, factor `m`, noise `alpha`.
/// An `alpha` outside -2..=2 falls back to `n - 1`. The result is at least 1.
pub fn edf_oadev_simple(n: f64, m: f64, alpha: i32) -> f64 {
    let edf = match alpha {
        2 => (n + 1.0) * (n - 2.0 * m) / (2.0 * (n - m)),
        1 => {
            let a = (n - 1.0) / (2.0 * m);
            let b = (2.0 * m + 1.0) * (n - 1.0) / 4.0;
            if a > 1.0 && b > 1.0 {
                (a.ln() * b.ln()).sqrt().exp()
            } else {
                1.0
            }
        }
        0 => {
            (3.0 * (n - 1.0) / (2.0 * m) - 2.0 * (n - 2.0) / n) * (4.0 * m * m)
                / (4.0 * m * m + 5.0)
        }
        -1 => {
            if m <= 1.0 {
                // NIST SP 1065 Table 5: 2(N − 2)² / (2.3N − 4.9).
                2.0 * (n - 2.0) * (n - 2.0) / (2.3 * n - 4.9)
            } else {
                5.0 * n * n / (4.0 * m * (n + 3.0 * m))
            }
        }
        -2 => {
            (n - 2.0) / (m * (n - 3.0) * (n - 3.0))
                * ((n - 1.0) * (n - 1.0) - 3.0 * m * (n - 1.0) + 4.0 * m * m)
        }
        _ => n - 1.0,
    };
    if edf.is_finite() {
        edf.max(1.0)
    } else {
        1.0
    }
}

/// Lower tail probability of the 1-sigma two-sided interval: (1 - erf(1/sqrt 2)) / 2.
pub const ONE_SIGMA_TAIL: f64 = 0.158_655_253_931_457_05;

/// 68.27 % chi-squared interval of a deviation with `edf` degrees of freedom (SP 1065 eq. (45)).
pub fn chi2_interval(dev: f64, edf: f64) -> (f64, f64) {
    let lo = chi2_quantile(1.0 - ONE_SIGMA_TAIL, edf);
    let hi = chi2_quantile(ONE_SIGMA_TAIL, edf);
    (dev * (edf / lo).sqrt(), dev * (edf / hi).sqrt())
}

/// The χ² quantile (statrs; the precision test against scipy is in `tests.rs`, the comparison
/// with the project's former own quantile in docs/numerics.md).
pub use crate::numerics::distributions::chi2_quantile;
