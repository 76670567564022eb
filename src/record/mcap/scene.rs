//! The 3D scene of a simulation as Foxglove's `SceneUpdate` on `/scene`: the world's bounds
//! and reflectors, each tag's true position, each antenna (an arrow along its boresight and
//! the cone of its −3 dB beamwidth) and the path it drove, each robot (a box of its
//! footprint) and the path it drove, and the live localizer's
//! estimates with their 95 % ellipsoids, coloured by state. Written every
//! [`SCENE_INTERVAL_US`] of the simulation's clock (at its truth instants), every entity in
//! each update under an id that stays the same, so Foxglove replaces it.

use std::collections::{BTreeMap, BTreeSet};
use std::io::Write;

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

use super::estimates::{EstimateItem, EstimateState};
use super::geo::{orientation, Truth, WORLD};
use super::msgs::MsgType;
use super::scene_msgs::{
    scene_update, Arrow, Color, Cylinder, Entity, Line, LineType, Pose, Solid, Text,
};
use super::{McapError, McapOut};
use llrp_gateway_vocab::pose::Pose as AntennaPose;

/// The topic of the scene.
pub const TOPIC: &str = "/scene";

/// Simulated time between two scene updates (µs): 2 Hz.
pub const SCENE_INTERVAL_US: u64 = 500_000;

/// The 95 % quantile of the chi-square distribution of 3 degrees of freedom: a position of
/// covariance Σ lies with 95 % probability within `d² = χ²` of Σ's Mahalanobis distance.
pub const CHI2_95_3DOF: f64 = 7.814_727_903_251_178;

/// Most points of an antenna's path; beyond it the path keeps every other point.
const MAX_PATH: usize = 1000;

/// Length of an antenna's drawn lobe (m).
const LOBE_M: f64 = 1.0;

/// Smallest diameter an ellipsoid is drawn with (m), so that a flat one (a 2D estimator's)
/// shows.
const MIN_DIAMETER_M: f64 = 0.01;

const TAG: Color = [0.92, 0.92, 0.92, 1.0];
const CONVERGED: Color = [0.1, 0.8, 0.25, 1.0];
const CONVERGING: Color = [1.0, 0.55, 0.0, 1.0];
const ANTENNA: Color = [0.9, 0.15, 0.15, 1.0];
const PATH: Color = [0.2, 0.5, 1.0, 1.0];
const ROBOT: Color = [0.95, 0.8, 0.1, 0.6];
const ROBOT_PATH: Color = [0.95, 0.8, 0.1, 1.0];
const BOUNDS: Color = [0.6, 0.6, 0.6, 1.0];
const REFLECTOR: Color = [0.4, 0.6, 0.9, 0.15];

/// What the scene knows of the world that does not move: the scenario's.
#[derive(Clone, Debug, Default)]
pub struct SceneWorld {
    /// The world's box, lowest and highest corner (m).
    pub bounds: Option<([f64; 3], [f64; 3])>,
    /// Reflecting planes: name, a point and the normal.
    pub reflectors: Vec<(String, [f64; 3], [f64; 3])>,
    /// Each antenna's full −3 dB beamwidth (degrees), by reader name and port.
    pub beamwidths: Vec<(String, u16, f64)>,
    /// Each robot's frame name (`robot_N`) and its box: length, width, height (m).
    pub robots: Vec<(String, [f64; 3])>,
}

/// A covariance's 95 % ellipsoid: its semi-axes and the orientation that takes the local
/// x, y, z onto them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ellipsoid {
    /// Semi-axis lengths (m): `sqrt(χ²₃(0.95) · λᵢ)` of the eigenvalues λ.
    pub semi_axes: [f64; 3],
    /// Orientation `(x, y, z, w)`: its rotation matrix's columns are the eigenvectors.
    pub orientation: [f64; 4],
}

/// The 95 % ellipsoid of a 3×3 row-major covariance (m²); none unless every entry is
/// finite. The matrix is symmetrised; a negative eigenvalue (rounding) counts as 0.
pub fn ellipsoid(covariance: &[f64; 9]) -> Option<Ellipsoid> {
    if !covariance.iter().all(|v| v.is_finite()) {
        return None;
    }
    let m = Matrix3::from_row_slice(covariance);
    let eigen = ((m + m.transpose()) * 0.5).symmetric_eigen();
    let mut axes = eigen.eigenvectors;
    if axes.determinant() < 0.0 {
        let flipped = -axes.column(2);
        axes.set_column(2, &flipped);
    }
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(axes));
    let k = CHI2_95_3DOF.sqrt();
    let semi = |i: usize| k * eigen.eigenvalues[i].max(0.0).sqrt();
    Some(Ellipsoid {
        semi_axes: [semi(0), semi(1), semi(2)],
        orientation: [q.i, q.j, q.k, q.w],
    })
}

/// An antenna's newest true pose and the positions it has been at.
type Tracked = (AntennaPose, Vec<[f64; 3]>);

/// What the scene shows, as the file's items come.
#[derive(Debug, Default)]
pub(super) struct Scene {
    world: SceneWorld,
    /// When the next update is due (UTC µs); none before the first instant.
    next_us: Option<u64>,
    /// Each antenna's true pose and path, by reader token and port.
    antennas: BTreeMap<(String, u16), Tracked>,
    /// Each robot's true pose `[x, y, heading]` and the path it drove, by frame name.
    robots: BTreeMap<String, ([f64; 3], Vec<[f64; 3]>)>,
    /// Each tag's true position, by EPC (upper-case).
    tags: BTreeMap<String, [f64; 3]>,
    /// Each tag's newest estimate, by EPC.
    estimates: BTreeMap<String, EstimateItem>,
    /// The estimates drawn in the last update (to be deleted once they have no position).
    drawn: BTreeSet<String>,
}

impl Scene {
    /// Takes a tag's new estimate.
    pub(super) fn estimate(&mut self, e: &EstimateItem) {
        self.estimates.insert(e.epc.to_uppercase(), e.clone());
    }
}

/// The orientation of `q` (x, y, z, w) followed by a quarter turn about its own +y, which
/// takes +z onto `q`'s +x.
fn z_onto_x(q: [f64; 4]) -> [f64; 4] {
    let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[3], q[0], q[1], q[2]));
    let r = q * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), std::f64::consts::FRAC_PI_2);
    [r.i, r.j, r.k, r.w]
}

/// The orientation that takes +z onto `normal`.
fn z_onto(normal: [f64; 3]) -> [f64; 4] {
    let n = Vector3::from(normal);
    let q = UnitQuaternion::rotation_between(&Vector3::z(), &n).unwrap_or_else(|| {
        // Opposite to +z (or zero, which a scenario refuses): half a turn about +x.
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
    });
    [q.i, q.j, q.k, q.w]
}

/// `c` projected onto the plane through `point` of normal `normal` (`point` for a zero
/// normal, which a scenario refuses).
fn on_plane(c: [f64; 3], point: [f64; 3], normal: [f64; 3]) -> [f64; 3] {
    let n = Vector3::from(normal);
    let Some(n) = n.try_normalize(0.0) else {
        return point;
    };
    let c = Vector3::from(c);
    (c - n * (c - Vector3::from(point)).dot(&n)).into()
}

/// The 12 edges of the box `lo`..`hi` as a line list.
fn box_edges(lo: [f64; 3], hi: [f64; 3]) -> Vec<[f64; 3]> {
    let corner = |i: usize| {
        [
            if i & 1 == 0 { lo[0] } else { hi[0] },
            if i & 2 == 0 { lo[1] } else { hi[1] },
            if i & 4 == 0 { lo[2] } else { hi[2] },
        ]
    };
    let mut points = Vec::with_capacity(24);
    for i in 0..8 {
        for bit in [1, 2, 4] {
            if i & bit == 0 {
                points.push(corner(i));
                points.push(corner(i | bit));
            }
        }
    }
    points
}

/// Adds `p` to `path` when it is more than 1 cm from the last point; beyond [`MAX_PATH`]
/// points the path keeps every other one (and its newest).
fn extend_path(path: &mut Vec<[f64; 3]>, p: [f64; 3]) {
    let moved = path
        .last()
        .is_none_or(|last| (0..3).map(|i| (last[i] - p[i]).powi(2)).sum::<f64>() > 1e-4);
    if moved {
        path.push(p);
    }
    if path.len() > MAX_PATH {
        let last = path.last().copied();
        let mut k = 0;
        path.retain(|_| {
            k += 1;
            k % 2 == 1
        });
        path.extend(last.filter(|l| path.last() != Some(l)));
    }
}

fn label(position: [f64; 3], text: &str, color: Color) -> Text {
    Text {
        position: [position[0], position[1], position[2] + 0.1],
        font_px: 14.0,
        color,
        text: text.to_string(),
    }
}

impl Scene {
    /// The world's bounds and reflectors.
    fn world_entities(&self, out: &mut Vec<Entity>) {
        if let Some((lo, hi)) = self.world.bounds {
            out.push(Entity {
                id: "world/bounds".into(),
                lines: vec![Line {
                    kind: LineType::List,
                    thickness_px: 1.5,
                    points: box_edges(lo, hi),
                    color: BOUNDS,
                }],
                ..Entity::default()
            });
        }
        let side = self.world.bounds.map_or(10.0, |(lo, hi)| {
            (0..3).map(|i| hi[i] - lo[i]).fold(1.0, f64::max)
        });
        for (i, (name, point, normal)) in self.world.reflectors.iter().enumerate() {
            let centre = match self.world.bounds {
                Some((lo, hi)) => on_plane(
                    std::array::from_fn(|k| (lo[k] + hi[k]) / 2.0),
                    *point,
                    *normal,
                ),
                None => *point,
            };
            out.push(Entity {
                id: format!("world/reflector/{i}"),
                metadata: vec![("name".into(), name.clone())],
                cubes: vec![Solid {
                    pose: Pose {
                        position: centre,
                        orientation: z_onto(*normal),
                    },
                    size: [side, side, 0.005],
                    color: REFLECTOR,
                }],
                texts: vec![label(centre, name, REFLECTOR)],
                ..Entity::default()
            });
        }
    }

    /// Each antenna: its arrow, its lobe, its label and its path.
    fn antenna_entities(&self, out: &mut Vec<Entity>) {
        for ((token, port), (pose, path)) in &self.antennas {
            let q = orientation(pose);
            let frame = format!("{token}/antenna_{port}");
            let mut e = Entity {
                id: format!("antenna/{frame}"),
                metadata: vec![("frame".into(), frame.clone())],
                arrows: vec![Arrow {
                    pose: Pose {
                        position: pose.position,
                        orientation: q,
                    },
                    shaft_length: 0.25,
                    shaft_diameter: 0.03,
                    head_length: 0.1,
                    head_diameter: 0.08,
                    color: ANTENNA,
                }],
                texts: vec![label(pose.position, &frame, ANTENNA)],
                ..Entity::default()
            };
            let beamwidth = (self.world.beamwidths.iter())
                .find(|(t, p, _)| t == token && p == port)
                .map(|(_, _, bw)| *bw);
            if let Some(bw) = beamwidth.filter(|bw| *bw < 180.0) {
                let bore = super::geo::boresight(pose);
                let diameter = 2.0 * LOBE_M * (bw.to_radians() / 2.0).tan();
                e.cylinders.push(Cylinder {
                    pose: Pose {
                        position: std::array::from_fn(|i| {
                            pose.position[i] + bore[i] * LOBE_M / 2.0
                        }),
                        orientation: z_onto_x(q),
                    },
                    size: [diameter, diameter, LOBE_M],
                    bottom_scale: 0.0,
                    top_scale: 1.0,
                    color: [ANTENNA[0], ANTENNA[1], ANTENNA[2], 0.12],
                });
            }
            out.push(e);
            if path.len() >= 2 {
                out.push(Entity {
                    id: format!("path/{frame}"),
                    lines: vec![Line {
                        kind: LineType::Strip,
                        thickness_px: 2.0,
                        points: path.clone(),
                        color: PATH,
                    }],
                    ..Entity::default()
                });
            }
        }
    }

    /// Each robot: a box of its footprint on the floor, its label and the path it drove.
    fn robot_entities(&self, out: &mut Vec<Entity>) {
        for (name, (pose, path)) in &self.robots {
            let size = (self.world.robots.iter())
                .find(|(n, _)| n == name)
                .map_or([0.5, 0.5, 0.3], |(_, s)| *s);
            let floor = AntennaPose {
                position: [pose[0], pose[1], size[2] / 2.0],
                yaw_rad: pose[2],
                pitch_rad: 0.0,
            };
            out.push(Entity {
                id: format!("robot/{name}"),
                metadata: vec![("frame".into(), name.clone())],
                cubes: vec![Solid {
                    pose: Pose {
                        position: floor.position,
                        orientation: orientation(&floor),
                    },
                    size,
                    color: ROBOT,
                }],
                texts: vec![label(floor.position, name, ROBOT_PATH)],
                ..Entity::default()
            });
            if path.len() >= 2 {
                out.push(Entity {
                    id: format!("path/{name}"),
                    lines: vec![Line {
                        kind: LineType::Strip,
                        thickness_px: 2.0,
                        points: path.clone(),
                        color: ROBOT_PATH,
                    }],
                    ..Entity::default()
                });
            }
        }
    }

    /// Each tag's true position, a small cube with its EPC.
    fn tag_entities(&self, out: &mut Vec<Entity>) {
        for (epc, p) in &self.tags {
            out.push(Entity {
                id: format!("truth/tag/{epc}"),
                metadata: vec![("epc".into(), epc.clone())],
                cubes: vec![Solid {
                    pose: Pose::at(*p),
                    size: [0.04; 3],
                    color: TAG,
                }],
                texts: vec![label(*p, epc, TAG)],
                ..Entity::default()
            });
        }
    }

    /// Each estimate with a position: a small sphere and its 95 % ellipsoid, green when
    /// converged, orange while converging; the ids of those drawn before that now have none.
    fn estimate_entities(&mut self, out: &mut Vec<Entity>) -> Vec<String> {
        let mut drawn = BTreeSet::new();
        for (epc, e) in &self.estimates {
            let Some(p) = e.position else {
                continue;
            };
            let color = match e.state {
                EstimateState::Converged => CONVERGED,
                _ => CONVERGING,
            };
            let id = format!("estimate/{epc}");
            let mut spheres = vec![Solid {
                pose: Pose::at(p),
                size: [0.03; 3],
                color,
            }];
            if let Some(el) = e.covariance.as_ref().and_then(ellipsoid) {
                spheres.push(Solid {
                    pose: Pose {
                        position: p,
                        orientation: el.orientation,
                    },
                    size: el.semi_axes.map(|a| (2.0 * a).max(MIN_DIAMETER_M)),
                    color: [color[0], color[1], color[2], 0.25],
                });
            }
            out.push(Entity {
                id: id.clone(),
                metadata: vec![
                    ("epc".into(), epc.clone()),
                    ("estimator".into(), e.estimator.clone()),
                    ("state".into(), e.state.name().into()),
                    ("samples".into(), e.samples.to_string()),
                ],
                spheres,
                ..Entity::default()
            });
            drawn.insert(id);
        }
        let gone = self.drawn.difference(&drawn).cloned().collect();
        self.drawn = drawn;
        gone
    }
}

impl<W: Write> McapOut<W> {
    /// Sets what the scene shows of the world that does not move (a simulation's scenario).
    pub fn scene_world(&mut self, world: &SceneWorld) {
        let mut w = world.clone();
        for (reader, _, _) in &mut w.beamwidths {
            *reader = self.token(reader);
        }
        self.scene.world = w;
    }

    /// Antenna `port` of reader `token` at `pose`: its arrow and its path in the scene.
    pub(super) fn scene_antenna(&mut self, token: &str, port: u16, pose: &AntennaPose) {
        let (p, path) = (self.scene.antennas)
            .entry((token.to_string(), port))
            .or_insert_with(|| (*pose, Vec::new()));
        *p = *pose;
        extend_path(path, p.position);
    }

    /// Takes instant `t` of reader `token` into the scene and writes the scene when an
    /// update is due.
    pub(super) fn scene_truth(&mut self, token: &str, t: &Truth) -> Result<(), McapError> {
        for (port, true_pose, _) in &t.antennas {
            self.scene_antenna(token, *port, true_pose);
        }
        for r in &t.robots {
            let (pose, path) = (self.scene.robots)
                .entry(r.name.clone())
                .or_insert_with(|| (r.true_pose, Vec::new()));
            *pose = r.true_pose;
            extend_path(path, [pose[0], pose[1], 0.0]);
        }
        for (epc, p) in &t.tags {
            self.scene.tags.insert(epc.to_uppercase(), *p);
        }
        if self.scene.next_us.is_some_and(|next| t.utc_us < next) {
            return Ok(());
        }
        self.scene.next_us = Some(t.utc_us.saturating_add(SCENE_INTERVAL_US));
        self.scene_at(t.utc_us)
    }

    /// Writes the scene as it stands, stamped `utc_us` (UTC µs).
    pub fn scene_at(&mut self, utc_us: u64) -> Result<(), McapError> {
        let mut entities = Vec::new();
        self.scene.world_entities(&mut entities);
        self.scene.antenna_entities(&mut entities);
        self.scene.robot_entities(&mut entities);
        self.scene.tag_entities(&mut entities);
        let gone = self.scene.estimate_entities(&mut entities);
        let ns = utc_us.saturating_mul(1000);
        let bytes = scene_update(&mut self.cdr, ns, WORLD, &gone, &entities);
        self.write(TOPIC, MsgType::SceneUpdate, ns, ns, &bytes)
    }
}

#[cfg(test)]
#[path = "scene_tests.rs"]
mod tests;
