//! Any byte stream into the device's receive path: frame decoder, message decoder and the
//! service (upload, commit to RAM flash, rollback …). Must never panic, and a good frame after
//! the noise must still be answered.
#![no_main]

use accomp::protocol::{
    decode_message, encode_frame, Board, DeviceMessage, FrameDecoder, HostFrame, Request,
    MAX_FRAME_LEN,
};
use accomp::service::Service;
use accomp::storage::{RamFlash, SlotLayout};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut decoder = FrameDecoder::<MAX_FRAME_LEN>::new();
    let mut service = Service::new(
        Board::Qemu,
        RamFlash::<3072, 1024, 4>::new(),
        SlotLayout::consecutive(1024),
    );
    let clock = || 0u64;
    for &b in data {
        if let Some(frame) = decoder.push(b) {
            if let Ok(body) = frame {
                let _ = decode_message::<HostFrame>(body);
            }
            let _ = service.handle_frame(frame, &clock);
        }
    }
    // Resynchronisation: delimiter, then a ping, must get its pong.
    let mut wire = [0u8; MAX_FRAME_LEN];
    let n = encode_frame(
        &HostFrame {
            id: 0xF00D,
            request: Request::Ping,
        },
        &mut wire,
    )
    .expect("a ping fits a frame");
    let mut answered = false;
    for &b in core::iter::once(&0u8).chain(&wire[..n]) {
        if let Some(frame) = decoder.push(b) {
            if let Some(DeviceMessage::Response { id: 0xF00D, .. }) =
                service.handle_frame(frame, &clock)
            {
                answered = true;
            }
        }
    }
    assert!(answered, "a good frame after the noise was not answered");
});
