//! Deterministic seeds: SplitMix64 mixing of the scenario seed with the identity of a draw, so
//! each draw depends only on what it is, never on call order.

use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// One SplitMix64 step: a well-mixed 64-bit function of `x`.
pub fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Mixes a list of words into one 64-bit value (order matters).
pub fn mix(words: &[u64]) -> u64 {
    words
        .iter()
        .fold(0x6C6C_7270_2D73_696D, |h, &w| splitmix64(h ^ splitmix64(w)))
}

/// Continues [`mix`]: `mix_on(mix(a), b)` is `mix` of `a` followed by `b`, so a prefix of
/// words common to many draws is mixed once.
pub fn mix_on(prefix: u64, words: &[u64]) -> u64 {
    words
        .iter()
        .fold(prefix, |h, &w| splitmix64(h ^ splitmix64(w)))
}

/// A uniform number in `[0, 1)` from a hash.
pub fn unit(hash: u64) -> f64 {
    (hash >> 11) as f64 / (1u64 << 53) as f64
}

/// A ChaCha8 generator seeded from the mixed words.
pub fn rng(words: &[u64]) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(mix(words))
}

/// A SplitMix64 stream seeded from the mixed words: the generator of one reply, which
/// draws a handful of numbers (ChaCha8 would spend most of its time setting up).
pub fn stream(words: &[u64]) -> Stream {
    Stream { state: mix(words) }
}

/// [`stream`] of a prefix already mixed ([`mix_on`]) followed by `words`.
pub fn stream_on(prefix: u64, words: &[u64]) -> Stream {
    Stream {
        state: mix_on(prefix, words),
    }
}

/// The SplitMix64 sequence from a 64-bit state ([`stream`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Stream {
    state: u64,
}

impl RngCore for Stream {
    fn next_u32(&mut self) -> u32 {
        (self.next_u64() >> 32) as u32
    }

    fn next_u64(&mut self) -> u64 {
        let x = self.state;
        self.state = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
        splitmix64(x)
    }

    fn fill_bytes(&mut self, dest: &mut [u8]) {
        for chunk in dest.chunks_mut(8) {
            let bytes = self.next_u64().to_le_bytes();
            chunk.copy_from_slice(&bytes[..chunk.len()]);
        }
    }

    fn try_fill_bytes(&mut self, dest: &mut [u8]) -> Result<(), rand::Error> {
        self.fill_bytes(dest);
        Ok(())
    }
}

/// Domain tags keeping the different kinds of draws apart.
pub mod domain {
    /// Per-slot read attempts (the scheduler before the Gen2 model; kept so other domains
    /// keep their values).
    pub const SLOT: u64 = 1;
    /// Phase offsets φ0.
    pub const PHASE_OFFSET: u64 = 2;
    /// Robot odometry noise.
    pub const ROBOT: u64 = 3;
    /// Default TID serial numbers.
    pub const TID: u64 = 4;
    /// Per-tag radio variation ([`super::super::tag::TagRadio`]).
    pub const TAG: u64 = 5;
    /// The reader/antenna part of the structured phase offset.
    pub const ANTENNA_PHASE: u64 = 6;
    /// Gen2 inventory rounds and their replies.
    pub const GEN2: u64 = 7;
    /// Inventoried-flag persistence times.
    pub const FLAGS: u64 = 8;
    /// What hardware adds: the antennas' phase patterns and fixed per-channel draws.
    pub const HARDWARE: u64 = 9;
    /// Tag access operations: the link's fades while a tag is accessed.
    pub const ACCESS: u64 = 10;
}

/// Default TID: `E2801160` (class E2, Impinj-style XTID manufacturer 0x801, model 0x160)
/// followed by a 64-bit serial derived from the EPC's bytes.
///
/// The EPC's length enters the serial except for an EPC-96 (whose TIDs predate other
/// lengths and stay as they were), so that EPCs such as `3000` and `30000000` get
/// different TIDs.
pub fn default_tid(epc: &[u8]) -> Vec<u16> {
    let mut h = domain::TID;
    if epc.len() != 12 {
        h = mix(&[h, epc.len() as u64]);
    }
    for chunk in epc.chunks(4) {
        let word = chunk.iter().fold(0u64, |a, &b| (a << 8) | u64::from(b));
        h = mix(&[h, word]);
    }
    let mut tid = vec![0xE280, 0x1160];
    tid.extend((0..4).map(|i| (h >> (48 - 16 * i)) as u16));
    tid
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_are_splitmix64_sequences() {
        let mut a = stream(&[1, 2, 3]);
        let mut b = stream(&[1, 2, 3]);
        let xs: Vec<u64> = (0..4).map(|_| a.next_u64()).collect();
        assert_eq!(xs, (0..4).map(|_| b.next_u64()).collect::<Vec<_>>());
        // Consecutive outputs are SplitMix64 of consecutive states.
        let s0 = mix(&[1, 2, 3]);
        assert_eq!(xs[0], splitmix64(s0));
        assert_eq!(xs[1], splitmix64(s0.wrapping_add(0x9E37_79B9_7F4A_7C15)));
        assert_ne!(stream(&[1, 2, 4]).next_u64(), xs[0]);
        let mut bytes = [0u8; 11];
        stream(&[1, 2, 3]).fill_bytes(&mut bytes);
        assert_eq!(bytes[..8], xs[0].to_le_bytes());
        assert_eq!(bytes[8..], xs[1].to_le_bytes()[..3]);
    }

    #[test]
    fn mixing_on_a_prefix_is_mixing_the_whole() {
        let words = [7, 1, 0, 3, 123_456_789];
        for split in 0..=words.len() {
            let (a, b) = words.split_at(split);
            assert_eq!(mix_on(mix(a), b), mix(&words));
            assert_eq!(stream_on(mix(a), b), stream(&words));
        }
    }

    #[test]
    fn mixing_is_order_sensitive_and_unit_is_in_range() {
        assert_ne!(mix(&[1, 2]), mix(&[2, 1]));
        assert_eq!(mix(&[1, 2]), mix(&[1, 2]));
        for i in 0..1000 {
            let u = unit(mix(&[i]));
            assert!((0.0..1.0).contains(&u));
        }
    }

    #[test]
    fn default_tid_is_stable_and_distinct() {
        let parse = |h| crate::scenario::tagmem::parse_epc(h).expect("valid EPC");
        let a = parse("300833B2DDD9014000000001");
        let b = parse("300833B2DDD9014000000002");
        let ta = default_tid(a.as_bytes());
        assert_eq!(ta.len(), 6);
        assert_eq!(&ta[..2], &[0xE280, 0x1160]);
        assert_eq!(ta, default_tid(a.as_bytes()));
        assert_ne!(ta, default_tid(b.as_bytes()));
        // An EPC-96's TID is what it was when EPCs were 96 bits only (the value the code
        // before other lengths gave).
        assert_eq!(ta, vec![0xE280, 0x1160, 0xA610, 0xCBB9, 0xC631, 0xFE90]);
        // Zero EPCs of other lengths get TIDs of their own.
        let short = default_tid(parse("3000").as_bytes());
        assert_ne!(short, default_tid(parse("30000000").as_bytes()));
        assert_ne!(short, default_tid(&[0x30, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]));
    }
}
