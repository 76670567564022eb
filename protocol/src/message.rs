//! LLRP messages: the typed bodies, the generic forms for the rest, and whole-frame codec.

use bytes::{BufMut, BytesMut};

use crate::codec::Body;
use crate::enums::{CapabilitiesRequest, ConfigRequest};
use crate::error::{DecodeError, ErrorKind, PathSeg};
use crate::frame::{FrameHeader, HEADER_LEN, VERSION_1_0_1, VERSION_1_1};
use crate::impinj::*;
use crate::params::*;

/// A message type with a fixed type number.
pub trait MessageDef {
    /// Spec name, e.g. `ADD_ROSPEC`.
    const NAME: &'static str;
    /// Message type number.
    const TYPE: u16;
}

/// A vendor message carried in CUSTOM_MESSAGE (type 1023).
pub trait CustomMessageDef {
    /// Spec name, e.g. `IMPINJ_ENABLE_EXTENSIONS`.
    const NAME: &'static str;
    /// Vendor ID.
    const VENDOR: u32;
    /// Message subtype.
    const SUBTYPE: u8;
}

/// CUSTOM_MESSAGE type number.
pub const CUSTOM_MESSAGE_TYPE: u16 = 1023;

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

/// A CUSTOM_MESSAGE the codec does not type, kept byte for byte.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct RawCustomMessage {
    /// Vendor ID.
    pub vendor: u32,
    /// Message subtype.
    pub subtype: u8,
    /// Everything after the subtype.
    #[cfg_attr(feature = "serde", serde(with = "crate::raw::hex_bytes"))]
    pub payload: Vec<u8>,
}

/// A message of a type the codec does not know, kept byte for byte.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct UnknownMessage {
    /// Message type number.
    pub msg_type: u16,
    /// The body after the 10-byte header.
    #[cfg_attr(feature = "serde", serde(with = "crate::raw::hex_bytes"))]
    pub payload: Vec<u8>,
}

/// The type a [`MessageBody`] variant holds for message `$t`: the message itself, or a box
/// for the few that are much larger than the rest (so that every message, reports above
/// all, stays small to move).
macro_rules! body_type {
    (GetReaderCapabilitiesResponse) => { Box<GetReaderCapabilitiesResponse> };
    (GetReaderConfigResponse) => { Box<GetReaderConfigResponse> };
    (ReaderEventNotification) => { Box<ReaderEventNotification> };
    (AddRospec) => { Box<AddRospec> };
    (SetReaderConfig) => { Box<SetReaderConfig> };
    (ClientRequestOp) => { Box<ClientRequestOp> };
    (AddAccessspec) => { Box<AddAccessspec> };
    (GetRospecsResponse) => { Box<GetRospecsResponse> };
    ($t:ident) => { $t };
}

macro_rules! message_body {
    (
        standard { $($std:ident),* $(,)? }
        custom { $($cus:ident),* $(,)? }
    ) => {
        /// The body of any LLRP message. The eight messages much larger than the rest
        /// (capabilities, configuration, ROSpec and AccessSpec definitions, reader events) are
        /// held in a `Box`, so that a message, a report above all, is cheap to move.
        #[derive(Clone, Debug, PartialEq, Eq)]
        #[cfg_attr(feature = "serde", derive(serde::Serialize))]
        #[cfg_attr(feature = "serde", serde(untagged))]
        #[allow(missing_docs, clippy::large_enum_variant)]
        pub enum MessageBody {
            $($std(body_type!($std)),)*
            $($cus($cus),)*
            /// A CUSTOM_MESSAGE of a vendor or subtype the codec does not type.
            Custom(RawCustomMessage),
            /// A message type the codec does not know.
            Unknown(UnknownMessage),
        }

        $(
            impl $std {
                /// This message's kind.
                pub const KIND: MessageKind = MessageKind::standard(<$std as MessageDef>::TYPE);
            }

            impl TryFrom<MessageBody> for $std {
                type Error = MessageBody;

                /// The message if the body is one; the body back otherwise.
                fn try_from(body: MessageBody) -> Result<Self, MessageBody> {
                    match body {
                        MessageBody::$std(m) => {
                            let boxed: Box<$std> = m.into();
                            Ok(*boxed)
                        }
                        other => Err(other),
                    }
                }
            }
        )*
        $(
            impl $cus {
                /// This message's kind.
                pub const KIND: MessageKind = MessageKind::custom(
                    <$cus as CustomMessageDef>::VENDOR,
                    <$cus as CustomMessageDef>::SUBTYPE,
                );
            }

            impl TryFrom<MessageBody> for $cus {
                type Error = MessageBody;

                /// The message if the body is one; the body back otherwise.
                fn try_from(body: MessageBody) -> Result<Self, MessageBody> {
                    match body {
                        MessageBody::$cus(m) => Ok(m),
                        other => Err(other),
                    }
                }
            }
        )*

        $(
            impl From<$std> for MessageBody {
                #[allow(clippy::useless_conversion)] // boxes the large messages only
                fn from(m: $std) -> Self {
                    MessageBody::$std(m.into())
                }
            }
        )*
        $(
            impl From<$cus> for MessageBody {
                fn from(m: $cus) -> Self {
                    MessageBody::$cus(m)
                }
            }
        )*

        impl MessageBody {
            /// Message type number.
            pub fn msg_type(&self) -> u16 {
                match self {
                    $(MessageBody::$std(_) => <$std as MessageDef>::TYPE,)*
                    $(MessageBody::$cus(_) => CUSTOM_MESSAGE_TYPE,)*
                    MessageBody::Custom(_) => CUSTOM_MESSAGE_TYPE,
                    MessageBody::Unknown(u) => u.msg_type,
                }
            }

            /// The message's kind: type number, and vendor and subtype of a CUSTOM_MESSAGE.
            pub fn kind(&self) -> MessageKind {
                match self {
                    $(MessageBody::$std(_) => <$std>::KIND,)*
                    $(MessageBody::$cus(_) => <$cus>::KIND,)*
                    MessageBody::Custom(c) => MessageKind::custom(c.vendor, c.subtype),
                    MessageBody::Unknown(u) => MessageKind::standard(u.msg_type),
                }
            }

            /// Spec name, e.g. `ADD_ROSPEC`; `CUSTOM_MESSAGE` / `UNKNOWN` for the generic forms.
            pub fn name(&self) -> &'static str {
                match self {
                    $(MessageBody::$std(_) => <$std as MessageDef>::NAME,)*
                    $(MessageBody::$cus(_) => <$cus as CustomMessageDef>::NAME,)*
                    MessageBody::Custom(_) => "CUSTOM_MESSAGE",
                    MessageBody::Unknown(_) => "UNKNOWN",
                }
            }

            /// Every typed message: (type, vendor, subtype, name); vendor 0 for standard ones.
            pub const TYPED: &'static [(u16, u32, u8, &'static str)] = &[
                $((<$std as MessageDef>::TYPE, 0, 0, <$std as MessageDef>::NAME),)*
                $((CUSTOM_MESSAGE_TYPE, <$cus as CustomMessageDef>::VENDOR, <$cus as CustomMessageDef>::SUBTYPE, <$cus as CustomMessageDef>::NAME),)*
            ];

            fn decode_body(ty: u16, body: &[u8]) -> Result<Self, DecodeError> {
                $(
                    if ty == <$std as MessageDef>::TYPE {
                        return <$std as Body>::decode_body(body).map(MessageBody::from);
                    }
                )*
                if ty == CUSTOM_MESSAGE_TYPE {
                    if body.len() < 4 {
                        return Err(DecodeError::at(body.as_ptr(), ErrorKind::Truncated).within(PathSeg::Field { name: "VendorIdentifier", index: 0 }));
                    }
                    if body.len() < 5 {
                        return Err(DecodeError::at(body[4..].as_ptr(), ErrorKind::Truncated).within(PathSeg::Field { name: "MessageSubtype", index: 1 }));
                    }
                    let vendor = u32::from_be_bytes([body[0], body[1], body[2], body[3]]);
                    let subtype = body[4];
                    $(
                        if vendor == <$cus as CustomMessageDef>::VENDOR && subtype == <$cus as CustomMessageDef>::SUBTYPE {
                            return <$cus as Body>::decode_body(&body[5..]).map(MessageBody::$cus);
                        }
                    )*
                    return Ok(MessageBody::Custom(RawCustomMessage { vendor, subtype, payload: body[5..].to_vec() }));
                }
                Ok(MessageBody::Unknown(UnknownMessage { msg_type: ty, payload: body.to_vec() }))
            }

            fn encode_body(&self, buf: &mut BytesMut) {
                match self {
                    $(MessageBody::$std(m) => m.encode_body(buf),)*
                    $(MessageBody::$cus(m) => {
                        buf.put_u32(<$cus as CustomMessageDef>::VENDOR);
                        buf.put_u8(<$cus as CustomMessageDef>::SUBTYPE);
                        m.encode_body(buf)
                    })*
                    MessageBody::Custom(c) => {
                        buf.put_u32(c.vendor);
                        buf.put_u8(c.subtype);
                        buf.put_slice(&c.payload);
                    }
                    MessageBody::Unknown(u) => buf.put_slice(&u.payload),
                }
            }

            /// A random valid body of typed message number `k` of [`Self::TYPED`].
            #[cfg(feature = "arbitrary")]
            pub fn sample_typed(k: usize, g: &mut crate::sample::Gen) -> Self {
                let makers: Vec<fn(&mut crate::sample::Gen) -> MessageBody> = vec![
                    $( |g| MessageBody::from(<$std as crate::sample::Sample>::sample(g)), )*
                    $( |g| MessageBody::$cus(<$cus as crate::sample::Sample>::sample(g)), )*
                ];
                makers[k % makers.len()](g)
            }
        }
    };
}

message_body! {
    standard {
        GetReaderCapabilities, GetReaderCapabilitiesResponse, GetReaderConfig,
        GetReaderConfigResponse, SetReaderConfig, SetReaderConfigResponse, CloseConnection,
        CloseConnectionResponse, AddRospec, AddRospecResponse, DeleteRospec, DeleteRospecResponse,
        StartRospec, StartRospecResponse, StopRospec, StopRospecResponse, EnableRospec,
        EnableRospecResponse, DisableRospec, DisableRospecResponse, GetRospecs, GetRospecsResponse,
        AddAccessspec, AddAccessspecResponse, DeleteAccessspec, DeleteAccessspecResponse,
        EnableAccessspec, EnableAccessspecResponse, DisableAccessspec, DisableAccessspecResponse,
        GetAccessspecs, GetAccessspecsResponse, ClientRequestOp, ClientRequestOpResponse,
        GetSupportedVersion, GetSupportedVersionResponse, SetProtocolVersion,
        SetProtocolVersionResponse, GetReport, RoAccessReport, Keepalive, KeepaliveAck,
        ReaderEventNotification, EnableEventsAndReports, ErrorMessage,
    }
    custom {
        ImpinjEnableExtensions, ImpinjEnableExtensionsResponse, ImpinjSaveSettings,
        ImpinjSaveSettingsResponse,
    }
}

/// What identifies a message type: its number, and for CUSTOM_MESSAGE its vendor and subtype
/// (both 0 for standard messages).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct MessageKind {
    /// Message type number.
    pub msg_type: u16,
    /// Vendor ID of a CUSTOM_MESSAGE (0 otherwise).
    pub vendor: u32,
    /// Subtype of a CUSTOM_MESSAGE (0 otherwise).
    pub subtype: u8,
}

impl MessageKind {
    /// A standard message type.
    pub const fn standard(msg_type: u16) -> Self {
        MessageKind {
            msg_type,
            vendor: 0,
            subtype: 0,
        }
    }

    /// A vendor message carried in CUSTOM_MESSAGE.
    pub const fn custom(vendor: u32, subtype: u8) -> Self {
        MessageKind {
            msg_type: CUSTOM_MESSAGE_TYPE,
            vendor,
            subtype,
        }
    }

    /// The kind of the message at the front of `frame` (header, then vendor and subtype of a
    /// CUSTOM_MESSAGE when present); `None` if the header is incomplete.
    pub fn of_frame(frame: &[u8]) -> Option<Self> {
        let h = FrameHeader::peek(frame)?;
        match frame.get(HEADER_LEN..HEADER_LEN + 5) {
            Some(b) if h.msg_type == CUSTOM_MESSAGE_TYPE => Some(MessageKind::custom(
                u32::from_be_bytes([b[0], b[1], b[2], b[3]]),
                b[4],
            )),
            _ => Some(MessageKind::standard(h.msg_type)),
        }
    }

    /// Spec name, e.g. `ADD_ROSPEC`; `CUSTOM_MESSAGE` / `UNKNOWN` for kinds the codec does not
    /// type.
    pub fn name(&self) -> &'static str {
        MessageBody::TYPED
            .iter()
            .find(|(t, v, s, _)| {
                *t == self.msg_type
                    && (self.msg_type != CUSTOM_MESSAGE_TYPE
                        || (*v == self.vendor && *s == self.subtype))
            })
            .map_or(
                if self.msg_type == CUSTOM_MESSAGE_TYPE {
                    "CUSTOM_MESSAGE"
                } else {
                    "UNKNOWN"
                },
                |e| e.3,
            )
    }
}

/// A request a client sends, answered by one response message.
pub trait Request: Into<MessageBody> {
    /// The message a reader answers this request with.
    type Response: Response;
}

/// A response message: it carries the LLRPStatus of its request.
pub trait Response:
    Default + Into<MessageBody> + TryFrom<MessageBody, Error = MessageBody>
{
    /// A response carrying only `status`.
    fn with_status(status: LlrpStatus) -> Self;
    /// The status the response carries.
    fn status(&self) -> &LlrpStatus;
}

/// The request/response pairs, and the other messages only a reader sends: the one table the
/// reader, the client and the tests take responses from.
macro_rules! requests {
    (
        pairs { $($req:ident => $resp:ident),* $(,)? }
        reader_initiated { $($ini:ident),* $(,)? }
    ) => {
        $(
            impl Request for $req {
                type Response = $resp;
            }

            impl Response for $resp {
                fn with_status(status: LlrpStatus) -> Self {
                    $resp { llrp_status: status, ..Default::default() }
                }

                fn status(&self) -> &LlrpStatus {
                    &self.llrp_status
                }
            }
        )*

        impl MessageKind {
            /// The kind of the response a reader sends to a request of this kind; `None` for
            /// messages without a response.
            pub fn response(&self) -> Option<MessageKind> {
                $(
                    if *self == <$req>::KIND {
                        return Some(<$resp>::KIND);
                    }
                )*
                None
            }

            /// The response to a request of this kind carrying only `status` (what a reader
            /// answers a request it refuses with); `None` for messages without a response,
            /// which a reader answers with ERROR_MESSAGE.
            pub fn error_response(&self, status: LlrpStatus) -> Option<MessageBody> {
                $(
                    if *self == <$req>::KIND {
                        return Some(<$resp as Response>::with_status(status).into());
                    }
                )*
                None
            }

            /// Whether only a reader sends messages of this kind (responses, reports, events,
            /// keepalives, CLIENT_REQUEST_OP, ERROR_MESSAGE).
            pub fn is_from_reader(&self) -> bool {
                [$(<$resp>::KIND,)* $(<$ini>::KIND,)*].contains(self)
            }
        }

        impl MessageBody {
            /// The LLRPStatus of a response message; `None` for other messages.
            pub fn status(&self) -> Option<&LlrpStatus> {
                match self {
                    $(MessageBody::$resp(m) => Some(&m.llrp_status),)*
                    MessageBody::ErrorMessage(m) => Some(&m.llrp_status),
                    _ => None,
                }
            }
        }
    };
}

requests! {
    pairs {
        GetReaderCapabilities => GetReaderCapabilitiesResponse,
        GetReaderConfig => GetReaderConfigResponse,
        SetReaderConfig => SetReaderConfigResponse,
        CloseConnection => CloseConnectionResponse,
        AddRospec => AddRospecResponse,
        DeleteRospec => DeleteRospecResponse,
        StartRospec => StartRospecResponse,
        StopRospec => StopRospecResponse,
        EnableRospec => EnableRospecResponse,
        DisableRospec => DisableRospecResponse,
        GetRospecs => GetRospecsResponse,
        AddAccessspec => AddAccessspecResponse,
        DeleteAccessspec => DeleteAccessspecResponse,
        EnableAccessspec => EnableAccessspecResponse,
        DisableAccessspec => DisableAccessspecResponse,
        GetAccessspecs => GetAccessspecsResponse,
        GetSupportedVersion => GetSupportedVersionResponse,
        SetProtocolVersion => SetProtocolVersionResponse,
        ImpinjEnableExtensions => ImpinjEnableExtensionsResponse,
        ImpinjSaveSettings => ImpinjSaveSettingsResponse,
    }
    reader_initiated { ClientRequestOp, RoAccessReport, Keepalive, ReaderEventNotification, ErrorMessage }
}

/// A whole LLRP message: header version and ID plus the body.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Message {
    /// Header version: 1 (LLRP 1.0.1) or 2 (LLRP 1.1).
    pub version: u8,
    /// Message ID; responses echo their request's.
    pub id: u32,
    /// The typed or generic body.
    pub body: MessageBody,
}

impl Message {
    /// An LLRP 1.0.1 message with this ID and body.
    pub fn new(id: u32, body: impl Into<MessageBody>) -> Self {
        Message {
            version: VERSION_1_0_1,
            id,
            body: body.into(),
        }
    }

    /// Message type number.
    pub fn msg_type(&self) -> u16 {
        self.body.msg_type()
    }

    /// Spec name of the message type.
    pub fn name(&self) -> &'static str {
        self.body.name()
    }

    /// Decodes one whole message (as delimited by [`crate::FrameSplitter`]).
    pub fn decode(frame: &[u8]) -> Result<Message, DecodeError> {
        let base = frame.as_ptr() as usize;
        Self::decode_inner(frame).map_err(|mut e| {
            e.offset = e.offset.saturating_sub(base).min(frame.len());
            e
        })
    }

    fn decode_inner(frame: &[u8]) -> Result<Message, DecodeError> {
        let Some(h) = FrameHeader::peek(frame) else {
            return Err(DecodeError::at(frame.as_ptr(), ErrorKind::Truncated));
        };
        let seg = PathSeg::Message {
            name: message_name(h.msg_type, frame),
            ty: h.msg_type,
        };
        if h.length as usize != frame.len() || frame.len() < HEADER_LEN {
            return Err(DecodeError::at(
                frame.as_ptr(),
                ErrorKind::BadMessageLength { len: h.length },
            )
            .within(seg));
        }
        if h.version != VERSION_1_0_1 && h.version != VERSION_1_1 {
            return Err(DecodeError::at(
                frame.as_ptr(),
                ErrorKind::UnsupportedVersion { version: h.version },
            )
            .within(seg));
        }
        let body = MessageBody::decode_body(h.msg_type, &frame[HEADER_LEN..])
            .map_err(|e| e.within(seg))?;
        Ok(Message {
            version: h.version,
            id: h.id,
            body,
        })
    }

    /// Appends the encoded message.
    pub fn encode(&self, buf: &mut BytesMut) {
        let start = buf.len();
        FrameHeader {
            version: self.version,
            msg_type: self.msg_type(),
            length: 0,
            id: self.id,
        }
        .encode(buf);
        self.body.encode_body(buf);
        let len = u32::try_from(buf.len() - start).unwrap_or(u32::MAX);
        buf[start + 2..start + 6].copy_from_slice(&len.to_be_bytes());
    }

    /// The encoded message.
    pub fn to_bytes(&self) -> BytesMut {
        let mut buf = BytesMut::with_capacity(64);
        self.encode(&mut buf);
        buf
    }
}

/// Spec name of message type `ty` (looking at the vendor/subtype of a CUSTOM_MESSAGE).
pub fn message_name(ty: u16, frame: &[u8]) -> &'static str {
    match MessageKind::of_frame(frame) {
        Some(k) if k.msg_type == ty => k.name(),
        _ => MessageKind::standard(ty).name(),
    }
}

#[cfg(feature = "serde")]
impl serde::Serialize for Message {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeStruct;
        let mut st = s.serialize_struct("Message", 5)?;
        st.serialize_field("message", self.name())?;
        st.serialize_field("type", &self.msg_type())?;
        st.serialize_field("version", &self.version)?;
        st.serialize_field("id", &self.id)?;
        st.serialize_field("body", &self.body)?;
        st.end()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_request_names_its_response_and_only_the_reader_sends_responses() {
        let mut pairs = 0;
        for &(ty, vendor, subtype, name) in MessageBody::TYPED {
            let kind = MessageKind {
                msg_type: ty,
                vendor,
                subtype,
            };
            assert_eq!(kind.name(), name);
            if let Some(resp) = kind.response() {
                pairs += 1;
                assert_eq!(resp.name(), format!("{name}_RESPONSE"), "{name}");
                assert!(resp.is_from_reader() && !kind.is_from_reader(), "{name}");
                let body = kind
                    .error_response(LlrpStatus::new(crate::StatusCode::M_ParameterError, "x"))
                    .expect("a request with a response has an error response");
                assert_eq!(body.kind(), resp);
                assert_eq!(
                    body.status().map(|s| s.status_code),
                    Some(crate::StatusCode::M_ParameterError)
                );
            } else if !name.ends_with("_RESPONSE") {
                // Messages without a response: reports, events, keepalives and their
                // acknowledgement, GET_REPORT, ENABLE_EVENTS_AND_REPORTS, ERROR_MESSAGE, and
                // CLIENT_REQUEST_OP (the reader's question).
                assert!(
                    kind.error_response(LlrpStatus::success()).is_none(),
                    "{name}"
                );
            }
        }
        assert_eq!(pairs, 20);
        assert!(KeepaliveAck::KIND.response().is_none() && !KeepaliveAck::KIND.is_from_reader());
        assert!(Keepalive::KIND.is_from_reader());
        assert_eq!(MessageKind::standard(999).name(), "UNKNOWN");
    }

    #[test]
    fn a_response_comes_back_out_of_its_body() {
        let body = MessageBody::from(AddRospecResponse::with_status(LlrpStatus::success()));
        let back = AddRospecResponse::try_from(body).expect("the same message");
        assert!(back.llrp_status.is_success());
        let other = MessageBody::from(KeepaliveAck::default());
        assert!(AddRospecResponse::try_from(other).is_err());
    }
}
