//! Solid-earth tide at the site: the change of gravity along the vertical and the tilt of the
//! ground, the one place where the simulator asks for them ([`tide_at`]).
//!
//! The tide changes slowly (periods ≥ 12 h), so it is evaluated every `step_s` seconds and
//! interpolated linearly in between ([`TideSampler`]): at 60 s the interpolation error is below
//! 1e-4 of the amplitude, and the ephemeris is not recomputed 3.5 million times for a 1 Hz run.

use serde::{Deserialize, Serialize};

use super::time::Utc;

/// A wave group: all catalogue waves whose frequency lies in [from, to) cycles per day.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GroupDef {
    /// ETERNA-style name (the main wave).
    pub name: &'static str,
    /// Lower bound, cpd (inclusive).
    pub from_cpd: f64,
    /// Upper bound, cpd (exclusive).
    pub to_cpd: f64,
}

/// The wave groups, in frequency order (boundaries between the main waves; the grouping ETERNA
/// users take for one to three months of data): the tidal analysis fits them and a scenario's
/// tide corrections name them.
pub const GROUPS: [GroupDef; 10] = [
    GroupDef {
        name: "Q1",
        from_cpd: 0.5,
        to_cpd: 0.911,
    },
    GroupDef {
        name: "O1",
        from_cpd: 0.911,
        to_cpd: 0.947,
    },
    GroupDef {
        name: "M1",
        from_cpd: 0.947,
        to_cpd: 0.986,
    },
    GroupDef {
        name: "P1K1",
        from_cpd: 0.986,
        to_cpd: 1.016,
    },
    GroupDef {
        name: "J1",
        from_cpd: 1.016,
        to_cpd: 1.5,
    },
    GroupDef {
        name: "N2",
        from_cpd: 1.5,
        to_cpd: 1.916,
    },
    GroupDef {
        name: "M2",
        from_cpd: 1.916,
        to_cpd: 1.95,
    },
    GroupDef {
        name: "L2",
        from_cpd: 1.95,
        to_cpd: 1.986,
    },
    GroupDef {
        name: "S2K2",
        from_cpd: 1.986,
        to_cpd: 2.5,
    },
    GroupDef {
        name: "M3",
        from_cpd: 2.5,
        to_cpd: 3.5,
    },
];

/// Where the station is.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Site {
    /// Geodetic latitude, degrees north.
    pub latitude_deg: f64,
    /// Longitude, degrees east.
    pub longitude_deg: f64,
    /// Ellipsoidal height, metres.
    pub height_m: f64,
}

/// Tide options.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TideParams {
    /// Include the tide (gravity into a_i, tilt into the foundation tilt).
    pub enabled: bool,
    /// Azimuth (0° north, 90° east) towards which a positive foundation tilt raises the input
    /// axis: the tide tilt is projected on it.
    pub tilt_azimuth_deg: f64,
    /// Evaluation step of the tide, seconds (interpolated linearly in between).
    pub step_s: f64,
}

/// Tide at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Tide {
    /// Gravity change, nm/s² (positive: stronger gravity).
    pub gravity_nm_s2: f64,
    /// Tilt along the configured azimuth, arcsec.
    pub tilt_arcsec: f64,
}

/// Why the tide cannot be evaluated.
#[derive(Debug, thiserror::Error)]
pub enum TideError {
    /// The site is not a place on Earth.
    #[error("tide: site refused: {0}")]
    Site(String),
}

/// The tide model for a site.
#[derive(Debug, Clone)]
pub struct TideModel {
    station: accomp::tide::Station,
    azimuth_deg: f64,
}

impl TideModel {
    /// The model at `site`, tilt projected on `azimuth_deg`.
    pub fn new(site: &Site, azimuth_deg: f64) -> Result<Self, TideError> {
        let station =
            accomp::tide::Station::new(site.latitude_deg, site.longitude_deg, site.height_m)
                .map_err(|e| TideError::Site(format!("{e:?}")))?;
        Ok(TideModel {
            station,
            azimuth_deg,
        })
    }

    /// The tide at a UTC instant: the single call into the tide model.
    pub fn tide_at(&self, utc: Utc) -> Tide {
        let s = self.station.tide_at_unix_seconds(utc.0);
        Tide {
            gravity_nm_s2: s.gravity_nm_s2,
            tilt_arcsec: s.tilt_arcsec(self.azimuth_deg).0,
        }
    }
}

/// Tide evaluated on a coarse grid and interpolated linearly.
#[derive(Debug, Clone)]
pub struct TideSampler {
    model: Option<TideModel>,
    start: Utc,
    step_s: f64,
    k: i64,
    a: Tide,
    b: Tide,
}

impl TideSampler {
    /// A sampler from `start`; `None` model: no tide (all zeros).
    pub fn new(model: Option<TideModel>, start: Utc, step_s: f64) -> Self {
        let step_s = if step_s > 0.0 { step_s } else { 60.0 };
        let mut s = TideSampler {
            model,
            start,
            step_s,
            k: i64::MIN,
            a: Tide::default(),
            b: Tide::default(),
        };
        s.load(0);
        s
    }

    fn load(&mut self, k: i64) {
        if let Some(m) = &self.model {
            let t = |k: i64| self.start.plus(k as f64 * self.step_s);
            self.a = if k == self.k + 1 {
                self.b
            } else {
                m.tide_at(t(k))
            };
            self.b = m.tide_at(t(k + 1));
        }
        self.k = k;
    }

    /// The tide `t_s` seconds after the start.
    pub fn at(&mut self, t_s: f64) -> Tide {
        if self.model.is_none() {
            return Tide::default();
        }
        let k = (t_s / self.step_s).floor() as i64;
        if k != self.k {
            self.load(k);
        }
        let f = t_s / self.step_s - k as f64;
        Tide {
            gravity_nm_s2: self.a.gravity_nm_s2 + f * (self.b.gravity_nm_s2 - self.a.gravity_nm_s2),
            tilt_arcsec: self.a.tilt_arcsec + f * (self.b.tilt_arcsec - self.a.tilt_arcsec),
        }
    }
}
