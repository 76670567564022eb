//! `sim --mcap FILE` (and `--foxglove ADDR`, the same messages live): the simulated readers'
//! sessions (each reader's recorder hands its entries on, as `proxy --mcap` does), their
//! antennas' poses and the ground truth (from the truth writer, [`super::truth`]), the live
//! localizer's estimates and the 3D scene in one MCAP file of ROS 2 messages
//! (docs/robotics.md).
//! The file is written on the MCAP writer's thread; a failed write is logged there and ends
//! the file, not the simulation.

use std::sync::atomic::{AtomicU64, Ordering};

use super::{record_path, SimError, SimOptions, Start};
use crate::foxglove::LiveServer;
use crate::localize::estimate::State;
use crate::localize::shared::{reason, Shared, TagView};
use crate::record::mcap::estimates::{EstimateItem, EstimateState};
use crate::record::mcap::scene::SceneWorld;
use crate::record::mcap::{McapError, McapItem, McapThread};
use crate::record::{Discard, Header, RecordOptions, Recorder, RecorderTask};
use crate::scenario::{ReaderSpec, Scenario};

/// Creates the `--mcap` file (an existing one is refused unless `--force`) and starts its
/// writer, which also feeds the `--foxglove` live view `live`, and hands it the scene's world
/// (`scenario`'s bounds, reflectors and antenna beamwidths); none without either.
pub(super) fn open(
    opts: &SimOptions,
    scenario: &Scenario,
    live: Option<&LiveServer>,
) -> Result<Option<McapThread>, SimError> {
    let mcap = McapThread::open(opts.mcap.as_deref(), opts.force, live.map(LiveServer::tap))
        .map_err(SimError::Mcap)?;
    if let Some(mcap) = &mcap {
        // The queue is new and empty: there is room.
        mcap.sender()
            .try_send(McapItem::SceneWorld(scene_world(scenario)));
    }
    Ok(mcap)
}

/// What the scene shows of `scenario`'s world that does not move.
fn scene_world(scenario: &Scenario) -> SceneWorld {
    let beamwidths = (scenario.readers.iter())
        .flat_map(|r| {
            (r.antennas.iter().zip(1u16..))
                .map(|(a, port)| (r.name.to_string(), port, a.beamwidth_deg))
        })
        .collect();
    SceneWorld {
        bounds: Some((scenario.world.min, scenario.world.max)),
        reflectors: (scenario.reflectors.iter())
            .map(|r| (r.name.clone(), r.point, r.normal))
            .collect(),
        beamwidths,
        robots: (crate::physics::distinct_robots(scenario).iter().enumerate())
            .map(|(i, r)| (super::truth::robot_frame(i), robot_box(r)))
            .collect(),
    }
}

/// A robot's box in the scene: `wheel_base` wide, as long plus a wheel's radius at either
/// end, and a wheel's diameter high.
fn robot_box(r: &crate::scenario::RobotSpec) -> [f64; 3] {
    let wheel = 2.0 * r.wheel_radius;
    [r.wheel_base + wheel, r.wheel_base, wheel]
}

/// Finishes the file once the readers and their recorders have stopped; what it holds is
/// logged, and so is an error.
pub(super) async fn finish(mcap: McapThread) {
    match mcap.finish_async().await {
        Ok(s) => tracing::info!(
            frames = s.frames,
            reads = s.reads,
            events = s.events,
            messages = s.messages,
            channels = s.channels,
            "the MCAP output is finished"
        ),
        Err(e) => tracing::error!(error = %e, "the MCAP file was not finished"),
    }
}

impl Start<'_> {
    /// The recorder of reader `spec`'s sessions (`--record`, `--mcap`: a file, the MCAP
    /// file, or both), and its writing task.
    pub(super) fn recorder(
        &self,
        spec: &ReaderSpec,
    ) -> Result<(Option<Recorder>, Option<RecorderTask>), SimError> {
        let options = RecordOptions {
            mcap: self.mcap.as_ref().map(|t| t.named(spec.name.as_ref())),
            ..self.opts.record_options.clone()
        };
        let mut header = Header::new(format!("sim:{}", spec.name), 0);
        header.scenario = Some(self.scenario.name.clone());
        let (r, task) = match &self.opts.record {
            Some(path) => {
                let path = record_path(path, &spec.name, self.scenario.readers.len());
                Recorder::create(&path, header, options).map_err(|source| SimError::Record {
                    reader: spec.name.clone(),
                    path: path.clone(),
                    source,
                })?
            }
            None if options.mcap.is_some() => Recorder::start(Discard, header, options)
                .map_err(|e| SimError::Mcap(McapError::Mcap { error: e.into() }))?,
            None => return Ok((None, None)),
        };
        Ok((Some(r), Some(task)))
    }
}

impl super::RunningSim {
    /// Hands every estimate `shared` publishes from now on to the `--mcap` file and the
    /// `--foxglove` view (none without either), logged at the simulation's clock. The
    /// localizer's thread offers them without waiting: an estimate with no room in the queue
    /// is dropped, with a warning (those published once the file is finished, silently).
    pub fn estimates_to_mcap(&self, shared: &Shared) {
        let Some(mcap) = &self.mcap else {
            return;
        };
        let sender = mcap.sender();
        let (clock, utc0) = (self.clock.clone(), self.utc0);
        let dropped = AtomicU64::new(0);
        shared.on_publish(move |tag| {
            let item = estimate_item(utc0.saturating_add(clock.now_us()), tag);
            if !sender.try_send(McapItem::Estimate(item))
                && !sender.is_closed()
                && dropped.fetch_add(1, Ordering::Relaxed) == 0
            {
                tracing::warn!("the MCAP writer is behind: estimates are dropped while it is");
            }
        });
    }
}

/// The MCAP file's estimate of `tag`, published at `logged_us`.
fn estimate_item(logged_us: u64, tag: &TagView) -> EstimateItem {
    let e = &tag.estimate;
    EstimateItem {
        logged_us,
        epc: e.epc.to_uppercase(),
        estimator: e.estimator.to_string(),
        state: match e.state {
            State::Converging => EstimateState::Converging,
            State::Converged => EstimateState::Converged,
            State::InsufficientGeometry => EstimateState::InsufficientGeometry,
        },
        position: e.estimate,
        covariance: e.covariance,
        pose_sigma_m: e.pose_sigma_m,
        samples: u32::try_from(e.samples).unwrap_or(u32::MAX),
        newest_phase_us: e.last_update_us,
        reads: tag.reads,
        reads_per_s: tag.reads_per_s,
        last_seen_us: tag.last_seen_us,
        reason: reason(e).unwrap_or_default(),
    }
}
