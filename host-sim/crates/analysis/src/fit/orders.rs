//! Every polynomial order fitted to every column (QR least squares in the conditioned
//! variable), the statistics that compare them, and the order chosen.

use super::*;

/// One polynomial order fitted to one coefficient column.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OrderFit {
    /// Polynomial order.
    pub order: usize,
    /// How well the order fits and predicts the column: what the orders are compared by.
    #[serde(flatten)]
    pub scores: OrderScores,
    /// Coefficients in x = (T − Tc)/Ts, ascending.
    pub coeffs_x: Vec<f64>,
    /// Their standard errors, √(diag((RᵀR)⁻¹))·s.
    pub std_errors_x: Vec<f64>,
    /// The same polynomial as monomials in raw °C (for comparison with the paper only).
    pub monomial_celsius: Vec<f64>,
    /// dK/dT at `--at`, column unit per °C.
    pub sensitivity_per_c: f64,
    /// K at `--at`, column unit (to form relative sensitivities such as (dK1/dT)/K1).
    pub value_at: f64,
}

/// The statistics one polynomial order is judged by against the others (written into the fit
/// JSON beside `order`, field by field).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OrderScores {
    /// s = √(RSS/(n − order − 1)), in the column's unit.
    pub residual_std: f64,
    /// √(RSS/n), comparable with the printed models' residual RMS.
    pub residual_rms: f64,
    /// AICc with k = order + 1 (null when n − k − 1 ≤ 0: never selected then).
    pub aicc: Option<f64>,
    /// Leave-one-out RMS prediction error, exact from the hat diagonal: e_i/(1 − h_ii).
    pub loo_rms: f64,
    /// F test of this order against the next lower one; null for order 0.
    pub f_test_p: Option<f64>,
}

/// A printed model evaluated at the table temperatures.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PrintedFit {
    /// Polynomial order.
    pub order: usize,
    /// √(mean residual²) against the table.
    pub residual_rms: f64,
    /// max |residual|.
    pub residual_max: f64,
    /// The paper's reported standard deviation.
    pub reported_std: Option<f64>,
    /// dK/dT of the printed model at `--at`, per °C.
    pub sensitivity_per_c: f64,
}

/// All orders of one column, the selected order and the printed models.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ColumnFit {
    /// CSV column name.
    pub name: String,
    /// Lowest-AICc order (ties → lower order).
    pub selected_order: usize,
    /// Orders 0.. with n − order − 1 ≥ 1.
    pub models: Vec<OrderFit>,
    /// The paper's printed models of this column (empty when none are available).
    pub paper_printed: Vec<PrintedFit>,
}

impl ColumnFit {
    /// The selected model.
    pub fn selected(&self) -> Option<&OrderFit> {
        self.models.iter().find(|m| m.order == self.selected_order)
    }
}

/// The `--json` document.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FitReport {
    /// One entry per coefficient column, in input order.
    pub coefficients: Vec<ColumnFit>,
}

/// AICc = n·ln(RSS/n) + 2k + 2k(k+1)/(n − k − 1) with k = order + 1: the polynomial
/// coefficients only, not the noise variance (counting it, k = order + 2, would change the
/// small-sample correction and, with n = 8, rule out order 4). None when n − k − 1 ≤ 0: the
/// correction is undefined there and such an order is never selected.
pub fn aicc(n: usize, rss: f64, k: usize) -> Option<f64> {
    if n <= k + 1 {
        return None;
    }
    let (nf, kf) = (n as f64, k as f64);
    Some(nf * (rss / nf).ln() + 2.0 * kf + 2.0 * kf * (kf + 1.0) / (nf - kf - 1.0))
}

/// The order with the lowest defined AICc; ties go to the lower order (orders arrive ascending).
pub fn select_order(candidates: impl IntoIterator<Item = (usize, Option<f64>)>) -> Option<usize> {
    let mut best: Option<(usize, f64)> = None;
    for (order, a) in candidates {
        if let Some(a) = a {
            // Strictly lower wins, so ties keep the lower order.
            if best.is_none_or(|(_, b)| a < b) {
                best = Some((order, a));
            }
        }
    }
    best.map(|(o, _)| o)
}

/// Fits one polynomial order to (T, y) in the normalized variable of `scale`.
pub fn fit_order(
    name: &str,
    scale: &TemperatureScale,
    temperatures_c: &[f64],
    y: &[f64],
    order: usize,
    at: Celsius,
) -> Result<(OrderFit, f64), FitError> {
    let n = y.len();
    let design: Vec<Vec<f64>> = temperatures_c
        .iter()
        .map(|t| {
            let x = scale.x_unclamped(Celsius(*t));
            (0..=order).map(|j| x.powi(j as i32)).collect()
        })
        .collect();
    let ls = least_squares(&design, y).map_err(|error| FitError::Linalg {
        column: name.to_owned(),
        order,
        error,
    })?;
    let dof = n - order - 1;
    let s = (ls.rss / dof as f64).sqrt();
    let loo_sq: f64 = ls
        .residuals
        .iter()
        .zip(&ls.leverage)
        .map(|(e, h)| (e / (1.0 - h)).powi(2))
        .sum();
    let std_errors_x = ls
        .unscaled_variances()
        .iter()
        .map(|v| v.sqrt() * s)
        .collect();
    let poly = TempPoly::from_coeffs(&ls.coeffs).unwrap_or_default();
    let x_at = scale.x_unclamped(at);
    let monomial_celsius = poly.to_monomial_celsius(scale)[..=order].to_vec();
    Ok((
        OrderFit {
            order,
            scores: OrderScores {
                residual_std: s,
                residual_rms: (ls.rss / n as f64).sqrt(),
                aicc: aicc(n, ls.rss, order + 1),
                loo_rms: (loo_sq / n as f64).sqrt(),
                f_test_p: None,
            },
            coeffs_x: ls.coeffs,
            std_errors_x,
            monomial_celsius,
            sensitivity_per_c: poly.derivative_x(x_at) / scale.half_span_c,
            value_at: poly.eval(x_at),
        },
        ls.rss,
    ))
}

/// Fits every order 0–4 that leaves at least one degree of freedom, runs the F tests and selects
/// the lowest-AICc order.
pub fn fit_column(
    name: &str,
    scale: &TemperatureScale,
    temperatures_c: &[f64],
    y: &[f64],
    at: Celsius,
) -> Result<ColumnFit, FitError> {
    if !at.0.is_finite() {
        return Err(FitError::BadAt);
    }
    let n = y.len();
    let mut models: Vec<OrderFit> = Vec::new();
    let mut prev_rss: Option<f64> = None;
    for order in (0..=MAX_ORDER).take_while(|o| n >= o + 2) {
        let (mut m, rss) = fit_order(name, scale, temperatures_c, y, order, at)?;
        if let Some(prev) = prev_rss {
            let dof = (n - order - 1) as f64;
            // F = (RSS_{p−1} − RSS_p)/(RSS_p/(n − p − 1)); an exact fit gives F = ∞, p = 0.
            let f = if rss > 0.0 {
                (prev - rss) / (rss / dof)
            } else {
                f64::INFINITY
            };
            m.scores.f_test_p =
                Some(
                    f_upper_tail(f, 1.0, dof).map_err(|error| FitError::Special {
                        column: name.to_owned(),
                        order,
                        error,
                    })?,
                );
        }
        prev_rss = Some(rss);
        models.push(m);
    }
    let selected_order = select_order(models.iter().map(|m| (m.order, m.scores.aicc)))
        .ok_or_else(|| FitError::NoSelectableOrder(name.to_owned()))?;
    Ok(ColumnFit {
        name: name.to_owned(),
        selected_order,
        models,
        paper_printed: Vec::new(),
    })
}

/// Evaluates a printed raw-°C model against the table (straight powers of T, as printed).
pub fn evaluate_printed(
    model: &PrintedModel,
    temperatures_c: &[f64],
    y: &[f64],
    at: Celsius,
) -> PrintedFit {
    let eval = |t: f64| {
        model
            .coeffs_celsius
            .iter()
            .rev()
            .fold(0.0, |acc, c| acc * t + c)
    };
    let residuals: Vec<f64> = temperatures_c
        .iter()
        .zip(y)
        .map(|(t, v)| v - eval(*t))
        .collect();
    let n = residuals.len().max(1) as f64;
    let slope = model
        .coeffs_celsius
        .iter()
        .enumerate()
        .skip(1)
        .rev()
        .fold(0.0, |acc, (j, c)| acc * at.0 + j as f64 * c);
    PrintedFit {
        order: model.order,
        residual_rms: (residuals.iter().map(|r| r * r).sum::<f64>() / n).sqrt(),
        residual_max: residuals.iter().fold(0.0, |m, r| f64::max(m, r.abs())),
        reported_std: model.reported_std,
        sensitivity_per_c: slope,
    }
}

/// Fits every column of the table and attaches the printed models of the same name.
pub fn fit_table(
    table: &CoefficientTable,
    printed: &[PrintedModel],
    at: Celsius,
) -> Result<FitReport, FitError> {
    let scale = table.scale().map_err(|error| FitError::Csv {
        path: PathBuf::new(),
        error,
    })?;
    let mut coefficients = Vec::new();
    for col in &table.columns {
        let mut fit = fit_column(&col.name, &scale, &table.temperatures_c, &col.values, at)?;
        fit.paper_printed = printed
            .iter()
            .filter(|p| p.coefficient == col.name)
            .map(|p| evaluate_printed(p, &table.temperatures_c, &col.values, at))
            .collect();
        coefficients.push(fit);
    }
    Ok(FitReport { coefficients })
}
