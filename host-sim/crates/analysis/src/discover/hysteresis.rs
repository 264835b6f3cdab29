//! Thermal hysteresis as a play (backlash) operator on the measured temperature.
//!
//! Physics: stress in the flexure, its epoxy joints and the coil former relaxes by stick–slip, so
//! the bias on a heating branch differs from the bias on a cooling branch at the same
//! temperature. The standard phenomenological description of rate-independent hysteresis is the
//! Preisach / Prandtl–Ishlinskii model: a non-negative superposition of play operators
//!
//! ```text
//! bias(t) = Σ_r w_r · p_r[T](t),   p_r[T](t) = min(T + r, max(T − r, p_r(t⁻)))   (w_r ≥ 0)
//! ```
//!
//! A play of half-width r follows T at distance r once T has moved 2r since its last reversal
//! and stands still in between. Written as T − p_r = r·h_r with h_r ∈ [−1, 1], the model is
//! (Σ w_r)·T − Σ w_r·r·h_r: the first part is a linear temperature coefficient (the baseline's
//! polynomial absorbs it), the second the branch term. One play gives the column h_r: +1 on a
//! heating branch, −1 on a cooling one, a linear change over the 2r of temperature after each
//! reversal; its coefficient is the **branch half-width** (heating bias − cooling bias = 2 × it).
//!
//! Why it is identifiable where the former sign-of-rate column was not: the play ignores any
//! temperature excursion smaller than 2r. Controller jitter and the RTD's reading noise (mK)
//! reverse the *rate* every few samples, so a sign(dT/dt) column turns them into a telegraph
//! signal that is not in the data; the play stays on its branch through them, so the measured
//! temperature's reading noise is not propagated (no errors-in-variables bias, as long as r is
//! above the reading noise — the grid starts there). Against `thermal_lag` (L_τ[T] − T ≈ −τ dT/dt)
//! it differs by its amplitude: the lag error scales with the rate, the branch term does not
//! (slow and fast cycles give the same offset) and it saturates after 2r.
//!
//! Fitting: a Preisach distribution. Each play of a 24-point log grid of widths (between 3 ×
//! the reading noise and a quarter of the temperature range) is whitened and projected off the
//! current model; the non-negative weights that best explain the whitened residual are found by
//! NNLS ([`nnls`], Lawson–Hanson; both signs tried) and normalised to sum 1 ([`Preisach`]), so
//! the column saturates at ±1 and its one linear coefficient is the branch half-width. The
//! effect's nonlinear parameter θ is the distribution's weighted geometric-mean width; the
//! selection charges the width search like a grid and each further width with a weight as one
//! more parameter. A spread of widths — what a real loop with smooth turns is — is then
//! representable, where one play was not (and lost to a thermal lag).
//!
//! Lag or loop: on a triangle of ONE rate a first-order lag is itself a Prandtl–Ishlinskii
//! operator (after a reversal L_τ[T] − T relaxes as exp(−ΔT/(Ṫτ)) in the temperature moved,
//! i.e. an exponential density of widths), so no fit can tell them apart there. What does is the
//! rate: the lag's offset scales with Ṫ, the loop's does not — records whose ramps differ (a
//! thermostat programme, excursions) separate them, and the selection's likelihood uses that
//! without being told.

use crate::sim::catalogue::Play;

/// The catalogue's play (backlash) operator of half-width `r` ([`Play`]) run over `u`, started
/// at `u[0]` (the virgin state: no branch yet). The state is carried across gaps: hysteresis is
/// a memory of the material, not of the recorder.
pub fn play(u: &[f64], r: f64) -> Vec<f64> {
    let mut p = Play::default();
    u.iter().map(|&x| p.step(x, r)).collect()
}

/// The branch column (T − p_r[T])/r ∈ [−1, 1]: +1 on a heating branch, −1 on a cooling branch.
pub fn branch(temp_c: &[f64], r_c: f64) -> Vec<f64> {
    if r_c.is_nan() || r_c <= 0.0 || r_c.is_infinite() {
        return vec![0.0; temp_c.len()];
    }
    play(temp_c, r_c)
        .iter()
        .zip(temp_c)
        .map(|(p, t)| (t - p) / r_c)
        .collect()
}

/// Reading-noise level of a temperature channel, °C: the median absolute *second* difference
/// divided by 0.6745·√6 (robust, and blind to a constant rate: a cycling programme's ramp
/// moves the reading by 10–20 mK between 2-min samples, which the first difference took for
/// noise — it put the play grid's lower end at 0.05 °C, above the narrow plays of a real loop;
/// only the turnovers, a few minutes per half-cycle, reach the second difference).
pub fn reading_noise_c(temp_c: &[f64]) -> f64 {
    let mut d: Vec<f64> = temp_c
        .windows(3)
        .map(|w| (w[2] - 2.0 * w[1] + w[0]).abs())
        .collect();
    if d.is_empty() {
        return 0.0;
    }
    let mid = d.len() / 2;
    let (_, m, _) = d.select_nth_unstable_by(mid, f64::total_cmp);
    *m / (0.6745 * 6f64.sqrt())
}

/// Search range of the play half-width, °C: from 3 × the reading noise (a play narrower than
/// that chatters on noise) to a quarter of the 1–99 % temperature range (a wider play hardly
/// ever leaves its dead band). `None` when the temperature never moves by more than its noise.
pub fn width_range_c(temp_c: &[f64]) -> Option<(f64, f64)> {
    let (q01, q99) = range_1_99_c(temp_c)?;
    let range = q99 - q01;
    let lo = (3.0 * reading_noise_c(temp_c)).max(1e-4 * range.max(1e-9));
    let hi = range / 4.0;
    (hi > 1.5 * lo).then_some((lo, hi))
}

/// Non-negative least squares (Lawson–Hanson active set) of `y ≈ Σ w_j·cols[j]`, w ≥ 0.
/// Small problems only (a few dozen columns; normal equations).
pub fn nnls(cols: &[Vec<f64>], y: &[f64]) -> Vec<f64> {
    let (ata, aty, _) = gram(cols, y);
    nnls_gram(&ata, &aty, &vec![true; cols.len()])
}

/// The normal equations of `y ≈ Σ w_j·cols[j]`: AᵀA, Aᵀy and yᵀy.
pub fn gram(cols: &[Vec<f64>], y: &[f64]) -> (Vec<Vec<f64>>, Vec<f64>, f64) {
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    // Symmetric: each product once (x·y and y·x are the same sum, term by term).
    let k = cols.len();
    let mut ata = vec![vec![0.0; k]; k];
    for i in 0..k {
        for j in 0..=i {
            let d = dot(&cols[i], &cols[j]);
            ata[i][j] = d;
            ata[j][i] = d;
        }
    }
    (ata, cols.iter().map(|a| dot(a, y)).collect(), dot(y, y))
}

/// [`nnls`] on its normal equations, the columns with `allowed[j]` false held at 0.
pub fn nnls_gram(ata: &[Vec<f64>], aty: &[f64], allowed: &[bool]) -> Vec<f64> {
    let k = aty.len();
    let mut w = vec![0.0; k];
    let mut passive = vec![false; k];
    // Unconstrained solution restricted to the passive set (Cholesky-free Gauss elimination).
    let solve = |passive: &[bool]| -> Vec<f64> {
        let idx: Vec<usize> = (0..k).filter(|&j| passive[j]).collect();
        let m = idx.len();
        let mut a: Vec<Vec<f64>> = idx
            .iter()
            .map(|&i| {
                let mut row: Vec<f64> = idx.iter().map(|&j| ata[i][j]).collect();
                row.push(aty[i]);
                row
            })
            .collect();
        for c in 0..m {
            let piv = (c..m)
                .max_by(|&p, &q| a[p][c].abs().total_cmp(&a[q][c].abs()))
                .unwrap_or(c);
            a.swap(c, piv);
            let d = a[c][c];
            if d.abs() < 1e-300 {
                continue;
            }
            let pivot_row = a[c].clone();
            for (r, row) in a.iter_mut().enumerate() {
                if r != c {
                    let f = row[c] / d;
                    for (x, p) in row.iter_mut().zip(&pivot_row).skip(c) {
                        *x -= f * p;
                    }
                }
            }
        }
        let mut z = vec![0.0; k];
        for (row, &i) in idx.iter().enumerate() {
            let d = a[row][row];
            z[i] = if d.abs() < 1e-300 { 0.0 } else { a[row][m] / d };
        }
        z
    };
    for _ in 0..(3 * k + 3) {
        // Gradient of ½‖y − Aw‖²: Aᵀy − AᵀAw.
        let grad: Vec<f64> = (0..k)
            .map(|i| aty[i] - (0..k).map(|j| ata[i][j] * w[j]).sum::<f64>())
            .collect();
        let scale = grad.iter().fold(0.0_f64, |m, g| m.max(g.abs())).max(1e-300);
        let Some(j) = (0..k)
            .filter(|&j| allowed[j] && !passive[j] && grad[j] > 1e-12 * scale)
            .max_by(|&a, &b| grad[a].total_cmp(&grad[b]))
        else {
            break;
        };
        passive[j] = true;
        loop {
            let z = solve(&passive);
            if (0..k).all(|i| !passive[i] || z[i] > 0.0) {
                w = z;
                break;
            }
            // Step back to the boundary and drop the variables that reach zero.
            let alpha = (0..k)
                .filter(|&i| passive[i] && z[i] <= 0.0)
                .map(|i| w[i] / (w[i] - z[i]))
                .fold(1.0_f64, f64::min);
            for i in 0..k {
                w[i] += alpha * (z[i] - w[i]);
                if passive[i] && w[i] <= 1e-15 * scale {
                    passive[i] = false;
                    w[i] = 0.0;
                }
            }
            if !passive.iter().any(|&p| p) {
                break;
            }
        }
    }
    w
}

/// Preisach (Prandtl–Ishlinskii) branch weights: the non-negative half-widths of plays of the
/// given widths that best explain `y` (already free of the temperature polynomial and the
/// rest of the model). Returns one branch half-width per width, in the unit of `y`.
pub fn preisach_nnls(temp_c: &[f64], widths_c: &[f64], y: &[f64]) -> Vec<f64> {
    let cols: Vec<Vec<f64>> = widths_c.iter().map(|&r| branch(temp_c, r)).collect();
    nnls(&cols, y)
}

/// The relay hysteron of thresholds `lower_c` < `upper_c` (the general Preisach model's
/// elementary operator) on `temp_c`: +1 once T has risen to the upper threshold, −1 once it has
/// fallen to the lower one, unchanged in between; 0 until the first of these (the virgin state
/// between the thresholds is unknown). Returns the states and the number of switches up and
/// down (the virgin state's first setting not counted).
pub fn relay(temp_c: &[f64], lower_c: f64, upper_c: f64) -> (Vec<f64>, usize, usize) {
    let (mut state, mut ups, mut downs) = (0.0, 0, 0);
    let out = temp_c
        .iter()
        .map(|&t| {
            let next = crate::sim::catalogue::relay_step(state, t, lower_c, upper_c);
            ups += usize::from(state < 0.0 && next > 0.0);
            downs += usize::from(state > 0.0 && next < 0.0);
            state = next;
            state
        })
        .collect();
    (out, ups, downs)
}

/// A relay in the branch convention of [`branch`]: −(relay state), so that between its
/// thresholds it reads +1 on the heating branch (the relay has not switched up yet) and −1 on
/// the cooling branch — a relay with a positive weight makes a loop of the same sense as a play
/// with a positive weight (a continuum of relays of one gap is a play).
pub fn relay_branch(temp_c: &[f64], lower_c: f64, upper_c: f64) -> Vec<f64> {
    relay(temp_c, lower_c, upper_c)
        .0
        .into_iter()
        .map(|v| -v)
        .collect()
}

/// Threshold levels of the relay dictionary: evenly spaced over the 1–99 % range of the
/// temperature (ten levels: thresholds 0.11 °C apart on a ±0.5 °C programme, up to 45 pairs).
/// Measured on the relay logs of `discover_hidden_shapes.rs` (named alone with the area within
/// ±30 %): 8 levels 0/6, 10 1/6, 12 0/6, 16 2/6, 20 2/6; the Bouc–Wen loops 8/8 at 10 and 16.
/// Ten, not sixteen: with 24 plays the dictionary's charge 2 ln M is 8.5 at ten levels, about
/// the BIC's ln n = 8.4 of a 3-day log at 60 s, but 9.9 at sixteen — which lost a Bouc–Wen loop
/// of `discover_hidden_shapes.rs`'s moderate draws to a thermal lag by ΔBIC 1.4.
pub const RELAY_LEVELS: usize = 10;

/// A relay is identifiable only when the record switches it this often each way: a relay
/// switched once is a step of the bias, not a loop.
pub const RELAY_MIN_SWITCHES: usize = 3;

/// The relays (β, α) of the dictionary that the record can identify: thresholds on
/// [`RELAY_LEVELS`] levels over the 1–99 % range of `temp_c`, the gap α − β at least
/// `min_gap_c` (twice the narrowest play's dead band: a narrower relay is a play's job, and
/// chatters on the reading noise), switched at least [`RELAY_MIN_SWITCHES`] times each way.
pub fn relay_dictionary(temp_c: &[f64], min_gap_c: f64) -> Vec<[f64; 2]> {
    let Some((lo, step)) = relay_levels(temp_c) else {
        return Vec::new();
    };
    let levels: Vec<f64> = (0..RELAY_LEVELS).map(|k| lo + step * k as f64).collect();
    let mut out = Vec::new();
    for (i, &b) in levels.iter().enumerate() {
        for &a in &levels[i + 1..] {
            if a - b >= min_gap_c && identifiable(temp_c, b, a) {
                out.push([b, a]);
            }
        }
    }
    out
}

/// The lowest threshold level of the relay dictionary and the levels' spacing, °C (`None` for
/// fewer than 4 rows).
pub fn relay_levels(temp_c: &[f64]) -> Option<(f64, f64)> {
    let (lo, hi) = range_1_99_c(temp_c)?;
    Some((lo, (hi - lo) / (RELAY_LEVELS - 1) as f64))
}

/// The 1 % and 99 % quantiles of the temperature, °C (`None` for fewer than 4 rows): the range
/// the hysteresis' plays and relays are sized on, robust to a few outliers.
fn range_1_99_c(temp_c: &[f64]) -> Option<(f64, f64)> {
    if temp_c.len() < 4 {
        return None;
    }
    let mut s = temp_c.to_vec();
    s.sort_by(f64::total_cmp);
    let q = |p: f64| s[((s.len() - 1) as f64 * p).round() as usize];
    Some((q(0.01), q(0.99)))
}

/// Whether the record switches the relay of thresholds `lower_c` < `upper_c` at least
/// [`RELAY_MIN_SWITCHES`] times each way (once is a step of the bias, not a loop).
fn identifiable(temp_c: &[f64], lower_c: f64, upper_c: f64) -> bool {
    let (_, ups, downs) = relay(temp_c, lower_c, upper_c);
    ups >= RELAY_MIN_SWITCHES && downs >= RELAY_MIN_SWITCHES
}

/// The level grid a relay's thresholds are refined in ([`refine_relays`]).
#[derive(Debug, Clone, Copy)]
pub struct RelayCells<'a> {
    /// The temperature the relays switch on, °C.
    pub temp_c: &'a [f64],
    /// The spacing of the dictionary's levels, °C ([`relay_levels`]).
    pub step_c: f64,
    /// The least gap α − β, °C.
    pub min_gap_c: f64,
}

/// [`refine_relays`]' result.
#[derive(Debug, Clone)]
pub struct RefinedRelays {
    /// The relays' thresholds [β, α], °C.
    pub relays_c: Vec<[f64; 2]>,
    /// Their columns, from the caller's `column`.
    pub cols: Vec<Vec<f64>>,
    /// How many thresholds moved off their levels (each a fitted parameter).
    pub moved: usize,
}

/// The relays of a fitted distribution with their thresholds moved inside their cells of the
/// dictionary's level grid (each at most 7/16 of a spacing `step_c` from its level, the gap at
/// least `min_gap_c`, still identifiable), where that lowers the residual of the
/// non-negative fit of the plays' columns `play_cols` and the relays' (`column` of a threshold
/// pair: the relay's column in the domain `y` is judged in) at the fit's `sign`. Each
/// threshold in turn, by steps of a quarter, an eighth and a sixteenth of the spacing.
///
/// Why: a threshold off the true one by a fraction of the spacing moves every switching by
/// the time the ramp takes to cover it — on ramps of 0.2–0.5 °C/h, minutes; on the whitened
/// residual (mostly its differences) those switchings then miss, and a longer output lag that
/// blurs them fits better (measured on 14-day relay logs with 5–20 min switching times: 32-min
/// lags chosen, loop areas +40 … +80 %, a lag of the temperature named beside to take the
/// rest). A threshold moved off its level is a fitted parameter: the move must pay the BIC's
/// ln n (n = rows of `y`, in n·ln RSS) once, and the caller charges it.
pub fn refine_relays(
    cells: &RelayCells,
    play_cols: &[Vec<f64>],
    relays_c: &[[f64; 2]],
    column: impl Fn([f64; 2]) -> Option<Vec<f64>>,
    y: &[f64],
    sign: f64,
) -> Option<RefinedRelays> {
    let RelayCells {
        temp_c,
        step_c,
        min_gap_c,
    } = *cells;
    let mut relays = relays_c.to_vec();
    let mut cols: Vec<Vec<f64>> = play_cols.to_vec();
    for r in &relays {
        cols.push(column(*r)?);
    }
    let np = play_cols.len();
    let rss_of = |cols: &[Vec<f64>]| {
        let (ata, aty, yy) = gram(cols, y);
        let b: Vec<f64> = aty.iter().map(|v| sign * v).collect();
        let w = nnls_gram(&ata, &b, &vec![true; cols.len()]);
        gram_rss(&ata, &b, yy, &w)
    };
    let n = (y.len() as f64).max(2.0);
    let score = |rss: f64, moved: usize| n * rss.max(1e-300).ln() + moved as f64 * n.ln();
    let mut moved = 0;
    let mut best = score(rss_of(&cols), moved);
    for k in 0..relays.len() {
        let level = relays[k];
        for side in 0..2 {
            for frac in [0.25, 0.125, 0.0625] {
                for dir in [-1.0, 1.0] {
                    let mut r = relays[k];
                    r[side] += dir * frac * step_c;
                    if r[1] - r[0] < min_gap_c || !identifiable(temp_c, r[0], r[1]) {
                        continue;
                    }
                    let Some(c) = column(r) else { continue };
                    let old = std::mem::replace(&mut cols[np + k], c);
                    let now_moved = moved + usize::from(relays[k][side] == level[side]);
                    let v = score(rss_of(&cols), now_moved);
                    if v < best {
                        best = v;
                        relays[k] = r;
                        moved = now_moved;
                        // One direction improved: the other is not tried at this step.
                        break;
                    }
                    cols[np + k] = old;
                }
            }
        }
    }
    Some(RefinedRelays {
        relays_c: relays,
        cols: cols.split_off(np),
        moved,
    })
}

/// A discrete Preisach distribution: plays (Prandtl–Ishlinskii) of several half-widths and
/// relay hysterons of several threshold pairs, the shape of the `thermal_hysteresis` column when
/// the selection has fitted one (NNLS weights, normalised to sum 1 over plays and relays). The
/// column is divided by `reach`, half its peak-to-peak over the record, so that its coefficient
/// is the branch half-width the record reaches (1 for saturated play loops: the coefficient is
/// then the saturation half-width, as for one play).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Preisach {
    /// Play half-widths, °C (the widths with a non-zero weight).
    pub widths_c: Vec<f64>,
    /// Their weights, ≥ 0.
    pub weights: Vec<f64>,
    /// Relay thresholds [β, α], °C (lower, upper; the relays with a non-zero weight).
    pub relays_c: Vec<[f64; 2]>,
    /// Their weights, ≥ 0 (with the plays' summing to 1).
    pub relay_weights: Vec<f64>,
    /// Half the peak-to-peak of Σ weights × operators over the record at the fitted widths (the
    /// column is divided by it).
    pub reach: f64,
    /// The area ∫(heating − cooling) dT of the column's loop per unit of its coefficient, °C,
    /// on the major loop over the record's 1–99 % temperature range (of the rate-independent
    /// loop, before `lag_s`).
    pub loop_area_c: f64,
    /// Time constant of the first-order lag through which the loop's output reaches the
    /// sensor, s (0: at once): a switching element's own switching time, or the thermal path
    /// from the hysteretic part to the proof mass ([`LOOP_LAGS_S`]).
    pub lag_s: f64,
    /// The loop as the record shows it, per unit coefficient, °C ([`record_loop_area_c`] of the
    /// column, lag included): with an output lag the record's ramps widen the loop by the
    /// distance they cover in the lag, and on ramps of similar rates the split between the
    /// thresholds' gap and the lag is not determined while this area is.
    pub record_loop_area_c: f64,
}

/// The area ∫(heating − cooling) dT of `column` as the record `temp_c` (spacing `dt_s`) shows
/// it, per unit of the column: the temperature's 2–98 % range in 24 bins; in each, the mean of
/// the column on the rows where the temperature is rising minus its mean where it is falling,
/// times the bin's width, summed over the bins with at least 5 rows of each. Rising and falling
/// from the change over ± 10 min (at least one row); rows whose change is within 4× the
/// reading noise (holds, turnovers) are neither. NaN when no bin qualifies.
pub fn record_loop_area_c(column: &[f64], temp_c: &[f64], dt_s: f64) -> f64 {
    const BINS: usize = 24;
    let n = temp_c.len().min(column.len());
    let w = ((600.0 / dt_s).round() as usize).max(1);
    if n < 2 * w + 2 {
        return f64::NAN;
    }
    let mut sorted: Vec<f64> = temp_c[..n]
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .collect();
    if sorted.len() < 2 {
        return f64::NAN;
    }
    sorted.sort_by(f64::total_cmp);
    let q = |p: f64| sorted[((sorted.len() - 1) as f64 * p).round() as usize];
    let (lo, hi) = (q(0.02), q(0.98));
    let width = (hi - lo) / BINS as f64;
    // A NaN width (a flat or non-finite record) is no range either.
    if width.is_nan() || width <= 0.0 {
        return f64::NAN;
    }
    let still = 4.0 * reading_noise_c(&temp_c[..n]);
    // Per bin: (sum rising, rows rising, sum falling, rows falling).
    let mut acc = [[0.0f64; 4]; BINS];
    for i in w..n - w {
        let d = temp_c[i + w] - temp_c[i - w];
        let b = ((temp_c[i] - lo) / width).floor();
        // A NaN change is neither rising nor falling.
        let moving = d.abs() > still;
        if !(0.0..BINS as f64).contains(&b) || !moving || !column[i].is_finite() {
            continue;
        }
        let a = &mut acc[b as usize];
        let k = if d > 0.0 { 0 } else { 2 };
        a[k] += column[i];
        a[k + 1] += 1.0;
    }
    let used: Vec<f64> = acc
        .iter()
        .filter(|a| a[1] >= 5.0 && a[3] >= 5.0)
        .map(|a| (a[0] / a[1] - a[2] / a[3]) * width)
        .collect();
    if used.is_empty() {
        f64::NAN
    } else {
        used.iter().sum()
    }
}

/// How far the temperature typically moves in a time: (k·`dt_s`, median |T[i + k] − T[i]|) for
/// k doubling from 1 up to a quarter of the record.
pub fn median_change_c(temp_c: &[f64], dt_s: f64) -> Vec<(f64, f64)> {
    let n = temp_c.len();
    let mut out = Vec::new();
    let mut k = 1;
    while 4 * k <= n {
        let mut d: Vec<f64> = (0..n - k)
            .map(|i| (temp_c[i + k] - temp_c[i]).abs())
            .filter(|v| v.is_finite())
            .collect();
        if !d.is_empty() {
            let mid = d.len() / 2;
            let (_, m, _) = d.select_nth_unstable_by(mid, f64::total_cmp);
            out.push((k as f64 * dt_s, *m));
        }
        k *= 2;
    }
    out
}

/// The typical time the temperature takes to move by `delta_c`, s, from its
/// [`median_change_c`]: the shortest time whose median change reaches it (∞ when none does).
/// Holds lengthen it.
pub fn crossing_time_s(median_change: &[(f64, f64)], delta_c: f64) -> f64 {
    median_change
        .iter()
        .find(|(_, m)| *m >= delta_c)
        .map_or(f64::INFINITY, |(t, _)| *t)
}

/// The output lags a Preisach distribution is tried with, s (0 and a factor-2 grid from 4 min
/// to 64 min): a relay that takes minutes to switch leaves after every switch a transient the
/// rate-independent loop cannot fit, which the noise model then takes as random walk (measured
/// on 14-day relay logs with 2–20 min switching times: the noise model's Allan deviation at 2 h
/// 3–5× the noise's own with the loop in the model) and which hides the loop below that
/// inflated floor. Longer than an hour, a lag of the loop is no longer told from a lag of the
/// temperature on 2–6 h ramps.
pub const LOOP_LAGS_S: [f64; 5] = [240.0, 480.0, 960.0, 1920.0, 3840.0];

impl Preisach {
    /// From NNLS weights over `widths_c` (plays) and `relays_c` (zero weights dropped); `None`
    /// when all are zero. `reach` and `loop_area_c` are set by [`Preisach::on_record`].
    pub fn from_weights(
        widths_c: &[f64],
        w: &[f64],
        relays_c: &[[f64; 2]],
        wr: &[f64],
    ) -> Option<Self> {
        let total: f64 = w.iter().chain(wr).filter(|v| **v > 0.0).sum();
        if !(total > 0.0 && total.is_finite()) {
            return None;
        }
        let (widths_c, weights) = active_normalised(widths_c, w, total);
        let (relays_c, relay_weights) = active_normalised(relays_c, wr, total);
        Some(Self {
            widths_c,
            weights,
            relays_c,
            relay_weights,
            reach: 1.0,
            loop_area_c: f64::NAN,
            lag_s: 0.0,
            record_loop_area_c: f64::NAN,
        })
    }

    /// The distribution with its output lagged by `lag_s` (s; 0: at once) and the loop area
    /// the record (`temp_c` at times `t_s`, nominal spacing `dt_s`) then shows.
    pub fn with_lag(
        mut self,
        lag_s: f64,
        temp_c: &[f64],
        t_s: &[f64],
        segment_start: &[bool],
        dt_s: f64,
    ) -> Self {
        self.lag_s = lag_s;
        let c = self.lagged_column(temp_c, t_s, segment_start, self.width_c());
        self.record_loop_area_c = record_loop_area_c(&c, temp_c, dt_s);
        self
    }

    /// [`Preisach::column`] through the output lag `lag_s` on the record's time grid `t_s`
    /// (restarted at each segment start, like every lag of the catalogue).
    pub fn lagged_column(
        &self,
        temp_c: &[f64],
        t_s: &[f64],
        segment_start: &[bool],
        theta: f64,
    ) -> Vec<f64> {
        let c = self.column(temp_c, theta);
        if self.lag_s > 0.0 {
            super::effects::lag_filter(&c, t_s, segment_start, self.lag_s)
        } else {
            c
        }
    }

    /// Sets `reach` (half the peak-to-peak of the operators' sum over `temp_c`) and
    /// `loop_area_c` (the major loop over its 1–99 % range).
    pub fn on_record(mut self, temp_c: &[f64]) -> Self {
        self.reach = 1.0;
        let theta = self.width_c();
        let raw = self.column(temp_c, theta);
        let (lo, hi) = raw
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(*v), b.max(*v))
            });
        let reach = 0.5 * (hi - lo);
        self.reach = if reach.is_finite() && reach > 1e-9 {
            reach
        } else {
            1.0
        };
        let mut s = temp_c.to_vec();
        s.sort_by(f64::total_cmp);
        let q = |p: f64| s[((s.len() - 1) as f64 * p).round() as usize];
        self.loop_area_c = if s.is_empty() {
            f64::NAN
        } else {
            self.major_loop_area_c(q(0.01), q(0.99))
        };
        self
    }

    /// The area ∫(heating − cooling) dT of the column's loop between `lo_c` and `hi_c`, °C per
    /// unit coefficient: the column run over lo → hi → lo → hi → lo in 400 steps a leg, the last
    /// heating and cooling legs compared at the same temperatures (trapezoids).
    pub fn major_loop_area_c(&self, lo_c: f64, hi_c: f64) -> f64 {
        const L: usize = 400;
        let d = (hi_c - lo_c) / L as f64;
        let mut t = Vec::with_capacity(4 * L + 1);
        for leg in 0..4 {
            for k in 0..L {
                let x = if leg % 2 == 0 { k } else { L - k };
                t.push(lo_c + d * x as f64);
            }
        }
        t.push(lo_c);
        let c = self.column(&t, self.width_c());
        let diff = |k: usize| c[2 * L + k] - c[4 * L - k];
        (0..L).map(|k| 0.5 * (diff(k) + diff(k + 1)) * d).sum()
    }

    /// The distribution's characteristic width: the weighted geometric mean of the plays'
    /// half-widths and the relays' half-gaps, °C (the effect's nonlinear parameter θ; one play:
    /// its half-width).
    pub fn width_c(&self) -> f64 {
        let plays = self
            .widths_c
            .iter()
            .zip(&self.weights)
            .map(|(r, w)| (*r, *w));
        let relays = self
            .relays_c
            .iter()
            .zip(&self.relay_weights)
            .map(|(r, w)| (0.5 * (r[1] - r[0]), *w));
        let (sw, sl) = plays
            .chain(relays)
            .fold((0.0, 0.0), |(sw, sl), (r, w)| (sw + w, sl + w * r.ln()));
        (sl / sw).exp()
    }

    /// The column (Σ w_k·h_{r_k·s}[T] + Σ v_j·relay_{c_j ∓ g_j·s}[T]) / reach, s = θ/θ₀: the
    /// distribution scaled so that its characteristic width is `theta` (θ = θ₀ gives the fitted
    /// shape; other θ scale every play width and every relay's gap about its centre alike, so
    /// the width's uncertainty and the shape check keep their meaning).
    pub fn column(&self, temp_c: &[f64], theta: f64) -> Vec<f64> {
        let scale = theta / self.width_c();
        let mut out = vec![0.0; temp_c.len()];
        for (r, w) in self.widths_c.iter().zip(&self.weights) {
            for (o, h) in out.iter_mut().zip(branch(temp_c, r * scale)) {
                *o += w * h / self.reach;
            }
        }
        for (r, w) in self.relays_c.iter().zip(&self.relay_weights) {
            let (lower_c, upper_c) = crate::sim::catalogue::relay_scaled(r[0], r[1], scale);
            for (o, h) in out.iter_mut().zip(relay_branch(temp_c, lower_c, upper_c)) {
                *o += w * h / self.reach;
            }
        }
        out
    }
}

/// The best non-negative Preisach distribution over the plays `widths_c` and the relays
/// `relays_c` for a residual: `cols` holds the plays' branch columns, then the relays', and `y`
/// the residual, all in the domain the fit is judged in (whitened, the current model projected
/// out). Both signs are tried (the heating branch may read lower or higher). A relay whose
/// weight does not pay the BIC's ln n (n = rows of `y`: the fit without it, re-solved, is worse
/// by less than that in n·ln RSS) is pruned, the weakest first, until every relay left pays.
/// Returns the distribution (`reach` 1 and no loop area: [`Preisach::on_record`]), the sign
/// and the number of active plays and relays.
pub fn fit_preisach(
    widths_c: &[f64],
    relays_c: &[[f64; 2]],
    cols: &[Vec<f64>],
    y: &[f64],
) -> Option<(Preisach, f64, usize)> {
    let np = widths_c.len();
    let k = cols.len();
    if k != np + relays_c.len() {
        return None;
    }
    let (ata, aty, yy) = gram(cols, y);
    let n = (y.len() as f64).max(2.0);
    let one_sign = |sign: f64| {
        let b: Vec<f64> = aty.iter().map(|v| sign * v).collect();
        let rss = |w: &[f64]| gram_rss(&ata, &b, yy, w);
        let mut allowed = vec![true; k];
        loop {
            let w = nnls_gram(&ata, &b, &allowed);
            let r = rss(&w);
            let mut weakest: Option<(usize, f64)> = None;
            for j in (np..k).filter(|&j| w[j] > 0.0) {
                allowed[j] = false;
                let d = n * (rss(&nnls_gram(&ata, &b, &allowed)) / r).ln();
                allowed[j] = true;
                if d < n.ln() && weakest.is_none_or(|(_, dw)| d < dw) {
                    weakest = Some((j, d));
                }
            }
            match weakest {
                Some((j, _)) => allowed[j] = false,
                None => return (w, r),
            }
        }
    };
    let (wp, rp) = one_sign(1.0);
    let (wn, rn) = one_sign(-1.0);
    let (w, sign) = if rp <= rn { (wp, 1.0) } else { (wn, -1.0) };
    // Weights at round-off level are no width of the loop (and would be charged as one).
    let top = w.iter().fold(0.0_f64, |m, v| m.max(*v));
    let w: Vec<f64> = w
        .iter()
        .map(|&v| if v > 1e-9 * top { v } else { 0.0 })
        .collect();
    let active = w.iter().filter(|v| **v > 0.0).count();
    Preisach::from_weights(widths_c, &w[..np], relays_c, &w[np..]).map(|p| (p, sign, active))
}

/// The residual sum of squares ‖y − Σ w_j·cols[j]‖² from the normal equations (`ata`, the
/// right-hand side `b`, yᵀy `yy`) at weights `w`, at least 1e-300 (a logarithm is taken of it).
fn gram_rss(ata: &[Vec<f64>], b: &[f64], yy: f64, w: &[f64]) -> f64 {
    let k = w.len();
    let quad: f64 = (0..k)
        .map(|i| w[i] * (0..k).map(|j| ata[i][j] * w[j]).sum::<f64>())
        .sum();
    (yy - 2.0 * w.iter().zip(b).map(|(w, b)| w * b).sum::<f64>() + quad).max(1e-300)
}

/// ΔBIC difference under which `thermal_lag` and `thermal_hysteresis` are said to explain the
/// temperature response equally (10: "very strong" evidence on the usual BIC scale).
pub const LAG_OR_LOOP_DBIC: f64 = 10.0;

/// The warning when the accepted one of `thermal_lag` / `thermal_hysteresis` (`chosen`, ΔBIC
/// `chosen_dbic`) beat the other (`other_dbic`, scored in the same round) by less than
/// [`LAG_OR_LOOP_DBIC`]: on ramps of one rate a lag is itself a Preisach operator, so the name
/// is then not a finding of the mechanism (module docs).
pub fn lag_or_loop_warning(chosen: &str, chosen_dbic: f64, other_dbic: f64) -> Option<String> {
    let other = match chosen {
        "thermal_lag" => "thermal_hysteresis",
        "thermal_hysteresis" => "thermal_lag",
        _ => return None,
    };
    (other_dbic < 0.0 && other_dbic - chosen_dbic < LAG_OR_LOOP_DBIC).then(|| {
        format!(
            "{chosen} (ΔBIC {chosen_dbic:.1}) was preferred to {other} (ΔBIC {other_dbic:.1}) by \
             less than {LAG_OR_LOOP_DBIC}: a first-order lag and a rate-independent loop differ \
             only where the temperature ramps at different rates (a lag's offset scales with the \
             rate, a loop's does not); this record's ramps do not tell them apart, so the name \
             is not a finding of which mechanism it is"
        )
    })
}

/// The operators with a positive weight and their weights as fractions of `total` (the NNLS
/// leaves the others at exactly 0).
fn active_normalised<T: Copy>(operators: &[T], w: &[f64], total: f64) -> (Vec<T>, Vec<f64>) {
    operators
        .iter()
        .zip(w)
        .filter(|(_, v)| **v > 0.0)
        .map(|(r, v)| (*r, v / total))
        .unzip()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_play_stands_still_until_the_input_has_reversed_by_twice_its_half_width() {
        // Up 0 → 2, down to 0.5, up to 1.0.
        let mut u: Vec<f64> = (0..=20).map(|i| 0.1 * f64::from(i)).collect();
        u.extend((1..=15).map(|i| 2.0 - 0.1 * f64::from(i)));
        u.extend((1..=5).map(|i| 0.5 + 0.1 * f64::from(i)));
        let h = branch(&u, 0.4);
        // Heating: after 0.8 °C of rise the play is on the branch, T − p = +r.
        assert!((h[20] - 1.0).abs() < 1e-12, "{}", h[20]);
        // 0.4 °C after the reversal at 2.0 it is half-way across: (T − p)/r = (1.6 − 1.6)/0.4 = 0.
        assert!(h[24].abs() < 1e-9, "{}", h[24]);
        // 0.8 °C after the reversal it is on the cooling branch.
        assert!((h[28] + 1.0).abs() < 1e-9, "{}", h[28]);
        // A 0.5 °C rise after the minimum at 0.5 does not reach the heating branch (needs 0.8).
        assert!(h[40] < 1.0 - 0.2, "{}", h[40]);
        assert!(h.iter().all(|x| x.abs() <= 1.0 + 1e-12));
    }

    #[test]
    fn a_play_wider_than_the_reading_noise_ignores_it() {
        // A plateau with ±3 mK noise (deterministic pseudo-noise) after a heating ramp.
        let mut u: Vec<f64> = (0..100).map(|i| 0.01 * f64::from(i)).collect();
        let plateau = u[99];
        u.extend((0..500).map(|i| plateau + 0.003 * (f64::from(i) * 2.399).sin()));
        let h = branch(&u, 0.02);
        assert!(h[100..].iter().all(|&x| x > 0.6), "the branch is kept");
        let s = reading_noise_c(&u[100..]);
        // The estimate is tuned for Gaussian noise; this sine is not: same order is what counts.
        assert!(s > 0.001 && s < 0.006, "{s}");
    }

    #[test]
    fn a_lagged_loop_is_the_first_order_lag_of_the_loop_and_no_lag_is_the_loop_itself() {
        // A triangle 0 → 1 → 0 °C of 100 rows a leg at 60 s, one relay [0.3, 0.7] °C.
        let temp: Vec<f64> = (0..400)
            .map(|i| {
                let x = f64::from(i % 200) / 100.0;
                if x <= 1.0 {
                    x
                } else {
                    2.0 - x
                }
            })
            .collect();
        let t: Vec<f64> = (0..400).map(|i| 60.0 * f64::from(i)).collect();
        let mut seg = vec![false; 400];
        seg[0] = true;
        let p = Preisach::from_weights(&[], &[], &[[0.3, 0.7]], &[1.0]).expect("one relay");
        let still = p.column(&temp, p.width_c());
        assert_eq!(p.lagged_column(&temp, &t, &seg, p.width_c()), still);
        let lagged = p
            .clone()
            .with_lag(600.0, &temp, &t, &seg, 60.0)
            .lagged_column(&temp, &t, &seg, p.width_c());
        let a = (-60.0f64 / 600.0).exp();
        let mut x = still[0];
        for i in 1..400 {
            x = a * x + (1.0 - a) * still[i];
            assert!((lagged[i] - x).abs() < 1e-12, "row {i}");
        }
    }

    #[test]
    fn the_crossing_time_is_the_lag_at_which_the_median_change_reaches_the_width() {
        // A ramp of 0.01 °C a row (60 s): 0.08 °C takes 8 rows, 0.1 °C the next doubling (16).
        let temp: Vec<f64> = (0..1000).map(|i| 0.01 * f64::from(i)).collect();
        let m = median_change_c(&temp, 60.0);
        assert_eq!(crossing_time_s(&m, 0.08), 8.0 * 60.0);
        assert_eq!(crossing_time_s(&m, 0.1), 16.0 * 60.0);
        // A constant temperature never crosses.
        assert!(crossing_time_s(&median_change_c(&[5.0; 100], 60.0), 0.01).is_infinite());
    }

    #[test]
    fn nnls_recovers_non_negative_weights_and_clips_negative_ones() {
        let n = 400;
        let a: Vec<f64> = (0..n).map(|i| (f64::from(i) * 0.05).sin()).collect();
        let b: Vec<f64> = (0..n).map(|i| (f64::from(i) * 0.013).cos()).collect();
        let c: Vec<f64> = (0..n).map(|i| f64::from(i % 7) - 3.0).collect();
        let y: Vec<f64> = (0..n as usize)
            .map(|i| 2.0 * a[i] + 0.5 * b[i] - 1.0 * c[i])
            .collect();
        let w = nnls(&[a.clone(), b.clone(), c.clone()], &y);
        // c's true weight is negative: it is set to 0 and the others fitted without it.
        assert_eq!(w[2], 0.0);
        assert!(
            (w[0] - 2.0).abs() < 0.1 && (w[1] - 0.5).abs() < 0.1,
            "{w:?}"
        );
        let y2: Vec<f64> = (0..n as usize).map(|i| 2.0 * a[i] + 0.5 * b[i]).collect();
        let w2 = nnls(&[a, b, c], &y2);
        assert!(
            (w2[0] - 2.0).abs() < 1e-9 && (w2[1] - 0.5).abs() < 1e-9 && w2[2].abs() < 1e-9,
            "{w2:?}"
        );
    }

    #[test]
    fn preisach_weights_of_a_two_width_distribution_are_found() {
        // Triangle cycles of ±0.5 °C with mK noise: a Preisach of widths 0.05 and 0.2 °C.
        let temp: Vec<f64> = (0..4000)
            .map(|i| {
                let ph = (f64::from(i) / 200.0).fract();
                let tri = if ph < 0.5 {
                    4.0 * ph - 1.0
                } else {
                    3.0 - 4.0 * ph
                };
                0.5 * tri + 0.002 * (f64::from(i) * 1.7).sin()
            })
            .collect();
        let y: Vec<f64> = branch(&temp, 0.05)
            .iter()
            .zip(branch(&temp, 0.2))
            .map(|(a, b)| 3.0 * a + 1.0 * b)
            .collect();
        let w = preisach_nnls(&temp, &[0.02, 0.05, 0.1, 0.2, 0.3], &y);
        assert!(
            (w[1] - 3.0).abs() < 1e-6 && (w[3] - 1.0).abs() < 1e-6,
            "{w:?}"
        );
        assert!(w[0].abs() + w[2].abs() + w[4].abs() < 1e-6, "{w:?}");
        assert!(width_range_c(&temp).is_some());
    }

    #[test]
    fn a_fitted_preisach_distribution_rebuilds_its_column_at_its_width_and_keeps_the_sign() {
        // A loop read lower on heating (negative half-width): 3 µ·h_0.05 + 1 µ·h_0.2, negated.
        let temp: Vec<f64> = (0..3000)
            .map(|i| 0.5 * (f64::from(i) * std::f64::consts::TAU / 400.0).sin())
            .collect();
        let widths = [0.02, 0.05, 0.1, 0.2, 0.3];
        let cols: Vec<Vec<f64>> = widths.iter().map(|&r| branch(&temp, r)).collect();
        let y: Vec<f64> = (0..temp.len())
            .map(|i| -(3.0 * cols[1][i] + cols[3][i]))
            .collect();
        let (p, _, active) = fit_preisach(&widths, &[], &cols, &y).expect("a distribution");
        assert_eq!(active, 2, "{p:?}");
        assert_eq!(p.widths_c, vec![0.05, 0.2], "{p:?}");
        assert!((p.weights[0] - 0.75).abs() < 1e-9, "{p:?}");
        let theta = p.width_c();
        assert!((theta - (0.75 * 0.05f64.ln() + 0.25 * 0.2f64.ln()).exp()).abs() < 1e-12);
        // At θ the column is the fitted shape, saturating at ±1: y = −4 × it.
        let c = p.column(&temp, theta);
        assert!(c.iter().zip(&y).all(|(c, y)| (4.0 * c + y).abs() < 1e-9));
        // At 2θ every width doubles.
        let c2 = p.column(&temp, 2.0 * theta);
        let (a, b) = (branch(&temp, 0.1), branch(&temp, 0.4));
        let want: Vec<f64> = a.iter().zip(&b).map(|(a, b)| 0.75 * a + 0.25 * b).collect();
        assert!(c2.iter().zip(&want).all(|(a, b)| (a - b).abs() < 1e-9));
    }

    #[test]
    fn a_relay_switches_at_its_thresholds_and_its_loop_area_is_twice_its_gap() {
        let t = [0.5, 0.8, 0.6, 0.2, 0.4, 0.8, 0.1];
        let (r, ups, downs) = relay(&t, 0.3, 0.7);
        // Virgin between the thresholds, up at 0.8, held at 0.6, down at 0.2, held, up, down.
        assert_eq!(r, vec![0.0, 1.0, 1.0, -1.0, -1.0, 1.0, -1.0]);
        assert_eq!(
            (ups, downs),
            (1, 2),
            "the virgin state's first setting is no switch"
        );
        assert_eq!(relay_branch(&t, 0.3, 0.7)[2], -1.0);
        // One relay of weight 1: +1 on heating, −1 on cooling over its 0.4 °C gap.
        let p = Preisach::from_weights(&[], &[], &[[0.3, 0.7]], &[2.0]).expect("a relay");
        assert_eq!(p.relay_weights, vec![1.0]);
        assert!((p.width_c() - 0.2).abs() < 1e-12);
        let a = p.major_loop_area_c(0.0, 1.0);
        assert!((a - 0.8).abs() < 0.02, "{a}");
        // A play of half-width 0.1 on the same range: 2 over the middle 0.6 °C, a linear turn
        // of 0.2 °C at each end (0.2 each): 1.6.
        let q = Preisach::from_weights(&[0.1], &[1.0], &[], &[]).expect("a play");
        let b = q.major_loop_area_c(0.0, 1.0);
        assert!((b - 1.6).abs() < 0.02, "{b}");
    }

    #[test]
    fn a_relay_among_plays_is_found_by_the_nnls_and_a_useless_one_is_pruned() {
        // Triangle cycles of 0.6–1 °C swings around 0: a relay [−0.1, 0.2] of weight 2 and a
        // play of 0.05 of weight 1, in small deterministic noise.
        let mut temp = Vec::new();
        for c in 0..30 {
            let amp = 0.3 + 0.2 * f64::from(c % 3) / 2.0;
            for i in 0..100 {
                temp.push(-amp + 2.0 * amp * f64::from(i) / 100.0);
            }
            for i in 0..100 {
                temp.push(amp - 2.0 * amp * f64::from(i) / 100.0);
            }
        }
        let widths = [0.02, 0.05, 0.1];
        let relays = [[-0.1, 0.2], [-0.25, 0.05], [0.0, 0.25]];
        let mut cols: Vec<Vec<f64>> = widths.iter().map(|&r| branch(&temp, r)).collect();
        cols.extend(relays.iter().map(|r| relay_branch(&temp, r[0], r[1])));
        let y: Vec<f64> = (0..temp.len())
            .map(|i| cols[1][i] + 2.0 * cols[3][i] + 0.01 * (f64::from(i as u32) * 1.3).sin())
            .collect();
        let (p, sign, active) = fit_preisach(&widths, &relays, &cols, &y).expect("a fit");
        assert_eq!(sign, 1.0);
        assert_eq!(p.relays_c, vec![[-0.1, 0.2]], "{p:?}");
        assert!((p.relay_weights[0] - 2.0 / 3.0).abs() < 0.01, "{p:?}");
        assert!(active <= 3, "{p:?}");
    }

    #[test]
    fn a_relay_between_the_grid_levels_gets_its_thresholds_back_inside_its_cell() {
        // Ramps of three rates between −0.5 and 0.5 °C; a relay [−0.13, 0.19] (the truth) and
        // a play of 0.05 (weight 0.5); the grid's relay is [−0.1, 0.2], spacing 0.1.
        let mut temp = Vec::new();
        for c in 0..24 {
            let n = [60, 100, 160][c % 3];
            temp.extend((0..n).map(|i| -0.5 + f64::from(i) / f64::from(n)));
            temp.extend((0..n).map(|i| 0.5 - f64::from(i) / f64::from(n)));
        }
        let play = branch(&temp, 0.05);
        let truth = relay_branch(&temp, -0.13, 0.19);
        let y: Vec<f64> = (0..temp.len())
            .map(|i| 0.5 * play[i] + truth[i] + 0.01 * (f64::from(i as u32) * 1.3).sin())
            .collect();
        let column = |r: [f64; 2]| Some(relay_branch(&temp, r[0], r[1]));
        let rss = |cols: &[Vec<f64>]| {
            let w = nnls(cols, &y);
            (0..y.len())
                .map(|i| (y[i] - cols.iter().zip(&w).map(|(c, w)| w * c[i]).sum::<f64>()).powi(2))
                .sum::<f64>()
        };
        let before = rss(&[play.clone(), relay_branch(&temp, -0.1, 0.2)]);
        let cells = RelayCells {
            temp_c: &temp,
            step_c: 0.1,
            min_gap_c: 0.02,
        };
        let RefinedRelays {
            relays_c: relays,
            cols,
            moved,
        } = refine_relays(
            &cells,
            std::slice::from_ref(&play),
            &[[-0.1, 0.2]],
            column,
            &y,
            1.0,
        )
        .expect("refined");
        assert_eq!(moved, 2, "both thresholds are charged");
        // Found within a sixteenth of the spacing (the smallest step), and the residual fell.
        assert!((relays[0][0] + 0.13).abs() <= 0.00625 + 1e-12, "{relays:?}");
        assert!((relays[0][1] - 0.19).abs() <= 0.00625 + 1e-12, "{relays:?}");
        let after = rss(&[play.clone(), cols[0].clone()]);
        assert!(after < 0.2 * before, "{after} vs {before}");
    }

    #[test]
    fn a_lag_and_a_loop_within_the_margin_are_said_to_be_indistinguishable() {
        let w = lag_or_loop_warning("thermal_lag", -120.0, -115.0).expect("said");
        assert!(w.contains("thermal_hysteresis (ΔBIC -115.0)"), "{w}");
        assert!(lag_or_loop_warning("thermal_lag", -120.0, -100.0).is_none());
        assert!(lag_or_loop_warning("thermal_hysteresis", -50.0, 3.0).is_none());
        assert!(lag_or_loop_warning("step", -50.0, -49.0).is_none());
    }
}
