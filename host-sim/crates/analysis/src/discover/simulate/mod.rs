//! `accomp discover --simulate`: the measured record against its simulated twin — what the
//! simulation gets wrong, the named cause, the extended simulator and the measured gain
//! (issue #14; method and the real-record figures in docs/discovery.md, "Simulation in the
//! loop").
//!
//! 1. The twin's deterministic run is the predicted record; the residual is measured −
//!    predicted (offset and linear drift removed: calibration constants, not predictions).
//! 2. The catalogue search (`discover`) runs on that residual — the cause; its final noise model
//!    is the twin's noise.
//! 3. [`ensemble`]: N seeded members; each member − the deterministic part is the simulator's
//!    own residual; [`spectra`]: ADEV, Welch PSD in bands, coherence with each measured channel.
//! 4. [`mismatch`]: where the measured residual leaves the members' 5–95 % envelopes, and the
//!    sentences; [`cause`]: which mismatch each accepted effect explains.
//! 5. The twin extended by the accepted effects (joint-fit parameters), the ensemble rerun, the
//!    same comparison; [`gain`]: forward-chaining residual std and the outside fractions,
//!    before and after.

pub mod cause;
pub mod drift;
pub mod ensemble;
mod entry;
mod error;
pub mod gain;
pub mod mismatch;
pub mod output;
pub mod settling;
pub mod spectra;
pub mod twin;

pub use entry::{simulate_dataset, write_report, write_scenario};
pub use error::SimulateError;

use super::import::Dataset;
use super::noise::NoiseModel;
use super::{select, Discovery};
use crate::sim::twin::drift::Settling;
use crate::twin::family::NoiseFamily;
use crate::twin::transients::Transients;
use ensemble::Yardstick;
use mismatch::Comparison;

/// Likelihood evaluations of the twin's noise fit (warm start).
const NOISE_EVALS: usize = 40;
/// The same for each drift order's profile likelihood (warm-started from the previous order's).
const DRIFT_NOISE_EVALS: usize = 60;

/// Smallest default ensemble. The envelope's 5 % and 95 % lines are quantile estimates: from
/// N members their error is about [`edge_error`]`(N)` = 1.3/√N of the envelope's half-width
/// ln(p95/p50) (0.29 at 20 members, 0.20 at 40, 0.13 at 100: the Gaussian order-statistic
/// formula, which the members' own scatter follows, docs/discovery.md), and the record's
/// outside fraction moves with them. 30 members keep `discover --simulate` on gMetrology
/// (50 000 points) within its 30 s at a load of 3 on two cores (40 took 31 s there).
pub const MIN_DEFAULT_ENSEMBLE: usize = 30;
/// Largest default ensemble (edge error 0.13).
pub const MAX_DEFAULT_ENSEMBLE: usize = 100;
/// Member-points the default ensemble spends (members × the record's points): a member's cost
/// grows with the record's points, so a shorter record affords more members in the same time
/// (30 members of gMetrology's 50 000 points).
pub const DEFAULT_MEMBER_POINTS: usize = 1_500_000;

/// The default ensemble size for a record of `points` points: [`DEFAULT_MEMBER_POINTS`] /
/// points, within [`MIN_DEFAULT_ENSEMBLE`]..=[`MAX_DEFAULT_ENSEMBLE`].
pub fn default_ensemble(points: usize) -> usize {
    (DEFAULT_MEMBER_POINTS / points.max(1)).clamp(MIN_DEFAULT_ENSEMBLE, MAX_DEFAULT_ENSEMBLE)
}

/// The 5/95 % lines' sampling error from `members` members, as a fraction of the envelope's
/// half-width: sd of the 95 % quantile estimate, √(p(1 − p)/N)/φ(z₀.₉₅), over z₀.₉₅ (a
/// Gaussian spread of the members' values; ln ADEV and ln PSD are nearly so).
pub fn edge_error(members: usize) -> f64 {
    let (p, z) = (0.95f64, 1.644_853_626_951_472_2_f64);
    let density = (-0.5 * z * z).exp() / (2.0 * std::f64::consts::PI).sqrt();
    (p * (1.0 - p) / members.max(1) as f64).sqrt() / density / z
}

/// Ensemble sizes taken: two members make the smallest envelope; a thousand give its 5/95 %
/// lines to 4 % of its half-width and take about two minutes on gMetrology (≈ 60 ms a member,
/// twice: base and extended).
pub const ENSEMBLE_RANGE: std::ops::RangeInclusive<usize> = 2..=1000;

/// Parses `--ensemble`, refusing a size outside [`ENSEMBLE_RANGE`] with the range named.
pub fn parse_ensemble(s: &str) -> Result<usize, String> {
    let n: usize = s
        .parse()
        .map_err(|_| format!("{s:?} is not a number of members"))?;
    if !ENSEMBLE_RANGE.contains(&n) {
        return Err(format!(
            "{n} members: the ensemble takes {}..={} members",
            ENSEMBLE_RANGE.start(),
            ENSEMBLE_RANGE.end()
        ));
    }
    Ok(n)
}

/// Effects a twin could not express: (effect name, why).
pub type Refused = Vec<(String, String)>;

/// What the comparison needs of a twin of the record (`twin::Twin` has it).
pub trait TwinModel: Sync + Sized {
    /// One effect the twin can be extended by (a scenario `[[effects]]` entry).
    type Effect: Clone;
    /// Why the twin cannot run.
    type Error: std::error::Error + Send + Sync + 'static;
    /// The output at the record's time stamps: `None` the deterministic part, `Some(seed)` one
    /// ensemble member with the simulator's noise.
    fn run(&self, seed: Option<u64>) -> Result<Vec<f64>, Self::Error>;
    /// The accepted effects of a discovery as the twin's effects (name, effect), with the
    /// effects it cannot express (name, why).
    fn effects_from(&self, d: &Discovery) -> (Vec<(String, Self::Effect)>, Refused);
    /// One member's draw of the accepted effects: parameters drawn from their uncertainty, the
    /// other cause of an ambiguous pair in odd members (same order as `effects_from`'s).
    fn effects_drawn(&self, d: &Discovery, member: u64) -> Vec<Self::Effect>;
    /// The twin extended by effects.
    fn extended(&self, effects: &[Self::Effect]) -> Self;
    /// The twin whose members draw their noise from the fitted family on the record's grid.
    fn with_family(&self, family: &NoiseFamily, grid: &spectra::RegularGrid) -> Self;
    /// The twin whose members also draw the record's transient disturbances.
    fn with_transients(&self, found: &Transients) -> Self;
    /// The twin whose members also carry the record's drift polynomial (Legendre coefficients
    /// with their 1σ, see [`drift`]) and the settling at its start, if any ([`settling`]:
    /// each member draws its τ and amplitude).
    fn with_drift(&self, coefficients: &[(f64, f64)], settling: Option<&Settling>) -> Self;
    /// What came from the record and what from defaults.
    fn provenance(&self) -> Vec<String>;
    /// The scenario as TOML (`accomp simulate` runs it), if the twin has one.
    fn scenario_toml(&self) -> Option<String>;
    /// The simulator's model of this twin's members with the discovery's accepted effects
    /// drawn (what `--write-scenario` writes and the extended ensemble runs), when the twin has
    /// a noise family and is the simulator.
    fn written_twin(&self, d: &Discovery) -> Option<crate::sim::twin::MemberModel>;
    /// Whether this is the station simulator (false: a stand-in, announced).
    fn is_simulator(&self) -> bool;
}

/// Scores of one comparison.
#[derive(Debug, Clone, PartialEq)]
pub struct Scores {
    /// Forward-chaining out-of-sample residual std (linear amplitudes refitted on each
    /// training part), output unit.
    pub residual_std_out_of_sample: f64,
    /// The same with the extension's amplitudes held at their whole-record values.
    pub residual_std_fixed_amplitudes: f64,
}

/// Everything `--simulate` produced.
#[derive(Debug, Clone)]
pub struct Simulation {
    /// Where the base scenario came from.
    pub scenario: String,
    /// Provenance lines of the twin.
    pub provenance: Vec<String>,
    /// Ensemble size.
    pub ensemble: usize,
    /// The comparison with the base twin.
    pub before: Comparison,
    /// With the extended twin.
    pub after: Comparison,
    /// Scores before.
    pub before_scores: Scores,
    /// After.
    pub after_scores: Scores,
    /// For each accepted effect, the `before` mismatches it explains.
    pub explained_by: Vec<(String, Vec<usize>)>,
    /// Effects the extended scenario could not express (name, why).
    pub refused: Vec<(String, String)>,
    /// The extended scenario's TOML, if the twin has a scenario (without the `[twin]` section:
    /// a station scenario).
    pub extended_toml: Option<String>,
    /// The extended twin's member model, when the members draw from the noise family: what
    /// `--write-scenario` writes (the scenario with its `[twin]` section and driver file), the
    /// same model the extended ensemble ran.
    pub written_twin: Option<crate::sim::twin::MemberModel>,
    /// The extended twin's deterministic part at the record's instants (members' residuals are
    /// taken from it).
    pub det_after: Vec<f64>,
    /// Each member's views of the extended ensemble (member k at index k − 1).
    pub members_after: Vec<spectra::Views>,
    /// Where it was written.
    pub extended_path: Option<std::path::PathBuf>,
    /// The catalogue search on measured − twin.
    pub cause: Discovery,
    /// Band frequencies (Hz) of the PSD and coherence.
    pub frequencies_hz: Vec<f64>,
    /// Channel names of the coherence.
    pub channels: Vec<String>,
    /// The measured residual before (detrended), output unit, at the record's stamps.
    pub residual_before: Vec<f64>,
    /// After.
    pub residual_after: Vec<f64>,
    /// Things the user must know (refused effects, a failed noise fit …).
    pub warnings: Vec<String>,
    /// Whether the twin is the station simulator.
    pub simulator: bool,
    /// The noise family the members draw from (None: the likelihood noise model, announced).
    pub family: Option<NoiseFamily>,
    /// Wall time of each stage (name, s): for docs/benchmarks.md.
    pub timing_s: Vec<(&'static str, f64)>,
    /// The drift polynomial removed from every residual (order and −ℓ per order tried).
    pub drift: drift::DriftOrder,
    /// Its Legendre coefficients on the record (P₀…P_order of the record's time on [−1, 1]) with
    /// their 1σ, output unit: generalised least squares on measured − extended twin under the
    /// noise model refitted with the drift removed.
    pub drift_coefficients: Vec<(f64, f64)>,
    /// Transient disturbances found in what the extended twin leaves (members draw them).
    pub transients: Transients,
    /// The instrument's settling at the record's start fitted with the drift polynomial (in
    /// the twin's drift when kept: in-sample, not a discovered cause); None: the record is too
    /// short for one or the fit failed.
    pub settling: Option<settling::SettlingFit>,
    /// The columns fitted out, with the drift polynomial, of the record's residual after
    /// extension and of every extended member's (see `fitted_columns`).
    pub fitted_out: Vec<Vec<f64>>,
    /// How many independent columns that fit has, the drift polynomial's included.
    pub fitted_out_independent: usize,
}

/// Runs the comparison with twins made by `build` (noise model → twin).
pub fn simulate<T, F>(
    ds: &Dataset,
    build: F,
    scenario: String,
    ensemble: usize,
    cfg: &select::Config,
) -> Result<Simulation, SimulateError>
where
    T: TwinModel,
    F: Fn(Option<&NoiseModel>) -> Result<T, T::Error>,
{
    if !ENSEMBLE_RANGE.contains(&ensemble) {
        return Err(SimulateError::EnsembleSize { members: ensemble });
    }
    let mut warnings = Vec::new();
    let mut timing_s = Vec::new();
    let mut clock = std::time::Instant::now();
    let mut lap = |name: &'static str| {
        timing_s.push((name, clock.elapsed().as_secs_f64()));
        clock = std::time::Instant::now();
    };
    // 1. The prediction and the residual's catalogue search (the cause).
    let quiet = build(None).map_err(SimulateError::twin)?;
    if !quiet.is_simulator() {
        warnings.push("the twin is not the station simulator (a test stand-in)".to_owned());
    }
    let det = quiet.run(None).map_err(SimulateError::twin)?;
    check_len(&det, ds)?;
    let mut resid_ds = ds.clone();
    for (y, p) in resid_ds.y.iter_mut().zip(&det) {
        *y -= p;
    }
    lap("twin");
    let spin = stage_spinner("catalogue search on the measured − twin residual");
    let cause = super::discover(resid_ds, None, cfg);
    spin.finish_and_clear();
    let cause = cause?;
    lap("catalogue search");
    let spin = stage_spinner("extension and the twin's noise model");
    // 2. The extension: the accepted effects as the twin's effects; each one's contribution is
    //    what it adds to the twin's prediction (the simulator's own rendering of it).
    let (effects, refused) = quiet.effects_from(&cause);
    let ext_quiet = quiet.extended(&effects.iter().map(|e| e.1.clone()).collect::<Vec<_>>());
    let det_ext = ext_quiet.run(None).map_err(SimulateError::twin)?;
    check_len(&det_ext, ds)?;
    let mut contrib = Vec::new();
    for (name, e) in &effects {
        let p = quiet
            .extended(std::slice::from_ref(e))
            .run(None)
            .map_err(SimulateError::twin)?;
        check_len(&p, ds)?;
        contrib.push((name.clone(), sub(&p, &det)));
    }
    // 3. The simulator's noise: the likelihood noise model (the discovery's: white + flicker +
    //    random walk, Kalman innovations, warm-started from the catalogue search's final fit)
    //    of what the extended twin cannot predict. Where the discovery's tidal analysis
    //    separates the instrument's drift (a relative gravimeter: cubic B-spline, everything
    //    slower than ≈ 0.25 cpd), the fit sees the residual without that drift: otherwise the
    //    three-term family spreads the drift's power into mid-band flicker and random walk
    //    (gMetrology: ×3–10 too much power at 0.4–20 cycles/day). The comparison itself keeps
    //    the drift: the simulation does not predict it, and says so at long τ.
    let yard = Yardstick::new(ds);
    let r_before = yard.detrend(&sub(&ds.y, &det));
    let r_after = yard.detrend(&sub(&ds.y, &det_ext));
    let idx: Vec<usize> = (0..ds.len()).collect();
    let (noise_input, noise_source) = match &cause.tidal {
        Ok(t) => match without_drift(ds, &r_after) {
            Ok(r) => (
                r,
                format!(
                    "noise model: likelihood fit (white + flicker + random walk) to the extended \
                     twin's residual without the tidal analysis' drift ({}); the drift stays in \
                     the comparison",
                    t.drift
                ),
            ),
            Err(why) => {
                warnings.push(format!(
                    "the tidal analysis' drift could not be removed before the noise fit ({why}): \
                     the noise model also describes the drift"
                ));
                (
                    r_after.clone(),
                    "noise model: likelihood fit to the extended twin's residual (drift included)"
                        .to_owned(),
                )
            }
        },
        Err(_) => (
            r_after.clone(),
            "noise model: likelihood fit (white + flicker + random walk) to the extended twin's \
             residual"
                .to_owned(),
        ),
    };
    let nf = NoiseModel::fit_ml(
        &ds.t_s,
        &idx,
        &noise_input,
        ds.dt_s,
        ds.span_s(),
        &[&cause.selection.final_noise.model],
        NOISE_EVALS,
        None,
    );
    if let Some(why) = &nf.failure {
        warnings.push(format!(
            "the noise model of the extended twin's residual could not be fitted ({why}): the \
             catalogue search's final noise model is the twin's noise instead"
        ));
    }
    let noise = if nf.failure.is_none() {
        nf.model
    } else {
        cause.selection.final_noise.model.clone()
    };
    spin.finish_and_clear();
    lap("extension and noise fit");
    // The instrument's smooth drift: the polynomial order selected by the likelihood (the noise
    // model refitted for each order) on what the extended twin leaves; removed from the record
    // and every member alike (calibration constants, as the level and the linear rate).
    // Transient disturbances (spikes far outside the Gaussian noise): found on what the
    // extended twin leaves, kept out of the noise fits, drawn by the members.
    let grid = yard.grid.clone();
    let transients = Transients::find(&grid.place(&r_after), grid.dt_s);
    let clean = |x: &[f64]| transients.removed(&grid.place(x));
    let r_clean = transients.removed_points(&grid.cell, &r_after);
    let last = std::cell::RefCell::new(noise.clone());
    let profile = |x: &[f64]| {
        let prev = last.borrow().clone();
        let f = NoiseModel::fit_ml(
            &ds.t_s,
            &idx,
            x,
            ds.dt_s,
            ds.span_s(),
            &[&prev, &noise],
            DRIFT_NOISE_EVALS,
            None,
        );
        let fitted = 0.5 * super::noise::neg2_loglik(&f.model, &ds.t_s, &idx, x);
        let held = 0.5 * super::noise::neg2_loglik(&prev, &ds.t_s, &idx, x);
        // The profile is the best model found: the refit or, if its search fell short, the
        // previous order's.
        if fitted <= held {
            *last.borrow_mut() = f.model;
            fitted
        } else {
            held
        }
    };
    // The instrument's settling at the record's start: an exponential fitted with the
    // polynomial of the highest order, kept by the profile likelihood (`settling`); the order
    // is then selected with it in.
    let settling_found = if ds.span_s() >= drift::MIN_SPAN_S {
        let whitener = super::noise::Whitener::new(&noise, &ds.t_s, idx.clone());
        settling::search(
            &ds.t_s,
            yard.unit_time(),
            &r_clean,
            drift::MAX_ORDER,
            ds.dt_s,
            |x| whitener.whiten(x),
        )
        .map(|f| {
            settling::decide(
                f,
                &ds.t_s,
                yard.unit_time(),
                &r_clean,
                drift::MAX_ORDER,
                profile,
            )
        })
    } else {
        None
    };
    // The order's profiles start from the same warm start with or without the settling.
    *last.borrow_mut() = noise.clone();
    let settling_cols: Vec<Vec<f64>> = settling_found
        .as_ref()
        .and_then(|f| f.kept())
        .map(|s| vec![Settling::column(&ds.t_s, s.tau_s.value)])
        .unwrap_or_default();
    let drift_order = drift::select_order(
        yard.unit_time(),
        &r_clean,
        &settling_cols,
        ds.span_s(),
        profile,
    );
    let yard = yard.with_drift_order(drift_order.order);
    // The settling is removed with the polynomial from every residual (record and members).
    let yard = if settling_cols.is_empty() {
        yard
    } else {
        yard.with_fitted_out(&settling_cols)
    };
    let r_before = yard.detrend(&r_before);
    let r_after = yard.detrend(&r_after);
    let drift_noise = NoiseModel::fit_ml(
        &ds.t_s,
        &idx,
        &yard.detrend(&r_clean),
        ds.dt_s,
        ds.span_s(),
        &[&last.borrow(), &noise],
        DRIFT_NOISE_EVALS,
        None,
    )
    .model;
    let whitener = super::noise::Whitener::new(&drift_noise, &ds.t_s, idx.clone());
    let mut drift_coefficients = drift::gls(
        yard.unit_time(),
        &transients.removed_points(&grid.cell, &sub(&ds.y, &det_ext)),
        drift_order.order,
        &settling_cols,
        |x| whitener.whiten(x),
    );
    // The settling's amplitude and σ from the same fit (its τ and τ's σ from the search).
    let settling_fit = settling_found.map(|mut f| {
        if f.kept().is_some() {
            if let Some(&(value, sigma)) = drift_coefficients.get(drift_order.order + 1) {
                f.fitted.amplitude = crate::sim::twin::draw::Drawn { value, sigma };
            }
        }
        f
    });
    drift_coefficients.truncate(drift_order.order + 1);
    let settling_kept = settling_fit.as_ref().and_then(|f| f.kept()).copied();
    lap("drift order");
    // The members' noise: the family (white, flicker, random walk, drift-rate walk,
    // Gauss–Markov, output filter) fitted by Whittle likelihood to what the extended twin
    // leaves with the drift polynomial removed and without the transients, from the lowest
    // bin the polynomial leaves; the members carry the polynomial (fitted coefficients) and
    // draw transients, and lose the polynomial again in the comparison.
    let family =
        match NoiseFamily::fit_after_drift(&clean(&r_after), yard.grid.dt_s, drift_order.order) {
            // Every instrument has a white floor: a fit that does not resolve one has traded it
            // for other terms (a filter corner with a random walk mimics it) and is not used.
            Ok(f) if !f.resolved(0) => {
                warnings.push(
                "the noise family's white level is not resolved (a degenerate fit): the members \
                 draw from the likelihood noise model instead"
                    .to_owned(),
            );
                None
            }
            Ok(f) => Some(f),
            Err(e) => {
                warnings.push(format!(
                    "the noise family could not be fitted ({e}): the members draw from the \
                 likelihood noise model instead"
                ));
                None
            }
        };
    lap("noise family");
    // 4. Ensembles and comparisons, before and after. Members of the extended twin draw the
    //    accepted effects' parameters (and the other cause of an ambiguous pair) as well as the
    //    noise's.
    let mut twin = build(Some(&noise)).map_err(SimulateError::twin)?;
    if let Some(f) = &family {
        twin = twin
            .with_family(f, &yard.grid)
            .with_transients(&transients)
            .with_drift(&drift_coefficients, settling_kept.as_ref());
    }
    let ext = twin.extended(&effects.iter().map(|e| e.1.clone()).collect::<Vec<_>>());
    let mut provenance = ext.provenance();
    provenance.push(noise_source);
    if let Some(s) = &settling_kept {
        provenance.push(format!(
            "drift: the instrument's settling at the record's start, {:.3e} ± {:.1e} {} × \
             exp(−t/τ), τ {:.3} ± {:.3} d, fitted with the drift polynomial and removed with it \
             from the record and every member (in-sample: a property of the instrument's \
             history in the twin's drift, not a discovered cause; members draw τ and the \
             amplitude)",
            s.amplitude.value,
            s.amplitude.sigma,
            ds.output_unit,
            s.tau_s.value / 86_400.0,
            s.tau_s.sigma / 86_400.0
        ));
    }
    if family.is_some() {
        provenance.push(
            "ensemble members: the noise family fitted to the extended twin's residual with the \
             drift polynomial and the transients removed (Whittle likelihood), each member with \
             its own draw of the family's parameters and of the transients, and the drift \
             polynomial at its fitted coefficients; members of the extended twin also draw \
             every accepted effect's parameters from their uncertainty"
                .to_owned(),
        );
    }
    let channels: Vec<String> = yard.channels.iter().map(|c| c.0.clone()).collect();
    let freqs = yard
        .welch
        .as_ref()
        .map(|w| w.frequencies())
        .unwrap_or_default();
    let members = ensemble::run(
        |k| twin.run(Some(k)).map_err(SimulateError::twin),
        &det,
        ensemble,
        &yard,
        "base",
    )?;
    let before = mismatch::compare(yard.views(&r_before), &members, &freqs, &channels);
    let explained_by = cause::explained_by(&yard, &before, &r_before, &contrib);
    // With a noise family, the members are the simulator's member model of the extended
    // twin: the same model `--write-scenario` writes and `accomp simulate` runs.
    let written_twin = twin.written_twin(&cause);
    // The record's residual after extension had the accepted effects (and the tide groups)
    // fitted out of it; each member's passes through the same least-squares fit, with the
    // drift polynomial, and so does the record's again (the same projection for both).
    // The twin's names are kinds, with " (tidal analysis)" or "#2" added.
    let in_twin: Vec<&str> = effects
        .iter()
        .filter_map(|e| e.0.split([' ', '#']).next())
        .collect();
    let mut fitted_out = settling_cols.clone();
    fitted_out.extend(fitted_columns(&cause, &in_twin));
    let yard_after = Yardstick::new(ds)
        .with_drift_order(drift_order.order)
        .with_fitted_out(&fitted_out);
    let r_after = yard_after.detrend(&r_after);
    let members_ext = ensemble::run(
        |k| match &written_twin {
            Some(m) => m.member(k).map_err(SimulateError::twin),
            None => twin
                .extended(&quiet.effects_drawn(&cause, k))
                .run(Some(k))
                .map_err(SimulateError::twin),
        },
        &det_ext,
        ensemble,
        &yard_after,
        "extended",
    )?;
    let mut after = mismatch::compare(yard_after.views(&r_after), &members_ext, &freqs, &channels);
    let members_after = members_ext;
    // What the extended twin still gets wrong is named: unmodelled, with its likely cause.
    let nyquist_cpd = 0.5 / yard.grid.dt_s * 86_400.0;
    for m in &mut after.mismatches {
        m.unmodelled = Some(mismatch::likely_cause(m, nyquist_cpd));
    }
    lap("ensembles and comparisons");
    // 5. Gain: forward chaining; the extension's contributions refitted on each training part.
    let base_std = gain::forward_std(ds, &det, &[], &noise);
    let before_scores = Scores {
        residual_std_out_of_sample: base_std,
        residual_std_fixed_amplitudes: base_std,
    };
    let contrib_cols: Vec<Vec<f64>> = contrib.iter().map(|c| c.1.clone()).collect();
    let after_scores = Scores {
        residual_std_out_of_sample: gain::forward_std(ds, &det_ext, &contrib_cols, &noise),
        residual_std_fixed_amplitudes: gain::forward_std(ds, &det_ext, &[], &noise),
    };
    lap("forward chaining");
    if !refused.is_empty() {
        warnings.push(format!(
            "{} accepted effect(s) could not be written into the scenario: {}",
            refused.len(),
            refused
                .iter()
                .map(|(n, w)| format!("{n} ({w})"))
                .collect::<Vec<_>>()
                .join("; ")
        ));
    }
    Ok(Simulation {
        scenario,
        provenance,
        ensemble,
        before,
        after,
        before_scores,
        after_scores,
        explained_by,
        refused,
        extended_toml: ext.scenario_toml(),
        extended_path: None,
        written_twin,
        det_after: det_ext,
        members_after,
        cause,
        frequencies_hz: freqs,
        channels,
        residual_before: r_before,
        residual_after: r_after,
        warnings,
        simulator: quiet.is_simulator(),
        family,
        timing_s,
        drift: drift_order,
        drift_coefficients,
        transients,
        settling: settling_fit,
        fitted_out_independent: yard_after.fitted_out_columns(),
        fitted_out,
    })
}

/// The columns the record's residual after extension was fitted on, at the record's instants,
/// for the effects the extended twin carries (`in_twin`, their kinds): each accepted effect's
/// linear columns at its jointly fitted nonlinear parameters; when the twin's tide comes from
/// the wave-group analysis, a free cosine and sine at each group's main wave (the groups'
/// factors and phases were fitted to the record); when it carries a pressure admittance, the
/// pressure channel. Effects the twin could not express stay in both residuals.
fn fitted_columns(cause: &Discovery, in_twin: &[&str]) -> Vec<Vec<f64>> {
    use crate::discover::import::ChannelKind;
    let has = |name: &str| in_twin.contains(&name);
    let mut cols: Vec<Vec<f64>> = Vec::new();
    if let Some(joint) = &cause.selection.joint {
        for (a, c) in cause.selection.accepted.iter().zip(&joint.effect_columns) {
            if has(a.effect.name()) {
                cols.extend(c.iter().cloned());
            }
        }
    }
    let ds = &cause.dataset;
    if let (true, Ok(t)) = (has("tidal_gravity"), &cause.tidal) {
        for g in &t.groups {
            let w = 2.0 * std::f64::consts::PI * g.main_wave_cpd / 86_400.0;
            cols.push(ds.t_s.iter().map(|t| (w * t).cos()).collect());
            cols.push(ds.t_s.iter().map(|t| (w * t).sin()).collect());
        }
    }
    if has("pressure_admittance") {
        if let Some(p) = ds.channel(ChannelKind::Pressure) {
            cols.push(p.values.clone());
        }
    }
    cols
}

impl Simulation {
    /// The views of a series at the record's instants as the extended ensemble's members are
    /// seen: minus the extended twin's deterministic part, the drift polynomial of the selected
    /// order removed (`ds`: the record the comparison ran on).
    pub fn member_views(&self, ds: &Dataset, series: &[f64]) -> spectra::Views {
        let yard = Yardstick::new(ds)
            .with_drift_order(self.drift.order)
            .with_fitted_out(&self.fitted_out);
        yard.views(&yard.detrend(&sub(series, &self.det_after)))
    }
}

/// A spinner with the elapsed time on stderr for a stage without countable steps (drawn only
/// on a terminal, like the ensemble's bars).
fn stage_spinner(what: &str) -> indicatif::ProgressBar {
    let p = indicatif::ProgressBar::new_spinner();
    p.set_style(
        indicatif::ProgressStyle::with_template("{spinner} {msg} ({elapsed})")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_spinner()),
    );
    p.set_message(what.to_owned());
    p.enable_steady_tick(std::time::Duration::from_millis(200));
    p
}

/// `r` minus its least-squares fit by the tidal analysis' drift columns (cubic B-splines with
/// knots every `tidal::DRIFT_KNOT_S`, per contiguous segment).
fn without_drift(ds: &Dataset, r: &[f64]) -> Result<Vec<f64>, String> {
    let cols = super::tidal::spline_drift(&ds.t_s, &ds.segment_start, super::tidal::DRIFT_KNOT_S);
    if cols.is_empty() {
        return Err("no drift columns".into());
    }
    let rows: Vec<Vec<f64>> = (0..r.len())
        .map(|i| cols.iter().map(|c| c[i]).collect())
        .collect();
    let ls = crate::numerics::linalg::least_squares(&rows, r).map_err(|e| e.to_string())?;
    Ok((0..r.len())
        .map(|i| {
            r[i] - cols
                .iter()
                .zip(&ls.coeffs)
                .map(|(c, b)| c[i] * b)
                .sum::<f64>()
        })
        .collect())
}

fn sub(a: &[f64], b: &[f64]) -> Vec<f64> {
    a.iter().zip(b).map(|(x, y)| x - y).collect()
}

fn check_len(p: &[f64], ds: &Dataset) -> Result<(), SimulateError> {
    if p.len() != ds.len() {
        return Err(SimulateError::Length {
            got: p.len(),
            points: ds.len(),
        });
    }
    if let Some(i) = p.iter().position(|v| !v.is_finite()) {
        return Err(SimulateError::NotFinite {
            index: i,
            t_s: ds.t_s[i],
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The 95 % line of N Gaussian members (the envelope's own rule, `spectra::percentiles`)
    /// scatters by `edge_error(N)` of the half-width 1.645σ.
    #[test]
    fn the_default_ensemble_grows_as_the_record_shortens_within_its_bounds() {
        for (points, members) in [
            (50_000, 30),
            (72_000, 30),
            (25_000, 60),
            (11_765, 100),
            (0, 100),
        ] {
            assert_eq!(default_ensemble(points), members, "{points} points");
        }
    }

    #[test]
    fn the_edge_error_formula_matches_the_scatter_of_the_95_percent_line() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for n in [20usize, 40] {
            let q: Vec<f64> = (0..3000)
                .map(|_| {
                    let mut v: Vec<f64> = (0..n).map(|_| StandardNormal.sample(&mut rng)).collect();
                    spectra::percentiles(&mut v).2
                })
                .collect();
            let m = q.iter().sum::<f64>() / q.len() as f64;
            let sd = (q.iter().map(|x| (x - m).powi(2)).sum::<f64>() / q.len() as f64).sqrt();
            let measured = sd / 1.644_853_626_951_472_2;
            assert!(
                (measured / edge_error(n) - 1.0).abs() < 0.12,
                "{n} members: {measured} against {}",
                edge_error(n)
            );
        }
        assert!((edge_error(40) - 0.204).abs() < 0.01);
    }
}
