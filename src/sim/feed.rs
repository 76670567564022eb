//! What the simulator hands the live localizer beside the LLRP bytes: every antenna's pose
//! (true, or what the robot itself would report) at a fixed interval of simulated time
//! ([`POSE_INTERVAL_US`] unless `sim --pose-interval-ms` says otherwise), as a robot's pose
//! feed would, the same pose at each read to stamp the reads with ([`pose_at`]), and the
//! ground truth for `GET /api/truth`.

use crate::reads::ReaderName;
use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::localize::estimate::ReaderGeometry;
use crate::localize::live::{Input, Settings, Tap};
use crate::localize::poses::PoseSample;
use crate::localize::refine::PoseErrorModel;
use crate::localize::series::Ambiguity;
use crate::physics::{AntennaPose, Model, World};
use crate::reads::PoseAt;
use crate::scenario::{Mount, PoseEstimateKind, Scenario};
use llrp_gateway_vocab::feed::{Truth, TruthTag};

/// Simulated time between two pose samples of an antenna by default, µs (10 Hz).
pub const POSE_INTERVAL_US: u64 = 100_000;

/// Wall time between two updates of the ground truth at most: at `--speed max` the pose
/// samples come thousands of times a second, and nobody reads the truth that often.
pub const TRUTH_EVERY: Duration = Duration::from_millis(50);

/// Which poses the simulator gives the localizer (`sim --poses`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PoseSource {
    /// The true antenna poses.
    Truth,
    /// What the robot itself would report: odometry, or the localization-like error of the
    /// scenario's `pose_estimate`.
    #[default]
    Estimated,
}

impl PoseSource {
    /// The pose of `antenna` of `m` at simulated time `t_us`, as this source gives it.
    fn pose(self, m: &Model, antenna: u16, t_us: u64) -> AntennaPose {
        match self {
            PoseSource::Truth => m.antenna_pose(antenna, t_us),
            PoseSource::Estimated => m.estimated_pose(antenna, t_us),
        }
    }
}

/// Reader `name`'s pose and truth feed.
pub struct Feed {
    tap: Tap,
    name: ReaderName,
    source: PoseSource,
    references: Arc<Vec<bool>>,
    /// Simulated time of the next sample.
    next_us: u64,
    /// Simulated time between two samples (µs).
    interval_us: u64,
    /// The tags' EPCs (hex), made at the first truth.
    epcs: Vec<crate::reads::Epc>,
    /// When the truth was last set.
    truth_at: Option<Instant>,
    /// The reads' clock at simulated time 0 (UTC µs): the truth's antenna poses are shown on
    /// it, as every time of the API is.
    utc0_us: u64,
}

impl Feed {
    /// A feed of reader `name` into `tap`, a sample every `interval_us` starting with the
    /// one at or before `now_us`.
    pub fn new(
        tap: Tap,
        name: ReaderName,
        source: PoseSource,
        references: Arc<Vec<bool>>,
        interval_us: u64,
        now_us: u64,
    ) -> Feed {
        let interval_us = interval_us.max(1);
        Feed {
            tap,
            name,
            source,
            references,
            next_us: now_us / interval_us * interval_us,
            interval_us,
            epcs: Vec::new(),
            truth_at: None,
            utc0_us: 0,
        }
    }

    /// Shows the truth's antenna poses on the reads' clock, simulated time 0 being `utc0_us`.
    pub fn with_utc0(mut self, utc0_us: u64) -> Feed {
        self.utc0_us = utc0_us;
        self
    }

    /// Sends the samples due up to simulated time `now_us`, and the truth at the newest (at
    /// most every [`TRUTH_EVERY`]).
    pub fn feed(&mut self, m: &Model, now_us: u64) {
        // After a long pause (the own inventory waits while a client is connected) the
        // samples restart shortly before now instead of catching up the whole pause.
        let every = self.interval_us;
        let resume = now_us.saturating_sub(10 * every) / every;
        self.next_us = self.next_us.max(resume * every);
        let mut poses = Vec::new();
        let mut last = None;
        while self.next_us <= now_us {
            let t = self.next_us;
            for a in 1..=m.antenna_count() {
                let pose = self.source.pose(m, a, t);
                poses.push(sample(&self.name, a, t, &pose));
            }
            last = Some(t);
            self.next_us += every;
        }
        if poses.is_empty() {
            return;
        }
        self.tap.offer(Input::Poses(poses));
        if self.truth_at.is_some_and(|at| at.elapsed() < TRUTH_EVERY) {
            return;
        }
        if let Some(t) = last {
            self.truth_at = Some(Instant::now());
            if self.epcs.len() != m.tag_count() {
                self.epcs = (0..m.tag_count())
                    .map(|k| crate::reads::Epc::from_bytes(m.tag_epc(k).as_bytes()))
                    .collect();
            }
            let truth = Truth {
                tags: (0..m.tag_count())
                    .map(|k| TruthTag {
                        epc: self.epcs[k].clone(),
                        position: m.tag_position(k, t),
                        reference: self.references.get(k).copied().unwrap_or(false),
                    })
                    .collect(),
                antennas: (1..=m.antenna_count())
                    .map(|a| sample(&self.name, a, t, &m.antenna_pose(a, t)))
                    .map(|mut p| {
                        p.t_us += self.utc0_us;
                        p
                    })
                    .collect(),
            };
            self.tap.offer(Input::Truth(truth));
        }
    }
}

/// The antennas' poses at any read of the reader on `model` whose clock starts at `utc0`
/// (UTC µs), true or as the robot reports them: what the simulator stamps its reads with.
pub fn pose_at(model: Arc<Model>, source: PoseSource, utc0: u64) -> PoseAt {
    PoseAt::new(move |antenna, t_us| {
        if antenna == 0 || antenna > model.antenna_count() {
            return None;
        }
        Some(source.pose(&model, antenna, t_us.checked_sub(utc0)?))
    })
}

/// A pose sample of reader `reader`'s `antenna` at `t_us`.
fn sample(reader: &ReaderName, antenna: u16, t_us: u64, pose: &AntennaPose) -> PoseSample {
    PoseSample {
        t_us,
        reader: Some(reader.clone()),
        antenna,
        pose: *pose,
    }
}

/// The error of the poses a robot of `scenario` reports, as the localizer is told it: the
/// largest over its antennas on robots whose `pose_estimate` is `localized`, the heading's
/// error taken in at the antenna's lever arm from the robot's centre; `None` when no antenna
/// has such poses (fixed antennas, or odometry, whose error grows without bound).
pub fn pose_error(scenario: &Scenario) -> Option<PoseErrorModel> {
    scenario
        .readers
        .iter()
        .flat_map(|r| &r.antennas)
        .filter_map(|a| match &a.mount {
            Mount::Robot { robot, offset }
                if robot.pose_estimate.kind == PoseEstimateKind::Localized =>
            {
                let e = &robot.pose_estimate;
                let lever = offset.position[0].hypot(offset.position[1]);
                let heading = lever * e.heading_sigma_deg.to_radians();
                Some(PoseErrorModel::new(
                    e.position_sigma_m.hypot(heading),
                    e.correlation_s,
                ))
            }
            _ => None,
        })
        .max_by(|a, b| a.sigma_m.total_cmp(&b.sigma_m))
}

/// The live localizer's settings for a scenario: its first reader's first antenna gives the
/// default phase sign, the π ambiguity, the side the antennas face (its yaw at time 0) and the
/// tags' height (the antenna's own, as each antenna assumes in \[A\]); every reader its own
/// phase sign and facing, from its first antenna the same way; the reference tags are the
/// scenario's, at their positions.
pub fn settings(scenario: &Scenario, base: Settings) -> Settings {
    let mut s = base;
    // The localizer is told the tags' curvature law, as it is told the poses' error.
    s.geometry.tag_curvature_sigma_rad = scenario.tag_variation.phase_curvature_sigma_rad;
    let world = World::new(scenario);
    for (i, spec) in scenario.readers.iter().enumerate() {
        let model = Model::in_world(&world, scenario, i);
        let Some(a) = spec.antennas.first() else {
            continue;
        };
        let pose = model.antenna_pose(1, 0);
        let facing = [pose.yaw_rad.cos(), pose.yaw_rad.sin()];
        if i == 0 {
            s.geometry.phase_sign = a.phase_sign;
            s.ambiguity = if a.phase_pi_ambiguity {
                Ambiguity::Pi
            } else {
                Ambiguity::None
            };
            s.geometry.tag_height_m = pose.position[2];
            s.geometry.facing = facing;
            s.geometry.references = (0..model.tag_count())
                .filter(|&k| scenario.tags.get(k).is_some_and(|t| t.reference))
                .map(|k| {
                    (
                        crate::reads::Epc::from_bytes(model.tag_epc(k).as_bytes()),
                        model.tag_position(k, 0),
                    )
                })
                .collect();
        }
        s.geometry.readers.insert(
            spec.name.to_string(),
            ReaderGeometry {
                phase_sign: a.phase_sign,
                facing,
            },
        );
    }
    s
}
