//! `accomp compensate`: physical samples → raw codes → firmware (or the same core on the host)
//! → output rows.

use std::path::Path;

use accomp::adc::AdcError;
use accomp::board::{accel_scale, arcsec_to_ads1262, celsius_to_ad7124, volts_to_ads1262};
use accomp::pipeline::{self, ChannelFlags, Frame, RawSample};
use accomp::table::CalibrationTable;
use accomp::units::{Celsius, TiltArcsec, Volts};

use super::samples_csv::SampleRow;
use super::{client::DEFAULT_WINDOW, Connection, DeviceError, Target};

/// One channel's code for a physical value: a value the ADC could not represent becomes the
/// rail code (what the chip would deliver, flagged saturated by the pipeline); a missing value
/// (NaN) becomes a DRDY timeout on that channel.
fn channel<T: Copy + Default>(code: Result<T, AdcError>, rail: T) -> (T, ChannelFlags) {
    match code {
        Ok(c) => (c, ChannelFlags::default()),
        Err(AdcError::NonFiniteInput) => (T::default(), ChannelFlags(ChannelFlags::DRDY_TIMEOUT)),
        // Beyond full scale (or a scale the table cannot have, refused by its validation).
        Err(_) => (rail, ChannelFlags::default()),
    }
}

/// The raw sample the board would have acquired for an input row. Without a tilt column the
/// tilt is the table's reference φ0 (no tilt correction).
pub fn raw_for_row(table: &CalibrationTable, row: &SampleRow) -> RawSample {
    let tilt = row.tilt_arcsec.unwrap_or(table.tilt.reference.0);
    let accel_rail = if row.output_v > 0.0 {
        i32::MAX
    } else {
        i32::MIN
    };
    let (accel, accel_flags) = channel(
        volts_to_ads1262(&accel_scale(Some(table)), Volts(row.output_v)).map(|c| c.0),
        accel_rail,
    );
    let (rtd, rtd_flags) = channel(
        celsius_to_ad7124(table, Celsius(row.temperature_c)).map(|c| c.0),
        0x00FF_FFFF,
    );
    let tilt_rail = if tilt > 0.0 { i32::MAX } else { i32::MIN };
    let (tilt, tilt_flags) = channel(
        arcsec_to_ads1262(table, TiltArcsec(tilt)).map(|c| c.0),
        tilt_rail,
    );
    RawSample {
        accel,
        rtd,
        tilt,
        accel_flags,
        rtd_flags,
        tilt_flags,
    }
}

/// Runs rows through `target` with `table_bytes` as calibration: each output row goes to
/// `on_row(time_s, frame)` in input order as soon as it is known, so a long run is on disk while
/// it runs (issue #15.8). On a device, the table is uploaded (and read back) unless it is
/// already the active one.
pub fn compensate_streaming(
    target: &Target,
    firmware: Option<&Path>,
    table_bytes: &[u8],
    rows: &[SampleRow],
    mut progress: impl FnMut(&str, usize, usize),
    mut on_row: impl FnMut(f64, &Frame) -> Result<(), DeviceError>,
) -> Result<(), DeviceError> {
    let table = CalibrationTable::decode(table_bytes).map_err(DeviceError::TableRefused)?;
    let raws: Vec<RawSample> = rows.iter().map(|r| raw_for_row(&table, r)).collect();
    match target {
        Target::Host => {
            for (i, raw) in raws.iter().enumerate() {
                let t_us = (rows[i].time_s * 1e6).round().max(0.0) as u64;
                let f = pipeline::process(i as u32, t_us, raw, Some(&table));
                on_row(rows[i].time_s, &f)?;
            }
        }
        _ => {
            let mut conn = Connection::open(target, firmware)?;
            let info = conn.client.info()?;
            if info.active_table != Some(table.id()) {
                // The upload activates it: the board keeps it, as `load` would leave it.
                eprintln!(
                    "activating table {:#010x} on the device (it stays active after this run; \
                     the previous one becomes the rollback table)",
                    table.id()
                );
                conn.client
                    .load(table_bytes, |sent, total| progress("upload", sent, total))?;
            }
            // The writer's error is kept aside: the client's callback speaks ClientError.
            let mut write_error = None;
            let streamed =
                conn.client
                    .stream_samples(&raws, DEFAULT_WINDOW, |i, frame| {
                        match on_row(rows[i].time_s, &frame) {
                            Ok(()) => Ok(()),
                            Err(e) => {
                                write_error = Some(e);
                                Err(super::ClientError::Unexpected("output write failed".into()))
                            }
                        }
                    });
            if let Some(e) = write_error {
                return Err(e);
            }
            streamed?;
            conn.close()?;
        }
    }
    Ok(())
}

/// `accomp compensate` end to end: reads the table and the samples CSV, streams the output CSV
/// to `output` (rows flushed at least every 200 ms while they arrive) and shows a progress bar
/// with samples/s on stderr (off a terminal, a plain line a minute).
pub fn run_to_file(
    target: &Target,
    firmware: Option<&Path>,
    calibration: &Path,
    input: &Path,
    output: &Path,
) -> Result<(), DeviceError> {
    use std::io::Write as _;
    let write_error = |source| DeviceError::Write {
        path: output.to_path_buf(),
        source,
    };
    accomp_log::outputs::check_file(output)?;
    let table = accomp_log::calibration_file::read_table_bytes(calibration)?;
    let (_, max_bytes) = accomp_log::reader::limits();
    let text = accomp_log::reader::read_text_limited(input, max_bytes).map_err(|source| {
        DeviceError::Read {
            path: input.to_path_buf(),
            source,
        }
    })?;
    let file = super::samples_csv::parse(&text).map_err(|error| DeviceError::Samples {
        path: input.to_path_buf(),
        error,
    })?;
    let out = std::fs::File::create(output).map_err(|source| DeviceError::Create {
        path: output.to_path_buf(),
        source,
    })?;
    let mut out = std::io::BufWriter::new(out);
    out.write_all(super::samples_csv::output_header(&file.metadata).as_bytes())
        .and_then(|()| out.flush())
        .map_err(write_error)?;
    let total = file.rows.len() as u64;
    let bar = indicatif::ProgressBar::new(total);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{msg:>8} [{bar:30}] {pos}/{len} {per_sec} ETA {eta}",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    bar.set_message("samples");
    // Off a terminal the bar is not drawn: a line a minute instead (as `simulate`, `discover`).
    let lines = accomp_numerics::parallel::ProgressLines::new(
        format!("compensate {}", input.display()),
        file.rows.len(),
        "samples",
    );
    let started = std::time::Instant::now();
    let mut last_flush = started;
    let mut written = 0u64;
    let result = compensate_streaming(
        target,
        firmware,
        &table,
        &file.rows,
        |what, done, total| {
            if what == "upload" {
                bar.set_message(format!("upload {done}/{total} B"));
            }
        },
        |t, f| {
            out.write_all(super::samples_csv::output_row(t, f).as_bytes())
                .map_err(write_error)?;
            written += 1;
            if written == 1 {
                bar.set_message("samples");
            }
            bar.set_position(written);
            lines.set(written as usize);
            if last_flush.elapsed() >= std::time::Duration::from_millis(200) {
                out.flush().map_err(write_error)?;
                last_flush = std::time::Instant::now();
            }
            Ok(())
        },
    );
    let finished = accomp_log::outputs::finish(out, output);
    bar.finish_and_clear();
    result?;
    finished?;
    eprintln!(
        "{written} samples through {target:?} in {:.2} s ({:.0} samples/s), written to {}",
        started.elapsed().as_secs_f64(),
        written as f64 / started.elapsed().as_secs_f64().max(1e-9),
        output.display()
    );
    Ok(())
}
