//! An antenna's pose at one time, as robots, pose files and simulators give it.

use serde::{Deserialize, Serialize};

/// One pose sample: a line of the pose file, a robot's message, a simulator's truth.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseSample {
    /// Robot (or site) time, µs.
    pub t_us: u64,
    /// Reader name.
    #[serde(default)]
    pub reader: String,
    /// Antenna port, 1-based.
    pub antenna: u16,
    /// Position (m).
    pub x: f64,
    /// Position (m).
    pub y: f64,
    /// Position (m).
    pub z: f64,
    /// Boresight azimuth about +z (degrees, 0 = +x).
    #[serde(default)]
    pub yaw_deg: f64,
    /// Boresight elevation (degrees, positive up).
    #[serde(default)]
    pub pitch_deg: f64,
}
