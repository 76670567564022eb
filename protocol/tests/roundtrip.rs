//! Property tests: every typed message survives encode → decode → encode, and decoding
//! arbitrary or corrupted bytes returns an error instead of panicking.

use llrp::message::MessageBody;
use llrp::sample::Gen;
use llrp::{FrameHeader, Message};
use proptest::prelude::*;

fn sample_message(k: usize, seed: u64) -> Message {
    let mut g = Gen::new(seed);
    let body = MessageBody::sample_typed(k, &mut g);
    Message {
        version: 1 + (seed % 2) as u8,
        id: (seed >> 7) as u32,
        body,
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn every_typed_message_round_trips(seed in any::<u64>()) {
        for k in 0..MessageBody::TYPED.len() {
            let msg = sample_message(k, seed);
            prop_assert_eq!(msg.name(), MessageBody::TYPED[k].3);
            let bytes = msg.to_bytes();
            let back = Message::decode(&bytes)
                .map_err(|e| TestCaseError::fail(format!("{}: {e}", msg.name())))?;
            prop_assert_eq!(&back, &msg);
            prop_assert_eq!(&back.to_bytes()[..], &bytes[..]);
        }
    }

    #[test]
    fn arbitrary_bodies_never_panic(ty in 0u16..1024, body in proptest::collection::vec(any::<u8>(), 0..300)) {
        let mut frame = Vec::new();
        FrameHeader { version: 1, msg_type: ty, length: 10 + body.len() as u32, id: 1 }.encode(&mut frame);
        frame.extend_from_slice(&body);
        if let Ok(m) = Message::decode(&frame) {
            // Whatever decodes must encode to something that decodes the same.
            let again = Message::decode(&m.to_bytes()).expect("re-decode");
            prop_assert_eq!(again, m);
        }
    }

    #[test]
    fn corrupted_messages_never_panic(k in 0usize..64, seed in any::<u64>(), flips in proptest::collection::vec((any::<usize>(), any::<u8>()), 1..6)) {
        let msg = sample_message(k % MessageBody::TYPED.len(), seed);
        let mut bytes = msg.to_bytes().to_vec();
        for (pos, val) in flips {
            let p = 10 + pos % (bytes.len() - 9).max(1);
            if p < bytes.len() {
                bytes[p] = val;
            }
        }
        match Message::decode(&bytes) {
            Ok(m) => {
                let again = Message::decode(&m.to_bytes()).expect("re-decode");
                prop_assert_eq!(again, m);
            }
            Err(e) => {
                prop_assert!(e.offset <= bytes.len());
                prop_assert!(!e.path.is_empty());
                let _ = e.to_status();
            }
        }
    }
}
