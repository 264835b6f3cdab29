//! Gain: how much better the extended twin predicts the record, out of sample.
//!
//! Forward chaining as in the discovery (`select::forward_validate`, splits at 50–90 % of the
//! span): the twin's prediction is the known part; what is fitted on the training part only is
//! the instrument's level and linear drift (and, for the extended twin, a linear correction of
//! each added effect's amplitude — so the added effects' amplitudes are not taken from the rows
//! that are predicted); the rows after the split are predicted. The score is the RMS of the
//! predicted rows' residual. A second figure holds the extension's amplitudes at the values
//! fitted on the whole record (`..._fixed_amplitudes`): it shows what the written scenario
//! itself does, but it is not out of sample in those amplitudes.

use crate::discover::baseline::trend_columns;
use crate::discover::import::Dataset;
use crate::discover::noise::NoiseModel;
use crate::discover::select::forward_validate;

/// Forward-chaining residual std of `measured − prediction` with trend columns plus `extra`
/// columns refitted on each training part.
pub fn forward_std(
    ds: &Dataset,
    prediction: &[f64],
    extra: &[Vec<f64>],
    noise: &NoiseModel,
) -> f64 {
    let y: Vec<f64> = ds.y.iter().zip(prediction).map(|(m, p)| m - p).collect();
    let mut cols = trend_columns(ds);
    cols.extend(extra.iter().cloned());
    forward_validate(ds, &cols, &y, noise).raw
}
