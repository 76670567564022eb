//! A tag's phases as the estimators take them: unwrapped per segment for the phase
//! estimators ([`observations`]), as reported per track for the filters
//! ([`pose_observations`]); each reader's phases times its own phase sign, so that every
//! estimator sees s = +1, and the side the antennas face of the reader that read the tag most.

use std::collections::BTreeMap;

use crate::calibrate::Calibration;
use crate::fix::Obs;
use crate::geometry::Geometry;
use crate::ingest::Ingest;
use crate::linear;
use crate::mhekf::PoseObs;
use crate::outliers::outliers;
use crate::series::{Places, SAME_PLACE_M};
use llrp_gateway_vocab::reader_name::ReaderName;

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
    /// Phases left out as outliers ([`outliers`]).
    pub outliers: usize,
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
    // Per phase, its (reader, antenna) track's number, for straightening the tracks.
    let mut track_of: Vec<usize> = Vec::new();
    // Per phase, its antenna position as reported (before any correction).
    let mut reported: Vec<[f64; 3]> = Vec::new();
    let mut tracks: BTreeMap<(&str, u16), usize> = BTreeMap::new();
    for (group, (key, series)) in ingest.tag_series(epc).enumerate() {
        let next = tracks.len();
        let track = *tracks.entry((key.1.as_str(), key.2)).or_insert(next);
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
                track_of.push(track);
                reported.push(s.antenna);
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
    let left_out = tidy(&mut obs, &mut track_of, &mut reported, tracks.len(), g);
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
        outliers: left_out,
    }
}

/// Takes the outliers out of `obs` (with their entries in the parallel lists `track_of`, each
/// phase's track of `tracks`, and `reported`, its antenna position as reported) and, with a
/// stated pose error in `g`, straightens the tracks and weighs the phases read parked; how
/// many phases were left out.
fn tidy(
    obs: &mut Vec<Obs>,
    track_of: &mut Vec<usize>,
    reported: &mut Vec<[f64; 3]>,
    tracks: usize,
    g: &Geometry,
) -> usize {
    let outlier = outliers(obs);
    let left_out = outlier.iter().filter(|&&x| x).count();
    if left_out > 0 {
        fn keep<T>(v: &mut Vec<T>, outlier: &[bool]) {
            let mut flags = outlier.iter();
            v.retain(|_| !flags.next().copied().unwrap_or(false));
        }
        keep(obs, &outlier);
        keep(track_of, &outlier);
        keep(reported, &outlier);
    }
    if let Some(m) = &g.pose_error {
        let by_track = in_time(obs, track_of, tracks);
        straighten(obs, &by_track, m.sigma_m);
        weigh_parked(obs, reported, &by_track, m.correlation_s);
    }
    left_out
}

/// Per track, the indices of its phases in `obs` in time order (`track_of`: each phase's
/// track, of `tracks`).
fn in_time(obs: &[Obs], track_of: &[usize], tracks: usize) -> Vec<Vec<usize>> {
    let mut by_track = vec![Vec::new(); tracks];
    for (i, &k) in track_of.iter().enumerate() {
        by_track[k].push(i);
    }
    for idx in &mut by_track {
        idx.sort_by_key(|&i| obs[i].t_us);
    }
    by_track
}

/// Each (reader, antenna) track of `obs` (`by_track`: its phases in time order) whose antenna
/// positions lie within [`linear::MAX_PATH_RMS_M`] and three pose-error σ (`sigma_m`) RMS of a
/// straight line, moved onto that line: a robot's own pose estimate scatters about the
/// straight path it drives, and that scatter is its error, not the antenna's motion (the
/// prior `linear` and `hyperbolic` make; docs/localize.md "Straight tracks").
fn straighten(obs: &mut [Obs], by_track: &[Vec<usize>], sigma_m: f64) {
    let limit = linear::MAX_PATH_RMS_M.min(3.0 * sigma_m);
    for idx in by_track {
        // The line through the positions in time order as thinning keeps them (a rest's
        // first reads), so that neither a long rest nor its thinning moves it.
        let mut place = Places::default();
        let points: Vec<[f64; 3]> = idx
            .iter()
            .map(|&i| obs[i].antenna)
            .filter(|&a| place.keeps(a))
            .collect();
        let Some((origin, u, perp)) = linear::line(&points) else {
            continue;
        };
        if perp > limit || u[2].abs() > linear::MAX_SLOPE {
            continue;
        }
        for &i in idx {
            let a = obs[i].antenna;
            let t: f64 = (0..3).map(|k| (a[k] - origin[k]) * u[k]).sum();
            obs[i].antenna = [origin[0] + t * u[0], origin[1] + t * u[1], a[2]];
        }
    }
}

/// The phases of each run of a track (`by_track`: its phases in time order) read from one
/// reported place (`reported`, within [`SAME_PLACE_M`]) for longer than the pose error's
/// correlation time `correlation_s`, weighted down so that the run weighs as much as the
/// track's reads of one correlation time while it moves: a resting robot's pose error rests
/// too, so the run's reads share one error that more reads do not average away
/// (docs/localize.md "Straight tracks"). Against the moving reads' rate, not the rest's own,
/// so that the weights stay as they were when the live localizer thins a tag's older reads.
fn weigh_parked(
    obs: &mut [Obs],
    reported: &[[f64; 3]],
    by_track: &[Vec<usize>],
    correlation_s: f64,
) {
    let tau_us = correlation_s * 1e6;
    for idx in by_track {
        // The runs at one place, and which of them are rests.
        let mut runs: Vec<(std::ops::Range<usize>, bool)> = Vec::new();
        let mut start = 0;
        while start < idx.len() {
            let first = reported[idx[start]];
            let same = |i: usize| {
                (reported[i][0] - first[0]).hypot(reported[i][1] - first[1]) <= SAME_PLACE_M
            };
            let end = (start..idx.len())
                .find(|&k| !same(idx[k]))
                .unwrap_or(idx.len());
            let span_us = (obs[idx[end - 1]].t_us - obs[idx[start]].t_us) as f64;
            runs.push((start..end, span_us > tau_us));
            start = end;
        }
        // The moving reads' weight per µs: from the first to the last moving read, less the
        // rests between them.
        let moving: Vec<&std::ops::Range<usize>> =
            runs.iter().filter(|r| !r.1).map(|r| &r.0).collect();
        let rate = match (moving.first(), moving.last()) {
            (Some(a), Some(b)) => {
                let (t0, t1) = (obs[idx[a.start]].t_us, obs[idx[b.end - 1]].t_us);
                let resting: u64 = runs
                    .iter()
                    .filter(|r| r.1)
                    .map(|r| (obs[idx[r.0.start]].t_us, obs[idx[r.0.end - 1]].t_us))
                    .filter(|&(a, b)| a >= t0 && b <= t1)
                    .map(|(a, b)| b - a)
                    .sum();
                let weight: f64 = moving
                    .iter()
                    .flat_map(|r| idx[(*r).clone()].iter())
                    .map(|&i| obs[i].weight)
                    .sum();
                let span = t1.saturating_sub(t0).saturating_sub(resting) as f64;
                (span > 0.0).then(|| weight / span)
            }
            _ => None,
        };
        for (run, rest) in runs {
            if !rest {
                continue;
            }
            let run = &idx[run];
            let total: f64 = run.iter().map(|&i| obs[i].weight).sum();
            let span_us = (obs[run[run.len() - 1]].t_us - obs[run[0]].t_us) as f64;
            // A track that never moves weighs its rest by the rest's own rate.
            let target = rate.map_or(total * tau_us / span_us, |r| r * tau_us);
            for &i in run {
                obs[i].weight *= target / total;
            }
        }
    }
}

/// One (reader, antenna) track of a tag's phases as reported, for the filters.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseTrack {
    /// Reader name; `None` for the reads that name none.
    pub reader: Option<ReaderName>,
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
        .map(|((key, antenna), mut obs)| {
            // The series key holds the reads' reader name as it came, "" for none: a name
            // is one again.
            let reader = ReaderName::parse(&key).ok();
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
                .track(&key, antenna)
                .take_while(|(t_us, _)| *t_us <= end)
                .map(|(t_us, p)| PoseObs {
                    t_us,
                    phase_rad: 0.0,
                    antenna: p.pose.position,
                    yaw_rad: p.pose.yaw_rad,
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
    use crate::estimate::{estimate_all, Estimator, ReaderGeometry};
    use crate::poses::Poses;
    use crate::series::Ambiguity;
    use crate::synthetic;
    use llrp_gateway_vocab::reads::Read;

    /// Reader `reader` passing along y = 0 reads a tag at `tag`, its phase times `sign`.
    fn pass(reader: &str, epc: &str, tag: [f64; 2], sign: f64) -> Vec<Read> {
        let lambda = crate::SPEED_OF_LIGHT / synthetic::FREQUENCY_HZ as f64;
        (0..300u64)
            .map(|k| {
                let x = -1.0 + 0.01 * k as f64;
                let d = (tag[0] - x).hypot(tag[1]);
                let phase = sign * 4.0 * std::f64::consts::PI * d / lambda + 0.4;
                Read {
                    reader: Some(reader.parse().expect("a reader name")),
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
        let mut g = crate::live::Settings::default().geometry;
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

    #[test]
    fn outliers_are_left_out_of_the_phases_and_counted() {
        let mut ingest = Ingest::new(Poses::new(), Ambiguity::None, 1_000_000);
        let mut reads = pass("p", "AA", [0.3, 1.2], 1.0);
        for (k, r) in reads.iter_mut().enumerate() {
            // 0.02 rad of noise, and 1 rad off at three reads.
            let off = 0.02 * ((k as f64) * 2.39).sin() + if k % 97 == 50 { 1.0 } else { 0.0 };
            let p = r.phase_rad.expect("a phase") + off;
            r.phase_rad = Some(p.rem_euclid(std::f64::consts::TAU));
        }
        for r in &reads {
            ingest.push(r);
        }
        let g = crate::live::Settings::default().geometry;
        let seen = observations(&ingest, "AA", &g);
        assert_eq!((seen.outliers, seen.obs.len()), (3, 297));
        assert!(seen
            .obs
            .iter()
            .all(|o| ![50, 147, 244].contains(&(o.t_us / 10_000))));
    }

    /// A phase read at `t_us` from `antenna`.
    fn at(t_us: u64, antenna: [f64; 3]) -> Obs {
        Obs {
            phase_rad: 0.0,
            antenna,
            wavelength_m: 0.33,
            segment: 0,
            group: 0,
            joint: 0,
            period_rad: 2.0 * std::f64::consts::PI,
            weight: 1.0,
            scatter_rad2: 0.0,
            t_us,
        }
    }

    #[test]
    fn a_straight_track_that_wobbles_is_moved_onto_its_line_and_a_bent_one_is_left() {
        // Track 0: along y = 0 with a 1 cm wobble (a pose error of σ 15 mm); track 1: an arc
        // 30 cm deep over 2 m.
        let mut obs: Vec<Obs> = (0..200)
            .map(|k| {
                let x = 0.01 * k as f64;
                at(k * 10_000, [x, 0.01 * (x * 7.0).sin(), 0.5])
            })
            .collect();
        obs.extend((0..200).map(|k| {
            let x = 0.01 * k as f64;
            at(k * 10_000, [x, 2.0 + 0.3 * (1.0 - (x - 1.0).powi(2)), 0.5])
        }));
        let track_of: Vec<usize> = (0..400).map(|i| i / 200).collect();
        let before = obs.clone();
        let by_track = in_time(&obs, &track_of, 2);
        straighten(&mut obs, &by_track, 0.015);
        let points: Vec<[f64; 3]> = obs[..200].iter().map(|o| o.antenna).collect();
        let (_, u, perp) = linear::line(&points).expect("a line");
        assert!(perp < 1e-9, "{perp} m off the line");
        assert!(u[0].abs() > 0.999, "{u:?}");
        for (a, b) in obs[..200].iter().zip(&before) {
            assert!(
                (a.antenna[0] - b.antenna[0]).abs() < 0.002,
                "{a:?} from {b:?}"
            );
            assert_eq!(a.antenna[2], b.antenna[2]);
        }
        assert_eq!(obs[200..], before[200..]);
    }

    #[test]
    fn a_long_rest_does_not_turn_the_line_of_its_track() {
        // A wobbling drive along y = 0, then 2,000 reads at rest where the estimate says
        // y = 12 mm (its error frozen with the robot).
        let mut obs: Vec<Obs> = (0..200)
            .map(|k| {
                let x = 0.01 * k as f64;
                at(k * 10_000, [x, 0.01 * (x * 7.0).sin(), 0.5])
            })
            .collect();
        obs.extend((200..2200).map(|k| at(k * 10_000, [2.0, 0.012, 0.5])));
        let moving: Vec<[f64; 3]> = obs[..200].iter().map(|o| o.antenna).collect();
        let (origin, u, _) = linear::line(&moving).expect("a line");
        let track_of = vec![0; obs.len()];
        let by_track = in_time(&obs, &track_of, 1);
        straighten(&mut obs, &by_track, 0.015);
        // Where the drive's own line is at the first read's along-line position.
        let a = obs[0].antenna;
        let t: f64 = (0..2).map(|k| (a[k] - origin[k]) * u[k]).sum();
        let y = origin[1] + t * u[1];
        assert!((a[1] - y).abs() < 0.002, "{} mm off", (a[1] - y) * 1e3);
    }

    #[test]
    fn a_rest_longer_than_the_correlation_time_weighs_as_one_correlation_time_of_driving() {
        // 2 s of driving, then 20 s at rest, then 1 s at rest elsewhere (shorter than the
        // correlation time: as driving), a read every 10 ms: 300 reads in 3 s of driving.
        let track = |rest: &mut dyn Iterator<Item = u64>| {
            let mut obs: Vec<Obs> = (0..200)
                .map(|k| at(k * 10_000, [0.005 * k as f64, 0.0, 0.5]))
                .collect();
            obs.extend(rest.map(|k| at(k * 10_000, [1.0, 0.0004, 0.5])));
            obs.extend((2200..2300).map(|k| at(k * 10_000, [1.5, 0.0, 0.5])));
            let reported: Vec<[f64; 3]> = obs.iter().map(|o| o.antenna).collect();
            let track_of = vec![0; obs.len()];
            let by_track = in_time(&obs, &track_of, 1);
            weigh_parked(&mut obs, &reported, &by_track, 2.0);
            obs
        };
        for obs in [
            track(&mut (200..2200)),
            // As the live localizer's thinning leaves a rest: its first 16 reads and its last.
            track(&mut (200..216).chain(2199..2200)),
        ] {
            let n = obs.len();
            assert!(obs[..200].iter().all(|o| o.weight == 1.0));
            assert!(obs[n - 100..].iter().all(|o| o.weight == 1.0));
            // The rest weighs as 2 s of driving's 100 reads a second, however many it holds.
            let rest: f64 = obs[200..n - 100].iter().map(|o| o.weight).sum();
            assert!((rest - 200.0).abs() < 1e-6, "{rest}");
        }
    }
}
