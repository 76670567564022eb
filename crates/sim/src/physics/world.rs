//! What every reader of a scenario sees alike, built once and shared by their models.

use std::sync::Arc;

use super::*;

/// What every reader of a scenario sees alike: the tags, reflectors and robot drives, built
/// once and shared by the readers' models.
#[derive(Clone, Debug)]
pub struct World {
    pub(super) tags: Arc<[TagModel]>,
    pub(super) planes: Arc<[Plane]>,
    pub(super) robots: Arc<[RobotTrajectory]>,
    /// When the last tag stops moving, µs (`u64::MAX`: never; 0: no tag moves).
    pub(super) tags_rest_us: u64,
}

impl World {
    /// The shared part of `scenario`'s models: every tag, reflector and robot drive.
    pub fn new(scenario: &Scenario) -> World {
        let robots: Vec<RobotTrajectory> = distinct_robots(scenario)
            .into_iter()
            .enumerate()
            .map(|(global, robot)| {
                let id = [scenario.seed, seed::domain::ROBOT, global as u64];
                // The localization error's stream: the odometry's words and one more.
                let error_id = [id[0], id[1], id[2], robot::ESTIMATE_STREAM];
                RobotTrajectory::simulate(robot, &mut seed::rng(&id))
                    .with_estimate(&robot.pose_estimate, &mut seed::rng(&error_id))
            })
            .collect();
        let tags: Vec<TagModel> = scenario
            .tags
            .iter()
            .enumerate()
            .map(|(index, t)| {
                let epc = parse_epc(&t.epc).unwrap_or_else(|_| [0; 12].into());
                TagModel {
                    epc,
                    tid: t
                        .tid
                        .as_deref()
                        .and_then(|h| parse_words(h).ok())
                        .unwrap_or_else(|| default_tid(epc.as_bytes())),
                    user: t
                        .user
                        .as_deref()
                        .map_or_else(default_user, |h| parse_words(h).unwrap_or_default()),
                    passwords: [&t.kill_password, &t.access_password].map(|p| {
                        p.as_deref()
                            .and_then(|h| parse_password(h).ok())
                            .unwrap_or(0)
                    }),
                    motion: PolylineMotion::new(t.position, t.path.as_ref()),
                    radio: tag::TagRadio::new(scenario, index, t),
                }
            })
            .collect();
        // Tags stop too: an antenna's field stops changing once both have.
        let tags_rest_us = tags
            .iter()
            .map(|t| {
                t.motion
                    .rest_s()
                    .map_or(u64::MAX, |s| rest_time_us(s + REST_MARGIN_S))
            })
            .max()
            .unwrap_or(0);
        World {
            tags: tags.into(),
            planes: multipath::planes(&scenario.reflectors).into(),
            robots: robots.into(),
            tags_rest_us,
        }
    }
}
