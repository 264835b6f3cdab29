//! The ensemble: the twin run N times with the simulator's noise (seeds 1..=N, so a run is
//! reproducible), each member's own residual (member − deterministic part, offset and linear
//! drift removed like the measured residual's) reduced to its [`Views`] as soon as it is made,
//! on all cores (std threads), with a progress bar on stderr.

use super::spectra::{ChannelSpectra, RegularGrid, Views, Welch};
use super::SimulateError;
use crate::discover::import::Dataset;

/// What every residual of one comparison is measured against: the record's grid, the Welch
/// set-up, the measured channels' spectra and the trend that is removed.
pub struct Yardstick<'a> {
    /// The record.
    pub ds: &'a Dataset,
    /// Its regular grid.
    pub grid: RegularGrid,
    /// Welch set-up (None: too short for a spectrum).
    pub welch: Option<Welch>,
    /// Measured channels (name, spectra on the Welch segments).
    pub channels: Vec<(String, ChannelSpectra)>,
    /// Order of the drift polynomial removed from every residual (1: level and linear rate;
    /// see [`super::drift`]).
    pub drift_order: usize,
    /// The record's time on [−1, 1] (the polynomials' argument).
    unit_t: Vec<f64>,
    /// With [`Yardstick::with_fitted_out`]: the drift polynomial's columns and the columns of
    /// the fit the record went through (the accepted effects' linear columns, the tide groups),
    /// projected out of every residual by least squares.
    fitted_out: Option<crate::numerics::linalg::OrthonormalBasis>,
}

impl<'a> Yardstick<'a> {
    /// Set-up for a record.
    pub fn new(ds: &'a Dataset) -> Self {
        let grid = RegularGrid::new(ds);
        let probe = grid.place(&ds.y);
        let welch = Welch::new(&probe, grid.dt_s);
        let channels = match &welch {
            Some(w) => ds
                .channels
                .iter()
                .filter(|c| c.kind != crate::discover::import::ChannelKind::Input)
                .map(|c| (c.name.clone(), w.channel_spectra(&grid.place(&c.values))))
                .collect(),
            None => Vec::new(),
        };
        Yardstick {
            ds,
            grid,
            welch,
            channels,
            drift_order: 1,
            unit_t: super::drift::unit_time(&ds.t_s),
            fitted_out: None,
        }
    }

    /// The same yardstick removing a drift polynomial of `order` from every residual (and
    /// nothing else: columns fitted out before are dropped).
    pub fn with_drift_order(mut self, order: usize) -> Self {
        self.drift_order = order.max(1);
        self.fitted_out = None;
        self
    }

    /// The same yardstick removing, jointly with the drift polynomial, the least-squares fit of
    /// `columns` (each at the record's instants) from every residual: the record's residual had
    /// the accepted effects fitted out of it, which takes part of its noise with them (the
    /// noise's projection on their columns); a member's residual passes through the same fit,
    /// so the two are compared alike. Columns of another length are ignored.
    pub fn with_fitted_out(mut self, columns: &[Vec<f64>]) -> Self {
        let n = self.unit_t.len();
        let mut cols: Vec<Vec<f64>> = (0..=self.drift_order)
            .map(|k| {
                self.unit_t
                    .iter()
                    .map(|&x| super::drift::legendre(x, self.drift_order)[k])
                    .collect()
            })
            .collect();
        cols.extend(columns.iter().filter(|c| c.len() == n).cloned());
        self.fitted_out = Some(crate::numerics::linalg::OrthonormalBasis::new(&cols));
        self
    }

    /// Number of independent columns fitted out of every residual (the drift polynomial's
    /// included).
    pub fn fitted_out_columns(&self) -> usize {
        self.fitted_out
            .as_ref()
            .map_or(self.drift_order + 1, |b| b.q.len())
    }

    /// The record's time on [−1, 1].
    pub fn unit_time(&self) -> &[f64] {
        &self.unit_t
    }

    /// Offset, linear drift and the drift polynomial's higher terms up to
    /// [`Yardstick::drift_order`] (least squares, per record) removed: the level, the drift rate
    /// and the shape of a smooth drift are calibration constants of an instrument, not
    /// predictions of the simulation; the measured residual and every member's are treated
    /// alike.
    pub fn detrend(&self, r: &[f64]) -> Vec<f64> {
        if let Some(b) = &self.fitted_out {
            if r.len() == self.unit_t.len() {
                return b.residual(r);
            }
        }
        let n = r.len().min(self.unit_t.len());
        if n < self.drift_order + 1 {
            return r.to_vec();
        }
        super::drift::remove(&self.unit_t[..n], &r[..n], self.drift_order).1
    }

    /// The views of a residual (already detrended).
    pub fn views(&self, r: &[f64]) -> Views {
        let placed = self.grid.place(r);
        let adev = super::spectra::adev(&placed, self.grid.dt_s);
        let (psd, coherence) = match &self.welch {
            Some(w) => (
                w.psd(&placed),
                self.channels
                    .iter()
                    .map(|(_, s)| w.coherence_to(&placed, s))
                    .collect(),
            ),
            None => (Vec::new(), Vec::new()),
        };
        Views {
            adev,
            psd,
            coherence,
        }
    }
}

/// The members' views; `member(k)` is member k's output (k = 1..=n).
pub fn run<M>(
    member: M,
    det: &[f64],
    n: usize,
    yard: &Yardstick,
    label: &str,
) -> Result<Vec<Views>, SimulateError>
where
    M: Fn(u64) -> Result<Vec<f64>, SimulateError> + Sync,
{
    let bar = indicatif::ProgressBar::new(n as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} members ({elapsed})")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    bar.set_message(format!("twin ensemble ({label})"));
    let threads = std::thread::available_parallelism()
        .map(|p| p.get())
        .unwrap_or(1)
        .clamp(1, n.max(1));
    let next = std::sync::atomic::AtomicUsize::new(0);
    // The bar is drawn on a terminal only: elsewhere (a log file, CI) a line at most every
    // PROGRESS_EVERY says where a long run is.
    let log = crate::numerics::parallel::ProgressLines::new(
        format!("twin ensemble ({label})"),
        n,
        "members",
    );
    let mut out: Vec<Option<Result<Views, SimulateError>>> = (0..n).map(|_| None).collect();
    std::thread::scope(|s| {
        let handles: Vec<_> = (0..threads)
            .map(|_| {
                s.spawn(|| {
                    let mut mine = Vec::new();
                    loop {
                        let k = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        if k >= n {
                            break;
                        }
                        let v = member(k as u64 + 1).map(|m| {
                            let r: Vec<f64> = m.iter().zip(det).map(|(a, b)| a - b).collect();
                            yard.views(&yard.detrend(&r))
                        });
                        bar.inc(1);
                        log.inc();
                        mine.push((k, v));
                    }
                    mine
                })
            })
            .collect();
        for h in handles {
            if let Ok(v) = h.join() {
                for (k, r) in v {
                    out[k] = Some(r);
                }
            }
        }
    });
    bar.finish_and_clear();
    out.into_iter()
        .enumerate()
        .map(|(k, r)| r.unwrap_or(Err(SimulateError::MemberLost(k + 1))))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dot(a: &[f64], b: &[f64]) -> f64 {
        a.iter().zip(b).map(|(x, y)| x * y).sum()
    }

    /// A residual holding a fitted effect's column loses it, with the drift polynomial, and what
    /// is left is exactly what the same fit leaves of the noise alone: the record's residual and
    /// a member's (noise only) go through one fit.
    #[test]
    fn the_fitted_columns_leave_record_and_member_alike() {
        let mut s = crate::sim::scenario::Scenario::preset("paper-1g").unwrap();
        s.run.duration_s = 86_400.0;
        s.run.interval_s = 300.0;
        let ds = crate::twin::tests::dataset(&s, 1);
        let n = ds.len();
        let col: Vec<f64> = ds
            .t_s
            .iter()
            .map(|t| (2.0 * std::f64::consts::PI * t / 7200.0).sin())
            .collect();
        // Deterministic noise (a fixed pseudo-random sequence).
        let noise: Vec<f64> = (0..n)
            .map(|i| ((i * 7919 + 13) % 101) as f64 / 101.0 - 0.5)
            .collect();
        let u = super::super::drift::unit_time(&ds.t_s);
        let record: Vec<f64> = (0..n)
            .map(|i| noise[i] + 3.0 * col[i] + 0.5 - 0.2 * u[i] + 0.1 * u[i] * u[i])
            .collect();
        // The drift polynomial alone leaves the column in.
        let plain = Yardstick::new(&ds).with_drift_order(2);
        assert_eq!(plain.fitted_out_columns(), 3);
        let left = plain.detrend(&record);
        assert!(dot(&left, &col).abs() > 0.5 * dot(&col, &col));
        let fitted = Yardstick::new(&ds)
            .with_drift_order(2)
            .with_fitted_out(&[col.clone(), vec![1.0; n + 1]]);
        // The polynomial's three columns and the effect's; the column of another length is
        // ignored.
        assert_eq!(fitted.fitted_out_columns(), 4);
        let rec = fitted.detrend(&record);
        let member = fitted.detrend(&noise);
        let scale = dot(&noise, &noise).sqrt();
        assert!(dot(&rec, &col).abs() < 1e-9 * scale);
        assert!(rec
            .iter()
            .zip(&member)
            .all(|(a, b)| (a - b).abs() < 1e-9 * scale));
        // The noise's own projection on the column is what the fit takes from the member.
        let taken: f64 = noise.iter().zip(&member).map(|(a, b)| (a - b).abs()).sum();
        assert!(taken > 0.0);
    }
}
