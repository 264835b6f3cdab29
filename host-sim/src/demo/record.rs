//! The recorded log of one experiment: simulated time, the firmware's frames, the raw codes and
//! the simulation's truth beside them, with the metadata that says what each is.

use super::*;

/// Log metadata as (key, value) pairs.
pub(super) type Metadata = Vec<(String, String)>;

/// A truth column of the log: its name and how to read it from a sample.
pub(super) type TruthColumn = (&'static str, fn(&Sample) -> f64);

/// Columns the log gets beside the firmware's (name, values).
pub(super) type ExtraColumns = Vec<(&'static str, Vec<f64>)>;

/// One column of the frames.
pub(super) fn frame_column(frames: &[Frame], f: fn(&Frame) -> f64) -> Vec<f64> {
    frames.iter().map(f).collect()
}

/// Step 6: the log (not yet written).
#[allow(clippy::too_many_arguments)] // the step's inputs, each a different product of the steps before
pub(super) fn record_log(
    samples: &[Sample],
    meta: &Metadata,
    table: &CalibrationTable,
    table_path: &Path,
    frames: &[Frame],
    k1_t0: f64,
    zero_g: bool,
    extra_cols: ExtraColumns,
    floor: Vec<f64>,
) -> anyhow::Result<Log> {
    let col = |f: fn(&Frame) -> f64| frame_column(frames, f);
    let mut log = Log::with_time(samples.iter().map(|s| s.time_s).collect())?;
    for (k, v) in meta {
        log.set_meta(k, v)?;
    }
    log.set_meta(
        "truth_scale_factor_v_per_g",
        meta.iter()
            .find(|(k, _)| k == "scale_factor_v_per_g")
            .map_or("", |(_, v)| v.as_str()),
    )?;
    log.set_meta("scale_factor_v_per_g", &format!("{k1_t0:.9}"))?;
    log.set_meta("calibration_id", &format!("{:#010x}", table.id()))?;
    log.set_meta("calibration_file", &table_path.display().to_string())?;
    log.set_meta("reference_c", &table.thermal.reference.0.to_string())?;
    log.set_meta("tilt_axis", if zero_g { "input" } else { "none" })?;
    log.set_meta(
        "time_base",
        "time_s is simulated time (host maps each InjectSample id to its simulated sample); \
         fw_time_s is the firmware's own clock in QEMU",
    )?;
    log.set_meta("recorded_by", "accomp demo (firmware in QEMU)")?;
    log.push_column("output_v", col(|f| f.output_v))?;
    log.push_column("temperature_c", col(|f| f.temperature_c))?;
    log.push_column("rtd_ohms", col(|f| f.rtd_ohms))?;
    log.push_column("tilt_arcsec", col(|f| f.tilt_arcsec))?;
    log.push_column("a_i_exact_g", col(|f| f.a_i_exact_g))?;
    log.push_column("output_linearized_v", col(|f| f.output_linearized_v))?;
    for (name, v) in extra_cols {
        log.push_column(name, v)?;
    }
    log.push_column("floor_a_i_g", floor)?;
    log.push_text_column(
        "status",
        TextColumn::from_strings(
            &frames
                .iter()
                .map(|f| status_names(f.status))
                .collect::<Vec<_>>(),
        ),
    )?;
    log.push_column("fw_seq", col(|f| f64::from(f.seq)))?;
    log.push_column("fw_time_s", col(|f| f.time_us as f64 * 1e-6))?;
    log.push_column(
        "accel_code",
        samples.iter().map(|s| f64::from(s.accel_code)).collect(),
    )?;
    log.push_column(
        "rtd_code",
        samples.iter().map(|s| f64::from(s.rtd_code)).collect(),
    )?;
    log.push_column(
        "tilt_code",
        samples.iter().map(|s| f64::from(s.tilt_code)).collect(),
    )?;
    let truth: [TruthColumn; 5] = [
        ("truth_input_g", |s| s.truth_input_g),
        ("truth_temperature_c", |s| s.truth_temperature_c),
        ("truth_tilt_arcsec", |s| s.truth_tilt_arcsec),
        ("truth_noise_g", |s| s.truth_noise_g),
        ("truth_room_c", |s| s.truth_room_c),
    ];
    for (name, f) in truth {
        log.push_column(name, samples.iter().map(f).collect())?;
    }
    Ok(log)
}
