//! The coefficient table (`accomp fit`'s input format) from a report.

use super::*;

/// One row of the coefficient table: a temperature and the weighted means (value, SE) of the
/// tests there.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TableRow {
    /// Mean temperature of the tests.
    pub temperature_c: f64,
    /// Tests combined.
    pub tests: usize,
    /// K0 (g), SE.
    pub k0_g: (f64, f64),
    /// K1 (V/g), SE.
    pub k1_v_per_g: (f64, f64),
    /// K2 (g/g²), SE.
    pub k2_g_per_g2: (f64, f64),
    /// δp (arcmin), SE, when a pendulum-axis test exists at this temperature.
    pub delta_p_arcmin: Option<(f64, f64)>,
    /// δo (arcmin), SE, when an output-axis test exists at this temperature.
    pub delta_o_arcmin: Option<(f64, f64)>,
}

/// The coefficient table: one row per test temperature (tests within
/// [`TEMPERATURE_GROUP_TOLERANCE_C`] combined by inverse-variance weighted means; K0, K1, K2
/// from every test, δp from pendulum-axis tests, δo from output-axis tests), sorted by
/// temperature.
pub fn coefficient_table(report: &TumbleReport) -> Result<Vec<TableRow>, TumbleError> {
    let mut groups: Vec<Vec<&TestSolution>> = Vec::new();
    for t in &report.tests {
        let temp = t
            .temperature
            .mean_c
            .ok_or_else(|| TumbleError::NoTemperature(t.id.clone()))?;
        match groups.iter_mut().find(|g| {
            g[0].temperature
                .mean_c
                .is_some_and(|a| (a - temp).abs() < TEMPERATURE_GROUP_TOLERANCE_C)
        }) {
            Some(g) => g.push(t),
            None => groups.push(vec![t]),
        }
    }
    let mut rows = Vec::new();
    for g in groups {
        let pick = |f: fn(&TestSolution) -> Estimate| g.iter().map(|t| f(t)).collect::<Vec<_>>();
        let axis = |a: RotationAxis| {
            g.iter()
                .filter(|t| t.rotation_axis == a)
                .map(|t| t.coefficients.misalignment_arcmin)
                .collect::<Vec<_>>()
        };
        let temps: Vec<f64> = g.iter().filter_map(|t| t.temperature.mean_c).collect();
        let (Some(k0), Some(k1), Some(k2)) = (
            weighted(&pick(|t| t.coefficients.k0_g)),
            weighted(&pick(|t| t.coefficients.k1_v_per_g)),
            weighted(&pick(|t| t.coefficients.k2_g_per_g2)),
        ) else {
            continue;
        };
        rows.push(TableRow {
            temperature_c: temps.iter().sum::<f64>() / temps.len() as f64,
            tests: g.len(),
            k0_g: k0,
            k1_v_per_g: k1,
            k2_g_per_g2: k2,
            delta_p_arcmin: weighted(&axis(RotationAxis::Pendulum)),
            delta_o_arcmin: weighted(&axis(RotationAxis::Output)),
        });
    }
    rows.sort_by(|a, b| a.temperature_c.total_cmp(&b.temperature_c));
    Ok(rows)
}

/// The coefficient table as CSV in the format of the shared Table 1 file
/// (`temperature_c,k0_g,k1_v_per_g,k2_g_per_g2,delta_p_arcmin` [`,delta_o_arcmin`]); with
/// `with_se`, one `<column>_se` column per coefficient is appended. A column is written when at
/// least one row has it; a row without it leaves the cell empty.
pub fn table_csv(report: &TumbleReport, with_se: bool) -> Result<String, TumbleError> {
    let rows = coefficient_table(report)?;
    let has_p = rows.iter().any(|r| r.delta_p_arcmin.is_some());
    let has_o = rows.iter().any(|r| r.delta_o_arcmin.is_some());
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# Static model coefficients from dividing-head tumble tests (accomp tumble)."
    );
    let _ = writeln!(
        s,
        "# Local gravity {} g_n ({}), g_n = {STANDARD_GRAVITY_M_S2} m/s^2; index error {} arcsec (1 sigma).",
        report.gravity_g, report.gravity_source, report.index_error_arcsec
    );
    let _ = writeln!(
        s,
        "# Columns: temperature (degC); K0 bias (g); K1 scale factor (V/g); K2 second-order nonlinearity (g/g^2);"
    );
    let _ = writeln!(
        s,
        "# delta_p / delta_o misalignments (arcmin). One row per test temperature (weighted mean of its tests)."
    );
    let mut cols = vec!["temperature_c", "k0_g", "k1_v_per_g", "k2_g_per_g2"];
    if has_p {
        cols.push("delta_p_arcmin");
    }
    if has_o {
        cols.push("delta_o_arcmin");
    }
    let mut header = cols.join(",");
    if with_se {
        for c in &cols[1..] {
            let _ = write!(header, ",{c}_se");
        }
    }
    let _ = writeln!(s, "{header}");
    let opt = |v: Option<(f64, f64)>, se: bool| {
        v.map_or(String::new(), |(m, e)| {
            format!("{}", if se { e } else { m })
        })
    };
    for r in rows {
        let mut vals = vec![Some(r.k0_g), Some(r.k1_v_per_g), Some(r.k2_g_per_g2)];
        if has_p {
            vals.push(r.delta_p_arcmin);
        }
        if has_o {
            vals.push(r.delta_o_arcmin);
        }
        let mut line = format!("{}", round_temperature(r.temperature_c));
        for v in &vals {
            let _ = write!(line, ",{}", opt(*v, false));
        }
        if with_se {
            for v in &vals {
                let _ = write!(line, ",{}", opt(*v, true));
            }
        }
        let _ = writeln!(s, "{line}");
    }
    Ok(s)
}

/// Temperatures to 0.001 °C: the RTD is good to 0.1 °C, more digits are noise.
pub(super) fn round_temperature(t: f64) -> f64 {
    (t * 1000.0).round() / 1000.0
}
