//! Reader events, their notification settings, keepalives and event holding.
use crate::enums::*;

use super::*;

llrp_struct! {
    /// A microsecond timestamp since the Unix epoch.
    pub struct UtcTimestamp: tlv [128] "UTCTimestamp" {
        microseconds "Microseconds": u64,
    } {}
}

llrp_struct! {
    /// Microseconds since the reader booted.
    pub struct Uptime: tlv [129] "Uptime" {
        microseconds "Microseconds": u64,
    } {}
}

llrp_struct! {
    /// The body of READER_EVENT_NOTIFICATION: a timestamp and the events that happened.
    pub struct ReaderEventNotificationData: tlv [246] "ReaderEventNotificationData" {} {
        timestamp: one Timestamp,
        hopping_event: opt HoppingEvent,
        gpi_event: opt GpiEvent,
        ro_spec_event: opt RoSpecEvent,
        report_buffer_level_warning_event: opt ReportBufferLevelWarningEvent,
        report_buffer_overflow_error_event: opt ReportBufferOverflowErrorEvent,
        reader_exception_event: opt ReaderExceptionEvent,
        rf_survey_event: opt RfSurveyEvent,
        ai_spec_event: opt AiSpecEvent,
        antenna_event: opt AntennaEvent,
        connection_attempt_event: opt ConnectionAttemptEvent,
        connection_close_event: opt ConnectionCloseEvent,
        custom: many Custom,
    }
}

llrp_struct! {
    /// The reader hopped to another channel.
    pub struct HoppingEvent: tlv [247] "HoppingEvent" {
        hop_table_id "HopTableID": u16,
        next_channel_index "NextChannelIndex": u16,
    } {}
}

llrp_struct! {
    /// A GPI port changed state.
    pub struct GpiEvent: tlv [248] "GPIEvent" {
        gpi_port_number "GPIPortNumber": u16,
        gpi_event "GPIEvent": bool = 1 bits; pad 7,
    } {}
}

llrp_struct! {
    /// An ROSpec started (0), ended (1) or was preempted (2).
    pub struct RoSpecEvent: tlv [249] "ROSpecEvent" {
        event_type "EventType": RoSpecEventType,
        ro_spec_id "ROSpecID": u32,
        preempting_ro_spec_id "PreemptingROSpecID": u32,
    } {}
}

llrp_struct! {
    /// The report buffer is filling up.
    pub struct ReportBufferLevelWarningEvent: tlv [250] "ReportBufferLevelWarningEvent" {
        report_buffer_percentage_full "ReportBufferPercentageFull": u8,
    } {}
}

llrp_struct! {
    /// The report buffer overflowed and reports were lost.
    pub struct ReportBufferOverflowErrorEvent: tlv [251] "ReportBufferOverflowErrorEvent" {} {}
}

llrp_struct! {
    /// A reader error, with the spec it happened in.
    pub struct ReaderExceptionEvent: tlv [252] "ReaderExceptionEvent" {
        message "Message": String,
    } {
        ro_spec_id: opt RoSpecId,
        spec_index: opt SpecIndex,
        inventory_parameter_spec_id: opt InventoryParameterSpecId,
        antenna_id: opt AntennaId,
        access_spec_id: opt AccessSpecId,
        op_spec_id: opt OpSpecId,
        custom: many Custom,
    }
}

llrp_struct! {
    /// An RF survey started (0) or ended (1).
    pub struct RfSurveyEvent: tlv [253] "RFSurveyEvent" {
        event_type "EventType": u8,
        ro_spec_id "ROSpecID": u32,
        spec_index "SpecIndex": u16,
    } {}
}

llrp_struct! {
    /// An AISpec ended (0), with optional singulation details.
    pub struct AiSpecEvent: tlv [254] "AISpecEvent" {
        event_type "EventType": AiSpecEventType,
        ro_spec_id "ROSpecID": u32,
        spec_index "SpecIndex": u16,
    } {
        c1g2_singulation_details: opt C1g2SingulationDetails,
    }
}

llrp_struct! {
    /// An antenna was disconnected (0) or connected (1).
    pub struct AntennaEvent: tlv [255] "AntennaEvent" {
        event_type "EventType": AntennaEventType,
        antenna_id "AntennaID": u16,
    } {}
}

llrp_struct! {
    /// Outcome of a connection attempt: 0 success, 1..4 failures (4: another connection attempted).
    pub struct ConnectionAttemptEvent: tlv [256] "ConnectionAttemptEvent" {
        status "Status": ConnectionAttemptStatus,
    } {}
}

llrp_struct! {
    /// The reader is closing the connection.
    pub struct ConnectionCloseEvent: tlv [257] "ConnectionCloseEvent" {} {}
}

llrp_struct! {
    /// Which reader events are reported.
    pub struct ReaderEventNotificationSpec: tlv [244] "ReaderEventNotificationSpec" {} {
        event_notification_state: many1 EventNotificationState,
    }
}

llrp_struct! {
    /// Reporting on (true) or off for one event type (0 hopping .. 8 connection attempt).
    pub struct EventNotificationState: tlv [245] "EventNotificationState" {
        event_type "EventType": NotificationEventType,
        notification_state "NotificationState": bool = 1 bits; pad 7,
    } {}
}

llrp_struct! {
    /// Keepalive: 0 none, 1 periodic every `periodic_trigger_value` ms.
    pub struct KeepaliveSpec: tlv [220] "KeepaliveSpec" {
        keepalive_trigger_type "KeepaliveTriggerType": KeepaliveTriggerType,
        periodic_trigger_value "PeriodicTriggerValue": u32,
    } {}
}

llrp_struct! {
    /// Hold events and reports on reconnect until ENABLE_EVENTS_AND_REPORTS.
    pub struct EventsAndReports: tlv [226] "EventsAndReports" {
        hold_events_and_reports_upon_reconnect "HoldEventsAndReportsUponReconnect": bool = 1 bits; pad 7,
    } {}
}
