//! Reproducible standard normal deviates for the discovery's unit tests, without a random-number
//! crate in the library: a 64-bit LCG (Knuth's MMIX constants), each deviate the sum of 12
//! uniforms minus 6 (variance 1; tails cut at ±6, which these tests never reach).

/// `n` deviates from the LCG seeded with `state`.
pub fn normals(n: usize, mut state: u64) -> Vec<f64> {
    (0..n)
        .map(|_| {
            (0..12)
                .map(|_| {
                    state = state
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    (state >> 11) as f64 / (1u64 << 53) as f64
                })
                .sum::<f64>()
                - 6.0
        })
        .collect()
}
