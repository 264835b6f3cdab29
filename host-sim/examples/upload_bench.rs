//! Calibration upload timing (docs/benchmarks.md, "Calibration upload"): bytes on the wire per
//! upload + verify + commit, the 115200 Bd wire time they imply, and QEMU wall-clock per step.
//!
//!     cargo xtask firmware && cargo run --release -p accomp-host --example upload_bench
//!     cargo run --release -p accomp-host --example upload_bench icount   # only the -icount part
use accomp::protocol::{
    encode_frame, upload_body_crc32, DeviceMessage, HostFrame, Request, Response, CHUNK_LEN,
    MAX_FRAME_LEN,
};
use accomp::table::ENCODED_LEN;
use accomp_host::device::{firmware_path, paper_table, qemu::QemuOptions, Qemu};
use std::time::{Duration, Instant};

fn frame_len<T: serde::Serialize>(m: &T) -> usize {
    let mut out = [0u8; MAX_FRAME_LEN];
    encode_frame(m, &mut out).unwrap()
}

fn main() {
    if std::env::args().nth(1).as_deref() == Some("icount") {
        icount_commit(&paper_table());
        return;
    }
    let table = paper_table().encode();
    let id = 0xFFFF_FFF0u32; // ids near the top: worst-case varint length
    let host = |r: Request| frame_len(&HostFrame { id, request: r });
    let dev = |b: Response| frame_len(&DeviceMessage::Response { id, body: b });
    let uid = 0xFFFF_FFF1u32; // worst-case varint length too
    let mut up = host(Request::UploadBegin {
        upload_id: uid,
        total_len: ENCODED_LEN as u32,
        body_crc32: upload_body_crc32(&table),
    });
    let mut down = dev(Response::Ok);
    for (i, c) in table.chunks(CHUNK_LEN).enumerate() {
        up += host(Request::UploadChunk {
            upload_id: uid,
            offset: (i * CHUNK_LEN) as u32,
            data: heapless::Vec::from_slice(c).unwrap(),
        });
        down += dev(Response::Ok);
    }
    up += host(Request::UploadCommit { upload_id: uid });
    down += dev(Response::Committed { table_id: id });
    let (up_upload, down_upload) = (up, down);
    for (i, c) in table.chunks(CHUNK_LEN).enumerate() {
        up += host(Request::ReadTable {
            offset: (i * CHUNK_LEN) as u32,
        });
        down += dev(Response::TableChunk {
            offset: (i * CHUNK_LEN) as u32,
            total_len: ENCODED_LEN as u32,
            data: heapless::Vec::from_slice(c).unwrap(),
        });
    }
    let ms = |bytes: usize| bytes as f64 * 10.0 / 115_200.0 * 1e3;
    println!(
        "upload+commit: {up_upload} B host→dev + {down_upload} B dev→host = {:.1} ms at 115200 Bd",
        ms(up_upload + down_upload)
    );
    println!(
        "with read-back verify: {up} B + {down} B = {:.1} ms at 115200 Bd",
        ms(up + down)
    );

    let (q, mut c) = Qemu::launch(&firmware_path(None), &QemuOptions::default()).unwrap();
    let runs = 20;
    let mut total = Duration::ZERO;
    let mut commit = Duration::ZERO;
    let mut begin = Duration::ZERO;
    let mut t2 = paper_table();
    for k in 0..runs {
        // Alternate two tables so every run really writes a slot.
        t2.date.day = 1 + (k % 2) as u8;
        let bytes = t2.encode();
        let t0 = Instant::now();
        let upload_id = c.begin_upload(&bytes).unwrap();
        begin += t0.elapsed();
        c.send_chunks(upload_id, &bytes, |_, _| {}).unwrap();
        let tc = Instant::now();
        c.call(Request::UploadCommit { upload_id }).unwrap();
        commit += tc.elapsed();
        assert_eq!(c.read_table().unwrap(), bytes.to_vec());
        total += t0.elapsed();
    }
    let n = runs as u32;
    println!(
        "QEMU wall clock per upload+verify+commit: {:?} (Begin {:?}, Commit {:?}, ping {:?})",
        total / n,
        begin / n,
        commit / n,
        {
            let t = Instant::now();
            for _ in 0..20 {
                c.ping().unwrap();
            }
            t.elapsed() / 20
        }
    );
    q.shutdown();
    icount_commit(&t2);
}

/// Firmware time of the Commit step in virtual time under `-icount shift=0` (1 instruction =
/// 1 ns; the idle time waiting for UART bytes advances with real time, so each measurement
/// brackets the Commit between two InjectSamples sent back to back and subtracts the same
/// bracket around a Commit of the same length that is refused at once (wrong upload id)).
/// The difference is the instructions of the real commit: CRC, decode and validate, the store's
/// program + read-back + marker + re-scan, preparing the table for the per-sample path, and
/// the erase ahead of the next spare slot (RAM "flash" in QEMU; the semihosting write-through
/// to the host file is one trapped instruction and not counted).
fn icount_commit(base: &accomp::table::CalibrationTable) {
    use accomp::protocol::DeviceMessage;
    let opts = QemuOptions {
        icount_shift: Some(0),
        ..QemuOptions::default()
    };
    let (q, mut c) = Qemu::launch(&firmware_path(None), &opts).unwrap();
    let raw = accomp::pipeline::RawSample::from_codes(1000, 5_000_000, 0);
    let bracket = |c: &mut accomp_host::device::Client, commit: Request| -> f64 {
        let a = c.send(Request::InjectSample { raw }).unwrap();
        c.send(commit).unwrap();
        let b = c.send(Request::InjectSample { raw }).unwrap();
        let (mut ta, mut tb) = (None, None);
        while ta.is_none() || tb.is_none() {
            match c.recv(Duration::from_secs(10)).unwrap() {
                DeviceMessage::Sample { id, frame } if id == a => ta = Some(frame.time_us),
                DeviceMessage::Sample { id, frame } if id == b => tb = Some(frame.time_us),
                _ => {}
            }
        }
        (tb.unwrap() - ta.unwrap()) as f64
    };
    let mut t = *base;
    let (mut real, mut refused) = (Vec::new(), Vec::new());
    const ROUNDS: u32 = 60;
    for k in 0..ROUNDS {
        t.date.day = 1 + (k % 3) as u8;
        let bytes = t.encode();
        let upload_id = c.begin_upload(&bytes).unwrap();
        c.send_chunks(upload_id, &bytes, |_, _| {}).unwrap();
        // Same frame length: the wrong id differs only in its last bit.
        refused.push(bracket(
            &mut c,
            Request::UploadCommit {
                upload_id: upload_id ^ 1,
            },
        ));
        real.push(bracket(&mut c, Request::UploadCommit { upload_id }));
        c.ping().unwrap(); // lets the erase ahead run before the next round
    }
    // The firmware's time stamps come from its TIM2 time base at 1 MHz (1 instruction = 1 ns
    // here): each bracket is quantised to 1 µs, and the difference of the means is unbiased.
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let sd = |v: &[f64]| {
        let m = mean(v);
        (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
    };
    let (r, f) = (mean(&real), mean(&refused));
    let se = ((sd(&real).powi(2) + sd(&refused).powi(2)) / ROUNDS as f64).sqrt();
    println!(
        "icount: InjectSample→InjectSample around a real Commit {r:.0} µs, around a refused one \
         {f:.0} µs (means of {ROUNDS}, 1 µs ticks) → Commit ≈ {:.0} ± {se:.0} µs of virtual time \
         = {:.2} ± {:.2} M instructions",
        r - f,
        (r - f) / 1e3,
        se / 1e3
    );
    q.shutdown();
}
