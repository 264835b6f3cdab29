//! Real FFTs through realfft (a maintained crate), planned once per length and thread.

use realfft::num_complex::Complex;
use realfft::RealFftPlanner;
use std::cell::RefCell;

thread_local! {
    static PLANNER: RefCell<RealFftPlanner<f64>> = RefCell::new(RealFftPlanner::new());
}

/// The spectrum of a real segment, bins 0..n/2 (forward, unnormalised: X_k = Σ x_j e^{−2πi kj/n});
/// `x` is used as scratch.
pub fn half_spectrum(x: &mut [f64]) -> Vec<(f64, f64)> {
    let n = x.len();
    if n < 2 {
        return x.iter().map(|&v| (v, 0.0)).collect();
    }
    let plan = PLANNER.with(|p| p.borrow_mut().plan_fft_forward(n));
    let mut out = plan.make_output_vec();
    // The lengths are the plan's own: process() cannot fail here.
    if plan.process(x, &mut out).is_err() {
        return vec![(f64::NAN, f64::NAN); n / 2];
    }
    out.iter().take(n / 2).map(|c| (c.re, c.im)).collect()
}

/// The real series of even length `2 (half.len() − 1)` whose spectrum is the Hermitian
/// extension of `half` (bins 0..=N/2), unnormalised: x_j = Σ_{k=0}^{N−1} X_k e^{+2πi kj/N} with
/// X_{N−k} = conj X_k. The imaginary parts of X_0 and X_{N/2} do not enter a real series and
/// are taken as zero.
pub fn real_from_half_spectrum(half: &[(f64, f64)]) -> Vec<f64> {
    if half.len() < 2 {
        return half.iter().map(|&(re, _)| re).collect();
    }
    let n = 2 * (half.len() - 1);
    let last = half.len() - 1;
    let mut spectrum: Vec<Complex<f64>> = half
        .iter()
        .enumerate()
        .map(|(k, &(re, im))| {
            let im = if k == 0 || k == last { 0.0 } else { im };
            Complex::new(re, im)
        })
        .collect();
    let plan = PLANNER.with(|p| p.borrow_mut().plan_fft_inverse(n));
    let mut out = plan.make_output_vec();
    // The lengths are the plan's own and the end bins are real: process() cannot fail here.
    if plan.process(&mut spectrum, &mut out).is_err() {
        return vec![f64::NAN; n];
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The direct sum x_j = Σ_k X_k e^{+2πi kj/N} over the Hermitian extension, in f64.
    fn direct(half: &[(f64, f64)]) -> Vec<f64> {
        let n = 2 * (half.len() - 1);
        (0..n)
            .map(|j| {
                (0..n)
                    .map(|k| {
                        let (re, im) = if k <= n / 2 {
                            half[k]
                        } else {
                            (half[n - k].0, -half[n - k].1)
                        };
                        let (re, im) = if k == 0 || k == n / 2 {
                            (re, 0.0)
                        } else {
                            (re, im)
                        };
                        let th = std::f64::consts::TAU * (k * j) as f64 / n as f64;
                        re * th.cos() - im * th.sin()
                    })
                    .sum()
            })
            .collect()
    }

    #[test]
    fn the_real_series_of_a_half_spectrum_is_the_direct_inverse_sum() {
        for n in [2usize, 8, 12, 64] {
            let half: Vec<(f64, f64)> = (0..=n / 2)
                .map(|k| ((k as f64 * 0.7).sin() + 0.3, (k as f64 * 1.3).cos()))
                .collect();
            let fast = real_from_half_spectrum(&half);
            let slow = direct(&half);
            assert_eq!(fast.len(), n);
            for (a, b) in fast.iter().zip(&slow) {
                assert!((a - b).abs() <= 1e-12 * n as f64, "n={n}: {a} vs {b}");
            }
        }
    }

    #[test]
    fn fft_of_a_cosine_puts_its_power_in_its_bin() {
        let n = 64;
        let mut x: Vec<f64> = (0..n)
            .map(|i| (2.0 * std::f64::consts::PI * 5.0 * i as f64 / n as f64).cos())
            .collect();
        let x = half_spectrum(&mut x);
        assert_eq!(x.len(), 32);
        assert!((x[5].0 - 32.0).abs() < 1e-9 && x[5].1.abs() < 1e-9);
        assert!(x[4].0.abs() < 1e-9 && x[6].0.abs() < 1e-9);
    }

    /// The spectrum equals the DFT's definition, Σ x_k e^{−2πi jk/n}, summed in f64 with exact
    /// twiddles (k·j reduced mod n), within 1e-12 of the largest bin.
    #[test]
    fn half_spectrum_is_the_dft_within_1e_12() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for n in [256usize, 4096] {
            let x: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
            let got = half_spectrum(&mut x.clone());
            let dft: Vec<(f64, f64)> = (0..n / 2)
                .map(|j| {
                    x.iter().enumerate().fold((0.0, 0.0), |(re, im), (k, v)| {
                        let a = -2.0 * std::f64::consts::PI * ((j * k) % n) as f64 / n as f64;
                        (re + v * a.cos(), im + v * a.sin())
                    })
                })
                .collect();
            let scale = dft.iter().map(|c| c.0.hypot(c.1)).fold(0.0, f64::max);
            for (j, (g, d)) in got.iter().zip(&dft).enumerate() {
                let err = (g.0 - d.0).hypot(g.1 - d.1);
                assert!(err <= 1e-12 * scale, "n {n} bin {j}: {g:?} vs {d:?}");
            }
        }
    }
}
