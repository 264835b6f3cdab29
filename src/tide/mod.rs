//! Solid-earth tide: the change of gravity and the tilt of the ground at a station, from a
//! low-precision analytic ephemeris of the Moon and the Sun.
//!
//! Used by the station simulator (tilt disturbs the 0 g position, gravity the 1 g logs) and by
//! the model discovery (`tidal_gravity`, `tidal_tilt` effects). The model, its constants, the
//! sign conventions and the agreement reached against ETERNA are written up in `docs/tide.md`.
//!
//! The computation is direct rather than harmonic: the Moon (Meeus ch. 47, ELP-2000/82 truncated)
//! and the Sun (Meeus ch. 25) are placed in the equatorial frame of date, the Earth is turned by
//! the mean sidereal time, and the gradient of the degree-2 (Moon and Sun) and degree-3 (Moon)
//! tide-generating potential is taken at the station's geocentric position. The elastic Earth
//! enters through the gravimetric factor δ = 1 + h − 3k/2 and the tilt factor γ = 1 + k − h,
//! split by tidal species so that each band gets its own Love numbers, with the free-core-nutation
//! resonance applied to the K1 line. No catalogue is stored, so the model is small enough for the
//! MCU and fast on the host.
//!
//! Everything is f64: the potential is a difference of large numbers only in the ephemeris
//! arguments (centuries × 481 267 °), and f32 would lose the Moon's position there.
//!
//! One file per concern: [`constants`] (physical constants, Love numbers), [`time`] (UTC,
//! Julian dates, sidereal time), [`ephemeris`] (Moon and Sun), [`station`] (gravity and tilt at
//! a station, series), plus the harmonic and CTE-1973 references.

use crate::units::{Gs, Radians, TiltArcsec, RAD_PER_ARCSEC};
use libm::{atan2, cos, fabs, floor, sin, sqrt};

pub mod constants;
pub mod ephemeris;
pub mod station;
pub mod time;

pub use constants::*;
pub use ephemeris::*;
pub use station::*;
pub use time::*;

// ---------------------------------------------------------------------------------------------
// Errors
// ---------------------------------------------------------------------------------------------

/// What was wrong with an input to the tide model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TideError {
    /// Month outside 1..=12.
    MonthOutOfRange,
    /// Day outside the month (leap years are known).
    DayOutOfRange,
    /// Hour ≥ 24, minute ≥ 60 or second outside 0 ≤ s < 61 (61 allows a leap second).
    TimeOfDayOutOfRange,
    /// Year outside 1600..=2400, where the Gregorian calendar and the ephemeris both hold.
    YearOutOfRange,
    /// Latitude outside −90..=90°.
    LatitudeOutOfRange,
    /// Height outside −11 000..=100 000 m (a typo, not a station).
    HeightOutOfRange,
    /// A NaN or infinite input.
    NotFinite,
    /// Series sample interval not strictly positive.
    IntervalNotPositive,
}

pub mod cte1973;
pub mod harmonic;

#[cfg(test)]
mod tests;
