//! Foxglove's well-known `SceneUpdate` schema in its ROS 2 form, `foxglove_msgs/msg/SceneUpdate`:
//! its `ros2msg` definitions (the field lists of `ros_foxglove_msgs/ros2/*.msg` of
//! foxglove/schemas, comments left out) and a CDR encoder for the entities llrp-gateway draws
//! (arrows, cubes, spheres, cylinders, lines and texts; no triangles or models).

use super::cdr::Cdr;

pub(super) const SCENE_UPDATE: &str = "\
# foxglove_msgs/msg/SceneUpdate: Foxglove's well-known SceneUpdate schema in its ROS 2 form.
foxglove_msgs/SceneEntityDeletion[] deletions
foxglove_msgs/SceneEntity[] entities
";
pub(super) const SCENE_ENTITY_DELETION: (&str, &str) = (
    "foxglove_msgs/msg/SceneEntityDeletion",
    "builtin_interfaces/Time timestamp\nuint8 MATCHING_ID=0\nuint8 ALL=1\nuint8 type\nstring id\n",
);
pub(super) const SCENE_ENTITY: (&str, &str) = (
    "foxglove_msgs/msg/SceneEntity",
    "builtin_interfaces/Time timestamp
string frame_id
string id
builtin_interfaces/Duration lifetime
bool frame_locked
foxglove_msgs/KeyValuePair[] metadata
foxglove_msgs/ArrowPrimitive[] arrows
foxglove_msgs/CubePrimitive[] cubes
foxglove_msgs/SpherePrimitive[] spheres
foxglove_msgs/CylinderPrimitive[] cylinders
foxglove_msgs/LinePrimitive[] lines
foxglove_msgs/TriangleListPrimitive[] triangles
foxglove_msgs/TextPrimitive[] texts
foxglove_msgs/ModelPrimitive[] models
",
);
pub(super) const DURATION: (&str, &str) = (
    "builtin_interfaces/msg/Duration",
    "int32 sec\nuint32 nanosec\n",
);
pub(super) const KEY_VALUE_PAIR: (&str, &str) = (
    "foxglove_msgs/msg/KeyValuePair",
    "string key\nstring value\n",
);
pub(super) const ARROW: (&str, &str) = (
    "foxglove_msgs/msg/ArrowPrimitive",
    "geometry_msgs/Pose pose\nfloat64 shaft_length\nfloat64 shaft_diameter\n\
     float64 head_length\nfloat64 head_diameter\nfoxglove_msgs/Color color\n",
);
pub(super) const COLOR: (&str, &str) = (
    "foxglove_msgs/msg/Color",
    "float64 r\nfloat64 g\nfloat64 b\nfloat64 a\n",
);
pub(super) const CUBE: (&str, &str) = (
    "foxglove_msgs/msg/CubePrimitive",
    "geometry_msgs/Pose pose\ngeometry_msgs/Vector3 size\nfoxglove_msgs/Color color\n",
);
pub(super) const SPHERE: (&str, &str) = (
    "foxglove_msgs/msg/SpherePrimitive",
    "geometry_msgs/Pose pose\ngeometry_msgs/Vector3 size\nfoxglove_msgs/Color color\n",
);
pub(super) const CYLINDER: (&str, &str) = (
    "foxglove_msgs/msg/CylinderPrimitive",
    "geometry_msgs/Pose pose\ngeometry_msgs/Vector3 size\nfloat64 bottom_scale\n\
     float64 top_scale\nfoxglove_msgs/Color color\n",
);
pub(super) const LINE: (&str, &str) = (
    "foxglove_msgs/msg/LinePrimitive",
    "uint8 LINE_STRIP=0\nuint8 LINE_LOOP=1\nuint8 LINE_LIST=2\nuint8 type\n\
     geometry_msgs/Pose pose\nfloat64 thickness\nbool scale_invariant\n\
     geometry_msgs/Point[] points\nfoxglove_msgs/Color color\nfoxglove_msgs/Color[] colors\n\
     uint32[] indices\n",
);
pub(super) const TRIANGLES: (&str, &str) = (
    "foxglove_msgs/msg/TriangleListPrimitive",
    "geometry_msgs/Pose pose\ngeometry_msgs/Point[] points\nfoxglove_msgs/Color color\n\
     foxglove_msgs/Color[] colors\nuint32[] indices\n",
);
pub(super) const TEXT: (&str, &str) = (
    "foxglove_msgs/msg/TextPrimitive",
    "geometry_msgs/Pose pose\nbool billboard\nfloat64 font_size\nbool scale_invariant\n\
     foxglove_msgs/Color color\nstring text\n",
);
pub(super) const MODEL: (&str, &str) = (
    "foxglove_msgs/msg/ModelPrimitive",
    "geometry_msgs/Pose pose\ngeometry_msgs/Vector3 scale\nfoxglove_msgs/Color color\n\
     bool override_color\nstring url\nstring media_type\nuint8[] data\n",
);

/// The identity orientation `(x, y, z, w)`.
pub const IDENTITY: [f64; 4] = [0.0, 0.0, 0.0, 1.0];

/// A position and an orientation `(x, y, z, w)` in the entity's frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// Position (m).
    pub position: [f64; 3],
    /// Orientation quaternion `(x, y, z, w)`.
    pub orientation: [f64; 4],
}

impl Pose {
    /// At `position`, not rotated.
    pub fn at(position: [f64; 3]) -> Pose {
        Pose {
            position,
            orientation: IDENTITY,
        }
    }
}

/// An RGBA colour, each in 0..1.
pub type Color = [f64; 4];

/// An arrow from its tail along its pose's +x.
#[derive(Clone, Debug, PartialEq)]
pub struct Arrow {
    /// Tail and direction.
    pub pose: Pose,
    /// Shaft length (m).
    pub shaft_length: f64,
    /// Shaft diameter (m).
    pub shaft_diameter: f64,
    /// Head length (m).
    pub head_length: f64,
    /// Head diameter (m).
    pub head_diameter: f64,
    /// Colour.
    pub color: Color,
}

/// A cube or a sphere (ellipsoid): its centre, orientation and size along each axis.
#[derive(Clone, Debug, PartialEq)]
pub struct Solid {
    /// Centre and orientation.
    pub pose: Pose,
    /// Size (a sphere's diameters) along the local x, y, z (m).
    pub size: [f64; 3],
    /// Colour.
    pub color: Color,
}

/// A cylinder or truncated cone along its local z.
#[derive(Clone, Debug, PartialEq)]
pub struct Cylinder {
    /// Centre and orientation (the flat faces perpendicular to the local z).
    pub pose: Pose,
    /// Size of the bounding box (m).
    pub size: [f64; 3],
    /// Diameter of the face at min z, as a share of the box's.
    pub bottom_scale: f64,
    /// Diameter of the face at max z, as a share of the box's.
    pub top_scale: f64,
    /// Colour.
    pub color: Color,
}

/// How a line's points are joined (the `LINE_*` constants).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LineType {
    /// 0-1, 1-2, ...
    Strip = 0,
    /// 0-1, 2-3, ...
    List = 2,
}

/// Points joined by lines, of one colour.
#[derive(Clone, Debug, PartialEq)]
pub struct Line {
    /// How the points are joined.
    pub kind: LineType,
    /// Thickness, in screen pixels.
    pub thickness_px: f64,
    /// The points (m, in the entity's frame).
    pub points: Vec<[f64; 3]>,
    /// Colour.
    pub color: Color,
}

/// A label that faces the camera, of a size in screen pixels.
#[derive(Clone, Debug, PartialEq)]
pub struct Text {
    /// Where its box's centre is.
    pub position: [f64; 3],
    /// Height of a line of text, pixels.
    pub font_px: f64,
    /// Colour.
    pub color: Color,
    /// The text.
    pub text: String,
}

/// One `foxglove_msgs/SceneEntity` (lifetime 0: shown until replaced; not frame-locked).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Entity {
    /// Its id: an entity replaces the one of the same id on the topic.
    pub id: String,
    /// Key-value pairs Foxglove shows when it is selected.
    pub metadata: Vec<(String, String)>,
    /// Arrows.
    pub arrows: Vec<Arrow>,
    /// Cubes.
    pub cubes: Vec<Solid>,
    /// Spheres and ellipsoids.
    pub spheres: Vec<Solid>,
    /// Cylinders and cones.
    pub cylinders: Vec<Cylinder>,
    /// Lines.
    pub lines: Vec<Line>,
    /// Texts.
    pub texts: Vec<Text>,
}

/// A sequence's element count as CDR's uint32.
fn count(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

fn f64s(cdr: &mut Cdr, values: &[f64]) {
    for v in values {
        cdr.f64(*v);
    }
}

fn pose(cdr: &mut Cdr, p: &Pose) {
    f64s(cdr, &p.position);
    f64s(cdr, &p.orientation);
}

fn solid(cdr: &mut Cdr, s: &Solid) {
    pose(cdr, &s.pose);
    f64s(cdr, &s.size);
    f64s(cdr, &s.color);
}

fn entity(cdr: &mut Cdr, stamp_ns: u64, frame_id: &str, e: &Entity) {
    cdr.time(stamp_ns).string(frame_id).string(&e.id);
    cdr.i32(0).u32(0).bool(false);
    cdr.u32(count(e.metadata.len()));
    for (k, v) in &e.metadata {
        cdr.string(k).string(v);
    }
    cdr.u32(count(e.arrows.len()));
    for a in &e.arrows {
        pose(cdr, &a.pose);
        f64s(
            cdr,
            &[
                a.shaft_length,
                a.shaft_diameter,
                a.head_length,
                a.head_diameter,
            ],
        );
        f64s(cdr, &a.color);
    }
    for solids in [&e.cubes, &e.spheres] {
        cdr.u32(count(solids.len()));
        for s in solids {
            solid(cdr, s);
        }
    }
    cdr.u32(count(e.cylinders.len()));
    for c in &e.cylinders {
        pose(cdr, &c.pose);
        f64s(cdr, &c.size);
        f64s(cdr, &[c.bottom_scale, c.top_scale]);
        f64s(cdr, &c.color);
    }
    cdr.u32(count(e.lines.len()));
    for l in &e.lines {
        cdr.u8(l.kind as u8);
        pose(cdr, &Pose::at([0.0; 3]));
        cdr.f64(l.thickness_px).bool(true);
        cdr.u32(count(l.points.len()));
        for p in &l.points {
            f64s(cdr, p);
        }
        f64s(cdr, &l.color);
        // No per-point colours, no indices.
        cdr.u32(0).u32(0);
    }
    // No triangles.
    cdr.u32(0);
    cdr.u32(count(e.texts.len()));
    for t in &e.texts {
        pose(cdr, &Pose::at(t.position));
        cdr.bool(true).f64(t.font_px).bool(true);
        f64s(cdr, &t.color);
        cdr.string(&t.text);
    }
    // No models.
    cdr.u32(0);
}

/// `foxglove_msgs/msg/SceneUpdate` at `stamp_ns` (UTC ns): the entities of ids `deleted`
/// removed, then `entities` (all in frame `frame_id`) added or replaced.
pub fn scene_update(
    cdr: &mut Cdr,
    stamp_ns: u64,
    frame_id: &str,
    deleted: &[String],
    entities: &[Entity],
) -> Vec<u8> {
    const MATCHING_ID: u8 = 0;
    cdr.u32(count(deleted.len()));
    for id in deleted {
        cdr.time(stamp_ns).u8(MATCHING_ID).string(id);
    }
    cdr.u32(count(entities.len()));
    for e in entities {
        entity(cdr, stamp_ns, frame_id, e);
    }
    cdr.finish()
}
