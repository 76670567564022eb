//! Zero-allocation reading of the tag observations in an RO_ACCESS_REPORT.
//!
//! [`Message::decode`] builds the whole typed tree; a consumer that only wants the reads
//! (a localizer, a recorder's index, a counter) can walk them in place instead:
//! [`tag_reads`] yields one flat [`TagRead`] per TagReportData, borrowing the EPC from the
//! frame. Parameters other than TagReportData, and sub-parameters a `TagRead` has no field
//! for (access results, other vendors' parameters, unknown types), are skipped after their
//! header is checked. On any malformed input the error is the one [`Message::decode`] gives
//! for the same frame, so offsets and parameter paths agree between the two paths.

use crate::codec::{Param, ParamHeader, CUSTOM_TYPE};
use crate::error::{DecodeError, ErrorKind, PathSeg};
use crate::frame::{FrameHeader, HEADER_LEN};
use crate::impinj::{ImpinjPeakRssi, ImpinjRfDopplerFrequency, ImpinjRfPhaseAngle};
use crate::message::{Message, MessageDef, RoAccessReport};
use crate::params::TagReportData;

/// Impinj's IANA private enterprise number.
const IMPINJ: u32 = 25882;

/// One tag observation (one TagReportData), with the EPC borrowed from the frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TagRead<'a> {
    /// EPC bytes (12 for an EPC-96 parameter).
    pub epc: &'a [u8],
    /// Number of meaningful EPC bits.
    pub epc_bits: u16,
    /// ROSpecID (TV 9).
    pub ro_spec_id: Option<u32>,
    /// SpecIndex (TV 14).
    pub spec_index: Option<u16>,
    /// InventoryParameterSpecID (TV 10).
    pub inventory_parameter_spec_id: Option<u16>,
    /// AntennaID (TV 1).
    pub antenna_id: Option<u16>,
    /// PeakRSSI in dBm (TV 6).
    pub peak_rssi: Option<i8>,
    /// ChannelIndex, 1-based into the hop table (TV 7).
    pub channel_index: Option<u16>,
    /// FirstSeenTimestampUTC, microseconds since the Unix epoch (TV 2).
    pub first_seen_utc: Option<u64>,
    /// FirstSeenTimestampUptime, microseconds (TV 3).
    pub first_seen_uptime: Option<u64>,
    /// LastSeenTimestampUTC, microseconds since the Unix epoch (TV 4).
    pub last_seen_utc: Option<u64>,
    /// LastSeenTimestampUptime, microseconds (TV 5).
    pub last_seen_uptime: Option<u64>,
    /// TagSeenCount (TV 8).
    pub tag_seen_count: Option<u16>,
    /// AccessSpecID (TV 16).
    pub access_spec_id: Option<u32>,
    /// ImpinjRFPhaseAngle, 0..4095 for 0..2π (the first, if several).
    pub phase_angle: Option<u16>,
    /// ImpinjPeakRSSI in hundredths of dBm.
    pub impinj_peak_rssi: Option<i16>,
    /// ImpinjRFDopplerFrequency in Hz × 16.
    pub doppler_frequency: Option<i16>,
}

/// Iterator over the [`TagRead`]s of one RO_ACCESS_REPORT frame; see [`tag_reads`].
#[derive(Clone, Debug)]
pub struct TagReads<'a> {
    frame: &'a [u8],
    rest: &'a [u8],
    failed: bool,
}

/// The tag reads of `frame`, which must be one whole RO_ACCESS_REPORT message.
pub fn tag_reads(frame: &[u8]) -> Result<TagReads<'_>, DecodeError> {
    let ok = frame.len() >= HEADER_LEN
        && FrameHeader::peek(frame).is_some_and(|h| {
            h.msg_type == RoAccessReport::TYPE
                && matches!(h.version, 1 | 2)
                && h.length as usize == frame.len()
        });
    if !ok {
        return Err(full_error(frame, 0));
    }
    Ok(TagReads {
        frame,
        rest: &frame[HEADER_LEN..],
        failed: false,
    })
}

/// The error the full decoder reports for `frame` (a plain one at `offset` if it accepts it).
#[cold]
fn full_error(frame: &[u8], offset: usize) -> DecodeError {
    match Message::decode(frame) {
        Err(e) => e,
        Ok(m) => {
            let mut e = DecodeError::at(std::ptr::null(), ErrorKind::Invalid);
            e.offset = offset;
            e.path = vec![PathSeg::Message {
                name: m.body.name(),
                ty: m.body.msg_type(),
            }];
            e
        }
    }
}

impl<'a> TagReads<'a> {
    /// Fails the iteration with the full decoder's error.
    #[cold]
    fn fail(&mut self, at: &[u8]) -> Option<Result<TagRead<'a>, DecodeError>> {
        self.failed = true;
        let offset = at.as_ptr() as usize - self.frame.as_ptr() as usize;
        Some(Err(full_error(self.frame, offset)))
    }
}

impl<'a> Iterator for TagReads<'a> {
    type Item = Result<TagRead<'a>, DecodeError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.failed {
            return None;
        }
        while !self.rest.is_empty() {
            let at = self.rest;
            let Ok(h) = ParamHeader::read(at) else {
                return self.fail(at);
            };
            let (this, rest) = at.split_at(h.size());
            self.rest = rest;
            if !h.tv() && h.ty() == <TagReportData as Param>::TYPE {
                return match read_tag(&this[4..]) {
                    Some(read) => Some(Ok(read)),
                    None => self.fail(at),
                };
            }
        }
        None
    }
}

#[inline(always)]
fn be16(b: &[u8]) -> u16 {
    u16::from_be_bytes([b[0], b[1]])
}

#[inline(always)]
fn be32(b: &[u8]) -> u32 {
    u32::from_be_bytes([b[0], b[1], b[2], b[3]])
}

#[inline(always)]
fn be64(b: &[u8]) -> u64 {
    u64::from_be_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]])
}

/// Reads one TagReportData body; `None` if anything in it is malformed or the EPC is absent.
#[inline]
fn read_tag(mut i: &[u8]) -> Option<TagRead<'_>> {
    let mut t = TagRead::default();
    let mut have_epc = false;
    while !i.is_empty() {
        let h = ParamHeader::read(i).ok()?;
        let (p, rest) = i.split_at(h.size());
        i = rest;
        if h.tv() {
            let v = &p[1..];
            match h.ty() {
                13 => {
                    t.epc = v;
                    t.epc_bits = 96;
                    have_epc = true;
                }
                1 => t.antenna_id = Some(be16(v)),
                2 => t.first_seen_utc = Some(be64(v)),
                3 => t.first_seen_uptime = Some(be64(v)),
                4 => t.last_seen_utc = Some(be64(v)),
                5 => t.last_seen_uptime = Some(be64(v)),
                6 => t.peak_rssi = Some(v[0] as i8),
                7 => t.channel_index = Some(be16(v)),
                8 => t.tag_seen_count = Some(be16(v)),
                9 => t.ro_spec_id = Some(be32(v)),
                10 => t.inventory_parameter_spec_id = Some(be16(v)),
                14 => t.spec_index = Some(be16(v)),
                16 => t.access_spec_id = Some(be32(v)),
                _ => {}
            }
            continue;
        }
        match h.ty() {
            241 => {
                // EPCData: u16 bit count, then ceil(bits / 8) bytes (then, rarely, extras).
                let bits = be16(p.get(4..6)?);
                t.epc = p.get(6..6 + usize::from(bits).div_ceil(8))?;
                t.epc_bits = bits;
                have_epc = true;
            }
            CUSTOM_TYPE if h.vendor() == IMPINJ => {
                let v = &p[12..];
                if h.subtype() == ImpinjRfPhaseAngle::SUBTYPE {
                    t.phase_angle = t.phase_angle.or(Some(be16(v.get(..2)?)));
                } else if h.subtype() == ImpinjPeakRssi::SUBTYPE {
                    t.impinj_peak_rssi = t.impinj_peak_rssi.or(Some(be16(v.get(..2)?) as i16));
                } else if h.subtype() == ImpinjRfDopplerFrequency::SUBTYPE {
                    t.doppler_frequency = t.doppler_frequency.or(Some(be16(v.get(..2)?) as i16));
                }
            }
            _ => {}
        }
    }
    have_epc.then_some(t)
}
