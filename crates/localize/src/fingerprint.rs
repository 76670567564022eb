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
//! the spread of the k references about the estimate: a measure of the reference spacing, not
//! a statistical covariance.

use std::collections::BTreeMap;

use crate::estimator::{Locate, Need, Tag, Takes};
use crate::fix::Fix3;
use crate::fix::NoFix;
use crate::ingest::Ingest;

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
fn cells(readings: &[Reading]) -> BTreeMap<Cell, (usize, f64, usize)> {
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
fn resemblance(
    target: &BTreeMap<Cell, (usize, f64, usize)>,
    reference: &BTreeMap<Cell, (usize, f64, usize)>,
) -> Option<f64> {
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

/// The target's position from its readings and the references' (position, readings).
pub fn locate(target: &[Reading], references: &[([f64; 3], Vec<Reading>)]) -> Result<Fix3, NoFix> {
    let t = cells(target);
    let mut scored: Vec<(f64, [f64; 3])> = references
        .iter()
        .filter_map(|(p, r)| resemblance(&t, &cells(r)).map(|d| (d, *p)))
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
    let mut covariance = [0.0; 9];
    for (_, p) in &scored {
        for (i, c) in covariance.iter_mut().enumerate() {
            *c += (p[i / 3] - position[i / 3]) * (p[i % 3] - position[i % 3]) / K as f64;
        }
    }
    if !(position.iter().chain(&covariance).all(|v| v.is_finite())) {
        return Err(NoFix::InsufficientGeometry);
    }
    Ok(Fix3 {
        position,
        covariance,
        rms_rad: scored[0].0,
    })
}

/// Fingerprinting as the localizer runs it: the tag against the reference tags of the
/// geometry (other than itself), each series a track; 3D, its height the references' (not
/// fitted to the phases: [`Locate::fits_height`] is false).
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
        locate(&target, &references)
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

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    const LAMBDA: f64 = 0.3463;

    /// Readings of a tag at `tag` from antennas at `heights` (one track each) passing along
    /// y = 0, x from −0.995 m to 2.995 m in 1 cm steps (symmetric about x = 1); phase offset
    /// `offset`.
    fn reads(
        tag: [f64; 3],
        heights: &[f64],
        offset: f64,
        rng: &mut impl rand::Rng,
    ) -> Vec<Reading> {
        let noise = Normal::new(0.0, 0.1).expect("valid σ");
        let noisy = offset.is_nan();
        let mut out = Vec::new();
        for (track, &az) in heights.iter().enumerate() {
            for k in 0..400 {
                let a = [-0.995 + 0.01 * f64::from(k), 0.0, az];
                let d = (0..3).map(|j| (tag[j] - a[j]).powi(2)).sum::<f64>().sqrt();
                let (c, e) = if noisy {
                    (0.4, noise.sample(rng))
                } else {
                    (offset, 0.0)
                };
                out.push(Reading {
                    track,
                    segment: 0,
                    antenna: a,
                    value: c + 4.0 * std::f64::consts::PI * d / LAMBDA + e,
                });
            }
        }
        out
    }

    fn quiet(tag: [f64; 3], heights: &[f64], offset: f64) -> Vec<Reading> {
        reads(
            tag,
            heights,
            offset,
            &mut rand_chacha::ChaCha8Rng::seed_from_u64(0),
        )
    }

    fn err(p: [f64; 3], tag: [f64; 3]) -> f64 {
        (0..3).map(|k| (p[k] - tag[k]).powi(2)).sum::<f64>().sqrt()
    }

    #[test]
    fn a_target_read_like_a_reference_is_placed_on_it() {
        let h = [0.5, 1.1];
        let spots = [
            [1.0, 1.5, 0.7],
            [0.6, 1.2, 0.5],
            [1.4, 1.8, 0.9],
            [0.2, 1.0, 0.3],
            [2.0, 2.0, 1.2],
        ];
        let refs: Vec<_> = spots.iter().map(|&p| (p, quiet(p, &h, 0.0))).collect();
        // Another phase offset, and a whole turn, change nothing.
        let target = quiet([1.0, 1.5, 0.7], &h, 2.0 + std::f64::consts::TAU);
        let fix = locate(&target, &refs).expect("a fix");
        assert!(err(fix.position, [1.0, 1.5, 0.7]) < 1e-3, "{fix:?}");
    }

    #[test]
    fn a_target_amid_symmetric_references_is_placed_at_their_centre_within_a_millimetre() {
        // The pass is symmetric about x = 1 and the antenna at z = 0.5: the four references
        // around the target resemble it equally; the far ones are not chosen.
        let tag = [1.0, 1.5, 0.5];
        let spots = [
            [0.9, 1.5, 0.5],
            [1.1, 1.5, 0.5],
            [1.0, 1.5, 0.4],
            [1.0, 1.5, 0.6],
            [2.5, 2.5, 0.5],
            [-0.5, 1.0, 0.5],
        ];
        let refs: Vec<_> = spots.iter().map(|&p| (p, quiet(p, &[0.5], 0.3))).collect();
        let fix = locate(&quiet(tag, &[0.5], 1.1), &refs).expect("a fix");
        assert!(err(fix.position, tag) < 1e-3, "{fix:?}");
        assert!(
            fix.covariance[0] > 0.0 && fix.covariance[8] > 0.0,
            "{fix:?}"
        );
    }

    #[test]
    fn with_noise_the_estimate_stays_among_the_nearest_references() {
        // A 20 cm grid of references; the estimate is a weighted mean of the four chosen, so
        // it is within the 4th-nearest reference's distance whenever those are the nearest.
        let h = [0.5, 1.1];
        let tag = [1.0, 1.55, 0.65];
        let mut spots = Vec::new();
        for x in [0.7, 0.9, 1.1, 1.3] {
            for y in [1.3, 1.5, 1.7] {
                for z in [0.4, 0.6, 0.8] {
                    spots.push([x, y, z]);
                }
            }
        }
        let mut dist: Vec<f64> = spots.iter().map(|&p| err(p, tag)).collect();
        dist.sort_by(f64::total_cmp);
        let r4 = dist[K - 1];
        let mut within = 0;
        for seed in 0..20 {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            let refs: Vec<_> = spots
                .iter()
                .map(|&p| (p, reads(p, &h, f64::NAN, &mut rng)))
                .collect();
            let fix = locate(&reads(tag, &h, f64::NAN, &mut rng), &refs).expect("a fix");
            within += usize::from(err(fix.position, tag) <= r4);
        }
        assert!(within >= 16, "{within} of 20 within {r4} m");
    }

    #[test]
    fn too_few_references_or_common_poses_is_insufficient_geometry() {
        let insufficient = Err(NoFix::InsufficientGeometry);
        let tag = [1.0, 1.5, 0.5];
        let spots = [
            [0.9, 1.5, 0.5],
            [1.1, 1.5, 0.5],
            [1.0, 1.5, 0.4],
            [1.0, 1.5, 0.6],
        ];
        let refs: Vec<_> = spots.iter().map(|&p| (p, quiet(p, &[0.5], 0.0))).collect();
        assert_eq!(locate(&quiet(tag, &[0.5], 0.0), &refs[..3]), insufficient);
        assert_eq!(locate(&quiet(tag, &[0.5], 0.0), &[]), insufficient);
        assert_eq!(locate(&[], &refs), insufficient);
        // Read by another antenna than the references: no common poses.
        let mut other = quiet(tag, &[0.5], 0.0);
        other.iter_mut().for_each(|r| r.track = 7);
        assert_eq!(locate(&other, &refs), insufficient);
        // Sharing only 19 cells (38 readings at 1 cm) with each reference.
        let mut few = quiet(tag, &[0.5], 0.0);
        few.truncate(38);
        assert_eq!(locate(&few, &refs), insufficient);
    }
}
