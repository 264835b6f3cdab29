//! Text, JSON and Markdown output of a discovery.

use super::Discovery;
use serde_json::{json, Map, Value};
use std::fmt::Write as _;
use std::path::Path;

fn params_json(p: &[(String, super::effects::Param)]) -> (Value, Value) {
    let mut v = Map::new();
    let mut s = Map::new();
    for (k, x) in p {
        v.insert(k.clone(), json!(finite(x.value)));
        s.insert(k.clone(), json!(finite(x.sigma)));
    }
    (Value::Object(v), Value::Object(s))
}

fn finite(x: f64) -> Option<f64> {
    x.is_finite().then_some(x)
}

/// The `--json` object.
pub fn json(d: &Discovery) -> Value {
    let s = &d.selection;
    let u = d.dataset.unit_per_g;
    let effects: Vec<Value> = s
        .accepted
        .iter()
        .map(|a| {
            let (p, sig) = params_json(&a.params);
            let mut o = json!({
                "name": a.effect.name(),
                "parameters": p,
                "uncertainties": sig,
                "residual_std_before": a.std_before,
                "residual_std_after": a.std_after,
                "residual_std_out_of_sample_before": a.cv_before.raw,
                "residual_std_out_of_sample_after": a.cv_after.raw,
                "one_step_std_out_of_sample_before": a.cv_before.whitened,
                "one_step_std_out_of_sample_after": a.cv_after.whitened,
                "gain_out_of_sample": a.gain_out_of_sample(),
                "delta_bic": a.delta_bic,
            });
            if let Some(c) = a.effect.channel() {
                o["channel"] = json!(c);
            }
            o
        })
        .collect();
    let g = |x: f64| u.map(|u| x / u);
    json!({
        "output": d.dataset.output_name,
        "output_unit": d.dataset.output_unit,
        "output_unit_per_g": u,
        "points": d.dataset.len(),
        "notes": d.dataset.notes,
        "baseline": {
            "description": d.baseline_description,
            "residual_std": s.baseline_std,
            "residual_std_out_of_sample": s.baseline_cv.raw,
            "one_step_std_out_of_sample": s.baseline_cv.whitened,
            "residual_std_g": g(s.baseline_std),
        },
        "not_candidates": d.not_candidates.iter().map(|(n, w)| json!({"name": n, "why": w})).collect::<Vec<_>>(),
        "effects": effects,
        "final": {
            "residual_std": s.final_std,
            "residual_std_out_of_sample": s.final_cv.raw,
            "one_step_std_out_of_sample": s.final_cv.whitened,
            "residual_std_g": g(s.final_std),
        },
        "analysis": {
            "lines_before": d.spectrum_before.lines.iter().take(8).collect::<Vec<_>>(),
            "lines_after": d.spectrum_after.lines.iter().take(8).collect::<Vec<_>>(),
            "correlations": d.correlations,
            "trend": d.trend,
            "adev_before": d.adev_before,
            "adev_after": d.adev_after,
        }
    })
}

/// Human-readable summary.
pub fn text(d: &Discovery) -> String {
    let s = &d.selection;
    let unit = &d.dataset.output_unit;
    let mut o = String::new();
    let _ = writeln!(
        o,
        "record: {} ({} points)",
        d.dataset.output_name,
        d.dataset.len()
    );
    for n in &d.dataset.notes {
        let _ = writeln!(o, "  {n}");
    }
    let _ = writeln!(o, "baseline: {}", d.baseline_description);
    let _ = writeln!(
        o,
        "  residual std {:.6e} {unit}, out of sample {:.6e} {unit}",
        s.baseline_std, s.baseline_cv.raw
    );
    let _ = writeln!(o, "what the baseline gets wrong:");
    let _ = writeln!(
        o,
        "  trend {:.4e} {unit}/day, best step {:.4e} {unit} at {:.0} s",
        d.trend.slope_per_day, d.trend.step_size, d.trend.step_time_s
    );
    for l in d
        .spectrum_before
        .lines
        .iter()
        .filter(|l| l.fap < 0.01)
        .take(6)
    {
        let _ = writeln!(
            o,
            "  line at {:.1} s ({:.3} h): amplitude {:.3e}, FAP {:.1e}",
            l.period_s,
            l.period_s / 3600.0,
            l.amplitude,
            l.fap
        );
    }
    let mut cs = d.correlations.clone();
    cs.sort_by(|a, b| b.r.abs().total_cmp(&a.r.abs()));
    for c in cs.iter().take(5) {
        let _ = writeln!(o, "  correlation with {}: r = {:+.3}", c.with, c.r);
    }
    for (n, w) in &d.not_candidates {
        let _ = writeln!(o, "  not a candidate: {n} ({w})");
    }
    let _ = writeln!(o, "accepted effects:");
    if s.accepted.is_empty() {
        let _ = writeln!(o, "  none");
    }
    for (i, a) in s.accepted.iter().enumerate() {
        let ps: Vec<String> = a
            .params
            .iter()
            .map(|(k, p)| format!("{k} = {:.5e} ± {:.2e}", p.value, p.sigma))
            .collect();
        let _ = writeln!(
            o,
            "  {}. {}{}: {}\n     ΔBIC {:.1}; std {:.4e} → {:.4e} {unit}; out of sample {:.4e} → {:.4e}; gain {:.1} %",
            i + 1,
            a.effect.name(),
            a.effect.channel().map(|c| format!(" ({c})")).unwrap_or_default(),
            ps.join(", "),
            a.delta_bic,
            a.std_before,
            a.std_after,
            a.cv_before.raw,
            a.cv_after.raw,
            100.0 * a.gain_out_of_sample()
        );
    }
    let rest: Vec<String> = s
        .last_round
        .iter()
        .map(|(n, b)| format!("{n} {b:.1}"))
        .collect();
    let _ = writeln!(
        o,
        "  last round, ΔBIC of the candidates left: {}",
        rest.join(", ")
    );
    let _ = writeln!(
        o,
        "final: residual std {:.6e} {unit}, out of sample {:.6e} {unit}",
        s.final_std, s.final_cv.raw
    );
    for ((t, a), (_, b)) in d.adev_before.iter().zip(&d.adev_after).step_by(3) {
        let _ = writeln!(o, "  ADEV({t:.0} s): {a:.3e} → {b:.3e} {unit}");
    }
    o
}

/// Writes `report.md` (and figures) into `dir`.
pub fn write_report(d: &Discovery, dir: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir)?;
    let mut md = String::new();
    let _ = writeln!(md, "# Model discovery report\n\n```text\n{}```\n", text(d));
    std::fs::write(dir.join("report.md"), md)?;
    Ok(())
}
