//! The host's numeric toolkit: one place for the linear algebra, the descriptive statistics, the
//! distribution functions, the real FFT and the one-dimensional minimiser every analysis uses
//! (docs/numerics.md, "Host numerics").

pub mod distributions;
pub mod fft;
pub mod lcg;
pub mod linalg;
pub mod optimize;
pub mod parallel;
pub mod series;
pub mod stats;
