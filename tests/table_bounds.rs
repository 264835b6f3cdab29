//! Issue #15.6: the table validator refuses coefficients outside physical bounds, and the
//! pipeline never reports a frame without an invalid flag while one of its fields is not finite.

use accomp::pipeline::{self, ChannelFlags, RawSample, Status};
use accomp::poly::{TempPoly, TemperatureScale};
use accomp::reference::paper_order2_table;
use accomp::table::{bounds, CalibrationTable, Coefficient, Field, TableError, ENCODED_LEN};
use accomp::units::{Celsius, TiltArcsec};
use proptest::prelude::*;

fn refused(t: &CalibrationTable) -> Option<TableError> {
    CalibrationTable::decode(&t.encode()).err()
}

#[test]
fn absurd_values_from_the_issue_are_refused_by_name() {
    // K2 = 1e10 g/g² used to pass with status OK.
    let mut t = paper_order2_table();
    t.thermal.models.nonlinearity_g_per_g2 = TempPoly::constant(1e10);
    assert_eq!(
        refused(&t),
        Some(TableError::OutOfBounds(Field::Polynomial(
            Coefficient::Nonlinearity
        )))
    );
    // A tilt scale of 1e48 arcsec/V gave a NaN tilt without TILT_INVALID.
    let mut t = paper_order2_table();
    t.tilt.scale_arcsec_per_v = 1e48;
    assert_eq!(refused(&t), Some(TableError::OutOfBounds(Field::Tilt)));
    let mut t = paper_order2_table();
    t.tilt.scale_arcsec_per_v = -1e-6;
    assert_eq!(refused(&t), Some(TableError::OutOfBounds(Field::Tilt)));
    let mut t = paper_order2_table();
    t.tilt.reference = TiltArcsec(1e6);
    assert_eq!(refused(&t), Some(TableError::OutOfBounds(Field::Tilt)));
}

#[test]
fn each_coefficient_bound_holds_over_the_whole_range_not_only_at_t0() {
    // A model that is fine at T0 (x = 0.43) but leaves its bound at the range's edge (x = ±1).
    for (which, bound) in [
        (Coefficient::Bias, bounds::MAX_BIAS_G),
        (Coefficient::Nonlinearity, bounds::MAX_NONLINEARITY_G_PER_G2),
        (Coefficient::MisalignmentP, bounds::MAX_MISALIGNMENT_RAD),
        (Coefficient::MisalignmentO, bounds::MAX_MISALIGNMENT_RAD),
    ] {
        let with = |top: f64| {
            let mut t = paper_order2_table();
            let m = &mut t.thermal.models;
            let p = match which {
                Coefficient::Bias => &mut m.bias_g,
                Coefficient::Nonlinearity => &mut m.nonlinearity_g_per_g2,
                Coefficient::MisalignmentP => &mut m.misalignment_p_rad,
                _ => &mut m.misalignment_o_rad,
            };
            *p = TempPoly {
                coeffs: [0.0, 0.0, 0.0, 0.0, top],
            };
            t
        };
        assert_eq!(
            refused(&with(1.01 * bound)),
            Some(TableError::OutOfBounds(Field::Polynomial(which))),
            "{which:?}"
        );
        assert_eq!(refused(&with(0.99 * bound)), None, "{which:?} just inside");
    }
}

#[test]
fn a_temperature_range_outside_the_platinum_rtd_is_refused() {
    let mut t = paper_order2_table();
    let s = TemperatureScale::for_range(Celsius(-250.0), Celsius(65.0)).unwrap();
    t.thermal.scale = s;
    assert_eq!(
        refused(&t),
        Some(TableError::OutOfBounds(Field::TemperatureScale))
    );
    let mut t = paper_order2_table();
    t.thermal.scale.center = Celsius(100.0);
    assert_eq!(
        refused(&t),
        Some(TableError::OutOfBounds(Field::TemperatureScale))
    );
}

#[test]
fn a_table_with_one_trailing_byte_names_both_sizes() {
    // Regression (#15.9): "expected 426 bytes, found 426".
    let mut bytes = paper_order2_table().encode().to_vec();
    bytes.push(0);
    let e = CalibrationTable::decode(&bytes).unwrap_err();
    assert_eq!(
        e,
        TableError::BadLength {
            expected: ENCODED_LEN as u32,
            found: ENCODED_LEN as u32 + 1
        }
    );
    assert_eq!(
        e.to_string(),
        format!(
            "bad length: expected {ENCODED_LEN} bytes, found {}",
            ENCODED_LEN + 1
        )
    );
    bytes.truncate(100);
    assert!(matches!(
        CalibrationTable::decode(&bytes),
        Err(TableError::BadLength { found: 100, .. })
    ));
}

/// A polynomial whose magnitude is at most `bound` on x ∈ [−1, 1] (Σ|c_k| ≤ bound), so the
/// generated tables reach their bounds without leaving them.
fn within(bound: f64) -> impl Strategy<Value = TempPoly> {
    prop::array::uniform5(-1.0..=1.0f64).prop_map(move |u| TempPoly {
        coeffs: u.map(|v| v * bound / 5.0),
    })
}

prop_compose! {
    /// Tables anywhere inside the documented bounds, edges included.
    fn bounded_table()(
        k0 in within(bounds::MAX_BIAS_G),
        k2 in within(bounds::MAX_NONLINEARITY_G_PER_G2),
        dp in within(bounds::MAX_MISALIGNMENT_RAD),
        d_o in within(bounds::MAX_MISALIGNMENT_RAD),
        k1_log in -1.9..1.9f64,
        k1_shape in prop::array::uniform4(-1.0..=1.0f64),
        lo in -200.0..800.0f64,
        span_frac in 0.001..=1.0f64,
        tilt_log in -3.0..5.0f64,
        tilt_negative in any::<bool>(),
        phi0 in -bounds::MAX_TILT_REFERENCE_ARCSEC..=bounds::MAX_TILT_REFERENCE_ARCSEC,
        axis in 0u8..3,
    ) -> Option<CalibrationTable> {
        let mut t = paper_order2_table();
        let hi = lo + span_frac * (850.0 - lo);
        t.thermal.scale = TemperatureScale::for_range(Celsius(lo), Celsius(hi)).ok()?;
        t.thermal.reference = Celsius(0.5 * (lo + hi));
        let k1_base = 10f64.powf(k1_log);
        let mut k1 = [k1_base, 0.0, 0.0, 0.0, 0.0];
        for (c, s) in k1.iter_mut().skip(1).zip(k1_shape) {
            *c = 0.05 * k1_base * s;
        }
        let m = &mut t.thermal.models;
        m.bias_g = k0;
        m.scale_factor_v_per_g = TempPoly { coeffs: k1 };
        m.nonlinearity_g_per_g2 = k2;
        m.misalignment_p_rad = dp;
        m.misalignment_o_rad = d_o;
        let scale = 10f64.powf(tilt_log);
        t.tilt.scale_arcsec_per_v = if tilt_negative { -scale } else { scale };
        t.tilt.reference = TiltArcsec(phi0);
        t.tilt.axis = match axis {
            0 => accomp::table::TiltAxis::Input,
            1 => accomp::table::TiltAxis::InputReversed,
            _ => accomp::table::TiltAxis::None,
        };
        Some(t)
    }
}

fn raw_sample() -> impl Strategy<Value = RawSample> {
    (
        any::<i32>(),
        0u32..(1 << 24),
        any::<i32>(),
        prop_oneof![4 => Just(0u8), 1 => 0u8..8],
        prop_oneof![4 => Just(0u8), 1 => 0u8..8],
        prop_oneof![4 => Just(0u8), 1 => 0u8..8],
    )
        .prop_map(|(accel, rtd, tilt, af, rf, tf)| RawSample {
            accel,
            rtd,
            tilt,
            accel_flags: ChannelFlags(af),
            rtd_flags: ChannelFlags(rf),
            tilt_flags: ChannelFlags(tf),
        })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 20_000, ..ProptestConfig::default() })]

    #[test]
    fn no_frame_carries_a_non_finite_field_without_a_flag_saying_why(
        table in bounded_table(),
        raws in prop::collection::vec(raw_sample(), 8),
    ) {
        let Some(table) = table else { return Ok(()) };
        // Every generated table lies inside the bounds: the validator must take it.
        prop_assert_eq!(table.validate(), Ok(()));
        for raw in &raws {
            let f = pipeline::process(0, 0, raw, Some(&table));
            let s = f.status;
            prop_assert!(!s.has(Status::NO_CALIBRATION));
            if !f.output_v.is_finite() {
                prop_assert!(s.has(Status::OUTPUT_INVALID), "{f:?}");
            }
            if !f.temperature_c.is_finite() {
                prop_assert!(s.has(Status::RTD_OPEN | Status::RTD_SHORT | Status::RTD_INVALID), "{f:?}");
            }
            if !f.tilt_arcsec.is_finite() {
                prop_assert!(s.has(Status::TILT_INVALID), "{f:?}");
            }
            let all_finite = [
                f.output_v, f.temperature_c, f.rtd_ohms, f.tilt_arcsec, f.a_i_exact_g,
                f.output_linearized_v,
            ]
            .iter()
            .all(|v| v.is_finite());
            // Only TEMP_OUT_OF_RANGE may accompany a frame whose values are all usable.
            if !all_finite {
                prop_assert!(s.0 & !Status::TEMP_OUT_OF_RANGE != 0, "status OK with {f:?}");
            }
        }
    }
}
