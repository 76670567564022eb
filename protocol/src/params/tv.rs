//! TV-encoded parameters (one-byte header, fixed-size value), LLRP 1.0.1 Table 5 and 1.1.

use bytes::{BufMut, BytesMut};

use crate::codec::{Absent, Field, Param, ParamHeader};
use crate::error::{DecodeError, PathSeg};

tv_param!(/// Antenna number, 1-based (TV 1).
    AntennaId, 1, "AntennaID", u16);
tv_param!(/// First time the tag was seen, µs since the Unix epoch (TV 2).
    FirstSeenTimestampUtc, 2, "FirstSeenTimestampUTC", u64);
tv_param!(/// First time the tag was seen, µs since reader boot (TV 3).
    FirstSeenTimestampUptime, 3, "FirstSeenTimestampUptime", u64);
tv_param!(/// Last time the tag was seen, µs since the Unix epoch (TV 4).
    LastSeenTimestampUtc, 4, "LastSeenTimestampUTC", u64);
tv_param!(/// Last time the tag was seen, µs since reader boot (TV 5).
    LastSeenTimestampUptime, 5, "LastSeenTimestampUptime", u64);
tv_param!(/// Peak received signal strength in whole dBm (TV 6).
    PeakRssi, 6, "PeakRSSI", i8);
tv_param!(/// 1-based index into the hop or fixed frequency table (TV 7).
    ChannelIndex, 7, "ChannelIndex", u16);
tv_param!(/// Number of times the tag was seen (TV 8).
    TagSeenCount, 8, "TagSeenCount", u16);
tv_param!(/// ROSpec that produced a report (TV 9).
    RoSpecId, 9, "ROSpecID", u32);
tv_param!(/// InventoryParameterSpec that produced a report (TV 10).
    InventoryParameterSpecId, 10, "InventoryParameterSpecID", u16);
tv_param!(/// Gen2 CRC of the tag (TV 11).
    C1g2Crc, 11, "C1G2-CRC", u16);
tv_param!(/// Gen2 protocol-control word (TV 12).
    C1g2Pc, 12, "C1G2-PC", u16);
tv_param!(/// A 96-bit EPC (TV 13).
    Epc96, 13, "EPC-96", [u8; 12], #[cfg_attr(feature = "serde", serde(with = "crate::raw::hex_bytes"))]);
tv_param!(/// 1-based index of the spec within its ROSpec (TV 14).
    SpecIndex, 14, "SpecIndex", u16);
tv_param!(/// Result of a client-requested OpSpec (TV 15).
    ClientRequestOpSpecResult, 15, "ClientRequestOpSpecResult", u16);
tv_param!(/// AccessSpec that produced a report (TV 16).
    AccessSpecId, 16, "AccessSpecID", u32);
tv_param!(/// OpSpec identifier (TV 17).
    OpSpecId, 17, "OpSpecID", u16);
tv_param!(/// Gen2 XPC word 1, LLRP 1.1 (TV 19).
    C1g2Xpcw1, 19, "C1G2XPCW1", u16);
tv_param!(/// Gen2 XPC word 2, LLRP 1.1 (TV 20).
    C1g2Xpcw2, 20, "C1G2XPCW2", u16);

/// Slot counts of a Gen2 inventory round (TV 18).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct C1g2SingulationDetails {
    /// `NumCollisionSlots` field.
    pub num_collision_slots: u16,
    /// `NumEmptySlots` field.
    pub num_empty_slots: u16,
}

impl Param for C1g2SingulationDetails {
    const NAME: &'static str = "C1G2SingulationDetails";
    const TYPE: u16 = 18;
    fn matches(h: &ParamHeader) -> bool {
        h.tv() && h.ty() == 18
    }
    fn decode_param(i: &[u8], _h: &ParamHeader) -> Result<Self, DecodeError> {
        let wrap = |e: DecodeError| {
            e.within(PathSeg::Param {
                name: Self::NAME,
                ty: 18,
            })
        };
        let (i, num_collision_slots) = u16::decode_field(&i[1..]).map_err(wrap)?;
        let (_, num_empty_slots) = u16::decode_field(i).map_err(wrap)?;
        Ok(C1g2SingulationDetails {
            num_collision_slots,
            num_empty_slots,
        })
    }
    fn encode_param(&self, buf: &mut BytesMut) {
        buf.put_u8(0x80 | 18);
        buf.put_u16(self.num_collision_slots);
        buf.put_u16(self.num_empty_slots);
    }
}

impl Absent for C1g2SingulationDetails {
    fn is_absent(&self) -> bool {
        false
    }
}

#[cfg(feature = "arbitrary")]
impl crate::sample::Sample for C1g2SingulationDetails {
    fn sample(g: &mut crate::sample::Gen) -> Self {
        C1g2SingulationDetails {
            num_collision_slots: crate::sample::Sample::sample(g),
            num_empty_slots: crate::sample::Sample::sample(g),
        }
    }
}
