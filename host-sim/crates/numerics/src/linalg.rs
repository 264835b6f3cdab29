//! Dense least squares for the host tools, over nalgebra's Householder QR: the design matrix is
//! factored itself, the normal equations are never formed, so the error grows with cond(A), not
//! cond(A)² — the difference between "fine" and "wrecked" for a 4th-order fit in raw °C. One
//! module for every fit on the host:
//! - [`least_squares`] (`fit`, `tumble`): solution, residuals, leverages, the unscaled
//!   covariance (RᵀR)⁻¹ and the solution operator R⁻¹Qᵀ (for propagating any noise covariance
//!   to the coefficients); a rank-deficient design is an error.
//! - [`OrthonormalBasis`] (`discover`): the same QR of columns scaled to unit norm, where a
//!   column that adds nothing new is *dropped* (coefficient 0 ± ∞) instead of refused — the
//!   discovery tries candidate columns that may overlap the baseline — and columns can be
//!   appended one at a time to score candidates against the current model.
//! - [`solve_square`]: a small square system that is not a least-squares problem (the
//!   noise model's 3×3 moment equations in `discover::noise`), by LU with partial pivoting.

use nalgebra::{DMatrix, DVector};
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

/// When a pivot |R_kk| counts as zero (column k adds nothing new).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RankTolerance {
    /// |R_kk| ≤ m·ε·max|a_ij|: rounding level, for well-scaled designs (the default).
    Rounding,
    /// |R_kk| ≤ rel·max_j ‖a_j‖₂: a design that is singular for the problem's purpose well above
    /// rounding (e.g. rel = 1e-5 refuses what a 1e-10 pivot of AᵀA would).
    RelativeToColumnNorm(f64),
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
    /// Diagonal of the hat matrix H = A(AᵀA)⁻¹Aᵀ = QQᵀ, h_ii = ‖row i of Q‖².
    pub leverage: Vec<f64>,
    /// R⁻¹ (n×n).
    r_inv: DMatrix<f64>,
    /// The thin Q (m×n).
    q: DMatrix<f64>,
}

impl LeastSquares {
    /// diag((RᵀR)⁻¹) = diag((AᵀA)⁻¹), the unscaled coefficient variances (AᵀA never formed).
    pub fn unscaled_variances(&self) -> Vec<f64> {
        self.r_inv
            .row_iter()
            .map(|row| row.iter().map(|v| v * v).sum())
            .collect()
    }

    /// (AᵀA)⁻¹ = R⁻¹R⁻ᵀ, row-major: times σ² it is the coefficients' covariance.
    pub fn unscaled_covariance(&self) -> Vec<Vec<f64>> {
        rows(&(&self.r_inv * self.r_inv.transpose()))
    }

    /// The solution operator A⁺ = R⁻¹Qᵀ (n×m, row-major): c = A⁺·y, so a noise covariance Σ of y
    /// gives A⁺ Σ A⁺ᵀ for c.
    pub fn solution_operator(&self) -> Vec<Vec<f64>> {
        rows(&(&self.r_inv * self.q.transpose()))
    }
}

fn rows(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    m.row_iter().map(|r| r.iter().copied().collect()).collect()
}

/// Solves min ‖A·c − y‖₂ for a full-rank A (rows = observations) by Householder QR.
pub fn least_squares(a: &[Vec<f64>], y: &[f64]) -> Result<LeastSquares, LinalgError> {
    least_squares_with(a, y, RankTolerance::Rounding)
}

/// [`least_squares`] with an explicit rank tolerance.
pub fn least_squares_with(
    a: &[Vec<f64>],
    y: &[f64],
    tolerance: RankTolerance,
) -> Result<LeastSquares, LinalgError> {
    let m = a.len();
    let n = a.first().map_or(0, Vec::len);
    if n == 0 || m < n || y.len() != m || a.iter().any(|row| row.len() != n) {
        return Err(LinalgError::Shape { rows: m, cols: n });
    }
    if a.iter().flatten().chain(y).any(|v| !v.is_finite()) {
        return Err(LinalgError::NonFinite);
    }
    let am = DMatrix::from_fn(m, n, |i, j| a[i][j]);
    let zero_pivot = match tolerance {
        RankTolerance::Rounding => (m as f64) * f64::EPSILON * am.amax().max(f64::MIN_POSITIVE),
        RankTolerance::RelativeToColumnNorm(rel) => {
            rel * am
                .column_iter()
                .map(|c| c.norm())
                .fold(0.0, f64::max)
                .max(f64::MIN_POSITIVE)
        }
    };
    let qr = am.clone().qr();
    let r = qr.r();
    if let Some(column) = (0..n).find(|&k| r[(k, k)].abs() <= zero_pivot) {
        return Err(LinalgError::RankDeficient { column });
    }
    let q = qr.q();
    let r_inv = r
        .solve_upper_triangular(&DMatrix::identity(n, n))
        .ok_or(LinalgError::RankDeficient { column: n - 1 })?;
    let yv = DVector::from_column_slice(y);
    let coeffs_v = r
        .solve_upper_triangular(&(q.transpose() * &yv))
        .ok_or(LinalgError::RankDeficient { column: n - 1 })?;
    let residuals: Vec<f64> = (yv - &am * &coeffs_v).iter().copied().collect();
    let rss = residuals.iter().map(|e| e * e).sum();
    let leverage = q
        .row_iter()
        .map(|row| row.iter().map(|v| v * v).sum())
        .collect();
    Ok(LeastSquares {
        coeffs: coeffs_v.iter().copied().collect(),
        residuals,
        rss,
        r: rows(&r),
        leverage,
        r_inv,
        q,
    })
}

/// Solves the square system `a·x = b` (`a` by rows) by LU with partial pivoting; `None` when `a`
/// is not square, its size differs from `b`'s, or it is singular. For small systems that are
/// not least squares (a least-squares fit goes through [`least_squares`], which never forms the
/// normal equations).
pub fn solve_square(a: &[Vec<f64>], b: &[f64]) -> Option<Vec<f64>> {
    let n = b.len();
    if a.len() != n || a.iter().any(|row| row.len() != n) {
        return None;
    }
    let m = DMatrix::from_fn(n, n, |r, c| a[r][c]);
    let x = m.lu().solve(&DVector::from_column_slice(b))?;
    Some(x.iter().copied().collect())
}

/// A column counts as dependent when its part orthogonal to the previous columns is below this
/// fraction of its own norm (|R_kk| of the unit-norm column).
pub const DEPENDENT_COLUMN_REL: f64 = 1.0e-9;

/// Projects `v` onto the orthogonal complement of the orthonormal columns `q`, in place, and
/// returns the coefficients removed (Qᵀv). Two passes: one projection loses orthogonality in
/// proportion to how much of `v` lay in span(Q); the second restores it to rounding
/// ("twice is enough", Giraud et al. 2005).
pub fn project_out(q: &[Vec<f64>], v: &mut [f64]) -> Vec<f64> {
    let mut coef = vec![0.0; q.len()];
    let mut vv = nalgebra::DVectorViewMut::from_slice(v, v.len());
    for _ in 0..2 {
        for (c, qj) in coef.iter_mut().zip(q) {
            let qv = nalgebra::DVectorView::from_slice(qj, qj.len());
            let d = qv.dot(&vv);
            *c += d;
            vv.axpy(-d, &qv, 1.0);
        }
    }
    coef
}

/// An orthonormal basis Q of the independent columns among those given, with the triangular
/// factor R (columns scaled to unit norm first, so that R is well scaled whatever the units):
/// X·diag(1/scale) restricted to the kept columns = Q·R.
///
/// Built by nalgebra's Householder QR; a column whose |R_kk| is below
/// [`DEPENDENT_COLUMN_REL`] is dropped and the rest refactored. [`push`](Self::push) appends
/// one column by the thin-Q column update (project out Q twice, normalise), which is what
/// scoring one candidate against the current model needs.
#[derive(Debug, Clone)]
pub struct OrthonormalBasis {
    /// Orthonormal columns, one per kept input column.
    pub q: Vec<Vec<f64>>,
    /// For each input column: its index into `q`, or `None` if it was dependent.
    pub kept: Vec<Option<usize>>,
    /// Norm of each input column (1 for a zero or non-finite one).
    pub scale: Vec<f64>,
    /// R (kept × kept, upper triangular), in scaled-column coordinates.
    r: DMatrix<f64>,
}

impl OrthonormalBasis {
    /// The basis of `cols` (each of the same length; rows = observations).
    pub fn new(cols: &[Vec<f64>]) -> Self {
        let mut b = OrthonormalBasis {
            q: Vec::new(),
            kept: vec![None; cols.len()],
            scale: Vec::with_capacity(cols.len()),
            r: DMatrix::zeros(0, 0),
        };
        // Candidates: non-zero, finite columns, in order.
        let mut candidates = Vec::new();
        for (j, c) in cols.iter().enumerate() {
            let norm = c.iter().map(|v| v * v).sum::<f64>().sqrt();
            b.scale.push(if norm > 0.0 { norm } else { 1.0 });
            if norm > 0.0 && norm.is_finite() {
                candidates.push(j);
            }
        }
        let m = cols.first().map_or(0, Vec::len);
        loop {
            if candidates.is_empty() || m == 0 {
                return b;
            }
            let k = candidates.len().min(m);
            let a = DMatrix::from_fn(m, candidates.len(), |i, j| {
                cols[candidates[j]][i] / b.scale[candidates[j]]
            });
            let qr = a.qr();
            let r = qr.r();
            // With more columns than rows, column m onwards is dependent by construction.
            let dependent = (0..k)
                .find(|&i| r[(i, i)].abs() < DEPENDENT_COLUMN_REL)
                .or((candidates.len() > m).then_some(m));
            if let Some(i) = dependent {
                candidates.remove(i);
                continue;
            }
            let q = qr.q();
            b.q = q
                .column_iter()
                .map(|c| c.iter().copied().collect())
                .collect();
            for (i, &j) in candidates.iter().enumerate() {
                b.kept[j] = Some(i);
            }
            b.r = r;
            return b;
        }
    }

    /// Appends one column; returns whether it was independent of the basis.
    pub fn push(&mut self, mut c: Vec<f64>) -> bool {
        let norm = c.iter().map(|v| v * v).sum::<f64>().sqrt();
        self.scale.push(if norm > 0.0 { norm } else { 1.0 });
        if norm == 0.0 || !norm.is_finite() {
            self.kept.push(None);
            return false;
        }
        c.iter_mut().for_each(|v| *v /= norm);
        let coef = project_out(&self.q, &mut c);
        let rest = c.iter().map(|v| v * v).sum::<f64>().sqrt();
        if rest < DEPENDENT_COLUMN_REL {
            self.kept.push(None);
            return false;
        }
        c.iter_mut().for_each(|v| *v /= rest);
        let k = self.q.len();
        let mut r = std::mem::replace(&mut self.r, DMatrix::zeros(0, 0)).resize(k + 1, k + 1, 0.0);
        for (i, v) in coef.iter().enumerate() {
            r[(i, k)] = *v;
        }
        r[(k, k)] = rest;
        self.r = r;
        self.kept.push(Some(k));
        self.q.push(c);
        true
    }

    /// `y` minus its projection on the basis.
    pub fn residual(&self, y: &[f64]) -> Vec<f64> {
        let mut r = y.to_vec();
        project_out(&self.q, &mut r);
        r
    }

    /// R⁻¹ (kept × kept).
    fn r_inverse(&self) -> DMatrix<f64> {
        let k = self.q.len();
        // R's diagonal is ≥ DEPENDENT_COLUMN_REL in magnitude by construction.
        self.r
            .solve_upper_triangular(&DMatrix::identity(k, k))
            .unwrap_or_else(|| DMatrix::from_element(k, k, f64::NAN))
    }

    /// Unscaled covariance (XᵀX)⁻¹ of the input columns' coefficients (dependent columns: row
    /// and column 0); times the residual variance it is the covariance of the fit.
    pub fn covariance(&self) -> Vec<Vec<f64>> {
        let rinv = self.r_inverse();
        let cov_q = &rinv * rinv.transpose();
        let m = self.kept.len();
        let mut cov = vec![vec![0.0; m]; m];
        for (a, ka) in self.kept.iter().enumerate() {
            for (b, kb) in self.kept.iter().enumerate() {
                if let (Some(i), Some(j)) = (ka, kb) {
                    cov[a][b] = cov_q[(*i, *j)] / (self.scale[a] * self.scale[b]);
                }
            }
        }
        cov
    }

    /// Least-squares coefficients of the input columns for `y` and their unscaled standard
    /// errors (√diag (XᵀX)⁻¹); dependent columns get 0 ± ∞.
    pub fn solve(&self, y: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let k = self.q.len();
        let yv = nalgebra::DVectorView::from_slice(y, y.len());
        let qty = DVector::from_fn(k, |i, _| {
            nalgebra::DVectorView::from_slice(&self.q[i], self.q[i].len()).dot(&yv)
        });
        let beta_q = self
            .r
            .solve_upper_triangular(&qty)
            .unwrap_or_else(|| DVector::from_element(k, f64::NAN));
        let rinv = self.r_inverse();
        let mut beta = Vec::with_capacity(self.kept.len());
        let mut se = Vec::with_capacity(self.kept.len());
        for (j, kept) in self.kept.iter().enumerate() {
            match kept {
                Some(i) => {
                    beta.push(beta_q[*i] / self.scale[j]);
                    se.push(rinv.row(*i).norm() / self.scale[j]);
                }
                None => {
                    beta.push(0.0);
                    se.push(f64::INFINITY);
                }
            }
        }
        (beta, se)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solve_square_solves_a_pivoting_3x3_and_refuses_a_singular_one() {
        // a[0][0] = 0 needs a row exchange; x = (1, −2, 3) by construction.
        let a = vec![
            vec![0.0, 2.0, 1.0],
            vec![4.0, 1.0, -1.0],
            vec![2.0, -3.0, 5.0],
        ];
        let x_true = [1.0, -2.0, 3.0];
        let b: Vec<f64> = a
            .iter()
            .map(|row| row.iter().zip(&x_true).map(|(r, x)| r * x).sum())
            .collect();
        let x = solve_square(&a, &b).unwrap();
        for (xi, ti) in x.iter().zip(&x_true) {
            assert!((xi - ti).abs() < 1e-14, "{x:?}");
        }
        let singular = vec![vec![1.0, 2.0], vec![2.0, 4.0]];
        assert_eq!(solve_square(&singular, &[1.0, 2.0]), None);
        assert_eq!(solve_square(&singular, &[1.0]), None);
    }

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
    fn covariance_and_solution_operator_agree_with_the_solution() {
        let t = [1.0, 2.0, 4.0, 7.0, 11.0];
        let y = [0.1, 0.3, 0.2, 0.6, 0.9];
        let ls = least_squares(&vandermonde(&t, 1), &y).unwrap();
        // c = A⁺·y.
        let op = ls.solution_operator();
        for (row, c) in op.iter().zip(&ls.coeffs) {
            let cy: f64 = row.iter().zip(&y).map(|(a, b)| a * b).sum();
            assert!((cy - c).abs() < 1e-14, "{cy} vs {c}");
        }
        // A⁺A⁺ᵀ = (AᵀA)⁻¹, whose diagonal is the variances.
        let cov = ls.unscaled_covariance();
        for i in 0..2 {
            for j in 0..2 {
                let s: f64 = op[i].iter().zip(&op[j]).map(|(a, b)| a * b).sum();
                assert!((s - cov[i][j]).abs() < 1e-13, "{s} vs {}", cov[i][j]);
            }
            assert!((cov[i][i] - ls.unscaled_variances()[i]).abs() < 1e-15);
        }
    }

    #[test]
    fn a_relative_tolerance_refuses_a_nearly_dependent_column() {
        let a = vec![vec![1.0, 1.0], vec![1.0, 1.0 + 1e-9], vec![1.0, 1.0]];
        assert!(least_squares(&a, &[1.0, 2.0, 3.0]).is_ok());
        assert_eq!(
            least_squares_with(
                &a,
                &[1.0, 2.0, 3.0],
                RankTolerance::RelativeToColumnNorm(1e-5)
            ),
            Err(LinalgError::RankDeficient { column: 1 })
        );
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

    fn columns_of(a: &[Vec<f64>]) -> Vec<Vec<f64>> {
        (0..a[0].len())
            .map(|j| a.iter().map(|row| row[j]).collect())
            .collect()
    }

    #[test]
    fn basis_recovers_known_coefficients_and_drops_a_dependent_column() {
        let n = 200;
        let x1: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin()).collect();
        let x2: Vec<f64> = (0..n).map(|i| i as f64 / n as f64).collect();
        let dup: Vec<f64> = x2.iter().map(|v| 2.0 * v).collect();
        let y: Vec<f64> = (0..n).map(|i| 3.0 + 2.0 * x1[i] - 5.0 * x2[i]).collect();
        let cols = vec![vec![1.0; n], x1, dup.clone(), x2, vec![0.0; n]];
        for b in [OrthonormalBasis::new(&cols), {
            let mut b = OrthonormalBasis::new(&[]);
            cols.iter().for_each(|c| {
                b.push(c.clone());
            });
            b
        }] {
            assert_eq!(b.kept, vec![Some(0), Some(1), Some(2), None, None]);
            let (beta, se) = b.solve(&y);
            // x2 enters through its first copy, 2·x2.
            for (got, want) in beta.iter().zip([3.0, 2.0, -2.5, 0.0, 0.0]) {
                assert!((got - want).abs() < 1e-12, "{beta:?}");
            }
            assert!(se[3].is_infinite() && se[4].is_infinite() && se[0].is_finite());
            assert!(b.residual(&y).iter().all(|r| r.abs() < 1e-12));
        }
    }

    #[test]
    fn basis_agrees_with_least_squares_on_a_full_rank_design() {
        let t: Vec<f64> = (0..30).map(|i| 20.0 + 1.5 * f64::from(i)).collect();
        let y: Vec<f64> = t.iter().map(|x| (x * 0.3).sin() + 0.01 * x).collect();
        let a = vandermonde(&t, 3);
        let ls = least_squares(&a, &y).unwrap();
        let b = OrthonormalBasis::new(&columns_of(&a));
        let (beta, se) = b.solve(&y);
        let cov = b.covariance();
        let want_cov = ls.unscaled_covariance();
        for j in 0..4 {
            let rel = |x: f64, w: f64| ((x - w) / w).abs();
            assert!(
                rel(beta[j], ls.coeffs[j]) < 1e-9,
                "{j}: {} {}",
                beta[j],
                ls.coeffs[j]
            );
            assert!(rel(se[j] * se[j], ls.unscaled_variances()[j]) < 1e-9);
            for k in 0..4 {
                assert!(rel(cov[j][k], want_cov[j][k]) < 1e-9);
            }
        }
        let res = b.residual(&y);
        for (r, e) in res.iter().zip(&ls.residuals) {
            assert!((r - e).abs() < 1e-12);
        }
    }

    #[test]
    fn projecting_out_leaves_a_vector_orthogonal_to_the_basis() {
        let t: Vec<f64> = (0..50).map(f64::from).collect();
        let b = OrthonormalBasis::new(&columns_of(&vandermonde(&t, 2)));
        // Nearly in the span: one projection would leave ~1e-8 relative in it.
        let mut v: Vec<f64> = t.iter().map(|x| x * x + 1e-8 * (x * 1.7).cos()).collect();
        let coef = project_out(&b.q, &mut v);
        assert_eq!(coef.len(), 3);
        for q in &b.q {
            let d: f64 = q.iter().zip(&v).map(|(a, b)| a * b).sum();
            assert!(d.abs() < 1e-20, "{d:e}");
        }
    }
}
