//! Fingerprinting with reference tags (\[A\] §III-B, after LANDMARC): for a target tag j and a
//! reference tag l at a known position, D = √(Σ_i (X_i^j − R_i^l)² / N) over the N antenna
//! poses i where both were read; the target is placed at the normalised weighted mean of the
//! k references with the least D, and pairs with few common poses are dropped. It needs no
//! antenna poses beyond telling poses apart, and no path shape.
//!
//! Ours, where \[A\] is silent: X and R are unwrapped phases (the series carry no RSSI);
//! an unwrapped phase is known only up to a constant per segment, so the mean difference is
//! removed per pair of segments (D is the spread of the differences); a "pose" is a 2 cm cell
//! of antenna position on one track (reader, antenna, channel), its value the mean phase read
//! in it; k = 4 and weights 1/D² (LANDMARC's); a pair needs 20 common cells. The covariance is
//! the error the method makes here, measured on the references located from each other
//! ([`leave_one_out`]): the second moment of truth − estimate of the references whose estimates
//! lie nearest this one, widened for the few draws it rests on, at least the spread of the k
//! references about the estimate (docs/localize.md "Fingerprinting, 3D").

use std::collections::BTreeMap;

use crate::calibrate::Calibration;
use crate::estimator::{Locate, Need, Tag, Takes};
use crate::fix::Fix3;
use crate::fix::NoFix;
use crate::geometry::Geometry;
use crate::ingest::Ingest;

mod covariance;
#[cfg(test)]
mod tests;

/// A reference tag located from the others: (its position, the estimate).
pub type Located = ([f64; 3], [f64; 3]);

/// References the estimate is the weighted mean of (LANDMARC's k).
pub const K: usize = 4;
/// Edge of the cells antenna positions are grouped in (m, ours).
pub const CELL_M: f64 = 0.02;
/// Fewest common cells for a target–reference pair to count (ours).
pub const MIN_COMMON: usize = 20;

/// One unwrapped phase of a tag and where it was read from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reading {
    /// Which (reader, antenna, channel) read it; numbered by the caller, the same for every
    /// tag.
    pub track: usize,
    /// Segment of its series (its own phase offset).
    pub segment: usize,
    /// Antenna position (m).
    pub antenna: [f64; 3],
    /// Unwrapped phase (rad).
    pub value: f64,
}

type Cell = (usize, i64, i64, i64);

/// Mean value per cell, with the segment of the first reading in it.
fn cells(readings: &[Reading]) -> Cells {
    let mut out: BTreeMap<Cell, (usize, f64, usize)> = BTreeMap::new();
    for r in readings {
        let [x, y, z] = r.antenna.map(|c| (c / CELL_M).floor() as i64);
        let e = out.entry((r.track, x, y, z)).or_insert((r.segment, 0.0, 0));
        if e.0 == r.segment {
            e.1 += r.value;
            e.2 += 1;
        }
    }
    out
}

/// D between two tags' cells, when they share at least [`MIN_COMMON`] cells.
fn resemblance(target: &Cells, reference: &Cells) -> Option<f64> {
    // Differences grouped by (track, target segment, reference segment).
    let mut groups: BTreeMap<(usize, usize, usize), Vec<f64>> = BTreeMap::new();
    for (cell, &(ts, tv, tn)) in target {
        if let Some(&(rs, rv, rn)) = reference.get(cell) {
            groups
                .entry((cell.0, ts, rs))
                .or_default()
                .push(tv / tn as f64 - rv / rn as f64);
        }
    }
    let n: usize = groups.values().map(Vec::len).sum();
    if n < MIN_COMMON {
        return None;
    }
    let sq: f64 = groups
        .values()
        .map(|d| {
            let mean = d.iter().sum::<f64>() / d.len() as f64;
            d.iter().map(|x| (x - mean).powi(2)).sum::<f64>()
        })
        .sum();
    let d = (sq / n as f64).sqrt();
    d.is_finite().then_some(d)
}

/// The cells of a tag's readings ([`cells`]).
type Cells = BTreeMap<Cell, (usize, f64, usize)>;

/// The weighted mean of the [`K`] references of `references` (position, cells) most like
/// `target`, other than the one at index `skip`, with the spread of the k about it and the
/// best D.
fn nearest(
    target: &Cells,
    references: &[([f64; 3], Cells)],
    skip: Option<usize>,
) -> Result<([f64; 3], [f64; 9], f64), NoFix> {
    let mut scored: Vec<(f64, [f64; 3])> = references
        .iter()
        .enumerate()
        .filter(|(l, _)| Some(*l) != skip)
        .filter_map(|(_, (p, r))| resemblance(target, r).map(|d| (d, *p)))
        .collect();
    if scored.len() < K {
        return Err(NoFix::InsufficientGeometry);
    }
    scored.sort_by(|a, b| a.0.total_cmp(&b.0));
    scored.truncate(K);
    // Weights 1/D², bounded so that a perfect match (D = 0) stays finite.
    let w: Vec<f64> = scored
        .iter()
        .map(|(d, _)| 1.0 / (d * d).max(1e-24))
        .collect();
    let total: f64 = w.iter().sum();
    let position: [f64; 3] = std::array::from_fn(|k| {
        scored
            .iter()
            .zip(&w)
            .map(|((_, p), w)| w * p[k])
            .sum::<f64>()
            / total
    });
    let mut spread = [0.0; 9];
    for (_, p) in &scored {
        for (i, c) in spread.iter_mut().enumerate() {
            *c += (p[i / 3] - position[i / 3]) * (p[i % 3] - position[i % 3]) / K as f64;
        }
    }
    if !(position.iter().chain(&spread).all(|v| v.is_finite())) {
        return Err(NoFix::InsufficientGeometry);
    }
    Ok((position, spread, scored[0].0))
}

/// Each of `references` (position, readings) located from the others, where it can be, in
/// their order.
pub fn leave_one_out(references: &[([f64; 3], Vec<Reading>)]) -> Vec<Option<[f64; 3]>> {
    let cells: Vec<([f64; 3], Cells)> = references.iter().map(|(p, r)| (*p, cells(r))).collect();
    (0..cells.len())
        .map(|l| nearest(&cells[l].1, &cells, Some(l)).ok().map(|n| n.0))
        .collect()
}

/// The target's position from its readings and the references' (position, readings), its
/// covariance from `located`, the references located from each other ([`leave_one_out`];
/// measured here when empty).
pub fn locate(
    target: &[Reading],
    references: &[([f64; 3], Vec<Reading>)],
    located: &[Located],
) -> Result<Fix3, NoFix> {
    let cells_of: Vec<([f64; 3], Cells)> = references.iter().map(|(p, r)| (*p, cells(r))).collect();
    let (position, spread, best) = nearest(&cells(target), &cells_of, None)?;
    let measured: Vec<Located>;
    let located = if located.is_empty() {
        measured = references
            .iter()
            .zip(leave_one_out(references))
            .filter_map(|((p, _), e)| Some((*p, e?)))
            .collect();
        &measured
    } else {
        located
    };
    let covariance = covariance::covariance(position, spread, located);
    if !covariance.iter().all(|v| v.is_finite()) {
        return Err(NoFix::InsufficientGeometry);
    }
    Ok(Fix3 {
        position,
        covariance,
        rms_rad: best,
    })
}

/// Fingerprinting as the localizer runs it: the tag against the reference tags of the
/// geometry (other than itself), each series a track; 3D, its height the references' (not
/// fitted to the phases: [`Locate::fits_height`] is false), its covariance from the references
/// located from each other ([`Locate::calibration`]).
#[derive(Clone, Copy, Debug)]
pub struct Fingerprint;

impl Locate for Fingerprint {
    fn name(&self) -> &'static str {
        "fingerprint"
    }

    fn takes(&self) -> Takes {
        Takes::References
    }

    fn needs(&self) -> &'static [Need] {
        &[Need::References]
    }

    fn calibration(&self, ingest: &Ingest, g: &Geometry) -> Calibration {
        let mut tracks = BTreeMap::new();
        let (mut epcs, mut references) = (Vec::new(), Vec::new());
        for (r, p) in &g.references {
            if let Some(epc) = ingest.tags().find(|t| *t == r.as_str()) {
                epcs.push(epc.to_string());
                references.push((*p, readings(ingest, epc, &mut tracks)));
            }
        }
        let located = epcs
            .into_iter()
            .zip(&references)
            .zip(leave_one_out(&references))
            .filter_map(|((epc, (p, _)), e)| Some((epc, *p, e?)))
            .collect();
        Calibration::from_located(located)
    }

    fn locate(&self, tag: &Tag<'_>) -> Result<Fix3, NoFix> {
        let (ingest, epc, g) = (tag.ingest, tag.epc, tag.geometry);
        let mut tracks = BTreeMap::new();
        let target = readings(ingest, epc, &mut tracks);
        let references: Vec<([f64; 3], Vec<Reading>)> = g
            .references
            .iter()
            .filter(|(r, _)| r.as_str() != epc)
            .filter_map(|(r, p)| {
                let seen = ingest.tags().find(|t| *t == r.as_str())?;
                Some((*p, readings(ingest, seen, &mut tracks)))
            })
            .collect();
        // The references located from the others, the tag itself left out when it is one.
        let located: Vec<Located> = tag
            .calibration
            .located()
            .iter()
            .filter(|(r, _, _)| r.as_str() != epc)
            .map(|(_, p, e)| (*p, *e))
            .collect();
        locate(&target, &references, &located)
    }
}

/// Tag `epc`'s readings for fingerprinting, each series a track numbered in `tracks`.
fn readings(
    ingest: &Ingest,
    epc: &str,
    tracks: &mut BTreeMap<(String, u16, u64), usize>,
) -> Vec<Reading> {
    let mut out = Vec::new();
    for (key, series) in ingest.tag_series(epc) {
        let next = tracks.len();
        let track = *tracks.entry((key.1.clone(), key.2, key.3)).or_insert(next);
        for (segment, seg) in series.segments().enumerate() {
            out.extend(seg.iter().map(|s| Reading {
                track,
                segment,
                antenna: s.antenna,
                value: s.phase_rad,
            }));
        }
    }
    out
}
