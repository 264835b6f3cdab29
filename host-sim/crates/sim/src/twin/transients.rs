//! Transient disturbances: short excursions far outside the Gaussian noise (a spring
//! gravimeter records a teleseismic earthquake or a knock as a spike of a few samples). They
//! make the noise non-stationary — the stretch of the record holding them is noisier — and a
//! Gaussian family fitted with them in spreads their power over every frequency.
//!
//! Found on the residual laid on its grid: first differences beyond [`THRESHOLD_SIGMAS`] robust
//! σ (1.4826 × the median absolute difference); flagged differences closer than
//! [`JOIN_CELLS`] form one event, its extent one cell wider on each side; its shape is the
//! residual there minus the straight line between the neighbouring cells. The noise family is
//! fitted to the residual with the events replaced by that line. Members draw a Poisson number
//! of events with the record's count as mean, each a shape of the record's (drawn with
//! replacement) at a uniformly drawn cell: the record's own disturbances, at its rate.
//!
//! The events live here, in the simulator, so that a written twin's `[twin.transients]` (one
//! `[[twin.transients.events]]` per event: first cell and shape) is drawn by `accomp simulate`
//! with the same code as the ensemble of `accomp discover --simulate`.

use rand::Rng;
use serde::{Deserialize, Serialize};

use super::InvalidTwin;
use crate::noise::{gauss, SimRng};

/// A first difference beyond this many robust σ starts an event (Gaussian noise: never in 10¹⁹
/// differences).
pub const THRESHOLD_SIGMAS: f64 = 10.0;
/// Flagged differences closer than this many cells are one event.
pub const JOIN_CELLS: usize = 4;

/// The record's transient events on its grid.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(from = "TransientsFile", into = "TransientsFile")]
pub struct Transients {
    /// Each event: first cell and its shape (excursion from the local line), output unit.
    pub events: Vec<(usize, Vec<f64>)>,
    /// Robust σ of the first differences, output unit.
    pub sigma_diff: f64,
    /// Cells of the grid.
    pub cells: usize,
    /// Grid spacing, s.
    pub dt_s: f64,
}

/// One event as a written twin holds it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct EventFile {
    /// First grid cell.
    cell: usize,
    /// Excursion from the local line at that cell and the following ones, output unit.
    shape: Vec<f64>,
}

/// [`Transients`] as a written twin holds it (named fields instead of tuples).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct TransientsFile {
    sigma_diff: f64,
    cells: usize,
    dt_s: f64,
    events: Vec<EventFile>,
}

impl From<TransientsFile> for Transients {
    fn from(f: TransientsFile) -> Self {
        Transients {
            events: f.events.into_iter().map(|e| (e.cell, e.shape)).collect(),
            sigma_diff: f.sigma_diff,
            cells: f.cells,
            dt_s: f.dt_s,
        }
    }
}

impl From<Transients> for TransientsFile {
    fn from(t: Transients) -> Self {
        TransientsFile {
            sigma_diff: t.sigma_diff,
            cells: t.cells,
            dt_s: t.dt_s,
            events: t
                .events
                .into_iter()
                .map(|(cell, shape)| EventFile { cell, shape })
                .collect(),
        }
    }
}

impl Transients {
    /// Checks a written twin's events: shapes of finite numbers, first cells on the grid of
    /// `grid_cells` cells.
    pub fn validate(&self, grid_cells: usize) -> Result<(), InvalidTwin> {
        for (event, (cell, shape)) in self.events.iter().enumerate() {
            if *cell >= grid_cells {
                return Err(InvalidTwin::TransientCell {
                    event,
                    cell: *cell,
                    grid_cells,
                });
            }
            if shape.is_empty() || shape.iter().any(|v| !v.is_finite()) {
                return Err(InvalidTwin::TransientShape { event });
            }
        }
        Ok(())
    }

    /// Finds the events of a placed residual (NaN = gap).
    pub fn find(placed: &[f64], dt_s: f64) -> Transients {
        let d: Vec<(usize, f64)> = placed
            .windows(2)
            .enumerate()
            .filter(|(_, w)| w[0].is_finite() && w[1].is_finite())
            .map(|(i, w)| (i, w[1] - w[0]))
            .collect();
        let mut abs: Vec<f64> = d.iter().map(|x| x.1.abs()).collect();
        abs.sort_by(f64::total_cmp);
        let sigma_diff = 1.4826 * abs.get(abs.len() / 2).copied().unwrap_or(0.0);
        let mut none = Transients {
            events: Vec::new(),
            sigma_diff,
            cells: placed.len(),
            dt_s,
        };
        if sigma_diff.is_nan() || sigma_diff <= 0.0 {
            return none;
        }
        let flagged: Vec<usize> = d
            .iter()
            .filter(|x| x.1.abs() > THRESHOLD_SIGMAS * sigma_diff)
            .map(|x| x.0)
            .collect();
        // Runs of flagged differences → cell ranges [a, b] (difference i joins cells i, i + 1).
        let mut ranges: Vec<(usize, usize)> = Vec::new();
        for &i in &flagged {
            match ranges.last_mut() {
                Some(r) if i <= r.1 + JOIN_CELLS => r.1 = i + 1,
                _ => ranges.push((i, i + 1)),
            }
        }
        for (a, b) in ranges {
            // One cell wider each side; the line runs between the cells just outside.
            let (a, b) = (a.saturating_sub(1), (b + 1).min(placed.len() - 1));
            let (Some(l), Some(r)) = (a.checked_sub(1), Some(b + 1).filter(|&r| r < placed.len()))
            else {
                continue;
            };
            if !(placed[l].is_finite() && placed[r].is_finite()) {
                continue;
            }
            let shape: Vec<f64> = (a..=b)
                .map(|c| {
                    let line =
                        placed[l] + (placed[r] - placed[l]) * (c - l) as f64 / (r - l) as f64;
                    if placed[c].is_finite() {
                        placed[c] - line
                    } else {
                        0.0
                    }
                })
                .collect();
            none.events.push((a, shape));
        }
        none
    }

    /// The placed residual with every event replaced by its line.
    pub fn removed(&self, placed: &[f64]) -> Vec<f64> {
        let mut x = placed.to_vec();
        for (a, shape) in &self.events {
            for (k, s) in shape.iter().enumerate() {
                if let Some(v) = x.get_mut(a + k) {
                    *v -= s;
                }
            }
        }
        x
    }

    /// Record values `x` (point i in grid cell `cells[i]`) with the events taken out.
    pub fn removed_points(&self, cells: &[usize], x: &[f64]) -> Vec<f64> {
        let mut shape_at = vec![0.0; self.cells];
        for (a, shape) in &self.events {
            for (k, s) in shape.iter().enumerate() {
                if let Some(v) = shape_at.get_mut(a + k) {
                    *v = *s;
                }
            }
        }
        x.iter()
            .zip(cells)
            .map(|(v, &c)| v - shape_at.get(c).copied().unwrap_or(0.0))
            .collect()
    }

    /// Events per day.
    pub fn rate_per_day(&self) -> f64 {
        let days = self.cells as f64 * self.dt_s / 86_400.0;
        if days > 0.0 {
            self.events.len() as f64 / days
        } else {
            0.0
        }
    }

    /// Largest excursion of each event, output unit.
    pub fn peaks(&self) -> Vec<f64> {
        self.events
            .iter()
            .map(|(_, s)| {
                s.iter()
                    .fold(0.0f64, |m, v| if v.abs() > m.abs() { *v } else { m })
            })
            .collect()
    }

    /// Adds one member's draw to a grid series `x`: a Poisson number of events (mean: the
    /// record's count), each a record shape at a uniformly drawn cell.
    pub fn add_drawn(&self, x: &mut [f64], rng: &mut SimRng) {
        if self.events.is_empty() || x.is_empty() {
            return;
        }
        let n = poisson(self.events.len() as f64, rng);
        for _ in 0..n {
            let (_, shape) = &self.events[rng.random_range(0..self.events.len())];
            let at = rng.random_range(0..x.len());
            for (k, s) in shape.iter().enumerate() {
                if let Some(v) = x.get_mut(at + k) {
                    *v += s;
                }
            }
        }
    }
}

/// A Poisson draw with mean `mean` (Knuth's product for small means, the normal approximation
/// above 30).
fn poisson(mean: f64, rng: &mut SimRng) -> usize {
    if mean > 30.0 {
        return (mean + mean.sqrt() * gauss(rng)).round().max(0.0) as usize;
    }
    let limit = (-mean).exp();
    let mut p = 1.0;
    let mut k = 0;
    loop {
        p *= rng.random::<f64>();
        if p <= limit {
            return k;
        }
        k += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::noise::stream;

    #[test]
    fn a_spike_in_gaussian_noise_is_found_removed_and_redrawn_at_its_rate() {
        let mut rng = stream(7, 0);
        let mut x: Vec<f64> = (0..20_000).map(|_| gauss(&mut rng)).collect();
        let clean = Transients::find(&x, 60.0);
        assert!(clean.events.is_empty(), "{:?}", clean.peaks());
        x[5000] += 40.0;
        x[5001] += 25.0;
        let t = Transients::find(&x, 60.0);
        assert_eq!(t.events.len(), 1);
        let r = t.removed(&x);
        assert!(
            r[5000].abs() < 5.0 && r[5001].abs() < 5.0,
            "{} {}",
            r[5000],
            r[5001]
        );
        assert!((t.peaks()[0] - 40.0).abs() < 5.0, "{:?}", t.peaks());
        // Members draw one event on average.
        let mut total = 0;
        for k in 0..200 {
            let mut y = vec![0.0; 20_000];
            t.add_drawn(&mut y, &mut stream(k, 1));
            total += y.iter().filter(|v| v.abs() > 20.0).count();
        }
        assert!((300..=500).contains(&total), "{total}");
    }
}
