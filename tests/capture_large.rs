//! `llrp-gateway import` of a capture larger than it may hold: a 2 GiB pcap of one LLRP
//! session (a reader sending 58 KB reports, one a segment, every thousandth out of order),
//! written to a temporary directory as it is made (never held in memory), imported by the
//! binary in under 100 MB of resident memory (its peak, from `getrusage`), then deleted.
//!
//! Heavy: 2 GiB written and read back (about 35 s in a debug build on two cores; 23 MB
//! peak measured), so it is `#[ignore]`d in a plain `cargo test`; `./scripts/test` runs it.

#[path = "common/reports.rs"]
mod reports;

use std::io::{BufWriter, Read, Write};
use std::net::Ipv4Addr;
use std::path::Path;
use std::process::{Command, Stdio};

use llrp::message::*;
use llrp::Message;
use llrp_gateway::record::pcapng::packet::{ethernet_ipv4_tcp, OutSegment, ACK, FIN, PSH, SYN};

/// The capture's size, at least.
const SIZE: u64 = 2 << 30;

/// The most resident memory the import may use.
const LIMIT_BYTES: u64 = 100_000_000;

const CLIENT: (Ipv4Addr, u16) = (Ipv4Addr::new(10, 0, 0, 7), 40001);
const READER: (Ipv4Addr, u16) = (Ipv4Addr::new(10, 0, 0, 5), 5084);

/// A classic pcap (microseconds, Ethernet) written record by record.
struct Pcap<W: Write> {
    out: W,
    written: u64,
    packets: u32,
}

impl<W: Write> Pcap<W> {
    fn new(mut out: W) -> Pcap<W> {
        let mut h = vec![0xD4, 0xC3, 0xB2, 0xA1, 2, 0, 4, 0];
        h.extend_from_slice(&[0; 8]);
        h.extend_from_slice(&262_144u32.to_le_bytes());
        h.extend_from_slice(&1u32.to_le_bytes());
        out.write_all(&h).expect("writes");
        Pcap {
            out,
            written: h.len() as u64,
            packets: 0,
        }
    }

    fn packet(&mut self, p: &[u8]) {
        let mut r = Vec::with_capacity(16);
        r.extend_from_slice(&(1_700_000_000 + self.packets / 1000).to_le_bytes());
        r.extend_from_slice(&(self.packets % 1000 * 1000).to_le_bytes());
        r.extend_from_slice(&(p.len() as u32).to_le_bytes());
        r.extend_from_slice(&(p.len() as u32).to_le_bytes());
        self.out.write_all(&r).expect("writes");
        self.out.write_all(p).expect("writes");
        self.written += (r.len() + p.len()) as u64;
        self.packets += 1;
    }
}

/// A segment of the session; `seq` is the sender's, `ack` the other's next.
fn segment(from_reader: bool, seq: u32, ack: u32, flags: u8, payload: &[u8]) -> Vec<u8> {
    let (src, dst) = if from_reader {
        (READER, CLIENT)
    } else {
        (CLIENT, READER)
    };
    ethernet_ipv4_tcp(&OutSegment {
        src,
        dst,
        seq,
        ack,
        flags,
        syn_options: None,
        window: 65535,
        ip_id: 1,
        payload,
    })
    .expect("fits")
}

/// A report of about 58 KB: one segment each.
fn report() -> Vec<u8> {
    let report = reports::many_reads(2900);
    let frame = Message::new(1, report).to_bytes().to_vec();
    assert!(
        (50_000..65_000).contains(&frame.len()),
        "{} bytes",
        frame.len()
    );
    frame
}

/// Writes the capture at `path`; returns the frames it holds.
fn write_capture(path: &Path) -> u64 {
    let file = std::fs::File::create(path).expect("creates the capture");
    let mut pcap = Pcap::new(BufWriter::with_capacity(1 << 20, file));
    let (mut c, mut r) = (1000u32, 5_000_000u32);
    pcap.packet(&segment(false, c, 0, SYN, &[]));
    c += 1;
    pcap.packet(&segment(true, r, c, SYN | ACK, &[]));
    r += 1;
    pcap.packet(&segment(false, c, r, ACK, &[]));
    let request = Message::new(1, GetReaderCapabilities::default()).to_bytes();
    pcap.packet(&segment(false, c, r, PSH | ACK, &request));
    c += request.len() as u32;
    // One packet built, then its sequence number (bytes 38..42) and the message ID (6..10 of
    // the LLRP header at 54) changed for each report: the checksums are not checked.
    let frame = report();
    let mut packet = segment(true, r, c, PSH | ACK, &frame);
    let mut held: Option<Vec<u8>> = None;
    let mut frames = 1;
    for id in 2u32.. {
        if pcap.written >= SIZE {
            break;
        }
        packet[38..42].copy_from_slice(&r.to_be_bytes());
        packet[60..64].copy_from_slice(&id.to_be_bytes());
        r = r.wrapping_add(frame.len() as u32);
        frames += 1;
        // Every 1000th report is captured after the one that follows it.
        match held.take() {
            Some(earlier) => {
                pcap.packet(&packet);
                pcap.packet(&earlier);
            }
            None if id % 1000 == 0 => held = Some(packet.clone()),
            None => pcap.packet(&packet),
        }
    }
    if let Some(last) = held {
        pcap.packet(&last);
    }
    pcap.packet(&segment(false, c, r, FIN | ACK, &[]));
    pcap.packet(&segment(true, r, c + 1, FIN | ACK, &[]));
    pcap.packet(&segment(false, c + 1, r + 1, ACK, &[]));
    pcap.out.flush().expect("flushes");
    frames
}

/// Runs `cmd` to its end; returns its exit status, standard error and peak resident bytes
/// (the largest of this test process's waited-for children: this file holds one test, and it
/// runs one child).
fn run_measured(cmd: &mut Command) -> (Option<i32>, String, u64) {
    let mut child = cmd.stderr(Stdio::piped()).spawn().expect("runs");
    let mut stderr = child.stderr.take().expect("piped");
    let log = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stderr.read_to_string(&mut s);
        s
    });
    let status = child.wait().expect("waits");
    // SAFETY: `rusage` is plain data that getrusage fills; RUSAGE_CHILDREN is a valid who.
    let (got, usage) = unsafe {
        let mut usage: libc::rusage = std::mem::zeroed();
        let got = libc::getrusage(libc::RUSAGE_CHILDREN, &mut usage);
        (got, usage)
    };
    assert_eq!(got, 0, "getrusage: {}", std::io::Error::last_os_error());
    // Linux reports ru_maxrss in KiB.
    let peak = u64::try_from(usage.ru_maxrss).unwrap_or(0) * 1024;
    (status.code(), log.join().unwrap_or_default(), peak)
}

#[test]
#[ignore = "writes and imports a 2 GiB capture (2 GiB of disk, ~35 s): ./scripts/test runs it"]
fn a_two_gib_capture_imports_in_under_100_mb() {
    let dir = tempfile::tempdir().expect("temp dir");
    let cap = dir.path().join("large.pcap");
    let started = std::time::Instant::now();
    let frames = write_capture(&cap);
    let size = std::fs::metadata(&cap).expect("the capture").len();
    assert!(size >= SIZE, "{size} bytes");
    eprintln!(
        "wrote {size} bytes, {frames} frames, in {:?}",
        started.elapsed()
    );
    let started = std::time::Instant::now();
    let (code, log, peak) = run_measured(
        Command::new(env!("CARGO_BIN_EXE_llrp-gateway"))
            .arg("import")
            .arg(&cap)
            .args(["--output", "/dev/null", "--force"]),
    );
    eprintln!(
        "import: {:?}, peak resident memory {:.1} MB; {log}",
        started.elapsed(),
        peak as f64 / 1e6
    );
    std::fs::remove_file(&cap).expect("deletes the capture");
    assert_eq!(code, Some(0), "{log}");
    assert!(
        log.contains(&format!(
            "1 connections, {frames} frames, reader 10.0.0.5:5084"
        )),
        "{log}"
    );
    assert!(!log.contains("warning"), "nothing lost or skipped: {log}");
    assert!(
        peak < LIMIT_BYTES,
        "peak resident memory {peak} bytes, over {LIMIT_BYTES}"
    );
}
