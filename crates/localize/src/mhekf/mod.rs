//! The multi-hypothesis extended Kalman filter of Bontempelli and Rizzardi (\[M\] §III-A, after
//! DiGiampaolo and Martinelli): per (robot, tag), the state ξ = (ρ, β, x, y, θ) is the tag's
//! range and bearing from the robot and the robot's pose, predicted from odometry increments
//! (u, ω) and corrected by the wrapped phase φ = mod(s·4πρ/λ + φ0, 2π). The range is known
//! only modulo λ/2, so one filter runs per whole number of half wavelengths up to the reach,
//! weighted by how well it explains the phases; the heaviest gives the tag,
//! x_T = x + ρ cos(θ − β), y_T = y + ρ sin(θ − β), with covariance J P Jᵀ.
//!
//! Ours, beyond \[M\]: a filter whose predicted phase has spread over more than one cycle
//! (the robot back in range after driving out of it on odometry alone) does not take the
//! nearest cycle for the right one: it splits into one filter per cycle within 3σ of its
//! prediction, each weighted by its innovation, and the phases that follow decide.

use nalgebra::{SMatrix, SVector};
use std::f64::consts::{PI, TAU};

use crate::estimator::{Locate, Need, Tag, Takes, SIGN};
use crate::fix::{Fix, Fix3, NoFix};
use crate::observe::pose_observations;

mod smooth;

type V5 = SVector<f64, 5>;
type M5 = SMatrix<f64, 5, 5>;

/// One phase as reported, with where the antenna was and when, for the filters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseObs {
    /// Read time (µs).
    pub t_us: u64,
    /// Phase as reported (rad), wrapped, not unwrapped.
    pub phase_rad: f64,
    /// Antenna position (m).
    pub antenna: [f64; 3],
    /// Antenna yaw (rad, about +z, 0 = +x); carried, not needed by the filter.
    pub yaw_rad: f64,
    /// Channel wavelength (m).
    pub wavelength_m: f64,
    /// Period the phase is known modulo (rad): 2π, or π with Impinj's π ambiguity.
    pub period_rad: f64,
    /// A read (`false`: a pose sample the antenna passed, for the odometry only; its phase is
    /// not looked at).
    pub read: bool,
}

/// The filter's settings; the defaults are \[M\]'s S3 scenario.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    /// Phase noise σ_φ (rad); default 0.2, \[M\]'s.
    pub sigma_phi_rad: f64,
    /// Right wheel's odometry constant K_R (m), variance K_R·|u_R| (\[M\] eq. 5); default 1e-5.
    pub k_r: f64,
    /// Left wheel's odometry constant K_L (m), variance K_L·|u_L|; default 1e-5.
    pub k_l: f64,
    /// Distance between the wheels d (m), for ω = (u_R − u_L)/d; default 0.5, \[M\]'s.
    pub wheelbase_m: f64,
    /// Farthest range a tag is read at, ρ_max (m); default 2, \[M\]'s.
    pub max_range_m: f64,
    /// Starting bearings per range hypothesis, evenly round the circle from β0 = 0; default 4.
    pub bearings: usize,
    /// σ of each starting bearing (rad); default π/3, \[M\]'s.
    pub sigma_bearing_rad: f64,
    /// Phase offset φ0 (rad), assumed calibrated; default 0 (S3 has none).
    pub phase_offset_rad: f64,
    /// Fewest reads for a fix; default 10.
    pub min_reads: usize,
    /// A hypothesis this far (natural log of weight) under the heaviest is dropped; default 1000.
    pub prune_log_weight: f64,
    /// Most hypotheses kept (the heaviest) when filters split; default 256.
    pub max_hypotheses: usize,
}

impl Default for Settings {
    fn default() -> Settings {
        Settings {
            sigma_phi_rad: 0.2,
            k_r: 1e-5,
            k_l: 1e-5,
            wheelbase_m: 0.5,
            max_range_m: 2.0,
            bearings: 4,
            sigma_bearing_rad: PI / 3.0,
            phase_offset_rad: 0.0,
            min_reads: 10,
            prune_log_weight: 1000.0,
            max_hypotheses: 256,
        }
    }
}

/// Angle `a` wrapped onto [−p/2, p/2).
fn wrap(a: f64, p: f64) -> f64 {
    (a + p / 2.0).rem_euclid(p) - p / 2.0
}

/// The innovations a read's wrapped innovation `nu` may stand for, given its predicted
/// variance `sv` and the phase's period: `nu` itself, and `nu + k·period` for every other
/// cycle within 3σ of the prediction, where one read can tell cycles apart at all (the
/// phase noise's own 3σ, `sigma_phi_rad`, within half a period); otherwise `nu` alone.
pub(crate) fn cycles(nu: f64, sv: f64, period: f64, sigma_phi_rad: f64) -> Vec<f64> {
    let mut out = vec![nu];
    let reach = 3.0 * sv.sqrt();
    if !(3.0 * sigma_phi_rad < period / 2.0 && reach.is_finite()) {
        return out;
    }
    let most = (reach / period).ceil() as i32;
    for k in (-most..=most).filter(|&k| k != 0) {
        let other = nu + f64::from(k) * period;
        if other.abs() <= reach {
            out.push(other);
        }
    }
    out
}

/// Range hypotheses n_max = ⌈ρ_max / (λP/4π)⌉: ⌈2ρ_max/λ⌉ without the π ambiguity (\[M\]).
pub fn hypotheses(max_range_m: f64, wavelength_m: f64, period_rad: f64) -> usize {
    let spacing = wavelength_m * period_rad / (4.0 * PI);
    (max_range_m / spacing).ceil().max(1.0) as usize
}

/// The exact motion of one step: the robot moves `u` along θ then turns by `omega`, the tag
/// fixed. Returns the new state, ∂f/∂ξ and ∂f/∂(u, ω).
pub(crate) fn predict(xi: &V5, u: f64, omega: f64) -> (V5, M5, SMatrix<f64, 5, 2>) {
    let (rho, beta, th) = (xi[0], xi[1], xi[4]);
    let a = th - beta;
    let (e, ep) = ([a.cos(), a.sin()], [-a.sin(), a.cos()]);
    let (et, etp) = ([th.cos(), th.sin()], [-th.sin(), th.cos()]);
    // d: from the moved robot to the tag.
    let d = [rho * e[0] - u * et[0], rho * e[1] - u * et[1]];
    let r = d[0].hypot(d[1]).max(1e-12);
    let gamma = d[1].atan2(d[0]);
    let dd_rho = e;
    let dd_beta = [-rho * ep[0], -rho * ep[1]];
    let dd_th = [rho * ep[0] - u * etp[0], rho * ep[1] - u * etp[1]];
    let dd_u = [-et[0], -et[1]];
    let dr = |v: [f64; 2]| (d[0] * v[0] + d[1] * v[1]) / r;
    let dg = |v: [f64; 2]| (d[0] * v[1] - d[1] * v[0]) / (r * r);
    let next = V5::new(
        r,
        wrap(th + omega - gamma, TAU),
        xi[2] + u * th.cos(),
        xi[3] + u * th.sin(),
        wrap(th + omega, TAU),
    );
    let mut f = M5::identity();
    f.set_row(
        0,
        &SMatrix::<f64, 1, 5>::new(dr(dd_rho), dr(dd_beta), 0.0, 0.0, dr(dd_th)),
    );
    f.set_row(
        1,
        &SMatrix::<f64, 1, 5>::new(-dg(dd_rho), -dg(dd_beta), 0.0, 0.0, 1.0 - dg(dd_th)),
    );
    f[(2, 4)] = -u * th.sin();
    f[(3, 4)] = u * th.cos();
    let g = SMatrix::<f64, 5, 2>::new(
        dr(dd_u),
        0.0,
        -dg(dd_u),
        1.0,
        th.cos(),
        0.0,
        th.sin(),
        0.0,
        0.0,
        1.0,
    );
    (next, f, g)
}

/// One filter: its state, covariance and log weight.
#[derive(Clone, Debug)]
struct Hypothesis {
    xi: V5,
    p: M5,
    log_w: f64,
}

impl Hypothesis {
    /// The tag position and its 2×2 covariance J P Jᵀ (\[M\] eqs. 37–38).
    fn tag(&self) -> ([f64; 2], SMatrix<f64, 2, 2>) {
        let (rho, beta, x, y, th) = (self.xi[0], self.xi[1], self.xi[2], self.xi[3], self.xi[4]);
        let (c, s) = ((th - beta).cos(), (th - beta).sin());
        let j = SMatrix::<f64, 2, 5>::new(
            c,
            rho * s,
            1.0,
            0.0,
            -rho * s,
            s,
            -rho * c,
            0.0,
            1.0,
            rho * c,
        );
        ([x + rho * c, y + rho * s], j * self.p * j.transpose())
    }
}

/// The fix of a tag at height `z` from one robot's reads `obs` (in time order; one antenna),
/// phase sign `sign` (+1, or −1 for \[M\]'s φ = mod(−4πρ/λ, 2π)). When the mirror images weigh
/// within a factor 100, the one on the side `facing` points to (from the last position) wins.
/// Its covariance is the filter's made [`honest`].
pub fn locate(
    obs: &[PoseObs],
    z: f64,
    sign: f64,
    facing: Option<[f64; 2]>,
    s: &Settings,
) -> Result<Fix, NoFix> {
    filtered(obs, z, sign, facing, s).map(|fix| honest(fix, obs, sign))
}

/// The multi-hypothesis EKF as the localizer runs it: one filter bank per (reader, antenna)
/// track, the fix with the least covariance trace; in 2D at the tag height assumed.
#[derive(Clone, Copy, Debug)]
pub struct Mhekf;

impl Locate for Mhekf {
    fn name(&self) -> &'static str {
        "mhekf"
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
            max_range_m: g.reach_m,
            ..Settings::default()
        };
        pose_observations(tag.ingest, tag.epc, g)
            .iter()
            .filter_map(|t| {
                let facing = g.facing_of(t.reader.as_deref().unwrap_or_default());
                locate(&t.obs, g.tag_height_m, SIGN, Some(facing), &s).ok()
            })
            .min_by(|a, b| {
                let tr = |f: &Fix| f.covariance[0] + f.covariance[3];
                tr(a).total_cmp(&tr(b))
            })
            .ok_or(NoFix::InsufficientGeometry)
            .map(Fix::planar)
    }
}

/// `fix` (of a tag from `obs`, phase sign `sign`) with its covariance made at least that of a
/// phase error smooth in the direction the tag is read from, which the filter, taking its
/// phases as independent, leaves out (docs/localize.md).
pub fn honest(fix: Fix, obs: &[PoseObs], sign: f64) -> Fix {
    let reads: Vec<&PoseObs> = obs.iter().filter(|o| o.read).collect();
    Fix {
        covariance: smooth::at_least(fix.covariance, fix.position, &reads, sign),
        ..fix
    }
}

/// [`locate`]'s fix with the filter's own covariance J P Jᵀ (\[M\] eqs. 37–38).
pub fn filtered(
    obs: &[PoseObs],
    z: f64,
    sign: f64,
    facing: Option<[f64; 2]>,
    s: &Settings,
) -> Result<Fix, NoFix> {
    // The reads; the pose samples before the first read give its pose covariance (\[M\]
    // eq. 26), those between reads the path the odometry noise is charged on.
    let reads: Vec<&PoseObs> = obs.iter().filter(|o| o.read).collect();
    let (start, last) = check(obs, &reads, s)?;
    let track = Track {
        obs,
        heading: headings(obs),
        to_wheels: SMatrix::<f64, 2, 2>::new(0.5, 0.5, 1.0 / s.wheelbase_m, -1.0 / s.wheelbase_m),
        z,
        sign,
        s,
    };
    let pose = track.pose_before(start);
    let mut hyps = track.initial(start, &pose);
    let r2 = s.sigma_phi_rad.powi(2).max(1e-12);
    for (k, o) in obs.iter().enumerate().skip(start + 1) {
        track.advance(&mut hyps, k, o, r2);
        if !o.read {
            continue;
        }
        prune(&mut hyps, s)?;
    }
    let chosen = choose(&hyps, facing, last)?;
    let (t, cov) = chosen.tag();
    let rms = (reads
        .iter()
        .map(|o| {
            let rho = (t[0] - o.antenna[0]).hypot(t[1] - o.antenna[1]);
            wrap(o.phase_rad - track.model(o, rho).0, o.period_rad).powi(2)
        })
        .sum::<f64>()
        / reads.len() as f64)
        .sqrt();
    let covariance = [cov[(0, 0)], cov[(0, 1)], cov[(1, 0)], cov[(1, 1)]];
    if !(t.iter().chain(&covariance).all(|v| v.is_finite())) {
        return Err(NoFix::InsufficientGeometry);
    }
    Ok(Fix {
        position: [t[0], t[1], z],
        covariance,
        rms_rad: rms,
    })
}

/// The first read's index and the last read, if the track allows a fix.
fn check<'a>(
    obs: &[PoseObs],
    reads: &[&'a PoseObs],
    s: &Settings,
) -> Result<(usize, &'a PoseObs), NoFix> {
    let ok = obs.iter().all(|o| o.antenna.iter().all(|v| v.is_finite()))
        && reads
            .iter()
            .all(|o| o.phase_rad.is_finite() && o.wavelength_m > 0.0 && o.period_rad > 0.0);
    let (min, max) = reads
        .iter()
        .fold(([f64::MAX; 2], [f64::MIN; 2]), |(lo, hi), o| {
            (
                [lo[0].min(o.antenna[0]), lo[1].min(o.antenna[1])],
                [hi[0].max(o.antenna[0]), hi[1].max(o.antenna[1])],
            )
        });
    let start = obs
        .iter()
        .position(|o| o.read)
        .ok_or(NoFix::InsufficientGeometry)?;
    let first = &obs[start];
    let last = *reads.last().ok_or(NoFix::InsufficientGeometry)?;
    let aperture = (max[0] - min[0]).hypot(max[1] - min[1]);
    if !ok || reads.len() < s.min_reads.max(2) || aperture < first.wavelength_m / 2.0 {
        return Err(NoFix::InsufficientGeometry);
    }
    Ok((start, last))
}

/// Heading at each vertex: the direction of travel to the next vertex, the last one's held.
fn headings(obs: &[PoseObs]) -> Vec<f64> {
    let mut chord: Vec<Option<f64>> = obs
        .windows(2)
        .map(|w| {
            let (dx, dy) = (
                w[1].antenna[0] - w[0].antenna[0],
                w[1].antenna[1] - w[0].antenna[1],
            );
            (dx.hypot(dy) > 1e-9).then(|| dy.atan2(dx))
        })
        .collect();
    chord.push(None);
    let mut heading = vec![0.0; obs.len()];
    let mut held = chord.iter().flatten().next().copied().unwrap_or(0.0);
    for (h, c) in heading.iter_mut().zip(&chord) {
        held = c.unwrap_or(held);
        *h = held;
    }
    heading
}

/// One track as the filter runs it: its vertices with their headings, and the settings.
struct Track<'a> {
    /// The pose samples and reads, in time order.
    obs: &'a [PoseObs],
    /// Each vertex's heading ([`headings`]).
    heading: Vec<f64>,
    /// W: the wheels' displacements to (u, ω).
    to_wheels: SMatrix<f64, 2, 2>,
    /// The tag height assumed (m).
    z: f64,
    /// The phase sign.
    sign: f64,
    /// The filter's settings.
    s: &'a Settings,
}

impl Track<'_> {
    /// The step from vertex k − 1 to k: its (u, ω) and the wheels' noise mapped through W.
    fn step(&self, k: usize) -> (f64, f64, SMatrix<f64, 2, 2>) {
        let (obs, heading, s) = (self.obs, &self.heading, self.s);
        let (prev, o) = (&obs[k - 1], &obs[k]);
        let u = (o.antenna[0] - prev.antenna[0]).hypot(o.antenna[1] - prev.antenna[1]);
        let omega = wrap(heading[k] - heading[k - 1], TAU);
        // Odometry noise (\[M\] eq. 5): the wheels' displacements u ± ωd/2.
        let (u_r, u_l) = (
            u + omega * s.wheelbase_m / 2.0,
            u - omega * s.wheelbase_m / 2.0,
        );
        let q = SMatrix::<f64, 2, 2>::new(s.k_r * u_r.abs(), 0.0, 0.0, s.k_l * u_l.abs());
        (u, omega, q)
    }

    /// The phase `o` would have at horizontal range `rho`, and its derivative in `rho`.
    fn model(&self, o: &PoseObs, rho: f64) -> (f64, f64) {
        let dz = self.z - o.antenna[2];
        let d = rho.hypot(dz);
        let k = self.sign * 4.0 * PI / o.wavelength_m;
        (k * d + self.s.phase_offset_rad, k * rho / d.max(1e-12))
    }

    /// The pose covariance at vertex `start`: the odometry's over the path driven to it.
    fn pose_before(&self, start: usize) -> M5 {
        let (obs, heading, to_wheels) = (self.obs, &self.heading, self.to_wheels);
        let mut pose = M5::zeros();
        for k in 1..=start {
            let (u, omega, q) = self.step(k);
            let dummy = V5::new(
                1.0,
                0.0,
                obs[k - 1].antenna[0],
                obs[k - 1].antenna[1],
                heading[k - 1],
            );
            let (_, f, g) = predict(&dummy, u, omega);
            let w = g * to_wheels;
            pose = f * pose * f.transpose() + w * q * w.transpose();
        }
        pose
    }

    /// The hypotheses at the first read, vertex `start` (\[M\] eqs. 21–26): per range and bearing.
    fn initial(&self, start: usize, pose: &M5) -> Vec<Hypothesis> {
        let (s, z, sign) = (self.s, self.z, self.sign);
        let first = &self.obs[start];
        let spacing = first.wavelength_m * first.period_rad / (4.0 * PI);
        let dz = z - first.antenna[2];
        let base = (sign * first.wavelength_m * (first.phase_rad - s.phase_offset_rad)
            / (4.0 * PI))
            .rem_euclid(spacing);
        let n_max = hypotheses(
            s.max_range_m.hypot(dz),
            first.wavelength_m,
            first.period_rad,
        );
        let sigma_d = s.sigma_phi_rad * first.wavelength_m / (4.0 * PI);
        let mut hyps: Vec<Hypothesis> = Vec::new();
        for n in 0..n_max {
            let d = base + n as f64 * spacing;
            if d <= dz.abs() + 1e-3 {
                continue;
            }
            let rho = (d * d - dz * dz).sqrt();
            for b in 0..s.bearings.max(1) {
                let beta = wrap(b as f64 * TAU / s.bearings.max(1) as f64, TAU);
                // The pose block only: the dummy's range and bearing rows are not the tag's.
                let mut p = M5::zeros();
                p.fixed_view_mut::<3, 3>(2, 2)
                    .copy_from(&pose.fixed_view::<3, 3>(2, 2));
                p[(0, 0)] = (sigma_d * d / rho).powi(2);
                p[(1, 1)] = s.sigma_bearing_rad.powi(2);
                hyps.push(Hypothesis {
                    xi: V5::new(
                        rho,
                        beta,
                        first.antenna[0],
                        first.antenna[1],
                        self.heading[start],
                    ),
                    p,
                    log_w: 0.0,
                });
            }
        }
        hyps
    }

    /// Moves every hypothesis to vertex `k` (`o`), at a read updating and splitting it by cycle.
    fn advance(&self, hyps: &mut Vec<Hypothesis>, k: usize, o: &PoseObs, r2: f64) {
        let (u, omega, q) = self.step(k);
        let mut split: Vec<Hypothesis> = Vec::new();
        for h in hyps.iter_mut() {
            let (xi, f, g) = predict(&h.xi, u, omega);
            let w = g * self.to_wheels;
            let p = f * h.p * f.transpose() + w * q * w.transpose();
            if !o.read {
                h.xi = xi;
                h.p = p;
                continue;
            }
            self.update(h, xi, p, o, r2, &mut split);
        }
        hyps.append(&mut split);
    }

    /// Updates hypothesis `h` (predicted: `xi`, `p`) with read `o`; other cycles go to `split`.
    fn update(
        &self,
        h: &mut Hypothesis,
        xi: V5,
        p: M5,
        o: &PoseObs,
        r2: f64,
        split: &mut Vec<Hypothesis>,
    ) {
        let (phi_hat, dh) = self.model(o, xi[0]);
        let hrow = SMatrix::<f64, 1, 5>::new(dh, 0.0, 0.0, 0.0, 0.0);
        let nu = wrap(o.phase_rad - phi_hat, o.period_rad);
        let sv = (hrow * p * hrow.transpose())[(0, 0)] + r2;
        let gain = p * hrow.transpose() / sv;
        let ikh = M5::identity() - gain * hrow;
        let p = ikh * p * ikh.transpose() + gain * gain.transpose() * r2;
        let p = (p + p.transpose()) / 2.0;
        let updated = |nu: f64| {
            let mut xi = xi + gain * nu;
            xi[1] = wrap(xi[1], TAU);
            xi[4] = wrap(xi[4], TAU);
            let log_w = h.log_w - 0.5 * nu * nu / sv;
            let ok = xi[0] > 1e-3 && log_w.is_finite() && p.iter().all(|v| v.is_finite());
            Hypothesis {
                xi,
                p,
                log_w: if ok { log_w } else { f64::NEG_INFINITY },
            }
        };
        let mut innovations = cycles(nu, sv, o.period_rad, self.s.sigma_phi_rad).into_iter();
        let own = innovations.next().unwrap_or(nu);
        split.extend(innovations.map(updated).filter(|b| b.log_w.is_finite()));
        *h = updated(own);
    }
}

/// Drops the light hypotheses and keeps the heaviest few; an error when none is left.
fn prune(hyps: &mut Vec<Hypothesis>, s: &Settings) -> Result<(), NoFix> {
    let best = hyps
        .iter()
        .map(|h| h.log_w)
        .fold(f64::NEG_INFINITY, f64::max);
    hyps.retain(|h| h.log_w >= best - s.prune_log_weight);
    if hyps.len() > s.max_hypotheses.max(1) {
        hyps.sort_by(|a, b| b.log_w.total_cmp(&a.log_w));
        hyps.truncate(s.max_hypotheses.max(1));
    }
    if hyps.is_empty() {
        return Err(NoFix::InsufficientGeometry);
    }
    Ok(())
}

/// The heaviest hypothesis, or the heaviest facing one within a factor 100 of it.
fn choose<'h>(
    hyps: &'h [Hypothesis],
    facing: Option<[f64; 2]>,
    last: &PoseObs,
) -> Result<&'h Hypothesis, NoFix> {
    let best = hyps
        .iter()
        .map(|h| h.log_w)
        .fold(f64::NEG_INFINITY, f64::max);
    let faces = |h: &&Hypothesis| {
        facing.is_none_or(|f| {
            let (t, _) = h.tag();
            (t[0] - last.antenna[0]) * f[0] + (t[1] - last.antenna[1]) * f[1] >= 0.0
        })
    };
    let heaviest = |a: &&Hypothesis, b: &&Hypothesis| a.log_w.total_cmp(&b.log_w);
    hyps.iter()
        .filter(|h| h.log_w >= best - 100f64.ln())
        .filter(faces)
        .max_by(heaviest)
        .or_else(|| hyps.iter().max_by(heaviest))
        .ok_or(NoFix::InsufficientGeometry)
}

/// Synthetic robot runs after \[M\]'s S3, for the tests here and in `wls`.
#[cfg(test)]
pub(crate) mod synth;

#[cfg(test)]
mod tests;
