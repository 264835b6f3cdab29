//! The baseline model and the least-squares machinery every extension reuses.
//!
//! # Fitting in the presence of correlated noise
//!
//! Accelerometer residuals are not white: flicker and random-walk noise make neighbouring points
//! nearly equal, so an ordinary least-squares fit counts the same information many times and
//! any smooth column "explains" the noise. The selection (`select`) whitens with a fitted
//! white + flicker + random-walk model (`noise`, [`Rows::with_noise`]); the baseline's
//! temperature-order choice here still uses the simpler AR(1) whitening: rows and columns are *whitened*, `z_t = x_t − φ·x_{t−1}` inside each
//! contiguous segment (the first row of a segment is dropped), with φ the lag-1 autocorrelation of
//! the current residual. Linear parameters are solved by a modified Gram–Schmidt QR with
//! re-orthogonalisation (a QR factorisation: no normal equations are formed), columns scaled to
//! unit norm first.
//!
//! # Baseline
//!
//! - With a calibration: the calibration's prediction of the output (equation (1) with the
//!   temperature models at the measured temperature, eq. (5) tilt) is subtracted with a fixed
//!   coefficient; offset and linear drift are free.
//! - Without: offset, linear drift, temperature polynomial (order 0–3, chosen by BIC on the
//!   whitened fit) and, when the output unit per g is known, the eq. (5) tilt term subtracted
//!   with its nominal coefficient (so that a tiltmeter gain error is left for `tilt_coupling`);
//!   when it is not known, the tilt term is a fitted column.

use super::import::{ChannelKind, Dataset};

/// Lag-1 autocorrelation of a series inside segments (0 if undefined), clipped to [0, 0.999].
pub fn ar1(r: &[f64], seg_start: &[bool]) -> f64 {
    let mean = r.iter().sum::<f64>() / r.len().max(1) as f64;
    let (mut num, mut den) = (0.0, 0.0);
    for t in 0..r.len() {
        let a = r[t] - mean;
        den += a * a;
        if t > 0 && !seg_start[t] {
            num += a * (r[t - 1] - mean);
        }
    }
    if den <= 0.0 {
        return 0.0;
    }
    (num / den).clamp(0.0, 0.999)
}

/// Which rows take part (true) and where whitening restarts.
#[derive(Debug, Clone)]
pub struct Rows {
    /// Indices t of whitened rows (t has a predecessor t−1 in the same segment and in the set).
    pub idx: Vec<usize>,
    /// The exact whitening of a fitted noise model; when set, `whiten` ignores φ.
    pub kalman: Option<super::noise::Whitener>,
}

impl Rows {
    /// Whitened rows of the points selected by `mask` (all when `None`).
    pub fn new(seg_start: &[bool], mask: Option<&[bool]>) -> Self {
        let inside = |t: usize| mask.is_none_or(|m| m[t]);
        let idx = (1..seg_start.len())
            .filter(|&t| !seg_start[t] && inside(t) && inside(t - 1))
            .collect();
        Rows { idx, kalman: None }
    }
    /// Rows whitened by the Kalman innovations of `model` (all points of `mask`; gaps are
    /// propagated over, no row is dropped).
    pub fn with_noise(
        model: &super::noise::NoiseModel,
        t_s: &[f64],
        mask: Option<&[bool]>,
    ) -> Self {
        let idx: Vec<usize> = (0..t_s.len())
            .filter(|&t| mask.is_none_or(|m| m[t]))
            .collect();
        let w = super::noise::Whitener::new(model, t_s, idx.clone());
        Rows {
            idx,
            kalman: Some(w),
        }
    }
    /// `x_t − φ x_{t−1}` on these rows, or the normalised innovations of the noise model.
    pub fn whiten(&self, x: &[f64], phi: f64) -> Vec<f64> {
        match &self.kalman {
            Some(w) => w.whiten(x),
            None => self.idx.iter().map(|&t| x[t] - phi * x[t - 1]).collect(),
        }
    }
}

/// An orthonormal basis of the whitened design columns with its triangular factor.
#[derive(Debug, Clone)]
pub struct Basis {
    /// Orthonormal columns (only the independent ones).
    pub q: Vec<Vec<f64>>,
    /// R (upper triangular over the kept columns), scaled-column coordinates.
    pub r: Vec<Vec<f64>>,
    /// For each input column: index into `q`, or `None` if it was dependent (coefficient 0).
    pub kept: Vec<Option<usize>>,
    /// Column scales (norm of each whitened input column).
    pub scale: Vec<f64>,
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Orthogonalises `v` against `q` twice (classical Gram–Schmidt twice is as stable as needed).
pub fn orthogonalize(q: &[Vec<f64>], v: &mut [f64]) -> Vec<f64> {
    let mut coef = vec![0.0; q.len()];
    for _ in 0..2 {
        for (j, qj) in q.iter().enumerate() {
            let c = dot(qj, v);
            coef[j] += c;
            for (vi, qi) in v.iter_mut().zip(qj) {
                *vi -= c * qi;
            }
        }
    }
    coef
}

impl Basis {
    /// QR of whitened columns; a column whose remaining norm is below 1e-9 of its own is
    /// dependent and gets no coefficient.
    pub fn new(cols: &[Vec<f64>]) -> Self {
        let mut b = Basis {
            q: Vec::new(),
            r: Vec::new(),
            kept: Vec::new(),
            scale: Vec::new(),
        };
        for c in cols {
            b.push(c.clone());
        }
        b
    }

    /// Adds one whitened column; returns whether it was independent.
    pub fn push(&mut self, mut c: Vec<f64>) -> bool {
        let norm = dot(&c, &c).sqrt();
        self.scale.push(if norm > 0.0 { norm } else { 1.0 });
        if norm == 0.0 || !norm.is_finite() {
            self.kept.push(None);
            return false;
        }
        for v in c.iter_mut() {
            *v /= norm;
        }
        let coef = orthogonalize(&self.q, &mut c);
        let rest = dot(&c, &c).sqrt();
        if rest < 1.0e-9 {
            self.kept.push(None);
            return false;
        }
        for v in c.iter_mut() {
            *v /= rest;
        }
        let mut col = coef;
        col.push(rest);
        self.r.push(col);
        self.kept.push(Some(self.q.len()));
        self.q.push(c);
        true
    }

    /// Residual of `y` after projection on the basis.
    pub fn residual(&self, y: &[f64]) -> Vec<f64> {
        let mut r = y.to_vec();
        orthogonalize(&self.q, &mut r);
        r
    }

    /// Coefficients of the input columns and their unscaled standard errors (sqrt of the
    /// diagonal of (XᵀX)⁻¹), dependent columns 0 ± ∞.
    pub fn solve(&self, y: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let k = self.q.len();
        let qty: Vec<f64> = self.q.iter().map(|q| dot(q, y)).collect();
        // R is stored by columns: r[j][i] = R[i][j] for i ≤ j.
        let rr = |i: usize, j: usize| if i <= j { self.r[j][i] } else { 0.0 };
        let mut beta_q = vec![0.0; k];
        for i in (0..k).rev() {
            let s: f64 = (i + 1..k).map(|j| rr(i, j) * beta_q[j]).sum();
            beta_q[i] = (qty[i] - s) / rr(i, i);
        }
        // R⁻¹ column by column for the variances: diag(R⁻¹R⁻ᵀ) = row sums of squares of R⁻¹.
        let mut rinv = vec![vec![0.0; k]; k];
        #[allow(clippy::needless_range_loop)] // triangular solve: indices are the algorithm
        for c in 0..k {
            for i in (0..=c).rev() {
                let s: f64 = (i + 1..=c).map(|j| rr(i, j) * rinv[j][c]).sum();
                rinv[i][c] = (if i == c { 1.0 } else { 0.0 } - s) / rr(i, i);
            }
        }
        let var_q: Vec<f64> = rinv
            .iter()
            .map(|row| row.iter().map(|v| v * v).sum())
            .collect();
        let mut beta = Vec::with_capacity(self.kept.len());
        let mut se = Vec::with_capacity(self.kept.len());
        for (j, kept) in self.kept.iter().enumerate() {
            match kept {
                Some(i) => {
                    beta.push(beta_q[*i] / self.scale[j]);
                    se.push(var_q[*i].sqrt() / self.scale[j]);
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

/// A generalised least-squares fit of raw columns to raw data with AR(1) whitening.
#[derive(Debug, Clone)]
pub struct Fit {
    /// Coefficients of the raw columns.
    pub beta: Vec<f64>,
    /// Their standard errors (scaled by the whitened residual std).
    pub se: Vec<f64>,
    /// Residual sum of squares in the whitened domain.
    pub rss_w: f64,
    /// Whitened rows.
    pub n_w: usize,
    /// Independent columns.
    pub k: usize,
}

/// Fits raw `cols` to `y` with whitening coefficient `phi` on `rows`.
pub fn gls(cols: &[Vec<f64>], y: &[f64], phi: f64, rows: &Rows) -> Fit {
    let wc: Vec<Vec<f64>> = cols.iter().map(|c| rows.whiten(c, phi)).collect();
    let wy = rows.whiten(y, phi);
    let basis = Basis::new(&wc);
    let res = basis.residual(&wy);
    let rss_w: f64 = res.iter().map(|v| v * v).sum();
    let k = basis.q.len();
    let n_w = wy.len();
    let s = (rss_w / (n_w.saturating_sub(k).max(1)) as f64).sqrt();
    let (beta, se) = basis.solve(&wy);
    Fit {
        beta,
        se: se.iter().map(|v| v * s).collect(),
        rss_w,
        n_w,
        k,
    }
}

/// Raw residual y − Σ βⱼ colⱼ.
pub fn raw_residual(cols: &[Vec<f64>], beta: &[f64], y: &[f64]) -> Vec<f64> {
    let mut r = y.to_vec();
    for (c, b) in cols.iter().zip(beta) {
        if *b != 0.0 {
            for (ri, ci) in r.iter_mut().zip(c) {
                *ri -= b * ci;
            }
        }
    }
    r
}

/// Sample standard deviation.
pub fn std(v: &[f64]) -> f64 {
    let n = v.len() as f64;
    if n < 2.0 {
        return 0.0;
    }
    let m = v.iter().sum::<f64>() / n;
    (v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1.0)).sqrt()
}

/// The baseline: a fixed prediction subtracted from the output plus free columns.
#[derive(Debug, Clone)]
pub struct Baseline {
    /// Human description.
    pub description: String,
    /// Output minus the fixed prediction (calibration or nominal tilt), output unit.
    pub target: Vec<f64>,
    /// Free columns.
    pub columns: Vec<Vec<f64>>,
    /// Names of the free columns.
    pub names: Vec<String>,
    /// Whether the nominal tilt term was subtracted (then `tilt_coupling` is a candidate).
    pub tilt_subtracted: bool,
}

/// The eq. (5) tilt term in g per unit input: sin θ at 0 g, input·(cos θ − 1) at 1 g.
pub fn tilt_term_g(ds: &Dataset) -> Option<Vec<f64>> {
    let tilts: Vec<&Vec<f64>> = ds
        .channels
        .iter()
        .filter(|c| c.kind == ChannelKind::Tilt)
        .map(|c| &c.values)
        .collect();
    if tilts.is_empty() {
        return None;
    }
    let input = ds.input_g.unwrap_or(0.0);
    Some(
        (0..ds.len())
            .map(|i| {
                if ds.is_one_g() {
                    let th2: f64 = tilts.iter().map(|t| t[i] * t[i]).sum();
                    input * (th2.sqrt().cos() - 1.0)
                } else {
                    tilts[0][i].sin()
                }
            })
            .collect(),
    )
}

/// Offset and linear drift columns (time centred and scaled for conditioning).
pub fn trend_columns(ds: &Dataset) -> Vec<Vec<f64>> {
    let span = ds.span_s().max(1.0);
    let t0 = ds.t_s.first().copied().unwrap_or(0.0);
    vec![
        vec![1.0; ds.len()],
        ds.t_s.iter().map(|t| (t - t0) / span - 0.5).collect(),
    ]
}

/// Builds the static baseline (no calibration). The temperature order 0–3 is chosen by BIC on
/// the whitened fit.
pub fn static_baseline(ds: &Dataset) -> Baseline {
    let mut target = ds.y.clone();
    let mut columns = trend_columns(ds);
    let mut names = vec!["offset".to_owned(), "linear_drift".to_owned()];
    let mut tilt_subtracted = false;
    let mut desc = vec!["offset".to_owned(), "linear drift".to_owned()];
    if let Some(tilt) = tilt_term_g(ds) {
        if let Some(u) = ds.unit_per_g {
            for (t, v) in target.iter_mut().zip(&tilt) {
                *t -= u * v;
            }
            tilt_subtracted = true;
            desc.push("eq. (5) tilt with nominal gain".into());
        } else {
            columns.push(tilt);
            names.push("tilt".into());
            desc.push("eq. (5) tilt (fitted gain)".into());
        }
    }
    if let Some(temp) = ds.channel(ChannelKind::Temperature) {
        let m = temp.values.iter().sum::<f64>() / ds.len() as f64;
        let s = std(&temp.values).max(1e-12);
        let x: Vec<f64> = temp.values.iter().map(|v| (v - m) / s).collect();
        // φ from the ordinary least-squares residual of the richest model.
        let rows = Rows::new(&ds.segment_start, None);
        let mut rich = columns.clone();
        for p in 1..=3 {
            rich.push(x.iter().map(|v| v.powi(p)).collect());
        }
        let ols = gls(&rich, &target, 0.0, &rows);
        let phi0 = ar1(&raw_residual(&rich, &ols.beta, &target), &ds.segment_start);
        let mut best: (f64, usize) = (f64::INFINITY, 0);
        for order in 0..=3usize {
            let mut cols = columns.clone();
            for p in 1..=order {
                cols.push(x.iter().map(|v| v.powi(p as i32)).collect());
            }
            let f = gls(&cols, &target, phi0, &rows);
            let n = f.n_w as f64;
            let bic = n * (f.rss_w / n).max(f64::MIN_POSITIVE).ln() + f.k as f64 * n.ln();
            if bic < best.0 - 1e-9 {
                best = (bic, order);
            }
        }
        for p in 1..=best.1 {
            columns.push(x.iter().map(|v| v.powi(p as i32)).collect());
            names.push(format!("temperature^{p}"));
        }
        desc.push(format!("temperature polynomial of order {}", best.1));
    }
    Baseline {
        description: format!("static model fitted to the log: {}", desc.join(", ")),
        target,
        columns,
        names,
        tilt_subtracted,
    }
}

/// Baseline from a calibration table: eq. (1) with the temperature models at the measured
/// temperature, eq. (5) tilt, subtracted with a fixed coefficient; offset and drift free.
pub fn calibrated_baseline(
    ds: &Dataset,
    table: &accomp::table::CalibrationTable,
) -> Result<Baseline, String> {
    let temp = ds
        .channel(ChannelKind::Temperature)
        .ok_or("a calibration baseline needs a temperature channel")?;
    let input = ds.input_g.unwrap_or(table.orientation.nominal_input.0);
    let tilt = tilt_term_g(ds);
    let cross = table.orientation.cross;
    let mut target = Vec::with_capacity(ds.len());
    for i in 0..ds.len() {
        let (k, _) = table
            .thermal
            .coefficients_at(accomp::units::Celsius(temp.values[i]))
            .map_err(|e| format!("calibration model at {} °C: {e:?}", temp.values[i]))?;
        let a = input + tilt.as_ref().map_or(0.0, |t| t[i]);
        let pred_v = k.output(accomp::units::Gs(a), cross).0;
        // The output unit: volts directly; a g-unit log compares with the model in g.
        let pred = if ds.output_unit == "v" {
            pred_v
        } else {
            ds.unit_per_g.unwrap_or(1.0) * pred_v / k.scale_factor_v_per_g
        };
        target.push(ds.y[i] - pred);
    }
    Ok(Baseline {
        description: "calibration prediction (eq. (1) at the measured temperature, eq. (5) tilt) + offset + linear drift".into(),
        target,
        columns: trend_columns(ds),
        names: vec!["offset".into(), "linear_drift".into()],
        tilt_subtracted: tilt.is_some(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn qr_solve_recovers_known_coefficients_and_flags_dependent_columns() {
        let n = 200;
        let x1: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin()).collect();
        let x2: Vec<f64> = (0..n).map(|i| i as f64 / n as f64).collect();
        let dup: Vec<f64> = x2.iter().map(|v| 2.0 * v).collect();
        let y: Vec<f64> = (0..n).map(|i| 3.0 + 2.0 * x1[i] - 5.0 * x2[i]).collect();
        let cols = vec![vec![1.0; n], x1, x2, dup];
        let b = Basis::new(&cols);
        let (beta, se) = b.solve(&y);
        assert!((beta[0] - 3.0).abs() < 1e-9 && (beta[1] - 2.0).abs() < 1e-9);
        assert!((beta[2] - -5.0).abs() < 1e-9);
        assert_eq!(b.kept[3], None);
        assert!(se[3].is_infinite());
    }

    #[test]
    fn whitening_drops_the_first_row_of_every_segment() {
        let seg = [true, false, false, true, false];
        let rows = Rows::new(&seg, None);
        assert_eq!(rows.idx, vec![1, 2, 4]);
        assert_eq!(
            rows.whiten(&[1.0, 2.0, 4.0, 8.0, 16.0], 0.5),
            vec![1.5, 3.0, 12.0]
        );
    }

    #[test]
    fn ar1_of_a_random_walk_is_near_one_and_of_alternation_is_clipped_to_zero() {
        let walk: Vec<f64> = (0..500)
            .map(|i| ((i * 7919) % 13) as f64 + i as f64)
            .collect();
        assert!(
            ar1(
                &walk,
                &[true; 1]
                    .iter()
                    .chain([false; 499].iter())
                    .copied()
                    .collect::<Vec<_>>()
            ) > 0.9
        );
        let alt: Vec<f64> = (0..100)
            .map(|i| if i % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let mut seg = vec![false; 100];
        seg[0] = true;
        assert_eq!(ar1(&alt, &seg), 0.0);
    }
}
