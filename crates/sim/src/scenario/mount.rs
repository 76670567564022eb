//! Reading an antenna `mount` from JSON: the `type` key picks the variant, the other keys are
//! read strictly with errors that keep their JSON path inside the mount.

use serde::de::{self, Deserializer};
use serde::Deserialize;

use super::format::{Mount, Pose, RobotSpec};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FixedRepr {
    #[serde(with = "mount_pose")]
    pose: Pose,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RobotRepr {
    robot: RobotSpec,
    #[serde(with = "mount_pose")]
    offset: Pose,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RecordedRepr {
    file: String,
}

/// Marks an error message that starts with a path inside the mount (`@robot.speed: ...`);
/// `Scenario::from_json` moves that path onto the error's JSON path.
pub(super) const INNER_PATH_MARK: char = '@';

/// Deserializes `value` as `T`, turning an error into one that names the inner path.
fn inner<T: for<'a> Deserialize<'a>, E: de::Error>(value: serde_json::Value) -> Result<T, E> {
    serde_path_to_error::deserialize(value).map_err(|e| {
        let path = e.path().to_string();
        if path == "." {
            E::custom(e.into_inner())
        } else {
            E::custom(format!("{INNER_PATH_MARK}{path}: {}", e.into_inner()))
        }
    })
}

impl<'de> Deserialize<'de> for Mount {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let value = serde_json::Value::deserialize(deserializer)?;
        let serde_json::Value::Object(mut map) = value else {
            return Err(de::Error::custom(
                "expected an object with \"type\": \"fixed\", \"robot\" or \"recorded\"",
            ));
        };
        let kind = match map.remove("type") {
            Some(serde_json::Value::String(s)) => s,
            Some(_) => {
                return Err(de::Error::custom(format!(
                    "{INNER_PATH_MARK}type: expected a string"
                )))
            }
            None => {
                return Err(de::Error::custom(
                    "missing field `type` (\"fixed\", \"robot\" or \"recorded\")",
                ))
            }
        };
        let rest = serde_json::Value::Object(map);
        match kind.as_str() {
            "fixed" => {
                let r: FixedRepr = inner(rest)?;
                Ok(Mount::Fixed { pose: r.pose })
            }
            "robot" => {
                let r: RobotRepr = inner(rest)?;
                Ok(Mount::Robot {
                    robot: r.robot,
                    offset: r.offset,
                })
            }
            "recorded" => {
                let r: RecordedRepr = inner(rest)?;
                Ok(Mount::Recorded {
                    file: r.file,
                    poses: Vec::new(),
                })
            }
            other => Err(de::Error::custom(format!(
                "{INNER_PATH_MARK}type: unknown mount type \"{other}\", expected \"fixed\", \"robot\" or \"recorded\""
            ))),
        }
    }
}

/// A [`Pose`] as the scenario file has it: `{"position": [x, y, z], "yaw_deg", "pitch_deg"}`
/// (metres, degrees; yaw and pitch 0 when absent; no other key). The degrees stop here.
pub(super) mod mount_pose {
    use llrp_gateway_vocab::pose::Pose;
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    #[derive(Serialize, Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Record {
        position: [f64; 3],
        #[serde(default)]
        yaw_deg: f64,
        #[serde(default)]
        pitch_deg: f64,
    }

    /// Writes `pose` in degrees (rounded as [`Pose::yaw_deg`] rounds them).
    pub fn serialize<S: Serializer>(pose: &Pose, s: S) -> Result<S::Ok, S::Error> {
        Record {
            position: pose.position,
            yaw_deg: pose.yaw_deg(),
            pitch_deg: pose.pitch_deg(),
        }
        .serialize(s)
    }

    /// Reads a pose given in degrees.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Pose, D::Error> {
        let r = Record::deserialize(d)?;
        Ok(Pose::from_degrees(r.position, r.yaw_deg, r.pitch_deg))
    }
}
