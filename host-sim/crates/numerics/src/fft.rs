//! Real FFTs through realfft (a maintained crate), planned once per length and thread.

use realfft::num_complex::Complex;
use realfft::RealFftPlanner;
use std::cell::RefCell;

thread_local! {
    static PLANNER: RefCell<RealFftPlanner<f64>> = RefCell::new(RealFftPlanner::new());
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
}
