//! Typed LLRP parameters, grouped by what they are for.

mod access;
mod capabilities;
mod config;
mod events;
mod report;
mod rospec;
mod status;
mod tv;

pub use access::*;
pub use capabilities::*;
pub use config::*;
pub use events::*;
pub use report::*;
pub use rospec::*;
pub use status::*;
pub use tv::*;

pub use crate::impinj::*;

use bytes::{BufMut, BytesMut};

use crate::codec::{Absent, Param, ParamHeader, CUSTOM_TYPE};
use crate::error::DecodeError;
use crate::raw::RawParam;

/// Every TLV type the codec decodes into a typed parameter (sorted).
pub const KNOWN_TLV_TYPES: &[u16] = &[
    128, 129, 137, 139, 140, 141, 142, 143, 144, 145, 146, 147, 148, 149, 177, 178, 179, 180, 181,
    182, 183, 184, 185, 186, 187, 188, 207, 208, 209, 210, 211, 217, 218, 219, 220, 221, 222, 223,
    224, 225, 226, 237, 238, 239, 240, 241, 242, 243, 244, 245, 246, 247, 248, 249, 250, 251, 252,
    253, 254, 255, 256, 257, 287, 288, 289, 327, 328, 329, 330, 331, 332, 333, 334, 335, 336, 337,
    338, 339, 341, 342, 343, 344, 345, 346, 347, 348, 349, 350, 351, 352, 353, 354, 1023,
];

/// Whether the codec has a typed form for TLV type `ty` (1023, Custom, included).
pub fn is_known_tlv(ty: u16) -> bool {
    KNOWN_TLV_TYPES.binary_search(&ty).is_ok()
}

llrp_choice! {
    no_sample
    /// A vendor (Custom, TLV 1023) parameter: a typed Impinj one, or any other kept raw.
    pub enum Custom "Custom" {
        ImpinjRequestedData(ImpinjRequestedData),
        ImpinjSubRegulatoryRegion(ImpinjSubRegulatoryRegion),
        ImpinjInventorySearchMode(ImpinjInventorySearchMode),
        ImpinjFixedFrequencyList(ImpinjFixedFrequencyList),
        ImpinjReducedPowerFrequencyList(ImpinjReducedPowerFrequencyList),
        ImpinjLowDutyCycle(ImpinjLowDutyCycle),
        ImpinjDetailedVersion(Box<ImpinjDetailedVersion>),
        ImpinjFrequencyCapabilities(ImpinjFrequencyCapabilities),
        ImpinjReaderTemperature(ImpinjReaderTemperature),
        ImpinjTagReportContentSelector(Box<ImpinjTagReportContentSelector>),
        ImpinjEnableSerializedTid(ImpinjEnableSerializedTid),
        ImpinjEnableRfPhaseAngle(ImpinjEnableRfPhaseAngle),
        ImpinjEnablePeakRssi(ImpinjEnablePeakRssi),
        ImpinjEnableGpsCoordinates(ImpinjEnableGpsCoordinates),
        ImpinjEnableOptimizedRead(Box<ImpinjEnableOptimizedRead>),
        ImpinjEnableRfDopplerFrequency(ImpinjEnableRfDopplerFrequency),
        ImpinjSerializedTid(ImpinjSerializedTid),
        ImpinjRfPhaseAngle(ImpinjRfPhaseAngle),
        ImpinjPeakRssi(ImpinjPeakRssi),
        ImpinjRfDopplerFrequency(ImpinjRfDopplerFrequency),
        Other(RawCustom),
    }
}

/// A Custom parameter the codec does not type, kept byte for byte.
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(transparent))]
pub struct RawCustom(pub RawParam);

impl Param for RawCustom {
    const NAME: &'static str = "Custom";
    const TYPE: u16 = CUSTOM_TYPE;
    fn matches(h: &ParamHeader) -> bool {
        !h.tv() && h.ty() == CUSTOM_TYPE
    }
    fn decode_param(i: &[u8], _h: &ParamHeader) -> Result<Self, DecodeError> {
        Ok(RawCustom(RawParam::new(i.to_vec())))
    }
    fn encode_param(&self, buf: &mut BytesMut) {
        buf.put_slice(&self.0.bytes);
    }
}

impl Absent for RawCustom {
    fn is_absent(&self) -> bool {
        false
    }
}

#[cfg(feature = "arbitrary")]
impl crate::sample::Sample for RawCustom {
    fn sample(g: &mut crate::sample::Gen) -> Self {
        RawCustom(g.raw_custom())
    }
}

/// Random Custom parameters avoid the Impinj selector's own sub-parameters: after the
/// selector's optional slots, such a parameter in its Custom list would be read back into
/// the slot (an ambiguity of the format, not of the codec).
#[cfg(feature = "arbitrary")]
impl crate::sample::Sample for Custom {
    fn sample(g: &mut crate::sample::Gen) -> Self {
        match g.index(12) {
            0 => Custom::ImpinjRequestedData(g.any()),
            1 => Custom::ImpinjSubRegulatoryRegion(g.any()),
            2 => Custom::ImpinjInventorySearchMode(g.any()),
            3 => Custom::ImpinjFixedFrequencyList(g.any()),
            4 => Custom::ImpinjDetailedVersion(g.any()),
            5 => Custom::ImpinjFrequencyCapabilities(g.any()),
            6 => Custom::ImpinjTagReportContentSelector(g.any()),
            7 => Custom::ImpinjRfPhaseAngle(g.any()),
            8 => Custom::ImpinjPeakRssi(g.any()),
            9 => Custom::ImpinjRfDopplerFrequency(g.any()),
            10 => Custom::ImpinjSerializedTid(g.any()),
            _ => Custom::Other(g.any()),
        }
    }
}

impl TagReportData {
    /// The EPC as bytes, whichever form it was reported in.
    pub fn epc_bytes(&self) -> &[u8] {
        match &self.epc {
            Epc::Epc96(e) => &e.0,
            Epc::EpcData(d) => &d.epc.bytes,
        }
    }

    /// Impinj RF phase angle (raw 0..4095), if reported.
    pub fn impinj_phase_angle(&self) -> Option<u16> {
        self.custom.iter().find_map(|c| match c {
            Custom::ImpinjRfPhaseAngle(p) => Some(p.phase_angle),
            _ => None,
        })
    }

    /// Impinj peak RSSI (hundredths of dBm), if reported.
    pub fn impinj_peak_rssi(&self) -> Option<i16> {
        self.custom.iter().find_map(|c| match c {
            Custom::ImpinjPeakRssi(p) => Some(p.rssi),
            _ => None,
        })
    }

    /// Impinj Doppler frequency (raw, Hz × 16), if reported.
    pub fn impinj_doppler(&self) -> Option<i16> {
        self.custom.iter().find_map(|c| match c {
            Custom::ImpinjRfDopplerFrequency(p) => Some(p.doppler_frequency),
            _ => None,
        })
    }
}
