//! The message types of llrp-gateway's MCAP files: their ROS 2 names, their `.msg`
//! definitions as MCAP's `ros2msg` schema encoding wants them (the type's own definition, then
//! each type it uses after a line of 80 `=` and `MSG: NAME`), and their CDR encoders.
//!
//! The RFID types are the package `ros2/llrp_gateway_msgs` of this repository (its `.msg`
//! files are included here, so the schema in a file is the published definition). Foxglove's
//! log is its well-known schema in its ROS 2 form, `foxglove_msgs/msg/Log` (the field order of
//! the foxglove_msgs package of foxglove/schemas), which Foxglove's Log panel shows.

use super::cdr::Cdr;
use super::{geo, scene_msgs};
use crate::reads::Read;
use crate::record::Direction;

/// A message type: its ROS 2 name and its `ros2msg` schema text.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MsgType {
    /// `llrp_gateway_msgs/msg/LlrpFrame`.
    LlrpFrame,
    /// `llrp_gateway_msgs/msg/TagRead`.
    TagRead,
    /// `llrp_gateway_msgs/msg/TagPhase`.
    TagPhase,
    /// `llrp_gateway_msgs/msg/ReaderEvent`.
    ReaderEvent,
    /// `foxglove_msgs/msg/Log`.
    Log,
    /// `foxglove_msgs/msg/PoseInFrame`.
    PoseInFrame,
    /// `tf2_msgs/msg/TFMessage`.
    TfMessage,
    /// `llrp_gateway_msgs/msg/TagPosition`.
    TagPosition,
    /// `llrp_gateway_msgs/msg/TagEstimate`.
    TagEstimate,
    /// `foxglove_msgs/msg/SceneUpdate`.
    SceneUpdate,
}

const TIME: (&str, &str) = ("builtin_interfaces/msg/Time", "int32 sec\nuint32 nanosec\n");
const HEADER: (&str, &str) = (
    "std_msgs/msg/Header",
    "builtin_interfaces/Time stamp\nstring frame_id\n",
);
const LOG: &str = "\
# foxglove_msgs/msg/Log: Foxglove's well-known Log schema in its ROS 2 form.
builtin_interfaces/Time timestamp
uint8 UNKNOWN=0
uint8 DEBUG=1
uint8 INFO=2
uint8 WARNING=3
uint8 ERROR=4
uint8 FATAL=5
uint8 level
string message
string name
string file
uint32 line
";

impl MsgType {
    /// Every type, in the order the schemas are written.
    pub const ALL: [MsgType; 10] = [
        MsgType::LlrpFrame,
        MsgType::TagRead,
        MsgType::TagPhase,
        MsgType::ReaderEvent,
        MsgType::Log,
        MsgType::PoseInFrame,
        MsgType::TfMessage,
        MsgType::TagPosition,
        MsgType::TagEstimate,
        MsgType::SceneUpdate,
    ];

    /// The ROS 2 type name (the MCAP schema's name).
    pub fn name(self) -> &'static str {
        match self {
            MsgType::LlrpFrame => "llrp_gateway_msgs/msg/LlrpFrame",
            MsgType::TagRead => "llrp_gateway_msgs/msg/TagRead",
            MsgType::TagPhase => "llrp_gateway_msgs/msg/TagPhase",
            MsgType::ReaderEvent => "llrp_gateway_msgs/msg/ReaderEvent",
            MsgType::Log => "foxglove_msgs/msg/Log",
            MsgType::PoseInFrame => "foxglove_msgs/msg/PoseInFrame",
            MsgType::TfMessage => "tf2_msgs/msg/TFMessage",
            MsgType::TagPosition => "llrp_gateway_msgs/msg/TagPosition",
            MsgType::TagEstimate => "llrp_gateway_msgs/msg/TagEstimate",
            MsgType::SceneUpdate => "foxglove_msgs/msg/SceneUpdate",
        }
    }

    /// Its own `.msg` text.
    fn own(self) -> &'static str {
        match self {
            MsgType::LlrpFrame => {
                include_str!("../../../ros2/llrp_gateway_msgs/msg/LlrpFrame.msg")
            }
            MsgType::TagRead => include_str!("../../../ros2/llrp_gateway_msgs/msg/TagRead.msg"),
            MsgType::TagPhase => {
                include_str!("../../../ros2/llrp_gateway_msgs/msg/TagPhase.msg")
            }
            MsgType::ReaderEvent => {
                include_str!("../../../ros2/llrp_gateway_msgs/msg/ReaderEvent.msg")
            }
            MsgType::Log => LOG,
            MsgType::PoseInFrame => geo::POSE_IN_FRAME,
            MsgType::TfMessage => geo::TF_MESSAGE,
            MsgType::TagPosition => {
                include_str!("../../../ros2/llrp_gateway_msgs/msg/TagPosition.msg")
            }
            MsgType::TagEstimate => {
                include_str!("../../../ros2/llrp_gateway_msgs/msg/TagEstimate.msg")
            }
            MsgType::SceneUpdate => scene_msgs::SCENE_UPDATE,
        }
    }

    /// The types it uses, each once, in the order of the schema text.
    fn dependencies(self) -> &'static [(&'static str, &'static str)] {
        match self {
            MsgType::LlrpFrame | MsgType::TagRead | MsgType::TagPhase | MsgType::ReaderEvent => {
                &[HEADER, TIME]
            }
            MsgType::Log => &[TIME],
            MsgType::PoseInFrame => &[TIME, geo::POSE, geo::POINT, geo::QUATERNION],
            MsgType::TfMessage => &[
                geo::TRANSFORM_STAMPED,
                HEADER,
                TIME,
                geo::TRANSFORM,
                geo::VECTOR3,
                geo::QUATERNION,
            ],
            MsgType::TagPosition => &[HEADER, TIME, geo::POINT],
            MsgType::TagEstimate => &[HEADER, TIME, geo::POINT],
            MsgType::SceneUpdate => &[
                scene_msgs::SCENE_ENTITY_DELETION,
                TIME,
                scene_msgs::SCENE_ENTITY,
                scene_msgs::DURATION,
                scene_msgs::KEY_VALUE_PAIR,
                scene_msgs::ARROW,
                geo::POSE,
                geo::POINT,
                geo::QUATERNION,
                scene_msgs::COLOR,
                scene_msgs::CUBE,
                geo::VECTOR3,
                scene_msgs::SPHERE,
                scene_msgs::CYLINDER,
                scene_msgs::LINE,
                scene_msgs::TRIANGLES,
                scene_msgs::TEXT,
                scene_msgs::MODEL,
            ],
        }
    }

    /// The MCAP `ros2msg` schema data: its definition, then each dependency's after the
    /// delimiter (MCAP's registry, "ros2msg Data Format").
    pub fn schema(self) -> String {
        let mut text = self.own().to_string();
        for (name, definition) in self.dependencies() {
            if !text.ends_with('\n') {
                text.push('\n');
            }
            text.push_str(&"=".repeat(80));
            text.push_str("\nMSG: ");
            text.push_str(name);
            text.push('\n');
            text.push_str(definition);
        }
        text
    }
}

/// `NaN` for a value the reader did not send (the message set's convention for floats).
fn or_nan(v: Option<f64>) -> f64 {
    v.unwrap_or(f64::NAN)
}

/// One frame (or non-frame bytes) of one connection and direction.
#[derive(Clone, Copy, Debug)]
pub struct FrameMsg<'a> {
    /// When the gateway received it, UTC ns.
    pub received_ns: u64,
    /// The reader's name.
    pub reader: &'a str,
    /// The reader's frame id.
    pub frame_id: &'a str,
    /// Connection number.
    pub conn: u32,
    /// Which way it went.
    pub dir: Direction,
    /// A whole LLRP frame (not stray bytes).
    pub whole_frame: bool,
    /// The bytes.
    pub data: &'a [u8],
}

/// `llrp_gateway_msgs/msg/LlrpFrame`.
pub fn llrp_frame(cdr: &mut Cdr, m: &FrameMsg<'_>) -> Vec<u8> {
    let direction = match m.dir {
        Direction::ToReader => 0,
        Direction::FromReader => 1,
    };
    cdr.header(m.received_ns, m.frame_id)
        .string(m.reader)
        .u32(m.conn)
        .u8(direction)
        .bool(m.whole_frame)
        .bytes(m.data)
        .finish()
}

/// `llrp_gateway_msgs/msg/TagRead` of a read whose antenna frame is `frame_id`.
pub fn tag_read(cdr: &mut Cdr, r: &Read, frame_id: &str) -> Vec<u8> {
    cdr.header(r.t_us.saturating_mul(1000), frame_id)
        .string(r.reader.as_deref().unwrap_or(""))
        .string(r.epc.as_str())
        .u16(r.antenna)
        .time(r.last_seen_us.unwrap_or(0).saturating_mul(1000))
        .f64(or_nan(r.phase_rad))
        .f64(or_nan(r.rssi_dbm))
        .u16(r.channel_index.unwrap_or(0))
        .u64(r.channel_frequency_hz.unwrap_or(0))
        .f64(or_nan(r.doppler_hz))
        .finish()
}

/// `llrp_gateway_msgs/msg/TagPhase` of a read with a phase, whose antenna frame is
/// `frame_id`, its phase unwrapped along its stream to `unwrapped_rad`.
pub fn tag_phase(cdr: &mut Cdr, r: &Read, frame_id: &str, unwrapped_rad: f64) -> Vec<u8> {
    cdr.header(r.t_us.saturating_mul(1000), frame_id)
        .string(r.reader.as_deref().unwrap_or(""))
        .string(r.epc.as_str())
        .u16(r.antenna)
        .u16(r.channel_index.unwrap_or(0))
        .u64(r.channel_frequency_hz.unwrap_or(0))
        .f64(or_nan(r.phase_rad))
        .f64(unwrapped_rad)
        .f64(or_nan(r.rssi_dbm))
        .finish()
}

/// One reader event.
#[derive(Clone, Copy, Debug)]
pub struct EventMsg<'a> {
    /// The event's time (the reader's, else the gateway's), UTC ns.
    pub stamp_ns: u64,
    /// The reader's name.
    pub reader: &'a str,
    /// The reader's frame id.
    pub frame_id: &'a str,
    /// Connection number.
    pub conn: u32,
    /// `connect`, `disconnect` or `notification`.
    pub kind: &'a str,
    /// In words, or the notification as JSON.
    pub detail: &'a str,
}

/// `llrp_gateway_msgs/msg/ReaderEvent`.
pub fn reader_event(cdr: &mut Cdr, e: &EventMsg<'_>) -> Vec<u8> {
    cdr.header(e.stamp_ns, e.frame_id)
        .string(e.reader)
        .u32(e.conn)
        .string(e.kind)
        .string(e.detail)
        .finish()
}

/// `foxglove_msgs/msg/Log` at INFO level of an event, named after its reader.
pub fn log(cdr: &mut Cdr, e: &EventMsg<'_>) -> Vec<u8> {
    const INFO: u8 = 2;
    let message = format!("connection {}: {}: {}", e.conn, e.kind, e.detail);
    cdr.time(e.stamp_ns)
        .u8(INFO)
        .string(&message)
        .string(e.reader)
        .string("")
        .u32(0)
        .finish()
}
