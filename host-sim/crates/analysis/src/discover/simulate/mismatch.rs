//! What the simulation gets wrong: the measured residual's views against the ensemble's 5–95 %
//! envelopes. A point (an ADEV τ, a PSD band, a coherence band) is *outside* when the measured
//! value lies above the 95 % or below the 5 % member; a *mismatch* is a maximal run of
//! neighbouring points outside on the same side. With N members a point of a faithful
//! simulation is outside about 10 % of the time by chance, so a single-point run is only reported
//! when it leaves the envelope by more than [`SINGLE_POINT_FACTOR`] (the fractions count every
//! point).

use super::spectra::{Envelope, Views};

/// A lone outside point is a mismatch only when it is this many times beyond the envelope edge.
pub const SINGLE_POINT_FACTOR: f64 = 1.5;
/// Coherence bands whose measured coherence is below this are never called coherent (the
/// envelope of a few members can be very low where the simulated residual is tiny).
pub const COHERENCE_FLOOR: f64 = 0.1;
/// Seconds per day (frequencies are reported in cycles/day).
const DAY_S: f64 = 86_400.0;

/// Which view.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Quantity {
    /// Allan deviation (range in τ, s).
    Adev,
    /// Power spectral density (range in cycles/day).
    Psd,
    /// Coherence with a channel (range in cycles/day).
    Coherence,
}

/// One range where the record leaves the envelope.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Mismatch {
    /// ADEV, PSD or coherence.
    pub quantity: Quantity,
    /// Range start (τ in s, or frequency in cycles/day).
    pub from: f64,
    /// Range end.
    pub to: f64,
    /// "s" or "cycles/day".
    pub unit: &'static str,
    /// "above" (measured above the envelope) or "below".
    pub direction: &'static str,
    /// Measured / envelope median, geometric mean over the range (ADEV and PSD: ×; coherence:
    /// the measured coherence's mean over the range).
    pub factor: f64,
    /// Points in the range.
    pub points: usize,
    /// The channel (coherence only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub channel: Option<String>,
    /// Index range of the points (for the cause attribution and the figures).
    #[serde(skip)]
    pub index: (usize, usize),
    /// After the extension: "unmodelled: <likely cause>" (the extended twin does not cover it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unmodelled: Option<String>,
}

/// Frequency bands of the solid-Earth tide's groups, cycles/day (diurnal, semidiurnal,
/// terdiurnal).
const TIDE_BANDS_CPD: [(f64, f64); 3] = [(0.8, 1.15), (1.75, 2.1), (2.8, 3.1)];

/// The likely cause of a mismatch the extended twin leaves, named from where it lies: a
/// coherent band → a coupling to that channel; tidal bands → the tide model; slower than a day
/// → the instrument's non-linear drift; the top octave → the output filter or aliasing; short
/// τ or a broad band within ×1.5 → the noise's spectral shape (a process the power-law family
/// lacks, or a level that changes); else a cause outside the catalogue. `nyquist_cpd`: the record's Nyquist
/// frequency in cycles/day.
pub fn likely_cause(m: &Mismatch, nyquist_cpd: f64) -> String {
    let (lo_cpd, hi_cpd) = match m.quantity {
        Quantity::Adev => (DAY_S / (2.0 * m.to), DAY_S / (2.0 * m.from)),
        _ => (m.from, m.to),
    };
    if m.quantity == Quantity::Coherence {
        return format!(
            "a coupling to {} the twin lacks (a transfer function, not a constant coefficient)",
            m.channel.as_deref().unwrap_or("the channel")
        );
    }
    let tidal = TIDE_BANDS_CPD
        .iter()
        .any(|(a, b)| lo_cpd <= *b && hi_cpd >= *a);
    if tidal && m.quantity == Quantity::Psd {
        return "the tide model (a constituent or loading the twin's tide lacks)".into();
    }
    if hi_cpd <= 1.0 || (m.quantity == Quantity::Adev && m.to >= DAY_S) {
        return "the instrument's slow non-linear drift (beyond the drift polynomial and the noise \
                family's random walks)"
            .into();
    }
    if lo_cpd >= 0.5 * nyquist_cpd {
        return "the instrument's output filter or aliasing near Nyquist (beyond a first-order \
                corner)"
            .into();
    }
    let f = if m.factor >= 1.0 {
        m.factor
    } else {
        1.0 / m.factor
    };
    if f < 1.5 {
        return "the noise's spectral shape between the family's power laws (a broad excess \
                within ×1.5: a process at these periods the family lacks, or a noise level that \
                changes over the record)"
            .into();
    }
    "a cause outside the catalogue".into()
}

/// The envelopes, the measured views and what differs.
#[derive(Debug, Clone, PartialEq)]
pub struct Comparison {
    /// ADEV envelope (x = τ s).
    pub adev: Envelope,
    /// PSD envelope (x = Hz).
    pub psd: Envelope,
    /// Coherence envelope per channel (name, envelope).
    pub coherence: Vec<(String, Envelope)>,
    /// The measured residual's views.
    pub measured: Views,
    /// Mismatch ranges, ADEV first, then PSD, then coherence.
    pub mismatches: Vec<Mismatch>,
    /// Fraction of ADEV points outside.
    pub adev_outside_fraction: f64,
    /// Fraction of PSD bands outside.
    pub psd_outside_fraction: f64,
    /// The envelope's own calibration: each member left out in turn, the fraction of its ADEV
    /// points outside the other members' 5–95 % envelope, averaged over the members (a record
    /// that behaves like a member lies outside about this often).
    pub member_adev_outside_fraction: f64,
    /// The same for the PSD bands.
    pub member_psd_outside_fraction: f64,
    /// The first two members' views (drawn beside the record in the report).
    pub shown: Vec<Views>,
}

/// Leave-one-member-out: the mean fraction of a member's points outside the envelope of the
/// others (`curves[j][i]`: member j, point i, on the abscissa `x`).
pub fn leave_one_out(x: &[f64], curves: &[Vec<f64>]) -> f64 {
    if curves.len() < 3 || x.is_empty() {
        return f64::NAN;
    }
    let fractions: Vec<f64> = (0..curves.len())
        .map(|j| {
            let others: Vec<Vec<f64>> = curves
                .iter()
                .enumerate()
                .filter(|(k, _)| *k != j)
                .map(|(_, c)| c.clone())
                .collect();
            fraction(&sides(&curves[j], &Envelope::of(x, &others)))
        })
        .filter(|f| f.is_finite())
        .collect();
    fractions.iter().sum::<f64>() / fractions.len().max(1) as f64
}

/// +1 above, −1 below, 0 inside (NaN: inside).
fn side(v: f64, lo: f64, hi: f64) -> i8 {
    if !(v.is_finite() && lo.is_finite() && hi.is_finite()) {
        0
    } else if v > hi {
        1
    } else if v < lo {
        -1
    } else {
        0
    }
}

/// Runs of equal non-zero sides: (start, end exclusive, side).
fn runs(sides: &[i8]) -> Vec<(usize, usize, i8)> {
    let mut v = Vec::new();
    let mut i = 0;
    while i < sides.len() {
        if sides[i] == 0 {
            i += 1;
            continue;
        }
        let mut j = i + 1;
        while j < sides.len() && sides[j] == sides[i] {
            j += 1;
        }
        v.push((i, j, sides[i]));
        i = j;
    }
    v
}

fn fraction(sides: &[i8]) -> f64 {
    if sides.is_empty() {
        return f64::NAN;
    }
    sides.iter().filter(|s| **s != 0).count() as f64 / sides.len() as f64
}

/// Geometric mean of measured / median over [a, b).
fn ratio(m: &[f64], med: &[f64], a: usize, b: usize) -> f64 {
    let (mut s, mut n) = (0.0, 0);
    for i in a..b {
        if m[i] > 0.0 && med[i] > 0.0 {
            s += (m[i] / med[i]).ln();
            n += 1;
        }
    }
    if n == 0 {
        f64::NAN
    } else {
        (s / n as f64).exp()
    }
}

/// How far beyond the edge a point is (≥ 1 outside).
fn beyond(v: f64, lo: f64, hi: f64) -> f64 {
    if v > hi && hi > 0.0 {
        v / hi
    } else if v < lo && v > 0.0 {
        lo / v
    } else {
        1.0
    }
}

/// Outside sides of the measured values against an envelope.
pub fn sides(measured: &[f64], e: &Envelope) -> Vec<i8> {
    (0..e.x.len())
        .map(|i| {
            side(
                measured.get(i).copied().unwrap_or(f64::NAN),
                e.low[i],
                e.high[i],
            )
        })
        .collect()
}

/// Compares measured views with the members'.
pub fn compare(
    measured: Views,
    members: &[Views],
    freqs_hz: &[f64],
    channels: &[String],
) -> Comparison {
    // ADEV: the members' τ are the measured one's (same grid, same gaps).
    let taus: Vec<f64> = measured.adev.iter().map(|p| p.0).collect();
    let adev_members: Vec<Vec<f64>> = members
        .iter()
        .map(|m| m.adev.iter().map(|p| p.1).collect())
        .collect();
    let adev = Envelope::of(&taus, &adev_members);
    let adev_meas: Vec<f64> = measured.adev.iter().map(|p| p.1).collect();
    let psd_members: Vec<Vec<f64>> = members.iter().map(|m| m.psd.clone()).collect();
    let psd = Envelope::of(freqs_hz, &psd_members);
    let coherence: Vec<(String, Envelope)> = channels
        .iter()
        .enumerate()
        .map(|(c, name)| {
            let ys: Vec<Vec<f64>> = members
                .iter()
                .map(|m| m.coherence.get(c).cloned().unwrap_or_default())
                .collect();
            (name.clone(), Envelope::of(freqs_hz, &ys))
        })
        .collect();
    let mut mismatches = Vec::new();
    let s_adev = sides(&adev_meas, &adev);
    push_runs(
        &mut mismatches,
        Quantity::Adev,
        &s_adev,
        &adev_meas,
        &adev,
        None,
    );
    let s_psd = sides(&measured.psd, &psd);
    push_runs(
        &mut mismatches,
        Quantity::Psd,
        &s_psd,
        &measured.psd,
        &psd,
        None,
    );
    for (c, (name, e)) in coherence.iter().enumerate() {
        let m = measured.coherence.get(c).cloned().unwrap_or_default();
        // Only coherence above the envelope is a finding (below: less coherent than noise).
        let s: Vec<i8> = sides(&m, e)
            .iter()
            .zip(&m)
            .map(|(s, v)| {
                if *s > 0 && *v >= COHERENCE_FLOOR {
                    1
                } else {
                    0
                }
            })
            .collect();
        push_runs(&mut mismatches, Quantity::Coherence, &s, &m, e, Some(name));
    }
    Comparison {
        adev_outside_fraction: fraction(&s_adev),
        psd_outside_fraction: fraction(&s_psd),
        member_adev_outside_fraction: leave_one_out(&taus, &adev_members),
        member_psd_outside_fraction: leave_one_out(freqs_hz, &psd_members),
        shown: members.iter().take(2).cloned().collect(),
        adev,
        psd,
        coherence,
        measured,
        mismatches,
    }
}

fn push_runs(
    out: &mut Vec<Mismatch>,
    q: Quantity,
    sides: &[i8],
    m: &[f64],
    e: &Envelope,
    channel: Option<&String>,
) {
    for (a, b, s) in runs(sides) {
        if b - a == 1 && q != Quantity::Coherence {
            let f = beyond(m[a], e.low[a], e.high[a]);
            if f < SINGLE_POINT_FACTOR {
                continue;
            }
        }
        let (from, to, unit) = match q {
            Quantity::Adev => (e.x[a], e.x[b - 1], "s"),
            _ => (e.x[a] * DAY_S, e.x[b - 1] * DAY_S, "cycles/day"),
        };
        let factor = match q {
            Quantity::Coherence => m[a..b].iter().sum::<f64>() / (b - a) as f64,
            _ => ratio(m, &e.median, a, b),
        };
        out.push(Mismatch {
            quantity: q,
            from,
            to,
            unit,
            direction: if s > 0 { "above" } else { "below" },
            factor,
            points: b - a,
            channel: channel.cloned(),
            index: (a, b),
            unmodelled: None,
        });
    }
}

/// τ in words (s, min, h, d).
pub fn tau_words(s: f64) -> String {
    if s < 120.0 {
        format!("{s:.0} s")
    } else if s < 2.0 * 3600.0 {
        format!("{:.0} min", s / 60.0)
    } else if s < 2.0 * DAY_S {
        format!("{:.1} h", s / 3600.0)
    } else {
        format!("{:.1} d", s / DAY_S)
    }
}

/// Frequency in cycles/day in words.
fn cpd_words(f: f64) -> String {
    if f >= 10.0 {
        format!("{f:.0}")
    } else if f >= 1.0 {
        format!("{f:.1}")
    } else {
        format!("{f:.2}")
    }
}

fn factor_words(f: f64) -> String {
    if !f.is_finite() {
        "by an undetermined factor".into()
    } else if f >= 1.0 {
        format!("by ×{}", round2(f))
    } else {
        format!("by ×{}", round2(1.0 / f))
    }
}

fn round2(f: f64) -> String {
    if f >= 9.95 {
        format!("{f:.0}")
    } else {
        format!("{f:.1}")
    }
}

/// The sentence a lab engineer reads.
pub fn sentence(m: &Mismatch) -> String {
    let verb = if m.direction == "above" {
        "underestimates"
    } else {
        "overestimates"
    };
    let range = |w: &dyn Fn(f64) -> String| {
        if m.points == 1 {
            format!("at {}", w(m.from))
        } else {
            format!("from {} to {}", w(m.from), w(m.to))
        }
    };
    match m.quantity {
        Quantity::Adev => format!(
            "the simulation {verb} the Allan deviation of the residual {} {}",
            range(&tau_words),
            factor_words(m.factor)
        ),
        Quantity::Psd => format!(
            "the simulation {verb} the residual's power {} cycles/day {}",
            if m.points == 1 {
                format!("at {}", cpd_words(m.from))
            } else {
                format!("at {}–{}", cpd_words(m.from), cpd_words(m.to))
            },
            factor_words(m.factor)
        ),
        Quantity::Coherence => format!(
            "the residual is coherent with {} at {} cycles/day (coherence {:.2}, above the \
             simulation's 95 % level)",
            m.channel.as_deref().unwrap_or("?"),
            if m.points == 1 {
                cpd_words(m.from)
            } else {
                format!("{}–{}", cpd_words(m.from), cpd_words(m.to))
            },
            m.factor
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env(n: usize) -> Envelope {
        Envelope {
            x: (1..=n).map(|i| i as f64).collect(),
            low: vec![0.8; n],
            median: vec![1.0; n],
            high: vec![1.2; n],
        }
    }

    /// The envelope's limits are placed so that members that are exchangeable (independent
    /// draws of one distribution) lie outside the others' 5–95 % envelope about 10 % of the
    /// time (20 members: the 5 % and 95 % of 19 by interpolation); curves that are identical
    /// never do. This checks where the limits sit, not the twin: for exchangeable members the
    /// figure is a rank statistic, 10 % whatever their distribution. Whether a record drawn
    /// from the model behaves like a member is `tests/twin_envelope.rs`.
    #[test]
    fn the_envelope_limits_leave_a_tenth_of_exchangeable_members_outside() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let x: Vec<f64> = (0..200).map(|i| i as f64).collect();
        let curves: Vec<Vec<f64>> = (0..20)
            .map(|_| x.iter().map(|_| StandardNormal.sample(&mut rng)).collect())
            .collect();
        let f = leave_one_out(&x, &curves);
        assert!((0.07..=0.15).contains(&f), "{f}");
        let same = vec![x.clone(); 20];
        assert_eq!(leave_one_out(&x, &same), 0.0);
    }

    #[test]
    fn runs_outside_become_ranges_and_lone_marginal_points_do_not() {
        let e = env(8);
        let m = [1.0, 3.0, 3.0, 3.0, 1.0, 1.25, 1.0, 0.1];
        let s = sides(&m, &e);
        let mut out = Vec::new();
        push_runs(&mut out, Quantity::Adev, &s, &m, &e, None);
        assert_eq!(out.len(), 2, "{out:?}");
        assert_eq!(
            (out[0].from, out[0].to, out[0].direction),
            (2.0, 4.0, "above")
        );
        assert!((out[0].factor - 3.0).abs() < 1e-12);
        assert_eq!((out[1].from, out[1].direction), (8.0, "below"));
        assert!(
            sentence(&out[0]).contains("underestimates"),
            "{}",
            sentence(&out[0])
        );
        let s1 = sentence(&out[1]);
        assert!(
            s1.contains("overestimates") && s1.ends_with("at 8 s by ×10"),
            "{s1}"
        );
        assert!((fraction(&s) - 5.0 / 8.0).abs() < 1e-12);
    }
}
