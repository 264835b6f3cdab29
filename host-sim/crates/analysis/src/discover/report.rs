//! Text, JSON and Markdown output of a discovery.
//!
//! The Markdown report links three figures drawn by the plot module ([`crate::plot::draw`]):
//! the residual before/after vs time, its Lomb–Scargle spectrum with the significant lines
//! marked, and its Allan deviation before/after with confidence bands.

use super::eiv::ChannelNoise;
use super::shape::ShapeCheck;
use super::{residual, DiscoverError, Discovery};
use crate::plot::decimate::buckets;
use crate::plot::draw::{
    self, AdevCurve, AdevFigure, Figure, Marker, Panel, TimeFigure, Trace, XYAxis, XYCurve,
    XYFigure,
};
use crate::plot::Format;
use plotters::style::RGBColor;
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
            let (p0, sig0) = params_json(&a.params_at_acceptance);
            let mut o = json!({
                "name": a.effect.name(),
                "parameters": p,
                "uncertainties": sig,
                "parameters_at_acceptance": p0,
                "uncertainties_at_acceptance": sig0,
                "residual_std_before": a.std_before,
                "residual_std_after": a.std_after,
                "residual_std_out_of_sample_before": a.cv_before.raw,
                "residual_std_out_of_sample_after": a.cv_after.raw,
                "prediction_z_out_of_sample_before": a.cv_before.prediction_z,
                "prediction_z_out_of_sample_after": a.cv_after.prediction_z,
                "gain_out_of_sample": a.gain_out_of_sample(),
                "residual_std_forward_before": a.forward_before.raw,
                "residual_std_forward_after": a.forward_after.raw,
                "prediction_z_forward_before": a.forward_before.prediction_z,
                "prediction_z_forward_after": a.forward_after.prediction_z,
                "gain_forward": a.gain_forward(),
                "delta_bic": a.delta_bic,
                "found_at_full_rate": a.full_rate,
            });
            if let Some(c) = a.effect.channel() {
                o["channel"] = json!(c);
                o["channel_unit"] = json!(d.dataset.channel_unit(c));
            }
            if let Some(f) = a.effect.drift_family() {
                o["drift_family"] = json!(f);
            }
            // "ambiguous: A or B": each other cause, its parameters and what would separate them.
            if !a.ambiguous_with.is_empty() {
                o["ambiguous_with"] = json!(a.ambiguous_with);
            }
            // The Preisach distribution of play widths the hysteresis column is made of.
            // The loop's area: the coefficient (the branch half-width) × the column's loop area.
            if a.effect == super::effects::Effect::ThermalHysteresis {
                if let Some(p) = &s.hysteresis {
                    o["preisach"] = json!(p);
                    let area = loop_area(a, p);
                    o["preisach"]["loop_area"] = json!(area);
                    let shown = record_loop_area(a, p);
                    o["preisach"]["record_loop_area"] = json!(shown);
                    if let Some(u) = u {
                        o["preisach"]["loop_area_g"] = json!(area / u);
                        o["preisach"]["record_loop_area_g"] = json!(shown / u);
                    }
                }
            }
            o
        })
        .collect();
    let g = |x: f64| u.map(|u| x / u);
    let mut warnings = d.warnings.clone();
    warnings.extend(s.warnings.iter().cloned());
    json!({
        "warnings": warnings,
        "output": d.dataset.output_name,
        "output_unit": d.dataset.output_unit,
        "output_unit_per_g": u,
        "points": d.dataset.len(),
        "notes": d.dataset.notes,
        "baseline": {
            "description": d.baseline_description,
            "residual_std": s.baseline_std,
            "residual_std_out_of_sample": s.baseline_cv.raw,
            "prediction_z_out_of_sample": s.baseline_cv.prediction_z,
            "residual_std_forward": s.baseline_forward.raw,
            "prediction_z_forward": s.baseline_forward.prediction_z,
            "residual_std_g": g(s.baseline_std),
            "noise": noise_json(&s.baseline_noise, d.dataset.dt_s),
        },
        "not_candidates": d.not_candidates.iter().map(|(n, w)| json!({"name": n, "why": w})).collect::<Vec<_>>(),
        "effects": effects,
        "channel_noise": d.channel_noise,
        "joint_fit": s.joint.as_ref().map(|j| json!({
            "coefficients": j.names,
            "covariance": j.covariance,
            "note": "parameters of `effects` come from this fit; the covariance is of the effects' linear coefficients (output units) and, when the tide is named, of its instrument delay (`<i>:tidal_gravity:delay_s`, seconds, refitted jointly), conditional on the other nonlinear parameters, whose uncertainties come from the likelihood profile",
        })),
        "refused": s.refused.iter().map(|(n, w)| json!({"name": n, "why": w})).collect::<Vec<_>>(),
        "forward_splits": super::select::FORWARD_SPLITS,
        "shape_checks": d.shape_checks,
        "final": {
            "residual_std": s.final_std,
            "residual_std_out_of_sample": s.final_cv.raw,
            "prediction_z_out_of_sample": s.final_cv.prediction_z,
            "residual_std_forward": s.final_forward.raw,
            "prediction_z_forward": s.final_forward.prediction_z,
            "gain_forward": 1.0 - s.final_forward.raw / s.baseline_forward.raw,
            "residual_std_g": g(s.final_std),
            "noise": noise_json(&s.final_noise, d.dataset.dt_s),
        },
        "analysis": {
            "lines_before": d.spectrum_before.lines.iter().take(8).collect::<Vec<_>>(),
            "lines_after": d.spectrum_after.lines.iter().take(8).collect::<Vec<_>>(),
            "correlations": d.correlations,
            "trend": d.trend,
            "adev_before": d.adev_before,
            "adev_after": d.adev_after,
        },
        "tidal_analysis": super::tidal::json_of(&d.tidal),
        "full_rate": super::fullrate::json_of(&d.full_rate),
        "unexplained_structure": d.unexplained,
        "calibration_table": d.table_check.as_ref().map(super::table_error::json_of),
    })
}

/// The noise model as reported: `white` the standard deviation of one point at the record's
/// spacing `dt_s`, `flicker` the flat Allan-deviation floor of the flicker part, `random_walk`
/// the diffusion in unit/√s; all in the output unit.
fn noise_json(f: &super::noise::NoiseFit, dt_s: f64) -> Value {
    json!({
        "white": f.model.white_var.sqrt(),
        "flicker": f.model.flicker_floor(),
        "random_walk": f.model.rw_per_s.sqrt(),
        "flicker_slope": f.model.flicker_slope(),
        "flicker_shortest_s": f.model.flicker.first().map(|c| c.0),
        "method": f.method,
        "spacing_s": dt_s,
        "neg2_log_likelihood": finite(f.neg2_loglik),
        "likelihood_evaluations": f.evaluations,
        "failure": f.failure,
    })
}

fn noise_text(f: &super::noise::NoiseFit, unit: &str) -> String {
    format!(
        "white {:.3e} {unit} per point, flicker {:.3e} {unit} (slope {:+.2}), random walk {:.3e} {unit}/√s ({})",
        f.model.white_var.sqrt(),
        f.model.flicker_floor(),
        f.model.flicker_slope(),
        f.model.rw_per_s.sqrt(),
        f.method
    )
}

const SECONDS_PER_DAY: f64 = 86_400.0;

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
    for w in d.warnings.iter().chain(&s.warnings) {
        let _ = writeln!(o, "WARNING: {w}");
    }
    let _ = writeln!(o, "baseline: {}", d.baseline_description);
    let _ = writeln!(
        o,
        "  residual std {:.6e} {unit}, out of sample {:.6e} {unit}",
        s.baseline_std, s.baseline_cv.raw
    );
    let _ = writeln!(o, "  noise: {}", noise_text(&s.baseline_noise, unit));
    for c in &d.channel_noise {
        let ChannelNoise {
            channel,
            noise,
            unit: channel_unit,
            std,
            smoothing_s,
            ..
        } = c;
        let used = match (c.resolved, c.smoothed) {
            (true, true) => {
                format!("the model uses its smoothed state (zero-phase, width {smoothing_s:.0} s)")
            }
            (true, false) => {
                format!("smoother of width {smoothing_s:.0} s fitted, the model uses the reading")
            }
            _ => "not resolved (the true value moves more than that from one point to the next, \
                  so no smoother can separate it): used as read"
                .to_owned(),
        };
        let _ = writeln!(
            o,
            "  channel_noise: {channel} reads with {noise:.3e} {channel_unit} white noise per point \
             (channel std {std:.3e}); {used}"
        );
    }
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
            "  {}. {}{}{}: {}\n     ΔBIC {:.1}; std {:.4e} → {:.4e} {unit}; out of sample {:.4e} → {:.4e}; gain {:.1} %; forward gain {:.1} %",
            i + 1,
            a.effect.name(),
            a.effect
                .channel()
                .map(|c| format!(" ({c}, {})", d.dataset.channel_unit(c)))
                .or_else(|| a.effect.drift_family().map(|f| format!(" (drift, {f})")))
                .unwrap_or_default(),
            if a.full_rate {
                " [found on the full-rate rows: τ and ΔBIC from there, coefficient from the \
                 binned joint fit]"
            } else {
                ""
            },
            ps.join(", "),
            a.delta_bic,
            a.std_before,
            a.std_after,
            a.cv_before.raw,
            a.cv_after.raw,
            100.0 * a.gain_out_of_sample(),
            100.0 * a.gain_forward()
        );
        for amb in &a.ambiguous_with {
            let ps: Vec<String> = amb
                .other_parameters
                .iter()
                .map(|(k, p)| format!("{k} = {:.4e}", p.value))
                .collect();
            let _ = writeln!(
                o,
                "     ambiguous: {} or {} (ΔBIC {:.1} vs {:.1}, fitted shapes overlap {:.2}); {} \
                 would be: {}; to separate them: {}",
                a.effect.name(),
                amb.other,
                a.delta_bic,
                amb.other_delta_bic,
                amb.overlap,
                amb.other,
                ps.join(", "),
                amb.separates
            );
        }
        if a.effect == super::effects::Effect::ThermalHysteresis {
            if let Some(p) = &s.hysteresis {
                let w: Vec<String> = p
                    .widths_c
                    .iter()
                    .zip(&p.weights)
                    .map(|(r, w)| format!("{r:.4} °C × {:.0} %", 100.0 * w))
                    .collect();
                let _ = writeln!(o, "     Preisach play half-widths: {}", w.join(", "));
                if !p.relays_c.is_empty() {
                    let r: Vec<String> = p
                        .relays_c
                        .iter()
                        .zip(&p.relay_weights)
                        .map(|(r, w)| format!("[{:.3}, {:.3}] °C × {:.0} %", r[0], r[1], 100.0 * w))
                        .collect();
                    let _ = writeln!(o, "     Preisach relays [β, α]: {}", r.join(", "));
                }
                let _ = writeln!(
                    o,
                    "     loop area ∫(heating − cooling) dT over the record's 1–99 % range: {:.4e} {}·°C",
                    loop_area(a, p),
                    d.dataset.output_unit
                );
                if p.lag_s > 0.0 {
                    let _ = writeln!(
                        o,
                        "     the loop's output reaches the sensor through a first-order lag of \
                         {:.0} s (a switching time or a thermal path; the area above is the \
                         rate-independent loop's)",
                        p.lag_s
                    );
                }
                let _ = writeln!(
                    o,
                    "     loop area as the record shows it (heating − cooling over its ramps): \
                     {:.4e} {}·°C",
                    record_loop_area(a, p),
                    d.dataset.output_unit
                );
            }
        }
    }
    for (n, why) in &s.refused {
        let _ = writeln!(o, "  refused: {n}: {why}");
    }
    for c in &d.shape_checks {
        let ShapeCheck {
            effect,
            second_theta,
            delta_chi2,
            threshold,
            ..
        } = c;
        let verdict = if c.poor {
            " — POOR FIT: the catalogue shape does not describe the data; the name is the closest cause"
        } else {
            ": shape adequate"
        };
        let _ = writeln!(
            o,
            "  shape check {effect}: two of its kind in its place (the other at {second_theta:.5e}) \
             improve χ² by {delta_chi2:.1} (charged {threshold:.1}){verdict}"
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
    let _ = writeln!(o, "  noise: {}", noise_text(&s.final_noise, unit));
    for ((t, a), (_, b)) in d.adev_before.iter().zip(&d.adev_after).step_by(3) {
        let _ = writeln!(o, "  ADEV({t:.0} s): {a:.3e} → {b:.3e} {unit}");
    }
    o.push_str(&super::unexplained::text_of(&d.unexplained, unit));
    o.push_str(&super::fullrate::text_of(&d.full_rate, unit));
    if let Some(c) = &d.table_check {
        o.push_str(&super::table_error::text_of(c, unit));
    }
    o.push_str(&super::tidal::text_of(&d.tidal));
    o
}

/// File stems of the report's figures, in the order they appear in `report.md`.
pub const FIGURES: [&str; 3] = ["residual_time", "residual_spectrum", "residual_adev"];

const BEFORE: RGBColor = RGBColor(200, 40, 40);
const AFTER: RGBColor = RGBColor(25, 90, 200);
/// False-alarm probability of the spectrum's significance line and of the marked lines.
const FAP_MARKED: f64 = 0.01;
/// At most this many significant lines are marked (more would hide the spectrum).
const MAX_MARKED_LINES: usize = 6;
/// The spectrum's y axis spans at most this many decades under its peak: the periodogram's
/// troughs reach 1e-8 and would squeeze the lines into the top of the figure.
const SPECTRUM_DECADES: f64 = 5.0;

/// A display scale for a unit: SI prefix for `g` and volts (`V`, or `v` as the log's column
/// suffix gives it), a power of ten otherwise.
fn display_scale(unit: &str, typical: f64) -> (f64, String) {
    if !(typical.is_finite() && typical > 0.0) {
        return (1.0, unit.to_owned());
    }
    let e3 = (typical.log10() / 3.0).floor() as i32 * 3;
    if e3 == 0 {
        return (1.0, unit.to_owned());
    }
    let prefix = match (unit, e3) {
        ("g" | "V" | "v", -3) => Some("m"),
        ("g" | "V" | "v", -6) => Some("µ"),
        ("g" | "V" | "v", -9) => Some("n"),
        _ => None,
    };
    let factor = 10f64.powi(-e3);
    match prefix {
        Some(p) => (factor, format!("{p}{unit}")),
        None => (factor, format!("1e{e3} {unit}")),
    }
}

/// Residual vs time, baseline (top) and final (bottom), same y range; a NaN is inserted at every
/// segment start so gaps are not bridged.
fn residual_time_figure(d: &Discovery) -> Figure {
    let ds = &d.dataset;
    let s = &d.selection;
    let t0 = ds.t_s.first().copied().unwrap_or(0.0);
    let span = ds.t_s.last().copied().unwrap_or(t0) - t0;
    let (t_unit, t_div) = if span <= 2.0 * SECONDS_PER_DAY {
        ("h", 3600.0)
    } else {
        ("days", SECONDS_PER_DAY)
    };
    let (k, unit) = display_scale(&ds.output_unit, s.baseline_std);
    let series = |r: &[f64]| {
        let (mut x, mut y) = (Vec::with_capacity(r.len()), Vec::with_capacity(r.len()));
        for (i, (&t, &v)) in ds.t_s.iter().zip(r).enumerate() {
            if i > 0 && ds.segment_start.get(i).copied().unwrap_or(false) {
                x.push(f64::NAN);
                y.push(f64::NAN);
            }
            x.push((t - t0) / t_div);
            y.push(v * k);
        }
        buckets(&x, &y, draw::WIDTH_PX as usize)
    };
    let n_eff = s.accepted.len();
    let panel = |label: String, r: &[f64], color| Panel {
        y_desc: format!("residual ({unit})"),
        traces: vec![Trace {
            label,
            runs: series(r),
            color,
        }],
    };
    Figure::Time(TimeFigure {
        title: format!("{}: residual before / after discovery", ds.output_name),
        x_desc: format!("time since first point ({t_unit})"),
        x_range: (0.0, if span > 0.0 { span / t_div } else { 1.0 }),
        panels: vec![
            panel(
                format!(
                    "baseline residual: σ = {:.3e} {}",
                    s.baseline_std, ds.output_unit
                ),
                &s.baseline_residual,
                BEFORE,
            ),
            panel(
                format!(
                    "final residual ({n_eff} effect(s) added): σ = {:.3e} {}",
                    s.final_std, ds.output_unit
                ),
                &s.final_residual,
                AFTER,
            ),
        ],
        shared_y: true,
    })
}

/// Readable period: s, h or days.
fn period_label(period_s: f64) -> String {
    if period_s < 3600.0 {
        format!("{period_s:.0} s")
    } else if period_s < 3.0 * SECONDS_PER_DAY {
        format!("{:.2} h", period_s / 3600.0)
    } else {
        format!("{:.1} d", period_s / SECONDS_PER_DAY)
    }
}

/// Lomb–Scargle power of the baseline and final residuals against frequency, log-log, with the
/// 1 % false-alarm level and the significant lines of the baseline residual marked.
fn residual_spectrum_figure(d: &Discovery) -> Figure {
    let curve = |label: &str, sp: &residual::Spectrum, color| XYCurve {
        label: label.to_owned(),
        color,
        points: sp
            .frequency_hz
            .iter()
            .copied()
            .zip(sp.power.iter().copied())
            .collect(),
    };
    let peak = d
        .spectrum_before
        .power
        .iter()
        .chain(&d.spectrum_after.power)
        .copied()
        .filter(|p| p.is_finite())
        .fold(0.0, f64::max);
    // The power z whose false-alarm probability over the M independent frequencies is
    // FAP_MARKED, inverting 1 − (1 − e^{−z})^M (residual.rs). The spectrum runs from 1/span to
    // f_max, so M = span · f_max = last / first frequency.
    let fap_level = match (
        d.spectrum_before.frequency_hz.first(),
        d.spectrum_before.frequency_hz.last(),
    ) {
        (Some(&f0), Some(&f1)) if f0 > 0.0 && f1 > f0 => {
            let m = f1 / f0;
            let single = -((1.0 - FAP_MARKED).ln() / m).exp_m1();
            vec![Marker {
                at: -single.ln(),
                label: format!("false-alarm probability {:.0} %", 100.0 * FAP_MARKED),
            }]
        }
        _ => Vec::new(),
    };
    let x_markers = d
        .spectrum_before
        .lines
        .iter()
        .filter(|l| l.fap < FAP_MARKED)
        .take(MAX_MARKED_LINES)
        .map(|l| Marker {
            at: l.frequency_hz,
            label: period_label(l.period_s),
        })
        .collect();
    Figure::XY(XYFigure {
        title: format!(
            "{}: Lomb–Scargle spectrum of the residual (marked: lines with FAP < {:.0} %)",
            d.dataset.output_name,
            100.0 * FAP_MARKED
        ),
        x: XYAxis::log("frequency (Hz)".into(), x_markers),
        y: XYAxis::log("normalised power".into(), fap_level),
        y_floor: (peak > 0.0).then(|| peak * 10f64.powf(-SPECTRUM_DECADES)),
        curves: vec![
            curve("baseline residual", &d.spectrum_before, BEFORE),
            curve("final residual", &d.spectrum_after, AFTER),
        ],
        x_spans: Vec::new(),
    })
}

/// OADEV of the baseline and final residuals with their 68 % confidence bands.
fn residual_adev_figure(d: &Discovery) -> Figure {
    let ds = &d.dataset;
    let curve = |label: &str, r: &[f64], color| AdevCurve {
        label: label.to_owned(),
        color,
        points: residual::adev_points(ds, r)
            .iter()
            .filter(|p| p.dev.is_finite() && p.dev > 0.0 && p.ci_high.is_finite())
            .map(|p| (p.tau_s, p.dev, p.ci_low, p.ci_high))
            .collect(),
    };
    Figure::Adev(AdevFigure {
        title: format!(
            "{}: Allan deviation of the residual, shaded: 68 % confidence interval",
            ds.output_name
        ),
        y_desc: format!("σ_y(τ) ({})", ds.output_unit),
        curves: vec![
            curve("baseline residual", &d.selection.baseline_residual, BEFORE),
            curve("final residual", &d.selection.final_residual, AFTER),
        ],
    })
}

/// The report's figures, as plain data, with their file stems ([`FIGURES`]) and captions.
pub fn figures(d: &Discovery) -> Vec<(&'static str, &'static str, Figure)> {
    vec![
        (
            FIGURES[0],
            "Residual before (baseline) and after (accepted effects) vs time",
            residual_time_figure(d),
        ),
        (
            FIGURES[1],
            "Lomb–Scargle spectrum of the residual; vertical lines: significant lines of the baseline residual",
            residual_spectrum_figure(d),
        ),
        (
            FIGURES[2],
            "Allan deviation of the residual before and after, 68 % confidence bands",
            residual_adev_figure(d),
        ),
    ]
}

/// Writes `report.md` and its figures (`<stem>.png` or `.svg`) into `dir`.
///
/// A figure that cannot be drawn (e.g. a record too short for any Allan deviation point) is left
/// out with a note in the report instead of failing the whole report.
pub fn write_report(d: &Discovery, dir: &Path, format: Format) -> Result<(), DiscoverError> {
    std::fs::create_dir_all(dir).map_err(|source| DiscoverError::CreateDir {
        dir: dir.to_path_buf(),
        source,
    })?;
    let mut md = String::new();
    let _ = writeln!(md, "# Model discovery report\n\n```text\n{}```\n", text(d));
    let _ = writeln!(md, "## Figures\n");
    for (stem, caption, fig) in figures(d) {
        let name = format!("{stem}.{}", format.ext());
        match draw::render(&fig, &dir.join(&name), format) {
            Ok(()) => {
                let _ = writeln!(md, "### {caption}\n\n![{caption}]({name})\n");
            }
            Err(e) => {
                let _ = writeln!(md, "### {caption}\n\nnot drawn: {e}\n");
            }
        }
    }
    crate::log::outputs::write_file(&dir.join("report.md"), md.as_bytes())?;
    Ok(())
}

/// The accepted loop's area ∫(heating − cooling) dT, output unit·°C: its coefficient (the
/// branch half-width) × the column's own loop area (`hysteresis::Preisach::loop_area_c`).
fn loop_area(a: &super::select::Accepted, p: &super::hysteresis::Preisach) -> f64 {
    half_width(a) * p.loop_area_c
}

/// The accepted loop's area as the record shows it, output unit·°C: its coefficient × the
/// column's record loop area (`hysteresis::Preisach::record_loop_area_c`, the lag included).
fn record_loop_area(a: &super::select::Accepted, p: &super::hysteresis::Preisach) -> f64 {
    half_width(a) * p.record_loop_area_c
}

/// The accepted loop's coefficient, the branch half-width (NaN when absent).
fn half_width(a: &super::select::Accepted) -> f64 {
    a.params
        .iter()
        .find(|(k, _)| k == "half_width")
        .map_or(f64::NAN, |(_, v)| v.value)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn display_scale_uses_si_prefixes_for_g_and_volts_and_powers_of_ten_otherwise() {
        assert_eq!(display_scale("g", 5e-6), (1e6, "µg".to_owned()));
        assert_eq!(display_scale("v", 2e-3), (1e3, "mv".to_owned()));
        assert_eq!(display_scale("nm/s²", 3e-6), (1e6, "1e-6 nm/s²".to_owned()));
        assert_eq!(display_scale("g", 2.0), (1.0, "g".to_owned()));
        assert_eq!(display_scale("g", 0.5), (1e3, "mg".to_owned()));
        assert_eq!(display_scale("g", 0.0), (1.0, "g".to_owned()));
    }

    #[test]
    fn period_labels_switch_from_seconds_to_hours_to_days() {
        assert_eq!(period_label(600.0), "600 s");
        assert_eq!(period_label(12.42 * 3600.0), "12.42 h");
        assert_eq!(period_label(14.0 * 86_400.0), "14.0 d");
    }
}
