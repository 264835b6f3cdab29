use super::stream::same_values;
use super::*;

fn fitted() -> CalibrationTable {
    let path = default_table1();
    fit_table1(&path).expect("Table 1 fits").0
}

fn first_sample(preset: &str) -> (Scenario, Sample) {
    let sc = Scenario::preset(preset).expect("preset");
    let s = Simulator::new(&sc, 1)
        .and_then(|mut sim| sim.step())
        .expect("one sample");
    (sc, s)
}

#[test]
fn the_1g_table_ignores_tilt_and_keeps_t0_at_60_c() {
    let (sc, s) = first_sample("paper-1g");
    let t = experiment_table(&fitted(), &sc, &s).expect("table");
    assert_eq!(t.tilt.axis, TiltAxis::None);
    assert_eq!(t.orientation.nominal_input, Gs(1.0));
    assert_eq!(t.orientation.cross, CrossAxis::default());
    assert_eq!(t.thermal.reference, Celsius(60.0));
}

#[test]
fn the_0g_table_applies_eq5_from_the_first_reading_with_t0_inside_the_range() {
    let (sc, s) = first_sample("paper-0g");
    let t = experiment_table(&fitted(), &sc, &s).expect("table");
    assert_eq!(t.tilt.axis, TiltAxis::Input);
    // φ0 is the first reading as the board converts it: the simulator's measured tilt.
    assert!((t.tilt.reference.0 - s.tilt_arcsec).abs() < 1e-6);
    assert_eq!(t.orientation.nominal_input, Gs(0.0));
    // Spindle along the output axis, input horizontal: the pendulum axis carries 1 g.
    assert_eq!(t.orientation.cross.a_p, Gs(1.0));
    // 25 °C is below Table 1's 30–65 °C: T0 moves to the edge.
    assert_eq!(t.thermal.reference, Celsius(30.0));
}

#[test]
fn frames_with_the_same_nan_values_compare_equal_and_a_one_ulp_change_does_not() {
    let f = Frame {
        seq: 1,
        time_us: 2,
        lost: Default::default(),
        output_v: 1.0,
        temperature_c: 60.0,
        rtd_ohms: 123.0,
        tilt_arcsec: f64::NAN,
        a_i_exact_g: 1.0,
        output_linearized_v: 1.3,
        status: Status::default(),
    };
    let mut g = f;
    g.seq = 9;
    g.time_us = 99;
    assert!(same_values(&f, &g));
    g.a_i_exact_g = f64::from_bits(1.0f64.to_bits() + 1);
    assert!(!same_values(&f, &g));
}
