//! The human-readable fit report.

use super::*;
use crate::text_table::Columns;

fn unit_of(column: &str) -> &str {
    match column {
        BIAS_COLUMN => "g",
        SCALE_FACTOR_COLUMN => "V/g",
        NONLINEARITY_COLUMN => "g/g²",
        MISALIGNMENT_P_COLUMN | MISALIGNMENT_O_COLUMN => "arcmin",
        _ => "column unit",
    }
}

fn opt(v: Option<f64>, prec: usize, sci: bool) -> String {
    match v {
        Some(x) if x.is_finite() && sci => format!("{x:.prec$e}"),
        Some(x) if x.is_finite() => format!("{x:.prec$}"),
        Some(_) => "inf".to_owned(),
        None => "—".to_owned(),
    }
}

/// The table of a coefficient's fitted orders (the monomials follow, unaligned).
const ORDERS: Columns<7> = Columns([
    ("order", 5),
    ("s", 11),
    ("rms", 11),
    ("AICc", 9),
    ("LOO rms", 11),
    ("F p", 9),
    ("dK/dT /°C", 13),
]);

/// The human-readable report: one table per coefficient.
pub fn render_text(report: &FitReport, at: Celsius, paper_source: Option<&Path>) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Fits in x = (T − Tc)/Ts over the table range; sensitivities at {} °C.",
        at.0
    );
    match paper_source {
        Some(p) => {
            let _ = writeln!(s, "Paper's printed models: {}", p.display());
        }
        None => {
            let _ = writeln!(
                s,
                "Paper's printed models: not available (no {PAPER_MODELS_FILE} beside the input; use --paper)."
            );
        }
    }
    for c in &report.coefficients {
        let unit = unit_of(&c.name);
        let _ = writeln!(
            s,
            "\n{} [{}]  selected order {} (lowest AICc)",
            c.name, unit, c.selected_order
        );
        let _ = writeln!(s, "  {}  monomial °C c0..cn", ORDERS.header());
        for m in &c.models {
            let mono: Vec<String> = m
                .monomial_celsius
                .iter()
                .map(|v| format!("{v:.4e}"))
                .collect();
            let cells = [
                m.order.to_string(),
                format!("{:.3e}", m.scores.residual_std),
                format!("{:.3e}", m.scores.residual_rms),
                opt(m.scores.aicc, 2, false),
                format!("{:.3e}", m.scores.loo_rms),
                opt(m.scores.f_test_p, 2, true),
                format!("{:.4e}", m.sensitivity_per_c),
            ];
            let selected = if m.order == c.selected_order {
                "  ←"
            } else {
                ""
            };
            let _ = writeln!(
                s,
                "  {}  [{}]{selected}",
                ORDERS.row(cells),
                mono.join(", ")
            );
        }
        if let Some(m) = c.selected() {
            if c.name == SCALE_FACTOR_COLUMN && m.value_at != 0.0 {
                let _ = writeln!(
                    s,
                    "  selected: relative sensitivity (dK1/dT)/K1 = {:.4e} /°C",
                    m.sensitivity_per_c / m.value_at
                );
            }
            if unit == "arcmin" {
                let _ = writeln!(
                    s,
                    "  selected: sensitivity {:.4} \"/°C",
                    m.sensitivity_per_c * 60.0
                );
            }
        }
        if c.paper_printed.is_empty() {
            let _ = writeln!(s, "  paper printed: none for this column");
        }
        for p in &c.paper_printed {
            let refit = c.models.iter().find(|m| m.order == p.order);
            let _ = writeln!(
                s,
                "  paper order {}: residual rms {:.3e}, max {:.3e}, reported std {}; refit rms {}; dK/dT {:.4e}",
                p.order,
                p.residual_rms,
                p.residual_max,
                p.reported_std.map_or("—".to_owned(), |v| format!("{v:.2e}")),
                refit.map_or("—".to_owned(), |m| format!("{:.3e}", m.scores.residual_rms)),
                p.sensitivity_per_c
            );
        }
    }
    s
}
