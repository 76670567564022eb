//! Reading a capture file: pcap or pcapng (told apart by their magic number), each packet
//! with its link type and its time in UTC microseconds.

use std::borrow::Cow;

use pcap_file::pcap::PcapParser;
use pcap_file::pcapng::blocks::interface_description::{
    InterfaceDescriptionBlock, InterfaceDescriptionOption,
};
use pcap_file::pcapng::{Block, PcapNgParser};
use pcap_file::{PcapError, TsResolution};

use super::packet::Link;
use super::ImportError;

/// One captured packet.
#[derive(Clone, Debug)]
pub struct Packet<'a> {
    /// 1-based number in the capture (as Wireshark counts).
    pub number: usize,
    /// When it was captured, UTC µs since the Unix epoch.
    pub utc_us: u64,
    /// Its link type: `Ok` if supported, else the pcap link-type number.
    pub link: Result<Link, u32>,
    /// The bytes captured.
    pub data: &'a [u8],
}

/// A capture's packets, and what was tolerated while reading it.
#[derive(Debug, Default)]
pub struct Packets<'a> {
    /// The packets in file order.
    pub packets: Vec<Packet<'a>>,
    /// Problems tolerated (a capture cut inside its last packet).
    pub warnings: Vec<String>,
}

/// The pcapng Section Header Block type, as the file's first four bytes (either byte order).
const PCAPNG_MAGIC: [u8; 4] = [0x0A, 0x0D, 0x0D, 0x0A];

/// Reads every packet of a pcap or pcapng capture held in memory.
pub fn read(data: &[u8]) -> Result<Packets<'_>, ImportError> {
    let magic = data.get(..4).ok_or_else(|| not_a_capture(data))?;
    if magic == PCAPNG_MAGIC {
        read_pcapng(data)
    } else if [
        [0xA1, 0xB2, 0xC3, 0xD4],
        [0xD4, 0xC3, 0xB2, 0xA1],
        [0xA1, 0xB2, 0x3C, 0x4D],
        [0x4D, 0x3C, 0xB2, 0xA1],
    ]
    .iter()
    .any(|m| m == magic)
    {
        read_pcap(data)
    } else {
        Err(not_a_capture(data))
    }
}

fn not_a_capture(data: &[u8]) -> ImportError {
    let start: String = data
        .iter()
        .take(8)
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(" ");
    let hint = if data.first() == Some(&b'{') {
        " (it looks like JSON: an llrp-gateway recording? `import` reads captures, `export` reads recordings)"
    } else {
        ""
    };
    ImportError::NotACapture {
        start: if start.is_empty() {
            "nothing (an empty file)".into()
        } else {
            start
        },
        hint,
    }
}

fn bad(data: &[u8], rest: &[u8], source: PcapError) -> ImportError {
    ImportError::Pcap {
        offset: data.len() - rest.len(),
        source,
    }
}

/// The warning for a capture that ends inside a packet or block (a capture still being
/// written, or killed).
fn cut(data: &[u8], rest: &[u8]) -> String {
    format!(
        "the capture ends inside a packet at byte {} (cut short while written?): its last {} bytes are ignored",
        data.len() - rest.len(),
        rest.len()
    )
}

/// The bytes of a packet parsed from the capture in memory. The parsers of pcap-file borrow
/// from their input slice; an owned copy (which they never make) would read as empty.
fn borrowed(data: Cow<'_, [u8]>) -> &'_ [u8] {
    match data {
        Cow::Borrowed(d) => d,
        Cow::Owned(_) => &[],
    }
}

fn read_pcap(data: &[u8]) -> Result<Packets<'_>, ImportError> {
    let (mut rest, parser) = PcapParser::new(data).map_err(|e| bad(data, data, e))?;
    let header = parser.header();
    let linktype = u32::from(header.datalink);
    let link = Link::from_linktype(linktype).ok_or(linktype);
    let nanos = header.ts_resolution == TsResolution::NanoSecond;
    let mut out = Packets::default();
    while !rest.is_empty() {
        // Raw packets: pcap-file's checked ones refuse a packet longer than the snap length,
        // which a capture made with a small snap length has everywhere; such a packet is
        // skipped as cut short, the capture still read.
        let (next, p) = match parser.next_raw_packet(rest) {
            Ok(x) => x,
            Err(PcapError::IncompleteBuffer) => {
                out.warnings.push(cut(data, rest));
                break;
            }
            Err(e) => return Err(bad(data, rest, e)),
        };
        let frac_us = if nanos { p.ts_frac / 1000 } else { p.ts_frac };
        out.packets.push(Packet {
            number: out.packets.len() + 1,
            utc_us: u64::from(p.ts_sec) * 1_000_000 + u64::from(frac_us),
            link,
            data: borrowed(p.data),
        });
        rest = next;
    }
    Ok(out)
}

/// An interface's time unit as (numerator, denominator) of seconds per tick, and its offset
/// in seconds (pcapng's `if_tsresol`, default 10^-6, and `if_tsoffset`).
fn time_base(idb: &InterfaceDescriptionBlock<'_>) -> Result<(u128, u64), &'static str> {
    let mut ticks_per_s: u128 = 1_000_000;
    let mut offset = 0;
    for o in &idb.options {
        match o {
            InterfaceDescriptionOption::IfTsResol(r) if r & 0x80 == 0 => {
                ticks_per_s = 10u128
                    .checked_pow(u32::from(*r))
                    .filter(|_| *r <= 30)
                    .ok_or("if_tsresol is beyond 10^-30 s")?;
            }
            InterfaceDescriptionOption::IfTsResol(r) => {
                ticks_per_s = 1u128
                    .checked_shl(u32::from(r & 0x7F))
                    .filter(|_| r & 0x7F <= 100)
                    .ok_or("if_tsresol is beyond 2^-100 s")?;
            }
            InterfaceDescriptionOption::IfTsOffset(s) => offset = *s,
            _ => {}
        }
    }
    Ok((ticks_per_s, offset))
}

fn read_pcapng(data: &[u8]) -> Result<Packets<'_>, ImportError> {
    let (mut rest, mut parser) = PcapNgParser::new(data).map_err(|e| bad(data, data, e))?;
    let mut out = Packets::default();
    let mut last_us = 0;
    while !rest.is_empty() {
        let (next, block) = match parser.next_block(rest) {
            Ok(x) => x,
            Err(PcapError::IncompleteBuffer) => {
                out.warnings.push(cut(data, rest));
                break;
            }
            Err(e) => return Err(bad(data, rest, e)),
        };
        // (interface, raw timestamp in the interface's ticks, data, original length)
        let (interface, ticks, bytes): (u32, Option<u128>, &[u8]) = match block {
            // pcap-file reports the raw timestamp as nanoseconds whatever the unit.
            Block::EnhancedPacket(p) => (
                p.interface_id,
                Some(p.timestamp.as_nanos()),
                borrowed(p.data),
            ),
            Block::Packet(p) => (
                u32::from(p.interface_id),
                Some(u128::from(p.timestamp)),
                borrowed(p.data),
            ),
            Block::SimplePacket(p) => {
                let d = borrowed(p.data);
                (0, None, &d[..(p.original_len as usize).min(d.len())])
            }
            _ => {
                rest = next;
                continue;
            }
        };
        let Some(idb) = parser.interfaces().get(interface as usize) else {
            return Err(bad(data, rest, PcapError::InvalidInterfaceId(interface)));
        };
        let linktype = u32::from(idb.linktype);
        let utc_us = match ticks {
            Some(t) => {
                let (per_s, offset) =
                    time_base(idb).map_err(|e| bad(data, rest, PcapError::InvalidField(e)))?;
                let us = t.saturating_mul(1_000_000) / per_s;
                u64::try_from(us)
                    .unwrap_or(u64::MAX)
                    .saturating_add(offset.saturating_mul(1_000_000))
            }
            // A Simple Packet Block has no time: that of the packet before it.
            None => last_us,
        };
        last_us = utc_us;
        out.packets.push(Packet {
            number: out.packets.len() + 1,
            utc_us,
            link: Link::from_linktype(linktype).ok_or(linktype),
            data: bytes,
        });
        rest = next;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A little-endian pcap with `magic`, snap length 60 and one packet cut to 60 bytes of 100.
    fn pcap(magic: [u8; 4], frac: u32) -> Vec<u8> {
        let mut p = magic.to_vec();
        p.extend_from_slice(&[2, 0, 4, 0]);
        p.extend_from_slice(&[0; 8]);
        p.extend_from_slice(&60u32.to_le_bytes());
        p.extend_from_slice(&1u32.to_le_bytes());
        p.extend_from_slice(&1_700_000_000u32.to_le_bytes());
        p.extend_from_slice(&frac.to_le_bytes());
        p.extend_from_slice(&60u32.to_le_bytes());
        p.extend_from_slice(&100u32.to_le_bytes());
        p.extend_from_slice(&[0xAB; 60]);
        p
    }

    #[test]
    fn pcap_in_micro_and_nanoseconds_with_packets_cut_by_the_snap_length() {
        for (magic, frac) in [
            ([0xD4, 0xC3, 0xB2, 0xA1], 123_456),
            ([0x4D, 0x3C, 0xB2, 0xA1], 123_456_789),
        ] {
            let data = pcap(magic, frac);
            let read = read(&data).expect("reads");
            assert!(read.warnings.is_empty(), "{:?}", read.warnings);
            let [p] = &read.packets[..] else {
                panic!("one packet: {:?}", read.packets)
            };
            assert_eq!(p.utc_us, 1_700_000_000_123_456);
            assert_eq!(
                (p.link, p.data.len(), p.number),
                (Ok(Link::Ethernet), 60, 1)
            );
        }
    }
}
