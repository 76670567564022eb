//! A pose message: one pose object, a JSON array of them, or JSON Lines, as `POST /api/poses`
//! takes it and a localizer worker takes it from MQTT.

use serde_json::Value;

use super::{validate, PoseSample};

/// The poses of `body` (one JSON object, an array of them, or JSON Lines: objects separated
/// by whitespace), every one checked; else why not, naming the pose's index (0-based), the
/// field and the reason. All or nothing.
pub fn parse_poses(body: &[u8]) -> Result<Vec<PoseSample>, String> {
    let text = body.trim_ascii();
    if text.is_empty() {
        return Err(
            "the body holds no pose: send a pose object, a JSON array of them, or JSON Lines"
                .into(),
        );
    }
    let values: Vec<Value> = if text.first() == Some(&b'[') {
        serde_json::from_slice(text).map_err(|e| format!("not a JSON array of poses: {e}"))?
    } else {
        serde_json::Deserializer::from_slice(text)
            .into_iter::<Value>()
            .enumerate()
            .map(|(i, v)| v.map_err(|e| format!("pose {i}: not JSON: {e}")))
            .collect::<Result<_, _>>()?
    };
    if values.is_empty() {
        return Err("the array holds no pose".into());
    }
    values
        .into_iter()
        .enumerate()
        .map(|(i, v)| pose(v).map_err(|e| format!("pose {i}: {e}")))
        .collect()
}

/// One value as a checked pose sample.
fn pose(v: Value) -> Result<PoseSample, String> {
    let p: PoseSample = serde_path_to_error::deserialize(v).map_err(|e| {
        let path = e.path().to_string();
        if path == "." {
            // A missing or unknown field: serde names it in the message.
            e.inner().to_string()
        } else {
            format!("{path}: {}", e.inner())
        }
    })?;
    validate(&p)?;
    // A name breaking the rule was refused above (`ReaderName`); none at all is refused here.
    if p.reader.is_none() {
        return Err("reader: must be a reader's name, not empty".into());
    }
    Ok(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    const ONE: &str =
        r#"{"t_us": 5, "reader": "r", "antenna": 1, "x": 1, "y": 2, "z": 0.5, "yaw_deg": 90}"#;

    #[test]
    fn takes_an_object_an_array_and_json_lines() {
        let one = parse_poses(ONE.as_bytes()).expect("one object");
        assert_eq!(one.len(), 1);
        assert_eq!(
            one[0].pose,
            super::super::Pose::from_degrees([1.0, 2.0, 0.5], 90.0, 0.0)
        );
        let array = format!("[{ONE}, {ONE}]");
        assert_eq!(parse_poses(array.as_bytes()).expect("array").len(), 2);
        let lines = format!("{ONE}\n{ONE}\n{ONE}\n");
        assert_eq!(parse_poses(lines.as_bytes()).expect("lines").len(), 3);
    }

    #[test]
    fn a_bad_pose_is_named_by_index_field_and_reason() {
        let bad = |body: String| parse_poses(body.as_bytes()).expect_err("bad");
        let e = bad(format!(
            "[{ONE}, {}]",
            ONE.replace("\"x\": 1", "\"x\": \"one\"")
        ));
        assert!(e.starts_with("pose 1: x: invalid type"), "{e}");
        let e = bad(ONE.replace("\"antenna\": 1", "\"antenna\": 0"));
        assert_eq!(e, "pose 0: antenna: must be a port number from 1");
        let e = bad(ONE.replace("\"reader\": \"r\"", "\"reader\": \" \""));
        assert!(e.starts_with("pose 0: reader:"), "{e}");
        let e = bad(ONE.replace("\"reader\": \"r\"", "\"reader\": \"\""));
        assert_eq!(e, "pose 0: reader: must be a reader's name, not empty");
        let e = bad(ONE.replace("\"reader\": \"r\"", "\"reader\": \"r\\t1\""));
        assert!(
            e.starts_with("pose 0: reader: reader name \"r\\t1\" holds a control character"),
            "{e}"
        );
        let e = bad(ONE.replace(", \"z\": 0.5", ""));
        assert!(e.contains("pose 0") && e.contains("`z`"), "{e}");
        let e = bad(ONE.replace("\"z\"", "\"w\""));
        assert!(e.contains("unknown field `w`"), "{e}");
        let e = bad(format!("{ONE}\n{{\"t_us\": -1}}"));
        assert!(e.starts_with("pose 1: t_us:"), "{e}");
        let e = bad(format!("{ONE}\nnot json"));
        assert!(e.starts_with("pose 1: not JSON"), "{e}");
        assert!(bad(String::new()).contains("no pose"));
        assert!(bad("[]".into()).contains("no pose"));
        assert!(bad("[1]".into()).starts_with("pose 0: invalid type"));
    }
}
