//! Firmware benchmark in QEMU (docs/benchmarks.md, "Firmware"): boots the ELF with
//! `-icount shift=0` (1 instruction = 1 ns of virtual time), loads a table and asks the
//! firmware to run the pipeline N times per case; prints instructions per sample.
//!
//! The last line, `instructions_per_sample <N>`, is the `new temperature every sample` case: the
//! RTD code changes from one sample to the next, as it does at every RTD conversion on a board
//! (the RTD's noise moves its last bits), so the temperature terms are recomputed each time. The
//! line above it, `cached_instructions_per_sample <N>`, is the largest of the steady-state cases
//! (the RTD code unchanged, the temperature terms from the cache: what an accelerometer sample
//! between two RTD readings costs).
use accomp::protocol::{Request, Response};
use accomp_host::device::{firmware_path, qemu::QemuOptions, Qemu};

fn main() {
    let count: u32 = std::env::args()
        .nth(1)
        .map(|s| s.parse().expect("count: a whole number"))
        .unwrap_or(100_000);
    let table = accomp_host::device::paper_table();
    let bytes = table.encode();
    let opts = QemuOptions {
        icount_shift: Some(0),
        ..QemuOptions::default()
    };
    let (q, mut c) = Qemu::launch(&firmware_path(None), &opts).expect("QEMU launch");
    c.timeout = std::time::Duration::from_secs(120);
    c.load(&bytes, |_, _| {}).expect("table upload");
    let mut steady_max = 0.0f64;
    let mut changing = 0.0f64;
    for (name, t, e, tilt, rtd_step) in [
        ("in range, 50 °C", 50.0, 1.3, 2.0, 0),
        ("clamped, 70 °C", 70.0, -0.7, 0.0, 0),
        ("new temperature every sample, 50 °C", 50.0, 1.3, 2.0, 1),
    ] {
        let raw = accomp::pipeline::raw_from_physical(
            &table,
            accomp::units::Volts(e),
            accomp::units::Celsius(t),
            accomp::units::TiltArcsec(tilt),
        )
        .expect("codes for the case");
        let request = Request::Bench {
            raw,
            count,
            rtd_step,
        };
        match c.call(request).expect("Bench request") {
            Response::Bench {
                count, elapsed_us, ..
            } => {
                let per_sample = elapsed_us as f64 * 1000.0 / f64::from(count);
                println!("{name}: {count} samples in {elapsed_us} µs virtual = {per_sample:.0} instructions/sample");
                if rtd_step == 0 {
                    steady_max = steady_max.max(per_sample);
                } else {
                    changing = per_sample;
                }
            }
            other => panic!("unexpected reply {other:?}"),
        }
    }
    q.shutdown();
    println!("cached_instructions_per_sample {steady_max:.0}");
    println!("instructions_per_sample {changing:.0}");
}
