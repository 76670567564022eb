//! The decoder against bytes written by Python's `rosbags` 0.11.9
//! (`Typestore.serialize_cdr`, types of its ROS 2 Humble store), the messages given in each
//! test's comment; the TagRead and LlrpFrame bytes are those of `cdr_tests.rs`.
//!
//! ```python
//! ts = get_typestore(Stores.ROS2_HUMBLE); T = ts.types
//! ts.serialize_cdr(msg, msg.__msgtype__).tobytes().hex()
//! ```

use super::*;
use crate::record::mcap::ros_in::{self, PoseType, RosPose, Stamped};
use crate::record::Direction;

fn hex(s: &str) -> Vec<u8> {
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).expect("hex"))
        .collect()
}

/// Header(stamp=Time(1700000000, 123456789), frame_id=FRAME) and
/// Pose(Point(1.5, -2.25, 0.5), Quaternion(0, 0, 0.5, 0.8660254037844386)) as decoded.
fn expected(frame: &str, child: &str) -> Stamped {
    Stamped {
        stamp_ns: 1_700_000_000_123_456_789,
        frame_id: frame.into(),
        child: child.into(),
        pose: RosPose {
            position: [1.5, -2.25, 0.5],
            orientation: [0.0, 0.0, 0.5, 0.866_025_403_784_438_6],
        },
    }
}

#[test]
fn a_pose_stamped_decodes_as_rosbags_wrote_it() {
    let b = hex(
        "0001000000f1536515cd5b07040000006d617000000000000000f83f00000000000002c0000000000000\
e03f00000000000000000000000000000000000000000000e03faa4c58e87ab6eb3f",
    );
    assert_eq!(
        PoseType::PoseStamped.decode(&b),
        Ok(vec![expected("map", "")])
    );
}

#[test]
fn a_pose_with_covariance_stamped_decodes_its_pose() {
    // Its covariance is 0, 1, ..., 35.
    let b = hex(
        "0001000000f1536515cd5b07040000006d617000000000000000f83f00000000000002c0000000000000\
e03f00000000000000000000000000000000000000000000e03faa4c58e87ab6eb3f0000000000000000\
000000000000f03f00000000000000400000000000000840000000000000104000000000000014400000\
0000000018400000000000001c4000000000000020400000000000002240000000000000244000000000\
0000264000000000000028400000000000002a400000000000002c400000000000002e40000000000000\
304000000000000031400000000000003240000000000000334000000000000034400000000000003540\
00000000000036400000000000003740000000000000384000000000000039400000000000003a400000\
000000003b400000000000003c400000000000003d400000000000003e400000000000003f4000000000\
00004040000000000080404000000000000041400000000000804140",
    );
    let t = PoseType::PoseWithCovarianceStamped;
    assert_eq!(t.decode(&b), Ok(vec![expected("map", "")]));
}

#[test]
fn an_odometry_decodes_its_frames_and_pose() {
    // header frame "odom", child_frame_id "base_link", the pose with covariance 0..35, a
    // twist of linear (0.1, 0, 0) and angular (0, 0, 0.2) with a zero covariance.
    let b = hex(
        "0001000000f1536515cd5b07050000006f646f6d000000000a000000626173655f6c696e6b0000000000\
0000000000000000f83f00000000000002c0000000000000e03f00000000000000000000000000000000\
000000000000e03faa4c58e87ab6eb3f0000000000000000000000000000f03f00000000000000400000\
0000000008400000000000001040000000000000144000000000000018400000000000001c4000000000\
000020400000000000002240000000000000244000000000000026400000000000002840000000000000\
2a400000000000002c400000000000002e40000000000000304000000000000031400000000000003240\
000000000000334000000000000034400000000000003540000000000000364000000000000037400000\
00000000384000000000000039400000000000003a400000000000003b400000000000003c4000000000\
00003d400000000000003e400000000000003f4000000000000040400000000000804040000000000000\
414000000000008041409a9999999999b93f000000000000000000000000000000000000000000000000\
00000000000000009a9999999999c93f0000000000000000000000000000000000000000000000000000\
000000000000000000000000000000000000000000000000000000000000000000000000000000000000\
000000000000000000000000000000000000000000000000000000000000000000000000000000000000\
000000000000000000000000000000000000000000000000000000000000000000000000000000000000\
000000000000000000000000000000000000000000000000000000000000000000000000000000000000\
000000000000000000000000000000000000000000000000000000000000000000000000000000000000\
000000000000000000000000000000000000000000000000000000000000000000000000000000000000\
00000000000000000000",
    );
    let t = PoseType::Odometry;
    assert_eq!(t.decode(&b), Ok(vec![expected("odom", "base_link")]));
}

#[test]
fn a_tf_message_decodes_every_transform() {
    // TFMessage([TransformStamped(Header(Time(1700000000, 5), "map"), "odom",
    //   Transform(Vector3(1, -2, 0), Quaternion(0, 0, sin 15°, cos 15°))),
    //   TransformStamped(Header(Time(1700000000, 7), "odom"), "base_link",
    //   Transform(Vector3(0.5, 0.25, 0), Quaternion(0, 0, 0, 1)))])
    let b = hex(
        "000100000200000000f1536505000000040000006d617000050000006f646f6d00000000000000000000\
f03f00000000000000c0000000000000000000000000000000000000000000000000900693c17d90d03f\
15bf4847dde8ee3f00f1536507000000050000006f646f6d000000000a000000626173655f6c696e6b00\
000000000000000000000000e03f000000000000d03f0000000000000000000000000000000000000000\
000000000000000000000000000000000000f03f",
    );
    let tfs = PoseType::TfMessage.decode(&b).expect("decodes");
    assert_eq!(tfs.len(), 2);
    assert_eq!(
        (
            tfs[0].stamp_ns,
            tfs[0].frame_id.as_str(),
            tfs[0].child.as_str()
        ),
        (1_700_000_000_000_000_005, "map", "odom")
    );
    assert_eq!(tfs[0].pose.position, [1.0, -2.0, 0.0]);
    assert_eq!(tfs[0].pose.orientation[2], 0.258_819_045_102_520_74);
    assert_eq!(
        (tfs[1].frame_id.as_str(), tfs[1].child.as_str()),
        ("odom", "base_link")
    );
    assert_eq!(tfs[1].pose.position, [0.5, 0.25, 0.0]);
    assert_eq!(tfs[1].pose.orientation, [0.0, 0.0, 0.0, 1.0]);
}

#[test]
fn a_tag_read_decodes_to_the_read_encoded_nan_as_none() {
    // cdr_tests.rs: TagRead(header=Header(stamp=Time(1796150652, 1000), frame_id="s1/antenna_2"),
    //   reader="s1", epc="E2801160", antenna=2, last_seen=Time(0, 0), phase_rad=1.5,
    //   rssi_dbm=nan, channel_index=7, channel_frequency_hz=902750000, doppler_hz=-0.25)
    let b = hex(
        "000100007c150f6be80300000d00000073312f616e74656e6e615f3200000000030000007331000009\
         000000453238303131363000000200000000000000000000000000000000000000f83f000000000000f87f\
         070000000000000030dfce3500000000000000000000d0bf",
    );
    let r = ros_in::tag_read(&b).expect("decodes");
    assert_eq!(r.epc.as_str(), "E2801160");
    assert_eq!(r.reader.as_deref(), Some("s1"));
    assert_eq!((r.antenna, r.t_us), (2, 1_796_150_652_000_001));
    assert_eq!((r.phase_rad, r.rssi_dbm), (Some(1.5), None));
    assert_eq!(
        (r.channel_index, r.channel_frequency_hz),
        (Some(7), Some(902_750_000))
    );
    assert_eq!((r.doppler_hz, r.last_seen_us), (Some(-0.25), None));
}

#[test]
fn an_llrp_frame_decodes_to_its_bytes() {
    // cdr_tests.rs: LlrpFrame(header=Header(stamp=Time(1796150652, 734522000),
    //   frame_id="r_127_0_0_1_38623"), reader="127.0.0.1:38623", connection=1, direction=1,
    //   whole_frame=True, data=043f0000002000000002)
    let b = hex(
        "000100007c150f6b90eac72b12000000725f3132375f305f305f315f3338363233000000100000003132\
         372e302e302e313a33383632330001000000010100000a000000043f0000002000000002",
    );
    let f = ros_in::llrp_frame(&b).expect("decodes");
    assert_eq!(f.received_ns, 1_796_150_652_734_522_000);
    assert_eq!((f.reader.as_str(), f.conn), ("127.0.0.1:38623", 1));
    assert_eq!((f.dir, f.whole_frame), (Direction::FromReader, true));
    assert_eq!(f.data, hex("043f0000002000000002"));
}

#[test]
fn a_big_endian_message_decodes_too() {
    // CDR_BE: 00 00 00 00, then uint16 0x0102 and (aligned to 4) uint32 0x03040506.
    let b = hex("000000000102000003040506");
    let mut c = CdrReader::new(&b).expect("CDR_BE");
    assert_eq!((c.u16(), c.u32()), (Ok(0x0102), Ok(0x0304_0506)));
}

#[test]
fn a_cut_message_or_another_encapsulation_is_refused() {
    let b = hex("000100000a000000616263");
    let mut c = CdrReader::new(&b).expect("CDR_LE");
    assert_eq!(c.string(), Err(CdrError::Short { at: 4, needed: 10 }));
    assert!(matches!(
        CdrReader::new(&hex("00030000")),
        Err(CdrError::Encapsulation(_))
    ));
    let ps = PoseType::PoseStamped.decode(&hex("0001000000f15365"));
    assert!(matches!(ps, Err(CdrError::Short { .. })));
}
