//! Read scheduling: the reader's read budget as a grid of attempt slots in absolute time, and
//! how likely an attempt is to succeed near the edge of the read zone.
//!
//! Slot k covers `[k·P, (k+1)·P)` µs with P = 10⁶ / reads_per_second; its attempt happens at a
//! jittered instant inside the slot, drawn from a generator seeded by the slot number (a
//! SplitMix64 stream, [`seed::stream`]: an attempt draws only a handful of numbers). A window
//! `[t0, t1)` holds exactly the attempts whose instants fall inside it, so windows of any
//! length — shorter than one slot too — average the right rate, and splitting a window in two
//! gives the same attempts.

use rand::Rng;

use super::seed::{self, Stream};

/// Slot period in µs for a read budget (attempts per second).
pub fn slot_period_us(reads_per_second: f64) -> f64 {
    1e6 / reads_per_second
}

/// One attempt slot: its number, its instant, and the generator for its draws.
pub struct Slot {
    /// Slot number k (absolute, from scenario start).
    pub k: u64,
    /// Instant of the attempt (µs).
    pub time_us: u64,
    /// Generator for every draw of this attempt.
    pub rng: Stream,
}

/// Most attempt slots one call returns (a window beyond that is cut short; at 1000 reads/s
/// this is close to three hours).
pub const MAX_SLOTS: u64 = 10_000_000;

/// The attempt slots whose instants fall in `[t0_us, t1_us)`, in time order (at most
/// [`MAX_SLOTS`]). `key` identifies the draw stream (scenario seed, reader, antenna).
pub fn slots(key: [u64; 3], reads_per_second: f64, t0_us: u64, t1_us: u64) -> Vec<Slot> {
    slot_iter(key, reads_per_second, t0_us, t1_us).collect()
}

/// The slots of [`slots`], one at a time.
pub fn slot_iter(key: [u64; 3], reads_per_second: f64, t0_us: u64, t1_us: u64) -> SlotIter {
    let usable = reads_per_second > 0.0 && reads_per_second.is_finite() && t1_us > t0_us;
    let period = slot_period_us(reads_per_second);
    let (next, last) = if usable {
        let first = (t0_us as f64 / period).floor().max(0.0) as u64;
        let last = ((t1_us as f64 / period).ceil() as u64).min(first.saturating_add(MAX_SLOTS));
        (first, last)
    } else {
        (1, 0)
    };
    SlotIter {
        prefix: seed::mix(&[key[0], seed::domain::SLOT, key[1], key[2]]),
        period,
        t0_us,
        t1_us,
        next,
        last,
    }
}

/// Iterator over the attempt slots of a window; see [`slot_iter`].
#[derive(Clone, Debug)]
pub struct SlotIter {
    /// The slot streams' seed words before the slot number, mixed once.
    prefix: u64,
    period: f64,
    t0_us: u64,
    t1_us: u64,
    /// Next slot number to look at; none left once it passes `last`.
    next: u64,
    last: u64,
}

impl Iterator for SlotIter {
    type Item = Slot;

    fn next(&mut self) -> Option<Slot> {
        while self.next <= self.last {
            let k = self.next;
            self.next += 1;
            // seed::stream(&[key[0], SLOT, key[1], key[2], k]), its prefix mixed once.
            let mut rng = seed::stream_on(self.prefix, &[k]);
            let jitter: f64 = rng.gen();
            let t = (k as f64 + jitter) * self.period;
            if !(t.is_finite() && t >= 0.0) {
                continue;
            }
            // Truncation is the floor of a non-negative time.
            let time_us = t as u64;
            if time_us >= self.t1_us {
                // Instants grow with k: nothing later falls in the window.
                self.next = self.last.saturating_add(1);
                return None;
            }
            if time_us >= self.t0_us {
                return Some(Slot { k, time_us, rng });
            }
        }
        None
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        let left = self.last.saturating_add(1).saturating_sub(self.next);
        (0, usize::try_from(left).ok())
    }
}

/// Midpoint of the success probability, in dB of forward-link margin above the tag's
/// sensitivity.
pub const EDGE_MARGIN_DB: f64 = 1.0;
/// Width of the logistic fall-off, in dB.
pub const EDGE_WIDTH_DB: f64 = 0.5;

/// Probability that an attempt on a tag powered `margin_db` above its sensitivity succeeds:
/// 0 below the sensitivity, then logistic in the margin (½ at 1 dB, 0.98 at 3 dB).
pub fn read_probability(margin_db: f64) -> f64 {
    if margin_db.is_nan() || margin_db < 0.0 {
        return 0.0;
    }
    let p = 1.0 / (1.0 + (-(margin_db - EDGE_MARGIN_DB) / EDGE_WIDTH_DB).exp());
    if p.is_finite() {
        p
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slots_cover_the_budget_and_split_consistently() {
        let key = [1, 0, 1];
        let all = slots(key, 1000.0, 0, 1_000_000);
        assert_eq!(all.len(), 1000);
        assert!(all.windows(2).all(|w| w[0].time_us < w[1].time_us));
        // Any split of the window yields the same attempts.
        let mut parts = Vec::new();
        let mut t = 0;
        for len in [1, 333, 7, 250_000, 123_457, 1_000_000] {
            let end = (t + len).min(1_000_000);
            parts.extend(
                slots(key, 1000.0, t, end)
                    .into_iter()
                    .map(|s| (s.k, s.time_us)),
            );
            t = end;
        }
        let whole: Vec<_> = all.iter().map(|s| (s.k, s.time_us)).collect();
        assert_eq!(parts, whole);
    }

    #[test]
    fn short_windows_average_the_rate() {
        // 300 reads/s in 1 ms windows: 0.3 per window on average.
        let n: usize = (0..10_000u64)
            .map(|i| slots([9, 0, 1], 300.0, i * 1000, (i + 1) * 1000).len())
            .sum();
        assert_eq!(n, 3000);
        assert!(slots([9, 0, 1], 0.0, 0, 1000).is_empty());
        assert!(slots([9, 0, 1], 1000.0, 50, 50).is_empty());
    }

    #[test]
    fn edge_probability_falls_off() {
        assert_eq!(read_probability(-0.1), 0.0);
        assert_eq!(read_probability(f64::NEG_INFINITY), 0.0);
        assert!((read_probability(EDGE_MARGIN_DB) - 0.5).abs() < 1e-12);
        assert!(read_probability(3.0) > 0.97);
        assert!(read_probability(20.0) > 0.999_999);
        assert!(read_probability(0.5) < read_probability(1.5));
    }
}
