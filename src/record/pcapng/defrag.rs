//! IP fragments of TCP packets reassembled with etherparse's `IpDefragBuf`, in a pool of
//! bounded size (etherparse's own `IpDefragPool` has no bound and takes strictly sliced
//! packets only): at most [`MAX_PACKETS`] packets and [`MAX_BYTES`] bytes at once, the
//! packet whose last fragment is oldest given up first.

use std::collections::HashMap;

use etherparse::defrag::IpDefragBuf;
use etherparse::ip_number;

use super::packet::{Fragment, FragmentKey};

/// Packets being reassembled at once, at most.
pub const MAX_PACKETS: usize = 1024;

/// Bytes of packets being reassembled, at most.
pub const MAX_BYTES: usize = 16 << 20;

/// A packet being reassembled.
#[derive(Debug)]
struct Partial {
    buf: IpDefragBuf,
    /// Its fragments so far, and the capture's packet index of the last one.
    fragments: u64,
    last: usize,
    /// The bytes its buffer holds.
    bytes: usize,
}

/// The packets being reassembled, and counts of what became of the fragments.
#[derive(Debug, Default)]
pub struct Defrag {
    active: HashMap<FragmentKey, Partial>,
    bytes: usize,
    /// Fragments taken.
    pub fragments: u64,
    /// Packets reassembled whole.
    pub reassembled: u64,
    /// Fragments given up: their packet never completed, went past the bounds, or had
    /// fragments that contradict each other.
    pub dropped: u64,
}

impl Defrag {
    /// Takes fragment `f` of capture packet `packet`; returns the IP payload of its packet
    /// (the TCP header and payload) once the packet is whole.
    pub fn add(&mut self, f: &Fragment<'_>, packet: usize) -> Option<Vec<u8>> {
        self.fragments += 1;
        let p = self.active.entry(f.key).or_insert_with(|| Partial {
            buf: IpDefragBuf::new(ip_number::TCP, Vec::new(), Vec::new()),
            fragments: 0,
            last: packet,
            bytes: 0,
        });
        p.fragments += 1;
        p.last = packet;
        if p.buf.add(f.offset, f.more, f.payload).is_err() {
            self.give_up(&f.key);
            return None;
        }
        let grown = p.buf.data().len().saturating_sub(p.bytes);
        p.bytes += grown;
        self.bytes += grown;
        if p.buf.is_complete() {
            let whole = self.active.remove(&f.key)?;
            self.bytes -= whole.bytes;
            self.reassembled += 1;
            return Some(whole.buf.take_bufs().0);
        }
        while self.active.len() > MAX_PACKETS || self.bytes > MAX_BYTES {
            let Some(oldest) = self
                .active
                .iter()
                .min_by_key(|(_, p)| p.last)
                .map(|(k, _)| *k)
            else {
                break;
            };
            self.give_up(&oldest);
        }
        None
    }

    /// Drops the packet of `key`, counting its fragments as given up.
    fn give_up(&mut self, key: &FragmentKey) {
        if let Some(p) = self.active.remove(key) {
            self.bytes -= p.bytes;
            self.dropped += p.fragments;
        }
    }

    /// At the end of the capture: the packets never completed are given up.
    pub fn finish(&mut self) {
        let keys: Vec<FragmentKey> = self.active.keys().copied().collect();
        for k in keys {
            self.give_up(&k);
        }
    }

    /// The warning that reports the fragments, if there were any.
    pub fn warning(&self) -> Option<String> {
        if self.fragments == 0 {
            return None;
        }
        let mut w = format!(
            "{} IP fragments of TCP packets, reassembled into {} packets",
            self.fragments, self.reassembled
        );
        if self.dropped > 0 {
            w.push_str(&format!(
                "; {} fragments of packets never completed (or past the reassembly bounds) are dropped",
                self.dropped
            ));
        }
        Some(w)
    }
}
