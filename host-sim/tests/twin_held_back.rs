//! The extended twin holds real records it was not built on: each half of the gMetrology
//! record's points (≈ 25 days each), analysed on its own as a held-back log, lies outside the extended
//! twin's 5–95 % envelope at no more than 20 % of its Allan-deviation points and of its PSD
//! bands, while a left-out member lies outside 5–15 % of the time.
//!
//! Non-circular: the records are real (the spring's own noise, drift, tide and pressure
//! response); the tool is told nothing about them and each half gets its own catalogue search,
//! noise family, drift order and transients. The halves differ: the first holds the
//! instrument's settling (no accepted cause holds it: the twin's drift carries it in-sample),
//! the second a data gap and the record's three transients. On both
//! halves the selection refuses `tidal_gravity` (forward chaining: the twin's tide is wrong
//! mostly in phase), so the twin must take the tide from the wave-group analysis, and its noise
//! family must not take the tide's lines for noise. The record is binned as `accomp discover`
//! bins it (86 s, 25 000 points per half), 20 members per half: ≈ 5 s per half.

use accomp_host::discover::select;
use accomp_host::discover::simulate::{output, simulate_dataset};

#[path = "common/real.rs"]
mod real;

const MEMBERS: usize = 20;
/// The outside fraction a held-back log may show after the extension.
const RECORD_OUTSIDE_MAX: f64 = 0.20;
/// The range a left-out member's outside fraction must fall in (a 5–95 % envelope: ≈ 10 %).
const MEMBER_OUTSIDE: std::ops::RangeInclusive<f64> = 0.05..=0.15;

fn held_back(a: f64, b: f64) {
    let ds = real::part(a, b);
    let s = simulate_dataset(&ds, None, MEMBERS, &select::Config::default()).expect("simulate");
    let text = output::text(&s, &ds.output_unit);
    eprintln!("part {a}..{b} of the record ({} points):\n{text}", ds.len());
    // Effects were found: the extension holds something beyond the base twin.
    assert!(
        !s.explained_by.is_empty(),
        "nothing found in part {a}..{b}: not a log with found effects\n{text}"
    );
    // The extension does not forecast the rest of the record worse than the base twin.
    assert!(
        s.after_scores.residual_std_out_of_sample <= s.before_scores.residual_std_out_of_sample,
        "extension worsens the out-of-sample residual in part {a}..{b}: {:.4e} → {:.4e}",
        s.before_scores.residual_std_out_of_sample,
        s.after_scores.residual_std_out_of_sample
    );
    let (c, r) = (&s.before, &s.after);
    // Nor does it leave more of the record outside than the base twin did.
    assert!(
        r.adev_outside_fraction <= c.adev_outside_fraction
            && r.psd_outside_fraction <= c.psd_outside_fraction,
        "extension leaves more outside in part {a}..{b}"
    );
    eprintln!(
        "part {a}..{b}: ADEV outside {:.1} % → {:.1} %, PSD {:.1} % → {:.1} %; member {:.1} % / \
         {:.1} %",
        100.0 * c.adev_outside_fraction,
        100.0 * r.adev_outside_fraction,
        100.0 * c.psd_outside_fraction,
        100.0 * r.psd_outside_fraction,
        100.0 * r.member_adev_outside_fraction,
        100.0 * r.member_psd_outside_fraction
    );
    for (what, v) in [
        ("member ADEV", r.member_adev_outside_fraction),
        ("member PSD", r.member_psd_outside_fraction),
    ] {
        assert!(
            MEMBER_OUTSIDE.contains(&v),
            "{what} outside fraction {v:.3} in part {a}..{b}"
        );
    }
    for (what, v) in [
        ("ADEV", r.adev_outside_fraction),
        ("PSD", r.psd_outside_fraction),
    ] {
        assert!(
            v <= RECORD_OUTSIDE_MAX,
            "{what}: {:.1} % of part {a}..{b} outside the extended twin's envelope\n{text}",
            100.0 * v
        );
    }
}

// The first half starts with the spring's settling, a slow drift discovery refuses as a
// `warmup` (over before the first forward cut, it forecasts the rest worse): no accepted cause
// holds it. The twin's drift carries it in-sample (an exponential fitted with the drift
// polynomial, removed from the record and every member, each member drawing its τ and
// amplitude), so the half lies inside the envelope like the second: measured with 20 members
// ADEV 46.2 → 0.0 %, PSD 20.0 → 8.0 % outside (before → after the extension); the settling
// 0.067 ± 0.004 mGal, τ 0.81 ± 0.14 d.
#[test]
fn the_first_half_of_the_real_record_held_back_lies_inside_the_extended_twins_envelope() {
    held_back(0.0, 0.5);
}

#[test]
fn the_second_half_of_the_real_record_held_back_lies_inside_the_extended_twins_envelope() {
    held_back(0.5, 1.0);
}
