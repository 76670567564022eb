//! The share of a tag's covariance that the antennas' pose error brings. A robot's reported
//! pose (a localization stack's) is off by an error shared by every tag read at one moment and
//! correlated over time; the phases' own noise, which is all the estimators' covariance
//! measures, says nothing of it. Propagated through the phase model's least squares (each
//! segment's offset free, as in `relock`), a pose error δ(t) moves the fix by
//! Δp = −A Σᵢ Jᵢ kᵢ uᵢᵀ δ(tᵢ), with Jᵢ the segment-centred Jacobian row, A = (JᵀJ)⁻¹, kᵢ = 4π/λᵢ
//! and uᵢ the horizontal part of the unit vector from the antenna to the tag. With δ a
//! first-order Gauss–Markov process of σ in x and in y (correlation e^(−|Δt|/τ)), independent
//! between readers, its covariance is σ² A S A, S = Σᵢⱼ ρᵢⱼ Bᵢ Bⱼᵀ, summed in time order in one
//! pass per reader.

use nalgebra::{DMatrix, SMatrix};

use crate::fix::Obs;
use crate::refine::PoseErrorModel;

/// One phase's Bᵢ: its centred Jacobian row (per position axis) times kᵢ uᵢᵀ; dims × 2.
type B = SMatrix<f64, 3, 2>;

/// The covariance (3×3 row-major, m²; rows and columns past `dims` 0) that the pose error `m`
/// adds to a fix at `position` from `obs`, whose phase `i` was read by reader
/// `reader_of(obs[i].group)`; `None` when the phases do not fix the position (A singular).
pub fn pose_share(
    obs: &[Obs],
    position: [f64; 3],
    dims: usize,
    m: &PoseErrorModel,
    reader_of: &dyn Fn(usize) -> usize,
) -> Option<[f64; 9]> {
    let dims = dims.clamp(2, 3);
    let segments = obs.iter().map(|o| o.segment + 1).max().unwrap_or(0);
    // Each phase's Jacobian row ∂(k·d)/∂p and the segment means, weighted by the reads.
    let mut rows: Vec<[f64; 3]> = Vec::with_capacity(obs.len());
    let mut units: Vec<[f64; 2]> = Vec::with_capacity(obs.len());
    let mut mean = vec![[0.0; 3]; segments];
    let mut weight = vec![0.0; segments];
    for o in obs {
        let v = [0, 1, 2].map(|a| position[a] - o.antenna[a]);
        let d = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(1e-9);
        let k = 4.0 * std::f64::consts::PI / o.wavelength_m;
        let row = [0, 1, 2].map(|a| if a < dims { k * v[a] / d } else { 0.0 });
        for a in 0..3 {
            mean[o.segment][a] += o.weight * row[a];
        }
        weight[o.segment] += o.weight;
        rows.push(row);
        units.push([k * v[0] / d, k * v[1] / d]);
    }
    for (m, w) in mean.iter_mut().zip(&weight) {
        if *w > 0.0 {
            *m = m.map(|x| x / w);
        }
    }
    // Centred, √weight-scaled rows (Jᵢ) and Bᵢ = √wᵢ Jᵢ kᵢ uᵢᵀ.
    let mut info = DMatrix::<f64>::zeros(dims, dims);
    let mut bs: Vec<B> = Vec::with_capacity(obs.len());
    for ((o, row), u) in obs.iter().zip(&rows).zip(&units) {
        let w = o.weight.sqrt();
        let j = [0, 1, 2].map(|a| w * (row[a] - mean[o.segment][a]));
        for a in 0..dims {
            for b in 0..dims {
                info[(a, b)] += j[a] * j[b];
            }
        }
        bs.push(B::from_fn(|a, c| w * j[a] * u[c]));
    }
    let a = info.try_inverse()?;
    // S in time order per reader: Cᵢ = ρ(tᵢ − tᵢ₋₁)(Cᵢ₋₁ + Bᵢ₋₁) is Σⱼ<ᵢ ρᵢⱼ Bⱼ.
    let mut order: Vec<usize> = (0..obs.len()).collect();
    order.sort_by_key(|&i| (reader_of(obs[i].group), obs[i].t_us));
    let tau_us = (m.correlation_s * 1e6).max(1.0);
    let mut s = SMatrix::<f64, 3, 3>::zeros();
    let mut c = B::zeros();
    for (n, &i) in order.iter().enumerate() {
        let reader = reader_of(obs[i].group);
        c = match n.checked_sub(1).map(|p| order[p]) {
            Some(p) if reader_of(obs[p].group) == reader => {
                let dt = obs[i].t_us.saturating_sub(obs[p].t_us) as f64;
                (c + bs[p]) * (-dt / tau_us).exp()
            }
            _ => B::zeros(),
        };
        let b = bs[i];
        s += b * b.transpose() + b * c.transpose() + c * b.transpose();
    }
    let s = DMatrix::from_fn(dims, dims, |x, y| s[(x, y)]);
    let cov = &a * s * &a * (m.sigma_m * m.sigma_m);
    let mut out = [0.0; 9];
    for x in 0..dims {
        for y in 0..dims {
            out[3 * x + y] = cov[(x, y)];
        }
    }
    out.iter().all(|v| v.is_finite()).then_some(out)
}

/// The covariance (3×3 row-major, m²; rows and columns past `dims` 0) that a tag's own
/// phase curvature a·θ² brings to a fix at `position` from `obs`, a drawn from N(0,
/// `sigma_rad`²) (rad per rad²): θ the angle between the direction a phase was read from and
/// the horizontal one of its segment's nearest read (the boresight of an antenna that faces
/// the path level).
/// Such a term bends the phase curve as a tag nearer or farther would and leaves no residual
/// (docs/measurement.md); through the least squares with each segment's offset free it moves
/// the fix by g·a, g = A Σᵢ wᵢ J̃ᵢ θᵢ², so its covariance is σ²·g gᵀ. `None` when the phases
/// do not fix the position.
pub fn curvature_share(
    obs: &[Obs],
    position: [f64; 3],
    dims: usize,
    sigma_rad: f64,
) -> Option<[f64; 9]> {
    let dims = dims.clamp(2, 3);
    let segments = obs.iter().map(|o| o.segment + 1).max().unwrap_or(0);
    let mut rows: Vec<[f64; 3]> = Vec::with_capacity(obs.len());
    let mut units: Vec<[f64; 3]> = Vec::with_capacity(obs.len());
    let mut mean = vec![[0.0; 3]; segments];
    let mut weight = vec![0.0; segments];
    let mut nearest = vec![(f64::INFINITY, [0.0; 3]); segments];
    for o in obs {
        let v = [0, 1, 2].map(|a| position[a] - o.antenna[a]);
        let d = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(1e-9);
        let k = 4.0 * std::f64::consts::PI / o.wavelength_m;
        let row = [0, 1, 2].map(|a| if a < dims { k * v[a] / d } else { 0.0 });
        for a in 0..3 {
            mean[o.segment][a] += o.weight * row[a];
        }
        weight[o.segment] += o.weight;
        let u = v.map(|x| x / d);
        if d < nearest[o.segment].0 {
            nearest[o.segment] = (d, u);
        }
        rows.push(row);
        units.push(u);
    }
    for (m, w) in mean.iter_mut().zip(&weight) {
        if *w > 0.0 {
            *m = m.map(|x| x / w);
        }
    }
    // The boresight: the nearest read's direction made horizontal (antennas that face the
    // path level, at whatever height: S1, S2, the rail).
    for n in &mut nearest {
        let h = n.1[0].hypot(n.1[1]);
        if h > 1e-6 {
            n.1 = [n.1[0] / h, n.1[1] / h, 0.0];
        }
    }
    // The curvature's phase is centred on each segment's offset, as the fit centres it.
    let mut bend = vec![0.0; segments];
    let thetas: Vec<f64> = obs
        .iter()
        .zip(&units)
        .map(|(o, u)| {
            let c = nearest[o.segment].1;
            let cos = (u[0] * c[0] + u[1] * c[1] + u[2] * c[2]).clamp(-1.0, 1.0);
            let t2 = cos.acos().powi(2);
            bend[o.segment] += o.weight * t2;
            t2
        })
        .collect();
    for (b, w) in bend.iter_mut().zip(&weight) {
        if *w > 0.0 {
            *b /= w;
        }
    }
    let mut info = DMatrix::<f64>::zeros(dims, dims);
    let mut push = nalgebra::DVector::<f64>::zeros(dims);
    for ((o, row), t2) in obs.iter().zip(&rows).zip(&thetas) {
        let j = [0, 1, 2].map(|a| row[a] - mean[o.segment][a]);
        for a in 0..dims {
            for b in 0..dims {
                info[(a, b)] += o.weight * j[a] * j[b];
            }
            push[a] += o.weight * j[a] * (t2 - bend[o.segment]);
        }
    }
    let g = info.try_inverse()? * push;
    let mut out = [0.0; 9];
    for x in 0..dims {
        for y in 0..dims {
            out[3 * x + y] = sigma_rad * sigma_rad * g[x] * g[y];
        }
    }
    out.iter().all(|v| v.is_finite()).then_some(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::relock;
    use crate::synthetic;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// χ² of 2 degrees of freedom at 95 %.
    const CHI2_2_95: f64 = 5.991;

    /// One pass at 1 m/s past a tag at `tag`, its phases from the true antenna positions and
    /// the positions reported with a Gauss–Markov error of σ `m.sigma_m` (x and y) from `seed`.
    fn pass_with_pose_error(tag: [f64; 3], m: &PoseErrorModel, seed: u64) -> Vec<Obs> {
        let mut obs = synthetic::passes(tag, &[tag[2]], (0.9, 0.0), 0.1, seed);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed ^ 0x5eed);
        let n = Normal::new(0.0, 1.0).expect("unit σ is valid");
        let step_us = 10_000_u64;
        let rho = (-(step_us as f64) / (m.correlation_s * 1e6)).exp();
        let mut delta = [0, 1].map(|_| m.sigma_m * n.sample(&mut rng));
        for (k, o) in obs.iter_mut().enumerate() {
            o.t_us = k as u64 * step_us;
            for d in &mut delta {
                *d = rho * *d + m.sigma_m * (1.0 - rho * rho).sqrt() * n.sample(&mut rng);
            }
            o.antenna[0] += delta[0];
            o.antenna[1] += delta[1];
        }
        obs
    }

    /// The squared Mahalanobis distance of `p` from `fix` under the 2×2 covariance `c`.
    fn mahalanobis2(p: [f64; 3], fix: [f64; 3], c: [f64; 4]) -> f64 {
        let (dx, dy) = (p[0] - fix[0], p[1] - fix[1]);
        let det = c[0] * c[3] - c[1] * c[2];
        (c[3] * dx * dx - (c[1] + c[2]) * dx * dy + c[0] * dy * dy) / det
    }

    #[test]
    fn the_95_percent_ellipse_holds_the_truth_under_pose_error_only_with_its_share() {
        let tag = [0.4, 1.1, 0.5];
        // Correlated over 10 s: over the 3 s pass the error is nearly a shift, which no
        // residual shows (over 1 s the smooth error's covariance, `robust`, sees most of it:
        // 87 of 100 then hold without the share).
        let m = PoseErrorModel::new(0.02, 10.0);
        let (mut with, mut without, runs) = (0, 0, 100);
        for seed in 0..runs {
            let obs = pass_with_pose_error(tag, &m, seed);
            let fix = relock::locate(&obs, tag[2], 1.0, [0.0, 1.0], 3.0).expect("a fix");
            let share = pose_share(&obs, fix.position, 2, &m, &|_| 0).expect("a share");
            let own = fix.covariance;
            let wide = [
                own[0] + share[0],
                own[1] + share[1],
                own[2] + share[3],
                own[3] + share[4],
            ];
            without += usize::from(mahalanobis2(tag, fix.position, own) <= CHI2_2_95);
            with += usize::from(mahalanobis2(tag, fix.position, wide) <= CHI2_2_95);
        }
        // Binomial(100, 0.95) falls under 85 with odds of about 1 in 10⁴.
        assert!(with >= 85, "{with}/{runs} inside with the pose share");
        assert!(without <= 50, "{without}/{runs} inside without it");
    }

    #[test]
    fn readers_apart_are_independent_and_a_long_correlation_adds_up() {
        let tag = [0.4, 1.1, 0.5];
        let obs = pass_with_pose_error(tag, &PoseErrorModel::new(0.0, 1.0), 1);
        let p = [tag[0], tag[1], tag[2]];
        let share = |tau: f64, reader: &dyn Fn(usize) -> usize| {
            pose_share(&obs, p, 2, &PoseErrorModel::new(0.02, tau), reader).expect("a share")
        };
        // A nearly white error averages out over 300 reads; a slow one does not.
        assert!(share(1e-6, &|_| 0)[0] * 10.0 < share(10.0, &|_| 0)[0]);
        // Every read on a reader of its own: as if the error were white.
        let mut apart = obs.clone();
        for (k, o) in apart.iter_mut().enumerate() {
            o.group = k;
        }
        // Correlated over 10 s: over the 3 s pass the error is nearly a shift, which no
        // residual shows (over 1 s the smooth error's covariance, `robust`, sees most of it:
        // 87 of 100 then hold without the share).
        let m = PoseErrorModel::new(0.02, 10.0);
        let alone = pose_share(&apart, p, 2, &m, &|group| group).expect("a share");
        assert!(alone[0] * 10.0 < share(10.0, &|_| 0)[0]);
    }

    #[test]
    fn the_95_percent_ellipse_holds_a_tags_own_curvature_only_with_its_share() {
        // A pass along x from −1 to 2 m past a tag 1.1 m off; the tag adds a·θ², a drawn
        // from N(0, 2²) per run (θ off the perpendicular, the antenna facing the path).
        let tag = [0.4, 1.1, 0.5];
        let sigma = 2.0;
        let n = Normal::new(0.0, sigma).expect("valid σ");
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let (mut with, mut without, runs) = (0, 0, 100);
        for seed in 0..runs {
            let a = n.sample(&mut rng);
            let mut obs = synthetic::passes(tag, &[tag[2]], (0.9, 0.0), 0.1, seed);
            for o in &mut obs {
                let theta = ((o.antenna[0] - tag[0]) / (tag[1] - o.antenna[1])).atan();
                o.phase_rad += a * theta * theta;
            }
            let fix = relock::locate(&obs, tag[2], 1.0, [0.0, 1.0], 3.0).expect("a fix");
            let share = curvature_share(&obs, fix.position, 2, sigma).expect("a share");
            let own = fix.covariance;
            let wide = [
                own[0] + share[0],
                own[1] + share[1],
                own[2] + share[3],
                own[3] + share[4],
            ];
            without += usize::from(mahalanobis2(tag, fix.position, own) <= CHI2_2_95);
            with += usize::from(mahalanobis2(tag, fix.position, wide) <= CHI2_2_95);
        }
        // Binomial(100, 0.95) falls under 85 with odds of about 1 in 10⁴.
        assert!(
            with >= 85,
            "{with}/{runs} inside with the curvature's share"
        );
        assert!(without <= 50, "{without}/{runs} inside without it");
        // No curvature, no share.
        let obs = synthetic::passes(tag, &[tag[2]], (0.9, 0.0), 0.1, 1);
        let none = curvature_share(&obs, tag, 2, 0.0).expect("a share");
        assert!(none.iter().all(|&v| v == 0.0));
    }
}
