//! The ROS 2 messages `localize` and `replay` read out of MCAP files, decoded from CDR
//! ([`super::cdr_read`]), field for field as their `.msg` definitions give them:
//! `geometry_msgs/msg/{PoseStamped, PoseWithCovarianceStamped}`, `nav_msgs/msg/Odometry`,
//! `tf2_msgs/msg/TFMessage` (ROS 2's `common_interfaces` and `geometry2` repositories) and this
//! project's `llrp_gateway_msgs/msg/{TagRead, LlrpFrame}` (`ros2/llrp_gateway_msgs/msg`).

use super::cdr_read::{CdrError, CdrReader};
use crate::reads::{Epc, Read, ReaderName};
use crate::record::Direction;

/// A `geometry_msgs/Pose`: position (m) and orientation (unit quaternion `[x, y, z, w]`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RosPose {
    /// Position `[x, y, z]` (m).
    pub position: [f64; 3],
    /// Orientation `[x, y, z, w]`.
    pub orientation: [f64; 4],
}

/// A pose of `child` in `frame_id` at `stamp_ns`: a stamped pose, an odometry's pose, or one
/// transform of a `TFMessage`.
#[derive(Clone, Debug, PartialEq)]
pub struct Stamped {
    /// The header's stamp, ns since the epoch of the robot's clock.
    pub stamp_ns: i64,
    /// The header's frame id (the parent frame).
    pub frame_id: String,
    /// The child frame (an odometry's or a transform's; empty for a stamped pose).
    pub child: String,
    /// The pose (a transform's translation and rotation).
    pub pose: RosPose,
}

/// The pose-bearing ROS 2 types `localize --poses BAG.mcap` takes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PoseType {
    /// `geometry_msgs/msg/PoseStamped`.
    PoseStamped,
    /// `geometry_msgs/msg/PoseWithCovarianceStamped` (amcl's `/amcl_pose`).
    PoseWithCovarianceStamped,
    /// `nav_msgs/msg/Odometry`.
    Odometry,
    /// `tf2_msgs/msg/TFMessage` (`/tf`, `/tf_static`).
    TfMessage,
}

impl PoseType {
    /// The type of a channel's schema name (`pkg/msg/Type`, or `pkg/Type`), if one of these.
    pub fn of_schema(name: &str) -> Option<PoseType> {
        match name.replace("/msg/", "/").as_str() {
            "geometry_msgs/PoseStamped" => Some(PoseType::PoseStamped),
            "geometry_msgs/PoseWithCovarianceStamped" => Some(PoseType::PoseWithCovarianceStamped),
            "nav_msgs/Odometry" => Some(PoseType::Odometry),
            "tf2_msgs/TFMessage" => Some(PoseType::TfMessage),
            _ => None,
        }
    }

    /// Decodes one message of this type: its poses (one, or a `TFMessage`'s transforms).
    pub fn decode(self, data: &[u8]) -> Result<Vec<Stamped>, CdrError> {
        let mut c = CdrReader::new(data)?;
        match self {
            PoseType::PoseStamped => {
                let (stamp_ns, frame_id) = c.header()?;
                let pose = pose(&mut c)?;
                Ok(vec![Stamped {
                    stamp_ns,
                    frame_id,
                    child: String::new(),
                    pose,
                }])
            }
            PoseType::PoseWithCovarianceStamped => {
                let (stamp_ns, frame_id) = c.header()?;
                let pose = pose(&mut c)?;
                // The covariance (36 float64) follows; not needed.
                Ok(vec![Stamped {
                    stamp_ns,
                    frame_id,
                    child: String::new(),
                    pose,
                }])
            }
            PoseType::Odometry => {
                let (stamp_ns, frame_id) = c.header()?;
                let child = c.string()?;
                let pose = pose(&mut c)?;
                // The pose's covariance and the twist follow; not needed.
                Ok(vec![Stamped {
                    stamp_ns,
                    frame_id,
                    child,
                    pose,
                }])
            }
            PoseType::TfMessage => (0..c.count()?).map(|_| transform(&mut c)).collect(),
        }
    }
}

/// A `geometry_msgs/Pose` (Point, Quaternion).
fn pose(c: &mut CdrReader<'_>) -> Result<RosPose, CdrError> {
    Ok(RosPose {
        position: [c.f64()?, c.f64()?, c.f64()?],
        orientation: [c.f64()?, c.f64()?, c.f64()?, c.f64()?],
    })
}

/// A `geometry_msgs/TransformStamped` (Header, child_frame_id, Transform of a Vector3 and a
/// Quaternion: a pose's layout).
fn transform(c: &mut CdrReader<'_>) -> Result<Stamped, CdrError> {
    let (stamp_ns, frame_id) = c.header()?;
    let child = c.string()?;
    let pose = pose(c)?;
    Ok(Stamped {
        stamp_ns,
        frame_id,
        child,
        pose,
    })
}

/// Why a `TagRead` is not a read.
#[derive(Debug, thiserror::Error)]
pub enum TagReadError {
    /// The CDR did not decode.
    #[error("{0}")]
    Cdr(#[from] CdrError),
    /// A field's value is not one a read may have.
    #[error("{0}")]
    Field(String),
}

/// `llrp_gateway_msgs/msg/TagRead` as a read (NaN and 0, the message's "not sent", become
/// `None`; the reverse of [`super::msgs::tag_read`]).
pub fn tag_read(data: &[u8]) -> Result<Read, TagReadError> {
    let mut c = CdrReader::new(data)?;
    let (stamp_ns, _frame_id) = c.header()?;
    let reader = c.string()?;
    let epc = c.string()?;
    let antenna = c.u16()?;
    let last_seen_ns = c.time()?;
    let phase_rad = c.f64()?;
    let rssi_dbm = c.f64()?;
    let channel_index = c.u16()?;
    let channel_frequency_hz = c.u64()?;
    let doppler_hz = c.f64()?;
    let field = |what: &str, e: String| TagReadError::Field(format!("{what}: {e}"));
    let some = |v: f64| (!v.is_nan()).then_some(v);
    let us = |ns: i64| u64::try_from(ns / 1000).ok();
    Ok(Read {
        epc: Epc::parse(&epc).map_err(|e| field("epc", e.to_string()))?,
        reader: if reader.is_empty() {
            None
        } else {
            Some(ReaderName::parse(&reader).map_err(|e| field("reader", e.to_string()))?)
        },
        antenna,
        t_us: us(stamp_ns).ok_or_else(|| field("header.stamp", "before 1970".into()))?,
        phase_rad: some(phase_rad),
        rssi_dbm: some(rssi_dbm),
        channel_index: (channel_index != 0).then_some(channel_index),
        channel_frequency_hz: (channel_frequency_hz != 0).then_some(channel_frequency_hz),
        doppler_hz: some(doppler_hz),
        antenna_pose: None,
        last_seen_us: us(last_seen_ns).filter(|&t| t != 0),
    })
}

/// A decoded `llrp_gateway_msgs/msg/LlrpFrame`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FrameIn {
    /// When the gateway received it, UTC ns.
    pub received_ns: i64,
    /// The reader's name.
    pub reader: String,
    /// Connection number.
    pub conn: u32,
    /// Which way it went.
    pub dir: Direction,
    /// A whole LLRP frame (not stray bytes).
    pub whole_frame: bool,
    /// The bytes.
    pub data: Vec<u8>,
}

/// `llrp_gateway_msgs/msg/LlrpFrame` (the reverse of [`super::msgs::llrp_frame`]).
pub fn llrp_frame(data: &[u8]) -> Result<FrameIn, CdrError> {
    let mut c = CdrReader::new(data)?;
    let (received_ns, _frame_id) = c.header()?;
    let reader = c.string()?;
    let conn = c.u32()?;
    let dir = if c.u8()? == 0 {
        Direction::ToReader
    } else {
        Direction::FromReader
    };
    Ok(FrameIn {
        received_ns,
        reader,
        conn,
        dir,
        whole_frame: c.bool()?,
        data: c.bytes()?,
    })
}
