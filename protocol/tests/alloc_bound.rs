//! Decoding never allocates more than a small constant times the frame length, plus the typed
//! message's own size, whatever the bytes say (counts and lengths are checked against the
//! frame before anything is allocated).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use llrp::message::MessageBody;
use llrp::sample::Gen;
use llrp::{FrameHeader, Message};
use proptest::prelude::*;

/// Bytes allocated per frame byte that decoding may use (Rust structs are larger than their
/// wire form: a 4-byte empty TLV becomes a struct with list headers).
const FACTOR: usize = 32;

/// Bytes a decode may allocate whatever the frame's length: the typed message itself. A
/// 16-byte SET_READER_CONFIG (ResetToFactoryDefault and a 5-byte unknown parameter kept as
/// it came) allocates 573 bytes, its struct and the kept parameter; proptest found it.
const FIXED: usize = 1024;

struct Counting;

thread_local! {
    static ALLOCATED: Cell<usize> = const { Cell::new(0) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let _ = ALLOCATED.try_with(|a| a.set(a.get() + layout.size()));
        System.alloc(layout)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let _ = ALLOCATED.try_with(|a| a.set(a.get() + new_size));
        System.realloc(ptr, layout, new_size)
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Total bytes allocated (not net) while decoding `frame`.
fn allocated_by_decode(frame: &[u8]) -> usize {
    let before = ALLOCATED.with(Cell::get);
    let result = Message::decode(frame);
    let after = ALLOCATED.with(Cell::get);
    drop(result);
    after - before
}

fn frame_of(ty: u16, body: &[u8]) -> Vec<u8> {
    let mut frame = Vec::new();
    FrameHeader {
        version: 1,
        msg_type: ty,
        length: 10 + body.len() as u32,
        id: 1,
    }
    .encode(&mut frame);
    frame.extend_from_slice(body);
    frame
}

#[test]
fn huge_counts_in_tiny_frames_allocate_nothing_big() {
    // GET_READER_CAPABILITIES_RESPONSE whose LLRPStatus claims a 65535-byte description,
    // and a FixedFrequencyTable-like u32v count of 65535 inside RegulatoryCapabilities.
    let status = [0x01, 0x1F, 0x00, 0x0A, 0x00, 0x00, 0xFF, 0xFF, 0x41, 0x42];
    let frame = frame_of(11, &status);
    assert!(Message::decode(&frame).is_err());
    assert!(allocated_by_decode(&frame) <= FACTOR * frame.len() + FIXED);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn valid_messages_stay_within_bound(k in 0usize..64, seed in any::<u64>()) {
        let mut g = Gen::new(seed);
        let msg = Message::new(1, MessageBody::sample_typed(k % MessageBody::TYPED.len(), &mut g));
        let frame = msg.to_bytes();
        let used = allocated_by_decode(&frame);
        prop_assert!(used <= FACTOR * frame.len() + FIXED, "{}: {} bytes for a {}-byte frame", msg.name(), used, frame.len());
    }

    #[test]
    fn arbitrary_bytes_stay_within_bound(ty in 0u16..1024, body in proptest::collection::vec(any::<u8>(), 0..400)) {
        let frame = frame_of(ty, &body);
        let used = allocated_by_decode(&frame);
        prop_assert!(used <= FACTOR * frame.len() + FIXED, "type {}: {} bytes for a {}-byte frame", ty, used, frame.len());
    }

    #[test]
    fn corrupted_messages_stay_within_bound(k in 0usize..64, seed in any::<u64>(), pos in any::<usize>(), val in any::<u8>()) {
        let mut g = Gen::new(seed);
        let msg = Message::new(1, MessageBody::sample_typed(k % MessageBody::TYPED.len(), &mut g));
        let mut frame = msg.to_bytes().to_vec();
        let p = 10 + pos % (frame.len() - 9).max(1);
        if p < frame.len() {
            frame[p] = val;
        }
        let used = allocated_by_decode(&frame);
        prop_assert!(used <= FACTOR * frame.len() + FIXED, "{}: {} bytes for a {}-byte frame", msg.name(), used, frame.len());
    }
}
