//! End to end in QEMU: the firmware ELF that `cargo xtask test` built, booted on the
//! netduinoplus2 model, driven over its UART exactly as a board on a serial port.
//!
//! No skipping: a missing ELF or qemu-system-arm fails these tests with the fix in the message.

use std::time::Instant;

use accomp::pipeline::{self, raw_from_physical, ChannelFlags, RawSample, Status};
use accomp::protocol::{upload_body_crc32, ErrorCode, Request, Response};
use accomp::table::{CalibrationTable, ENCODED_LEN};
use accomp::units::{Celsius, Gs, TiltArcsec, Volts};
use accomp_host::device::{paper_table, ClientError};

#[path = "common/qemu.rs"]
mod qemu;
use qemu::{boot, boot_loaded, Rng};

fn table() -> CalibrationTable {
    paper_table()
}

fn same_bits(a: f64, b: f64) -> bool {
    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
}

#[test]
fn ten_thousand_samples_match_the_host_core_bit_for_bit_with_faults_flagged() {
    let t = table();
    let (qemu, mut c) = boot();
    let id = c.load(&t.encode(), |_, _| {}).unwrap();
    assert_eq!(id, t.id());
    assert_eq!(c.info().unwrap().active_table, Some(t.id()));

    // Over the calibrated range and a little beyond (clamped + flagged), ±1.2 g, ±20" of tilt.
    let mut rng = Rng(0x5EED_1234_ABCD_0001);
    let mut raws = Vec::new();
    for i in 0..10_000 {
        let temp = 28.0 + 39.0 * rng.next();
        let a = -1.2 + 2.4 * rng.next();
        let tilt = -20.0 + 40.0 * rng.next();
        let (k, _) = t.thermal.coefficients_at(Celsius(temp)).unwrap();
        let e = k.output(Gs(a), t.orientation.cross);
        let mut raw = raw_from_physical(&t, e, Celsius(temp), TiltArcsec(tilt)).unwrap();
        // Every 97th sample carries a fault, cycling through the kinds.
        if i % 97 == 0 {
            match (i / 97) % 5 {
                0 => raw.rtd = 0x00FF_FFFF,                                  // open RTD
                1 => raw.rtd = 50,                                           // shorted RTD
                2 => raw.accel_flags = ChannelFlags(ChannelFlags::CHECKSUM), // bad checksum
                3 => raw.tilt_flags = ChannelFlags(ChannelFlags::DRDY_TIMEOUT), // no DRDY
                _ => raw.accel = i32::MAX,                                   // saturated
            }
        }
        raws.push(raw);
    }

    let started = Instant::now();
    let frames = c.process_samples(&raws, 8, |_, _| {}).unwrap();
    let elapsed = started.elapsed();
    eprintln!("10,000 samples through QEMU in {elapsed:?}");
    assert_eq!(frames.len(), raws.len());

    let mut faults_seen = 0;
    for (i, (raw, f)) in raws.iter().zip(&frames).enumerate() {
        // The host runs the same core function on the same codes with the firmware's seq/time.
        let h = pipeline::process(f.seq, f.time_us, raw, Some(&t));
        assert_eq!(f.status, h.status, "sample {i}");
        for (name, a, b) in [
            ("output_v", f.output_v, h.output_v),
            ("temperature_c", f.temperature_c, h.temperature_c),
            ("rtd_ohms", f.rtd_ohms, h.rtd_ohms),
            ("tilt_arcsec", f.tilt_arcsec, h.tilt_arcsec),
            ("a_i_exact_g", f.a_i_exact_g, h.a_i_exact_g),
            (
                "output_linearized_v",
                f.output_linearized_v,
                h.output_linearized_v,
            ),
        ] {
            assert!(
                same_bits(a, b),
                "sample {i} {name}: firmware {a:e} host {b:e}"
            );
        }
        if i % 97 == 0 {
            faults_seen += 1;
            let want = match (i / 97) % 5 {
                0 => Status::RTD_OPEN,
                1 => Status::RTD_SHORT,
                2 => Status::ADC_CHECKSUM,
                3 => Status::DRDY_TIMEOUT | Status::TILT_INVALID,
                _ => Status::ADC_SATURATED | Status::OUTPUT_INVALID,
            };
            assert!(f.status.has(want), "sample {i}: status {:?}", f.status);
            assert!(
                f.a_i_exact_g.is_nan(),
                "sample {i}: faulty sample gave a number"
            );
        } else {
            assert!(f.a_i_exact_g.is_finite(), "sample {i}: {:?}", f.status);
        }
    }
    assert_eq!(faults_seen, 104);
    // Sequence numbers count every processed sample, in order.
    assert!(frames.windows(2).all(|w| w[1].seq == w[0].seq + 1));
    assert!(frames.windows(2).all(|w| w[1].time_us >= w[0].time_us));
    // The stamps come from TIM2 at 1 MHz, which QEMU models (docs/architecture.md, "QEMU"), as
    // on the front-end; the 1 kHz SysTick would give whole milliseconds only.
    let sub_ms = frames.iter().filter(|f| f.time_us % 1_000 != 0).count();
    assert!(
        sub_ms > frames.len() / 2,
        "only {sub_ms} of {} time stamps are not whole milliseconds: not the µs time base",
        frames.len()
    );
    drop(qemu);
}

#[test]
fn garbage_and_malformed_frames_are_ignored_and_corrupted_tables_refused() {
    let good = table();
    let (qemu, mut c) = boot_loaded(&good);
    let raw: RawSample =
        raw_from_physical(&good, Volts(1.3), Celsius(50.0), TiltArcsec(0.0)).unwrap();

    // Line noise, a frame with a broken CRC, and a COBS frame that is not a request.
    c.send_raw(&[0x13, 0x37, 0xFF, 0x00, 0x00, 0x55, 0x00])
        .unwrap();
    c.send_raw(&[0x05, 0x01, 0x02, 0x03, 0x04, 0x00]).unwrap();
    let before = c.info().unwrap().frames_dropped;
    assert!(before >= 2, "garbage frames are counted, got {before}");
    let frames = c.process_samples(&[raw], 1, |_, _| {}).unwrap();
    assert_eq!(
        frames[0],
        pipeline::process(frames[0].seq, frames[0].time_us, &raw, Some(&good))
    );

    // Corrupted uploads, each refused with its own code; the good table stays active.
    let mut flipped = good.encode();
    flipped[200] ^= 0x01;
    let mut nan = good;
    nan.thermal.models.bias_g.coeffs[2] = f64::NAN;
    let encoded = good.encode();
    let cases: [(&str, Vec<u8>, ErrorCode); 3] = [
        ("bit flip", flipped.to_vec(), ErrorCode::TableBadCrc),
        (
            "truncated",
            encoded[..ENCODED_LEN - 7].to_vec(),
            ErrorCode::TableBadLength,
        ),
        (
            "NaN coefficient",
            nan.encode().to_vec(),
            ErrorCode::TableNonFinite,
        ),
    ];
    for (what, bytes, code) in cases {
        let err = c.upload(&bytes, |_, _| {}).unwrap_err();
        assert_eq!(err.device_code(), Some(code), "{what}: {err}");
        assert_eq!(c.info().unwrap().active_table, Some(good.id()), "{what}");
    }
    // A chunk out of order names the offset the device expected.
    c.call(Request::UploadBegin {
        upload_id: 5,
        total_len: ENCODED_LEN as u32,
        body_crc32: upload_body_crc32(&encoded),
    })
    .unwrap();
    let err = c
        .call(Request::UploadChunk {
            upload_id: 5,
            offset: 64,
            data: heapless::Vec::from_slice(&encoded[64..128]).unwrap(),
        })
        .unwrap_err();
    match err {
        ClientError::Device(e) => {
            assert_eq!((e.code, e.detail), (ErrorCode::ChunkOutOfOrder as u16, 0))
        }
        other => panic!("{other}"),
    }
    // And the good table is still the one used for samples.
    let frames = c.process_samples(&[raw], 1, |_, _| {}).unwrap();
    assert_eq!(
        frames[0],
        pipeline::process(frames[0].seq, frames[0].time_us, &raw, Some(&good))
    );
    assert_eq!(c.read_table().unwrap(), encoded.to_vec());
    assert!(matches!(c.call(Request::Ping).unwrap(), Response::Pong));
    drop(qemu);
}
