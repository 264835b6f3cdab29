//! Measures the gain of a coupling to the rate of a noisy channel (errors in variables) when
//! the rate is taken from the reading in four ways, by generalised least squares under the
//! output's known noise (white + flicker + random walk, `tests/common/hidden.rs`) with an offset
//! and a linear drift beside it — the fit the discovery makes, without its selection:
//!
//! - `raw`: central differences of the reading;
//! - `avg`: central differences of the reading averaged over ±15 min;
//! - `wiener`: regression calibration — E[true rate | readings] by a Wiener filter of the
//!   reading, S_signal/(S_signal + S_noise) per frequency, S_noise the reading's white floor
//!   fitted to the upper three quarters of its own spectrum as N + A·(2 sin πfΔt)^(−α)
//!   (`discover::rate::reading_floor`, the floor `rate_coupling`'s band uses),
//!   S_signal + S_noise its periodogram smoothed over ±10 % of each frequency;
//! - `eiv`: the same filter with the reading noise the discovery's errors-in-variables model
//!   fits to the channel (`discover::eiv::denoise`, the local-linear-trend maximum likelihood
//!   reported as `channel_noise`);
//! - `oracle`: the same filter with the true reading noise as the floor;
//! - `band`: what `rate_coupling` uses (`discover::rate::band_limited_rate`) — the rate kept
//!   only where the reading's smoothed periodogram stands 10× above that white floor (gain 1
//!   there, 0 elsewhere).
//!
//! Two channels: slow ramps (a ±0.5 °C programme of 2–6 h ramps, 14 days at 120 s, RTD noise
//! 1–5 mK) and a thermostat's fast controller noise (AR(1) of 0.165 °C, correlation 15 min,
//! 4 days at 60 s, read with 1–5 mK). Prints the gain found / the true gain per record.
//!
//! `cargo run -p accomp-host --example rate_regression_calibration [records]`

#[path = "../tests/common/hidden.rs"]
mod hidden;
#[path = "../tests/common/synth.rs"]
mod synth;

use accomp_host::numerics::series::central_difference;
use accomp_host::sim::noise::AllanParams;
use rand::Rng;

fn moving_average(x: &[f64], half: usize) -> Vec<f64> {
    let n = x.len();
    (0..n)
        .map(|i| {
            let (a, b) = (i.saturating_sub(half), (i + half + 1).min(n));
            x[a..b].iter().sum::<f64>() / (b - a) as f64
        })
        .collect()
}

/// E[true rate | readings] by a Wiener filter of the reading (see the top); `floor`: the
/// reading noise variance, None to take it from the spectrum's top quarter.
fn wiener_rate(w: &[f64], dt: f64, floor: Option<f64>) -> Vec<f64> {
    // The discovery's frequency-domain rate with the Wiener weight 1 − noise/S in place of its
    // band (S: the periodogram smoothed as there).
    accomp_host::discover::rate::filtered_rate(w, dt, |p| {
        let noise = floor.unwrap_or_else(|| accomp_host::discover::rate::reading_floor(p));
        move |ps| (1.0 - noise / ps).max(0.0)
    })
}

/// The reading noise variance the discovery's errors-in-variables model fits to `reading`.
fn eiv_floor(reading: &[f64], dt: f64) -> Option<f64> {
    use accomp_host::discover::{eiv, import};
    let n = reading.len();
    let mut log =
        accomp_host::log::Log::with_time((0..n).map(|i| i as f64 * dt).collect()).expect("time");
    // The output does not enter the channel's model; the import refuses a constant one.
    log.push_column("output_g", (0..n).map(|i| i as f64).collect())
        .expect("column");
    log.push_column("temperature_c", reading.to_vec())
        .expect("column");
    let ds = import::dataset_from_log(&log, &import::DatasetOptions::default()).ok()?;
    let (_, report) = eiv::denoise(&ds, false);
    report
        .iter()
        .find(|c| c.channel == "temperature_c")
        .map(|c| c.noise * c.noise)
}

fn main() {
    let records: u64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(4);
    println!(
        "channel, record, reading noise mK: gain found / true for raw, avg, wiener, eiv, oracle, band"
    );
    for case in ["slow ramps", "controller noise"] {
        for rec in 0..records {
            let mut r = synth::rng(0x2A7E_0000 + rec + if case == "slow ramps" { 0 } else { 64 });
            let (dt, t_true, reading, sigma_r) = if case == "slow ramps" {
                let (st, _) = synth::programme_station(14 * 720, 120.0, &mut r);
                (
                    120.0,
                    st.temp_true_c.clone(),
                    st.temp_meas_c.clone(),
                    st.rtd_noise_c,
                )
            } else {
                let (n, dt, tau, sd): (usize, f64, f64, f64) = (4 * 1440, 60.0, 900.0, 0.165);
                let a: f64 = (-dt / tau).exp();
                let mut c = sd * synth::gauss(&mut r);
                let t: Vec<f64> = (0..n)
                    .map(|_| {
                        c = a * c + (1.0 - a * a).sqrt() * sd * synth::gauss(&mut r);
                        25.0 + c
                    })
                    .collect();
                let s = r.random_range(0.001..0.005);
                let w: Vec<f64> = t.iter().map(|v| v + s * synth::gauss(&mut r)).collect();
                (dt, t, w, s)
            };
            let n = t_true.len();
            let rate = central_difference(&t_true, dt);
            let rms = (rate.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
            // 2 µg rms of coupling.
            let g = 2.0e-6 / rms;
            let noise = synth::draw_noise(&mut r);
            let e = synth::sensor_noise(
                n,
                dt,
                noise.white_1s,
                noise.flicker_floor,
                noise.rw_per_sqrt_s,
                &mut r,
            );
            let y: Vec<f64> = rate.iter().zip(&e).map(|(v, e)| g * v + e).collect();
            let allan = AllanParams {
                white_adev_1s: noise.white_1s,
                flicker_floor: noise.flicker_floor,
                random_walk_per_sqrt_s: noise.rw_per_sqrt_s,
            };
            let half = (900.0 / dt).round() as usize;
            let regressors = [
                central_difference(&reading, dt),
                central_difference(&moving_average(&reading, half), dt),
                wiener_rate(&reading, dt, None),
                wiener_rate(
                    &reading,
                    dt,
                    Some(eiv_floor(&reading, dt).unwrap_or(f64::NAN)),
                ),
                wiener_rate(&reading, dt, Some(sigma_r * sigma_r)),
                accomp_host::discover::rate::band_limited_rate(
                    &reading,
                    &(0..n).map(|i| i as f64 * dt).collect::<Vec<_>>(),
                    &(0..n).map(|i| i == 0).collect::<Vec<_>>(),
                ),
            ];
            let gains: Vec<String> = regressors
                .iter()
                .map(|x| {
                    let cols = vec![
                        vec![1.0; n],
                        (0..n).map(|i| i as f64 / n as f64).collect(),
                        x.clone(),
                    ];
                    let c = hidden::gls_coefficients(&y, &cols, &allan, dt, n as f64 * dt);
                    format!("{:.3}", c[2] / g)
                })
                .collect();
            println!("{case}, {rec}, {:.1}: {}", sigma_r * 1e3, gains.join(", "));
        }
    }
}
