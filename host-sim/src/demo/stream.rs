//! The simulated raw ADC codes through the firmware in QEMU, in chunks that are retried when
//! answers stop coming, with a progress bar.

use super::*;

/// The raw sample the board would acquire: the simulator's codes, no driver faults.
pub(super) fn raw(s: &Sample) -> RawSample {
    RawSample::from_codes(s.accel_code, s.rtd_code, s.tilt_code)
}

/// A progress bar of `len` samples labelled `prefix`.
pub(super) fn bar(len: u64, prefix: &str) -> ProgressBar {
    let b = ProgressBar::new(len);
    b.set_style(
        ProgressStyle::with_template(
            "{prefix:>9} {bar:40} {pos}/{len} samples, {per_sec}, {eta} left",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    b.set_prefix(prefix.to_owned());
    b
}

/// Bit-for-bit equality of the values of two frames (NaN equals NaN; seq/time differ by design).
pub(super) fn same_values(a: &Frame, b: &Frame) -> bool {
    let v = |f: &Frame| {
        [
            f.output_v,
            f.temperature_c,
            f.rtd_ohms,
            f.tilt_arcsec,
            f.a_i_exact_g,
            f.output_linearized_v,
        ]
        .map(f64::to_bits)
    };
    v(a) == v(b) && a.status == b.status
}

/// Readings per `process_samples` call: a lost frame costs at most one chunk's retry.
pub(super) const STREAM_CHUNK: usize = 256;
/// Retries of one chunk before the demo gives up.
const STREAM_RETRIES: usize = 3;

/// Streams `raws` through the device in chunks. The device drops inbound frames when its queue
/// is full and a frame can be lost on the line; the pipeline is stateless, so a chunk whose
/// answers stop coming is simply sent again (late answers to the old ids are ignored by the
/// client). Returns the frames in input order and the number of chunks retried.
pub(super) fn stream(
    client: &mut device::Client,
    raws: &[RawSample],
    bar: &ProgressBar,
) -> anyhow::Result<(Vec<Frame>, usize)> {
    let mut out = Vec::with_capacity(raws.len());
    let mut retried = 0;
    for chunk in raws.chunks(STREAM_CHUNK) {
        let base = out.len() as u64;
        let mut tries = 0;
        loop {
            match client.process_samples(chunk, DEFAULT_WINDOW, |done, _| {
                bar.set_position(base + done as u64)
            }) {
                Ok(frames) => {
                    out.extend(frames);
                    break;
                }
                Err(device::ClientError::Timeout(..)) if tries < STREAM_RETRIES => {
                    tries += 1;
                    retried += 1;
                    bar.println(format!(
                        "no answer within {:?} at reading {base}+: sending those {} readings again",
                        client.timeout,
                        chunk.len()
                    ));
                }
                Err(e) => return Err(e.into()),
            }
        }
    }
    Ok((out, retried))
}
