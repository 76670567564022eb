//! The covariance an estimator reports when its residuals are correlated along the pass (an
//! angle-dependent phase error, a reflection, the poses' own error): at least the classic
//! (JᵀJ)⁻¹·σ² and at least the cluster-robust (sandwich) one in every direction, the clusters
//! runs of consecutive phases (Liang & Zeger, *Biometrika* 1986; Cameron & Miller, *J. Human
//! Resources* 2015). docs/localize.md "Residuals correlated along the pass".

use nalgebra::{DMatrix, DVector, Matrix3, SymmetricEigen, Vector3};
use rustc_hash::FxHashMap;

/// Clusters of consecutive phases a segment is cut into.
pub const CLUSTERS_PER_SEGMENT: usize = 10;

/// The cluster of each phase: runs of consecutive phases of one segment (`segment_of`), each
/// holding about a [`CLUSTERS_PER_SEGMENT`]th of its segment's `weight`, numbered in order.
pub fn clusters(segment_of: &[usize], weight: &[f64]) -> Vec<usize> {
    let segments = segment_of.iter().map(|s| s + 1).max().unwrap_or(0);
    let mut total = vec![0.0; segments];
    for (&s, &w) in segment_of.iter().zip(weight) {
        total[s] += w;
    }
    let (mut ids, mut id, mut filled) = (Vec::with_capacity(segment_of.len()), 0, 0.0);
    let mut current = usize::MAX;
    for (&s, &w) in segment_of.iter().zip(weight) {
        let limit = total[s] / CLUSTERS_PER_SEGMENT as f64;
        if current != usize::MAX && (s != current || filled >= limit) {
            id += 1;
            filled = 0.0;
        }
        current = s;
        ids.push(id);
        filled += w;
    }
    ids
}

/// `classic` made at least the sandwich `bread`·(Σ g_c g_cᵀ)·`bread`·G/(G − 1) in every
/// direction, g_c the sum of the rows of `scores` (one a phase: its Jacobian row times its
/// residual) over cluster c of `cluster_of`: `classic` plus the positive part of their
/// difference; `classic` itself when that is not finite.
pub fn at_least_sandwich(
    classic: &DMatrix<f64>,
    bread: &DMatrix<f64>,
    scores: &DMatrix<f64>,
    cluster_of: &[usize],
) -> DMatrix<f64> {
    let dims = bread.nrows();
    let count = cluster_of.iter().map(|c| c + 1).max().unwrap_or(0);
    let mut sums = vec![DVector::<f64>::zeros(dims); count];
    for (i, &c) in cluster_of.iter().enumerate() {
        for a in 0..dims {
            sums[c][a] += scores[(i, a)];
        }
    }
    let mut meat = DMatrix::<f64>::zeros(dims, dims);
    for g in &sums {
        meat += g * g.transpose();
    }
    let correction = if count > 1 {
        count as f64 / (count - 1) as f64
    } else {
        1.0
    };
    at_least(classic, &(bread * meat * bread * correction))
}

/// `a` made at least `b` in every direction: `a` plus the positive part of `b − a`; `a`
/// itself when that is not finite.
pub fn at_least(a: &DMatrix<f64>, b: &DMatrix<f64>) -> DMatrix<f64> {
    let extra = b - a;
    if !extra.iter().all(|x| x.is_finite()) {
        return a.clone();
    }
    let eigen = SymmetricEigen::new(extra);
    let positive = eigen.eigenvalues.map(|v| v.max(0.0));
    a + &eigen.eigenvectors * DMatrix::from_diagonal(&positive) * eigen.eigenvectors.transpose()
}

/// Angle (rad) over which the phase error of the direction a tag is read from stays alike:
/// the Gaussian kernel's length that [`smooth_error`] assumes.
pub const SMOOTH_ERROR_RAD: f64 = 12.0 * std::f64::consts::PI / 180.0;

/// Phases whose directions fall in one cell of this size (rad) share one kernel value in
/// [`smooth_error`]: half of [`SMOOTH_ERROR_RAD`], across which the kernel falls to 0.88, so
/// that a tag seen over 60° by 40° takes about 100 cells (a covariance, not a position, is
/// what the approximation moves).
const CELL_RAD: f64 = SMOOTH_ERROR_RAD / 2.0;

/// One row of a least-squares problem as [`smooth_error`] sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Row {
    /// Unit direction between the tag and the antenna when the phase was read.
    pub direction: [f64; 3],
    /// Reads the row stands for; its residual and Jacobian row are scaled by its square root.
    pub weight: f64,
    /// Segment whose offset the row's residual and Jacobian row are centred on (weighted).
    pub segment: usize,
}

/// The covariance of a fit whose phases carry white noise and an error smooth in the
/// direction the tag is read from (a phase pattern of the antenna or the tag): the error
/// taken as a Gaussian process over directions, kernel exp(−θ²/2ℓ²) with ℓ
/// [`SMOOTH_ERROR_RAD`], σ_n²·(JᵀJ)⁻¹ + σ_s²·(JᵀJ)⁻¹·(Jᵀ√W K √W J)·(JᵀJ)⁻¹ with (JᵀJ)⁻¹ =
/// `bread`, σ_n² and σ_s² as [`evidence`] finds them. Unlike the cluster-robust covariance it
/// counts the part of the error that looks like geometry, which no residual shows.
/// `jacobian` and `residuals` are the rows' as solved (√weight-scaled, centred per segment
/// when `centred`). `None` when the residuals show no smooth error (see [`Evidence`]).
pub fn smooth_error(
    bread: &DMatrix<f64>,
    jacobian: &DMatrix<f64>,
    residuals: &DVector<f64>,
    rows: &[Row],
    centred: bool,
) -> Option<DMatrix<f64>> {
    smooth_error_and_evidence(bread, jacobian, residuals, rows, centred)?.1
}

/// [`smooth_error`] with the [`evidence`] it rests on (`None` when there is none either).
pub fn smooth_error_and_evidence(
    bread: &DMatrix<f64>,
    jacobian: &DMatrix<f64>,
    residuals: &DVector<f64>,
    rows: &[Row],
    centred: bool,
) -> Option<(Evidence, Option<DMatrix<f64>>)> {
    let (found, meat) = evidence_and_meat(bread, jacobian, residuals, rows, centred)?;
    let cov = found.smooth_variance().and_then(|smooth| {
        let cov = bread * found.noise_variance() + bread * meat * bread * smooth;
        cov.iter().all(|x| x.is_finite()).then_some(cov)
    });
    Some((found, cov))
}

/// What the residuals of one or more least-squares fits tell about a smooth error beyond the
/// white noise ([`evidence`]); fits of one tag add up (`+`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Evidence {
    /// ‖r‖² − σ_n²·dof summed: what the residuals hold beyond the noise.
    excess: f64,
    /// tr M − tr((JᵀJ)⁻¹JᵀMJ) summed: what a unit smooth error leaves in the residuals.
    seen: f64,
    /// (σ_n²)²·2·dof summed: the excess's variance on white noise alone.
    spread: f64,
    /// σ_n²·dof and dof summed.
    noise_dof: f64,
    dof: f64,
}

impl std::ops::Add for Evidence {
    type Output = Evidence;

    /// Both fits' evidence.
    fn add(self, other: Evidence) -> Evidence {
        Evidence {
            excess: self.excess + other.excess,
            seen: self.seen + other.seen,
            spread: self.spread + other.spread,
            noise_dof: self.noise_dof + other.noise_dof,
            dof: self.dof + other.dof,
        }
    }
}

impl Evidence {
    /// σ_s² (the smooth error's variance, in the residuals' units squared); `None` when the
    /// excess is within twice its own spread on white noise alone.
    pub fn smooth_variance(&self) -> Option<f64> {
        (self.seen > 0.0 && self.excess > 2.0 * self.spread.sqrt()).then(|| self.excess / self.seen)
    }

    /// σ_n², the white noise's variance per read.
    pub fn noise_variance(&self) -> f64 {
        self.noise_dof / self.dof.max(1.0)
    }
}

/// What one fit's residuals tell about a smooth error: the white noise σ_n² (per read) from
/// the differences of consecutive residuals of a segment (von Neumann), and what the residuals
/// hold beyond it against what a unit smooth error would leave in them once the fit has
/// absorbed its part (E‖r‖² = σ_s²·(tr M − tr((JᵀJ)⁻¹JᵀMJ)) + σ_n²·dof, M = √W C K Cᵀ √W, C
/// the centring on the segments, the identity when not `centred`).
pub fn evidence(
    bread: &DMatrix<f64>,
    jacobian: &DMatrix<f64>,
    residuals: &DVector<f64>,
    rows: &[Row],
    centred: bool,
) -> Option<Evidence> {
    evidence_and_meat(bread, jacobian, residuals, rows, centred).map(|(e, _)| e)
}

/// [`evidence`], and Jᵀ√W K √W J on the way.
fn evidence_and_meat(
    bread: &DMatrix<f64>,
    jacobian: &DMatrix<f64>,
    residuals: &DVector<f64>,
    rows: &[Row],
    centred: bool,
) -> Option<(Evidence, DMatrix<f64>)> {
    let (n, dims) = (rows.len(), bread.nrows());
    let segments = rows.iter().map(|r| r.segment + 1).max().unwrap_or(0);
    let offsets = if centred { segments } else { 0 };
    let dof = n as f64 - (dims + offsets) as f64;
    if dims > 3 || n != residuals.len() || n != jacobian.nrows() || dof < 1.0 {
        return None;
    }
    let (mut diff, mut scale) = (0.0, 0.0);
    for i in 1..n {
        let (a, b) = (&rows[i - 1], &rows[i]);
        if a.segment == b.segment && a.weight > 0.0 && b.weight > 0.0 {
            let d = residuals[i] / b.weight.sqrt() - residuals[i - 1] / a.weight.sqrt();
            diff += d * d;
            scale += 1.0 / a.weight + 1.0 / b.weight;
        }
    }
    if scale <= 0.0 {
        return None;
    }
    let noise = diff / scale;
    let meat = kernel_sum(
        rows.iter()
            .enumerate()
            .map(|(i, r)| (r.direction, scaled_row(jacobian, i, r.weight))),
    );
    let meat = DMatrix::from_fn(dims, dims, |a, b| meat[(a, b)]);
    // Each segment's Σ w_c w_d K(c, d) over runs of its consecutive rows within CELL_RAD of
    // the run's first.
    let far = 1.0 - (CELL_RAD * CELL_RAD) / 2.0;
    let mut runs: Vec<Vec<([f64; 3], f64)>> = vec![Vec::new(); segments];
    let mut last = usize::MAX;
    for r in rows {
        let run = &mut runs[r.segment];
        match run.last_mut() {
            Some(c) if last == r.segment && dot(c.0, r.direction) >= far => c.1 += r.weight,
            _ => run.push((r.direction, r.weight)),
        }
        last = r.segment;
    }
    let (mut within, mut total) = (vec![0.0; segments], vec![0.0; segments]);
    for (s, run) in runs.iter().enumerate() {
        for (ci, c) in run.iter().enumerate() {
            total[s] += c.1;
            within[s] += c.1 * c.1;
            for d in run[ci + 1..].iter().filter(|_| centred) {
                within[s] += 2.0 * c.1 * d.1 * kernel(c.0, d.0);
            }
        }
    }
    // tr M: Σ_s (W_s − Σ_{c,d∈s} w_c w_d K / W_s).
    let trace_m: f64 = (0..segments)
        .filter(|&s| total[s] > 0.0)
        .map(|s| total[s] - if centred { within[s] / total[s] } else { 0.0 })
        .sum();
    let seen = trace_m - (bread * &meat).trace();
    let found = Evidence {
        excess: residuals.norm_squared() - noise * dof,
        seen,
        spread: noise * noise * 2.0 * dof,
        noise_dof: noise * dof,
        dof,
    };
    [found.excess, found.seen, found.spread]
        .iter()
        .all(|x| x.is_finite())
        .then_some((found, meat))
}

/// Row `i` of `jacobian` times √`weight`, padded to three.
fn scaled_row(jacobian: &DMatrix<f64>, i: usize, weight: f64) -> Vector3<f64> {
    let mut z = Vector3::zeros();
    for a in 0..jacobian.ncols().min(3) {
        z[a] = jacobian[(i, a)] * weight.sqrt();
    }
    z
}

/// The smooth error's kernel between two unit directions; 0 beyond the angle where it falls
/// under 1e-6.
fn kernel(a: [f64; 3], b: [f64; 3]) -> f64 {
    let l2 = SMOOTH_ERROR_RAD * SMOOTH_ERROR_RAD;
    let gap = 1.0 - dot(a, b);
    if gap > 14.0 * l2 {
        0.0
    } else {
        (-gap / l2).exp()
    }
}

/// Σ_ij K(u_i, u_j)·g_i·g_jᵀ over `influence` (direction u_i, vector g_i): the covariance a
/// unit smooth error brings to whatever moves by g_i per unit error on row i. Rows are pooled
/// in cells of about half [`SMOOTH_ERROR_RAD`] of angle (the error depends on the direction
/// alone, whatever the segment or channel).
pub fn kernel_sum(influence: impl Iterator<Item = ([f64; 3], Vector3<f64>)>) -> Matrix3<f64> {
    let mut index: FxHashMap<[i64; 3], usize> = FxHashMap::default();
    let mut cells: Vec<([f64; 3], Vector3<f64>)> = Vec::new();
    for (u, g) in influence {
        // A cube grid on the unit vector: cells of about CELL_RAD of angle, no trigonometry.
        let key = u.map(|x| (x / CELL_RAD).round() as i64);
        let at = *index.entry(key).or_insert_with(|| {
            cells.push((u, Vector3::zeros()));
            cells.len() - 1
        });
        cells[at].1 += g;
    }
    let mut sum = Matrix3::<f64>::zeros();
    for (ci, c) in cells.iter().enumerate() {
        // Σ_{d after c} K(c, d)·g_d: the pairs (c, d) and (d, c) at once.
        let mut others = Vector3::zeros();
        for d in &cells[ci + 1..] {
            others += d.1 * kernel(c.0, d.0);
        }
        sum += c.1 * c.1.transpose() + c.1 * others.transpose() + others * c.1.transpose();
    }
    sum
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clusters_cut_each_segment_into_runs_by_weight() {
        let ids = clusters(
            &[0; 20].iter().chain(&[1; 5]).copied().collect::<Vec<_>>(),
            &[1.0; 25],
        );
        // 20 phases in runs of 2, then 5 in runs of one (a tenth of 5 is under a phase).
        assert_eq!(&ids[..4], &[0, 0, 1, 1]);
        assert_eq!(ids[19], 9);
        assert_eq!(&ids[20..], &[10, 11, 12, 13, 14]);
    }

    #[test]
    fn the_reported_covariance_is_at_least_either_in_every_direction() {
        let classic = DMatrix::from_row_slice(2, 2, &[4.0, 0.0, 0.0, 1.0]);
        let bread = DMatrix::identity(2, 2);
        // Two clusters whose scores sum to (0, 3) and (0, −3): a sandwich of 18·2 along y only.
        let scores = DMatrix::from_row_slice(4, 2, &[0.0, 1.0, 0.0, 2.0, 0.0, -1.0, 0.0, -2.0]);
        let r = at_least_sandwich(&classic, &bread, &scores, &[0, 0, 1, 1]);
        assert!(
            (r[(0, 0)] - 4.0).abs() < 1e-9 && (r[(1, 1)] - 36.0).abs() < 1e-9,
            "{r}"
        );
        // Uncorrelated scores that cancel: the classic stands.
        let quiet = DMatrix::from_row_slice(2, 2, &[0.0, 0.1, 0.0, -0.1]);
        assert_eq!(
            at_least_sandwich(&classic, &bread, &quiet, &[0, 0]),
            classic
        );
    }

    /// Rows at 141 directions from −35° to 35° of one segment, a one-column Jacobian sin θ
    /// (what an along-path position moves), centred; the residuals of `error` after the fit.
    fn fit_rows(error: &[f64]) -> (DMatrix<f64>, DMatrix<f64>, DVector<f64>, Vec<Row>) {
        let n = error.len();
        let angles: Vec<f64> = (0..n)
            .map(|i| (-35.0 + 70.0 * i as f64 / (n - 1) as f64).to_radians())
            .collect();
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        let g: Vec<f64> = angles.iter().map(|a| a.sin()).collect();
        let (gm, em) = (mean(&g), mean(error));
        let j = DMatrix::from_fn(n, 1, |i, _| g[i] - gm);
        let bread = (j.transpose() * &j).try_inverse().expect("a full column");
        let e = DVector::from_fn(n, |i, _| error[i] - em);
        let r = &e - &j * (&bread * (j.transpose() * &e));
        let rows = angles
            .iter()
            .map(|a| Row {
                direction: [a.sin(), a.cos(), 0.0],
                weight: 1.0,
                segment: 0,
            })
            .collect();
        (bread, j, r, rows)
    }

    #[test]
    fn white_noise_shows_no_smooth_error_and_a_smooth_one_is_sized() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let white = Normal::new(0.0, 0.02).expect("valid σ");
        let (mut found, mut sizes) = (0, Vec::new());
        for seed in 0..20 {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            let noise: Vec<f64> = (0..141).map(|_| white.sample(&mut rng)).collect();
            let (bread, j, r, rows) = fit_rows(&noise);
            let e = evidence(&bread, &j, &r, &rows, true).expect("evidence");
            found += usize::from(e.smooth_variance().is_some());
            assert!((e.noise_variance().sqrt() - 0.02).abs() < 0.005, "{e:?}");
            // The same noise plus 0.3 rad of a cosine of the angle turning over 40°.
            let smooth: Vec<f64> = noise
                .iter()
                .enumerate()
                .map(|(i, x)| {
                    let a = (-35.0 + 70.0 * i as f64 / 140.0_f64).to_radians();
                    x + 0.3 * std::f64::consts::SQRT_2 * (a * 9.0 + seed as f64).cos()
                })
                .collect();
            let (bread, j, r, rows) = fit_rows(&smooth);
            let e = evidence(&bread, &j, &r, &rows, true).expect("evidence");
            sizes.push(e.smooth_variance().map_or(0.0, f64::sqrt));
        }
        // Twice its own spread: about one seed in forty on white noise.
        assert!(
            found <= 2,
            "a smooth error found on white noise in {found} of 20"
        );
        let mean = sizes.iter().sum::<f64>() / sizes.len() as f64;
        assert!(
            sizes.iter().all(|&s| s > 0.1) && (0.15..0.6).contains(&mean),
            "σ_s {sizes:?}"
        );
    }

    #[test]
    fn the_kernel_sum_adds_rows_alike_and_leaves_far_ones_apart() {
        let g = |x: f64| Vector3::new(x, 0.0, 0.0);
        let near = kernel_sum([([0.0, 1.0, 0.0], g(1.0)), ([0.0, 1.0, 0.0], g(2.0))].into_iter());
        assert!((near[(0, 0)] - 9.0).abs() < 1e-12, "{near}");
        let far = kernel_sum([([0.0, 1.0, 0.0], g(1.0)), ([1.0, 0.0, 0.0], g(2.0))].into_iter());
        assert!((far[(0, 0)] - 5.0).abs() < 1e-9, "{far}");
        // Opposite influences at one direction cancel: an error both see alike moves nothing.
        let cancel =
            kernel_sum([([0.0, 1.0, 0.0], g(1.0)), ([0.0, 1.0, 0.0], g(-1.0))].into_iter());
        assert!(cancel[(0, 0)].abs() < 1e-12, "{cancel}");
    }
}
