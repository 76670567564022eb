//! Unit tests of the parent module.

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

/// What was read of each packet: number, time, link, length, cut; and the warnings.
type Read = (
    Vec<(usize, u64, Result<Link, u32>, usize, bool)>,
    Vec<String>,
);

fn read(input: impl std::io::Read + Send) -> Result<Read, ImportError> {
    let mut got = Vec::new();
    let warnings = read_packets(input, |p| {
        got.push((p.number, p.utc_us, p.link, p.data.len(), p.cut));
        Ok(())
    })?;
    Ok((got, warnings))
}

/// A reader that hands over at most 7 bytes a call, as a slow pipe would.
struct Trickle<'a>(&'a [u8]);

impl std::io::Read for Trickle<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = buf.len().min(7).min(self.0.len());
        buf[..n].copy_from_slice(&self.0[..n]);
        self.0 = &self.0[n..];
        Ok(n)
    }
}

#[test]
fn pcap_in_micro_and_nanoseconds_with_packets_cut_by_the_snap_length() {
    for (magic, frac) in [
        ([0xD4, 0xC3, 0xB2, 0xA1], 123_456),
        ([0x4D, 0x3C, 0xB2, 0xA1], 123_456_789),
    ] {
        let data = pcap(magic, frac);
        let (packets, warnings) = read(&data[..]).expect("reads");
        assert!(warnings.is_empty(), "{warnings:?}");
        assert_eq!(
            packets,
            [(1, 1_700_000_000_123_456, Ok(Link::Ethernet), 60, true)]
        );
    }
}

#[test]
fn a_capture_is_read_the_same_in_small_pieces_and_a_cut_one_up_to_the_cut() {
    let mut data = pcap([0xD4, 0xC3, 0xB2, 0xA1], 5);
    let one = data[24..].to_vec();
    for _ in 0..50 {
        data.extend_from_slice(&one);
    }
    let (whole, warnings) = read(&data[..]).expect("reads");
    assert_eq!(whole.len(), 51);
    assert!(warnings.is_empty(), "{warnings:?}");
    let (trickled, _) = read(Trickle(&data)).expect("reads in pieces");
    assert_eq!(trickled, whole);
    let (cut, warnings) = read(&data[..data.len() - 10]).expect("reads to the cut");
    assert_eq!(cut.len(), 50);
    assert!(
        warnings[0].contains("inside a packet at byte")
            && warnings[0].contains("its last 66 bytes"),
        "{warnings:?}"
    );
}

/// A pcapng section (little-endian) with one Ethernet interface of time unit 10^-`resol` s,
/// then `blocks`.
fn pcapng(resol: u8, blocks: &[Vec<u8>]) -> Vec<u8> {
    let mut f = vec![
        0x0A, 0x0D, 0x0D, 0x0A, 28, 0, 0, 0, 0x4D, 0x3C, 0x2B, 0x1A, 1, 0, 0, 0,
    ];
    f.extend_from_slice(&(-1i64).to_le_bytes());
    f.extend_from_slice(&28u32.to_le_bytes());
    // IDB: type 1, length 32, Ethernet, snap length 0, if_tsresol, end of options.
    f.extend_from_slice(&[1, 0, 0, 0, 32, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0]);
    f.extend_from_slice(&[9, 0, 1, 0, resol, 0, 0, 0, 0, 0, 0, 0]);
    f.extend_from_slice(&32u32.to_le_bytes());
    for b in blocks {
        f.extend_from_slice(b);
    }
    f
}

/// A pcapng block of `kind` with `body` (a multiple of 4 bytes long).
fn block(kind: u32, body: &[u8]) -> Vec<u8> {
    let len = (12 + body.len()) as u32;
    let mut b = kind.to_le_bytes().to_vec();
    b.extend_from_slice(&len.to_le_bytes());
    b.extend_from_slice(body);
    b.extend_from_slice(&len.to_le_bytes());
    b
}

/// The body of an enhanced (`obsolete` false) or obsolete packet block at `ticks` holding
/// 8 bytes on `interface`.
fn packet_body(interface: u32, ticks: u64, obsolete: bool) -> Vec<u8> {
    let mut b = if obsolete {
        (interface as u16).to_le_bytes().to_vec()
    } else {
        interface.to_le_bytes().to_vec()
    };
    if obsolete {
        b.extend_from_slice(&[0, 0]);
    }
    b.extend_from_slice(&((ticks >> 32) as u32).to_le_bytes());
    b.extend_from_slice(&(ticks as u32).to_le_bytes());
    b.extend_from_slice(&8u32.to_le_bytes());
    b.extend_from_slice(&8u32.to_le_bytes());
    b.extend_from_slice(&[0xCD; 8]);
    b
}

#[test]
fn pcapng_enhanced_simple_and_obsolete_blocks_in_the_interface_s_time_unit() {
    let t = 1_700_000_000_000_123u64; // µs
    let data = pcapng(
        9,
        &[
            block(6, &packet_body(0, t * 1000 + 999, false)),
            block(3, &[8, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8]),
            block(2, &packet_body(0, (t + 5) * 1000, true)),
        ],
    );
    let (packets, warnings) = read(&data[..]).expect("reads");
    assert!(warnings.is_empty(), "{warnings:?}");
    let link = Ok(Link::Ethernet);
    assert_eq!(
        packets,
        [
            (1, t, link, 8, false),
            (2, t, link, 8, false),
            (3, t + 5, link, 8, false)
        ]
    );
    let bad = pcapng(6, &[block(6, &packet_body(1, 0, false))]);
    let e = read(&bad[..]).expect_err("interface 1 is not declared");
    assert_eq!(
        e.to_string(),
        "packet 1: it names interface 1, and the section declares 1"
    );
}
