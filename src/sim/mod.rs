//! `llrp-gateway sim`: builds one simulated reader per scenario reader, listens on each one's
//! LLRP address and writes ground truth (tag positions, antenna poses over time) as JSONL.

use crate::reads::ReaderName;
use std::io::{self, BufWriter};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use tokio::net::TcpListener;
use tokio::sync::watch;
use tokio::task::JoinHandle;

use crate::localize::live::{Input, Tap};
use crate::net::clock::{Clock, Speed};
use crate::net::server::{serve_tls, LiveHook, Observer, SimReader};
use crate::net::tls::{ServerFiles, TlsError};
use crate::physics::{Model, World};
use crate::reader::faults::FaultPanel;
use crate::reader::gpio::GpioPanel;
use crate::reader::memory::TagMemory;
use crate::reader::session::Session;
use crate::reader::{Reader, ReaderProfile};
use crate::record::{RecordOptions, RecorderTask};
use crate::scenario::{ReaderSpec, Scenario};
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;

pub mod feed;
mod mcap;
pub mod own;
pub mod tag_memory;
mod truth;

pub use feed::PoseSource;
use truth::{truth_by_clock, truth_writer, Truth};

/// Faults the readers applied, by reader and fault (`/metrics`' `faults`).
pub type FaultCounts = Family<Vec<(String, String)>, Counter>;

/// Longest a shutdown waits for the readers' tasks (each gives its client at most half a
/// second to take the ConnectionCloseEvent).
pub const SHUTDOWN_WAIT: std::time::Duration = std::time::Duration::from_millis(800);

/// Simulated time between two ground-truth lines, µs.
pub const TRUTH_INTERVAL_US: u64 = 100_000;

/// How to run the simulation.
#[derive(Clone, Debug)]
pub struct SimOptions {
    /// Listen addresses overriding the scenario's, reader by reader (in scenario order).
    pub listen: Vec<String>,
    /// How fast simulated time runs.
    pub speed: Speed,
    /// Where to write ground truth (JSONL), if anywhere.
    pub truth: Option<PathBuf>,
    /// Where to write the readers' sessions, poses and ground truth as MCAP
    /// (docs/robotics.md), if anywhere.
    pub mcap: Option<PathBuf>,
    /// Serve what the MCAP file would hold, live, to Foxglove clients on this address
    /// (`--foxglove`; with or without `mcap`).
    pub foxglove: Option<String>,
    /// Replace an existing truth file (`--force`); without it an existing one is refused.
    pub force: bool,
    /// Record every reader's sessions (one file per reader when there are several:
    /// [`record_path`]).
    pub record: Option<PathBuf>,
    /// Rotation size of the recordings.
    pub record_options: RecordOptions,
    /// Serve LLRP over TLS with this certificate and key on every reader's address (LLRP over
    /// TLS is on port 5085 by convention; `listen` chooses the port).
    pub tls: Option<ServerFiles>,
    /// Feed the live localizer: every frame the readers send, their antennas' poses and
    /// the ground truth; while no client is connected (and time runs by the wall clock)
    /// each reader inventories by itself for it.
    pub localize: Option<LocalizeFeed>,
    /// Counts the LLRP frames clients send the readers (`/metrics`' `frames_in`).
    pub frames_in: Counter,
    /// The tags' memory is read from this file (when it exists) and written back to it
    /// ([`tag_memory`]).
    pub tag_memory: Option<PathBuf>,
    /// Counts each fault a reader applies, labelled `reader` and `fault`.
    pub fault_counts: Option<FaultCounts>,
}

/// What the simulator feeds the live localizer.
#[derive(Clone, Debug)]
pub struct LocalizeFeed {
    /// The localizer's tap.
    pub tap: Tap,
    /// Which poses it is given.
    pub poses: PoseSource,
    /// Simulated time between two pose samples of an antenna (µs).
    pub pose_interval_us: u64,
    /// Each read is stamped with its antenna's pose at the read.
    pub read_poses: bool,
}

impl Default for SimOptions {
    fn default() -> Self {
        SimOptions {
            listen: Vec::new(),
            speed: Speed::Factor(1.0),
            truth: None,
            mcap: None,
            foxglove: None,
            force: false,
            record: None,
            record_options: RecordOptions::default(),
            tls: None,
            localize: None,
            frames_in: Counter::default(),
            tag_memory: None,
            fault_counts: None,
        }
    }
}

/// Why the simulation could not start.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// The scenario has no reader.
    #[error("the scenario has no reader")]
    NoReader,
    /// The TLS certificate or key cannot be used.
    #[error("TLS: {0}")]
    Tls(#[from] TlsError),
    /// A listen address could not be bound.
    #[error("reader {reader}: cannot listen on {addr}: {source}")]
    Listen {
        /// Reader name.
        reader: ReaderName,
        /// The address.
        addr: String,
        /// Why.
        source: io::Error,
    },
    /// A recording could not be created.
    #[error("reader {reader}: cannot create the recording {path}: {source}")]
    Record {
        /// Reader name.
        reader: ReaderName,
        /// The file.
        path: PathBuf,
        /// Why.
        source: io::Error,
    },
    /// The truth file could not be created.
    #[error("cannot create the truth file {0}")]
    Truth(crate::files::OutputError),
    /// The MCAP file could not be created.
    #[error("cannot write the MCAP file: {0}")]
    Mcap(crate::record::mcap::McapError),
    /// The Foxglove live view could not listen.
    #[error("{0}")]
    Live(#[from] crate::foxglove::LiveError),
    /// The tag memory file could not be read.
    #[error("{0}")]
    TagMemory(#[from] tag_memory::TagMemoryError),
}

/// A running simulation: its listeners and how to stop it.
pub struct RunningSim {
    /// Bound address of each reader, in scenario order.
    pub addrs: Vec<SocketAddr>,
    /// Names of the readers, in scenario order.
    pub names: Vec<ReaderName>,
    /// Each reader's GPIO as seen from outside (toggle its inputs, read its state), in
    /// scenario order.
    pub gpio: Vec<Arc<GpioPanel>>,
    /// Each reader's faults as seen from outside (inject them), in scenario order.
    pub faults: Vec<Arc<FaultPanel>>,
    shutdown: watch::Sender<bool>,
    tasks: Vec<JoinHandle<io::Result<()>>>,
    truth: Option<Arc<Truth>>,
    recordings: Vec<RecorderTask>,
    /// The `--mcap` file's writer, finished last.
    mcap: Option<crate::record::mcap::McapThread>,
    /// The Foxglove live view (`--foxglove`), stopped after the MCAP output.
    live: Option<crate::foxglove::LiveServer>,
    own: Vec<JoinHandle<()>>,
    /// Writes the tags' memory back to its file (`--tag-memory`).
    saver: Option<Arc<tag_memory::Saver>>,
    /// The simulation's clock and its UTC time 0 (µs), which stamp what is logged.
    clock: Arc<Clock>,
    utc0: u64,
}

impl RunningSim {
    /// Stops accepting clients, sends each connected client the ConnectionCloseEvent and closes
    /// it, waits for every reader's task to end (at most [`SHUTDOWN_WAIT`]) and flushes the
    /// ground truth.
    pub async fn shutdown(self) {
        let _ = self.shutdown.send(true);
        let all = async {
            for t in self.tasks {
                let _ = t.await;
            }
        };
        if tokio::time::timeout(SHUTDOWN_WAIT, all).await.is_err() {
            tracing::warn!("a reader did not stop within {SHUTDOWN_WAIT:?}");
        }
        for t in self.own {
            // It stops at its next await; one still computing is left to finish alone.
            let _ = tokio::time::timeout(SHUTDOWN_WAIT, t).await;
        }
        // Each recording ends once its reader's task (holding the recorder) has ended.
        for r in self.recordings {
            match tokio::time::timeout(SHUTDOWN_WAIT, r).await {
                Ok(Ok(Ok(()))) => {}
                Ok(Ok(Err(e))) => tracing::error!("writing a recording failed: {e}"),
                Ok(Err(e)) => tracing::error!("a recording's writer failed: {e}"),
                Err(_) => tracing::warn!("a recording was not finished within {SHUTDOWN_WAIT:?}"),
            }
        }
        if let Some(t) = &self.truth {
            t.flush();
        }
        if let Some(m) = self.mcap {
            mcap::finish(m).await;
        }
        if let Some(live) = self.live {
            live.shutdown().await;
        }
        // The readers have stopped: what they wrote last is in the file.
        if let Some(saver) = &self.saver {
            saver.save().await;
        }
    }
}

/// What every reader of one simulation shares while it is started.
struct Start<'a> {
    scenario: &'a Scenario,
    opts: &'a SimOptions,
    /// The `--mcap` file's queue (each reader's recorder gets a tee of its own).
    mcap: Option<crate::record::mcap::McapTee>,
    truth: Option<Arc<Truth>>,
    /// The tags that move (their truth is written at each line).
    moving: Vec<usize>,
    tls: Option<crate::net::tls::Acceptor>,
    world: World,
    utc0: u64,
    clock: Arc<Clock>,
    shutdown: watch::Receiver<bool>,
    references: Arc<Vec<bool>>,
    /// The tags' memory, one for every reader: a tag written by one reads so on all.
    memory: Arc<TagMemory>,
}

/// One reader started: its serving task and what runs beside it.
struct Started {
    addr: SocketAddr,
    gpio: Arc<GpioPanel>,
    faults: Arc<FaultPanel>,
    task: JoinHandle<io::Result<()>>,
    recording: Option<RecorderTask>,
    own: Vec<JoinHandle<()>>,
}

/// Starts every reader of `scenario`; returns once all listen.
pub async fn start(scenario: &Scenario, opts: &SimOptions) -> Result<RunningSim, SimError> {
    if scenario.readers.is_empty() {
        return Err(SimError::NoReader);
    }
    let out = match &opts.truth {
        Some(path) => Some(Mutex::new(BufWriter::new(
            crate::files::create_stream(path, &[], opts.force).map_err(SimError::Truth)?,
        ))),
        None => None,
    };
    let live = match &opts.foxglove {
        Some(addr) => Some(crate::foxglove::LiveServer::bind(addr).await?),
        None => None,
    };
    let mcap = mcap::open(opts, scenario, live.as_ref())?;
    let truth = (out.is_some() || mcap.is_some()).then(|| {
        Arc::new(Truth::new(
            out,
            mcap.as_ref().map(crate::record::mcap::McapThread::sender),
        ))
    });
    let (shutdown, rx) = watch::channel(false);
    let s = Start {
        scenario,
        opts,
        mcap: mcap.as_ref().map(|m| m.tee("")),
        truth,
        moving: (scenario.tags.iter().enumerate())
            .filter(|(_, t)| t.path.is_some())
            .map(|(i, _)| i)
            .collect(),
        tls: opts.tls.as_ref().map(ServerFiles::acceptor).transpose()?,
        // The tags, reflectors and robot drives, once for every reader.
        world: World::new(scenario),
        // Simulated time 0 is this instant: the readers' UTC timestamps then track the wall
        // clock at real-time speed, however long the world took to build.
        utc0: crate::utc::now_us(),
        clock: Arc::new(Clock::new(opts.speed)),
        memory: Arc::new(TagMemory::new()),
        shutdown: rx,
        references: Arc::new(scenario.tags.iter().map(|t| t.reference).collect()),
    };
    let saver = match &opts.tag_memory {
        Some(path) => {
            let model = Arc::new(Model::in_world(&s.world, scenario, 0));
            let saver = Arc::new(tag_memory::Saver::open(path, model, s.memory.clone())?);
            Some(saver)
        }
        None => None,
    };
    let mut running = RunningSim {
        addrs: Vec::new(),
        names: Vec::new(),
        gpio: Vec::new(),
        faults: Vec::new(),
        shutdown,
        tasks: Vec::new(),
        truth: s.truth.clone(),
        recordings: Vec::new(),
        mcap,
        live,
        own: Vec::new(),
        saver: saver.clone(),
        clock: s.clock.clone(),
        utc0: s.utc0,
    };
    if let Some(saver) = &saver {
        running.own.push(saver.spawn(s.shutdown.clone()));
    }
    for (i, spec) in scenario.readers.iter().enumerate() {
        let started = s.reader(i, spec).await?;
        running.addrs.push(started.addr);
        running.names.push(spec.name.clone());
        running.gpio.push(started.gpio);
        running.faults.push(started.faults);
        running.tasks.push(started.task);
        running.recordings.extend(started.recording);
        running.own.extend(started.own);
    }
    Ok(running)
}

impl Start<'_> {
    /// Starts reader `i` (`spec`): binds its address and serves it.
    async fn reader(&self, i: usize, spec: &ReaderSpec) -> Result<Started, SimError> {
        let addr = (self.opts.listen.get(i).cloned()).unwrap_or_else(|| spec.listen.clone());
        let listen_error = |source| SimError::Listen {
            reader: spec.name.clone(),
            addr: addr.clone(),
            source,
        };
        let listener = TcpListener::bind(&addr).await.map_err(listen_error)?;
        let bound = listener.local_addr().map_err(listen_error)?;
        let model = Arc::new(Model::in_world(&self.world, self.scenario, i));
        let profile = ReaderProfile::from_scenario(self.scenario, i, &model);
        let reader =
            Reader::new(profile.clone(), model.clone(), self.utc0).with_memory(self.memory.clone());
        let gpio = Arc::clone(reader.gpio_panel());
        let mut own = Vec::new();
        let mut observer = self.truth_observer(spec, &model, &mut own);
        let mut hook = None;
        if let Some(l) = &self.opts.localize {
            let (h, feed_observer) = self.live(l, spec, &model, &profile, &mut own);
            observer = Some(both(observer, feed_observer));
            hook = Some(h);
        }
        let session = Session::new(reader);
        let faults = Arc::clone(session.fault_panel());
        if let Some(counts) = self.opts.fault_counts.clone() {
            let name = spec.name.to_string();
            faults.on_applied(move |fault| {
                let labels = vec![
                    ("reader".into(), name.clone()),
                    ("fault".into(), fault.into()),
                ];
                counts.get_or_create(&labels).inc();
            });
        }
        let mut sim = SimReader::new(session, self.clock.clone(), observer);
        if let Some(h) = hook {
            sim = sim.with_live(h);
        }
        let (recorder, recording) = self.recorder(spec)?;
        tracing::info!(reader = %spec.name, %bound, tls = self.tls.is_some(), "simulated reader listening");
        let task = tokio::spawn(serve_tls(
            listener,
            self.tls.clone(),
            sim,
            self.shutdown.clone(),
            recorder,
        ));
        Ok(Started {
            addr: bound,
            gpio,
            faults,
            task,
            recording,
            own,
        })
    }

    /// The truth writer of reader `spec`: an observer of the served reader at `--speed max`
    /// (simulated time moves only as it steps), else a task on the clock (pushed to `own`).
    fn truth_observer(
        &self,
        spec: &ReaderSpec,
        model: &Arc<Model>,
        own: &mut Vec<JoinHandle<()>>,
    ) -> Option<Observer> {
        let t = self.truth.as_ref()?;
        let mut write = truth_writer(
            t.clone(),
            spec.name.clone(),
            self.moving.clone(),
            self.utc0,
            model.clone(),
        );
        if self.opts.speed == Speed::Max {
            return Some(Box::new(move |r: &Reader| write(r.now_us())));
        }
        own.push(tokio::spawn(truth_by_clock(
            write,
            self.clock.clone(),
            self.shutdown.clone(),
        )));
        None
    }

    /// Reader `spec` on the live localizer's feed: announced with its hop table, antennas and
    /// poses; the served reader's hook and the observer that feeds its poses and truth; and,
    /// at real-time speeds, its own inventory while no client is connected (pushed to `own`).
    fn live(
        &self,
        l: &LocalizeFeed,
        spec: &ReaderSpec,
        model: &Arc<Model>,
        profile: &ReaderProfile,
        own: &mut Vec<JoinHandle<()>>,
    ) -> (LiveHook, Observer) {
        let utc0 = self.utc0;
        l.tap.offer(Input::Reader {
            name: spec.name.clone(),
            hop_table: Some(llrp::units::HopTable {
                id: 1,
                frequencies_khz: profile.frequencies_khz.clone(),
            }),
            antennas: (1..=model.antenna_count()).collect(),
            clock_offset_us: i64::try_from(utc0).unwrap_or(i64::MAX),
            poses: l
                .read_poses
                .then(|| feed::pose_at(model.clone(), l.poses, utc0)),
        });
        let feed = |now_us| {
            own::feed_fn(
                feed::Feed::new(
                    l.tap.clone(),
                    spec.name.clone(),
                    l.poses,
                    self.references.clone(),
                    l.pose_interval_us,
                    now_us,
                )
                .with_utc0(utc0),
            )
        };
        let (client, client_rx) = watch::channel(false);
        let hook = LiveHook {
            name: spec.name.clone(),
            tap: l.tap.clone(),
            client: Some(client),
            frames_in: Some(self.opts.frames_in.clone()),
        };
        if self.opts.speed != Speed::Max {
            let (model, profile, memory) = (model.clone(), profile.clone(), self.memory.clone());
            let task = own::OwnTask {
                make_reader: Box::new(move || {
                    Reader::new(profile.clone(), model.clone(), utc0).with_memory(memory.clone())
                }),
                clock: self.clock.clone(),
                tap: l.tap.clone(),
                name: spec.name.clone(),
                feed: feed(0),
            };
            own.push(tokio::spawn(own::run(
                task,
                client_rx,
                self.shutdown.clone(),
            )));
        }
        (hook, feed(0))
    }
}

/// One observer calling `first` (if any), then `second`.
fn both(first: Option<Observer>, mut second: Box<dyn FnMut(&Reader) + Send>) -> Observer {
    match first {
        Some(mut f) => Box::new(move |r: &Reader| {
            f(r);
            second(r);
        }),
        None => second,
    }
}

/// The recording file of reader `name`: `path` itself when the scenario has one reader,
/// else `STEM-NAME.EXT` beside it.
pub fn record_path(path: &Path, name: &str, readers: usize) -> PathBuf {
    if readers <= 1 {
        return path.to_owned();
    }
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let file = match path.extension() {
        Some(ext) => format!("{stem}-{name}.{}", ext.to_string_lossy()),
        None => format!("{stem}-{name}"),
    };
    path.with_file_name(file)
}
