//! [`Backoff`]: the one back-off between attempts that every part which retries uses: the
//! inventory client's reconnections ([`super::client`]), the MQTT publisher's and the MQTT
//! workers' (`crate::fleet`), and the pause after a failed accept of every LLRP server
//! ([`super::serve`], [`super::drive`]). It is here, in the socket layer, because all of them
//! may name `net` (ARCHITECTURE.md's rules 8, 9 and 13); it needs no async runtime (the fleet's
//! threads sleep, the servers' tasks await, for the wait it gives).

use std::time::Duration;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Capped exponential back-off with "equal jitter" (Marc Brooker, "Exponential Backoff And
/// Jitter", AWS Architecture Blog, 2015: `t = min(cap, base·2^n)`, a wait drawn uniformly
/// from `[t/2, t]`), counting failures in a row from n = 1 and never below `base`: the first
/// wait is drawn from `[base, 2·base]`, the second from `[2·base, 4·base]`, …, and once the
/// cap is reached from `[cap/2, cap]` (from `[base, cap]` when the cap is below `2·base`).
///
/// So every wait is within `[base, cap]`; below the cap each window starts where the one
/// before ended, so the waits grow; and clients that failed together, a fleet whose broker
/// restarted, spread over half of each window instead of coming back in lockstep. Full jitter (`[0, t]`) spreads wider but may retry at once, which
/// would break the `--backoff-ms` floor the inventory client documents.
///
/// After `retries` failures in a row (`None`: never) there is no next attempt
/// ([`next_delay`](Backoff::next_delay) gives `None`); [`reset`](Backoff::reset) after a
/// success starts over. Drawn from a ChaCha stream seeded at random, or from
/// [`seeded`](Backoff::seeded) where a test needs the same waits every run.
#[derive(Clone, Debug)]
pub struct Backoff {
    base: Duration,
    cap: Duration,
    retries: Option<u32>,
    failures: u32,
    rng: ChaCha8Rng,
}

impl Backoff {
    /// Waits from `base` up to `cap` (at least `base`), allowing `retries` retries after
    /// failures in a row (`None`: unlimited); seeded at random.
    pub fn new(base: Duration, cap: Duration, retries: Option<u32>) -> Self {
        Backoff {
            base,
            cap: cap.max(base),
            retries,
            failures: 0,
            rng: ChaCha8Rng::seed_from_u64(rand::random()),
        }
    }

    /// The same back-off drawing its jitter from `seed`: the same waits every run.
    pub fn seeded(mut self, seed: u64) -> Self {
        self.rng = ChaCha8Rng::seed_from_u64(seed);
        self
    }

    /// Records a failed attempt; the wait before the next one, or `None` when no retry is
    /// left.
    pub fn next_delay(&mut self) -> Option<Duration> {
        let wait = self.failed();
        match self.retries {
            Some(r) if self.failures > r => None,
            _ => Some(wait),
        }
    }

    /// Records a failed attempt; the wait before the next one, whatever the retry limit (for
    /// the loops that retry for as long as they run).
    pub fn failed(&mut self) -> Duration {
        self.failures = self.failures.saturating_add(1);
        let (lo, hi) = self.window();
        let wait = Duration::from_nanos(self.rng.gen_range(lo..=hi));
        // Whole milliseconds where the window allows, so that logs read `reconnecting in
        // 734ms`; the rounding down stays within the window.
        let ms = Duration::from_millis(wait.as_millis() as u64);
        if ms.as_nanos() >= u128::from(lo) {
            ms
        } else {
            wait
        }
    }

    /// The window (ns) of the current failure's wait: `[max(base, t/2), t]`, `t =
    /// min(cap, base·2^failures)`.
    fn window(&self) -> (u64, u64) {
        let nanos = |d: Duration| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX);
        let (base, cap) = (nanos(self.base), nanos(self.cap));
        // 2^64 already exceeds any cap held in u64 nanoseconds.
        let factor = 1u128 << self.failures.min(64);
        let t = u128::from(base).saturating_mul(factor).min(u128::from(cap));
        // `t` is at most `cap`, a u64.
        let t = u64::try_from(t).unwrap_or(cap);
        ((t / 2).max(base).min(t), t)
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
    fn every_wait_is_within_base_and_cap_and_they_grow_until_the_cap() {
        for seed in 0..200 {
            let mut b = Backoff::new(ms(100), ms(5000), None).seeded(seed);
            let waits: Vec<_> = (0..12).map(|_| b.failed()).collect();
            for (n, w) in waits.iter().enumerate() {
                assert!(
                    *w >= ms(100) && *w <= ms(5000),
                    "seed {seed} wait {n}: {w:?}"
                );
            }
            // [100, 200], [200, 400], [400, 800], [800, 1600], [1600, 3200]: each no shorter
            // than the one before; then [2500, 5000] at the cap.
            for pair in waits[..5].windows(2) {
                assert!(pair[1] >= pair[0], "seed {seed}: {waits:?}");
            }
            assert!(waits[0] <= ms(200) && waits[1] >= ms(200) && waits[1] <= ms(400));
            assert!(
                waits[5..].iter().all(|w| *w >= ms(2500)),
                "seed {seed}: {waits:?}"
            );
        }
    }

    #[test]
    fn the_first_wait_is_jittered_too() {
        let firsts: std::collections::BTreeSet<_> = (0..50)
            .map(|seed| {
                Backoff::new(ms(500), ms(30_000), None)
                    .seeded(seed)
                    .failed()
            })
            .collect();
        assert!(firsts.len() > 10, "{firsts:?}");
        assert!(firsts.iter().all(|w| *w >= ms(500) && *w <= ms(1000)));
    }

    #[test]
    fn a_success_starts_it_over_and_the_retries_run_out() {
        let mut b = Backoff::new(ms(100), ms(1000), Some(6)).seeded(1);
        let waits: Vec<_> = std::iter::from_fn(|| b.next_delay()).collect();
        assert_eq!(waits.len(), 6);
        assert!(waits[5] >= ms(500), "{waits:?}");
        assert_eq!(b.next_delay(), None, "still none after the last retry");
        assert_eq!(b.failures(), 8);
        b.reset();
        let again = b.next_delay().expect("a retry after the success");
        assert!(again >= ms(100) && again <= ms(200), "{again:?}");
        let mut zero = Backoff::new(ms(50), ms(10), Some(0));
        assert_eq!(
            zero.next_delay(),
            None,
            "no retries: the first failure is the last"
        );
    }

    #[test]
    fn two_seeds_draw_different_waits_and_one_seed_the_same() {
        let run = |seed| {
            let mut b = Backoff::new(ms(100), ms(30_000), None).seeded(seed);
            (0..10).map(|_| b.failed()).collect::<Vec<_>>()
        };
        assert_ne!(run(1), run(2), "a fleet does not come back in lockstep");
        assert_eq!(run(3), run(3));
        // Unseeded back-offs too (drawn from the system's randomness).
        let mut a = Backoff::new(ms(100), ms(30_000), None);
        let mut b = Backoff::new(ms(100), ms(30_000), None);
        let (a, b): (Vec<_>, Vec<_>) = (0..10).map(|_| (a.failed(), b.failed())).unzip();
        assert_ne!(a, b);
    }

    #[test]
    fn a_cap_at_the_base_gives_the_base_and_a_long_run_keeps_the_cap() {
        let mut flat = Backoff::new(ms(50), ms(10), None);
        assert!((0..5).all(|_| flat.failed() == ms(50)));
        let mut long = Backoff::new(ms(1), ms(3_600_000), None).seeded(9);
        let last = (0..1000).map(|_| long.failed()).last().expect("a thousand");
        assert!(last >= ms(1_800_000) && last <= ms(3_600_000), "{last:?}");
    }
}
