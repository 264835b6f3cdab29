//! The scenario file (TOML): every parameter of a simulated run, and the built-in presets.
//!
//! Every table and field is required and unknown fields are refused, so a scenario file is the
//! complete record of a run (with the seed) and a typo cannot silently fall back to a default.
//! Two later additions are optional, so that older files still load and mean what they meant:
//! `[instrument]` (absent: the accelerometer) and `[[effects]]` (absent: none).
//! `accomp simulate --print-preset paper-1g` prints a complete file to start from.

use serde::{Deserialize, Serialize};

use super::accelerometer::{
    AccelerometerParams, CalibrationSource, HeadPosition, OrientationParams, SpindleAxis,
};
use super::adc::{Ad7124Params, AdcParams, Ads1262Params};
use super::barometer::BarometerParams;
use super::effects::ScenarioEffect;
use super::gravimeter::{GravimeterParams, InstrumentParams};
use super::noise::AllanParams;
use super::rtd::RtdParams;
use super::thermostat::{RoomParams, ThermostatParams};
use super::tide::{Site, TideParams};
use super::tilt::{FoundationParams, TiltmeterParams};

/// Duration and sampling of the run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunParams {
    /// UTC start, ISO 8601 (`YYYY-MM-DDTHH:MM:SSZ`).
    pub start_utc: String,
    /// Length of the run, seconds.
    pub duration_s: f64,
    /// Sample interval, seconds.
    pub interval_s: f64,
}

/// A complete scenario.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Short name, written into the log metadata.
    pub name: String,
    /// What the scenario represents.
    pub description: String,
    /// Duration and sampling.
    pub run: RunParams,
    /// Where the station is.
    pub site: Site,
    /// The laboratory room.
    pub room: RoomParams,
    /// The thermostat.
    pub thermostat: ThermostatParams,
    /// The instrument on the dividing head.
    pub accelerometer: AccelerometerParams,
    /// The RTD.
    pub rtd: RtdParams,
    /// The foundation.
    pub foundation: FoundationParams,
    /// The solid-earth tide.
    pub tide: TideParams,
    /// The tiltmeter.
    pub tiltmeter: TiltmeterParams,
    /// The converters.
    pub adc: AdcParams,
    /// Station pressure and the barometer.
    pub barometer: BarometerParams,
    /// The instrument (`[instrument] kind = "gravimeter"`); absent: the accelerometer of the
    /// `[accelerometer]` table.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub instrument: Option<InstrumentParams>,
    /// Catalogue effects on top of the station physics (`[[effects]]`, `effects.rs`); absent:
    /// none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub effects: Vec<ScenarioEffect>,
    /// A written twin of a measured record (`[twin]`, docs/simulator.md "The written twin"):
    /// `accomp simulate` then computes one member of the twin at the record's instants instead
    /// of running the station; absent: a station scenario.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub twin: Option<crate::twin::TwinSpec>,
}

/// Why a scenario is refused.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    /// The TOML does not parse or does not match the scenario's fields.
    #[error("scenario: {0}")]
    Toml(#[from] toml::de::Error),
    /// A value is out of its physical range.
    #[error("scenario: {0}")]
    Invalid(String),
    /// An `[[effects]]` entry is out of its range.
    #[error("scenario: {0}")]
    Effect(#[from] crate::effects::InvalidEffect),
    /// The `[instrument]` gravimeter is out of its range.
    #[error("scenario: {0}")]
    Instrument(#[from] crate::gravimeter::InvalidInstrument),
    /// `run.start_utc` is refused.
    #[error("scenario: {0}")]
    Start(#[from] InvalidStart),
    /// A numeric field is not finite or outside its physical range.
    #[error("scenario: {0}")]
    Field(#[from] InvalidField),
    /// The `[twin]` section is inconsistent.
    #[error("scenario: [twin]: {0}")]
    Twin(#[from] crate::twin::InvalidTwin),
    /// Neither a file nor a preset of that name.
    #[error("no scenario file or preset named {0:?} (presets: {presets})", presets = PRESETS.join(", "))]
    Unknown(String),
    /// The file exists but is not UTF-8 text (a scenario is TOML).
    #[error("scenario file {0:?} is not UTF-8 text (a scenario is a TOML file)")]
    NotUtf8(String),
    /// The file exists but could not be read, or is larger than a scenario can be.
    #[error("scenario file {0:?}: {1}")]
    Unreadable(String, String),
}

/// Largest scenario file read (a complete scenario is about 3 KB of TOML).
pub const MAX_SCENARIO_BYTES: u64 = 1 << 20;

/// Names of the built-in presets.
pub const PRESETS: [&str; 2] = ["paper-1g", "paper-0g"];

const DAY_S: f64 = 86_400.0;

impl Scenario {
    /// Parses a scenario from TOML text and checks it.
    pub fn from_toml(text: &str) -> Result<Self, ScenarioError> {
        let s: Scenario = toml::from_str(text)?;
        s.validate()?;
        Ok(s)
    }

    /// The scenario as TOML text (all fields).
    pub fn to_toml(&self) -> String {
        // Serializing plain structs of numbers, strings and vectors cannot fail.
        toml::to_string(self).unwrap_or_default()
    }

    /// A built-in preset by name.
    pub fn preset(name: &str) -> Option<Self> {
        match name {
            "paper-1g" => Some(paper_1g()),
            "paper-0g" => Some(paper_0g()),
            _ => None,
        }
    }

    /// The gravimeter, when the station carries one instead of the accelerometer.
    pub fn gravimeter(&self) -> Option<&GravimeterParams> {
        match &self.instrument {
            Some(InstrumentParams::Gravimeter(g)) => Some(g),
            _ => None,
        }
    }

    /// Number of samples of the run.
    pub fn samples(&self) -> u64 {
        (self.run.duration_s / self.run.interval_s).floor() as u64
    }

    /// Checks the ranges that would otherwise produce NaN or nonsense.
    pub fn validate(&self) -> Result<(), ScenarioError> {
        let bad = |m: &str| Err(ScenarioError::Invalid(m.to_string()));
        let r = &self.run;
        if !(r.interval_s.is_finite() && r.interval_s > 0.0) {
            return bad("run.interval_s must be > 0");
        }
        if !(r.duration_s.is_finite() && r.duration_s >= r.interval_s) {
            return bad("run.duration_s must be at least one interval");
        }
        check_start(&r.start_utc, r.duration_s)?;
        self.check_field_ranges()?;
        if !(-90.0..=90.0).contains(&self.site.latitude_deg) {
            return bad("site.latitude_deg must be within ±90");
        }
        let n = &self.accelerometer.noise_g;
        let stds = [
            self.room.weather_std_c,
            self.thermostat.controller_std_c,
            self.thermostat.setpoint_walk_c_per_sqrt_day,
            n.white_adev_1s,
            n.flicker_floor,
            n.random_walk_per_sqrt_s,
            self.rtd.accuracy_c,
            self.rtd.noise_uv_rms,
            self.tiltmeter.noise_arcsec,
            self.tiltmeter.resolution_arcsec,
            self.adc.ads1262.noise_uv_rms,
            self.foundation.creep_arcsec_per_sqrt_day,
            self.room.door_rate_per_day,
            self.barometer.s2_amplitude_hpa,
            self.barometer.s1_amplitude_hpa,
            self.barometer.weather_std_hpa,
            self.barometer.noise_hpa,
            self.barometer.resolution_hpa,
        ];
        if stds.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
            return bad("noise levels, rates and resolutions must be finite and ≥ 0");
        }
        let taus = [
            self.room.weather_tau_h,
            self.room.door_decay_min,
            self.thermostat.controller_tau_s,
            self.thermostat.room_lowpass_h,
            self.thermostat.proof_mass_lag_s,
            self.foundation.building_lag_h,
            self.adc.board_lowpass_min,
            self.tide.step_s,
            self.barometer.weather_tau_h,
        ];
        if taus.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
            return bad("time constants must be finite and ≥ 0");
        }
        if !(self.tiltmeter.scale_arcsec_per_v.is_finite()
            && self.tiltmeter.scale_arcsec_per_v != 0.0)
        {
            return bad("tiltmeter.scale_arcsec_per_v must be non-zero");
        }
        let b = &self.barometer;
        if !(b.sea_level_hpa.is_finite() && b.sea_level_hpa > 0.0) {
            return bad("barometer.sea_level_hpa must be > 0");
        }
        // The barometric formula of the troposphere holds below 11 km.
        if !(self.site.height_m.is_finite() && self.site.height_m < 11_000.0) {
            return bad("site.height_m must be below 11 km (barometric formula)");
        }
        if !(b.s2_peak_solar_h.is_finite() && b.s1_peak_solar_h.is_finite()) {
            return bad("barometer peak hours must be finite");
        }
        if let Some(InstrumentParams::Gravimeter(g)) = &self.instrument {
            g.validate()?;
        }
        for (i, e) in self.effects.iter().enumerate() {
            e.validate(i)?;
        }
        if let Some(t) = &self.twin {
            t.validate(self.effects.len())?;
        }
        Ok(())
    }
}

/// Years a run may start and end in: where the tide and sun ephemerides are used (their
/// series are fitted to the 20th and 21st centuries), with margin.
pub const RUN_YEARS: std::ops::RangeInclusive<i64> = 1900..=2199;

/// Why `run.start_utc` is refused (the message quotes the value).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum InvalidStart {
    /// No year in front.
    #[error("run.start_utc = {0:?}: not of the form YYYY-MM-DDTHH:MM:SSZ")]
    NoYear(String),
    /// The year is outside [`RUN_YEARS`].
    #[error(
        "run.start_utc = {start:?}: year {year} outside {}..={} (the range of the tide and \
         sun ephemerides)",
        RUN_YEARS.start(),
        RUN_YEARS.end()
    )]
    Year {
        /// The value.
        start: String,
        /// Its year.
        year: i64,
    },
    /// Not the format, or a day or time that does not exist.
    #[error(
        "run.start_utc = {0:?}: not of the form YYYY-MM-DDTHH:MM:SSZ, or a day or time that \
         does not exist"
    )]
    NotADate(String),
    /// The run ends after the last of [`RUN_YEARS`].
    #[error(
        "run.start_utc + run.duration_s ends after {}-12-31: outside the range of the tide and \
         sun ephemerides",
        RUN_YEARS.end()
    )]
    EndsTooLate,
}

/// `run.start_utc`: the format, a day and time that exist, and a start and end within
/// [`RUN_YEARS`], each failure said as such.
fn check_start(start: &str, duration_s: f64) -> Result<(), InvalidStart> {
    let year = start
        .trim()
        .split('-')
        .next()
        .and_then(|y| y.parse::<i64>().ok());
    let Some(year) = year else {
        return Err(InvalidStart::NoYear(start.to_owned()));
    };
    if !RUN_YEARS.contains(&year) {
        return Err(InvalidStart::Year {
            start: start.to_owned(),
            year,
        });
    }
    let t = super::time::Utc::parse(start).map_err(|_| InvalidStart::NotADate(start.to_owned()))?;
    // 2200-01-01T00:00:00Z in seconds since 1970.
    const END_UNIX_S: f64 = 7_258_118_400.0;
    if duration_s.is_finite() && t.0 + duration_s > END_UNIX_S {
        return Err(InvalidStart::EndsTooLate);
    }
    Ok(())
}

/// The physical range of each numeric field of the station's tables, by dotted path (array
/// indices left out). A value outside is refused with the field's name and the range, so that
/// `room.mean_c = 1e30` is not a 16,000 °C room and an empty output column. `run.*` is checked
/// by the size limits of `simulate`; `[instrument]` and `[[effects]]` by their own validation.
const FIELD_RANGES: &[(&str, f64, f64)] = &[
    ("site.latitude_deg", -90.0, 90.0),
    ("site.longitude_deg", -180.0, 360.0),
    ("site.height_m", -500.0, 11_000.0),
    ("room.mean_c", -50.0, 60.0),
    ("room.diurnal_amplitude_c", 0.0, 30.0),
    ("room.diurnal_peak_solar_h", 0.0, 24.0),
    ("room.weather_std_c", 0.0, 20.0),
    ("room.weather_tau_h", 0.0, 8_760.0),
    ("room.door_rate_per_day", 0.0, 1_440.0),
    ("room.door_step_c", -20.0, 20.0),
    ("room.door_decay_min", 0.0, 1_440.0),
    ("thermostat.setpoint_c", -50.0, 150.0),
    ("thermostat.controller_std_c", 0.0, 10.0),
    ("thermostat.controller_tau_s", 0.0, 86_400.0),
    ("thermostat.setpoint_walk_c_per_sqrt_day", 0.0, 10.0),
    ("thermostat.room_coupling", 0.0, 1.0),
    ("thermostat.room_lowpass_h", 0.0, 8_760.0),
    ("thermostat.proof_mass_lag_s", 0.0, 86_400.0),
    ("accelerometer.noise_g.white_adev_1s", 0.0, 1e3),
    ("accelerometer.noise_g.flicker_floor", 0.0, 1e3),
    ("accelerometer.noise_g.random_walk_per_sqrt_s", 0.0, 1e3),
    ("accelerometer.orientation.cross_sign", -1.0, 1.0),
    (
        "accelerometer.orientation.indexing_std_arcsec",
        0.0,
        3_600.0,
    ),
    (
        "accelerometer.orientation.positions.angle_deg",
        -360.0,
        360.0,
    ),
    ("accelerometer.orientation.positions.dwell_s", 0.0, 1e8),
    ("rtd.r0_ohm", 1.0, 10_000.0),
    ("rtd.cvd_a", 0.0, 0.01),
    ("rtd.cvd_b", -1e-5, 1e-5),
    ("rtd.cvd_c", -1e-10, 1e-10),
    ("rtd.accuracy_c", 0.0, 10.0),
    ("rtd.excitation_ua", 0.0, 10_000.0),
    ("rtd.self_heating_c_per_mw", 0.0, 10.0),
    ("rtd.noise_uv_rms", 0.0, 1_000.0),
    ("foundation.initial_arcsec", -3_600.0, 3_600.0),
    ("foundation.building_arcsec_per_c", -100.0, 100.0),
    ("foundation.building_lag_h", 0.0, 8_760.0),
    ("foundation.creep_arcsec_per_sqrt_day", 0.0, 100.0),
    ("tide.tilt_azimuth_deg", -360.0, 360.0),
    ("tide.step_s", 0.0, 86_400.0),
    ("tiltmeter.noise_arcsec", 0.0, 100.0),
    ("tiltmeter.resolution_arcsec", 0.0, 100.0),
    ("tiltmeter.scale_arcsec_per_v", -1e6, 1e6),
    ("adc.board_lowpass_min", 0.0, 1_440.0),
    ("adc.ads1262.vref_v", 0.1, 5.5),
    ("adc.ads1262.vref_tempco_ppm_per_c", -1_000.0, 1_000.0),
    ("adc.ads1262.vref_calibrated_at_c", -50.0, 150.0),
    ("adc.ads1262.accel_pga_gain", 1.0, 32.0),
    ("adc.ads1262.tilt_pga_gain", 1.0, 32.0),
    ("adc.ads1262.noise_uv_rms", 0.0, 1_000.0),
    ("adc.ads1262.gain_error_ppm", -1e5, 1e5),
    ("adc.ads1262.offset_uv", -1e6, 1e6),
    ("adc.ad7124.pga_gain", 1.0, 128.0),
    ("adc.ad7124.reference_resistor_ohm", 1.0, 1e6),
    ("adc.ad7124.reference_resistor_error_ppm", -1e5, 1e5),
    ("adc.ad7124.gain_error_ppm", -1e5, 1e5),
    ("barometer.sea_level_hpa", 800.0, 1_100.0),
    ("barometer.s2_amplitude_hpa", 0.0, 10.0),
    ("barometer.s2_peak_solar_h", 0.0, 24.0),
    ("barometer.s1_amplitude_hpa", 0.0, 10.0),
    ("barometer.s1_peak_solar_h", 0.0, 24.0),
    ("barometer.weather_std_hpa", 0.0, 50.0),
    ("barometer.weather_tau_h", 0.0, 8_760.0),
    ("barometer.noise_hpa", 0.0, 10.0),
    ("barometer.resolution_hpa", 0.0, 10.0),
];

/// A numeric field refused, by its dotted path (array indices as `[i]`) and value.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InvalidField {
    /// NaN or an infinity.
    #[error("{path} = {value}: must be a finite number")]
    NotFinite {
        /// The field.
        path: String,
        /// Its value.
        value: f64,
    },
    /// Outside the field's [`FIELD_RANGES`] range.
    #[error("{path} = {value}: outside its physical range {lo} ..= {hi}")]
    OutOfRange {
        /// The field.
        path: String,
        /// Its value.
        value: f64,
        /// Lowest value allowed.
        lo: f64,
        /// Highest value allowed.
        hi: f64,
    },
}

/// Every numeric leaf of a TOML value with its dotted path (array indices as `[i]`).
fn numeric_fields(v: &toml::Value, path: &str, out: &mut Vec<(String, f64)>) {
    match v {
        toml::Value::Float(f) => out.push((path.to_owned(), *f)),
        toml::Value::Integer(i) => out.push((path.to_owned(), *i as f64)),
        toml::Value::Table(t) => {
            for (k, x) in t {
                let p = if path.is_empty() {
                    k.clone()
                } else {
                    format!("{path}.{k}")
                };
                numeric_fields(x, &p, out);
            }
        }
        toml::Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                numeric_fields(x, &format!("{path}[{i}]"), out);
            }
        }
        _ => {}
    }
}

impl Scenario {
    /// Every numeric field finite (NaN and infinities refused by name), and each station field
    /// within its [`FIELD_RANGES`] range.
    fn check_field_ranges(&self) -> Result<(), InvalidField> {
        let Ok(v) = toml::Value::try_from(self) else {
            return Ok(());
        };
        let mut fields = Vec::new();
        numeric_fields(&v, "", &mut fields);
        for (path, x) in fields {
            if !x.is_finite() {
                return Err(InvalidField::NotFinite { path, value: x });
            }
            let key: String = {
                // `positions[2].angle_deg` → `positions.angle_deg`
                let mut k = String::with_capacity(path.len());
                let mut skip = false;
                for c in path.chars() {
                    match c {
                        '[' => skip = true,
                        ']' => skip = false,
                        _ if !skip => k.push(c),
                        _ => {}
                    }
                }
                k
            };
            if let Some((_, lo, hi)) = FIELD_RANGES.iter().find(|(f, ..)| *f == key) {
                if !(*lo..=*hi).contains(&x) {
                    return Err(InvalidField::OutOfRange {
                        path,
                        value: x,
                        lo: *lo,
                        hi: *hi,
                    });
                }
            }
        }
        Ok(())
    }
}

/// Resolves a command-line scenario argument: a preset name or a TOML file path.
pub fn load(arg: &str) -> Result<Scenario, ScenarioError> {
    if let Some(s) = Scenario::preset(arg) {
        return Ok(s);
    }
    use std::io::Read as _;
    let file = match std::fs::File::open(arg) {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(ScenarioError::Unknown(arg.to_string()))
        }
        Err(e) => return Err(ScenarioError::Unreadable(arg.to_string(), e.to_string())),
    };
    let mut bytes = Vec::new();
    file.take(MAX_SCENARIO_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| ScenarioError::Unreadable(arg.to_string(), e.to_string()))?;
    if bytes.len() as u64 > MAX_SCENARIO_BYTES {
        return Err(ScenarioError::Unreadable(
            arg.to_string(),
            format!("larger than {MAX_SCENARIO_BYTES} bytes, not a scenario"),
        ));
    }
    let text = String::from_utf8(bytes).map_err(|_| ScenarioError::NotUtf8(arg.to_string()))?;
    Scenario::from_toml(&text)
}

fn beijing() -> Site {
    // Changcheng Institute of Metrology & Measurement, Beijing (approximate).
    Site {
        latitude_deg: 40.0,
        longitude_deg: 116.25,
        height_m: 60.0,
    }
}

/// The paper-1g Pt100 (also the RTD tests' sensor, without self-heating and noise).
pub(crate) fn pt100() -> RtdParams {
    RtdParams {
        r0_ohm: 100.0,
        cvd_a: 3.9083e-3,
        cvd_b: -5.775e-7,
        cvd_c: -4.183e-12,
        accuracy_c: 0.1,
        excitation_ua: 250.0,
        self_heating_c_per_mw: 0.05,
        noise_uv_rms: 0.1,
    }
}

/// The board's converters: nominal values from the core's front-end module (`accomp::board`),
/// imperfections (tempco, noise) of the simulated board.
fn board() -> AdcParams {
    use accomp::board as fe;
    AdcParams {
        ads1262: Ads1262Params {
            vref_v: fe::ADS1262_VREF.0,
            vref_tempco_ppm_per_c: 0.5,
            vref_calibrated_at_c: 20.0,
            accel_pga_gain: fe::ACCEL_PGA_GAIN,
            tilt_pga_gain: fe::TILT_PGA_GAIN,
            noise_uv_rms: 0.3,
            gain_error_ppm: 0.0,
            offset_uv: 0.0,
        },
        ad7124: Ad7124Params {
            pga_gain: fe::RTD_PGA_GAIN,
            reference_resistor_ohm: fe::RTD_REFERENCE_OHMS,
            reference_resistor_error_ppm: 0.0,
            gain_error_ppm: 0.0,
        },
        board_lowpass_min: 30.0,
    }
}

fn tiltmeter() -> TiltmeterParams {
    TiltmeterParams {
        noise_arcsec: 0.02,
        resolution_arcsec: 0.1,
        scale_arcsec_per_v: 10.0,
    }
}

/// Beijing's barometric environment: standard sea-level mean; S2 = 1.16·cos³(40°) ≈ 0.5 hPa
/// peaking at 10 and 22 LST; S1 0.3 hPa peaking at 7 LST (continental mid latitude); weather
/// 4 hPa with a 2-day correlation time (a season of passing systems); a PTB330-class barometer
/// (0.01 hPa noise and resolution). Sources in `barometer.rs`.
pub(crate) fn barometer() -> BarometerParams {
    BarometerParams {
        sea_level_hpa: 1013.25,
        s2_amplitude_hpa: 0.5,
        s2_peak_solar_h: 10.0,
        s1_amplitude_hpa: 0.3,
        s1_peak_solar_h: 7.0,
        weather_std_hpa: 4.0,
        weather_tau_h: 48.0,
        noise_hpa: 0.01,
        resolution_hpa: 0.01,
    }
}

fn static_head(angle_deg: f64) -> OrientationParams {
    OrientationParams {
        spindle_axis: SpindleAxis::Output,
        cross_sign: 1.0,
        positions: vec![HeadPosition {
            angle_deg,
            dwell_s: 0.0,
        }],
        indexing_std_arcsec: 0.2,
    }
}

/// The paper's 1 g test: JN-06 A12124 at 60 °C for 41 days (see docs/simulator.md for the
/// choice of every magnitude).
fn paper_1g() -> Scenario {
    Scenario {
        name: "paper-1g".into(),
        description: "JN-06-like accelerometer, input axis up (1 g), thermostat at 60 °C, 41 days"
            .into(),
        run: RunParams {
            start_utc: "2016-03-01T00:00:00Z".into(),
            duration_s: 41.0 * DAY_S,
            interval_s: 60.0,
        },
        site: beijing(),
        room: RoomParams {
            mean_c: 20.0,
            diurnal_amplitude_c: 1.5,
            diurnal_peak_solar_h: 15.0,
            weather_std_c: 1.0,
            weather_tau_h: 72.0,
            door_rate_per_day: 2.0,
            door_step_c: 0.8,
            door_decay_min: 20.0,
        },
        thermostat: ThermostatParams {
            setpoint_c: 60.0,
            controller_std_c: 0.165,
            controller_tau_s: 900.0,
            setpoint_walk_c_per_sqrt_day: 0.005,
            room_coupling: 0.03,
            room_lowpass_h: 2.0,
            proof_mass_lag_s: 60.0,
        },
        accelerometer: AccelerometerParams {
            instrument: "JN-06 A12124 (simulated)".into(),
            calibration: CalibrationSource::PaperPrintedOrder2,
            noise_g: AllanParams {
                white_adev_1s: 2e-6,
                flicker_floor: 1e-6,
                random_walk_per_sqrt_s: 7e-9,
            },
            orientation: static_head(90.0),
        },
        rtd: pt100(),
        foundation: FoundationParams {
            initial_arcsec: 0.0,
            building_arcsec_per_c: 0.1,
            building_lag_h: 4.0,
            creep_arcsec_per_sqrt_day: 0.05,
        },
        tide: TideParams {
            enabled: true,
            tilt_azimuth_deg: 0.0,
            step_s: 60.0,
        },
        tiltmeter: tiltmeter(),
        adc: board(),
        barometer: barometer(),
        instrument: None,
        effects: Vec::new(),
        twin: None,
    }
}

/// The paper's 0 g test: an SNJ-103-like accelerometer, input axis horizontal, at room
/// temperature for one day with a daily foundation tilt of about 0.45". The station is the 1 g
/// test's (site, RTD, tide, tiltmeter, converters, barometer); what differs is written here.
fn paper_0g() -> Scenario {
    let base = paper_1g();
    Scenario {
        name: "paper-0g".into(),
        description:
            "SNJ-103-like accelerometer, input axis horizontal (0 g), room temperature, 1 day, \
             about 0.45\" of daily foundation tilt"
                .into(),
        run: RunParams {
            start_utc: "2016-05-10T00:00:00Z".into(),
            duration_s: DAY_S,
            ..base.run
        },
        room: RoomParams {
            mean_c: 22.0,
            weather_std_c: 0.3,
            door_step_c: 0.5,
            ..base.room
        },
        thermostat: ThermostatParams {
            setpoint_c: 25.0,
            controller_std_c: 0.01,
            controller_tau_s: 600.0,
            setpoint_walk_c_per_sqrt_day: 0.002,
            room_coupling: 0.005,
            room_lowpass_h: 3.0,
            ..base.thermostat
        },
        accelerometer: AccelerometerParams {
            instrument: "SNJ-103 (simulated, JN-06-like models)".into(),
            noise_g: AllanParams {
                white_adev_1s: 1e-6,
                flicker_floor: 0.5e-6,
                random_walk_per_sqrt_s: 8e-9,
            },
            orientation: static_head(0.0),
            ..base.accelerometer
        },
        foundation: FoundationParams {
            building_arcsec_per_c: 0.21,
            creep_arcsec_per_sqrt_day: 0.02,
            ..base.foundation
        },
        ..base
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_ranged_field_exists_and_the_presets_are_within_their_ranges() {
        let s = Scenario::preset("paper-1g").unwrap();
        let mut fields = Vec::new();
        numeric_fields(&toml::Value::try_from(&s).unwrap(), "", &mut fields);
        let names: Vec<String> = fields.iter().map(|(p, _)| p.replace("[0]", "")).collect();
        for (f, lo, hi) in FIELD_RANGES {
            assert!(
                names.iter().any(|n| n == f),
                "{f} is no field of a scenario"
            );
            assert!(lo < hi, "{f}");
        }
        for name in PRESETS {
            Scenario::preset(name).unwrap().validate().unwrap();
        }
    }

    #[test]
    fn out_of_range_nan_and_infinite_fields_are_refused_by_name_with_the_range() {
        let text = Scenario::preset("paper-1g").unwrap().to_toml();
        for (from, to, said) in [
            ("mean_c = 20.0", "mean_c = 1e30", "room.mean_c = 1000000000000000000000000000000: outside its physical range -50 ..= 60"),
            ("sea_level_hpa = 1013.25", "sea_level_hpa = nan", "barometer.sea_level_hpa = NaN: must be a finite number"),
            ("door_step_c = 0.8", "door_step_c = -inf", "room.door_step_c = -inf: must be a finite number"),
            ("angle_deg = 90.0", "angle_deg = inf", "accelerometer.orientation.positions[0].angle_deg = inf"),
            ("start_utc = \"2016-03-01T00:00:00Z\"", "start_utc = \"9999-12-31T00:00:00Z\"", "year 9999 outside 1900..=2199"),
            ("start_utc = \"2016-03-01T00:00:00Z\"", "start_utc = \"2016-02-30T00:00:00Z\"", "does not exist"),
        ] {
            assert!(text.contains(from), "{from}");
            let e = Scenario::from_toml(&text.replace(from, to)).unwrap_err().to_string();
            assert!(e.contains(said), "{to}: {e}");
        }
    }

    #[test]
    fn presets_round_trip_through_toml() {
        for name in PRESETS {
            let s = Scenario::preset(name).unwrap();
            let back = Scenario::from_toml(&s.to_toml()).unwrap();
            assert_eq!(back, s, "{name}");
        }
    }

    #[test]
    fn unknown_and_missing_fields_are_refused() {
        let text = Scenario::preset("paper-1g").unwrap().to_toml();
        let typo = text.replace("setpoint_c", "set_point_c");
        assert!(matches!(
            Scenario::from_toml(&typo),
            Err(ScenarioError::Toml(_))
        ));
        let missing = text.replace("proof_mass_lag_s = 60.0\n", "");
        assert!(matches!(
            Scenario::from_toml(&missing),
            Err(ScenarioError::Toml(_))
        ));
    }

    #[test]
    fn a_scenario_without_the_barometer_table_is_refused() {
        let text = Scenario::preset("paper-0g").unwrap().to_toml();
        let start = text.find("[barometer]").unwrap();
        let end = text[start + 1..]
            .find("\n[")
            .map_or(text.len(), |i| start + 1 + i + 1);
        let without = format!("{}{}", &text[..start], &text[end..]);
        assert!(!without.contains("s2_amplitude_hpa"));
        assert!(matches!(
            Scenario::from_toml(&without),
            Err(ScenarioError::Toml(_))
        ));
        let mut s = Scenario::preset("paper-0g").unwrap();
        s.barometer.sea_level_hpa = 0.0;
        // Outside the field's physical range (checked before the "must be > 0" of validate).
        assert!(
            matches!(s.validate(), Err(e @ ScenarioError::Field(_)) if e.to_string().contains("sea_level"))
        );
    }

    #[test]
    fn impossible_values_are_refused_by_name() {
        let mut s = Scenario::preset("paper-0g").unwrap();
        s.run.interval_s = 0.0;
        assert!(matches!(s.validate(), Err(ScenarioError::Invalid(m)) if m.contains("interval")));
        let mut s = Scenario::preset("paper-0g").unwrap();
        s.accelerometer.noise_g.white_adev_1s = -1.0;
        assert!(s.validate().is_err());
        assert!(matches!(
            load("no-such-preset"),
            Err(ScenarioError::Unknown(_))
        ));
    }

    #[test]
    fn a_file_without_instrument_or_effects_loads_as_the_accelerometer_without_effects() {
        // Files written before `[instrument]` and `[[effects]]` existed: the preset's TOML
        // has neither (empty/absent ones are not written) and loads with their defaults.
        let text = Scenario::preset("paper-1g").unwrap().to_toml();
        assert!(
            !text.contains("instrument]") && !text.contains("effects"),
            "{text}"
        );
        let s = Scenario::from_toml(&text).unwrap();
        assert!(s.instrument.is_none() && s.effects.is_empty() && s.gravimeter().is_none());
    }

    #[test]
    fn a_gravimeter_in_an_unknown_unit_or_an_unknown_effect_kind_is_refused_by_name() {
        let text = Scenario::preset("paper-0g").unwrap().to_toml();
        let grav = |unit: &str| {
            format!(
                "{text}\n[instrument]\nkind = \"gravimeter\"\nname = \"g\"\nunit = \"{unit}\"\n\
                 offset = 0.0\ndrift_per_day = 0.0\ntide_factor = 1.0\ntide_delay_s = 0.0\n\
                 pressure_admittance_per_hpa = 0.0\n\
                 noise = {{ white_adev_1s = 1.0, flicker_floor = 0.0, random_walk_per_sqrt_s = 0.0 }}\n"
            )
        };
        let ok = Scenario::from_toml(&grav("ugal")).unwrap();
        assert_eq!(ok.gravimeter().map(|g| g.column()), Some("gravity_ugal"));
        assert!(matches!(
            Scenario::from_toml(&grav("volt")),
            Err(ScenarioError::Instrument(e)) if e.field == "unit"
                && e.to_string().contains("instrument.unit") && e.to_string().contains("volt")
        ));
        let unknown = format!("{text}\n[[effects]]\nkind = \"gremlins\"\nsize = 1.0\n");
        assert!(matches!(
            Scenario::from_toml(&unknown),
            Err(ScenarioError::Toml(e)) if e.to_string().contains("gremlins")
        ));
        let bad = format!("{text}\n[[effects]]\nkind = \"periodic\"\nperiod_s = 0.0\namplitude = 1.0\nphase_rad = 0.0\n");
        assert!(matches!(
            Scenario::from_toml(&bad),
            Err(ScenarioError::Effect(e)) if e.index == 0 && e.field == "period_s"
                && e.to_string().contains("effects[0] (periodic): period_s")
        ));
    }

    #[test]
    fn the_1g_preset_lasts_41_days_and_sampling_is_configurable() {
        let mut s = Scenario::preset("paper-1g").unwrap();
        assert_eq!(s.samples(), 41 * 1440);
        s.run.interval_s = 1.0;
        assert_eq!(s.samples(), 41 * 86_400);
    }
}
