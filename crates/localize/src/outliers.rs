//! Phase outliers: a read whose phase leaves the line through its two neighbours in time,
//! against theirs, by more than [`OUTLIER_SIGMAS`] robust σ of that test over its segment. A real reader gives 0.15–0.23 % of
//! such reads (real-reads.md: beyond 5 robust σ, on top of tails of excess kurtosis 2–3.5);
//! one of them moves a fix as much as hundreds of ordinary reads.
//!
//! Ours: d_i = φ_i − (the neighbours' line at t_i) is e at an outlier of e and −e/2 beside
//! it; where the phase curve bends (near the tag, fast) d is large but alike for neighbours.
//! So the test is d_i against its neighbours' mean, 1.5·e at an outlier, and only the
//! largest of three is a candidate. σ is 1.4826 × its median magnitude over the segment;
//! O(n). Reads first and last in their segment are never flagged.

use crate::fix::Obs;

/// A phase whose test is further out than this many robust σ is an outlier (the notes count
/// phases beyond 5 robust σ).
pub const OUTLIER_SIGMAS: f64 = 5.0;

/// Fewest phases a segment needs for its outliers to be looked for.
pub const MIN_SEGMENT: usize = 9;

/// Per phase of `obs` (segments contiguous, each in time order), whether it is an outlier.
pub fn outliers(obs: &[Obs]) -> Vec<bool> {
    let mut out = vec![false; obs.len()];
    let mut scratch = Scratch::default();
    let mut start = 0;
    while start < obs.len() {
        let segment = obs[start].segment;
        let end = start
            + obs[start..]
                .iter()
                .take_while(|o| o.segment == segment)
                .count();
        if end - start >= MIN_SEGMENT {
            flag(&obs[start..end], &mut scratch, &mut out[start..end]);
        }
        start = end;
    }
    out
}

/// Buffers [`flag`] reuses from one segment to the next.
#[derive(Default)]
struct Scratch {
    d: Vec<f64>,
    signature: Vec<f64>,
    magnitudes: Vec<f64>,
}

/// Flags the outliers of one segment `seg` in `out`.
fn flag(seg: &[Obs], scratch: &mut Scratch, out: &mut [bool]) {
    let Scratch {
        d,
        signature,
        magnitudes,
    } = scratch;
    // b's departure from the line through a and c at b's time (a fraction `at` of the way).
    let off = |a: &Obs, b: &Obs, c: &Obs| {
        let span = c.t_us as f64 - a.t_us as f64;
        let at = if span != 0.0 {
            (b.t_us as f64 - a.t_us as f64) / span
        } else {
            0.5
        };
        b.phase_rad - (a.phase_rad + (c.phase_rad - a.phase_rad) * at)
    };
    let n = seg.len();
    d.clear();
    // The ends against the line through their next two (extrapolated): compared, never
    // flagged (their noise is twice an inner phase's), so that an outlier at an end does not
    // get its neighbour flagged.
    d.push(off(&seg[1], &seg[0], &seg[2]));
    d.extend(seg.windows(3).map(|w| off(&w[0], &w[1], &w[2])));
    d.push(off(&seg[n - 3], &seg[n - 1], &seg[n - 2]));
    // The outlier's signature: d_i against its neighbours' mean, 1.5·e at an outlier of e,
    // −e beside it, and near 0 where the phase curve merely bends (the curvature moves all
    // three alike, as where a fast pass goes by the tag).
    signature.clear();
    signature.extend((0..n).map(|i| match i {
        0 => d[0] - d[1],
        _ if i == n - 1 => d[n - 1] - d[n - 2],
        _ => d[i] - (d[i - 1] + d[i + 1]) / 2.0,
    }));
    magnitudes.clear();
    magnitudes.extend(signature[1..n - 1].iter().map(|x| x.abs()));
    let mid = magnitudes.len() / 2;
    let (_, median, _) = magnitudes.select_nth_unstable_by(mid, f64::total_cmp);
    // The signature's own robust σ: white noise of σ gives it σ·√4.375
    // (1.5φ_i − φ_i±1 + φ_i±2/4), so an outlier is found from about 7σ of the phase on.
    let sigma = 1.4826 * *median;
    if !(sigma > 0.0 && sigma.is_finite()) {
        return;
    }
    for i in 1..n - 1 {
        let m = signature[i].abs();
        out[i] = m > OUTLIER_SIGMAS * sigma
            && m >= signature[i - 1].abs()
            && m >= signature[i + 1].abs();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic;

    #[test]
    fn white_noise_has_no_outliers_and_planted_ones_are_found() {
        let mut obs = synthetic::passes([0.8, 2.1, 0.5], &[0.5, 0.9], (0.7, 1.0), 0.02, 3);
        for (i, o) in obs.iter_mut().enumerate() {
            o.t_us = i as u64 * 10_000;
        }
        assert_eq!(outliers(&obs).iter().filter(|&&x| x).count(), 0);
        let planted = [17, 150, 151, 299, 300, 433];
        for (k, &i) in planted.iter().enumerate() {
            obs[i].phase_rad += if k % 2 == 0 { 0.4 } else { -1.5 };
        }
        let found: Vec<usize> = outliers(&obs)
            .iter()
            .enumerate()
            .filter_map(|(i, &x)| x.then_some(i))
            .collect();
        // 150 and 151 side by side: only the larger is found. 299 and 300 are the last and
        // first of their segments: never flagged, and their neighbours are not either.
        assert_eq!(found, vec![17, 150, 433]);
    }

    #[test]
    fn a_short_segment_is_left_alone() {
        let mut obs = synthetic::passes([0.8, 2.1, 0.5], &[0.5], (0.7, 0.0), 0.02, 3);
        obs.truncate(MIN_SEGMENT - 1);
        obs[3].phase_rad += 3.0;
        assert!(outliers(&obs).iter().all(|&x| !x));
    }

    #[test]
    fn a_fast_pass_close_by_bends_the_phase_without_outliers() {
        // 8 cm between reads (λ/4: the most a series allows) 0.3 m from the tag, where the
        // phase curve bends most.
        let mut obs: Vec<Obs> = synthetic::passes([0.5, 0.3, 0.5], &[0.5], (0.7, 0.0), 0.01, 5)
            .into_iter()
            .step_by(8)
            .collect();
        for (i, o) in obs.iter_mut().enumerate() {
            o.t_us = i as u64 * 20_000;
        }
        assert!(outliers(&obs).iter().all(|&x| !x));
        // The second difference alone would have flagged the reads nearest the tag.
        obs[19].phase_rad += 0.5;
        let found: Vec<usize> = outliers(&obs)
            .iter()
            .enumerate()
            .filter_map(|(i, &x)| x.then_some(i))
            .collect();
        assert_eq!(found, vec![19]);
    }
}
