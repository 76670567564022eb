//! Reads into phase series: each read of the reads file (or the gateway's [`Read`]) joined with
//! its antenna's pose and filed under its (reader, antenna, tag, channel) series.
//!
//! A read's pose is its own `antenna_pose` when the source gave one, else the pose file's at
//! its time ([`Poses::at`]). Reads without a phase, a channel frequency or a pose are set aside
//! and counted by reason, never guessed.

use std::collections::{BTreeMap, BTreeSet};

use rustc_hash::FxHashMap;

use super::poses::{Poses, Track};
use super::series::{Ambiguity, Series};
use super::SPEED_OF_LIGHT;
use crate::reads::Read;

/// The series key: EPC (hex as the reads give it), reader, antenna port, channel frequency
/// (Hz). The EPC comes first so that one tag's series are next to each other.
pub type Key = (String, String, u16, u64);

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

/// The pose tracks one batch of reads has looked up (reader, antenna, its track if there is
/// one, and where its last lookup landed): a handful of antennas, scanned.
#[allow(clippy::type_complexity)]
struct Tracks<'r, 'p>(Vec<(&'r str, u16, Option<Track<'p>>, usize)>);

impl<'r, 'p> Tracks<'r, 'p> {
    /// Most antennas remembered; beyond it a track is looked up each time.
    const MAX: usize = 64;

    /// [`Poses::position_at`] through the remembered track of `reader`'s `antenna`.
    fn position_at(
        &mut self,
        poses: &'p Poses,
        reader: &'r str,
        antenna: u16,
        t_us: u64,
    ) -> Option<([f64; 3], f64)> {
        let known = self.0.iter().position(|e| e.1 == antenna && e.0 == reader);
        let i = match known {
            Some(i) => i,
            None if self.0.len() < Self::MAX => {
                self.0
                    .push((reader, antenna, poses.track_at(reader, antenna), 0));
                self.0.len() - 1
            }
            None => return poses.position_at(reader, antenna, t_us),
        };
        let (_, _, track, cursor) = &mut self.0[i];
        track.as_ref()?.position_at(t_us, cursor)
    }
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
    by_tag: FxHashMap<String, Vec<usize>>,
    /// The tags with series, in EPC order.
    tags: BTreeSet<String>,
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
        self.extend(std::slice::from_ref(read));
    }

    /// Takes `reads` in order, as [`Ingest::push`] does each: each antenna's pose track is
    /// found once and its reads looked up from where the last one landed, and the EPC and
    /// reader name of reads a few ahead are fetched into the cache while the one before them
    /// is filed (reads in memory hold them on the heap, one allocation each, which would
    /// otherwise be waited for read by read).
    pub fn extend(&mut self, reads: &[Read]) {
        const AHEAD: usize = 8;
        // Taken out for the batch, so that the series can be filed while its tracks are
        // borrowed; put back below.
        let poses = std::mem::take(&mut self.poses);
        let mut tracks = Tracks(Vec::new());
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
        let pose = match &read.antenna_pose {
            Some(p) => Some(([p.x, p.y, p.z], p.yaw_deg)),
            None => tracks.position_at(poses, reader, read.antenna, read.t_us),
        };
        let Some((position, yaw_deg)) = pose else {
            self.set_aside.no_pose += 1;
            return;
        };
        let found = self.by_tag.get(read.epc.as_str()).and_then(|of_tag| {
            of_tag.iter().copied().find(|&i| {
                let k = &self.series[i].0;
                (k.2, k.3) == (read.antenna, f_hz) && k.1 == reader
            })
        });
        let key = || (read.epc.clone(), reader.to_string(), read.antenna, f_hz);
        let i = found.unwrap_or_else(|| self.add_series(key()));
        self.series[i]
            .1
            .push(read.t_us, phase, position, yaw_deg.to_radians());
        self.taken += 1;
    }

    /// A new series under `key`: where it is.
    fn add_series(&mut self, key: Key) -> usize {
        let i = self.series.len();
        let wavelength = SPEED_OF_LIGHT / key.3 as f64;
        let series = Series::new(wavelength, self.ambiguity, self.max_gap_us);
        self.tags.insert(key.0.clone());
        let of_tag = self.by_tag.entry(key.0.clone()).or_default();
        let at = of_tag.partition_point(|&j| self.series[j].0 < key);
        of_tag.insert(at, i);
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
        of_tag.iter().map(|&i| {
            let (key, series) = &self.series[i];
            (key, series)
        })
    }

    /// The tags with at least one series, in EPC order.
    pub fn tags(&self) -> impl Iterator<Item = &str> {
        self.tags.iter().map(String::as_str)
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
        for &i in self.by_tag.get(epc).map_or(&[][..], Vec::as_slice) {
            self.series[i].1.thin();
        }
    }

    /// Keeps tag `epc` within `bound` phases once it is over: its series thinned
    /// ([`Ingest::thin_tag`]), and if that leaves more than three quarters of the bound
    /// (segments of one or two phases, as of a series split at every channel visit, do not
    /// thin), its oldest segments dropped down to half the bound ([`Ingest::trim_tag`]).
    pub fn bound_tag(&mut self, epc: &str, bound: usize) {
        if self.tag_samples(epc) <= bound {
            return;
        }
        self.thin_tag(epc);
        if self.tag_samples(epc) > bound / 4 * 3 {
            self.trim_tag(epc, bound / 2);
        }
    }

    /// Drops tag `epc`'s oldest segments, whichever series they are in, until it holds at
    /// most `target` phases; a series left with none is forgotten.
    pub fn trim_tag(&mut self, epc: &str, target: usize) {
        let of_tag = self.by_tag.get(epc).map_or(&[][..], Vec::as_slice);
        let mut starts: Vec<(u64, usize, usize)> = of_tag
            .iter()
            .flat_map(|&i| {
                self.series[i]
                    .1
                    .segments()
                    .map(move |seg| (seg.first().map_or(0, |x| x.t_us), seg.len(), i))
            })
            .collect();
        let mut held: usize = starts.iter().map(|s| s.1).sum();
        starts.sort_unstable_by_key(|s| s.0);
        let mut drops: BTreeMap<usize, usize> = BTreeMap::new();
        for (_, len, i) in starts {
            if held <= target {
                break;
            }
            held -= len;
            *drops.entry(i).or_default() += 1;
        }
        // From the last place down, so that a removal moves no series still to be trimmed.
        for (i, n) in drops.into_iter().rev() {
            let series = &mut self.series[i].1;
            series.drop_oldest(n);
            if series.is_empty() {
                self.remove_series(i);
            }
        }
    }

    /// Forgets the series at `i`; the last series takes its place.
    fn remove_series(&mut self, i: usize) {
        let (key, _) = self.series.swap_remove(i);
        if let Some(of_tag) = self.by_tag.get_mut(&key.0) {
            of_tag.retain(|&j| j != i);
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
            for j in of_tag.iter_mut().filter(|j| **j == moved_from) {
                *j = i;
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::localize::poses::PoseSample;
    use crate::localize::series::Sample;
    use crate::reads::AntennaPose;

    fn read(epc: &str, t_us: u64, phase: Option<f64>, f: Option<u64>) -> Read {
        Read {
            epc: epc.into(),
            reader: Some("r".into()),
            antenna: 1,
            t_us,
            phase_rad: phase,
            rssi_dbm: Some(-50.0),
            channel_index: Some(1),
            channel_frequency_hz: f,
            doppler_hz: None,
            antenna_pose: None,
            last_seen_us: None,
        }
    }

    #[test]
    fn reads_are_filed_by_series_or_set_aside_by_reason() {
        let mut poses = Poses::new();
        for (t, x) in [(0, 0.0), (100_000, 0.01), (200_000, 0.02)] {
            poses.add(PoseSample {
                t_us: t,
                reader: "r".into(),
                antenna: 1,
                x,
                y: 1.0,
                z: 0.5,
                yaw_deg: x * 1000.0,
                pitch_deg: 0.0,
            });
        }
        let mut ingest = Ingest::new(poses, Ambiguity::None, 1_000_000);
        ingest.push(&read("A1", 50_000, Some(1.0), Some(915_250_000)));
        ingest.push(&read("A1", 150_000, Some(1.1), Some(915_250_000)));
        ingest.push(&read("A1", 160_000, Some(2.0), Some(902_750_000)));
        ingest.push(&read("B2", 60_000, Some(0.3), Some(915_250_000)));
        ingest.push(&read("B2", 70_000, None, Some(915_250_000)));
        ingest.push(&read("B2", 80_000, Some(0.3), None));
        ingest.push(&read("B2", 900_000, Some(0.3), Some(915_250_000)));
        // A read carrying its own pose needs no pose file.
        let mut own = read("C3", 5_000_000, Some(0.5), Some(915_250_000));
        own.antenna_pose = Some(AntennaPose {
            x: 3.0,
            y: 0.0,
            z: 1.0,
            yaw_deg: 0.0,
            pitch_deg: 0.0,
        });
        ingest.push(&own);
        assert_eq!(ingest.taken(), 5);
        assert_eq!(
            ingest.set_aside(),
            SetAside {
                no_phase: 1,
                no_frequency: 1,
                no_pose: 1,
                weak: 0
            }
        );
        // A1 on two channels: two series; B2 and C3 one each.
        assert_eq!(ingest.series().count(), 4);
        let key = ("A1".to_string(), "r".to_string(), 1, 915_250_000);
        let (_, a1) = ingest
            .series()
            .find(|(k, _)| **k == key)
            .expect("A1's series");
        let seg = a1.segments().next().expect("a segment");
        assert_eq!(seg.len(), 2);
        // The antenna position interpolated at each read: x = 0.005 and 0.015.
        assert!((seg[0].antenna[0] - 0.005).abs() < 1e-12);
        assert!((seg[1].antenna[0] - 0.015).abs() < 1e-12);
        // With its yaw, interpolated too (5° and 15°), and the phase as reported.
        assert!((seg[0].yaw_rad - 5f64.to_radians()).abs() < 1e-12);
        assert!((seg[1].yaw_rad - 15f64.to_radians()).abs() < 1e-12);
        assert_eq!((seg[0].raw_phase_rad, seg[1].raw_phase_rad), (1.0, 1.1));
    }

    #[test]
    fn reads_under_the_rssi_floor_are_set_aside_and_counted() {
        let mut ingest =
            Ingest::new(Poses::new(), Ambiguity::None, 1_000_000).with_min_rssi(Some(-65.0));
        let with = |t_us: u64, rssi: Option<f64>| Read {
            rssi_dbm: rssi,
            ..posed("A1", t_us, 0.001 * t_us as f64 / 1000.0, 915_250_000)
        };
        for (t, rssi) in [
            (0, Some(-50.0)),
            (1_000, Some(-65.0)),
            (2_000, Some(-65.01)),
            (3_000, Some(-80.0)),
            (4_000, None),
        ] {
            ingest.push(&with(t, rssi));
        }
        // At the floor and above, and without RSSI: filed; under it: set aside.
        assert_eq!(ingest.taken(), 3);
        assert_eq!(ingest.set_aside().weak, 2);
        assert_eq!(ingest.set_aside().total(), 2);
        let (_, series) = ingest.series().next().expect("A1's series");
        let times: Vec<u64> = series.samples().iter().map(|s| s.t_us).collect();
        assert_eq!(times, [0, 1_000, 4_000]);
        // No floor: every read filed.
        let mut all = Ingest::new(Poses::new(), Ambiguity::None, 1_000_000);
        for t in [2_000, 3_000] {
            all.push(&with(t, Some(-80.0)));
        }
        assert_eq!((all.taken(), all.set_aside().weak), (2, 0));
    }

    #[test]
    fn extending_by_a_slice_files_as_pushing_each_read() {
        // Two tags on two channels, interleaved, with a late read among them.
        let mut reads: Vec<Read> = (0..40u64)
            .map(|k| {
                let (epc, f) = if k % 3 == 0 {
                    ("A1", 915_250_000)
                } else {
                    ("B2", 902_750_000)
                };
                posed(epc, k * 10_000, 0.004 * k as f64, f)
            })
            .collect();
        reads.swap(20, 22);
        let mut one_by_one = Ingest::new(Poses::new(), Ambiguity::None, 1_000_000);
        for r in &reads {
            one_by_one.push(r);
        }
        let mut extended = Ingest::new(Poses::new(), Ambiguity::None, 1_000_000);
        extended.extend(&reads);
        assert_eq!(extended.taken(), 40);
        let series = |i: &Ingest| -> Vec<(Key, Vec<Sample>)> {
            i.series()
                .map(|(k, s)| (k.clone(), s.samples().to_vec()))
                .collect()
        };
        assert_eq!(series(&extended), series(&one_by_one));
        assert_eq!(series(&extended).len(), 2);
    }

    /// A read of phase 0.5 rad carrying its own pose: the antenna at `x` on the x axis.
    fn posed(epc: &str, t_us: u64, x: f64, f_hz: u64) -> Read {
        let mut r = read(epc, t_us, Some(0.5), Some(f_hz));
        r.antenna_pose = Some(AntennaPose {
            x,
            y: 1.0,
            z: 0.5,
            yaw_deg: 0.0,
            pitch_deg: 0.0,
        });
        r
    }

    #[test]
    fn a_tag_of_two_phase_segments_stays_within_its_bound_and_keeps_its_newest_reads() {
        let mut ingest = Ingest::new(Poses::new(), Ambiguity::None, 1_000);
        let bound = 4096;
        // Pairs of reads on 50 channels in turn, a gap longer than the series allows
        // between visits: every segment holds two phases, which thinning cannot halve.
        let mut most = 0;
        for k in 0..20_000u64 {
            let f = 902_750_000 + (k / 2 % 50) * 500_000;
            let r = posed("A1", k * 10_000, 0.0, f);
            ingest.push(&r);
            ingest.bound_tag("A1", bound);
            most = most.max(ingest.tag_samples("A1"));
        }
        assert!(most <= bound, "held {most}");
        assert!(ingest.tag_samples("A1") >= bound / 2);
        let newest = ingest
            .tag_series("A1")
            .filter_map(|(_, s)| s.segments().last()?.last().map(|x| x.t_us))
            .max();
        assert_eq!(newest, Some(19_999 * 10_000));
    }

    #[test]
    fn a_trimmed_tags_emptied_series_is_forgotten_and_the_others_still_found() {
        let mut ingest = Ingest::new(Poses::new(), Ambiguity::None, 1_000);
        let (f1, f2) = (902_750_000, 903_250_000);
        // A1's series on f1 first (oldest), then B2's on f1 and f2, then A1's on f2.
        ingest.push(&posed("A1", 0, 0.0, f1));
        ingest.push(&posed("B2", 10, 0.0, f1));
        ingest.push(&posed("B2", 20, 0.0, f2));
        for k in 0..4 {
            ingest.push(&posed("A1", 100_000 + k * 10, 0.0, f2));
        }
        // Down to 4 phases: A1's oldest segment, all of its f1 series, goes.
        ingest.trim_tag("A1", 4);
        fn channels(ingest: &Ingest, epc: &str) -> Vec<(u64, usize)> {
            let of_tag = ingest.tag_series(epc);
            of_tag.map(|(k, s)| (k.3, s.len())).collect()
        }
        assert_eq!(channels(&ingest, "A1"), vec![(f2, 4)]);
        assert_eq!(channels(&ingest, "B2"), vec![(f1, 1), (f2, 1)]);
        // A read of the series moved into the forgotten one's place goes to it.
        ingest.push(&posed("B2", 30, 0.0, f2));
        ingest.push(&posed("A1", 100_100, 0.0, f1));
        assert_eq!(channels(&ingest, "B2"), vec![(f1, 1), (f2, 2)]);
        assert_eq!(channels(&ingest, "A1"), vec![(f1, 1), (f2, 4)]);
        assert_eq!(ingest.tags().collect::<Vec<_>>(), vec!["A1", "B2"]);
        assert_eq!(ingest.series().count(), 4);
    }

    #[test]
    fn a_tag_of_long_segments_is_thinned_and_keeps_its_oldest_read() {
        let mut ingest = Ingest::new(Poses::new(), Ambiguity::None, 1_000_000);
        // One pass, a read every 10 ms moving 1 mm: a single segment.
        for k in 0..20_000u64 {
            ingest.push(&posed("B2", k * 10_000, k as f64 * 0.001, 915_250_000));
            ingest.bound_tag("B2", 4096);
        }
        let (_, s) = ingest.tag_series("B2").next().expect("a series");
        assert_eq!(s.segments().len(), 1);
        assert!(s.len() <= 4096);
        assert_eq!(s.samples()[0].t_us, 0, "the aperture stays");
    }
}
