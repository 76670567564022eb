//! A tag's phases as the estimators take them: unwrapped per segment for the phase
//! estimators ([`observations`]), as reported per track for the filters
//! ([`pose_observations`]); each reader's phases times its own phase sign, so that every
//! estimator sees s = +1, and the side the antennas face of the reader that read the tag most.

use std::collections::BTreeMap;

use super::calibrate::Calibration;
use super::geometry::Geometry;
use super::ingest::Ingest;
use super::mhekf::PoseObs;
use super::relock::Obs;

/// One tag's phases for the phase estimators.
#[derive(Clone, Debug, PartialEq)]
pub struct Observed {
    /// Every unwrapped phase of its series, times its reader's phase sign (so that the
    /// estimators see s = +1), one segment number per (series, segment), one group per series.
    pub obs: Vec<Obs>,
    /// The time of the newest (µs).
    pub last_us: u64,
    /// The side the antennas face of the reader with the most of the tag's phases.
    pub facing: [f64; 2],
    /// Per group (series), its reader's number among the tag's readers.
    pub reader_of_group: Vec<usize>,
}

/// Tag `epc`'s phases, each reader's by its own settings in `g`.
pub fn observations(ingest: &Ingest, epc: &str, g: &Geometry) -> Observed {
    calibrated_observations(ingest, epc, g, &Calibration::default())
}

/// [`observations`] with the offsets of `calibration` taken off the phases of the antennas it
/// calibrates, whose series on one (reader, channel) then form one joint group; the antenna
/// positions moved by `g`'s pose corrections where it has them.
pub fn calibrated_observations(
    ingest: &Ingest,
    epc: &str,
    g: &Geometry,
    calibration: &Calibration,
) -> Observed {
    let mut obs: Vec<Obs> = Vec::new();
    let mut last_us = 0;
    // (reader, antenna or none when calibrated, channel) → joint group.
    let mut joints: BTreeMap<(&str, Option<u16>, u64), usize> = BTreeMap::new();
    let mut per_reader: BTreeMap<&str, usize> = BTreeMap::new();
    let mut reader_of_group = Vec::new();
    let mut numbers: BTreeMap<&str, usize> = BTreeMap::new();
    for (group, (key, series)) in ingest.tag_series(epc).enumerate() {
        let next = numbers.len();
        reader_of_group.push(*numbers.entry(key.1.as_str()).or_insert(next));
        let (lambda, period_rad) = (series.wavelength_m(), series.ambiguity().period());
        let offset = calibration.offset(&key.1, key.2, key.3);
        let sign = g.sign_of(&key.1);
        *per_reader.entry(key.1.as_str()).or_default() += series.len();
        let next = joints.len();
        let joint = *joints
            .entry((key.1.as_str(), offset.map_or(Some(key.2), |_| None), key.3))
            .or_insert(next);
        for seg in series.segments() {
            let segment = obs.last().map_or(0, |o| o.segment + 1);
            for s in seg {
                last_us = last_us.max(s.t_us);
                let antenna = match &g.pose_corrections {
                    Some(c) => {
                        let d = c.at(&key.1, s.t_us);
                        [s.antenna[0] + d[0], s.antenna[1] + d[1], s.antenna[2]]
                    }
                    None => s.antenna,
                };
                obs.push(Obs {
                    phase_rad: sign * (s.phase_rad - offset.unwrap_or(0.0)),
                    antenna,
                    wavelength_m: lambda,
                    segment,
                    group,
                    joint,
                    period_rad,
                    weight: 1.0,
                    scatter_rad2: 0.0,
                    t_us: s.t_us,
                });
            }
        }
    }
    // The most-read reader, the first by name on a tie.
    let facing = per_reader
        .iter()
        .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(a.0)))
        .map_or(g.facing, |(r, _)| g.facing_of(r));
    Observed {
        obs,
        last_us,
        facing,
        reader_of_group,
    }
}

/// One (reader, antenna) track of a tag's phases as reported, for the filters.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseTrack {
    /// Reader name.
    pub reader: String,
    /// Antenna port.
    pub antenna: u16,
    /// Every channel's reads, in time order.
    pub obs: Vec<PoseObs>,
}

/// Tag `epc`'s reads per (reader, antenna), channels merged in time order, each phase as
/// reported times its reader's phase sign (so that the filters see s = +1), with the
/// antenna's position and yaw; among them, the antenna's pose samples up to its last read
/// (`read: false`), for the odometry.
pub fn pose_observations(ingest: &Ingest, epc: &str, g: &Geometry) -> Vec<PoseTrack> {
    let mut tracks: BTreeMap<(String, u16), Vec<PoseObs>> = BTreeMap::new();
    for (key, series) in ingest.tag_series(epc) {
        let (lambda, period) = (series.wavelength_m(), series.ambiguity().period());
        let sign = g.sign_of(&key.1);
        let track = tracks.entry((key.1.clone(), key.2)).or_default();
        for s in series.samples() {
            track.push(PoseObs {
                t_us: s.t_us,
                phase_rad: (sign * s.raw_phase_rad).rem_euclid(period),
                antenna: s.antenna,
                yaw_rad: s.yaw_rad,
                wavelength_m: lambda,
                period_rad: period,
                read: true,
            });
        }
    }
    tracks
        .into_iter()
        .map(|((reader, antenna), mut obs)| {
            obs.sort_by_key(|o| o.t_us);
            // The antenna's pose samples up to its last read: the path the filter's odometry
            // noise is charged on (\[M\] eq. 26 before the first read, and between reads).
            let (Some(&head), Some(end)) = (obs.first(), obs.last().map(|o| o.t_us)) else {
                return PoseTrack {
                    reader,
                    antenna,
                    obs,
                };
            };
            let mut path: Vec<PoseObs> = ingest
                .poses()
                .track(&reader, antenna)
                .take_while(|(t_us, _)| *t_us <= end)
                .map(|(t_us, p)| PoseObs {
                    t_us,
                    phase_rad: 0.0,
                    antenna: [p.x, p.y, p.z],
                    yaw_rad: p.yaw_deg.to_radians(),
                    read: false,
                    ..head
                })
                .collect();
            path.append(&mut obs);
            // Stable: a pose sample at a read's time comes before the read.
            path.sort_by_key(|o| o.t_us);
            let obs = path;
            PoseTrack {
                reader,
                antenna,
                obs,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::localize::estimate::{estimate_all, Estimator, ReaderGeometry};
    use crate::localize::poses::Poses;
    use crate::localize::series::Ambiguity;
    use crate::localize::synthetic;
    use crate::reads::Read;

    /// Reader `reader` passing along y = 0 reads a tag at `tag`, its phase times `sign`.
    fn pass(reader: &str, epc: &str, tag: [f64; 2], sign: f64) -> Vec<Read> {
        let lambda = crate::localize::SPEED_OF_LIGHT / synthetic::FREQUENCY_HZ as f64;
        (0..300u64)
            .map(|k| {
                let x = -1.0 + 0.01 * k as f64;
                let d = (tag[0] - x).hypot(tag[1]);
                let phase = sign * 4.0 * std::f64::consts::PI * d / lambda + 0.4;
                Read {
                    reader: Some(reader.to_string()),
                    ..synthetic::read(epc, k * 10_000, phase, [x, 0.0, 0.5])
                }
            })
            .collect()
    }

    #[test]
    fn each_reader_is_read_by_its_own_sign_and_facing() {
        // Reader "n" reports the phase negated and faces −y; "p" is as the defaults say.
        let mut ingest = Ingest::new(Poses::new(), Ambiguity::None, 1_000_000);
        let (a, b) = ([0.3, 1.2], [0.6, -1.4]);
        for r in pass("p", "AA", a, 1.0)
            .iter()
            .chain(&pass("n", "BB", b, -1.0))
        {
            ingest.push(r);
        }
        let mut g = crate::localize::live::Settings::default().geometry;
        g.readers.insert(
            "n".into(),
            ReaderGeometry {
                phase_sign: -1.0,
                facing: [0.0, -1.0],
            },
        );
        let seen = observations(&ingest, "BB", &g);
        assert_eq!(seen.facing, [0.0, -1.0]);
        let all = estimate_all(&ingest, Estimator::Relock, &g);
        for (e, want) in all.iter().zip([a, b]) {
            let p = e.estimate.expect("a position");
            assert!(
                (p[0] - want[0]).hypot(p[1] - want[1]) < 1e-3,
                "{}: {p:?}",
                e.epc
            );
        }
        // Told nothing of reader "n", its tag is not found where it is.
        g.readers.clear();
        let wrong = &estimate_all(&ingest, Estimator::Relock, &g)[1];
        let found = wrong
            .estimate
            .is_some_and(|p| (p[0] - b[0]).hypot(p[1] - b[1]) < 0.05);
        assert!(!found, "{wrong:?}");
    }
}
