//! Poses and positions in an MCAP file: an antenna's pose as Foxglove's well-known
//! `PoseInFrame` in its ROS 2 form (`foxglove_msgs/msg/PoseInFrame`), the antenna frames as
//! `tf2_msgs/msg/TFMessage` (the ROS 2 type of Foxglove's `FrameTransform`s) and a tag's true
//! position as `llrp_gateway_msgs/msg/TagPosition`; each with its `ros2msg` schema text (the
//! field lists of the `foxglove_msgs`, `tf2_msgs` and `geometry_msgs` packages) and its CDR
//! encoder.
//!
//! An antenna's frame: its origin at the antenna, +x its boresight (yaw about +z, then pitch
//! up), +z up when the pitch is 0. The world frame is `map`.

use std::io::Write;

use super::cdr::Cdr;
use super::msgs::MsgType;
use super::{McapError, McapOut};
use llrp_gateway_vocab::pose::Pose as AntennaPose;

/// The world frame every pose is given in.
pub const WORLD: &str = "map";

pub(super) const POSE_IN_FRAME: &str = "\
# foxglove_msgs/msg/PoseInFrame: Foxglove's well-known PoseInFrame schema in its ROS 2 form.
builtin_interfaces/Time timestamp
string frame_id
geometry_msgs/Pose pose
";
pub(super) const TF_MESSAGE: &str = "geometry_msgs/TransformStamped[] transforms\n";
pub(super) const POSE: (&str, &str) = (
    "geometry_msgs/msg/Pose",
    "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n",
);
pub(super) const POINT: (&str, &str) = (
    "geometry_msgs/msg/Point",
    "float64 x\nfloat64 y\nfloat64 z\n",
);
pub(super) const QUATERNION: (&str, &str) = (
    "geometry_msgs/msg/Quaternion",
    "float64 x\nfloat64 y\nfloat64 z\nfloat64 w\n",
);
pub(super) const TRANSFORM_STAMPED: (&str, &str) = (
    "geometry_msgs/msg/TransformStamped",
    "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n",
);
pub(super) const TRANSFORM: (&str, &str) = (
    "geometry_msgs/msg/Transform",
    "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n",
);
pub(super) const VECTOR3: (&str, &str) = (
    "geometry_msgs/msg/Vector3",
    "float64 x\nfloat64 y\nfloat64 z\n",
);

/// The orientation `(x, y, z, w)` of an antenna's frame: a yaw about +z, then a pitch that
/// raises the boresight (+x), a rotation of `-pitch` about the new +y.
pub fn orientation(pose: &AntennaPose) -> [f64; 4] {
    let (sy, cy) = (pose.yaw_rad / 2.0).sin_cos();
    let (sp, cp) = (-pose.pitch_rad / 2.0).sin_cos();
    // q_z(yaw) * q_y(-pitch)
    [-sy * sp, cy * sp, sy * cp, cy * cp]
}

/// The unit vector of an antenna's boresight (its frame's +x) in the world frame.
pub fn boresight(pose: &AntennaPose) -> [f64; 3] {
    let (sy, cy) = pose.yaw_rad.sin_cos();
    let (sp, cp) = pose.pitch_rad.sin_cos();
    [cy * cp, sy * cp, sp]
}

/// Appends a `geometry_msgs/Point` (or `Vector3`) and a `Quaternion`.
fn pose_fields(cdr: &mut Cdr, pose: &AntennaPose) {
    for v in pose.position.iter().chain(orientation(pose).iter()) {
        cdr.f64(*v);
    }
}

/// A robot at one instant, as one reader's truth sees it.
#[derive(Clone, Debug, PartialEq)]
pub struct RobotAt {
    /// Its frame's name (`robot_N`, N from 1 in the scenario's order).
    pub name: String,
    /// Its true pose `[x m, y m, heading rad]` (the scene's).
    pub true_pose: [f64; 3],
    /// The pose it reports (its frame on `/tf`, the parent of the antennas it carries).
    pub reported: [f64; 3],
    /// The ports of the reader's antennas it carries.
    pub ports: Vec<u16>,
}

/// The pose of `antenna` in the frame of a robot at `robot` `[x, y, heading]` (a rotation
/// about +z only, so yaw and pitch stay a yaw and a pitch).
fn in_robot_frame(robot: [f64; 3], antenna: &AntennaPose) -> AntennaPose {
    let (s, c) = robot[2].sin_cos();
    let (dx, dy) = (
        antenna.position[0] - robot[0],
        antenna.position[1] - robot[1],
    );
    AntennaPose {
        position: [c * dx + s * dy, -s * dx + c * dy, antenna.position[2]],
        yaw_rad: antenna.yaw_rad - robot[2],
        pitch_rad: antenna.pitch_rad,
    }
}

/// A robot's pose `[x, y, heading]` on the floor as a pose.
fn floor_pose(robot: [f64; 3]) -> AntennaPose {
    AntennaPose {
        position: [robot[0], robot[1], 0.0],
        yaw_rad: robot[2],
        pitch_rad: 0.0,
    }
}

/// What the simulator knows of one reader at one instant.
#[derive(Clone, Debug)]
pub struct Truth {
    /// The reader's name.
    pub reader: String,
    /// The instant, UTC µs (the simulation's clock).
    pub utc_us: u64,
    /// Each antenna: its port, its true pose and the pose the robot reports.
    pub antennas: Vec<(u16, AntennaPose, AntennaPose)>,
    /// Tags and their true positions (every tag at the start, then the moving ones).
    pub tags: Vec<(String, [f64; 3])>,
    /// The robots carrying the reader's antennas.
    pub robots: Vec<RobotAt>,
}

impl<W: Write> McapOut<W> {
    /// One instant of a simulated reader: each antenna's reported pose on
    /// `/llrp/READER/antenna_N/pose`; on `/tf` each robot's reported pose as a transform
    /// from `map` to `robot_N` and each antenna's as one to `READER/antenna_N` from its
    /// robot's frame (from `map` when no robot carries it); its true pose on
    /// `/truth/READER/antenna_N/pose`; the tags on `/truth/tags`; and, when one is due, the
    /// scene ([`super::scene`]).
    pub fn truth(&mut self, t: &Truth) -> Result<(), McapError> {
        let token = self.token(&t.reader);
        let ns = t.utc_us.saturating_mul(1000);
        let mut tf = Cdr::new();
        let transforms = t.antennas.len() + t.robots.len();
        tf.u32(u32::try_from(transforms).unwrap_or(u32::MAX));
        for r in &t.robots {
            tf.header(ns, WORLD).string(&r.name);
            pose_fields(&mut tf, &floor_pose(r.reported));
        }
        for (port, true_pose, reported) in &t.antennas {
            let frame = format!("{token}/antenna_{port}");
            let carrier = t.robots.iter().find(|r| r.ports.contains(port));
            for (topic, pose) in [
                (format!("/llrp/{token}/antenna_{port}/pose"), reported),
                (format!("/truth/{token}/antenna_{port}/pose"), true_pose),
            ] {
                self.cdr.time(ns).string(WORLD);
                pose_fields(&mut self.cdr, pose);
                let bytes = self.cdr.finish();
                self.write(&topic, MsgType::PoseInFrame, ns, ns, &bytes)?;
            }
            match carrier {
                Some(r) => {
                    tf.header(ns, &r.name).string(&frame);
                    pose_fields(&mut tf, &in_robot_frame(r.reported, reported));
                }
                None => {
                    tf.header(ns, WORLD).string(&frame);
                    pose_fields(&mut tf, reported);
                }
            }
        }
        if transforms > 0 {
            self.write("/tf", MsgType::TfMessage, ns, ns, &tf.finish())?;
        }
        for (epc, p) in &t.tags {
            self.cdr.header(ns, WORLD).string(&epc.to_uppercase());
            for v in p {
                self.cdr.f64(*v);
            }
            let bytes = self.cdr.finish();
            self.write("/truth/tags", MsgType::TagPosition, ns, ns, &bytes)?;
        }
        self.scene_truth(&token, t)
    }
}

/// Antenna poses a running gateway received (`POST /api/poses`, MQTT, a pose file).
#[derive(Clone, Debug, PartialEq)]
pub struct ReceivedPoses {
    /// When the gateway took them, UTC µs (the MCAP log time).
    pub received_us: u64,
    /// Each pose: its reader's name, its time (the reads' clock, µs), its port and the pose.
    pub poses: Vec<(String, u64, u16, AntennaPose)>,
}

impl<W: Write> McapOut<W> {
    /// Antenna poses received from outside: each on `/llrp/READER/antenna_N/pose` (as a
    /// simulation's reported poses) and on `/tf` as a transform from `map` to
    /// `READER/antenna_N`, stamped with its own time; each antenna and its path join the
    /// scene (written when the estimates or the poses pace it).
    pub fn received_poses(&mut self, p: &ReceivedPoses) -> Result<(), McapError> {
        let log_ns = p.received_us.saturating_mul(1000);
        for (reader, t_us, port, pose) in &p.poses {
            let token = self.token(reader);
            let ns = t_us.saturating_mul(1000);
            let frame = format!("{token}/antenna_{port}");
            self.cdr.time(ns).string(WORLD);
            pose_fields(&mut self.cdr, pose);
            let bytes = self.cdr.finish();
            let topic = format!("/llrp/{token}/antenna_{port}/pose");
            self.write(&topic, MsgType::PoseInFrame, log_ns, ns, &bytes)?;
            self.cdr.u32(1).header(ns, WORLD).string(&frame);
            pose_fields(&mut self.cdr, pose);
            let bytes = self.cdr.finish();
            self.write("/tf", MsgType::TfMessage, log_ns, ns, &bytes)?;
            self.scene_antenna(&token, *port, pose);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rotate(q: [f64; 4], v: [f64; 3]) -> [f64; 3] {
        let [x, y, z, w] = q;
        // v' = q v q*, expanded.
        let (vx, vy, vz) = (v[0], v[1], v[2]);
        let tx = 2.0 * (y * vz - z * vy);
        let ty = 2.0 * (z * vx - x * vz);
        let tz = 2.0 * (x * vy - y * vx);
        [
            vx + w * tx + (y * tz - z * ty),
            vy + w * ty + (z * tx - x * tz),
            vz + w * tz + (x * ty - y * tx),
        ]
    }

    #[test]
    fn an_antenna_frame_s_x_axis_is_its_boresight() {
        let yaw = 0.7_f64;
        let pitch = 0.3_f64;
        let pose = AntennaPose {
            position: [1.0, 2.0, 3.0],
            yaw_rad: yaw,
            pitch_rad: pitch,
        };
        let b = rotate(orientation(&pose), [1.0, 0.0, 0.0]);
        let want = [
            yaw.cos() * pitch.cos(),
            yaw.sin() * pitch.cos(),
            pitch.sin(),
        ];
        for (g, w) in b.iter().zip(want) {
            assert!((g - w).abs() < 1e-12, "{b:?} vs {want:?}");
        }
        let n: f64 = orientation(&pose).iter().map(|c| c * c).sum();
        assert!((n - 1.0).abs() < 1e-12);
    }

    #[test]
    fn an_antenna_in_its_robot_s_frame_composes_back_to_its_pose_in_the_world() {
        let robot = [2.0, 3.0, 0.8];
        let antenna = AntennaPose {
            position: [2.5, 3.4, 0.7],
            yaw_rad: 2.0,
            pitch_rad: 0.2,
        };
        let rel = in_robot_frame(robot, &antenna);
        let q = orientation(&floor_pose(robot));
        let p = rotate(q, rel.position);
        let world = [p[0] + robot[0], p[1] + robot[1], p[2]];
        let close = |a: [f64; 3], b: [f64; 3]| (0..3).all(|i| (a[i] - b[i]).abs() < 1e-12);
        assert!(close(world, antenna.position), "{world:?}");
        for axis in [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]] {
            let composed = rotate(q, rotate(orientation(&rel), axis));
            let direct = rotate(orientation(&antenna), axis);
            assert!(close(composed, direct), "{composed:?} vs {direct:?}");
        }
    }
}
