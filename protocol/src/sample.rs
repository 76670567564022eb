//! Random valid messages and parameters, for property tests, fuzz seeds and benchmarks.

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use crate::codec::BitVec;
use crate::raw::{Extra, RawParam};

/// Deepest nesting at which optional and repeated sub-parameters are still generated.
const MAX_DEPTH: u32 = 6;

/// A seeded generator of random protocol values.
pub struct Gen {
    rng: StdRng,
    depth: u32,
}

/// A type with a random valid value.
pub trait Sample: Sized {
    /// A random value.
    fn sample(g: &mut Gen) -> Self;
}

impl Gen {
    /// A generator seeded with `seed` (same seed, same values).
    pub fn new(seed: u64) -> Self {
        Gen {
            rng: StdRng::seed_from_u64(seed),
            depth: 0,
        }
    }

    /// A value of `T`.
    pub fn any<T: Sample>(&mut self) -> T {
        T::sample(self)
    }

    /// A value in `lo..=hi`.
    pub fn range<T: rand::distributions::uniform::SampleUniform + PartialOrd>(
        &mut self,
        lo: T,
        hi: T,
    ) -> T {
        self.rng.gen_range(lo..=hi)
    }

    /// `width` random bits.
    pub fn bits(&mut self, width: u32) -> u32 {
        let v: u32 = self.rng.gen();
        if width >= 32 {
            v
        } else {
            v & ((1 << width) - 1)
        }
    }

    /// An index below `n` (n > 0).
    pub fn index(&mut self, n: usize) -> usize {
        self.rng.gen_range(0..n)
    }

    /// Runs `f` one level deeper.
    pub fn nested<T>(&mut self, f: impl FnOnce(&mut Gen) -> T) -> T {
        self.depth += 1;
        let v = f(self);
        self.depth -= 1;
        v
    }

    /// `Some` about half the time, while not too deep.
    pub fn option<T>(&mut self, f: impl FnOnce(&mut Gen) -> T) -> Option<T> {
        if self.depth < MAX_DEPTH && self.rng.gen_bool(0.5) {
            Some(self.nested(f))
        } else {
            None
        }
    }

    /// `min` to `min + 2` values (just `min` when deep).
    pub fn list<T>(&mut self, min: usize, mut f: impl FnMut(&mut Gen) -> T) -> Vec<T> {
        let n = if self.depth < MAX_DEPTH {
            min + self.rng.gen_range(0..=2)
        } else {
            min
        };
        (0..n).map(|_| self.nested(&mut f)).collect()
    }

    /// Now and then, an unknown parameter at the start or end of `n` typed sub-parameters.
    pub fn extras(&mut self, n: usize) -> Vec<Extra> {
        if self.rng.gen_ratio(1, 10) {
            let at = if self.rng.gen_bool(0.5) { 0 } else { n };
            let ty = self.rng.gen_range(900u16..1000);
            let len = self.rng.gen_range(0..6usize);
            let mut bytes = Vec::with_capacity(4 + len);
            bytes.extend_from_slice(&ty.to_be_bytes());
            bytes.extend_from_slice(&((4 + len) as u16).to_be_bytes());
            bytes.extend((0..len).map(|_| self.rng.gen::<u8>()));
            vec![Extra {
                at: at as u32,
                param: RawParam::new(bytes),
            }]
        } else {
            Vec::new()
        }
    }

    /// A Custom parameter of a vendor the codec does not type.
    pub fn raw_custom(&mut self) -> RawParam {
        let vendor = [161u32, 10642, 4242][self.index(3)];
        let subtype: u32 = self.rng.gen_range(0..200);
        let len = self.rng.gen_range(0..8usize);
        let mut bytes = Vec::with_capacity(12 + len);
        bytes.extend_from_slice(&1023u16.to_be_bytes());
        bytes.extend_from_slice(&((12 + len) as u16).to_be_bytes());
        bytes.extend_from_slice(&vendor.to_be_bytes());
        bytes.extend_from_slice(&subtype.to_be_bytes());
        bytes.extend((0..len).map(|_| self.rng.gen::<u8>()));
        RawParam::new(bytes)
    }
}

macro_rules! sample_int {
    ($($t:ty),*) => {$(
        impl Sample for $t {
            fn sample(g: &mut Gen) -> Self {
                g.rng.gen()
            }
        }
    )*};
}

sample_int!(u8, u16, u32, u64, i8, i16, bool);

impl Sample for [u8; 12] {
    fn sample(g: &mut Gen) -> Self {
        g.rng.gen()
    }
}

impl<T: Sample> Sample for Vec<T> {
    fn sample(g: &mut Gen) -> Self {
        let n = g.rng.gen_range(0..4);
        (0..n).map(|_| T::sample(g)).collect()
    }
}

impl<T: Sample> Sample for Box<T> {
    fn sample(g: &mut Gen) -> Self {
        Box::new(T::sample(g))
    }
}

impl Sample for String {
    fn sample(g: &mut Gen) -> Self {
        const WORDS: [&str; 6] = [
            "",
            "ok",
            "Speedway R420",
            "5.14.0.240",
            "µ-reader",
            "ünïcode",
        ];
        WORDS[g.index(WORDS.len())].to_string()
    }
}

impl Sample for BitVec {
    fn sample(g: &mut Gen) -> Self {
        let bits: u16 = g.rng.gen_range(0..=128);
        let bytes = (0..usize::from(bits).div_ceil(8))
            .map(|_| g.rng.gen())
            .collect();
        BitVec { bits, bytes }
    }
}

/// The benchmark's RO_ACCESS_REPORT: `n_tags` reads, each with EPC-96, AntennaID, PeakRSSI,
/// ChannelIndex, First/LastSeenTimestampUTC, TagSeenCount, ImpinjRFPhaseAngle, ImpinjPeakRSSI.
pub fn benchmark_report(n_tags: usize, seed: u64) -> crate::Message {
    use crate::impinj::{ImpinjPeakRssi, ImpinjRfPhaseAngle};
    use crate::params::*;
    let mut g = Gen::new(seed);
    let t0: u64 = 1_763_900_000_000_000;
    let tag_report_data = (0..n_tags)
        .map(|k| {
            let mut epc = [0u8; 12];
            epc[0] = 0x30;
            epc[4..].copy_from_slice(&(k as u64).to_be_bytes());
            let rssi = g.range(-7500i16, -3000);
            let seen = t0 + k as u64 * 1000;
            TagReportData {
                epc: Epc::Epc96(Epc96(epc)),
                antenna_id: Some(AntennaId(g.range(1, 4))),
                peak_rssi: Some(PeakRssi((rssi / 100) as i8)),
                channel_index: Some(ChannelIndex(g.range(1, 50))),
                first_seen_timestamp_utc: Some(FirstSeenTimestampUtc(seen)),
                last_seen_timestamp_utc: Some(LastSeenTimestampUtc(seen + 250)),
                tag_seen_count: Some(TagSeenCount(1)),
                custom: vec![
                    Custom::ImpinjRfPhaseAngle(ImpinjRfPhaseAngle {
                        phase_angle: g.range(0, 4095),
                        ..Default::default()
                    }),
                    Custom::ImpinjPeakRssi(ImpinjPeakRssi {
                        rssi,
                        ..Default::default()
                    }),
                ],
                ..Default::default()
            }
        })
        .collect();
    crate::Message::new(
        1,
        crate::message::RoAccessReport {
            tag_report_data,
            ..Default::default()
        },
    )
}

/// Most ParameterErrors that fit nested in one LLRPStatus (a TLV's length is 16 bits).
pub const MAX_FITTING_NESTING: usize = (u16::MAX as usize - 4 - 4 - 4) / 8;

/// A frame of message type `msg_type` whose body is one LLRPStatus (M_ParameterError) holding
/// a chain of `depth` ParameterErrors, each inside the one before: what a hostile peer sends
/// to exhaust a recursive decoder. Built iteratively; `depth` is capped at
/// [`MAX_FITTING_NESTING`].
pub fn nested_status_frame(msg_type: u16, id: u32, depth: usize) -> Vec<u8> {
    let depth = depth.min(MAX_FITTING_NESTING);
    // LLRPStatus: header, StatusCode, ErrorDescription (empty), then the chain; each
    // ParameterError: header, ParameterType (289), ErrorCode (P_ParameterError), the next.
    let status_len = 4 + 2 + 2 + 8 * depth;
    let mut f = Vec::with_capacity(10 + status_len);
    f.extend_from_slice(&((1u16 << 10) | (msg_type & 0x3FF)).to_be_bytes());
    f.extend_from_slice(&((10 + status_len) as u32).to_be_bytes());
    f.extend_from_slice(&id.to_be_bytes());
    f.extend_from_slice(&287u16.to_be_bytes());
    f.extend_from_slice(&(status_len as u16).to_be_bytes());
    f.extend_from_slice(&100u16.to_be_bytes());
    f.extend_from_slice(&0u16.to_be_bytes());
    for level in 0..depth {
        f.extend_from_slice(&289u16.to_be_bytes());
        f.extend_from_slice(&((8 * (depth - level)) as u16).to_be_bytes());
        f.extend_from_slice(&289u16.to_be_bytes());
        f.extend_from_slice(&200u16.to_be_bytes());
    }
    f
}
