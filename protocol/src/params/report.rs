//! What reports contain: report specs, content selectors and tag report data.
use crate::enums::*;

use super::*;

llrp_struct! {
    /// When to send RO reports (0 none, 1 N tags or end of AISpec, 2 N tags or end of ROSpec, ...) and what they hold.
    pub struct RoReportSpec: tlv [237] "ROReportSpec" {
        ro_report_trigger "ROReportTrigger": RoReportTriggerType,
        n "N": u16,
    } {
        tag_report_content_selector: one TagReportContentSelector,
        custom: many Custom,
    }
}

llrp_struct! {
    /// Which optional fields each TagReportData carries.
    pub struct TagReportContentSelector: tlv [238] "TagReportContentSelector" {
        enable_ro_spec_id "EnableROSpecID": bool = 1 bits,
        enable_spec_index "EnableSpecIndex": bool = 1 bits,
        enable_inventory_parameter_spec_id "EnableInventoryParameterSpecID": bool = 1 bits,
        enable_antenna_id "EnableAntennaID": bool = 1 bits,
        enable_channel_index "EnableChannelIndex": bool = 1 bits,
        enable_peak_rssi "EnablePeakRSSI": bool = 1 bits,
        enable_first_seen_timestamp "EnableFirstSeenTimestamp": bool = 1 bits,
        enable_last_seen_timestamp "EnableLastSeenTimestamp": bool = 1 bits,
        enable_tag_seen_count "EnableTagSeenCount": bool = 1 bits,
        enable_access_spec_id "EnableAccessSpecID": bool = 1 bits; pad 6,
    } {
        air_protocol_epc_memory_selector: many C1g2EpcMemorySelector,
        custom: many Custom,
    }
}

llrp_struct! {
    /// Whether Gen2 reports carry the CRC and PC words (and XPC in LLRP 1.1).
    pub struct C1g2EpcMemorySelector: tlv [348] "C1G2EPCMemorySelector" {
        enable_crc "EnableCRC": bool = 1 bits,
        enable_pc_bits "EnablePCBits": bool = 1 bits,
        enable_xpc_bits "EnableXPCBits": bool = 1 bits; pad 5,
    } {}
}

llrp_struct! {
    /// When access results are reported: 0 with the RO report, 1 at the end of the AccessSpec.
    pub struct AccessReportSpec: tlv [239] "AccessReportSpec" {
        access_report_trigger "AccessReportTrigger": AccessReportTriggerType,
    } {}
}

llrp_struct! {
    /// One tag read: the EPC and whichever fields the content selector enabled.
    pub struct TagReportData: tlv [240] "TagReportData" {} {
        epc: one Epc,
        ro_spec_id: opt RoSpecId,
        spec_index: opt SpecIndex,
        inventory_parameter_spec_id: opt InventoryParameterSpecId,
        antenna_id: opt AntennaId,
        peak_rssi: opt PeakRssi,
        channel_index: opt ChannelIndex,
        first_seen_timestamp_utc: opt FirstSeenTimestampUtc,
        first_seen_timestamp_uptime: opt FirstSeenTimestampUptime,
        last_seen_timestamp_utc: opt LastSeenTimestampUtc,
        last_seen_timestamp_uptime: opt LastSeenTimestampUptime,
        tag_seen_count: opt TagSeenCount,
        air_protocol_tag_data: many AirProtocolTagData,
        access_spec_id: opt AccessSpecId,
        op_spec_results: many OpSpecResult,
        custom: many Custom,
    }
}

llrp_choice! {
    /// A tag's EPC: any length (EPCData) or exactly 96 bits (EPC-96).
    pub enum Epc "EPCParameter" {
        Epc96(Epc96),
        EpcData(EpcData),
    }
}

llrp_struct! {
    /// An EPC of any bit length.
    pub struct EpcData: tlv [241] "EPCData" {
        epc "EPC": crate::codec::BitVec,
    } {}
}

llrp_choice! {
    /// Gen2 protocol words reported with a tag.
    pub enum AirProtocolTagData "AirProtocolTagData" {
        C1g2Pc(C1g2Pc),
        C1g2Crc(C1g2Crc),
        C1g2Xpcw1(C1g2Xpcw1),
        C1g2Xpcw2(C1g2Xpcw2),
    }
}

llrp_choice! {
    /// A timestamp: UTC or reader uptime.
    pub enum Timestamp "Timestamp" {
        Utc(UtcTimestamp),
        Uptime(Uptime),
    }
}

llrp_struct! {
    /// RF survey results of one spec.
    pub struct RfSurveyReportData: tlv [242] "RFSurveyReportData" {} {
        ro_spec_id: opt RoSpecId,
        spec_index: opt SpecIndex,
        frequency_rssi_level_entry: many1 FrequencyRssiLevelEntry,
        custom: many Custom,
    }
}

llrp_struct! {
    /// Average and peak RSSI measured on one frequency.
    pub struct FrequencyRssiLevelEntry: tlv [243] "FrequencyRSSILevelEntry" {
        frequency "Frequency": u32,
        bandwidth "Bandwidth": u32,
        average_rssi "AverageRSSI": i8,
        peak_rssi "PeakRSSI": i8,
    } {
        timestamp: one Timestamp,
    }
}
