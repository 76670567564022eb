//! Piecewise-linear motion: tags moving along waypoints, recorded antenna pose lists, and a
//! robot's vertical antenna axis; and where on a robot its antenna is.

use super::geometry::{add_scaled, distance, sub, wrap_pi, Vec3};
use crate::scenario::{Path, PoseSample, VerticalAxis};

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

/// Pose `[x, y, z, yaw_rad, pitch_rad]` interpolated in a recorded list at `t_s`; held at the
/// first and last samples outside the recording. Yaw takes the shorter way round.
pub fn recorded_pose(poses: &[PoseSample], t_s: f64) -> [f64; 5] {
    let as_array = |p: &PoseSample| {
        [
            p.x,
            p.y,
            p.z,
            p.yaw_deg.to_radians(),
            p.pitch_deg.to_radians(),
        ]
    };
    let Some(first) = poses.first() else {
        return [0.0; 5];
    };
    if t_s.is_nan() || t_s <= first.t_s {
        return as_array(first);
    }
    let i = poses.partition_point(|p| p.t_s <= t_s);
    if i >= poses.len() {
        return as_array(&poses[poses.len() - 1]);
    }
    let (a, b) = (as_array(&poses[i - 1]), as_array(&poses[i]));
    let span = poses[i].t_s - poses[i - 1].t_s;
    let f = if span > 0.0 {
        (t_s - poses[i - 1].t_s) / span
    } else {
        0.0
    };
    let lerp = |x: f64, y: f64| x + f * (y - x);
    [
        lerp(a[0], b[0]),
        lerp(a[1], b[1]),
        lerp(a[2], b[2]),
        wrap_pi(a[3] + f * wrap_pi(b[3] - a[3])),
        lerp(a[4], b[4]),
    ]
}

/// How far a recorded pose strays from its value at `t0_s` during `[t0_s, t1_s]`: the largest
/// change of x, y and z (m) and a bound on the boresight's turn (rad: the yaw and pitch steps
/// summed).
pub fn recorded_excursion(poses: &[PoseSample], t0_s: f64, t1_s: f64) -> [f64; 4] {
    let start = recorded_pose(poses, t0_s);
    let end = recorded_pose(poses, t1_s);
    let turn = |a: [f64; 5], b: [f64; 5]| wrap_pi(b[3] - a[3]).abs() + (b[4] - a[4]).abs();
    let mut far = [0.0f64; 4];
    let mut see = |p: [f64; 5]| {
        for i in 0..3 {
            far[i] = far[i].max((p[i] - start[i]).abs());
        }
    };
    // Positions are linear between samples (each change peaks at a sample or at the end);
    // the boresight turns at most by the sum of the steps between them.
    see(end);
    let (mut swing, mut last) = (0.0, start);
    if t0_s.is_finite() && t1_s.is_finite() {
        for p in poses.iter().filter(|p| p.t_s > t0_s && p.t_s < t1_s) {
            let here = recorded_pose(poses, p.t_s);
            see(here);
            swing += turn(last, here);
            last = here;
        }
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
        let s = |t_s, x, yaw_deg| PoseSample {
            t_s,
            x,
            y: 0.0,
            z: 1.0,
            yaw_deg,
            pitch_deg: 0.0,
        };
        let poses = [s(1.0, 0.0, 170.0), s(3.0, 2.0, -170.0)];
        assert_eq!(recorded_pose(&poses, 0.0)[0], 0.0);
        let mid = recorded_pose(&poses, 2.0);
        assert!((mid[0] - 1.0).abs() < 1e-12);
        // 170° → −170° goes through 180°, not through 0°.
        assert!((mid[3].abs() - std::f64::consts::PI).abs() < 1e-9);
        assert_eq!(recorded_pose(&poses, 9.0)[0], 2.0);
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
