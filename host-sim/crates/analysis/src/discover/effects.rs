//! The catalogue of named physical effects. Each is a parametric extension of the design matrix:
//! linear parameters (amplitudes, coefficients, gains) are solved by least squares with the rest
//! of the model, nonlinear ones (`tau_s`, `lag_s`, `period_s`, `time_s`) by a 1-D grid followed
//! by a golden-section refinement. Physics and magnitudes: `docs/discovery.md`.

use super::import::{ChannelKind, Dataset};
use crate::sim::catalogue::{
    aging, creep, step_fraction, warmup, EffectKind, FirstOrderLag, RateOfChange, SecondOrderLag,
};
use accomp::tide::Station;

/// One effect of the catalogue, bound to a channel where it needs one.
#[derive(Debug, Clone, PartialEq)]
pub enum Effect {
    /// First-order lag between the RTD and the proof mass: column L_τ[T] − T.
    ThermalLag,
    /// Different bias on heating and cooling branches: a Preisach distribution of play
    /// operators on the temperature, Σ w_k·(T − p_{r_k}[T])/r_k with NNLS weights summing to 1
    /// (`hysteresis.rs`; `Context::hysteresis`), θ its characteristic width; without a fitted
    /// distribution, one play of half-width θ.
    ThermalHysteresis,
    /// Bias following the torquer power ∝ input² through the coil's thermal time constant: column
    /// L_τ[a²] − a² (the instantaneous part is the baseline's K2·a², per-position levels).
    SelfHeating,
    /// Exponential transient after power-on: column exp(−t/τ).
    Warmup,
    /// Logarithmic aging trend: column ln(1 + t/τ) (beside the baseline's linear drift).
    AgingDrift,
    /// A bias change: column 0 before, 1 after, crossing over a linear ramp of `duration_s`
    /// centred on the nonlinear parameter `time_s` (`duration_s` 0: the jump H(t − time_s)).
    /// The duration is fitted on [`step_durations`] (the candidate carries 0); a slow tare is one
    /// step with its duration, not several jumps along its ramp.
    Step {
        /// Transition duration, s (0: abrupt).
        duration_s: f64,
    },
    /// Solid-earth tide gravity (1 g records): column tide × unit_per_g × input.
    TidalGravity,
    /// Solid-earth tide tilt along the sensitive axis (0 g records): north and east columns.
    TidalTilt,
    /// Diurnal (solar-day) building tilt (0 g records): sin/cos of the solar day.
    BuildingTilt,
    /// Tiltmeter gain error: the nominal eq. (5) tilt term as a free column (smoothed over
    /// [`TILT_COUPLING_SMOOTHING_S`], see there).
    TiltCoupling,
    /// Coupling to an auxiliary channel through a first-order lag: column L_lag[c].
    AmbientCoupling(String),
    /// Barometric admittance: column pressure (Pa).
    PressureAdmittance,
    /// A line at a period matching no known cause: sin/cos columns.
    Periodic,
    /// A channel through a gain on its rate of change: column dc/dt (centred), the catalogue's
    /// [`RateOfChange`] run over the channel (restarted per segment).
    RateCoupling(String),
    /// The lag error of a channel through a second-order lag of τ: column L2_τ[c] − c (centred),
    /// the catalogue's [`SecondOrderLag`] run over the channel (restarted per segment).
    Lag2Coupling(String),
    /// A power-law drift: column (t − t₀)^θ in days ([`creep`]), θ the exponent.
    CreepDrift,
}

impl Effect {
    /// Its entry in the catalogue of effects (`accomp_sim::catalogue`), which the simulator reads
    /// too.
    pub fn kind(&self) -> EffectKind {
        match self {
            Effect::ThermalLag => EffectKind::ThermalLag,
            Effect::ThermalHysteresis => EffectKind::ThermalHysteresis,
            Effect::SelfHeating => EffectKind::SelfHeating,
            Effect::Warmup => EffectKind::Warmup,
            Effect::AgingDrift => EffectKind::AgingDrift,
            Effect::Step { .. } => EffectKind::Step,
            Effect::TidalGravity => EffectKind::TidalGravity,
            Effect::TidalTilt => EffectKind::TidalTilt,
            Effect::BuildingTilt => EffectKind::BuildingTilt,
            Effect::TiltCoupling => EffectKind::TiltCoupling,
            Effect::AmbientCoupling(_) => EffectKind::AmbientCoupling,
            Effect::PressureAdmittance => EffectKind::PressureAdmittance,
            Effect::Periodic => EffectKind::Periodic,
            Effect::RateCoupling(_) => EffectKind::RateCoupling,
            Effect::Lag2Coupling(_) => EffectKind::Lag2Coupling,
            Effect::CreepDrift => EffectKind::CreepDrift,
        }
    }

    /// Catalogue name.
    pub fn name(&self) -> &'static str {
        self.kind().name()
    }

    /// The channel it is bound to, if any.
    pub fn channel(&self) -> Option<&str> {
        match self {
            Effect::AmbientCoupling(c) | Effect::RateCoupling(c) | Effect::Lag2Coupling(c) => {
                Some(c)
            }
            _ => None,
        }
    }

    /// The channel whose transfer function it is, if it is one (a lag on the temperature, the
    /// pressure admittance, a coupling): one transfer function per channel is fitted, its order
    /// chosen by the criterion among these.
    pub fn coupled_channel<'a>(&'a self, ds: &'a Dataset) -> Option<&'a str> {
        match self {
            Effect::ThermalLag => ds
                .channel(ChannelKind::Temperature)
                .map(|c| c.name.as_str()),
            Effect::PressureAdmittance => {
                ds.channel(ChannelKind::Pressure).map(|c| c.name.as_str())
            }
            _ => self.channel(),
        }
    }

    /// A drift's family, if it is one (the linear drift is in the baseline).
    pub fn drift_family(&self) -> Option<&'static str> {
        match self {
            Effect::Warmup => Some("exponential"),
            Effect::AgingDrift => Some("logarithmic"),
            Effect::CreepDrift => Some("power law"),
            _ => None,
        }
    }

    /// Whether the rest of a record judges the effect by its extrapolation: a drift family or a
    /// step, whose difference from the baseline's linear drift is the level it predicts for
    /// the rest (without it, the drift's slope takes the level change and is extrapolated).
    /// Fitted on the first part, such an effect is constant or slow after the cut, and a
    /// prediction that takes in each later reading would take that level in too: forward
    /// chaining judges it by one forecast of the whole rest (`validation::forward_validate`).
    /// Every other effect is judged block by block (`validation::forward_validate_blocked`).
    pub fn judged_by_extrapolation(&self) -> bool {
        self.drift_family().is_some() || matches!(self, Effect::Step { .. })
    }

    /// Whether the effect can be accepted more than once (at other parameters).
    pub fn repeatable(&self) -> bool {
        self.kind().repeatable()
    }
}

/// Precomputed series shared by the candidates.
#[derive(Debug, Clone, Default)]
pub struct Context {
    /// Tide gravity in g at each point, if site and time are known.
    pub tide_gravity_g: Option<Vec<f64>>,
    /// Tide tilt north and east in rad, if site and time are known.
    pub tide_tilt_rad: Option<(Vec<f64>, Vec<f64>)>,
    /// Nominal eq. (5) tilt term in output units (if subtracted by the baseline).
    pub tilt_term: Option<Vec<f64>>,
    /// The Preisach distribution of the accepted `thermal_hysteresis` (set by the selection
    /// once it has fitted one): its column is then that distribution scaled to width θ; without
    /// one, a single play of half-width θ.
    pub hysteresis: Option<super::hysteresis::Preisach>,
    /// Lags found on the full-rate rows (`fullrate`), as their columns on the bins: a lag of τ
    /// shorter than a bin has no exact column on the bins themselves (the discrete lag of the
    /// block means at τ < Δt is not the block means of the lag), so its column is the block
    /// means of the lag computed at the rows' own rate. [`columns`] returns it for that effect
    /// at exactly that τ.
    pub full_rate: Vec<FastColumn>,
    /// The `rate_coupling` columns of each channel, from the channel as read
    /// ([`rate_columns`]); a channel not here takes its columns from the dataset's values.
    pub rate_columns: Vec<RateColumn>,
}

/// A channel's `rate_coupling` columns: its band-limited rate and, where it matters, the
/// timing of that rate within a row ([`super::rate`]).
#[derive(Debug, Clone, PartialEq)]
pub struct RateColumn {
    /// The channel.
    pub channel: String,
    /// The centred band-limited rate, channel unit per s.
    pub rate: Vec<f64>,
    /// The timing column (backward − centred rate), `None` when left out: its rms is below
    /// [`super::rate::TIMING_MIN_RATIO`] × the rate's.
    pub timing: Option<Vec<f64>>,
    /// rms of the timing column / rms of the rate.
    pub timing_ratio: f64,
    /// Taken on the full-rate rows and averaged into the bins (bins of fewer than
    /// [`super::fullrate::MIN_ROWS_PER_BIN`] rows), not on the bins.
    pub from_rows: bool,
}

impl RateColumn {
    /// The columns of a channel from its [`super::rate::RateColumns`], the timing kept when it
    /// matters.
    fn new(channel: &str, c: super::rate::RateColumns, from_rows: bool) -> Self {
        let timing_ratio = c.timing_ratio();
        Self {
            channel: channel.to_owned(),
            rate: c.rate,
            timing: (timing_ratio >= super::rate::TIMING_MIN_RATIO).then_some(c.timing),
            timing_ratio,
            from_rows,
        }
    }

    /// Its design columns: the rate, then the timing if fitted.
    pub fn columns(&self) -> Vec<Vec<f64>> {
        std::iter::once(self.rate.clone())
            .chain(self.timing.clone())
            .collect()
    }

    /// What the output says about how the columns were made (the fallbacks that change the
    /// coupling's fit).
    pub fn note(&self) -> String {
        format!(
            "rate_coupling ({}): rate band-limited above the channel's reading floor{}; {}",
            self.channel,
            if self.from_rows {
                " on the full-rate rows, averaged into the bins (bins of fewer than 4 rows: a \
                 rate on their uneven means would not be the rows' rate)"
            } else {
                ""
            },
            match self.timing {
                Some(_) => format!(
                    "its timing within a row fitted as position_in_row (1 = backward, \
                     0 = centred; its column {:.0} % of the rate's)",
                    100.0 * self.timing_ratio
                ),
                None => format!(
                    "position_in_row not fitted: its column is {:.1} % of the rate's (below \
                     {:.0} %), the rate taken as centred",
                    100.0 * self.timing_ratio,
                    100.0 * super::rate::TIMING_MIN_RATIO
                ),
            }
        )
    }
}

/// A lag of the full-rate stage as a column of the binned model (see [`Context::full_rate`]).
#[derive(Debug, Clone, PartialEq)]
pub struct FastColumn {
    /// `ThermalLag` or `AmbientCoupling(channel)`.
    pub effect: Effect,
    /// Its τ, s (found on the full-rate rows, held).
    pub tau_s: f64,
    /// The block means of its column at the full rate, on the bins.
    pub column: Vec<f64>,
}

impl Context {
    /// The full-rate column of `e` at `theta`, if the full-rate stage found that lag.
    pub fn full_rate_column(&self, e: &Effect, theta: f64) -> Option<&FastColumn> {
        self.full_rate
            .iter()
            .find(|f| f.effect == *e && f.tau_s == theta)
    }
}

/// Tide series at the dataset's instants (evaluated at most every 60 s and interpolated
/// linearly: the tide's fastest line, M3/M4 at ~6 h, changes by < 1e-5 of its range in 60 s).
pub fn tide_series(ds: &Dataset) -> Option<(Vec<f64>, Vec<f64>, Vec<f64>)> {
    let start = ds.start_unix_s?;
    let (lat, lon, h) = ds.site?;
    let st = Station::new(lat, lon, h).ok()?;
    let step = 60.0_f64;
    let t0 = *ds.t_s.first()?;
    let t1 = *ds.t_s.last()?;
    let n = ((t1 - t0) / step).ceil() as usize + 2;
    let nodes: Vec<_> = (0..n)
        .map(|k| st.tide_at_unix_seconds(start + t0 + k as f64 * step))
        .collect();
    let mut g = Vec::with_capacity(ds.len());
    let mut tn = Vec::with_capacity(ds.len());
    let mut te = Vec::with_capacity(ds.len());
    let mas = accomp::tide::MAS_PER_RAD;
    for &t in &ds.t_s {
        let x = (t - t0) / step;
        let k = (x.floor() as usize).min(n - 2);
        let f = x - k as f64;
        let (a, b) = (&nodes[k], &nodes[k + 1]);
        let lerp = |u: f64, v: f64| u + (v - u) * f;
        g.push(lerp(a.gravity_gs().0, b.gravity_gs().0));
        tn.push(lerp(a.tilt_north_mas, b.tilt_north_mas) / mas);
        te.push(lerp(a.tilt_east_mas, b.tilt_east_mas) / mas);
    }
    Some((g, tn, te))
}

/// The catalogue's rate (`RateOfChange`) of a channel, restarted at each segment, centred.
pub fn catalogue_rate(u: &[f64], t: &[f64], seg_start: &[bool]) -> Vec<f64> {
    transfer(u, t, seg_start, 0.0, true)
}

/// A catalogue transfer function (`RateOfChange`, `SecondOrderLag`) run over a channel,
/// restarted at each segment, centred.
fn transfer(u: &[f64], t: &[f64], seg_start: &[bool], tau_s: f64, rate: bool) -> Vec<f64> {
    centred(if rate {
        per_segment(u, t, seg_start, |r: &mut RateOfChange, t, u| r.step(t, u))
    } else {
        per_segment(u, t, seg_start, |l: &mut SecondOrderLag, t, u| {
            l.step(t, u, tau_s)
        })
    })
}

/// A catalogue operator stepped over a channel one instant at a time (`step(state, t, u)`), a
/// fresh one at each segment's start: the coupling's path is taken as settled after a gap.
fn per_segment<S: Default>(
    u: &[f64],
    t: &[f64],
    seg_start: &[bool],
    mut step: impl FnMut(&mut S, f64, f64) -> f64,
) -> Vec<f64> {
    let mut state = S::default();
    u.iter()
        .zip(t)
        .zip(seg_start)
        .map(|((&u, &t), &s)| {
            if s {
                state = S::default();
            }
            step(&mut state, t, u)
        })
        .collect()
}

/// The values of the channel a coupling names.
fn channel_values<'a>(ds: &'a Dataset, name: &str) -> Option<&'a [f64]> {
    ds.channels
        .iter()
        .find(|c| c.name == name)
        .map(|c| c.values.as_slice())
}

/// The catalogue's first-order low-pass `τ dx/dt = u − x` ([`FirstOrderLag`], exact for the
/// actual spacing) run over `u`, restarted at each segment with the current input.
pub fn lag_filter(u: &[f64], t: &[f64], seg_start: &[bool], tau_s: f64) -> Vec<f64> {
    per_segment(u, t, seg_start, |l: &mut FirstOrderLag, t, u| {
        l.step(t, u, tau_s)
    })
}

fn centred(v: Vec<f64>) -> Vec<f64> {
    let m = v.iter().sum::<f64>() / v.len().max(1) as f64;
    v.into_iter().map(|x| x - m).collect()
}

/// Log-spaced grid.
pub fn log_grid(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    if n < 2 || hi <= lo {
        return vec![lo];
    }
    (0..n)
        .map(|i| lo * (hi / lo).powf(i as f64 / (n - 1) as f64))
        .collect()
}

/// A step's column: 0 before, 1 after, a linear ramp of `duration_s` centred on `time_s` in
/// between (`duration_s` ≤ 0: the jump, 1 from `time_s` on).
pub fn step_column(t: &[f64], time_s: f64, duration_s: f64) -> Vec<f64> {
    t.iter()
        .map(|&x| step_fraction(x, time_s, duration_s))
        .collect()
}

/// Longest transition a `step` may take, s: a slower change is a drift (`aging_drift`,
/// `warmup`), not a tare.
pub const STEP_DURATION_MAX_S: f64 = 6.0 * 3600.0;

/// The grid of a step's transition durations besides 0 (abrupt): 12 log-spaced points from two
/// spacings to the shorter of an eighth of the record and [`STEP_DURATION_MAX_S`]. The best at
/// the last point is at the edge of the search (refused, said); the first is next to the
/// physical bound 0, not an edge.
pub fn step_durations(ds: &Dataset) -> Vec<f64> {
    let lo = 2.0 * ds.dt_s;
    let hi = (ds.span_s() / 8.0).min(STEP_DURATION_MAX_S);
    if hi < 2.0 * lo {
        return Vec::new();
    }
    log_grid(lo, hi, 12)
}

/// Half-width of the centred moving average applied to the `tilt_coupling` column, seconds.
///
/// A tiltmeter's own reading noise (white noise, quantisation: 0.035" rms per sample for the
/// simulator's 0.02"/0.1" tiltmeter, 0.17 µg at 0 g) is in the tilt column but not in the
/// accelerometer. Regressed as is, the column is an errors-in-variables regressor: after the
/// whitening of a flicker/random-walk residual, which weights the fast changes where that noise
/// dominates, the gain is pulled towards −1 (measured: −1.00 ± 0.05 for true gains of −0.28 and
/// +0.36). A gain error acts on the slow tilt (building and tide tilt, hours): averaging over
/// ±15 min keeps it and cuts the reading noise by √(30 min/Δt).
pub const TILT_COUPLING_SMOOTHING_S: f64 = 900.0;

/// The `rate_coupling` columns of every driver channel of `ds`, from its values `as_read` (the
/// channels before the errors-in-variables smoothing, same names and rows): the rate
/// band-limited to where the channel stands above its reading noise, and its timing within a
/// row ([`super::rate`]). With `full` (the same log's rows, unbinned) and bins of more than one
/// and fewer than [`super::fullrate::MIN_ROWS_PER_BIN`] rows, they are taken on the rows and
/// averaged into the bins: bins of 1 or 2 rows (70.8 s bins of 60 s rows) have uneven counts
/// and times, which a rate on the bins, spaced as if even, does not follow (measured: its gain
/// 6 % high), while the bin mean of the rows' rate is what the output's bin mean holds.
pub fn rate_columns(
    ds: &Dataset,
    as_read: &[super::import::Channel],
    full: Option<&Dataset>,
) -> Vec<RateColumn> {
    let rpp = ds.rows_per_point();
    let rows = full.filter(|_| rpp > 1.0 && rpp < super::fullrate::MIN_ROWS_PER_BIN);
    let driver = |c: &&super::import::Channel| {
        matches!(
            c.kind,
            ChannelKind::Temperature | ChannelKind::Pressure | ChannelKind::Other
        )
    };
    let drivers: Vec<&super::import::Channel> = as_read
        .iter()
        .filter(|c| c.values.len() == ds.t_s.len())
        .filter(driver)
        .collect();
    // The channels on all cores: each is a filter over the record's rows or points.
    crate::numerics::parallel::par_map_balanced(&drivers, |c| {
        let on_rows = rows.and_then(|f| {
            let ch = f.channels.iter().find(|r| r.name == c.name)?;
            let r = super::rate::band_limited_rates(&ch.values, &f.t_s, &f.segment_start);
            Some(super::rate::RateColumns {
                rate: super::import::block_means_like(f, ds, &r.rate)?,
                timing: super::import::block_means_like(f, ds, &r.timing)?,
            })
        });
        match on_rows {
            Some(r) => RateColumn::new(&c.name, r, true),
            None => RateColumn::new(
                &c.name,
                super::rate::band_limited_rates(&c.values, &ds.t_s, &ds.segment_start),
                false,
            ),
        }
    })
}

/// Centred moving average over ±`half_window_s` inside each segment (the window shrinks at the
/// segment's ends): the baseline's running mean, the same that smooths the tilt term.
pub use super::baseline::centred_mean as moving_average;

/// The candidates applicable to a dataset, and the catalogue entries that are not, with why.
pub fn candidates(
    ds: &Dataset,
    ctx: &Context,
    tilt_subtracted: bool,
) -> (Vec<Effect>, Vec<(String, String)>) {
    let mut yes = Vec::new();
    let mut no = Vec::new();
    let mut say = |e: &str, why: &str| no.push((e.to_owned(), why.to_owned()));
    let temp = ds.channel(ChannelKind::Temperature);
    let temp_varies = temp.is_some_and(|c| super::baseline::std(&c.values) > 1e-6);
    if temp_varies {
        yes.push(Effect::ThermalLag);
        if temp.is_some_and(|c| super::hysteresis::width_range_c(&c.values).is_some()) {
            yes.push(Effect::ThermalHysteresis);
        } else {
            say(
                "thermal_hysteresis",
                "the temperature never moves by more than a few times its reading noise",
            );
        }
    } else {
        say("thermal_lag", "no varying temperature channel");
        say("thermal_hysteresis", "no varying temperature channel");
    }
    match ds.changing_input() {
        Some(_) => yes.push(Effect::SelfHeating),
        None => say("self_heating", "no changing input_g channel"),
    }
    yes.push(Effect::Warmup);
    yes.push(Effect::AgingDrift);
    yes.push(Effect::Step { duration_s: 0.0 });
    let one_g = ds.is_one_g();
    match (&ctx.tide_gravity_g, ds.unit_per_g, one_g) {
        (Some(_), Some(_), true) => yes.push(Effect::TidalGravity),
        (None, _, _) => say(
            "tidal_gravity",
            "no start_utc or site (latitude_deg, longitude_deg)",
        ),
        (_, None, _) => say("tidal_gravity", "output unit per g unknown"),
        _ => say("tidal_gravity", "not a 1 g record (input_g metadata)"),
    }
    if ds.input_g.is_some() && !one_g && ds.unit_per_g.is_some() {
        if ctx.tide_tilt_rad.is_some() {
            yes.push(Effect::TidalTilt);
        } else {
            say("tidal_tilt", "no start_utc or site");
        }
        yes.push(Effect::BuildingTilt);
    } else {
        say(
            "tidal_tilt",
            "a 0 g effect: needs input_g ≈ 0 and a known output unit per g",
        );
        say(
            "building_tilt",
            "a 0 g effect: needs input_g ≈ 0 and a known output unit per g",
        );
    }
    if tilt_subtracted && ctx.tilt_term.is_some() {
        yes.push(Effect::TiltCoupling);
    } else {
        say(
            "tilt_coupling",
            "no tilt channel, or the tilt gain is already fitted (unit per g unknown)",
        );
    }
    let ambient =
        moving_channel_couplings(ds, &[ChannelKind::Other], 0.0, &[Effect::AmbientCoupling]);
    if ambient.is_empty() {
        say(
            "ambient_coupling",
            "no auxiliary channel besides temperature, tilt, pressure, input",
        );
    }
    yes.extend(ambient);
    match ds.channel(ChannelKind::Pressure) {
        Some(_) => yes.push(Effect::PressureAdmittance),
        None => say("pressure_admittance", "no pressure channel"),
    }
    yes.push(Effect::Periodic);
    // Every channel that moves is a driver: the transfer functions the fixed entries above do
    // not hold (a gain on its rate, a second-order lag), one per channel, the order chosen by
    // the criterion against the entries above. The tilt acts through eq. (5) (`tilt_coupling`).
    let drivers = moving_channel_couplings(
        ds,
        &[
            ChannelKind::Temperature,
            ChannelKind::Pressure,
            ChannelKind::Other,
        ],
        1e-9,
        &[Effect::RateCoupling, Effect::Lag2Coupling],
    );
    if drivers.is_empty() {
        say(
            "rate_coupling",
            "no temperature, pressure or auxiliary channel that moves",
        );
        say(
            "lag2_coupling",
            "no temperature, pressure or auxiliary channel that moves",
        );
    }
    yes.extend(drivers);
    yes.push(Effect::CreepDrift);
    (yes, no)
}

/// The couplings `make` of every channel of one of the `kinds` whose readings scatter by more
/// than `min_std` (a channel that does not move cannot be told from the offset), channel by
/// channel in the dataset's order.
fn moving_channel_couplings(
    ds: &Dataset,
    kinds: &[ChannelKind],
    min_std: f64,
    make: &[fn(String) -> Effect],
) -> Vec<Effect> {
    ds.channels
        .iter()
        .filter(|c| kinds.contains(&c.kind) && super::baseline::std(&c.values) > min_std)
        .flat_map(|c| make.iter().map(|m| m(c.name.clone())))
        .collect()
}

/// The 1-D grid of the nonlinear parameter (empty for purely linear effects).
pub fn grid(e: &Effect, ds: &Dataset) -> Vec<f64> {
    let span = ds.span_s().max(10.0 * ds.dt_s);
    let dt = ds.dt_s;
    match e {
        Effect::ThermalLag => log_grid(2.0 * dt, span / 5.0, 24),
        // The coil's time constant: from two samples to a fifth of the record (a longer lag is
        // a slow trend, not a response to the programme).
        Effect::SelfHeating => log_grid(2.0 * dt, span / 5.0, 24),
        // Play half-width in °C, from 3 × the temperature's reading noise to a quarter of its
        // range (`hysteresis::width_range_c`); 24 points: the look-elsewhere charge 2 ln 24
        // stays below the BIC's ln n for any record this long.
        Effect::ThermalHysteresis => ds
            .channel(ChannelKind::Temperature)
            .and_then(|c| super::hysteresis::width_range_c(&c.values))
            .map_or_else(Vec::new, |(lo, hi)| log_grid(lo, hi, 24)),
        Effect::Warmup => log_grid(3.0 * dt, span / 3.0, 24),
        Effect::AgingDrift => log_grid(span / 1000.0, span * 3.0, 24),
        Effect::Lag2Coupling(_) => log_grid(2.0 * dt, span / 10.0, 20),
        // Exponents from a settling t^0.2 to a t^5 acceleration; 1 is the baseline's drift.
        Effect::CreepDrift => log_grid(0.2, 5.0, 24),
        Effect::AmbientCoupling(_) => {
            let mut g = vec![0.0];
            g.extend(log_grid(2.0 * dt, span / 10.0, 16));
            g
        }
        _ => Vec::new(),
    }
}

/// Design columns of an effect at nonlinear parameter `theta` (NaN when not applicable).
pub fn columns(e: &Effect, ds: &Dataset, ctx: &Context, theta: f64) -> Vec<Vec<f64>> {
    let t = &ds.t_s;
    let t0 = t.first().copied().unwrap_or(0.0);
    let seg = &ds.segment_start;
    let temp = || {
        ds.channel(ChannelKind::Temperature)
            .map(|c| c.values.clone())
    };
    let u = ds.unit_per_g.unwrap_or(1.0);
    if let Some(f) = ctx.full_rate_column(e, theta) {
        return vec![f.column.clone()];
    }
    match e {
        Effect::ThermalLag => temp()
            .map(|tc| {
                let l = lag_filter(&tc, t, seg, theta);
                vec![l.iter().zip(&tc).map(|(a, b)| a - b).collect()]
            })
            .unwrap_or_default(),
        Effect::ThermalHysteresis => temp()
            .map(|tc| {
                vec![match &ctx.hysteresis {
                    Some(p) => p.lagged_column(&tc, t, seg, theta),
                    None => super::hysteresis::branch(&tc, theta),
                }]
            })
            .unwrap_or_default(),
        // Torquer power ∝ I² ∝ a²: the coil temperature and with it the bias follow a² through a
        // first-order lag; the step part a² is collinear with K2·a² (the baseline's levels), so
        // only the lag error carries the effect. Restarted per segment at the current input (the
        // coil is taken as settled at the start of a segment).
        Effect::SelfHeating => ds
            .changing_input()
            .map(|a| {
                let a2: Vec<f64> = a.iter().map(|x| x * x).collect();
                let l = lag_filter(&a2, t, seg, theta);
                vec![l.iter().zip(&a2).map(|(l, u)| l - u).collect()]
            })
            .unwrap_or_default(),
        Effect::Warmup => vec![t.iter().map(|x| warmup(x - t0, theta)).collect()],
        Effect::AgingDrift => vec![t.iter().map(|x| aging(x - t0, theta)).collect()],
        Effect::Step { duration_s } => vec![step_column(t, theta, *duration_s)],
        Effect::TidalGravity => ctx
            .tide_gravity_g
            .as_ref()
            .map(|g| {
                // The tide acts along the vertical: projected on the input axis, sign(input) on
                // a static 1 g test, the row's input on a head programme.
                let s = u * ds.input_g.unwrap_or(1.0).signum();
                vec![match ds.changing_input() {
                    Some(a) => g.iter().zip(a).map(|(v, a)| v * a * u).collect(),
                    None => g.iter().map(|v| v * s).collect(),
                }]
            })
            .unwrap_or_default(),
        Effect::TidalTilt => ctx
            .tide_tilt_rad
            .as_ref()
            .map(|(n, ea)| {
                vec![
                    n.iter().map(|v| v * u).collect(),
                    ea.iter().map(|v| v * u).collect(),
                ]
            })
            .unwrap_or_default(),
        Effect::BuildingTilt => {
            let start = ds.start_unix_s.unwrap_or(0.0);
            let w = 2.0 * std::f64::consts::PI / 86_400.0;
            vec![
                t.iter().map(|x| (w * (start + x)).sin()).collect(),
                t.iter().map(|x| (w * (start + x)).cos()).collect(),
            ]
        }
        Effect::TiltCoupling => ctx
            .tilt_term
            .as_ref()
            .map(|v| vec![moving_average(v, t, seg, TILT_COUPLING_SMOOTHING_S)])
            .unwrap_or_default(),
        Effect::AmbientCoupling(name) => ds
            .channels
            .iter()
            .find(|c| &c.name == name)
            .map(|c| vec![centred(lag_filter(&c.values, t, seg, theta))])
            .unwrap_or_default(),
        Effect::PressureAdmittance => ds
            .channel(ChannelKind::Pressure)
            .map(|c| vec![centred(c.values.clone())])
            .unwrap_or_default(),
        Effect::Periodic => {
            let w = 2.0 * std::f64::consts::PI / theta;
            vec![
                t.iter().map(|x| (w * x).sin()).collect(),
                t.iter().map(|x| (w * x).cos()).collect(),
            ]
        }
        Effect::RateCoupling(name) => match ctx.rate_columns.iter().find(|c| &c.channel == name) {
            Some(c) => c.columns(),
            None => channel_values(ds, name)
                .map(|v| {
                    RateColumn::new(name, super::rate::band_limited_rates(v, t, seg), false)
                        .columns()
                })
                .unwrap_or_default(),
        },
        Effect::Lag2Coupling(name) => channel_values(ds, name)
            .map(|v| {
                let l2 = transfer(v, t, seg, theta, false);
                vec![centred(l2.iter().zip(v).map(|(l, c)| l - c).collect())]
            })
            .unwrap_or_default(),
        Effect::CreepDrift => vec![t.iter().map(|x| creep(x - t0, theta)).collect()],
    }
}

/// A parameter value with its 1-σ uncertainty (NaN when not estimated).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Param {
    /// Value.
    pub value: f64,
    /// 1-σ uncertainty.
    pub sigma: f64,
}

/// Named parameters of a fitted effect, from its nonlinear parameter, its linear coefficients
/// and their standard errors. Keys exactly as the catalogue in the issue.
pub fn parameters(
    e: &Effect,
    ds: &Dataset,
    theta: Param,
    beta: &[f64],
    se: &[f64],
) -> Vec<(String, Param)> {
    let p = |v: f64, s: f64| Param { value: v, sigma: s };
    let b0 = beta.first().copied().unwrap_or(f64::NAN);
    let s0 = se.first().copied().unwrap_or(f64::NAN);
    let amp2 = || {
        let (a, b) = (beta[0], beta[1]);
        let r = a.hypot(b);
        let sr = if r > 0.0 {
            ((a * se[0]).powi(2) + (b * se[1]).powi(2)).sqrt() / r
        } else {
            f64::NAN
        };
        (r, sr, b.atan2(a), if r > 0.0 { sr / r } else { f64::NAN })
    };
    let mut out: Vec<(String, Param)> = match e {
        Effect::ThermalLag => vec![("tau_s".into(), theta), ("coefficient".into(), p(b0, s0))],
        Effect::ThermalHysteresis => vec![
            ("half_width".into(), p(b0, s0)),
            ("play_half_width_c".into(), theta),
        ],
        Effect::SelfHeating => vec![("tau_s".into(), theta), ("coefficient".into(), p(b0, s0))],
        Effect::Warmup => vec![("tau_s".into(), theta), ("amplitude".into(), p(b0, s0))],
        Effect::AgingDrift => vec![("tau_s".into(), theta), ("amplitude".into(), p(b0, s0))],
        Effect::Step { duration_s } => vec![
            ("time_s".into(), theta),
            ("size".into(), p(b0, s0)),
            // Its σ is not estimated: the duration is the best of a grid (refined), 0 = abrupt.
            ("duration_s".into(), p(*duration_s, f64::NAN)),
        ],
        Effect::TidalGravity => vec![("amplitude_factor".into(), p(b0, s0))],
        Effect::TidalTilt => {
            let (r, sr, ph, sph) = amp2();
            vec![
                ("amplitude_factor".into(), p(r, sr)),
                ("azimuth_deg".into(), p(ph.to_degrees(), sph.to_degrees())),
            ]
        }
        Effect::BuildingTilt | Effect::Periodic => {
            let (r, sr, ph, sph) = amp2();
            let mut v = vec![
                ("amplitude".into(), p(r, sr)),
                ("phase_rad".into(), p(ph, sph)),
            ];
            if matches!(e, Effect::Periodic) {
                v.insert(0, ("period_s".into(), theta));
            }
            v
        }
        Effect::TiltCoupling => vec![("gain".into(), p(b0, s0))],
        Effect::AmbientCoupling(_) => {
            vec![("coefficient".into(), p(b0, s0)), ("lag_s".into(), theta)]
        }
        Effect::PressureAdmittance => vec![("coefficient".into(), p(b0, s0))],
        // With its timing column: the gain at position p in the row, b·(rate + p·timing), so
        // p = β₁/β₀; the two columns are orthogonal (odd and even in time), so its σ is the
        // ratio's without a covariance term.
        Effect::RateCoupling(_) => {
            let mut v = vec![("coefficient".into(), p(b0, s0))];
            if let (Some(&b1), Some(&s1)) = (beta.get(1), se.get(1)) {
                let pos = b1 / b0;
                v.push((
                    "position_in_row".into(),
                    p(pos, (s1 * s1 + (pos * s0).powi(2)).sqrt() / b0.abs()),
                ));
            }
            v
        }
        Effect::Lag2Coupling(_) => vec![("tau_s".into(), theta), ("coefficient".into(), p(b0, s0))],
        Effect::CreepDrift => vec![("exponent".into(), theta), ("amplitude".into(), p(b0, s0))],
    };
    // Output-unit amplitudes also in g when the unit is known.
    if let Some(u) = ds.unit_per_g {
        let extra: Vec<(String, Param)> = out
            .iter()
            .filter(|(k, _)| {
                matches!(
                    k.as_str(),
                    "amplitude" | "size" | "half_width" | "coefficient"
                )
            })
            .filter(|_| !matches!(e, Effect::TiltCoupling | Effect::TidalGravity))
            .map(|(k, v)| (format!("{k}_g"), p(v.value / u, v.sigma / u)))
            .collect();
        out.extend(extra);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The discovery names what the catalogue lists, with the catalogue's parameters in its
    /// order, for every effect it looks for: what the simulator injects under the same names.
    #[test]
    fn every_effect_reports_the_catalogue_parameters() {
        let all = [
            Effect::ThermalLag,
            Effect::ThermalHysteresis,
            Effect::SelfHeating,
            Effect::Warmup,
            Effect::AgingDrift,
            Effect::Step { duration_s: 0.0 },
            Effect::TidalGravity,
            Effect::TidalTilt,
            Effect::BuildingTilt,
            Effect::TiltCoupling,
            Effect::AmbientCoupling("room_c".into()),
            Effect::PressureAdmittance,
            Effect::Periodic,
            Effect::RateCoupling("room_c".into()),
            Effect::Lag2Coupling("room_c".into()),
            Effect::CreepDrift,
        ];
        let discovered: Vec<EffectKind> = EffectKind::ALL
            .into_iter()
            .filter(|k| k.discovered())
            .collect();
        assert_eq!(all.iter().map(Effect::kind).collect::<Vec<_>>(), discovered);
        let ds = Dataset {
            unit_per_g: None,
            ..Dataset::test_g(vec![0.0, 1.0], vec![0.0, 0.0], 1.0)
        };
        let theta = Param {
            value: 1.0,
            sigma: 0.1,
        };
        for e in &all {
            let named = parameters(e, &ds, theta, &[1.0, 1.0], &[0.1, 0.1]);
            // A rate coupling's timing within the row is the discovery's own (the simulator's
            // rate is a backward difference, its position fixed).
            let keys: Vec<&str> = named
                .iter()
                .map(|(k, _)| k.as_str())
                .filter(|k| !(*k == "position_in_row" && matches!(e, Effect::RateCoupling(_))))
                .collect();
            assert_eq!(keys, e.kind().parameter_names(), "{}", e.name());
        }
    }

    /// A rate coupling with its timing column reports the gain at its position in the row,
    /// p = β₁/β₀ with the ratio's σ (orthogonal columns); with the rate alone, no position.
    #[test]
    fn a_rate_coupling_reports_its_position_in_the_row_from_its_two_gains() {
        let ds = Dataset {
            unit_per_g: None,
            ..Dataset::test_g(vec![0.0, 1.0], vec![0.0, 0.0], 1.0)
        };
        let e = Effect::RateCoupling("temperature_c".into());
        let theta = Param {
            value: f64::NAN,
            sigma: f64::NAN,
        };
        let two = parameters(&e, &ds, theta, &[2.0, 1.8], &[0.1, 0.2]);
        let pos = two
            .iter()
            .find(|(k, _)| k == "position_in_row")
            .map(|(_, p)| *p)
            .expect("position_in_row");
        assert!((pos.value - 0.9).abs() < 1e-12);
        let want = (0.2f64.powi(2) + (0.9f64 * 0.1).powi(2)).sqrt() / 2.0;
        assert!((pos.sigma - want).abs() < 1e-12, "{}", pos.sigma);
        let one = parameters(&e, &ds, theta, &[2.0], &[0.1]);
        assert!(one.iter().all(|(k, _)| k != "position_in_row"));
    }

    #[test]
    fn lag_filter_reaches_63_percent_after_one_time_constant() {
        let t: Vec<f64> = (0..=100).map(f64::from).collect();
        let mut u = vec![1.0; 101];
        u[0] = 0.0;
        let mut seg = vec![false; 101];
        seg[0] = true;
        let y = lag_filter(&u, &t, &seg, 10.0);
        // 1 − e^{−1} = 0.632 at t = τ (input stepped at t = 0+).
        assert!((y[10] - 0.632_12).abs() < 1e-4, "{}", y[10]);
    }

    #[test]
    fn moving_average_keeps_a_ramp_and_cuts_white_noise_by_the_window_length() {
        let n = 2000;
        let t: Vec<f64> = (0..n).map(|i| 60.0 * i as f64).collect();
        let mut seg = vec![false; n];
        seg[0] = true;
        seg[1000] = true;
        // A ramp is kept exactly where the window is whole (±15 points of 60 s).
        let ramp: Vec<f64> = t.iter().map(|x| 1e-3 * x).collect();
        let m = moving_average(&ramp, &t, &seg, 900.0);
        assert!((m[500] - ramp[500]).abs() < 1e-9 && (m[1500] - ramp[1500]).abs() < 1e-9);
        // At a segment start only that segment's points count: the mean of points 1000..=1015.
        assert!((m[1000] - 1e-3 * 60.0 * 1007.5).abs() < 1e-9, "{}", m[1000]);
        // Alternating ±1 (the fastest white-noise component) averages to ±1/31 over 31 points.
        let alt: Vec<f64> = (0..n)
            .map(|i| if i % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let a = moving_average(&alt, &t, &seg, 900.0);
        assert!((a[500].abs() - 1.0 / 31.0).abs() < 1e-12, "{}", a[500]);
    }

    #[test]
    fn self_heating_column_is_the_lag_error_of_the_squared_input_after_a_head_move() {
        use crate::discover::import::Channel;
        let n = 200;
        let t: Vec<f64> = (0..n).map(|i| 10.0 * f64::from(i)).collect();
        // +1 g for 100 rows, then 0 g: a² drops from 1 to 0 at t = 1000 s.
        let a: Vec<f64> = (0..n).map(|i| if i < 100 { 1.0 } else { 0.0 }).collect();
        let ds = Dataset {
            channels: vec![Channel {
                name: "input_g".into(),
                kind: ChannelKind::Input,
                values: a,
            }],
            ..Dataset::test_g(t, vec![0.0; n as usize], 10.0)
        };
        let c = columns(&Effect::SelfHeating, &ds, &Context::default(), 300.0);
        // Settled before the move; after it the coil cools as e^{−(t − 990)/τ}: the filter holds
        // each sample's input over the interval before it, so the move is dated to the last
        // sample at the old position (at most one interval early).
        assert_eq!(c[0][99], 0.0);
        let want = (-(1300.0 - 990.0) / 300.0_f64).exp();
        assert!((c[0][130] - want).abs() < 1e-12, "{}", c[0][130]);
        let (yes, _) = candidates(&ds, &Context::default(), false);
        assert!(yes.contains(&Effect::SelfHeating));
    }
}
