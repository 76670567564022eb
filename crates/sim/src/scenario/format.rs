//! The scenario file's data types: what a JSON scenario may contain, with its defaults.
//!
//! Every struct refuses unknown fields, so a misspelt key is an error naming its JSON path.

use serde::{Deserialize, Serialize};

use super::defaults::*;

use llrp_gateway_vocab::pose::PoseSample;
use llrp_gateway_vocab::reader_name::ReaderName;

/// Axis-aligned box that contains every tag, antenna and waypoint of the scenario (metres).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorldBounds {
    /// Lowest corner `[x, y, z]`.
    pub min: [f64; 3],
    /// Highest corner `[x, y, z]`.
    pub max: [f64; 3],
}

/// An infinite reflecting plane (wall, floor, rack face) used by the image method.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Reflector {
    /// Free-text label, e.g. `"floor"`.
    #[serde(default)]
    pub name: String,
    /// Any point on the plane.
    pub point: [f64; 3],
    /// Plane normal (need not be unit length, must not be zero).
    pub normal: [f64; 3],
    /// Magnitude of the reflection coefficient in `[0, 1]`; the reflection also flips phase by π.
    pub coefficient: f64,
}

/// Straight-line motion of a tag through waypoints at constant speed, starting at its position.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Path {
    /// Points visited after the tag's `position`, in order.
    pub waypoints: Vec<[f64; 3]>,
    /// Speed along the path in m/s.
    pub speed: f64,
    /// Simulated time (s) at which the tag starts moving.
    #[serde(default)]
    pub start_s: f64,
    /// Return to `position` after the last waypoint and repeat forever.
    #[serde(default)]
    pub loop_path: bool,
}

/// One tag.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TagSpec {
    /// EPC as hex: 1 to 31 whole 16-bit words (24 digits for the common EPC-96).
    pub epc: String,
    /// Position at time 0 (metres).
    pub position: [f64; 3],
    /// Optional motion.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub path: Option<Path>,
    /// A reference tag: its position is known to the localizer (fingerprinting, calibration).
    #[serde(default)]
    pub reference: bool,
    /// TID memory as hex (whole 16-bit words); default `E2801160` followed by 16 hex digits
    /// derived from the EPC.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tid: Option<String>,
    /// User memory as hex (whole 16-bit words; `""` for none); default 512 bits of zeros,
    /// Impinj Monza 4QT's user memory.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub user: Option<String>,
    /// Kill password as 8 hex digits (32 bits); default `00000000` (the tag cannot be killed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kill_password: Option<String>,
    /// Access password as 8 hex digits (32 bits); default `00000000` (every access is secured).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub access_password: Option<String>,
    /// Axis of the tag's dipole (any length but zero); none: the tag is aligned with every
    /// antenna (peak dipole gain, no polarisation loss).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub orientation: Option<[f64; 3]>,
    /// This tag's chip sensitivity against the antenna's `tag_sensitivity_dbm` (dB, positive:
    /// less sensitive); none: drawn from the scenario's `tag_variation`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensitivity_offset_db: Option<f64>,
    /// This tag's backscatter strength against the nominal (dB); none: drawn from the
    /// scenario's `tag_variation`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub backscatter_offset_db: Option<f64>,
}

/// Spread of tag-to-tag (chip and inlay) variation, drawn per tag from the seed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TagVariation {
    /// Standard deviation of the chip sensitivity across tags (dB).
    #[serde(default = "default_tag_spread")]
    pub sensitivity_sigma_db: f64,
    /// Standard deviation of the backscatter strength across tags (dB).
    #[serde(default = "default_tag_spread")]
    pub backscatter_sigma_db: f64,
    /// RMS (rad) of each tag's smooth phase error against the direction it is read from
    /// (inlay, orientation, mounting), the same on every channel; 0: none.
    #[serde(default)]
    pub phase_pattern_rad: f64,
    /// Angle (degrees) over which that phase error decorrelates.
    #[serde(default = "default_pattern_deg")]
    pub phase_pattern_deg: f64,
    /// Standard deviation across tags of the tag's phase curvature a (rad per rad²): each tag
    /// adds a·θ² to its phase, θ the angle off the reading antenna's boresight (held at
    /// 60°), so a localizer sees it nearer or farther by about a·λ/2π; 0: none.
    #[serde(default)]
    pub phase_curvature_sigma_rad: f64,
    /// Standard deviation across tags of the tag's own group delay (ns): a phase linear in
    /// frequency that differs from tag to tag.
    #[serde(default)]
    pub delay_sigma_ns: f64,
    /// Standard deviation of a fixed phase per (tag, antenna, channel) (rad).
    #[serde(default)]
    pub channel_phase_sigma_rad: f64,
    /// Standard deviation of a fixed RSSI offset per (tag, antenna, channel) (dB).
    #[serde(default)]
    pub channel_rssi_sigma_db: f64,
}

impl Default for TagVariation {
    fn default() -> TagVariation {
        TagVariation {
            sensitivity_sigma_db: default_tag_spread(),
            backscatter_sigma_db: default_tag_spread(),
            phase_pattern_rad: 0.0,
            phase_pattern_deg: default_pattern_deg(),
            phase_curvature_sigma_rad: 0.0,
            delay_sigma_ns: 0.0,
            channel_phase_sigma_rad: 0.0,
            channel_rssi_sigma_db: 0.0,
        }
    }
}

/// How an antenna's reported RSSI is made from the channel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RssiModel {
    /// The noise-free channel plus Gaussian measurement noise in dB (`rssi_sigma_db`),
    /// quantised to `rssi_resolution_db`, as a reader reports it.
    #[default]
    Reader,
    /// \[G\] eq. 5: an absolute noise `rssi_noise` added to the amplitude inside the log.
    GazeboEq5,
}

/// Where an antenna's phase offsets φ0 come from when `phase_offset_rad` does not list them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PhaseOffsets {
    /// φ0 = reader/antenna part + cable delay (linear in frequency) + per-tag part.
    #[default]
    Structured,
    /// An independent uniform φ0 per (antenna, tag, channel), as before the structured model.
    RandomPerChannel,
}

/// Frequency plan of a reader.
#[derive(Clone, Debug, PartialEq)]
pub enum Region {
    /// ETSI EN 302 208 four-channel plan: 865.7, 866.3, 866.9, 867.5 MHz.
    Etsi,
    /// FCC part 15: 50 channels 902.75 + 0.5·k MHz, listed in a fixed pseudo-random hop order.
    Fcc,
    /// Any hop table, in hop order (kHz).
    Custom {
        /// Channel frequencies in kHz, in hop order.
        hop_table_khz: Vec<u32>,
    },
}

/// One reader (one LLRP endpoint).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReaderSpec {
    /// Reader name (unique in the scenario; the rule of [`ReaderName`]).
    pub name: ReaderName,
    /// TCP address the simulated reader listens on.
    #[serde(default = "default_listen")]
    pub listen: String,
    /// Frequency plan.
    pub region: Region,
    /// Time on each channel before hopping to the next, in ms. Defaults: FCC and custom
    /// tables 400 ms (the FCC part 15 maximum dwell), ETSI 4000 ms (EN 302 208's 4 s limit of
    /// continuous transmission on one channel).
    #[serde(default = "unset_f64")]
    pub hop_dwell_ms: f64,
    /// Stay on this channel (1-based index into the table) instead of rotating.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fixed_channel: Option<u16>,
    /// Accepted from older files and unused: the Gen2 inventory model sets the read rate.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reads_per_second: Option<f64>,
    /// With ROReportTrigger 1 (N tags or end of AISpec) and N = 0, an inventory nothing can
    /// end (Null stop triggers on AISpec and ROSpec) sends what it has read every this many ms,
    /// as Impinj readers do; 0 holds the reads until the ROSpec ends, the letter of LLRP.
    #[serde(default = "default_report_interval_ms")]
    pub report_interval_ms: u32,
    /// Time the reader takes at the start of every AISpec before its first inventory round,
    /// ms (0: none; the `impinj-r420` model's is fitted to an R420 whose AISpec ends at each
    /// tag, docs/measurement.md "Reader models").
    #[serde(default)]
    pub aispec_setup_ms: f64,
    /// The reader's pause after each inventory round before its next Query, ms (0: none; the
    /// `impinj-r420` model's is fitted to R420s reading one to 40 tags continuously,
    /// docs/measurement.md "Read rate against population").
    #[serde(default)]
    pub round_gap_ms: f64,
    /// Antennas; antenna port `i + 1` is `antennas[i]`.
    pub antennas: Vec<AntennaSpec>,
    /// The reader model whose defaults this reader's antennas took (else the scenario's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reader_model: Option<String>,
    /// The reader device it presents itself as over LLRP (identity, tables, extensions;
    /// [`super::device::DEVICES`]); none: the default, an Impinj Speedway R420.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub device: Option<String>,
    /// GPI and GPO ports, and what drives the inputs (default: four of each, idle).
    #[serde(default)]
    pub gpio: super::gpio::GpioSpec,
    /// Faults injected on a timeline of simulated time (docs/simulator.md, "Fault
    /// injection").
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub faults: Vec<super::faults::ScheduledFault>,
    /// Whether ROSpecs, AccessSpecs and the configuration survive a reboot (false: lost, as
    /// on an Impinj reader whose settings were not saved with IMPINJ_SAVE_SETTINGS).
    #[serde(default)]
    pub persist_state: bool,
}

/// Orientation and position of an antenna or an antenna offset (metres, radians): the
/// vocabulary's one pose. The scenario file writes it `{"position": [x, y, z], "yaw_deg",
/// "pitch_deg"}` (yaw about +z, 0 = +x, 90 = +y; pitch positive up; both 0 when absent),
/// converted where the mount is read and written (`scenario/mount.rs`).
pub use llrp_gateway_vocab::pose::Pose;

/// Vertical axis moving a robot's antenna up and down (triangle wave, starting at `min_z`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VerticalAxis {
    /// Lowest antenna height (world z, metres).
    pub min_z: f64,
    /// Highest antenna height (world z, metres).
    pub max_z: f64,
    /// Vertical speed in m/s.
    pub speed: f64,
}

/// A differential-drive robot following waypoints (\[M\] eqs. 1–11).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotSpec {
    /// Start pose `[x m, y m, heading rad]` (heading 0 = +x); odometry starts from it.
    pub start: [f64; 3],
    /// Waypoints `[x, y]` visited in order.
    pub waypoints: Vec<[f64; 2]>,
    /// Maximum linear speed in m/s (at most 2).
    pub speed: f64,
    /// Wheel radius r in metres.
    #[serde(default = "default_wheel_radius")]
    pub wheel_radius: f64,
    /// Distance d between the wheels in metres.
    #[serde(default = "default_wheel_base")]
    pub wheel_base: f64,
    /// Right-wheel odometry noise: variance (m²) per metre of wheel travel.
    #[serde(default = "default_k_odometry")]
    pub k_r: f64,
    /// Left-wheel odometry noise: variance (m²) per metre of wheel travel.
    #[serde(default = "default_k_odometry")]
    pub k_l: f64,
    /// Proportional gain of the linear speed on the distance to the waypoint (1/s).
    #[serde(default = "default_k_v")]
    pub k_v: f64,
    /// Proportional gain of the turn rate on the heading error (1/s).
    #[serde(default = "default_k_omega")]
    pub k_omega: f64,
    /// Distance (m) at which a waypoint counts as reached.
    #[serde(default = "default_tolerance")]
    pub tolerance_m: f64,
    /// Optional vertical axis carrying the antenna.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vertical: Option<VerticalAxis>,
    /// After the last waypoint, start again from the first.
    #[serde(default)]
    pub loop_path: bool,
    /// Where the pose the robot reports (its estimate of its own pose) comes from.
    #[serde(default)]
    pub pose_estimate: PoseEstimate,
}

/// How a robot estimates its own pose: by dead reckoning, or as a localization stack does.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PoseEstimateKind {
    /// Integrated wheel odometry (`k_r`, `k_l`): drifts without bound.
    #[default]
    Odometry,
    /// The true pose plus a bounded, time-correlated error (AMCL or SLAM on a map).
    Localized,
}

/// A robot's pose estimate; the σ and correlation time apply to `kind` "localized" only.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseEstimate {
    /// Where the estimate comes from.
    pub kind: PoseEstimateKind,
    /// Stationary standard deviation of the x error and of the y error (m).
    #[serde(default = "default_position_sigma")]
    pub position_sigma_m: f64,
    /// Stationary standard deviation of the heading error (degrees).
    #[serde(default = "default_heading_sigma")]
    pub heading_sigma_deg: f64,
    /// Correlation time of the errors (s): their autocorrelation at lag τ is e^(−τ/this).
    #[serde(default = "default_correlation")]
    pub correlation_s: f64,
}

impl Default for PoseEstimate {
    fn default() -> PoseEstimate {
        PoseEstimate {
            kind: PoseEstimateKind::Odometry,
            position_sigma_m: default_position_sigma(),
            heading_sigma_deg: default_heading_sigma(),
            correlation_s: default_correlation(),
        }
    }
}

// Localization error defaults, ours (docs/simulator.md "Pose estimates"): between the
// millimetres of scan matching at taught-in points and the "< 1 cm, < 1°" of LIDAR
// localization on a good map.
fn default_position_sigma() -> f64 {
    0.015
}
fn default_heading_sigma() -> f64 {
    0.5
}
fn default_correlation() -> f64 {
    2.0
}

/// Where an antenna is and how it moves. JSON: `{"type": "fixed", "pose": {...}}`,
/// `{"type": "robot", "robot": {...}, "offset": {...}}` or `{"type": "recorded", "file": "..."}`.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum Mount {
    /// A fixed antenna.
    Fixed {
        /// Its pose in the world.
        #[serde(with = "super::mount::mount_pose")]
        pose: Pose,
    },
    /// An antenna on a robot.
    Robot {
        /// The robot and its path.
        robot: RobotSpec,
        /// Antenna pose in the robot frame (x forward, y left, z up from the floor).
        #[serde(with = "super::mount::mount_pose")]
        offset: Pose,
    },
    /// An antenna moved along a recorded pose list.
    Recorded {
        /// CSV (header `t_s,x,y,z,yaw_deg,pitch_deg`) or JSONL with the same keys; a relative
        /// path resolves against the scenario file's directory.
        file: String,
        /// The poses read from `file` when the scenario was loaded (in µs and radians, the
        /// reader's name and this antenna's port on each).
        #[serde(skip)]
        poses: Vec<PoseSample>,
    },
}

/// Distribution of the optional extra phase noise n_opt (\[G\] eq. 4), in radians.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum NoiseDist {
    /// Uniform on `[low, high)`.
    Uniform {
        /// Lower bound.
        low: f64,
        /// Upper bound.
        high: f64,
    },
    /// Exponential with rate `lambda`.
    Exponential {
        /// Rate (1/rad).
        lambda: f64,
    },
    /// Gamma with `shape` k and `scale` θ.
    Gamma {
        /// Shape k.
        shape: f64,
        /// Scale θ.
        scale: f64,
    },
    /// Weibull with `scale` λ and `shape` k.
    Weibull {
        /// Scale λ.
        scale: f64,
        /// Shape k.
        shape: f64,
    },
    /// Normal with `mean` and standard deviation `std`.
    Normal {
        /// Mean.
        mean: f64,
        /// Standard deviation.
        std: f64,
    },
    /// Log-normal: exp of a normal with mean `mu` and standard deviation `sigma`.
    Lognormal {
        /// Mean of the underlying normal.
        mu: f64,
        /// Standard deviation of the underlying normal.
        sigma: f64,
    },
    /// Chi-squared with `k` degrees of freedom.
    ChiSquared {
        /// Degrees of freedom.
        k: f64,
    },
    /// Cauchy with `median` and `scale`.
    Cauchy {
        /// Median.
        median: f64,
        /// Scale.
        scale: f64,
    },
}

/// One antenna port of a reader.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AntennaSpec {
    /// Where the antenna is.
    pub mount: Mount,
    /// Boresight gain in dBi (\[G\] Table 1 "gain 3" is linear: 4.77 dBi).
    #[serde(default = "default_gain_dbi")]
    pub gain_dbi: f64,
    /// Full −3 dB beamwidth in degrees, in (0, 360]; 360 is isotropic.
    #[serde(default = "default_beamwidth")]
    pub beamwidth_deg: f64,
    /// Conducted transmit power in dBm (before the cable).
    #[serde(default = "default_tx_power")]
    pub tx_power_dbm: f64,
    /// Cable loss in dB (counted on the way out and on the way back).
    #[serde(default = "default_cable_loss")]
    pub cable_loss_db: f64,
    /// Power a tag chip needs to wake up, in dBm.
    #[serde(default = "default_tag_sensitivity")]
    pub tag_sensitivity_dbm: f64,
    /// Phase offset φ0 per channel (index 0 = channel 1), the same for every tag; missing
    /// channels get offsets as `phase_offsets` says.
    #[serde(default)]
    pub phase_offset_rad: Vec<f64>,
    /// How φ0 is made for the channels `phase_offset_rad` does not list.
    #[serde(default)]
    pub phase_offsets: PhaseOffsets,
    /// One-way group delay of the cable and the reader's front end (ns): a phase of
    /// 4π·f·τ, linear in frequency, in the structured φ0.
    #[serde(default = "default_cable_delay")]
    pub cable_delay_ns: f64,
    /// +1: φ = φ0 + 4πD/λ (\[G\] eq. 4); −1: φ = φ0 − 4πD/λ (\[M\] eq. 13).
    #[serde(default = "default_phase_sign")]
    pub phase_sign: f64,
    /// Standard deviation σ_φ of the Gaussian phase noise (rad) of a read at or above
    /// `phase_noise_ref_dbm`; below it σ grows as the backscatter amplitude falls.
    #[serde(default = "default_phase_noise")]
    pub phase_noise_rad: f64,
    /// RSSI (dBm) down to which the phase and Doppler noise keep their nominal σ.
    #[serde(default = "default_noise_ref")]
    pub phase_noise_ref_dbm: f64,
    /// Report the phase with Impinj's π ambiguity: a read's phase is shifted by π or not,
    /// at random.
    #[serde(default)]
    pub phase_pi_ambiguity: bool,
    /// Standard deviation of the Doppler measurement noise at or above `phase_noise_ref_dbm`
    /// (Hz).
    #[serde(default = "default_doppler_sigma")]
    pub doppler_sigma_hz: f64,
    /// How the reported RSSI is made.
    #[serde(default)]
    pub rssi_model: RssiModel,
    /// Standard deviation of the RSSI measurement noise (dB; `rssi_model` "reader").
    #[serde(default = "default_rssi_sigma")]
    pub rssi_sigma_db: f64,
    /// Step the reader reports RSSI in (dB; 0: unquantised; `rssi_model` "reader").
    #[serde(default = "default_rssi_resolution")]
    pub rssi_resolution_db: f64,
    /// Standard deviation of the noise added inside the RSSI log (\[G\] eq. 5; used only with
    /// `rssi_model` "gazebo_eq5"; default 0.01).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rssi_noise: Option<f64>,
    /// Optional extra phase noise n_opt.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub extra_phase_noise: Option<NoiseDist>,
    /// Nominal read range r (metres).
    #[serde(default = "default_range")]
    pub range_m: f64,
    /// Relative standard deviation σ_r of the read range.
    #[serde(default = "default_range_sigma")]
    pub range_sigma: f64,
    /// Steps per turn of the reported phase, as a power of two (12: every code of Impinj's
    /// 12-bit field; 10: every fourth, as an R420 reports).
    #[serde(default = "default_phase_bits")]
    pub phase_resolution_bits: u8,
    /// How fast the phase, Doppler (and, with `rssi_sigma_grows`, RSSI) noise grows below
    /// `phase_noise_ref_dbm`: σ ∝ 10^(k·(ref − RSSI)/20).
    #[serde(default = "default_noise_exponent")]
    pub noise_exponent: f64,
    /// The RSSI noise grows below `phase_noise_ref_dbm` as the phase noise does.
    #[serde(default)]
    pub rssi_sigma_grows: bool,
    /// Degrees of freedom of a Student's t phase noise (same σ, heavier tails); 0: Gaussian.
    #[serde(default)]
    pub phase_noise_dof: f64,
    /// Share of reads whose phase is an outlier (N(0, (12σ)²) added).
    #[serde(default)]
    pub phase_outlier_rate: f64,
    /// Share of reads whose RSSI is an outlier (2–6 dB either way).
    #[serde(default)]
    pub rssi_outlier_rate: f64,
    /// Backscatter compression: above `compression_knee_db` of forward-link margin over the
    /// tag's wake-up power, its RSSI grows only by (1 − this) dB per dB (0: linear).
    #[serde(default)]
    pub backscatter_compression: f64,
    /// Forward-link margin (dB over the tag's wake-up power) where compression starts.
    #[serde(default)]
    pub compression_knee_db: f64,
    /// RSSI change across the band (dB per MHz from the hop table's centre), common to all
    /// tags: the reader's and antenna's frequency response.
    #[serde(default)]
    pub rssi_tilt_db_per_mhz: f64,
    /// RMS (rad) of the antenna's smooth angle-dependent phase error (its phase centre moving
    /// off boresight), the same on every channel and for every tag; 0: none.
    #[serde(default)]
    pub phase_pattern_rad: f64,
    /// Angle (degrees) over which that phase error decorrelates.
    #[serde(default = "default_pattern_deg")]
    pub phase_pattern_deg: f64,
    /// Angle (degrees) off boresight at which the angle-dependent phase error (this
    /// antenna's and that of the tags it reads) has doubled its boresight RMS: it grows as
    /// 1 + (θ/angle)², held past 60°; 0: the same at every angle.
    #[serde(default)]
    pub phase_pattern_growth_deg: f64,
}

/// \[G\] Table 1's RSS noise, the default of `rssi_noise`.
pub const DEFAULT_RSSI_NOISE: f64 = 0.01;

impl AntennaSpec {
    /// The \[G\] eq. 5 noise σ: `rssi_noise` or its default.
    pub fn eq5_noise(&self) -> f64 {
        self.rssi_noise.unwrap_or(DEFAULT_RSSI_NOISE)
    }
}
