//! The typed LLRP messages, one definition each (fields and sub-parameters in spec order).

use crate::enums::{CapabilitiesRequest, ConfigRequest};
use crate::params::*;

macro_rules! empty_message {
    ($(#[$m:meta])* $name:ident, $ty:literal, $spec:literal) => {
        llrp_struct! {
            $(#[$m])*
            pub struct $name: message [$ty] $spec {} { custom: many Custom }
        }
    };
}

macro_rules! status_message {
    ($(#[$m:meta])* $name:ident, $ty:literal, $spec:literal) => {
        llrp_struct! {
            $(#[$m])*
            pub struct $name: message [$ty] $spec {} { llrp_status: one LlrpStatus, custom: many Custom }
        }
    };
}

macro_rules! id_message {
    ($(#[$m:meta])* $name:ident, $ty:literal, $spec:literal, $field:ident $fspec:literal) => {
        llrp_struct! {
            $(#[$m])*
            pub struct $name: message [$ty] $spec { $field $fspec: u32 } { custom: many Custom }
        }
    };
}

llrp_struct! {
    /// GET_READER_CAPABILITIES: 0 all, 1 general, 2 LLRP, 3 regulatory, 4 air protocol.
    pub struct GetReaderCapabilities: message [1] "GET_READER_CAPABILITIES" {
        requested_data "RequestedData": CapabilitiesRequest,
    } { custom: many Custom }
}

llrp_struct! {
    /// GET_READER_CAPABILITIES_RESPONSE.
    pub struct GetReaderCapabilitiesResponse: message [11] "GET_READER_CAPABILITIES_RESPONSE" {} {
        llrp_status: one LlrpStatus,
        general_device_capabilities: opt GeneralDeviceCapabilities,
        llrp_capabilities: opt LlrpCapabilities,
        regulatory_capabilities: opt RegulatoryCapabilities,
        c1g2_llrp_capabilities: opt C1g2LlrpCapabilities,
        custom: many Custom,
    }
}

llrp_struct! {
    /// GET_READER_CONFIG: which configuration to return (0 all) for which antenna and ports.
    pub struct GetReaderConfig: message [2] "GET_READER_CONFIG" {
        antenna_id "AntennaID": u16,
        requested_data "RequestedData": ConfigRequest,
        gpi_port_num "GPIPortNum": u16,
        gpo_port_num "GPOPortNum": u16,
    } { custom: many Custom }
}

llrp_struct! {
    /// GET_READER_CONFIG_RESPONSE.
    pub struct GetReaderConfigResponse: message [12] "GET_READER_CONFIG_RESPONSE" {} {
        llrp_status: one LlrpStatus,
        identification: opt Identification,
        antenna_properties: many AntennaProperties,
        antenna_configuration: many AntennaConfiguration,
        reader_event_notification_spec: opt ReaderEventNotificationSpec,
        ro_report_spec: opt RoReportSpec,
        access_report_spec: opt AccessReportSpec,
        llrp_configuration_state_value: opt LlrpConfigurationStateValue,
        keepalive_spec: opt KeepaliveSpec,
        gpi_port_current_state: many GpiPortCurrentState,
        gpo_write_data: many GpoWriteData,
        events_and_reports: opt EventsAndReports,
        custom: many Custom,
    }
}

llrp_struct! {
    /// SET_READER_CONFIG: optionally reset to factory defaults, then apply what is given.
    pub struct SetReaderConfig: message [3] "SET_READER_CONFIG" {
        reset_to_factory_default "ResetToFactoryDefault": bool = 1 bits; pad 7,
    } {
        reader_event_notification_spec: opt ReaderEventNotificationSpec,
        antenna_properties: many AntennaProperties,
        antenna_configuration: many AntennaConfiguration,
        ro_report_spec: opt RoReportSpec,
        access_report_spec: opt AccessReportSpec,
        keepalive_spec: opt KeepaliveSpec,
        gpo_write_data: many GpoWriteData,
        gpi_port_current_state: many GpiPortCurrentState,
        events_and_reports: opt EventsAndReports,
        custom: many Custom,
    }
}

status_message!(/// SET_READER_CONFIG_RESPONSE.
    SetReaderConfigResponse, 13, "SET_READER_CONFIG_RESPONSE");
empty_message!(/// CLOSE_CONNECTION: the client asks the reader to close.
    CloseConnection, 14, "CLOSE_CONNECTION");
status_message!(/// CLOSE_CONNECTION_RESPONSE.
    CloseConnectionResponse, 4, "CLOSE_CONNECTION_RESPONSE");

llrp_struct! {
    /// ADD_ROSPEC: add a (disabled) ROSpec.
    pub struct AddRospec: message [20] "ADD_ROSPEC" {} { ro_spec: one RoSpec, custom: many Custom }
}

status_message!(/// ADD_ROSPEC_RESPONSE.
    AddRospecResponse, 30, "ADD_ROSPEC_RESPONSE");
id_message!(/// DELETE_ROSPEC: delete one ROSpec, or all with ID 0.
    DeleteRospec, 21, "DELETE_ROSPEC", ro_spec_id "ROSpecID");
status_message!(/// DELETE_ROSPEC_RESPONSE.
    DeleteRospecResponse, 31, "DELETE_ROSPEC_RESPONSE");
id_message!(/// START_ROSPEC: start an enabled ROSpec.
    StartRospec, 22, "START_ROSPEC", ro_spec_id "ROSpecID");
status_message!(/// START_ROSPEC_RESPONSE.
    StartRospecResponse, 32, "START_ROSPEC_RESPONSE");
id_message!(/// STOP_ROSPEC: stop an active ROSpec.
    StopRospec, 23, "STOP_ROSPEC", ro_spec_id "ROSpecID");
status_message!(/// STOP_ROSPEC_RESPONSE.
    StopRospecResponse, 33, "STOP_ROSPEC_RESPONSE");
id_message!(/// ENABLE_ROSPEC: enable one ROSpec, or all with ID 0.
    EnableRospec, 24, "ENABLE_ROSPEC", ro_spec_id "ROSpecID");
status_message!(/// ENABLE_ROSPEC_RESPONSE.
    EnableRospecResponse, 34, "ENABLE_ROSPEC_RESPONSE");
id_message!(/// DISABLE_ROSPEC: disable one ROSpec, or all with ID 0.
    DisableRospec, 25, "DISABLE_ROSPEC", ro_spec_id "ROSpecID");
status_message!(/// DISABLE_ROSPEC_RESPONSE.
    DisableRospecResponse, 35, "DISABLE_ROSPEC_RESPONSE");
empty_message!(/// GET_ROSPECS: list the ROSpecs.
    GetRospecs, 26, "GET_ROSPECS");

llrp_struct! {
    /// GET_ROSPECS_RESPONSE.
    pub struct GetRospecsResponse: message [36] "GET_ROSPECS_RESPONSE" {} {
        llrp_status: one LlrpStatus,
        ro_specs: many RoSpec,
        custom: many Custom,
    }
}

llrp_struct! {
    /// ADD_ACCESSSPEC: add a (disabled) AccessSpec.
    pub struct AddAccessspec: message [40] "ADD_ACCESSSPEC" {} { access_spec: one AccessSpec, custom: many Custom }
}

status_message!(/// ADD_ACCESSSPEC_RESPONSE.
    AddAccessspecResponse, 50, "ADD_ACCESSSPEC_RESPONSE");
id_message!(/// DELETE_ACCESSSPEC: delete one AccessSpec, or all with ID 0.
    DeleteAccessspec, 41, "DELETE_ACCESSSPEC", access_spec_id "AccessSpecID");
status_message!(/// DELETE_ACCESSSPEC_RESPONSE.
    DeleteAccessspecResponse, 51, "DELETE_ACCESSSPEC_RESPONSE");
id_message!(/// ENABLE_ACCESSSPEC: enable one AccessSpec, or all with ID 0.
    EnableAccessspec, 42, "ENABLE_ACCESSSPEC", access_spec_id "AccessSpecID");
status_message!(/// ENABLE_ACCESSSPEC_RESPONSE.
    EnableAccessspecResponse, 52, "ENABLE_ACCESSSPEC_RESPONSE");
id_message!(/// DISABLE_ACCESSSPEC: disable one AccessSpec, or all with ID 0.
    DisableAccessspec, 43, "DISABLE_ACCESSSPEC", access_spec_id "AccessSpecID");
status_message!(/// DISABLE_ACCESSSPEC_RESPONSE.
    DisableAccessspecResponse, 53, "DISABLE_ACCESSSPEC_RESPONSE");
empty_message!(/// GET_ACCESSSPECS: list the AccessSpecs.
    GetAccessspecs, 44, "GET_ACCESSSPECS");

llrp_struct! {
    /// GET_ACCESSSPECS_RESPONSE.
    pub struct GetAccessspecsResponse: message [54] "GET_ACCESSSPECS_RESPONSE" {} {
        llrp_status: one LlrpStatus,
        access_specs: many AccessSpec,
        custom: many Custom,
    }
}

llrp_struct! {
    /// CLIENT_REQUEST_OP: the reader asks the client what to do with a tag.
    pub struct ClientRequestOp: message [45] "CLIENT_REQUEST_OP" {} { tag_report_data: one TagReportData }
}

llrp_struct! {
    /// CLIENT_REQUEST_OP_RESPONSE: the client's operations for that tag.
    pub struct ClientRequestOpResponse: message [55] "CLIENT_REQUEST_OP_RESPONSE" {} {
        client_request_response: one ClientRequestResponse,
    }
}

empty_message!(/// GET_SUPPORTED_VERSION (LLRP 1.1).
    GetSupportedVersion, 46, "GET_SUPPORTED_VERSION");

llrp_struct! {
    /// GET_SUPPORTED_VERSION_RESPONSE: current and highest supported version (LLRP 1.1).
    pub struct GetSupportedVersionResponse: message [56] "GET_SUPPORTED_VERSION_RESPONSE" {
        current_version "CurrentVersion": u8,
        supported_version "SupportedVersion": u8,
    } { llrp_status: one LlrpStatus, custom: many Custom }
}

llrp_struct! {
    /// SET_PROTOCOL_VERSION (LLRP 1.1).
    pub struct SetProtocolVersion: message [47] "SET_PROTOCOL_VERSION" {
        protocol_version "ProtocolVersion": u8,
    } { custom: many Custom }
}

status_message!(/// SET_PROTOCOL_VERSION_RESPONSE (LLRP 1.1).
    SetProtocolVersionResponse, 57, "SET_PROTOCOL_VERSION_RESPONSE");
empty_message!(/// GET_REPORT: ask for buffered reports now.
    GetReport, 60, "GET_REPORT");

llrp_struct! {
    /// RO_ACCESS_REPORT: tag reads and RF survey results.
    pub struct RoAccessReport: message [61] "RO_ACCESS_REPORT" {} {
        tag_report_data: many TagReportData,
        rf_survey_report_data: many RfSurveyReportData,
        custom: many Custom,
    }
}

empty_message!(/// KEEPALIVE: the reader checks the connection.
    Keepalive, 62, "KEEPALIVE");
empty_message!(/// KEEPALIVE_ACK: the client's answer to KEEPALIVE.
    KeepaliveAck, 72, "KEEPALIVE_ACK");

llrp_struct! {
    /// READER_EVENT_NOTIFICATION.
    pub struct ReaderEventNotification: message [63] "READER_EVENT_NOTIFICATION" {} {
        reader_event_notification_data: one ReaderEventNotificationData,
        custom: many Custom,
    }
}

empty_message!(/// ENABLE_EVENTS_AND_REPORTS: release held events and reports.
    EnableEventsAndReports, 64, "ENABLE_EVENTS_AND_REPORTS");
status_message!(/// ERROR_MESSAGE: the reader could not handle a message.
    ErrorMessage, 100, "ERROR_MESSAGE");
