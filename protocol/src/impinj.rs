//! Impinj extensions (vendor 25882): typed vendor parameters and custom messages.

use crate::params::{C1g2Read, Custom, LlrpStatus};

/// Impinj's IANA private enterprise number.
pub const IMPINJ_VENDOR_ID: u32 = 25882;

llrp_struct! {
    /// Extra data to include in GET_READER_CAPABILITIES / GET_READER_CONFIG answers (1000 all capabilities, 2000 all configuration, ...).
    pub struct ImpinjRequestedData: custom [25882 21] "ImpinjRequestedData" {
        requested_data "RequestedData": u32,
    } { custom: many Custom }
}

llrp_struct! {
    /// Impinj regulatory sub-region (0 FCC Part 15.247, 7 ETSI EN 302 208 v1.2.1, ...).
    pub struct ImpinjSubRegulatoryRegion: custom [25882 22] "ImpinjSubRegulatoryRegion" {
        regulatory_region "RegulatoryRegion": u16,
    } { custom: many Custom }
}

llrp_struct! {
    /// Inventory search mode: 0 reader selected, 1 single target, 2 dual target, 3 single target with suppression.
    pub struct ImpinjInventorySearchMode: custom [25882 23] "ImpinjInventorySearchMode" {
        inventory_search_mode "InventorySearchMode": u16,
    } { custom: many Custom }
}

llrp_struct! {
    /// Channels to use: 0 disabled, 1 auto select, 2 the listed 1-based channel indices.
    pub struct ImpinjFixedFrequencyList: custom [25882 26] "ImpinjFixedFrequencyList" {
        fixed_frequency_mode "FixedFrequencyMode": u16; pad 16,
        channel_list "ChannelList": Vec<u16>,
    } { custom: many Custom }
}

llrp_struct! {
    /// Channels on which to transmit at reduced power.
    pub struct ImpinjReducedPowerFrequencyList: custom [25882 27] "ImpinjReducedPowerFrequencyList" {
        reduced_power_mode "ReducedPowerMode": u16; pad 16,
        channel_list "ChannelList": Vec<u16>,
    } { custom: many Custom }
}

llrp_struct! {
    /// Low duty cycle: stop transmitting when the field is empty.
    pub struct ImpinjLowDutyCycle: custom [25882 28] "ImpinjLowDutyCycle" {
        low_duty_cycle_mode "LowDutyCycleMode": u16,
        empty_field_timeout "EmptyFieldTimeout": u16,
        field_ping_interval "FieldPingInterval": u16,
    } { custom: many Custom }
}

llrp_struct! {
    /// Model, serial number and software/firmware/FPGA/PCBA versions.
    pub struct ImpinjDetailedVersion: custom [25882 29] "ImpinjDetailedVersion" {
        model_name "ModelName": String,
        serial_number "SerialNumber": String,
        software_version "SoftwareVersion": String,
        firmware_version "FirmwareVersion": String,
        fpga_version "FPGAVersion": String,
        pcba_version "PCBAVersion": String,
    } { custom: many Custom }
}

llrp_struct! {
    /// Every frequency the reader can use, in kHz.
    pub struct ImpinjFrequencyCapabilities: custom [25882 30] "ImpinjFrequencyCapabilities" {
        frequency_list "FrequencyList": Vec<u32>,
    } { custom: many Custom }
}

llrp_struct! {
    /// Reader temperature in °C.
    pub struct ImpinjReaderTemperature: custom [25882 37] "ImpinjReaderTemperature" {
        temperature "Temperature": i16,
    } { custom: many Custom }
}

llrp_struct! {
    /// Which Impinj fields tag reports carry; an absent feature counts as disabled.
    pub struct ImpinjTagReportContentSelector: custom [25882 50] "ImpinjTagReportContentSelector" {} {
        enable_serialized_tid: opt ImpinjEnableSerializedTid,
        enable_rf_phase_angle: opt ImpinjEnableRfPhaseAngle,
        enable_peak_rssi: opt ImpinjEnablePeakRssi,
        enable_gps_coordinates: opt ImpinjEnableGpsCoordinates,
        enable_optimized_read: opt ImpinjEnableOptimizedRead,
        enable_rf_doppler_frequency: opt ImpinjEnableRfDopplerFrequency,
        custom: many Custom,
    }
}

llrp_struct! {
    /// Report the TID with each tag (mode 1).
    pub struct ImpinjEnableSerializedTid: custom [25882 51] "ImpinjEnableSerializedTID" {
        serialized_tid_mode "SerializedTIDMode": u16,
    } { custom: many Custom }
}

llrp_struct! {
    /// Report the RF phase angle with each tag (mode 1).
    pub struct ImpinjEnableRfPhaseAngle: custom [25882 52] "ImpinjEnableRFPhaseAngle" {
        rf_phase_angle_mode "RFPhaseAngleMode": u16,
    } { custom: many Custom }
}

llrp_struct! {
    /// Report peak RSSI in hundredths of dBm with each tag (mode 1).
    pub struct ImpinjEnablePeakRssi: custom [25882 53] "ImpinjEnablePeakRSSI" {
        peak_rssi_mode "PeakRSSIMode": u16,
    } { custom: many Custom }
}

llrp_struct! {
    /// Report GPS coordinates with each tag (mode 1).
    pub struct ImpinjEnableGpsCoordinates: custom [25882 54] "ImpinjEnableGPSCoordinates" {
        gps_coordinates_mode "GPSCoordinatesMode": u16,
    } { custom: many Custom }
}

llrp_struct! {
    /// Read tag memory during inventory (mode 1) with the given reads.
    pub struct ImpinjEnableOptimizedRead: custom [25882 65] "ImpinjEnableOptimizedRead" {
        optimized_read_mode "OptimizedReadMode": u16,
    } {
        c1g2_read: many C1g2Read,
        custom: many Custom,
    }
}

llrp_struct! {
    /// Report the RF Doppler frequency with each tag (mode 1).
    pub struct ImpinjEnableRfDopplerFrequency: custom [25882 67] "ImpinjEnableRFDopplerFrequency" {
        rf_doppler_frequency_mode "RFDopplerFrequencyMode": u16,
    } { custom: many Custom }
}

llrp_struct! {
    /// The tag's TID words.
    pub struct ImpinjSerializedTid: custom [25882 55] "ImpinjSerializedTID" {
        tid "TID": Vec<u16>,
    } { custom: many Custom }
}

llrp_struct! {
    /// RF phase angle of the tag's reply: 0..4095 for 0..2π.
    pub struct ImpinjRfPhaseAngle: custom [25882 56] "ImpinjRFPhaseAngle" {
        phase_angle "PhaseAngle": u16,
    } { custom: many Custom }
}

llrp_struct! {
    /// Peak RSSI in hundredths of dBm.
    pub struct ImpinjPeakRssi: custom [25882 57] "ImpinjPeakRSSI" {
        rssi "RSSI": i16,
    } { custom: many Custom }
}

llrp_struct! {
    /// Doppler frequency in Hz × 16 (signed, 4 fractional bits).
    pub struct ImpinjRfDopplerFrequency: custom [25882 68] "ImpinjRFDopplerFrequency" {
        doppler_frequency "DopplerFrequency": i16,
    } { custom: many Custom }
}

llrp_struct! {
    /// IMPINJ_ENABLE_EXTENSIONS: turn on Impinj extensions for this connection.
    pub struct ImpinjEnableExtensions: custom_message [25882 21] "IMPINJ_ENABLE_EXTENSIONS" {
        reserved "Reserved": u32,
    } { custom: many Custom }
}

llrp_struct! {
    /// IMPINJ_ENABLE_EXTENSIONS_RESPONSE.
    pub struct ImpinjEnableExtensionsResponse: custom_message [25882 22] "IMPINJ_ENABLE_EXTENSIONS_RESPONSE" {} {
        llrp_status: one LlrpStatus,
        custom: many Custom,
    }
}

llrp_struct! {
    /// IMPINJ_SAVE_SETTINGS: persist (true) the current configuration.
    pub struct ImpinjSaveSettings: custom_message [25882 23] "IMPINJ_SAVE_SETTINGS" {
        save_configuration "SaveConfiguration": bool = 1 bits; pad 7,
    } { custom: many Custom }
}

llrp_struct! {
    /// IMPINJ_SAVE_SETTINGS_RESPONSE.
    pub struct ImpinjSaveSettingsResponse: custom_message [25882 24] "IMPINJ_SAVE_SETTINGS_RESPONSE" {} {
        llrp_status: one LlrpStatus,
        custom: many Custom,
    }
}
