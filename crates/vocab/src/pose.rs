//! An antenna's pose in SI units ([`Pose`]: metres and radians) and a timed sample of it
//! ([`PoseSample`]), as robots, pose files and simulators give it.
//!
//! Files and messages carry degrees (`{"x", "y", "z", "yaw_deg", "pitch_deg"}`): the
//! conversion is here, in serde, and nowhere past it. Degrees written out are rounded to
//! 1e-9° ([`Pose::yaw_deg`]), so that a yaw that came in as a decimal goes out as it came
//! (30 → rad → 30, not 29.999999999999996).

use serde::{Deserialize, Serialize, Serializer};

use crate::reader_name::{empty_is_none, ReaderName};

/// Position and boresight of an antenna at one instant (metres, radians).
///
/// In files and messages it is the pose record `{"x", "y", "z"[, "yaw_deg", "pitch_deg"]}`
/// (metres, degrees; yaw and pitch 0 when absent; no other key).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(from = "PoseRecord", into = "PoseRecord")]
pub struct Pose {
    /// Position `[x, y, z]` (m).
    pub position: [f64; 3],
    /// Boresight azimuth about +z (rad, 0 = +x, π/2 = +y).
    pub yaw_rad: f64,
    /// Boresight elevation (rad, positive up).
    pub pitch_rad: f64,
}

/// Degrees above which [`rounded_degrees`] leaves a value as it is (1e-9° steps would no
/// longer be exact in an `f64`).
const ROUNDED_UP_TO_DEG: f64 = 1e6;

/// `rad` in degrees, rounded to 1e-9°: the degrees a decimal given in degrees (up to nine
/// places) was, without the noise of the way through radians.
pub fn rounded_degrees(rad: f64) -> f64 {
    let deg = rad.to_degrees();
    if deg.abs() < ROUNDED_UP_TO_DEG {
        (deg * 1e9).round() / 1e9
    } else {
        deg
    }
}

impl Pose {
    /// The pose at `position` (m) with yaw and pitch given in degrees.
    pub fn from_degrees(position: [f64; 3], yaw_deg: f64, pitch_deg: f64) -> Pose {
        Pose {
            position,
            yaw_rad: yaw_deg.to_radians(),
            pitch_rad: pitch_deg.to_radians(),
        }
    }

    /// The yaw in degrees, as files show it (rounded to 1e-9°, [`rounded_degrees`]).
    pub fn yaw_deg(&self) -> f64 {
        rounded_degrees(self.yaw_rad)
    }

    /// The pitch in degrees, as files show it (rounded to 1e-9°, [`rounded_degrees`]).
    pub fn pitch_deg(&self) -> f64 {
        rounded_degrees(self.pitch_rad)
    }

    /// Why the pose is no pose, naming the record's field, if one of its numbers is not
    /// finite.
    pub fn check_finite(&self) -> Result<(), String> {
        for (key, v, deg) in [
            ("x", self.position[0], false),
            ("y", self.position[1], false),
            ("z", self.position[2], false),
            ("yaw_deg", self.yaw_rad, true),
            ("pitch_deg", self.pitch_rad, true),
        ] {
            if !v.is_finite() {
                let shown = if deg { v.to_degrees() } else { v };
                return Err(format!("{key}: must be finite, got {shown}"));
            }
        }
        Ok(())
    }
}

/// A [`Pose`] as files and messages carry it: metres and degrees.
#[derive(Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct PoseRecord {
    x: f64,
    y: f64,
    z: f64,
    #[serde(default)]
    yaw_deg: f64,
    #[serde(default)]
    pitch_deg: f64,
}

impl From<PoseRecord> for Pose {
    fn from(r: PoseRecord) -> Pose {
        Pose::from_degrees([r.x, r.y, r.z], r.yaw_deg, r.pitch_deg)
    }
}

impl From<Pose> for PoseRecord {
    fn from(p: Pose) -> PoseRecord {
        let [x, y, z] = p.position;
        PoseRecord {
            x,
            y,
            z,
            yaw_deg: p.yaw_deg(),
            pitch_deg: p.pitch_deg(),
        }
    }
}

/// One pose sample: a line of the pose file, a robot's message, a simulator's truth, a
/// recorded pose of a scenario.
///
/// In files and messages it is the flat record `{"t_us", "reader", "antenna", "x", "y", "z",
/// "yaw_deg", "pitch_deg"}` (reader, yaw and pitch may be left out; no other key); an
/// unnamed reader's `reader` is `""`.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(from = "SampleRecord")]
pub struct PoseSample {
    /// Robot (or site) time, µs.
    pub t_us: u64,
    /// Reader name; `None` for the unnamed reader (whose reads name none either).
    pub reader: Option<ReaderName>,
    /// Antenna port, 1-based.
    pub antenna: u16,
    /// The antenna's pose.
    pub pose: Pose,
}

/// A [`PoseSample`] as files and messages carry it.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SampleRecord {
    t_us: u64,
    #[serde(default, deserialize_with = "empty_is_none")]
    reader: Option<ReaderName>,
    antenna: u16,
    x: f64,
    y: f64,
    z: f64,
    #[serde(default)]
    yaw_deg: f64,
    #[serde(default)]
    pitch_deg: f64,
}

impl From<SampleRecord> for PoseSample {
    fn from(r: SampleRecord) -> PoseSample {
        PoseSample {
            t_us: r.t_us,
            reader: r.reader,
            antenna: r.antenna,
            pose: Pose::from_degrees([r.x, r.y, r.z], r.yaw_deg, r.pitch_deg),
        }
    }
}

/// [`SampleRecord`] borrowing the sample, to write it without copying the reader's name.
#[derive(Serialize)]
struct SampleOut<'a> {
    t_us: u64,
    reader: &'a str,
    antenna: u16,
    x: f64,
    y: f64,
    z: f64,
    yaw_deg: f64,
    pitch_deg: f64,
}

impl Serialize for PoseSample {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let [x, y, z] = self.pose.position;
        SampleOut {
            t_us: self.t_us,
            reader: self.reader.as_deref().unwrap_or(""),
            antenna: self.antenna,
            x,
            y,
            z,
            yaw_deg: self.pose.yaw_deg(),
            pitch_deg: self.pose.pitch_deg(),
        }
        .serialize(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn degrees_given_as_decimals_come_back_as_given_through_json() {
        for deg in [
            30.0f64,
            45.5,
            -90.0,
            0.1,
            0.0,
            180.0,
            -179.9999,
            359.123456789,
        ] {
            let json =
                format!(r#"{{"x":1.5,"y":-2.0,"z":0.25,"yaw_deg":{deg},"pitch_deg":{deg}}}"#);
            let pose: Pose = serde_json::from_str(&json).expect("a pose");
            assert_eq!(pose.yaw_rad, deg.to_radians());
            assert_eq!((pose.yaw_deg(), pose.pitch_deg()), (deg, deg));
            let back: serde_json::Value =
                serde_json::from_str(&serde_json::to_string(&pose).expect("text")).expect("JSON");
            assert_eq!(back["yaw_deg"].as_f64(), Some(deg), "{json}");
            assert_eq!(back["pitch_deg"].as_f64(), Some(deg), "{json}");
            assert_eq!(back["x"].as_f64(), Some(1.5));
            let sample: PoseSample = serde_json::from_str(&format!(
                r#"{{"t_us":7,"reader":"r","antenna":2,"x":1.5,"y":-2.0,"z":0.25,"yaw_deg":{deg}}}"#
            ))
            .expect("a sample");
            let text = serde_json::to_string(&sample).expect("text");
            assert_eq!(
                text,
                format!(
                    r#"{{"t_us":7,"reader":"r","antenna":2,"x":1.5,"y":-2.0,"z":0.25,"yaw_deg":{},"pitch_deg":0.0}}"#,
                    serde_json::to_string(&deg).expect("a number")
                )
            );
            assert_eq!(serde_json::from_str::<PoseSample>(&text).ok(), Some(sample));
        }
        // Outside the rounding's range, the value is left as it is.
        assert_eq!(
            rounded_degrees(1e300f64.to_radians()),
            1e300f64.to_radians().to_degrees()
        );
        assert!(rounded_degrees(f64::NAN).is_nan());
    }

    #[test]
    fn the_records_keep_their_defaults_and_refuse_unknown_keys() {
        let p: Pose = serde_json::from_str(r#"{"x":1,"y":2,"z":3}"#).expect("a pose");
        assert_eq!(p, Pose::from_degrees([1.0, 2.0, 3.0], 0.0, 0.0));
        let e = serde_json::from_str::<Pose>(r#"{"x":1,"y":2,"z":3,"yaw":4}"#).expect_err("yaw");
        assert!(e.to_string().contains("unknown field `yaw`"), "{e}");
        let s: PoseSample =
            serde_json::from_str(r#"{"t_us":1,"antenna":1,"x":1,"y":2,"z":3}"#).expect("a sample");
        assert_eq!((&s.reader, s.pose.yaw_rad), (&None, 0.0));
        assert!(serde_json::to_string(&s)
            .expect("text")
            .contains(r#""reader":"""#));
        let e = serde_json::from_str::<PoseSample>(
            r#"{"t_us":1,"reader":"r\n","antenna":1,"x":1,"y":2,"z":3}"#,
        )
        .expect_err("a line end");
        assert!(e.to_string().contains("control character"), "{e}");
        let e = serde_json::from_str::<PoseSample>(r#"{"t_us":1,"antenna":1,"x":1,"y":2}"#)
            .expect_err("no z");
        assert!(e.to_string().contains("`z`"), "{e}");
        let e =
            serde_json::from_str::<PoseSample>(r#"{"t_us":1,"antenna":1,"x":1,"y":2,"z":3,"w":0}"#)
                .expect_err("w");
        assert!(e.to_string().contains("unknown field `w`"), "{e}");
    }
}
