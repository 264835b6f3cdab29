//! Physical units as newtypes, so that a value's unit is in its type and never guessed.
//!
//! Angles used by the maths are radians; the paper and the lab print misalignments in arcmin and
//! tilts in arcsec. The conversions live here and only here.

/// Radians per arcminute (π / 10 800).
pub const RAD_PER_ARCMIN: f64 = core::f64::consts::PI / 10_800.0;
/// Radians per arcsecond (π / 648 000): 1" = 4.848 µrad.
pub const RAD_PER_ARCSEC: f64 = core::f64::consts::PI / 648_000.0;
/// Absolute zero in °C, the lower bound of any physical temperature.
pub const ABSOLUTE_ZERO_C: f64 = -273.15;

macro_rules! unit {
    ($(#[$doc:meta])* $name:ident) => {
        $(#[$doc])*
        #[derive(Debug, Clone, Copy, PartialEq, PartialOrd, Default)]
        pub struct $name(pub f64);

        impl $name {
            /// The bare number in this unit.
            #[inline]
            pub const fn value(self) -> f64 {
                self.0
            }
            /// True when the value is neither NaN nor infinite.
            #[inline]
            pub fn is_finite(self) -> bool {
                self.0.is_finite()
            }
        }
    };
}

unit!(
    /// Electric potential in volts (accelerometer output E across the sense resistor).
    Volts
);
unit!(
    /// Temperature in degrees Celsius (ITS-90).
    Celsius
);
unit!(
    /// Resistance of the platinum RTD in ohms.
    RtdOhms
);
unit!(
    /// Resistance in ohms (reference or sense resistors).
    Ohms
);
unit!(
    /// Foundation tilt in arcseconds.
    TiltArcsec
);
unit!(
    /// Angle in arcminutes (how the paper prints misalignments δp, δo).
    Arcmin
);
unit!(
    /// Angle in radians.
    Radians
);
unit!(
    /// Acceleration in units of g (the paper's unit for a_i, a_p, a_o and K0).
    Gs
);
unit!(
    /// Time in seconds.
    Seconds
);

impl Arcmin {
    /// The same angle in radians.
    #[inline]
    pub fn to_radians(self) -> Radians {
        Radians(self.0 * RAD_PER_ARCMIN)
    }
}

impl TiltArcsec {
    /// The same angle in radians.
    #[inline]
    pub fn to_radians(self) -> Radians {
        Radians(self.0 * RAD_PER_ARCSEC)
    }
}

impl Radians {
    /// The same angle in arcminutes.
    #[inline]
    pub fn to_arcmin(self) -> Arcmin {
        Arcmin(self.0 / RAD_PER_ARCMIN)
    }
    /// The same angle in arcseconds.
    #[inline]
    pub fn to_arcsec(self) -> TiltArcsec {
        TiltArcsec(self.0 / RAD_PER_ARCSEC)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_arcsecond_is_4_848_microradians() {
        // Paper: 1" = 4.85 µrad.
        assert!((TiltArcsec(1.0).to_radians().0 - 4.848_136_8e-6).abs() < 1e-12);
    }

    #[test]
    fn arcmin_round_trip_is_exact_to_rounding() {
        let a = Arcmin(2.62);
        assert!((a.to_radians().to_arcmin().0 - 2.62).abs() < 1e-14);
        assert!((Arcmin(60.0).to_radians().0 - TiltArcsec(3600.0).to_radians().0).abs() < 1e-18);
    }
}
