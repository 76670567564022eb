//! Phase offsets between a reader's antennas, from reference tags (ours, for `relock`).
//!
//! A series' phase offset is the sum of the antenna's part (its cable, its port) and the tag's
//! (its chip, its mounting): φ0 = A_antenna + T_tag on one channel. Two antennas of one reader
//! reading one tag therefore differ by A_a − A_b whatever the tag, and a reference tag at a
//! known position measures that difference: its offset on each antenna is the circular mean of
//! θ − s·4πd/λ over its reads. With the differences known, a tag's series on several antennas
//! share one offset modulo the period, which [`crate::join`] uses to join them; the phase
//! differences between antennas at different heights then carry the tag's height, where the
//! separate offsets left it to the curvature of each pass alone.
//!
//! Per (reader, channel): the base antenna is the one that read the most reference tags; an
//! antenna's offset is the circular mean, over the references both read, of the difference of
//! their offsets, kept when at least [`MIN_REFERENCES`] agree (mean resultant length at least
//! [`MIN_AGREEMENT`]). A reference whose own reads scatter (multipath, a wrong position) is
//! left out by the same test on its series.

use llrp_gateway_vocab::epc::Epc;
use std::collections::BTreeMap;
use std::f64::consts::TAU;

use crate::ingest::Ingest;
use crate::lanes::sin_cos_f32;

/// Fewest reference tags read by both antennas for an offset between them.
pub const MIN_REFERENCES: usize = 2;
/// Least mean resultant length (1: all equal) of a series' residuals, and of the references'
/// differences, to be used.
pub const MIN_AGREEMENT: f64 = 0.8;

/// What an estimator measures on the reference tags once for every tag
/// ([`crate::estimator::Locate::calibration`]): each calibrated antenna's offset relative to
/// its reader's base antenna on a channel (rad), for `relock`; the reference tags located from
/// the others, for `fingerprint`'s covariance.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Calibration {
    /// (reader, channel frequency Hz) → antenna port → offset (rad).
    offsets: BTreeMap<(String, u64), BTreeMap<u16, f64>>,
    /// Reference tags located from the others: (EPC, position, estimate).
    located: Vec<(String, [f64; 3], [f64; 3])>,
}

/// The circular mean of `angles` (rad, period `period`) and their mean resultant length.
fn circular_mean(angles: impl Iterator<Item = f64>, period: f64) -> (f64, f64) {
    let (mut re, mut im, mut n) = (0.0, 0.0, 0usize);
    for a in angles {
        // Whole turns off in f64 (1.5·2⁵² rounds to the nearest integer), then sin and cos
        // in f32 to 2e-6: a libm sin/cos a reference read was most of the calibration.
        const ROUND: f64 = 6_755_399_441_055_744.0;
        let x = a * TAU / period;
        let turns = (x / TAU + ROUND) - ROUND;
        let (s, c) = sin_cos_f32((x - turns * TAU) as f32);
        let (s, c) = (f64::from(s), f64::from(c));
        re += c;
        im += s;
        n += 1;
    }
    if n == 0 {
        return (0.0, 0.0);
    }
    (im.atan2(re) * period / TAU, re.hypot(im) / n as f64)
}

impl Calibration {
    /// The offsets measured by `references` (EPC, true position) in `ingest`'s
    /// series, each reader's phase sign `sign(reader)`.
    pub fn from_references(
        ingest: &Ingest,
        references: &[(Epc, [f64; 3])],
        sign: &dyn Fn(&str) -> f64,
    ) -> Calibration {
        // (reader, channel) → reference → antenna → (offset, period).
        type PerReference = BTreeMap<usize, BTreeMap<u16, (f64, f64)>>;
        let mut measured: BTreeMap<(String, u64), PerReference> = BTreeMap::new();
        for (r, (epc, position)) in references.iter().enumerate() {
            for (key, series) in ingest.tag_series(epc) {
                let (lambda, period) = (series.wavelength_m(), series.ambiguity().period());
                let sign = sign(&key.1);
                let residuals = series.samples().iter().map(|s| {
                    let d = (0..3)
                        .map(|a| (position[a] - s.antenna[a]).powi(2))
                        .sum::<f64>()
                        .sqrt();
                    s.raw_phase_rad - sign * 4.0 * std::f64::consts::PI * d / lambda
                });
                let (offset, agreement) = circular_mean(residuals, period);
                if agreement >= MIN_AGREEMENT {
                    measured
                        .entry((key.1.clone(), key.3))
                        .or_default()
                        .entry(r)
                        .or_default()
                        .insert(key.2, (offset, period));
                }
            }
        }
        let mut offsets = BTreeMap::new();
        for (channel, by_reference) in measured {
            let mut seen: BTreeMap<u16, usize> = BTreeMap::new();
            for antennas in by_reference.values() {
                for &a in antennas.keys() {
                    *seen.entry(a).or_default() += 1;
                }
            }
            // The most-read antenna, the lowest port on a tie.
            let Some(base) = seen
                .iter()
                .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(a.0)))
                .map(|(&a, _)| a)
            else {
                continue;
            };
            let mut table = BTreeMap::new();
            table.insert(base, 0.0);
            for &a in seen.keys().filter(|&&a| a != base) {
                let diffs: Vec<(f64, f64)> = by_reference
                    .values()
                    .filter_map(|m| Some((m.get(&a)?, m.get(&base)?)))
                    .map(|(x, y)| (x.0 - y.0, x.1))
                    .collect();
                let Some(&(_, period)) = diffs.first() else {
                    continue;
                };
                let (offset, agreement) = circular_mean(diffs.iter().map(|d| d.0), period);
                if diffs.len() >= MIN_REFERENCES && agreement >= MIN_AGREEMENT {
                    table.insert(a, offset);
                }
            }
            if table.len() > 1 {
                offsets.insert(channel, table);
            }
        }
        Calibration {
            offsets,
            located: Vec::new(),
        }
    }

    /// The reference tags `located` from the others (EPC, position, estimate), and no offsets.
    pub fn from_located(located: Vec<(String, [f64; 3], [f64; 3])>) -> Calibration {
        Calibration {
            offsets: BTreeMap::new(),
            located,
        }
    }

    /// The reference tags located from the others (EPC, position, estimate).
    pub fn located(&self) -> &[(String, [f64; 3], [f64; 3])] {
        &self.located
    }

    /// Antenna `antenna`'s offset relative to its reader's base antenna on the channel of
    /// `frequency_hz`, when calibrated.
    pub fn offset(&self, reader: &str, antenna: u16, frequency_hz: u64) -> Option<f64> {
        self.offsets
            .get(&(reader.to_string(), frequency_hz))?
            .get(&antenna)
            .copied()
    }

    /// Whether no antenna is calibrated.
    pub fn is_empty(&self) -> bool {
        self.offsets.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::poses::Poses;
    use crate::series::Ambiguity;
    use crate::synthetic;
    use llrp_gateway_vocab::reads::Read;

    /// Reads of tag `epc` at `tag` by antennas 1..=3 at heights 0.4, 0.9, 1.4 passing along
    /// y = 0, each antenna with offset `antenna_offset · port`, the tag with `tag_offset`.
    fn reads(epc: &str, tag: [f64; 3], tag_offset: f64, antenna_offset: f64) -> Vec<Read> {
        let mut out = Vec::new();
        for port in 1..=3u16 {
            let z = 0.4 + 0.5 * f64::from(port - 1);
            for k in 0..200u64 {
                let a = [-1.0 + 0.01 * k as f64, 0.0, z];
                let d = (0..3).map(|j| (tag[j] - a[j]).powi(2)).sum::<f64>().sqrt();
                let lambda = crate::SPEED_OF_LIGHT / synthetic::FREQUENCY_HZ as f64;
                let phase = 4.0 * std::f64::consts::PI * d / lambda
                    + tag_offset
                    + antenna_offset * f64::from(port);
                out.push(Read {
                    antenna: port,
                    ..synthetic::read(epc, 1_000 * k + u64::from(port), phase, a)
                });
            }
        }
        out
    }

    #[test]
    fn references_measure_the_offsets_between_antennas() {
        let mut ingest = Ingest::new(Poses::default(), Ambiguity::None, 10_000_000);
        let refs = [
            (Epc::parse("AA").expect("hex"), [0.2, 1.0, 0.8]),
            (Epc::parse("BB").expect("hex"), [-0.3, 1.4, 1.2]),
        ];
        let mut all = reads("AA", refs[0].1, 0.3, 1.1);
        all.extend(reads("BB", refs[1].1, 2.9, 1.1));
        all.sort_by_key(|r| r.t_us);
        for r in &all {
            ingest.push(r);
        }
        let cal = Calibration::from_references(&ingest, &refs, &|_| 1.0);
        let base = cal
            .offset("", 1, synthetic::FREQUENCY_HZ)
            .expect("antenna 1");
        assert_eq!(base, 0.0, "the base antenna: most references, lowest port");
        for port in 2..=3u16 {
            let got = cal
                .offset("", port, synthetic::FREQUENCY_HZ)
                .expect("calibrated");
            let want = 1.1 * f64::from(port - 1);
            let err = (got - want + TAU / 2.0).rem_euclid(TAU) - TAU / 2.0;
            assert!(err.abs() < 1e-6, "antenna {port}: {got} against {want}");
        }
        // A tag's series on the calibrated antennas: three groups, one joint group, and the
        // antennas' offsets taken off (the phases of one position differ by the tag's alone).
        let g = crate::live::Settings::default().geometry;
        let obs = crate::estimate::calibrated_observations(&ingest, "BB", &g, &cal).obs;
        let groups: std::collections::BTreeSet<usize> = obs.iter().map(|o| o.group).collect();
        assert_eq!(groups.len(), 3);
        assert!(obs.iter().all(|o| o.joint == obs[0].joint));
        let uncalibrated = crate::estimate::observations(&ingest, "BB", &g).obs;
        assert_eq!(
            uncalibrated
                .iter()
                .map(|o| o.joint)
                .collect::<std::collections::BTreeSet<_>>(),
            groups
        );
        // One reference is not enough; a wrong position scatters and is left out.
        let one = Calibration::from_references(&ingest, &refs[..1], &|_| 1.0);
        assert!(one.is_empty());
        let wrong = [
            refs[0].clone(),
            (Epc::parse("BB").expect("hex"), [0.9, 0.3, 0.1]),
        ];
        assert!(Calibration::from_references(&ingest, &wrong, &|_| 1.0).is_empty());
    }
}
