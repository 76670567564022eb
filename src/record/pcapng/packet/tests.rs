//! Unit tests of the parent module.

use std::net::Ipv6Addr;

use super::*;
use etherparse::SlicedPacket;

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
    .expect("fits")
}

fn hex(s: &str) -> Vec<u8> {
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).expect("hex"))
        .collect()
}

fn tcp_segment(p: Parsed<'_>) -> InSegment<'_> {
    match p {
        Parsed::Segment(s) => s,
        Parsed::Fragment(f) => panic!("a fragment: {f:?}"),
    }
}

#[test]
fn built_packets_have_valid_checksums_and_parse_back() {
    for (payload, mss) in [
        (&b"odd"[..], None),
        (&b"even"[..], Some((1460, 7))),
        (&[][..], None),
    ] {
        let p = segment(payload, mss);
        let strict = SlicedPacket::from_ethernet(&p).expect("a valid packet");
        let Some(etherparse::NetSlice::Ipv4(ip)) = &strict.net else {
            panic!("IPv4")
        };
        let h = ip.header().to_header();
        assert_eq!(h.header_checksum, h.calc_header_checksum(), "IPv4 checksum");
        let Some(TransportSlice::Tcp(t)) = &strict.transport else {
            panic!("TCP")
        };
        let sum = t.calc_checksum_ipv4(h.source, h.destination).expect("sums");
        assert_eq!(t.checksum(), sum, "TCP checksum over the pseudo-header");
        let s = tcp_segment(parse(Link::Ethernet, &p).expect("a TCP segment"));
        assert_eq!(s.src, "127.0.0.2:40001".parse().expect("addr"));
        assert_eq!(s.dst, "127.0.0.1:5084".parse().expect("addr"));
        assert_eq!((s.seq, s.ack, s.flags), (0xFFFF_FFF0, 7, PSH | ACK));
        assert_eq!(s.payload, payload);
    }
}

#[test]
fn built_packets_are_byte_for_byte_those_of_the_former_hand_written_builder() {
    // Pinned from the builder export used before etherparse: exports keep their bytes.
    assert_eq!(
        segment(b"odd", None),
        hex(
            "00000000000000000000000008004500002b0003400040063cc77f0000027f0000019c4113dc\
             fffffff0000000075018ffff2e4c00006f6464"
        )
    );
    let syn = ethernet_ipv4_tcp(&OutSegment {
        src: (Ipv4Addr::new(127, 0, 0, 1), 5084),
        dst: (Ipv4Addr::new(127, 0, 0, 2), 40001),
        seq: 0x1234_5678,
        ack: 0,
        flags: SYN,
        syn_options: Some((1460, 7)),
        window: 65535,
        ip_id: 1,
        payload: &[],
    })
    .expect("fits");
    assert_eq!(
        syn,
        hex(
            "0000000000000000000000000800450000300001400040063cc47f0000017f00000213dc9c41\
             12345678000000007002ffff6d4b0000020405b401030307"
        )
    );
}

#[test]
fn cooked_raw_and_vlan_links_and_ethernet_padding() {
    let eth = segment(b"abc", None);
    let ip = &eth[14..];
    let payload = |l, d| tcp_segment(parse(l, d).expect("TCP")).payload.to_vec();
    assert_eq!(payload(Link::RawIp, ip), b"abc");
    // Packet type, ARPHRD_LOOPBACK (772), address length 6, address, protocol IPv4.
    let mut sll = vec![0, 0, 3, 4, 0, 6, 0, 0, 0, 0, 0, 0, 0, 0, 0x08, 0x00];
    sll.extend_from_slice(ip);
    assert_eq!(payload(Link::LinuxSll, &sll), b"abc");
    let mut vlan = eth[..12].to_vec();
    vlan.extend_from_slice(&[0x81, 0x00, 0x00, 0x05]);
    vlan.extend_from_slice(&eth[12..]);
    vlan.extend_from_slice(&[0; 6]); // padding after the IP packet
    assert_eq!(payload(Link::Ethernet, &vlan), b"abc");
    assert_eq!(parse(Link::Ethernet, &eth[..40]), Err(Skip::Truncated));
    let mut arp = eth.clone();
    arp[12..14].copy_from_slice(&0x0806u16.to_be_bytes());
    assert_eq!(parse(Link::Ethernet, &arp), Err(Skip::NotTcp));
}

#[test]
fn an_ipv4_total_length_of_zero_takes_the_packet_as_captured() {
    // TCP segmentation offload: the sending host's capture holds the large segment before
    // the card splits it, with an IPv4 total length of 0.
    let big = vec![0x5A; 20_000];
    let mut eth = segment(&[], None);
    eth.extend_from_slice(&big);
    eth[16..18].copy_from_slice(&[0, 0]);
    let s = tcp_segment(parse(Link::Ethernet, &eth).expect("a TSO segment"));
    assert_eq!(s.payload, &big[..]);
}

/// An IPv6 packet from ::1 to ::1 whose extension headers `ext` (first one `first`) come
/// before the TCP segment of `segment(b"v6")`.
fn ipv6(first: u8, ext: &[u8]) -> Vec<u8> {
    let eth = segment(b"v6", None);
    let tcp = &eth[34..];
    let mut ip = vec![0x60, 0, 0, 0];
    ip.extend_from_slice(&((tcp.len() + ext.len()) as u16).to_be_bytes());
    ip.extend_from_slice(&[first, 64]);
    ip.extend_from_slice(&Ipv6Addr::LOCALHOST.octets());
    ip.extend_from_slice(&Ipv6Addr::LOCALHOST.octets());
    ip.extend_from_slice(ext);
    ip.extend_from_slice(tcp);
    ip
}

#[test]
fn ipv6_with_extension_headers_the_authentication_header_among_them() {
    // Hop-by-hop options (8 bytes), then TCP.
    let hop = ipv6(0, &[6, 0, 0, 0, 0, 0, 0, 0]);
    let s = tcp_segment(parse(Link::RawIp, &hop).expect("v6"));
    assert_eq!(s.payload, b"v6");
    assert_eq!(s.dst, "[::1]:5084".parse().expect("addr"));
    // Authentication Header (RFC 4302): next header TCP, length 4 (6 words: 24 bytes), SPI,
    // sequence number, a 12-byte ICV.
    let mut ah = vec![6, 4, 0, 0, 0, 0, 0x10, 0x01, 0, 0, 0, 1];
    ah.extend_from_slice(&[0xAA; 12]);
    let with_ah = ipv6(51, &ah);
    let s = tcp_segment(parse(Link::RawIp, &with_ah).expect("v6 with AH"));
    assert_eq!(s.payload, b"v6");
    assert_eq!(s.src, "[::1]:40001".parse().expect("addr"));
}

#[test]
fn fragments_are_handed_over_and_the_reassembled_payload_parses() {
    let eth = segment(b"fragmented", None);
    let mut first = eth.clone();
    first[20] = 0x20; // more fragments, offset 0
    let Ok(Parsed::Fragment(f)) = parse(Link::Ethernet, &first) else {
        panic!("a fragment")
    };
    assert!(f.more);
    assert_eq!(f.offset.value(), 0);
    assert_eq!(f.key.id, 3);
    assert_eq!(f.payload, &eth[34..]);
    let s = reassembled(f.key.src, f.key.dst, f.payload).expect("TCP");
    assert_eq!(s.payload, b"fragmented");
    // A fragment of a UDP datagram is of no interest.
    let mut udp = first.clone();
    udp[23] = 17;
    assert_eq!(parse(Link::Ethernet, &udp), Err(Skip::NotTcp));
}

#[test]
fn an_ipv6_fragment_header_makes_a_fragment() {
    // Fragment header: next header TCP, reserved, offset 0 with more fragments, ID 0x01020304.
    let first = ipv6(44, &[6, 0, 0, 1, 1, 2, 3, 4]);
    let Ok(Parsed::Fragment(f)) = parse(Link::RawIp, &first) else {
        panic!("a fragment")
    };
    assert!(f.more);
    assert_eq!((f.key.id, f.offset.value()), (0x0102_0304, 0));
    assert_eq!(f.key.src, IpAddr::from(Ipv6Addr::LOCALHOST));
    let s = reassembled(f.key.src, f.key.dst, f.payload).expect("TCP");
    assert_eq!(s.payload, b"v6");
}
