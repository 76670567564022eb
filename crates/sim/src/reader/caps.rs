//! What the simulated reader says about itself: GET_READER_CAPABILITIES content built from the
//! scenario (antennas, regulatory region with its real channel table, power and mode tables).

use llrp::enums::CapabilitiesRequest;
use llrp::message::GetReaderCapabilitiesResponse;
use llrp::params::*;

use super::device::{ModeEntry, DEFAULT};
use super::ReaderProfile;

/// Impinj's IANA private enterprise number (DeviceManufacturerName of an Impinj reader).
pub const IMPINJ_VENDOR: u32 = super::device::IMPINJ_PEN;
/// Highest index of the default device's transmit power table (its highest power).
pub const POWER_LEVELS: u16 = DEFAULT.power.last_index;
/// ModeIdentifiers of the default device's C1G2 RF mode table.
pub const RF_MODES: [u32; 10] = [0, 1, 2, 3, 4, 5, 1000, 1002, 1003, 1004];

fn general(p: &ReaderProfile) -> GeneralDeviceCapabilities {
    GeneralDeviceCapabilities {
        max_number_of_antenna_supported: p.ports,
        can_set_antenna_properties: false,
        has_utc_clock_capability: true,
        device_manufacturer_name: p.device.manufacturer,
        model_name: p.device.model,
        reader_firmware_version: p.device.firmware.into(),
        receive_sensitivity_table_entry: (1..=p.device.sensitivity_levels)
            .map(|i| ReceiveSensitivityTableEntry {
                index: i,
                // Index 1 is the full sensitivity (0 dB); higher indices desensitise (Impinj).
                receive_sensitivity_value: if i == 1 { 0 } else { i as i16 + 8 },
                ..Default::default()
            })
            .collect(),
        per_antenna_receive_sensitivity_range: (1..=p.ports)
            .map(|a| PerAntennaReceiveSensitivityRange {
                antenna_id: a,
                receive_sensitivity_index_min: 1,
                receive_sensitivity_index_max: p.device.sensitivity_levels,
                ..Default::default()
            })
            .collect(),
        gpio_capabilities: GpioCapabilities {
            num_gpis: p.gpis,
            num_gpos: p.gpos,
            ..Default::default()
        },
        per_antenna_air_protocol: (1..=p.ports)
            .map(|a| PerAntennaAirProtocol {
                antenna_id: a,
                protocol_ids: vec![1],
                ..Default::default()
            })
            .collect(),
        ..Default::default()
    }
}

fn llrp_caps(p: &ReaderProfile) -> LlrpCapabilities {
    let d = p.device;
    LlrpCapabilities {
        can_do_rf_survey: false,
        can_report_buffer_fill_warning: true,
        supports_client_request_op_spec: false,
        can_do_tag_inventory_state_aware_singulation: true,
        supports_event_and_report_holding: true,
        max_num_priority_levels_supported: d.max_priority_levels,
        client_request_op_spec_timeout: 0,
        max_num_ro_specs: d.max_rospecs,
        max_num_specs_per_ro_spec: d.max_specs_per_rospec,
        max_num_inventory_parameter_specs_per_ai_spec: 1,
        max_num_access_specs: d.max_access_specs,
        max_num_op_specs_per_access_spec: d.max_op_specs_per_access_spec,
        ..Default::default()
    }
}

fn rf_mode(m: &ModeEntry) -> C1g2UhfRfModeTableEntry {
    C1g2UhfRfModeTableEntry {
        mode_identifier: m.id,
        dr_value: true,
        epc_hag_tc_conformance: m.conformance,
        m_value: m.m_value,
        forward_link_modulation: m.modulation,
        spectral_mask_indicator: m.mask,
        bdr_value: m.bdr,
        pie_value: m.pie,
        min_tari_value: m.tari_ns.0,
        max_tari_value: m.tari_ns.1,
        step_tari_value: m.step_tari_ns,
        ..Default::default()
    }
}

/// The hop table or fixed frequency table the reader advertises (and reports channels into).
pub fn frequency_information(p: &ReaderProfile) -> FrequencyInformation {
    if p.hopping {
        FrequencyInformation {
            hopping: true,
            frequency_hop_table: vec![FrequencyHopTable {
                hop_table_id: 1,
                frequencies: p.frequencies_khz.clone(),
                ..Default::default()
            }],
            ..Default::default()
        }
    } else {
        FrequencyInformation {
            hopping: false,
            fixed_frequency_table: Some(FixedFrequencyTable {
                frequencies: p.frequencies_khz.clone(),
                ..Default::default()
            }),
            ..Default::default()
        }
    }
}

fn regulatory(p: &ReaderProfile) -> RegulatoryCapabilities {
    RegulatoryCapabilities {
        country_code: p.country_code,
        communications_standard: p.communications_standard,
        uhf_band_capabilities: Some(UhfBandCapabilities {
            transmit_power_level_table_entry: p
                .device
                .power
                .indices()
                .filter_map(|i| {
                    Some(TransmitPowerLevelTableEntry {
                        index: i,
                        transmit_power_value: p.device.power.cdbm(i)?,
                        ..Default::default()
                    })
                })
                .collect(),
            frequency_information: frequency_information(p),
            c1g2_uhf_rf_mode_table: vec![C1g2UhfRfModeTable {
                entries: p.device.modes.iter().map(rf_mode).collect(),
                ..Default::default()
            }],
            ..Default::default()
        }),
        ..Default::default()
    }
}

/// MaxNumSelectFiltersPerQuery: C1G2Filters an inventory command may carry (an Impinj
/// reader's two: sllurp's `llrp_proto.py` notes that more give an overflow error there).
pub const MAX_SELECT_FILTERS: u16 = 2;

fn c1g2_caps() -> C1g2LlrpCapabilities {
    C1g2LlrpCapabilities {
        // Both are supported (`access::ops`).
        can_support_block_erase: true,
        can_support_block_write: true,
        max_num_select_filters_per_query: MAX_SELECT_FILTERS,
        ..Default::default()
    }
}

/// GET_READER_CAPABILITIES_RESPONSE body for RequestedData `requested` (0 all, 1 general,
/// 2 LLRP, 3 regulatory, 4 air protocol); `None` for an unknown value.
pub fn capabilities(
    p: &ReaderProfile,
    requested: CapabilitiesRequest,
) -> Option<GetReaderCapabilitiesResponse> {
    use CapabilitiesRequest as R;
    let all = requested == R::All;
    if !requested.is_known() {
        return None;
    }
    Some(GetReaderCapabilitiesResponse {
        llrp_status: LlrpStatus::success(),
        general_device_capabilities: (all || requested == R::GeneralDeviceCapabilities)
            .then(|| general(p)),
        llrp_capabilities: (all || requested == R::LlrpCapabilities).then(|| llrp_caps(p)),
        regulatory_capabilities: (all || requested == R::RegulatoryCapabilities)
            .then(|| regulatory(p)),
        c1g2_llrp_capabilities: (all || requested == R::AirProtocolLlrpCapabilities)
            .then(c1g2_caps),
        ..Default::default()
    })
}

/// Impinj capability parameters for ImpinjRequestedData `requested` (1000 all, 1001 detailed
/// version, 1002 frequency capabilities).
pub fn impinj_capabilities(p: &ReaderProfile, requested: u32) -> Vec<Custom> {
    let mut out = Vec::new();
    if matches!(requested, 1000 | 1001) {
        out.push(Custom::ImpinjDetailedVersion(Box::new(
            ImpinjDetailedVersion {
                model_name: format!("{} (llrp-gateway simulation)", p.device.display_name),
                serial_number: p.reader_id.iter().map(|b| format!("{b:02x}")).collect(),
                software_version: p.device.firmware.into(),
                firmware_version: p.device.firmware.into(),
                fpga_version: "0.0.0.0".into(),
                pcba_version: "0.0.0.0".into(),
                ..Default::default()
            },
        )));
    }
    if matches!(requested, 1000 | 1002) {
        let mut all = p.frequencies_khz.clone();
        all.sort_unstable();
        out.push(Custom::ImpinjFrequencyCapabilities(
            ImpinjFrequencyCapabilities {
                frequency_list: all,
                ..Default::default()
            },
        ));
    }
    out
}

/// Impinj configuration parameters for ImpinjRequestedData `requested` (2000 all, 2001
/// sub-regulatory region, 2004 reader temperature).
pub fn impinj_configuration(p: &ReaderProfile, requested: u32) -> Vec<Custom> {
    let mut out = Vec::new();
    if matches!(requested, 2000 | 2001) {
        // Impinj region codes: 0 FCC Part 15.247, 7 ETSI EN 302 208 v1.2.1.
        let region = if p.communications_standard == 2 { 7 } else { 0 };
        out.push(Custom::ImpinjSubRegulatoryRegion(
            ImpinjSubRegulatoryRegion {
                regulatory_region: region,
                ..Default::default()
            },
        ));
    }
    if matches!(requested, 2000 | 2004) {
        out.push(Custom::ImpinjReaderTemperature(ImpinjReaderTemperature {
            temperature: 38,
            ..Default::default()
        }));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reader::device::IMPINJ_R420;

    /// The default device's RF modes that the simulator advertised before devices existed
    /// keep their entries (the physics' Impinj links, advertised as Impinj readers do); the
    /// others (4, 5, 1002–1004) run as mode 2 and as AutoSet.
    #[test]
    fn the_default_mode_table_is_the_one_advertised_before() {
        let ids: Vec<u32> = IMPINJ_R420.modes.iter().map(|m| m.id).collect();
        assert_eq!(ids, RF_MODES);
        for (m, &id) in IMPINJ_R420.modes.iter().zip(RF_MODES.iter()) {
            let Some(link) = crate::physics::gen2::RfMode::impinj(id) else {
                let like = if id < 1000 { 2 } else { 1000 };
                let same = IMPINJ_R420.mode(like).expect("mode 2 and 1000 are there");
                assert_eq!(m.link, same.link, "{id}");
                continue;
            };
            let miller = link.miller;
            let tari = (link.tari_us * 1e3).round() as u32;
            let want = (
                id,
                [1, 2, 4, 8]
                    .iter()
                    .position(|&x| x == miller)
                    .map(|p| p as u8),
                if miller <= 2 { (2, 2) } else { (0, 3) },
                (link.blf_khz * 1e3).round() as u32,
                (link.pie * 1e3).round() as u32,
                (tari, if id == 1000 { 25_000 } else { tari }),
            );
            let got = (
                m.id,
                Some(m.m_value),
                (m.modulation, m.mask),
                m.bdr,
                m.pie,
                m.tari_ns,
            );
            assert_eq!(got, want);
            assert_eq!(m.link, link);
        }
        assert_eq!(IMPINJ_R420.modes.len(), RF_MODES.len());
    }
}
