//! Calibration upload timing (docs/benchmarks.md, "Calibration upload"): bytes on the wire per
//! upload + verify + commit, the 115200 Bd wire time they imply, and QEMU wall-clock per step.
//!
//!     cargo xtask firmware && cargo run --release -p accomp-host --example upload_bench
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
        let upload_id = c.new_upload_id();
        c.call(Request::UploadBegin {
            upload_id,
            total_len: ENCODED_LEN as u32,
            body_crc32: upload_body_crc32(&bytes),
        })
        .unwrap();
        begin += t0.elapsed();
        for (i, ch) in bytes.chunks(CHUNK_LEN).enumerate() {
            c.call(Request::UploadChunk {
                upload_id,
                offset: (i * CHUNK_LEN) as u32,
                data: heapless::Vec::from_slice(ch).unwrap(),
            })
            .unwrap();
        }
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
}
