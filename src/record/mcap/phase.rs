//! Each tag's phase unwrapped along its stream (one tag, antenna and channel of one reader),
//! for `llrp_gateway_msgs/msg/TagPhase` on `/llrp/READER/phase_unwrapped`: the reads' phase
//! as a time series without its 2π wraps. Phase jumps between channels are not unwrapped
//! across: each channel is a stream of its own.

use std::collections::HashMap;
use std::f64::consts::TAU;

use crate::reads::Read;

/// One stream: the reader's topic token, the EPC, the antenna, the channel index and the
/// channel's frequency (0 for none).
type Stream = (String, String, u16, u16, u64);

/// The newest unwrapped phase of every stream seen.
#[derive(Debug, Default)]
pub struct Unwrapper {
    last: HashMap<Stream, f64>,
}

impl Unwrapper {
    /// Read `r` of reader `token`'s phase unwrapped along its stream: its raw phase plus the
    /// multiple of 2π that puts it within π of the stream's previous value (its raw phase
    /// for a stream's first read); `None` for a read with no (finite) phase.
    pub fn unwrap(&mut self, token: &str, r: &Read) -> Option<f64> {
        let raw = r.phase_rad.filter(|p| p.is_finite())?;
        let key = (
            token.to_string(),
            r.epc.as_str().to_string(),
            r.antenna,
            r.channel_index.unwrap_or(0),
            r.channel_frequency_hz.unwrap_or(0),
        );
        let unwrapped = match self.last.get(&key) {
            Some(last) => raw + TAU * ((last - raw) / TAU).round(),
            None => raw,
        };
        self.last.insert(key, unwrapped);
        Some(unwrapped)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reads::Epc;

    fn read(epc: &str, channel: u16, phase: f64) -> Read {
        Read {
            epc: Epc::parse(epc).expect("an EPC"),
            reader: None,
            antenna: 1,
            t_us: 0,
            phase_rad: Some(phase),
            rssi_dbm: None,
            channel_index: Some(channel),
            channel_frequency_hz: None,
            doppler_hz: None,
            antenna_pose: None,
            last_seen_us: None,
        }
    }

    #[test]
    fn a_stream_that_wraps_is_unwrapped_and_another_channel_starts_its_own() {
        let mut u = Unwrapper::default();
        let mut got = Vec::new();
        for p in [6.0, 0.1, 0.5, 6.2, 5.9] {
            got.push(u.unwrap("r", &read("AA", 1, p)).expect("a phase"));
        }
        let want = [6.0, 0.1 + TAU, 0.5 + TAU, 6.2, 5.9];
        for (g, w) in got.iter().zip(want) {
            assert!((g - w).abs() < 1e-12, "{got:?} vs {want:?}");
        }
        // Another channel, another tag: streams of their own, from their raw phase.
        assert_eq!(u.unwrap("r", &read("AA", 2, 0.2)), Some(0.2));
        assert_eq!(u.unwrap("r", &read("BB", 1, 0.3)), Some(0.3));
        assert_eq!(
            u.unwrap(
                "r",
                &Read {
                    phase_rad: None,
                    ..read("AA", 1, 0.0)
                }
            ),
            None
        );
    }
}
