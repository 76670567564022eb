//! What the simulated reader says about itself: GET_READER_CAPABILITIES content built from the
//! scenario (antennas, regulatory region with its real channel table, power and mode tables).

use llrp::enums::CapabilitiesRequest;
use llrp::message::GetReaderCapabilitiesResponse;
use llrp::params::*;

use super::ReaderProfile;

/// Impinj's IANA private enterprise number (DeviceManufacturerName of an Impinj reader).
pub const IMPINJ_VENDOR: u32 = 25882;
/// ModelName of an Impinj Speedway R420 (what Octane-era clients expect to see).
pub const MODEL_R420: u32 = 2001002;
/// Firmware version string reported in GeneralDeviceCapabilities.
pub const FIRMWARE: &str = "5.12.0.240";
/// Lowest power of the transmit power table, hundredths of dBm (index 1).
pub const POWER_MIN_CDBM: i16 = 1000;
/// Power table step, hundredths of dBm (0.25 dB, as Impinj readers).
pub const POWER_STEP_CDBM: i16 = 25;
/// Number of entries of the transmit power table (10.00 … 32.50 dBm).
pub const POWER_LEVELS: u16 = 91;
/// Number of entries of the receive sensitivity table.
pub const SENSITIVITY_LEVELS: u16 = 42;
/// ModeIdentifiers of the C1G2 RF mode table.
pub const RF_MODES: [u32; 5] = [0, 1, 2, 3, 1000];

/// Transmit power in dBm of a power-table index (1-based); `None` outside the table.
pub fn power_dbm(index: u16) -> Option<f64> {
    (1..=POWER_LEVELS)
        .contains(&index)
        .then(|| f64::from(POWER_MIN_CDBM + (index as i16 - 1) * POWER_STEP_CDBM) / 100.0)
}

/// The power-table index closest to `dbm`.
pub fn power_index(dbm: f64) -> u16 {
    let steps = ((dbm * 100.0 - f64::from(POWER_MIN_CDBM)) / f64::from(POWER_STEP_CDBM)).round();
    (steps.clamp(0.0, f64::from(POWER_LEVELS - 1)) as u16) + 1
}

fn general(p: &ReaderProfile) -> GeneralDeviceCapabilities {
    GeneralDeviceCapabilities {
        max_number_of_antenna_supported: p.antennas,
        can_set_antenna_properties: false,
        has_utc_clock_capability: true,
        device_manufacturer_name: IMPINJ_VENDOR,
        model_name: MODEL_R420,
        reader_firmware_version: FIRMWARE.into(),
        receive_sensitivity_table_entry: (1..=SENSITIVITY_LEVELS)
            .map(|i| ReceiveSensitivityTableEntry {
                index: i,
                // Index 1 is the full sensitivity (0 dB); higher indices desensitise (Impinj).
                receive_sensitivity_value: if i == 1 { 0 } else { i as i16 + 8 },
                ..Default::default()
            })
            .collect(),
        per_antenna_receive_sensitivity_range: (1..=p.antennas)
            .map(|a| PerAntennaReceiveSensitivityRange {
                antenna_id: a,
                receive_sensitivity_index_min: 1,
                receive_sensitivity_index_max: SENSITIVITY_LEVELS,
                ..Default::default()
            })
            .collect(),
        gpio_capabilities: GpioCapabilities {
            num_gpis: 4,
            num_gpos: 4,
            ..Default::default()
        },
        per_antenna_air_protocol: (1..=p.antennas)
            .map(|a| PerAntennaAirProtocol {
                antenna_id: a,
                protocol_ids: vec![1],
                ..Default::default()
            })
            .collect(),
        ..Default::default()
    }
}

fn llrp_caps() -> LlrpCapabilities {
    LlrpCapabilities {
        can_do_rf_survey: false,
        can_report_buffer_fill_warning: true,
        supports_client_request_op_spec: false,
        can_do_tag_inventory_state_aware_singulation: true,
        supports_event_and_report_holding: true,
        max_num_priority_levels_supported: 8,
        client_request_op_spec_timeout: 0,
        max_num_ro_specs: super::MAX_ROSPECS,
        max_num_specs_per_ro_spec: 32,
        max_num_inventory_parameter_specs_per_ai_spec: 1,
        max_num_access_specs: super::MAX_ACCESS_SPECS,
        max_num_op_specs_per_access_spec: 8,
        ..Default::default()
    }
}

/// The Tari range (ns) mode `id` of the RF mode table allows.
pub fn tari_range_ns(id: u32) -> (u32, u32) {
    let mode = crate::physics::gen2::RfMode::impinj(id)
        .unwrap_or(crate::physics::gen2::RfMode::IMPINJ_MODE_2);
    let min = (mode.tari_us * 1e3).round() as u32;
    (min, if id == 1000 { 25_000 } else { min })
}

fn rf_mode(id: u32) -> C1g2UhfRfModeTableEntry {
    // The link parameters the physics runs each mode with; the forward link modulation
    // (0 PR-ASK, 2 DSB-ASK) and spectral mask (2 multi-interrogator, 3 dense) as Impinj's.
    let mode = crate::physics::gen2::RfMode::impinj(id)
        .unwrap_or(crate::physics::gen2::RfMode::IMPINJ_MODE_2);
    let m = match mode.miller {
        1 => 0,
        2 => 1,
        4 => 2,
        _ => 3,
    };
    let (fwd, mask) = if mode.miller <= 2 { (2, 2) } else { (0, 3) };
    let dr = true;
    let bdr = (mode.blf_khz * 1e3).round() as u32;
    let pie = (mode.pie * 1e3).round() as u32;
    let (tmin, tmax) = tari_range_ns(id);
    C1g2UhfRfModeTableEntry {
        mode_identifier: id,
        dr_value: dr,
        epc_hag_tc_conformance: false,
        m_value: m,
        forward_link_modulation: fwd,
        spectral_mask_indicator: mask,
        bdr_value: bdr,
        pie_value: pie,
        min_tari_value: tmin,
        max_tari_value: tmax,
        step_tari_value: 0,
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
            transmit_power_level_table_entry: (1..=POWER_LEVELS)
                .map(|i| TransmitPowerLevelTableEntry {
                    index: i,
                    transmit_power_value: POWER_MIN_CDBM + (i as i16 - 1) * POWER_STEP_CDBM,
                    ..Default::default()
                })
                .collect(),
            frequency_information: frequency_information(p),
            c1g2_uhf_rf_mode_table: vec![C1g2UhfRfModeTable {
                entries: RF_MODES.iter().map(|&m| rf_mode(m)).collect(),
                ..Default::default()
            }],
            ..Default::default()
        }),
        ..Default::default()
    }
}

fn c1g2_caps() -> C1g2LlrpCapabilities {
    C1g2LlrpCapabilities {
        can_support_block_erase: false,
        can_support_block_write: false,
        max_num_select_filters_per_query: 2,
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
        llrp_capabilities: (all || requested == R::LlrpCapabilities).then(llrp_caps),
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
                model_name: "Speedway R420 (llrp-gateway simulation)".into(),
                serial_number: p.reader_id.iter().map(|b| format!("{b:02x}")).collect(),
                software_version: FIRMWARE.into(),
                firmware_version: FIRMWARE.into(),
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

    #[test]
    fn power_table_round_trips_indices() {
        for i in 1..=POWER_LEVELS {
            let dbm = power_dbm(i).expect("index in table");
            assert_eq!(power_index(dbm), i);
        }
        assert_eq!(power_dbm(0), None);
        assert_eq!(power_dbm(POWER_LEVELS + 1), None);
        assert_eq!(power_dbm(POWER_LEVELS), Some(32.5));
    }
}
