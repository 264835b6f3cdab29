//! A transient that the rest of the record refutes is not a finding. The first half of the real
//! gMetrology record (25.5 d, the CLI's binning) starts with the spring's settling, which
//! continues as a slow non-linear drift: an exponential fits its first day (ΔBIC ≈ −119,
//! blocked cross-validation better) but, fitted with the drift on the first part of the
//! record, it moves the drift's slope and the rest of the record is forecast worse than the
//! noise model predicts. Nothing is hidden or told: the tool runs on the measured rows.

#[path = "common/hidden.rs"]
mod hidden;
#[path = "common/real.rs"]
mod real;

use accomp_host::discover::{discover, select};

#[test]
fn a_settling_transient_that_worsens_the_forecast_of_the_rest_is_refused() {
    let ds = real::part(0.0, 0.5);
    let d = discover(ds, None, &select::Config::default()).expect("discovery");
    eprintln!("{}", accomp_host::discover::report::text(&d));
    let acc = &d.selection.accepted;
    // No accepted effect may make the forward forecast worse than before it and worse than
    // the noise model's own prediction of its errors (normalised prediction z above 1).
    for a in acc {
        let (b, f) = (a.forward_before.prediction_z, a.forward_after.prediction_z);
        assert!(
            f <= b.max(1.0),
            "{} accepted with forward prediction z {b:.4} → {f:.4}",
            a.effect.name()
        );
    }
    assert!(
        !acc.iter().any(|a| a.effect.name() == "warmup"),
        "warm-up accepted on the first half: {:?}",
        acc.iter().map(|a| a.effect.name()).collect::<Vec<_>>()
    );
    // Refused, with why (it passed the criterion and the blocked cross-validation).
    let why = hidden::refusal(&d, "warmup");
    assert!(
        why.contains("forward"),
        "warmup not refused for the forecast: {why:?}"
    );
    // The earth tide is still named.
    assert!(acc.iter().any(|a| a.effect.name() == "tidal_gravity"));
}
