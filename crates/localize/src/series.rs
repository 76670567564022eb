//! Phase series: the reads of one (reader, antenna, tag, channel), unwrapped.
//!
//! Consecutive reported phases are unwrapped by adding ±2π whenever they jump by more than π
//! (\[G\]'s "Shannon theorem"), which is right only while the antenna moves less than λ/4
//! between two reads of the tag (the round trip then changes by less than λ/2, the phase by
//! less than π). A read after a larger move starts a new segment, counted, since the turns in
//! between cannot be known; so does a read after a gap in time longer than the series allows.
//! A reader with Impinj's π ambiguity reports φ or φ + π at random: its phases are folded onto
//! [0, π) and unwrapped by ±π, which follows φ itself up to a constant, and the motion limit
//! halves to λ/8. A series never crosses
//! channels: each channel has its own λ and φ0.

use crate::{distance, Vec3};

/// How a reader's phase is ambiguous.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Ambiguity {
    /// The reported phase is the phase (mod 2π).
    #[default]
    None,
    /// The reported phase is the phase or the phase + π (Impinj's π ambiguity).
    Pi,
}

impl Ambiguity {
    /// The period the phase is known modulo.
    pub fn period(self) -> f64 {
        match self {
            Ambiguity::None => std::f64::consts::TAU,
            Ambiguity::Pi => std::f64::consts::PI,
        }
    }
}

/// One unwrapped sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// Read time, µs.
    pub t_us: u64,
    /// Unwrapped phase (rad; continuous within a segment, offset arbitrary).
    pub phase_rad: f64,
    /// Antenna position at the read (m).
    pub antenna: Vec3,
    /// Antenna yaw at the read (rad, about +z, 0 = +x).
    pub yaw_rad: f64,
    /// The phase as reported (rad), not unwrapped: equal to `phase_rad` modulo the ambiguity's
    /// period.
    pub raw_phase_rad: f64,
}

/// Antenna positions this close (m) to the first of a run of reads count as one place when a
/// series is thinned ([`Series::thin_places`]).
pub const SAME_PLACE_M: f64 = 0.005;
/// Reads of one place a thinned series keeps (besides a segment's last).
pub const KEPT_AT_ONE_PLACE: usize = 16;

/// The rule of [`Series::thin_places`] over one segment's antenna positions in order: of each
/// run within [`SAME_PLACE_M`] of its first, the first [`KEPT_AT_ONE_PLACE`] are kept.
#[derive(Clone, Copy, Debug, Default)]
pub struct Places {
    anchor: Option<[f64; 3]>,
    run: usize,
}

impl Places {
    /// Whether the phase read at `antenna`, next in its segment, is one the rule keeps.
    pub fn keeps(&mut self, antenna: [f64; 3]) -> bool {
        match self.anchor {
            Some(a) if distance(antenna, a) <= SAME_PLACE_M => self.run += 1,
            _ => (self.anchor, self.run) = (Some(antenna), 0),
        }
        self.run < KEPT_AT_ONE_PLACE
    }
}

/// Why a series starts a new segment between two reads.
#[derive(Clone, Copy)]
enum Split {
    /// The antenna moved too far to unwrap.
    Motion,
    /// Too long passed.
    Gap,
}

/// The step from unwrapped phase `prev` to the nearest turn of `folded` (a phase folded onto
/// `period`): within ±period/2.
fn step(folded: f64, prev: f64, period: f64) -> f64 {
    // Whole periods off by a floor, not `rem_euclid` (a libm fmod, a good part of filing a
    // read): `prev` grows along a segment, so the difference is not near one period.
    let x = folded - prev + period / 2.0;
    let mut r = x - (x / period).floor() * period;
    if r >= period {
        r -= period;
    } else if r < 0.0 {
        r += period;
    }
    r - period / 2.0
}

/// `phase` onto [0, `period`): a reported phase already is, or is one period above it
/// (π ambiguity), both exact without a libm fmod (so is a yaw in degrees, period 360).
pub(crate) fn fold(phase: f64, period: f64) -> f64 {
    if (0.0..period).contains(&phase) {
        phase
    } else if (period..2.0 * period).contains(&phase) {
        phase - period
    } else {
        phase.rem_euclid(period)
    }
}

/// Default longest time between two reads of one segment (µs): the motion check is what
/// keeps unwrapping right for a static tag; the gap bounds how long a tag may go unread
/// (moved by hand, a pose feed that stalled) before its phases start afresh. A slow robot
/// reads a tag on each antenna only every second or two (\[A\]'s 3.5 cm/s, 100 tags).
pub const DEFAULT_MAX_GAP_US: u64 = 10_000_000;

/// The segments of one (reader, antenna, tag, channel) series.
///
/// The samples of all segments lie in one vector, with the index where each segment starts:
/// thinning, dropping old segments and pushing new reads then move samples within it and
/// allocate only when it outgrows its capacity (a vector per segment, reallocated as each
/// grew, closed and thinned, left glibc's heap fragmented: a fleet worker's RSS grew by
/// 20 MiB a minute over a heap of bounded size).
#[derive(Clone, Debug)]
pub struct Series {
    wavelength_m: f64,
    ambiguity: Ambiguity,
    /// Longest time between two reads of one segment (µs).
    max_gap_us: u64,
    /// Every segment's samples, oldest segment first, each in time order.
    samples: Vec<Sample>,
    /// Where each segment starts in `samples` (the first at 0); the last is being extended.
    starts: Vec<usize>,
    /// Segments started because the antenna moved too far between two reads.
    splits_motion: u64,
    /// Segments started because too long passed between two reads.
    splits_gap: u64,
}

impl Series {
    /// An empty series on a channel of wavelength `wavelength_m`.
    pub fn new(wavelength_m: f64, ambiguity: Ambiguity, max_gap_us: u64) -> Series {
        Series {
            wavelength_m,
            ambiguity,
            max_gap_us,
            samples: Vec::new(),
            starts: Vec::new(),
            splits_motion: 0,
            splits_gap: 0,
        }
    }

    /// The channel's wavelength (m).
    pub fn wavelength_m(&self) -> f64 {
        self.wavelength_m
    }

    /// How the reader's phase is ambiguous.
    pub fn ambiguity(&self) -> Ambiguity {
        self.ambiguity
    }

    /// Largest antenna displacement between two reads that unwrapping can follow (m): λ/4,
    /// or λ/8 with the π ambiguity.
    pub fn motion_limit_m(&self) -> f64 {
        self.wavelength_m / 4.0 * self.ambiguity.period() / std::f64::consts::TAU
    }

    /// Adds a read of reported phase `phase_rad` with the antenna at `antenna`, its yaw
    /// `yaw_rad`. A read older than the newest held is put in its place in time, and the
    /// series comes out as it would have had the reads come in time order (a broker may
    /// deliver a tag's reads late; only phases thinned away before it came can differ).
    pub fn push(&mut self, t_us: u64, phase_rad: f64, antenna: Vec3, yaw_rad: f64) {
        if self.samples.last().is_some_and(|last| t_us < last.t_us) {
            self.insert_late(t_us, phase_rad, antenna, yaw_rad);
            return;
        }
        let folded = fold(phase_rad, self.ambiguity.period());
        let unwrapped = match self.samples.last().copied() {
            Some(prev) => self.link(&prev, t_us, folded, antenna),
            None => None,
        };
        if unwrapped.is_none() {
            self.starts.push(self.samples.len());
        }
        self.samples.push(Sample {
            t_us,
            phase_rad: unwrapped.unwrap_or(folded),
            antenna,
            yaw_rad,
            raw_phase_rad: phase_rad,
        });
    }

    /// Why a read at `t_us` with the antenna at `antenna` cannot follow `prev` in its
    /// segment, if it cannot: the antenna moved λ/4 (λ/8) or more, or too long passed.
    fn split(&self, prev: &Sample, t_us: u64, antenna: Vec3) -> Option<Split> {
        if distance(prev.antenna, antenna) >= self.motion_limit_m() {
            Some(Split::Motion)
        } else if t_us.saturating_sub(prev.t_us) > self.max_gap_us {
            Some(Split::Gap)
        } else {
            None
        }
    }

    /// The split counter of `why`.
    fn counter(&mut self, why: Split) -> &mut u64 {
        match why {
            Split::Motion => &mut self.splits_motion,
            Split::Gap => &mut self.splits_gap,
        }
    }

    /// The unwrapped phase of a read at `t_us` (`folded` onto the ambiguity's period, the
    /// antenna at `antenna`) that follows `prev` in its segment, or `None` when it starts a
    /// new one (the split counted).
    fn link(&mut self, prev: &Sample, t_us: u64, folded: f64, antenna: Vec3) -> Option<f64> {
        match self.split(prev, t_us, antenna) {
            Some(why) => {
                *self.counter(why) += 1;
                None
            }
            None => Some(prev.phase_rad + step(folded, prev.phase_rad, self.ambiguity.period())),
        }
    }

    /// Undoes the count of the split between `prev` and `next`, if there was one.
    fn unlink(&mut self, prev: &Sample, next: &Sample) {
        if let Some(why) = self.split(prev, next.t_us, next.antenna) {
            let n = self.counter(why);
            *n = n.saturating_sub(1);
        }
    }

    /// Puts a read older than the newest in its place: the links to the samples either side
    /// are made again, and the segment that follows it unwrapped again behind it.
    fn insert_late(&mut self, t_us: u64, phase_rad: f64, antenna: Vec3, yaw_rad: f64) {
        let period = self.ambiguity.period();
        let at = self.samples.partition_point(|s| s.t_us <= t_us);
        // In range: the newest sample is later than `t_us` (the caller's test).
        let next = self.samples[at];
        let prev = at.checked_sub(1).map(|i| self.samples[i]);
        let next_started = self.starts.binary_search(&at).is_ok();
        if let (Some(p), true) = (prev, next_started) {
            self.unlink(&p, &next);
        }
        let folded = phase_rad.rem_euclid(period);
        let unwrapped = match prev {
            Some(p) => self.link(&p, t_us, folded, antenna),
            None => None,
        };
        let new = Sample {
            t_us,
            phase_rad: unwrapped.unwrap_or(folded),
            antenna,
            yaw_rad,
            raw_phase_rad: phase_rad,
        };
        let next_folded = next.raw_phase_rad.rem_euclid(period);
        let next_phase = self.link(&new, next.t_us, next_folded, next.antenna);
        // The segment `next` now begins or continues, up to the next start after it.
        let end = self
            .starts
            .iter()
            .copied()
            .find(|&s| s > at)
            .unwrap_or(self.samples.len());
        // Each step again as in time order (the same operations, so the same bits), unless
        // it lands on another turn than before: then thinning had left too long a step to
        // unwrap, and the step as it was stands.
        let mut before = next.phase_rad;
        self.samples[at].phase_rad = next_phase.unwrap_or(next_folded);
        for j in at + 1..end {
            let (prev, s) = (self.samples[j - 1].phase_rad, self.samples[j]);
            let was = s.phase_rad - before;
            before = s.phase_rad;
            let now = step(s.raw_phase_rad.rem_euclid(period), prev, period);
            let now = if (now - was).abs() < period / 2.0 {
                now
            } else {
                was
            };
            self.samples[j].phase_rad = prev + now;
        }
        self.samples.insert(at, new);
        // Starts after the new sample move up by one; the new one and `next` (now at + 1)
        // start segments when their links failed.
        self.starts.retain(|&s| s != at);
        for s in &mut self.starts {
            if *s > at {
                *s += 1;
            }
        }
        let mut fresh = Vec::with_capacity(2);
        if unwrapped.is_none() {
            fresh.push(at);
        }
        if next_phase.is_none() {
            fresh.push(at + 1);
        }
        let k = self.starts.partition_point(|&s| s < at);
        self.starts.splice(k..k, fresh);
    }

    /// Phases held, over all segments.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// Whether no phase is held.
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// Drops reads that add no aperture: of each run of a segment's reads whose antenna
    /// stayed within [`SAME_PLACE_M`] of the run's first, keeps the first
    /// [`KEPT_AT_ONE_PLACE`] and the segment's last (which the next read is unwrapped
    /// against). A parked antenna's thousands of reads then weigh as a few, and the reads
    /// that made the aperture are all kept.
    pub fn thin_places(&mut self) {
        let mut kept = 0;
        for k in 0..self.starts.len() {
            let (a, b) = self.bounds(k);
            self.starts[k] = kept;
            let mut place = Places::default();
            for i in a..b {
                if place.keeps(self.samples[i].antenna) || i + 1 == b {
                    self.samples[kept] = self.samples[i];
                    kept += 1;
                }
            }
        }
        self.samples.truncate(kept);
    }

    /// Keeps every other phase of each segment, and each segment's last (which the next read
    /// is unwrapped against): the aperture stays, the density halves.
    pub fn thin(&mut self) {
        let mut kept = 0;
        for k in 0..self.starts.len() {
            let (a, b) = self.bounds(k);
            self.starts[k] = kept;
            for i in a..b {
                if (i - a) % 2 == 0 || i + 1 == b {
                    self.samples[kept] = self.samples[i];
                    kept += 1;
                }
            }
        }
        self.samples.truncate(kept);
    }

    /// Drops the segments numbered in `which` (0 the oldest).
    pub fn drop_segments(&mut self, which: &[usize]) {
        let mut kept = 0;
        let mut starts = Vec::with_capacity(self.starts.len());
        for k in 0..self.starts.len() {
            if which.contains(&k) {
                continue;
            }
            let (a, b) = self.bounds(k);
            starts.push(kept);
            self.samples.copy_within(a..b, kept);
            kept += b - a;
        }
        self.samples.truncate(kept);
        self.starts = starts;
    }

    /// Where segment `k` lies in `samples`.
    fn bounds(&self, k: usize) -> (usize, usize) {
        let end = self
            .starts
            .get(k + 1)
            .copied()
            .unwrap_or(self.samples.len());
        (self.starts[k], end)
    }

    /// The segments, oldest first.
    pub fn segments(&self) -> impl ExactSizeIterator<Item = &[Sample]> + DoubleEndedIterator {
        (0..self.starts.len()).map(|k| {
            let (a, b) = self.bounds(k);
            &self.samples[a..b]
        })
    }

    /// Every sample, segment after segment.
    pub fn samples(&self) -> &[Sample] {
        &self.samples
    }

    /// Samples this series has room for without allocating.
    pub fn capacity(&self) -> usize {
        self.samples.capacity()
    }

    /// Segments started because the antenna moved λ/4 (λ/8) or more between two reads, and
    /// because more than the gap passed.
    pub fn splits(&self) -> (u64, u64) {
        (self.splits_motion, self.splits_gap)
    }
}

#[cfg(test)]
mod tests;
