//! Reader operation specs: ROSpec, triggers, AISpec and the inventory configuration inside it.
use crate::enums::*;

use super::{Custom, RoReportSpec, UtcTimestamp};

llrp_struct! {
    /// A reader operation: boundary triggers, antenna inventory specs and reporting.
    pub struct RoSpec: tlv [177] "ROSpec" {
        ro_spec_id "ROSpecID": u32,
        priority "Priority": u8; in 0..=7,
        current_state "CurrentState": RoSpecState,
    } {
        ro_boundary_spec: one RoBoundarySpec,
        specs: many1 SpecParameter,
        ro_report_spec: opt RoReportSpec,
    }
}

llrp_choice! {
    /// One spec of an ROSpec: an AISpec, an RFSurveySpec or a vendor spec.
    pub enum SpecParameter "SpecParameter" {
        AiSpec(AiSpec),
        RfSurveySpec(RfSurveySpec),
        Custom(Custom),
    }
}

llrp_struct! {
    /// When an ROSpec starts and stops.
    pub struct RoBoundarySpec: tlv [178] "ROBoundarySpec" {} {
        ro_spec_start_trigger: one RoSpecStartTrigger,
        ro_spec_stop_trigger: one RoSpecStopTrigger,
    }
}

llrp_struct! {
    /// ROSpec start trigger: 0 null, 1 immediate, 2 periodic, 3 GPI.
    pub struct RoSpecStartTrigger: tlv [179] "ROSpecStartTrigger" {
        ro_spec_start_trigger_type "ROSpecStartTriggerType": RoSpecStartTriggerType; in 0..=3,
    } {
        periodic_trigger_value: opt PeriodicTriggerValue,
        gpi_trigger_value: opt GpiTriggerValue,
    }
}

llrp_struct! {
    /// Periodic start: first after `offset` ms (or at a UTC time), then every `period` ms.
    pub struct PeriodicTriggerValue: tlv [180] "PeriodicTriggerValue" {
        offset "Offset": u32,
        period "Period": u32,
    } {
        utc_timestamp: opt UtcTimestamp,
    }
}

llrp_struct! {
    /// A GPI port event that triggers, with a timeout in ms.
    pub struct GpiTriggerValue: tlv [181] "GPITriggerValue" {
        gpi_port_num "GPIPortNum": u16,
        gpi_event "GPIEvent": bool = 1 bits; pad 7,
        timeout "Timeout": u32,
    } {}
}

llrp_struct! {
    /// ROSpec stop trigger: 0 null, 1 duration (ms), 2 GPI with timeout.
    pub struct RoSpecStopTrigger: tlv [182] "ROSpecStopTrigger" {
        ro_spec_stop_trigger_type "ROSpecStopTriggerType": RoSpecStopTriggerType; in 0..=2,
        duration_trigger_value "DurationTriggerValue": u32,
    } {
        gpi_trigger_value: opt GpiTriggerValue,
    }
}

llrp_struct! {
    /// Antenna inventory spec: which antennas (0 = all), when to stop, how to inventory.
    pub struct AiSpec: tlv [183] "AISpec" {
        antenna_ids "AntennaIDs": Vec<u16>,
    } {
        ai_spec_stop_trigger: one AiSpecStopTrigger,
        inventory_parameter_specs: many1 InventoryParameterSpec,
        custom: many Custom,
    }
}

llrp_struct! {
    /// AISpec stop trigger: 0 null, 1 duration, 2 GPI with timeout, 3 tag observation.
    pub struct AiSpecStopTrigger: tlv [184] "AISpecStopTrigger" {
        ai_spec_stop_trigger_type "AISpecStopTriggerType": AiSpecStopTriggerType; in 0..=3,
        duration_trigger "DurationTrigger": u32,
    } {
        gpi_trigger_value: opt GpiTriggerValue,
        tag_observation_trigger: opt TagObservationTrigger,
    }
}

llrp_struct! {
    /// Stop an AISpec after N tags, N attempts or T ms of silence (each with a timeout).
    pub struct TagObservationTrigger: tlv [185] "TagObservationTrigger" {
        trigger_type "TriggerType": TagObservationTriggerType; pad 8,
        number_of_tags "NumberOfTags": u16,
        number_of_attempts "NumberOfAttempts": u16,
        t "T": u16,
        timeout "Timeout": u32,
    } {}
}

llrp_struct! {
    /// Air protocol and per-antenna settings of one inventory.
    pub struct InventoryParameterSpec: tlv [186] "InventoryParameterSpec" {
        inventory_parameter_spec_id "InventoryParameterSpecID": u16,
        protocol_id "ProtocolID": AirProtocol,
    } {
        antenna_configuration: many AntennaConfiguration,
        custom: many Custom,
    }
}

llrp_struct! {
    /// An RF survey over a frequency range (LLRP 1.0.1 §10.2.3).
    pub struct RfSurveySpec: tlv [187] "RFSurveySpec" {
        antenna_id "AntennaID": u16,
        start_frequency "StartFrequency": u32,
        end_frequency "EndFrequency": u32,
    } {
        rf_survey_spec_stop_trigger: one RfSurveySpecStopTrigger,
        custom: many Custom,
    }
}

llrp_struct! {
    /// RF survey stop: 0 null, 1 duration, 2 N iterations through the range.
    pub struct RfSurveySpecStopTrigger: tlv [188] "RFSurveySpecStopTrigger" {
        stop_trigger_type "StopTriggerType": u8,
        duration_period "DurationPeriod": u32,
        n "N": u32,
    } {}
}

llrp_struct! {
    /// Receiver, transmitter and Gen2 settings for one antenna (0 = all).
    pub struct AntennaConfiguration: tlv [222] "AntennaConfiguration" {
        antenna_id "AntennaID": u16,
    } {
        rf_receiver: opt RfReceiver,
        rf_transmitter: opt RfTransmitter,
        c1g2_inventory_command: many C1g2InventoryCommand,
        custom: many Custom,
    }
}

llrp_struct! {
    /// Receiver sensitivity, as an index into the capabilities table.
    pub struct RfReceiver: tlv [223] "RFReceiver" {
        receiver_sensitivity "ReceiverSensitivity": u16,
    } {}
}

llrp_struct! {
    /// Hop table, channel and transmit power (index into the power table).
    pub struct RfTransmitter: tlv [224] "RFTransmitter" {
        hop_table_id "HopTableID": u16,
        channel_index "ChannelIndex": u16,
        transmit_power "TransmitPower": u16,
    } {}
}

llrp_struct! {
    /// Gen2 inventory settings: filters, RF mode, singulation.
    pub struct C1g2InventoryCommand: tlv [330] "C1G2InventoryCommand" {
        tag_inventory_state_aware "TagInventoryStateAware": bool = 1 bits; pad 7,
    } {
        c1g2_filter: many C1g2Filter,
        c1g2_rf_control: opt C1g2RfControl,
        c1g2_singulation_control: opt C1g2SingulationControl,
        custom: many Custom,
    }
}

llrp_struct! {
    /// A Gen2 Select filter.
    pub struct C1g2Filter: tlv [331] "C1G2Filter" {
        t "T": u8 = 2 bits; pad 6,
    } {
        c1g2_tag_inventory_mask: one C1g2TagInventoryMask,
        state_aware_action: opt C1g2TagInventoryStateAwareFilterAction,
        state_unaware_action: opt C1g2TagInventoryStateUnawareFilterAction,
    }
}

llrp_struct! {
    /// Memory bank, bit pointer and mask a filter matches.
    pub struct C1g2TagInventoryMask: tlv [332] "C1G2TagInventoryMask" {
        mb "MB": u8 = 2 bits; pad 6,
        pointer "Pointer": u16,
        tag_mask "TagMask": crate::codec::BitVec,
    } {}
}

llrp_struct! {
    /// State-aware filter target and action.
    pub struct C1g2TagInventoryStateAwareFilterAction: tlv [333] "C1G2TagInventoryStateAwareFilterAction" {
        target "Target": u8,
        action "Action": u8,
    } {}
}

llrp_struct! {
    /// State-unaware filter action.
    pub struct C1g2TagInventoryStateUnawareFilterAction: tlv [334] "C1G2TagInventoryStateUnawareFilterAction" {
        action "Action": u8,
    } {}
}

llrp_struct! {
    /// RF mode (a ModeIdentifier of the mode table) and Tari in ns.
    pub struct C1g2RfControl: tlv [335] "C1G2RFControl" {
        mode_index "ModeIndex": u16,
        tari "Tari": u16,
    } {}
}

llrp_struct! {
    /// Gen2 session, expected tag population and transit time.
    pub struct C1g2SingulationControl: tlv [336] "C1G2SingulationControl" {
        session "Session": u8 = 2 bits; pad 6,
        tag_population "TagPopulation": u16,
        tag_transit_time "TagTransitTime": u32,
    } {
        state_aware_singulation_action: opt C1g2TagInventoryStateAwareSingulationAction,
    }
}

llrp_struct! {
    /// State-aware singulation: inventoried state and SL flag to select.
    pub struct C1g2TagInventoryStateAwareSingulationAction: tlv [337] "C1G2TagInventoryStateAwareSingulationAction" {
        i "I": bool = 1 bits,
        s "S": bool = 1 bits; pad 6,
    } {}
}
