//! The live localizer: a worker thread that takes LLRP frames, reads and antenna poses through
//! a bounded [`Tap`] (which never waits: what does not fit is dropped and counted), files the
//! reads into phase series, re-estimates the tags whose series changed and publishes the
//! estimates to [`Shared`].
//!
//! A read that carries its antenna's pose is filed at once. One whose antenna has no pose at
//! or after the read's time yet waits (a robot's pose
//! may arrive after the reads it explains, and over MQTT on another topic) until one comes,
//! for at most [`POSE_WAIT`], or until [`MAX_WAITING`] reads wait; then it is filed or set
//! aside. Whether a read waits depends on its own time and the poses alone, not on other
//! tags' reads, so workers on different shards file a tag's reads alike.
//!
//! Memory is bounded per tag ([`crate::ingest::Ingest::bound_tag`]): when a tag holds more
//! than [`Settings::max_samples_per_tag`] phases, the reads that add no aperture go first
//! (a parked antenna's), then its segments read from one place, then every series of it is
//! thinned to every other sample (the newest kept), so the aperture stays and the density
//! falls off with age; if that leaves more than three quarters of the bound (segments of one
//! or two phases, which do not thin), the tag's oldest segments are dropped down to half the
//! bound.
//!
//! A tag that `relock` has located (converged) is updated from its last fix instead of the
//! grid search, which is most of an update's cost; an update that does not converge from
//! there is done again from the grid, as is one after [`REFRESH`] of such updates. Such
//! a warm estimate depends on when the updates ran, so once the tag has had no new read for
//! [`SETTLE`] it is estimated once more from the grid, and published when that differs from
//! the warm one by more than [`SETTLED_SAME_M`]: what a tag settles at is a function of its
//! reads alone (two workers on different shards publish what one does).
//!
//! With a stated pose error (a robot's localization stack's), the antenna positions are
//! corrected from every tag's phases as `localize` does offline ([`crate::refine`]), again
//! each time the reads' clock has moved on by [`REFINE_EVERY_US`] or a tenth of the time read
//! so far, and every tag is estimated again on them.

use llrp_gateway_vocab::epc::Epc;
use std::collections::{BTreeMap, HashMap, VecDeque};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::estimator::Takes;
use crate::ingest::Ingest;
use crate::poses::{PoseSample, Poses};
use crate::shared::{AntennaView, Shared, TagView, RECENT_READS};
use llrp_gateway_vocab::reads::Read;

pub use crate::settings::Settings;
pub use llrp_gateway_vocab::feed::{Input, Mirror, Tap};

mod refinement;
mod rounds;

pub use refinement::{REFINED_SAME_M, REFINE_EVERY_US};
pub use rounds::{REFRESH, SETTLE, SETTLED_SAME_M};

/// Longest a read waits for a pose at or after its time (wall-clock time at the localizer).
pub const POSE_WAIT: Duration = Duration::from_secs(2);

/// How much of each antenna's pose track the live localizer keeps (µs), for the estimators
/// that do not walk the path driven (all but mhekf and wls, which keep up to
/// [`crate::poses::MAX_TRACK`] samples).
pub const POSE_KEEP_US: u64 = 60_000_000;

/// Most reads waiting for a pose; beyond it the oldest is filed (or set aside) at once.
pub const MAX_WAITING: usize = 100_000;

/// How often the live localizer gives the allocator's free memory back
/// ([`Settings::release_memory`]).
const RELEASE_EVERY: Duration = Duration::from_secs(10);

/// Reader time over which read rates are counted (µs).
const RATE_WINDOW_US: u64 = 2_000_000;

/// A reader or tag that sent no read for this long (wall clock) shows a rate of 0.
const RATE_SILENCE: Duration = Duration::from_secs(3);

/// A running live localizer.
pub struct Live {
    /// Where to send its input.
    pub tap: Tap,
    /// What it publishes.
    pub shared: Arc<Shared>,
    worker: Option<JoinHandle<()>>,
    stop: Arc<AtomicBool>,
}

impl Live {
    /// Starts the worker thread.
    pub fn start(settings: Settings) -> std::io::Result<Live> {
        let shared = Arc::new(Shared::new());
        let (tx, rx) = mpsc::sync_channel(settings.tap_capacity.max(1));
        let worker = Worker::new(settings, shared.clone());
        let stop = Arc::new(AtomicBool::new(false));
        let stopping = stop.clone();
        let handle = std::thread::Builder::new()
            .name("localizer".into())
            .spawn(move || worker.run(rx, &stopping))?;
        Ok(Live {
            tap: Tap::new(
                tx,
                shared.metrics.dropped_taps.clone(),
                shared.links().clone(),
            ),
            shared,
            worker: Some(handle),
            stop,
        })
    }

    /// Stops the worker once it has taken in what is already there, and waits for it (taps
    /// still held elsewhere are refused from then on).
    pub fn stop(mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(h) = self.worker.take() {
            let _ = h.join();
        }
    }
}

impl Drop for Live {
    fn drop(&mut self) {
        // Not waited for: the worker ends within its next wait.
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// Per-tag bookkeeping of the worker.
#[derive(Default)]
struct TagState {
    /// A read came since the last estimate; with its arrival time.
    dirty_since: Option<Instant>,
    last_estimate: Option<Instant>,
    /// The last `relock` fix, where it converged: the next update starts from it.
    warm: Option<[f64; 3]>,
    /// When the first update from the previous fix since the last from the grid ran.
    warm_since: Option<Instant>,
    /// The last estimate started from the previous fix: one from the grid is owed once the
    /// tag settles.
    settle_due: bool,
    rate_start_us: u64,
    rate_count: u64,
    /// When its last read arrived (for [`RATE_SILENCE`]); `None` once its rate shows 0.
    read_at: Option<Instant>,
}

struct Worker {
    settings: Settings,
    shared: Arc<Shared>,
    ingest: Ingest,
    decoders: llrp_gateway_vocab::reads::Decoders,
    /// Reads waiting for a pose, with their arrival.
    waiting: VecDeque<(Read, Instant)>,
    reader_rates: HashMap<String, (u64, u64)>,
    /// When each reader's last read arrived; removed once its rate shows 0.
    reader_read_at: HashMap<String, Instant>,
    /// When the rates were last checked for silence.
    silence_checked: Instant,
    tags: BTreeMap<Epc, TagState>,
    set_aside_seen: u64,
    /// Input came since the waiting reads were last looked at.
    taken_since_flush: bool,
    /// The readers whose first pose the geometry was derived with.
    derived: std::collections::BTreeSet<String>,
    /// The first and the newest time of a filed read (µs, the reads' clock).
    read_span_us: Option<(u64, u64)>,
    /// The newest read's time when the poses were last refined.
    refined_at_us: Option<u64>,
}

impl Worker {
    fn new(settings: Settings, shared: Arc<Shared>) -> Worker {
        // A read keeps the pose it was filed with; only the filters (mhekf, wls) walk the
        // path driven.
        let keep = match settings.estimator.locator().takes() {
            Takes::Tracks => None,
            Takes::Phases | Takes::References => Some(POSE_KEEP_US),
        };
        let poses = Poses::new()
            .with_reach(settings.pose_reach_us)
            .with_keep(keep);
        Worker {
            ingest: Ingest::new(poses, settings.ambiguity, settings.max_gap_us)
                .with_min_rssi(settings.min_rssi_dbm),
            settings,
            shared,
            decoders: llrp_gateway_vocab::reads::Decoders::default(),
            waiting: VecDeque::new(),
            reader_rates: HashMap::new(),
            reader_read_at: HashMap::new(),
            silence_checked: Instant::now(),
            tags: BTreeMap::new(),
            set_aside_seen: 0,
            taken_since_flush: false,
            derived: std::collections::BTreeSet::new(),
            read_span_us: None,
            refined_at_us: None,
        }
    }

    fn run(mut self, rx: Receiver<Input>, stop: &AtomicBool) {
        let mut released = Instant::now();
        loop {
            if released.elapsed() >= RELEASE_EVERY {
                if let Some(release) = self.settings.release_memory {
                    release();
                }
                released = Instant::now();
            }
            if stop.load(Ordering::Relaxed) {
                // What is there already, and no more (a simulator may still be sending).
                for _ in 0..self.settings.tap_capacity {
                    match rx.try_recv() {
                        Ok(input) => self.take(input),
                        Err(_) => break,
                    }
                }
                self.flush_waiting(true);
                self.refine_poses(true);
                self.estimate(Duration::MAX, true);
                return;
            }
            let wait = if self.any_dirty() {
                Duration::from_millis(5)
            } else {
                Duration::from_millis(200)
            };
            match rx.recv_timeout(wait) {
                Ok(input) => {
                    self.take(input);
                    // Everything that is there already, then estimates.
                    let started = Instant::now();
                    while let Ok(input) = rx.try_recv() {
                        self.take(input);
                        if started.elapsed() >= self.settings.compute_budget {
                            break;
                        }
                    }
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => {
                    self.flush_waiting(true);
                    self.refine_poses(true);
                    self.estimate(Duration::MAX, true);
                    return;
                }
            }
            // Whether a waiting read is ready changes only with new poses or reads, or once
            // it has waited long enough.
            let expired = self
                .waiting
                .front()
                .is_some_and(|(_, at)| at.elapsed() >= POSE_WAIT);
            if std::mem::take(&mut self.taken_since_flush) || expired {
                self.flush_waiting(false);
            }
            self.refine_poses(false);
            self.estimate(self.settings.compute_budget, false);
            self.silence_rates();
        }
    }

    /// Shows a rate of 0 for the readers and tags that sent nothing for [`RATE_SILENCE`]
    /// (a rate is otherwise updated only as reads come); checked twice a second at most.
    fn silence_rates(&mut self) {
        if self.silence_checked.elapsed() < RATE_SILENCE / 6 {
            return;
        }
        self.silence_checked = Instant::now();
        let silent = |at: &Instant| at.elapsed() >= RATE_SILENCE;
        let readers: Vec<String> = self
            .reader_read_at
            .iter()
            .filter(|(_, at)| silent(at))
            .map(|(name, _)| name.clone())
            .collect();
        for name in readers {
            self.reader_read_at.remove(&name);
            self.reader_rates.remove(&name);
            self.shared.update_reader(&name, |v| v.reads_per_s = 0.0);
        }
        let estimator = self.settings.estimator.name();
        for (epc, t) in &mut self.tags {
            if t.read_at.as_ref().is_some_and(silent) {
                t.read_at = None;
                t.rate_count = 0;
                t.rate_start_us = u64::MAX;
                self.shared.update_tag(
                    epc,
                    || TagView::unseen(epc, estimator),
                    |v| v.reads_per_s = 0.0,
                );
            }
        }
    }

    fn any_dirty(&self) -> bool {
        self.tags.values().any(|t| t.dirty_since.is_some())
    }

    fn take(&mut self, input: Input) {
        self.taken_since_flush = true;
        match input {
            Input::Reader {
                name,
                hop_table,
                antennas,
                clock_offset_us,
                poses,
            } => {
                self.decoders.register(&name, hop_table, &antennas, poses);
                self.ingest.poses_mut().set_offset(&name, clock_offset_us);
                self.shared.update_reader(&name, |v| {
                    for a in antennas {
                        if !v.antennas.iter().any(|x| x.antenna == a) {
                            v.antennas.push(AntennaView {
                                antenna: a,
                                pose: None,
                            });
                        }
                    }
                    v.antennas.sort_by_key(|a| a.antenna);
                });
            }
            Input::Frames {
                reader,
                bytes,
                now_utc_us,
            } => {
                let decoder = self.decoders.of(&reader);
                let mut reads = Vec::new();
                for frame in llrp_gateway_vocab::reads::frames(&bytes) {
                    let Ok(frame) = frame else {
                        self.shared.metrics.decode_errors.inc();
                        break;
                    };
                    self.shared.metrics.frames_out.inc();
                    if decoder.frame(frame, now_utc_us, &mut reads).is_err() {
                        self.shared.metrics.decode_errors.inc();
                    }
                }
                self.reads(reads);
            }
            Input::Reads(reads) => self.reads(reads),
            Input::Poses(poses) => self.take_poses(poses),
            // A reader's link is written by its source (`Tap::links`); events and keepalives
            // are for mirrors.
            Input::Status { .. } | Input::Event { .. } | Input::Keepalive { .. } => {}
            Input::Truth(truth) => self.shared.set_truth(truth),
        }
    }

    /// Files pose samples `poses`, shows each antenna's newest in its reader's view, and
    /// derives the geometry of readers with their first pose.
    fn take_poses(&mut self, poses: Vec<PoseSample>) {
        self.shared.metrics.poses.inc_by(poses.len() as u64);
        // The unnamed reader (of reads that name none) is "" in the localizer's maps.
        let name = |p: &PoseSample| p.reader.as_deref().unwrap_or_default().to_owned();
        let new: Vec<String> = poses
            .iter()
            .filter(|p| {
                !self
                    .derived
                    .contains(p.reader.as_deref().unwrap_or_default())
            })
            .map(name)
            .collect();
        let mut newest: HashMap<(String, u16), PoseSample> = HashMap::new();
        let mut taken = Vec::with_capacity(poses.len());
        for p in poses {
            newest.insert((name(&p), p.antenna), p.clone());
            self.ingest.poses_mut().add(p.clone());
            // On the reads' clock, as the API shows them.
            let offset = self.ingest.poses_mut().offset(&name(&p));
            taken.push(PoseSample {
                t_us: p.t_us.saturating_add_signed(offset),
                ..p
            });
        }
        self.shared.poses_taken(&taken);
        for ((reader, antenna), mut p) in newest {
            // Shown on the reads' clock (UTC µs for LLRP readers), as every other time
            // of the API is: a pose comes on the robot's.
            let offset = self.ingest.poses_mut().offset(&reader);
            p.t_us = p.t_us.saturating_add_signed(offset);
            self.shared.update_reader(&reader, |v| {
                match v.antennas.iter_mut().find(|a| a.antenna == antenna) {
                    Some(a) => a.pose = Some(p),
                    None => {
                        v.antennas.push(AntennaView {
                            antenna,
                            pose: Some(p),
                        });
                        v.antennas.sort_by_key(|a| a.antenna);
                    }
                }
            });
        }
        self.derive(new, &[]);
    }

    /// With [`Settings::derive_geometry`], the geometry again once readers `new` have their
    /// first pose (or read with its own antenna pose, `reads`).
    fn derive(&mut self, new: Vec<String>, reads: &[Read]) {
        let Some(file) = &self.settings.derive_geometry else {
            return;
        };
        let before = self.derived.len();
        self.derived.extend(new);
        if self.derived.len() > before {
            let corrections = self.settings.geometry.pose_corrections.take();
            self.settings.geometry = crate::offline::geometry(file, reads, self.ingest.poses());
            self.settings.geometry.pose_corrections = corrections;
        }
    }

    fn reads(&mut self, reads: Vec<Read>) {
        self.shared.metrics.reads.inc_by(reads.len() as u64);
        if self.settings.derive_geometry.is_some() {
            let posed: Vec<Read> = reads
                .iter()
                .filter(|r| r.antenna_pose.is_some())
                .filter(|r| {
                    !self
                        .derived
                        .contains(r.reader.as_deref().unwrap_or_default())
                })
                .cloned()
                .collect();
            let new = posed
                .iter()
                .map(|r| r.reader.as_deref().unwrap_or_default().to_owned())
                .collect();
            self.derive(new, &posed);
        }
        let now = Instant::now();
        for r in reads {
            self.waiting.push_back((r, now));
        }
        while self.waiting.len() > MAX_WAITING {
            if let Some((r, at)) = self.waiting.pop_front() {
                self.shared
                    .metrics
                    .pose_wait_seconds
                    .observe(at.elapsed().as_secs_f64());
                self.file(r);
            }
        }
    }

    /// Files the waiting reads that have a pose now, or will never get one.
    fn flush_waiting(&mut self, all: bool) {
        let mut keep = VecDeque::new();
        while let Some((r, at)) = self.waiting.pop_front() {
            let reader = r.reader.as_deref().unwrap_or_default();
            let ready = all
                || r.antenna_pose.is_some()
                || r.phase_rad.is_none()
                || self
                    .ingest
                    .poses()
                    .newest(reader, r.antenna)
                    .is_some_and(|t| t >= r.t_us)
                || at.elapsed() >= POSE_WAIT;
            if ready {
                self.shared
                    .metrics
                    .pose_wait_seconds
                    .observe(at.elapsed().as_secs_f64());
                self.file(r);
            } else {
                keep.push_back((r, at));
            }
        }
        self.waiting = keep;
    }

    fn file(&mut self, r: Read) {
        let now = Instant::now();
        let before = self.ingest.taken();
        self.ingest.push(&r);
        if self.ingest.taken() > before {
            self.read_span_us = Some(match self.read_span_us {
                Some((first, newest)) => (first.min(r.t_us), newest.max(r.t_us)),
                None => (r.t_us, r.t_us),
            });
        }
        // Thinned as the reads come, not as estimates are made: what a tag holds is then a
        // function of its reads alone (two workers on different shards hold what one does).
        if self.ingest.taken() > before {
            self.ingest
                .bound_tag(&r.epc, self.settings.max_samples_per_tag);
        }
        let aside = self.ingest.set_aside();
        let aside = aside.total();
        if aside > self.set_aside_seen {
            self.shared
                .metrics
                .set_aside
                .inc_by(aside - self.set_aside_seen);
            self.set_aside_seen = aside;
        }
        let reader = r.reader.as_deref().unwrap_or_default().to_owned();
        let rate = self
            .reader_rates
            .entry(reader.clone())
            .or_insert((r.t_us, 0));
        rate.1 += 1;
        let reader_rate = rolled(rate, r.t_us);
        self.reader_read_at.insert(reader.clone(), now);
        self.shared.update_reader(&reader, |v| {
            v.reads += 1;
            if let Some(x) = reader_rate {
                v.reads_per_s = x;
            }
        });
        let state = self.tags.entry(r.epc.clone()).or_insert_with(|| TagState {
            rate_start_us: r.t_us,
            ..TagState::default()
        });
        if self.ingest.taken() > before && state.dirty_since.is_none() {
            state.dirty_since = Some(now);
        }
        state.read_at = Some(now);
        if state.rate_start_us == u64::MAX {
            // The first read after a silence starts a new window.
            state.rate_start_us = r.t_us;
        }
        let mut window = (state.rate_start_us, state.rate_count + 1);
        let tag_rate = rolled(&mut window, r.t_us);
        (state.rate_start_us, state.rate_count) = window;
        let estimator = self.settings.estimator.name();
        let epc = r.epc.clone();
        self.shared.update_tag(
            &epc,
            || TagView::unseen(&epc, estimator),
            |v| {
                v.reads += 1;
                v.last_seen_us = v.last_seen_us.max(r.t_us);
                if let Some(x) = tag_rate {
                    v.reads_per_s = x;
                }
                if v.recent.len() == RECENT_READS {
                    v.recent.pop_front();
                }
                v.recent.push_back(r);
            },
        );
    }
}

/// Counts one read at `t_us` into a rate window `(start, count)`; the rate (per second)
/// once the window spans [`RATE_WINDOW_US`], which then starts again.
fn rolled(window: &mut (u64, u64), t_us: u64) -> Option<f64> {
    let span = t_us.saturating_sub(window.0);
    if span < RATE_WINDOW_US {
        return None;
    }
    let rate = window.1 as f64 / (span as f64 / 1e6);
    *window = (t_us, 0);
    Some(rate)
}
