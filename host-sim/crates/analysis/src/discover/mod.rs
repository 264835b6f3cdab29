//! `accomp discover`: show what the model gets wrong on a measured record, name the physical
//! cause from a catalogue, extend the model, and measure the gain out of sample.
//!
//! - [`import`]: our log, the gMetrology `.tsf`, the AQG CSV → [`import::Dataset`].
//! - [`baseline`]: the calibration or static baseline and the (whitened) least squares.
//! - [`residual`]: spectrum, correlations, trend/step, Allan deviation of the residual.
//! - [`eiv`]: errors in variables: each regressor channel's reading noise, fitted and smoothed.
//! - [`effects`]: the catalogue of named effects as design-matrix extensions.
//! - [`hysteresis`]: play / Preisach operators of the thermal hysteresis.
//! - [`fullrate`]: lags faster than the bins, fitted on the full-rate rows in the frequency domain.
//! - [`changepoints`]: many steps at once: a noise-model MOSUM scan, the set validated together.
//! - [`plausibility`]: a flexible effect must stand above the noise and beat the simpler cause.
//! - [`table_error`]: with a calibration, errors of the table's temperature models, corrected.
//! - [`unexplained`]: structure left that no cause explains (Allan excess, a spectral line).
//! - [`shape`]: whether an accepted effect's shape describes the data (poor-fit check).
//! - [`select`]: greedy selection with BIC (effective sample size) and blocked cross-validation;
//!   its parts: [`current_model`] (the model under its fitted noise model), [`fitters`] (each
//!   candidate's best fit and ΔBIC), [`acceptance`] (the checks after the BIC), [`validation`]
//!   (cross-validation, forward chaining), [`joint`] (the final joint fit).
//! - [`report`]: text, JSON and the Markdown report with figures.
//!
//! The command's arguments and output: `accomp_host::cli::discover`. Method, catalogue, rates and
//! measured-data findings: `docs/discovery.md`.

pub mod acceptance;
pub mod baseline;
pub mod changepoints;
pub mod current_model;
pub mod effects;
pub mod eiv;
mod error;
pub mod fitters;
pub mod fullrate;
pub mod hysteresis;
pub mod import;
pub mod joint;
pub mod noise;
pub mod plausibility;
pub mod rate;
pub mod report;
pub mod residual;
pub mod select;
pub mod shape;
pub mod simulate;
pub mod table_error;
pub mod tidal;
pub mod unexplained;
pub mod validation;

pub use error::DiscoverError;

use effects::{Context, Effect};
use import::{Dataset, DatasetOptions, Format};

/// Everything a discovery run found.
#[derive(Debug, Clone)]
pub struct Discovery {
    /// The dataset as fitted: with [`FIT_ON_SMOOTHED_CHANNELS`] its regressor channels are the
    /// errors-in-variables model's smoothed states ([`eiv`]); the readings as measured are in
    /// `measured_channels`.
    pub dataset: Dataset,
    /// The regressor channels as read from the record.
    pub measured_channels: Vec<import::Channel>,
    /// Baseline description and free-column names.
    pub baseline_description: String,
    /// Baseline column names.
    pub baseline_names: Vec<String>,
    /// Catalogue entries that were not candidates, with why.
    pub not_candidates: Vec<(String, String)>,
    /// Candidates considered.
    pub candidates: Vec<Effect>,
    /// The selection.
    pub selection: select::Selection,
    /// Residual analysis of the baseline.
    pub spectrum_before: residual::Spectrum,
    /// After.
    pub spectrum_after: residual::Spectrum,
    /// Correlations of the baseline residual.
    pub correlations: Vec<residual::Correlation>,
    /// Trend/step of the baseline residual.
    pub trend: residual::Trend,
    /// ADEV (tau, dev) of the baseline residual.
    pub adev_before: Vec<(f64, f64)>,
    /// ADEV of the final residual.
    pub adev_after: Vec<(f64, f64)>,
    /// Reading noise of each measured regressor channel and the smoother the model used
    /// (errors in variables, [`eiv`]).
    pub channel_noise: Vec<eiv::ChannelNoise>,
    /// Warnings about the input and the run (also in the selection's own `warnings`); printed
    /// first in the text output and listed in the JSON `warnings`.
    pub warnings: Vec<String>,
    /// Shape checks of the accepted effects (a poor fit is said, see `shape`).
    pub shape_checks: Vec<shape::ShapeCheck>,
    /// Wave-group tidal analysis of a gravity record, or why it was not run.
    pub tidal: Result<tidal::TidalAnalysis, tidal::NotRun>,
    /// The fast terms fitted on the full-rate rows ([`fullrate`]) when the selection ran on bins
    /// of at least [`fullrate::MIN_ROWS_PER_BIN`] rows; `Err` says why it could not run; `None`
    /// when the record was not binned that coarsely.
    pub full_rate: Option<Result<fullrate::FullRate, fullrate::FullRateError>>,
    /// With a calibration table: the test of its temperature models ([`table_error`]).
    pub table_check: Option<table_error::TableCheck>,
    /// Structure the final model leaves that no cause explains ([`unexplained`]).
    pub unexplained: Vec<unexplained::Structure>,
}

/// The shared series of the candidates.
pub fn context(ds: &Dataset, base: &baseline::Baseline) -> Context {
    let tide = effects::tide_series(ds);
    let tilt_term = if base.tilt_subtracted {
        baseline::tilt_term_g(ds)
            .map(|v| v.iter().map(|x| x * ds.unit_per_g.unwrap_or(1.0)).collect())
    } else {
        None
    };
    Context {
        tide_gravity_g: tide.as_ref().map(|t| t.0.clone()),
        tide_tilt_rad: tide.map(|t| (t.1, t.2)),
        tilt_term,
        hysteresis: None,
        full_rate: Vec::new(),
        rate_columns: Vec::new(),
    }
}

/// Whether the effects are fitted on the errors-in-variables model's smoothed channel states
/// ([`eiv`]) rather than on the readings. On since the hysteresis column is a Preisach
/// distribution (the 14-day hysteresis logs of `discover_hidden_shapes.rs` are found in 8/8 with
/// it on and off; with one play it had moved a log to a `thermal_lag`); with it on a real lag
/// is fitted at its τ without the RTD's reading noise in its column. Measured both ways in
/// docs/discovery.md, "Errors in variables".
pub const FIT_ON_SMOOTHED_CHANNELS: bool = true;

/// Runs the whole discovery on a dataset.
pub fn discover(
    ds: Dataset,
    table: Option<&accomp::table::CalibrationTable>,
    cfg: &select::Config,
) -> Result<Discovery, baseline::BaselineError> {
    discover_binned(ds, None, table, cfg)
}

/// [`discover`] on a binned dataset with its full-rate rows (`full`, the same log unbinned):
/// on bins of at least [`fullrate::MIN_ROWS_PER_BIN`] rows, after the binned rounds the
/// full-rate stage ([`fullrate`]) fits the lags faster than the bins, and what it finds joins
/// the final model (its column averaged into the bins, τ held) before the joint fit, so the
/// parameters, the residual and the checks after it hold it; on fewer, the rows give the rate
/// columns ([`effects::rate_columns`]).
pub fn discover_binned(
    ds: Dataset,
    full: Option<Dataset>,
    table: Option<&accomp::table::CalibrationTable>,
    cfg: &select::Config,
) -> Result<Discovery, baseline::BaselineError> {
    let measured_channels = ds.channels.clone();
    // Errors in variables: each channel's reading noise and smoother are fitted and reported;
    // see FIT_ON_SMOOTHED_CHANNELS for whether the effects are fitted on the smoothed states.
    let (mut ds, channel_noise) = eiv::denoise(&ds, FIT_ON_SMOOTHED_CHANNELS);
    // With a table, its temperature models are tested first: an error found there enters the
    // baseline, so the catalogue is searched on what the table does not explain.
    let (base, table_check) = match table {
        Some(t) => {
            let b = baseline::calibrated_baseline(&ds, t)?;
            let (check, extended) = table_error::check(&ds, t, &b, cfg);
            (extended, Some(check))
        }
        None => (baseline::static_baseline(&ds), None),
    };
    let mut ctx = context(&ds, &base);
    // A rate coupling's column is the band-limited rate of the channel as read ([`rate`]): the
    // smoothed state's filter is set by an estimated reading noise whose error would pass into
    // the gain.
    ctx.rate_columns = effects::rate_columns(&ds, &measured_channels, full.as_ref());
    ds.notes
        .extend(ctx.rate_columns.iter().map(effects::RateColumn::note));
    let (cands, not_candidates) = effects::candidates(&ds, &ctx, base.tilt_subtracted);
    let rounds = select::rounds(&ds, &base.target, &base.columns, &cands, &ctx, cfg);
    // The rows of bins of fewer than `MIN_ROWS_PER_BIN` served the rate columns only.
    let full = full.filter(|_| ds.rows_per_point() >= fullrate::MIN_ROWS_PER_BIN);
    let mut full_rate = full.map(|f| fullrate::analyse(&f, &ds, &rounds.accepted).map(|r| (f, r)));
    let fast = match &mut full_rate {
        Some(Ok((f, r))) => {
            let (fast, left) = fullrate::binned_columns(f, &ds, r);
            r.refused.extend(left);
            fast
        }
        _ => Vec::new(),
    };
    let full_rate = full_rate.map(|r| r.map(|(_, r)| r));
    let sel = select::finish(&ds, &base.target, &base.columns, cfg, rounds, &fast);
    // The accepted hysteresis's Preisach distribution and the full-rate lags' columns shape
    // their columns from here on.
    let ctx = Context {
        hysteresis: sel.hysteresis.clone(),
        full_rate: sel.full_rate_columns.clone(),
        ..ctx
    };
    let spectrum_before = residual::periodogram(&ds.t_s, &sel.baseline_residual, 4096);
    let spectrum_after = residual::periodogram(&ds.t_s, &sel.final_residual, 4096);
    let correlations = residual::correlations(&ds, &sel.baseline_residual);
    let trend = residual::trend(&ds, &sel.baseline_residual);
    let adev_before = residual::adev(&ds, &sel.baseline_residual);
    let adev_after = residual::adev(&ds, &sel.final_residual);
    let unexplained = unexplained::find(&ds, &sel.final_residual, &sel.final_noise.model);
    // The shape check whitens with the Allan fit of the final residual; where that fit is not
    // possible it uses white noise, which changes what it calls poor: said, never silent.
    let mut warnings = ds.warnings.clone();
    let final_noise = match noise::NoiseModel::fit(&adev_after, ds.dt_s, ds.span_s()) {
        Some(m) => m,
        None => {
            if !sel.accepted.is_empty() {
                warnings.push(
                    "shape check: the final residual's Allan deviation could not be fitted \
                     (too few points on its time grid), so the shape checks whiten with white \
                     noise of the residual's variance; a \"poor fit\" there may be correlated \
                     noise"
                        .into(),
                );
            }
            noise::NoiseModel::white(baseline::std(&sel.final_residual).powi(2).max(1e-300))
        }
    };
    let shape_checks = shape::check(
        &ds,
        &ctx,
        &sel.columns,
        &base.target,
        &sel.accepted,
        &final_noise,
    );
    let tidal = tidal_analysis(&ds, &base.target, &base.columns, &ctx, &sel.accepted);
    Ok(Discovery {
        shape_checks,
        baseline_description: base.description.clone(),
        baseline_names: base.names.clone(),
        not_candidates,
        candidates: cands,
        selection: sel,
        spectrum_before,
        spectrum_after,
        correlations,
        trend,
        adev_before,
        adev_after,
        warnings,
        channel_noise,
        measured_channels,
        tidal,
        full_rate,
        table_check,
        unexplained,
        dataset: ds,
    })
}

/// Loads a record and runs the discovery (library entry point used by the CLI and the tests).
pub fn discover_path(
    path: &std::path::Path,
    format: Format,
    opts: &DatasetOptions,
    table: Option<&accomp::table::CalibrationTable>,
    cfg: &select::Config,
) -> Result<(Discovery, Vec<import::BadRow>), DiscoverError> {
    let (log, bad) = import::load_for_dataset(path, format, opts.output.as_deref())?;
    let d = discover_log(log, &bad, opts, table, cfg)?;
    Ok((d, bad))
}

/// [`discover_path`] on a log already read (`bad`: the rows its reader refused): the dataset,
/// the selection on it and, when the dataset is binned, the full-rate stage on the rows. The log
/// is consumed: it is dropped before the fit.
pub fn discover_log(
    log: crate::log::Log,
    bad: &[import::BadRow],
    opts: &DatasetOptions,
    table: Option<&accomp::table::CalibrationTable>,
    cfg: &select::Config,
) -> Result<Discovery, DiscoverError> {
    let mut opts = opts.clone();
    if let Some(t) = table {
        opts.unit_per_g_from_calibration = t
            .thermal
            .coefficients_at(t.thermal.reference)
            .ok()
            .map(|(k, _)| k.scale_factor_v_per_g);
    }
    // Bins of several rows hide what is faster than two of them: the full-rate rows are kept
    // for the fast terms, and on bins of a few rows for the rate columns
    // (`effects::rate_columns`). Both reductions read the same log and are made at once, the
    // rows whenever the log has more of them than points may be kept (they are then binned
    // unless gaps drop enough rows, which the binned reduction tells); the log itself is dropped
    // first: it holds every column read.
    let may_bin = log.time_s().len() > opts.max_points;
    let (ds, full) = crate::numerics::parallel::join(
        || import::dataset_from_log(&log, &opts),
        || may_bin.then(|| import::full_rate_from_log(&log, &opts)),
    );
    let mut ds = ds?;
    note_bad_rows(&mut ds, bad);
    let full = full.filter(|_| ds.rows_per_point() > 1.0).transpose()?;
    drop(log);
    Ok(discover_binned(ds, full, table, cfg)?)
}

/// Says in the dataset's notes how many rows the reader skipped and why (the first ten).
pub fn note_bad_rows(ds: &mut Dataset, bad: &[import::BadRow]) {
    if !bad.is_empty() {
        ds.notes.push(format!(
            "{} bad row(s) skipped: {}",
            bad.len(),
            bad.iter()
                .take(10)
                .map(|b| format!("line {}: {}", b.line, b.reason))
                .collect::<Vec<_>>()
                .join("; ")
        ));
    }
}

/// The tidal analysis inside `accomp discover`: the record's baseline target, with the
/// baseline's columns and every accepted effect except the tide itself and the pressure
/// admittance (which the analysis fits) as nuisance columns, at their accepted nonlinear
/// parameters. Here, not in `tidal`, so that `tidal` does not depend on `select` (which
/// depends on `tidal`'s clock).
fn tidal_analysis(
    ds: &Dataset,
    target: &[f64],
    base_cols: &[Vec<f64>],
    ctx: &effects::Context,
    accepted: &[select::Accepted],
) -> Result<tidal::TidalAnalysis, tidal::NotRun> {
    if let Some(why) = tidal::not_applicable(ds) {
        return Err(why);
    }
    let mut nuisance = base_cols.to_vec();
    for a in accepted {
        if !matches!(
            a.effect,
            effects::Effect::TidalGravity | effects::Effect::PressureAdmittance
        ) {
            nuisance.extend(effects::columns(&a.effect, ds, ctx, a.theta.value));
        }
    }
    tidal::analyse(ds, target, &nuisance)
}
