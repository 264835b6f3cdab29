//! Quick timing of the QEMU round trip (development aid).
use accomp::protocol::Request;
use accomp_host::device::{firmware_path, qemu::QemuOptions, Qemu};
use std::time::Instant;

fn main() {
    let (q, mut c) = Qemu::launch(&firmware_path(None), &QemuOptions::default()).unwrap();
    let t = Instant::now();
    for _ in 0..100 {
        c.call(Request::Ping).unwrap();
    }
    println!("ping rtt {:?}", t.elapsed() / 100);
    let raw = accomp::pipeline::RawSample::from_codes(1000, 5_000_000, 0);
    for w in [1, 4, 8, 12] {
        let raws = vec![raw; 500];
        let t = Instant::now();
        c.process_samples(&raws, w, |_, _| {}).unwrap();
        println!("window {w}: {:?}/sample", t.elapsed() / 500);
    }
    q.shutdown();
}
