//! Dense phases fitted in bins (ours, for time): each run of a segment's consecutive phases
//! within a bin's width of path ([`BIN_M`], [`SEPARATE_BIN_M`]) one phase, weighted by its
//! reads, its noise kept as its scatter.

use super::distance;
use crate::fix::Obs;
use crate::lanes;

/// Neighbouring phases of one segment within this of the first's antenna position (m) are
/// fitted as one bin: over 2 cm of path the model phase departs from a straight line by
/// s²/2d of range, on average 0.6 mrad at 1 m (2 mrad at 0.3 m) at 915 MHz, so the bin's
/// mean phase at its mean antenna position gives up only its count, which it keeps as its
/// weight, its noise about the line, which it keeps as its scatter, and the line's slope,
/// which is little of what a long segment tells ([`BIN_SEGMENT_M`]).
pub(super) const BIN_M: f64 = 0.02;

/// The bins of the fit with separate offsets (m), twice [`BIN_M`]: its Levenberg–Marquardt
/// solve takes time in proportion to the phases it holds, and over 4 cm the model phase
/// departs from the line by 2.4 mrad at 1 m (8 mrad at 0.3 m), still well under the phase
/// noise; S1's and S2's errors moved by under 0.5 mm. The joining ([`super::split`]) keeps
/// [`BIN_M`]: at 4 cm it located one or two tags fewer on S2 at `--mode 1`.
pub(super) const SEPARATE_BIN_M: f64 = 2.0 * BIN_M;

/// `obs` with each run of consecutive phases of one segment within `width` (m) of the run's
/// first antenna position merged into one bin ([`Obs::weight`], [`Obs::scatter_rad2`]);
/// segments shorter than [`BIN_SEGMENT_M`] as they are, and two phases farther apart than
/// [`TIGHT_M`] apart (their line would leave no scatter to keep).
pub(super) fn bin(obs: &[Obs], width: f64) -> Vec<Obs> {
    let mut out = Vec::with_capacity(obs.len());
    for segment in lanes::runs(obs, |o| o.segment) {
        let segment = &obs[segment];
        // A short segment is kept as read: the slope of its phases within a bin, which a bin
        // gives up, is much of what it tells.
        let (first, last) = (segment[0].antenna, segment[segment.len() - 1].antenna);
        if distance(first, last) < BIN_SEGMENT_M {
            out.extend_from_slice(segment);
            continue;
        }
        let mut rest = segment;
        while let Some(first) = rest.first() {
            let near = |o: &&Obs| distance(o.antenna, first.antenna) <= width;
            let mut n = rest.iter().take_while(near).count();
            if n == 2 && distance(rest[1].antenna, first.antenna) > TIGHT_M {
                n = 1;
            }
            let (run, next) = rest.split_at(n);
            out.push(merge(run));
            rest = next;
        }
    }
    out
}

/// A tag's phases are binned when it has more than this many: binning is for time, and
/// where reads are sparse no bin would hold more than a dwell's repeats.
pub(super) const BIN_ABOVE: usize = 800;

/// Segments shorter than this (m, first to last phase) are not binned: the slopes within the
/// bins, which binning gives up, are 1/25 of a segment's slope information at this length
/// ((2 cm / 10 cm)²) and more below it.
const BIN_SEGMENT_M: f64 = 0.1;

/// A bin within this of its first antenna position (m) takes its scatter about its mean: the
/// model phase moves under 0.06 rad over it (at 915 MHz), under the phase noise.
const TIGHT_M: f64 = 0.0015;

/// One bin of `run` (phases of one segment): the weighted means, the summed weight, and the
/// scatter of the phases (plus their own) about their mean where the run is within
/// [`TIGHT_M`], else about their weighted least-squares line along the run's direction,
/// scaled by (w − 1)/(w − 2) for the line's slope, so that either way the scatter stands for
/// w − 1 of the w reads' squared deviations (the bin's mean takes the last one, in the fit).
fn merge(run: &[Obs]) -> Obs {
    let first = run[0]; // `bin` passes runs of at least one phase.
    if run.len() == 1 {
        return first;
    }
    // The weighted sums of weight, phase and antenna position in one pass (each summed in
    // the reads' order, as separate sums would be).
    let (mut total, mut phase, mut antenna, mut time) = (0.0, 0.0, [0.0; 3], 0.0);
    for o in run {
        total += o.weight;
        phase += o.weight * o.phase_rad;
        time += o.weight * o.t_us as f64;
        for (sum, x) in antenna.iter_mut().zip(o.antenna) {
            *sum += o.weight * x;
        }
    }
    let phase = phase / total;
    let antenna = antenna.map(|x| x / total);
    // Position along the run: from its mean, along first → last.
    let last = run[run.len() - 1].antenna;
    let dir = [0, 1, 2].map(|a| last[a] - first.antenna[a]);
    let len = distance(first.antenna, last);
    let along = |o: &Obs| {
        (0..3)
            .map(|a| (o.antenna[a] - antenna[a]) * dir[a])
            .sum::<f64>()
            / len.max(f64::MIN_POSITIVE)
    };
    let (mut sxx, mut sxy) = (0.0, 0.0);
    for o in run {
        let x = along(o);
        sxx += o.weight * x * x;
        sxy += o.weight * x * (o.phase_rad - phase);
    }
    let tight = run
        .iter()
        .all(|o| distance(o.antenna, first.antenna) <= TIGHT_M);
    let (slope, scale) = match (tight, sxx > 0.0 && total > 2.0) {
        (false, true) => (sxy / sxx, (total - 1.0) / (total - 2.0)),
        _ => (0.0, 1.0),
    };
    let scatter = run
        .iter()
        .map(|o| {
            o.scatter_rad2 + scale * o.weight * (o.phase_rad - phase - slope * along(o)).powi(2)
        })
        .sum();
    Obs {
        phase_rad: phase,
        antenna,
        weight: total,
        scatter_rad2: scatter,
        t_us: (time / total).round() as u64,
        ..first
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Problem, Search};
    use super::*;
    use crate::relock::problem::solve;

    /// Dense reads (2 mm apart) of a tag from passes at 0.4 and 1.4 m, x from −1 m to 2 m, cut
    /// into 30 cm segments with offsets of their own, the last 6 cm of each pass a segment
    /// of its own: what binning takes.
    fn dense(tag: [f64; 3], noise: f64, seed: u64) -> Vec<Obs> {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let n = Normal::new(0.0, noise.max(1e-300)).expect("valid σ");
        let mut obs = Vec::new();
        for (pass, z) in [0.4, 1.4].into_iter().enumerate() {
            for k in 0..1500 {
                let a = [-1.0 + 0.002 * k as f64, 0.0, z];
                let segment = 11 * pass + k / 150 + usize::from(k >= 1470);
                let d = distance(tag, a);
                let e = if noise > 0.0 { n.sample(&mut rng) } else { 0.0 };
                obs.push(Obs {
                    phase_rad: 0.3 * segment as f64 + 4.0 * std::f64::consts::PI * d / 0.33 + e,
                    antenna: a,
                    wavelength_m: 0.33,
                    segment,
                    group: segment,
                    joint: segment,
                    period_rad: std::f64::consts::TAU,
                    weight: 1.0,
                    scatter_rad2: 0.0,
                    t_us: 0,
                });
            }
        }
        obs
    }

    fn search3d() -> Search {
        Search {
            dims: 3,
            z: 0.0,
            sign: 1.0,
            facing: [0.0, 1.0],
            mid: [0.5, 0.0],
            lo: [-4.0, -3.0, 0.0],
            hi: [5.0, 3.0, 2.4],
            hint: None,
        }
    }

    #[test]
    fn bins_keep_every_read_and_short_segments_and_the_noise() {
        for width in [BIN_M, SEPARATE_BIN_M] {
            bins_keep_every_read_and_short_segments_and_the_noise_at(width);
        }
    }

    fn bins_keep_every_read_and_short_segments_and_the_noise_at(width: f64) {
        let obs = dense([0.9, 1.2, 1.3], 0.1, 7);
        let bins = bin(&obs, width);
        assert!(bins.len() * 5 < obs.len(), "{} bins", bins.len());
        let reads: f64 = bins.iter().map(|o| o.weight).sum();
        assert_eq!(reads, obs.len() as f64);
        // The 6 cm segments at the passes' ends are kept as read.
        for short in [10, 21] {
            let held = |v: &[Obs]| v.iter().filter(|o| o.segment == short).count();
            assert_eq!((held(&obs), held(&bins)), (30, 30), "segment {short}");
        }
        // The scatter stands for the noise the means hide: Σ (w − 1) of σ² = 0.01.
        let hidden: f64 = bins.iter().map(|o| o.weight - 1.0).sum();
        let scatter: f64 = bins.iter().map(|o| o.scatter_rad2).sum();
        let variance = scatter / hidden;
        assert!((variance - 0.01).abs() < 0.001, "{variance}");
        // Noise-free, the phases lie on their bins' lines to well under a milliradian at
        // 2 cm (the departure grows as the width squared).
        let clean = bin(&dense([0.9, 1.2, 1.3], 0.0, 7), width);
        let worst = clean
            .iter()
            .map(|o| o.scatter_rad2 / o.weight)
            .fold(0.0, f64::max);
        assert!(worst < 1e-6 * (width / BIN_M).powi(4), "{width} m: {worst}");
    }

    #[test]
    fn binned_phases_fit_as_their_reads_do() {
        let tag = [0.9, 1.2, 1.3];
        let s = search3d();
        let start = [0.93, 1.18, 1.32];
        let solve_on =
            |obs: &[Obs]| solve(Problem::new(obs, 3, 0.0, 1.0, &start), &s).expect("a solution");
        for width in [BIN_M, SEPARATE_BIN_M] {
            let clean = dense(tag, 0.0, 1);
            let (p, _, _) = solve_on(&bin(&clean, width));
            let err = (0..3).map(|a| (p[a] - tag[a]).powi(2)).sum::<f64>().sqrt();
            // The bias of a bin's mean phase on a curved phase grows as its width squared:
            // under 0.1 mm at 2 cm (0.12 mm at 4 cm).
            let bound = 1e-4 * (width / BIN_M).powi(2);
            assert!(err < bound, "noise-free, {width} m: {err} m");
        }
        for (seed, width) in (0..4).flat_map(|s| [(s, BIN_M), (s, SEPARATE_BIN_M)]) {
            let obs = dense(tag, 0.1, seed);
            let (reads, bins) = (solve_on(&obs), solve_on(&bin(&obs, width)));
            for a in 0..3 {
                // Within a fifth of σ of each other, σ and the RMS residual within 10 %.
                let sigma = reads.1[(a, a)].sqrt();
                let apart = (reads.0[a] - bins.0[a]).abs();
                assert!(
                    apart < 0.2 * sigma,
                    "seed {seed} width {width} axis {a}: {apart} vs σ {sigma}"
                );
                let ratio = bins.1[(a, a)].sqrt() / sigma;
                assert!(
                    (ratio - 1.0).abs() < 0.1,
                    "seed {seed} width {width} axis {a}: σ ratio {ratio}"
                );
            }
            assert!(
                (bins.2 / reads.2 - 1.0).abs() < 0.1,
                "{} {}",
                bins.2,
                reads.2
            );
        }
    }
}
