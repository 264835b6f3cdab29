//! The `--simulate` part of the text, the JSON `"simulation"` object and the report's figures
//! (measured vs envelope for ADEV and PSD, before and after, mismatched ranges shaded).

use super::mismatch::{sentence, Comparison, Quantity};
use super::{Scores, Simulation};
use crate::plot::draw::{Figure, Marker, XYAxis, XYCurve, XYFigure};
use plotters::style::RGBColor;
use serde_json::{json, Map, Value};
use std::fmt::Write as _;

fn finite(x: f64) -> Option<f64> {
    x.is_finite().then_some(x)
}

fn side_json(c: &Comparison, s: &Scores) -> Value {
    json!({
        "residual_std_out_of_sample": finite(s.residual_std_out_of_sample),
        "residual_std_fixed_amplitudes": finite(s.residual_std_fixed_amplitudes),
        "adev_outside_fraction": finite(c.adev_outside_fraction),
        "psd_outside_fraction": finite(c.psd_outside_fraction),
        "calibration": {
            "method": "leave one member out: the fraction of its points outside the other members' 5-95 % envelope, mean over the members",
            "member_adev_outside_fraction": finite(c.member_adev_outside_fraction),
            "member_psd_outside_fraction": finite(c.member_psd_outside_fraction),
        },
        "mismatches": c.mismatches.iter().map(|m| {
            let mut o = serde_json::to_value(m).unwrap_or(Value::Null);
            if let Value::Object(map) = &mut o {
                map.insert("sentence".into(), json!(sentence(m)));
                map.insert("factor".into(), json!(finite(m.factor)));
            }
            o
        }).collect::<Vec<_>>(),
        "adev": {
            "tau_s": c.adev.x,
            "measured": c.measured.adev.iter().map(|p| finite(p.1)).collect::<Vec<_>>(),
            "envelope_5": c.adev.low.iter().map(|v| finite(*v)).collect::<Vec<_>>(),
            "envelope_50": c.adev.median.iter().map(|v| finite(*v)).collect::<Vec<_>>(),
            "envelope_95": c.adev.high.iter().map(|v| finite(*v)).collect::<Vec<_>>(),
        },
        "psd": {
            "frequency_hz": c.psd.x,
            "measured": c.measured.psd.iter().map(|v| finite(*v)).collect::<Vec<_>>(),
            "envelope_5": c.psd.low.iter().map(|v| finite(*v)).collect::<Vec<_>>(),
            "envelope_50": c.psd.median.iter().map(|v| finite(*v)).collect::<Vec<_>>(),
            "envelope_95": c.psd.high.iter().map(|v| finite(*v)).collect::<Vec<_>>(),
        },
    })
}

/// The JSON `"simulation"` object.
pub fn json(s: &Simulation) -> Value {
    let mut ex = Map::new();
    for (name, idx) in &s.explained_by {
        ex.insert(name.clone(), json!(idx));
    }
    let rel = |b: f64, a: f64| finite(1.0 - a / b);
    json!({
        "scenario": s.scenario,
        "twin": if s.simulator { "simulator" } else { "stand-in" },
        "provenance": s.provenance,
        "ensemble": s.ensemble,
        "envelope_edge_error": json!({
            "method": "sd of the 5/95 % lines' quantile estimate from the members, as a fraction of the envelope's half-width ln(p95/p50): sqrt(p(1-p)/N)/phi(z)/z at p = 0.95",
            "fraction_of_half_width": finite(super::edge_error(s.ensemble)),
        }),
        "residual": format!("measured − twin prediction, the drift polynomial of order {} removed (offset and linear drift at order 1)", s.drift.order),
        "fitted_out_after_extension": json!({
            "method": "after extension the record's residual and every member's pass through the same least-squares fit: the drift polynomial, each accepted effect's linear columns at its jointly fitted nonlinear parameters and, when the tide comes from the wave-group analysis, a free cosine and sine at each group's main wave",
            "independent_columns": s.fitted_out_independent,
        }),
        "drift": json!({
            "method": "Legendre polynomial of the record's time on [-1, 1], removed from the record and every member alike; order by BIC on the time-domain likelihood (white + flicker + random walk refitted per order, Kalman innovations); coefficients by generalised least squares",
            "order": s.drift.order,
            "neg_loglik_per_order": s.drift.neg_loglik.iter().map(|(k, v)| json!({"order": k, "neg_loglik": finite(*v)})).collect::<Vec<_>>(),
            "bic_price_per_coefficient": finite(s.drift.threshold),
            "coefficients": s.drift_coefficients.iter().enumerate().map(|(k, (v, e))| json!({"legendre": k, "value": finite(*v), "sigma": finite(*e)})).collect::<Vec<_>>(),
            "unit": s.cause.dataset.output_unit,
            "settling": s.settling.as_ref().map(|f| json!({
                "method": "amplitude * exp(-(t - t0)/tau) from the record's first instant, fitted with the drift polynomial of the highest order (generalised least squares, tau by golden-section search on ln tau); kept when the profile likelihood improves by more than ln n, the amplitude is beyond 3 sigma and tau is not at an end of its range; in the twin's drift (in-sample: a property of the instrument's history, not a discovered cause and not forecast), removed with the polynomial from the record and every member, members draw tau and amplitude",
                "in_twin": f.kept().is_some(),
                "tau_s": finite(f.fitted.tau_s.value),
                "tau_s_sigma": finite(f.fitted.tau_s.sigma),
                "amplitude": finite(f.fitted.amplitude.value),
                "amplitude_sigma": finite(f.fitted.amplitude.sigma),
                "neg_loglik_gain": finite(f.gain),
                "price": finite(f.price),
                "refused": f.refused,
            })),
        }),
        "transients": json!({
            "method": format!("first differences beyond {} robust sigma of the extended twin's residual; the noise family is fitted without them, members draw a Poisson number of the record's shapes at random cells", crate::twin::transients::THRESHOLD_SIGMAS),
            "count": s.transients.events.len(),
            "rate_per_day": finite(s.transients.rate_per_day()),
            "sigma_diff": finite(s.transients.sigma_diff),
            "events": s.transients.events.iter().zip(s.transients.peaks()).map(|((a, shape), p)| json!({"t_s": *a as f64 * s.transients.dt_s, "cells": shape.len(), "peak": finite(p)})).collect::<Vec<_>>(),
        }),
        "before": side_json(&s.before, &s.before_scores),
        "after": side_json(&s.after, &s.after_scores),
        "gain": {
            "residual_std_out_of_sample": rel(s.before_scores.residual_std_out_of_sample, s.after_scores.residual_std_out_of_sample),
            "adev_outside_fraction": {"before": finite(s.before.adev_outside_fraction), "after": finite(s.after.adev_outside_fraction)},
            "psd_outside_fraction": {"before": finite(s.before.psd_outside_fraction), "after": finite(s.after.psd_outside_fraction)},
        },
        "noise_family": s.family.as_ref().map(|f| json!({
            "method": "Whittle likelihood on the periodogram of the extended twin's residual (first differences, Hann taper), the drift polynomial and the transients removed",
            "psd": "S(f) = [h0 + h_1/f + h_2/f^2 + h_4/f^4 + q/(1 + (f/fg)^2)] / (1 + (f/fc)^2), one-sided, unit^2/Hz (q, fg: the Gauss-Markov term)",
            "gauss_markov_refused": f.gm_search.refusal(f.resolved(5)),
            "periodogram_bins": f.bins,
            "line_bins_left_out": f.line_bins,
            "components": f.components(&s.cause.dataset.output_unit).iter().map(|c| json!({
                "name": c.name,
                "coefficient": finite(c.coefficient),
                "sigma": finite(c.sigma),
                "level": finite(c.level),
                "level_sigma": finite(c.level_sigma),
                "level_unit": c.level_unit,
                "resolved": c.resolved,
            })).collect::<Vec<_>>(),
        })),
        "explained_by": Value::Object(ex),
        "refused": s.refused.iter().map(|(n, w)| json!({"effect": n, "why": w})).collect::<Vec<_>>(),
        "extended_scenario": s.extended_path.as_ref().map(|p| p.display().to_string()),
        "coherence_channels": s.channels,
        "warnings": s.warnings,
        "timing_s": s.timing_s.iter().map(|(k, v)| json!({"stage": k, "seconds": v})).collect::<Vec<_>>(),
    })
}

/// The text printed first.
pub fn text(s: &Simulation, unit: &str) -> String {
    let mut o = String::new();
    for w in &s.warnings {
        let _ = writeln!(o, "WARNING: {w}");
    }
    let _ = writeln!(
        o,
        "Simulation in the loop: the record against its simulated twin ({} members: the \
         envelope's 5/95 % lines known to ±{:.0} % of its half-width; base scenario: {})",
        s.ensemble,
        100.0 * super::edge_error(s.ensemble),
        s.scenario
    );
    for p in &s.provenance {
        let _ = writeln!(o, "  twin: {p}");
    }
    let _ = writeln!(
        o,
        "  after extension: the record's residual and every member's pass through the same \
         least-squares fit ({} independent columns: the drift polynomial, the accepted effects' \
         linear columns, the tide groups' main waves)",
        s.fitted_out_independent
    );
    let _ = writeln!(
        o,
        "  drift: Legendre polynomial of order {} (BIC on the time-domain likelihood), removed \
         from the record and every member alike; coefficients {}",
        s.drift.order,
        s.drift_coefficients
            .iter()
            .map(|(v, e)| format!("{v:.3e} ± {e:.1e}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    if let Some(f) = &s.settling {
        let c = &f.fitted;
        let what = format!(
            "{:.3e} ± {:.1e} {unit} × exp(−t/τ), τ {:.3} ± {:.3} d from the record's start \
             (−ℓ improves by {:.1}, price {:.1})",
            c.amplitude.value,
            c.amplitude.sigma,
            c.tau_s.value / 86_400.0,
            c.tau_s.sigma / 86_400.0,
            f.gain,
            f.price
        );
        let _ = match &f.refused {
            None => writeln!(
                o,
                "  settling: {what}; in the twin's drift (in-sample: the instrument's history, \
                 not a discovered cause, not forecast), removed with the polynomial from the \
                 record and every member; members draw τ and the amplitude"
            ),
            Some(why) => writeln!(o, "  settling: none in the twin ({why}; best fit {what})"),
        };
    }
    let _ = writeln!(
        o,
        "  transients: {} beyond {} robust σ of the first differences ({:.3} per day), peaks {} \
         {unit}; drawn by the members",
        s.transients.events.len(),
        crate::twin::transients::THRESHOLD_SIGMAS,
        s.transients.rate_per_day(),
        s.transients
            .peaks()
            .iter()
            .map(|p| format!("{p:.2e}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    if let Some(f) = &s.family {
        let _ = writeln!(
            o,
            "  noise family (Whittle likelihood on the extended twin's residual, {} bins; {} bins \
             of narrow lines left out, not noise):",
            f.bins, f.line_bins
        );
        for c in f.components(unit) {
            let _ = writeln!(
                o,
                "    {:<24} {:.3e} ± {:.1e} {}{}",
                c.name,
                c.level,
                c.level_sigma,
                c.level_unit,
                if c.resolved { "" } else { " (not resolved)" }
            );
        }
        if let Some(why) = f.gm_search.refusal(f.resolved(5)) {
            let _ = writeln!(o, "    gauss_markov refused: {why}");
        }
    }
    let _ = writeln!(
        o,
        "\nWhat the simulation gets wrong (measured − twin, against the members' 5–95 % envelope):"
    );
    if s.before.mismatches.is_empty() {
        let _ = writeln!(
            o,
            "  nothing: the measured residual stays inside the envelopes"
        );
    }
    for (i, m) in s.before.mismatches.iter().enumerate() {
        let _ = writeln!(o, "  [{i}] {}", sentence(m));
    }
    let _ = writeln!(
        o,
        "\nCause (catalogue search on the measured − twin residual):"
    );
    if s.explained_by.is_empty() {
        let _ = writeln!(o, "  no effect accepted");
    }
    let mut explained = vec![false; s.before.mismatches.len()];
    for (name, idx) in &s.explained_by {
        for &i in idx {
            explained[i] = true;
        }
        let what = if idx.is_empty() {
            "explains none of the mismatches, alone or with the other accepted effects".to_owned()
        } else {
            format!(
                "explains {}",
                idx.iter()
                    .map(|i| format!("[{i}]"))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        };
        let _ = writeln!(o, "  {name}: {what}");
    }
    let left: Vec<String> = explained
        .iter()
        .enumerate()
        .filter(|(_, e)| !**e)
        .map(|(i, _)| format!("[{i}]"))
        .collect();
    if !left.is_empty() && !s.before.mismatches.is_empty() {
        let _ = writeln!(
            o,
            "  not explained by the accepted effects, alone or together: {}",
            left.join(", ")
        );
    }
    let pct = |b: f64, a: f64| 100.0 * (1.0 - a / b);
    let _ = writeln!(
        o,
        "\nGain (base twin → twin extended by the accepted effects):"
    );
    let _ = writeln!(
        o,
        "  out-of-sample residual std (forward chaining): {:.4e} → {:.4e} {unit} ({:+.1} %)",
        s.before_scores.residual_std_out_of_sample,
        s.after_scores.residual_std_out_of_sample,
        -pct(
            s.before_scores.residual_std_out_of_sample,
            s.after_scores.residual_std_out_of_sample
        )
    );
    let _ = writeln!(
        o,
        "  ADEV points outside the envelope: {:.0} % → {:.0} %; PSD bands outside: {:.0} % → {:.0} %",
        100.0 * s.before.adev_outside_fraction,
        100.0 * s.after.adev_outside_fraction,
        100.0 * s.before.psd_outside_fraction,
        100.0 * s.after.psd_outside_fraction
    );
    let _ = writeln!(
        o,
        "  a member left out lies outside the others' envelope (the envelope's calibration): \
         ADEV {:.0} % → {:.0} %, PSD {:.0} % → {:.0} %",
        100.0 * s.before.member_adev_outside_fraction,
        100.0 * s.after.member_adev_outside_fraction,
        100.0 * s.before.member_psd_outside_fraction,
        100.0 * s.after.member_psd_outside_fraction
    );
    if s.after.mismatches.is_empty() {
        let _ = writeln!(
            o,
            "  after the extension the residual stays inside the envelopes"
        );
    } else {
        let _ = writeln!(o, "  still wrong after the extension (unmodelled):");
        for m in &s.after.mismatches {
            let _ = writeln!(
                o,
                "    {} — likely cause: {}",
                sentence(m),
                m.unmodelled.as_deref().unwrap_or("not named")
            );
        }
    }
    match (&s.extended_path, &s.extended_toml) {
        (Some(p), _) => {
            let _ = writeln!(o, "  extended scenario written to {}", p.display());
        }
        (None, Some(_)) => {
            let _ = writeln!(
                o,
                "  extended scenario: pass --write-scenario FILE to write it"
            );
        }
        (None, None) => {}
    }
    o
}

const MEASURED: RGBColor = RGBColor(200, 30, 30);
const ENVELOPE: RGBColor = RGBColor(40, 90, 180);
const MEDIAN: RGBColor = RGBColor(120, 150, 210);

const MEMBERS: [RGBColor; 2] = [RGBColor(110, 110, 110), RGBColor(170, 170, 170)];

/// A mismatch's label on the figures: its number, factor and what explains it (before) or
/// its likely cause (after, unmodelled).
fn label(s: &Simulation, after: bool, i: usize) -> String {
    let c = if after { &s.after } else { &s.before };
    let m = &c.mismatches[i];
    let why = if after {
        format!(
            "unmodelled: {}",
            m.unmodelled
                .as_deref()
                .unwrap_or("?")
                .split(" (")
                .next()
                .unwrap_or("")
        )
    } else {
        let names: Vec<&str> = s
            .explained_by
            .iter()
            .filter(|(_, idx)| idx.contains(&i))
            .map(|(n, _)| n.as_str())
            .collect();
        if names.is_empty() {
            "not explained".into()
        } else {
            names.join(", ")
        }
    };
    format!("[{i}] ×{:.1} {why}", m.factor)
}

fn figure(c: &Comparison, q: Quantity, title: String, unit: &str, labels: &[String]) -> Figure {
    // PSD and its bands on a cycles/day axis (the mismatch ranges are in cycles/day too).
    let (x, m, e, x_desc, y_desc): (Vec<f64>, Vec<f64>, _, String, String) = match q {
        Quantity::Adev => (
            c.adev.x.clone(),
            c.measured.adev.iter().map(|p| p.1).collect(),
            &c.adev,
            "averaging time τ (s)".into(),
            format!("σ_y(τ) ({unit})"),
        ),
        _ => (
            c.psd.x.iter().map(|f| f * 86_400.0).collect(),
            c.measured.psd.clone(),
            &c.psd,
            "frequency (cycles/day)".into(),
            format!("PSD ({unit}²/Hz)"),
        ),
    };
    let pts = |y: &[f64]| x.iter().copied().zip(y.iter().copied()).collect::<Vec<_>>();
    let member = |v: &super::spectra::Views| -> Vec<f64> {
        match q {
            Quantity::Adev => v.adev.iter().map(|p| p.1).collect(),
            _ => v.psd.clone(),
        }
    };
    let x_markers = c
        .mismatches
        .iter()
        .zip(labels)
        .filter(|(mm, _)| mm.quantity == q)
        .map(|(mm, l)| Marker {
            at: (x[mm.index.0] * x[mm.index.1 - 1]).sqrt(),
            label: l.clone(),
        })
        .collect();
    // A run of points is shaded from half-way to its neighbours on each side (the points are
    // octave τ or log-spaced band centres: geometric midpoints).
    let edge = |i: usize, j: usize| (x[i] * x[j]).sqrt();
    let x_spans = c
        .mismatches
        .iter()
        .filter(|mm| mm.quantity == q)
        .map(|mm| {
            let (a, b) = mm.index;
            let lo = if a > 0 { edge(a - 1, a) } else { x[a] };
            let hi = if b < x.len() {
                edge(b - 1, b)
            } else {
                x[b - 1]
            };
            (lo, hi)
        })
        .collect();
    Figure::XY(XYFigure {
        title,
        x: XYAxis::log(x_desc, x_markers),
        y: XYAxis::log(y_desc, Vec::new()),
        y_floor: None,
        curves: vec![
            XYCurve {
                label: "simulation 5 % / 95 %".into(),
                color: ENVELOPE,
                points: pts(&e.low),
            },
            XYCurve {
                label: String::new(),
                color: ENVELOPE,
                points: pts(&e.high),
            },
            XYCurve {
                label: "simulation median".into(),
                color: MEDIAN,
                points: pts(&e.median),
            },
            XYCurve {
                label: "member 1".into(),
                color: MEMBERS[0],
                points: c.shown.first().map(|v| pts(&member(v))).unwrap_or_default(),
            },
            XYCurve {
                label: "member 2".into(),
                color: MEMBERS[1],
                points: c.shown.get(1).map(|v| pts(&member(v))).unwrap_or_default(),
            },
            XYCurve {
                label: "measured".into(),
                color: MEASURED,
                points: pts(&m),
            },
        ],
        x_spans,
    })
}

/// The report's simulation figures: (file stem, caption, figure).
pub fn figures(s: &Simulation, unit: &str) -> Vec<(&'static str, String, Figure)> {
    let mut v = Vec::new();
    for (stem, q, c, when) in [
        (
            "simulate_adev_before",
            Quantity::Adev,
            &s.before,
            "base twin",
        ),
        (
            "simulate_adev_after",
            Quantity::Adev,
            &s.after,
            "extended twin",
        ),
        ("simulate_psd_before", Quantity::Psd, &s.before, "base twin"),
        (
            "simulate_psd_after",
            Quantity::Psd,
            &s.after,
            "extended twin",
        ),
    ] {
        let what = if q == Quantity::Adev {
            "Allan deviation"
        } else {
            "Welch PSD"
        };
        let caption = format!(
            "{what} of measured − {when} against the ensemble's 5–95 % envelope ({} members), two \
             members beside it; shaded and labelled: the mismatched ranges",
            s.ensemble
        );
        let after = std::ptr::eq(c, &s.after);
        let labels: Vec<String> = (0..c.mismatches.len())
            .map(|i| label(s, after, i))
            .collect();
        v.push((
            stem,
            caption.clone(),
            figure(c, q, format!("{what}: measured vs {when}"), unit, &labels),
        ));
    }
    v
}
