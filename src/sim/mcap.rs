//! `sim --mcap FILE` (and `--foxglove ADDR`, the same messages live): the simulated readers'
//! sessions (each reader's recorder hands its entries on, as `proxy --mcap` does), their
//! antennas' poses and the ground truth (from the truth writer, [`super::truth`]), the live
//! localizer's estimates and the 3D scene in one MCAP file of ROS 2 messages
//! (docs/robotics.md).
//! The file is written on the MCAP writer's thread; a failed write is logged there and ends
//! the file, not the simulation.

use super::{record_path, SimError, SimOptions, Start};
use crate::foxglove::LiveServer;
use crate::localize::shared::Shared;
use crate::mcap_estimates::ScenePacing;
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
    /// `--foxglove` view (none without either), logged at the simulation's clock
    /// ([`crate::mcap_estimates`]; the truth paces the scene).
    pub fn estimates_to_mcap(&self, shared: &Shared) {
        let Some(mcap) = &self.mcap else {
            return;
        };
        let (clock, utc0) = (self.clock.clone(), self.utc0);
        crate::mcap_estimates::estimates_to_mcap(
            shared,
            mcap.sender(),
            move || utc0.saturating_add(clock.now_us()),
            ScenePacing::ByTruth,
        );
    }
}
