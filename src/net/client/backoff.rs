//! [`Backoff`]: the capped exponential back-off between connection attempts.

use std::time::Duration;

/// Capped exponential back-off between connection attempts: `initial`, twice that, four
/// times, … never more than `max`; after `retries` failed retries in a row (`None`: never)
/// there is no next attempt. Deterministic (no jitter): one client per reader.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Backoff {
    initial: Duration,
    max: Duration,
    retries: Option<u32>,
    failures: u32,
}

impl Backoff {
    /// A schedule starting at `initial`, capped at `max` (at least `initial`), allowing
    /// `retries` retries after failures in a row (`None`: unlimited).
    pub fn new(initial: Duration, max: Duration, retries: Option<u32>) -> Self {
        Backoff {
            initial,
            max: max.max(initial),
            retries,
            failures: 0,
        }
    }

    /// Records a failed attempt; the wait before the next one, or `None` when no retry is
    /// left.
    pub fn next_delay(&mut self) -> Option<Duration> {
        self.failures = self.failures.saturating_add(1);
        if self.retries.is_some_and(|r| self.failures > r) {
            return None;
        }
        // 2^(failures-1), saturating long before u32 runs out: the cap applies anyway.
        let factor = 1u32 << (self.failures - 1).min(20);
        Some(self.initial.saturating_mul(factor).min(self.max))
    }

    /// Failed attempts in a row so far.
    pub fn failures(&self) -> u32 {
        self.failures
    }

    /// The retries allowed after failures in a row (`None`: unlimited).
    pub fn retries(&self) -> Option<u32> {
        self.retries
    }

    /// Starts over after a success.
    pub fn reset(&mut self) {
        self.failures = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    #[test]
    fn the_backoff_doubles_up_to_its_cap_and_stops_after_the_retries() {
        let mut b = Backoff::new(ms(100), ms(1000), Some(6));
        let delays: Vec<_> = std::iter::from_fn(|| b.next_delay()).collect();
        assert_eq!(
            delays,
            [ms(100), ms(200), ms(400), ms(800), ms(1000), ms(1000)]
        );
        assert_eq!(b.next_delay(), None, "still none after the last retry");
        b.reset();
        assert_eq!(b.next_delay(), Some(ms(100)), "a success starts it over");
    }

    #[test]
    fn an_unlimited_backoff_keeps_its_cap() {
        let mut b = Backoff::new(ms(500), ms(30_000), None);
        let last = (0..1000).map(|_| b.next_delay()).last().flatten();
        assert_eq!(last, Some(ms(30_000)));
        let mut zero = Backoff::new(ms(50), ms(10), Some(0));
        assert_eq!(
            zero.next_delay(),
            None,
            "no retries: the first failure is the last"
        );
    }
}
