//! A reader's general-purpose inputs and outputs in the scenario: how many of each it has,
//! and what its inputs do over simulated time (a list of level changes, and photo-eyes that
//! pulse at a period, as an object on a conveyor breaks the beam).
//!
//! The port counts default to the reader's device's ([`super::device::DEVICES`]): the default
//! Impinj Speedway Revolution R420 has four opto-isolated inputs and four outputs (Speedway
//! Revolution Installation and Operations Guide, Octane 4.8, Appendix B "GPIO Details").

use serde::{Deserialize, Serialize};

use super::validate::{invalid, Check};

/// GPI ports of the default device (the R420's four).
pub const DEFAULT_GPIS: u16 = 4;
/// GPO ports of the default device (the R420's four).
pub const DEFAULT_GPOS: u16 = 4;
/// Most GPI or GPO ports a scenario reader may have.
pub const MAX_PORTS: u16 = 64;
/// Latest time a GPI change or photo-eye may be scheduled at (one week), ms.
pub const MAX_TIME_MS: u64 = 7 * 24 * 3_600_000;

/// A level of a GPI line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Level {
    /// Logic 1 (3–30 V on an R420's input).
    High,
    /// Logic 0.
    Low,
}

impl Level {
    /// Whether the level is high.
    pub fn is_high(self) -> bool {
        self == Level::High
    }
}

/// A reader's GPIO: port counts and what drives its inputs.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GpioSpec {
    /// Number of GPI ports (0: none; GPIOCapabilities.NumGPIs); absent: the device's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gpis: Option<u16>,
    /// Number of GPO ports (0: none; GPIOCapabilities.NumGPOs); absent: the device's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gpos: Option<u16>,
    /// Level changes of the inputs, in time order.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub gpi_timeline: Vec<GpiChange>,
    /// Inputs that pulse periodically (a photo-eye on a conveyor).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub photo_eyes: Vec<PhotoEye>,
}

impl GpioSpec {
    /// The (GPI, GPO) port counts of a reader presenting `device` (`None` or an unknown name:
    /// the default device): the scenario's where it gives them, else the device's.
    pub fn ports(&self, device: Option<&str>) -> (u16, u16) {
        let (gpis, gpos) = super::device::gpio(device);
        (self.gpis.unwrap_or(gpis), self.gpos.unwrap_or(gpos))
    }
}

/// One level change of a GPI line at a simulated time.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GpiChange {
    /// Simulated time of the change, ms.
    pub t_ms: u64,
    /// GPI port, 1-based.
    pub port: u16,
    /// The level the line moves to.
    pub state: Level,
}

/// A GPI line that goes to its active level for `width_ms` every `period_ms`, starting at
/// `start_ms`: an object breaking a photo-eye's beam on a conveyor.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhotoEye {
    /// GPI port, 1-based.
    pub port: u16,
    /// Simulated time of the first pulse's leading edge, ms.
    #[serde(default)]
    pub start_ms: u64,
    /// Time from one pulse's leading edge to the next, ms.
    pub period_ms: u64,
    /// How long each pulse lasts, ms (less than the period).
    pub width_ms: u64,
    /// Number of pulses (none: for ever).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub count: Option<u64>,
    /// The level during a pulse; the line rests at the other.
    #[serde(default = "default_active")]
    pub active: Level,
}

fn default_active() -> Level {
    Level::High
}

/// Checks a reader's GPIO (`p` is the reader's path, `device` its device): port counts,
/// ports in range, times in order, pulses shorter than their period, and one source per port.
pub(super) fn validate_gpio(p: &str, g: &GpioSpec, device: Option<&str>) -> Check {
    let (gpis, gpos) = g.ports(device);
    for (name, n) in [("gpis", gpis), ("gpos", gpos)] {
        if n > MAX_PORTS {
            return Err(invalid(
                format!("{p}.gpio.{name}"),
                format!("at most {MAX_PORTS} ports, got {n}"),
            ));
        }
    }
    let port_ok = |path: String, port: u16| -> Check {
        if port == 0 || port > gpis {
            return Err(invalid(
                path,
                format!("must be a GPI port in [1, {gpis}] (gpio.gpis), got {port}"),
            ));
        }
        Ok(())
    };
    let mut previous = 0;
    for (k, c) in g.gpi_timeline.iter().enumerate() {
        let e = format!("{p}.gpio.gpi_timeline[{k}]");
        port_ok(format!("{e}.port"), c.port)?;
        if c.t_ms > MAX_TIME_MS {
            return Err(invalid(
                format!("{e}.t_ms"),
                format!("must be at most {MAX_TIME_MS} ms, got {}", c.t_ms),
            ));
        }
        if c.t_ms < previous {
            return Err(invalid(
                format!("{e}.t_ms"),
                format!(
                    "the timeline must be in time order: {} ms comes after {previous} ms",
                    c.t_ms
                ),
            ));
        }
        previous = c.t_ms;
    }
    for (k, eye) in g.photo_eyes.iter().enumerate() {
        validate_eye(&format!("{p}.gpio.photo_eyes[{k}]"), eye, &port_ok)?;
        let shared = g.gpi_timeline.iter().any(|c| c.port == eye.port)
            || g.photo_eyes[..k].iter().any(|o| o.port == eye.port);
        if shared {
            return Err(invalid(
                format!("{p}.gpio.photo_eyes[{k}].port"),
                format!(
                    "GPI {} is already driven by the timeline or another photo-eye: \
                     one source per port",
                    eye.port
                ),
            ));
        }
    }
    Ok(())
}

/// Checks one photo-eye (`e` is its path).
fn validate_eye(e: &str, eye: &PhotoEye, port_ok: &impl Fn(String, u16) -> Check) -> Check {
    port_ok(format!("{e}.port"), eye.port)?;
    if eye.start_ms > MAX_TIME_MS {
        return Err(invalid(
            format!("{e}.start_ms"),
            format!("must be at most {MAX_TIME_MS} ms, got {}", eye.start_ms),
        ));
    }
    if eye.period_ms == 0 || eye.period_ms > MAX_TIME_MS {
        return Err(invalid(
            format!("{e}.period_ms"),
            format!("must be in [1, {MAX_TIME_MS}] ms, got {}", eye.period_ms),
        ));
    }
    if eye.width_ms == 0 || eye.width_ms >= eye.period_ms {
        return Err(invalid(
            format!("{e}.width_ms"),
            format!(
                "must be at least 1 ms and less than period_ms ({}), got {}",
                eye.period_ms, eye.width_ms
            ),
        ));
    }
    if eye.count == Some(0) {
        return Err(invalid(
            format!("{e}.count"),
            "must be at least 1 (leave it out for pulses for ever)",
        ));
    }
    Ok(())
}
