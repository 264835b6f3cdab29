//! The demo's calibration tables: Table 1 fitted as the lab would, and each experiment's table
//! derived from it (orientation, tilt axis, φ0).

use super::stream::raw;
use super::*;

/// Table 1 in the repository's `data/` (where the sources were built from).
pub(super) fn default_table1() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../data")
        .join(TABLE1_FILE)
}

/// Fits Table 1 and builds the lab's calibration table (T0 = 60 °C, the paper's 1 g test).
pub(super) fn fit_table1(path: &Path) -> anyhow::Result<(CalibrationTable, Vec<(String, usize)>)> {
    let text =
        fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let table = fit::parse_coefficient_table(&text)
        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    let report = fit::fit_table(&table, &[], Celsius(50.0))?;
    let scale = table
        .scale()
        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    let cal = fit::calibration_table(&report, scale, Celsius(60.0), "JN-06 A12124", DEMO_DATE)?;
    let orders = report
        .coefficients
        .iter()
        .map(|c| (c.name.clone(), c.selected_order))
        .collect();
    Ok((cal, orders))
}

/// The table of one experiment: the fitted models with the test's orientation and tilt set-up.
///
/// - 1 g (input axis up): tilt about the spindle changes a_i only as cos φ (second order), so the
///   tilt axis is `None`; no cross-axis input.
/// - 0 g (input axis horizontal): eq. (5) applies (`TiltAxis::Input`) with φ0 = the first tilt
///   reading, and the cross axis along the spindle carries 1 g. T0 moves to the nearest edge of
///   the calibrated range (the table refuses a T0 outside it), so the linearized output is not
///   offset by a 30 °C extrapolation.
pub(super) fn experiment_table(
    base: &CalibrationTable,
    sc: &Scenario,
    first: &Sample,
) -> anyhow::Result<CalibrationTable> {
    let mut t = *base;
    let o = &sc.accelerometer.orientation;
    let angle = o
        .positions
        .first()
        .map_or(0.0, |p| p.angle_deg)
        .to_radians();
    let (a_i, cross) = crate::sim::accelerometer::axes(o.spindle_axis, o.cross_sign, angle, 1.0);
    // Round the nominal orientation to the exact values a lab would type in.
    let round = |v: f64| (v * 1e6).round() / 1e6;
    t.orientation.nominal_input = Gs(round(a_i.0));
    t.orientation.cross = CrossAxis {
        a_p: Gs(round(cross.a_p.0)),
        a_o: Gs(round(cross.a_o.0)),
    };
    let zero_g = a_i.0.abs() < 0.5;
    if zero_g {
        t.tilt.axis = TiltAxis::Input;
        // φ0: what the board reads at the start, through the same conversion the firmware uses.
        let f = pipeline::process(0, 0, &raw(first), Some(&t));
        t.tilt.reference = TiltArcsec(f.tilt_arcsec);
        let (lo, hi) = (t.thermal.scale.min.0, t.thermal.scale.max.0);
        t.thermal.reference = Celsius(sc.thermostat.setpoint_c.clamp(lo, hi));
    } else {
        t.tilt.axis = TiltAxis::None;
    }
    t.validate()
        .map_err(|e| anyhow::anyhow!("experiment table refused: {e:?}"))?;
    Ok(t)
}
