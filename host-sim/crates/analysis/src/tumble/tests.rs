//! Tests of the tumble analysis (round trips through the simulator are in tests/tumble_roundtrip.rs).

use super::*;

const K1: f64 = 1.3;
const K0: f64 = 0.005;
const K2: f64 = 2e-5;
/// 2 arcmin in rad, written out: 2·π/10800.
const DELTA_RAD: f64 = 2.0 * std::f64::consts::PI / 10_800.0;

/// A log whose outputs are equation (1) written out by hand (not through the core), with the
/// head at `angle + tilt` and one row per entry of `readings` (offsets added to E).
#[derive(Clone, Copy)]
struct HandLog<'a> {
    axis: &'a str,
    angles_deg: &'a [f64],
    /// Local gravity, standard g.
    g: f64,
    k3: f64,
    tilt_rad: f64,
    readings: &'a [f64],
    /// `# key: value` lines written before the header.
    extra_meta: &'a str,
}

/// The classic four-position test (0°, 90°, 180°, 270°).
const FOUR_POSITIONS_DEG: [f64; 4] = [0.0, 90.0, 180.0, 270.0];

impl<'a> HandLog<'a> {
    /// An exact four-position log about `axis` at 1 g: no K3, no tilt, one noiseless reading
    /// per position.
    fn four_positions(axis: &'a str) -> Self {
        HandLog::at(axis, &FOUR_POSITIONS_DEG)
    }

    /// The same exact log at `angles_deg`.
    fn at(axis: &'a str, angles_deg: &'a [f64]) -> Self {
        HandLog {
            axis,
            angles_deg,
            g: 1.0,
            k3: 0.0,
            tilt_rad: 0.0,
            readings: &[0.0],
            extra_meta: "",
        }
    }

    fn text(self) -> String {
        let HandLog {
            axis,
            angles_deg,
            g,
            k3,
            tilt_rad,
            readings,
            extra_meta,
        } = self;
        let mut s = format!("# rotation_axis: {axis}\n{extra_meta}angle_deg,output_v\n");
        for &a in angles_deg {
            let th = a.to_radians() + tilt_rad;
            let ai = g * th.sin();
            let cross = g * th.cos();
            let mis = if axis == "output" {
                DELTA_RAD * cross
            } else {
                -DELTA_RAD * cross
            };
            let e = K1 * (K0 + ai + K2 * ai * ai + k3 * ai * ai * ai + mis);
            for d in readings {
                s.push_str(&format!("{a},{}\n", e + d));
            }
        }
        s
    }
}

/// [`HandLog::four_positions`] as text.
fn four_position_log(axis: &str) -> String {
    HandLog::four_positions(axis).text()
}

fn solve(text: &str) -> Result<TumbleReport, TumbleError> {
    solve_log(&parse_log(text)?, &TumbleOptions::default())
}

fn zero_index() -> TumbleOptions {
    TumbleOptions {
        index_error_arcsec: Some(0.0),
        ..TumbleOptions::default()
    }
}

#[test]
fn four_noise_free_positions_recover_k0_k1_k2_and_delta_p_exactly() {
    let r = solve(&four_position_log("pendulum")).unwrap();
    let t = &r.tests[0];
    assert_eq!(
        (t.fit.unknowns, t.fit.dof, t.fit.noise_basis),
        (4, 0, NoiseBasis::None)
    );
    assert!((t.coefficients.k1_v_per_g.value - K1).abs() < 1e-14);
    assert!((t.coefficients.k0_g.value - K0).abs() < 1e-15);
    assert!((t.coefficients.k2_g_per_g2.value - K2).abs() < 1e-14);
    assert!((t.coefficients.misalignment_arcmin.value - 2.0).abs() < 1e-10);
    assert!(t.coefficients.k3_g_per_g3.is_none());
    let f = t.four_point.unwrap();
    assert!((f.k0_g - K0).abs() < 1e-15 && (f.k1_v_per_g - K1).abs() < 1e-14);
    assert!((f.k2_g_per_g2 - K2).abs() < 1e-14);
    assert!((f.misalignment_arcmin - 2.0).abs() < 1e-10);
}

#[test]
fn rotation_about_the_output_axis_identifies_delta_o_with_its_own_sign() {
    let r = solve(&four_position_log("output")).unwrap();
    let t = &r.tests[0];
    assert_eq!(t.rotation_axis, RotationAxis::Output);
    assert!((t.coefficients.misalignment_arcmin.value - 2.0).abs() < 1e-10);
    // E0 − E180 = +2·K1·δo·g for the output axis.
    let f = t.four_point.unwrap();
    assert!((f.zero_difference_v - 2.0 * K1 * DELTA_RAD).abs() < 1e-15);
    assert!((f.misalignment_arcmin - 2.0).abs() < 1e-10);
}

#[test]
fn eight_positions_add_k3_and_recover_it() {
    let angles: Vec<f64> = (0..8).map(|i| 45.0 * f64::from(i)).collect();
    let r = solve(
        &HandLog {
            k3: 3e-5,
            ..HandLog::at("pendulum", &angles)
        }
        .text(),
    )
    .unwrap();
    let t = &r.tests[0];
    assert_eq!((t.fit.unknowns, t.fit.dof), (5, 3));
    assert!((t.coefficients.k3_g_per_g3.unwrap().value - 3e-5).abs() < 1e-13);
    assert!((t.coefficients.k1_v_per_g.value - K1).abs() < 1e-13);
    // The four-point K1 absorbs K3: (E90 − E270)/2 = K1·(1 + K3).
    let f = t.four_point.unwrap();
    assert!((f.k1_v_per_g - K1 * (1.0 + 3e-5)).abs() < 1e-13);
}

#[test]
fn local_gravity_from_metadata_is_divided_by_standard_gravity() {
    let g = 9.7940 / 9.80665;
    let text = HandLog {
        g,
        extra_meta: "# local_gravity_m_s2: 9.7940\n",
        ..HandLog::four_positions("pendulum")
    }
    .text();
    let r = solve(&text).unwrap();
    assert!((r.gravity_g - g).abs() < 1e-15);
    assert!((r.tests[0].coefficients.k1_v_per_g.value - K1).abs() < 1e-13);
    // Ignoring local gravity (1 g forced) makes K1 wrong by the gravity ratio.
    let forced = solve_log(
        &parse_log(&text).unwrap(),
        &TumbleOptions {
            gravity_g: Some(1.0),
            ..TumbleOptions::default()
        },
    )
    .unwrap();
    assert!((forced.tests[0].coefficients.k1_v_per_g.value - K1 * g).abs() < 1e-13);
}

#[test]
fn index_error_propagates_to_half_the_angle_variance_at_four_points() {
    // Hand propagation for 0/90/180/270 with σθ = 0.2": K0 and δ are half-sum and
    // half-difference of E0 and E180, where dE/dθ = ±K1·g, so σ(K0) = σθ·g/√2 and
    // σ(δ) = σθ/√2; K2 also gets σθ/√2 (E0, E180 enter it with weight 1/(2K1)).
    let r = solve(&four_position_log("pendulum")).unwrap();
    let t = &r.tests[0];
    let sigma_rad = 0.2 * 4.848_136_811e-6;
    let half = sigma_rad / std::f64::consts::SQRT_2;
    assert!(t.coefficients.k0_g.se_noise.is_none());
    assert!(
        (t.coefficients.k0_g.se_index / half - 1.0).abs() < 1e-3,
        "{}",
        t.coefficients.k0_g.se_index
    );
    assert!((t.coefficients.k2_g_per_g2.se / half - 1.0).abs() < 1e-3);
    let delta_arcmin = 0.2 / 60.0 / std::f64::consts::SQRT_2;
    assert!((t.coefficients.misalignment_arcmin.se / delta_arcmin - 1.0).abs() < 1e-3);
    // K1 only sees dE/dθ = ±K1·δ at 90°/270°: σ = K1·δ·σθ/√2 ≈ 1e-9 V/g.
    assert!((t.coefficients.k1_v_per_g.se / (K1 * DELTA_RAD * half) - 1.0).abs() < 1e-2);
}

#[test]
fn reading_scatter_gives_the_noise_se_when_the_design_is_exactly_determined() {
    // Two readings ±d per position: sample sd d·√2, SE of each mean d. K0 = c0/c1 with
    // c0 = (E0+E180)/2 and c1 = (E90−E270)/2 independent, each of variance d²/2, so
    // σ²(K0) = (d²/2)·(1 + K0²)/K1².
    let d = 1e-6;
    let log = parse_log(
        &HandLog {
            readings: &[-d, d],
            ..HandLog::four_positions("pendulum")
        }
        .text(),
    )
    .unwrap();
    let r = solve_log(&log, &zero_index()).unwrap();
    let t = &r.tests[0];
    assert_eq!(t.fit.noise_basis, NoiseBasis::ReadingScatter);
    assert_eq!(t.positions[0].readings, 2);
    assert!((t.positions[0].scatter_v.unwrap() - d * std::f64::consts::SQRT_2).abs() < 1e-12);
    let expect = d * ((1.0 + K0 * K0) / 2.0).sqrt() / K1;
    assert!(
        (t.coefficients.k0_g.se / expect - 1.0).abs() < 1e-6,
        "{}",
        t.coefficients.k0_g.se
    );
    assert_eq!(t.coefficients.k0_g.se_index, 0.0);
}

#[test]
fn residual_se_is_used_when_there_are_more_positions_than_unknowns() {
    // Twelve positions, one reading each, one output off by ε: the residuals are non-zero
    // and sum to zero (the constant column), and the SE basis is the residuals.
    let angles: Vec<f64> = (0..12).map(|i| 30.0 * f64::from(i)).collect();
    let mut text = HandLog::at("pendulum", &angles).text();
    text = text.replacen("\n30,", "\n30,1e-6+", 1);
    // "1e-6+x" is not a number: this checks the malformed-row path on the way.
    assert!(matches!(
        solve(&text),
        Err(TumbleError::Malformed { line: 4, .. })
    ));
    let mut lines: Vec<String> = HandLog::at("pendulum", &angles)
        .text()
        .lines()
        .map(String::from)
        .collect();
    let (a, e) = lines[3].split_once(',').unwrap();
    lines[3] = format!("{a},{}", e.parse::<f64>().unwrap() + 1e-6);
    let r = solve_log(&parse_log(&lines.join("\n")).unwrap(), &zero_index()).unwrap();
    let t = &r.tests[0];
    assert_eq!(
        (t.fit.unknowns, t.fit.dof, t.fit.noise_basis),
        (5, 7, NoiseBasis::Residuals)
    );
    let sum: f64 = t.positions.iter().map(|p| p.residual_v).sum();
    assert!(sum.abs() < 1e-15);
    assert!(t.fit.rms_residual_v > 1e-8 && t.coefficients.k0_g.se_noise.unwrap() > 0.0);
}

#[test]
fn foundation_tilt_cancels_in_the_bias_and_enters_the_misalignment_fully() {
    // Tilt φ = 1": the zero difference E0 − E180 grows by 2·K1·φ (tilt counted twice), so
    // δ = difference/(2·K1·g) is off by φ = 1/60 arcmin; the sum (bias) is unchanged.
    let phi = 4.848_136_811e-6;
    let r = solve(
        &HandLog {
            tilt_rad: phi,
            ..HandLog::four_positions("output")
        }
        .text(),
    )
    .unwrap();
    let f = r.tests[0].four_point.unwrap();
    // Sum: 2·K1·(K0 + K2·sin²φ); K2·φ² is 5e-16 g, the rest is rounding of π in the
    // head angle — nine orders below the 2·K1·φ = 1.3e-5 V the tilt puts into the difference.
    assert!((f.zero_sum_v - 2.0 * K1 * K0).abs() < 1e-14);
    // The four-point K1 carries (1 − δo·φ) from the 90°/270° pair, hence 1e-10 on K0.
    assert!((f.k0_g - K0).abs() < 1e-10);
    assert!((f.zero_difference_v - 2.0 * K1 * (DELTA_RAD + phi)).abs() < 1e-12);
    assert!((f.misalignment_arcmin - (2.0 + 1.0 / 60.0)).abs() < 1e-6);
    assert!((r.tests[0].coefficients.misalignment_arcmin.value - (2.0 + 1.0 / 60.0)).abs() < 1e-6);
}

#[test]
fn fewer_positions_than_unknowns_is_refused_with_counts() {
    let e = solve(&HandLog::at("pendulum", &[0.0, 120.0, 240.0]).text());
    assert_eq!(
        e,
        Err(TumbleError::TooFewPositions {
            test: "1".into(),
            positions: 3,
            unknowns: 4
        })
    );
}

#[test]
fn positions_within_half_a_circle_are_refused() {
    let e = solve(&HandLog::at("pendulum", &[0.0, 45.0, 90.0, 135.0, 180.0]).text());
    assert!(matches!(
        e,
        Err(TumbleError::AnglesDoNotCoverCircle { largest_gap_deg, .. }) if (largest_gap_deg - 180.0).abs() < 1e-9
    ));
}

#[test]
fn six_equally_spaced_positions_fit_four_unknowns_but_would_alias_k3() {
    // At multiples of 60°, sin 3θ = 0, so sin³θ = ¾·sin θ: K3 is not separable from K1.
    // Below 8 positions K3 is not fitted, so six positions solve with 2 dof.
    let angles: Vec<f64> = (0..6).map(|i| 60.0 * f64::from(i)).collect();
    let r = solve(&HandLog::at("pendulum", &angles).text()).unwrap();
    assert_eq!((r.tests[0].fit.unknowns, r.tests[0].fit.dof), (4, 2));
    for th in &angles {
        let s = th.to_radians().sin();
        assert!((s.powi(3) - 0.75 * s).abs() < 1e-15);
    }
}

#[test]
fn nan_output_is_refused_with_its_line() {
    let text = "# rotation_axis: output\nangle_deg,output_v\n0,0.1\n90,NaN\n";
    assert_eq!(
        parse_log(text),
        Err(TumbleError::NonFinite {
            line: 4,
            column: "output_v".into()
        })
    );
}

#[test]
fn malformed_rows_and_missing_columns_are_named() {
    assert!(matches!(
        parse_log("angle_deg,output_v\n0,0.1\n90\n"),
        Err(TumbleError::Malformed { line: 3, .. })
    ));
    assert!(matches!(
        parse_log("angle_deg,output_v\n0,abc\n"),
        Err(TumbleError::Malformed { line: 2, .. })
    ));
    assert_eq!(
        parse_log("angle_deg,volts\n0,1\n"),
        Err(TumbleError::MissingColumn("output_v"))
    );
    assert_eq!(parse_log("# only: comments\n"), Err(TumbleError::NoHeader));
    assert_eq!(parse_log("angle_deg,output_v\n"), Err(TumbleError::Empty));
}

#[test]
fn the_rotation_axis_must_be_stated() {
    let text = four_position_log("pendulum").replace("# rotation_axis: pendulum\n", "");
    assert_eq!(solve(&text), Err(TumbleError::MissingRotationAxis));
    let bad = four_position_log("pendulum").replace("pendulum", "input");
    assert!(matches!(solve(&bad), Err(TumbleError::BadParameter { .. })));
}

#[test]
fn without_a_test_column_a_restarted_sequence_or_a_time_gap_starts_a_new_test() {
    let rows = |t0: f64| -> String {
        [0.0, 90.0, 180.0, 270.0]
            .iter()
            .enumerate()
            .map(|(i, a)| {
                let th: f64 = f64::to_radians(*a);
                let e = K1 * (K0 + th.sin());
                format!("{},{a},{e}\n", t0 + 10.0 * i as f64)
            })
            .collect()
    };
    // Two sequences back to back: the return to 0° starts test 2 at line 7.
    let text = format!(
        "# rotation_axis: pendulum\ntime_s,angle_deg,output_v\n{}{}",
        rows(0.0),
        rows(40.0)
    );
    let r = solve(&text).unwrap();
    assert_eq!(r.tests.len(), 2);
    assert_eq!(r.tests[1].first_line, 7);
    // A gap alone: 0, 90 | gap | 180, 270, … must split even though no angle repeats.
    let log = parse_log(
        "# rotation_axis: pendulum\ntime_s,angle_deg,output_v\n0,0,1\n10,90,1\n9000,180,1\n9010,270,1\n",
    )
    .unwrap();
    let tests = split_tests(&log.rows, DEFAULT_TEST_GAP_S);
    assert_eq!(tests.len(), 2);
    assert_eq!(tests[1].1[0].line, 5);
}

#[test]
fn regression_on_time_matches_a_hand_computed_example() {
    // t = 0..3, y = 1, 3, 2, 5: slope 5.5/5 = 1.1, RSS 2.7, s = √1.35, SE(slope) = s/√5.
    let (mean, b, bse, s) = regress_on_time(&[0.0, 1.0, 2.0, 3.0], &[1.0, 3.0, 2.0, 5.0]).unwrap();
    assert!((mean - 2.75).abs() < 1e-15);
    assert!((b - 1.1).abs() < 1e-14);
    assert!((s - 1.35f64.sqrt()).abs() < 1e-14);
    assert!((bse - 1.35f64.sqrt() / 5f64.sqrt()).abs() < 1e-14);
    assert!(regress_on_time(&[0.0, 1.0], &[1.0, 2.0]).is_none());
}

#[test]
fn table_combines_a_pendulum_and_an_output_log_into_both_misalignment_columns() {
    let with_t = |axis: &str| {
        HandLog {
            readings: &[-1e-6, 1e-6],
            ..HandLog::four_positions(axis)
        }
        .text()
        .replace("angle_deg,output_v\n", "angle_deg,output_v,temperature_c\n")
        .lines()
        .map(|l| {
            if l.starts_with('#') || l.starts_with("angle") {
                l.to_string()
            } else {
                format!("{l},50.0")
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
    };
    let a = parse_log(&with_t("pendulum")).unwrap();
    let b = parse_log(&with_t("output")).unwrap();
    let r = analyse(&[&a, &b], &TumbleOptions::default()).unwrap();
    let csv = table_csv(&r, false).unwrap();
    let mut data = csv.lines().filter(|l| !l.starts_with('#'));
    assert_eq!(
        data.next(),
        Some("temperature_c,k0_g,k1_v_per_g,k2_g_per_g2,delta_p_arcmin,delta_o_arcmin")
    );
    let row: Vec<f64> = data
        .next()
        .unwrap()
        .split(',')
        .map(|c| c.parse().unwrap())
        .collect();
    assert_eq!(row[0], 50.0);
    assert!((row[1] - K0).abs() < 1e-12 && (row[2] - K1).abs() < 1e-12);
    assert!((row[4] - 2.0).abs() < 1e-6 && (row[5] - 2.0).abs() < 1e-6);
    assert!(data.next().is_none());
}

#[test]
fn a_reversed_angle_sense_is_refused_as_a_negative_scale_factor() {
    // θ → −θ: the 90° and 270° readings swap.
    let text = four_position_log("pendulum")
        .replace("\n90,", "\nX,")
        .replace("\n270,", "\n90,")
        .replace("\nX,", "\n270,");
    assert!(matches!(
        solve(&text),
        Err(TumbleError::BadScaleFactor { k1, .. }) if (k1 + K1).abs() < 1e-12
    ));
}

#[test]
fn table_needs_a_temperature_per_test() {
    let r = solve(&four_position_log("pendulum")).unwrap();
    assert_eq!(
        table_csv(&r, false),
        Err(TumbleError::NoTemperature("1".into()))
    );
}
