//! The modified Allan deviation's sums (the inner-sum recurrence run as independent chains).

use super::Phase;

impl Phase {
    /// MDEV sum of squared inner sums and term count at factor `m`.
    pub(super) fn mdev_sum(&self, m: usize) -> (f64, usize) {
        let x = &self.x;
        let Some(n) = (x.len() + 1).checked_sub(3 * m) else {
            return (0.0, 0);
        };
        if n == 0 {
            return (0.0, 0);
        }
        // Inner sum at j, summed directly (restart value of a chain).
        let direct = |j: usize| -> f64 {
            (j..j + m)
                .map(|i| x[i + 2 * m] - 2.0 * x[i + m] + x[i])
                .sum()
        };
        // Step from j to j + 1; only valid for j + 3m < x.len().
        let step = |j: usize| x[j + 3 * m] - 3.0 * x[j + 2 * m] + 3.0 * x[j + m] - x[j];
        let valid = |j: usize| match &self.nan_before {
            None => true,
            Some(nb) => nb[j + 3 * m - 1] == nb[j],
        };
        const CHAINS: usize = 4;
        let part = n / CHAINS;
        let mut s = 0.0;
        let mut used = 0usize;
        let mut tail_start = 0;
        let mut tail_v = 0.0;
        if part >= 64 && self.nan_before.is_none() {
            // Independent chains interleaved, so the serial adds overlap in the pipeline.
            let mut v = [0.0f64; CHAINS];
            let mut acc = [0.0f64; CHAINS];
            for (c, vc) in v.iter_mut().enumerate() {
                *vc = direct(c * part);
            }
            for t in 0..part {
                for c in 0..CHAINS {
                    let j = c * part + t;
                    acc[c] += v[c] * v[c];
                    // The last step of the last chain may step past the final term; it is
                    // only taken when j + 1 is still a term.
                    if j + 1 < n {
                        v[c] += step(j);
                    }
                }
            }
            s = acc.iter().sum();
            used = CHAINS * part;
            tail_start = CHAINS * part;
            tail_v = v[CHAINS - 1];
        } else if n > 0 {
            tail_v = direct(0);
        }
        for j in tail_start..n {
            if valid(j) {
                s += tail_v * tail_v;
                used += 1;
            }
            if j + 1 < n {
                tail_v += step(j);
            }
        }
        (s, used)
    }
}
