//! The human-readable report.

use super::*;
use crate::text_table::Columns;

pub(super) fn fmt_est(e: &Estimate) -> String {
    format!("{:>16.9e} ± {:.2e}", e.value, e.se)
}

/// The table of a test's positions.
const POSITIONS: Columns<5> = Columns([
    ("angle_deg", 10),
    ("n", 4),
    ("mean_v", 16),
    ("scatter_v", 11),
    ("residual_v", 12),
]);

/// A human-readable report.
pub fn render_text(r: &TumbleReport) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "local gravity {} g_n ({}); index error {} arcsec (1σ)",
        r.gravity_g, r.gravity_source, r.index_error_arcsec
    );
    for t in &r.tests {
        let _ = writeln!(
            s,
            "\ntest {} (line {}), rotation about the {} axis{}{}",
            t.id,
            t.first_line,
            match t.rotation_axis {
                RotationAxis::Output => "output",
                RotationAxis::Pendulum => "pendulum",
            },
            t.temperature
                .mean_c
                .map_or(String::new(), |c| format!(", {c:.3} °C")),
            t.time_s
                .map_or(String::new(), |x| format!(", t = {x:.0} s")),
        );
        let _ = writeln!(s, "  {}", POSITIONS.header());
        for p in &t.positions {
            let cells = [
                format!("{:.4}", p.angle_deg),
                p.readings.to_string(),
                format!("{:.10}", p.mean_v),
                p.scatter_v.map_or("-".into(), |v| format!("{v:.2e}")),
                format!("{:.3e}", p.residual_v),
            ];
            let _ = writeln!(s, "  {}", POSITIONS.row(cells));
        }
        let _ = writeln!(
            s,
            "  least squares ({} unknowns, {} dof, noise from {:?}, rms residual {:.2e} V):",
            t.fit.unknowns, t.fit.dof, t.fit.noise_basis, t.fit.rms_residual_v
        );
        let _ = writeln!(s, "    K0 (g)       {}", fmt_est(&t.coefficients.k0_g));
        let _ = writeln!(
            s,
            "    K1 (V/g)     {}",
            fmt_est(&t.coefficients.k1_v_per_g)
        );
        let _ = writeln!(
            s,
            "    K2 (g/g²)    {}",
            fmt_est(&t.coefficients.k2_g_per_g2)
        );
        let _ = writeln!(
            s,
            "    {} {}",
            match t.rotation_axis {
                RotationAxis::Output => "δo (arcmin) ",
                RotationAxis::Pendulum => "δp (arcmin) ",
            },
            fmt_est(&t.coefficients.misalignment_arcmin)
        );
        if let Some(k3) = &t.coefficients.k3_g_per_g3 {
            let _ = writeln!(s, "    K3 (g/g³)    {}", fmt_est(k3));
        }
        if let Some(f) = &t.four_point {
            let _ = writeln!(
                s,
                "  four-point (paper): K0 {:.9e} g, K1 {:.9e} V/g, K2 {:.3e} g/g², δ {:.5} arcmin",
                f.k0_g, f.k1_v_per_g, f.k2_g_per_g2, f.misalignment_arcmin
            );
        }
    }
    for g in &r.stability {
        let _ = writeln!(
            s,
            "\nstability over {} tests, {:.2} days{}:",
            g.tests,
            g.span_days,
            g.temperature_c
                .map_or(String::new(), |c| format!(" at {c:.2} °C"))
        );
        for c in &g.coefficients {
            let _ = writeln!(
                s,
                "  {:<20} mean {:>15.9e}  slope {:>10.3e} ± {:.2e} /day  regression sd {:.3e}",
                c.coefficient, c.mean, c.slope_per_day, c.slope_se_per_day, c.regression_sd
            );
        }
    }
    s
}
