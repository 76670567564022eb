//! What each block of a capture gives: the legacy pcap header and records; pcapng's section
//! headers, interfaces, and enhanced, simple and obsolete packet blocks.

use pcap_parser::pcapng::UnknownBlock;
use pcap_parser::traits::PcapNGPacketBlock;
use pcap_parser::Linktype;

use super::*;

/// The obsolete Packet Block's type (pcapng's block type 2).
const PACKET_BLOCK: u32 = 2;

fn link_of(linktype: Linktype) -> Result<Link, u32> {
    let number = linktype.0 as u32;
    Link::from_linktype(number).ok_or(number)
}

impl State {
    /// Takes one block: a packet goes to `each`, the others set what follows.
    pub(super) fn block(
        &mut self,
        block: PcapBlockOwned<'_>,
        each: &mut impl FnMut(&Packet<'_>) -> Result<(), ImportError>,
    ) -> Result<(), ImportError> {
        match block {
            PcapBlockOwned::LegacyHeader(h) => {
                self.legacy = Some((link_of(h.network), h.is_nanosecond_precision()));
            }
            PcapBlockOwned::Legacy(p) => {
                // pcap-parser hands the file header over before any record.
                let (link, nanos) = self.legacy.unwrap_or((Err(0), false));
                let frac_us = if nanos { p.ts_usec / 1000 } else { p.ts_usec };
                let utc_us = u64::from(p.ts_sec) * 1_000_000 + u64::from(frac_us);
                self.emit(utc_us, link, p.data, p.caplen < p.origlen, each)?;
            }
            PcapBlockOwned::NG(b) => self.ng(b, each)?,
        }
        Ok(())
    }

    fn ng(
        &mut self,
        b: Block<'_>,
        each: &mut impl FnMut(&Packet<'_>) -> Result<(), ImportError>,
    ) -> Result<(), ImportError> {
        match b {
            Block::SectionHeader(shb) => {
                self.interfaces.clear();
                self.big_endian = shb.big_endian();
            }
            Block::InterfaceDescription(idb) => self.interfaces.push(Interface {
                link: link_of(idb.linktype),
                ticks_per_s: idb.ts_resolution(),
                offset_s: idb.ts_offset(),
            }),
            Block::EnhancedPacket(p) => {
                let iface = self.interface(p.if_id)?;
                let ticks = (u64::from(p.ts_high) << 32) | u64::from(p.ts_low);
                let utc_us = self.time(&iface, ticks)?;
                let data = p.packet_data();
                self.emit(utc_us, iface.link, data, p.caplen < p.origlen, each)?;
            }
            Block::SimplePacket(p) => {
                // No time: that of the packet before it.
                let iface = self.interface(0)?;
                let data = p.packet_data();
                let cut = (data.len() as u64) < u64::from(p.origlen);
                self.emit(self.last_us, iface.link, data, cut, each)?;
            }
            Block::Unknown(u)
                if u.block_type == PACKET_BLOCK || u.block_type == PACKET_BLOCK.swap_bytes() =>
            {
                self.obsolete(&u, each)?;
            }
            _ => {}
        }
        Ok(())
    }

    /// The obsolete Packet Block: interface (16 bits), drops (16), time (64), captured and
    /// original lengths (32 each), the data.
    fn obsolete(
        &mut self,
        u: &UnknownBlock<'_>,
        each: &mut impl FnMut(&Packet<'_>) -> Result<(), ImportError>,
    ) -> Result<(), ImportError> {
        let d = u.data;
        let big = self.big_endian;
        let u32_at = |at: usize| {
            d.get(at..at + 4).map(|b| {
                let b = [b[0], b[1], b[2], b[3]];
                if big {
                    u32::from_be_bytes(b)
                } else {
                    u32::from_le_bytes(b)
                }
            })
        };
        let bad = || self.bad_packet("an obsolete Packet Block shorter than its fields".into());
        let (Some(first), Some(high), Some(low), Some(caplen), Some(origlen)) =
            (u32_at(0), u32_at(4), u32_at(8), u32_at(12), u32_at(16))
        else {
            return Err(bad());
        };
        let interface = if big { first >> 16 } else { first & 0xFFFF };
        let data = d.get(20..20 + caplen as usize).ok_or_else(bad)?;
        let iface = self.interface(interface)?;
        let utc_us = self.time(&iface, (u64::from(high) << 32) | u64::from(low))?;
        self.emit(utc_us, iface.link, data, caplen < origlen, each)
    }

    /// The interface a packet names.
    fn interface(&self, id: u32) -> Result<Interface, ImportError> {
        self.interfaces.get(id as usize).copied().ok_or_else(|| {
            self.bad_packet(format!(
                "it names interface {id}, and the section declares {}",
                self.interfaces.len()
            ))
        })
    }

    /// A packet's time in UTC µs from its ticks in the interface's unit.
    fn time(&self, iface: &Interface, ticks: u64) -> Result<u64, ImportError> {
        let per_s = iface.ticks_per_s.ok_or_else(|| {
            self.bad_packet("its interface's if_tsresol is finer than 10^-19 s or 2^-63 s".into())
        })?;
        let us = u128::from(ticks) * 1_000_000 / u128::from(per_s);
        let us = u64::try_from(us).unwrap_or(u64::MAX);
        let offset_us = iface.offset_s.unsigned_abs().saturating_mul(1_000_000);
        Ok(if iface.offset_s >= 0 {
            us.saturating_add(offset_us)
        } else {
            us.saturating_sub(offset_us)
        })
    }

    /// The error for the packet being read.
    fn bad_packet(&self, reason: String) -> ImportError {
        ImportError::Packet {
            number: self.packets + 1,
            reason,
        }
    }

    fn emit(
        &mut self,
        utc_us: u64,
        link: Result<Link, u32>,
        data: &[u8],
        cut: bool,
        each: &mut impl FnMut(&Packet<'_>) -> Result<(), ImportError>,
    ) -> Result<(), ImportError> {
        self.packets += 1;
        self.last_us = utc_us;
        each(&Packet {
            number: self.packets,
            utc_us,
            link,
            data,
            cut,
        })
    }
}
