//! Piecewise-linear motion: tags moving along waypoints, recorded antenna pose lists, and a
//! robot's vertical antenna axis; and where on a robot its antenna is.

use super::geometry::{add_scaled, distance, sub, wrap_pi, Vec3};
use super::AntennaPose;
use crate::scenario::{Path, VerticalAxis};
use llrp_gateway_vocab::pose::PoseSample;

/// A tag's position over time: still, or moving along a polyline at constant speed.
#[derive(Clone, Debug, PartialEq)]
pub struct PolylineMotion {
    points: Vec<Vec3>,
    /// Cumulative length at each point.
    lengths: Vec<f64>,
    speed: f64,
    start_s: f64,
    looping: bool,
}

impl PolylineMotion {
    /// Motion starting at `position` and following `path` (still when `path` is `None`).
    pub fn new(position: Vec3, path: Option<&Path>) -> PolylineMotion {
        let mut points = vec![position];
        let (mut speed, mut start_s, mut looping) = (0.0, 0.0, false);
        if let Some(p) = path {
            points.extend(p.waypoints.iter().copied());
            if p.loop_path {
                points.push(position);
            }
            speed = if p.speed.is_finite() {
                p.speed.max(0.0)
            } else {
                0.0
            };
            start_s = if p.start_s.is_finite() {
                p.start_s
            } else {
                0.0
            };
            looping = p.loop_path;
        }
        let mut lengths = Vec::with_capacity(points.len());
        let mut total = 0.0;
        for (i, p) in points.iter().enumerate() {
            if i > 0 {
                total += distance(points[i - 1], *p);
            }
            lengths.push(total);
        }
        PolylineMotion {
            points,
            lengths,
            speed,
            start_s,
            looping,
        }
    }

    /// Speed along the path (m/s; 0 for a still tag): no position moves faster.
    pub fn speed(&self) -> f64 {
        if self.lengths.last().is_some_and(|&l| l > 0.0) {
            self.speed
        } else {
            0.0
        }
    }

    /// Time (s) from which the tag stays where it is; `None` if it never stops (a loop).
    pub fn rest_s(&self) -> Option<f64> {
        let total = self.lengths.last().copied().unwrap_or(0.0);
        if self.speed <= 0.0 || total <= 0.0 {
            Some(0.0)
        } else if self.looping {
            None
        } else {
            Some(self.start_s.max(0.0) + total / self.speed)
        }
    }

    /// Position at time `t_s` (seconds).
    pub fn position(&self, t_s: f64) -> Vec3 {
        let total = self.lengths.last().copied().unwrap_or(0.0);
        if self.speed <= 0.0 || total <= 0.0 || !t_s.is_finite() {
            return self.points[0];
        }
        let mut s = self.speed * (t_s - self.start_s).max(0.0);
        if self.looping {
            s = s.rem_euclid(total);
        } else if s >= total {
            return self.points[self.points.len() - 1];
        }
        // First point whose cumulative length exceeds s.
        let i = self.lengths.partition_point(|&l| l <= s).max(1);
        let (a, b) = (self.points[i - 1], self.points[i]);
        let seg = self.lengths[i] - self.lengths[i - 1];
        let f = if seg > 0.0 {
            (s - self.lengths[i - 1]) / seg
        } else {
            0.0
        };
        add_scaled(a, f, sub(b, a))
    }
}

/// The pose interpolated in a recorded list at `t_us` (µs since scenario start); held at
/// the first and last samples outside the recording. Between two samples the yaw takes the
/// shorter way round, onto [−π, π].
pub fn recorded_pose(poses: &[PoseSample], t_us: u64) -> AntennaPose {
    let Some(first) = poses.first() else {
        return AntennaPose::default();
    };
    if t_us <= first.t_us {
        return first.pose;
    }
    let i = poses.partition_point(|p| p.t_us <= t_us);
    if i >= poses.len() {
        return poses[poses.len() - 1].pose;
    }
    let (a, b) = (&poses[i - 1].pose, &poses[i].pose);
    let span = poses[i].t_us - poses[i - 1].t_us;
    let f = if span > 0 {
        (t_us - poses[i - 1].t_us) as f64 / span as f64
    } else {
        0.0
    };
    let lerp = |x: f64, y: f64| x + f * (y - x);
    let (ya, yb) = (a.yaw_rad, b.yaw_rad);
    AntennaPose {
        position: [
            lerp(a.position[0], b.position[0]),
            lerp(a.position[1], b.position[1]),
            lerp(a.position[2], b.position[2]),
        ],
        yaw_rad: wrap_pi(ya + f * wrap_pi(yb - ya)),
        pitch_rad: lerp(a.pitch_rad, b.pitch_rad),
    }
}

/// How far a recorded pose strays from its value at `t0_us` during `[t0_us, t1_us]`: the
/// largest change of x, y and z (m) and a bound on the boresight's turn (rad: the yaw and
/// pitch steps summed).
pub fn recorded_excursion(poses: &[PoseSample], t0_us: u64, t1_us: u64) -> [f64; 4] {
    let start = recorded_pose(poses, t0_us);
    let end = recorded_pose(poses, t1_us);
    let turn = |a: AntennaPose, b: AntennaPose| {
        wrap_pi(b.yaw_rad - a.yaw_rad).abs() + (b.pitch_rad - a.pitch_rad).abs()
    };
    let mut far = [0.0f64; 4];
    let mut see = |p: AntennaPose| {
        for ((f, x), x0) in far.iter_mut().zip(p.position).zip(start.position) {
            *f = f.max((x - x0).abs());
        }
    };
    // Positions are linear between samples (each change peaks at a sample or at the end);
    // the boresight turns at most by the sum of the steps between them.
    see(end);
    let (mut swing, mut last) = (0.0, start);
    for p in poses.iter().filter(|p| p.t_us > t0_us && p.t_us < t1_us) {
        let here = recorded_pose(poses, p.t_us);
        see(here);
        swing += turn(last, here);
        last = here;
    }
    far[3] = swing + turn(last, end);
    far
}

/// Height of an antenna on a vertical axis at `t_s`: a triangle wave starting at `min_z`,
/// rising at `speed` to `max_z` and back.
pub fn vertical_z(axis: &VerticalAxis, t_s: f64) -> f64 {
    let span = axis.max_z - axis.min_z;
    if !(span > 0.0 && axis.speed > 0.0 && t_s.is_finite()) {
        return axis.min_z;
    }
    let travel = (axis.speed * t_s.max(0.0)).rem_euclid(2.0 * span);
    if travel <= span {
        axis.min_z + travel
    } else {
        axis.max_z - (travel - span)
    }
}

/// Position of an antenna mounted on a robot at (`x`, `y`) whose heading has cosine `c` and
/// sine `s`: the robot's position plus the mount `offset` turned by the heading, at the
/// height of the robot's `vertical` axis at `t_s` if it has one (the offset's otherwise).
/// The caller works out the cosine and sine, so that each keeps its own trigonometry.
pub fn mounted_position(
    [x, y]: [f64; 2],
    (c, s): (f64, f64),
    offset: Vec3,
    vertical: Option<&VerticalAxis>,
    t_s: f64,
) -> Vec3 {
    let [ox, oy, oz] = offset;
    let z = vertical.map_or(oz, |v| vertical_z(v, t_s));
    [x + c * ox - s * oy, y + s * ox + c * oy, z]
}

#[cfg(test)]
mod tests {
    use super::*;
    use llrp_gateway_vocab::pose::Pose;

    #[test]
    fn tag_moves_along_its_waypoints() {
        let path = Path {
            waypoints: vec![[4.0, 0.0, 0.0], [4.0, 3.0, 0.0]],
            speed: 2.0,
            start_s: 1.0,
            loop_path: false,
        };
        let m = PolylineMotion::new([0.0; 3], Some(&path));
        assert_eq!(m.position(0.5), [0.0; 3]);
        assert_eq!(m.position(2.0), [2.0, 0.0, 0.0]);
        assert_eq!(m.position(3.0), [4.0, 0.0, 0.0]);
        assert_eq!(m.position(4.0), [4.0, 2.0, 0.0]);
        assert_eq!(m.position(100.0), [4.0, 3.0, 0.0]);
        let looping = PolylineMotion::new(
            [0.0; 3],
            Some(&Path {
                loop_path: true,
                start_s: 0.0,
                ..path
            }),
        );
        // Loop length 4 + 3 + 5 = 12 m: after 6 s (12 m) it is back at the start.
        let p = looping.position(6.0 + 1.0);
        assert!((p[0] - 2.0).abs() < 1e-9 && p[1].abs() < 1e-9);
        assert_eq!(
            PolylineMotion::new([1.0, 2.0, 3.0], None).position(5.0),
            [1.0, 2.0, 3.0]
        );
    }

    #[test]
    fn recorded_poses_interpolate_linearly_and_hold_at_the_ends() {
        let s = |t_us, x, yaw_deg| PoseSample {
            t_us,
            reader: Some("r".parse().expect("a reader name")),
            antenna: 1,
            pose: Pose::from_degrees([x, 0.0, 1.0], yaw_deg, 0.0),
        };
        let poses = [s(1_000_000, 0.0, 170.0), s(3_000_000, 2.0, -170.0)];
        assert_eq!(recorded_pose(&poses, 0).position[0], 0.0);
        let mid = recorded_pose(&poses, 2_000_000);
        assert!((mid.position[0] - 1.0).abs() < 1e-12);
        // 170° → −170° goes through 180°, not through 0°.
        assert!((mid.yaw_rad.abs() - std::f64::consts::PI).abs() < 1e-9);
        assert_eq!(recorded_pose(&poses, 9_000_000).position[0], 2.0);
    }

    #[test]
    fn vertical_axis_is_a_triangle_wave() {
        let axis = VerticalAxis {
            min_z: 0.5,
            max_z: 2.0,
            speed: 0.5,
        };
        assert_eq!(vertical_z(&axis, 0.0), 0.5);
        assert!((vertical_z(&axis, 1.0) - 1.0).abs() < 1e-12);
        assert!((vertical_z(&axis, 3.0) - 2.0).abs() < 1e-12);
        assert!((vertical_z(&axis, 4.0) - 1.5).abs() < 1e-12);
        assert!((vertical_z(&axis, 6.0) - 0.5).abs() < 1e-12);
    }

    #[test]
    fn mounted_antenna_turns_with_the_robot_and_rides_its_lift() {
        // Heading +90°: the offset's +x points along +y, its +y along −x.
        let offset = [0.2, 0.3, 0.5];
        assert_eq!(
            mounted_position([1.0, 2.0], (0.0, 1.0), offset, None, 1.0),
            [1.0 - 0.3, 2.0 + 0.2, 0.5]
        );
        let axis = VerticalAxis {
            min_z: 0.5,
            max_z: 2.0,
            speed: 0.5,
        };
        let p = mounted_position([1.0, 2.0], (1.0, 0.0), offset, Some(&axis), 1.0);
        assert_eq!(p, [1.2, 2.3, vertical_z(&axis, 1.0)]);
    }
}
