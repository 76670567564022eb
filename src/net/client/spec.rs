//! [`InventorySpec`]: what an inventory asks the reader for, as the SET_READER_CONFIG and
//! ROSpec it sends, checked against the reader's capabilities.

use llrp::enums::{KeepaliveTriggerType, RoReportTriggerType};
use llrp::message::{GetReaderCapabilitiesResponse, SetReaderConfig};
use llrp::params::{
    AntennaConfiguration, C1g2InventoryCommand, C1g2RfControl, C1g2SingulationControl, Custom,
    ImpinjInventorySearchMode, KeepaliveSpec, RoReportSpec, RoSpec, TagReportContentSelector,
};

use super::ClientError;

/// What an inventory asks the reader for. Every Gen2 setting left `None` keeps the reader's
/// own.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct InventorySpec {
    /// ROSpecID of the inventory's ROSpec.
    pub rospec_id: u32,
    /// Antenna ports to inventory (1-based); empty: all.
    pub antennas: Vec<u16>,
    /// Enable the Impinj extensions and ask for Impinj phase, peak RSSI and Doppler.
    pub impinj: bool,
    /// A report after every N TagReportData (ROReportTrigger "upon N tags or end of ROSpec").
    pub report_every: u16,
    /// Gen2 session 0..=3 (C1G2SingulationControl).
    pub session: Option<u8>,
    /// Impinj inventory search mode (ImpinjInventorySearchMode).
    pub search_mode: Option<u16>,
    /// RF mode: a ModeIdentifier of the reader's C1G2UHFRFModeTable (C1G2RFControl ModeIndex).
    pub mode: Option<u16>,
    /// Periodic KEEPALIVE interval asked of the reader, ms; 0: none.
    pub keepalive_ms: u32,
}

impl Default for InventorySpec {
    fn default() -> Self {
        InventorySpec {
            rospec_id: 1,
            antennas: Vec::new(),
            impinj: false,
            report_every: 1,
            session: None,
            search_mode: None,
            mode: None,
            keepalive_ms: 5000,
        }
    }
}

impl InventorySpec {
    /// The SET_READER_CONFIG this inventory sends: the keepalive setting only.
    pub fn reader_config(&self) -> SetReaderConfig {
        let keepalive = if self.keepalive_ms > 0 {
            KeepaliveSpec {
                keepalive_trigger_type: KeepaliveTriggerType::Periodic,
                periodic_trigger_value: self.keepalive_ms,
                ..Default::default()
            }
        } else {
            KeepaliveSpec::default()
        };
        SetReaderConfig {
            keepalive_spec: Some(keepalive),
            ..Default::default()
        }
    }

    /// The ROSpec: started by START_ROSPEC (a Null start trigger, which every reader
    /// honours), no stop trigger, the spec's antennas, every standard report field (and the
    /// Impinj ones), and one AntennaConfiguration per antenna (`antenna_count` of them when
    /// all are inventoried) when a Gen2 setting is given.
    pub fn rospec(&self, antenna_count: u16) -> RoSpec {
        let antennas = if self.antennas.is_empty() {
            vec![0]
        } else {
            self.antennas.clone()
        };
        let mut report = RoReportSpec::new(
            RoReportTriggerType::UponNTagsOrEndOfRoSpec,
            self.report_every,
        )
        .with_content(TagReportContentSelector::all());
        if self.impinj {
            report = report.with_impinj(true, true, true);
        }
        let mut spec = RoSpec::immediate(self.rospec_id, antennas)
            .with_start(llrp::params::RoSpecStartTrigger::null())
            .with_report(report);
        if self.session.is_some() || self.mode.is_some() || self.search_mode.is_some() {
            let ids: Vec<u16> = if self.antennas.is_empty() {
                (1..=antenna_count.max(1)).collect()
            } else {
                self.antennas.clone()
            };
            let command = C1g2InventoryCommand {
                c1g2_rf_control: self.mode.map(|m| C1g2RfControl {
                    mode_index: m,
                    tari: 0,
                    ..Default::default()
                }),
                c1g2_singulation_control: self.session.map(|s| C1g2SingulationControl {
                    session: s,
                    tag_population: 32,
                    tag_transit_time: 0,
                    ..Default::default()
                }),
                custom: self
                    .search_mode
                    .map(|m| {
                        Custom::ImpinjInventorySearchMode(ImpinjInventorySearchMode {
                            inventory_search_mode: m,
                            ..Default::default()
                        })
                    })
                    .into_iter()
                    .collect(),
                ..Default::default()
            };
            spec = spec.with_antenna_configuration(
                ids.into_iter()
                    .map(|antenna_id| AntennaConfiguration {
                        antenna_id,
                        c1g2_inventory_command: vec![command.clone()],
                        ..Default::default()
                    })
                    .collect(),
            );
        }
        spec
    }

    /// Checks the spec against the reader's capabilities: antennas it has, an RF mode in its
    /// mode table. Capabilities the reader does not report are not checked.
    pub fn check(&self, caps: &GetReaderCapabilitiesResponse) -> Result<(), ClientError> {
        if let Some(g) = &caps.general_device_capabilities {
            let n = g.max_number_of_antenna_supported;
            if let Some(a) = self.antennas.iter().find(|&&a| a == 0 || a > n) {
                return Err(ClientError::Unsupported(format!(
                    "antenna {a}: the reader has antennas 1..={n}"
                )));
            }
        }
        let modes: Vec<u32> = caps
            .regulatory_capabilities
            .iter()
            .flat_map(|r| r.uhf_band_capabilities.iter())
            .flat_map(|u| u.c1g2_uhf_rf_mode_table.iter())
            .flat_map(|t| t.entries.iter().map(|e| e.mode_identifier))
            .collect();
        if let Some(m) = self.mode {
            if !modes.is_empty() && !modes.contains(&u32::from(m)) {
                let list: Vec<String> = modes.iter().map(u32::to_string).collect();
                return Err(ClientError::Unsupported(format!(
                    "RF mode {m} is not in the reader's mode table ({})",
                    list.join(", ")
                )));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use llrp::params::SpecParameter;

    #[test]
    fn the_rospec_carries_the_settings_per_antenna() {
        let spec = InventorySpec {
            antennas: vec![1, 3],
            impinj: true,
            report_every: 7,
            session: Some(1),
            search_mode: Some(2),
            mode: Some(1002),
            ..Default::default()
        };
        let ro = spec.rospec(4);
        let report = ro.ro_report_spec.as_ref().expect("a report spec");
        assert_eq!(report.n, 7);
        assert_eq!(report.custom.len(), 1, "the Impinj selector");
        let SpecParameter::AiSpec(ai) = &ro.specs[0] else {
            panic!("an AISpec first");
        };
        assert_eq!(ai.antenna_ids, [1, 3]);
        let configs = &ai.inventory_parameter_specs[0].antenna_configuration;
        assert_eq!(
            configs.iter().map(|c| c.antenna_id).collect::<Vec<_>>(),
            [1, 3]
        );
        let cmd = &configs[1].c1g2_inventory_command[0];
        assert_eq!(
            cmd.c1g2_rf_control.as_ref().map(|r| r.mode_index),
            Some(1002)
        );
        assert_eq!(
            cmd.c1g2_singulation_control.as_ref().map(|s| s.session),
            Some(1)
        );
        assert!(matches!(
            &cmd.custom[..],
            [Custom::ImpinjInventorySearchMode(m)] if m.inventory_search_mode == 2
        ));
        // All antennas: one configuration per antenna the reader has.
        let all = InventorySpec {
            session: Some(0),
            ..Default::default()
        }
        .rospec(4);
        let SpecParameter::AiSpec(ai) = &all.specs[0] else {
            panic!("an AISpec first");
        };
        assert_eq!(ai.antenna_ids, [0]);
        assert_eq!(
            ai.inventory_parameter_specs[0].antenna_configuration.len(),
            4
        );
        // No Gen2 setting: the reader's own, no configuration sent.
        let plain = InventorySpec::default().rospec(4);
        let SpecParameter::AiSpec(ai) = &plain.specs[0] else {
            panic!("an AISpec first");
        };
        assert!(ai.inventory_parameter_specs[0]
            .antenna_configuration
            .is_empty());
        assert!(plain.ro_report_spec.expect("report spec").custom.is_empty());
    }
}
