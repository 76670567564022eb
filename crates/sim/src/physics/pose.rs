//! Where each antenna is and points: its true pose (fixed, recorded or mounted on a robot)
//! and the pose a robot would report.

use super::geometry::{self, wrap_pi};
use super::multipath::Aim;
use super::{fastmath, motion, robot, seconds, AntennaPose, Model, Mover};

impl Model {
    /// The robot antenna `antenna` rides on, as an index into [`super::distinct_robots`] of
    /// the scenario; none for a fixed or recorded antenna.
    pub fn antenna_robot(&self, antenna: u16) -> Option<usize> {
        let a = usize::from(antenna)
            .checked_sub(1)
            .and_then(|i| self.antennas.get(i))?;
        match &a.mover {
            Mover::Robot { robot, .. } => Some(*robot),
            _ => None,
        }
    }

    /// Robot `robot`'s true pose `[x m, y m, heading rad]` at `t_us` (`robot` as
    /// [`Model::antenna_robot`] numbers it); none for an unknown one.
    pub fn robot_pose(&self, robot: usize, t_us: u64) -> Option<[f64; 3]> {
        Some(self.robots.get(robot)?.true_pose(seconds(t_us)))
    }

    /// The pose `[x m, y m, heading rad]` robot `robot` reports at `t_us` (its estimate of its
    /// own pose, that of [`Model::estimated_pose`]); none for an unknown one.
    pub fn robot_reported_pose(&self, robot: usize, t_us: u64) -> Option<[f64; 3]> {
        Some(self.robots.get(robot)?.estimated_pose(seconds(t_us)))
    }

    /// True position of antenna `antenna` at `t_us` (that of [`Model::antenna_pose`] up to
    /// rounding, the heading's sine and cosine through [`fastmath::cis`], without working out
    /// the boresight).
    pub fn antenna_position(&self, antenna: u16, t_us: u64) -> [f64; 3] {
        let Some(a) = usize::from(antenna)
            .checked_sub(1)
            .and_then(|i| self.antennas.get(i))
        else {
            return [0.0; 3];
        };
        match &a.mover {
            Mover::Robot {
                robot,
                offset,
                vertical,
            } => {
                let Some(trajectory) = self.robots.get(*robot) else {
                    return [0.0; 3];
                };
                let t = seconds(t_us);
                let [x, y, theta] = trajectory.true_pose(t);
                let (c, s) = fastmath::cis(theta);
                motion::mounted_position([x, y], (c, s), offset.position, vertical.as_ref(), t)
            }
            _ => self.antenna_pose(antenna, t_us).position,
        }
    }

    /// The [`Aim`] of the true pose of antenna `antenna` at `t_us`: `Aim::new` of
    /// [`Model::antenna_pose`] up to rounding, with a robot mount's constant trigonometry
    /// taken from [`MountAim`], the heading's through [`fastmath::cis`] and the boresight's
    /// azimuth by the angle-sum formulas (within 1e-15 of each component).
    pub(super) fn aim(&self, antenna: u16, t_us: u64) -> Aim {
        let robot_mount = usize::from(antenna)
            .checked_sub(1)
            .and_then(|i| self.antennas.get(i))
            .and_then(|a| match (&a.mover, a.mount_aim) {
                (
                    Mover::Robot {
                        robot,
                        offset,
                        vertical,
                    },
                    Some(m),
                ) => Some((self.robots.get(*robot)?, offset, vertical, m)),
                _ => None,
            });
        let Some((trajectory, offset, vertical, m)) = robot_mount else {
            return Aim::new(&self.antenna_pose(antenna, t_us));
        };
        let t = seconds(t_us);
        let [x, y, theta] = trajectory.true_pose(t);
        let (c, s) = fastmath::cis(theta);
        let (yaw_cos, yaw_sin) = (c * m.yaw_cos - s * m.yaw_sin, s * m.yaw_cos + c * m.yaw_sin);
        let boresight = [m.pitch_cos * yaw_cos, m.pitch_cos * yaw_sin, m.pitch_sin];
        Aim {
            position: motion::mounted_position(
                [x, y],
                (c, s),
                offset.position,
                vertical.as_ref(),
                t,
            ),
            boresight,
            boresight_norm: geometry::norm(boresight),
        }
    }

    /// The pose of `antenna`, a robot mount's robot at `robot_pose` of its trajectory.
    pub(super) fn pose(&self, antenna: u16, t_us: u64, robot_pose: robot::PoseOf) -> AntennaPose {
        let origin = AntennaPose::default();
        let Some(a) = usize::from(antenna)
            .checked_sub(1)
            .and_then(|i| self.antennas.get(i))
        else {
            return origin;
        };
        let t = seconds(t_us);
        match &a.mover {
            Mover::Fixed(pose) => *pose,
            Mover::Recorded(poses) => motion::recorded_pose(poses, t_us),
            Mover::Robot {
                robot,
                offset,
                vertical,
            } => {
                let Some(trajectory) = self.robots.get(*robot) else {
                    return origin;
                };
                let [x, y, theta] = robot_pose(trajectory, t);
                let (s, c) = theta.sin_cos();
                AntennaPose {
                    position: motion::mounted_position(
                        [x, y],
                        (c, s),
                        offset.position,
                        vertical.as_ref(),
                        t,
                    ),
                    yaw_rad: wrap_pi(theta + offset.yaw_rad),
                    pitch_rad: offset.pitch_rad,
                }
            }
        }
    }
}
