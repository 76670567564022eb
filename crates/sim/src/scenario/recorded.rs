//! Recorded antenna pose lists: CSV (`t_s,x,y,z,yaw_deg,pitch_deg`) or JSON Lines with the
//! same keys, one pose per line, times strictly increasing.

use serde::{Deserialize, Serialize};

/// One recorded antenna pose.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseSample {
    /// Time since scenario start, in seconds.
    pub t_s: f64,
    /// Position x (m).
    pub x: f64,
    /// Position y (m).
    pub y: f64,
    /// Position z (m).
    pub z: f64,
    /// Boresight azimuth in degrees.
    pub yaw_deg: f64,
    /// Boresight elevation in degrees.
    pub pitch_deg: f64,
}

const COLUMNS: [&str; 6] = ["t_s", "x", "y", "z", "yaw_deg", "pitch_deg"];

/// Parses a pose list; JSON Lines if the first non-blank line starts with `{`, CSV otherwise.
/// The error names the 1-based line and the reason.
pub fn parse_poses(text: &str) -> Result<Vec<PoseSample>, String> {
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'));
    let Some((first_no, first)) = lines.next() else {
        return Err("no poses".to_string());
    };
    let mut poses = Vec::new();
    if first.starts_with('{') {
        for (no, line) in std::iter::once((first_no, first)).chain(lines) {
            let p: PoseSample =
                serde_json::from_str(line).map_err(|e| format!("line {no}: {e}"))?;
            poses.push(p);
        }
    } else {
        let header: Vec<&str> = first.split(',').map(str::trim).collect();
        if header != COLUMNS {
            return Err(format!(
                "line {first_no}: CSV header must be `{}`, got `{first}`",
                COLUMNS.join(",")
            ));
        }
        for (no, line) in lines {
            let fields: Vec<&str> = line.split(',').map(str::trim).collect();
            if fields.len() != COLUMNS.len() {
                return Err(format!(
                    "line {no}: expected {} values, got {}",
                    COLUMNS.len(),
                    fields.len()
                ));
            }
            let mut v = [0.0; 6];
            for (slot, (field, name)) in v.iter_mut().zip(fields.iter().zip(COLUMNS)) {
                *slot = field
                    .parse::<f64>()
                    .map_err(|_| format!("line {no}: {name} is not a number: `{field}`"))?;
            }
            poses.push(PoseSample {
                t_s: v[0],
                x: v[1],
                y: v[2],
                z: v[3],
                yaw_deg: v[4],
                pitch_deg: v[5],
            });
        }
    }
    check_poses(&poses)?;
    Ok(poses)
}

/// Checks that a pose list is non-empty, finite and strictly increasing in time from t ≥ 0.
pub fn check_poses(poses: &[PoseSample]) -> Result<(), String> {
    if poses.is_empty() {
        return Err("no poses".to_string());
    }
    for (i, p) in poses.iter().enumerate() {
        let values = [p.t_s, p.x, p.y, p.z, p.yaw_deg, p.pitch_deg];
        if values.iter().any(|v| !v.is_finite()) {
            return Err(format!("pose {}: values must be finite", i + 1));
        }
        if p.t_s < 0.0 {
            return Err(format!("pose {}: t_s must be >= 0, got {}", i + 1, p.t_s));
        }
        if i > 0 && p.t_s <= poses[i - 1].t_s {
            return Err(format!(
                "pose {}: t_s must increase strictly, got {} after {}",
                i + 1,
                p.t_s,
                poses[i - 1].t_s
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_and_jsonl_give_the_same_poses() {
        let csv = "t_s,x,y,z,yaw_deg,pitch_deg\n0,1,2,3,90,0\n1.5,2,2,3,180,10\n";
        let jsonl = "{\"t_s\":0,\"x\":1,\"y\":2,\"z\":3,\"yaw_deg\":90,\"pitch_deg\":0}\n\
                     {\"t_s\":1.5,\"x\":2,\"y\":2,\"z\":3,\"yaw_deg\":180,\"pitch_deg\":10}\n";
        let a = parse_poses(csv).expect("valid CSV");
        let b = parse_poses(jsonl).expect("valid JSONL");
        assert_eq!(a, b);
        assert_eq!(a.len(), 2);
        assert_eq!(a[1].yaw_deg, 180.0);
    }

    #[test]
    fn bad_pose_lists_name_the_line() {
        let err = parse_poses("t_s,x,y,z,yaw_deg,pitch_deg\n0,1,2,3,90\n").unwrap_err();
        assert!(err.contains("line 2"), "{err}");
        let err = parse_poses("t,x,y,z,yaw,pitch\n").unwrap_err();
        assert!(err.contains("header"), "{err}");
        let err =
            parse_poses("t_s,x,y,z,yaw_deg,pitch_deg\n1,0,0,0,0,0\n1,0,0,0,0,0\n").unwrap_err();
        assert!(err.contains("increase"), "{err}");
        assert!(parse_poses("").is_err());
    }
}
