//! Firmware benchmark in QEMU (docs/benchmarks.md, "Firmware"): boots the ELF with
//! `-icount shift=0` (1 instruction = 1 ns of virtual time), loads a table and asks the
//! firmware to run the pipeline N times; prints instructions per sample.
use accomp::protocol::{Request, Response};
use accomp_host::device::{firmware_path, qemu::QemuOptions, Qemu};

fn main() {
    let count: u32 = std::env::args()
        .nth(1)
        .map(|s| s.parse().unwrap())
        .unwrap_or(20_000);
    let table = accomp_host::device::paper_table();
    let bytes = table.encode();
    let opts = QemuOptions {
        icount_shift: Some(0),
        ..QemuOptions::default()
    };
    let (q, mut c) = Qemu::launch(&firmware_path(None), &opts).unwrap();
    c.timeout = std::time::Duration::from_secs(120);
    c.load(&bytes, |_, _| {}).unwrap();
    for (name, t, e, tilt) in [
        ("in range, 50 °C", 50.0, 1.3, 2.0),
        ("clamped, 70 °C", 70.0, -0.7, 0.0),
    ] {
        let raw = accomp::pipeline::raw_from_physical(
            &table,
            accomp::units::Volts(e),
            accomp::units::Celsius(t),
            accomp::units::TiltArcsec(tilt),
        )
        .unwrap();
        match c.call(Request::Bench { raw, count }).unwrap() {
            Response::Bench {
                count, elapsed_us, ..
            } => println!(
                "{name}: {count} samples in {elapsed_us} µs virtual = {:.0} instructions/sample",
                elapsed_us as f64 * 1000.0 / f64::from(count)
            ),
            other => panic!("{other:?}"),
        }
    }
    q.shutdown();
}
