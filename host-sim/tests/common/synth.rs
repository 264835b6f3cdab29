//! Independent log generator for the non-circular hidden-effect tests
//! (`discover_hidden_shapes.rs`, `discover_hidden_null.rs`).
//!
//! Written without the station simulator and without the detector's assumptions:
//! - flicker noise is **1/f by spectral synthesis** (Gaussian Fourier coefficients of a one-sided
//!   PSD h/f on a grid twice the record, one inverse real FFT; written here, not `sim/noise.rs`'s sum of
//!   AR(1) terms, which is also the detector's noise family);
//! - white noise and a random walk from a Box–Muller Gaussian of our own;
//! - the channels a real station logs, each with its own reading noise: an RTD reading the
//!   mounting block with a fixed offset and mK white noise, thermostat excursions (door-like
//!   bumps that decay over an hour), a slow set-point wander, an optional ±0.5 °C cycling
//!   programme; two tiltmeter axes (slow foundation tilt + reading noise); a barometer (weather
//!   + reading noise).
//!
//! The output is in g (`output_g`), a 1 g record (`input_g = 1`), no site or start time (no
//! tide: the record stands for one whose tide has been removed).

#![allow(dead_code)]

use accomp::table::CalibrationTable;
use accomp::units::Celsius;
use accomp_host::discover::import::DatasetOptions;
use accomp_host::discover::{self as disc, select, Discovery};
use accomp_host::log::Log;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A test log's thermal programme: a ±0.5 °C cycle whose period is drawn from `period_h` (hours)
/// when `cycling`, else the regulated thermostat.
pub fn thermal(cycling: bool, period_h: std::ops::Range<f64>, rng: &mut ChaCha8Rng) -> Thermal {
    if cycling {
        Thermal::Cycling {
            amplitude_c: 0.5,
            period_s: rng.random_range(period_h) * 3600.0,
        }
    } else {
        Thermal::Regulated
    }
}

/// Standard normal deviate (Box–Muller).
pub fn gauss(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = rng.random::<f64>().max(1e-300);
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Gaussian noise with one-sided PSD `psd(f)` (unit²/Hz), `n` samples every `dt_s`, by spectral
/// synthesis on a grid of N ≥ 2n (so the record is not periodic): x_j = Σ_k √(S(f_k)Δf)·
/// (a_k cos 2πf_k t_j + b_k sin 2πf_k t_j), a, b standard normal, f_k = k/(N·dt), k = 1…N/2.
pub fn spectral_noise(
    n: usize,
    dt_s: f64,
    psd: impl Fn(f64) -> f64,
    rng: &mut ChaCha8Rng,
) -> Vec<f64> {
    let big = (2 * n).next_power_of_two();
    let df = 1.0 / (big as f64 * dt_s);
    // x_j = Re Σ_k c_k e^{+2πi kj/N} with c_k = amp (a_k − i b_k): the inverse real FFT of the
    // half spectrum c_k / 2 (the Hermitian extension supplies the conjugate half), except the
    // Nyquist bin, which enters once and only by its real part.
    let mut half = vec![(0.0, 0.0); big / 2 + 1];
    for (k, bin) in half.iter_mut().enumerate().skip(1) {
        let amp = (psd(k as f64 * df) * df).sqrt();
        let (a, b) = (amp * gauss(rng), amp * gauss(rng));
        *bin = if k == big / 2 {
            (a, 0.0)
        } else {
            (a / 2.0, -b / 2.0)
        };
    }
    let mut x = accomp_numerics::fft::real_from_half_spectrum(&half);
    x.truncate(n);
    x
}

/// 1/f (flicker) noise of Allan-deviation floor `floor`: S(f) = h/f with h = floor²/(2 ln 2).
pub fn flicker(n: usize, dt_s: f64, floor: f64, rng: &mut ChaCha8Rng) -> Vec<f64> {
    let h = floor * floor / (2.0 * std::f64::consts::LN_2);
    spectral_noise(n, dt_s, |f| h / f, rng)
}

/// Sensor noise: white of Allan deviation `white_1s` at 1 s, 1/f flicker of floor `flicker_floor`,
/// random walk `rw_per_sqrt_s` (all in the output unit).
pub fn sensor_noise(
    n: usize,
    dt_s: f64,
    white_1s: f64,
    flicker_floor: f64,
    rw_per_sqrt_s: f64,
    rng: &mut ChaCha8Rng,
) -> Vec<f64> {
    let fl = flicker(n, dt_s, flicker_floor, rng);
    let mut walk = 0.0;
    let sw = white_1s / dt_s.sqrt();
    let sr = rw_per_sqrt_s * dt_s.sqrt();
    fl.iter()
        .map(|f| {
            walk += sr * gauss(rng);
            f + walk + sw * gauss(rng)
        })
        .collect()
}

/// First-order low pass (exact for a held input), started at the first value.
pub fn low_pass(u: &[f64], dt_s: f64, tau_s: f64) -> Vec<f64> {
    let a = (-dt_s / tau_s).exp();
    let mut x = u.first().copied().unwrap_or(0.0);
    u.iter()
        .map(|v| {
            x = a * x + (1.0 - a) * v;
            x
        })
        .collect()
}

/// How the mounting block's temperature is driven.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Thermal {
    /// A regulated thermostat: controller noise, set-point wander, excursions.
    Regulated,
    /// The same plus a cycling programme: rounded triangle of ±`amplitude_c` with `period_s`.
    Cycling {
        /// Half the peak-to-peak swing, °C.
        amplitude_c: f64,
        /// Period, s.
        period_s: f64,
    },
    /// The same plus a thermostat programme whose ramps differ: ±`amplitude_c` triangles, each
    /// half-cycle's duration drawn uniformly in [`min_half_s`, `max_half_s`] (so the heating
    /// and cooling rates change from ramp to ramp, as on a lab's programmed chamber), the
    /// corners rounded by the chamber's 5-minute thermal time constant.
    Programme {
        /// Half the peak-to-peak swing, °C.
        amplitude_c: f64,
        /// Shortest half-cycle, s.
        min_half_s: f64,
        /// Longest half-cycle, s.
        max_half_s: f64,
    },
}

/// The cycling programme of the lag-or-loop and table-error tests: ±0.5 °C, 8 h period.
pub const EIGHT_HOUR_CYCLE: Thermal = Thermal::Cycling {
    amplitude_c: 0.5,
    period_s: 8.0 * 3600.0,
};

/// A generated station record: time, true and measured channels.
#[derive(Debug, Clone)]
pub struct Station {
    /// Sample interval, s.
    pub dt_s: f64,
    /// Time, s.
    pub t_s: Vec<f64>,
    /// True mounting-block temperature, °C.
    pub temp_true_c: Vec<f64>,
    /// The RTD's reading of it: + fixed offset + reading noise, °C.
    pub temp_meas_c: Vec<f64>,
    /// True tilts (x, y), arcsec.
    pub tilt_true_arcsec: (Vec<f64>, Vec<f64>),
    /// Tiltmeter readings, arcsec.
    pub tilt_meas_arcsec: (Vec<f64>, Vec<f64>),
    /// True pressure, hPa.
    pub pressure_true_hpa: Vec<f64>,
    /// Barometer reading, hPa.
    pub pressure_meas_hpa: Vec<f64>,
    /// The RTD's reading noise (°C rms) and offset (°C), for the record.
    pub rtd_noise_c: f64,
    /// RTD offset.
    pub rtd_offset_c: f64,
}

/// Generates the station channels for `n` samples every `dt_s`.
pub fn station(n: usize, dt_s: f64, thermal: Thermal, rng: &mut ChaCha8Rng) -> Station {
    let t_s: Vec<f64> = (0..n).map(|i| i as f64 * dt_s).collect();
    let span = n as f64 * dt_s;
    // Controller: AR(1), 2–8 mK rms, 2–10 min correlation.
    let c_std = rng.random_range(0.002..0.008);
    let c_tau = rng.random_range(120.0..600.0);
    let a = (-dt_s / c_tau).exp();
    let mut c = c_std * gauss(rng);
    // Set-point wander: 5–20 mK per √day.
    let wander = rng.random_range(0.005..0.02) * (dt_s / 86_400.0).sqrt();
    let mut w = 0.0;
    // Excursions: Poisson, 0.5–2 per day, ±(20–150) mK, decaying over 20–90 min.
    let rate = rng.random_range(0.5..2.0) / 86_400.0;
    let mut bumps: Vec<(f64, f64, f64)> = Vec::new();
    let mut tb = 0.0;
    loop {
        tb += -(rng.random::<f64>().max(1e-12)).ln() / rate;
        if tb >= span {
            break;
        }
        let sgn = if rng.random::<bool>() { 1.0 } else { -1.0 };
        bumps.push((
            tb,
            sgn * rng.random_range(0.02..0.15),
            rng.random_range(1200.0..5400.0),
        ));
    }
    let phase = rng.random_range(0.0..1.0);
    let setpoint = rng.random_range(40.0..60.0);
    // The programme's corners: (time, level) from before the start to after the end.
    let corners: Vec<(f64, f64)> = match thermal {
        Thermal::Programme {
            amplitude_c,
            min_half_s,
            max_half_s,
        } => {
            let mut tc = -phase * max_half_s;
            let mut level = if rng.random::<bool>() { 1.0 } else { -1.0 };
            let mut v = vec![(tc, level * amplitude_c)];
            while tc <= span + max_half_s {
                tc += rng.random_range(min_half_s..max_half_s);
                level = -level;
                v.push((tc, level * amplitude_c));
            }
            v
        }
        _ => Vec::new(),
    };
    let programme = |t: f64| {
        let k = corners.partition_point(|c| c.0 <= t).max(1);
        let (a, b) = (corners[k - 1], corners[(k).min(corners.len() - 1)]);
        if b.0 > a.0 {
            a.1 + (b.1 - a.1) * (t - a.0) / (b.0 - a.0)
        } else {
            a.1
        }
    };
    let chamber = (-dt_s / 300.0).exp();
    let mut prog_state = if corners.is_empty() {
        0.0
    } else {
        programme(0.0)
    };
    let temp_true_c: Vec<f64> = t_s
        .iter()
        .map(|&t| {
            c = a * c + (1.0 - a * a).sqrt() * c_std * gauss(rng);
            w += wander * gauss(rng);
            let ex: f64 = bumps
                .iter()
                .filter(|b| t >= b.0)
                .map(|b| {
                    // Rises over 5 min, decays with its time constant.
                    let x = t - b.0;
                    b.1 * (1.0 - (-x / 300.0).exp()) * (-x / b.2).exp()
                })
                .sum();
            let prog = match thermal {
                Thermal::Regulated => 0.0,
                Thermal::Cycling {
                    amplitude_c,
                    period_s,
                } => {
                    // A triangle's rounded version: the thermostat ramps at a constant rate
                    // and turns over a few minutes (first five odd harmonics).
                    let x = std::f64::consts::TAU * (t / period_s + phase);
                    let tri: f64 = [1.0, 3.0, 5.0, 7.0, 9.0]
                        .iter()
                        .enumerate()
                        .map(|(k, m)| {
                            let s = if k % 2 == 0 { 1.0 } else { -1.0 };
                            s * (m * x).sin() / (m * m)
                        })
                        .sum();
                    amplitude_c * tri * 8.0 / (std::f64::consts::PI.powi(2)) / 0.9986
                }
                Thermal::Programme { .. } => {
                    prog_state = chamber * prog_state + (1.0 - chamber) * programme(t);
                    prog_state
                }
            };
            setpoint + c + w + ex + prog
        })
        .collect();
    // RTD: fixed offset ±50 mK (calibration), white reading noise 1–5 mK, 0.1 mK resolution.
    let rtd_offset_c = rng.random_range(-0.05..0.05);
    let rtd_noise_c = rng.random_range(0.001..0.005);
    let temp_meas_c = temp_true_c
        .iter()
        .map(|x| ((x + rtd_offset_c + rtd_noise_c * gauss(rng)) * 1e4).round() / 1e4)
        .collect();
    // Foundation tilt: slow (AR(1) over 6 h) 0.5″ plus a diurnal 0.2″; tiltmeter noise 0.02″.
    let tilt = |rng: &mut ChaCha8Rng| {
        let a = (-dt_s / 21_600.0).exp();
        let mut x = 0.5 * gauss(rng);
        let ph = rng.random_range(0.0..std::f64::consts::TAU);
        let truth: Vec<f64> = t_s
            .iter()
            .map(|&t| {
                x = a * x + (1.0 - a * a).sqrt() * 0.5 * gauss(rng);
                x + 0.2 * (std::f64::consts::TAU * t / 86_400.0 + ph).sin()
            })
            .collect();
        let meas = truth.iter().map(|v| v + 0.02 * gauss(rng)).collect();
        (truth, meas)
    };
    let (tx, mx) = tilt(rng);
    let (ty, my) = tilt(rng);
    // Weather: AR(1) of 5 hPa over 2 days around 1010 hPa; barometer noise 0.02 hPa.
    let ap = (-dt_s / 172_800.0).exp();
    let mut p = 5.0 * gauss(rng);
    let pressure_true_hpa: Vec<f64> = t_s
        .iter()
        .map(|_| {
            p = ap * p + (1.0 - ap * ap).sqrt() * 5.0 * gauss(rng);
            1010.0 + p
        })
        .collect();
    let pressure_meas_hpa = pressure_true_hpa
        .iter()
        .map(|v| v + 0.02 * gauss(rng))
        .collect();
    Station {
        dt_s,
        t_s,
        temp_true_c,
        temp_meas_c,
        tilt_true_arcsec: (tx, ty),
        tilt_meas_arcsec: (mx, my),
        pressure_true_hpa,
        pressure_meas_hpa,
        rtd_noise_c,
        rtd_offset_c,
    }
}

/// Sensor noise levels of the generated accelerometer (g): white 2 µg at 1 s, 1/f floor
/// 0.3–1 µg, random walk 2–8 ng/√s (navigation grade).
#[derive(Debug, Clone, Copy)]
pub struct SensorNoise {
    /// White, Allan deviation at 1 s.
    pub white_1s: f64,
    /// Flicker floor.
    pub flicker_floor: f64,
    /// Random walk per √s.
    pub rw_per_sqrt_s: f64,
}

/// Draws the sensor's noise levels.
pub fn draw_noise(rng: &mut ChaCha8Rng) -> SensorNoise {
    SensorNoise {
        white_1s: 2.0e-6,
        flicker_floor: rng.random_range(0.3e-6..1.0e-6),
        rw_per_sqrt_s: rng.random_range(2.0e-9..8.0e-9),
    }
}

/// The rate of change of the true temperature, °C/s: central differences, one-sided at the ends.
pub fn true_rate_c_per_s(st: &Station) -> Vec<f64> {
    central_difference(&st.temp_true_c, st.dt_s)
}

pub use accomp_host::numerics::series::central_difference;

/// What a coupling of `k` per °C through a lag adds to the output: k·(lagged − temp), per point.
pub fn lag_error(lagged: &[f64], temp: &[f64], k: f64) -> Vec<f64> {
    lagged.iter().zip(temp).map(|(l, t)| k * (l - t)).collect()
}

/// A regulated station whose thermostat adds controller noise (AR(1), 0.1–0.2 °C, correlation
/// time 10–20 min) to the true temperature, read by the RTD (offset, noise, 0.1 mK steps), and
/// its sensor's noise levels, drawn in that order; also the controller noise's level (°C) and
/// correlation time (s) as drawn.
pub fn controller_noise_station(
    n: usize,
    dt_s: f64,
    r: &mut ChaCha8Rng,
) -> (Station, SensorNoise, (f64, f64)) {
    let mut st = station(n, dt_s, Thermal::Regulated, r);
    let (sd, tau) = (r.random_range(0.1..0.2), r.random_range(600.0..1200.0));
    let a = (-dt_s / tau).exp();
    let mut c = sd * gauss(r);
    for k in 0..n {
        c = a * c + (1.0 - a * a).sqrt() * sd * gauss(r);
        st.temp_true_c[k] += c;
        st.temp_meas_c[k] =
            ((st.temp_true_c[k] + st.rtd_offset_c + st.rtd_noise_c * gauss(r)) * 1e4).round() / 1e4;
    }
    (st, draw_noise(r), (sd, tau))
}

/// A station on a lab's programmed chamber (±0.5 °C ramps of 2–6 h, what makes
/// `thermal_hysteresis` a candidate) and its sensor's noise levels, drawn in that order.
pub fn programme_station(n: usize, dt_s: f64, rng: &mut ChaCha8Rng) -> (Station, SensorNoise) {
    let st = station(
        n,
        dt_s,
        Thermal::Programme {
            amplitude_c: 0.5,
            min_half_s: 2.0 * 3600.0,
            max_half_s: 6.0 * 3600.0,
        },
        rng,
    );
    let noise = draw_noise(rng);
    (st, noise)
}

/// The accelerometer's output in g at 1 g: 1 + bias polynomial of the true temperature
/// (1–10 µg/°C, a few 0.1 µg/°C²) + the 1 g tilt term (cos θ − 1) + `extra_g` + noise.
pub fn output_g(
    st: &Station,
    noise: &SensorNoise,
    extra_g: &[f64],
    rng: &mut ChaCha8Rng,
) -> Vec<f64> {
    let n = st.t_s.len();
    let e = sensor_noise(
        n,
        st.dt_s,
        noise.white_1s,
        noise.flicker_floor,
        noise.rw_per_sqrt_s,
        rng,
    );
    let t_ref = st.temp_true_c[0];
    let k1 = rng.random_range(1.0e-6..10.0e-6) * if rng.random::<bool>() { 1.0 } else { -1.0 };
    let k2 = rng.random_range(-0.5e-6..0.5e-6);
    let rad = std::f64::consts::PI / (180.0 * 3600.0);
    (0..n)
        .map(|i| {
            let d = st.temp_true_c[i] - t_ref;
            let th =
                (st.tilt_true_arcsec.0[i].powi(2) + st.tilt_true_arcsec.1[i].powi(2)).sqrt() * rad;
            1.0 + 3.0e-5 + k1 * d + k2 * d * d + (th.cos() - 1.0) + extra_g[i] + e[i]
        })
        .collect()
}

/// The record as the board would log it (measured channels only).
pub fn log_of(st: &Station, output_g: Vec<f64>) -> Log {
    let mut log = Log::with_time(st.t_s.clone()).expect("time");
    log.set_meta("input_g", "1").expect("meta");
    for (name, v) in [
        ("output_g", output_g),
        ("temperature_c", st.temp_meas_c.clone()),
        ("tilt_x_arcsec", st.tilt_meas_arcsec.0.clone()),
        ("tilt_y_arcsec", st.tilt_meas_arcsec.1.clone()),
        ("pressure_hpa", st.pressure_meas_hpa.clone()),
    ] {
        log.push_column(name, v).expect("column");
    }
    log
}

/// A fresh generator from a seed.
pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// Wilson score interval (95 %, z = 1.96) of `k` successes in `n` trials.
pub fn wilson(k: usize, n: usize) -> (f64, f64) {
    if n == 0 {
        return (0.0, 1.0);
    }
    let z = 1.959_964_f64;
    let (k, n) = (k as f64, n as f64);
    let p = k / n;
    let den = 1.0 + z * z / n;
    let c = (p + z * z / (2.0 * n)) / den;
    let h = z * (p * (1.0 - p) / n + z * z / (4.0 * n * n)).sqrt() / den;
    ((c - h).max(0.0), (c + h).min(1.0))
}

/// One-sided exact (Clopper–Pearson) upper bound at confidence 1 − `alpha` of a rate with `k`
/// events in `n` trials (bisection on the binomial CDF).
pub fn binomial_upper(k: usize, n: usize, alpha: f64) -> f64 {
    let cdf = |p: f64| {
        // P(X ≤ k | n, p)
        let mut term = (1.0 - p).powi(n as i32);
        let mut s = term;
        for i in 0..k {
            term *= (n - i) as f64 / (i + 1) as f64 * p / (1.0 - p).max(1e-300);
            s += term;
        }
        s
    };
    let (mut lo, mut hi) = (k as f64 / n.max(1) as f64, 1.0);
    for _ in 0..60 {
        let m = 0.5 * (lo + hi);
        if cdf(m) > alpha {
            lo = m;
        } else {
            hi = m;
        }
    }
    hi
}

/// The bias K0 (g) of `table`'s thermal models at `t_c` (inside the table's range).
pub fn bias_g_at(table: &CalibrationTable, t_c: f64) -> f64 {
    table
        .thermal
        .coefficients_at(Celsius(t_c))
        .expect("in range")
        .0
        .bias_g
}

/// Runs the discovery on `log` with the default options, given the calibration `table` (if any).
pub fn discover(log: Log, table: Option<&CalibrationTable>) -> Discovery {
    disc::discover_log(
        log,
        &[],
        &DatasetOptions::default(),
        table,
        &select::Config::default(),
    )
    .expect("discover")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spectral_noise_is_the_sum_of_cosines_it_is_documented_as() {
        let (n, dt_s) = (50, 2.0);
        let psd = |f: f64| 1e-6 / f;
        let x = spectral_noise(n, dt_s, psd, &mut rng(9));
        // The same draws, summed directly: x_j = Σ_k √(S(f_k)Δf)(a_k cos + b_k sin)(2πf_k t_j).
        let big = (2 * n).next_power_of_two();
        let df = 1.0 / (big as f64 * dt_s);
        let mut r = rng(9);
        let terms: Vec<(f64, f64, f64)> = (1..=big / 2)
            .map(|k| {
                let f = k as f64 * df;
                let amp = (psd(f) * df).sqrt();
                (f, amp * gauss(&mut r), amp * gauss(&mut r))
            })
            .collect();
        for (j, &xj) in x.iter().enumerate() {
            let t = j as f64 * dt_s;
            let direct: f64 = terms
                .iter()
                .map(|&(f, a, b)| {
                    let th = std::f64::consts::TAU * f * t;
                    a * th.cos() + b * th.sin()
                })
                .sum();
            assert!(
                (xj - direct).abs() <= 1e-12 * (1.0 + direct.abs()),
                "j={j}: {xj} vs {direct}"
            );
        }
    }

    #[test]
    fn spectral_flicker_has_a_flat_allan_deviation_at_its_floor() {
        // Overlapping ADEV at τ = 16 and 256 samples, averaged over draws: flat, ≈ the floor.
        let (n, dt, floor) = (8192usize, 1.0, 1.0);
        let mut r = rng(7);
        let adev = |x: &[f64], m: usize| {
            let c: Vec<f64> = std::iter::once(0.0)
                .chain(x.iter().scan(0.0, |s, v| {
                    *s += v;
                    Some(*s)
                }))
                .collect();
            let k = x.len() + 1 - 2 * m;
            let s: f64 = (0..k)
                .map(|i| {
                    let d = (c[i + 2 * m] - 2.0 * c[i + m] + c[i]) / m as f64;
                    d * d
                })
                .sum();
            (s / (2.0 * k as f64)).sqrt()
        };
        let (mut a16, mut a256) = (0.0, 0.0);
        for _ in 0..8 {
            let x = flicker(n, dt, floor, &mut r);
            a16 += adev(&x, 16) / 8.0;
            a256 += adev(&x, 256) / 8.0;
        }
        assert!((a16 - floor).abs() < 0.2, "{a16}");
        assert!((a256 - floor).abs() < 0.3, "{a256}");
    }

    #[test]
    fn wilson_and_clopper_pearson_bounds_match_tabulated_values() {
        let (lo, hi) = wilson(8, 10);
        assert!(
            (lo - 0.490).abs() < 2e-3 && (hi - 0.943).abs() < 2e-3,
            "{lo} {hi}"
        );
        // 0 events in 59 trials: the 95 % upper bound is 1 − 0.05^(1/59) = 4.95 %.
        let u = binomial_upper(0, 59, 0.05);
        assert!((u - (1.0 - 0.05_f64.powf(1.0 / 59.0))).abs() < 1e-6, "{u}");
    }
}
