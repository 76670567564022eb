//! Ethernet, IPv4/IPv6 and TCP headers: building the packets of an export (with valid IPv4
//! and TCP checksums) and taking captured packets apart down to their TCP segment.

use std::net::{IpAddr, Ipv4Addr, Ipv6Addr, SocketAddr};

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

/// Ethernet header length.
const ETHERNET_LEN: usize = 14;
/// IPv4 header length without options.
const IPV4_LEN: usize = 20;
/// TCP header length without options.
const TCP_LEN: usize = 20;

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

/// The Internet checksum (RFC 1071) of `data`, continuing from the partial sum `sum`.
fn ones_complement_sum(mut sum: u32, data: &[u8]) -> u32 {
    let mut chunks = data.chunks_exact(2);
    for c in &mut chunks {
        sum += u32::from(u16::from_be_bytes([c[0], c[1]]));
    }
    if let [last] = chunks.remainder() {
        sum += u32::from(*last) << 8;
    }
    sum
}

/// Folds a partial sum into the 16-bit one's-complement checksum.
fn fold(mut sum: u32) -> u16 {
    while sum > 0xFFFF {
        sum = (sum & 0xFFFF) + (sum >> 16);
    }
    !(sum as u16)
}

/// Whether the one's-complement sum over `data` (checksum field included) verifies.
pub fn checksum_ok(data: &[u8]) -> bool {
    fold(ones_complement_sum(0, data)) == 0
}

/// An Ethernet frame holding `seg` in IPv4 and TCP, checksums filled in. Both MAC addresses
/// are zero, as on Linux's loopback interface.
pub fn ethernet_ipv4_tcp(seg: &OutSegment<'_>) -> Vec<u8> {
    // MSS (4 bytes), NOP, window scale (3 bytes).
    let options = if seg.syn_options.is_some() { 8 } else { 0 };
    let tcp_len = TCP_LEN + options + seg.payload.len();
    let ip_len = IPV4_LEN + tcp_len;
    let mut p = Vec::with_capacity(ETHERNET_LEN + ip_len);
    p.extend_from_slice(&[0; 12]);
    p.extend_from_slice(&0x0800u16.to_be_bytes());
    // IPv4: version 4, 5 words, DF, TTL 64, TCP.
    let ip = p.len();
    p.extend_from_slice(&[0x45, 0]);
    // The caller keeps segments within the MSS, far below 65535 bytes.
    p.extend_from_slice(&(ip_len as u16).to_be_bytes());
    p.extend_from_slice(&seg.ip_id.to_be_bytes());
    p.extend_from_slice(&[0x40, 0, 64, 6, 0, 0]);
    p.extend_from_slice(&seg.src.0.octets());
    p.extend_from_slice(&seg.dst.0.octets());
    let sum = fold(ones_complement_sum(0, &p[ip..ip + IPV4_LEN]));
    p[ip + 10..ip + 12].copy_from_slice(&sum.to_be_bytes());
    // TCP.
    let tcp = p.len();
    p.extend_from_slice(&seg.src.1.to_be_bytes());
    p.extend_from_slice(&seg.dst.1.to_be_bytes());
    p.extend_from_slice(&seg.seq.to_be_bytes());
    let ack = if seg.flags & ACK != 0 { seg.ack } else { 0 };
    p.extend_from_slice(&ack.to_be_bytes());
    p.push((((TCP_LEN + options) / 4) as u8) << 4);
    p.push(seg.flags);
    p.extend_from_slice(&seg.window.to_be_bytes());
    p.extend_from_slice(&[0, 0, 0, 0]); // checksum, urgent pointer
    if let Some((mss, shift)) = seg.syn_options {
        p.extend_from_slice(&[2, 4]);
        p.extend_from_slice(&mss.to_be_bytes());
        p.extend_from_slice(&[1, 3, 3, shift]);
    }
    p.extend_from_slice(seg.payload);
    let mut pseudo = Vec::with_capacity(12);
    pseudo.extend_from_slice(&seg.src.0.octets());
    pseudo.extend_from_slice(&seg.dst.0.octets());
    pseudo.extend_from_slice(&[0, 6]);
    pseudo.extend_from_slice(&(tcp_len as u16).to_be_bytes());
    let sum = fold(ones_complement_sum(
        ones_complement_sum(0, &pseudo),
        &p[tcp..],
    ));
    p[tcp + 16..tcp + 18].copy_from_slice(&sum.to_be_bytes());
    p
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

/// Why a captured packet holds no TCP segment this module can use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Skip {
    /// Not IP, or IP but not TCP: of no interest.
    NotTcp,
    /// An IP fragment (fragments are not reassembled).
    Fragment,
    /// The packet ends before its headers do, or its headers are inconsistent (also a packet
    /// cut short by the capture's snap length).
    Truncated,
}

/// Takes a captured packet apart down to its TCP segment.
pub fn parse(link: Link, data: &[u8]) -> Result<InSegment<'_>, Skip> {
    let ip = match link {
        Link::RawIp => data,
        Link::Ethernet => {
            let mut at = 12;
            let mut ethertype = be16(data, at)?;
            // 802.1Q and 802.1ad tags, possibly stacked.
            while ethertype == 0x8100 || ethertype == 0x88A8 {
                at += 4;
                ethertype = be16(data, at)?;
            }
            match ethertype {
                0x0800 | 0x86DD => data.get(at + 2..).ok_or(Skip::Truncated)?,
                _ => return Err(Skip::NotTcp),
            }
        }
        Link::LinuxSll => match be16(data, 14)? {
            0x0800 | 0x86DD => data.get(16..).ok_or(Skip::Truncated)?,
            _ => return Err(Skip::NotTcp),
        },
        Link::LinuxSll2 => match be16(data, 0)? {
            0x0800 | 0x86DD => data.get(20..).ok_or(Skip::Truncated)?,
            _ => return Err(Skip::NotTcp),
        },
        Link::Null => {
            let family = data.get(..4).ok_or(Skip::Truncated)?;
            // Written in the capturing host's byte order: 2 is AF_INET, 10/24/28/30 AF_INET6.
            let f = u32::from_le_bytes([family[0], family[1], family[2], family[3]]);
            let f = if f > 0xFFFF { f.swap_bytes() } else { f };
            match f {
                2 | 10 | 24 | 28 | 30 => &data[4..],
                _ => return Err(Skip::NotTcp),
            }
        }
    };
    match ip.first().map(|b| b >> 4) {
        Some(4) => ipv4(ip),
        Some(6) => ipv6(ip),
        Some(_) => Err(Skip::NotTcp),
        None => Err(Skip::Truncated),
    }
}

fn be16(data: &[u8], at: usize) -> Result<u16, Skip> {
    match data.get(at..at + 2) {
        Some(b) => Ok(u16::from_be_bytes([b[0], b[1]])),
        None => Err(Skip::Truncated),
    }
}

fn be32(data: &[u8], at: usize) -> Result<u32, Skip> {
    match data.get(at..at + 4) {
        Some(b) => Ok(u32::from_be_bytes([b[0], b[1], b[2], b[3]])),
        None => Err(Skip::Truncated),
    }
}

fn ipv4(ip: &[u8]) -> Result<InSegment<'_>, Skip> {
    let ihl = usize::from(ip.first().ok_or(Skip::Truncated)? & 0x0F) * 4;
    let total = usize::from(be16(ip, 2)?);
    if ihl < IPV4_LEN || total < ihl || ip.len() < total {
        return Err(Skip::Truncated);
    }
    if ip[9] != 6 {
        return Err(Skip::NotTcp);
    }
    // More-fragments set, or a fragment offset.
    if be16(ip, 6)? & 0x3FFF != 0 {
        return Err(Skip::Fragment);
    }
    let src = Ipv4Addr::new(ip[12], ip[13], ip[14], ip[15]);
    let dst = Ipv4Addr::new(ip[16], ip[17], ip[18], ip[19]);
    tcp(IpAddr::V4(src), IpAddr::V4(dst), &ip[ihl..total])
}

fn ipv6(ip: &[u8]) -> Result<InSegment<'_>, Skip> {
    if ip.len() < 40 {
        return Err(Skip::Truncated);
    }
    let payload_len = usize::from(be16(ip, 4)?);
    let end = 40 + payload_len;
    if ip.len() < end {
        return Err(Skip::Truncated);
    }
    let addr = |at: usize| {
        let mut o = [0u8; 16];
        o.copy_from_slice(&ip[at..at + 16]);
        Ipv6Addr::from(o)
    };
    let (src, dst) = (addr(8), addr(24));
    let mut next = ip[6];
    let mut at = 40;
    loop {
        match next {
            6 => break,
            // Hop-by-hop, routing, destination options: skip them.
            0 | 43 | 60 => {
                let h = ip.get(at..at + 2).ok_or(Skip::Truncated)?;
                next = h[0];
                at += (usize::from(h[1]) + 1) * 8;
            }
            44 => return Err(Skip::Fragment),
            _ => return Err(Skip::NotTcp),
        }
    }
    if at > end {
        return Err(Skip::Truncated);
    }
    tcp(IpAddr::V6(src), IpAddr::V6(dst), &ip[at..end])
}

fn tcp(src: IpAddr, dst: IpAddr, t: &[u8]) -> Result<InSegment<'_>, Skip> {
    let offset = usize::from(t.get(12).ok_or(Skip::Truncated)? >> 4) * 4;
    if offset < TCP_LEN || t.len() < offset {
        return Err(Skip::Truncated);
    }
    Ok(InSegment {
        src: SocketAddr::new(src, be16(t, 0)?),
        dst: SocketAddr::new(dst, be16(t, 2)?),
        seq: be32(t, 4)?,
        ack: be32(t, 8)?,
        flags: t[13],
        payload: &t[offset..],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn segment(payload: &[u8], syn_options: Option<(u16, u8)>) -> Vec<u8> {
        ethernet_ipv4_tcp(&OutSegment {
            src: (Ipv4Addr::new(127, 0, 0, 2), 40001),
            dst: (Ipv4Addr::new(127, 0, 0, 1), 5084),
            seq: 0xFFFF_FFF0,
            ack: 7,
            flags: PSH | ACK,
            syn_options,
            window: 65535,
            ip_id: 3,
            payload,
        })
    }

    #[test]
    fn built_packets_have_valid_checksums_and_parse_back() {
        for (payload, mss) in [
            (&b"odd"[..], None),
            (&b"even"[..], Some((1460, 7))),
            (&[][..], None),
        ] {
            let p = segment(payload, mss);
            assert!(checksum_ok(&p[14..34]), "IPv4 header checksum");
            let tcp_len = p.len() - 34;
            let mut pseudo = vec![127, 0, 0, 2, 127, 0, 0, 1, 0, 6];
            pseudo.extend_from_slice(&(tcp_len as u16).to_be_bytes());
            pseudo.extend_from_slice(&p[34..]);
            assert!(checksum_ok(&pseudo), "TCP checksum over the pseudo-header");
            let s = parse(Link::Ethernet, &p).expect("a TCP segment");
            assert_eq!(s.src, "127.0.0.2:40001".parse().expect("addr"));
            assert_eq!(s.dst, "127.0.0.1:5084".parse().expect("addr"));
            assert_eq!((s.seq, s.ack, s.flags), (0xFFFF_FFF0, 7, PSH | ACK));
            assert_eq!(s.payload, payload);
        }
    }

    #[test]
    fn a_known_checksum() {
        // The textbook IPv4 header (192.168.0.1 → 192.168.0.199, UDP): checksum 0xB861.
        let mut h = [
            0x45, 0x00, 0x00, 0x73, 0x00, 0x00, 0x40, 0x00, 0x40, 0x11, 0, 0, 0xC0, 0xA8, 0x00,
            0x01, 0xC0, 0xA8, 0x00, 0xC7,
        ];
        let sum = fold(ones_complement_sum(0, &h));
        assert_eq!(sum, 0xB861);
        h[10..12].copy_from_slice(&sum.to_be_bytes());
        assert!(checksum_ok(&h));
    }

    #[test]
    fn cooked_raw_and_vlan_links_and_ethernet_padding() {
        let eth = segment(b"abc", None);
        let ip = &eth[14..];
        assert_eq!(parse(Link::RawIp, ip).expect("raw").payload, b"abc");
        // Packet type, ARPHRD_LOOPBACK (772), address length 6, address, protocol IPv4.
        let mut sll = vec![0, 0, 3, 4, 0, 6, 0, 0, 0, 0, 0, 0, 0, 0, 0x08, 0x00];
        sll.extend_from_slice(ip);
        assert_eq!(parse(Link::LinuxSll, &sll).expect("sll").payload, b"abc");
        let mut vlan = eth[..12].to_vec();
        vlan.extend_from_slice(&[0x81, 0x00, 0x00, 0x05]);
        vlan.extend_from_slice(&eth[12..]);
        vlan.extend_from_slice(&[0; 6]); // padding after the IP packet
        assert_eq!(parse(Link::Ethernet, &vlan).expect("vlan").payload, b"abc");
        assert_eq!(parse(Link::Ethernet, &eth[..40]), Err(Skip::Truncated));
        let mut arp = eth.clone();
        arp[12..14].copy_from_slice(&0x0806u16.to_be_bytes());
        assert_eq!(parse(Link::Ethernet, &arp), Err(Skip::NotTcp));
        let mut frag = eth.clone();
        frag[20] = 0x20; // more fragments
        assert_eq!(parse(Link::Ethernet, &frag), Err(Skip::Fragment));
    }

    #[test]
    fn ipv6_with_an_extension_header() {
        let eth = segment(b"v6", None);
        let tcp = &eth[34..];
        let mut ip = vec![0x60, 0, 0, 0];
        ip.extend_from_slice(&((tcp.len() + 8) as u16).to_be_bytes());
        ip.extend_from_slice(&[0, 64]); // next: hop-by-hop
        ip.extend_from_slice(&Ipv6Addr::LOCALHOST.octets());
        ip.extend_from_slice(&Ipv6Addr::LOCALHOST.octets());
        ip.extend_from_slice(&[6, 0, 0, 0, 0, 0, 0, 0]);
        ip.extend_from_slice(tcp);
        let s = parse(Link::RawIp, &ip).expect("v6");
        assert_eq!(s.payload, b"v6");
        assert_eq!(s.dst, "[::1]:5084".parse().expect("addr"));
    }
}
