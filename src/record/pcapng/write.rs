//! Writing a pcapng capture block by block with pcap-parser's serializer: a section header,
//! one interface, then enhanced packet blocks, each written as it comes (little-endian).

use std::borrow::Cow;
use std::io::Write;

use pcap_parser::{
    EnhancedPacketBlock, InterfaceDescriptionBlock, Linktype, OptionCode, PcapNGOption,
    SectionHeaderBlock, ToVec,
};

/// Why a block could not be written.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    /// pcap-parser could not encode the block (it cannot happen with the blocks written here,
    /// whose lengths are all far below the format's limits).
    #[error("encoding a pcapng block: {0}")]
    Encode(String),
    /// The output refused the bytes.
    #[error("{0}")]
    Io(#[from] std::io::Error),
}

/// A pcapng capture being written to `W`.
pub struct PcapNgOut<W: Write> {
    out: W,
}

/// A pcapng option of `code` holding `value` (padded by the serializer).
fn option(code: OptionCode, value: Vec<u8>) -> PcapNGOption<'static> {
    PcapNGOption {
        code,
        // Options are comments and names of a few hundred bytes at most.
        len: u16::try_from(value.len()).unwrap_or(u16::MAX),
        value: Cow::Owned(value),
    }
}

/// A pcapng option holding a UTF-8 string.
pub fn text(code: OptionCode, s: &str) -> PcapNGOption<'static> {
    option(code, s.as_bytes().to_vec())
}

fn encode(block: &mut impl ToVec) -> Result<Vec<u8>, WriteError> {
    block
        .to_vec()
        .map_err(|e| WriteError::Encode(format!("{e:?}")))
}

impl<W: Write> PcapNgOut<W> {
    /// Starts the capture with a section header holding `options`.
    pub fn new(mut out: W, options: Vec<PcapNGOption<'static>>) -> Result<Self, WriteError> {
        let mut shb = SectionHeaderBlock {
            block_type: 0,
            block_len1: 0,
            bom: 0,
            major_version: 1,
            minor_version: 0,
            // Unknown (the section is written as it goes).
            section_len: -1,
            options,
            block_len2: 0,
        };
        out.write_all(&encode(&mut shb)?)?;
        Ok(PcapNgOut { out })
    }

    /// Declares an interface of `linktype` with `options` and time unit 10^-`tsresol` s.
    pub fn interface(
        &mut self,
        linktype: Linktype,
        tsresol: u8,
        mut options: Vec<PcapNGOption<'static>>,
    ) -> Result<(), WriteError> {
        options.push(option(OptionCode::IfTsresol, vec![tsresol]));
        let mut idb = InterfaceDescriptionBlock {
            block_type: 0,
            block_len1: 0,
            linktype,
            reserved: 0,
            snaplen: 0,
            options,
            block_len2: 0,
            if_tsresol: tsresol,
            if_tsoffset: 0,
        };
        self.out.write_all(&encode(&mut idb)?)?;
        Ok(())
    }

    /// Writes one packet of interface 0 at `ticks` (in the interface's time unit) with a
    /// comment.
    pub fn packet(&mut self, ticks: u64, data: &[u8], comment: &str) -> Result<(), WriteError> {
        // The export's packets are at most an Ethernet header and an IPv4 packet long.
        let len = u32::try_from(data.len()).unwrap_or(u32::MAX);
        let mut epb = EnhancedPacketBlock {
            block_type: 0,
            block_len1: 0,
            if_id: 0,
            ts_high: (ticks >> 32) as u32,
            ts_low: ticks as u32,
            caplen: len,
            origlen: len,
            data,
            options: vec![text(OptionCode::Comment, comment)],
            block_len2: 0,
        };
        self.out.write_all(&encode(&mut epb)?)?;
        Ok(())
    }
}
