//! Range and consistency checks of a parsed scenario; every error names the JSON path of the
//! offending value and says what was expected and what was found.

use std::collections::HashSet;

use super::tagmem::{parse_epc, parse_password, parse_words};
use super::{
    AntennaSpec, Mount, NoiseDist, Pose, ReaderSpec, Region, RobotSpec, Scenario, ScenarioError,
};

/// Highest robot speed allowed (\[M\]: v ≤ 2 m/s).
pub const MAX_ROBOT_SPEED: f64 = 2.0;
/// Highest tag speed allowed (a fast conveyor or forklift), m/s.
pub const MAX_TAG_SPEED: f64 = 10.0;
/// Highest read budget: one attempt per µs of simulated time at most.
pub const MAX_READS_PER_SECOND: f64 = 100_000.0;
/// Longest interval between the reports of an AISpec without its own end (one hour), ms.
pub const MAX_REPORT_INTERVAL_MS: u32 = 3_600_000;
/// Longest AISpec setup a scenario may give (ms).
pub const MAX_AISPEC_SETUP_MS: f64 = 10_000.0;
/// Longest pause after an inventory round (ms).
pub const MAX_ROUND_GAP_MS: f64 = 1_000.0;
/// Most antenna ports per reader.
pub const MAX_ANTENNAS: usize = 64;

pub(super) type Check = Result<(), ScenarioError>;

pub(super) fn invalid(path: impl Into<String>, reason: impl Into<String>) -> ScenarioError {
    ScenarioError::Invalid {
        path: path.into(),
        reason: reason.into(),
    }
}

/// `value` must be finite and within `[lo, hi]`.
pub(super) fn in_range(path: &str, value: f64, lo: f64, hi: f64) -> Check {
    if value.is_finite() && value >= lo && value <= hi {
        Ok(())
    } else {
        Err(invalid(
            path,
            format!("must be in [{lo}, {hi}], got {value}"),
        ))
    }
}

/// `value` must be finite and > 0 (and ≤ `hi`).
pub(super) fn positive(path: &str, value: f64, hi: f64) -> Check {
    if value.is_finite() && value > 0.0 && value <= hi {
        Ok(())
    } else {
        Err(invalid(path, format!("must be in (0, {hi}], got {value}")))
    }
}

/// `value` must be finite and ≥ 0.
fn non_negative(path: &str, value: f64) -> Check {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(invalid(
            path,
            format!("must be finite and >= 0, got {value}"),
        ))
    }
}

fn finite(path: &str, v: &[f64]) -> Check {
    if v.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(invalid(path, format!("must be finite, got {v:?}")))
    }
}

/// Checks a point lies inside the world box (with 1 mm of slack).
fn inside(s: &Scenario, path: &str, p: &[f64]) -> Check {
    finite(path, p)?;
    let (min, max) = (s.world.min, s.world.max);
    let ok = p
        .iter()
        .enumerate()
        .all(|(i, &x)| x >= min[i] - 1e-3 && x <= max[i] + 1e-3);
    if ok {
        Ok(())
    } else {
        Err(invalid(
            path,
            format!("must be inside the world box {min:?}..{max:?}, got {p:?}"),
        ))
    }
}

/// Checks every value of the scenario.
pub(super) fn validate(s: &Scenario) -> Check {
    if s.name.trim().is_empty() {
        return Err(invalid("name", "must not be empty"));
    }
    finite("world.min", &s.world.min)?;
    finite("world.max", &s.world.max)?;
    for i in 0..3 {
        if s.world.min[i] >= s.world.max[i] {
            return Err(invalid(
                "world",
                format!(
                    "min must be below max on every axis, got {:?} and {:?}",
                    s.world.min, s.world.max
                ),
            ));
        }
    }
    for (i, r) in s.reflectors.iter().enumerate() {
        let p = format!("reflectors[{i}]");
        finite(&format!("{p}.point"), &r.point)?;
        finite(&format!("{p}.normal"), &r.normal)?;
        if r.normal.iter().all(|&x| x == 0.0) {
            return Err(invalid(
                format!("{p}.normal"),
                "must not be the zero vector",
            ));
        }
        in_range(&format!("{p}.coefficient"), r.coefficient, 0.0, 1.0)?;
    }
    validate_tags(s)?;
    in_range(
        "tag_variation.sensitivity_sigma_db",
        s.tag_variation.sensitivity_sigma_db,
        0.0,
        6.0,
    )?;
    in_range(
        "tag_variation.backscatter_sigma_db",
        s.tag_variation.backscatter_sigma_db,
        0.0,
        6.0,
    )?;
    super::hardware_checks::tag_variation(&s.tag_variation)?;
    if s.readers.is_empty() {
        return Err(invalid("readers", "must list at least one reader"));
    }
    let mut names = HashSet::new();
    let mut listens = HashSet::new();
    for (i, r) in s.readers.iter().enumerate() {
        let p = format!("readers[{i}]");
        if !names.insert(r.name.as_str()) {
            return Err(invalid(
                format!("{p}.name"),
                format!("duplicate reader name \"{}\"", r.name),
            ));
        }
        if !listens.insert(r.listen.as_str()) {
            return Err(invalid(
                format!("{p}.listen"),
                format!("another reader already listens on {}", r.listen),
            ));
        }
        validate_reader(s, &p, r)?;
    }
    Ok(())
}

fn validate_tags(s: &Scenario) -> Check {
    let mut epcs = HashSet::new();
    for (i, t) in s.tags.iter().enumerate() {
        let p = format!("tags[{i}]");
        let epc = parse_epc(&t.epc).map_err(|e| invalid(format!("{p}.epc"), e))?;
        if !epcs.insert(epc) {
            return Err(invalid(
                format!("{p}.epc"),
                format!("duplicate EPC {}", t.epc),
            ));
        }
        inside(s, &format!("{p}.position"), &t.position)?;
        if let Some(tid) = &t.tid {
            let words = parse_words(tid).map_err(|e| invalid(format!("{p}.tid"), e))?;
            if words.is_empty() {
                return Err(invalid(
                    format!("{p}.tid"),
                    "must not be empty (omit it for the default)",
                ));
            }
        }
        if let Some(user) = &t.user {
            parse_words(user).map_err(|e| invalid(format!("{p}.user"), e))?;
        }
        for (name, v) in [
            ("kill_password", &t.kill_password),
            ("access_password", &t.access_password),
        ] {
            if let Some(v) = v {
                parse_password(v).map_err(|e| invalid(format!("{p}.{name}"), e))?;
            }
        }
        if let Some(axis) = &t.orientation {
            finite(&format!("{p}.orientation"), axis)?;
            if axis.iter().all(|&x| x == 0.0) {
                return Err(invalid(
                    format!("{p}.orientation"),
                    "must not be the zero vector (omit it for an aligned tag)",
                ));
            }
        }
        for (name, v) in [
            ("sensitivity_offset_db", t.sensitivity_offset_db),
            ("backscatter_offset_db", t.backscatter_offset_db),
        ] {
            if let Some(v) = v {
                in_range(&format!("{p}.{name}"), v, -20.0, 20.0)?;
            }
        }
        if let Some(path) = &t.path {
            let pp = format!("{p}.path");
            if path.waypoints.is_empty() {
                return Err(invalid(
                    format!("{pp}.waypoints"),
                    "must list at least one waypoint",
                ));
            }
            for (j, w) in path.waypoints.iter().enumerate() {
                inside(s, &format!("{pp}.waypoints[{j}]"), w)?;
            }
            positive(&format!("{pp}.speed"), path.speed, MAX_TAG_SPEED)?;
            non_negative(&format!("{pp}.start_s"), path.start_s)?;
        }
    }
    Ok(())
}

fn validate_reader(s: &Scenario, p: &str, r: &ReaderSpec) -> Check {
    if r.listen.parse::<std::net::SocketAddr>().is_err() {
        return Err(invalid(
            format!("{p}.listen"),
            format!(
                "must be an IP address and port such as 127.0.0.1:5084, got \"{}\"",
                r.listen
            ),
        ));
    }
    if let Region::Custom { hop_table_khz } = &r.region {
        validate_hop_table(&format!("{p}.region.hop_table_khz"), hop_table_khz)?;
    }
    positive(&format!("{p}.hop_dwell_ms"), r.hop_dwell_ms, 3_600_000.0)?;
    let channels = r.region.frequencies_khz().len();
    if let Some(c) = r.fixed_channel {
        if c == 0 || usize::from(c) > channels {
            return Err(invalid(
                format!("{p}.fixed_channel"),
                format!("must be a channel index in [1, {channels}], got {c}"),
            ));
        }
    }
    validate_reader_timing(p, r)?;
    if r.antennas.is_empty() {
        return Err(invalid(
            format!("{p}.antennas"),
            "must list at least one antenna",
        ));
    }
    if r.antennas.len() > MAX_ANTENNAS {
        return Err(invalid(
            format!("{p}.antennas"),
            format!(
                "at most {MAX_ANTENNAS} antennas per reader, got {}",
                r.antennas.len()
            ),
        ));
    }
    for (a, antenna) in r.antennas.iter().enumerate() {
        validate_antenna(s, &format!("{p}.antennas[{a}]"), antenna, channels)?;
    }
    super::device::validate(p, r)?;
    super::gpio::validate_gpio(p, &r.gpio, r.device.as_deref())?;
    super::faults::validate_faults(p, &r.faults, r.antennas.len())
}

/// Checks a custom region's hop table: 1 to 65535 distinct UHF RFID channels.
fn validate_hop_table(rp: &str, hop_table_khz: &[u32]) -> Check {
    if hop_table_khz.is_empty() || hop_table_khz.len() > usize::from(u16::MAX) {
        return Err(invalid(rp, "must list between 1 and 65535 channels"));
    }
    let mut seen = HashSet::new();
    for (k, &f) in hop_table_khz.iter().enumerate() {
        if !(840_000..=960_000).contains(&f) {
            return Err(invalid(
                format!("{rp}[{k}]"),
                format!("must be a UHF RFID frequency in [840000, 960000] kHz, got {f}"),
            ));
        }
        if !seen.insert(f) {
            return Err(invalid(
                format!("{rp}[{k}]"),
                format!("duplicate channel {f} kHz"),
            ));
        }
    }
    Ok(())
}

/// Checks a reader's read rate, AISpec setup, pause between rounds and report interval.
fn validate_reader_timing(p: &str, r: &ReaderSpec) -> Check {
    if let Some(rate) = r.reads_per_second {
        positive(&format!("{p}.reads_per_second"), rate, MAX_READS_PER_SECOND)?;
    }
    in_range(
        &format!("{p}.aispec_setup_ms"),
        r.aispec_setup_ms,
        0.0,
        MAX_AISPEC_SETUP_MS,
    )?;
    in_range(
        &format!("{p}.round_gap_ms"),
        r.round_gap_ms,
        0.0,
        MAX_ROUND_GAP_MS,
    )?;
    if r.report_interval_ms > MAX_REPORT_INTERVAL_MS {
        return Err(invalid(
            format!("{p}.report_interval_ms"),
            format!(
                "must be at most {MAX_REPORT_INTERVAL_MS} (one hour; 0 holds reads until the ROSpec ends), got {}",
                r.report_interval_ms
            ),
        ));
    }
    Ok(())
}

fn validate_antenna(s: &Scenario, p: &str, a: &AntennaSpec, channels: usize) -> Check {
    validate_mount(s, p, &a.mount)?;
    in_range(&format!("{p}.gain_dbi"), a.gain_dbi, -20.0, 30.0)?;
    if !(a.beamwidth_deg.is_finite() && a.beamwidth_deg > 0.0 && a.beamwidth_deg <= 360.0) {
        return Err(invalid(
            format!("{p}.beamwidth_deg"),
            format!("must be in (0, 360], got {}", a.beamwidth_deg),
        ));
    }
    in_range(&format!("{p}.tx_power_dbm"), a.tx_power_dbm, -10.0, 40.0)?;
    in_range(&format!("{p}.cable_loss_db"), a.cable_loss_db, 0.0, 40.0)?;
    in_range(
        &format!("{p}.tag_sensitivity_dbm"),
        a.tag_sensitivity_dbm,
        -40.0,
        0.0,
    )?;
    validate_antenna_noise(p, a, channels)?;
    positive(&format!("{p}.range_m"), a.range_m, 1000.0)?;
    in_range(&format!("{p}.range_sigma"), a.range_sigma, 0.0, 1.0)?;
    super::hardware_checks::antenna(p, a)
}

/// Checks where an antenna is mounted: a pose in the world, a robot and an offset, or a
/// recording.
fn validate_mount(s: &Scenario, p: &str, mount: &Mount) -> Check {
    match mount {
        Mount::Fixed { pose } => validate_pose(s, &format!("{p}.mount.pose"), pose, true)?,
        Mount::Robot { robot, offset } => {
            validate_robot(s, &format!("{p}.mount.robot"), robot)?;
            validate_pose(s, &format!("{p}.mount.offset"), offset, false)?;
        }
        Mount::Recorded { file, .. } => {
            if file.trim().is_empty() {
                return Err(invalid(format!("{p}.mount.file"), "must name a file"));
            }
        }
    }
    Ok(())
}

/// Checks an antenna's phase offsets and sign and its phase, RSSI and Doppler noise.
fn validate_antenna_noise(p: &str, a: &AntennaSpec, channels: usize) -> Check {
    if a.phase_offset_rad.len() > channels {
        return Err(invalid(
            format!("{p}.phase_offset_rad"),
            format!(
                "has {} entries but the region has {channels} channels",
                a.phase_offset_rad.len()
            ),
        ));
    }
    for (k, &v) in a.phase_offset_rad.iter().enumerate() {
        finite(&format!("{p}.phase_offset_rad[{k}]"), &[v])?;
    }
    if a.phase_sign != 1.0 && a.phase_sign != -1.0 {
        return Err(invalid(
            format!("{p}.phase_sign"),
            format!("must be 1 or -1, got {}", a.phase_sign),
        ));
    }
    in_range(
        &format!("{p}.phase_noise_rad"),
        a.phase_noise_rad,
        0.0,
        100.0,
    )?;
    in_range(&format!("{p}.rssi_noise"), a.eq5_noise(), 0.0, 10.0)?;
    in_range(&format!("{p}.rssi_sigma_db"), a.rssi_sigma_db, 0.0, 20.0)?;
    in_range(
        &format!("{p}.rssi_resolution_db"),
        a.rssi_resolution_db,
        0.0,
        10.0,
    )?;
    in_range(
        &format!("{p}.phase_noise_ref_dbm"),
        a.phase_noise_ref_dbm,
        -150.0,
        30.0,
    )?;
    in_range(
        &format!("{p}.doppler_sigma_hz"),
        a.doppler_sigma_hz,
        0.0,
        1000.0,
    )?;
    in_range(
        &format!("{p}.cable_delay_ns"),
        a.cable_delay_ns,
        0.0,
        10_000.0,
    )?;
    if let Some(d) = &a.extra_phase_noise {
        check_noise(d).map_err(|e| invalid(format!("{p}.extra_phase_noise"), e))?;
    }
    Ok(())
}

fn validate_pose(s: &Scenario, p: &str, pose: &Pose, in_world: bool) -> Check {
    if in_world {
        inside(s, &format!("{p}.position"), &pose.position)?;
    } else {
        finite(&format!("{p}.position"), &pose.position)?;
    }
    // In the file's degrees, as its author wrote them (rounded back to 1e-9°).
    in_range(&format!("{p}.yaw_deg"), pose.yaw_deg(), -360.0, 360.0)?;
    in_range(&format!("{p}.pitch_deg"), pose.pitch_deg(), -90.0, 90.0)
}

fn validate_robot(s: &Scenario, p: &str, r: &RobotSpec) -> Check {
    inside(s, &format!("{p}.start"), &r.start[..2])?;
    finite(&format!("{p}.start"), &r.start)?;
    if r.waypoints.is_empty() {
        return Err(invalid(
            format!("{p}.waypoints"),
            "must list at least one waypoint",
        ));
    }
    for (i, w) in r.waypoints.iter().enumerate() {
        inside(s, &format!("{p}.waypoints[{i}]"), w)?;
    }
    positive(&format!("{p}.speed"), r.speed, MAX_ROBOT_SPEED)?;
    positive(&format!("{p}.wheel_radius"), r.wheel_radius, 2.0)?;
    positive(&format!("{p}.wheel_base"), r.wheel_base, 10.0)?;
    in_range(&format!("{p}.k_r"), r.k_r, 0.0, 1.0)?;
    in_range(&format!("{p}.k_l"), r.k_l, 0.0, 1.0)?;
    positive(&format!("{p}.k_v"), r.k_v, 100.0)?;
    positive(&format!("{p}.k_omega"), r.k_omega, 100.0)?;
    positive(&format!("{p}.tolerance_m"), r.tolerance_m, 10.0)?;
    let e = &r.pose_estimate;
    non_negative(
        &format!("{p}.pose_estimate.position_sigma_m"),
        e.position_sigma_m,
    )?;
    non_negative(
        &format!("{p}.pose_estimate.heading_sigma_deg"),
        e.heading_sigma_deg,
    )?;
    if !(e.correlation_s.is_finite() && e.correlation_s > 0.0) {
        return Err(invalid(
            format!("{p}.pose_estimate.correlation_s"),
            format!("must be finite and > 0, got {}", e.correlation_s),
        ));
    }
    if let Some(v) = &r.vertical {
        let vp = format!("{p}.vertical");
        in_range(
            &format!("{vp}.min_z"),
            v.min_z,
            s.world.min[2],
            s.world.max[2],
        )?;
        in_range(
            &format!("{vp}.max_z"),
            v.max_z,
            s.world.min[2],
            s.world.max[2],
        )?;
        if v.max_z <= v.min_z {
            return Err(invalid(
                format!("{vp}.max_z"),
                format!("must be above min_z ({}), got {}", v.min_z, v.max_z),
            ));
        }
        positive(&format!("{vp}.speed"), v.speed, MAX_ROBOT_SPEED)?;
    }
    Ok(())
}

/// Reads the pose lists of recorded mounts, resolving relative paths against `dir`.
pub(super) fn load_recorded(s: &mut Scenario, dir: &std::path::Path) -> Check {
    for (r, reader) in s.readers.iter_mut().enumerate() {
        for (a, antenna) in reader.antennas.iter_mut().enumerate() {
            if let Mount::Recorded { file, poses } = &mut antenna.mount {
                // At most MAX_ANTENNAS (64) antennas: `validate` checked it before.
                let port = u16::try_from(a + 1).unwrap_or(u16::MAX);
                let p = format!("readers[{r}].antennas[{a}].mount.file");
                let path = dir.join(&*file);
                let text = std::fs::read_to_string(&path)
                    .map_err(|e| invalid(&p, format!("cannot read {}: {e}", path.display())))?;
                *poses = super::recorded::parse_poses(&text, &reader.name, port)
                    .map_err(|e| invalid(&p, format!("{}: {e}", path.display())))?;
            }
        }
    }
    Ok(())
}

/// Validates a distribution's parameters; the reason names the bad parameter.
pub fn check_noise(dist: &NoiseDist) -> Result<(), String> {
    fn finite(name: &str, v: f64) -> Result<(), String> {
        if v.is_finite() {
            Ok(())
        } else {
            Err(format!("{name} must be finite, got {v}"))
        }
    }
    fn positive(name: &str, v: f64) -> Result<(), String> {
        if v > 0.0 && v.is_finite() {
            Ok(())
        } else {
            Err(format!("{name} must be > 0, got {v}"))
        }
    }
    match *dist {
        NoiseDist::Uniform { low, high } => {
            finite("low", low)?;
            finite("high", high)?;
            if high > low {
                Ok(())
            } else {
                Err(format!("high must be > low, got low {low}, high {high}"))
            }
        }
        NoiseDist::Exponential { lambda } => positive("lambda", lambda),
        NoiseDist::Gamma { shape, scale } => {
            positive("shape", shape)?;
            positive("scale", scale)
        }
        NoiseDist::Weibull { scale, shape } => {
            positive("scale", scale)?;
            positive("shape", shape)
        }
        NoiseDist::Normal { mean, std } => {
            finite("mean", mean)?;
            if std >= 0.0 && std.is_finite() {
                Ok(())
            } else {
                Err(format!("std must be >= 0, got {std}"))
            }
        }
        NoiseDist::Lognormal { mu, sigma } => {
            finite("mu", mu)?;
            if sigma >= 0.0 && sigma.is_finite() {
                Ok(())
            } else {
                Err(format!("sigma must be >= 0, got {sigma}"))
            }
        }
        NoiseDist::ChiSquared { k } => positive("k", k),
        NoiseDist::Cauchy { median, scale } => {
            finite("median", median)?;
            positive("scale", scale)
        }
    }
}
