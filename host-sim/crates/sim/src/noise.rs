//! Seeded random processes: Gaussian draws, AR(1) (discretized Ornstein–Uhlenbeck), random walk,
//! flicker (1/f) as a sum of AR(1) processes, and the three-component Allan noise of a sensor.
//!
//! Every part of the station draws from its own ChaCha8 stream derived from the scenario seed
//! ([`stream`]), so adding a draw to one part never shifts the random numbers of another.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// The generator used everywhere: ChaCha8, explicit seed, portable and reproducible.
pub type SimRng = ChaCha8Rng;

/// Independent stream `id` of the run with seed `seed`.
pub fn stream(seed: u64, id: u64) -> SimRng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(id);
    rng
}

/// One standard normal draw (ziggurat).
#[inline]
pub fn gauss(rng: &mut SimRng) -> f64 {
    rng.sample(StandardNormal)
}

/// A stationary AR(1) process x[n+1] = φ·x[n] + √(1−φ²)·σ·ε with φ = exp(−Δ/τ): the exact
/// sampling of an Ornstein–Uhlenbeck process of standard deviation σ and correlation time τ.
#[derive(Debug, Clone)]
pub struct Ar1 {
    phi: f64,
    drive: f64,
    x: f64,
}

impl Ar1 {
    /// Starts in the stationary distribution (first value drawn with standard deviation σ), so
    /// the statistics hold from the first sample and no burn-in is needed.
    pub fn new(std: f64, tau_s: f64, interval_s: f64, rng: &mut SimRng) -> Self {
        let phi = if tau_s > 0.0 {
            (-interval_s / tau_s).exp()
        } else {
            0.0
        };
        Ar1 {
            phi,
            drive: std * (1.0 - phi * phi).sqrt(),
            x: std * gauss(rng),
        }
    }

    /// Current value.
    #[inline]
    pub fn value(&self) -> f64 {
        self.x
    }

    /// Advances one interval and returns the new value.
    #[inline]
    pub fn step(&mut self, rng: &mut SimRng) -> f64 {
        self.x = self.phi * self.x + self.drive * gauss(rng);
        self.x
    }
}

/// A random walk x[n+1] = x[n] + s·√Δ·ε starting at 0: Brownian motion with diffusion
/// coefficient s (unit per √s).
#[derive(Debug, Clone)]
pub struct RandomWalk {
    step_std: f64,
    x: f64,
}

impl RandomWalk {
    /// A walk of `per_sqrt_s` units per √s sampled every `interval_s`.
    pub fn new(per_sqrt_s: f64, interval_s: f64) -> Self {
        RandomWalk {
            step_std: per_sqrt_s * interval_s.sqrt(),
            x: 0.0,
        }
    }

    /// Current value.
    #[inline]
    pub fn value(&self) -> f64 {
        self.x
    }

    /// Advances one interval and returns the new value.
    #[inline]
    pub fn step(&mut self, rng: &mut SimRng) -> f64 {
        self.x += self.step_std * gauss(rng);
        self.x
    }
}

/// Ratio between the correlation times of successive AR(1) components of [`Flicker`]
/// (√10: two per decade keeps the ripple of the Allan deviation below ±5 %).
const FLICKER_TAU_RATIO: f64 = 3.162_277_660_168_379_5;

/// Flicker (1/f) noise as a sum of equal-variance AR(1) processes with correlation times spaced
/// by a constant ratio r from τ_min to τ_max.
///
/// Each component has the one-sided PSD 4·v·τ/(1 + (2πfτ)²); summed over log-spaced τ this
/// tends to S(f) = v/(ln r · f) between 1/(2πτ_max) and 1/(2πτ_min). For S(f) = h₋₁/f the Allan
/// deviation is flat, σ² = 2·ln2·h₋₁, so the per-component variance for an Allan floor σ_f is
/// v = σ_f²·ln r/(2·ln 2).
#[derive(Debug, Clone)]
pub struct Flicker {
    parts: Vec<Ar1>,
}

impl Flicker {
    /// Flicker with Allan-deviation floor `floor` flat for τ between about 2·τ_min and τ_max/5.
    pub fn new(
        floor: f64,
        tau_min_s: f64,
        tau_max_s: f64,
        interval_s: f64,
        rng: &mut SimRng,
    ) -> Self {
        let mut parts = Vec::new();
        if floor > 0.0 && tau_max_s > tau_min_s {
            let v = floor * floor * FLICKER_TAU_RATIO.ln() / (2.0 * std::f64::consts::LN_2);
            let mut tau = tau_min_s;
            while tau <= tau_max_s * FLICKER_TAU_RATIO {
                parts.push(Ar1::new(v.sqrt(), tau, interval_s, rng));
                tau *= FLICKER_TAU_RATIO;
            }
        }
        Flicker { parts }
    }

    /// Number of AR(1) components (zero when the floor is zero).
    pub fn components(&self) -> usize {
        self.parts.len()
    }

    /// Advances one interval and returns the new value.
    #[inline]
    pub fn step(&mut self, rng: &mut SimRng) -> f64 {
        self.parts.iter_mut().map(|p| p.step(rng)).sum()
    }
}

/// The three Allan parameters of a sensor's noise, in the sensor's unit (g for the
/// accelerometer).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AllanParams {
    /// White noise: Allan deviation at τ = 1 s (unit; falls as τ^−1/2).
    pub white_adev_1s: f64,
    /// Flicker floor: the flat Allan deviation (unit).
    pub flicker_floor: f64,
    /// Random-walk coefficient K: Allan deviation K·√(τ/3) (unit per √s; rises as τ^+1/2).
    pub random_walk_per_sqrt_s: f64,
}

impl AllanParams {
    /// No noise at all.
    pub const NONE: Self = AllanParams {
        white_adev_1s: 0.0,
        flicker_floor: 0.0,
        random_walk_per_sqrt_s: 0.0,
    };
}

/// Sensor noise with the Allan deviation
/// σ²(τ) = w²·(1 s/τ) + f² + K²·τ/3 for τ ≥ the sample interval Δ.
///
/// Mapping to samples taken every Δ (each sample the average over its interval, as a ΔΣ ADC
/// delivers): white std w·√(1 s/Δ); flicker from [`Flicker`] with τ from Δ to 10× the run;
/// random walk steps of K·√Δ.
#[derive(Debug, Clone)]
pub struct AllanNoise {
    white_std: f64,
    flicker: Flicker,
    walk: RandomWalk,
}

impl AllanNoise {
    /// Noise for a run of `duration_s` sampled every `interval_s`.
    pub fn new(p: &AllanParams, interval_s: f64, duration_s: f64, rng: &mut SimRng) -> Self {
        AllanNoise {
            white_std: p.white_adev_1s / interval_s.sqrt(),
            flicker: Flicker::new(
                p.flicker_floor,
                interval_s,
                10.0 * duration_s.max(interval_s),
                interval_s,
                rng,
            ),
            walk: RandomWalk::new(p.random_walk_per_sqrt_s, interval_s),
        }
    }

    /// The next sample: white + flicker + random walk.
    #[inline]
    pub fn step(&mut self, rng: &mut SimRng) -> f64 {
        self.white_std * gauss(rng) + self.flicker.step(rng) + self.walk.step(rng)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Overlapping Allan deviation at averaging factor m (τ = m·1 s), written out from its
    /// definition: phase x_k = Σ (y − ȳ)·1 s over N + 1 points and
    /// σ² = Σ_k (x_{k+2m} − 2 x_{k+m} + x_k)² / (2 m² (N + 1 − 2m)). The analysis crate's
    /// `allan` (cross-checked against allantools) is above the simulator, which does not use it.
    pub(crate) fn oadev(y: &[f64], m: usize) -> f64 {
        let mean = y.iter().sum::<f64>() / y.len() as f64;
        let mut x = Vec::with_capacity(y.len() + 1);
        x.push(0.0);
        for v in y {
            x.push(x[x.len() - 1] + (v - mean));
        }
        let n = x.len();
        if n < 2 * m + 1 {
            return f64::NAN;
        }
        let s: f64 = (0..n - 2 * m)
            .map(|k| (x[k + 2 * m] - 2.0 * x[k + m] + x[k]).powi(2))
            .sum();
        (s / (2.0 * (m * m) as f64 * (n - 2 * m) as f64)).sqrt()
    }

    fn slope(y: &[f64], m1: usize, m2: usize) -> f64 {
        (oadev(y, m2) / oadev(y, m1)).ln() / ((m2 as f64) / (m1 as f64)).ln()
    }

    fn series(p: AllanParams, n: usize, seed: u64) -> Vec<f64> {
        let mut rng = stream(seed, 1);
        let mut noise = AllanNoise::new(&p, 1.0, n as f64, &mut rng);
        (0..n).map(|_| noise.step(&mut rng)).collect()
    }

    #[test]
    fn white_noise_has_slope_minus_one_half_and_the_given_adev_at_one_second() {
        let p = AllanParams {
            white_adev_1s: 2e-6,
            flicker_floor: 0.0,
            random_walk_per_sqrt_s: 0.0,
        };
        let y = series(p, 1 << 18, 11);
        let s = slope(&y, 4, 256);
        assert!((s + 0.5).abs() < 0.05, "slope {s}");
        let a1 = oadev(&y, 1);
        assert!((a1 / 2e-6 - 1.0).abs() < 0.02, "adev(1 s) {a1:e}");
    }

    #[test]
    fn flicker_noise_is_flat_at_the_given_floor() {
        let p = AllanParams {
            white_adev_1s: 0.0,
            flicker_floor: 1e-6,
            random_walk_per_sqrt_s: 0.0,
        };
        let n = 1 << 18;
        // Average the estimate over a few seeds: a single flicker realisation scatters ±20 %.
        let (mut a8, mut a512) = (0.0, 0.0);
        for seed in 0..6 {
            let y = series(p, n, 100 + seed);
            a8 += oadev(&y, 8) / 6.0;
            a512 += oadev(&y, 512) / 6.0;
        }
        let s = (a512 / a8).ln() / 64f64.ln();
        assert!(s.abs() < 0.08, "slope {s}");
        for a in [a8, a512] {
            assert!((a / 1e-6 - 1.0).abs() < 0.15, "floor {a:e}");
        }
    }

    #[test]
    fn random_walk_has_slope_plus_one_half_and_k_times_root_tau_over_three() {
        let k = 1e-8;
        let p = AllanParams {
            white_adev_1s: 0.0,
            flicker_floor: 0.0,
            random_walk_per_sqrt_s: k,
        };
        let (mut a4, mut a64) = (0.0, 0.0);
        for seed in 0..4 {
            let y = series(p, 1 << 18, 200 + seed);
            a4 += oadev(&y, 4) / 4.0;
            a64 += oadev(&y, 64) / 4.0;
        }
        let s = (a64 / a4).ln() / 16f64.ln();
        assert!((s - 0.5).abs() < 0.06, "slope {s}");
        let expect = k * (64.0f64 / 3.0).sqrt();
        assert!(
            (a64 / expect - 1.0).abs() < 0.15,
            "adev(64 s) {a64:e} vs {expect:e}"
        );
    }

    #[test]
    fn ar1_has_the_configured_std_and_correlation_time() {
        let (std, tau, dt) = (0.15, 900.0, 60.0);
        let mut rng = stream(7, 3);
        let mut p = Ar1::new(std, tau, dt, &mut rng);
        let n = 400_000;
        let x: Vec<f64> = (0..n).map(|_| p.step(&mut rng)).collect();
        let mean = x.iter().sum::<f64>() / n as f64;
        let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n as f64;
        let cov1 = x
            .windows(2)
            .map(|w| (w[0] - mean) * (w[1] - mean))
            .sum::<f64>()
            / (n - 1) as f64;
        let rho = cov1 / var;
        let tau_est = -dt / rho.ln();
        assert!((var.sqrt() / std - 1.0).abs() < 0.03, "std {}", var.sqrt());
        assert!((tau_est / tau - 1.0).abs() < 0.05, "tau {tau_est}");
    }

    #[test]
    fn streams_of_one_seed_are_independent_and_reproducible() {
        let a: Vec<f64> = (0..4).map(|_| gauss(&mut stream(5, 1))).collect();
        let mut r1 = stream(5, 1);
        let mut r2 = stream(5, 2);
        let x1: Vec<f64> = (0..4).map(|_| gauss(&mut r1)).collect();
        let x2: Vec<f64> = (0..4).map(|_| gauss(&mut r2)).collect();
        assert_ne!(x1, x2);
        assert_eq!(a[0], x1[0]);
        let mut r3 = stream(5, 1);
        assert_eq!(x1, (0..4).map(|_| gauss(&mut r3)).collect::<Vec<_>>());
    }
}
