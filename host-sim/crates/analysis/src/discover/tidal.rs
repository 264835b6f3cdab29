//! Tidal analysis of a gravity record, ETERNA style: the theoretical tide of each wave group
//! (Q1, O1, M1, P1+K1, J1, N2, M2, L2, S2+K2, M3) from the Cartwright–Tayler–Edden catalogue
//! of the core ([`accomp::tide::cte1973`]) is fitted by least squares with an amplitude factor
//! and a phase per group, jointly with a smooth drift, the discovery's other columns and, where
//! the record has one, the pressure channel (admittance). Then:
//!
//! - factors are given against the **rigid Earth** (the classical gravimetric factor δ, ≈ 1.16)
//!   and against the **model's elastic Earth** (observed / the δ of `accomp::tide`, 1 = the
//!   model is exact);
//! - one instrument **time delay** is fitted to the group phases (a delay τ shows as a phase lag
//!   ω·τ growing with frequency), per band and for all bands together, with χ² of the
//!   consistency;
//! - uncertainties follow ETERNA: the least-squares covariance scaled by the residual's noise
//!   level in each tidal band (mean Fourier amplitude → equivalent white noise), so a red
//!   residual is not taken as white.
//!
//! The long-period band (< 0.5 cpd) is not analysed: a cubic B-spline drift with knots every
//! [`DRIFT_KNOT_S`] takes it together with the instrument drift, as ETERNA's high-pass filter does.
//! Method and the check on the gMetrology record: `docs/tide.md`.

use super::effects::Param;
use super::import::{ChannelKind, Dataset};
use crate::numerics::linalg::OrthonormalBasis;
use accomp::tide::cte1973::CTE1973;
use accomp::tide::harmonic::{sin_cos, DoodsonArguments, Wave, WaveGravity};
use accomp::tide::{Station, NM_S2_PER_M_S2, STANDARD_GRAVITY_M_S2};
use serde::Serialize;

pub use accomp_sim::tide::{GroupDef, GROUPS};

/// Knot spacing of the B-spline drift, seconds (2 days: passes < 0.1 % of a diurnal wave's
/// power into the drift, takes everything slower than ~0.25 cpd).
pub const DRIFT_KNOT_S: f64 = 2.0 * 86_400.0;

/// Shortest record analysed, seconds: below two days the diurnal and semidiurnal bands are not
/// separated from each other and from the drift.
pub const MIN_SPAN_S: f64 = 2.0 * 86_400.0;

/// Spacing of the nodes at which the group tides are evaluated exactly, seconds; between them a
/// 4-point Lagrange interpolation (error ~ (ωh)⁴/40 ≈ 6e-6 of M3, less for the slower bands).
const NODE_S: f64 = 600.0;

/// One fitted wave group.
#[derive(Debug, Clone, Serialize)]
pub struct GroupFit {
    /// Group name (merged groups are joined with '+').
    pub name: String,
    /// Frequency band, cpd.
    pub from_cpd: f64,
    /// Upper bound, cpd.
    pub to_cpd: f64,
    /// Frequency of the group's largest wave at this station, cpd.
    pub main_wave_cpd: f64,
    /// Catalogue waves in the group.
    pub waves: usize,
    /// Amplitude of the group's largest wave, rigid Earth, output unit.
    pub theoretical_amplitude: f64,
    /// The model's δ for the largest wave.
    pub model_delta: f64,
    /// Observed / rigid-Earth tide (classical gravimetric factor δ).
    pub amplitude_factor_rigid_earth: Param,
    /// Phase against the rigid-Earth tide, degrees, positive = observed leads.
    pub phase_deg: Param,
    /// Observed / the model's elastic-Earth tide (1 = the model is exact).
    pub amplitude_factor_vs_elastic_model: Param,
    /// Phase against the elastic model, degrees (the model has no phase lag).
    pub phase_vs_elastic_model_deg: Param,
    /// Phase left after removing the fitted delay (ω·delay_s added back), degrees.
    pub phase_after_delay_deg: f64,
}

/// The instrument delay fitted to the group phases.
#[derive(Debug, Clone, Serialize)]
pub struct DelayFit {
    /// Delay of the record behind the tide, seconds (all groups used), 1 σ inflated by
    /// √(χ²/dof) when that exceeds 1.
    pub delay_s: Param,
    /// χ² per degree of freedom of the phases about a pure delay (≈ 1: one delay explains all
    /// bands; ≫ 1: the phases also hold something else, e.g. ocean loading).
    pub chi2_per_dof: f64,
    /// Delay from each band alone: diurnal, semidiurnal, terdiurnal.
    pub by_band: Vec<(String, Param)>,
    /// Groups used (factor determined to better than 10 %).
    pub groups_used: Vec<String>,
}

/// Pressure admittance.
#[derive(Debug, Clone, Serialize)]
pub struct Admittance {
    /// Output unit per hPa.
    pub per_hpa: Param,
    /// The same in nm/s² per hPa (10 nm/s² = 1 µGal).
    pub nm_s2_per_hpa: Param,
}

/// Everything the analysis found.
#[derive(Debug, Clone, Serialize)]
pub struct TidalAnalysis {
    /// Catalogue used.
    pub catalogue: String,
    /// Drift model.
    pub drift: String,
    /// Output unit.
    pub unit: String,
    /// Wave groups.
    pub groups: Vec<GroupFit>,
    /// The delay.
    pub delay: DelayFit,
    /// Pressure admittance, when the record has a pressure channel.
    pub pressure_admittance: Option<Admittance>,
    /// Residual std, output unit.
    pub residual_std: f64,
    /// Equivalent white noise of the residual per band (name, output unit): the scale of the
    /// uncertainties.
    pub band_noise: Vec<(String, f64)>,
    /// What the two references mean.
    pub references: String,
}

/// The theoretical tide of the groups at the record's times: rigid (δ = 1) and elastic
/// (δ per wave from the model), each as cos and sin parts in nm/s².
struct GroupTides {
    defs: Vec<GroupDef>,
    names: Vec<String>,
    /// Per group: (waves, main-wave index into the wave list).
    waves: Vec<Vec<(Wave, WaveGravity, f64)>>,
    rigid: Vec<[Vec<f64>; 2]>,
    elastic: Vec<[Vec<f64>; 2]>,
}

fn merged_groups(span_s: f64) -> Vec<(String, GroupDef)> {
    // Rayleigh: two groups whose main waves are closer than 1/span cannot be told apart; the
    // smaller is merged into its neighbour of the same band (names joined with '+').
    let span_d = span_s / 86_400.0;
    let main = |g: &GroupDef| -> f64 {
        match g.name {
            "Q1" => 0.893_244,
            "O1" => 0.929_536,
            "M1" => 0.966_446,
            "P1K1" => 1.002_738,
            "J1" => 1.039_030,
            "N2" => 1.895_982,
            "M2" => 1.932_274,
            "L2" => 1.968_565,
            "S2K2" => 2.0,
            _ => 2.898_410,
        }
    };
    let mut out: Vec<(String, GroupDef, f64)> = Vec::new();
    for g in GROUPS {
        let f = main(&g);
        if let Some(last) = out.last_mut() {
            let same_band = (last.2.round() - f.round()).abs() < 0.5;
            if same_band && (f - last.2) * span_d < 1.0 {
                // The larger group keeps its main frequency.
                let big = ["O1", "P1K1", "M2", "S2K2"];
                if big.contains(&g.name) {
                    last.2 = f;
                }
                last.0 = format!("{}+{}", last.0, g.name);
                last.1.to_cpd = g.to_cpd;
                continue;
            }
        }
        out.push((g.name.to_owned(), g, f));
    }
    out.into_iter().map(|(n, g, _)| (n, g)).collect()
}

/// 4-point Lagrange interpolation of node values `v` (spacing `h`, first node at `x0`) at `x`.
fn lagrange4(v: &[f64], x0: f64, h: f64, x: f64) -> f64 {
    let p = (x - x0) / h;
    let n = v.len();
    let k = (p.floor() as isize - 1).clamp(0, n as isize - 4) as usize;
    let u = p - k as f64;
    let (a, b, c, d) = (v[k], v[k + 1], v[k + 2], v[k + 3]);
    // Nodes at u = 0, 1, 2, 3.
    let l0 = -(u - 1.0) * (u - 2.0) * (u - 3.0) / 6.0;
    let l1 = u * (u - 2.0) * (u - 3.0) / 2.0;
    let l2 = -u * (u - 1.0) * (u - 3.0) / 2.0;
    let l3 = u * (u - 1.0) * (u - 2.0) / 6.0;
    a * l0 + b * l1 + c * l2 + d * l3
}

impl GroupTides {
    fn new(st: &Station, start_unix_s: f64, t_s: &[f64], span_s: f64) -> Self {
        let groups = merged_groups(span_s);
        let mut waves: Vec<Vec<(Wave, WaveGravity, f64)>> = vec![Vec::new(); groups.len()];
        for w in CTE1973.iter() {
            let f = w.frequency_cpd();
            if let Some(i) = groups
                .iter()
                .position(|(_, g)| f >= g.from_cpd && f < g.to_cpd)
            {
                waves[i].push((*w, st.wave_gravity(w), st.gravimetric_factor(w)));
            }
        }
        let t0 = t_s.first().copied().unwrap_or(0.0) - 2.0 * NODE_S;
        let t1 = t_s.last().copied().unwrap_or(0.0) + 2.0 * NODE_S;
        let nodes = ((t1 - t0) / NODE_S).ceil() as usize + 1;
        let ng = groups.len();
        // Node values: [group][rigid cos, rigid sin, elastic cos, elastic sin][node].
        let mut nv = vec![
            [
                vec![0.0; nodes],
                vec![0.0; nodes],
                vec![0.0; nodes],
                vec![0.0; nodes]
            ];
            ng
        ];
        #[allow(clippy::needless_range_loop)] // k is the node index of four arrays per group
        for k in 0..nodes {
            let args = DoodsonArguments::at_unix_seconds(start_unix_s + t0 + k as f64 * NODE_S);
            for (g, ws) in waves.iter().enumerate() {
                let (mut rc, mut rs, mut ec, mut es) = (0.0, 0.0, 0.0, 0.0);
                for (w, wg, delta) in ws {
                    let (s, c) = sin_cos(w.argument_rad(&args) + wg.phase_rad);
                    rc += wg.amplitude_nm_s2 * c;
                    rs += wg.amplitude_nm_s2 * s;
                    ec += delta * wg.amplitude_nm_s2 * c;
                    es += delta * wg.amplitude_nm_s2 * s;
                }
                nv[g][0][k] = rc;
                nv[g][1][k] = rs;
                nv[g][2][k] = ec;
                nv[g][3][k] = es;
            }
        }
        let at = |v: &Vec<f64>| -> Vec<f64> {
            t_s.iter().map(|&t| lagrange4(v, t0, NODE_S, t)).collect()
        };
        let rigid = nv.iter().map(|g| [at(&g[0]), at(&g[1])]).collect();
        let elastic = nv.iter().map(|g| [at(&g[2]), at(&g[3])]).collect();
        Self {
            defs: groups.iter().map(|g| g.1).collect(),
            names: groups.into_iter().map(|g| g.0).collect(),
            waves,
            rigid,
            elastic,
        }
    }

    /// Index of the largest wave (rigid amplitude at the station) of group g.
    fn main_wave(&self, g: usize) -> Option<&(Wave, WaveGravity, f64)> {
        self.waves[g].iter().max_by(|a, b| {
            a.1.amplitude_nm_s2
                .abs()
                .total_cmp(&b.1.amplitude_nm_s2.abs())
        })
    }
}

/// Cubic B-spline drift columns per contiguous segment, knots every `knot_s`.
pub fn spline_drift(t_s: &[f64], seg_start: &[bool], knot_s: f64) -> Vec<Vec<f64>> {
    let n = t_s.len();
    let mut cols = Vec::new();
    let mut i = 0;
    while i < n {
        let mut j = i + 1;
        while j < n && !seg_start[j] {
            j += 1;
        }
        let (a, b) = (t_s[i], t_s[j - 1]);
        let intervals = (((b - a) / knot_s).ceil() as usize).max(1);
        let h = ((b - a) / intervals as f64).max(1e-9);
        let first = cols.len();
        for _ in 0..intervals + 3 {
            cols.push(vec![0.0; n]);
        }
        for k in i..j {
            let x = ((t_s[k] - a) / h).clamp(0.0, intervals as f64);
            let c = (x.floor() as usize).min(intervals - 1);
            let u = x - c as f64;
            let b0 = (1.0 - u).powi(3) / 6.0;
            let b1 = (3.0 * u * u * u - 6.0 * u * u + 4.0) / 6.0;
            let b2 = (-3.0 * u * u * u + 3.0 * u * u + 3.0 * u + 1.0) / 6.0;
            let b3 = u * u * u / 6.0;
            for (q, v) in [b0, b1, b2, b3].into_iter().enumerate() {
                cols[first + c + q][k] = v;
            }
        }
        i = j;
    }
    cols
}

/// Least squares through the host's one QR ([`OrthonormalBasis`]: columns equilibrated, a
/// column that adds less than [`DEPENDENT_COLUMN_REL`](crate::numerics::linalg::DEPENDENT_COLUMN_REL) of its own norm is dropped, coefficient 0).
/// Returns coefficients and the unscaled covariance (XᵀX)⁻¹ (0 rows/columns for dropped ones).
fn lstsq(cols: &[&[f64]], y: &[f64]) -> (Vec<f64>, Vec<Vec<f64>>) {
    let owned: Vec<Vec<f64>> = cols.iter().map(|c| c.to_vec()).collect();
    let basis = OrthonormalBasis::new(&owned);
    let (beta, _) = basis.solve(y);
    (beta, basis.covariance())
}

/// Equivalent white-noise std of `r` in a frequency band (cpd): the mean Fourier amplitude
/// ā of the residual over the band, σ = ā·√(N/π) (for white noise of std σ the amplitude
/// spectrum (2/N)|Σ r e^{−iωt}| has mean σ√(π/N)).
fn band_noise(t_s: &[f64], r: &[f64], from_cpd: f64, to_cpd: f64) -> f64 {
    let n = r.len() as f64;
    let span = (t_s.last().copied().unwrap_or(0.0) - t_s.first().copied().unwrap_or(0.0)).max(1.0);
    // Half a Rayleigh step: every resolved frequency is sampled.
    let df = 0.5 / span;
    let (f0, f1) = (from_cpd / 86_400.0, to_cpd / 86_400.0);
    let mut sum = 0.0;
    let mut count = 0usize;
    let mut f = f0;
    while f < f1 {
        let w = 2.0 * std::f64::consts::PI * f;
        let (mut re, mut im) = (0.0, 0.0);
        for (t, v) in t_s.iter().zip(r) {
            let (s, c) = (w * t).sin_cos();
            re += v * c;
            im += v * s;
        }
        sum += 2.0 / n * (re * re + im * im).sqrt();
        count += 1;
        f += df;
    }
    if count == 0 {
        return f64::NAN;
    }
    sum / count as f64 * (n / std::f64::consts::PI).sqrt()
}

/// Why the tidal analysis did not run on a record.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NotRun {
    /// The output is not in a gravity unit.
    #[error("not a gravity record (output unit '{0}', not mGal, µGal, nm/s² or m/s²)")]
    NotGravity(String),
    /// The tide cannot be computed without the time and the place.
    #[error("no start_utc or site (latitude_deg, longitude_deg)")]
    NoTimeOrSite,
    /// The output's unit per g is not known.
    #[error("output unit per g unknown")]
    NoUnitPerG,
    /// Too short to separate the bands.
    #[error(
        "record spans {:.1} h, under the {:.0} h that separate the diurnal and semidiurnal \
         bands from each other and from the drift",
        span_s / 3600.0,
        MIN_SPAN_S / 3600.0
    )]
    TooShort {
        /// The record's span, s.
        span_s: f64,
    },
    /// The core's tide model refuses the site.
    #[error("site: {0}")]
    Site(String),
}

/// Why a record is not analysed, or `None` when it can be.
pub fn not_applicable(ds: &Dataset) -> Option<NotRun> {
    if !crate::log::GRAVITY_UNITS.contains(&ds.output_unit.as_str()) {
        return Some(NotRun::NotGravity(ds.output_unit.clone()));
    }
    if ds.start_unix_s.is_none() || ds.site.is_none() {
        return Some(NotRun::NoTimeOrSite);
    }
    if ds.unit_per_g.is_none() {
        return Some(NotRun::NoUnitPerG);
    }
    if ds.span_s() < MIN_SPAN_S {
        return Some(NotRun::TooShort {
            span_s: ds.span_s(),
        });
    }
    None
}

/// Runs the analysis on `target` (the record, in its output unit) with extra nuisance columns
/// (the discovery's baseline and non-tidal effects; may be empty).
pub fn analyse(
    ds: &Dataset,
    target: &[f64],
    nuisance: &[Vec<f64>],
) -> Result<TidalAnalysis, NotRun> {
    if let Some(why) = not_applicable(ds) {
        return Err(why);
    }
    let (lat, lon, h) = ds.site.ok_or(NotRun::NoTimeOrSite)?;
    let start = ds.start_unix_s.ok_or(NotRun::NoTimeOrSite)?;
    let st = Station::new(lat, lon, h).map_err(|e| NotRun::Site(format!("{e:?}")))?;
    let u = ds.unit_per_g.ok_or(NotRun::NoUnitPerG)?;
    // nm/s² → output unit (a vertical gravity record: the tide adds to what it measures).
    let to_unit = u / (STANDARD_GRAVITY_M_S2 * NM_S2_PER_M_S2);
    let gt = GroupTides::new(&st, start, &ds.t_s, ds.span_s());
    let ng = gt.names.len();
    let scaled = |v: &[f64]| -> Vec<f64> { v.iter().map(|x| x * to_unit).collect() };
    let pressure = ds.channel(ChannelKind::Pressure).map(|c| -> Vec<f64> {
        let m = c.values.iter().sum::<f64>() / c.values.len() as f64;
        // Pa → hPa, centred.
        c.values.iter().map(|p| (p - m) / 100.0).collect()
    });
    let drift = spline_drift(&ds.t_s, &ds.segment_start, DRIFT_KNOT_S);

    // One fit per reference: the columns differ only by the δ per wave inside a group.
    // Frisch–Waugh: the nuisance space (the discovery's columns and the drift, which overlap:
    // an offset or a linear drift is also a sum of B-splines) is projected out by an
    // orthonormal basis that drops dependent columns, and the tide and pressure columns are
    // solved on what is left. Their covariance is then that of a small, well-conditioned
    // system, whatever the nuisance columns' collinearity.
    let mut nuis = super::baseline::Basis::new(&[]);
    for c in nuisance.iter().chain(&drift) {
        nuis.push(c.clone());
    }
    let y_perp = nuis.residual(target);
    let fit = |cs: &[[Vec<f64>; 2]]| {
        let mut cols: Vec<Vec<f64>> = Vec::new();
        for [c, s] in cs {
            cols.push(nuis.residual(&scaled(c)));
            cols.push(nuis.residual(&scaled(s)));
        }
        if let Some(p) = &pressure {
            cols.push(nuis.residual(p));
        }
        let refs: Vec<&[f64]> = cols.iter().map(Vec::as_slice).collect();
        let (beta, cov) = lstsq(&refs, &y_perp);
        let mut r = y_perp.clone();
        for (c, b) in cols.iter().zip(&beta) {
            for (ri, ci) in r.iter_mut().zip(c) {
                *ri -= b * ci;
            }
        }
        (beta, cov, r)
    };
    let (beta_r, cov_r, resid) = fit(&gt.rigid);
    let (beta_e, cov_e, _) = fit(&gt.elastic);

    let bands = [
        ("diurnal", 0.5, 1.5),
        ("semidiurnal", 1.5, 2.5),
        ("terdiurnal", 2.5, 3.5),
    ];
    let noise: Vec<(String, f64)> = bands
        .iter()
        .map(|(n, a, b)| ((*n).to_owned(), band_noise(&ds.t_s, &resid, *a, *b)))
        .collect();
    let band_of = |cpd: f64| {
        bands
            .iter()
            .position(|(_, a, b)| cpd >= *a && cpd < *b)
            .unwrap_or(0)
    };
    // Amplitude factor and phase from (a, b) = δ(cos κ, sin κ) with covariance σ²·C.
    let polar = |beta: &[f64], cov: &[Vec<f64>], g: usize, s2: f64| -> (Param, Param) {
        let (a, b) = (beta[2 * g], beta[2 * g + 1]);
        // b is the negated sin coefficient (see `flip`): its covariance with a changes sign.
        let (caa, cbb, cab) = (
            cov[2 * g][2 * g] * s2,
            cov[2 * g + 1][2 * g + 1] * s2,
            -cov[2 * g][2 * g + 1] * s2,
        );
        let d = a.hypot(b);
        // In y = a·C − b·S the phase lead κ has tan κ = b/a.
        let k = b.atan2(a);
        let (ca, sa) = (a / d, b / d);
        let var_d = ca * ca * caa + sa * sa * cbb + 2.0 * ca * sa * cab;
        let var_k = (sa * sa * caa + ca * ca * cbb - 2.0 * ca * sa * cab) / (d * d);
        (
            Param {
                value: d,
                sigma: var_d.max(0.0).sqrt(),
            },
            Param {
                value: k.to_degrees(),
                sigma: var_k.max(0.0).sqrt().to_degrees(),
            },
        )
    };
    // The fitted columns are "a·C − b·S" only if the sin column enters with a minus sign:
    // flip b so that κ is a lead.
    let flip = |beta: &[f64]| -> Vec<f64> {
        let mut v = beta.to_vec();
        for g in 0..ng {
            v[2 * g + 1] = -v[2 * g + 1];
        }
        v
    };
    let (beta_r, beta_e) = (flip(&beta_r), flip(&beta_e));
    let mut groups = Vec::with_capacity(ng);
    for g in 0..ng {
        let Some((w, wg, delta)) = gt.main_wave(g).copied() else {
            continue;
        };
        let cpd = w.frequency_cpd();
        let s = noise[band_of(cpd)].1;
        let s2 = s * s;
        let (dr, kr) = polar(&beta_r, &cov_r, g, s2);
        let (de, ke) = polar(&beta_e, &cov_e, g, s2);
        groups.push(GroupFit {
            name: gt.names[g].clone(),
            from_cpd: gt.defs[g].from_cpd,
            to_cpd: gt.defs[g].to_cpd,
            main_wave_cpd: cpd,
            waves: gt.waves[g].len(),
            theoretical_amplitude: wg.amplitude_nm_s2.abs() * to_unit,
            model_delta: delta,
            amplitude_factor_rigid_earth: dr,
            phase_deg: kr,
            amplitude_factor_vs_elastic_model: de,
            phase_vs_elastic_model_deg: ke,
            phase_after_delay_deg: f64::NAN,
        });
    }
    let delay = fit_delay(&mut groups);
    let pressure_admittance = pressure.as_ref().map(|_| {
        let j = 2 * ng;
        // Pressure acts over all frequencies; its σ uses the residual's equivalent white noise
        // just below the diurnal band, where the synoptic pressure changes that carry the
        // admittance still are after the drift.
        let s = band_noise(&ds.t_s, &resid, 0.3, 0.8);
        let v = beta_r[j];
        let sg = cov_r[j][j].max(0.0).sqrt() * s;
        let nm = 1.0 / to_unit;
        Admittance {
            per_hpa: Param {
                value: v,
                sigma: sg,
            },
            nm_s2_per_hpa: Param {
                value: v * nm,
                sigma: sg * nm,
            },
        }
    });
    Ok(TidalAnalysis {
        catalogue: format!(
            "Cartwright-Tayler-Edden 1973, {} waves (degree 2 and 3)",
            CTE1973.len()
        ),
        drift: format!(
            "cubic B-spline per segment, knots every {:.0} d (long-period tides go with it)",
            DRIFT_KNOT_S / 86_400.0
        ),
        unit: ds.output_unit.clone(),
        groups,
        delay,
        pressure_admittance,
        residual_std: super::baseline::std(&resid),
        band_noise: noise,
        references: "amplitude_factor_rigid_earth / phase_deg: against the rigid-Earth tide of \
                     the catalogue (the classical gravimetric factor, ~1.16); \
                     amplitude_factor_vs_elastic_model / phase_vs_elastic_model_deg: against the \
                     elastic-Earth tide of accomp::tide (DDW 1999 body tide with FCN resonance, \
                     no ocean loading); phase positive = the record leads"
            .into(),
    })
}

/// The model's tide gravity (g, as `effects::tide_series`) on a 60-s grid reaching
/// `margin_s` beyond the record at both ends, so that the tide can be read at delayed times
/// (the delay of the joint fit, `select`).
#[derive(Debug, Clone)]
pub struct TideClock {
    t0_s: f64,
    step_s: f64,
    g: Vec<f64>,
}

impl TideClock {
    /// The clock of a record with a start time and a site; `None` otherwise.
    pub fn new(ds: &Dataset, margin_s: f64) -> Option<Self> {
        let start = ds.start_unix_s?;
        let (lat, lon, h) = ds.site?;
        let st = Station::new(lat, lon, h).ok()?;
        let step_s = 60.0;
        let t0_s = ds.t_s.first()? - margin_s - step_s;
        let t1 = ds.t_s.last()? + margin_s + step_s;
        let n = ((t1 - t0_s) / step_s).ceil() as usize + 2;
        let g = (0..n)
            .map(|k| {
                st.tide_at_unix_seconds(start + t0_s + k as f64 * step_s)
                    .gravity_gs()
                    .0
            })
            .collect();
        Some(TideClock { t0_s, step_s, g })
    }

    /// Tide gravity (g) at each of `t_s` delayed by `delay_s` (the tide at t − delay; linear
    /// between the 60-s nodes, as `effects::tide_series`).
    pub fn delayed(&self, t_s: &[f64], delay_s: f64) -> Vec<f64> {
        let last = self.g.len().saturating_sub(2);
        t_s.iter()
            .map(|&t| {
                let x = ((t - delay_s - self.t0_s) / self.step_s).max(0.0);
                let k = (x.floor() as usize).min(last);
                let f = x - k as f64;
                self.g[k] + (self.g[k + 1] - self.g[k]) * f
            })
            .collect()
    }
}

/// Weighted least squares of the group phases κ_g = −ω_g·τ (groups with factor σ/δ < 10 %):
/// overall and per band.
fn fit_delay(groups: &mut [GroupFit]) -> DelayFit {
    let omega = |g: &GroupFit| 2.0 * std::f64::consts::PI * g.main_wave_cpd / 86_400.0;
    let usable = |g: &GroupFit| {
        let d = g.amplitude_factor_rigid_earth;
        d.sigma.is_finite() && d.sigma < 0.1 * d.value && g.phase_deg.sigma > 0.0
    };
    let solve = |sel: &dyn Fn(&GroupFit) -> bool| -> Option<(Param, f64, usize)> {
        let (mut swx, mut sww, mut m) = (0.0, 0.0, 0usize);
        let pts: Vec<(f64, f64, f64)> = groups
            .iter()
            .filter(|g| usable(g) && sel(g))
            .map(|g| {
                (
                    omega(g),
                    g.phase_deg.value.to_radians(),
                    g.phase_deg.sigma.to_radians(),
                )
            })
            .collect();
        for &(w, k, s) in &pts {
            let wt = 1.0 / (s * s);
            swx += wt * w * (-k);
            sww += wt * w * w;
            m += 1;
        }
        if m == 0 {
            return None;
        }
        let tau = swx / sww;
        let chi2: f64 = pts
            .iter()
            .map(|&(w, k, s)| ((k + w * tau) / s).powi(2))
            .sum();
        let dof = m.saturating_sub(1);
        let c = if dof > 0 { chi2 / dof as f64 } else { f64::NAN };
        let infl = if c.is_finite() {
            c.max(1.0).sqrt()
        } else {
            1.0
        };
        Some((
            Param {
                value: tau,
                sigma: infl / sww.sqrt(),
            },
            c,
            m,
        ))
    };
    let all = solve(&|_| true);
    let mut by_band = Vec::new();
    for (name, a, b) in [
        ("diurnal", 0.5, 1.5),
        ("semidiurnal", 1.5, 2.5),
        ("terdiurnal", 2.5, 3.5),
    ] {
        if let Some((p, _, _)) = solve(&|g: &GroupFit| g.main_wave_cpd >= a && g.main_wave_cpd < b)
        {
            by_band.push((name.to_owned(), p));
        }
    }
    let nan = Param {
        value: f64::NAN,
        sigma: f64::NAN,
    };
    let (delay_s, chi2_per_dof) = all.map_or((nan, f64::NAN), |(p, c, _)| (p, c));
    let used: Vec<String> = groups
        .iter()
        .filter(|g| usable(g))
        .map(|g| g.name.clone())
        .collect();
    if delay_s.value.is_finite() {
        for g in groups.iter_mut() {
            g.phase_after_delay_deg = g.phase_deg.value + (omega(g) * delay_s.value).to_degrees();
        }
    }
    DelayFit {
        delay_s,
        chi2_per_dof,
        by_band,
        groups_used: used,
    }
}

/// Text for the discovery report: the analysis, or one line saying why a record was not
/// analysed (nothing for records that are not gravity records at all).
pub fn text_of(t: &Result<TidalAnalysis, NotRun>) -> String {
    match t {
        Ok(a) => a.text(),
        Err(NotRun::NotGravity(_)) => String::new(),
        Err(why) => format!("tidal analysis (wave groups): not run, {why}\n"),
    }
}

/// JSON for the discovery report (`"not_run"` with the reason when it was not run).
pub fn json_of(t: &Result<TidalAnalysis, NotRun>) -> serde_json::Value {
    match t {
        Ok(a) => serde_json::to_value(a).unwrap_or(serde_json::Value::Null),
        Err(why) => serde_json::json!({ "not_run": why.to_string() }),
    }
}

impl TidalAnalysis {
    /// Text block for `accomp discover`.
    pub fn text(&self) -> String {
        use std::fmt::Write as _;
        let mut o = String::new();
        let _ = writeln!(
            o,
            "tidal analysis (wave groups; {}; drift: {}):",
            self.catalogue, self.drift
        );
        let _ = writeln!(
            o,
            "  group   waves  theory({u:>5})  δ rigid Earth      phase (°)       vs elastic model   phase−delay (°)",
            u = self.unit
        );
        for g in &self.groups {
            let _ = writeln!(
                o,
                "  {:<7} {:>5}  {:>13.5}  {:.4} ± {:.4}  {:>+7.3} ± {:.3}  {:.4} ± {:.4}   {:>+7.3}",
                g.name,
                g.waves,
                g.theoretical_amplitude,
                g.amplitude_factor_rigid_earth.value,
                g.amplitude_factor_rigid_earth.sigma,
                g.phase_deg.value,
                g.phase_deg.sigma,
                g.amplitude_factor_vs_elastic_model.value,
                g.amplitude_factor_vs_elastic_model.sigma,
                g.phase_after_delay_deg,
            );
        }
        let d = &self.delay;
        let _ = write!(
            o,
            "  delay_s = {:.1} ± {:.1} s (χ²/dof {:.2} over {})",
            d.delay_s.value,
            d.delay_s.sigma,
            d.chi2_per_dof,
            d.groups_used.join(", ")
        );
        for (b, p) in &d.by_band {
            let _ = write!(o, "; {b} {:.1} ± {:.1}", p.value, p.sigma);
        }
        let _ = writeln!(o);
        if let Some(p) = &self.pressure_admittance {
            let _ = writeln!(
                o,
                "  pressure admittance = {:.3e} ± {:.1e} {}/hPa = {:.3} ± {:.3} nm/s²/hPa",
                p.per_hpa.value,
                p.per_hpa.sigma,
                self.unit,
                p.nm_s2_per_hpa.value,
                p.nm_s2_per_hpa.sigma
            );
        }
        let _ = writeln!(o, "  ({})", self.references);
        o
    }
}

#[cfg(test)]
mod tests;
