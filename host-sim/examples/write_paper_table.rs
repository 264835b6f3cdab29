//! Writes the paper's JN-06 A12124 calibration table (binary) to the given path.
fn main() {
    let path = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "paper.acal".into());
    std::fs::write(&path, accomp_host::device::paper_table().encode()).expect("writable path");
    println!("{path}");
}
