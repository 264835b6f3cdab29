//! Structure no cause explains.
//!
//! After the selection, the final residual should be the final noise model (white + flicker +
//! random walk) and nothing else. Two tests say where it is not, with the τ range or frequency
//! and the size, instead of forcing a name from the catalogue:
//!
//! - **Allan deviation above the noise model's band.** At each octave τ, the residual's overlapping
//!   Allan variance times its equivalent degrees of freedom over the model's Allan variance is
//!   χ² with those degrees; a τ is above the band when that exceeds the χ² quantile of
//!   1 − [`ADEV_ALPHA`] and the deviation is at least [`ADEV_MIN_RATIO`] × the model's, from
//!   [`ADEV_MIN_TAU_SPACINGS`] spacings on. Neighbouring τ above the band make one range; a range is reported with
//!   its largest ratio and the excess deviation √(σ²_A − σ²_model) there.
//! - **A spectral line.** The residual whitened by the noise model (its Kalman innovations) is
//!   white if the model holds; its Lomb–Scargle periodogram's strongest peak with a false-alarm
//!   probability below [`LINE_FAP`] and at least two cycles in the record is a line, reported
//!   with its period and the amplitude of
//!   the sinusoid fitted to the (unwhitened) residual at that frequency.

use super::import::Dataset;
use super::noise::{NoiseModel, Whitener};
use super::residual;

/// One-sided probability of the Allan band at each τ.
pub const ADEV_ALPHA: f64 = 1e-3;
/// False-alarm probability below which a line of the whitened residual is reported.
pub const LINE_FAP: f64 = 1e-3;
/// The Allan test starts at this many spacings: the noise model's flicker comb begins at a
/// correlation time of at least one spacing, so over the first two octaves its shape is not the
/// 1/f flicker's (measured: ×1.07–1.19 at 60–120 s on 60 s logs with nothing hidden).
pub const ADEV_MIN_TAU_SPACINGS: f64 = 4.0;
/// And a τ counts only when the deviation is at least this factor above the model's: with
/// thousands of degrees of freedom at short τ, the χ² test alone flags a few percent of
/// misfit of the noise model's shape, which is not structure.
pub const ADEV_MIN_RATIO: f64 = 1.1;

/// What remains.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Structure {
    /// The Allan deviation is above the noise model's band from `tau_from_s` to `tau_to_s`.
    AllanExcess {
        /// First τ above the band, s.
        tau_from_s: f64,
        /// Last τ above the band, s.
        tau_to_s: f64,
        /// τ of the largest ratio, s.
        tau_peak_s: f64,
        /// Measured / model Allan deviation there.
        ratio: f64,
        /// √(σ²_A − σ²_model) there, output unit.
        excess_deviation: f64,
    },
    /// A line of the whitened residual.
    Line {
        /// Frequency, Hz.
        frequency_hz: f64,
        /// Period, s.
        period_s: f64,
        /// Amplitude of the sinusoid fitted to the residual, output unit.
        amplitude: f64,
        /// False-alarm probability (whitened residual).
        fap: f64,
    },
}

/// The Allan ranges above the band and the strongest line of the whitened residual.
pub fn find(ds: &Dataset, resid: &[f64], noise: &NoiseModel) -> Vec<Structure> {
    let mut out = Vec::new();
    let pts = residual::adev_points(ds, resid);
    let mut run: Vec<(f64, f64, f64)> = Vec::new();
    let flush = |run: &mut Vec<(f64, f64, f64)>, out: &mut Vec<Structure>| {
        if let Some(&(tp, ratio, excess)) = run.iter().max_by(|a, b| a.1.total_cmp(&b.1)) {
            out.push(Structure::AllanExcess {
                tau_from_s: run[0].0,
                tau_to_s: run[run.len() - 1].0,
                tau_peak_s: tp,
                ratio,
                excess_deviation: excess,
            });
        }
        run.clear();
    };
    for p in &pts {
        let model = noise.avar(p.tau_s);
        let above = p.edf >= 1.0
            && model > 0.0
            && p.tau_s >= ADEV_MIN_TAU_SPACINGS * ds.dt_s
            && p.dev >= ADEV_MIN_RATIO * model.sqrt()
            && p.dev * p.dev * p.edf / model
                > crate::numerics::distributions::chi2_quantile(1.0 - ADEV_ALPHA, p.edf);
        if above {
            run.push((
                p.tau_s,
                p.dev / model.sqrt(),
                (p.dev * p.dev - model).max(0.0).sqrt(),
            ));
        } else {
            flush(&mut run, &mut out);
        }
    }
    flush(&mut run, &mut out);
    // The line test on the innovations.
    let idx: Vec<usize> = (0..resid.len()).collect();
    let w = Whitener::new(noise, &ds.t_s, idx);
    let white = w.whiten(resid);
    if white.len() == ds.t_s.len() {
        let spec = residual::periodogram(&ds.t_s, &white, 4096);
        // At least two cycles in the record (as the catalogue's `periodic`): a "line" of one
        // cycle is a slow drift's share of the lowest frequency, not a period.
        let span = ds.span_s();
        if let Some(l) = spec
            .lines
            .iter()
            .find(|l| l.fap < LINE_FAP && l.period_s <= span / 2.0)
        {
            out.push(Structure::Line {
                frequency_hz: l.frequency_hz,
                period_s: l.period_s,
                amplitude: sinusoid_amplitude(&ds.t_s, resid, l.frequency_hz),
                fap: l.fap,
            });
        }
    }
    out
}

/// Amplitude of the least-squares sinusoid (with an offset) at `f_hz`.
fn sinusoid_amplitude(t: &[f64], y: &[f64], f_hz: f64) -> f64 {
    let w = 2.0 * std::f64::consts::PI * f_hz;
    let rows: Vec<Vec<f64>> = t
        .iter()
        .map(|&x| vec![1.0, (w * x).sin(), (w * x).cos()])
        .collect();
    crate::numerics::linalg::least_squares(&rows, y)
        .map_or(f64::NAN, |ls| ls.coeffs[1].hypot(ls.coeffs[2]))
}

/// The text report's section.
pub fn text_of(s: &[Structure], unit: &str) -> String {
    use std::fmt::Write as _;
    let mut o = String::from("unexplained structure (no cause in the model explains it):\n");
    if s.is_empty() {
        o.push_str("  none: the final residual is within its noise model\n");
    }
    for x in s {
        let _ = match x {
            Structure::AllanExcess {
                tau_from_s,
                tau_to_s,
                tau_peak_s,
                ratio,
                excess_deviation,
            } => writeln!(
                o,
                "  Allan deviation above the noise model's band from τ = {tau_from_s:.0} s to \
                 {tau_to_s:.0} s: up to ×{ratio:.2} at {tau_peak_s:.0} s, excess deviation \
                 {excess_deviation:.3e} {unit}"
            ),
            Structure::Line {
                frequency_hz,
                period_s,
                amplitude,
                fap,
            } => writeln!(
                o,
                "  spectral line at {frequency_hz:.4e} Hz (period {period_s:.0} s = \
                 {:.2} h): amplitude {amplitude:.3e} {unit}, FAP {fap:.1e} after whitening",
                period_s / 3600.0
            ),
        };
    }
    o
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::discover::import::Dataset;

    fn gauss(state: &mut u64) -> f64 {
        // Box–Muller on a 64-bit LCG: enough for a unit test's white noise.
        let mut u = || {
            *state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((*state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let (a, b) = (u(), u());
        (-2.0 * a.ln()).sqrt() * (2.0 * std::f64::consts::PI * b).cos()
    }

    /// White noise under its own model shows nothing; a sinusoid of 1.5 σ added to it is a line
    /// at its period with its amplitude.
    #[test]
    fn white_noise_is_within_its_model_and_a_hidden_line_is_found() {
        let n = 4000;
        let t: Vec<f64> = (0..n).map(|i| 60.0 * i as f64).collect();
        let mut s = 7u64;
        let e: Vec<f64> = (0..n).map(|_| gauss(&mut s)).collect();
        let ds = Dataset::test_g(t.clone(), e.clone(), 60.0);
        let model = NoiseModel::white(1.0);
        assert!(find(&ds, &e, &model).is_empty());
        let period = 7.3 * 3600.0;
        let y: Vec<f64> = t
            .iter()
            .zip(&e)
            .map(|(x, v)| v + 0.3 * (2.0 * std::f64::consts::PI * x / period).sin())
            .collect();
        let found = find(&ds, &y, &model);
        let line = found
            .iter()
            .find_map(|x| match x {
                Structure::Line {
                    period_s,
                    amplitude,
                    ..
                } => Some((*period_s, *amplitude)),
                _ => None,
            })
            .expect("a line");
        assert!((line.0 / period - 1.0).abs() < 0.02, "{line:?}");
        assert!((line.1 / 0.3 - 1.0).abs() < 0.3, "{line:?}");
    }
}
