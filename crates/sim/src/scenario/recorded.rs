//! Recorded antenna pose lists: CSV (`t_s,x,y,z,yaw_deg,pitch_deg`) or JSON Lines with the
//! same keys, one pose per line, times strictly increasing. The file's seconds and degrees
//! stop here: the list is parsed into [`PoseSample`]s (µs, radians).

use llrp_gateway_vocab::pose::{Pose, PoseSample};
use llrp_gateway_vocab::reader_name::ReaderName;
use llrp_gateway_vocab::table;
use serde::Deserialize;

/// One line of a recorded pose list, as the file has it (seconds, metres, degrees).
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
struct Row {
    t_s: f64,
    x: f64,
    y: f64,
    z: f64,
    yaw_deg: f64,
    pitch_deg: f64,
}

const COLUMNS: [&str; 6] = ["t_s", "x", "y", "z", "yaw_deg", "pitch_deg"];

/// Parses the pose list of antenna `antenna` of reader `reader`; JSON Lines if the first
/// non-blank line starts with `{`, CSV otherwise. The error names the 1-based line and the
/// reason, or the pose (1-based) for times out of order.
pub fn parse_poses(
    text: &str,
    reader: &ReaderName,
    antenna: u16,
) -> Result<Vec<PoseSample>, String> {
    let rows = parse_rows(text)?;
    check_rows(&rows)?;
    let mut poses: Vec<PoseSample> = Vec::with_capacity(rows.len());
    for (i, r) in rows.iter().enumerate() {
        // Finite and at least 0 (checked above); `as` saturates past u64's µs (half a
        // million years).
        let t_us = (r.t_s * 1e6).round() as u64;
        if let Some(before) = poses.last().filter(|p| p.t_us >= t_us) {
            return Err(format!(
                "pose {}: t_s must be at least 1 µs after the one before, got {} after {} s",
                i + 1,
                r.t_s,
                before.t_us as f64 * 1e-6
            ));
        }
        poses.push(PoseSample {
            t_us,
            reader: Some(reader.clone()),
            antenna,
            pose: Pose::from_degrees([r.x, r.y, r.z], r.yaw_deg, r.pitch_deg),
        });
    }
    Ok(poses)
}

/// The rows of a pose list, JSON Lines or CSV (through [`table`]: quoted cells, a
/// byte-order mark and CRLF line ends as a spreadsheet writes them). Blank lines and lines
/// starting with `#` are skipped in both.
fn parse_rows(text: &str) -> Result<Vec<Row>, String> {
    let text = table::strip_bom(text);
    if !table::is_json_lines(text) {
        return parse_csv_rows(text);
    }
    let mut rows = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let r: Row = serde_json::from_str(line).map_err(|e| format!("line {}: {e}", i + 1))?;
        rows.push(r);
    }
    if rows.is_empty() {
        return Err("no poses".to_string());
    }
    Ok(rows)
}

/// The rows of a pose list in CSV, under the header [`COLUMNS`].
fn parse_csv_rows(text: &str) -> Result<Vec<Row>, String> {
    if text
        .lines()
        .all(|l| l.trim().is_empty() || l.trim().starts_with('#'))
    {
        return Err("no poses".to_string());
    }
    let mut csv = table::CsvRows::new(text.as_bytes()).map_err(|e| e.to_string())?;
    if csv.header() != COLUMNS {
        return Err(format!(
            "CSV header must be `{}`, got `{}`",
            COLUMNS.join(","),
            csv.header().join(",")
        ));
    }
    let mut rows = Vec::new();
    for row in csv.by_ref() {
        let row = row.map_err(|e| e.to_string())?;
        let no = row.line;
        if row.cells.len() != COLUMNS.len() {
            return Err(format!(
                "line {no}: expected {} values, got {}",
                COLUMNS.len(),
                row.cells.len()
            ));
        }
        let mut v = [0.0; 6];
        for (slot, (field, name)) in v.iter_mut().zip(row.cells.iter().zip(COLUMNS)) {
            *slot = field
                .parse::<f64>()
                .map_err(|_| format!("line {no}: {name} is not a number: `{field}`"))?;
        }
        rows.push(Row {
            t_s: v[0],
            x: v[1],
            y: v[2],
            z: v[3],
            yaw_deg: v[4],
            pitch_deg: v[5],
        });
    }
    Ok(rows)
}

/// Checks that a pose list is non-empty, finite and strictly increasing in time from t ≥ 0.
fn check_rows(rows: &[Row]) -> Result<(), String> {
    if rows.is_empty() {
        return Err("no poses".to_string());
    }
    for (i, p) in rows.iter().enumerate() {
        let values = [p.t_s, p.x, p.y, p.z, p.yaw_deg, p.pitch_deg];
        if values.iter().any(|v| !v.is_finite()) {
            return Err(format!("pose {}: values must be finite", i + 1));
        }
        if p.t_s < 0.0 {
            return Err(format!("pose {}: t_s must be >= 0, got {}", i + 1, p.t_s));
        }
        if i > 0 && p.t_s <= rows[i - 1].t_s {
            return Err(format!(
                "pose {}: t_s must increase strictly, got {} after {}",
                i + 1,
                p.t_s,
                rows[i - 1].t_s
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
        let r = ReaderName::parse("r").expect("a name");
        let a = parse_poses(csv, &r, 2).expect("valid CSV");
        let b = parse_poses(jsonl, &r, 2).expect("valid JSONL");
        assert_eq!(a, b);
        assert_eq!(a.len(), 2);
        // As a spreadsheet saves it: a byte-order mark, CRLF, a quoted cell.
        let excel =
            "\u{feff}t_s,x,y,z,yaw_deg,pitch_deg\r\n0,1,2,3,\"90\",0\r\n1.5,2,2,3,180,10\r\n";
        assert_eq!(parse_poses(excel, &r, 2).expect("valid CSV"), a);
        assert_eq!(
            (a[1].t_us, a[1].reader.as_ref(), a[1].antenna),
            (1_500_000, Some(&r), 2)
        );
        assert_eq!(a[1].pose, Pose::from_degrees([2.0, 2.0, 3.0], 180.0, 10.0));
    }

    #[test]
    fn bad_pose_lists_name_the_line() {
        let r = ReaderName::parse("r").expect("a name");
        let parse = |text| parse_poses(text, &r, 1);
        let err = parse("t_s,x,y,z,yaw_deg,pitch_deg\n0,1,2,3,90\n").unwrap_err();
        assert!(err.contains("line 2"), "{err}");
        let err = parse("t,x,y,z,yaw,pitch\n").unwrap_err();
        assert!(err.contains("header"), "{err}");
        let err = parse("t_s,x,y,z,yaw_deg,pitch_deg\n1,0,0,0,0,0\n1,0,0,0,0,0\n").unwrap_err();
        assert!(err.contains("increase"), "{err}");
        let err =
            parse("t_s,x,y,z,yaw_deg,pitch_deg\n1,0,0,0,0,0\n1.0000001,0,0,0,0,0\n").unwrap_err();
        assert!(err.contains("pose 2") && err.contains("1 µs"), "{err}");
        assert!(parse("").is_err());
    }
}
