//! What the live localizer publishes for the HTTP API and anyone else who asks: every tag's
//! latest estimate with its read statistics, every reader's status and antenna poses, the
//! simulation's ground truth when there is one, a stream of estimate updates, and counters.
//!
//! The localizer's worker writes it; readers take short read locks and copy what they need.

use llrp_gateway_vocab::epc::Epc;
use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, RwLock, RwLockReadGuard, RwLockWriteGuard};

use crate::estimate::{Estimate, State};
use crate::poses::PoseSample;
use llrp_gateway_vocab::feed::Links;
pub use llrp_gateway_vocab::feed::{Truth, TruthTag};
use llrp_gateway_vocab::reader_name::ReaderName;
use llrp_gateway_vocab::reads::Read;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::histogram::Histogram;
use prometheus_client::registry::Registry;
use prometheus_client::registry::Unit;
use serde::Serialize;

/// Recent reads kept per tag for its detail view.
pub const RECENT_READS: usize = 32;

/// Estimate updates an event stream should buffer for a slow subscriber before it misses
/// some (the HTTP event stream's and the MQTT publisher's).
pub const EVENT_BUFFER: usize = 1024;

/// One told of every published estimate ([`Shared::on_publish`]).
type Subscriber = Box<dyn Fn(&Arc<TagView>) + Send + Sync>;

/// Those told of every published estimate.
#[derive(Default)]
struct Subscribers(RwLock<Vec<Subscriber>>);

/// One told of every batch of antenna poses taken ([`Shared::on_poses`]).
type PoseSubscriber = Box<dyn Fn(&[PoseSample]) + Send + Sync>;

/// Those told of every batch of antenna poses taken.
#[derive(Default)]
struct PoseSubscribers(RwLock<Vec<PoseSubscriber>>);

impl std::fmt::Debug for PoseSubscribers {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} pose subscribers", read(&self.0).len())
    }
}

impl std::fmt::Debug for Subscribers {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} subscribers", read(&self.0).len())
    }
}

/// One tag as the API shows it.
#[derive(Clone, Debug, Serialize)]
pub struct TagView {
    /// The latest estimate.
    #[serde(flatten)]
    pub estimate: Estimate,
    /// Time of the tag's newest read (µs, the reads' clock).
    pub last_seen_us: u64,
    /// Reads of the tag taken in.
    pub reads: u64,
    /// Reads per second of reader time over the last rate window.
    pub reads_per_s: f64,
    /// The newest reads, oldest first (at most [`RECENT_READS`]).
    #[serde(skip)]
    pub recent: VecDeque<Read>,
}

impl TagView {
    /// A tag `epc` taken in by `estimator` with no read and no estimate yet.
    pub fn unseen(epc: &str, estimator: &'static str) -> TagView {
        TagView {
            estimate: Estimate {
                epc: epc.to_owned(),
                estimator,
                estimate: None,
                covariance: None,
                samples: 0,
                state: crate::estimate::State::InsufficientGeometry,
                last_update_us: 0,
                pose_sigma_m: None,
            },
            last_seen_us: 0,
            reads: 0,
            reads_per_s: 0.0,
            recent: VecDeque::new(),
        }
    }
}

/// One antenna of a reader and its newest pose.
#[derive(Clone, Debug, Serialize)]
pub struct AntennaView {
    /// Antenna port.
    pub antenna: u16,
    /// The newest pose sample, if any came.
    pub pose: Option<PoseSample>,
}

/// What the localizer keeps of one reader: its reads and its antennas' newest poses.
#[derive(Clone, Debug, Default)]
pub struct ReaderStats {
    /// Reads taken in from this reader.
    pub reads: u64,
    /// Reads per second of reader time over the last rate window.
    pub reads_per_s: f64,
    /// Antennas, by port.
    pub antennas: Vec<AntennaView>,
}

/// One reader as the API shows it: its link (from the feed's sources) and its statistics
/// (from the localizer).
#[derive(Clone, Debug, Default, Serialize)]
pub struct ReaderView {
    /// The reader's name (a [`ReaderName`], or empty for the reads that name none).
    pub name: String,
    /// Whether an LLRP client is connected (for a simulated reader; a proxied reader's
    /// upstream connection).
    pub connected: bool,
    /// The connected peer, if any.
    pub peer: Option<String>,
    /// Whether an inventory runs, and who runs it: `client`, `self` (the simulator's own
    /// inventory while no client is connected) or `idle`.
    pub inventory: String,
    /// Reads taken in from this reader.
    pub reads: u64,
    /// Reads per second of reader time over the last rate window.
    pub reads_per_s: f64,
    /// Antennas, by port.
    pub antennas: Vec<AntennaView>,
}

/// The localizer's counters and histograms; the application registers them
/// ([`Metrics::register`]) beside its other subsystems' and serves them at `GET /metrics`.
#[derive(Debug)]
pub struct Metrics {
    /// LLRP frames the readers sent to their clients, as the localizer took them in (frames
    /// the tap dropped count in `dropped_taps` instead).
    pub frames_out: Counter,
    /// Tag reads taken in.
    pub reads: Counter,
    /// Frames from a reader that did not decode.
    pub decode_errors: Counter,
    /// Inputs (reads or poses, counted one by one) the tap dropped because the localizer
    /// was behind.
    pub dropped_taps: Counter,
    /// Reads set aside: no phase, no channel frequency, or no pose within reach.
    pub set_aside: Counter,
    /// Pose samples taken in.
    pub poses: Counter,
    /// Compute time of one tag's estimate (s).
    pub estimator_seconds: Histogram,
    /// From a read's filing (its pose in) to its tag's updated estimate (s).
    pub update_latency_seconds: Histogram,
    /// From a read's arrival at the localizer to its filing: the wait for its pose (s).
    pub pose_wait_seconds: Histogram,
}

impl Metrics {
    fn new() -> Metrics {
        let buckets = || {
            Histogram::new(
                [
                    0.0001, 0.0002, 0.0005, 0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5,
                    1.0, 2.0, 5.0,
                ]
                .into_iter(),
            )
        };
        Metrics {
            frames_out: Counter::default(),
            reads: Counter::default(),
            decode_errors: Counter::default(),
            dropped_taps: Counter::default(),
            set_aside: Counter::default(),
            poses: Counter::default(),
            estimator_seconds: buckets(),
            update_latency_seconds: buckets(),
            pose_wait_seconds: buckets(),
        }
    }

    /// Registers the localizer's metrics in `registry` (the metrics are handles: the clones
    /// registered count with the fields).
    pub fn register(&self, registry: &mut Registry) {
        registry.register(
            "frames_out",
            "LLRP frames the readers sent to their clients, as the localizer took them in",
            self.frames_out.clone(),
        );
        registry.register("reads", "Tag reads taken in", self.reads.clone());
        registry.register(
            "decode_errors",
            "Frames from a reader that did not decode",
            self.decode_errors.clone(),
        );
        registry.register(
            "dropped_taps",
            "Reads and poses the localizer's tap dropped because the localizer was behind",
            self.dropped_taps.clone(),
        );
        registry.register(
            "reads_set_aside",
            "Reads without a phase, a channel frequency or a pose within reach",
            self.set_aside.clone(),
        );
        registry.register("poses", "Pose samples taken in", self.poses.clone());
        registry.register_with_unit(
            "estimator",
            "Compute time of one tag's estimate",
            Unit::Seconds,
            self.estimator_seconds.clone(),
        );
        registry.register_with_unit(
            "update_latency",
            "From a read's filing (its pose in) to its tag's updated estimate",
            Unit::Seconds,
            self.update_latency_seconds.clone(),
        );
        registry.register_with_unit(
            "pose_wait",
            "From a read's arrival at the localizer to its filing: the wait for its pose",
            Unit::Seconds,
            self.pose_wait_seconds.clone(),
        );
    }

    /// The localizer's metrics alone in the OpenMetrics text format, named as the
    /// application serves them (`llrp_gateway_reads_total`, …).
    pub fn render(&self) -> String {
        let mut registry = Registry::with_prefix("llrp_gateway");
        self.register(&mut registry);
        let mut out = String::new();
        // Writing into a String cannot fail.
        let _ = prometheus_client::encoding::text::encode(&mut out, &registry);
        out
    }
}

/// The localizer's published state (see the module's documentation).
#[derive(Debug)]
pub struct Shared {
    tags: RwLock<BTreeMap<String, TagView>>,
    readers: RwLock<BTreeMap<String, ReaderStats>>,
    links: Arc<Links>,
    truth: RwLock<Option<Truth>>,
    subscribers: Subscribers,
    pose_subscribers: PoseSubscribers,
    /// Counters for `/metrics`.
    pub metrics: Metrics,
    generation: AtomicU64,
}

impl Default for Shared {
    fn default() -> Self {
        Shared::new()
    }
}

fn read<T>(lock: &RwLock<T>) -> RwLockReadGuard<'_, T> {
    // A writer that panicked leaves the views as they were: still worth showing.
    lock.read().unwrap_or_else(|e| e.into_inner())
}

fn write<T>(lock: &RwLock<T>) -> RwLockWriteGuard<'_, T> {
    lock.write().unwrap_or_else(|e| e.into_inner())
}

impl Shared {
    /// Nothing known yet.
    pub fn new() -> Shared {
        Shared {
            tags: RwLock::default(),
            readers: RwLock::default(),
            links: Arc::default(),
            truth: RwLock::default(),
            subscribers: Subscribers::default(),
            pose_subscribers: PoseSubscribers::default(),
            metrics: Metrics::new(),
            generation: AtomicU64::new(0),
        }
    }

    /// Every tag, in EPC order.
    pub fn tags(&self) -> Vec<TagView> {
        read(&self.tags).values().cloned().collect()
    }

    /// The tag of EPC `epc`, if it was read.
    pub fn tag(&self, epc: &Epc) -> Option<TagView> {
        read(&self.tags).get(epc.as_str()).cloned()
    }

    /// Every reader, by name: those with a link and those read from.
    pub fn readers(&self) -> Vec<ReaderView> {
        let links = self.links.all();
        let stats = read(&self.readers);
        // The readers read from include the unnamed one (""), of reads that name none.
        let names: BTreeSet<&str> = links
            .keys()
            .map(ReaderName::as_str)
            .chain(stats.keys().map(String::as_str))
            .collect();
        names
            .into_iter()
            .map(|name| {
                let link = links.get(name).cloned().unwrap_or_default();
                let s = stats.get(name).cloned().unwrap_or_default();
                ReaderView {
                    name: name.to_owned(),
                    connected: link.connected,
                    peer: link.peer,
                    inventory: link.inventory.as_str().to_owned(),
                    reads: s.reads,
                    reads_per_s: s.reads_per_s,
                    antennas: s.antennas,
                }
            })
            .collect()
    }

    /// The readers' links, which the feed's sources write.
    pub fn links(&self) -> &Arc<Links> {
        &self.links
    }

    /// The simulation's ground truth; `None` for a real reader.
    pub fn truth(&self) -> Option<Truth> {
        read(&self.truth).clone()
    }

    /// Calls `f` with every estimate published from now on, on the localizer's thread: `f`
    /// must not block (the application's event streams hand it to a bounded channel).
    pub fn on_publish(&self, f: impl Fn(&Arc<TagView>) + Send + Sync + 'static) {
        write(&self.subscribers.0).push(Box::new(f));
    }

    /// Calls `f` with every batch of antenna poses the localizer takes from now on (from
    /// `POST /api/poses`, MQTT or a pose file), on the reads' clock, on the localizer's
    /// thread: `f` must not block.
    pub fn on_poses(&self, f: impl Fn(&[PoseSample]) + Send + Sync + 'static) {
        write(&self.pose_subscribers.0).push(Box::new(f));
    }

    /// Tells the pose subscribers of `poses`.
    pub(crate) fn poses_taken(&self, poses: &[PoseSample]) {
        for f in read(&self.pose_subscribers.0).iter() {
            f(poses);
        }
    }

    /// How many times the tags changed (for pollers).
    pub fn generation(&self) -> u64 {
        self.generation.load(Ordering::Relaxed)
    }

    /// Sets the ground truth (simulation only).
    pub fn set_truth(&self, truth: Truth) {
        *write(&self.truth) = Some(truth);
    }

    /// Changes reader `name`'s statistics (created empty if new).
    pub(crate) fn update_reader(&self, name: &str, f: impl FnOnce(&mut ReaderStats)) {
        let mut readers = write(&self.readers);
        match readers.get_mut(name) {
            Some(stats) => f(stats),
            None => f(readers.entry(name.to_owned()).or_default()),
        }
    }

    /// Changes tag `epc`'s view with `f` (creating it from `new` if it is not there yet).
    pub(crate) fn update_tag(
        &self,
        epc: &str,
        new: impl FnOnce() -> TagView,
        f: impl FnOnce(&mut TagView),
    ) {
        let mut tags = write(&self.tags);
        let view = tags.entry(epc.to_string()).or_insert_with(new);
        f(view);
    }

    /// Publishes tag `epc`'s new estimate to the views and the event stream.
    pub(crate) fn publish(&self, estimate: Estimate) {
        let epc = estimate.epc.clone();
        let snapshot = {
            let mut tags = write(&self.tags);
            let Some(view) = tags.get_mut(&epc) else {
                return;
            };
            view.estimate = estimate;
            Arc::new(view.clone())
        };
        self.generation.fetch_add(1, Ordering::Relaxed);
        for f in read(&self.subscribers.0).iter() {
            f(&snapshot);
        }
    }
}

/// A position as the API writes it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct Point {
    /// x (m).
    pub x: f64,
    /// y (m).
    pub y: f64,
    /// z (m).
    pub z: f64,
}

impl From<[f64; 3]> for Point {
    fn from([x, y, z]: [f64; 3]) -> Point {
        Point { x, y, z }
    }
}

/// One tag in `GET /api/tags` and in `localize --output`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TagJson {
    /// EPC, upper-case hex.
    pub epc: String,
    /// The estimated position; `null` with insufficient geometry.
    pub estimate: Option<Point>,
    /// Covariance of the estimate, 3×3 row-major (m²); `null` without an estimate.
    pub covariance: Option<[f64; 9]>,
    /// Estimator name.
    pub estimator: &'static str,
    /// `converging`, `converged` or `insufficient_geometry`.
    pub state: State,
    /// Phases the estimate rests on.
    pub samples: usize,
    /// Time of the newest read (µs, the reads' clock: UTC for LLRP readers).
    pub last_seen: u64,
    /// Reads per second over the last rate window (reader time).
    pub reads_per_s: f64,
    /// Why the state is not `converged`, in a sentence (`null` when converged).
    pub reason: Option<String>,
}

impl TagJson {
    /// The API's form of an estimate and its read statistics.
    pub fn new(e: &Estimate, last_seen: u64, reads_per_s: f64) -> TagJson {
        TagJson {
            epc: e.epc.clone(),
            estimate: e.estimate.map(Point::from),
            covariance: e.covariance,
            estimator: e.estimator,
            state: e.state,
            samples: e.samples,
            last_seen,
            reads_per_s,
            reason: reason(e),
        }
    }
}

/// Why an estimate is not converged, for a user: what it lacks and what would give it.
pub fn reason(e: &Estimate) -> Option<String> {
    use crate::estimate::{State, CONVERGED_SIGMA_M};
    match e.state {
        State::Converged => None,
        State::InsufficientGeometry if e.samples == 0 => Some(
            "no phase taken in yet: a position needs reads with phase, channel frequency and \
             an antenna pose"
                .into(),
        ),
        State::InsufficientGeometry => Some(format!(
            "no position from {} phases: the antenna has not passed the tag (read from one \
             place, or along too short a stretch), or its reads came too far apart to follow \
             the phase (over a quarter wavelength, about 8 cm, of travel between two reads, as \
             from a client that reports each tag once a second); a position needs reads from \
             poses spread along a pass by it, close together",
            e.samples
        )),
        State::Converging => {
            let sigma_mm = e
                .covariance
                .map_or(f64::NAN, |c| crate::estimate::worse_sigma(&c) * 1e3);
            let sigma_m = sigma_mm * 1e-3;
            match e.pose_sigma_m {
                // More reads do not help when the phases alone have converged and the poses'
                // own error is what keeps the estimate from it (in a weak geometry both are
                // large, and more aperture helps).
                Some(pose)
                    if sigma_m * sigma_m - pose * pose <= CONVERGED_SIGMA_M * CONVERGED_SIGMA_M =>
                {
                    Some(format!(
                        "σ {sigma_mm:.0} mm along its worse axis, {:.0} mm of it from the \
                         antenna poses' own error (the robot's localization), which more \
                         reads do not remove; converged at {:.0} mm or less",
                        pose * 1e3,
                        CONVERGED_SIGMA_M * 1e3
                    ))
                }
                _ => Some(format!(
                    "not yet trustworthy: σ {sigma_mm:.0} mm along its worse axis; converged \
                     at {:.0} mm or less",
                    CONVERGED_SIGMA_M * 1e3
                )),
            }
        }
    }
}

impl From<&TagView> for TagJson {
    fn from(v: &TagView) -> TagJson {
        TagJson::new(&v.estimate, v.last_seen_us, v.reads_per_s)
    }
}

/// The document of `GET /api/tags` and `localize --output`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TagsJson {
    /// Every tag, in EPC order.
    pub tags: Vec<TagJson>,
}
