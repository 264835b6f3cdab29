//! TEMPORARY stand-in for `sim::twin::Twin` until the simulator's twin lands (helper "simfx"):
//! a gravimeter twin of the model tide (elastic Earth, factor 1) plus the record's noise model.
//! Announced in the output whenever used. To be deleted.

use super::TwinModel;
use crate::discover::import::Dataset;
use crate::discover::noise::NoiseModel;
use crate::discover::Discovery;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

/// The stand-in twin.
#[derive(Debug, Clone)]
pub struct StandIn {
    t_s: Vec<f64>,
    seg: Vec<bool>,
    det: Vec<f64>,
    noise: Option<NoiseModel>,
    provenance: Vec<String>,
}

impl StandIn {
    /// From a record.
    pub fn new(ds: &Dataset, noise: Option<&NoiseModel>) -> Self {
        let mut provenance = vec!["twin: STAND-IN (the simulator's twin has not landed)".into()];
        let det = match (
            crate::discover::effects::tide_series(ds),
            ds.unit_per_g,
            ds.is_one_g(),
        ) {
            (Some((g, _, _)), Some(u), true) => {
                provenance.push("tide: model tide at the record's site and time, factor 1".into());
                let a = ds.input_g.unwrap_or(1.0);
                g.iter().map(|x| x * u * a).collect()
            }
            _ => {
                provenance.push("no tide (site, time or unit unknown)".into());
                vec![0.0; ds.len()]
            }
        };
        StandIn {
            t_s: ds.t_s.clone(),
            seg: ds.segment_start.clone(),
            det,
            noise: noise.cloned(),
            provenance,
        }
    }
}

impl TwinModel for StandIn {
    fn run(&self, seed: Option<u64>) -> Result<Vec<f64>, String> {
        let (Some(seed), Some(nm)) = (seed, &self.noise) else {
            return Ok(self.det.clone());
        };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut g = || -> f64 { StandardNormal.sample(&mut rng) };
        let mut ou: Vec<f64> = nm.flicker.iter().map(|&(_, v)| v.sqrt() * g()).collect();
        let mut rw = 0.0;
        let mut out = Vec::with_capacity(self.det.len());
        for i in 0..self.det.len() {
            let dt = if i == 0 || self.seg[i] {
                f64::INFINITY
            } else {
                self.t_s[i] - self.t_s[i - 1]
            };
            let mut f = 0.0;
            for (x, &(tc, v)) in ou.iter_mut().zip(&nm.flicker) {
                let a = (-dt / tc).exp();
                *x = a * *x + (v * (1.0 - a * a)).sqrt() * g();
                f += *x;
            }
            if dt.is_finite() {
                rw += (nm.rw_per_s * dt).sqrt() * g();
            }
            out.push(self.det[i] + nm.white_var.sqrt() * g() + f + rw);
        }
        Ok(out)
    }

    type Effect = (String, Vec<f64>);

    fn effects_from(&self, d: &Discovery) -> (Vec<(String, Self::Effect)>, super::Refused) {
        let v = super::cause::contributions(d)
            .into_iter()
            .map(|(n, c)| (n.clone(), (n, c)))
            .collect();
        (v, Vec::new())
    }

    fn extended(&self, effects: &[Self::Effect]) -> Self {
        let mut t = self.clone();
        for (_, c) in effects {
            for (x, v) in t.det.iter_mut().zip(c) {
                *x += v;
            }
        }
        t
    }

    fn provenance(&self) -> Vec<String> {
        self.provenance.clone()
    }

    fn scenario_toml(&self) -> Option<String> {
        None
    }

    fn is_simulator(&self) -> bool {
        false
    }
}
