//! Antenna poses as the localizer receives them: the pose file (JSON Lines or CSV with the keys
//! `t_us, reader, antenna, x, y, z, yaw_deg, pitch_deg`, the keys `sim --truth` writes), one
//! track per (reader, antenna), interpolated to a read's timestamp.
//!
//! A read takes the pose of its reader's antenna at its own time plus the reader's clock
//! offset (reader time − robot time, configurable per reader). Between two samples the position
//! is interpolated linearly and the yaw (in radians, as every angle past the file) along the
//! shorter way round; a read before the first
//! sample, after the last, or between two samples further apart than the reach has no pose
//! ([`Poses::at`] gives `None`): it is set aside and counted, never guessed.

use std::collections::BTreeMap;
use std::f64::consts::{PI, TAU};
use std::io::BufRead;

use rustc_hash::FxHashMap;

use crate::series::fold;

mod message;

pub use message::parse_poses;

pub use llrp_gateway_vocab::pose::{Pose, PoseSample};
use llrp_gateway_vocab::reader_name::ReaderName;
use llrp_gateway_vocab::table;

/// Why a pose file could not be read: the line and the reason, naming the field.
#[derive(Debug, thiserror::Error)]
pub enum PoseError {
    /// The file could not be read.
    #[error("{0}")]
    Io(#[from] std::io::Error),
    /// A line is not a valid pose.
    #[error("line {line}: {reason}")]
    Line {
        /// 1-based line number.
        line: usize,
        /// What is wrong, naming the field.
        reason: String,
    },
}

/// A pose file that could not be used: its path and why.
#[derive(Debug, thiserror::Error)]
#[error("{}: {}", .path.display(), .source)]
pub struct PoseFileError {
    /// The file.
    pub path: std::path::PathBuf,
    /// Why.
    pub source: PoseError,
}

/// The CSV header the pose file's CSV form must start with.
pub const CSV_HEADER: &str = "t_us,reader,antenna,x,y,z,yaw_deg,pitch_deg";

/// Every antenna's pose track, and the readers' clock offsets.
#[derive(Clone, Debug, Default)]
pub struct Poses {
    /// Per reader, per antenna, samples in time order (by reader first, so that a lookup
    /// takes the reader's name as it is, without a copy).
    tracks: FxHashMap<String, BTreeMap<u16, Vec<PoseSample>>>,
    /// Per reader, reader time − robot time (µs).
    offsets: FxHashMap<String, i64>,
    /// Longest gap between two samples a read may fall in (µs).
    reach_us: u64,
    /// Samples older than this behind their track's newest are dropped (µs); `None`: kept
    /// up to [`MAX_TRACK`].
    keep_us: Option<u64>,
}

/// Most samples kept per antenna track; beyond it the older half is dropped.
pub const MAX_TRACK: usize = 65_536;

/// Default reach: a read between two samples at most this far apart gets a pose (µs).
pub const DEFAULT_REACH_US: u64 = 500_000;

impl Poses {
    /// No poses yet, with the default reach.
    pub fn new() -> Poses {
        Poses {
            reach_us: DEFAULT_REACH_US,
            ..Poses::default()
        }
    }

    /// Sets the longest gap between samples a read may be interpolated in.
    pub fn with_reach(mut self, reach_us: u64) -> Poses {
        self.reach_us = reach_us;
        self
    }

    /// These poses keeping only the last `keep_us` of each track (`None`: up to
    /// [`MAX_TRACK`] samples).
    pub fn with_keep(mut self, keep_us: Option<u64>) -> Poses {
        self.keep_us = keep_us;
        self
    }

    /// Sets `reader`'s clock offset: reader time − robot time, µs.
    pub fn set_offset(&mut self, reader: &str, offset_us: i64) {
        self.offsets.insert(reader.to_string(), offset_us);
    }

    /// Adds a sample (kept in time order; a sample at a time already held replaces it).
    pub fn add(&mut self, p: PoseSample) {
        // The unnamed reader's track is under "", where its reads (naming none) look.
        let reader = p.reader.as_deref().unwrap_or_default();
        if !self.tracks.contains_key(reader) {
            self.tracks.insert(reader.to_owned(), BTreeMap::new());
        }
        // The reader's map is there: inserted just above where it was not.
        let track = self
            .tracks
            .get_mut(reader)
            .expect("the reader's map, inserted above")
            .entry(p.antenna)
            .or_default();
        match track.binary_search_by_key(&p.t_us, |s| s.t_us) {
            Ok(i) => track[i] = p,
            Err(i) => track.insert(i, p),
        }
        if track.len() > MAX_TRACK {
            track.drain(..MAX_TRACK / 2);
        }
        if let (Some(keep), Some(newest)) = (self.keep_us, track.last().map(|s| s.t_us)) {
            let old = track.partition_point(|s| s.t_us.saturating_add(keep) < newest);
            // In steps of a good many samples, not one at a time.
            if old >= 64 {
                track.drain(..old);
            }
        }
    }

    /// These poses with each sample replaced by `f` of it and its reader's clock offset
    /// (reader time − robot time, µs); `f` keeps its time.
    pub fn mapped(&self, f: impl Fn(&PoseSample, i64) -> PoseSample) -> Poses {
        let mut out = self.clone();
        for (reader, antennas) in out.tracks.iter_mut() {
            let offset = self.offset(reader);
            for s in antennas.values_mut().flatten() {
                *s = PoseSample {
                    t_us: s.t_us,
                    ..f(s, offset)
                };
            }
        }
        out
    }

    /// Every sample held, track by track.
    pub fn samples(&self) -> Vec<PoseSample> {
        self.all_tracks().flatten().cloned().collect()
    }

    /// The first sample of each track.
    pub fn first_samples(&self) -> Vec<&PoseSample> {
        self.all_tracks().filter_map(|t| t.first()).collect()
    }

    /// The earliest sample of any track.
    pub fn first(&self) -> Option<&PoseSample> {
        self.all_tracks()
            .filter_map(|t| t.first())
            .min_by_key(|p| p.t_us)
    }

    /// The samples of `reader`'s `antenna`, oldest first, each with its time in reader time
    /// (µs).
    pub fn track<'a>(
        &'a self,
        reader: &str,
        antenna: u16,
    ) -> impl Iterator<Item = (u64, &'a PoseSample)> + 'a {
        let offset = i128::from(self.offset(reader));
        self.track_of(reader, antenna)
            .into_iter()
            .flatten()
            .filter_map(move |p| Some((u64::try_from(i128::from(p.t_us) + offset).ok()?, p)))
    }

    /// Reader time (µs) of the newest sample of `reader`'s `antenna`, if any.
    pub fn newest(&self, reader: &str, antenna: u16) -> Option<u64> {
        let last = self.track_of(reader, antenna)?.last()?;
        let offset = self.offset(reader);
        u64::try_from(i128::from(last.t_us) + i128::from(offset)).ok()
    }

    /// Number of samples held.
    pub fn len(&self) -> usize {
        self.all_tracks().map(Vec::len).sum()
    }

    /// Whether no sample is held.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Reads the pose file at `path` (JSON Lines or CSV, as [`Poses::read`]).
    pub fn load(path: &std::path::Path) -> Result<Poses, PoseFileError> {
        let failed = |source| PoseFileError {
            path: path.to_owned(),
            source,
        };
        let file = std::fs::File::open(path).map_err(|e| failed(PoseError::Io(e)))?;
        Poses::read(std::io::BufReader::new(file)).map_err(failed)
    }

    /// Reads a pose file, JSON Lines or CSV (told apart by its first line that is not
    /// blank; CSV through [`llrp_gateway_vocab::table`]: quoted cells, a byte-order mark and
    /// CRLF line ends are read as a spreadsheet writes them).
    pub fn read(mut input: impl BufRead) -> Result<Poses, PoseError> {
        let mut first = String::new();
        let mut skipped = 0;
        while first.trim().is_empty() {
            first.clear();
            if input.read_line(&mut first)? == 0 {
                return Ok(Poses::new());
            }
            skipped += 1;
        }
        if table::is_json_lines(&first) {
            return Self::read_json_lines(skipped, &first, input);
        }
        // Blank lines before the header are kept, so the CSV reader's line numbers are the
        // file's.
        let head = "\n".repeat(skipped - 1) + &first;
        Self::read_csv(std::io::Read::chain(std::io::Cursor::new(head), input))
    }

    /// The JSON Lines form, whose first line that is not blank, `first`, is line `first_no`.
    fn read_json_lines(
        first_no: usize,
        first: &str,
        input: impl BufRead,
    ) -> Result<Poses, PoseError> {
        let mut poses = Poses::new();
        let first = table::strip_bom(first).to_string();
        let lines = std::iter::once(Ok(first)).chain(input.lines());
        for (i, line) in lines.enumerate() {
            let line = line?;
            let text = line.trim();
            if text.is_empty() {
                continue;
            }
            let sample = serde_json::from_str::<PoseSample>(text)
                .map_err(|e| e.to_string())
                .and_then(check)
                .map_err(|reason| PoseError::Line {
                    line: first_no + i,
                    reason,
                })?;
            poses.add(sample);
        }
        Ok(poses)
    }

    /// The CSV form: a header naming at least the columns of [`CSV_HEADER`], in any order.
    fn read_csv(input: impl std::io::Read) -> Result<Poses, PoseError> {
        let mut rows = table::CsvRows::new(input).map_err(csv_error)?;
        let columns = rows.header().to_vec();
        for key in CSV_HEADER.split(',') {
            if !columns.iter().any(|c| c == key) {
                return Err(PoseError::Line {
                    line: 1,
                    reason: format!("CSV header lacks the column {key:?}"),
                });
            }
        }
        let mut poses = Poses::new();
        for row in rows.by_ref() {
            let row = row.map_err(csv_error)?;
            let sample = csv_sample(&columns, &row.cells)
                .and_then(check)
                .map_err(|reason| PoseError::Line {
                    line: row.line as usize,
                    reason,
                })?;
            poses.add(sample);
        }
        Ok(poses)
    }

    /// The pose of `reader`'s `antenna` at reader time `t_us`: interpolated between the
    /// samples around it when they are at most the reach apart (or exactly at a sample);
    /// `None` otherwise.
    pub fn at(&self, reader: &str, antenna: u16, t_us: u64) -> Option<PoseSample> {
        let (t, before, after) = self.around(reader, antenna, t_us)?;
        let Some((after, f)) = after else {
            return Some(before.clone());
        };
        Some(PoseSample {
            t_us: t,
            reader: before.reader.clone(),
            antenna,
            pose: blend(&before.pose, &after.pose, f),
        })
    }

    /// The position (m) and yaw (rad) of [`Poses::at`], without making a sample.
    pub fn position_at(&self, reader: &str, antenna: u16, t_us: u64) -> Option<([f64; 3], f64)> {
        self.track_at(reader, antenna)?.position_at(t_us, &mut 0)
    }

    /// [`Track::around`] on `reader`'s `antenna`.
    #[allow(clippy::type_complexity)]
    fn around(
        &self,
        reader: &str,
        antenna: u16,
        t_us: u64,
    ) -> Option<(u64, &PoseSample, Option<(&PoseSample, f64)>)> {
        self.track_at(reader, antenna)?.around(t_us, &mut 0)
    }

    /// The track of `reader`'s `antenna` with its clock offset, to look many reads up in.
    pub fn track_at(&self, reader: &str, antenna: u16) -> Option<Track<'_>> {
        Some(Track {
            samples: self.track_of(reader, antenna)?,
            offset_us: self.offset(reader),
            reach_us: self.reach_us,
        })
    }

    /// `reader`'s clock offset (reader time − robot time, µs; 0 when not set).
    pub fn offset(&self, reader: &str) -> i64 {
        if self.offsets.is_empty() {
            return 0;
        }
        self.offsets.get(reader).copied().unwrap_or(0)
    }

    /// The samples of `reader`'s `antenna`.
    fn track_of(&self, reader: &str, antenna: u16) -> Option<&Vec<PoseSample>> {
        self.tracks.get(reader)?.get(&antenna)
    }

    /// Every track.
    fn all_tracks(&self) -> impl Iterator<Item = &Vec<PoseSample>> {
        self.tracks.values().flat_map(BTreeMap::values)
    }
}

/// One antenna's pose track with its reader's clock offset and the reach: the reads of one
/// antenna looked up in turn, each starting where the one before landed.
#[derive(Clone, Copy, Debug)]
pub struct Track<'a> {
    samples: &'a [PoseSample],
    offset_us: i64,
    reach_us: u64,
}

impl<'a> Track<'a> {
    /// [`Poses::position_at`] on this track; `cursor` is where the last lookup landed (0 at
    /// first), and is moved to where this one does.
    pub fn position_at(&self, t_us: u64, cursor: &mut usize) -> Option<([f64; 3], f64)> {
        let (_, before, after) = self.around(t_us, cursor)?;
        let Some((after, f)) = after else {
            return Some((before.pose.position, before.pose.yaw_rad));
        };
        let p = blend(&before.pose, &after.pose, f);
        Some((p.position, p.yaw_rad))
    }

    /// Robot time of reader time `t_us`, and the sample at it, or the samples around it with
    /// the fraction of the way from the first to the second (at most the reach apart);
    /// `cursor` as for [`Track::position_at`].
    #[allow(clippy::type_complexity)]
    fn around(
        &self,
        t_us: u64,
        cursor: &mut usize,
    ) -> Option<(u64, &'a PoseSample, Option<(&'a PoseSample, f64)>)> {
        let track = self.samples;
        let t = i128::from(t_us) - i128::from(self.offset_us);
        let t = u64::try_from(t).ok()?;
        let i = at_or_before(track, t, *cursor);
        *cursor = i;
        let before = track.get(i.checked_sub(1)?)?;
        if before.t_us == t {
            return Some((t, before, None));
        }
        let after = track.get(i)?;
        if after.t_us - before.t_us > self.reach_us {
            return None;
        }
        let f = (t - before.t_us) as f64 / (after.t_us - before.t_us) as f64;
        Some((t, before, Some((after, f))))
    }
}

/// How many of `track`'s samples (in time order) are at or before `t`: first `hint` (the
/// count for a time a little before: the same, or one more), then where the track's mean
/// interval puts `t` (right, or next to it, on a track sampled at a steady rate), else by
/// binary search.
fn at_or_before(track: &[PoseSample], t: u64, hint: usize) -> usize {
    // Exactly i + 1 samples are at or before t (the times in order).
    let fits = |i: usize| {
        i < track.len() && track[i].t_us <= t && track.get(i + 1).is_none_or(|s| s.t_us > t)
    };
    if let Some(i) = [hint.checked_sub(1), Some(hint)]
        .into_iter()
        .flatten()
        .find(|&i| fits(i))
    {
        return i + 1;
    }
    let (Some(first), Some(last)) = (track.first(), track.last()) else {
        return 0;
    };
    if t < first.t_us {
        return 0;
    }
    if t >= last.t_us {
        return track.len();
    }
    // first ≤ t < last, so the span is positive and the guess under len − 1 (a float's
    // rounding is caught by the checks below).
    let f = (t - first.t_us) as f64 / (last.t_us - first.t_us) as f64;
    let guess = (f * (track.len() - 1) as f64) as usize;
    let fits = |i: usize| track[i].t_us <= t && track[i + 1].t_us > t;
    for i in [Some(guess), guess.checked_sub(1), Some(guess + 1)]
        .into_iter()
        .flatten()
    {
        if i < track.len() - 1 && fits(i) {
            return i + 1;
        }
    }
    track.partition_point(|s| s.t_us <= t)
}

/// The pose a fraction `f` of the way from `a` to `b`: the position and pitch linearly, the
/// yaw turned the short way round, in [−π, π).
fn blend(a: &Pose, b: &Pose, f: f64) -> Pose {
    let lerp = |u: f64, v: f64| u + (v - u) * f;
    // Onto [0, 2π) without a libm fmod where it is within a turn of it (`series::fold`).
    let turn = fold(b.yaw_rad - a.yaw_rad + PI, TAU) - PI;
    let yaw_rad = fold(a.yaw_rad + turn * f + PI, TAU) - PI;
    let [p, q] = [a.position, b.position];
    Pose {
        position: [lerp(p[0], q[0]), lerp(p[1], q[1]), lerp(p[2], q[2])],
        yaw_rad,
        pitch_rad: lerp(a.pitch_rad, b.pitch_rad),
    }
}

/// A CSV file's error as a pose file's.
fn csv_error(e: table::CsvError) -> PoseError {
    match e {
        table::CsvError::Io(e) => PoseError::Io(e),
        table::CsvError::Syntax { line, reason } => PoseError::Line {
            line: line as usize,
            reason,
        },
    }
}

/// A CSV row's cells under `columns` as a sample.
fn csv_sample(columns: &[String], cells: &[String]) -> Result<PoseSample, String> {
    if cells.len() != columns.len() {
        return Err(format!(
            "has {} fields, the header {}",
            cells.len(),
            columns.len()
        ));
    }
    let cell = |key: &str| -> &str {
        columns
            .iter()
            .position(|c| c == key)
            .and_then(|i| cells.get(i))
            .map_or("", String::as_str)
    };
    let number = |key: &str| -> Result<f64, String> {
        let v = cell(key);
        v.parse::<f64>()
            .map_err(|_| format!("{key}: not a number: {v:?}"))
    };
    Ok(PoseSample {
        t_us: cell("t_us")
            .parse()
            .map_err(|_| format!("t_us: not a whole number of µs: {:?}", cell("t_us")))?,
        reader: match cell("reader") {
            "" => None,
            name => Some(ReaderName::parse(name).map_err(|e| format!("reader: {e}"))?),
        },
        antenna: cell("antenna")
            .parse()
            .map_err(|_| format!("antenna: not a port number: {:?}", cell("antenna")))?,
        pose: Pose::from_degrees(
            [number("x")?, number("y")?, number("z")?],
            number("yaw_deg")?,
            number("pitch_deg")?,
        ),
    })
}

/// A sample whose numbers are all finite and whose antenna is a port.
fn check(p: PoseSample) -> Result<PoseSample, String> {
    validate(&p)?;
    Ok(p)
}

/// Whether `p`'s numbers are all finite and its antenna is a port (the reason, naming the
/// field, when not).
pub fn validate(p: &PoseSample) -> Result<(), String> {
    p.pose.check_finite()?;
    if p.antenna == 0 {
        return Err("antenna: must be a port number from 1".into());
    }
    Ok(())
}

#[cfg(test)]
mod tests;
