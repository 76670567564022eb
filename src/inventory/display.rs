//! What the run saw ([`Stats`]) and how it is shown: the summary, and the log and live lines
//! on stderr ([`Screen`]).

use std::collections::{BTreeMap, HashSet};
use std::io::{self, IsTerminal, Write};
use std::time::{Duration, Instant};

use crate::reads::Read;

/// How often the live lines change.
const LIVE_EVERY: Duration = Duration::from_secs(1);

/// Reads seen on one antenna.
#[derive(Clone, Debug, Default)]
struct AntennaStats {
    reads: u64,
    /// Reads since the last live line.
    recent: u64,
    rssi: Option<(f64, f64)>,
}

/// What the run saw.
#[derive(Debug)]
pub(super) struct Stats {
    reads: u64,
    epcs: HashSet<String>,
    antennas: BTreeMap<u16, AntennaStats>,
    /// When the first inventory started.
    pub(super) started: Option<Instant>,
    pub(super) connections: u32,
    pub(super) keepalives: u64,
    pub(super) bad_reports: u64,
    /// Tag reads that were not this inventory's (an earlier client's ROSpec), dropped.
    pub(super) foreign_reads: u64,
}

impl Stats {
    pub(super) fn new() -> Self {
        Stats {
            reads: 0,
            epcs: HashSet::new(),
            antennas: BTreeMap::new(),
            started: None,
            connections: 0,
            keepalives: 0,
            bad_reports: 0,
            foreign_reads: 0,
        }
    }

    pub(super) fn add(&mut self, r: &Read) {
        self.reads += 1;
        if !self.epcs.contains(r.epc.as_str()) {
            self.epcs.insert(r.epc.to_string());
        }
        let a = self.antennas.entry(r.antenna).or_default();
        a.reads += 1;
        a.recent += 1;
        if let Some(v) = r.rssi_dbm {
            a.rssi = Some(a.rssi.map_or((v, v), |(lo, hi)| (lo.min(v), hi.max(v))));
        }
    }

    fn seconds(&self, now: Instant) -> f64 {
        self.started
            .map_or(0.0, |s| now.duration_since(s).as_secs_f64())
    }

    /// The summary: a totals line and a line per antenna.
    pub(super) fn summary(&self, addr: &str, now: Instant) -> String {
        let secs = self.seconds(now);
        let rate = if secs > 0.0 {
            self.reads as f64 / secs
        } else {
            0.0
        };
        let mut s = format!(
            "llrp-gateway inventory: {addr}: {} reads, {} distinct EPCs in {secs:.1} s \
             ({rate:.1} reads/s); connections: {}, keepalives answered: {}",
            self.reads,
            self.epcs.len(),
            self.connections,
            self.keepalives
        );
        if self.bad_reports > 0 {
            s.push_str(&format!(
                ", undecodable reports skipped: {}",
                self.bad_reports
            ));
        }
        if self.foreign_reads > 0 {
            s.push_str(&format!(
                ", reads of another client's ROSpec ignored: {}",
                self.foreign_reads
            ));
        }
        s.push('\n');
        for (id, a) in &self.antennas {
            s.push_str(&format!(
                "  antenna {id}: {} reads, RSSI {}\n",
                a.reads,
                rssi_range(a.rssi)
            ));
        }
        s
    }
}

fn rssi_range(r: Option<(f64, f64)>) -> String {
    match r {
        Some((lo, hi)) => format!("{lo:.1}..{hi:.1} dBm"),
        None => "none reported".into(),
    }
}

/// Log lines on stderr, and on a terminal the live lines below them.
pub(super) struct Screen {
    live: bool,
    /// Live lines currently drawn.
    drawn: usize,
    last_live: Instant,
}

impl Screen {
    pub(super) fn new() -> Self {
        Screen {
            live: io::stderr().is_terminal(),
            drawn: 0,
            last_live: Instant::now(),
        }
    }

    pub(super) fn clear(&mut self) {
        if self.drawn > 0 {
            let mut e = io::stderr().lock();
            // Up over the live lines, clearing each; best effort on a terminal.
            for _ in 0..self.drawn {
                let _ = write!(e, "\x1b[1A\x1b[2K");
            }
            let _ = e.flush();
            self.drawn = 0;
        }
    }

    pub(super) fn log(&mut self, line: &str) {
        self.clear();
        eprintln!("llrp-gateway inventory: {line}");
    }

    /// Redraws the live lines once a second (a terminal only).
    pub(super) fn tick(&mut self, stats: &mut Stats, now: Instant) {
        let dt = now.duration_since(self.last_live);
        if dt < LIVE_EVERY {
            return;
        }
        self.last_live = now;
        let dt = dt.as_secs_f64();
        let mut lines = Vec::new();
        for (id, a) in &mut stats.antennas {
            lines.push(format!(
                "antenna {id}: {} reads, {:.1} reads/s, RSSI {}",
                a.reads,
                a.recent as f64 / dt,
                rssi_range(a.rssi)
            ));
            a.recent = 0;
        }
        if !self.live {
            return;
        }
        self.clear();
        let mut e = io::stderr().lock();
        if lines.is_empty() {
            lines.push("no reads yet".into());
        }
        for l in &lines {
            let _ = writeln!(e, "{l}");
        }
        let _ = e.flush();
        self.drawn = lines.len();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_summary_has_totals_and_each_antennas_rssi_range() {
        let mut s = Stats::new();
        let read = |epc: &str, antenna, rssi| Read {
            epc: crate::reads::Epc::parse(epc).expect("hex"),
            reader: None,
            antenna,
            t_us: 0,
            phase_rad: None,
            rssi_dbm: rssi,
            channel_index: None,
            channel_frequency_hz: None,
            doppler_hz: None,
            antenna_pose: None,
            last_seen_us: None,
        };
        s.add(&read("AA", 1, Some(-60.0)));
        s.add(&read("AA", 1, Some(-50.5)));
        s.add(&read("BB", 2, None));
        s.connections = 1;
        let text = s.summary("r:5084", Instant::now());
        assert!(text.contains("3 reads, 2 distinct EPCs"), "{text}");
        assert!(
            text.contains("antenna 1: 2 reads, RSSI -60.0..-50.5 dBm"),
            "{text}"
        );
        assert!(
            text.contains("antenna 2: 1 reads, RSSI none reported"),
            "{text}"
        );
    }
}
