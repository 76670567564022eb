//! Message kinds and the request/response table: which response answers which request, and
//! which messages only a reader sends.

use super::*;

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

impl MessageBody {
    /// The ConnectionAttemptEvent status of a READER_EVENT_NOTIFICATION that carries one.
    pub fn connection_attempt(&self) -> Option<crate::enums::ConnectionAttemptStatus> {
        match self {
            MessageBody::ReaderEventNotification(n) => n
                .reader_event_notification_data
                .connection_attempt_event
                .as_ref()
                .map(|e| e.status),
            _ => None,
        }
    }

    /// Whether this is a READER_EVENT_NOTIFICATION with a ConnectionCloseEvent (a reader's
    /// last word before it closes a connection).
    pub fn is_connection_close(&self) -> bool {
        matches!(self, MessageBody::ReaderEventNotification(n)
            if n.reader_event_notification_data.connection_close_event.is_some())
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
