//! The shapes of the API's JSON for its OpenAPI document. They describe what the handlers
//! send (the types in `localize::shared`, `reads` and `localize::poses`); the tests below
//! check that every key the real types write is described here and nothing more.
// The types are never built: they exist for their schemas.
#![allow(dead_code)]

use utoipa::ToSchema;

/// A position (m).
#[derive(ToSchema)]
pub struct Point {
    /// x (m).
    pub x: f64,
    /// y (m).
    pub y: f64,
    /// z (m).
    pub z: f64,
}

/// How far an estimate has come.
#[derive(ToSchema)]
#[schema(rename_all = "snake_case")]
pub enum State {
    /// A position, σ above 1 cm.
    Converging,
    /// A position within 1 cm (one σ along its worse axis).
    Converged,
    /// Too little geometry for a position.
    InsufficientGeometry,
}

/// One tag's latest estimate.
#[derive(ToSchema)]
pub struct Tag {
    /// EPC, upper-case hex.
    pub epc: String,
    /// The estimated position; null with insufficient geometry.
    #[schema(required = true)]
    pub estimate: Option<Point>,
    /// Covariance of the estimate: 9 numbers, 3×3 row-major (m²); null without an estimate.
    #[schema(required = true)]
    pub covariance: Option<Vec<f64>>,
    /// Estimator name.
    pub estimator: String,
    /// How far the estimate has come.
    pub state: State,
    /// Phases the estimate rests on.
    pub samples: u64,
    /// Time of the newest read (µs, the reads' clock: UTC for LLRP readers).
    pub last_seen: u64,
    /// Reads per second over the last rate window (reader time); 0 after 3 s without reads.
    pub reads_per_s: f64,
    /// Why the state is not `converged`, in a sentence; null when converged.
    #[schema(required = true)]
    pub reason: Option<String>,
}

/// `GET /api/tags`.
#[derive(ToSchema)]
pub struct Tags {
    /// Every tag, in EPC order.
    pub tags: Vec<Tag>,
}

/// The antenna's pose at a read, where the source knew it.
#[derive(ToSchema)]
pub struct AntennaPose {
    /// Position (m).
    pub x: f64,
    /// Position (m).
    pub y: f64,
    /// Position (m).
    pub z: f64,
    /// Boresight azimuth about +z (degrees).
    pub yaw_deg: Option<f64>,
    /// Boresight elevation (degrees).
    pub pitch_deg: Option<f64>,
}

/// One tag read.
#[derive(ToSchema)]
pub struct Read {
    /// EPC, upper-case hex.
    pub epc: String,
    /// The name of the reader that reported it (absent when unknown).
    pub reader: Option<String>,
    /// Antenna port (1-based; 0 when the report carried none).
    pub antenna: u16,
    /// First-seen time, UTC µs.
    pub t_us: u64,
    /// RF phase (rad, 0..2π).
    #[schema(required = true)]
    pub phase_rad: Option<f64>,
    /// Peak RSSI (dBm).
    #[schema(required = true)]
    pub rssi_dbm: Option<f64>,
    /// 1-based channel index into the reader's hop table.
    #[schema(required = true)]
    pub channel_index: Option<u16>,
    /// The channel's frequency (Hz).
    #[schema(required = true)]
    pub channel_frequency_hz: Option<u64>,
    /// Doppler frequency (Hz).
    #[schema(required = true)]
    pub doppler_hz: Option<f64>,
    /// The antenna's pose at the read (absent when the source did not know it).
    pub antenna_pose: Option<AntennaPose>,
}

/// `GET /api/tags/{epc}`: a tag and its newest reads.
#[derive(ToSchema)]
pub struct TagDetail {
    /// EPC, upper-case hex.
    pub epc: String,
    /// The estimated position; null with insufficient geometry.
    #[schema(required = true)]
    pub estimate: Option<Point>,
    /// Covariance of the estimate: 9 numbers, 3×3 row-major (m²).
    #[schema(required = true)]
    pub covariance: Option<Vec<f64>>,
    /// Estimator name.
    pub estimator: String,
    /// How far the estimate has come.
    pub state: State,
    /// Phases the estimate rests on.
    pub samples: u64,
    /// Time of the newest read (µs).
    pub last_seen: u64,
    /// Reads per second over the last rate window; 0 after 3 s without reads.
    pub reads_per_s: f64,
    /// Why the state is not `converged`, in a sentence; null when converged.
    #[schema(required = true)]
    pub reason: Option<String>,
    /// The newest reads (at most 32), oldest first.
    pub recent_reads: Vec<Read>,
}

/// One antenna pose sample (a line of the pose file).
#[derive(ToSchema)]
pub struct Pose {
    /// µs. Posted: the robot's clock (the reader's clock offset, if one is set, maps it onto
    /// the reads' clock). Shown by `/api/readers` and `/api/truth`: the reads' clock (UTC µs
    /// for LLRP readers), as every other time of the API.
    pub t_us: u64,
    /// Reader name: not empty, no white space at either end, no control character, at most
    /// 256 bytes (UTF-8); case kept and compared exactly.
    pub reader: String,
    /// Antenna port, from 1.
    pub antenna: u16,
    /// Position (m).
    pub x: f64,
    /// Position (m).
    pub y: f64,
    /// Position (m).
    pub z: f64,
    /// Boresight azimuth about +z (degrees, 0 = +x); 0 when absent.
    pub yaw_deg: Option<f64>,
    /// Boresight elevation (degrees, positive up); 0 when absent.
    pub pitch_deg: Option<f64>,
}

/// One antenna of a reader.
#[derive(ToSchema)]
pub struct Antenna {
    /// Antenna port.
    pub antenna: u16,
    /// The newest pose sample; null before any.
    #[schema(required = true)]
    pub pose: Option<Pose>,
}

/// One reader.
#[derive(ToSchema)]
pub struct Reader {
    /// The reader's name (empty for the reads that name no reader).
    pub name: String,
    /// Whether an LLRP client (or a proxy's upstream) is connected.
    pub connected: bool,
    /// The connected peer.
    #[schema(required = true)]
    pub peer: Option<String>,
    /// Who runs an inventory: `client`, `self` or `idle`.
    pub inventory: String,
    /// Reads taken in from this reader.
    pub reads: u64,
    /// Reads per second over the last rate window (reader time).
    pub reads_per_s: f64,
    /// Antennas, by port.
    pub antennas: Vec<Antenna>,
}

/// `GET /api/readers`.
#[derive(ToSchema)]
pub struct Readers {
    /// Every reader, by name.
    pub readers: Vec<Reader>,
}

/// One tag's true position.
#[derive(ToSchema)]
pub struct TruthTag {
    /// EPC, upper-case hex.
    pub epc: String,
    /// True position (m).
    pub position: Point,
    /// A reference tag (its position is known to the localizer).
    pub reference: bool,
}

/// `GET /api/truth`: the simulation's ground truth.
#[derive(ToSchema)]
pub struct Truth {
    /// Every tag's true position.
    pub tags: Vec<TruthTag>,
    /// Every antenna's true pose now.
    pub antennas: Vec<Pose>,
}

/// `POST /api/poses` taken.
#[derive(ToSchema)]
pub struct Accepted {
    /// Poses handed to the localizer.
    pub accepted: u64,
}

/// Any error.
#[derive(ToSchema)]
pub struct Error {
    /// What went wrong.
    pub error: String,
}

#[cfg(test)]
mod tests {
    use std::collections::{BTreeSet, VecDeque};

    use utoipa::openapi::schema::Schema;
    use utoipa::openapi::RefOr;
    use utoipa::PartialSchema;

    use super::*;
    use crate::localize::estimate::{Estimate, State as EstimateState};
    use crate::localize::poses::PoseSample;
    use crate::localize::shared::{AntennaView, ReaderView, TagJson, TagView};
    use crate::reads::{Pose as ReadPose, Read as RealRead};

    fn properties<T: PartialSchema>() -> BTreeSet<String> {
        match T::schema() {
            RefOr::T(Schema::Object(o)) => o.properties.keys().cloned().collect(),
            _ => panic!("not an object schema"),
        }
    }

    fn required<T: PartialSchema>() -> BTreeSet<String> {
        match T::schema() {
            RefOr::T(Schema::Object(o)) => o.required.into_iter().collect(),
            _ => panic!("not an object schema"),
        }
    }

    fn keys(v: &impl serde::Serialize) -> BTreeSet<String> {
        match serde_json::to_value(v).expect("serialises") {
            serde_json::Value::Object(m) => m.keys().cloned().collect(),
            other => panic!("not an object: {other}"),
        }
    }

    #[test]
    fn the_schemas_name_every_key_the_real_json_has() {
        let pose = PoseSample {
            t_us: 1,
            reader: Some("r".parse().expect("a reader name")),
            antenna: 1,
            pose: ReadPose::from_degrees([0.0, 0.0, 0.0], 0.0, 0.0),
        };
        let read = RealRead {
            epc: crate::reads::Epc::parse("AA").expect("hex"),
            reader: Some("r".parse().expect("a reader name")),
            antenna: 1,
            t_us: 1,
            phase_rad: Some(1.0),
            rssi_dbm: Some(-50.0),
            channel_index: Some(1),
            channel_frequency_hz: Some(865_700_000),
            doppler_hz: Some(0.0),
            antenna_pose: Some(ReadPose::from_degrees([0.0, 0.0, 0.0], 0.0, 0.0)),
            last_seen_us: None,
        };
        let view = TagView {
            estimate: Estimate {
                epc: "AA".into(),
                estimator: "relock",
                estimate: Some([0.0; 3]),
                covariance: Some([0.0; 9]),
                samples: 1,
                state: EstimateState::Converged,
                last_update_us: 1,
                pose_sigma_m: None,
            },
            last_seen_us: 1,
            reads: 1,
            reads_per_s: 1.0,
            recent: VecDeque::new(),
        };
        let reader = ReaderView {
            antennas: vec![AntennaView {
                antenna: 1,
                pose: Some(pose.clone()),
            }],
            ..ReaderView::default()
        };
        assert_eq!(keys(&TagJson::from(&view)), properties::<Tag>());
        let mut detail = properties::<Tag>();
        detail.insert("recent_reads".into());
        assert_eq!(detail, properties::<TagDetail>());
        assert_eq!(keys(&read), properties::<Read>());
        assert_eq!(
            keys(&read.antenna_pose.expect("a pose")),
            properties::<AntennaPose>()
        );
        assert_eq!(keys(&pose), properties::<Pose>());
        assert_eq!(keys(&reader), properties::<Reader>());
        assert_eq!(keys(&reader.antennas[0]), properties::<Antenna>());
        // Required: the keys always written, null or not.
        assert_eq!(keys(&TagJson::from(&view)), required::<Tag>());
        assert_eq!(keys(&reader), required::<Reader>());
        let bare = RealRead {
            reader: None,
            antenna_pose: None,
            ..read
        };
        assert_eq!(keys(&bare), required::<Read>());
    }
}
