//! Decodes arbitrary message bodies under a valid header; whatever decodes must re-encode to
//! bytes that decode to the same message, and errors must stay inside the frame.
#![no_main]

use libfuzzer_sys::fuzz_target;
use llrp::{FrameHeader, Message};

fuzz_target!(|data: &[u8]| {
    if data.len() < 2 {
        return;
    }
    let ty = u16::from_be_bytes([data[0], data[1]]) & 0x3FF;
    let body = &data[2..];
    let mut frame = Vec::with_capacity(10 + body.len());
    FrameHeader { version: 1, msg_type: ty, length: (10 + body.len()) as u32, id: 1 }.encode(&mut frame);
    frame.extend_from_slice(body);
    match Message::decode(&frame) {
        Ok(m) => {
            let again = m.to_bytes();
            let m2 = Message::decode(&again).expect("re-encoded message decodes");
            assert_eq!(m, m2);
            let _ = serde_json::to_string(&m);
        }
        Err(e) => {
            assert!(e.offset <= frame.len());
            let _ = e.to_status();
        }
    }
});
