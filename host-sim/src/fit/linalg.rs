//! Dense least squares by Householder QR, written out so that the fitting never forms the normal
//! equations: QR works on the design matrix itself, so its error grows with cond(A), not
//! cond(A)² — the difference between "fine" and "wrecked" for a 4th-order fit in raw °C.

use thiserror::Error;

/// Why a least-squares problem cannot be solved.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum LinalgError {
    /// Fewer rows than unknowns, or rows of unequal length.
    #[error("design matrix is {rows}×{cols}: need at least as many rows as columns")]
    Shape {
        /// Rows (observations).
        rows: usize,
        /// Columns (unknowns).
        cols: usize,
    },
    /// A column is (numerically) a combination of the previous ones.
    #[error("design matrix is rank deficient at column {column}")]
    RankDeficient {
        /// The column whose pivot vanished.
        column: usize,
    },
    /// A NaN or infinity in the matrix or the data.
    #[error("non-finite value in the least-squares data")]
    NonFinite,
}

/// The solution of min ‖A·c − y‖₂ together with what the statistics need.
#[derive(Debug, Clone, PartialEq)]
pub struct LeastSquares {
    /// The coefficients c.
    pub coeffs: Vec<f64>,
    /// y − A·c, computed from the original A (not from Qᵀy) so that they are the true residuals.
    pub residuals: Vec<f64>,
    /// Σ residuals².
    pub rss: f64,
    /// The triangular factor R (n×n, row-major, lower part zero): AᵀA = RᵀR.
    pub r: Vec<Vec<f64>>,
    /// Diagonal of the hat matrix H = A(AᵀA)⁻¹Aᵀ, h_ii = ‖R⁻ᵀ·a_i‖².
    pub leverage: Vec<f64>,
}

impl LeastSquares {
    /// diag((RᵀR)⁻¹) = diag((AᵀA)⁻¹), the unscaled coefficient variances, from R⁻¹ (triangular
    /// back substitution; AᵀA itself is never formed).
    pub fn unscaled_variances(&self) -> Vec<f64> {
        let rinv = upper_inverse(&self.r);
        rinv.iter()
            .map(|row| row.iter().map(|v| v * v).sum())
            .collect()
    }
}

/// Solves min ‖A·c − y‖₂ for a full-rank A (rows = observations) by Householder QR.
pub fn least_squares(a: &[Vec<f64>], y: &[f64]) -> Result<LeastSquares, LinalgError> {
    let m = a.len();
    let n = a.first().map_or(0, Vec::len);
    if n == 0 || m < n || y.len() != m || a.iter().any(|row| row.len() != n) {
        return Err(LinalgError::Shape { rows: m, cols: n });
    }
    if a.iter().flatten().chain(y).any(|v| !v.is_finite()) {
        return Err(LinalgError::NonFinite);
    }
    // Column-major working copy (Householder acts on columns): the top n rows become R.
    let mut cols: Vec<Vec<f64>> = (0..n)
        .map(|j| a.iter().map(|row| row[j]).collect())
        .collect();
    let mut qty = y.to_vec();
    let scale = a
        .iter()
        .flatten()
        .fold(0.0_f64, |acc, v| acc.max(v.abs()))
        .max(f64::MIN_POSITIVE);
    for k in 0..n {
        let x = &cols[k][k..];
        let norm = x.iter().map(|v| v * v).sum::<f64>().sqrt();
        // A pivot below m·ε of the matrix scale means column k adds nothing new.
        if norm <= (m as f64) * f64::EPSILON * scale {
            return Err(LinalgError::RankDeficient { column: k });
        }
        // Reflect onto −sign(x0)·‖x‖ e1 so that v0 = x0 − α never cancels.
        let alpha = if x[0] >= 0.0 { -norm } else { norm };
        let mut v = x.to_vec();
        v[0] -= alpha;
        let vtv: f64 = v.iter().map(|x| x * x).sum();
        let reflect = |target: &mut [f64]| {
            let dot: f64 = v.iter().zip(target.iter()).map(|(vi, ti)| vi * ti).sum();
            let f = 2.0 * dot / vtv;
            for (ti, vi) in target.iter_mut().zip(&v) {
                *ti -= f * vi;
            }
        };
        for col in cols.iter_mut().skip(k) {
            reflect(&mut col[k..]);
        }
        reflect(&mut qty[k..]);
    }
    let r: Vec<Vec<f64>> = (0..n)
        .map(|i| {
            (0..n)
                .map(|j| if j >= i { cols[j][i] } else { 0.0 })
                .collect()
        })
        .collect();
    let coeffs = back_substitute(&r, &qty[..n]);
    let residuals: Vec<f64> = a
        .iter()
        .zip(y)
        .map(|(row, yi)| {
            yi - row
                .iter()
                .zip(&coeffs)
                .map(|(aij, cj)| aij * cj)
                .sum::<f64>()
        })
        .collect();
    let rss = residuals.iter().map(|e| e * e).sum();
    let leverage = a
        .iter()
        .map(|row| {
            forward_substitute_transposed(&r, row)
                .iter()
                .map(|z| z * z)
                .sum()
        })
        .collect();
    Ok(LeastSquares {
        coeffs,
        residuals,
        rss,
        r,
        leverage,
    })
}

/// Solves R·x = b for upper-triangular R with a non-zero diagonal.
fn back_substitute(r: &[Vec<f64>], b: &[f64]) -> Vec<f64> {
    let n = b.len();
    let mut x = vec![0.0; n];
    for i in (0..n).rev() {
        let s: f64 = ((i + 1)..n).map(|j| r[i][j] * x[j]).sum();
        x[i] = (b[i] - s) / r[i][i];
    }
    x
}

/// Solves Rᵀ·z = b for upper-triangular R (forward substitution on the transpose).
fn forward_substitute_transposed(r: &[Vec<f64>], b: &[f64]) -> Vec<f64> {
    let n = b.len();
    let mut z = vec![0.0; n];
    for i in 0..n {
        let s: f64 = (0..i).map(|j| r[j][i] * z[j]).sum();
        z[i] = (b[i] - s) / r[i][i];
    }
    z
}

/// R⁻¹ of an upper-triangular R, solved column by column, returned row-major.
fn upper_inverse(r: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let n = r.len();
    let cols: Vec<Vec<f64>> = (0..n)
        .map(|c| {
            let e: Vec<f64> = (0..n).map(|i| if i == c { 1.0 } else { 0.0 }).collect();
            back_substitute(r, &e)
        })
        .collect();
    (0..n)
        .map(|i| cols.iter().map(|c| c[i]).collect())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vandermonde(t: &[f64], order: usize) -> Vec<Vec<f64>> {
        t.iter()
            .map(|ti| (0..=order).map(|j| ti.powi(j as i32)).collect())
            .collect()
    }

    #[test]
    fn recovers_an_exact_cubic() {
        let t: Vec<f64> = (0..9).map(|i| -1.0 + 0.25 * f64::from(i)).collect();
        let y: Vec<f64> = t
            .iter()
            .map(|x| 0.5 - 2.0 * x + 0.75 * x * x + 3.0 * x * x * x)
            .collect();
        let ls = least_squares(&vandermonde(&t, 3), &y).unwrap();
        for (got, want) in ls.coeffs.iter().zip([0.5, -2.0, 0.75, 3.0]) {
            assert!((got - want).abs() < 1e-14, "{got} vs {want}");
        }
        assert!(ls.rss < 1e-28);
    }

    #[test]
    fn straight_line_far_from_the_origin_matches_the_exact_rational_closed_form() {
        // t = 100 000 + i: cond([1, t]) ≈ 1e5·√(mean t²)/σ_t ~ 1e10 for the normal equations'
        // AᵀA, ~1e5 for A itself. Integer data, so the closed form
        //   slope = (nΣty − ΣtΣy)/(nΣt² − (Σt)²), intercept = (Σy − slope·Σt)/n
        // is evaluated exactly in i128 and only divided at the end.
        let t: Vec<i128> = (0..10).map(|i| 100_000 + i).collect();
        let y: Vec<i128> = [3, 7, 4, 9, 12, 8, 15, 14, 19, 17].to_vec();
        let n = t.len() as i128;
        let st: i128 = t.iter().sum();
        let sy: i128 = y.iter().sum();
        let stt: i128 = t.iter().map(|v| v * v).sum();
        let sty: i128 = t.iter().zip(&y).map(|(a, b)| a * b).sum();
        let num = n * sty - st * sy;
        let den = n * stt - st * st;
        let slope = num as f64 / den as f64;
        // intercept = (Σy·den − num·Σt)/(n·den), exact numerator in i128.
        let intercept = (sy * den - num * st) as f64 / (n * den) as f64;

        let tf: Vec<f64> = t.iter().map(|v| *v as f64).collect();
        let yf: Vec<f64> = y.iter().map(|v| *v as f64).collect();
        let ls = least_squares(&vandermonde(&tf, 1), &yf).unwrap();
        // QR's forward error is ~cond(A)·ε ≈ 1e5 · 2e-16; allow 1e-9 relative.
        assert!(((ls.coeffs[1] - slope) / slope).abs() < 1e-9);
        assert!(((ls.coeffs[0] - intercept) / intercept).abs() < 1e-9);
    }

    #[test]
    fn leverages_sum_to_the_number_of_parameters_and_variances_match_the_line_formula() {
        let t = [1.0, 2.0, 4.0, 7.0, 11.0];
        let y = [0.1, 0.3, 0.2, 0.6, 0.9];
        let ls = least_squares(&vandermonde(&t, 1), &y).unwrap();
        let trace: f64 = ls.leverage.iter().sum();
        assert!((trace - 2.0).abs() < 1e-13);
        // Straight line: var(slope)/σ² = 1/Sxx, var(intercept)/σ² = Σt²/(n·Sxx).
        let n = 5.0;
        let mean = t.iter().sum::<f64>() / n;
        let sxx: f64 = t.iter().map(|v| (v - mean) * (v - mean)).sum();
        let stt: f64 = t.iter().map(|v| v * v).sum();
        let var = ls.unscaled_variances();
        assert!((var[1] - 1.0 / sxx).abs() < 1e-14);
        assert!((var[0] - stt / (n * sxx)).abs() < 1e-13);
        // Leverage of a line: 1/n + (t − mean)²/Sxx.
        for (h, ti) in ls.leverage.iter().zip(t) {
            assert!((h - (1.0 / n + (ti - mean).powi(2) / sxx)).abs() < 1e-14);
        }
    }

    #[test]
    fn duplicate_columns_and_too_few_rows_are_refused() {
        let a = vec![vec![1.0, 2.0], vec![1.0, 2.0], vec![1.0, 2.0]];
        assert_eq!(
            least_squares(&a, &[1.0, 2.0, 3.0]),
            Err(LinalgError::RankDeficient { column: 1 })
        );
        let a = vec![vec![1.0, 2.0]];
        assert!(matches!(
            least_squares(&a, &[1.0]),
            Err(LinalgError::Shape { .. })
        ));
        let a = vec![vec![1.0], vec![f64::NAN]];
        assert_eq!(least_squares(&a, &[1.0, 2.0]), Err(LinalgError::NonFinite));
    }
}
