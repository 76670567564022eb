//! Constructors for the specs a client sends most: ROSpecs with their triggers and report
//! specs, as clients such as sllurp build them. Shared by the LLRP client, the tests and the
//! benchmarks instead of repeated struct literals.
//!
//! ```
//! use llrp::enums::RoReportTriggerType;
//! use llrp::params::{AiSpecStopTrigger, RoReportSpec, RoSpec, TagReportContentSelector};
//!
//! // sllurp's `inventory -a 0 -n 1 --impinj-reports`: all antennas, stop after one tag,
//! // report each read with every field and Impinj's phase, RSSI and Doppler.
//! let spec = RoSpec::immediate(1, vec![0])
//!     .with_ai_stop(AiSpecStopTrigger::n_tags(1, 0))
//!     .with_report(
//!         RoReportSpec::new(RoReportTriggerType::UponNTagsOrEndOfAiSpec, 1)
//!             .with_content(TagReportContentSelector::all())
//!             .with_impinj(true, true, true),
//!     );
//! assert_eq!(spec.ro_spec_id, 1);
//! ```

use crate::enums::*;
use crate::params::*;

impl RoSpec {
    /// ROSpec `id`: Immediate start, no stop trigger, one AISpec over `antennas` (0 = all)
    /// with no stop trigger and one Gen2 InventoryParameterSpec (ID 1), no report spec (the
    /// reader's default applies).
    pub fn immediate(id: u32, antennas: Vec<u16>) -> RoSpec {
        RoSpec {
            ro_spec_id: id,
            ro_boundary_spec: RoBoundarySpec {
                ro_spec_start_trigger: RoSpecStartTrigger {
                    ro_spec_start_trigger_type: RoSpecStartTriggerType::Immediate,
                    ..Default::default()
                },
                ..Default::default()
            },
            specs: vec![SpecParameter::AiSpec(AiSpec {
                antenna_ids: antennas,
                inventory_parameter_specs: vec![InventoryParameterSpec::gen2(1)],
                ..Default::default()
            })],
            ..Default::default()
        }
    }

    /// The same spec with this start trigger.
    pub fn with_start(mut self, start: RoSpecStartTrigger) -> RoSpec {
        self.ro_boundary_spec.ro_spec_start_trigger = start;
        self
    }

    /// The same spec with this stop trigger.
    pub fn with_stop(mut self, stop: RoSpecStopTrigger) -> RoSpec {
        self.ro_boundary_spec.ro_spec_stop_trigger = stop;
        self
    }

    /// The same spec with this stop trigger on every AISpec.
    pub fn with_ai_stop(mut self, stop: AiSpecStopTrigger) -> RoSpec {
        for s in &mut self.specs {
            if let SpecParameter::AiSpec(ai) = s {
                ai.ai_spec_stop_trigger = stop.clone();
            }
        }
        self
    }

    /// The same spec with this report spec.
    pub fn with_report(mut self, report: RoReportSpec) -> RoSpec {
        self.ro_report_spec = Some(report);
        self
    }

    /// The same spec with this priority (0 highest, 7 lowest).
    pub fn with_priority(mut self, priority: u8) -> RoSpec {
        self.priority = priority;
        self
    }

    /// The same spec with these antenna configurations in its first AISpec's inventory.
    pub fn with_antenna_configuration(mut self, config: Vec<AntennaConfiguration>) -> RoSpec {
        if let Some(SpecParameter::AiSpec(ai)) = self.specs.first_mut() {
            if let Some(ips) = ai.inventory_parameter_specs.first_mut() {
                ips.antenna_configuration = config;
            }
        }
        self
    }
}

impl InventoryParameterSpec {
    /// An EPCglobal Class 1 Gen 2 inventory with ID `id` and no antenna configuration.
    pub fn gen2(id: u16) -> InventoryParameterSpec {
        InventoryParameterSpec {
            inventory_parameter_spec_id: id,
            protocol_id: AirProtocol::EpcGlobalClass1Gen2,
            ..Default::default()
        }
    }
}

impl RoSpecStartTrigger {
    /// Starts `offset_ms` after it is enabled, then every `period_ms`.
    pub fn periodic(offset_ms: u32, period_ms: u32) -> RoSpecStartTrigger {
        RoSpecStartTrigger {
            ro_spec_start_trigger_type: RoSpecStartTriggerType::Periodic,
            periodic_trigger_value: Some(PeriodicTriggerValue {
                offset: offset_ms,
                period: period_ms,
                ..Default::default()
            }),
            ..Default::default()
        }
    }

    /// Starts only on START_ROSPEC.
    pub fn null() -> RoSpecStartTrigger {
        RoSpecStartTrigger::default()
    }

    /// Starts when GPI `port` moves to `event` (true: low to high).
    pub fn gpi(port: u16, event: bool) -> RoSpecStartTrigger {
        RoSpecStartTrigger {
            ro_spec_start_trigger_type: RoSpecStartTriggerType::Gpi,
            gpi_trigger_value: Some(GpiTriggerValue::new(port, event, 0)),
            ..Default::default()
        }
    }
}

impl GpiTriggerValue {
    /// GPI `port` moving to `event` (true: low to high), with a timeout of `timeout_ms` (0:
    /// none; ignored in a start trigger).
    pub fn new(port: u16, event: bool, timeout_ms: u32) -> GpiTriggerValue {
        GpiTriggerValue {
            gpi_port_num: port,
            gpi_event: event,
            timeout: timeout_ms,
            ..Default::default()
        }
    }
}

impl RoSpecStopTrigger {
    /// Ends when its AISpecs are done, or on STOP_ROSPEC.
    pub fn null() -> RoSpecStopTrigger {
        RoSpecStopTrigger::default()
    }

    /// Ends `ms` after it started.
    pub fn duration(ms: u32) -> RoSpecStopTrigger {
        RoSpecStopTrigger {
            ro_spec_stop_trigger_type: RoSpecStopTriggerType::Duration,
            duration_trigger_value: ms,
            ..Default::default()
        }
    }

    /// Ends when GPI `port` moves to `event` (true: low to high), or `timeout_ms` after it
    /// started (0: no timeout).
    pub fn gpi(port: u16, event: bool, timeout_ms: u32) -> RoSpecStopTrigger {
        RoSpecStopTrigger {
            ro_spec_stop_trigger_type: RoSpecStopTriggerType::GpiWithTimeout,
            gpi_trigger_value: Some(GpiTriggerValue::new(port, event, timeout_ms)),
            ..Default::default()
        }
    }
}

impl AiSpecStopTrigger {
    /// Ends only with its ROSpec.
    pub fn null() -> AiSpecStopTrigger {
        AiSpecStopTrigger::default()
    }

    /// Ends `ms` after it started.
    pub fn duration(ms: u32) -> AiSpecStopTrigger {
        AiSpecStopTrigger {
            ai_spec_stop_trigger_type: AiSpecStopTriggerType::Duration,
            duration_trigger: ms,
            ..Default::default()
        }
    }

    /// Ends when GPI `port` moves to `event` (true: low to high), or `timeout_ms` after it
    /// started (0: no timeout).
    pub fn gpi(port: u16, event: bool, timeout_ms: u32) -> AiSpecStopTrigger {
        AiSpecStopTrigger {
            ai_spec_stop_trigger_type: AiSpecStopTriggerType::GpiWithTimeout,
            gpi_trigger_value: Some(GpiTriggerValue::new(port, event, timeout_ms)),
            ..Default::default()
        }
    }

    /// Ends on this tag observation trigger.
    pub fn observation(trigger: TagObservationTrigger) -> AiSpecStopTrigger {
        AiSpecStopTrigger {
            ai_spec_stop_trigger_type: AiSpecStopTriggerType::TagObservation,
            tag_observation_trigger: Some(trigger),
            ..Default::default()
        }
    }

    /// Ends once `n` tags have been seen, or after `timeout_ms` (0: no timeout).
    pub fn n_tags(n: u16, timeout_ms: u32) -> AiSpecStopTrigger {
        Self::observation(TagObservationTrigger {
            trigger_type: TagObservationTriggerType::UponSeeingNTagsOrTimeout,
            number_of_tags: n,
            timeout: timeout_ms,
            ..Default::default()
        })
    }
}

impl RoReportSpec {
    /// Reports with `trigger` and N = `n`, with an empty content selector (the EPC only).
    pub fn new(trigger: RoReportTriggerType, n: u16) -> RoReportSpec {
        RoReportSpec {
            ro_report_trigger: trigger,
            n,
            ..Default::default()
        }
    }

    /// The same spec with this content selector.
    pub fn with_content(mut self, selector: TagReportContentSelector) -> RoReportSpec {
        self.tag_report_content_selector = selector;
        self
    }

    /// The same spec with an ImpinjTagReportContentSelector for the Impinj RF phase angle,
    /// peak RSSI (hundredths of dBm) and RF Doppler frequency, each on or off.
    pub fn with_impinj(mut self, phase: bool, peak_rssi: bool, doppler: bool) -> RoReportSpec {
        let mode = u16::from;
        self.custom
            .retain(|c| !matches!(c, Custom::ImpinjTagReportContentSelector(_)));
        self.custom
            .push(Custom::ImpinjTagReportContentSelector(Box::new(
                ImpinjTagReportContentSelector {
                    enable_rf_phase_angle: Some(ImpinjEnableRfPhaseAngle {
                        rf_phase_angle_mode: mode(phase),
                        ..Default::default()
                    }),
                    enable_peak_rssi: Some(ImpinjEnablePeakRssi {
                        peak_rssi_mode: mode(peak_rssi),
                        ..Default::default()
                    }),
                    enable_rf_doppler_frequency: Some(ImpinjEnableRfDopplerFrequency {
                        rf_doppler_frequency_mode: mode(doppler),
                        ..Default::default()
                    }),
                    ..Default::default()
                },
            )));
        self
    }
}

impl TagReportContentSelector {
    /// Every standard field on (ROSpecID, SpecIndex, InventoryParameterSpecID, AntennaID,
    /// ChannelIndex, PeakRSSI, first and last seen, TagSeenCount, AccessSpecID).
    pub fn all() -> TagReportContentSelector {
        TagReportContentSelector {
            enable_ro_spec_id: true,
            enable_spec_index: true,
            enable_inventory_parameter_spec_id: true,
            enable_antenna_id: true,
            enable_channel_index: true,
            enable_peak_rssi: true,
            enable_first_seen_timestamp: true,
            enable_last_seen_timestamp: true,
            enable_tag_seen_count: true,
            enable_access_spec_id: true,
            ..Default::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::message::AddRospec;
    use crate::Message;

    #[test]
    fn a_built_rospec_encodes_and_decodes_to_itself() {
        let spec = RoSpec::immediate(3, vec![1, 2])
            .with_stop(RoSpecStopTrigger::duration(5000))
            .with_ai_stop(AiSpecStopTrigger::n_tags(4, 1000))
            .with_priority(2)
            .with_report(
                RoReportSpec::new(RoReportTriggerType::UponNTagsOrEndOfRoSpec, 10)
                    .with_content(TagReportContentSelector::all())
                    .with_impinj(true, false, true)
                    .with_impinj(true, true, true),
            );
        let m = Message::new(
            1,
            AddRospec {
                ro_spec: spec.clone(),
                ..Default::default()
            },
        );
        let back = Message::decode(&m.to_bytes()).expect("a valid ADD_ROSPEC");
        assert_eq!(back, m);
        let report = spec.ro_report_spec.expect("a report spec");
        assert_eq!(
            report.custom.len(),
            1,
            "one Impinj selector, the last one given"
        );
    }
}
