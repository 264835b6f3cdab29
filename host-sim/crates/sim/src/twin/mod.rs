//! The twin of a measured record as the simulator holds it: the member model.
//!
//! A twin predicts a record at the record's own instants: the scenario's instrument and effects
//! driven by the record's drivers ([`record::TwinRecord`]), plus, for member k, the member's
//! draw of the accepted effects' parameters ([`draw::EffectDraws`]), its noise from the
//! fitted noise family ([`family::NoiseFamily`]) with its draw of the record's transient
//! disturbances ([`transients::Transients`]), and the record's drift polynomial with the
//! instrument's settling at the record's start, if any ([`drift::DriftPolynomial`]). The analysis (`accomp-analysis`, `twin`)
//! builds these from a record and a discovery; the scenario's `[twin]` section
//! ([`TwinSpec`]) holds them with a driver file beside it, so that `accomp simulate ext.toml
//! --seed k` computes member k with the same code as the ensemble of `accomp discover
//! --simulate` (docs/simulator.md, "The written twin").

pub mod draw;
pub mod drift;
pub mod family;
pub mod record;
pub mod transients;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::effects::ScenarioEffect;
use crate::noise::stream;
use crate::scenario::Scenario;
use crate::time::UtcParseError;
use crate::SimError;
use draw::EffectDraws;
use drift::DriftPolynomial;
use family::{GridNoise, NoiseFamily};
use record::{Drivers, Simulated, TwinRecord};
use transients::Transients;

/// Random stream of a member's instrument noise.
pub const NOISE_STREAM: u64 = 3;

/// The fixed driver columns of a driver file, in order (units in the names), before the
/// ambient channels.
pub const DRIVER_COLUMNS: [&str; 8] = [
    "t_s",
    "cell",
    "temperature_c",
    "tilt_rad",
    "pressure_dev_pa",
    "input_g",
    "tide_nm_s2",
    "tide_tilt_rad",
];

/// Why a twin cannot run.
#[derive(Debug, thiserror::Error)]
pub enum TwinRunError {
    /// The gravimeter's unit is not one the model knows.
    #[error("gravity in an unknown unit {unit:?} (known: {known})")]
    UnknownGravityUnit {
        /// The unit.
        unit: String,
        /// The known units.
        known: String,
    },
    /// The scenario's start time does not parse.
    #[error("the scenario's start time: {0}")]
    Start(#[from] UtcParseError),
    /// The simulator refused the scenario or failed while running it.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// An effect cannot be built into the chain.
    #[error(transparent)]
    Effect(#[from] crate::effects::EffectError),
}

/// Why a written twin cannot be loaded.
#[derive(Debug, thiserror::Error)]
pub enum TwinFileError {
    /// The driver file named by `[twin] drivers_file` is not there.
    #[error("twin driver file {path} (named by the scenario's [twin] drivers_file) is missing")]
    DriversMissing {
        /// Where it was looked for.
        path: PathBuf,
    },
    /// The driver file cannot be read.
    #[error("twin driver file {path}: {why}")]
    DriversUnreadable {
        /// The file.
        path: PathBuf,
        /// Why.
        why: String,
    },
    /// A line of the driver file is malformed.
    #[error("twin driver file {path}, line {line}: {why}")]
    DriversMalformed {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// What is wrong.
        why: String,
    },
    /// The scenario has no `[twin]` section.
    #[error("the scenario has no [twin] section: it is not a written twin")]
    NotATwin,
    /// The `[twin]` section is inconsistent.
    #[error("scenario [twin]: {0}")]
    Invalid(#[from] InvalidTwin),
    /// A fixed effect of the `[twin]` scenario cannot be driven by the driver file.
    #[error("scenario [twin]: fixed effect {name} cannot be applied: {why}")]
    FixedEffect {
        /// The effect's name.
        name: String,
        /// Why not.
        why: String,
    },
    /// The twin cannot run.
    #[error(transparent)]
    Run(#[from] TwinRunError),
}

/// Why a `[twin]` section is refused before its driver file is read (the message names the
/// field at fault).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InvalidTwin {
    /// The noise family is refused.
    #[error(transparent)]
    Noise(#[from] family::FamilyError),
    /// A transient event starts outside the grid.
    #[error("transients event {event}: cell {cell} is not a cell of the {grid_cells}-cell grid")]
    TransientCell {
        /// Index of the event.
        event: usize,
        /// Its first cell.
        cell: usize,
        /// Cells of the grid.
        grid_cells: usize,
    },
    /// A transient event's shape is empty or not finite.
    #[error("transients event {event}: the shape must be finite numbers (at least one)")]
    TransientShape {
        /// Index of the event.
        event: usize,
    },
    /// A drift coefficient is not finite.
    #[error("drift: Legendre coefficient {order} must be a finite value and σ")]
    DriftCoefficient {
        /// The Legendre order of the coefficient.
        order: usize,
    },
    /// The settling's τ is not positive, or a value or σ not finite.
    #[error("drift.settling: tau_s must be > 0 and every value and σ finite")]
    Settling,
    /// More fixed effects than the scenario has.
    #[error("fixed_effects = {fixed} but the scenario has {effects} [[effects]]")]
    FixedEffects {
        /// `fixed_effects`.
        fixed: usize,
        /// Entries of `[[effects]]`.
        effects: usize,
    },
    /// Fewer than two points or grid cells.
    #[error("points = {points}, grid_cells = {grid_cells}: a twin needs at least two")]
    TooFewPoints {
        /// `points`.
        points: usize,
        /// `grid_cells`.
        grid_cells: usize,
    },
    /// The output scales are not finite numbers.
    #[error("unit_per_g and out_scale must be finite (out_scale ≠ 0)")]
    OutputScale,
    /// `simulated.ambient` does not match `ambient_channels`.
    #[error("simulated.ambient must have one entry per ambient channel")]
    SimulatedAmbient,
}

/// The scenario's `[twin]` section: what a member of the twin is, beyond the station.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TwinSpec {
    /// The driver file, relative to the scenario's directory: the record's instants, their grid
    /// cells and the drivers there (columns [`DRIVER_COLUMNS`] then `ambient_channels`).
    pub drivers_file: String,
    /// Rows in the driver file (the record's points).
    pub points: usize,
    /// The record's output column and unit (what a member predicts).
    pub output_name: String,
    /// The output unit.
    pub output_unit: String,
    /// Record output units per g.
    pub unit_per_g: f64,
    /// Record output units per instrument unit.
    pub out_scale: f64,
    /// The ambient channels of the driver file (centred), in order.
    #[serde(default)]
    pub ambient_channels: Vec<String>,
    /// Which drivers are simulated (a member draws its own weather for those that enter the
    /// output).
    pub simulated: Simulated,
    /// The first `fixed_effects` `[[effects]]` entries are every member's; the rest are the
    /// nominal values of `draws`, which each member draws anew.
    pub fixed_effects: usize,
    /// Cells of the record's regular grid (the noise is synthesised on it).
    pub grid_cells: usize,
    /// The noise family.
    pub noise: NoiseFamily,
    /// The accepted effects and their uncertainties.
    pub draws: EffectDraws,
    /// The record's transient disturbances (members draw a Poisson number of them at random
    /// cells); absent: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub transients: Option<Transients>,
    /// The drift polynomial every member carries, with the settling at the record's start each
    /// member draws; absent: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub drift: Option<DriftPolynomial>,
}

impl TwinSpec {
    /// Checks what can be checked without the driver file.
    pub fn validate(&self, effects: usize) -> Result<(), InvalidTwin> {
        self.noise.validate()?;
        if let Some(t) = &self.transients {
            t.validate(self.grid_cells)?;
        }
        if let Some(d) = &self.drift {
            d.validate()?;
        }
        if self.fixed_effects > effects {
            return Err(InvalidTwin::FixedEffects {
                fixed: self.fixed_effects,
                effects,
            });
        }
        if self.points < 2 || self.grid_cells < 2 {
            return Err(InvalidTwin::TooFewPoints {
                points: self.points,
                grid_cells: self.grid_cells,
            });
        }
        if !(self.unit_per_g.is_finite() && self.out_scale.is_finite() && self.out_scale != 0.0) {
            return Err(InvalidTwin::OutputScale);
        }
        if self.simulated.ambient.len() != self.ambient_channels.len() {
            return Err(InvalidTwin::SimulatedAmbient);
        }
        Ok(())
    }
}

/// A twin's member model: the deterministic part at the record's instants (fixed effects in),
/// the draws and the noise on the grid.
#[derive(Debug, Clone)]
pub struct MemberModel {
    /// The deterministic part with the fixed effects.
    pub record: TwinRecord,
    /// The accepted effects each member draws (None: none).
    pub draws: Option<EffectDraws>,
    /// The noise family on the record's grid (with the transients).
    pub noise: GridNoise,
    /// The drift polynomial every member carries (None: none).
    pub drift: Option<DriftPolynomial>,
}

impl MemberModel {
    /// Member `seed`'s output at the record's instants: its draw of the effects added to the
    /// deterministic part (its own weather where a simulated driver enters), then its noise and
    /// transients, then the drift polynomial and its own draw of the settling.
    pub fn member(&self, seed: u64) -> Result<Vec<f64>, TwinRunError> {
        let rec = match &self.draws {
            Some(d) => self.record.extended(&d.drawn(seed)).0,
            None => self.record.clone(),
        };
        let mut out = rec.member_det(seed)?;
        self.noise
            .add_member(&mut out, &mut stream(seed, NOISE_STREAM));
        if let Some(d) = &self.drift {
            d.add_member(&mut out, &self.record.t_s, seed);
        }
        Ok(out)
    }

    /// The nominal effects (the draws' fitted values).
    pub fn nominal_effects(&self) -> Vec<ScenarioEffect> {
        self.draws
            .as_ref()
            .map(|d| d.nominal().0)
            .unwrap_or_default()
    }

    /// The scenario's `[twin]` section and the driver file's text for this model; the scenario
    /// written is `record.scenario` extended by the nominal effects, with this section.
    pub fn written(
        &self,
        drivers_file: &str,
        output_name: &str,
        output_unit: &str,
    ) -> (Scenario, String) {
        let fixed = self.record.scenario.effects.len();
        let mut s = self.record.extended(&self.nominal_effects()).0.scenario;
        let d = &self.record.drivers;
        s.twin = Some(TwinSpec {
            drivers_file: drivers_file.to_owned(),
            points: self.record.t_s.len(),
            output_name: output_name.to_owned(),
            output_unit: output_unit.to_owned(),
            unit_per_g: self.record.unit_per_g,
            out_scale: self.record.out_scale,
            ambient_channels: d.ambient_names.clone(),
            simulated: d.simulated.clone(),
            fixed_effects: fixed,
            grid_cells: self.noise.len,
            noise: self.noise.family.clone(),
            draws: self.draws.clone().unwrap_or(EffectDraws {
                record_start_s: self.record.t_s.first().copied().unwrap_or(0.0),
                record_interval_s: 0.0,
                record_channels: Vec::new(),
                tide_groups: None,
                effects: Vec::new(),
                admittance_per_hpa: None,
            }),
            transients: self.noise.transients.clone(),
            drift: self.drift.clone(),
        });
        (s, drivers_text(&self.record.t_s, &self.noise.cells, d))
    }

    /// Loads a written twin: `scenario` (with its `[twin]` section) read from `scenario_path`,
    /// its driver file beside it.
    pub fn load(scenario: &Scenario, scenario_path: &Path) -> Result<MemberModel, TwinFileError> {
        let spec = scenario.twin.as_ref().ok_or(TwinFileError::NotATwin)?;
        spec.validate(scenario.effects.len())?;
        let dir = scenario_path.parent().unwrap_or(Path::new("."));
        let path = dir.join(&spec.drivers_file);
        if !path.exists() {
            return Err(TwinFileError::DriversMissing { path });
        }
        let text =
            std::fs::read_to_string(&path).map_err(|e| TwinFileError::DriversUnreadable {
                path: path.clone(),
                why: e.to_string(),
            })?;
        let (t_s, cells, drivers) = parse_drivers(&text, spec, &path)?;
        let mut base = scenario.clone();
        base.twin = None;
        base.effects.truncate(spec.fixed_effects);
        let (record, refused) =
            TwinRecord::new(base, t_s, drivers, spec.unit_per_g, spec.out_scale)?;
        if let Some((name, why)) = refused.first() {
            return Err(TwinFileError::FixedEffect {
                name: name.clone(),
                why: why.clone(),
            });
        }
        Ok(MemberModel {
            record,
            draws: Some(spec.draws.clone()),
            noise: GridNoise {
                family: spec.noise.clone(),
                cells,
                len: spec.grid_cells,
                transients: spec.transients.clone(),
            },
            drift: spec.drift.clone(),
        })
    }
}

/// The driver file's text: a `#` comment, the header, one row per record point; numbers in
/// Rust's shortest round-trip form, so that they read back bit for bit.
pub fn drivers_text(t_s: &[f64], cells: &[usize], d: &Drivers) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# accomp twin drivers: the record's instants, their grid cells and the drivers there"
    );
    let mut header: Vec<&str> = DRIVER_COLUMNS.to_vec();
    header.extend(d.ambient_names.iter().map(String::as_str));
    let _ = writeln!(s, "{}", header.join(","));
    for i in 0..t_s.len() {
        let _ = write!(
            s,
            "{:?},{},{:?},{:?},{:?},{:?},{:?},{:?}",
            t_s[i],
            cells.get(i).copied().unwrap_or(0),
            d.temperature_c[i],
            d.tilt_rad[i],
            d.pressure_dev_pa[i],
            d.input_g[i],
            d.tide_nm_s2[i],
            d.tide_tilt_rad[i]
        );
        for a in &d.ambient {
            let _ = write!(s, ",{:?}", a[i]);
        }
        s.push('\n');
    }
    s
}

/// Reads a driver file written by [`drivers_text`].
fn parse_drivers(
    text: &str,
    spec: &TwinSpec,
    path: &Path,
) -> Result<(Vec<f64>, Vec<usize>, Drivers), TwinFileError> {
    let bad = |line: usize, why: String| TwinFileError::DriversMalformed {
        path: path.to_path_buf(),
        line,
        why,
    };
    let mut expected: Vec<&str> = DRIVER_COLUMNS.to_vec();
    expected.extend(spec.ambient_channels.iter().map(String::as_str));
    let mut rows = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.starts_with('#') && !l.trim().is_empty());
    let (hl, header) = rows.next().ok_or_else(|| bad(1, "no header line".into()))?;
    let cols: Vec<&str> = header.split(',').map(str::trim).collect();
    if cols != expected {
        return Err(bad(
            hl + 1,
            format!("columns {cols:?}, expected {expected:?}"),
        ));
    }
    let n = spec.points;
    let mut t_s = Vec::with_capacity(n);
    let mut cells = Vec::with_capacity(n);
    let mut v: Vec<Vec<f64>> = vec![Vec::with_capacity(n); expected.len() - 2];
    for (i, line) in rows {
        let f: Vec<&str> = line.split(',').collect();
        if f.len() != expected.len() {
            return Err(bad(
                i + 1,
                format!("{} fields, expected {}", f.len(), expected.len()),
            ));
        }
        let num = |k: usize| -> Result<f64, TwinFileError> {
            f[k].trim().parse::<f64>().map_err(|_| {
                bad(
                    i + 1,
                    format!("{} = {:?} is not a number", expected[k], f[k]),
                )
            })
        };
        t_s.push(num(0)?);
        cells.push(
            f[1].trim()
                .parse::<usize>()
                .ok()
                .filter(|c| *c < spec.grid_cells)
                .ok_or_else(|| {
                    bad(
                        i + 1,
                        format!(
                            "cell {:?} is not a cell of the {}-cell grid",
                            f[1], spec.grid_cells
                        ),
                    )
                })?,
        );
        for (k, col) in v.iter_mut().enumerate() {
            col.push(num(k + 2)?);
        }
    }
    if t_s.len() != n {
        return Err(bad(
            text.lines().count(),
            format!("{} rows, the scenario says points = {n}", t_s.len()),
        ));
    }
    let mut it = v.into_iter();
    let mut next = || it.next().unwrap_or_default();
    let temperature_c = next();
    let tilt_rad = next();
    let pressure_dev_pa = next();
    let input_g = next();
    let tide_nm_s2 = next();
    let tide_tilt_rad = next();
    let ambient: Vec<Vec<f64>> = (0..spec.ambient_channels.len()).map(|_| next()).collect();
    Ok((
        t_s,
        cells,
        Drivers {
            temperature_c,
            tilt_rad,
            pressure_dev_pa,
            input_g,
            ambient_names: spec.ambient_channels.clone(),
            ambient,
            tide_nm_s2,
            tide_tilt_rad,
            simulated: spec.simulated.clone(),
        },
    ))
}
