//! The 64-bit LCG (Knuth's MMIX constants) that generates the Allan cross-check fixture in
//! Python (`host-sim/tests/data/make_allantools_xcheck.py`) and its 41-day benchmark log in
//! Rust: the same few lines in both languages give the same numbers bit for bit, which no
//! library generator promises.

/// The generator's state.
#[derive(Debug, Clone)]
pub struct Lcg(pub u64);

impl Lcg {
    /// A uniform number in [0, 1) (the state's top 53 bits).
    pub fn uniform(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Sum of 12 uniforms minus 6: mean 0, variance exactly 1 (near-Gaussian).
    pub fn normal(&mut self) -> f64 {
        (0..12).map(|_| self.uniform()).sum::<f64>() - 6.0
    }
}
