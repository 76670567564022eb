//! Faults injected into a simulated reader: what an integrator's software must cope with (a
//! cable pulled, the network dropping, a reboot, a slow or silent reader, a full report
//! buffer), on a timeline of simulated time in the scenario (a reader's `faults`) or at once
//! through the HTTP API. The same JSON object names a fault in both: `{"fault":
//! "antenna_disconnect", "antenna": 2}`.

use serde::{Deserialize, Serialize};

use super::validate::{invalid, Check};

/// Boot time of a reboot unless the fault says otherwise, wall ms (a real reader takes far
/// longer; a test or a demonstration should not wait that long).
pub const DEFAULT_BOOT_MS: u64 = 3_000;
/// Duration of a fault that lasts unless it says otherwise, wall ms.
pub const DEFAULT_FOR_MS: u64 = 10_000;
/// Longest boot, delay or fault duration, wall ms (one hour).
pub const MAX_DURATION_MS: u64 = 3_600_000;
/// Most keepalives one fault may lose.
pub const MAX_KEEPALIVES: u32 = 1_000;
/// Longest ReaderExceptionEvent message, bytes (an LLRP UTF-8 string has a 16-bit length).
pub const MAX_MESSAGE_BYTES: usize = 1_024;

/// One fault and its parameters.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "fault", rename_all = "snake_case", deny_unknown_fields)]
pub enum Fault {
    /// The cable of antenna port `antenna` is pulled: AntennaEvent (disconnected), no reads
    /// on that port, AntennaProperties.AntennaConnected false.
    AntennaDisconnect {
        /// Antenna port, 1-based.
        antenna: u16,
    },
    /// The cable of antenna port `antenna` is plugged back: AntennaEvent (connected), reads
    /// again.
    AntennaReconnect {
        /// Antenna port, 1-based.
        antenna: u16,
    },
    /// The reader drops the client's connection: a TCP reset, no ConnectionCloseEvent.
    DropConnection,
    /// The reader reboots: the connection closes, nothing listens for `boot_ms` of wall
    /// time, then the reader is back with its state lost (or kept).
    Reboot {
        /// Keep ROSpecs, AccessSpecs and configuration over the reboot (none: the
        /// scenario reader's `persist_state`).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        keep_state: Option<bool>,
        /// How long the reader is unreachable, wall ms.
        #[serde(default = "default_boot_ms")]
        boot_ms: u64,
    },
    /// The reader answers requests `ms` late (it takes each request that late, in order) for
    /// `for_ms` of wall time.
    DelayResponses {
        /// The delay of each request, wall ms.
        ms: u64,
        /// How long requests are delayed, wall ms.
        #[serde(default = "default_for_ms")]
        for_ms: u64,
    },
    /// The reader sends none of its next `count` KEEPALIVEs.
    LoseKeepalives {
        /// How many KEEPALIVEs are not sent.
        count: u32,
    },
    /// The report buffer is full for `for_ms` of wall time, as if the client had stopped
    /// reading: ReportBufferLevelWarningEvent, ReportBufferOverflowErrorEvent, reports lost.
    FillReportBuffer {
        /// How long the buffer stays full, wall ms.
        #[serde(default = "default_for_ms")]
        for_ms: u64,
    },
    /// The reader reports an unexpected error: a ReaderExceptionEvent with `message`.
    ReaderException {
        /// The event's Message.
        message: String,
    },
}

fn default_boot_ms() -> u64 {
    DEFAULT_BOOT_MS
}

fn default_for_ms() -> u64 {
    DEFAULT_FOR_MS
}

impl Fault {
    /// Every fault's name, as `fault` spells it.
    pub const NAMES: [&'static str; 8] = [
        "antenna_disconnect",
        "antenna_reconnect",
        "drop_connection",
        "reboot",
        "delay_responses",
        "lose_keepalives",
        "fill_report_buffer",
        "reader_exception",
    ];

    /// The fault's name, as `fault` spells it.
    pub fn name(&self) -> &'static str {
        let k = match self {
            Fault::AntennaDisconnect { .. } => 0,
            Fault::AntennaReconnect { .. } => 1,
            Fault::DropConnection => 2,
            Fault::Reboot { .. } => 3,
            Fault::DelayResponses { .. } => 4,
            Fault::LoseKeepalives { .. } => 5,
            Fault::FillReportBuffer { .. } => 6,
            Fault::ReaderException { .. } => 7,
        };
        Fault::NAMES[k]
    }

    /// Checks the fault's parameters for a reader of `antennas` antenna ports: the field that
    /// is wrong and why.
    pub fn check(&self, antennas: usize) -> Result<(), (&'static str, String)> {
        let duration = |field: &'static str, ms: u64, min: u64| {
            if ms < min || ms > MAX_DURATION_MS {
                return Err((
                    field,
                    format!("must be in [{min}, {MAX_DURATION_MS}] ms, got {ms}"),
                ));
            }
            Ok(())
        };
        match self {
            Fault::AntennaDisconnect { antenna } | Fault::AntennaReconnect { antenna } => {
                if *antenna == 0 || usize::from(*antenna) > antennas {
                    return Err((
                        "antenna",
                        format!("must be an antenna port in [1, {antennas}], got {antenna}"),
                    ));
                }
                Ok(())
            }
            Fault::DropConnection => Ok(()),
            Fault::Reboot { boot_ms, .. } => duration("boot_ms", *boot_ms, 0),
            Fault::DelayResponses { ms, for_ms } => {
                duration("ms", *ms, 1)?;
                duration("for_ms", *for_ms, 1)
            }
            Fault::LoseKeepalives { count } => {
                if *count == 0 || *count > MAX_KEEPALIVES {
                    return Err((
                        "count",
                        format!("must be in [1, {MAX_KEEPALIVES}], got {count}"),
                    ));
                }
                Ok(())
            }
            Fault::FillReportBuffer { for_ms } => duration("for_ms", *for_ms, 1),
            Fault::ReaderException { message } => {
                if message.len() > MAX_MESSAGE_BYTES {
                    return Err((
                        "message",
                        format!("at most {MAX_MESSAGE_BYTES} bytes, got {}", message.len()),
                    ));
                }
                Ok(())
            }
        }
    }
}

/// A fault at a simulated time: `{"t_ms": 5000, "fault": "reboot"}`.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ScheduledFault {
    /// Simulated time of the fault, ms.
    pub t_ms: u64,
    /// The fault.
    #[serde(flatten)]
    pub fault: Fault,
}

/// Checks a reader's fault timeline (`p` is the reader's path): each fault's parameters for a
/// reader of `antennas` ports, times in order and at most [`super::gpio::MAX_TIME_MS`].
pub(super) fn validate_faults(p: &str, faults: &[ScheduledFault], antennas: usize) -> Check {
    let mut previous = 0;
    for (k, f) in faults.iter().enumerate() {
        let e = format!("{p}.faults[{k}]");
        if f.t_ms > super::gpio::MAX_TIME_MS {
            return Err(invalid(
                format!("{e}.t_ms"),
                format!(
                    "must be at most {} ms, got {}",
                    super::gpio::MAX_TIME_MS,
                    f.t_ms
                ),
            ));
        }
        if f.t_ms < previous {
            return Err(invalid(
                format!("{e}.t_ms"),
                format!(
                    "the timeline must be in time order: {} ms comes after {previous} ms",
                    f.t_ms
                ),
            ));
        }
        previous = f.t_ms;
        f.fault
            .check(antennas)
            .map_err(|(field, why)| invalid(format!("{e}.{field}"), why))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::Scenario;

    /// A valid scenario of one two-antenna reader, as JSON.
    fn base() -> serde_json::Value {
        serde_json::json!({
            "name": "t",
            "seed": 1,
            "world": { "min": [0, 0, 0], "max": [10, 10, 3] },
            "tags": [ { "epc": "300833B2DDD9014000000001", "position": [5, 5, 1] } ],
            "readers": [ {
                "name": "r",
                "region": "fcc",
                "antennas": [
                    { "mount": { "type": "fixed", "pose": { "position": [1, 5, 1] } } },
                    { "mount": { "type": "fixed", "pose": { "position": [9, 5, 1] } } }
                ]
            } ]
        })
    }

    fn error_of(v: &serde_json::Value) -> String {
        match Scenario::from_json(&v.to_string()) {
            Ok(_) => panic!("scenario should have been refused"),
            Err(e) => e.to_string(),
        }
    }
    #[test]
    fn a_fault_timeline_reads_each_fault_with_its_defaults() {
        let mut v = base();
        v["readers"][0]["persist_state"] = true.into();
        v["readers"][0]["faults"] = serde_json::json!([
            { "t_ms": 1000, "fault": "antenna_disconnect", "antenna": 1 },
            { "t_ms": 2000, "fault": "reboot" },
            { "t_ms": 3000, "fault": "delay_responses", "ms": 1500 },
            { "t_ms": 3000, "fault": "reader_exception", "message": "RF fault" }
        ]);
        let s = Scenario::from_json(&v.to_string()).expect("a fault timeline is valid");
        let r = &s.readers[0];
        assert!(r.persist_state);
        let got: Vec<_> = r.faults.iter().map(|f| (f.t_ms, f.fault.clone())).collect();
        assert_eq!(
            got,
            [
                (1000, Fault::AntennaDisconnect { antenna: 1 }),
                (
                    2000,
                    Fault::Reboot {
                        keep_state: None,
                        boot_ms: DEFAULT_BOOT_MS
                    }
                ),
                (
                    3000,
                    Fault::DelayResponses {
                        ms: 1500,
                        for_ms: DEFAULT_FOR_MS
                    }
                ),
                (
                    3000,
                    Fault::ReaderException {
                        message: "RF fault".into()
                    }
                ),
            ]
        );
        assert_eq!(s.readers[0].antennas.len(), 2);
    }

    #[test]
    fn a_fault_timelines_errors_name_the_field() {
        let antennas = 2;
        let cases = [
            (
                serde_json::json!([ { "t_ms": 1, "fault": "antenna_disconnect", "antenna": 0 } ]),
                format!("readers[0].faults[0].antenna: must be an antenna port in [1, {antennas}]"),
            ),
            (
                serde_json::json!([ { "t_ms": 9, "fault": "drop_connection" },
                                    { "t_ms": 5, "fault": "drop_connection" } ]),
                "readers[0].faults[1].t_ms: the timeline must be in time order".to_string(),
            ),
            (
                serde_json::json!([ { "t_ms": 1, "fault": "delay_responses", "ms": 0 } ]),
                "readers[0].faults[0].ms: must be in [1, 3600000] ms, got 0".to_string(),
            ),
            (
                serde_json::json!([ { "t_ms": 1, "fault": "lose_keepalives", "count": 0 } ]),
                "readers[0].faults[0].count: must be in [1, 1000]".to_string(),
            ),
        ];
        for (faults, expected) in cases {
            let mut v = base();
            v["readers"][0]["faults"] = faults;
            let e = error_of(&v);
            assert!(e.starts_with(&expected), "{e}");
        }
        for (bad, expected) in [
            (
                serde_json::json!([ { "t_ms": 1, "fault": "meltdown" } ]),
                "unknown variant `meltdown`",
            ),
            (
                serde_json::json!([ { "t_ms": 1, "fault": "reboot", "boot_s": 3 } ]),
                "unknown field `boot_s`",
            ),
            (
                serde_json::json!([ { "t_ms": 1, "fault": "lose_keepalives" } ]),
                "missing field `count`",
            ),
        ] {
            let mut v = base();
            v["readers"][0]["faults"] = bad;
            let e = error_of(&v);
            assert!(e.contains(expected) && e.contains("faults[0]"), "{e}");
        }
    }
}
