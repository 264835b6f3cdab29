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
//! the current residual. Linear parameters are solved by the host's QR
//! (`numerics::linalg::OrthonormalBasis`, nalgebra's Householder: no normal equations are
//! formed), columns scaled to unit norm first.
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

/// An orthonormal basis of the whitened design columns with its triangular factor: the host's
/// one QR (nalgebra's Householder, dependent columns dropped), kept at this path for the
/// discovery's callers.
pub use crate::numerics::linalg::OrthonormalBasis as Basis;

/// Projects `v` off the orthonormal columns `q` (twice) and returns the coefficients removed.
pub use crate::numerics::linalg::project_out as orthogonalize;

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

/// Sample standard deviation (kept at this path for the discovery's callers; the toolkit's).
pub use crate::numerics::stats::std;

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

/// Half-width of the tilt smoothing on a head programme, s.
pub const TILT_SMOOTHING_S: f64 = 300.0;

/// Centred running mean over ±`half_s` seconds, never across a segment start.
pub fn centred_mean(x: &[f64], t: &[f64], seg_start: &[bool], half_s: f64) -> Vec<f64> {
    let n = x.len();
    let mut seg_id = vec![0usize; n];
    for i in 1..n {
        seg_id[i] = seg_id[i - 1] + usize::from(seg_start[i]);
    }
    let mut prefix = vec![0.0; n + 1];
    for i in 0..n {
        prefix[i + 1] = prefix[i] + x[i];
    }
    let (mut lo, mut hi) = (0usize, 0usize);
    (0..n)
        .map(|i| {
            while t[i] - t[lo] > half_s || seg_id[lo] != seg_id[i] {
                lo += 1;
            }
            hi = hi.max(i);
            while hi + 1 < n && t[hi + 1] - t[i] <= half_s && seg_id[hi + 1] == seg_id[i] {
                hi += 1;
            }
            (prefix[hi + 1] - prefix[lo]) / (hi + 1 - lo) as f64
        })
        .collect()
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
    if let Some(a) = ds.changing_input() {
        // A head programme: eq. (5) at each row's nominal input, sin(θ + φ) − sin θ with
        // θ = asin(a) taken in [−90°, 90°] (cos θ = √(1 − a²) ≥ 0: an `input_g` column cannot
        // tell 0° from 180°; a programme through 180° would need the head angle). At ±1 g this is
        // a·(cos φ − 1), at 0 g sin φ: the two static cases.
        //
        // At the 0 g positions the tilt enters at first order, and so does the tiltmeter's
        // reading noise (0.02″ ≈ 0.1 µg per reading) and its quantisation dither: subtracted
        // at full gain they add noise that the fit then "corrects" by shrinking the tilt gain
        // (errors in variables; measured: `tilt_coupling` accepted on null logs). The
        // foundation tilt has nothing faster than the building's hours-long lag, so the tilt
        // is taken as a centred mean over ±TILT_SMOOTHING_S inside each segment.
        let smoothed: Vec<Vec<f64>> = tilts
            .iter()
            .map(|t| centred_mean(t, &ds.t_s, &ds.segment_start, TILT_SMOOTHING_S))
            .collect();
        return Some(
            (0..ds.len())
                .map(|i| {
                    let th2: f64 = smoothed.iter().map(|t| t[i] * t[i]).sum();
                    let cos_head = (1.0 - a[i] * a[i]).max(0.0).sqrt();
                    a[i] * (th2.sqrt().cos() - 1.0) + cos_head * smoothed[0][i].sin()
                })
                .collect(),
        );
    }
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

/// At most this many distinct input values get one level each; more (a continuous sweep) are
/// described by a cubic in the input instead.
pub const MAX_INPUT_LEVELS: usize = 16;

/// Distinct values of the input, in order of first appearance (exact comparison: the input
/// column is the commanded head programme, and the importer never bins across a head move).
fn distinct_inputs(a: &[f64]) -> Vec<f64> {
    let mut v: Vec<f64> = Vec::new();
    for x in a {
        if !v.contains(x) {
            v.push(*x);
        }
    }
    v
}

/// Columns describing eq. (1)'s dependence on a changing input at the reference temperature:
/// one level per distinct input value beyond the first (the offset column is the first level,
/// so no column is a combination of the others), or a cubic in the input when there are more
/// than [`MAX_INPUT_LEVELS`] values.
///
/// Levels rather than K1·a + K2·a²: with three positions (−1, 0, +1 g) they span the same space,
/// with more they also absorb the cross-axis term δo·a_p, which differs between positions in a
/// way a polynomial in a alone does not describe, and any odd K3·a³. The price: K1 and K2 are
/// not reported separately (the baseline is a nuisance model here).
pub fn input_columns(a: &[f64]) -> (Vec<Vec<f64>>, Vec<String>) {
    let levels = distinct_inputs(a);
    if levels.len() <= MAX_INPUT_LEVELS {
        let cols = levels
            .iter()
            .skip(1)
            .map(|l| a.iter().map(|x| f64::from(u8::from(x == l))).collect())
            .collect();
        let names = levels
            .iter()
            .skip(1)
            .map(|l| format!("level(input={l:+.4} g)"))
            .collect();
        (cols, names)
    } else {
        let cols = (1..=3)
            .map(|p| a.iter().map(|x| x.powi(p)).collect())
            .collect();
        let names = (1..=3).map(|p| format!("input^{p}")).collect();
        (cols, names)
    }
}

/// Builds the static baseline (no calibration). The temperature order 0–3 is chosen by BIC on
/// the whitened fit.
///
/// With a changing input (a head programme) the model is eq. (1) per position:
/// K0(T) + K1(T)·a + K2·a² → the levels of [`input_columns`] plus, for each temperature power
/// xᵖ, the bias column xᵖ and the scale-factor column a·xᵖ (K1's temperature dependence times
/// the input; K2(T)·a² is left out: K2 ~ 10 µg/g² with a few ppm/°C is far below the noise).
pub fn static_baseline(ds: &Dataset) -> Baseline {
    let mut target = ds.y.clone();
    let mut columns = trend_columns(ds);
    let mut names = vec!["offset".to_owned(), "linear_drift".to_owned()];
    let mut tilt_subtracted = false;
    let mut desc = vec!["offset".to_owned(), "linear drift".to_owned()];
    let input = ds.changing_input();
    if let Some(a) = input {
        let (c, n) = input_columns(a);
        desc.push(format!(
            "eq. (1) per head position ({} input values: {})",
            n.len() + 1,
            if n.first().is_some_and(|s| s.starts_with("level")) {
                "one level each"
            } else {
                "cubic in the input"
            }
        ));
        columns.extend(c);
        names.extend(n);
    }
    // Temperature power p as columns: xᵖ, and a·xᵖ when the input changes.
    let temp_cols = |x: &[f64], p: i32| -> Vec<Vec<f64>> {
        let xp: Vec<f64> = x.iter().map(|v| v.powi(p)).collect();
        let mut v = Vec::new();
        if let Some(a) = input {
            v.push(xp.iter().zip(a).map(|(x, a)| x * a).collect());
        }
        v.insert(0, xp);
        v
    };
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
            rich.extend(temp_cols(&x, p));
        }
        let ols = gls(&rich, &target, 0.0, &rows);
        let phi0 = ar1(&raw_residual(&rich, &ols.beta, &target), &ds.segment_start);
        let mut best: (f64, usize) = (f64::INFINITY, 0);
        for order in 0..=3usize {
            let mut cols = columns.clone();
            for p in 1..=order {
                cols.extend(temp_cols(&x, p as i32));
            }
            let f = gls(&cols, &target, phi0, &rows);
            let n = f.n_w as f64;
            let bic = n * (f.rss_w / n).max(f64::MIN_POSITIVE).ln() + f.k as f64 * n.ln();
            if bic < best.0 - 1e-9 {
                best = (bic, order);
            }
        }
        for p in 1..=best.1 {
            columns.extend(temp_cols(&x, p as i32));
            names.push(format!("temperature^{p}"));
            if input.is_some() {
                names.push(format!("input*temperature^{p}"));
            }
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

/// Why a calibration baseline cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BaselineError {
    /// The record has no temperature channel to evaluate the table's models at.
    #[error("a calibration baseline needs a temperature channel")]
    NoTemperature,
    /// The table's temperature models refuse a row's temperature.
    #[error("calibration model at {temperature_c} °C: {why}")]
    Model {
        /// The row's temperature, °C.
        temperature_c: f64,
        /// The core's error.
        why: String,
    },
}

/// Baseline from a calibration table: eq. (1) with the temperature models at the measured
/// temperature, eq. (5) tilt, subtracted with a fixed coefficient; offset and drift free.
pub fn calibrated_baseline(
    ds: &Dataset,
    table: &accomp::table::CalibrationTable,
) -> Result<Baseline, BaselineError> {
    let temp = ds
        .channel(ChannelKind::Temperature)
        .ok_or(BaselineError::NoTemperature)?;
    let input = ds.input_g.unwrap_or(table.orientation.nominal_input.0);
    let changing = ds.changing_input();
    let tilt = tilt_term_g(ds);
    let mut target = Vec::with_capacity(ds.len());
    for i in 0..ds.len() {
        let (k, _) = table
            .thermal
            .coefficients_at(accomp::units::Celsius(temp.values[i]))
            .map_err(|e| BaselineError::Model {
                temperature_c: temp.values[i],
                why: format!("{e:?}"),
            })?;
        let (nominal, cross) = match changing {
            // A head programme: the row's input; the cross axis that turns with it is taken
            // along the pendulum axis (spindle along the output axis, s = +1, the simulator's
            // and the paper's mounting), a_p = cos θ = √(1 − a²) with θ in [−90°, 90°].
            Some(a) => (
                a[i],
                accomp::model::CrossAxis {
                    a_p: accomp::units::Gs((1.0 - a[i] * a[i]).max(0.0).sqrt()),
                    a_o: accomp::units::Gs(0.0),
                },
            ),
            None => (input, table.orientation.cross),
        };
        let a = nominal + tilt.as_ref().map_or(0.0, |t| t[i]);
        let pred_v = k.output(accomp::units::Gs(a), cross).0;
        // The output unit: volts directly; a g-unit log compares with the model in g.
        let pred = if ds.output_unit == "v" {
            pred_v
        } else {
            ds.unit_per_g.unwrap_or(1.0) * pred_v / k.scale_factor_v_per_g
        };
        target.push(ds.y[i] - pred);
    }
    let mut columns = trend_columns(ds);
    let mut names: Vec<String> = vec!["offset".into(), "linear_drift".into()];
    let mut description = "calibration prediction (eq. (1) at the measured temperature, eq. (5) tilt) + offset + linear drift".to_owned();
    if let Some(a) = changing {
        // A calibration knows K1 and K2 to a few ppm and µg/g² only; at 1 g such an error is a
        // square wave of several µg following the programme, which the catalogue would
        // otherwise misname (self_heating's column is made of the same input changes). The
        // residual scale factor and K2 are therefore free.
        columns.push(a.to_vec());
        columns.push(a.iter().map(|x| x * x).collect());
        names.push("scale_factor_error".into());
        names.push("k2_error".into());
        description.push_str(" + residual scale factor (a) and K2 (a²) for the head programme");
    }
    Ok(Baseline {
        description,
        target,
        columns,
        names,
        tilt_subtracted: tilt.is_some(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::discover::import::Channel;

    /// A 4-position head programme (+1, 0, −1, 0 g, 50 rows each, 10 s apart) with a
    /// temperature that wanders; no tilt, no noise.
    fn programme_dataset(n: usize) -> (Dataset, Vec<f64>, Vec<f64>) {
        let t: Vec<f64> = (0..n).map(|i| 10.0 * i as f64).collect();
        let a: Vec<f64> = (0..n)
            .map(|i| [1.0, 0.0, -1.0, 0.0][(i / 50) % 4])
            .collect();
        let temp: Vec<f64> = t
            .iter()
            .map(|x| 60.0 + 0.3 * (x / 1700.0).sin() + 0.1 * (x / 430.0).cos())
            .collect();
        let mut seg = vec![false; n];
        seg[0] = true;
        let ds = Dataset {
            t_s: t,
            y: vec![0.0; n],
            segment_start: seg,
            channels: vec![
                Channel {
                    name: "temperature_c".into(),
                    kind: ChannelKind::Temperature,
                    values: temp.clone(),
                },
                Channel {
                    name: "input_g".into(),
                    kind: ChannelKind::Input,
                    values: a.clone(),
                },
            ],
            output_name: "output_v".into(),
            output_unit: "v".into(),
            unit_per_g: None,
            input_g: Some(1.0),
            start_unix_s: None,
            site: None,
            dt_s: 10.0,
            samples_per_point: Vec::new(),
            notes: Vec::new(),
            warnings: Vec::new(),
        };
        (ds, a, temp)
    }

    /// The unweighted least-squares fit of the baseline, which must leave no residual (the data
    /// are made from the baseline's own model).
    fn fit_exactly(ds: &Dataset, b: &Baseline) -> Fit {
        let f = gls(
            &b.columns,
            &b.target,
            0.0,
            &Rows::new(&ds.segment_start, None),
        );
        let r = raw_residual(&b.columns, &f.beta, &b.target);
        let worst = r.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        assert!(worst < 1e-12, "residual {worst:e}");
        f
    }

    fn coefficient(b: &Baseline, beta: &[f64], name: &str) -> f64 {
        let i = b.names.iter().position(|n| n == name);
        assert!(i.is_some(), "no column {name} in {:?}", b.names);
        i.map_or(f64::NAN, |i| beta[i])
    }

    #[test]
    fn static_baseline_fits_eq1_per_head_position_exactly() {
        let n = 800;
        let (mut ds, a, temp) = programme_dataset(n);
        // E = K1(T)·a + K1·K0(T) + K1·K2·a², K1 with a 50 ppm/°C tempco (a temperature
        // dependence that moves with the input) and K0 with 20 µg/°C. The K1 tempco acting on
        // K2·a² (5e-5/°C × 2e-5 × 0.3 °C ≈ 3e-10 of the output) is below any noise and is not
        // in the baseline, so it is not in the data either.
        let (k1, s1, k0, b1, k2) = (1.2, 50.0e-6, 3.0e-4, 20.0e-6, 2.0e-5);
        ds.y = (0..n)
            .map(|i| {
                let dt = temp[i] - 60.0;
                k1 * (1.0 + s1 * dt) * a[i] + k1 * (k0 + b1 * dt) + k1 * k2 * a[i] * a[i]
            })
            .collect();
        let b = static_baseline(&ds);
        assert_eq!(b.columns.len(), b.names.len());
        let f = fit_exactly(&ds, &b);
        // The temperature column is (T − mean)/std: its coefficients are the tempcos × std(T).
        let m = temp.iter().sum::<f64>() / n as f64;
        let st = std(&temp);
        let sf = coefficient(&b, &f.beta, "input*temperature^1");
        assert!((sf - k1 * s1 * st).abs() < 1e-12, "{sf:e}");
        let bias = coefficient(&b, &f.beta, "temperature^1");
        assert!((bias - k1 * b1 * st).abs() < 1e-12, "{bias:e}");
        // Levels relative to the first position (+1 g), the input terms at the mean temperature:
        // 0 g loses K1(m)·1 + K1·K2, −1 g loses 2·K1(m).
        let l0 = coefficient(&b, &f.beta, "level(input=+0.0000 g)");
        let want = -k1 * (1.0 + s1 * (m - 60.0)) - k1 * k2;
        assert!((l0 - want).abs() < 1e-12, "{l0} vs {want}");
        let lm = coefficient(&b, &f.beta, "level(input=-1.0000 g)");
        let want = -2.0 * k1 * (1.0 + s1 * (m - 60.0));
        assert!((lm - want).abs() < 1e-12, "{lm} vs {want}");
    }

    #[test]
    fn centred_mean_averages_inside_the_window_and_never_across_a_segment() {
        let t: Vec<f64> = (0..10).map(f64::from).collect();
        let x: Vec<f64> = vec![0.0, 3.0, 0.0, 3.0, 0.0, 100.0, 0.0, 3.0, 0.0, 3.0];
        let mut seg = vec![false; 10];
        seg[0] = true;
        seg[5] = true;
        let m = centred_mean(&x, &t, &seg, 1.0);
        // Row 2: rows 1–3; row 4: rows 3–4 only (row 5 starts a new segment).
        assert_eq!(m[2], 2.0);
        assert_eq!(m[4], 1.5);
        assert_eq!(m[5], 50.0);
    }

    #[test]
    fn input_levels_leave_out_the_first_value_and_a_sweep_becomes_a_cubic() {
        let (c, n) = input_columns(&[1.0, 1.0, 0.0, -1.0, 0.0]);
        assert_eq!(n, vec!["level(input=+0.0000 g)", "level(input=-1.0000 g)"]);
        assert_eq!(c[0], vec![0.0, 0.0, 1.0, 0.0, 1.0]);
        let sweep: Vec<f64> = (0..40).map(|i| f64::from(i) / 40.0).collect();
        let (c, n) = input_columns(&sweep);
        assert_eq!(n, vec!["input^1", "input^2", "input^3"]);
        assert!((c[1][20] - 0.25).abs() < 1e-15);
    }

    #[test]
    fn calibrated_baseline_predicts_each_row_at_its_own_input() {
        let n = 800;
        let (mut ds, a, temp) = programme_dataset(n);
        let table = accomp::reference::paper_order2_table();
        // The residual scale-factor and K2 errors the baseline leaves free, plus an offset.
        let (d_sf, d_k2, off) = (4.0e-6, -3.0e-6, 7.0e-6);
        ds.y = (0..n)
            .map(|i| {
                let (k, _) = table
                    .thermal
                    .coefficients_at(accomp::units::Celsius(temp[i]))
                    .unwrap();
                // Eq. (1) written out: K1·(K0 + a + K2·a² + δo·a_p), a_p = √(1 − a²).
                let a_p = (1.0 - a[i] * a[i]).sqrt();
                k.scale_factor_v_per_g
                    * (k.bias_g
                        + a[i]
                        + k.nonlinearity_g_per_g2 * a[i] * a[i]
                        + k.misalignment_o.0 * a_p)
                    + off
                    + d_sf * a[i]
                    + d_k2 * a[i] * a[i]
            })
            .collect();
        let b = calibrated_baseline(&ds, &table).unwrap();
        assert_eq!(
            b.names,
            vec!["offset", "linear_drift", "scale_factor_error", "k2_error"]
        );
        let f = fit_exactly(&ds, &b);
        assert!((f.beta[0] - off).abs() < 1e-12 && (f.beta[1]).abs() < 1e-12);
        assert!((f.beta[2] - d_sf).abs() < 1e-12 && (f.beta[3] - d_k2).abs() < 1e-12);
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
