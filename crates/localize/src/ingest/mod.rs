//! Reads into phase series: each read of the reads file (or the gateway's [`Read`]) joined with
//! its antenna's pose and filed under its (reader, antenna, tag, channel) series.
//!
//! A read's pose is its own `antenna_pose` when the source gave one, else the pose file's at
//! its time ([`Poses::at`]). Reads without a phase, a channel frequency or a pose are set aside
//! and counted by reason, never guessed.

use std::collections::{BTreeMap, BTreeSet};

use rustc_hash::FxHashMap;

use crate::poses::{Poses, Track};
use crate::series::{Ambiguity, Sample, Series};
use crate::SPEED_OF_LIGHT;
use llrp_gateway_vocab::reads::{Epc, Read};

/// The series key: EPC (hex as the reads give it), reader, antenna port, channel frequency
/// (Hz). The EPC comes first so that one tag's series are next to each other.
pub type Key = (Epc, String, u16, u64);

/// Reads set aside, by reason.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SetAside {
    /// The read carried no phase.
    pub no_phase: u64,
    /// The read's channel frequency is unknown.
    pub no_frequency: u64,
    /// No pose within reach of the read's time.
    pub no_pose: u64,
    /// Its RSSI was under the floor ([`Ingest::with_min_rssi`]).
    pub weak: u64,
}

impl SetAside {
    /// Reads set aside for any reason.
    pub fn total(&self) -> u64 {
        self.no_phase + self.no_frequency + self.no_pose + self.weak
    }
}

/// Whether `read`'s RSSI is under `floor` (dBm): such a read is set aside. A read without
/// RSSI, or no floor, is not.
pub fn under_floor(read: &Read, floor: Option<f64>) -> bool {
    matches!((floor, read.rssi_dbm), (Some(floor), Some(rssi)) if rssi < floor)
}

/// The place of `name` in `readers`, added at the end if it is not there.
fn intern(readers: &mut Vec<String>, name: &str) -> u32 {
    let i = readers.iter().position(|r| r == name).unwrap_or_else(|| {
        readers.push(name.to_string());
        readers.len() - 1
    });
    // As many readers as 2³² would not fit in memory as names.
    u32::try_from(i).unwrap_or(u32::MAX)
}

/// Asks the CPU to bring the cache line at `p` in (a hint: no load, no fault).
#[inline(always)]
fn prefetch(p: *const u8) {
    // SAFETY: SSE is part of every x86_64 CPU (the target's baseline), and a prefetch
    // neither reads memory into the program nor faults, whatever `p` is.
    #[cfg(target_arch = "x86_64")]
    unsafe {
        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(p.cast());
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

/// One antenna a batch of reads has met: its reader's name and id ([`Ingest`]'s interned
/// names), its pose track if there is one, and where its last lookup landed.
struct Met<'r, 'p> {
    reader: &'r str,
    port: u16,
    id: u32,
    track: Option<Track<'p>>,
    cursor: usize,
}

/// The antennas one batch of reads has met (a handful, scanned), up to `limit` of them.
struct Tracks<'r, 'p> {
    met: Vec<Met<'r, 'p>>,
    limit: usize,
}

impl<'r, 'p> Tracks<'r, 'p> {
    /// Most antennas a batch remembers; beyond it each read's are looked up afresh.
    const MAX: usize = 64;

    /// The antenna `port` of `reader`, remembered now (its reader's id from `id`) if it was
    /// not and there is room.
    fn get(
        &mut self,
        poses: &'p Poses,
        reader: &'r str,
        port: u16,
        id: impl FnOnce() -> u32,
    ) -> Option<&mut Met<'r, 'p>> {
        let known = self
            .met
            .iter()
            .position(|m| m.port == port && m.reader == reader);
        let i = match known {
            Some(i) => i,
            None if self.met.len() < self.limit => {
                self.met.push(Met {
                    reader,
                    port,
                    id: id(),
                    track: poses.track_at(reader, port),
                    cursor: 0,
                });
                self.met.len() - 1
            }
            None => return None,
        };
        Some(&mut self.met[i])
    }
}

/// Where a tag's series is, with what tells it from the tag's others: its reader's id, its
/// antenna port and its channel frequency (Hz).
#[derive(Clone, Copy, Debug)]
struct Slot {
    index: usize,
    reader: u32,
    port: u16,
    f_hz: u64,
}

/// Every series of the reads taken in so far.
#[derive(Clone, Debug)]
pub struct Ingest {
    poses: Poses,
    ambiguity: Ambiguity,
    max_gap_us: u64,
    /// Reads weaker than this (dBm) are set aside.
    min_rssi_dbm: Option<f64>,
    /// The series, each with its key, in no order.
    series: Vec<(Key, Series)>,
    /// Each tag's series (where they are in `series`), in key order, by EPC: a read's series
    /// is found by one hash of its EPC and a scan of its tag's few series, with no key built.
    by_tag: FxHashMap<Epc, Vec<Slot>>,
    /// Every reader name met, a series' reader is its place here: a read's series is told
    /// from its tag's others by numbers, not names.
    readers: Vec<String>,
    /// The tags with series, in EPC order.
    tags: BTreeSet<Epc>,
    set_aside: SetAside,
    taken: u64,
}

impl Ingest {
    /// Series of reads whose poses come from `poses` (or the reads themselves), unwrapped
    /// with `ambiguity`, a segment broken by more than `max_gap_us` between two reads.
    pub fn new(poses: Poses, ambiguity: Ambiguity, max_gap_us: u64) -> Ingest {
        Ingest {
            poses,
            ambiguity,
            max_gap_us,
            min_rssi_dbm: None,
            series: Vec::new(),
            by_tag: FxHashMap::default(),
            readers: Vec::new(),
            tags: BTreeSet::new(),
            set_aside: SetAside::default(),
            taken: 0,
        }
    }

    /// This ingest with every read whose RSSI is under `dbm` set aside (counted, never
    /// filed): a weak read's phase is noisy enough to slip the unwrapping. A read without RSSI
    /// is kept.
    pub fn with_min_rssi(mut self, dbm: Option<f64>) -> Ingest {
        self.min_rssi_dbm = dbm;
        self
    }

    /// Takes one read (a read older than its series' newest is put in its place in time).
    pub fn push(&mut self, read: &Read) {
        // One read remembers no antenna: nothing to allocate for the live path's read at a
        // time.
        self.file(std::slice::from_ref(read), 0);
    }

    /// Takes `reads` in order, as [`Ingest::push`] does each: each antenna's pose track is
    /// found once and its reads looked up from where the last one landed, and the EPC and
    /// reader name of reads a few ahead are fetched into the cache while the one before them
    /// is filed (reads in memory hold them on the heap, one allocation each, which would
    /// otherwise be waited for read by read).
    pub fn extend(&mut self, reads: &[Read]) {
        self.file(reads, Tracks::MAX);
    }

    /// [`Ingest::extend`], remembering up to `antennas` antennas' tracks.
    fn file(&mut self, reads: &[Read], antennas: usize) {
        const AHEAD: usize = 8;
        // Taken out for the batch, so that the series can be filed while its tracks are
        // borrowed; put back below.
        let poses = std::mem::take(&mut self.poses);
        let mut tracks = Tracks {
            met: Vec::new(),
            limit: antennas,
        };
        for (i, read) in reads.iter().enumerate() {
            if let Some(next) = reads.get(i + AHEAD) {
                prefetch(next.epc.as_ptr());
                if let Some(reader) = &next.reader {
                    prefetch(reader.as_ptr());
                }
            }
            self.take(read, &poses, &mut tracks);
        }
        self.poses = poses;
    }

    /// Files one read, its pose from `poses` through `tracks`.
    fn take<'r, 'p>(&mut self, read: &'r Read, poses: &'p Poses, tracks: &mut Tracks<'r, 'p>) {
        if under_floor(read, self.min_rssi_dbm) {
            self.set_aside.weak += 1;
            return;
        }
        let Some(phase) = read.phase_rad else {
            self.set_aside.no_phase += 1;
            return;
        };
        let Some(f_hz) = read.channel_frequency_hz.filter(|&f| f > 0) else {
            self.set_aside.no_frequency += 1;
            return;
        };
        let reader = read.reader.as_deref().unwrap_or_default();
        let own = read.antenna_pose.as_ref().map(|p| (p.position, p.yaw_rad));
        let readers = &mut self.readers;
        let (id, pose) = match tracks.get(poses, reader, read.antenna, || intern(readers, reader)) {
            Some(met) => {
                let (track, cursor) = (&met.track, &mut met.cursor);
                let pose = own.or_else(|| track.as_ref()?.position_at(read.t_us, cursor));
                (met.id, pose)
            }
            None => {
                let pose = own.or_else(|| poses.position_at(reader, read.antenna, read.t_us));
                (intern(readers, reader), pose)
            }
        };
        let Some((position, yaw_rad)) = pose else {
            self.set_aside.no_pose += 1;
            return;
        };
        let found = self.by_tag.get(read.epc.as_str()).and_then(|of_tag| {
            let s = of_tag
                .iter()
                .find(|s| (s.port, s.f_hz, s.reader) == (read.antenna, f_hz, id))?;
            Some(s.index)
        });
        let key = || (read.epc.clone(), reader.to_string(), read.antenna, f_hz);
        let i = found.unwrap_or_else(|| self.add_series(key(), id));
        self.series[i].1.push(read.t_us, phase, position, yaw_rad);
        self.taken += 1;
    }

    /// A new series under `key` (its reader's id `reader`): where it is.
    fn add_series(&mut self, key: Key, reader: u32) -> usize {
        let i = self.series.len();
        let wavelength = SPEED_OF_LIGHT / key.3 as f64;
        let series = Series::new(wavelength, self.ambiguity, self.max_gap_us);
        self.tags.insert(key.0.clone());
        let of_tag = self.by_tag.entry(key.0.clone()).or_default();
        let at = of_tag.partition_point(|s| self.series[s.index].0 < key);
        let slot = Slot {
            index: i,
            reader,
            port: key.2,
            f_hz: key.3,
        };
        of_tag.insert(at, slot);
        self.series.push((key, series));
        i
    }

    /// Every series, in key order.
    pub fn series(&self) -> impl Iterator<Item = (&Key, &Series)> {
        self.tags().flat_map(|epc| self.tag_series(epc))
    }

    /// The series of tag `epc`, in key order.
    pub fn tag_series<'a>(&'a self, epc: &str) -> impl Iterator<Item = (&'a Key, &'a Series)> {
        let of_tag = self.by_tag.get(epc).map_or(&[][..], Vec::as_slice);
        of_tag.iter().map(|s| {
            let (key, series) = &self.series[s.index];
            (key, series)
        })
    }

    /// The tags with at least one series, in EPC order.
    pub fn tags(&self) -> impl Iterator<Item = &str> {
        self.tags.iter().map(Epc::as_str)
    }

    /// The pose tracks reads are joined with.
    pub fn poses(&self) -> &Poses {
        &self.poses
    }

    /// The pose tracks, to add samples as they arrive.
    pub fn poses_mut(&mut self) -> &mut Poses {
        &mut self.poses
    }

    /// Phases held for tag `epc`.
    pub fn tag_samples(&self, epc: &str) -> usize {
        self.tag_series(epc).map(|(_, s)| s.len()).sum()
    }

    /// Halves the phases held for tag `epc` ([`Series::thin`] on each of its series).
    pub fn thin_tag(&mut self, epc: &str) {
        for s in self.by_tag.get(epc).map_or(&[][..], Vec::as_slice) {
            self.series[s.index].1.thin();
        }
    }

    /// Keeps tag `epc` within `bound` phases once it is over: first the reads that add no
    /// aperture go (a parked antenna's: [`Series::thin_places`]); if that leaves more than
    /// three quarters of the bound, its segments read from one place (an antenna whose
    /// position, as its own estimate gives it, wandered but never left [`PARKED_SPAN_M`]) are
    /// dropped down to half the bound; then its series are thinned ([`Ingest::thin_tag`]),
    /// and if that still leaves more (segments of one or two phases, as of a series split at
    /// every channel visit, do not thin), its oldest segments are dropped down to half the
    /// bound ([`Ingest::trim_tag`]).
    pub fn bound_tag(&mut self, epc: &str, bound: usize) {
        if self.tag_samples(epc) <= bound {
            return;
        }
        for s in self.by_tag.get(epc).map_or(&[][..], Vec::as_slice) {
            self.series[s.index].1.thin_places();
        }
        if self.tag_samples(epc) <= bound / 4 * 3 {
            return;
        }
        self.drop_segments_of(epc, bound / 2, true);
        if self.tag_samples(epc) <= bound / 4 * 3 {
            return;
        }
        self.thin_tag(epc);
        if self.tag_samples(epc) > bound / 4 * 3 {
            self.trim_tag(epc, bound / 2);
        }
    }

    /// Drops tag `epc`'s segments, whichever series they are in, until it holds at most
    /// `target` phases: first those read from one place (an antenna that stayed within
    /// [`PARKED_SPAN_M`] through the segment, which adds no aperture), oldest first, then the
    /// oldest; a series' last segment (being extended) goes only in the second round. A series
    /// left with none is forgotten.
    pub fn trim_tag(&mut self, epc: &str, target: usize) {
        self.drop_segments_of(epc, target, false);
    }

    /// [`Ingest::trim_tag`], or with `parked_only` its first round alone.
    fn drop_segments_of(&mut self, epc: &str, target: usize, parked_only: bool) {
        let of_tag = self.by_tag.get(epc).map_or(&[][..], Vec::as_slice);
        // (adds aperture or is being extended, first read's time, phases, series, segment)
        let mut segments: Vec<(bool, u64, usize, usize, usize)> = of_tag
            .iter()
            .map(|s| s.index)
            .flat_map(|i| {
                let series = &self.series[i].1;
                let last = series.segments().len().saturating_sub(1);
                series.segments().enumerate().map(move |(k, seg)| {
                    let first = seg.first().map_or(0, |x| x.t_us);
                    (k == last || !parked(seg), first, seg.len(), i, k)
                })
            })
            .collect();
        let mut held: usize = segments.iter().map(|s| s.2).sum();
        segments.sort_unstable_by_key(|s| (s.0, s.1));
        let mut drops: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
        for (aperture, _, len, i, k) in segments {
            if held <= target || (parked_only && aperture) {
                break;
            }
            held -= len;
            drops.entry(i).or_default().push(k);
        }
        // From the last place down, so that a removal moves no series still to be trimmed.
        for (i, which) in drops.into_iter().rev() {
            let series = &mut self.series[i].1;
            series.drop_segments(&which);
            if series.is_empty() {
                self.remove_series(i);
            }
        }
    }

    /// Forgets the series at `i`; the last series takes its place.
    fn remove_series(&mut self, i: usize) {
        let (key, _) = self.series.swap_remove(i);
        if let Some(of_tag) = self.by_tag.get_mut(&key.0) {
            of_tag.retain(|s| s.index != i);
            if of_tag.is_empty() {
                self.by_tag.remove(&key.0);
                self.tags.remove(&key.0);
            }
        }
        let moved_from = self.series.len();
        let Some((moved, _)) = self.series.get(i) else {
            return; // it was the last
        };
        if let Some(of_tag) = self.by_tag.get_mut(&moved.0) {
            for s in of_tag.iter_mut().filter(|s| s.index == moved_from) {
                s.index = i;
            }
        }
    }

    /// Reads filed into a series.
    pub fn taken(&self) -> u64 {
        self.taken
    }

    /// Reads set aside, by reason.
    pub fn set_aside(&self) -> SetAside {
        self.set_aside
    }
}

/// A segment whose antenna stays this close (m) to where it began is read from one place when
/// a tag is trimmed ([`Ingest::trim_tag`]): a parked robot's own pose estimate wanders a few
/// centimetres (S1's stack: σ 15 mm over 2 s), while a pass at 0.3 m/s covers 12 cm in a
/// 400 ms channel visit.
pub const PARKED_SPAN_M: f64 = 0.05;

/// Whether every phase of `segment` was read within [`PARKED_SPAN_M`] of its first one's
/// antenna position.
fn parked(segment: &[Sample]) -> bool {
    let Some(first) = segment.first() else {
        return true;
    };
    segment.iter().all(|s| {
        let d = [0, 1, 2].map(|k| s.antenna[k] - first.antenna[k]);
        (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() <= PARKED_SPAN_M
    })
}

#[cfg(test)]
mod tests;
