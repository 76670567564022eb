//! What a reader can do: GET_READER_CAPABILITIES_RESPONSE content.

use super::*;

llrp_struct! {
    /// Antennas, clock, manufacturer, model, firmware and receive sensitivity table.
    pub struct GeneralDeviceCapabilities: tlv [137] "GeneralDeviceCapabilities" {
        max_number_of_antenna_supported "MaxNumberOfAntennaSupported": u16,
        can_set_antenna_properties "CanSetAntennaProperties": bool = 1 bits,
        has_utc_clock_capability "HasUTCClockCapability": bool = 1 bits; pad 14,
        device_manufacturer_name "DeviceManufacturerName": u32,
        model_name "ModelName": u32,
        reader_firmware_version "ReaderFirmwareVersion": String,
    } {
        receive_sensitivity_table_entry: many1 ReceiveSensitivityTableEntry,
        per_antenna_receive_sensitivity_range: many PerAntennaReceiveSensitivityRange,
        gpio_capabilities: one GpioCapabilities,
        per_antenna_air_protocol: many1 PerAntennaAirProtocol,
    }
}

llrp_struct! {
    /// One receive sensitivity level (dB relative to maximum).
    pub struct ReceiveSensitivityTableEntry: tlv [139] "ReceiveSensitivityTableEntry" {
        index "Index": u16,
        receive_sensitivity_value "ReceiveSensitivityValue": i16,
    } {}
}

llrp_struct! {
    /// Air protocols an antenna supports (1 = EPC Class 1 Gen 2).
    pub struct PerAntennaAirProtocol: tlv [140] "PerAntennaAirProtocol" {
        antenna_id "AntennaID": u16,
        protocol_ids "ProtocolIDs": Vec<u8>,
    } {}
}

llrp_struct! {
    /// Number of GPI and GPO ports.
    pub struct GpioCapabilities: tlv [141] "GPIOCapabilities" {
        num_gpis "NumGPIs": u16,
        num_gpos "NumGPOs": u16,
    } {}
}

llrp_struct! {
    /// Receive sensitivity indices valid for one antenna.
    pub struct PerAntennaReceiveSensitivityRange: tlv [149] "PerAntennaReceiveSensitivityRange" {
        antenna_id "AntennaID": u16,
        receive_sensitivity_index_min "ReceiveSensitivityIndexMin": u16,
        receive_sensitivity_index_max "ReceiveSensitivityIndexMax": u16,
    } {}
}

llrp_struct! {
    /// LLRP features and limits (ROSpecs, priorities, AccessSpecs).
    pub struct LlrpCapabilities: tlv [142] "LLRPCapabilities" {
        can_do_rf_survey "CanDoRFSurvey": bool = 1 bits,
        can_report_buffer_fill_warning "CanReportBufferFillWarning": bool = 1 bits,
        supports_client_request_op_spec "SupportsClientRequestOpSpec": bool = 1 bits,
        can_do_tag_inventory_state_aware_singulation "CanDoTagInventoryStateAwareSingulation": bool = 1 bits,
        supports_event_and_report_holding "SupportsEventAndReportHolding": bool = 1 bits; pad 3,
        max_num_priority_levels_supported "MaxNumPriorityLevelsSupported": u8,
        client_request_op_spec_timeout "ClientRequestOpSpecTimeout": u16,
        max_num_ro_specs "MaxNumROSpecs": u32,
        max_num_specs_per_ro_spec "MaxNumSpecsPerROSpec": u32,
        max_num_inventory_parameter_specs_per_ai_spec "MaxNumInventoryParameterSpecsPerAISpec": u32,
        max_num_access_specs "MaxNumAccessSpecs": u32,
        max_num_op_specs_per_access_spec "MaxNumOpSpecsPerAccessSpec": u32,
    } {}
}

llrp_struct! {
    /// Country, regulatory standard and the UHF band the reader uses.
    pub struct RegulatoryCapabilities: tlv [143] "RegulatoryCapabilities" {
        country_code "CountryCode": u16,
        communications_standard "CommunicationsStandard": u16,
    } {
        uhf_band_capabilities: opt UhfBandCapabilities,
        custom: many Custom,
    }
}

llrp_struct! {
    /// Transmit power table, frequencies and Gen2 RF modes.
    pub struct UhfBandCapabilities: tlv [144] "UHFBandCapabilities" {} {
        transmit_power_level_table_entry: many1 TransmitPowerLevelTableEntry,
        frequency_information: one FrequencyInformation,
        c1g2_uhf_rf_mode_table: many1 C1g2UhfRfModeTable,
    }
}

llrp_struct! {
    /// One transmit power level, in hundredths of dBm.
    pub struct TransmitPowerLevelTableEntry: tlv [145] "TransmitPowerLevelTableEntry" {
        index "Index": u16,
        transmit_power_value "TransmitPowerValue": i16,
    } {}
}

llrp_struct! {
    /// Hopping or fixed frequencies, with their tables.
    pub struct FrequencyInformation: tlv [146] "FrequencyInformation" {
        hopping "Hopping": bool = 1 bits; pad 7,
    } {
        frequency_hop_table: many FrequencyHopTable,
        fixed_frequency_table: opt FixedFrequencyTable,
    }
}

llrp_struct! {
    /// A hop table: channel frequencies in kHz, in hop order.
    pub struct FrequencyHopTable: tlv [147] "FrequencyHopTable" {
        hop_table_id "HopTableID": u8; pad 8,
        frequencies "Frequencies": Vec<u32>,
    } {}
}

llrp_struct! {
    /// Fixed channel frequencies in kHz.
    pub struct FixedFrequencyTable: tlv [148] "FixedFrequencyTable" {
        frequencies "Frequencies": Vec<u32>,
    } {}
}

llrp_struct! {
    /// Gen2 access features.
    pub struct C1g2LlrpCapabilities: tlv [327] "C1G2LLRPCapabilities" {
        can_support_block_erase "CanSupportBlockErase": bool = 1 bits,
        can_support_block_write "CanSupportBlockWrite": bool = 1 bits,
        can_support_block_permalock "CanSupportBlockPermalock": bool = 1 bits,
        can_support_tag_recommissioning "CanSupportTagRecommissioning": bool = 1 bits,
        can_support_umi_method2 "CanSupportUMIMethod2": bool = 1 bits,
        can_support_xpc "CanSupportXPC": bool = 1 bits; pad 2,
        max_num_select_filters_per_query "MaxNumSelectFiltersPerQuery": u16,
    } {}
}

llrp_struct! {
    /// The Gen2 RF modes the reader offers.
    pub struct C1g2UhfRfModeTable: tlv [328] "C1G2UHFRFModeTable" {} {
        entries: many1 C1g2UhfRfModeTableEntry,
    }
}

llrp_struct! {
    /// One Gen2 RF mode: link parameters and Tari range.
    pub struct C1g2UhfRfModeTableEntry: tlv [329] "C1G2UHFRFModeTableEntry" {
        mode_identifier "ModeIdentifier": u32,
        dr_value "DRValue": bool = 1 bits,
        epc_hag_tc_conformance "EPCHAGTCConformance": bool = 1 bits; pad 6,
        m_value "MValue": u8,
        forward_link_modulation "ForwardLinkModulation": u8,
        spectral_mask_indicator "SpectralMaskIndicator": u8,
        bdr_value "BDRValue": u32,
        pie_value "PIEValue": u32,
        min_tari_value "MinTariValue": u32,
        max_tari_value "MaxTariValue": u32,
        step_tari_value "StepTariValue": u32,
    } {}
}
