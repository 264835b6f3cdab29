//! `accomp table show|get|verify`: what a calibration table file holds, the device's active
//! table, and whether the firmware would accept a file (the same `CalibrationTable::decode` the
//! board runs).

use crate::calibration_file::{decode_named, read_table, read_table_bytes};
use accomp::poly::TempPoly;
use accomp::table::{CalibrationTable, ENCODED_LEN};
use accomp::units::{Celsius, RAD_PER_ARCMIN};
use anyhow::Result;
use serde::Serialize;
use serde_json::Value;
use std::path::PathBuf;

/// One temperature model as printed (in the unit the lab reads).
#[derive(Serialize)]
struct PolyJson {
    order: usize,
    coeffs_x: Vec<f64>,
    monomial_celsius: Vec<f64>,
    at_reference: f64,
    slope_per_c_at_reference: f64,
}

impl PolyJson {
    fn new(p: &TempPoly, t: &CalibrationTable, unit_scale: f64) -> Self {
        let s = &t.thermal.scale;
        let scaled = p.scaled(unit_scale);
        let x_ref = s.x_unclamped(t.thermal.reference);
        PolyJson {
            order: p.order(),
            coeffs_x: scaled.coeffs[..=p.order()].to_vec(),
            monomial_celsius: scaled.to_monomial_celsius(s)[..=p.order()].to_vec(),
            at_reference: scaled.eval(x_ref),
            slope_per_c_at_reference: scaled.derivative_x(x_ref) / s.half_span_c,
        }
    }
}

#[derive(Serialize)]
struct NormalizationJson {
    center_c: f64,
    half_span_c: f64,
}

#[derive(Serialize)]
struct TiltJson {
    reference_arcsec: f64,
    scale_arcsec_per_v: f64,
    axis: String,
    adc_gain_correction: f64,
    adc_offset_v: f64,
}

#[derive(Serialize)]
struct RtdJson {
    r0_ohm: f64,
    a: f64,
    b: f64,
    c: f64,
    reference_resistor_ohm: f64,
    adc_gain_correction: f64,
    pga_gain: f64,
}

#[derive(Serialize)]
struct AccelerometerChannelJson {
    adc_gain_correction: f64,
    adc_offset_v: f64,
    sense_resistor_ohm: f64,
}

#[derive(Serialize)]
struct OrientationJson {
    a_p_g: f64,
    a_o_g: f64,
    nominal_input_g: f64,
}

/// What `accomp table show --json` prints.
#[derive(Serialize)]
struct TableJson<'a> {
    id: String,
    serial: &'a str,
    date: String,
    range_c: [f64; 2],
    normalization: NormalizationJson,
    reference_c: f64,
    k0_g: PolyJson,
    k1_v_per_g: PolyJson,
    k2_g_per_g2: PolyJson,
    delta_p_arcmin: PolyJson,
    delta_o_arcmin: PolyJson,
    tilt: TiltJson,
    rtd: RtdJson,
    accelerometer_channel: AccelerometerChannelJson,
    orientation: OrientationJson,
    encoded_len: usize,
}

/// `accomp table verify --json` (fields in the order printed).
#[derive(Serialize)]
struct VerifyJson {
    #[serde(skip_serializing_if = "Option::is_none")]
    error: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    id: Option<String>,
    valid: bool,
}

/// The table as one JSON object (misalignments in arcmin, as the lab prints them).
pub fn table_json(t: &CalibrationTable) -> Value {
    let m = &t.thermal.models;
    let s = &t.thermal.scale;
    let view = TableJson {
        id: format!("{:08x}", t.id()),
        serial: t.serial_str().unwrap_or("<invalid>"),
        date: format!("{:04}-{:02}-{:02}", t.date.year, t.date.month, t.date.day),
        range_c: [s.min.0, s.max.0],
        normalization: NormalizationJson {
            center_c: s.center.0,
            half_span_c: s.half_span_c,
        },
        reference_c: t.thermal.reference.0,
        k0_g: PolyJson::new(&m.bias_g, t, 1.0),
        k1_v_per_g: PolyJson::new(&m.scale_factor_v_per_g, t, 1.0),
        k2_g_per_g2: PolyJson::new(&m.nonlinearity_g_per_g2, t, 1.0),
        delta_p_arcmin: PolyJson::new(&m.misalignment_p_rad, t, 1.0 / RAD_PER_ARCMIN),
        delta_o_arcmin: PolyJson::new(&m.misalignment_o_rad, t, 1.0 / RAD_PER_ARCMIN),
        tilt: TiltJson {
            reference_arcsec: t.tilt.reference.0,
            scale_arcsec_per_v: t.tilt.scale_arcsec_per_v,
            axis: format!("{:?}", t.tilt.axis),
            adc_gain_correction: t.tilt.adc_gain_correction,
            adc_offset_v: t.tilt.adc_offset.0,
        },
        rtd: RtdJson {
            r0_ohm: t.rtd.cvd.r0,
            a: t.rtd.cvd.a,
            b: t.rtd.cvd.b,
            c: t.rtd.cvd.c,
            reference_resistor_ohm: t.rtd.reference_resistor.0,
            adc_gain_correction: t.rtd.adc_gain_correction,
            pga_gain: t.rtd.pga_gain,
        },
        accelerometer_channel: AccelerometerChannelJson {
            adc_gain_correction: t.accel.adc_gain_correction,
            adc_offset_v: t.accel.adc_offset.0,
            sense_resistor_ohm: t.accel.sense_resistor.0,
        },
        orientation: OrientationJson {
            a_p_g: t.orientation.cross.a_p.0,
            a_o_g: t.orientation.cross.a_o.0,
            nominal_input_g: t.orientation.nominal_input.0,
        },
        encoded_len: ENCODED_LEN,
    };
    // Plain structs of numbers and strings: serializing cannot fail.
    serde_json::to_value(view).unwrap_or(Value::Null)
}

/// Human-readable description.
pub fn table_text(t: &CalibrationTable) -> String {
    let s = &t.thermal.scale;
    let mut out = String::new();
    let serial = t.serial_str().unwrap_or("<invalid>");
    out += &format!(
        "calibration table {:08x}  serial {serial}  date {:04}-{:02}-{:02}\n",
        t.id(),
        t.date.year,
        t.date.month,
        t.date.day
    );
    out += &format!(
        "range {:.2} … {:.2} °C, x = (T − {:.3})/{:.3}, T0 = {:.2} °C\n",
        s.min.0, s.max.0, s.center.0, s.half_span_c, t.thermal.reference.0
    );
    let m = &t.thermal.models;
    for (name, p, k) in [
        ("K0 [g]", &m.bias_g, 1.0),
        ("K1 [V/g]", &m.scale_factor_v_per_g, 1.0),
        ("K2 [g/g²]", &m.nonlinearity_g_per_g2, 1.0),
        ("δp [arcmin]", &m.misalignment_p_rad, 1.0 / RAD_PER_ARCMIN),
        ("δo [arcmin]", &m.misalignment_o_rad, 1.0 / RAD_PER_ARCMIN),
    ] {
        let q = p.scaled(k);
        let x0 = s.x_unclamped(Celsius(t.thermal.reference.0));
        out += &format!(
            "  {name:<12} order {}  at T0 {:+.9e}  dK/dT {:+.4e}/°C  coeffs(x) {:?}\n",
            p.order(),
            q.eval(x0),
            q.derivative_x(x0) / s.half_span_c,
            &q.coeffs[..=p.order()]
        );
    }
    out += &format!(
        "RTD R0 {} Ω, A {:e}, B {:e}, C {:e}, Rref {} Ω, PGA {}\n",
        t.rtd.cvd.r0,
        t.rtd.cvd.a,
        t.rtd.cvd.b,
        t.rtd.cvd.c,
        t.rtd.reference_resistor.0,
        t.rtd.pga_gain
    );
    out += &format!(
        "tilt φ0 {}\", {} \"/V, axis {:?}; sense resistor {} Ω; orientation a_i {} g, a_p {} g, a_o {} g\n",
        t.tilt.reference.0,
        t.tilt.scale_arcsec_per_v,
        t.tilt.axis,
        t.accel.sense_resistor.0,
        t.orientation.nominal_input.0,
        t.orientation.cross.a_p.0,
        t.orientation.cross.a_o.0
    );
    out
}

/// `accomp table …` arguments.
#[derive(clap::Args, Debug)]
pub struct TableArgs {
    #[command(subcommand)]
    action: TableAction,
}

#[derive(clap::Subcommand, Debug)]
enum TableAction {
    /// Print what a table holds.
    Show {
        /// Calibration table file (as written by `accomp fit -o`).
        path: PathBuf,
        /// One JSON object instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Read the device's active table into a file.
    Get(TableGetArgs),
    /// Check a table as the firmware would; exits non-zero with the named error if refused.
    Verify {
        /// Calibration table file.
        path: PathBuf,
        /// One JSON object instead of text.
        #[arg(long)]
        json: bool,
    },
}

/// Runs `accomp table …`.
pub fn run(args: &TableArgs) -> Result<()> {
    match &args.action {
        TableAction::Show { path, json } => {
            let t = read_table(path)?;
            if *json {
                println!("{}", serde_json::to_string_pretty(&table_json(&t))?);
            } else {
                print!("{}", table_text(&t));
            }
        }
        TableAction::Get(get) => run_get(get)?,
        TableAction::Verify { path, json } => {
            let bytes = match read_table_bytes(path) {
                Ok(b) => b,
                Err(e) => {
                    // With its cause: `cannot read <file>: <system error>`.
                    let e = anyhow::Error::from(e);
                    if *json {
                        println!(
                            "{}",
                            serde_json::json!({"valid": false, "error": format!("{e:#}")})
                        );
                    }
                    return Err(e);
                }
            };
            match decode_named(&bytes) {
                Ok(t) => {
                    if *json {
                        let v = VerifyJson {
                            valid: true,
                            id: Some(format!("{:08x}", t.id())),
                            error: None,
                        };
                        println!("{}", serde_json::to_string(&v)?);
                    } else {
                        println!("{}: valid, id {:08x}", path.display(), t.id());
                    }
                }
                Err(e) => {
                    if *json {
                        let v = VerifyJson {
                            valid: false,
                            id: None,
                            error: Some(e.to_string()),
                        };
                        println!("{}", serde_json::to_string(&v)?);
                    }
                    anyhow::bail!("{}: refused: {e}", path.display());
                }
            }
        }
    }
    Ok(())
}

/// Read the device's active table into a file.
#[derive(clap::Args, Debug)]
pub struct TableGetArgs {
    #[command(flatten)]
    pub device: super::load::DeviceArgs,
    /// Where to write the table.
    #[arg(short, long)]
    pub output: PathBuf,
}

/// Runs `accomp table get`.
pub fn run_get(args: &TableGetArgs) -> anyhow::Result<()> {
    crate::outputs::check_file(&args.output)?;
    let mut conn = args.device.open()?;
    let bytes = conn.client.read_table()?;
    conn.close()?;
    crate::outputs::write_file(&args.output, &bytes)?;
    eprintln!("{} bytes written to {}", bytes.len(), args.output.display());
    Ok(())
}
