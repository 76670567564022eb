//! Distributed weighted least squares by average consensus (\[M\] §III-B): each robot's own
//! fixes of the tag are its measurements z = H·(x_T, y_T) + η with H = I₂ (\[M\] eq. 36) and
//! Cov(η) = C = J P Jᵀ from its filter (eq. 37), so it holds F_i = Σ Hᵀ C⁻¹ H and
//! a_i = Σ Hᵀ C⁻¹ z. The robots exchange them over a random connectivity graph with
//! maximum-degree weights, F_i ← F_i + Σ_{j∈N_i} (F_j − F_i)/(1 + d_max) (the same for a_i),
//! and each node's estimate F_i⁻¹ a_i approaches the centralised WLS solution F⁻¹ a.

use nalgebra::{DMatrix, Matrix2, Vector2};
use rand::{Rng, SeedableRng};

use std::collections::BTreeMap;

use crate::estimator::{Locate, Need, Tag, Takes, SIGN};
use crate::fix::{Fix, Fix3, NoFix};
use crate::mhekf::{self, PoseObs};
use crate::observe::pose_observations;
use crate::robust;
use llrp_gateway_vocab::reader_name::ReaderName;

/// The exchange's settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    /// Consensus rounds per estimate; default 50, \[M\]'s "50 messages for each iteration".
    pub rounds: usize,
    /// Chance of a link between two robots beyond the spanning tree; default 0.5.
    pub link_probability: f64,
    /// Seed of the random connectivity graph; default 0.
    pub seed: u64,
    /// Mahalanobis distance² beyond which a robot's fix counts as contradicted by the others';
    /// default 13.82, χ² with 2 degrees of freedom at 0.999.
    pub gate: f64,
    /// Each robot's filter.
    pub filter: mhekf::Settings,
}

impl Default for Settings {
    fn default() -> Settings {
        Settings {
            rounds: 50,
            link_probability: 0.5,
            seed: 0,
            gate: 13.82,
            filter: mhekf::Settings::default(),
        }
    }
}

/// How the exchange went.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConsensusReport {
    /// Robots with a fix of the tag whose information was combined: the nodes.
    pub robots: usize,
    /// Robots with a fix that withdrew it as contradicted by the others'.
    pub withdrawn: usize,
    /// Links of the connectivity graph.
    pub edges: usize,
    /// Rounds run.
    pub rounds: usize,
    /// Messages sent: one (F_i, a_i) per node per neighbour per round, rounds × edges × 2, for
    /// every exchange, plus the flooding of each check's largest statistic ((n − 1) × edges × 2).
    pub messages: u64,
    /// Largest distance of a node's estimate from the centralised WLS solution (m).
    pub disagreement: f64,
}

/// One node's composite information matrix F_i and state a_i.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Node {
    /// F_i = Σ C⁻¹ (m⁻²).
    pub information: Matrix2<f64>,
    /// a_i = Σ C⁻¹ z (m⁻¹).
    pub state: Vector2<f64>,
}

impl Node {
    /// A robot's node from its fixes (H = I₂); `None` if none has an invertible covariance.
    pub fn from_fixes(fixes: &[Fix]) -> Option<Node> {
        let mut node = Node {
            information: Matrix2::zeros(),
            state: Vector2::zeros(),
        };
        let mut any = false;
        for f in fixes {
            let [a, b, c, d] = f.covariance;
            let Some(inv) = Matrix2::new(a, b, c, d).try_inverse() else {
                continue;
            };
            if inv.iter().all(|v| v.is_finite()) {
                node.information += inv;
                node.state += inv * Vector2::new(f.position[0], f.position[1]);
                any = true;
            }
        }
        any.then_some(node)
    }

    /// The node's estimate F_i⁻¹ a_i.
    pub fn estimate(&self) -> Option<Vector2<f64>> {
        self.information.try_inverse().map(|inv| inv * self.state)
    }
}

/// A random connected graph on `n` nodes (ours): node k links to a random earlier node (a
/// spanning tree), then every other pair links with chance `p`. Edges (i, j), i < j.
pub fn graph(n: usize, p: f64, seed: u64) -> Vec<(usize, usize)> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut edges: Vec<(usize, usize)> = (1..n).map(|k| (rng.gen_range(0..k), k)).collect();
    for j in 1..n {
        for i in 0..j {
            if !edges.contains(&(i, j)) && rng.gen::<f64>() < p {
                edges.push((i, j));
            }
        }
    }
    edges.sort_unstable();
    edges
}

/// `rounds` synchronous rounds of average consensus with maximum-degree weights over `edges`.
pub fn consensus(nodes: &mut [Node], edges: &[(usize, usize)], rounds: usize) {
    let mut degree = vec![0usize; nodes.len()];
    for &(i, j) in edges {
        degree[i] += 1;
        degree[j] += 1;
    }
    let eps = 1.0 / (1 + degree.iter().copied().max().unwrap_or(0)) as f64;
    for _ in 0..rounds {
        let old = nodes.to_vec();
        for &(i, j) in edges {
            let (df, da) = (
                old[j].information - old[i].information,
                old[j].state - old[i].state,
            );
            nodes[i].information += df * eps;
            nodes[i].state += da * eps;
            nodes[j].information -= df * eps;
            nodes[j].state -= da * eps;
        }
    }
}

/// How far a robot's own fix `own` is from the rest of the `n` robots' combined one, which
/// it has from its consensus state `agreed` (n·F̄ − F_i, n·ā − a_i): the Mahalanobis distance²
/// of the difference under the sum of both covariances; 0 where either cannot be inverted.
fn disagreement_with_the_rest(own: &Node, agreed: &Node, n: usize) -> f64 {
    let rest_f = agreed.information * n as f64 - own.information;
    let rest_a = agreed.state * n as f64 - own.state;
    let (Some(own_c), Some(rest_c)) = (own.information.try_inverse(), rest_f.try_inverse()) else {
        return 0.0;
    };
    let d = own_c * own.state - rest_c * rest_a;
    (own_c + rest_c)
        .try_inverse()
        .map(|s| (d.transpose() * s * d)[(0, 0)])
        .filter(|m2| m2.is_finite())
        .unwrap_or(0.0)
}

/// The tag at height `z` from several robots' reads: per robot, its tracks (one antenna each,
/// in time order), each run through [`mhekf::locate`]. The robots with a fix exchange their
/// information; a robot whose fix the others' contradict (Mahalanobis distance² above
/// `s.gate`) withdraws, one at a time while three or more remain, and the rest exchange again
/// (ours: \[M\] combines every fix). The result is the first remaining robot's node, its
/// covariance (n·F_i)⁻¹, made at least (ours) what the combination's weights give the fixes'
/// [`mhekf::honest`] covariances: the filters' own covariances weigh and gate, as in \[M\],
/// but leave out a phase error smooth in the direction the tag is read from.
pub fn locate(
    robots: &[Vec<Vec<PoseObs>>],
    z: f64,
    sign: f64,
    facing: Option<[f64; 2]>,
    s: &Settings,
) -> Result<(Fix, ConsensusReport), NoFix> {
    let robot_fixes = robot_fixes(robots, z, sign, facing, s);
    let own = robot_fixes.nodes;
    let honest = robot_fixes.honest;
    let (sq, reads) = (robot_fixes.sq, robot_fixes.reads);
    if own.is_empty() {
        return Err(NoFix::InsufficientGeometry);
    }
    let Agreed {
        active,
        nodes,
        edges,
        messages,
    } = withdraw_and_agree(&own, s);
    let n = nodes.len();
    let (f_sum, a_sum) = active
        .iter()
        .fold((Matrix2::zeros(), Vector2::zeros()), |(f, a), &i| {
            (f + own[i].information, a + own[i].state)
        });
    let central = f_sum
        .try_inverse()
        .map(|inv| inv * a_sum)
        .ok_or(NoFix::InsufficientGeometry)?;
    let mut disagreement: f64 = 0.0;
    for nd in &nodes {
        let e = nd.estimate().ok_or(NoFix::InsufficientGeometry)?;
        disagreement = disagreement.max((e - central).norm());
    }
    let first = nodes.first().ok_or(NoFix::InsufficientGeometry)?;
    let x = first.estimate().ok_or(NoFix::InsufficientGeometry)?;
    let cov = (first.information * n as f64)
        .try_inverse()
        .ok_or(NoFix::InsufficientGeometry)?;
    // x ≈ Σ F⁻¹C_f⁻¹ z_f over the fixes f of the robots still in: its covariance with each
    // fix's honest one.
    let weights = f_sum.try_inverse().ok_or(NoFix::InsufficientGeometry)?;
    let spread = honest_spread(&active, &honest, &weights);
    let cov = robust::at_least(
        &DMatrix::from_column_slice(2, 2, cov.as_slice()),
        &DMatrix::from_column_slice(2, 2, spread.as_slice()),
    );
    let covariance = [cov[(0, 0)], cov[(0, 1)], cov[(1, 0)], cov[(1, 1)]];
    if !(x.iter().chain(&covariance).all(|v| v.is_finite()) && disagreement.is_finite()) {
        return Err(NoFix::InsufficientGeometry);
    }
    let report = ConsensusReport {
        robots: n,
        withdrawn: own.len() - n,
        edges: edges.len(),
        rounds: s.rounds,
        messages,
        disagreement,
    };
    let fix = Fix {
        position: [x[0], x[1], z],
        covariance,
        rms_rad: (sq / reads.max(1) as f64).sqrt(),
    };
    Ok((fix, report))
}

/// Each robot's filter fixes and the node they make.
struct RobotFixes {
    /// One node per robot with a fix.
    nodes: Vec<Node>,
    /// Per node: its tracks' fixes and their [`mhekf::honest`] widenings.
    honest: Vec<(Vec<Fix>, Vec<Fix>)>,
    /// Σ rms² · phases over the fixes.
    sq: f64,
    /// Phases behind the fixes.
    reads: usize,
}

/// Runs each robot's tracks through the filter; a robot with a fix becomes a node.
fn robot_fixes(
    robots: &[Vec<Vec<PoseObs>>],
    z: f64,
    sign: f64,
    facing: Option<[f64; 2]>,
    s: &Settings,
) -> RobotFixes {
    let (mut nodes, mut honest) = (Vec::new(), Vec::new());
    let (mut sq, mut reads) = (0.0, 0usize);
    for tracks in robots {
        let (fixes, wide): (Vec<Fix>, Vec<Fix>) = tracks
            .iter()
            .filter_map(|obs| {
                let fix = mhekf::filtered(obs, z, sign, facing, &s.filter).ok()?;
                sq += fix.rms_rad.powi(2) * obs.len() as f64;
                reads += obs.len();
                Some((fix.clone(), mhekf::honest(fix, obs, sign)))
            })
            .unzip();
        if let Some(node) = Node::from_fixes(&fixes) {
            nodes.push(node);
            honest.push((fixes, wide));
        }
    }
    RobotFixes {
        nodes,
        honest,
        sq,
        reads,
    }
}

/// The outcome of the consensus rounds.
struct Agreed {
    /// The robots still in (indices into the nodes).
    active: Vec<usize>,
    /// Their nodes after consensus.
    nodes: Vec<Node>,
    /// The last graph's edges.
    edges: Vec<(usize, usize)>,
    /// Messages sent.
    messages: u64,
}

/// Consensus rounds, the robot most at odds (beyond the gate) withdrawing while three are in.
fn withdraw_and_agree(own: &[Node], s: &Settings) -> Agreed {
    let mut active: Vec<usize> = (0..own.len()).collect();
    let mut messages = 0u64;
    let (nodes, edges) = loop {
        let mut work: Vec<Node> = active.iter().map(|&i| own[i]).collect();
        let edges = graph(work.len(), s.link_probability, s.seed);
        consensus(&mut work, &edges, s.rounds);
        messages += (s.rounds * edges.len() * 2) as u64;
        if work.len() < 3 {
            break (work, edges);
        }
        // The largest statistic reaches every node by flooding: n − 1 rounds at most.
        messages += ((work.len() - 1) * edges.len() * 2) as u64;
        let worst = work
            .iter()
            .zip(&active)
            .map(|(nd, &i)| disagreement_with_the_rest(&own[i], nd, work.len()))
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(&b.1));
        match worst {
            Some((k, m2)) if m2 > s.gate => {
                active.remove(k);
            }
            _ => break (work, edges),
        }
    };
    Agreed {
        active,
        nodes,
        edges,
        messages,
    }
}

/// What the combination's `weights` give the honest covariances of the `active` robots' fixes.
fn honest_spread(
    active: &[usize],
    honest: &[(Vec<Fix>, Vec<Fix>)],
    weights: &Matrix2<f64>,
) -> Matrix2<f64> {
    let mut spread = Matrix2::zeros();
    for &i in active {
        for (own, wide) in honest[i].0.iter().zip(&honest[i].1) {
            let [a, b, c, d] = own.covariance;
            let [e, f, g, h] = wide.covariance;
            if let Some(inv) = Matrix2::new(a, b, c, d).try_inverse() {
                let k = weights * inv;
                spread += k * Matrix2::new(e, f, g, h) * k.transpose();
            }
        }
    }
    spread
}

/// Distributed WLS as the localizer runs it: each reader a robot, its (reader, antenna)
/// tracks its filters; in 2D at the tag height assumed.
#[derive(Clone, Copy, Debug)]
pub struct Wls;

impl Locate for Wls {
    fn name(&self) -> &'static str {
        "wls"
    }

    fn takes(&self) -> Takes {
        Takes::Tracks
    }

    fn needs(&self) -> &'static [Need] {
        &[Need::CalibratedReader]
    }

    fn locate(&self, tag: &Tag<'_>) -> Result<Fix3, NoFix> {
        let g = tag.geometry;
        let s = Settings {
            filter: mhekf::Settings {
                max_range_m: g.reach_m,
                ..mhekf::Settings::default()
            },
            ..Settings::default()
        };
        let mut robots: BTreeMap<Option<ReaderName>, Vec<Vec<PoseObs>>> = BTreeMap::new();
        for t in pose_observations(tag.ingest, tag.epc, g) {
            robots.entry(t.reader).or_default().push(t.obs);
        }
        // One side for the consensus: the first robot's (a swarm's readers share a layout).
        let facing = robots
            .keys()
            .next()
            .map_or(g.facing, |r| g.facing_of(r.as_deref().unwrap_or_default()));
        let robots: Vec<Vec<Vec<PoseObs>>> = robots.into_values().collect();
        locate(&robots, g.tag_height_m, SIGN, Some(facing), &s).map(|(fix, _)| fix.planar())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mhekf::synth::{error, run};
    use std::f64::consts::TAU;

    /// The default exchange with filters told the odometry is exact.
    fn exact_odometry() -> Settings {
        Settings {
            filter: mhekf::Settings {
                k_r: 0.0,
                k_l: 0.0,
                ..mhekf::Settings::default()
            },
            ..Settings::default()
        }
    }

    /// `n` robots' single tracks round `tag`, each from its own start.
    fn swarm(
        tag: [f64; 3],
        n: usize,
        steps: usize,
        sigma: f64,
        k: f64,
        seed: u64,
    ) -> Vec<Vec<Vec<PoseObs>>> {
        (0..n)
            .map(|i| {
                let a = i as f64 * TAU / n as f64 + seed as f64;
                let start = [tag[0] + 1.5 * a.cos(), tag[1] + 1.5 * a.sin()];
                vec![run(
                    tag,
                    start,
                    a + 2.0,
                    0.5,
                    steps,
                    sigma,
                    k,
                    seed * 100 + i as u64,
                )]
            })
            .collect()
    }

    #[test]
    fn the_nodes_reach_the_centralised_solution_and_messages_are_counted() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut nodes: Vec<Node> = (0..6)
            .map(|_| {
                let (a, b, c) = (
                    rng.gen_range(1.0..5.0),
                    rng.gen_range(-0.5..0.5),
                    rng.gen_range(1.0..5.0),
                );
                let f = Matrix2::new(a, b, b, c);
                Node {
                    information: f,
                    state: f * Vector2::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0)),
                }
            })
            .collect();
        let (f, a) = nodes
            .iter()
            .fold((Matrix2::zeros(), Vector2::zeros()), |(f, a), n| {
                (f + n.information, a + n.state)
            });
        let central = f.try_inverse().expect("invertible") * a;
        let edges = graph(6, 0.3, 11);
        // Connected: every node reached from node 0.
        let mut seen = [false; 6];
        seen[0] = true;
        for _ in 0..6 {
            for &(i, j) in &edges {
                let any = seen[i] || seen[j];
                seen[i] = any;
                seen[j] = any;
            }
        }
        assert!(seen.iter().all(|&x| x), "{edges:?}");
        let before: f64 = nodes
            .iter()
            .map(|n| (n.estimate().unwrap() - central).norm())
            .fold(0.0, f64::max);
        consensus(&mut nodes, &edges, 300);
        for n in &nodes {
            let e = n.estimate().expect("invertible");
            assert!(
                (e - central).norm() < 1e-6,
                "{e} vs {central} (was {before})"
            );
            // The average itself: F_i → F/n.
            assert!((n.information * 6.0 - f).norm() < 1e-6);
        }
        assert!(before > 1e-3, "the nodes must start apart: {before}");
    }

    #[test]
    fn a_noise_free_tag_is_recovered_within_a_millimetre() {
        let tag = [2.0, 1.0, 0.5];
        let s = Settings {
            rounds: 200,
            ..exact_odometry()
        };
        let robots = swarm(tag, 3, 1500, 0.0, 0.0, 1);
        let (fix, report) = locate(&robots, tag[2], -1.0, None, &s).expect("a fix");
        let (err, _) = error(&fix, tag);
        assert!(err < 1e-3, "{err} m: {fix:?}");
        assert_eq!((report.robots, report.withdrawn), (3, 0));
        // The exchange, then the flooding of the one check's largest statistic (n − 1 rounds).
        assert_eq!(report.messages, (200 + 2) * report.edges as u64 * 2);
        assert!(report.disagreement < 1e-6, "{report:?}");
        // One robot: no exchange, its own WLS.
        let (alone, report) = locate(&robots[..1], tag[2], -1.0, None, &s).expect("a fix");
        assert_eq!((report.robots, report.edges, report.messages), (1, 0, 0));
        let own = mhekf::locate(&robots[0][0], tag[2], -1.0, None, &s.filter).expect("a fix");
        assert!((alone.position[0] - own.position[0]).abs() < 1e-12);
        assert!((alone.position[1] - own.position[1]).abs() < 1e-12);
    }

    #[test]
    fn with_phase_noise_the_error_stays_within_the_covariance() {
        // σ_φ = 0.2 rad, exact poses (the filters told so), three robots.
        let tag = [0.0, 0.0, 0.5];
        let s = exact_odometry();
        let mut within = 0;
        for seed in 0..20 {
            let robots = swarm(tag, 3, 1000, 0.2, 0.0, seed);
            let (fix, _) = locate(&robots, tag[2], -1.0, None, &s).expect("a fix");
            let (err, m2) = error(&fix, tag);
            assert!(err < 0.01, "seed {seed}: {err} m");
            within += usize::from(m2 <= 6.0);
        }
        assert!(within >= 16, "{within} of 20 within the 95 % ellipse");
    }

    #[test]
    fn five_robots_do_better_than_one_on_s3() {
        // σ_φ = 0.2 rad, odometry-only poses with K = 1e-5: [M] reports < 3 cm with five.
        let tag = [0.0, 0.0, 0.5];
        let s = Settings::default();
        let (mut one, mut five) = (0.0, 0.0);
        let seeds = 8;
        for seed in 0..seeds {
            let robots = swarm(tag, 5, 1500, 0.2, 1e-5, seed);
            let (fix, report) = locate(&robots, tag[2], -1.0, None, &s).expect("a fix");
            assert_eq!(report.robots + report.withdrawn, 5);
            five += error(&fix, tag).0;
            let (alone, _) = locate(&robots[..1], tag[2], -1.0, None, &s).expect("a fix");
            one += error(&alone, tag).0;
        }
        let (one, five) = (one / seeds as f64, five / seeds as f64);
        assert!(five < one, "five robots {five} m, one {one} m");
        assert!(five <= 0.03, "five robots {five} m");
    }

    #[test]
    fn a_robot_whose_fix_the_others_contradict_withdraws() {
        // Four robots read the tag; a fifth's reads are of a spot 35 cm away (two range
        // cycles at 867 MHz: the wrong hypothesis a filter can settle on), with as tight a fix.
        let tag = [0.0, 0.0, 0.5];
        let s = exact_odometry();
        let mut robots = swarm(tag, 4, 1000, 0.05, 0.0, 3);
        let elsewhere = [0.35, 0.0, 0.5];
        robots.push(swarm(elsewhere, 1, 1000, 0.05, 0.0, 4).remove(0));
        let (fix, report) = locate(&robots, tag[2], -1.0, None, &s).expect("a fix");
        assert_eq!((report.robots, report.withdrawn), (4, 1), "{report:?}");
        let (err, _) = error(&fix, tag);
        assert!(err < 0.005, "{err} m with the fifth withdrawn");
        // Without the check the fifth pulls the combined fix toward its spot.
        let all = Settings {
            gate: f64::INFINITY,
            ..s
        };
        let (fix, report) = locate(&robots, tag[2], -1.0, None, &all).expect("a fix");
        assert_eq!((report.robots, report.withdrawn), (5, 0));
        let (err, _) = error(&fix, tag);
        assert!(err > 0.03, "{err} m with all five combined");
    }

    #[test]
    fn no_robot_with_a_fix_is_insufficient_geometry() {
        let s = Settings::default();
        assert_eq!(
            locate(&[], 0.5, -1.0, None, &s),
            Err(NoFix::InsufficientGeometry)
        );
        // A robot that never had the tag in range, one with two reads.
        let far = run([50.0, 50.0, 0.5], [0.0, 0.0], 0.0, 0.5, 100, 0.0, 0.0, 1);
        let short = run([0.0, 0.0, 0.5], [1.0, 0.0], 0.0, 0.5, 2, 0.0, 0.0, 1);
        assert!(far.is_empty() && short.len() == 2);
        let robots = vec![vec![far], vec![short]];
        assert_eq!(
            locate(&robots, 0.5, -1.0, None, &s),
            Err(NoFix::InsufficientGeometry)
        );
        // A robot without a fix is left out of the exchange.
        let mut robots = robots;
        robots.push(swarm([0.0, 0.0, 0.5], 1, 1000, 0.0, 0.0, 2).remove(0));
        let (_, report) = locate(&robots, 0.5, -1.0, None, &s).expect("a fix");
        assert_eq!((report.robots, report.messages), (1, 0));
    }
}
