//! The accelerometer under test on the dividing head: its orientation in the gravity field, the
//! static model (the paper's eq. (1)) with temperature-dependent coefficients, and its noise.
//!
//! ```text
//! E = K1(T)·(K0(T) + n(t) + a_i + K2(T)·a_i² + δo(T)·a_p − δp(T)·a_o)
//! ```
//! T is the proof-mass temperature; n(t) is white + flicker + random-walk noise referred to the
//! input (g) with the given Allan parameters. The coefficients follow the *true* temperature
//! models of the simulated instrument, evaluated without clamping (physics has no calibrated
//! range; the compensation does).
//!
//! Orientation: the dividing head turns about a horizontal spindle. The head angle θ is measured
//! from the horizontal to the input axis, so θ = 90° is the "1 g" position (input axis up) and
//! θ = 0° the "0 g" position. A foundation tilt φ about the spindle adds to θ, so that a positive
//! tilt turns the input axis towards +g, the convention of eq. (5). With the spindle along the
//! output axis the pendulum axis turns with the input axis, and the other way round:
//!
//! ```text
//! a_i = g·sin(θ + φ)       a_p or a_o = s·g·cos(θ + φ)       (s = ±1: which way it points)
//! ```

use std::path::PathBuf;

use accomp::compensation::ThermalCompensator;
use accomp::model::{CrossAxis, StaticCoefficients};
use accomp::table::CalibrationTable;
use accomp::units::{Celsius, Gs, Radians, Volts, RAD_PER_ARCSEC};
use serde::{Deserialize, Serialize};

use super::noise::{gauss, AllanNoise, AllanParams, SimRng};

/// Where the true coefficient models of the simulated instrument come from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "source", rename_all = "kebab-case", deny_unknown_fields)]
pub enum CalibrationSource {
    /// The paper's printed order-2 models of JN-06 A12124 (Tables 2–5, raw °C), normalized over
    /// the calibrated 30–65 °C; δo = 0 (the paper does not give it).
    PaperPrintedOrder2,
    /// A calibration table file as written by `accomp fit -o` (the binary table format).
    TableFile {
        /// Path of the table file.
        path: PathBuf,
    },
}

/// Which instrument axis lies along the dividing head's spindle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SpindleAxis {
    /// Output axis along the spindle: the pendulum axis turns with the input axis (a_o = 0).
    Output,
    /// Pendulum axis along the spindle: the output axis turns with the input axis (a_p = 0).
    Pendulum,
}

/// One position of the dividing head and how long it is held.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HeadPosition {
    /// Head angle θ, degrees from the horizontal to the input axis.
    pub angle_deg: f64,
    /// Dwell at this position, seconds (ignored when there is only one position).
    pub dwell_s: f64,
}

/// Mounting and dividing-head programme.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OrientationParams {
    /// Instrument axis along the spindle.
    pub spindle_axis: SpindleAxis,
    /// +1 or −1: sign of the cross axis that turns with the input axis (s in the module doc).
    pub cross_sign: f64,
    /// Head positions, visited in order and repeated (one position: a static test).
    pub positions: Vec<HeadPosition>,
    /// Indexing error of the head, standard deviation in arcsec, drawn anew at each move.
    pub indexing_std_arcsec: f64,
}

/// The instrument.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AccelerometerParams {
    /// Instrument name written into the log metadata.
    pub instrument: String,
    /// True coefficient models.
    pub calibration: CalibrationSource,
    /// Noise referred to the input, g.
    pub noise_g: AllanParams,
    /// Orientation on the dividing head.
    pub orientation: OrientationParams,
}

/// Why the accelerometer cannot be built.
#[derive(Debug, thiserror::Error)]
pub enum AccelError {
    /// The table file could not be read.
    #[error("cannot read calibration table {path}: {source}")]
    Read {
        /// Path.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// The table file is not a valid table.
    #[error("calibration table {path} refused: {reason:?}")]
    Table {
        /// Path.
        path: PathBuf,
        /// Reason.
        reason: accomp::table::TableError,
    },
    /// The orientation programme is unusable.
    #[error("orientation: {0}")]
    Orientation(&'static str),
}

/// The paper's printed order-2 models of JN-06 A12124 (Tables 2–5), T0 = `reference_c`.
pub fn paper_order2_models(reference_c: f64) -> ThermalCompensator {
    accomp::reference::paper_order2_models(Celsius(reference_c))
}

impl CalibrationSource {
    /// The true coefficient models, with T0 = `reference_c` for the printed models (a table
    /// file carries its own T0).
    pub fn load(&self, reference_c: f64) -> Result<ThermalCompensator, AccelError> {
        match self {
            CalibrationSource::PaperPrintedOrder2 => Ok(paper_order2_models(reference_c)),
            CalibrationSource::TableFile { path } => {
                let bytes = std::fs::read(path).map_err(|source| AccelError::Read {
                    path: path.clone(),
                    source,
                })?;
                let table =
                    CalibrationTable::decode(&bytes).map_err(|reason| AccelError::Table {
                        path: path.clone(),
                        reason,
                    })?;
                Ok(table.thermal)
            }
        }
    }
}

/// The five coefficients of `models` at T, *without* clamping to the calibrated range.
pub fn true_coefficients(models: &ThermalCompensator, t: f64) -> StaticCoefficients {
    let x = models.scale.x_unclamped(Celsius(t));
    let m = &models.models;
    StaticCoefficients {
        bias_g: m.bias_g.eval(x),
        scale_factor_v_per_g: m.scale_factor_v_per_g.eval(x),
        nonlinearity_g_per_g2: m.nonlinearity_g_per_g2.eval(x),
        misalignment_p: Radians(m.misalignment_p_rad.eval(x)),
        misalignment_o: Radians(m.misalignment_o_rad.eval(x)),
    }
}

/// Accelerations along the instrument axes for a total angle θ + φ (rad) and gravity g (in g).
pub fn axes(spindle: SpindleAxis, cross_sign: f64, angle_rad: f64, g: f64) -> (Gs, CrossAxis) {
    let (s, c) = angle_rad.sin_cos();
    let cross = cross_sign * g * c;
    let axis = match spindle {
        SpindleAxis::Output => CrossAxis {
            a_p: Gs(cross),
            a_o: Gs(0.0),
        },
        SpindleAxis::Pendulum => CrossAxis {
            a_p: Gs(0.0),
            a_o: Gs(cross),
        },
    };
    (Gs(g * s), axis)
}

/// The dividing head: which position is active at a time, with its indexing error.
#[derive(Debug, Clone)]
pub struct DividingHead {
    p: OrientationParams,
    cycle_s: f64,
    current: Option<usize>,
    error_rad: f64,
}

impl DividingHead {
    /// A head running the programme `p`.
    pub fn new(p: &OrientationParams) -> Result<Self, AccelError> {
        if p.positions.is_empty() {
            return Err(AccelError::Orientation("no head position"));
        }
        if p.cross_sign.abs() != 1.0 {
            return Err(AccelError::Orientation("cross_sign must be +1 or −1"));
        }
        let cycle_s: f64 = p.positions.iter().map(|q| q.dwell_s).sum();
        if p.positions.len() > 1 && !(cycle_s > 0.0 && p.positions.iter().all(|q| q.dwell_s > 0.0))
        {
            return Err(AccelError::Orientation("every dwell must be > 0 s"));
        }
        Ok(DividingHead {
            p: p.clone(),
            cycle_s,
            current: None,
            error_rad: 0.0,
        })
    }

    fn index_at(&self, t_s: f64) -> usize {
        if self.p.positions.len() == 1 {
            return 0;
        }
        let mut r = t_s.rem_euclid(self.cycle_s);
        for (i, q) in self.p.positions.iter().enumerate() {
            if r < q.dwell_s {
                return i;
            }
            r -= q.dwell_s;
        }
        self.p.positions.len() - 1
    }

    /// The commanded head angle plus indexing error (rad) at `t_s`; a new error is drawn when
    /// the head moves to another position.
    pub fn angle_rad(&mut self, t_s: f64, rng: &mut SimRng) -> f64 {
        let i = self.index_at(t_s);
        if self.current != Some(i) {
            self.current = Some(i);
            self.error_rad = self.p.indexing_std_arcsec * RAD_PER_ARCSEC * gauss(rng);
        }
        self.p
            .positions
            .get(i)
            .map_or(0.0, |q| q.angle_deg.to_radians())
            + self.error_rad
    }

    /// The nominal input a_i (g) of the first position, for the log metadata.
    pub fn nominal_input_g(&self) -> f64 {
        self.p
            .positions
            .first()
            .map_or(0.0, |q| q.angle_deg.to_radians().sin())
    }
}

/// The instrument: true models and noise.
#[derive(Debug, Clone)]
pub struct Accelerometer {
    models: ThermalCompensator,
    noise: AllanNoise,
}

/// One output sample of the instrument.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AccelSample {
    /// E, the output across the sense resistor, before the ADC.
    pub output: Volts,
    /// The noise n(t) that went into it, g.
    pub noise_g: f64,
}

impl Accelerometer {
    /// An instrument with true models `models` and noise `noise`.
    pub fn new(models: ThermalCompensator, noise: AllanNoise) -> Self {
        Accelerometer { models, noise }
    }

    /// The true models.
    pub fn models(&self) -> &ThermalCompensator {
        &self.models
    }

    /// Eq. (1) at proof-mass temperature `t_c`, with the next noise sample added to the input.
    pub fn sample(&mut self, t_c: f64, a_i: Gs, cross: CrossAxis, rng: &mut SimRng) -> AccelSample {
        let k = true_coefficients(&self.models, t_c);
        let n = self.noise.step(rng);
        // The noise enters like a bias change: it is referred to the input.
        let k = StaticCoefficients {
            bias_g: k.bias_g + n,
            ..k
        };
        AccelSample {
            output: k.output(a_i, cross),
            noise_g: n,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::noise::stream;
    use super::*;

    #[test]
    fn printed_models_reproduce_table_1_to_the_precision_of_their_printed_digits() {
        // Table 1 of the paper at 30, 50 and 65 °C (K0 g, K1 V/g, δp arcmin). The printed
        // 3-digit coefficients leave up to 1.1e-5 g in K0 at 30 °C (hand-evaluated).
        let m = paper_order2_models(60.0);
        for (t, k0, k1, dp) in [
            (30.0, 0.0046556, 1.3260063, 2.62),
            (50.0, 0.0056442, 1.3267168, 2.01),
            (65.0, 0.0065180, 1.3270820, 1.82),
        ] {
            let k = true_coefficients(&m, t);
            assert!((k.bias_g - k0).abs() < 1.2e-5, "K0({t}) = {}", k.bias_g);
            assert!((k.scale_factor_v_per_g - k1).abs() < 4e-6, "K1({t})");
            assert!(
                (k.misalignment_p.to_arcmin().0 - dp).abs() < 0.007,
                "δp({t})"
            );
        }
    }

    #[test]
    fn true_coefficients_extrapolate_instead_of_clamping() {
        let m = paper_order2_models(60.0);
        let k25 = true_coefficients(&m, 25.0);
        // Printed bias polynomial at 25 °C, evaluated by hand.
        let hand = 0.003554 + 2.97e-5 * 25.0 + 2.46e-7 * 625.0;
        assert!((k25.bias_g - hand).abs() < 1e-15);
    }

    #[test]
    fn head_at_90_degrees_gives_one_g_and_a_positive_tilt_raises_the_zero_g_input() {
        let (a, c) = axes(SpindleAxis::Output, 1.0, 90f64.to_radians(), 1.0);
        assert!((a.0 - 1.0).abs() < 1e-15 && c.a_p.0.abs() < 1e-15);
        let tilt = 1.0 * RAD_PER_ARCSEC;
        let (a, c) = axes(SpindleAxis::Pendulum, -1.0, tilt, 1.0);
        assert!((a.0 - 4.848e-6).abs() < 1e-9);
        assert!((c.a_o.0 + 1.0).abs() < 1e-10 && c.a_p.0 == 0.0);
    }

    #[test]
    fn a_four_point_tumble_visits_each_position_for_its_dwell() {
        let p = OrientationParams {
            spindle_axis: SpindleAxis::Output,
            cross_sign: 1.0,
            positions: [0.0, 90.0, 180.0, 270.0]
                .iter()
                .map(|&a| HeadPosition {
                    angle_deg: a,
                    dwell_s: 600.0,
                })
                .collect(),
            indexing_std_arcsec: 0.0,
        };
        let mut head = DividingHead::new(&p).unwrap();
        let mut rng = stream(1, 1);
        for (t, expect) in [
            (0.0, 0.0),
            (599.0, 0.0),
            (600.0, 90.0),
            (1500.0, 180.0),
            (1900.0, 270.0),
            (2399.0, 270.0),
            (2400.0, 0.0),
        ] {
            let got = head.angle_rad(t, &mut rng).to_degrees();
            assert!((got - expect).abs() < 1e-9, "t={t}: {got}");
        }
    }

    #[test]
    fn indexing_error_is_redrawn_only_when_the_head_moves() {
        let p = OrientationParams {
            spindle_axis: SpindleAxis::Output,
            cross_sign: 1.0,
            positions: vec![
                HeadPosition {
                    angle_deg: 0.0,
                    dwell_s: 100.0,
                },
                HeadPosition {
                    angle_deg: 180.0,
                    dwell_s: 100.0,
                },
            ],
            indexing_std_arcsec: 0.2,
        };
        let mut head = DividingHead::new(&p).unwrap();
        let mut rng = stream(9, 1);
        let a0 = head.angle_rad(0.0, &mut rng);
        assert_eq!(a0, head.angle_rad(50.0, &mut rng));
        let a1 = head.angle_rad(100.0, &mut rng) - std::f64::consts::PI;
        let a2 = head.angle_rad(200.0, &mut rng);
        assert!(a0 != 0.0 && a1 != 0.0 && a2 != a0);
        assert!(a0.abs() < 1.0 * RAD_PER_ARCSEC);
    }

    #[test]
    fn a_table_file_written_by_fit_is_loaded_as_the_true_models() {
        use accomp::table::*;

        let thermal = paper_order2_models(55.0);
        let table = CalibrationTable::with_board_defaults(
            "SIM-TEST",
            CalibrationDate {
                year: 2026,
                month: 1,
                day: 2,
            },
            thermal,
        );
        let dir = crate::scratch::Scratch::new("sim-table");
        let path = dir.join("table.bin");
        std::fs::write(&path, table.encode()).unwrap();
        let toml_text = format!(
            "source = \"table-file\"\npath = {:?}\n",
            path.display().to_string()
        );
        let source: CalibrationSource = toml::from_str(&toml_text).unwrap();
        let loaded = source.load(60.0).unwrap();
        // The table's own T0 (55 °C) is kept, not the scenario's set point.
        assert_eq!(loaded, thermal);
        let bad = CalibrationSource::TableFile {
            path: "/nonexistent/table.bin".into(),
        };
        assert!(matches!(bad.load(60.0), Err(AccelError::Read { .. })));
    }
}
