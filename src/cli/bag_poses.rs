//! `localize --poses BAG`: a robot's poses out of its own bag, as the localizer's antenna pose
//! samples: the poses of one topic (`geometry_msgs/msg/PoseStamped`,
//! `PoseWithCovarianceStamped` as amcl's `/amcl_pose`, `nav_msgs/msg/Odometry`), or of a chain
//! of frames on `/tf` (with `/tf_static`), each composed with each antenna's offset in the
//! robot frame. A sample's time is its header's stamp, on the robot's clock (the settings'
//! `clock_offsets_us` give reader time − robot time, as for a pose file).

use std::collections::BTreeMap;
use std::path::Path;

use crate::localize::offline::AntennaOffset;
use crate::localize::poses::{Pose, PoseSample};
use crate::reads::ReaderName;
use crate::record::mcap::read::{topics_in_words, Bag, BagError};
use crate::record::mcap::ros_in::{PoseType, RosPose, Stamped};

/// The robot's poses on `topic` in time order (stamp ns, pose). With `frames` (a chain
/// `parent, ..., robot` of at least two), `topic` is a `tf2_msgs/msg/TFMessage` topic, and a
/// pose is the chain's transforms composed, at each stamp of the chain's busiest link.
pub fn robot_track(
    bag: &Bag,
    topic: &str,
    frames: &[String],
) -> Result<Vec<(i64, RosPose)>, BagError> {
    let tf = !frames.is_empty();
    let with_static = |t: &str| t == topic || (tf && t == "/tf_static");
    let (messages, topics) = bag.messages(with_static)?;
    let err = |t: &str, reason: String| BagError::new(&bag.path, Some(t), reason);
    if !topics.iter().any(|(t, _)| t == topic) {
        return Err(err(
            topic,
            format!("no such topic ({})", topics_in_words(&topics)),
        ));
    }
    let mut stamped = Vec::new();
    for m in &messages {
        let ty = PoseType::of_schema(&m.schema).ok_or_else(|| {
            err(
                &m.topic,
                format!(
                    "of type {}, not a geometry_msgs/msg/PoseStamped, \
                     PoseWithCovarianceStamped, nav_msgs/msg/Odometry or tf2_msgs/msg/TFMessage",
                    m.schema
                ),
            )
        })?;
        if (ty == PoseType::TfMessage) != tf {
            let why = if tf {
                "--frames needs a tf2_msgs/msg/TFMessage topic (/tf)"
            } else {
                "a tf2_msgs/msg/TFMessage topic needs the frame chain (--frames PARENT,...,ROBOT)"
            };
            return Err(err(&m.topic, format!("of type {}: {why}", m.schema)));
        }
        let poses = ty
            .decode(&m.data)
            .map_err(|e| err(&m.topic, format!("a message does not decode: {e}")))?;
        stamped.extend(poses);
    }
    let mut track = if tf {
        chain(stamped, frames).map_err(|reason| err(topic, reason))?
    } else {
        stamped.into_iter().map(|s| (s.stamp_ns, s.pose)).collect()
    };
    track.sort_by_key(|(t, _)| *t);
    if track.is_empty() {
        return Err(err(topic, "no poses".into()));
    }
    Ok(track)
}

/// The chain `frames[0] -> ... -> frames[n]` composed from the transforms, at each stamp of
/// its busiest link (a link of one transform, as a static one, holds at every time; another
/// is interpolated between its transforms, and a time outside its span gives no pose).
fn chain(transforms: Vec<Stamped>, frames: &[String]) -> Result<Vec<(i64, RosPose)>, String> {
    let mut links: BTreeMap<(String, String), Vec<(i64, RosPose)>> = BTreeMap::new();
    for t in transforms {
        let key = (
            t.frame_id.trim_start_matches('/').to_owned(),
            t.child.trim_start_matches('/').to_owned(),
        );
        links.entry(key).or_default().push((t.stamp_ns, t.pose));
    }
    let mut chain = Vec::new();
    for pair in frames.windows(2) {
        let key = (pair[0].clone(), pair[1].clone());
        let Some(mut link) = links.remove(&key) else {
            let known: Vec<String> = links.keys().map(|(p, c)| format!("{p} -> {c}")).collect();
            return Err(format!(
                "the frame chain does not connect: no transform from {} to {} (transforms: {})",
                pair[0],
                pair[1],
                if known.is_empty() {
                    "none".into()
                } else {
                    known.join(", ")
                }
            ));
        };
        link.sort_by_key(|(t, _)| *t);
        chain.push(link);
    }
    let busiest = chain
        .iter()
        .max_by_key(|l| l.len())
        .cloned()
        .unwrap_or_default();
    Ok(busiest
        .iter()
        .filter_map(|(t, _)| {
            let mut pose = identity();
            for link in &chain {
                pose = compose(&pose, &at(link, *t)?);
            }
            Some((*t, pose))
        })
        .collect())
}

/// The pose of a link at `t`: its only transform, or interpolated between the two around `t`.
fn at(link: &[(i64, RosPose)], t: i64) -> Option<RosPose> {
    if let [(_, only)] = link {
        return Some(*only);
    }
    let i = link.partition_point(|(s, _)| *s < t);
    let (t1, p1) = link.get(i)?;
    if *t1 == t {
        return Some(*p1);
    }
    let (t0, p0) = link.get(i.checked_sub(1)?)?;
    let f = (t - t0) as f64 / (t1 - t0) as f64;
    let mut q = p1.orientation;
    // The shorter way round.
    if dot(&p0.orientation, &q) < 0.0 {
        q = q.map(|v| -v);
    }
    let lerp = |a: f64, b: f64| a + (b - a) * f;
    let o: [f64; 4] = std::array::from_fn(|k| lerp(p0.orientation[k], q[k]));
    Some(RosPose {
        position: std::array::from_fn(|k| lerp(p0.position[k], p1.position[k])),
        orientation: normalized(o),
    })
}

fn identity() -> RosPose {
    RosPose {
        position: [0.0; 3],
        orientation: [0.0, 0.0, 0.0, 1.0],
    }
}

fn dot(a: &[f64; 4], b: &[f64; 4]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn normalized(q: [f64; 4]) -> [f64; 4] {
    let n = dot(&q, &q).sqrt();
    if n > 0.0 {
        q.map(|v| v / n)
    } else {
        [0.0, 0.0, 0.0, 1.0]
    }
}

/// `v` rotated by the unit quaternion `q` (`[x, y, z, w]`).
fn rotate(q: &[f64; 4], v: [f64; 3]) -> [f64; 3] {
    let [x, y, z, w] = *q;
    // v + 2w (u × v) + 2 u × (u × v), u the vector part.
    let c = [
        y * v[2] - z * v[1],
        z * v[0] - x * v[2],
        x * v[1] - y * v[0],
    ];
    let cc = [
        y * c[2] - z * c[1],
        z * c[0] - x * c[2],
        x * c[1] - y * c[0],
    ];
    std::array::from_fn(|k| v[k] + 2.0 * (w * c[k] + cc[k]))
}

/// `a` then `b` (b given in a's frame).
fn compose(a: &RosPose, b: &RosPose) -> RosPose {
    let r = rotate(&a.orientation, b.position);
    let [x1, y1, z1, w1] = a.orientation;
    let [x2, y2, z2, w2] = b.orientation;
    RosPose {
        position: std::array::from_fn(|k| a.position[k] + r[k]),
        orientation: normalized([
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        ]),
    }
}

/// The offset of `reader`'s `antenna`: its own, else its reader's for every antenna, else one
/// for every reader's `antenna`, else one for every antenna; `None` without any.
fn offset_of<'a>(
    offsets: &'a [AntennaOffset],
    reader: Option<&ReaderName>,
    antenna: u16,
) -> Option<&'a AntennaOffset> {
    let rank = |o: &AntennaOffset| match (o.reader.as_ref(), o.antenna) {
        (Some(r), _) if Some(r) != reader => None,
        (_, Some(a)) if a != antenna => None,
        (r, a) => Some(u8::from(r.is_some()) * 2 + u8::from(a.is_some())),
    };
    offsets
        .iter()
        .filter_map(|o| Some((rank(o)?, o)))
        .max_by_key(|(r, _)| *r)
        .map(|(_, o)| o)
}

/// The pose samples of each antenna `(reader, antenna)` along the robot's `track` (stamps in
/// ns on the robot's clock), each antenna at its offset (none: at the robot's origin,
/// facing ahead). A stamp before the epoch is refused (`path`, `topic` name it).
pub fn antenna_samples(
    track: &[(i64, RosPose)],
    antennas: &[(Option<ReaderName>, u16)],
    offsets: &[AntennaOffset],
    path: &Path,
    topic: &str,
) -> Result<Vec<PoseSample>, BagError> {
    let mut out = Vec::with_capacity(track.len() * antennas.len());
    for (reader, antenna) in antennas {
        let o = offset_of(offsets, reader.as_ref(), *antenna)
            .cloned()
            .unwrap_or_default();
        let (s, c) = (o.yaw_deg.to_radians() / 2.0).sin_cos();
        let mount = RosPose {
            position: [o.x, o.y, o.z],
            orientation: [0.0, 0.0, s, c],
        };
        for (stamp, robot) in track {
            let t_us = u64::try_from(stamp.div_euclid(1000)).map_err(|_| {
                BagError::new(
                    path,
                    Some(topic),
                    format!("a stamp before 1970 ({stamp} ns)"),
                )
            })?;
            let a = compose(robot, &mount);
            let boresight = rotate(&a.orientation, [1.0, 0.0, 0.0]);
            out.push(PoseSample {
                t_us,
                reader: reader.clone(),
                antenna: *antenna,
                pose: Pose {
                    position: a.position,
                    yaw_rad: boresight[1].atan2(boresight[0]),
                    pitch_rad: boresight[2].clamp(-1.0, 1.0).asin(),
                },
            });
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn yawed(x: f64, y: f64, yaw_deg: f64) -> RosPose {
        let h = yaw_deg.to_radians() / 2.0;
        RosPose {
            position: [x, y, 0.0],
            orientation: [0.0, 0.0, h.sin(), h.cos()],
        }
    }

    #[test]
    fn an_antenna_offset_turns_with_the_robot() {
        let offset = AntennaOffset {
            x: 0.5,
            y: 0.25,
            z: 0.75,
            yaw_deg: -90.0,
            ..AntennaOffset::default()
        };
        let track = [(1_000_000_000, yawed(2.0, 3.0, 90.0))];
        let s = antenna_samples(&track, &[(None, 1)], &[offset], Path::new("b"), "/p")
            .expect("samples");
        // Facing +y, the antenna 0.5 ahead is at y + 0.5, 0.25 left at x − 0.25.
        let p = s[0].pose.position;
        assert!(
            (p[0] - 1.75).abs() < 1e-12 && (p[1] - 3.5).abs() < 1e-12,
            "{p:?}"
        );
        assert!((p[2] - 0.75).abs() < 1e-12);
        assert!(s[0].pose.yaw_rad.abs() < 1e-12, "{}", s[0].pose.yaw_rad);
        assert_eq!(s[0].t_us, 1_000_000);
    }

    #[test]
    fn a_chain_composes_its_links_and_interpolates_the_busy_one() {
        let tf = |t: i64, p: &str, c: &str, pose: RosPose| Stamped {
            stamp_ns: t,
            frame_id: p.into(),
            child: c.into(),
            pose,
        };
        let frames = ["map".to_string(), "odom".into(), "base_link".into()];
        let got = chain(
            vec![
                tf(0, "map", "odom", yawed(1.0, 0.0, 90.0)),
                tf(10, "odom", "base_link", yawed(1.0, 0.0, 0.0)),
                tf(20, "odom", "base_link", yawed(3.0, 0.0, 0.0)),
            ],
            &frames,
        )
        .expect("connects");
        assert_eq!(got.len(), 2);
        // odom turned 90°: base_link at odom x = 1 is map (1, 1).
        assert!((got[0].1.position[0] - 1.0).abs() < 1e-12);
        assert!((got[0].1.position[1] - 1.0).abs() < 1e-12);
        let e = chain(vec![], &frames).expect_err("no transforms");
        assert!(e.contains("no transform from map to odom"), "{e}");
    }
}
