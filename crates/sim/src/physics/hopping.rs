//! Frequency hopping: which channel the reader transmits on at a given time.
//!
//! The reader walks its table in table order (for FCC the table itself is in a pseudo-random
//! order), staying `dwell` on each channel: position = ⌊t / dwell⌋ mod n. All regions rotate
//! this way — ETSI readers too, since EN 302 208 limits continuous transmission on one channel
//! to 4 s — unless the scenario pins a `fixed_channel`.

/// A reader's channel schedule.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HopSchedule {
    /// Number of channels in the table (at least 1).
    pub channels: u16,
    /// Time on each channel in µs (at least 1).
    pub dwell_us: u64,
    /// The one channel used when set (1-based).
    pub fixed: Option<u16>,
}

impl HopSchedule {
    /// A schedule over `channels` channels with `dwell_ms` per channel, or pinned to `fixed`.
    pub fn new(channels: usize, dwell_ms: f64, fixed: Option<u16>) -> HopSchedule {
        let channels = u16::try_from(channels.max(1)).unwrap_or(u16::MAX);
        let dwell = (dwell_ms * 1000.0).round();
        let dwell_us = if dwell.is_finite() && dwell >= 1.0 {
            dwell as u64
        } else {
            1
        };
        HopSchedule {
            channels,
            dwell_us,
            fixed: fixed.filter(|&c| (1..=channels).contains(&c)),
        }
    }

    /// The 1-based channel in use at `t_us`.
    pub fn channel_at(&self, t_us: u64) -> u16 {
        match self.fixed {
            Some(c) => c,
            None => ((t_us / self.dwell_us) % u64::from(self.channels)) as u16 + 1,
        }
    }

    /// Start time (µs) of the dwell containing `t_us`.
    pub fn dwell_start(&self, t_us: u64) -> u64 {
        t_us - t_us % self.dwell_us
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hops_through_every_channel_with_the_right_dwell() {
        let s = HopSchedule::new(50, 400.0, None);
        let mut seen = vec![0u32; 50];
        let mut changes = Vec::new();
        let mut last = s.channel_at(0);
        // Sample every millisecond over two full cycles.
        for ms in 0..(2 * 50 * 400) {
            let c = s.channel_at(ms * 1000);
            assert!((1..=50).contains(&c));
            seen[usize::from(c - 1)] += 1;
            if c != last {
                changes.push(ms);
                last = c;
            }
        }
        assert!(seen.iter().all(|&n| n == 800), "{seen:?}");
        assert_eq!(changes.len(), 99);
        assert!(changes.windows(2).all(|w| w[1] - w[0] == 400));
        assert_eq!(changes[0], 400);
        assert_eq!(s.channel_at(399_999), 1);
        assert_eq!(s.channel_at(400_000), 2);
        assert_eq!(s.dwell_start(401_234), 400_000);
    }

    #[test]
    fn fixed_channel_and_degenerate_inputs() {
        let s = HopSchedule::new(4, 4000.0, Some(3));
        assert!((0..100).all(|i| s.channel_at(i * 1_000_000) == 3));
        let bad = HopSchedule::new(0, f64::NAN, Some(9));
        assert_eq!(bad.channels, 1);
        assert_eq!(bad.fixed, None);
        assert_eq!(bad.channel_at(12_345), 1);
    }
}
