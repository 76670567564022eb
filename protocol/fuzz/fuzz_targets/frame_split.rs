//! Splits arbitrary bytes into frames (small maximum length) and decodes each frame found.
#![no_main]

use libfuzzer_sys::fuzz_target;
use llrp::{FrameError, FrameSplitter, Message, Split};

fuzz_target!(|data: &[u8]| {
    let splitter = FrameSplitter::new(4096);
    let mut rest = data;
    loop {
        match splitter.split(rest) {
            Ok(Split::Frame(h)) => {
                let len = h.length as usize;
                assert!(len >= 10 && len <= rest.len());
                let _ = Message::decode(&rest[..len]);
                rest = &rest[len..];
            }
            Ok(Split::Incomplete(n)) => {
                assert!(n > 0);
                break;
            }
            Err(FrameError::UnsupportedVersion(h)) => {
                let len = h.length as usize;
                if len > rest.len() {
                    break;
                }
                rest = &rest[len..];
            }
            Err(_) => break,
        }
    }
});
