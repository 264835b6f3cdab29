//! Round trip of issue 7: simulate tumble tests at Table 1's eight temperatures from known
//! temperature models, solve them with `accomp tumble`, fit the resulting coefficient table with
//! `accomp fit`'s least squares, and check that the true models are recovered within the stated
//! uncertainties. Seeded, so every run sees the same noise.

use accomp::units::{Celsius, RAD_PER_ARCMIN};
use accomp_host::fit;
use accomp_host::tumble::{self, TumbleOptions};
use accomp_host::tumble_sim::{simulate_tumble, TumbleSimConfig};

#[path = "common/scratch.rs"]
mod scratch;

/// True values of the four table columns at T, from the generator's models.
fn truth_at(cfg: &TumbleSimConfig, t: f64) -> [f64; 4] {
    let (k, _) = cfg.models.coefficients_at(Celsius(t)).unwrap();
    [
        k.bias_g,
        k.scale_factor_v_per_g,
        k.nonlinearity_g_per_g2,
        k.misalignment_p.0 / RAD_PER_ARCMIN,
    ]
}

const COLUMNS: [&str; 4] = ["k0_g", "k1_v_per_g", "k2_g_per_g2", "delta_p_arcmin"];

/// Two-sided 99.73 % (the "3σ" coverage) quantile of Student's t with 8 − 3 = 5 degrees of
/// freedom: an unweighted order-2 fit estimates its own σ from five residual dof, so its
/// prediction interval is t-distributed, not normal (scipy.stats.t.ppf(0.99865, 5) = 5.507).
const T5_3SIGMA: f64 = 5.507;

struct Outcome {
    /// Largest |fit(T_i) − true(T_i)| / (√h_ii · s) of `accomp fit`'s unweighted order-2 fit.
    worst_fit_t: f64,
    /// Largest |fit(T_i) − true(T_i)| / σ_pred(T_i) of the order-2 fit weighted by the tumble's
    /// stated SEs (σ known, so normal).
    worst_weighted_sigma: f64,
    /// Σ ((tumble estimate − truth)/stated SE)² over 8 temperatures × 4 coefficients.
    chi2_tumble: f64,
}

fn round_trip(cfg: &TumbleSimConfig) -> Outcome {
    let (log_text, truth) = simulate_tumble(cfg).unwrap();
    assert_eq!(truth.len(), 8);
    let log = tumble::parse_log(&log_text).unwrap();
    let report = tumble::solve_log(&log, &TumbleOptions::default()).unwrap();
    assert_eq!(report.tests.len(), 8);

    // The tumble estimates against the truth, in units of their stated SE.
    let mut chi2_tumble = 0.0;
    for t in &report.tests {
        let truth = truth_at(cfg, t.temperature.mean_c.unwrap());
        let est = [
            t.coefficients.k0_g,
            t.coefficients.k1_v_per_g,
            t.coefficients.k2_g_per_g2,
            t.coefficients.misalignment_arcmin,
        ];
        for (e, v) in est.iter().zip(truth) {
            chi2_tumble += ((e.value - v) / e.se).powi(2);
        }
    }

    // The table goes through fit's own CSV parser (format compatibility) and least squares.
    let csv = tumble::table_csv(&report, false).unwrap();
    let table = fit::parse_coefficient_table(&csv).unwrap();
    let names: Vec<&str> = table.columns.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, COLUMNS);
    let scale = table.scale().unwrap();
    let temps = &table.temperatures_c;
    let design: Vec<Vec<f64>> = temps
        .iter()
        .map(|t| {
            let x = scale.x_unclamped(Celsius(*t));
            vec![1.0, x, x * x]
        })
        .collect();
    let mut worst_fit_t: f64 = 0.0;
    let mut worst_weighted_sigma: f64 = 0.0;
    for (j, col) in table.columns.iter().enumerate() {
        let se: Vec<f64> = report
            .tests
            .iter()
            .map(|t| match j {
                0 => t.coefficients.k0_g.se,
                1 => t.coefficients.k1_v_per_g.se,
                2 => t.coefficients.k2_g_per_g2.se,
                _ => t.coefficients.misalignment_arcmin.se,
            })
            .collect();
        let (order2, _) =
            fit::fit_order(&col.name, &scale, temps, &col.values, 2, Celsius(50.0)).unwrap();
        // Prediction SE of the fitted polynomial at each table temperature: √h_ii · s, with
        // the leverage of the same design from fit's QR.
        let ls = accomp_host::numerics::linalg::least_squares(&design, &col.values).unwrap();
        for (i, t) in temps.iter().enumerate() {
            let x = scale.x_unclamped(Celsius(*t));
            let fitted = order2.coeffs_x[0] + order2.coeffs_x[1] * x + order2.coeffs_x[2] * x * x;
            let sigma = ls.leverage[i].sqrt() * order2.scores.residual_std;
            let dev = (fitted - truth_at(cfg, *t)[j]).abs() / sigma;
            worst_fit_t = worst_fit_t.max(dev);
        }
        // Weighted: rows divided by the stated SE; then the weighted hat diagonal gives
        // σ_pred,i = √h_ii · se_i. (Rows are in temperature order in both the report and the
        // table because the simulation steps the temperature upwards.)
        let wdesign: Vec<Vec<f64>> = design
            .iter()
            .zip(&se)
            .map(|(r, s)| r.iter().map(|v| v / s).collect())
            .collect();
        let wy: Vec<f64> = col.values.iter().zip(&se).map(|(v, s)| v / s).collect();
        let w = accomp_host::numerics::linalg::least_squares(&wdesign, &wy).unwrap();
        for (i, t) in temps.iter().enumerate() {
            let x = scale.x_unclamped(Celsius(*t));
            let fitted = w.coeffs[0] + w.coeffs[1] * x + w.coeffs[2] * x * x;
            let sigma = w.leverage[i].sqrt() * se[i];
            let dev = (fitted - truth_at(cfg, *t)[j]).abs() / sigma;
            worst_weighted_sigma = worst_weighted_sigma.max(dev);
        }
    }
    Outcome {
        worst_fit_t,
        worst_weighted_sigma,
        chi2_tumble,
    }
}

/// Binomial count bounds: the number of failures k out of n trials at per-trial probability p
/// lies in [lo, hi] with probability ≥ 99.9 % (normal approximation with continuity, widened to
/// at least 0..=1 above zero; fine for n·p ≥ 1).
fn binomial_bounds(n: usize, p: f64) -> (usize, usize) {
    let (m, s) = (n as f64 * p, (n as f64 * p * (1.0 - p)).sqrt());
    let lo = (m - 3.29 * s - 0.5).floor().max(0.0) as usize;
    let hi = (m + 3.29 * s + 0.5).ceil().max(1.0) as usize;
    (lo, hi)
}

/// The stated uncertainties are honest over many seeds, not only for the two fixed ones below:
/// over 200 seeds of the four-point tumble the three checks of `round_trip` fail about as often
/// as their significance levels say. (Per seed: 32 weighted checks at 3σ fail with probability
/// 1 − 0.9973³² = 8.3 %; χ²(32) leaves 12…63 with 0.2 %; the unweighted t₅ checks at 0.27 %
/// each, 32 per seed, 8.3 %, but the 32 are correlated within a coefficient, so only an upper
/// bound is asserted for them.) Figures quoted in docs/tumble.md.
#[test]
fn over_200_seeds_the_round_trip_checks_fail_at_their_stated_rates() {
    const SEEDS: usize = 200;
    let (mut unweighted, mut weighted, mut chi2_out) = (0, 0, 0);
    for seed in 1..=SEEDS as u64 {
        let cfg = TumbleSimConfig::table1_default(seed).unwrap();
        let o = round_trip(&cfg);
        unweighted += usize::from(o.worst_fit_t >= T5_3SIGMA);
        weighted += usize::from(o.worst_weighted_sigma >= 3.0);
        chi2_out += usize::from(!(12.0..63.0).contains(&o.chi2_tumble));
    }
    eprintln!(
        "4 positions, {SEEDS} seeds: unweighted > t5 {unweighted}, weighted > 3σ {weighted}, \
         χ² outside {chi2_out}"
    );
    let per_seed_3sigma = 1.0 - (1.0 - 0.0027f64).powi(32);
    let (lo, hi) = binomial_bounds(SEEDS, per_seed_3sigma);
    assert!(
        (lo..=hi).contains(&weighted),
        "weighted fit beyond 3σ in {weighted}/{SEEDS} seeds, expected {lo}..={hi}"
    );
    let (_, hi_chi2) = binomial_bounds(SEEDS, 0.002);
    assert!(
        chi2_out <= hi_chi2,
        "χ² outside 12..63 in {chi2_out}/{SEEDS} seeds, at most {hi_chi2} expected"
    );
    let (_, hi_t) = binomial_bounds(SEEDS, per_seed_3sigma);
    assert!(
        unweighted <= hi_t,
        "unweighted fit beyond t5 in {unweighted}/{SEEDS} seeds, at most {hi_t} expected"
    );
}

/// The three checks of a round trip: both order-2 fits within 3σ of the truth, and the tumble's
/// 32 estimates consistent with their stated SEs.
fn assert_recovers_the_true_models(o: &Outcome) {
    assert!(
        o.worst_fit_t < T5_3SIGMA,
        "accomp fit's order-2 model deviates {:.2} s·√h from the true model",
        o.worst_fit_t
    );
    assert!(
        o.worst_weighted_sigma < 3.0,
        "the weighted order-2 fit deviates {:.2} σ from the true model",
        o.worst_weighted_sigma
    );
    // 32 normalized deviations: χ²(32) lies in 12..63 with 99.8 % probability. Above, the
    // stated SEs are too small; below, they are inflated.
    assert!(
        (12.0..63.0).contains(&o.chi2_tumble),
        "χ² of the tumble estimates {:.1} for 32 values",
        o.chi2_tumble
    );
}

#[test]
fn eight_temperatures_four_point_tumble_then_fit_recover_the_true_order2_models() {
    let cfg = TumbleSimConfig::table1_default(7).unwrap();
    assert_recovers_the_true_models(&round_trip(&cfg));
}

#[test]
fn eight_temperatures_twelve_point_tumble_with_k3_then_fit_recover_the_true_models() {
    let mut cfg = TumbleSimConfig::table1_default(11).unwrap();
    cfg.positions = 12;
    cfg.k3_g_per_g3 = 2e-5;
    assert_recovers_the_true_models(&round_trip(&cfg));
}

#[test]
fn repeated_tests_give_the_bias_drift_within_its_slope_uncertainty() {
    let mut cfg = TumbleSimConfig::table1_default(5).unwrap();
    cfg.temperatures_c = vec![60.0];
    cfg.repeats = 10;
    cfg.test_gap_s = 86_400.0;
    cfg.bias_drift_g_per_day = 3e-6;
    let (text, truth) = simulate_tumble(&cfg).unwrap();
    let report = tumble::solve_log(
        &tumble::parse_log(&text).unwrap(),
        &TumbleOptions::default(),
    )
    .unwrap();
    assert_eq!(report.stability.len(), 1);
    let g = &report.stability[0];
    assert_eq!(g.tests, 10);
    let k0 = g
        .coefficients
        .iter()
        .find(|c| c.coefficient == "k0_g")
        .unwrap();
    assert!(
        (k0.slope_per_day - 3e-6).abs() < 3.0 * k0.slope_se_per_day,
        "slope {:e} ± {:e}",
        k0.slope_per_day,
        k0.slope_se_per_day
    );
    // Without drift in K1, its regression sd is the test-to-test scatter: compare with the
    // stated SE of a single test (same order, within a factor 3 either way).
    let k1 = g
        .coefficients
        .iter()
        .find(|c| c.coefficient == "k1_v_per_g")
        .unwrap();
    let se1 = report.tests[0].coefficients.k1_v_per_g.se;
    assert!(k1.regression_sd > se1 / 3.0 && k1.regression_sd < 3.0 * se1);
    assert!((truth[9].coefficients.bias_g - truth[0].coefficients.bias_g) > 0.0);
}

#[test]
fn the_cli_chain_simulate_tumble_fit_runs_and_fit_reads_the_table() {
    let dir = scratch::Scratch::new("tumble");
    let log = dir.join("tumble.csv");
    let table = dir.join("coefficients.csv");
    let exe = env!("CARGO_BIN_EXE_accomp");
    let run = |args: &[&str]| {
        let out = std::process::Command::new(exe).args(args).output().unwrap();
        assert!(
            out.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8(out.stdout).unwrap()
    };
    run(&[
        "simulate-tumble",
        "--seed",
        "3",
        "-o",
        log.to_str().unwrap(),
    ]);
    let json = run(&[
        "tumble",
        log.to_str().unwrap(),
        "--json",
        "-o",
        table.to_str().unwrap(),
    ]);
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(v["tests"].as_array().unwrap().len(), 8);
    assert_eq!(v["gravity_g"], 1.0);
    let fitted = run(&["fit", table.to_str().unwrap(), "--json"]);
    let f: serde_json::Value = serde_json::from_str(&fitted).unwrap();
    let names: Vec<&str> = f["coefficients"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["name"].as_str().unwrap())
        .collect();
    assert_eq!(
        names,
        ["k0_g", "k1_v_per_g", "k2_g_per_g2", "delta_p_arcmin"]
    );
    // A bad log fails with the line number in the message.
    std::fs::write(
        &log,
        "# rotation_axis: output\nangle_deg,output_v\n0,0.1\n90,nan\n",
    )
    .unwrap();
    let out = std::process::Command::new(exe)
        .args(["tumble", log.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("line 4"));
}
