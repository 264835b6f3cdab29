//! Couplings as transfer functions per channel, with shapes the detector does not parametrise
//! exactly, injected into noise the detector did not make: white + 1/f flicker + random walk
//! with a real thermostat programme (`common/synth.rs`). The tool runs blind; the test compares
//! afterwards.
//!
//! - a bias on the rate of temperature change (central differences of the TRUE temperature; the
//!   detector differentiates the smoothed RTD reading backwards);
//! - a second-order lag of two UNEQUAL stages on the temperature (the detector fits a first-order
//!   lag or two equal stages): named a coupling of `temperature_c` whose delay is the stages' sum;
//! - a first-order lag on slow ramps, where a gain on the rate explains it as well: reported as
//!   "ambiguous: A or B" with both parameter sets and what would separate them;
//! - a bias on the rate of a thermostat's controller noise (AR(1) of 0.1–0.2 °C over 10–20 min on
//!   a regulated station, read by the RTD with 1–5 mK): the rate lives at the shortest periods,
//!   next to the reading noise, so it is named only if the rate is taken without its gain being
//!   attenuated by that noise (errors in variables).
//!
//! Tolerances, stated before measuring: coefficients ±40 % (controller noise: ±25 %), delays
//! within e^0.5.
//! Measured figures: docs/discovery-causes.md, "Transfer functions per channel".

#[path = "common/hidden.rs"]
mod hidden;
#[path = "common/synth.rs"]
mod synth;

use accomp_host::discover::{self, Discovery};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

const DT_S: f64 = 120.0;
const ROWS: usize = 14 * 720;

fn blind(st: &synth::Station, noise: &synth::SensorNoise, extra: &[f64], seed: u64) -> Discovery {
    let mut r = synth::rng(seed);
    let y = synth::output_g(st, noise, extra, &mut r);
    hidden::discover_blind(&synth::log_of(st, y)).1
}

fn why(d: &Discovery) -> String {
    format!(
        "refused {:?}; last round {:?}; candidates {:?}; baseline {}",
        d.selection.refused, d.selection.last_round, d.candidates, d.baseline_description
    )
}

fn no_absorbers(d: &Discovery) {
    let names = hidden::accepted_names(d);
    assert!(
        !names
            .iter()
            .any(|n| n == "thermal_hysteresis" || n == "periodic"),
        "a loop or free lines took the coupling's place: {:?}",
        hidden::accepted_with_params(d)
    );
}

/// One draw's own generator (seeded from `rng`) and the programme station drawn with it.
fn programme_draw(rng: &mut ChaCha8Rng) -> (ChaCha8Rng, synth::Station, synth::SensorNoise) {
    let mut r = synth::rng(rng.random::<u64>());
    let (st, noise) = synth::programme_station(ROWS, DT_S, &mut r);
    (r, st, noise)
}

/// No absorber is accepted, and a `rate_coupling` of the temperature channel is, with its
/// coefficient within `tolerance` (relative) of the hidden `g` (g·s/°C).
fn assert_rate_coupling_of_temperature(d: &Discovery, g: f64, tolerance: f64) {
    no_absorbers(d);
    let a = hidden::accepted(d, "rate_coupling")
        .unwrap_or_else(|| panic!("rate_coupling named: {}", why(d)));
    assert_eq!(a.effect.channel(), Some("temperature_c"));
    let k = hidden::param_value(a, "coefficient");
    assert!(
        (k / g - 1.0).abs() < tolerance,
        "coefficient {k:.3e} against {g:.3e}"
    );
}

#[test]
fn a_bias_on_the_rate_of_temperature_change_is_a_rate_coupling_of_the_temperature() {
    let mut rng = synth::rng(0x7A7E_0001);
    for i in 0..2 {
        let (mut r, st, noise) = programme_draw(&mut rng);
        let rate = synth::true_rate_c_per_s(&st);
        // 2–4 µg at the programme's fastest ramp (0.5 °C per 2 h).
        let g = hidden::sign(&mut r) * r.random_range(2.0e-6..4.0e-6) / (1.0 / 7200.0);
        let extra: Vec<f64> = rate.iter().map(|v| g * v).collect();
        let d = blind(&st, &noise, &extra, r.random());
        eprintln!(
            "rate {i}: g {g:.3e} g·s/°C → {:?}",
            hidden::accepted_with_params(&d)
        );
        assert_rate_coupling_of_temperature(&d, g, 0.4);
        let text = discover::report::text(&d);
        assert!(text.contains("rate_coupling (temperature_c, °C)"), "{text}");
    }
}

#[test]
fn a_bias_on_the_rate_of_controller_noise_is_a_rate_coupling_with_its_gain() {
    // 4 days at 60 s, as the paper-1g preset's records.
    let (rows, dt) = (4 * 1440, 60.0);
    let mut rng = synth::rng(0x7A7E_0006);
    for i in 0..2 {
        let mut r = synth::rng(rng.random::<u64>());
        let (st, noise, (sd, tau)) = synth::controller_noise_station(rows, dt, &mut r);
        let rate = synth::true_rate_c_per_s(&st);
        let rms = (rate.iter().map(|v| v * v).sum::<f64>() / rows as f64).sqrt();
        // 2–4 µg rms of coupling.
        let g = hidden::sign(&mut r) * r.random_range(2.0e-6..4.0e-6) / rms;
        let extra: Vec<f64> = rate.iter().map(|v| g * v).collect();
        let d = blind(&st, &noise, &extra, r.random());
        eprintln!(
            "controller {i}: {sd:.3} °C over {tau:.0} s, RTD {:.1} mK, g {g:.3e} g·s/°C → {:?}",
            st.rtd_noise_c * 1e3,
            hidden::accepted_with_params(&d)
        );
        assert_rate_coupling_of_temperature(&d, g, 0.25);
    }
}

#[test]
fn a_second_order_lag_of_unequal_stages_is_a_coupling_of_the_temperature_with_their_delay() {
    let mut rng = synth::rng(0x7A7E_0002);
    for i in 0..2 {
        let (mut r, st, noise) = programme_draw(&mut rng);
        let (t1, t2) = (
            r.random_range(600.0..1200.0),
            r.random_range(1800.0..3600.0),
        );
        let k = hidden::sign(&mut r) * r.random_range(6.0e-6..10.0e-6);
        let l2 = synth::low_pass(&synth::low_pass(&st.temp_true_c, DT_S, t1), DT_S, t2);
        let extra = synth::lag_error(&l2, &st.temp_true_c, k);
        let d = blind(&st, &noise, &extra, r.random());
        eprintln!(
            "lag2 {i}: τ {t1:.0} + {t2:.0} s, {:.1} µg/°C → {:?}",
            k * 1e6,
            hidden::accepted_with_params(&d)
        );
        no_absorbers(&d);
        hidden::assert_temperature_lag(&d, t1 + t2, k);
    }
}

#[test]
fn a_lag_on_a_slow_cycle_is_reported_ambiguous_with_a_rate_coupling_and_what_separates_them() {
    // A ±1.5 °C daily sine (a lab's day, no thermostat excursions), read by the RTD with its
    // offset and reading noise: for a sine, the lag error L_τ[T] − T is a·T + b·dT/dt, and the
    // baseline holds T, so a first-order lag and a gain on the rate are the same column. The
    // record starts at the top of the cycle, where the rate is 0 and a lag is settled (started
    // on a ramp, the lag's start-up transient would tell it from the rate).
    let mut r = synth::rng(0x7A7E_0005);
    let mut st = synth::station(ROWS, DT_S, synth::Thermal::Regulated, &mut r);
    for i in 0..ROWS {
        let day = 20.0 + 1.5 * (std::f64::consts::TAU * st.t_s[i] / 86_400.0).cos();
        st.temp_true_c[i] = day;
        st.temp_meas_c[i] = day + st.rtd_offset_c + st.rtd_noise_c * synth::gauss(&mut r);
    }
    let noise = synth::draw_noise(&mut r);
    let (tau, k) = (1800.0, 20.0e-6);
    let lag = synth::low_pass(&st.temp_true_c, DT_S, tau);
    let extra = synth::lag_error(&lag, &st.temp_true_c, k);
    let d = blind(&st, &noise, &extra, r.random());
    eprintln!("slow ramps: {:?}", hidden::accepted_with_params(&d));
    const TEMPERATURE_COUPLINGS: [&str; 3] = ["thermal_lag", "rate_coupling", "lag2_coupling"];
    let a = d
        .selection
        .accepted
        .iter()
        .find(|a| TEMPERATURE_COUPLINGS.contains(&a.effect.name()))
        .unwrap_or_else(|| panic!("no coupling of the temperature named: {}", why(&d)));
    // The rate coupling's side of the ambiguity when the lag is named (other equal causes, a
    // second stage, may be listed beside it).
    let amb = a
        .ambiguous_with
        .iter()
        .find(|x| x.other == "rate_coupling")
        .or(a.ambiguous_with.first())
        .unwrap_or_else(|| panic!("{} not reported ambiguous: {}", a.effect.name(), why(&d)));
    eprintln!(
        "slow ramps: {} ambiguous with {} {:?} (overlap {:.3}); separates: {}",
        a.effect.name(),
        amb.other,
        amb.other_parameters,
        amb.overlap,
        amb.separates
    );
    assert!(TEMPERATURE_COUPLINGS.contains(&amb.other.as_str()) && amb.other != a.effect.name());
    assert!(
        a.effect.name() == "rate_coupling" || amb.other == "rate_coupling",
        "the rate is one of the two: {} {:?}",
        why(&d),
        d.channel_noise
    );
    assert!(amb.separates.contains("rate"), "{}", amb.separates);
    assert!(!amb.other_parameters.is_empty());
    assert!(!amb.separates.is_empty());
    let text = discover::report::text(&d);
    assert!(text.contains("ambiguous: "), "{text}");
}
