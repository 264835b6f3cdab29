//! The host's numeric toolkit: one place for the linear algebra, the descriptive statistics and
//! the distribution functions every analysis uses (docs/numerics.md, "Host numerics").

pub mod distributions;
pub mod linalg;
pub mod stats;
