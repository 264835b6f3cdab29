//! `accomp compensate`: physical samples → raw codes → firmware (or the same core on the host)
//! → output rows.

use std::path::Path;

use accomp::adc::AdcError;
use accomp::frontend::{accel_scale, arcsec_to_ads1262, celsius_to_ad7124, volts_to_ads1262};
use accomp::pipeline::{self, ChannelFlags, Frame, RawSample};
use accomp::table::CalibrationTable;
use accomp::units::{Celsius, TiltArcsec, Volts};

use super::samples_csv::SampleRow;
use super::{client::DEFAULT_WINDOW, Connection, Target};

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

/// Runs rows through `target` with `table_bytes` as calibration; returns (time_s, frame) rows.
/// On a device, the table is uploaded (and read back) unless it is already the active one.
pub fn compensate(
    target: &Target,
    firmware: Option<&Path>,
    table_bytes: &[u8],
    rows: &[SampleRow],
    mut progress: impl FnMut(&str, usize, usize),
) -> anyhow::Result<Vec<(f64, Frame)>> {
    let table = CalibrationTable::decode(table_bytes)
        .map_err(|e| anyhow::anyhow!("calibration refused locally: {e:?}"))?;
    let raws: Vec<RawSample> = rows.iter().map(|r| raw_for_row(&table, r)).collect();
    let frames: Vec<Frame> = match target {
        Target::Host => raws
            .iter()
            .enumerate()
            .map(|(i, raw)| {
                let t_us = (rows[i].time_s * 1e6).round().max(0.0) as u64;
                pipeline::process(i as u32, t_us, raw, Some(&table))
            })
            .collect(),
        _ => {
            let mut conn = Connection::open(target, firmware)?;
            let info = conn.client.info()?;
            if info.active_table != Some(table.id()) {
                conn.client
                    .load(table_bytes, |sent, total| progress("upload", sent, total))?;
            }
            let frames = conn
                .client
                .process_samples(&raws, DEFAULT_WINDOW, |done, total| {
                    progress("samples", done, total)
                })?;
            if let Some(q) = conn.qemu.take() {
                q.shutdown();
            }
            frames
        }
    };
    Ok(rows.iter().map(|r| r.time_s).zip(frames).collect())
}
