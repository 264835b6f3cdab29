//! The platinum resistance thermometer on the thermostat's mounting block.
//!
//! R = CVD(T_mount + δ + P·θ) with δ the sensor's calibration error — fixed for the whole run,
//! drawn once from the seed, uniform within ±accuracy (the paper: 0.1 °C) — and P·θ the
//! self-heating of the excitation current I (P = I²R, θ in °C/mW). The 4-wire voltage I·R picks up
//! the ADC's input-referred noise v_n; being ratiometric, the measurement reads
//! R_meas = R + v_n/I, independent of I's own drift.

use accomp::rtd::CallendarVanDusen;
use accomp::units::{Celsius, RtdOhms};
use rand::Rng;
use serde::{Deserialize, Serialize};

use super::noise::{gauss, SimRng};

/// RTD parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RtdParams {
    /// R0 of the sensor, Ω (the conversion on the board assumes the same constants).
    pub r0_ohm: f64,
    /// Callendar–Van Dusen A, 1/°C.
    pub cvd_a: f64,
    /// Callendar–Van Dusen B, 1/°C².
    pub cvd_b: f64,
    /// Callendar–Van Dusen C, 1/°C⁴.
    pub cvd_c: f64,
    /// Accuracy: bound of the fixed unknown offset, °C.
    pub accuracy_c: f64,
    /// Excitation current, µA.
    pub excitation_ua: f64,
    /// Self-heating coefficient, °C per mW dissipated.
    pub self_heating_c_per_mw: f64,
    /// Input-referred voltage noise of the RTD channel per sample, µV rms.
    pub noise_uv_rms: f64,
}

/// One RTD reading before the ADC.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RtdReading {
    /// Resistance the ADC sees, Ω (noise included).
    pub resistance: RtdOhms,
}

/// The sensor with its drawn offset.
#[derive(Debug, Clone)]
pub struct Rtd {
    cvd: CallendarVanDusen,
    offset_c: f64,
    excitation_a: f64,
    self_heating_c_per_w: f64,
    noise_ohm: f64,
}

impl Rtd {
    /// Draws the sensor's offset from `rng`.
    pub fn new(p: &RtdParams, rng: &mut SimRng) -> Self {
        let offset_c = if p.accuracy_c > 0.0 {
            rng.random_range(-p.accuracy_c..=p.accuracy_c)
        } else {
            0.0
        };
        let excitation_a = p.excitation_ua * 1e-6;
        Rtd {
            cvd: CallendarVanDusen {
                r0: p.r0_ohm,
                a: p.cvd_a,
                b: p.cvd_b,
                c: p.cvd_c,
            },
            offset_c,
            excitation_a,
            self_heating_c_per_w: p.self_heating_c_per_mw * 1e3,
            noise_ohm: if excitation_a > 0.0 {
                p.noise_uv_rms * 1e-6 / excitation_a
            } else {
                0.0
            },
        }
    }

    /// The sensor's fixed offset, °C (a truth value: the analysis never sees it).
    pub fn offset_c(&self) -> f64 {
        self.offset_c
    }

    /// The constants the board uses to convert.
    pub fn cvd(&self) -> CallendarVanDusen {
        self.cvd
    }

    /// The reading for the block temperature `t_c`.
    pub fn read(&self, t_c: f64, rng: &mut SimRng) -> RtdReading {
        let r0 = self.cvd.resistance(Celsius(t_c + self.offset_c)).0;
        let heating = self.excitation_a * self.excitation_a * r0 * self.self_heating_c_per_w;
        let r = self
            .cvd
            .resistance(Celsius(t_c + self.offset_c + heating))
            .0;
        RtdReading {
            resistance: RtdOhms(r + self.noise_ohm * gauss(rng)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::noise::stream;
    use super::*;

    /// The presets' Pt100 without self-heating and reading noise.
    fn pt100() -> RtdParams {
        RtdParams {
            self_heating_c_per_mw: 0.0,
            noise_uv_rms: 0.0,
            ..super::super::scenario::pt100()
        }
    }

    #[test]
    fn the_offset_is_fixed_within_a_run_bounded_by_the_accuracy_and_differs_between_seeds() {
        let offsets: Vec<f64> = (0..20)
            .map(|s| Rtd::new(&pt100(), &mut stream(s, 4)).offset_c())
            .collect();
        assert!(offsets.iter().all(|o| o.abs() <= 0.1));
        assert!(offsets.windows(2).all(|w| w[0] != w[1]));
        let mut rng = stream(3, 4);
        let rtd = Rtd::new(&pt100(), &mut rng);
        for t in [20.0, 60.0, 65.0] {
            let back = rtd
                .cvd()
                .temperature(rtd.read(t, &mut rng).resistance)
                .unwrap()
                .0;
            assert!((back - t - rtd.offset_c()).abs() < 1e-9);
        }
    }

    #[test]
    fn self_heating_follows_i_squared_r() {
        // 1 mA in 123.24 Ω at 60 °C dissipates 0.12324 mW; at 0.5 °C/mW that is +0.0616 °C.
        let p = RtdParams {
            accuracy_c: 0.0,
            excitation_ua: 1000.0,
            self_heating_c_per_mw: 0.5,
            ..pt100()
        };
        let mut rng = stream(1, 4);
        let rtd = Rtd::new(&p, &mut rng);
        let back = rtd
            .cvd()
            .temperature(rtd.read(60.0, &mut rng).resistance)
            .unwrap()
            .0;
        assert!((back - 60.0 - 0.0616).abs() < 2e-4, "{back}");
    }
}
