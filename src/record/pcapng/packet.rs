//! Ethernet, IPv4/IPv6 and TCP with etherparse: building the packets of an export (its
//! packet builder fills in the lengths and the IPv4 and TCP checksums) and taking captured
//! packets apart down to their TCP segment (its lax slicing, which takes what captures on
//! the sending host hold: an IPv4 total length of 0 under TCP segmentation offload, IPv6
//! extension headers, the Authentication Header among them, and IP fragments).

use std::net::{IpAddr, Ipv4Addr, SocketAddr};

use etherparse::err::packet::SliceError;
use etherparse::{
    ip_number, EtherType, IpFragOffset, IpHeaders, Ipv4Header, Ipv6ExtensionSlice,
    LaxIpPayloadSlice, LaxNetSlice, LaxSlicedPacket, PacketBuilder, TcpHeader, TcpOptionElement,
    TcpSlice, TransportSlice,
};

/// TCP flag FIN.
pub const FIN: u8 = 0x01;
/// TCP flag SYN.
pub const SYN: u8 = 0x02;
/// TCP flag RST.
pub const RST: u8 = 0x04;
/// TCP flag PSH.
pub const PSH: u8 = 0x08;
/// TCP flag ACK.
pub const ACK: u8 = 0x10;

/// One TCP segment of an export, from `src` to `dst`.
#[derive(Clone, Debug)]
pub struct OutSegment<'a> {
    /// Sender.
    pub src: (Ipv4Addr, u16),
    /// Receiver.
    pub dst: (Ipv4Addr, u16),
    /// Sequence number.
    pub seq: u32,
    /// Acknowledgement number (sent with ACK set).
    pub ack: u32,
    /// Flags (`SYN | ACK`, …).
    pub flags: u8,
    /// The MSS and window-scale options to announce (SYN segments only).
    pub syn_options: Option<(u16, u8)>,
    /// Receive window.
    pub window: u16,
    /// IPv4 identification.
    pub ip_id: u16,
    /// The payload.
    pub payload: &'a [u8],
}

/// Why an export's packet cannot be built: a payload too large for one IPv4 packet.
#[derive(Debug, thiserror::Error)]
#[error("a TCP segment of {0} bytes does not fit in an IPv4 packet")]
pub struct TooLarge(pub usize);

/// An Ethernet frame holding `seg` in IPv4 (DF, TTL 64) and TCP, lengths and checksums filled
/// in by etherparse's packet builder. Both MAC addresses are zero, as on Linux's loopback.
pub fn ethernet_ipv4_tcp(seg: &OutSegment<'_>) -> Result<Vec<u8>, TooLarge> {
    let too_large = |_| TooLarge(seg.payload.len());
    // The builder sets the payload length, the protocol and the header checksum.
    let mut ip = Ipv4Header::new(
        0,
        64,
        ip_number::TCP,
        seg.src.0.octets(),
        seg.dst.0.octets(),
    )
    .map_err(too_large)?;
    ip.identification = seg.ip_id;
    ip.dont_fragment = true;
    let mut tcp = TcpHeader::new(seg.src.1, seg.dst.1, seg.seq, seg.window);
    tcp.fin = seg.flags & FIN != 0;
    tcp.syn = seg.flags & SYN != 0;
    tcp.rst = seg.flags & RST != 0;
    tcp.psh = seg.flags & PSH != 0;
    tcp.ack = seg.flags & ACK != 0;
    if tcp.ack {
        tcp.acknowledgment_number = seg.ack;
    }
    if let Some((mss, shift)) = seg.syn_options {
        // MSS (4 bytes), NOP, window scale (3 bytes): 8 bytes, within the 40 TCP allows.
        tcp.set_options(&[
            TcpOptionElement::MaximumSegmentSize(mss),
            TcpOptionElement::Noop,
            TcpOptionElement::WindowScale(shift),
        ])
        .map_err(|_| TooLarge(seg.payload.len()))?;
    }
    let builder = PacketBuilder::ethernet2([0; 6], [0; 6])
        .ip(IpHeaders::Ipv4(ip, Default::default()))
        .tcp_header(tcp);
    let mut p = Vec::with_capacity(builder.size(seg.payload.len()));
    builder
        .write(&mut p, seg.payload)
        .map_err(|_| TooLarge(seg.payload.len()))?;
    Ok(p)
}

/// How a capture's packets start (the pcap link types this module takes apart).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Link {
    /// Ethernet II (DLT 1), with 802.1Q VLAN tags.
    Ethernet,
    /// Raw IPv4 or IPv6 (DLT 101, 228, 229).
    RawIp,
    /// Linux cooked capture v1 (DLT 113, `tcpdump -i any`).
    LinuxSll,
    /// Linux cooked capture v2 (DLT 276).
    LinuxSll2,
    /// BSD loopback: a 4-byte address family (DLT 0 and 108).
    Null,
}

impl Link {
    /// The link type of a pcap link-type number, if supported.
    pub fn from_linktype(linktype: u32) -> Option<Link> {
        match linktype {
            1 => Some(Link::Ethernet),
            101 | 228 | 229 => Some(Link::RawIp),
            113 => Some(Link::LinuxSll),
            276 => Some(Link::LinuxSll2),
            0 | 108 => Some(Link::Null),
            _ => None,
        }
    }
}

/// A captured TCP segment.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct InSegment<'a> {
    /// Sender.
    pub src: SocketAddr,
    /// Receiver.
    pub dst: SocketAddr,
    /// Sequence number.
    pub seq: u32,
    /// Acknowledgement number.
    pub ack: u32,
    /// Flags.
    pub flags: u8,
    /// The payload (within the IP packet's length; Ethernet padding removed).
    pub payload: &'a [u8],
}

/// One fragment of an IP packet that carries TCP.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Fragment<'a> {
    /// The sender, the receiver and the identification: the packet it belongs to.
    pub key: FragmentKey,
    /// Where its bytes go in the packet's payload.
    pub offset: IpFragOffset,
    /// Whether more fragments follow.
    pub more: bool,
    /// Its part of the payload.
    pub payload: &'a [u8],
}

/// The packet a fragment belongs to: sender, receiver, identification.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct FragmentKey {
    /// Sender.
    pub src: IpAddr,
    /// Receiver.
    pub dst: IpAddr,
    /// IP identification (IPv4's 16 bits, IPv6's fragment header's 32).
    pub id: u32,
}

/// What a captured packet holds that the importer uses.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Parsed<'a> {
    /// A whole TCP segment.
    Segment(InSegment<'a>),
    /// A fragment of an IP packet carrying TCP (to reassemble).
    Fragment(Fragment<'a>),
}

/// Why a captured packet holds no TCP segment this module can use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Skip {
    /// Not IP, or IP but not TCP: of no interest.
    NotTcp,
    /// The packet ends before its headers do, or its headers are inconsistent (also a packet
    /// cut short by the capture's snap length).
    Truncated,
}

/// Takes a captured packet apart down to its TCP segment, or the fragment it is.
pub fn parse(link: Link, data: &[u8]) -> Result<Parsed<'_>, Skip> {
    let sliced = match link {
        Link::RawIp => from_ip(data)?,
        Link::Ethernet => LaxSlicedPacket::from_ethernet(data).map_err(|_| Skip::Truncated)?,
        // The cooked headers are a fixed layout ending in the EtherType: 16 bytes in v1
        // (type at 14), 20 in v2 (type at 0).
        Link::LinuxSll => {
            LaxSlicedPacket::from_ether_type(EtherType(be16(data, 14)?), tail(data, 16)?)
        }
        Link::LinuxSll2 => {
            LaxSlicedPacket::from_ether_type(EtherType(be16(data, 0)?), tail(data, 20)?)
        }
        Link::Null => {
            let family = data.get(..4).ok_or(Skip::Truncated)?;
            // Written in the capturing host's byte order: 2 is AF_INET, 10/24/28/30 AF_INET6.
            let f = u32::from_le_bytes([family[0], family[1], family[2], family[3]]);
            let f = if f > 0xFFFF { f.swap_bytes() } else { f };
            match f {
                2 | 10 | 24 | 28 | 30 => from_ip(&data[4..])?,
                _ => return Err(Skip::NotTcp),
            }
        }
    };
    tcp_of(&sliced)
}

fn be16(data: &[u8], at: usize) -> Result<u16, Skip> {
    match data.get(at..at + 2) {
        Some(b) => Ok(u16::from_be_bytes([b[0], b[1]])),
        None => Err(Skip::Truncated),
    }
}

fn tail(data: &[u8], at: usize) -> Result<&[u8], Skip> {
    data.get(at..).ok_or(Skip::Truncated)
}

fn from_ip(data: &[u8]) -> Result<LaxSlicedPacket<'_>, Skip> {
    use etherparse::err::ip::LaxHeaderSliceError;
    LaxSlicedPacket::from_ip(data).map_err(|e| match e {
        LaxHeaderSliceError::Len(_) => Skip::Truncated,
        LaxHeaderSliceError::Content(_) => Skip::NotTcp,
    })
}

/// The TCP segment or fragment of a packet sliced down to its network layer.
fn tcp_of<'a>(sliced: &LaxSlicedPacket<'a>) -> Result<Parsed<'a>, Skip> {
    let (src, dst, payload): (IpAddr, IpAddr, &LaxIpPayloadSlice<'a>) = match &sliced.net {
        Some(LaxNetSlice::Ipv4(v)) => (
            v.header().source_addr().into(),
            v.header().destination_addr().into(),
            v.payload(),
        ),
        Some(LaxNetSlice::Ipv6(v)) => (
            v.header().source_addr().into(),
            v.header().destination_addr().into(),
            v.payload(),
        ),
        Some(LaxNetSlice::Arp(_)) => return Err(Skip::NotTcp),
        None => {
            return Err(match sliced.stop_err {
                Some((SliceError::Len(_), _)) => Skip::Truncated,
                _ => Skip::NotTcp,
            })
        }
    };
    let is_tcp = payload.ip_number == ip_number::TCP;
    if payload.incomplete {
        // The IP length runs past the bytes captured.
        return Err(Skip::Truncated);
    }
    if payload.fragmented && is_tcp {
        return fragment(sliced, src, dst, payload).map(Parsed::Fragment);
    }
    match (&sliced.transport, &sliced.stop_err) {
        (Some(TransportSlice::Tcp(t)), _) => Ok(Parsed::Segment(segment(src, dst, t))),
        (_, Some((SliceError::Len(_), _))) => Err(Skip::Truncated),
        (_, Some(_)) if is_tcp => Err(Skip::Truncated),
        _ => Err(Skip::NotTcp),
    }
}

/// The fragment an IPv4 or IPv6 packet is.
fn fragment<'a>(
    sliced: &LaxSlicedPacket<'a>,
    src: IpAddr,
    dst: IpAddr,
    payload: &LaxIpPayloadSlice<'a>,
) -> Result<Fragment<'a>, Skip> {
    let (id, offset, more) = match &sliced.net {
        Some(LaxNetSlice::Ipv4(v)) => {
            let h = v.header();
            (
                u32::from(h.identification()),
                h.fragments_offset(),
                h.more_fragments(),
            )
        }
        Some(LaxNetSlice::Ipv6(v)) => v
            .extensions()
            .clone()
            .into_iter()
            .find_map(|e| match e {
                Ipv6ExtensionSlice::Fragment(f) => {
                    Some((f.identification(), f.fragment_offset(), f.more_fragments()))
                }
                _ => None,
            })
            .ok_or(Skip::Truncated)?,
        _ => return Err(Skip::NotTcp),
    };
    Ok(Fragment {
        key: FragmentKey { src, dst, id },
        offset,
        more,
        payload: payload.payload,
    })
}

fn segment<'a>(src: IpAddr, dst: IpAddr, t: &TcpSlice<'a>) -> InSegment<'a> {
    let flag = |on: bool, f: u8| if on { f } else { 0 };
    InSegment {
        src: SocketAddr::new(src, t.source_port()),
        dst: SocketAddr::new(dst, t.destination_port()),
        seq: t.sequence_number(),
        ack: t.acknowledgment_number(),
        flags: flag(t.fin(), FIN)
            | flag(t.syn(), SYN)
            | flag(t.rst(), RST)
            | flag(t.psh(), PSH)
            | flag(t.ack(), ACK),
        payload: t.payload(),
    }
}

/// The TCP segment in a reassembled IP payload from `src` to `dst`.
pub fn reassembled(src: IpAddr, dst: IpAddr, payload: &[u8]) -> Result<InSegment<'_>, Skip> {
    let t = TcpSlice::from_slice(payload).map_err(|_| Skip::Truncated)?;
    Ok(segment(src, dst, &t))
}

#[cfg(test)]
mod tests;
