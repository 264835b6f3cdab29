//! Any bytes into the table validator: refused with a named error, or accepted and then the
//! re-encoding is exactly the input (what the device stores, reads back and reports as its id).
//!
//! Inputs whose first byte is odd are first given a valid header and CRC, so the fuzzer gets
//! past the CRC into the field checks instead of spending itself on 2^-32 odds.
#![no_main]

use accomp::table::{CalibrationTable, CRC32, ENCODED_LEN, FORMAT_VERSION, MAGIC, PAYLOAD_LEN};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut framed = [0u8; ENCODED_LEN];
    let bytes: &[u8] = match data.split_first() {
        Some((mode, rest)) if mode & 1 == 1 => {
            let n = rest.len().min(ENCODED_LEN);
            framed[..n].copy_from_slice(&rest[..n]);
            framed[..4].copy_from_slice(&MAGIC);
            framed[4..6].copy_from_slice(&FORMAT_VERSION.to_le_bytes());
            framed[6..8].copy_from_slice(&[0, 0]);
            framed[8..12].copy_from_slice(&(PAYLOAD_LEN as u32).to_le_bytes());
            let crc = CRC32.checksum(&framed[..ENCODED_LEN - 4]);
            framed[ENCODED_LEN - 4..].copy_from_slice(&crc.to_le_bytes());
            &framed
        }
        _ => data,
    };
    if let Ok(t) = CalibrationTable::decode(bytes) {
        assert_eq!(bytes.len(), ENCODED_LEN);
        assert_eq!(&t.encode()[..], bytes, "accepted table re-encodes differently");
    }
});
