//! Cause: which mismatch each accepted effect explains. The catalogue search runs on the
//! measured − twin residual (`discover` with the twin's prediction as the known part); each
//! accepted effect's contribution (its joint-fit columns × coefficients) is then taken out of
//! the measured residual alone, the views recomputed, and a mismatch counts as explained by the
//! effect when its excess beyond the envelope (Σ ln(measured / envelope edge) over the range's
//! points) falls to at most [`EXPLAINED_EXCESS`] of what it was. A run of neighbouring
//! outside points can hold two causes (a tide's bands beside a hidden line's): when all the
//! effects taken out together explain it, every effect whose own removal takes at least
//! [`JOINT_SHARE`] of the excess away is credited with it too.

use super::ensemble::Yardstick;
use super::mismatch::{Comparison, Quantity};

/// A mismatch is explained when at most this fraction of its excess is left.
pub const EXPLAINED_EXCESS: f64 = 0.5;
/// The share of a jointly explained mismatch's excess an effect must take away on its own to
/// be credited (a lesser share is the views' fluctuation under any change of the residual).
pub const JOINT_SHARE: f64 = 0.1;

/// Σ ln(beyond edge) of measured values over [a, b) on the mismatch's side.
fn excess(m: &[f64], lo: &[f64], hi: &[f64], a: usize, b: usize, above: bool) -> f64 {
    (a..b)
        .map(|i| {
            let v = m.get(i).copied().unwrap_or(f64::NAN);
            let r = if above { v / hi[i] } else { lo[i] / v };
            if r.is_finite() && r > 1.0 {
                r.ln()
            } else {
                0.0
            }
        })
        .sum()
}

/// For each effect, the indices of the `before` mismatches it explains.
pub fn explained_by(
    yard: &Yardstick,
    before: &Comparison,
    measured_residual: &[f64],
    contributions: &[(String, Vec<f64>)],
) -> Vec<(String, Vec<usize>)> {
    let base = excesses(before, &before.measured);
    let without = |cols: &[&Vec<f64>]| {
        let r: Vec<f64> = measured_residual
            .iter()
            .enumerate()
            .map(|(i, r)| r - cols.iter().map(|c| c[i]).sum::<f64>())
            .collect();
        excesses(before, &yard.views(&yard.detrend(&r)))
    };
    let single: Vec<Vec<f64>> = contributions.iter().map(|(_, c)| without(&[c])).collect();
    let all = without(&contributions.iter().map(|c| &c.1).collect::<Vec<_>>());
    let explains = |b: f64, a: f64| b > 0.0 && a <= EXPLAINED_EXCESS * b;
    contributions
        .iter()
        .enumerate()
        .map(|(k, (name, _))| {
            let idx = (0..base.len())
                .filter(|&i| {
                    let b = base[i];
                    explains(b, single[k][i])
                        || (explains(b, all[i]) && b - single[k][i] >= JOINT_SHARE * b)
                })
                .collect();
            (name.clone(), idx)
        })
        .collect()
}

/// Excess of every mismatch of `cmp` measured on views `v`.
fn excesses(cmp: &Comparison, v: &super::spectra::Views) -> Vec<f64> {
    cmp.mismatches
        .iter()
        .map(|m| {
            let (a, b) = m.index;
            let above = m.direction == "above";
            match m.quantity {
                Quantity::Adev => {
                    let y: Vec<f64> = v.adev.iter().map(|p| p.1).collect();
                    excess(&y, &cmp.adev.low, &cmp.adev.high, a, b, above)
                }
                Quantity::Psd => excess(&v.psd, &cmp.psd.low, &cmp.psd.high, a, b, above),
                Quantity::Coherence => {
                    let c = cmp
                        .coherence
                        .iter()
                        .position(|(n, _)| Some(n) == m.channel.as_ref());
                    match c {
                        Some(c) => {
                            let e = &cmp.coherence[c].1;
                            let y = v.coherence.get(c).cloned().unwrap_or_default();
                            excess(&y, &e.low, &e.high, a, b, above)
                        }
                        None => 0.0,
                    }
                }
            }
        })
        .collect()
}
