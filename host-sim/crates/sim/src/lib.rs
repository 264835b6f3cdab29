//! The station simulator: the paper's test station as explicit, parameterized physical models,
//! one file per part, run sample by sample and written in the log format.
//!
//! - `thermostat.rs`: room (daily cycle, weather, doors), thermostat, proof-mass lag;
//! - `accelerometer.rs`: dividing head orientation, eq. (1) with true temperature models, noise;
//! - `rtd.rs`: Callendar–Van Dusen sensor with a fixed unknown offset, excitation, noise;
//! - `tilt.rs`: foundation (building thermal tilt, creep) and the tiltmeter;
//! - `tide.rs`: solid-earth tide gravity and tilt at the site (core `tide` model);
//! - `barometer.rs`: station pressure (height, atmospheric tide, weather) and the barometer;
//! - `adc.rs`: ADS1262 and AD7124 codes as the board sees them;
//! - `noise.rs`: seeded processes (AR(1), random walk, flicker, Allan noise);
//! - `gravimeter.rs`: a gravimeter in place of the accelerometer (output in a gravity unit);
//! - `catalogue.rs`: the catalogue of effects (names, parameters, units), which the discovery
//!   reads too; `effects.rs`: its effects as optional scenario physics;
//! - `scenario.rs`: the TOML scenario and presets; UTC (`time`) and the log writer (`writer`)
//!   are `accomp-log`'s.
//!
//! Physics, parameters and default magnitudes: docs/simulator.md.

pub mod accelerometer;
pub mod adc;
pub mod barometer;
pub mod catalogue;
pub mod effects;
pub mod gravimeter;
pub mod noise;
pub mod rtd;
pub mod scenario;
pub mod thermostat;
pub mod tide;
pub mod tilt;
pub mod twin;

/// Unit tests' scratch folders, removed on drop (the integration tests' own helper).
#[cfg(test)]
#[path = "../../../tests/common/scratch.rs"]
mod scratch;
pub use accomp_log::{time, writer};

use std::io::Write;

use accomp::units::{Volts, RAD_PER_ARCSEC};

use accelerometer::{axes, AccelError, Accelerometer, DividingHead};
use barometer::Barometer;
use effects::{ChainSetup, Drive, EffectChain};
use gravimeter::GravimeterParams;
use noise::{stream, AllanNoise, SimRng};
use rtd::Rtd;
use scenario::Scenario;
use thermostat::{LowPass, Room, Thermostat};
use tide::{TideModel, TideSampler};
use tilt::{tiltmeter_reading, Foundation};
use time::Utc;
use writer::{Column, LogWriter};

/// Standard gravity, m/s² (the tide's gravity change is turned into g with it): the core's.
pub use accomp::tide::STANDARD_GRAVITY_M_S2;

/// Random streams, one per part (see [`noise::stream`]).
mod streams {
    pub const ROOM: u64 = 1;
    pub const THERMOSTAT: u64 = 2;
    pub const ACCEL_NOISE: u64 = 3;
    pub const RTD: u64 = 4;
    pub const HEAD: u64 = 5;
    pub const FOUNDATION: u64 = 6;
    pub const TILTMETER: u64 = 7;
    pub const ADC: u64 = 8;
    pub const BAROMETER: u64 = 9;
    pub const EFFECTS: u64 = 10;
    pub const GRAVIMETER: u64 = 11;
}

/// Why a simulation fails.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// The scenario is unusable.
    #[error(transparent)]
    Scenario(#[from] scenario::ScenarioError),
    /// The instrument could not be set up.
    #[error(transparent)]
    Accelerometer(#[from] AccelError),
    /// The tide model refused the site.
    #[error(transparent)]
    Tide(#[from] tide::TideError),
    /// An ADC conversion was impossible (non-finite input: a model produced NaN).
    #[error("ADC conversion failed at t = {time_s} s: {error:?}")]
    Adc {
        /// When.
        time_s: f64,
        /// Why.
        error: accomp::adc::AdcError,
    },
    /// The scenario's effects cannot be set up (an unknown ambient channel, a bad site).
    #[error(transparent)]
    Effects(#[from] effects::EffectError),
    /// A twin cannot be built from the record.
    #[error("twin: {0}")]
    Twin(String),
    /// Writing the log failed.
    #[error("writing the log: {0}")]
    Io(#[from] std::io::Error),
    /// The log just written could not be read back.
    #[error("reading the simulated log back: {0}")]
    ReadBack(#[from] accomp_log::LogError),
}

/// Options of a run that are not physics.
#[derive(Debug, Clone, Copy, Default)]
pub struct Options {
    /// Add the raw ADC code columns (accel_code, rtd_code, tilt_code).
    pub codes: bool,
}

/// One simulated sample: what the board measures and the truth behind it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Seconds since the start.
    pub time_s: f64,
    /// Accelerometer output measured by the ADS1262 (NaN when saturated).
    pub output_v: f64,
    /// Temperature measured by the RTD (NaN when the conversion failed).
    pub temperature_c: f64,
    /// Tilt measured by the tiltmeter (NaN when saturated).
    pub tilt_arcsec: f64,
    /// Station pressure measured by the barometer, hPa.
    pub pressure_hpa: f64,
    /// Gravimeter output in its unit (NaN when the station carries the accelerometer).
    pub gravity: f64,
    /// ADS1262 accelerometer code, signed.
    pub accel_code: i32,
    /// AD7124 RTD code.
    pub rtd_code: u32,
    /// ADS1262 tiltmeter code, signed.
    pub tilt_code: i32,
    /// True input acceleration a_i, g.
    pub truth_input_g: f64,
    /// True a_p, g.
    pub truth_a_p_g: f64,
    /// True a_o, g.
    pub truth_a_o_g: f64,
    /// True proof-mass temperature (what the coefficients follow), °C.
    pub truth_temperature_c: f64,
    /// True mounting-block temperature (what the RTD sits on), °C.
    pub truth_mount_temperature_c: f64,
    /// Room temperature, °C.
    pub truth_room_c: f64,
    /// Board temperature (ADC reference), °C.
    pub truth_board_c: f64,
    /// True foundation tilt including the tide, arcsec.
    pub truth_tilt_arcsec: f64,
    /// Tide part of the tilt, arcsec.
    pub truth_tide_tilt_arcsec: f64,
    /// Tide gravity change, nm/s².
    pub truth_tide_gravity_nm_s2: f64,
    /// Accelerometer noise referred to the input, g.
    pub truth_noise_g: f64,
    /// Accelerometer output before the ADC, V.
    pub truth_output_v: f64,
    /// Head angle including indexing error, degrees.
    pub truth_head_angle_deg: f64,
    /// True station pressure, hPa.
    pub truth_pressure_hpa: f64,
    /// Resistance of the RTD as wired (offset, self-heating and reading noise included), ohms:
    /// what the virtual board's AD7124 model measures.
    pub truth_rtd_ohms: f64,
}

/// The whole station.
pub struct Simulator {
    scenario: Scenario,
    start: Utc,
    interval_s: f64,
    samples: u64,
    next: u64,
    room: Room,
    thermostat: Thermostat,
    board: LowPass,
    accel: Accelerometer,
    head: DividingHead,
    rtd: Rtd,
    foundation: Foundation,
    tide: TideSampler,
    barometer: Barometer,
    effects: Option<EffectChain>,
    gravimeter: Option<Gravimeter>,
    rng_room: SimRng,
    rng_thermostat: SimRng,
    rng_accel: SimRng,
    rng_rtd: SimRng,
    rng_head: SimRng,
    rng_foundation: SimRng,
    rng_tiltmeter: SimRng,
    rng_adc: SimRng,
    rng_barometer: SimRng,
    rng_effects: SimRng,
}

/// The gravimeter's running parts.
struct Gravimeter {
    p: GravimeterParams,
    unit_per_nm_s2: f64,
    noise: AllanNoise,
    tide: TideSampler,
    rng: SimRng,
}

/// Output units per g of the scenario's instrument: K1 at the set point (V/g) for the
/// accelerometer, the gravity unit's for the gravimeter.
pub fn unit_per_g(scenario: &Scenario) -> Result<f64, SimError> {
    match scenario.gravimeter() {
        Some(g) => g
            .unit_per_g()
            .ok_or_else(|| SimError::Twin(format!("unknown gravity unit {:?}", g.unit))),
        None => {
            let models = scenario
                .accelerometer
                .calibration
                .load(scenario.thermostat.setpoint_c)?;
            Ok(
                accelerometer::true_coefficients(&models, scenario.thermostat.setpoint_c)
                    .scale_factor_v_per_g,
            )
        }
    }
}

impl Simulator {
    /// Sets up every part from the scenario and the seed.
    pub fn new(scenario: &Scenario, seed: u64) -> Result<Self, SimError> {
        scenario.validate()?;
        let s = scenario;
        let dt = s.run.interval_s;
        let start = Utc::parse(&s.run.start_utc)
            .map_err(|e| scenario::ScenarioError::Invalid(e.to_string()))?;
        let mut rng_room = stream(seed, streams::ROOM);
        let mut rng_thermostat = stream(seed, streams::THERMOSTAT);
        let mut rng_accel = stream(seed, streams::ACCEL_NOISE);
        let mut rng_rtd = stream(seed, streams::RTD);
        let mut rng_barometer = stream(seed, streams::BAROMETER);
        let models = s.accelerometer.calibration.load(s.thermostat.setpoint_c)?;
        let noise = AllanNoise::new(
            &s.accelerometer.noise_g,
            dt,
            s.run.duration_s,
            &mut rng_accel,
        );
        let tide_model = if s.tide.enabled {
            Some(TideModel::new(&s.site, s.tide.tilt_azimuth_deg)?)
        } else {
            None
        };
        let head = DividingHead::new(&s.accelerometer.orientation)?;
        let effects = if s.effects.is_empty() {
            None
        } else {
            let input_g = match s.gravimeter() {
                Some(_) => 1.0,
                None => head.nominal_input_g(),
            };
            Some(EffectChain::new(
                &s.effects,
                ChainSetup {
                    start_unix_s: start.0,
                    site: (s.site.latitude_deg, s.site.longitude_deg, s.site.height_m),
                    span_s: (0.0, s.run.duration_s),
                    unit_per_g: unit_per_g(s)?,
                    input_g,
                    ambient: effects::SIMULATED_AMBIENT
                        .iter()
                        .map(|c| (*c).to_owned())
                        .collect(),
                },
            )?)
        };
        let gravimeter = match s.gravimeter() {
            Some(g) => {
                let mut rng = stream(seed, streams::GRAVIMETER);
                let noise = AllanNoise::new(&g.noise, dt, s.run.duration_s, &mut rng);
                let model = if s.tide.enabled {
                    Some(TideModel::new(&s.site, s.tide.tilt_azimuth_deg)?)
                } else {
                    None
                };
                Some(Gravimeter {
                    unit_per_nm_s2: g.unit_per_nm_s2().ok_or_else(|| {
                        SimError::Twin(format!("unknown gravity unit {:?}", g.unit))
                    })?,
                    noise,
                    tide: TideSampler::new(model, start, s.tide.step_s),
                    p: g.clone(),
                    rng,
                })
            }
            None => None,
        };
        Ok(Simulator {
            effects,
            gravimeter,
            rng_effects: stream(seed, streams::EFFECTS),
            start,
            interval_s: dt,
            samples: s.samples(),
            next: 0,
            room: Room::new(&s.room, dt, &mut rng_room),
            thermostat: Thermostat::new(&s.thermostat, dt, &mut rng_thermostat),
            // The board starts at the mean room temperature.
            board: LowPass::new(s.adc.board_lowpass_min * 60.0, dt, s.room.mean_c),
            accel: Accelerometer::new(models, noise),
            head,
            rtd: Rtd::new(&s.rtd, &mut rng_rtd),
            foundation: Foundation::new(&s.foundation, dt),
            tide: TideSampler::new(tide_model, start, s.tide.step_s),
            barometer: Barometer::new(&s.barometer, s.site.height_m, dt, &mut rng_barometer),
            rng_room,
            rng_thermostat,
            rng_accel,
            rng_rtd,
            rng_head: stream(seed, streams::HEAD),
            rng_foundation: stream(seed, streams::FOUNDATION),
            rng_tiltmeter: stream(seed, streams::TILTMETER),
            rng_adc: stream(seed, streams::ADC),
            rng_barometer,
            scenario: scenario.clone(),
        })
    }

    /// Number of samples of the run.
    pub fn samples(&self) -> u64 {
        self.samples
    }

    /// The RTD's drawn offset (truth).
    pub fn rtd_offset_c(&self) -> f64 {
        self.rtd.offset_c()
    }

    /// K1 of the true model at the set point, V/g.
    pub fn scale_factor_at_setpoint(&self) -> f64 {
        accelerometer::true_coefficients(self.accel.models(), self.scenario.thermostat.setpoint_c)
            .scale_factor_v_per_g
    }

    /// The log metadata of this run.
    pub fn metadata(&self, seed: u64) -> Vec<(String, String)> {
        let s = &self.scenario;
        let mut m: Vec<(String, String)> = vec![
            ("instrument".into(), s.accelerometer.instrument.clone()),
            ("start_utc".into(), self.start.to_string()),
            ("latitude_deg".into(), s.site.latitude_deg.to_string()),
            ("longitude_deg".into(), s.site.longitude_deg.to_string()),
            ("height_m".into(), s.site.height_m.to_string()),
            (
                "input_g".into(),
                format!("{}", round_to(self.head.nominal_input_g(), 12)),
            ),
            (
                "scale_factor_v_per_g".into(),
                format!("{}", round_to(self.scale_factor_at_setpoint(), 9)),
            ),
            ("seed".into(), seed.to_string()),
            ("scenario".into(), s.name.clone()),
            ("interval_s".into(), s.run.interval_s.to_string()),
            ("duration_s".into(), s.run.duration_s.to_string()),
            ("setpoint_c".into(), s.thermostat.setpoint_c.to_string()),
            ("tilt_axis".into(), "input".into()),
            (
                "tiltmeter_scale_arcsec_per_v".into(),
                s.tiltmeter.scale_arcsec_per_v.to_string(),
            ),
            (
                "generator".into(),
                format!("accomp simulate {}", env!("CARGO_PKG_VERSION")),
            ),
        ];
        m.push((
            "truth_rtd_offset_c".into(),
            format!("{}", round_to(self.rtd_offset_c(), 9)),
        ));
        if let Some(g) = s.gravimeter() {
            // A vertical gravimeter: its input is gravity (1 g), its unit the column's suffix.
            for (k, v) in m.iter_mut() {
                match k.as_str() {
                    "instrument" => *v = g.name.clone(),
                    "input_g" => *v = "1".into(),
                    _ => {}
                }
            }
            m.retain(|(k, _)| k != "scale_factor_v_per_g");
        }
        m
    }

    /// Advances one sample.
    pub fn step(&mut self) -> Result<Sample, SimError> {
        let s = &self.scenario;
        let t = self.next as f64 * self.interval_s;
        self.next += 1;
        let utc = self.start.plus(t);
        let solar_h = (utc.0 / 3600.0 + s.site.longitude_deg / 15.0).rem_euclid(24.0);

        let room = self.room.step(t, solar_h, &mut self.rng_room);
        let room_dev = room - self.room.mean_c();
        let board = self.board.step(room);
        let (mount, proof) = self.thermostat.step(room_dev, &mut self.rng_thermostat);

        let tide = self.tide.at(t);
        let tilt = self.foundation.step(room_dev, &mut self.rng_foundation) + tide.tilt_arcsec;
        let head = self.head.angle_rad(t, &mut self.rng_head);
        let g = 1.0 + tide.gravity_nm_s2 * 1e-9 / STANDARD_GRAVITY_M_S2;
        let (a_i, cross) = axes(
            s.accelerometer.orientation.spindle_axis,
            s.accelerometer.orientation.cross_sign,
            head + tilt * RAD_PER_ARCSEC,
            g,
        );
        let mut e = self.accel.sample(proof, a_i, cross, &mut self.rng_accel);
        // The barometer draws from its own stream: stepping it before the output changes none
        // of its values.
        let pressure = self.barometer.step(solar_h, &mut self.rng_barometer);
        let pressure_dev_pa = (pressure.truth_hpa - self.barometer.mean_hpa()) * 100.0;
        let effect = match &mut self.effects {
            Some(chain) => chain.output_term(&Drive {
                t_s: t,
                temperature_c: mount,
                input_g: a_i.0,
                tilt_rad: tilt * RAD_PER_ARCSEC,
                pressure_dev_pa,
                ambient: &[room_dev, board - self.room.mean_c()],
            }),
            None => 0.0,
        };
        let gravity = match &mut self.gravimeter {
            Some(gm) => {
                let p = &gm.p;
                gm.p.offset
                    + p.drift_per_day * t / 86_400.0
                    + p.tide_factor
                        * gm.tide.at(t - p.tide_delay_s).gravity_nm_s2
                        * gm.unit_per_nm_s2
                    + p.pressure_admittance_per_hpa * pressure_dev_pa / 100.0
                    + gm.noise.step(&mut gm.rng)
                    + effect
            }
            None => {
                e.output = Volts(e.output.0 + effect);
                f64::NAN
            }
        };

        let ads = &s.adc.ads1262;
        let adc_err = |error| SimError::Adc { time_s: t, error };
        let accel =
            adc::ads1262_convert(ads, ads.accel_pga_gain, e.output, board, &mut self.rng_adc)
                .map_err(adc_err)?;

        let reading = self.rtd.read(mount, &mut self.rng_rtd);
        let rtd = adc::ad7124_convert(&s.adc.ad7124, reading.resistance).map_err(adc_err)?;
        let temperature_c = rtd
            .ohms
            .and_then(|r| self.rtd.cvd().temperature(r).ok())
            .map_or(f64::NAN, |c| c.0);

        let tilt_read = tiltmeter_reading(&s.tiltmeter, tilt, &mut self.rng_tiltmeter);
        let k = s.tiltmeter.scale_arcsec_per_v;
        let tilt_conv = adc::ads1262_convert(
            ads,
            ads.tilt_pga_gain,
            Volts(tilt_read / k),
            board,
            &mut self.rng_adc,
        )
        .map_err(adc_err)?;

        let mut temperature_c = temperature_c;
        let mut tilt_arcsec = tilt_conv.volts.map_or(f64::NAN, |v| v.0 * k);
        let mut pressure_hpa = pressure.measured_hpa;
        if let Some(chain) = self.effects.as_ref().filter(|c| c.has_reading_noise()) {
            let (dt_c, dtilt_rad, dp_pa) = chain.reading_noise(&mut self.rng_effects);
            temperature_c += dt_c;
            tilt_arcsec += dtilt_rad / RAD_PER_ARCSEC;
            pressure_hpa += dp_pa / 100.0;
        }

        Ok(Sample {
            time_s: t,
            output_v: accel.volts.map_or(f64::NAN, |v| v.0),
            temperature_c,
            tilt_arcsec,
            pressure_hpa,
            gravity,
            accel_code: accel.code as i32,
            rtd_code: rtd.code,
            tilt_code: tilt_conv.code as i32,
            truth_input_g: a_i.0,
            truth_a_p_g: cross.a_p.0,
            truth_a_o_g: cross.a_o.0,
            truth_temperature_c: proof,
            truth_mount_temperature_c: mount,
            truth_room_c: room,
            truth_board_c: board,
            truth_tilt_arcsec: tilt,
            truth_tide_tilt_arcsec: tide.tilt_arcsec,
            truth_tide_gravity_nm_s2: tide.gravity_nm_s2,
            truth_noise_g: e.noise_g,
            truth_output_v: e.output.0,
            truth_head_angle_deg: head.to_degrees(),
            truth_pressure_hpa: pressure.truth_hpa,
            truth_rtd_ohms: reading.resistance.0,
        })
    }
}

fn round_to(v: f64, decimals: i32) -> f64 {
    let p = 10f64.powi(decimals);
    (v * p).round() / p
}

/// The log's columns: measured first, codes if asked, then the truth.
pub fn columns(opts: &Options) -> Vec<Column> {
    let c = |name, d| Column {
        name,
        decimals: Some(d),
    };
    let mut v = vec![
        c("time_s", 3),
        c("output_v", 10),
        c("temperature_c", 6),
        c("tilt_arcsec", 6),
        c("pressure_hpa", 3),
    ];
    if opts.codes {
        for name in ["accel_code", "rtd_code", "tilt_code"] {
            v.push(Column {
                name,
                decimals: None,
            });
        }
    }
    v.extend([
        c("truth_input_g", 12),
        c("truth_a_p_g", 12),
        c("truth_a_o_g", 12),
        c("truth_temperature_c", 6),
        c("truth_mount_temperature_c", 6),
        c("truth_room_c", 4),
        c("truth_board_c", 4),
        c("truth_tilt_arcsec", 6),
        c("truth_tide_tilt_arcsec", 6),
        c("truth_tide_gravity_nm_s2", 3),
        c("truth_noise_g", 12),
        c("truth_output_v", 12),
        c("truth_head_angle_deg", 8),
        c("truth_pressure_hpa", 4),
    ]);
    v
}

/// The log's columns for a scenario: a gravimeter writes `gravity_<unit>` where the
/// accelerometer writes `output_v`.
pub fn columns_for(scenario: &Scenario, opts: &Options) -> Vec<Column> {
    let mut v = columns(opts);
    if let Some(g) = scenario.gravimeter() {
        v[1] = Column {
            name: g.column(),
            decimals: Some(match g.unit.as_str() {
                "mgal" => 7,
                "ugal" => 4,
                "nm_s2" => 3,
                _ => 12,
            }),
        };
    }
    v
}

fn row(s: &Sample, opts: &Options, out: &mut Vec<f64>) {
    out.clear();
    out.extend([
        s.time_s,
        if s.gravity.is_nan() {
            s.output_v
        } else {
            s.gravity
        },
        s.temperature_c,
        s.tilt_arcsec,
        s.pressure_hpa,
    ]);
    if opts.codes {
        out.extend([
            f64::from(s.accel_code),
            f64::from(s.rtd_code),
            f64::from(s.tilt_code),
        ]);
    }
    out.extend([
        s.truth_input_g,
        s.truth_a_p_g,
        s.truth_a_o_g,
        s.truth_temperature_c,
        s.truth_mount_temperature_c,
        s.truth_room_c,
        s.truth_board_c,
        s.truth_tilt_arcsec,
        s.truth_tide_tilt_arcsec,
        s.truth_tide_gravity_nm_s2,
        s.truth_noise_g,
        s.truth_output_v,
        s.truth_head_angle_deg,
        s.truth_pressure_hpa,
    ]);
}

/// What a finished run reports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Summary {
    /// Rows written.
    pub rows: u64,
    /// The RTD's drawn offset, °C.
    pub rtd_offset_c: f64,
    /// K1 at the set point, V/g.
    pub scale_factor_v_per_g: f64,
}

/// Runs a scenario and writes its log to `out`. `progress(done, total)` is called every
/// 2^14 samples and at the end.
pub fn simulate<W: Write>(
    scenario: &Scenario,
    seed: u64,
    opts: &Options,
    out: W,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<(Summary, W), SimError> {
    let mut sim = Simulator::new(scenario, seed)?;
    let mut w = LogWriter::new(out, &sim.metadata(seed), columns_for(scenario, opts))?;
    let total = sim.samples();
    let mut values = Vec::with_capacity(24);
    for i in 0..total {
        let s = sim.step()?;
        row(&s, opts, &mut values);
        w.row(&values)?;
        if i % (1 << 14) == 0 {
            progress(i, total);
        }
    }
    progress(total, total);
    let summary = Summary {
        rows: total,
        rtd_offset_c: sim.rtd_offset_c(),
        scale_factor_v_per_g: sim.scale_factor_at_setpoint(),
    };
    Ok((summary, w.finish()?))
}

/// The log [`simulate`] writes for `scenario` with `seed` (no code columns), read back as any
/// reader of a log file reads it: what a round trip through the format gives.
pub fn simulate_log(scenario: &Scenario, seed: u64) -> Result<accomp_log::Log, SimError> {
    let bytes = simulate(
        scenario,
        seed,
        &Options::default(),
        Vec::new(),
        &mut |_, _| {},
    )?
    .1;
    Ok(accomp_log::Log::read(&bytes[..])?)
}

#[cfg(test)]
mod tests {
    use super::accelerometer::{paper_order2_models, HeadPosition};
    use super::scenario::Scenario;
    use super::*;
    use accomp::model::CrossAxis;
    use accomp::units::Celsius;
    use accomp_log::Log;

    fn run(s: &Scenario, seed: u64, codes: bool) -> Vec<u8> {
        simulate(s, seed, &Options { codes }, Vec::new(), &mut |_, _| {})
            .unwrap()
            .1
    }

    fn short_0g() -> Scenario {
        let mut s = Scenario::preset("paper-0g").unwrap();
        s.run.duration_s = 6.0 * 3600.0;
        s
    }

    fn std(v: &[f64]) -> f64 {
        let n = v.len() as f64;
        let m = v.iter().sum::<f64>() / n;
        (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / n).sqrt()
    }

    fn peak_to_peak(v: &[f64]) -> f64 {
        v.iter().cloned().fold(f64::MIN, f64::max) - v.iter().cloned().fold(f64::MAX, f64::min)
    }

    #[test]
    fn the_same_seed_gives_a_byte_identical_log_and_another_seed_a_different_one() {
        let s = short_0g();
        let a = run(&s, 42, true);
        assert_eq!(a, run(&s, 42, true));
        assert_ne!(a, run(&s, 43, true));
    }

    fn fnv1a(bytes: &[u8]) -> u64 {
        bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
            (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
        })
    }

    #[test]
    fn the_presets_write_the_bytes_they_wrote_before_effects_and_instruments_existed() {
        // FNV-1a of `accomp simulate <preset> --days 0.5 --seed 42 --codes`, written by the
        // simulator of main at 62a21c1 (before `[instrument]` and `[[effects]]`): the optional
        // tables must not move a single draw or digit of a scenario that does not use them.
        for (name, len, hash) in [
            ("paper-0g", 170_818, 0x44a2_0284_6d52_a42d_u64),
            ("paper-1g", 172_155, 0x05df_d03e_c46a_8367_u64),
        ] {
            let mut s = Scenario::preset(name).unwrap();
            s.run.duration_s = 0.5 * 86_400.0;
            let bytes = run(&s, 42, true);
            assert_eq!((bytes.len(), fnv1a(&bytes)), (len, hash), "{name}");
        }
    }

    #[test]
    fn a_zero_effect_changes_no_byte_and_a_real_one_changes_only_its_channel() {
        use super::effects::ScenarioEffect;
        let base = short_0g();
        let mut zero = short_0g();
        zero.effects = vec![ScenarioEffect::Step {
            time_s: 3600.0,
            size: 0.0,
            duration_s: 0.0,
        }];
        assert_eq!(run(&base, 7, false), run(&zero, 7, false));
        // Reading noise on the temperature: only temperature_c moves.
        let mut noisy = short_0g();
        noisy.effects = vec![ScenarioEffect::ChannelNoise {
            channel: "temperature_c".into(),
            noise: 0.01,
        }];
        let (a, b) = (
            Log::read(&run(&base, 7, false)[..]).unwrap(),
            Log::read(&run(&noisy, 7, false)[..]).unwrap(),
        );
        assert_eq!(a.column("output_v"), b.column("output_v"));
        assert_eq!(a.column("tilt_arcsec"), b.column("tilt_arcsec"));
        let d: Vec<f64> = a
            .column("temperature_c")
            .unwrap()
            .iter()
            .zip(b.column("temperature_c").unwrap())
            .map(|(x, y)| y - x)
            .collect();
        assert!((std(&d) - 0.01).abs() < 0.002, "{}", std(&d));
    }

    #[test]
    fn the_log_carries_the_metadata_and_the_measured_codes_read_back_to_the_measured_values() {
        let s = short_0g();
        let log = Log::read(&run(&s, 5, true)[..]).unwrap();
        for key in [
            "start_utc",
            "latitude_deg",
            "longitude_deg",
            "height_m",
            "input_g",
            "instrument",
            "scale_factor_v_per_g",
            "seed",
        ] {
            assert!(log.meta(key).is_some(), "{key}");
        }
        assert_eq!(log.meta("seed"), Some("5"));
        assert_eq!(log.len(), 360);
        // output_v is code × LSB (2.5 V / 2^31 at gain 1), printed to 1e-10 V.
        let lsb = 2.5 / 2_147_483_648.0;
        let out = log.column("output_v").unwrap();
        let code = log.column("accel_code").unwrap();
        for (v, c) in out.iter().zip(code) {
            assert!((v - c * lsb).abs() < 0.6e-10, "{v} vs {c}");
        }
    }

    #[test]
    fn the_rtd_offset_is_one_fixed_value_for_the_whole_run() {
        let mut s = Scenario::preset("paper-1g").unwrap();
        s.run.duration_s = 4.0 * 86_400.0;
        let mut sim = Simulator::new(&s, 9).unwrap();
        let offset = sim.rtd_offset_c();
        assert!(offset.abs() <= 0.1);
        let (mut first, mut second) = (Vec::new(), Vec::new());
        let n = sim.samples();
        for i in 0..n {
            let x = sim.step().unwrap();
            let err = x.temperature_c - x.truth_mount_temperature_c;
            if i < n / 2 { &mut first } else { &mut second }.push(err);
        }
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        // Self-heating (250 µA in 123 Ω at 0.05 °C/mW) adds 0.0004 °C; noise averages out.
        for half in [&first, &second] {
            assert!(
                (mean(half) - offset - 0.0004).abs() < 3e-4,
                "{}",
                mean(half)
            );
            assert!(std(half) < 2e-3);
        }
    }

    #[test]
    fn the_1g_preset_gives_the_papers_magnitudes_before_and_after_compensation() {
        let s = Scenario::preset("paper-1g").unwrap();
        let log = Log::read(&run(&s, 1, false)[..]).unwrap();
        let k1: f64 = log.meta_f64("scale_factor_v_per_g").unwrap().unwrap();
        let out = log.column("output_v").unwrap();
        let temp = log.column("temperature_c").unwrap();
        let raw: Vec<f64> = out.iter().map(|v| v / k1).collect();
        // Compensated with the paper's models at the RTD temperature (core exact compensation).
        let models = paper_order2_models(60.0);
        let comp: Vec<f64> = out
            .iter()
            .zip(temp)
            .map(|(&e, &t)| {
                models
                    .exact(Volts(e), Celsius(t), CrossAxis::default())
                    .unwrap()
                    .input
                    .0
            })
            .collect();
        let (before, after) = (std(&raw), std(&comp));
        // Paper: 1.43e-5 g → 6.6e-6 g over 41 days.
        assert!(
            (0.9e-5..2.2e-5).contains(&before),
            "uncompensated {before:e}"
        );
        assert!((3e-6..1.2e-5).contains(&after), "compensated {after:e}");
        assert!(after < 0.6 * before);
    }

    #[test]
    fn the_0g_preset_tilts_about_0_45_arcsec_a_day_worth_about_2_micro_g() {
        let s = Scenario::preset("paper-0g").unwrap();
        let log = Log::read(&run(&s, 1, false)[..]).unwrap();
        let tilt = log.column("truth_tilt_arcsec").unwrap();
        let a_i = log.column("truth_input_g").unwrap();
        let ptp = peak_to_peak(tilt);
        assert!((0.35..0.6).contains(&ptp), "tilt p-p {ptp}\"");
        // 1" = 4.85 µg at 0 g (paper): the input follows the tilt.
        let effect = peak_to_peak(a_i);
        assert!((1.7e-6..2.9e-6).contains(&effect), "a_i p-p {effect:e}");
        // Tilt compensation with the measured tilt (eq. 5) reduces the 0 g scatter.
        let k1: f64 = log.meta_f64("scale_factor_v_per_g").unwrap().unwrap();
        let out = log.column("output_v").unwrap();
        let meas = log.column("tilt_arcsec").unwrap();
        let comp: Vec<f64> = out
            .iter()
            .zip(meas)
            .map(|(&e, &t)| {
                accomp::compensation::tilt_compensated(
                    Volts(e),
                    k1,
                    accomp::units::TiltArcsec(t),
                    accomp::units::TiltArcsec(meas[0]),
                )
                .0 / k1
            })
            .collect();
        let raw: Vec<f64> = out.iter().map(|v| v / k1).collect();
        assert!(
            std(&comp) < std(&raw),
            "{:e} vs {:e}",
            std(&comp),
            std(&raw)
        );
    }

    #[test]
    fn the_barometer_draws_from_its_own_stream_and_changes_no_other_channel() {
        let a = short_0g();
        let mut b = short_0g();
        b.barometer.weather_std_hpa = 0.0;
        b.barometer.noise_hpa = 0.5;
        let (mut sa, mut sb) = (
            Simulator::new(&a, 8).unwrap(),
            Simulator::new(&b, 8).unwrap(),
        );
        let mut pressure_differs = false;
        for _ in 0..sa.samples() {
            let (x, y) = (sa.step().unwrap(), sb.step().unwrap());
            assert_eq!(
                (x.output_v, x.temperature_c, x.tilt_arcsec),
                (y.output_v, y.temperature_c, y.tilt_arcsec)
            );
            pressure_differs |= x.pressure_hpa != y.pressure_hpa;
        }
        assert!(pressure_differs);
        // 60 m above sea level in the standard atmosphere: 1006.07 hPa, ± the weather and tide.
        let log = Log::read(&run(&a, 8, false)[..]).unwrap();
        let p = log.column("pressure_hpa").unwrap();
        let mean = p.iter().sum::<f64>() / p.len() as f64;
        assert!((mean - 1006.07).abs() < 20.0, "{mean}");
        assert!(log.column("truth_pressure_hpa").is_some());
    }

    #[test]
    fn a_tumble_programme_moves_the_input_through_the_head_positions() {
        let mut s = short_0g();
        s.accelerometer.orientation.positions = [90.0, 180.0, 270.0, 0.0]
            .iter()
            .map(|&angle_deg| HeadPosition {
                angle_deg,
                dwell_s: 3600.0,
            })
            .collect();
        let mut sim = Simulator::new(&s, 3).unwrap();
        let mut seen = Vec::new();
        for _ in 0..sim.samples() {
            let x = sim.step().unwrap();
            if x.time_s % 3600.0 == 1800.0 {
                seen.push((x.truth_input_g * 1e4).round() / 1e4);
            }
        }
        assert_eq!(seen, vec![1.0, 0.0, -1.0, 0.0, 1.0, 0.0]);
    }
}
