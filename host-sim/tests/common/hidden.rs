//! Shared by the hidden-effect tests (`discover_hidden*.rs`): how large a hidden effect is,
//! measured the way detection theory measures it.
//!
//! "A magnitude near the noise level" is the **matched-filter signal-to-noise ratio**: the
//! detection statistic an ideal detector would have if it knew the shape of the effect and the
//! true noise, after the nuisance columns of the baseline (offset, drift, temperature
//! polynomial…) have absorbed what they can:
//!
//!   SNR² = ‖P⊥ W s‖², W the whitening by the true noise covariance, P⊥ the projection
//!   orthogonal to the whitened nuisance columns.
//!
//! This puts every effect on the same footing. The earlier definition (amplitude over the Allan
//! deviation at the effect's own time scale) made a start-of-record transient of "SNR 3" carry
//! an ideal χ² of ≈ 10 while a periodic line of "SNR 3" carried hundreds, so per-effect rates
//! measured the definition rather than the tool.
//!
//! The noise is the simulator's sensor noise as documented in `sim/noise.rs` (written here
//! again from that description, not called): white of Allan deviation w at 1 s, flicker as a
//! sum of stationary AR(1) components with correlation times Δ·r^k up to 10 × the run
//! (r = √10), each of variance f²·ln r/(2 ln 2), and a random walk K per √s starting at zero.
//! That is a linear state-space model, so W is the Kalman filter's normalised innovations.

// Each test crate uses a different subset of this module.
#![allow(dead_code)]

use accomp_host::discover::effects::Param;
use accomp_host::discover::import::{dataset_from_log, Dataset, DatasetOptions};
use accomp_host::discover::select::{self, Accepted};
use accomp_host::discover::{self as disc, Discovery};
use accomp_host::log::Log;
use accomp_host::sim::noise::AllanParams;
use accomp_host::sim::scenario::Scenario;
use accomp_host::sim::{Sample, Simulator};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// Switches off the catalogue effects a preset has built in — the tide, the proof-mass thermal
/// lag, the ADC reference tempco (an ambient coupling through the board temperature) — so that
/// "no hidden effect" in a simulated log means none.
pub fn quiet_station(sc: &mut Scenario) {
    sc.tide.enabled = false;
    sc.thermostat.proof_mass_lag_s = 1.0e-3;
    sc.adc.ads1262.vref_tempco_ppm_per_c = 0.0;
}

/// A station simulated to its end.
pub struct StationRun {
    /// Its scale factor K1 at the thermostat's set point (output unit per g).
    pub k1: f64,
    /// The log metadata the simulator writes.
    pub meta: Vec<(String, String)>,
    /// Every sample, in order.
    pub samples: Vec<Sample>,
}

/// Simulates scenario `sc` with `seed` to its end.
pub fn run_station(sc: &Scenario, seed: u64) -> StationRun {
    let mut sim = Simulator::new(sc, seed).expect("simulator");
    StationRun {
        k1: sim.scale_factor_at_setpoint(),
        meta: sim.metadata(seed),
        samples: run(&mut sim),
    }
}

/// Runs the simulator to its end: every sample, in order.
pub fn run(sim: &mut Simulator) -> Vec<Sample> {
    (0..sim.samples())
        .map(|_| sim.step().expect("step"))
        .collect()
}

/// One field of every sample.
pub fn column(samples: &[Sample], field: impl FnMut(&Sample) -> f64) -> Vec<f64> {
    samples.iter().map(field).collect()
}

/// The record's start (Unix seconds) from the simulator's metadata (`start_utc`).
pub fn start_unix_s(meta: &[(String, String)]) -> f64 {
    meta.iter()
        .find(|(k, _)| k == "start_utc")
        .and_then(|(_, v)| accomp_host::discover::import::parse_utc(v))
        .expect("start_utc")
}

/// An accepted effect's parameter `key` (value and σ).
pub fn param(a: &Accepted, key: &str) -> Option<Param> {
    a.params.iter().find(|(k, _)| k == key).map(|(_, p)| *p)
}

/// The accepted steps as (time_s, size, σ of the size).
pub fn accepted_steps(d: &Discovery) -> Vec<(f64, f64, f64)> {
    d.selection
        .accepted
        .iter()
        .filter(|a| a.effect.name() == "step")
        .map(|a| {
            let size = param(a, "size").expect("a step has a size");
            let time = param(a, "time_s").expect("a step has a time");
            (time.value, size.value, size.sigma)
        })
        .collect()
}

/// The value of an accepted effect's parameter (NaN when it has no such key).
pub fn param_value(a: &Accepted, key: &str) -> f64 {
    a.params
        .iter()
        .find(|(k, _)| k == key)
        .map_or(f64::NAN, |(_, p)| p.value)
}

/// ±1 with equal probability.
pub fn sign(rng: &mut ChaCha8Rng) -> f64 {
    if rng.random::<bool>() {
        1.0
    } else {
        -1.0
    }
}

/// The log's scale factor K1 (V/g) from its metadata, 1 when absent (output already in g).
pub fn k1_of(log: &Log) -> f64 {
    log.meta_f64("scale_factor_v_per_g")
        .ok()
        .flatten()
        .unwrap_or(1.0)
}

/// Why the discovery refused the effect `name` (empty when it did not refuse it).
pub fn refusal(d: &Discovery, name: &str) -> String {
    d.selection
        .refused
        .iter()
        .find(|(n, _)| n == name)
        .map(|(_, why)| why.clone())
        .unwrap_or_default()
}

/// Runs `accomp discover` on a log with default options, told nothing: the dataset as
/// imported and the discovery.
pub fn discover_blind(log: &Log) -> (Dataset, Discovery) {
    let ds = dataset_from_log(log, &DatasetOptions::default()).expect("dataset");
    let d = disc::discover(ds.clone(), None, &select::Config::default()).expect("discover");
    (ds, d)
}

/// Names of the accepted effects, in order.
pub fn accepted_names(d: &Discovery) -> Vec<String> {
    d.selection
        .accepted
        .iter()
        .map(|a| a.effect.name().to_owned())
        .collect()
}

/// The accepted effects with their parameters, for the test's log.
pub fn accepted_with_params(d: &Discovery) -> Vec<String> {
    d.selection
        .accepted
        .iter()
        .map(|a| {
            let p: Vec<String> = a
                .params
                .iter()
                .map(|(k, v)| format!("{k}={:.3e}", v.value))
                .collect();
            format!("{} [{}]", a.effect.name(), p.join(" "))
        })
        .collect()
}

/// The accepted effect named `name`, quietly (see [`find_named`]).
pub fn accepted<'d>(d: &'d Discovery, name: &str) -> Option<&'d Accepted> {
    d.selection
        .accepted
        .iter()
        .find(|a| a.effect.name() == name)
}

/// Asserts a lag of the temperature was named with the delay `true_delay_s` (within a factor
/// e^0.5) and the coefficient `true_coefficient` (within 40 %): the delay of the fitted transfer
/// function is τ of a `thermal_lag`, 2τ of a `lag2_coupling` of two equal stages.
pub fn assert_temperature_lag(d: &Discovery, true_delay_s: f64, true_coefficient: f64) {
    let (a, delay) = match (accepted(d, "thermal_lag"), accepted(d, "lag2_coupling")) {
        (Some(a), _) => (a, param_value(a, "tau_s")),
        (None, Some(a)) => {
            assert_eq!(a.effect.channel(), Some("temperature_c"));
            (a, 2.0 * param_value(a, "tau_s"))
        }
        _ => panic!(
            "no lag of the temperature named: {:?}; refused {:?}",
            accepted_with_params(d),
            d.selection.refused
        ),
    };
    assert!(
        (delay / true_delay_s).ln().abs() < 0.5,
        "delay {delay:.0} s against {true_delay_s:.0} s"
    );
    let c = param_value(a, "coefficient");
    assert!(
        (c / true_coefficient - 1.0).abs() < 0.4,
        "coefficient {c:.3e} against {true_coefficient:.3e}"
    );
}

/// The accepted effect named `name`; when there is none (and something was hidden), prints
/// the last round's ΔBIC so a miss can be read from the log.
pub fn find_named<'d>(d: &'d Discovery, name: &str) -> Option<&'d Accepted> {
    let hit = d
        .selection
        .accepted
        .iter()
        .find(|a| a.effect.name() == name);
    if hit.is_none() && name != "none" {
        eprintln!("    last round (ΔBIC): {:?}", d.selection.last_round);
    }
    hit
}

/// Detection tally of a hidden-effect test: named, parameters within tolerance and (where the
/// test checks it) out-of-sample gain close to the true-parameter gain, overall and per effect.
#[derive(Default)]
pub struct Tally {
    /// Draws.
    pub draws: usize,
    /// Hidden effect named.
    pub named: usize,
    /// Named with its parameters within tolerance.
    pub params: usize,
    /// Named with its gain close.
    pub gains: usize,
    /// Per effect: (draws, named).
    pub per_effect: std::collections::BTreeMap<String, (usize, usize)>,
}

impl Tally {
    /// Counts one draw of effect `name`.
    pub fn add(&mut self, name: &str, named: bool, params_ok: bool, gain_ok: bool) {
        self.draws += 1;
        self.named += usize::from(named);
        self.params += usize::from(named && params_ok);
        self.gains += usize::from(named && gain_ok);
        let e = self.per_effect.entry(name.to_owned()).or_default();
        e.0 += 1;
        e.1 += usize::from(named);
    }

    /// Prints the per-effect counts and the rate line `<label> DETECTION RATE k/n …` (with the
    /// gain count when the test checks gains).
    pub fn print(&self, label: &str, with_gain: bool) {
        for (name, (n, k)) in &self.per_effect {
            eprintln!("{label} {name}: named {k}/{n}");
        }
        let gain = if with_gain {
            format!(", gain close {}", self.gains)
        } else {
            String::new()
        };
        eprintln!(
            "{label} DETECTION RATE {}/{} (parameters within tolerance {}{gain})",
            self.named, self.draws, self.params
        );
    }
}

/// What one hidden-effect draw came to: the effect as drawn, whether it was named, whether its
/// parameters (and, where the test checks it, its gain) came out within tolerance, and all that
/// was accepted.
pub struct Outcome<H> {
    /// The hidden effect with its drawn parameters.
    pub hidden: H,
    /// The discovery named it.
    pub named: bool,
    /// Named with its parameters within tolerance.
    pub params_ok: bool,
    /// Named with its out-of-sample gain close to the true-parameter gain (`None`: not checked).
    pub gain_ok: Option<bool>,
    /// Names of all accepted effects.
    pub accepted: Vec<String>,
}

/// Runs `draws` hidden-effect draws from `rng` — each an effect and its SNR (`draw`), then the
/// seed of its log — through `run_one`, prints every outcome and the rates under `label`, and
/// returns the tally.
pub fn tally_draws<H: std::fmt::Debug>(
    label: &str,
    rng: &mut ChaCha8Rng,
    draws: usize,
    mut draw: impl FnMut(&mut ChaCha8Rng) -> (H, f64),
    mut run_one: impl FnMut(&H, f64, u64) -> Outcome<H>,
    name: impl Fn(&H) -> &'static str,
) -> Tally {
    let mut tally = Tally::default();
    let mut with_gain = false;
    for i in 0..draws {
        let (h, snr) = draw(rng);
        let seed = rng.random::<u64>();
        let o = run_one(&h, snr, seed);
        let gain = o.gain_ok.map_or(String::new(), |g| format!(" gain={g}"));
        eprintln!(
            "{label} draw {i}: hidden {:?} at SNR {snr:.1}: accepted {:?} named={} params={}{gain}",
            o.hidden, o.accepted, o.named, o.params_ok
        );
        with_gain |= o.gain_ok.is_some();
        tally.add(
            name(&o.hidden),
            o.named,
            o.params_ok,
            o.gain_ok.unwrap_or(false),
        );
    }
    tally.print(label, with_gain);
    tally
}

/// Bouc–Wen hysteresis of a temperature series, a differential model of stick–slip (used for
/// friction, joints and structural hysteresis), not a sum of play operators (the detector's
/// Preisach model):
///
/// ```text
/// dz/dT = (1/w)·(1 − |z|ⁿ·(β·sgn(dT·z) + 1 − β)),   z(0) = 0,   |z| ≤ 1
/// ```
///
/// rate-independent (dz ∝ dT), saturating at z = ±1 (heating / cooling branch), leaving a
/// branch with slope (1/w)(1 + (2β − 1)|z|ⁿ) — every reversal, however small, moves z (the
/// controller's mK jitter makes it chatter, which a play wider than the jitter does not) —
/// and approaching the other branch with a shape set by the exponent n (n = 1: exponential in
/// temperature, large n: nearly linear then sharp). Integrated along the series with sub-steps
/// of at most 2 % of w.
pub fn bouc_wen(temp: &[f64], w: f64, n: f64, beta: f64) -> Vec<f64> {
    let mut z: f64 = 0.0;
    let mut prev = temp.first().copied().unwrap_or(0.0);
    temp.iter()
        .map(|&x| {
            let d = x - prev;
            prev = x;
            let m = ((d.abs() / (0.02 * w)).ceil() as usize).max(1);
            let h = d / m as f64;
            for _ in 0..m {
                let s = if h * z >= 0.0 { 1.0 } else { -1.0 };
                z += h / w * (1.0 - z.abs().powf(n) * (beta * s + 1.0 - beta));
                z = z.clamp(-1.0, 1.0);
            }
            z
        })
        .collect()
}

/// Bouc–Wen parameters (transition width w °C, exponent n, β) drawn from ONE value of `rng`
/// (a sub-generator seeded by it), so the draws after it stay as they were: w 0.03–0.1 °C,
/// n 1–3, β 0.5–0.9.
pub fn draw_bouc_wen(rng: &mut ChaCha8Rng) -> (f64, f64, f64) {
    use rand::SeedableRng;
    let r = &mut ChaCha8Rng::seed_from_u64(rng.random::<u64>());
    (
        r.random_range(0.03..0.1),
        r.random_range(1.0..3.0),
        r.random_range(0.5..0.9),
    )
}

/// A relay hysteron (the general Preisach model's elementary operator): +1 after the
/// temperature rose to `upper_c`, −1 after it fell to `lower_c`, unchanged in between; the bias
/// follows the relay's state through a critically damped second-order switching of time
/// `tau_s` (two first-order stages of τ/2: a real switching element does not flip instantly),
/// each relay with its own — so the shape is neither the detector's rate-independent loop nor
/// its loop behind one first-order lag. Written here from the definition, not with the
/// detector's operator.
#[derive(Debug, Clone, Copy)]
pub struct Relay {
    pub lower_c: f64,
    pub upper_c: f64,
    pub size_g: f64,
    pub tau_s: f64,
}

/// The accepted loop's figure `key` of its Preisach distribution in the JSON report (NaN when
/// no loop is named).
pub fn loop_figure(d: &Discovery, key: &str) -> f64 {
    disc::report::json(d)["effects"]
        .as_array()
        .and_then(|v| v.iter().find(|e| e["name"] == "thermal_hysteresis"))
        .and_then(|e| e["preisach"][key].as_f64())
        .unwrap_or(f64::NAN)
}

/// 1–3 relays of one sign (one material) on the temperature `temp` (°C), each of 1.5–4 × `unit`,
/// threshold gaps 0.1–0.6 °C, their midpoints within ±0.42 °C of the median temperature (inside
/// a ±0.5 °C programme's range), switching times 2–20 min.
pub fn draw_relays(temp: &[f64], unit: f64, r: &mut ChaCha8Rng) -> Vec<Relay> {
    let mut sorted = temp.to_vec();
    sorted.sort_by(f64::total_cmp);
    let centre = sorted[temp.len() / 2];
    let sign = if r.random::<bool>() { 1.0 } else { -1.0 };
    (0..r.random_range(1..=3usize))
        .map(|_| {
            let gap = r.random_range(0.1..0.6);
            let mid = r.random_range(-(0.42 - gap / 2.0)..(0.42 - gap / 2.0));
            Relay {
                lower_c: centre + mid - gap / 2.0,
                upper_c: centre + mid + gap / 2.0,
                size_g: sign * unit * r.random_range(1.5..4.0),
                tau_s: r.random_range(120.0..1200.0),
            }
        })
        .collect()
}

/// The relays' bias on the true temperature, g.
pub fn relay_series(relays: &[Relay], temp: &[f64], dt_s: f64) -> Vec<f64> {
    let mut out = vec![0.0; temp.len()];
    for r in relays {
        let mid = 0.5 * (r.lower_c + r.upper_c);
        let mut state = if temp[0] >= mid { 1.0 } else { -1.0 };
        let (mut x1, mut x2) = (state, state);
        let a = if r.tau_s > 0.0 {
            (-dt_s / (0.5 * r.tau_s)).exp()
        } else {
            0.0
        };
        for (o, &t) in out.iter_mut().zip(temp) {
            if t >= r.upper_c {
                state = 1.0;
            } else if t <= r.lower_c {
                state = -1.0;
            }
            x1 = a * x1 + (1.0 - a) * state;
            x2 = a * x2 + (1.0 - a) * x1;
            *o += r.size_g * x2;
        }
    }
    out
}

/// The loop's area as the record shows it, g·°C: the temperature range (2–98 %) cut into 24
/// bins, in each the mean of `s` on heating rows minus its mean on cooling rows (the direction
/// from the temperature's change over ±14 min, turnovers and holds left out), times the bin's
/// width, summed. A relay of size s and thresholds β < α switched instantly gives −2s(α − β).
/// `dt_s` is the rows' spacing.
pub fn branch_area(s: &[f64], temp: &[f64], dt_s: f64) -> f64 {
    let n = temp.len();
    let h = ((840.0 / dt_s).round() as usize).max(1);
    let mut sorted = temp.to_vec();
    sorted.sort_by(f64::total_cmp);
    let q = |p: f64| sorted[((n - 1) as f64 * p).round() as usize];
    let (lo, hi) = (q(0.02), q(0.98));
    let bins = 24;
    let w = (hi - lo) / bins as f64;
    let mut acc = vec![[0.0f64; 4]; bins];
    for i in h..n.saturating_sub(h) {
        let d = temp[i + h] - temp[i - h];
        let b = ((temp[i] - lo) / w).floor();
        if !(0.0..bins as f64).contains(&b) || d.abs() < 0.02 {
            continue;
        }
        let a = &mut acc[b as usize];
        if d > 0.0 {
            a[0] += s[i];
            a[1] += 1.0;
        } else {
            a[2] += s[i];
            a[3] += 1.0;
        }
    }
    acc.iter()
        .filter(|a| a[1] >= 5.0 && a[3] >= 5.0)
        .map(|a| (a[0] / a[1] - a[2] / a[3]) * w)
        .sum()
}

/// A log with the simulator's metadata and the given columns, as the board would record it.
pub fn log_with(t_s: Vec<f64>, meta: &[(String, String)], columns: Vec<(&str, Vec<f64>)>) -> Log {
    let mut log = Log::with_time(t_s).expect("time");
    for (k, v) in meta {
        log.set_meta(k, v).expect("meta");
    }
    for (name, values) in columns {
        log.push_column(name, values).expect("column");
    }
    log
}

/// Asserts that `count` of `total` is at least `percent` % (integer arithmetic, so 8 of 10 is
/// exactly 80 %).
pub fn assert_at_least_percent(count: usize, total: usize, percent: usize, what: &str) {
    assert!(
        count * 100 >= total * percent,
        "{what}: {count}/{total}, below {percent} %"
    );
}

/// Asserts that `count` of `total` is at most `percent` %.
pub fn assert_at_most_percent(count: usize, total: usize, percent: usize, what: &str) {
    assert!(
        count * 100 <= total * percent,
        "{what}: {count}/{total}, above {percent} %"
    );
}

/// Runs `accepted_on(seed)` on `draws` null logs (seeds from `seed`) and returns how many
/// accepted anything, printing each.
pub fn false_discoveries(
    label: &str,
    seed: u64,
    draws: usize,
    mut accepted_on: impl FnMut(u64) -> Vec<String>,
) -> usize {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut count = 0;
    for i in 0..draws {
        let accepted = accepted_on(rng.random::<u64>());
        eprintln!("{label} null draw {i}: accepted {accepted:?}");
        count += usize::from(!accepted.is_empty());
    }
    eprintln!("{label} FALSE-DISCOVERY RATE {count}/{draws}");
    count
}

/// The null test: `draws` logs with nothing hidden (their seeds drawn from `seed`), at most
/// `percent` % of them with an accepted effect.
pub fn assert_null_rate_at_most(
    label: &str,
    seed: u64,
    draws: usize,
    percent: usize,
    accepted_on: impl FnMut(u64) -> Vec<String>,
) {
    let count = false_discoveries(label, seed, draws, accepted_on);
    let what = format!("false discoveries on {label} null logs");
    assert_at_most_percent(count, draws, percent, &what);
}

/// The noise of the simulated sensor as a state-space model sampled every `interval_s`.
struct NoiseStateSpace {
    /// AR(1) coefficients of the flicker components, then 1.0 for the random walk.
    phi: Vec<f64>,
    /// Process noise variance per step, same order.
    q: Vec<f64>,
    /// Initial state variance, same order (stationary for AR(1), zero for the walk).
    p0: Vec<f64>,
    /// White measurement noise variance.
    r: f64,
}

impl NoiseStateSpace {
    fn new(p: &AllanParams, interval_s: f64, duration_s: f64) -> Self {
        let ratio = 10f64.sqrt();
        let (mut phi, mut q, mut p0) = (Vec::new(), Vec::new(), Vec::new());
        if p.flicker_floor > 0.0 {
            let v = p.flicker_floor.powi(2) * ratio.ln() / (2.0 * std::f64::consts::LN_2);
            let tau_max = 10.0 * duration_s.max(interval_s);
            let mut tau = interval_s;
            while tau <= tau_max * ratio {
                let f = (-interval_s / tau).exp();
                phi.push(f);
                q.push(v * (1.0 - f * f));
                p0.push(v);
                tau *= ratio;
            }
        }
        phi.push(1.0);
        q.push(p.random_walk_per_sqrt_s.powi(2) * interval_s);
        p0.push(0.0);
        NoiseStateSpace {
            phi,
            q,
            p0,
            r: p.white_adev_1s.powi(2) / interval_s,
        }
    }

    /// Normalised innovations of every column (all columns share the gains).
    fn whiten(&self, columns: &[&[f64]]) -> Vec<Vec<f64>> {
        let k = self.phi.len();
        let n = columns.first().map_or(0, |c| c.len());
        let mut p = vec![0.0; k * k];
        for i in 0..k {
            p[i * k + i] = self.p0[i];
        }
        let mut states = vec![vec![0.0; k]; columns.len()];
        let mut out = vec![Vec::with_capacity(n); columns.len()];
        let mut ph = vec![0.0; k];
        for t in 0..n {
            // Predict: x ← Φx, P ← ΦPΦ + Q (Φ diagonal).
            for i in 0..k {
                for j in 0..k {
                    p[i * k + j] *= self.phi[i] * self.phi[j];
                }
                p[i * k + i] += self.q[i];
            }
            // Observation y = Σ states + white: S = 1ᵀP1 + r, gain P1/S.
            for i in 0..k {
                ph[i] = (0..k).map(|j| p[i * k + j]).sum();
            }
            let s = ph.iter().sum::<f64>() + self.r;
            let sqrt_s = s.sqrt();
            for ((c, x), o) in columns.iter().zip(states.iter_mut()).zip(out.iter_mut()) {
                for (xi, f) in x.iter_mut().zip(&self.phi) {
                    *xi *= f;
                }
                let e = c[t] - x.iter().sum::<f64>();
                o.push(e / sqrt_s);
                for (xi, h) in x.iter_mut().zip(&ph) {
                    *xi += h / s * e;
                }
            }
            // P ← P − (P1)(P1)ᵀ/S.
            for i in 0..k {
                for j in 0..k {
                    p[i * k + j] -= ph[i] * ph[j] / s;
                }
            }
        }
        out
    }
}

/// The factor that scales an effect of unit size, `shape`, to the matched-filter SNR `snr`
/// ([`matched_filter_snr`] with the same arguments); 0 for a shape the nuisance absorbs whole.
pub fn scale_to_snr(
    shape: &[f64],
    nuisance: &[Vec<f64>],
    noise: &AllanParams,
    interval_s: f64,
    duration_s: f64,
    snr: f64,
) -> f64 {
    let unit_snr = matched_filter_snr(shape, nuisance, noise, interval_s, duration_s);
    if unit_snr > 0.0 {
        snr / unit_snr
    } else {
        0.0
    }
}

/// Matched-filter SNR of the effect `shape` (in the noise's unit, one value per sample of a run
/// sampled every `interval_s` for `duration_s`) against the sensor noise `noise`, after
/// projecting out the `nuisance` columns (each one value per sample).
pub fn matched_filter_snr(
    shape: &[f64],
    nuisance: &[Vec<f64>],
    noise: &AllanParams,
    interval_s: f64,
    duration_s: f64,
) -> f64 {
    let model = NoiseStateSpace::new(noise, interval_s, duration_s);
    let mut cols: Vec<&[f64]> = nuisance.iter().map(Vec::as_slice).collect();
    cols.push(shape);
    let mut w = model.whiten(&cols);
    // Gram–Schmidt (twice, for orthogonality at these condition numbers) of the whitened
    // nuisance columns, then the shape's part orthogonal to them.
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let mut basis: Vec<Vec<f64>> = Vec::new();
    for col in w.drain(..) {
        let mut v = col;
        for _ in 0..2 {
            for b in &basis {
                let c = dot(&v, b);
                for (vi, bi) in v.iter_mut().zip(b) {
                    *vi -= c * bi;
                }
            }
        }
        let norm = dot(&v, &v).sqrt();
        if basis.len() == nuisance.len() {
            return norm;
        }
        if norm > 1e-9 * (v.len() as f64).sqrt() {
            basis.push(v.iter().map(|x| x / norm).collect());
        } else {
            // A nuisance column dependent on the others adds nothing; keep the count aligned.
            basis.push(vec![0.0; v.len()]);
        }
    }
    0.0
}

/// Generalised least squares of `y` on `cols` (one value per sample each) under the sensor
/// noise `noise`: both whitened by the same Kalman filter, then ordinary least squares. The
/// coefficients in the order of `cols`.
pub fn gls_coefficients(
    y: &[f64],
    cols: &[Vec<f64>],
    noise: &AllanParams,
    interval_s: f64,
    duration_s: f64,
) -> Vec<f64> {
    let model = NoiseStateSpace::new(noise, interval_s, duration_s);
    let mut all: Vec<&[f64]> = cols.iter().map(Vec::as_slice).collect();
    all.push(y);
    let w = model.whiten(&all);
    let (yw, cw) = w.split_last().expect("y is there");
    let n = yw.len();
    let a: Vec<Vec<f64>> = (0..n).map(|i| cw.iter().map(|c| c[i]).collect()).collect();
    accomp_numerics::linalg::least_squares(&a, yw)
        .map(|f| f.coeffs)
        .unwrap_or_else(|_| vec![f64::NAN; cols.len()])
}

/// Offset, linear drift and a cubic in the centred temperature: the nuisance columns of a
/// static baseline (what it can absorb of any effect).
pub fn static_nuisance(t_s: &[f64], temperature_c: &[f64]) -> Vec<Vec<f64>> {
    let n = t_s.len().max(1) as f64;
    let t_mean = t_s.iter().sum::<f64>() / n;
    let c_mean = temperature_c.iter().sum::<f64>() / n;
    let dc: Vec<f64> = temperature_c.iter().map(|c| c - c_mean).collect();
    vec![
        vec![1.0; t_s.len()],
        t_s.iter().map(|t| t - t_mean).collect(),
        dc.clone(),
        dc.iter().map(|d| d * d).collect(),
        dc.iter().map(|d| d * d * d).collect(),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn noise(w: f64, f: f64, k: f64) -> AllanParams {
        AllanParams {
            white_adev_1s: w,
            flicker_floor: f,
            random_walk_per_sqrt_s: k,
        }
    }

    #[test]
    fn in_white_noise_the_snr_of_a_constant_is_its_size_over_the_standard_error_of_a_mean() {
        // n samples of std σ: a constant of size a has SNR a·√n/σ.
        let (n, dt) = (400usize, 4.0_f64);
        let sigma = 2.0e-6 / dt.sqrt();
        let s = vec![1.0e-6; n];
        let snr = matched_filter_snr(&s, &[], &noise(2.0e-6, 0.0, 0.0), dt, n as f64 * dt);
        let expect = 1.0e-6 * (n as f64).sqrt() / sigma;
        assert!((snr / expect - 1.0).abs() < 1e-9, "{snr} vs {expect}");
        // …and nothing is left of it once an offset column may absorb it.
        let snr0 = matched_filter_snr(&s, &[vec![1.0; n]], &noise(2.0e-6, 0.0, 0.0), dt, 1600.0);
        assert!(snr0 < 1e-6 * expect, "{snr0}");
    }

    #[test]
    fn in_a_random_walk_a_step_is_seen_only_through_its_one_increment() {
        // Pure random walk (no white): whitening is differencing, so a step of size a has
        // SNR a/(K√Δ) whatever its position.
        let (n, dt, k) = (200usize, 10.0_f64, 1.0e-8);
        let s: Vec<f64> = (0..n).map(|i| if i >= 80 { 5.0e-8 } else { 0.0 }).collect();
        let snr = matched_filter_snr(&s, &[], &noise(1e-15, 0.0, k), dt, n as f64 * dt);
        let expect = 5.0e-8 / (k * dt.sqrt());
        assert!((snr / expect - 1.0).abs() < 1e-6, "{snr} vs {expect}");
    }
}
