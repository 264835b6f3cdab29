//! The overlapping Allan deviation's sums: one tau with gaps, and the vectorised multi-tau pass
//! of a gapless record.

use super::Phase;
use std::ops::Range;

impl Phase {
    /// OADEV sum of squares and term count at factor `m`.
    pub(super) fn oadev_sum(&self, m: usize) -> (f64, usize) {
        let x = &self.x;
        let Some(n) = x.len().checked_sub(2 * m) else {
            return (0.0, 0);
        };
        match &self.nan_before {
            None => oadev_sums_gapless(x, &[m]).pop().unwrap_or((0.0, 0)),
            Some(nb) => {
                let (a, b, c) = (&x[..n], &x[m..m + n], &x[2 * m..2 * m + n]);
                let mut s = 0.0;
                let mut used = 0;
                for k in 0..n {
                    if nb[k + 2 * m] == nb[k] {
                        let d = c[k] - 2.0 * b[k] + a[k];
                        s += d * d;
                        used += 1;
                    }
                }
                (s, used)
            }
        }
    }
}

/// Lanes of an OADEV sum: term `k` goes to partial sum `k % LANES`, the partial sums are added
/// in lane order at the end, then the last `n % LANES` terms one by one. A fixed order, so the
/// result does not depend on blocking, tau grouping or threads (and the loop vectorises).
const LANES: usize = 8;

/// Phase points per block of the multi-tau OADEV pass (32 KiB): the block and the short-tau
/// windows next to it stay in L1/L2 while every tau is evaluated on them.
const BLOCK: usize = 4096;

/// Taus evaluated side by side in the OADEV kernel: their accumulator chains are independent,
/// which hides the add latency that one tau's 8 lanes alone cannot.
const TAUS_PER_KERNEL: usize = 4;

/// OADEV sums `sum_k (x_{k+2m} - 2 x_{k+m} + x_k)^2` and term counts for every `m` in `ms`, in
/// one pass over `x` by blocks (all taus on a block before the next block).
pub(super) fn oadev_sums_gapless(x: &[f64], ms: &[usize]) -> Vec<(f64, usize)> {
    let ns: Vec<usize> = ms.iter().map(|&m| x.len().saturating_sub(2 * m)).collect();
    let mut acc = vec![[0.0f64; LANES]; ms.len()];
    let max_n = ns.iter().copied().max().unwrap_or(0);
    let mut full: Vec<usize> = Vec::with_capacity(ms.len());
    for k0 in (0..max_n).step_by(BLOCK) {
        // Taus with a whole block left go through the multi-tau kernel; a tau's last, shorter
        // block (whole chunks of LANES only) through the one-tau kernel.
        full.clear();
        for (i, &n) in ns.iter().enumerate() {
            if n >= k0 + BLOCK {
                full.push(i);
            } else if n > k0 {
                let len = (n - k0) / LANES * LANES;
                let mut a = [acc[i]];
                accumulate_block::<1>(&mut a, x, k0..k0 + len, [ms[i]]);
                acc[i] = a[0];
            }
        }
        let mut groups = full.chunks_exact(TAUS_PER_KERNEL);
        for g in &mut groups {
            let idx: [usize; TAUS_PER_KERNEL] = std::array::from_fn(|t| g[t]);
            let mut a = idx.map(|i| acc[i]);
            accumulate_block(&mut a, x, k0..k0 + BLOCK, idx.map(|i| ms[i]));
            for (t, &i) in idx.iter().enumerate() {
                acc[i] = a[t];
            }
        }
        for &i in groups.remainder() {
            let mut a = [acc[i]];
            accumulate_block::<1>(&mut a, x, k0..k0 + BLOCK, [ms[i]]);
            acc[i] = a[0];
        }
    }
    ms.iter()
        .zip(&ns)
        .zip(&acc)
        .map(|((&m, &n), lanes)| {
            let mut s: f64 = lanes.iter().sum();
            for k in n / LANES * LANES..n {
                let d = x[k + 2 * m] - 2.0 * x[k + m] + x[k];
                s += d * d;
            }
            (s, n)
        })
        .collect()
}

/// Adds the squared second differences of `terms` (their count a multiple of [`LANES`], all
/// terms existing) of `T` taus to their lane accumulators; AVX2 when the CPU has it (same
/// operations in the same order, so the same result).
fn accumulate_block<const T: usize>(
    acc: &mut [[f64; LANES]; T],
    x: &[f64],
    terms: Range<usize>,
    ms: [usize; T],
) {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2, checked just above.
            unsafe { accumulate_block_avx2(acc, x, terms, ms) };
            return;
        }
    }
    accumulate_block_portable(acc, x, terms, ms);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn accumulate_block_avx2<const T: usize>(
    acc: &mut [[f64; LANES]; T],
    x: &[f64],
    terms: Range<usize>,
    ms: [usize; T],
) {
    accumulate_block_portable(acc, x, terms, ms);
}

#[inline(always)]
fn accumulate_block_portable<const T: usize>(
    acc: &mut [[f64; LANES]; T],
    x: &[f64],
    terms: Range<usize>,
    ms: [usize; T],
) {
    let Range { start, end } = terms;
    let a = &x[start..end];
    let b: [&[f64]; T] = ms.map(|m| &x[start + m..end + m]);
    let c: [&[f64]; T] = ms.map(|m| &x[start + 2 * m..end + 2 * m]);
    let mut lanes = *acc;
    for (j, ka) in a.chunks_exact(LANES).enumerate() {
        let r = j * LANES..(j + 1) * LANES;
        for t in 0..T {
            let (kb, kc) = (&b[t][r.clone()], &c[t][r.clone()]);
            for l in 0..LANES {
                let d = kc[l] - 2.0 * kb[l] + ka[l];
                lanes[t][l] += d * d;
            }
        }
    }
    *acc = lanes;
}
