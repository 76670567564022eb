//! Phase ReLock's least-squares problem in the tag's position alone, and its solution by
//! Levenberg–Marquardt with the position's covariance.

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{DMatrix, DVector, Dyn, Owned};

use super::Search;
use crate::fix::{NoFix, Obs};
use crate::robust;

/// The least-squares problem in the position alone: each segment's offset is at its best
/// for the position (the mean residual of the segment), so residuals and Jacobian columns are
/// centred per segment (variable projection: the offsets are linear, and the position's
/// covariance from the centred Jacobian is its marginal covariance). A bin of reads
/// ([`Obs::weight`]) counts as its reads: its residual is weighted by the square root of
/// their count.
pub(super) struct Problem<'a> {
    obs: &'a [Obs],
    /// 1 over the reads per segment (one entry a segment).
    inverse_weights: Vec<f64>,
    /// Each phase's √weight.
    root_weights: Vec<f64>,
    /// Reads, and the bins' scatter (rad²), over all phases.
    reads: f64,
    scatter_rad2: f64,
    /// Each phase's s·4π/λ (rad/m).
    k: Vec<f64>,
    /// 2: (x, y) at height `z`; 3: (x, y, z).
    dims: usize,
    z: f64,
    p: DVector<f64>,
    /// Each phase's antenna-to-position vector and its length at `p` (the residuals and the
    /// Jacobian of one position share them).
    to: Vec<([f64; 3], f64)>,
}

impl<'a> Problem<'a> {
    pub(super) fn new(
        obs: &'a [Obs],
        dims: usize,
        z: f64,
        sign: f64,
        start: &[f64],
    ) -> Problem<'a> {
        let segments = obs.iter().map(|o| o.segment + 1).max().unwrap_or(0);
        let mut weights = vec![0.0; segments];
        for o in obs {
            weights[o.segment] += o.weight;
        }
        let mut problem = Problem {
            obs,
            inverse_weights: weights
                .iter()
                .map(|&w| if w > 0.0 { 1.0 / w } else { 0.0 })
                .collect(),
            root_weights: obs.iter().map(|o| o.weight.sqrt()).collect(),
            reads: weights.iter().sum(),
            scatter_rad2: obs.iter().map(|o| o.scatter_rad2).sum(),
            k: obs
                .iter()
                .map(|o| sign * 4.0 * std::f64::consts::PI / o.wavelength_m)
                .collect(),
            dims,
            z,
            p: DVector::from_column_slice(&start[..dims]),
            to: Vec::with_capacity(obs.len()),
        };
        problem.update();
        problem
    }

    /// Each phase's vector from its antenna to the position, and its length (at least 1 nm).
    fn update(&mut self) {
        let z = if self.dims == 3 { self.p[2] } else { self.z };
        let (x, y) = (self.p[0], self.p[1]);
        self.to.clear();
        self.to.extend(self.obs.iter().map(|o| {
            let v = [x - o.antenna[0], y - o.antenna[1], z - o.antenna[2]];
            (
                v,
                (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(1e-9),
            )
        }));
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for Problem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.p.copy_from(x);
        self.update();
    }

    fn params(&self) -> DVector<f64> {
        self.p.clone()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        let mut r = Vec::with_capacity(self.obs.len());
        let mut mean = vec![0.0; self.inverse_weights.len()];
        for ((o, k), &(_, d)) in self.obs.iter().zip(&self.k).zip(&self.to) {
            let v = o.phase_rad - k * d;
            mean[o.segment] += o.weight * v;
            r.push(v);
        }
        for (m, inv) in mean.iter_mut().zip(&self.inverse_weights) {
            *m *= inv;
        }
        for ((o, v), w) in self.obs.iter().zip(r.iter_mut()).zip(&self.root_weights) {
            *v = w * (*v - mean[o.segment]);
        }
        Some(DVector::from_vec(r))
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        // Column-major, filled in place: column a holds ∂r_i/∂p_a.
        let n = self.obs.len();
        let mut j = vec![0.0; n * self.dims];
        let mut mean = vec![[0.0; 3]; self.inverse_weights.len()];
        for (i, ((o, k), &(v, d))) in self.obs.iter().zip(&self.k).zip(&self.to).enumerate() {
            let g = -k / d;
            for a in 0..self.dims {
                let x = g * v[a];
                j[a * n + i] = x;
                mean[o.segment][a] += o.weight * x;
            }
        }
        for (m, inv) in mean.iter_mut().zip(&self.inverse_weights) {
            for x in m.iter_mut() {
                *x *= inv;
            }
        }
        for a in 0..self.dims {
            let column = j[a * n..(a + 1) * n].iter_mut();
            for ((x, o), w) in column.zip(self.obs).zip(&self.root_weights) {
                *x = w * (*x - mean[o.segment][a]);
            }
        }
        Some(DMatrix::from_vec(n, self.dims, j))
    }
}

/// Runs Levenberg–Marquardt from `problem`'s start; the solution, its covariance ((JᵀJ)⁻¹
/// times the residual variance) and the RMS residual, both per read (a bin's scatter
/// counted). A solution outside the search box of `s` is no fix: the phases did not pin the
/// tag down.
pub(super) fn solve(problem: Problem<'_>, s: &Search) -> Result<Solution, NoFix> {
    let (dims, segments) = (problem.dims, problem.inverse_weights.len());
    let (reads, scatter) = (problem.reads, problem.scatter_rad2);
    let (solved, report) = solver().minimize(problem);
    let j = solved.jacobian().ok_or(NoFix::InsufficientGeometry)?;
    // The objective is ½‖r‖² at the parameters returned.
    let squares = 2.0 * report.objective_function + scatter;
    let variance = squares / (reads - (dims + segments) as f64).max(1.0);
    let info = DMatrix::from_fn(dims, dims, |a, b| j.column(a).dot(&j.column(b)));
    let bread = info.try_inverse().ok_or(NoFix::InsufficientGeometry)?;
    let cov = &bread * variance;
    let p = solved.p;
    let inside = (0..2).all(|a| p[a].is_finite() && p[a] >= s.lo[a] && p[a] <= s.hi[a]);
    let finite = (0..dims).all(|a| p[a].is_finite() && cov[(a, a)].is_finite());
    if !(inside && finite) {
        return Err(NoFix::InsufficientGeometry);
    }
    Ok((p, cov, (squares / reads.max(1.0)).sqrt()))
}

/// The covariance to report for `fit` of `obs`, once it is chosen: at least its classic one,
/// the cluster-robust (sandwich) one and the one of a smooth angle-dependent phase error in
/// every direction (`robust`); the classic one steers the search (joining, the weak axes).
pub(super) fn reported(fit: &Solution, obs: &[Obs], s: &Search) -> DMatrix<f64> {
    let (p, cov, _) = fit;
    let problem = Problem::new(obs, s.dims, s.z, s.sign, p.as_slice());
    let (Some(r), Some(j)) = (problem.residuals(), problem.jacobian()) else {
        return cov.clone();
    };
    let dims = s.dims;
    let info = DMatrix::from_fn(dims, dims, |a, b| j.column(a).dot(&j.column(b)));
    let (Some(bread), true) = (info.try_inverse(), r.iter().all(|x| x.is_finite())) else {
        return cov.clone();
    };
    let scores = DMatrix::from_fn(r.len(), dims, |i, a| j[(i, a)] * r[i]);
    let segment_of: Vec<usize> = obs.iter().map(|o| o.segment).collect();
    let weight: Vec<f64> = obs.iter().map(|o| o.weight).collect();
    let cluster_of = robust::clusters(&segment_of, &weight);
    let sandwich = robust::at_least_sandwich(cov, &bread, &scores, &cluster_of);
    let rows: Vec<robust::Row> = obs
        .iter()
        .zip(&problem.to)
        .map(|(o, &(v, d))| robust::Row {
            direction: v.map(|x| x / d),
            weight: o.weight,
            segment: o.segment,
        })
        .collect();
    match robust::smooth_error(&bread, &j, &r, &rows, true) {
        Some(smooth) => robust::at_least(&sandwich, &smooth),
        None => sandwich,
    }
}

/// Levenberg–Marquardt with the relative tolerances at 1e-8 (the crate's default, 30 machine
/// epsilons, spent some 9 evaluations a solve on S2 where these take 6, for the same fixes to
/// a tenth of a millimetre: 1e-8 of a position is well under a micrometre).
fn solver() -> LevenbergMarquardt<f64> {
    const TOL: f64 = 1e-8;
    LevenbergMarquardt::new()
        .with_xtol(TOL)
        .with_ftol(TOL)
        .with_gtol(TOL)
}

/// A solution: position, covariance ((JᵀJ)⁻¹·σ²) and RMS residual (the covariance to report
/// is [`reported`]'s, from the phases it was solved on).
pub(super) type Solution = (DVector<f64>, DMatrix<f64>, f64);
