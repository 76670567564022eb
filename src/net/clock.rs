//! Simulated time: real time, real time scaled by a factor, or as fast as the client drains.

use std::str::FromStr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use crate::reader::session::Deadline;

/// How fast simulated time runs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Speed {
    /// Simulated time runs this many times faster than real time (1.0 = real time).
    Factor(f64),
    /// Simulated time advances in steps as soon as the client has taken the previous step's
    /// reports.
    Max,
}

impl FromStr for Speed {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if s.eq_ignore_ascii_case("max") {
            return Ok(Speed::Max);
        }
        match s.parse::<f64>() {
            Ok(x) if x.is_finite() && x > 0.0 => Ok(Speed::Factor(x)),
            _ => Err(format!(
                "speed must be a positive number or `max`, got `{s}`"
            )),
        }
    }
}

/// Simulated step taken each time the client has drained the previous one (`--speed max`).
pub const MAX_SPEED_STEP_US: u64 = 100_000;

/// The simulated clock shared by a reader's connections.
#[derive(Debug)]
pub struct Clock {
    speed: Speed,
    start: Instant,
    /// Simulated µs reached in `Max` mode.
    stepped_us: AtomicU64,
}

impl Clock {
    /// A clock starting now at simulated time 0.
    pub fn new(speed: Speed) -> Self {
        Clock {
            speed,
            start: Instant::now(),
            stepped_us: AtomicU64::new(0),
        }
    }

    /// The speed setting.
    pub fn speed(&self) -> Speed {
        self.speed
    }

    /// Wall-clock milliseconds since the clock started.
    pub fn wall_ms(&self) -> u64 {
        self.start.elapsed().as_millis() as u64
    }

    /// Current simulated time, µs.
    pub fn now_us(&self) -> u64 {
        match self.speed {
            Speed::Factor(f) => (self.start.elapsed().as_secs_f64() * 1e6 * f) as u64,
            Speed::Max => self.stepped_us.load(Ordering::Relaxed),
        }
    }

    /// The instant a session's deadline falls due: its keepalive on the wall clock and, in
    /// real-time modes, its simulated deadline (just past it, so that the simulated time read
    /// then has reached it). `--speed max` steps simulated time itself, so only the keepalive
    /// counts there.
    pub fn wake_at(&self, d: Deadline) -> Option<Instant> {
        let wall = d.wall_ms.map(|ms| self.start + Duration::from_millis(ms));
        let sim = match self.speed {
            Speed::Factor(f) => d
                .sim_us
                .map(|us| self.start + Duration::from_secs_f64((us + 1) as f64 / 1e6 / f)),
            Speed::Max => None,
        };
        match (wall, sim) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// In `Max` mode, moves simulated time one step on and returns it.
    pub fn step(&self) -> u64 {
        self.stepped_us
            .fetch_add(MAX_SPEED_STEP_US, Ordering::Relaxed)
            + MAX_SPEED_STEP_US
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn speed_parses_numbers_and_max() {
        assert_eq!("max".parse::<Speed>(), Ok(Speed::Max));
        assert_eq!("2.5".parse::<Speed>(), Ok(Speed::Factor(2.5)));
        assert!("0".parse::<Speed>().is_err());
        assert!("-1".parse::<Speed>().is_err());
        assert!("fast".parse::<Speed>().is_err());
    }

    #[test]
    fn max_clock_moves_only_when_stepped() {
        let c = Clock::new(Speed::Max);
        assert_eq!(c.now_us(), 0);
        assert_eq!(c.step(), MAX_SPEED_STEP_US);
        assert_eq!(c.now_us(), MAX_SPEED_STEP_US);
    }
}
