//! LLRP messages: the typed bodies, the generic forms for the rest, and whole-frame codec.

use bytes::{BufMut, BytesMut};

use crate::codec::Body;
use crate::error::{DecodeError, ErrorKind, PathSeg};
use crate::frame::{FrameHeader, HEADER_LEN, VERSION_1_0_1, VERSION_1_1};
use crate::impinj::*;
use crate::params::*;

mod defs;
mod kind;

pub use defs::*;
pub use kind::*;

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

impl ReaderEventNotification {
    /// A READER_EVENT_NOTIFICATION with a ConnectionAttemptEvent of `status`, stamped `utc_us`
    /// (UTC µs): what a reader tells a client of its connection attempt.
    pub fn connection_attempt(
        status: crate::enums::ConnectionAttemptStatus,
        utc_us: u64,
    ) -> ReaderEventNotification {
        ReaderEventNotification {
            reader_event_notification_data: ReaderEventNotificationData {
                timestamp: Timestamp::Utc(UtcTimestamp {
                    microseconds: utc_us,
                    ..Default::default()
                }),
                connection_attempt_event: Some(ConnectionAttemptEvent {
                    status,
                    ..Default::default()
                }),
                ..Default::default()
            },
            ..Default::default()
        }
    }
}
