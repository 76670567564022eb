//! The encoder against bytes written by Python's `rosbags` 0.11.9 (`Typestore.serialize_cdr`)
//! for the same messages, its types registered from `ros2/llrp_gateway_msgs/msg/*.msg`
//! (the script is in the test's comment, so the vectors can be made again).
//!
//! ```python
//! ts = get_typestore(Stores.ROS2_HUMBLE); ts.register(get_types_from_msg(text, name)) ...
//! ts.serialize_cdr(msg, msg.__msgtype__).tobytes().hex()
//! ```

use super::*;
use crate::reads::{Epc, Read, ReaderName};
use crate::record::mcap::estimates::{tag_estimate, EstimateItem, EstimateState};
use crate::record::mcap::msgs::{self, FrameMsg};
use crate::record::mcap::scene_msgs::{
    scene_update, Arrow, Cylinder, Entity, Line, LineType, Pose, Solid, Text,
};
use crate::record::Direction;

fn hex(s: &str) -> Vec<u8> {
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).expect("hex"))
        .collect()
}

#[test]
fn an_llrp_frame_encodes_as_rosbags_writes_it() {
    // LlrpFrame(header=Header(stamp=Time(1796150652, 734522000), frame_id="r_127_0_0_1_38623"),
    //   reader="127.0.0.1:38623", connection=1, direction=1, whole_frame=True,
    //   data=043f0000002000000002)
    let rosbags = hex(
        "000100007c150f6b90eac72b12000000725f3132375f305f305f315f3338363233000000100000003132\
         372e302e302e313a33383632330001000000010100000a000000043f0000002000000002",
    );
    let m = FrameMsg {
        received_ns: 1_796_150_652_734_522_000,
        reader: "127.0.0.1:38623",
        frame_id: "r_127_0_0_1_38623",
        conn: 1,
        dir: Direction::FromReader,
        whole_frame: true,
        data: &hex("043f0000002000000002"),
    };
    assert_eq!(msgs::llrp_frame(&mut Cdr::new(), &m), rosbags);
}

#[test]
fn a_tag_read_encodes_as_rosbags_writes_it_nan_for_a_missing_value() {
    // TagRead(header=Header(stamp=Time(1796150652, 1000), frame_id="s1/antenna_2"),
    //   reader="s1", epc="E2801160", antenna=2, last_seen=Time(0, 0), phase_rad=1.5,
    //   rssi_dbm=nan, channel_index=7, channel_frequency_hz=902750000, doppler_hz=-0.25)
    let rosbags = hex(
        "000100007c150f6be80300000d00000073312f616e74656e6e615f3200000000030000007331000009\
         000000453238303131363000000200000000000000000000000000000000000000f83f000000000000f87f\
         070000000000000030dfce3500000000000000000000d0bf",
    );
    let read = Read {
        epc: Epc::parse("E2801160").expect("epc"),
        reader: Some(ReaderName::parse("s1").expect("name")),
        antenna: 2,
        t_us: 1_796_150_652_000_001,
        phase_rad: Some(1.5),
        rssi_dbm: None,
        channel_index: Some(7),
        channel_frequency_hz: Some(902_750_000),
        doppler_hz: Some(-0.25),
        antenna_pose: None,
        last_seen_us: None,
    };
    assert_eq!(
        msgs::tag_read(&mut Cdr::new(), &read, "s1/antenna_2"),
        rosbags
    );
}

#[test]
fn values_align_to_their_size_after_the_encapsulation_header() {
    let b = Cdr::new().u8(1).u16(2).u8(3).u32(4).u8(5).f64(6.0).finish();
    assert_eq!(&b[..4], &[0, 1, 0, 0], "CDR_LE");
    // u8 at 0, u16 at 2, u8 at 4, u32 at 8, u8 at 12, f64 at 16 (offsets after the header).
    assert_eq!(
        &b[4..],
        &hex("010002000300000004000000050000000000000000001840")[..]
    );
}

#[test]
fn a_time_splits_into_seconds_and_nanoseconds_saturating_past_2038() {
    assert_eq!(
        ros_time(1_500_000_000_123_456_789),
        (1_500_000_000, 123_456_789)
    );
    assert_eq!(
        ros_time(u64::MAX),
        (i32::MAX, (u64::MAX % 1_000_000_000) as u32)
    );
}

#[test]
fn a_tag_estimate_encodes_as_rosbags_writes_it() {
    // TagEstimate(header=Header(stamp=Time(1796150652, 1000), frame_id="map"),
    //   epc="E2801160", estimator="relock", state=0, position=Point(1.5, -2.0, 0.5),
    //   covariance=[0.04, 0.01, 0, 0.01, 0.09, 0, 0, 0, 0], pose_sigma_m=nan, samples=42,
    //   reads=43, reads_per_s=12.5, last_seen=Time(1796150652, 2000), reason="not yet")
    let rosbags = hex(
        "000100007c150f6be8030000040000006d61700009000000453238303131363000000000070000007265\
         6c6f636b000000000000000000000000f83f00000000000000c0000000000000e03f7b14ae47e17aa43f\
         7b14ae47e17a843f00000000000000007b14ae47e17a843f0ad7a3703d0ab73f00000000000000000000\
         00000000000000000000000000000000000000000000000000000000f87f2a000000000000002b000000\
         0000000000000000000029407c150f6bd0070000080000006e6f742079657400",
    );
    let e = EstimateItem {
        logged_us: 0,
        epc: "e2801160".into(),
        estimator: "relock".into(),
        state: EstimateState::Converging,
        position: Some([1.5, -2.0, 0.5]),
        covariance: Some([0.04, 0.01, 0.0, 0.01, 0.09, 0.0, 0.0, 0.0, 0.0]),
        pose_sigma_m: None,
        samples: 42,
        newest_phase_us: 1_796_150_652_000_001,
        reads: 43,
        reads_per_s: 12.5,
        last_seen_us: 1_796_150_652_000_002,
        reason: "not yet".into(),
    };
    assert_eq!(tag_estimate(&mut Cdr::new(), &e), rosbags);
}

#[test]
fn a_scene_update_encodes_as_rosbags_writes_it() {
    // SceneUpdate(deletions=[SceneEntityDeletion(Time(1796150652, 500000000), 0,
    //   "estimate/E2")], entities=[SceneEntity(Time(1796150652, 500000000), "map",
    //   "antenna/s1/antenna_1", Duration(0, 0), False, [KeyValuePair("k", "v")], one arrow,
    //   cube, sphere, cylinder, line strip (thickness 2, scale invariant, identity pose) and
    //   billboard text (14, scale invariant) of colour (0.5, 0.25, 1, 0.125), no triangles or
    //   models)]), every pose's orientation (0, 0, 0, 1) but the arrow's (0, 0, 0.5, 0.75).
    let rosbags = hex(
        "00010000010000007c150f6b0065cd1d000000000c000000657374696d6174652f453200010000007c15\
         0f6b0065cd1d040000006d61700015000000616e74656e6e612f73312f616e74656e6e615f3100000000\
         00000000000000000000000001000000020000006b000000020000007600000001000000000000000000\
         00000000f03f000000000000004000000000000008400000000000000000000000000000000000000000\
         0000e03f000000000000e83f000000000000d03fb81e85eb51b89e3f9a9999999999b93f7b14ae47e17a\
         b43f000000000000e03f000000000000d03f000000000000f03f000000000000c03f0100000000000000\
         000000000000f03f000000000000f03f000000000000f03f000000000000000000000000000000000000\
         000000000000000000000000f03f7b14ae47e17aa43f7b14ae47e17aa43f7b14ae47e17aa43f00000000\
         0000e03f000000000000d03f000000000000f03f000000000000c03f0100000000000000000000000000\
         004000000000000000400000000000000040000000000000000000000000000000000000000000000000\
         000000000000f03f000000000000e03f000000000000d03f7b14ae47e17a843f000000000000e03f0000\
         00000000d03f000000000000f03f000000000000c03f0100000000000000000000000000084000000000\
         000008400000000000000840000000000000000000000000000000000000000000000000000000000000\
         f03f000000000000f03f000000000000f03f00000000000000400000000000000000000000000000f03f\
         000000000000e03f000000000000d03f000000000000f03f000000000000c03f01000000000000000000\
         000000000000000000000000000000000000000000000000000000000000000000000000000000000000\
         00000000000000000000f03f000000000000004001000000020000000000000000000000000000000000\
         00000000000000000000000000000000f03f000000000000e03f0000000000000000000000000000e03f\
         000000000000d03f000000000000f03f000000000000c03f000000000000000000000000010000000000\
         00000000f03f0000000000000040cdcccccccccc08400000000000000000000000000000000000000000\
         00000000000000000000f03f01000000000000000000000000002c400100000000000000000000000000\
         e03f000000000000d03f000000000000f03f000000000000c03f030000007331000000000000",
    );
    let color = [0.5, 0.25, 1.0, 0.125];
    let solid = |p: [f64; 3], size: [f64; 3]| Solid {
        pose: Pose::at(p),
        size,
        color,
    };
    let e = Entity {
        id: "antenna/s1/antenna_1".into(),
        metadata: vec![("k".into(), "v".into())],
        arrows: vec![Arrow {
            pose: Pose {
                position: [1.0, 2.0, 3.0],
                orientation: [0.0, 0.0, 0.5, 0.75],
            },
            shaft_length: 0.25,
            shaft_diameter: 0.03,
            head_length: 0.1,
            head_diameter: 0.08,
            color,
        }],
        cubes: vec![solid([1.0; 3], [0.04; 3])],
        spheres: vec![solid([2.0; 3], [0.5, 0.25, 0.01])],
        cylinders: vec![Cylinder {
            pose: Pose::at([3.0; 3]),
            size: [1.0, 1.0, 2.0],
            bottom_scale: 0.0,
            top_scale: 1.0,
            color,
        }],
        lines: vec![Line {
            kind: LineType::Strip,
            thickness_px: 2.0,
            points: vec![[0.0; 3], [1.0, 0.5, 0.0]],
            color,
        }],
        texts: vec![Text {
            position: [1.0, 2.0, 3.1],
            font_px: 14.0,
            color,
            text: "s1".into(),
        }],
    };
    let stamp = 1_796_150_652_500_000_000;
    let got = scene_update(&mut Cdr::new(), stamp, "map", &["estimate/E2".into()], &[e]);
    assert_eq!(got, rosbags);
}

#[test]
fn a_tag_phase_encodes_as_rosbags_writes_it_nan_for_a_missing_rssi() {
    // TagPhase(header=Header(stamp=Time(1796150652, 1000), frame_id="s1/antenna_2"),
    //   reader="s1", epc="E2801160", antenna=2, channel_index=7,
    //   channel_frequency_hz=902750000, phase_rad=1.5,
    //   phase_unwrapped_rad=1.5-2*3.141592653589793*3, rssi_dbm=nan)
    let rosbags = hex(
        "000100007c150f6be80300000d00000073312f616e74656e6e615f32000000000300000073310000\
         090000004532383031313630000002000700000030dfce3500000000000000000000f83fd221337f\
         7c5931c0000000000000f87f",
    );
    let read = Read {
        epc: Epc::parse("E2801160").expect("epc"),
        reader: Some(ReaderName::parse("s1").expect("name")),
        antenna: 2,
        t_us: 1_796_150_652_000_001,
        phase_rad: Some(1.5),
        rssi_dbm: None,
        channel_index: Some(7),
        channel_frequency_hz: Some(902_750_000),
        doppler_hz: Some(-0.25),
        antenna_pose: None,
        last_seen_us: None,
    };
    let unwrapped = 1.5 - 2.0 * std::f64::consts::PI * 3.0;
    assert_eq!(
        msgs::tag_phase(&mut Cdr::new(), &read, "s1/antenna_2", unwrapped),
        rosbags
    );
}
