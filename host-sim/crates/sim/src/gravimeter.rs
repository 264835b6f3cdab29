//! A gravimeter in place of the accelerometer: a relative (spring) or absolute (atom) gravity
//! meter whose output is gravity in a gravity unit, as the measured records are (the gMetrology
//! `.tsf` in mGal, the AQG CSV in nm/s²).
//!
//! ```text
//! g_out(t) = offset + drift·t + factor·tide(t − delay) + admittance·(p − p̄) + n(t)
//! ```
//! - tide: the simulator's solid-earth tide gravity (`tide.rs`, the core ephemeris model with
//!   the elastic Earth), converted to the output unit;
//! - admittance: the barometric admittance, output unit per hPa of the true station pressure
//!   (typically −3 nm/s²/hPa = −0.3 µGal/hPa: the attraction and loading of the air column);
//! - drift: linear instrumental drift (a spring gravimeter creeps by up to mGal/day);
//! - n(t): white + flicker + random walk with the given Allan levels, in the output unit
//!   (`noise::AllanNoise`).
//!
//! The scenario selects it with `[instrument] kind = "gravimeter"`; without an `[instrument]`
//! table the station carries the accelerometer (`accelerometer.rs`), as it always did.

use serde::{Deserialize, Serialize};

use super::noise::AllanParams;

/// Gravity units the gravimeter can write: the record column suffixes `accomp discover` reads
/// (`accomp_log::unit_per_g_for_suffix`).
pub use accomp_log::GRAVITY_UNITS as UNITS;

/// A gravimeter parameter out of its range (`instrument.<field> <why>`).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("instrument.{field} {why}")]
pub struct InvalidInstrument {
    /// The `[instrument]` field.
    pub field: &'static str,
    /// What it must be.
    pub why: String,
}

/// The gravimeter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GravimeterParams {
    /// Instrument name written into the log metadata.
    pub name: String,
    /// Output unit, one of [`UNITS`]; the log column is `gravity_<unit>`.
    pub unit: String,
    /// Reading at t = 0, output unit.
    pub offset: f64,
    /// Linear drift, output unit per day.
    pub drift_per_day: f64,
    /// Factor on the model's elastic-Earth tide (1: the model is exact).
    pub tide_factor: f64,
    /// Delay of the output behind the tide, s (instrument filter).
    pub tide_delay_s: f64,
    /// Barometric admittance, output unit per hPa.
    pub pressure_admittance_per_hpa: f64,
    /// Noise, output unit.
    pub noise: AllanParams,
}

/// Which instrument the station carries.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum InstrumentParams {
    /// The accelerometer of the `[accelerometer]` table (the default without `[instrument]`).
    Accelerometer,
    /// A gravimeter; the `[accelerometer]` table is then unused.
    Gravimeter(GravimeterParams),
}

impl GravimeterParams {
    /// A gravimeter that reads the model's tide exactly (factor 1, no delay), with no drift, no
    /// barometric admittance and no noise, reading 0 at t = 0. A station's instrument is this
    /// one with what it does differently set on top (`..GravimeterParams::ideal(name, unit)`).
    pub fn ideal(name: impl Into<String>, unit: impl Into<String>) -> Self {
        GravimeterParams {
            name: name.into(),
            unit: unit.into(),
            offset: 0.0,
            drift_per_day: 0.0,
            tide_factor: 1.0,
            tide_delay_s: 0.0,
            pressure_admittance_per_hpa: 0.0,
            noise: AllanParams::NONE,
        }
    }

    /// Output units per g.
    pub fn unit_per_g(&self) -> Option<f64> {
        accomp_log::unit_per_g_for_suffix(&self.unit)
    }

    /// Output units per nm/s² of gravity.
    pub fn unit_per_nm_s2(&self) -> Option<f64> {
        self.unit_per_g()
            .map(|u| u / (accomp::tide::STANDARD_GRAVITY_M_S2 * accomp::tide::NM_S2_PER_M_S2))
    }

    /// The log column of the output.
    pub fn column(&self) -> &'static str {
        match self.unit.as_str() {
            "mgal" => "gravity_mgal",
            "ugal" => "gravity_ugal",
            "nm_s2" => "gravity_nm_s2",
            _ => "gravity_m_s2",
        }
    }

    /// Checks the ranges.
    pub fn validate(&self) -> Result<(), InvalidInstrument> {
        if !UNITS.contains(&self.unit.as_str()) {
            return Err(InvalidInstrument {
                field: "unit",
                why: format!(
                    "{:?} is not a gravity unit ({})",
                    self.unit,
                    UNITS.join(", ")
                ),
            });
        }
        let finite = [
            ("offset", self.offset),
            ("drift_per_day", self.drift_per_day),
            ("tide_factor", self.tide_factor),
            (
                "pressure_admittance_per_hpa",
                self.pressure_admittance_per_hpa,
            ),
        ];
        if let Some((name, _)) = finite.iter().find(|(_, v)| !v.is_finite()) {
            return Err(InvalidInstrument {
                field: name,
                why: "must be finite".into(),
            });
        }
        if !(self.tide_delay_s.is_finite() && self.tide_delay_s.abs() <= 7200.0) {
            return Err(InvalidInstrument {
                field: "tide_delay_s",
                why: "must be within ±7200 s".into(),
            });
        }
        let n = &self.noise;
        if [n.white_adev_1s, n.flicker_floor, n.random_walk_per_sqrt_s]
            .iter()
            .any(|v| !(v.is_finite() && *v >= 0.0))
        {
            return Err(InvalidInstrument {
                field: "noise",
                why: "levels must be finite and ≥ 0".into(),
            });
        }
        Ok(())
    }
}
