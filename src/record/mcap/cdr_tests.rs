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
use crate::record::mcap::msgs::{self, FrameMsg};
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
