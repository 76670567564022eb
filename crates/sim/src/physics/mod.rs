//! The radio-channel model of a simulated reader: which tags each antenna reads, when, and
//! with which RSSI, phase, channel and Doppler shift.
//!
//! [`Model`] is built once per reader from a [`Scenario`]; it precomputes robot drives and
//! answers queries by simulated time (µs since scenario start). Every random draw is seeded
//! from the scenario seed and the identity of the draw (reader, antenna, epoch, reply), so the
//! answers never depend on call order. The building blocks are public for testing against
//! closed forms: [`phase`], [`rssi`], [`multipath`], [`antenna`], [`hopping`], [`schedule`],
//! [`robot`], [`motion`], [`noise`], [`fastmath`].

pub mod antenna;
pub mod fastmath;
mod field;
pub mod flags;
pub mod gen2;
pub mod geometry;
pub mod hardware;
pub mod hopping;
mod inventory;
pub mod lookahead;
pub mod motion;
pub mod multipath;
pub mod noise;
pub mod phase;
pub mod pool;
mod pose;
pub mod robot;
pub mod rounds;
pub mod rssi;
pub mod schedule;
pub mod seed;
pub mod tag;
mod world;

#[cfg(test)]
mod realism_tests;
#[cfg(test)]
mod tests;

pub use world::World;

use crate::scenario::tagmem::{default_user, parse_epc, parse_password, parse_words};
use crate::scenario::{AntennaSpec, Mount, PhaseOffsets, Pose, RobotSpec, Scenario, VerticalAxis};
use llrp_gateway_vocab::pose::PoseSample;
use seed::default_tid;
use std::sync::Arc;

use antenna::{Lobe, Pattern};
use field::{FieldCache, GainTable};
use geometry::wrap_pi;
use hopping::HopSchedule;
use motion::PolylineMotion;
use multipath::Plane;
use robot::RobotTrajectory;

/// Length of an inventory epoch (one antenna dwell on the fixed grid), µs.
pub fn inventory_epoch_us() -> u64 {
    inventory::FIELD_BUCKET_US
}

/// Position and boresight of an antenna at one instant (metres, radians): the vocabulary's
/// one pose.
pub use llrp_gateway_vocab::pose::Pose as AntennaPose;

/// One successful tag read.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Read {
    /// Index into `scenario.tags`.
    pub tag: usize,
    /// Antenna port, 1-based.
    pub antenna: u16,
    /// Simulated µs since scenario start.
    pub time_us: u64,
    /// 1-based index into the reader's frequency table.
    pub channel_index: u16,
    /// Carrier frequency in kHz.
    pub frequency_khz: u32,
    /// Received backscatter power in dBm, unrounded.
    pub rssi_dbm: f64,
    /// Reported phase in `[0, 2π)` (0 when not asked for, see [`Want`]).
    pub phase_rad: f64,
    /// Doppler shift in Hz, positive when the tag approaches the antenna (0 when not asked
    /// for).
    pub doppler_hz: f64,
    /// The forward link's margin over the tag's read sensitivity at the read, dB: what an
    /// access on the tag has to work with (a write needs more, `reader::access::link`).
    pub margin_db: f64,
}

/// Which optional values of a [`Read`] to work out; the others (tag, antenna, time, channel,
/// RSSI) always are, and asking for fewer never changes them or which reads happen.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Want {
    /// The reported phase.
    pub phase: bool,
    /// The Doppler shift.
    pub doppler: bool,
}

impl Want {
    /// Every value.
    pub const ALL: Want = Want {
        phase: true,
        doppler: true,
    };

    /// Whether reads made with `self` carry everything `other` asks for.
    pub fn covers(self, other: Want) -> bool {
        (self.phase || !other.phase) && (self.doppler || !other.doppler)
    }
}

/// How an antenna moves.
#[derive(Clone, Debug)]
enum Mover {
    Fixed(AntennaPose),
    Robot {
        /// Index into `Model::robots`.
        robot: usize,
        offset: Pose,
        vertical: Option<VerticalAxis>,
    },
    Recorded(Vec<PoseSample>),
}

#[derive(Clone, Debug)]
struct AntennaModel {
    spec: AntennaSpec,
    mover: Mover,
    /// The gain pattern's constants, tabulated for the channel.
    /// (Shared by the antennas with the same lobe.)
    pattern: Arc<Pattern>,
    /// The gain over the direction cosine, for the field bounds.
    /// (Shared by the antennas with the same lobe.)
    gains: Arc<GainTable>,
    /// From this time (µs) on neither the antenna nor any tag moves (`u64::MAX`: never).
    rest_us: u64,
    /// For a robot mount: the cosine and sine of the offset's yaw and pitch.
    mount_aim: Option<MountAim>,
    /// Bounds on how fast the antenna moves and turns, when known (fixed and robot mounts).
    rates: Option<field::Rates>,
    /// The structured φ0 without the tag's part, per channel (index 0 = channel 1): the
    /// scenario's listed offsets, else the reader/antenna part plus the cable's 4π·f·τ.
    phase_base: Vec<f64>,
    /// What the antenna's hardware adds to its reads.
    hardware: hardware::AntennaHardware,
}

/// The constant part of a robot-mounted antenna's boresight.
#[derive(Clone, Copy, Debug)]
struct MountAim {
    /// Cosine and sine of the offset's yaw.
    yaw_cos: f64,
    yaw_sin: f64,
    pitch_cos: f64,
    pitch_sin: f64,
}

#[derive(Clone, Debug)]
struct TagModel {
    epc: crate::scenario::tagmem::TagEpc,
    tid: Vec<u16>,
    user: Vec<u16>,
    /// Kill and access passwords.
    passwords: [u32; 2],
    motion: PolylineMotion,
    radio: tag::TagRadio,
}

/// The channel model of one reader of a scenario.
#[derive(Clone, Debug)]
pub struct Model {
    seed: u64,
    reader: usize,
    table: Vec<u32>,
    wavelengths: Vec<f64>,
    hops: HopSchedule,
    antennas: Vec<AntennaModel>,
    /// The scenario's tags, shared by every reader's model.
    tags: Arc<[TagModel]>,
    /// The reflectors with usable normals, prepared for the channel.
    planes: Arc<[Plane]>,
    /// The tag antenna's linear gain, [`rssi::db_to_linear`] of [`rssi::TAG_GAIN_DBI`].
    tag_gain_linear: f64,
    /// Every robot of the scenario (shared; a robot mount names its index here).
    robots: Arc<[RobotTrajectory]>,
    /// Field classifications per antenna ([`field`]); never changes a result.
    field_cache: FieldCache,
    /// `seed::mix(&[seed, PHASE_OFFSET, reader])`: the phase offsets' common prefix.
    phase_prefix: u64,
}

/// Every distinct robot of the scenario, in order of first appearance over all readers, so
/// antennas sharing a robot (on any reader) share one drive and one odometry.
pub fn distinct_robots(scenario: &Scenario) -> Vec<&RobotSpec> {
    let mut robots: Vec<&RobotSpec> = Vec::new();
    for antenna in scenario.readers.iter().flat_map(|r| &r.antennas) {
        if let Mount::Robot { robot, .. } = &antenna.mount {
            if !robots.contains(&robot) {
                robots.push(robot);
            }
        }
    }
    robots
}

/// How antenna mount `mount` moves: fixed, replayed from a recording, or on one of
/// `all_robots` (the scenario's, by [`distinct_robots`]).
fn mover_of(mount: &Mount, all_robots: &[&RobotSpec]) -> Mover {
    match mount {
        Mount::Fixed { pose } => Mover::Fixed(pose_from(pose)),
        Mount::Recorded { poses, .. } => Mover::Recorded(poses.clone()),
        Mount::Robot { robot, offset } => {
            // `robot` was collected from this very scenario, so it is in the list.
            let global = all_robots.iter().position(|r| *r == robot).unwrap_or(0);
            Mover::Robot {
                robot: global,
                offset: *offset,
                vertical: robot.vertical.clone(),
            }
        }
    }
}

/// When an antenna moved by `mover` comes to rest for good (s), if it does.
fn still_after_s(mover: &Mover, robots: &[RobotTrajectory]) -> Option<f64> {
    match mover {
        Mover::Fixed(_) => Some(0.0),
        Mover::Recorded(poses) => Some(
            poses
                .last()
                .map_or(0.0, |p| seconds(p.t_us) + REST_MARGIN_S),
        ),
        Mover::Robot {
            robot, vertical, ..
        } => match vertical {
            Some(v) if v.speed > 0.0 && v.max_z > v.min_z => None,
            // A moment after the last stored sample, the pose is that sample's.
            _ => robots
                .get(*robot)
                .map(|r: &RobotTrajectory| r.duration_s() + REST_MARGIN_S),
        },
    }
}

/// The constant part of the boresight of an antenna on a robot (`None` for other mounts).
fn mount_aim(mount: &Mount) -> Option<MountAim> {
    match mount {
        Mount::Robot { offset, .. } => {
            let pitch = offset.pitch_rad;
            let (yaw_sin, yaw_cos) = offset.yaw_rad.sin_cos();
            Some(MountAim {
                yaw_cos,
                yaw_sin,
                pitch_cos: pitch.cos(),
                pitch_sin: pitch.sin(),
            })
        }
        _ => None,
    }
}

/// The antenna's fastest motion and turn, for the field bounds (`None`: not bounded).
fn max_rates(mover: &Mover, robots: &[RobotTrajectory]) -> Option<field::Rates> {
    match mover {
        Mover::Fixed(_) => Some(field::Rates::default()),
        Mover::Recorded(_) => None,
        Mover::Robot {
            robot,
            offset,
            vertical,
        } => robots.get(*robot).map(|r: &RobotTrajectory| {
            let [v, w] = r.max_rates();
            let arm = offset.position[0].hypot(offset.position[1]);
            let lift = vertical
                .as_ref()
                .filter(|v| v.speed.is_finite() && v.speed > 0.0)
                .map_or(0.0, |v| v.speed);
            // The antenna moves with the robot, swings on its arm as the robot turns
            // and rides the lift; a relative margin covers rounding.
            field::Rates {
                speed: (v + arm * w + lift) * (1.0 + 1e-9),
                turn: w * (1.0 + 1e-9),
            }
        }),
    }
}

/// The antenna's phase offset per channel of `table`: the scenario's where given, else
/// its random offset plus the cable's phase.
fn phase_base(
    scenario: &Scenario,
    reader: usize,
    port: u64,
    table: &[u32],
    a: &AntennaSpec,
) -> Vec<f64> {
    let antenna_phase = std::f64::consts::TAU
        * seed::unit(seed::mix(&[
            scenario.seed,
            seed::domain::ANTENNA_PHASE,
            reader as u64,
            port,
        ]));
    table
        .iter()
        .enumerate()
        .map(|(k, &f)| match a.phase_offset_rad.get(k) {
            Some(&given) => given,
            None => geometry::wrap_2pi(
                antenna_phase
                    + a.phase_sign
                        * phase::cable_phase(f64::from(f) * 1e3, a.cable_delay_ns * 1e-9),
            ),
        })
        .collect()
}

/// The hardware imperfections of antenna `port` of reader `reader`.
fn antenna_hardware(
    scenario: &Scenario,
    reader: usize,
    port: u64,
    table: &[u32],
    a: &AntennaSpec,
) -> hardware::AntennaHardware {
    hardware::AntennaHardware {
        phase_field: hardware::SmoothField::new(
            &[scenario.seed, seed::domain::HARDWARE, reader as u64, port],
            a.phase_pattern_rad,
            a.phase_pattern_deg.to_radians(),
        ),
        pattern_growth_rad: a.phase_pattern_growth_deg.to_radians(),
        band_db: hardware::band_offsets(table, a.rssi_tilt_db_per_mhz),
        prefix: seed::mix(&[
            scenario.seed,
            seed::domain::HARDWARE,
            reader as u64,
            port,
            0,
        ]),
        channel_phase_sigma: scenario.tag_variation.channel_phase_sigma_rad,
        channel_rssi_sigma: scenario.tag_variation.channel_rssi_sigma_db,
    }
}

impl Model {
    /// Builds the model of reader `reader` (index into `scenario.readers`); seeds derive from
    /// `scenario.seed`. An index past the last reader gives a model with no antennas. (Models
    /// of several readers of one scenario share its data through [`Model::in_world`].)
    pub fn new(scenario: &Scenario, reader: usize) -> Model {
        Self::in_world(&World::new(scenario), scenario, reader)
    }

    /// The model of reader `reader` of `scenario`, sharing `world` (made from the same
    /// scenario) with the other readers' models.
    pub fn in_world(world: &World, scenario: &Scenario, reader: usize) -> Model {
        let spec = scenario.readers.get(reader);
        let table = spec.map(|r| r.region.frequencies_khz()).unwrap_or_default();
        let wavelengths = table.iter().map(|&f| phase::wavelength_m(f)).collect();
        let hops = spec.map_or(HopSchedule::new(1, 1.0, None), |r| {
            HopSchedule::new(table.len(), r.hop_dwell_ms, r.fixed_channel)
        });
        let all_robots = distinct_robots(scenario);
        let robots = &world.robots;
        let mut antennas = Vec::new();
        let mut tables = Vec::new();
        let mut patterns = Vec::new();
        for a in spec.map_or(&[][..], |r| &r.antennas) {
            let port = antennas.len() as u64 + 1;
            let mover = mover_of(&a.mount, &all_robots);
            let lobe = Lobe::new(a.gain_dbi, a.beamwidth_deg);
            let still_s = still_after_s(&mover, robots);
            let rates = max_rates(&mover, robots);
            antennas.push(AntennaModel {
                hardware: antenna_hardware(scenario, reader, port, &table, a),
                phase_base: phase_base(scenario, reader, port, &table, a),
                spec: a.clone(),
                rates,
                mount_aim: mount_aim(&a.mount),
                mover,
                pattern: shared_pattern(&mut patterns, &lobe),
                gains: shared_table(&mut tables, &lobe),
                rest_us: still_s.map_or(u64::MAX, rest_time_us),
            });
        }
        let tags_rest = world.tags_rest_us;
        for a in &mut antennas {
            a.rest_us = field::rest_grid(a.rest_us.max(tags_rest));
        }
        let field_cache = FieldCache::new(antennas.len());
        Model {
            seed: scenario.seed,
            reader,
            table,
            wavelengths,
            hops,
            antennas,
            tags: Arc::clone(&world.tags),
            planes: Arc::clone(&world.planes),
            tag_gain_linear: rssi::db_to_linear(rssi::TAG_GAIN_DBI),
            robots: Arc::clone(&world.robots),
            field_cache,
            phase_prefix: seed::mix(&[scenario.seed, seed::domain::PHASE_OFFSET, reader as u64]),
        }
    }

    /// Number of antenna ports.
    pub fn antenna_count(&self) -> u16 {
        u16::try_from(self.antennas.len()).unwrap_or(u16::MAX)
    }

    /// The reader's channel table in hop order (ChannelIndex k is `table[k - 1]`).
    pub fn frequencies_khz(&self) -> &[u32] {
        &self.table
    }

    /// Channel (1-based index into [`Model::frequencies_khz`]) in use at `t_us`: the table is
    /// walked in order, `hop_dwell_ms` per channel, unless the scenario pins `fixed_channel`.
    pub fn channel_at(&self, t_us: u64) -> u16 {
        self.hops.channel_at(t_us)
    }

    /// The reader's hop schedule (channel count, dwell, pinned channel).
    pub fn hop_schedule(&self) -> HopSchedule {
        self.hops
    }

    /// Wavelength (m) of channel `channel` (1-based); that of channel 1 if out of range.
    pub fn wavelength_m(&self, channel: u16) -> f64 {
        let i = usize::from(channel.max(1) - 1);
        self.wavelengths
            .get(i)
            .or(self.wavelengths.first())
            .copied()
            .unwrap_or(phase::wavelength_m(866_300))
    }

    /// True position of tag `tag` at `t_us` (the origin for an unknown tag).
    pub fn tag_position(&self, tag: usize, t_us: u64) -> [f64; 3] {
        self.tags
            .get(tag)
            .map_or([0.0; 3], |t| t.motion.position(seconds(t_us)))
    }

    /// True pose of antenna `antenna` (1-based) at `t_us` (ground truth; the origin for an
    /// unknown antenna).
    pub fn antenna_pose(&self, antenna: u16, t_us: u64) -> AntennaPose {
        self.pose(antenna, t_us, RobotTrajectory::true_pose)
    }

    /// Pose of antenna `antenna` as dead-reckoned from wheel odometry; the true pose for
    /// fixed and recorded antennas.
    pub fn odometry_pose(&self, antenna: u16, t_us: u64) -> AntennaPose {
        self.pose(antenna, t_us, RobotTrajectory::odometry_pose)
    }

    /// Pose of antenna `antenna` as its robot estimates it (per its `pose_estimate`), what it
    /// would hand a localizer; the true pose for fixed and recorded antennas.
    pub fn estimated_pose(&self, antenna: u16, t_us: u64) -> AntennaPose {
        self.pose(antenna, t_us, RobotTrajectory::estimated_pose)
    }

    /// Inventoried flags for this scenario's tags, every one in state A.
    pub fn new_flags(&self) -> flags::Flags {
        flags::Flags::new(self.seed, self.tags.len())
    }

    /// Number of tags.
    pub fn tag_count(&self) -> usize {
        self.tags.len()
    }

    /// The generator of the draws of an access on `tag` singulated by `antenna` at
    /// `time_us`: seeded by the scenario and that identity only.
    pub fn access_stream(&self, tag: usize, antenna: u16, time_us: u64) -> seed::Stream {
        seed::stream(&[
            self.seed,
            seed::domain::ACCESS,
            self.reader as u64,
            tag as u64,
            u64::from(antenna),
            time_us,
        ])
    }

    /// EPC of tag `tag` (an all-zero EPC-96 for an unknown tag).
    pub fn tag_epc(&self, tag: usize) -> crate::scenario::tagmem::TagEpc {
        self.tags.get(tag).map_or([0; 12].into(), |t| t.epc)
    }

    /// TID memory of tag `tag` as 16-bit words.
    pub fn tag_tid(&self, tag: usize) -> Vec<u16> {
        self.tags.get(tag).map_or_else(Vec::new, |t| t.tid.clone())
    }

    /// User memory of tag `tag` as 16-bit words.
    pub fn tag_user(&self, tag: usize) -> Vec<u16> {
        self.tags.get(tag).map_or_else(Vec::new, |t| t.user.clone())
    }

    /// Kill and access passwords of tag `tag` (0 and 0 for an unknown tag).
    pub fn tag_passwords(&self, tag: usize) -> (u32, u32) {
        self.tags
            .get(tag)
            .map_or((0, 0), |t| (t.passwords[0], t.passwords[1]))
    }

    /// Phase offset φ0 (rad) of (antenna, tag, channel): the scenario's per-channel value if
    /// listed; otherwise, structured, the reader/antenna part plus the cable's 4π·f·τ plus
    /// the tag's part, or, when the antenna asks for `random_per_channel`, uniform in
    /// `[0, 2π)` drawn from the seed for each (antenna, tag, channel).
    pub fn phase_offset(&self, antenna: u16, tag: usize, channel: u16) -> f64 {
        let Some(a) = self.antennas.get(usize::from(antenna.max(1) - 1)) else {
            return 0.0;
        };
        let k = usize::from(channel.max(1) - 1);
        if let Some(&given) = a.spec.phase_offset_rad.get(k) {
            return given;
        }
        match a.spec.phase_offsets {
            PhaseOffsets::Structured => {
                let f_hz = self.table.get(k).map_or(0.0, |&f| f64::from(f) * 1e3);
                let tag_part = self.tags.get(tag).map_or(0.0, |t| {
                    t.radio.phase_rad
                        + a.spec.phase_sign * phase::cable_phase(f_hz, t.radio.delay_ns * 1e-9)
                });
                geometry::wrap_2pi(
                    a.phase_base.get(k).copied().unwrap_or(0.0)
                        + tag_part
                        + a.hardware.phase_rad(tag, channel),
                )
            }
            PhaseOffsets::RandomPerChannel => {
                // seed::mix(&[seed, PHASE_OFFSET, reader, antenna, tag, channel]), its
                // prefix mixed once.
                let h = seed::mix_on(
                    self.phase_prefix,
                    &[u64::from(antenna), tag as u64, u64::from(channel)],
                );
                std::f64::consts::TAU * seed::unit(h)
            }
        }
    }
}

/// The gain table of `lobe`: one of `tables` if one has that lobe, otherwise a new one,
/// added to them.
fn shared_table(tables: &mut Vec<(Lobe, Arc<GainTable>)>, lobe: &Lobe) -> Arc<GainTable> {
    if let Some((_, t)) = tables.iter().find(|(l, _)| l == lobe) {
        return t.clone();
    }
    let t = Arc::new(GainTable::new(lobe));
    tables.push((*lobe, t.clone()));
    t
}

/// The tabulated pattern of `lobe`: one of `patterns` if one has that lobe, otherwise a new
/// one, added to them.
fn shared_pattern(patterns: &mut Vec<Arc<Pattern>>, lobe: &Lobe) -> Arc<Pattern> {
    if let Some(p) = patterns.iter().find(|p| p.lobe == *lobe) {
        return p.clone();
    }
    let p = Arc::new(Pattern::new(lobe));
    patterns.push(p.clone());
    p
}

/// A fixed mount's pose, its yaw onto [−π, π].
fn pose_from(p: &Pose) -> AntennaPose {
    AntennaPose {
        yaw_rad: wrap_pi(p.yaw_rad),
        ..*p
    }
}

/// Added to the time something stops, so that interpolation has surely reached its last point.
const REST_MARGIN_S: f64 = 0.1;

/// A rest time in seconds as µs, rounded up (`u64::MAX` when it is not a finite time).
fn rest_time_us(t_s: f64) -> u64 {
    let us = (t_s.max(0.0) * 1e6).ceil();
    if us.is_finite() && us < u64::MAX as f64 {
        us as u64
    } else {
        u64::MAX
    }
}

/// Microseconds to seconds.
fn seconds(t_us: u64) -> f64 {
    t_us as f64 * 1e-6
}
