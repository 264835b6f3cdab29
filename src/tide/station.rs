//! The station: the tide-generating potential's gradient at a place on the elastic Earth, as
//! gravity and tilt, one instant or a series.

use super::*;

// ---------------------------------------------------------------------------------------------
// Station
// ---------------------------------------------------------------------------------------------

/// Elastic factors of one station: gravimetric δ and tilt γ per species.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ElasticFactors {
    /// δ for the degree-2 long-period (2,0) band, latitude corrected.
    pub delta_20: f64,
    /// δ for the degree-2 diurnal band at O1 (the resonance reference).
    pub delta_21: f64,
    /// δ at K1, after the free-core-nutation resonance.
    pub delta_k1: f64,
    /// δ for the degree-2 semidiurnal band.
    pub delta_22: f64,
    /// δ for degree 3.
    pub delta_3: f64,
    /// γ for the long-period band (no latitude term: it is singular where P20 vanishes).
    pub gamma_20: f64,
    /// γ for the diurnal band at O1.
    pub gamma_21: f64,
    /// γ at K1.
    pub gamma_k1: f64,
    /// γ for the semidiurnal band.
    pub gamma_22: f64,
    /// γ for degree 3.
    pub gamma_3: f64,
}

/// A station: where the tide is evaluated, with all position-only quantities precomputed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Station {
    pub(super) latitude_deg: f64,
    pub(super) longitude_rad: f64,
    pub(super) height_m: f64,
    /// sin and cos of the geocentric latitude.
    pub(super) sin_gc: f64,
    pub(super) cos_gc: f64,
    /// Geocentric radius, m.
    pub(super) radius_m: f64,
    /// sin and cos of (geodetic − geocentric latitude): rotates radial/north into up/north.
    pub(super) sin_dev: f64,
    pub(super) cos_dev: f64,
    /// Normal gravity at the station (GRS80 + free air), m/s².
    pub(super) gravity_m_s2: f64,
    /// δ(2,0)·(3 s² − 1) with the latitude terms multiplied out (finite where P20 = 0).
    pub(super) delta20_p20: f64,
    pub(super) factors: ElasticFactors,
}

/// Tide at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TideSample {
    /// Change of gravity, nm/s², positive when the gravity the station feels increases
    /// (ETERNA / earthtide convention: about −δ × the upward tidal acceleration).
    pub gravity_nm_s2: f64,
    /// Tilt towards north, milliarcseconds: γ × (northward tidal acceleration) / g.
    ///
    /// Positive when the tide pulls north, which is what a horizontal accelerometer whose
    /// sensitive axis points north reads (in units of g × angle). Same sign as ETERNA's /
    /// earthtide's `tidal_tilt` at azimuth 0 (checked by the test vectors).
    pub tilt_north_mas: f64,
    /// Tilt towards east, milliarcseconds, same convention.
    pub tilt_east_mas: f64,
}

impl TideSample {
    /// Tilt along an azimuth (0° = north, 90° = east, clockwise), milliarcseconds.
    #[inline]
    pub fn tilt_mas(&self, azimuth_deg: f64) -> f64 {
        let az = azimuth_deg * DEG;
        self.tilt_north_mas * cos(az) + self.tilt_east_mas * sin(az)
    }
    /// Tilt along an azimuth, arcseconds.
    #[inline]
    pub fn tilt_arcsec(&self, azimuth_deg: f64) -> TiltArcsec {
        TiltArcsec(self.tilt_mas(azimuth_deg) * 1.0e-3)
    }
    /// Tilt along an azimuth, radians.
    #[inline]
    pub fn tilt_radians(&self, azimuth_deg: f64) -> Radians {
        Radians(self.tilt_mas(azimuth_deg) / MAS_PER_RAD)
    }
    /// Gravity change in m/s².
    #[inline]
    pub fn gravity_m_s2(&self) -> f64 {
        self.gravity_nm_s2 / NM_S2_PER_M_S2
    }
    /// Gravity change in units of standard gravity.
    #[inline]
    pub fn gravity_gs(&self) -> Gs {
        Gs(self.gravity_m_s2() / STANDARD_GRAVITY_M_S2)
    }
}

/// Gravity of the elastic model split by tidal band, nm/s² (same sign as
/// [`TideSample::gravity_nm_s2`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GravitySpecies {
    /// Degree 2, order 0 (long-period, including the permanent tide).
    pub long_period_nm_s2: f64,
    /// Degree 2, order 1 (diurnal, K1 with its resonant factor).
    pub diurnal_nm_s2: f64,
    /// Degree 2, order 2 (semidiurnal).
    pub semidiurnal_nm_s2: f64,
    /// Degree 3, all orders (the Moon's; terdiurnal M3 and small parts of the other bands).
    pub degree3_nm_s2: f64,
}

/// Radial, north and east gradient of one piece of the potential (m/s², up/north/east).
#[derive(Clone, Copy, Default)]
pub(super) struct Gradient {
    up: f64,
    north: f64,
    east: f64,
}

impl Station {
    /// A station at geodetic (GRS80/WGS84) latitude, east longitude (degrees) and ellipsoidal
    /// height (metres).
    pub fn new(latitude_deg: f64, longitude_deg: f64, height_m: f64) -> Result<Self, TideError> {
        if !(latitude_deg.is_finite() && longitude_deg.is_finite() && height_m.is_finite()) {
            return Err(TideError::NotFinite);
        }
        if !(-90.0..=90.0).contains(&latitude_deg) {
            return Err(TideError::LatitudeOutOfRange);
        }
        if !(-11_000.0..=100_000.0).contains(&height_m) {
            return Err(TideError::HeightOutOfRange);
        }
        let phi = latitude_deg * DEG;
        let (sp, cp) = (sin(phi), cos(phi));
        let n = GRS80_A_M / sqrt(1.0 - GRS80_E2 * sp * sp);
        let p = (n + height_m) * cp;
        let z = (n * (1.0 - GRS80_E2) + height_m) * sp;
        let radius_m = sqrt(p * p + z * z);
        let gc = atan2(z, p);
        let dev = phi - gc;
        let (sin_gc, cos_gc) = (sin(gc), cos(gc));

        let gravity_m_s2 = GRS80_GAMMA_E_M_S2 * (1.0 + GRS80_SOMIGLIANA_K * sp * sp)
            / sqrt(1.0 - GRS80_E2 * sp * sp)
            - FREE_AIR_GRADIENT_PER_M * height_m;

        // Latitude dependence (DDW 1999 as tabulated for ETERNA), in ct = cos(colatitude).
        let ct2 = sin_gc * sin_gc;
        let p20 = 3.0 * ct2 - 1.0;
        // 0.335410 = 3/(4√5), 0.894427 = 2/√5: normalisation of the "+"/"−" terms.
        let delta20_p20 = DELTA_2[0] * p20
            + DELTA_20_PLUS * 0.335_410 * (35.0 * ct2 * ct2 - 30.0 * ct2 + 3.0)
            + DELTA_20_MINUS * 0.894_427;
        let lat21 = 0.612_372 * (7.0 * ct2 - 3.0);
        let lat22 = 0.866_025 * (7.0 * ct2 - 1.0);
        let delta_21 = DELTA_2[1] + DELTA_21_PLUS * lat21;
        let delta_22 = DELTA_2[2] + DELTA_22_PLUS * lat22;
        let gamma_21 = 1.0 + LOVE_K_2[1] - LOVE_H_2[1] + GAMMA_21_PLUS * lat21;
        let gamma_22 = 1.0 + LOVE_K_2[2] - LOVE_H_2[2] + GAMMA_22_PLUS * lat22;
        let resonance = (OMEGA_K1_DEG_H - OMEGA_O1_DEG_H) / (OMEGA_FCN_DEG_H - OMEGA_K1_DEG_H);
        let factors = ElasticFactors {
            // Reported value at this latitude; where P20 ≈ 0 the ratio is meaningless and the
            // plain DDW value is shown instead (the computation uses delta20_p20).
            delta_20: if fabs(p20) > 1e-3 {
                delta20_p20 / p20
            } else {
                DELTA_2[0]
            },
            delta_21,
            delta_k1: delta_21 + DELTA_FCN * resonance,
            delta_22,
            delta_3: DELTA_3,
            gamma_20: 1.0 + LOVE_K_2[0] - LOVE_H_2[0],
            gamma_21,
            gamma_k1: gamma_21 + GAMMA_FCN * resonance,
            gamma_22,
            gamma_3: 1.0 + LOVE_HK_3.1 - LOVE_HK_3.0,
        };
        Ok(Self {
            latitude_deg,
            longitude_rad: longitude_deg * DEG,
            height_m,
            sin_gc,
            cos_gc,
            radius_m,
            sin_dev: sin(dev),
            cos_dev: cos(dev),
            gravity_m_s2,
            delta20_p20,
            factors,
        })
    }

    /// Geodetic latitude, degrees.
    pub fn latitude_deg(&self) -> f64 {
        self.latitude_deg
    }
    /// Ellipsoidal height, metres.
    pub fn height_m(&self) -> f64 {
        self.height_m
    }
    /// Geocentric latitude, degrees.
    pub fn geocentric_latitude_deg(&self) -> f64 {
        atan2(self.sin_gc, self.cos_gc) / DEG
    }
    /// Geocentric radius, metres.
    pub fn geocentric_radius_m(&self) -> f64 {
        self.radius_m
    }
    /// Normal gravity used to turn horizontal acceleration into tilt, m/s².
    pub fn normal_gravity_m_s2(&self) -> f64 {
        self.gravity_m_s2
    }
    /// The elastic factors in use at this station.
    pub fn elastic_factors(&self) -> ElasticFactors {
        self.factors
    }

    /// Tide at a Unix time (seconds since 1970-01-01 UTC).
    pub fn tide_at_unix_seconds(&self, unix_s: f64) -> TideSample {
        self.tide_at_julian_date(julian_date_from_unix_seconds(unix_s))
    }

    /// Tide at a UTC calendar instant.
    pub fn tide_at_utc(&self, time: &UtcTime) -> TideSample {
        self.tide_at_julian_date(time.julian_date())
    }

    /// Tide at a UTC Julian date.
    pub fn tide_at_julian_date(&self, jd_utc: f64) -> TideSample {
        self.tide_from_bodies(&Bodies::at_julian_date_utc(jd_utc), gmst_rad(jd_utc))
    }

    /// Tide from given body positions and Greenwich sidereal time (the series path).
    pub fn tide_from_bodies(&self, bodies: &Bodies, gmst: f64) -> TideSample {
        self.tide_parts(bodies, gmst).0
    }

    /// Gravity split by band at a Unix time: what the elastic model puts into each species.
    /// The parts sum to [`TideSample::gravity_nm_s2`].
    pub fn gravity_species_at_unix_seconds(&self, unix_s: f64) -> GravitySpecies {
        let jd = julian_date_from_unix_seconds(unix_s);
        self.tide_parts(&Bodies::at_julian_date_utc(jd), gmst_rad(jd))
            .1
    }

    /// The tide and its gravity split by species.
    fn tide_parts(&self, bodies: &Bodies, gmst: f64) -> (TideSample, GravitySpecies) {
        let lst = gmst + self.longitude_rad;
        let (s_lst, c_lst) = (sin(lst), cos(lst));
        let (s, c, r) = (self.sin_gc, self.cos_gc, self.radius_m);
        let f = &self.factors;

        // δ-weighted upward and north gradients per species: long-period, diurnal,
        // semidiurnal, degree 3 (the north part enters gravity through the deviation).
        let mut g_up = [0.0; 4];
        let mut g_north = [0.0; 4];
        let mut t_up = 0.0; // γ-weighted
        let mut t_north = 0.0;
        let mut t_east = 0.0;

        for (pos, gm, degree3) in [
            (&bodies.moon_m, GM_MOON_M3_S2, true),
            (&bodies.sun_m, GM_SUN_M3_S2, false),
        ] {
            let d2 = pos[0] * pos[0] + pos[1] * pos[1] + pos[2] * pos[2];
            let d = sqrt(d2);
            let inv_d = 1.0 / d;
            // Direction cosines of the body seen from the local meridian: p = sin dec,
            // q = cos dec cos H, w = cos dec sin H (H = local hour angle).
            let p = pos[2] * inv_d;
            let q = (pos[0] * c_lst + pos[1] * s_lst) * inv_d;
            let w = (pos[0] * s_lst - pos[1] * c_lst) * inv_d;
            // GM r / d³: scale of the degree-2 gradient.
            let k2 = gm * r * inv_d * inv_d * inv_d;

            let (g20, g21, g22) = degree2_gradients(s, c, p, q, w, k2);
            // Long-period band: the latitude-corrected δ·P20 replaces δ·(3s²−1) in the radial term.
            g_up[0] += 0.5 * k2 * self.delta20_p20 * (3.0 * p * p - 1.0);
            g_up[1] += f.delta_21 * g21.up;
            g_up[2] += f.delta_22 * g22.up;
            g_north[0] += f.delta_20 * g20.north;
            g_north[1] += f.delta_21 * g21.north;
            g_north[2] += f.delta_22 * g22.north;
            t_up += f.gamma_20 * g20.up + f.gamma_21 * g21.up + f.gamma_22 * g22.up;
            t_north += f.gamma_20 * g20.north + f.gamma_21 * g21.north + f.gamma_22 * g22.north;
            t_east += f.gamma_21 * g21.east + f.gamma_22 * g22.east;

            if degree3 {
                // Degree 3 (Moon only; for the Sun r/d ≈ 4e-5 makes it < 0.01 nm/s²).
                let x = s * p + c * q; // cos of the zenith angle of the body
                let k3 = k2 * r * inv_d;
                let p3 = 0.5 * (5.0 * x * x * x - 3.0 * x);
                let dp3 = 0.5 * (15.0 * x * x - 3.0);
                let g3 = Gradient {
                    up: 3.0 * k3 * p3,
                    north: k3 * dp3 * (c * p - s * q),
                    east: -k3 * dp3 * w,
                };
                g_up[3] += f.delta_3 * g3.up;
                g_north[3] += f.delta_3 * g3.north;
                t_up += f.gamma_3 * g3.up;
                t_north += f.gamma_3 * g3.north;
                t_east += f.gamma_3 * g3.east;
            }
        }

        // K1 line: the orbit-averaged diurnal moment gets the FCN-resonant factors on top of
        // the O1-referenced ones already applied above.
        let mx = bodies.k1_moment[0] * r;
        let my = bodies.k1_moment[1] * r;
        let pq = mx * c_lst + my * s_lst; // ⟨p q⟩ × GM r / d³ equivalent
        let pw = mx * s_lst - my * c_lst;
        let k1 = Gradient {
            up: 6.0 * s * c * pq,
            north: 3.0 * (c * c - s * s) * pq,
            east: -3.0 * s * pw,
        };
        let dd = f.delta_k1 - f.delta_21;
        let dg = f.gamma_k1 - f.gamma_21;
        g_up[1] += dd * k1.up;
        g_north[1] += dd * k1.north;
        t_up += dg * k1.up;
        t_north += dg * k1.north;
        t_east += dg * k1.east;

        // Radial/geocentric-north → ellipsoid normal/geodetic-north; upward tidal acceleration
        // lowers the gravity the station feels.
        let band =
            |i: usize| -(self.cos_dev * g_up[i] + self.sin_dev * g_north[i]) * NM_S2_PER_M_S2;
        let species = GravitySpecies {
            long_period_nm_s2: band(0),
            diurnal_nm_s2: band(1),
            semidiurnal_nm_s2: band(2),
            degree3_nm_s2: band(3),
        };
        let north = self.cos_dev * t_north - self.sin_dev * t_up;
        let to_mas = MAS_PER_RAD / self.gravity_m_s2;
        (
            TideSample {
                gravity_nm_s2: species.long_period_nm_s2
                    + species.diurnal_nm_s2
                    + species.semidiurnal_nm_s2
                    + species.degree3_nm_s2,
                tilt_north_mas: north * to_mas,
                tilt_east_mas: t_east * to_mas,
            },
            species,
        )
    }

    /// Tide at `start_unix_s + i × interval_s`, i = 0, 1, …, without allocation.
    ///
    /// The Moon and Sun are computed at nodes [`SERIES_NODE_STEP_S`] apart and interpolated
    /// linearly in Cartesian coordinates; the Earth's rotation is exact at every sample. The
    /// interpolation error is < 1e-6 of the tide (docs/tide.md, test
    /// `series_matches_direct_evaluation`).
    pub fn series(&self, start_unix_s: f64, interval_s: f64) -> Result<TideSeries<'_>, TideError> {
        if !(start_unix_s.is_finite() && interval_s.is_finite()) {
            return Err(TideError::NotFinite);
        }
        if interval_s <= 0.0 {
            return Err(TideError::IntervalNotPositive);
        }
        Ok(TideSeries {
            station: self,
            start_unix_s,
            interval_s,
            index: 0,
            nodes: None,
        })
    }
}

/// Degree-2 gradients (up, north, east) for the three species, before any Love numbers.
///
/// From the addition theorem P2(cos ψ) = ¼(3s²−1)(3p²−1) + 3 s c p q + ¾ c² (q² − w²), with
/// s, c the sine and cosine of the geocentric latitude; V2 = (GM r²/d³)·P2, so ∂V/∂r = 2V/r,
/// north = (1/r) ∂V/∂φ, east = (1/(r cos φ)) ∂V/∂λ with ∂q/∂λ = −w, ∂w/∂λ = q.
#[inline]
pub(super) fn degree2_gradients(
    s: f64,
    c: f64,
    p: f64,
    q: f64,
    w: f64,
    k2: f64,
) -> (Gradient, Gradient, Gradient) {
    let p2 = 3.0 * p * p - 1.0;
    let pq = p * q;
    let qq_ww = q * q - w * w;
    let g20 = Gradient {
        up: 0.5 * k2 * (3.0 * s * s - 1.0) * p2,
        north: 1.5 * k2 * s * c * p2,
        east: 0.0,
    };
    let g21 = Gradient {
        up: 6.0 * k2 * s * c * pq,
        north: 3.0 * k2 * (c * c - s * s) * pq,
        east: -3.0 * k2 * s * p * w,
    };
    let g22 = Gradient {
        up: 1.5 * k2 * c * c * qq_ww,
        north: -1.5 * k2 * s * c * qq_ww,
        east: -3.0 * k2 * c * q * w,
    };
    (g20, g21, g22)
}

/// Spacing of the ephemeris nodes of [`TideSeries`], seconds.
///
/// Why 600 s: the Moon moves 0.09° in that time, so the chord of linear interpolation sags by
/// 3e-7 of its distance, a 1e-6 change of the tide (< 0.002 nm/s²); the ephemeris then costs
/// one evaluation per 600 samples at 1 Hz.
pub const SERIES_NODE_STEP_S: f64 = 600.0;

/// Iterator over a regularly sampled tide series: yields (Unix seconds, tide).
#[derive(Debug, Clone)]
pub struct TideSeries<'a> {
    station: &'a Station,
    start_unix_s: f64,
    interval_s: f64,
    index: u64,
    /// Cached ephemeris nodes: (node index k, bodies at k, bodies at k+1).
    nodes: Option<(i64, Bodies, Bodies)>,
}

impl TideSeries<'_> {
    fn bodies_at_node(&self, k: i64) -> Bodies {
        let t = self.start_unix_s + k as f64 * SERIES_NODE_STEP_S;
        Bodies::at_julian_date_utc(julian_date_from_unix_seconds(t))
    }
}

impl Iterator for TideSeries<'_> {
    type Item = (f64, TideSample);

    fn next(&mut self) -> Option<Self::Item> {
        // Time from the index, not by accumulation, so a 3.5-million-sample run does not drift.
        let offset_s = self.index as f64 * self.interval_s;
        let unix_s = self.start_unix_s + offset_s;
        self.index = self.index.checked_add(1)?;
        let jd = julian_date_from_unix_seconds(unix_s);
        let gmst = gmst_rad(jd);
        if self.interval_s >= SERIES_NODE_STEP_S {
            let bodies = Bodies::at_julian_date_utc(jd);
            return Some((unix_s, self.station.tide_from_bodies(&bodies, gmst)));
        }
        let pos = offset_s / SERIES_NODE_STEP_S;
        let k = floor(pos) as i64;
        let w = pos - k as f64;
        let (a, b) = match self.nodes {
            Some((kk, a, b)) if kk == k => (a, b),
            Some((kk, _, b)) if kk + 1 == k => {
                let next = self.bodies_at_node(k + 1);
                self.nodes = Some((k, b, next));
                (b, next)
            }
            _ => {
                let a = self.bodies_at_node(k);
                let b = self.bodies_at_node(k + 1);
                self.nodes = Some((k, a, b));
                (a, b)
            }
        };
        let bodies = Bodies::lerp(&a, &b, w);
        Some((unix_s, self.station.tide_from_bodies(&bodies, gmst)))
    }
}
