//! Errors of the calibration table's temperature models.
//!
//! With `--calibration`, the baseline is the table's eq. (1) at the measured temperature plus a
//! free offset and drift: a coefficient model that has changed since calibration leaves
//! ΔC·(T − T0)^p in the residual, which on a cycling temperature the catalogue would otherwise
//! take for a lag or a loop. Before the selection, each coefficient C of the table (K0, K1, K2,
//! δp, δo) and each power p = 1…3 of (T − T0) is tried as a column: the output the table would
//! predict with C + ε·(T − T0)^p, minus its prediction, over ε (so the column is exactly what
//! loading the changed table does to the prediction, through the core's eq. (1), whatever the
//! record's input and unit). Greedy, at most [`MAX_TERMS`] terms, each accepted when
//!
//!   ΔBIC = Δ(−2 ln L) + ln n + max(ln n, 2 ln M) < 0,
//!
//! −2 ln L under the noise model (white + flicker + random walk) fitted by likelihood to the
//! residual with and without the column, M the number of columns tried. An accepted term enters
//! the baseline, so the catalogue is searched on what the table does not explain.
//!
//! Columns that the record cannot tell apart (at a fixed input, a K0 and a K1 change have the
//! same shape; over a small temperature range far from T0 so do neighbouring powers) are listed
//! as equivalents with the size each would need; the first in the order K0, K1, K2, δp, δo and
//! the lowest power is named. The corrected table applies the named changes to the table's
//! polynomials (in its normalised variable x: (T − T0)^p = (Ts·x + Tc − T0)^p expanded) and must
//! pass the core's validator, else it is refused by the validator's name.

use super::baseline::{calibrated_baseline, gls, raw_residual, std, Baseline, Rows};
use super::import::Dataset;
use super::noise::{white_scale_from_counts, NoiseModel};
use super::residual;
use accomp::poly::TempPoly;
use accomp::table::{CalibrationTable, Coefficient};

/// At most this many table terms.
pub const MAX_TERMS: usize = 3;
/// Highest power of (T − T0) tried.
pub const MAX_POWER: u32 = 3;
/// Two columns are equivalent for this record when, off the baseline's offset and drift, the
/// cosine of their angle is above this.
pub const EQUIVALENT_COSINE: f64 = 0.999;
/// Likelihood evaluations of each noise fit (warm-started from the Allan fit).
const NOISE_EVALS: usize = 36;

/// One coefficient of the table: which, its key, its name in the report, its unit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TableCoefficient {
    /// Which polynomial.
    pub which: Coefficient,
    /// Key of the table's field (`bias_g` …).
    pub key: &'static str,
    /// The paper's symbol.
    pub symbol: &'static str,
    /// Unit of the coefficient.
    pub unit: &'static str,
}

/// The table's coefficients, in the order ties are named.
pub const COEFFICIENTS: [TableCoefficient; 5] = [
    TableCoefficient {
        which: Coefficient::Bias,
        key: "bias_g",
        symbol: "K0",
        unit: "g",
    },
    TableCoefficient {
        which: Coefficient::ScaleFactor,
        key: "scale_factor_v_per_g",
        symbol: "K1",
        unit: "V/g",
    },
    TableCoefficient {
        which: Coefficient::Nonlinearity,
        key: "nonlinearity_g_per_g2",
        symbol: "K2",
        unit: "g/g²",
    },
    TableCoefficient {
        which: Coefficient::MisalignmentP,
        key: "misalignment_p_rad",
        symbol: "δp",
        unit: "rad",
    },
    TableCoefficient {
        which: Coefficient::MisalignmentO,
        key: "misalignment_o_rad",
        symbol: "δo",
        unit: "rad",
    },
];

/// A table term found: the table's C should change by `change`·(T − T0)^`power`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct TableTerm {
    /// Coefficient symbol (K0 …).
    pub symbol: &'static str,
    /// The table field's key.
    pub key: &'static str,
    /// Power of (T − T0).
    pub power: u32,
    /// The change to apply to the table, coefficient unit per °C^power.
    pub change: f64,
    /// Its 1-σ uncertainty.
    pub sigma: f64,
    /// Unit of `change`.
    pub unit: String,
    /// ΔBIC of the term.
    pub delta_bic: f64,
    /// Changes this record cannot tell from it: (symbol, power, change that explains it equally).
    pub equivalent: Vec<(&'static str, u32, f64)>,
}

/// The test of the table and what loading its correction gains.
#[derive(Debug, Clone)]
pub struct TableCheck {
    /// T0 of the table, °C.
    pub reference_c: f64,
    /// Terms found, in the order accepted.
    pub terms: Vec<TableTerm>,
    /// ΔBIC of the best column not accepted (positive: no further term), with its name.
    pub next_best: Option<(String, f64)>,
    /// The corrected table (the validator passed it), when terms were found.
    pub corrected: Option<CalibrationTable>,
    /// Why the corrected table is refused (the core validator's verdict by name).
    pub refused: Option<String>,
    /// Residual std with the table as given (offset and drift fitted), output unit.
    pub std_given: f64,
    /// The same with the corrected table.
    pub std_corrected: Option<f64>,
    /// Out-of-sample (blocked cross-validation) residual std with the table as given.
    pub std_given_out_of_sample: f64,
    /// The same with the corrected table.
    pub std_corrected_out_of_sample: Option<f64>,
}

fn poly_mut(t: &mut CalibrationTable, which: Coefficient) -> &mut TempPoly {
    let m = &mut t.thermal.models;
    match which {
        Coefficient::Bias => &mut m.bias_g,
        Coefficient::ScaleFactor => &mut m.scale_factor_v_per_g,
        Coefficient::Nonlinearity => &mut m.nonlinearity_g_per_g2,
        Coefficient::MisalignmentP => &mut m.misalignment_p_rad,
        Coefficient::MisalignmentO => &mut m.misalignment_o_rad,
    }
}

fn binomial(n: u32, k: u32) -> f64 {
    (0..k).fold(1.0, |acc, i| acc * f64::from(n - i) / f64::from(i + 1))
}

/// The table with `change`·(T − T0)^`power` added to coefficient `which`: in the normalised
/// variable x = (T − Tc)/Ts, T − T0 = Ts·x + (Tc − T0), expanded binomially.
pub fn with_change(
    t: &CalibrationTable,
    which: Coefficient,
    power: u32,
    change: f64,
) -> CalibrationTable {
    let mut out = *t;
    let s = t.thermal.scale;
    let (h, d) = (s.half_span_c, s.center.0 - t.thermal.reference.0);
    let p = poly_mut(&mut out, which);
    for j in 0..=power {
        p.coeffs[j as usize] +=
            change * binomial(power, j) * h.powi(j as i32) * d.powi((power - j) as i32);
    }
    out
}

/// The size of a unit change of each coefficient used for the numerical column (the prediction
/// is linear in every coefficient but K1, and in K1 to rounding over ε).
fn epsilon(t: &CalibrationTable, which: Coefficient) -> f64 {
    match which {
        Coefficient::ScaleFactor => {
            1e-6 * t
                .thermal
                .coefficients_at(t.thermal.reference)
                .map_or(1.0, |(k, _)| k.scale_factor_v_per_g.abs())
        }
        _ => 1e-6,
    }
}

/// Likelihood noise model of a residual, warm-started from its Allan fit.
fn noise_of(ds: &Dataset, r: &[f64]) -> NoiseModel {
    let idx: Vec<usize> = (0..r.len()).collect();
    let start = NoiseModel::fit(&residual::adev(ds, r), ds.dt_s, ds.span_s());
    let starts: Vec<&NoiseModel> = start.iter().collect();
    NoiseModel::fit_ml(
        &ds.t_s,
        &idx,
        r,
        ds.dt_s,
        ds.span_s(),
        &starts,
        NOISE_EVALS,
        white_scale_from_counts(&ds.samples_per_point),
    )
    .model
}

/// −2 ln L of `y` on `cols` under `noise`, with the fit.
fn neg2(
    ds: &Dataset,
    cols: &[Vec<f64>],
    y: &[f64],
    noise: &NoiseModel,
) -> (f64, super::baseline::Fit) {
    let rows = Rows::with_noise(noise, &ds.t_s, None);
    let f = gls(cols, y, 0.0, &rows);
    let ld = rows.kalman.as_ref().map_or(0.0, |w| w.log_det());
    (f.rss_w + ld, f)
}

/// A column off the span of `base` (least squares), for the equivalence test.
fn off(base: &[Vec<f64>], c: &[f64]) -> Vec<f64> {
    match crate::numerics::linalg::least_squares(
        &(0..c.len())
            .map(|i| base.iter().map(|b| b[i]).collect())
            .collect::<Vec<Vec<f64>>>(),
        c,
    ) {
        Ok(ls) => ls.residuals,
        Err(_) => c.to_vec(),
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Tests the table on the record: the terms found, the corrected table and its gain, and the
/// baseline extended by the terms' columns (what the selection then runs on).
pub fn check(
    ds: &Dataset,
    table: &CalibrationTable,
    base: &Baseline,
    cfg: &super::select::Config,
) -> (TableCheck, Baseline) {
    // Every (coefficient, power) column this record can see.
    let mut cands: Vec<(TableCoefficient, u32, Vec<f64>)> = Vec::new();
    for c in COEFFICIENTS {
        let eps = epsilon(table, c.which);
        for p in 1..=MAX_POWER {
            let changed = with_change(table, c.which, p, eps);
            let Ok(b) = calibrated_baseline(ds, &changed) else {
                continue;
            };
            // Loading the changed table lowers the target by what it adds to the prediction.
            let col: Vec<f64> = base
                .target
                .iter()
                .zip(&b.target)
                .map(|(a, b)| (a - b) / eps)
                .collect();
            let scale = col.iter().map(|v| v.abs()).fold(0.0, f64::max);
            let o = off(&base.columns, &col);
            if scale > 0.0 && dot(&o, &o).sqrt() > 1e-9 * scale * (col.len() as f64).sqrt() {
                cands.push((c, p, col));
            }
        }
    }
    let n = ds.len() as f64;
    let charge = n.ln() + n.ln().max(2.0 * (cands.len().max(1) as f64).ln());
    let mut ext = base.clone();
    let mut terms: Vec<TableTerm> = Vec::new();
    let mut next_best = None;
    let mut used = vec![false; cands.len()];
    let r0 = raw_residual(
        &ext.columns,
        &gls(
            &ext.columns,
            &ext.target,
            0.0,
            &Rows::new(&ds.segment_start, None),
        )
        .beta,
        &ext.target,
    );
    let mut noise0 = noise_of(ds, &r0);
    let given_noise = noise0.clone();
    while terms.len() < MAX_TERMS {
        let (l0, _) = neg2(ds, &ext.columns, &ext.target, &noise0);
        // The best column under the current noise model.
        let mut best: Option<(usize, f64)> = None;
        for (i, (_, _, col)) in cands.iter().enumerate() {
            if used[i] {
                continue;
            }
            let mut cols = ext.columns.clone();
            cols.push(col.clone());
            let (l, _) = neg2(ds, &cols, &ext.target, &noise0);
            if best.is_none_or(|b| l < b.1) {
                best = Some((i, l));
            }
        }
        let Some((ib, _)) = best else { break };
        // Ties go to the first in the catalogue's order (K0 before K1, lower powers first).
        let ob = off(&ext.columns, &cands[ib].2);
        let nb = dot(&ob, &ob).sqrt();
        let equivalent_to_best = |i: usize| {
            let o = off(&ext.columns, &cands[i].2);
            (dot(&o, &ob) / (dot(&o, &o).sqrt() * nb)).abs() > EQUIVALENT_COSINE
        };
        let named = (0..cands.len())
            .find(|&i| !used[i] && (i == ib || equivalent_to_best(i)))
            .unwrap_or(ib);
        let mut cols = ext.columns.clone();
        cols.push(cands[named].2.clone());
        let ols = gls(&cols, &ext.target, 0.0, &Rows::new(&ds.segment_start, None));
        let noise1 = noise_of(ds, &raw_residual(&cols, &ols.beta, &ext.target));
        let (l1, fit) = neg2(ds, &cols, &ext.target, &noise1);
        let delta_bic = l1 - l0 + charge;
        let (c, p, _) = &cands[named];
        let label = format!("{}·(T − T0)^{p}", c.symbol);
        if delta_bic >= 0.0 {
            next_best = Some((label, delta_bic));
            break;
        }
        let k = cols.len() - 1;
        let change = fit.beta[k];
        let on = off(&ext.columns, &cands[named].2);
        let equivalent = (0..cands.len())
            .filter(|&i| i != named && !used[i])
            .filter_map(|i| {
                let o = off(&ext.columns, &cands[i].2);
                let cos = dot(&o, &on) / (dot(&o, &o).sqrt() * dot(&on, &on).sqrt());
                (cos.abs() > EQUIVALENT_COSINE).then(|| {
                    (
                        cands[i].0.symbol,
                        cands[i].1,
                        change * dot(&o, &on) / dot(&o, &o),
                    )
                })
            })
            .collect();
        terms.push(TableTerm {
            symbol: c.symbol,
            key: c.key,
            power: *p,
            change,
            sigma: fit.se[k],
            unit: format!("{}/°C^{p}", c.unit),
            delta_bic,
            equivalent,
        });
        used[named] = true;
        ext.columns.push(cands[named].2.clone());
        ext.names.push(format!("table_error {label}"));
        noise0 = noise1;
    }
    if !terms.is_empty() {
        let t: Vec<String> = terms
            .iter()
            .map(|t| format!("{}·(T − T0)^{}", t.symbol, t.power))
            .collect();
        ext.description
            .push_str(&format!(" + table error {} (table_error)", t.join(" + ")));
    }
    // The corrected table: each term applied to its polynomial, then the core's validator.
    let mut corrected = None;
    let mut refused = None;
    let mut std_corrected = None;
    let mut std_corrected_oos = None;
    let fixed = |target: &[f64]| {
        let f = gls(
            &base.columns,
            target,
            0.0,
            &Rows::new(&ds.segment_start, None),
        );
        std(&raw_residual(&base.columns, &f.beta, target))
    };
    let std_given = fixed(&base.target);
    let cv = |target: &[f64]| {
        super::select::cross_validate(ds, &base.columns, target, &given_noise, cfg).raw
    };
    let std_given_oos = cv(&base.target);
    if !terms.is_empty() {
        let mut t = *table;
        for term in &terms {
            let c = COEFFICIENTS
                .iter()
                .find(|c| c.key == term.key)
                .map_or(Coefficient::Bias, |c| c.which);
            t = with_change(&t, c, term.power, term.change);
        }
        match t.validate() {
            Ok(()) => {
                if let Ok(b) = calibrated_baseline(ds, &t) {
                    std_corrected = Some(fixed(&b.target));
                    std_corrected_oos = Some(cv(&b.target));
                }
                corrected = Some(t);
            }
            Err(e) => refused = Some(crate::log::calibration_file::TableRefused(e).to_string()),
        }
    }
    (
        TableCheck {
            reference_c: table.thermal.reference.0,
            terms,
            next_best,
            corrected,
            refused,
            std_given,
            std_corrected,
            std_given_out_of_sample: std_given_oos,
            std_corrected_out_of_sample: std_corrected_oos,
        },
        ext,
    )
}

/// The text report's section.
pub fn text_of(c: &TableCheck, unit: &str) -> String {
    use std::fmt::Write as _;
    let mut o = String::new();
    let _ = writeln!(
        o,
        "calibration table (errors of its temperature models, T0 = {} °C):",
        c.reference_c
    );
    if c.terms.is_empty() {
        let _ = writeln!(
            o,
            "  none found{}",
            c.next_best
                .as_ref()
                .map(|(n, b)| format!(" (best: {n}, ΔBIC {b:.1})"))
                .unwrap_or_default()
        );
    }
    for t in &c.terms {
        let eq: Vec<String> = t
            .equivalent
            .iter()
            .map(|(s, p, v)| format!("{s}·(T − T0)^{p} by {v:.4e}"))
            .collect();
        let _ = writeln!(
            o,
            "  table_error: {} should change by {:.4e} ± {:.2e} {} × (T − T0)^{}; ΔBIC {:.1}{}",
            t.symbol,
            t.change,
            t.sigma,
            t.unit,
            t.power,
            t.delta_bic,
            if eq.is_empty() {
                String::new()
            } else {
                format!(
                    "\n     this record cannot tell it from: {} (the first is named)",
                    eq.join(", ")
                )
            }
        );
    }
    if let Some(why) = &c.refused {
        let _ = writeln!(o, "  corrected table refused by the validator: {why}");
    }
    if let (Some(a), Some(b)) = (c.std_corrected, c.std_corrected_out_of_sample) {
        let _ = writeln!(
            o,
            "  loading the corrected table: residual std {:.4e} → {:.4e} {unit}, out of sample \
             {:.4e} → {:.4e} {unit} (offset and drift fitted)",
            c.std_given, a, c.std_given_out_of_sample, b
        );
    }
    o
}

/// The JSON `calibration_table` value.
pub fn json_of(c: &TableCheck) -> serde_json::Value {
    serde_json::json!({
        "reference_c": c.reference_c,
        "terms": c.terms,
        "next_best": c.next_best.as_ref().map(|(n, b)| serde_json::json!({"name": n, "delta_bic": b})),
        "corrected_table_refused": c.refused,
        "residual_std_given": c.std_given,
        "residual_std_corrected": c.std_corrected,
        "residual_std_out_of_sample_given": c.std_given_out_of_sample,
        "residual_std_out_of_sample_corrected": c.std_corrected_out_of_sample,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use accomp::units::Celsius;

    /// The change written into the table's normalised polynomial is ΔC·(T − T0)^p at every
    /// temperature (checked against the direct evaluation).
    #[test]
    fn a_change_in_powers_of_t_minus_t0_is_written_into_the_normalised_polynomial() {
        let t = accomp::reference::paper_order2_table();
        let t0 = t.thermal.reference.0;
        for p in 1..=MAX_POWER {
            let c = with_change(&t, Coefficient::Bias, p, 2e-6);
            for temp in [31.0, 45.5, 60.0, 64.0] {
                let before = t.thermal.coefficients_at(Celsius(temp)).unwrap().0.bias_g;
                let after = c.thermal.coefficients_at(Celsius(temp)).unwrap().0.bias_g;
                let want = 2e-6 * (temp - t0).powi(p as i32);
                assert!(
                    (after - before - want).abs() < 1e-15,
                    "p {p} T {temp}: {} vs {want}",
                    after - before
                );
            }
        }
    }
}
