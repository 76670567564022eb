//! The messages of Foxglove's WebSocket protocol (`foxglove.websocket.v1`,
//! <https://github.com/foxglove/ws-protocol/blob/main/docs/spec.md>) that this server sends
//! and takes: server info, status, advertise, message data; subscribe and unsubscribe.

use serde::Deserialize;
use serde_json::json;

use super::LiveChannel;

/// The WebSocket subprotocol.
pub const SUBPROTOCOL: &str = "foxglove.websocket.v1";

/// The binary opcode of a Message Data frame.
const MESSAGE_DATA: u8 = 0x01;

/// A status message's level.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Level {
    /// Information.
    Info = 0,
    /// Something the client did was not taken, or messages were dropped.
    Warning = 1,
    /// A request was refused.
    Error = 2,
}

/// The Server Info message: no optional capability (no client publishing, parameters,
/// services, time).
pub fn server_info(session: &str) -> String {
    json!({
        "op": "serverInfo",
        "name": format!("llrp-gateway {}", env!("CARGO_PKG_VERSION")),
        "capabilities": [],
        "metadata": {},
        "sessionId": session,
    })
    .to_string()
}

/// A Status message.
pub fn status(level: Level, message: &str) -> String {
    json!({"op": "status", "level": level as u8, "message": message}).to_string()
}

/// An Advertise message for `channels` (the schema is the `ros2msg` text itself).
pub fn advertise<'a>(channels: impl IntoIterator<Item = &'a LiveChannel>) -> String {
    let channels: Vec<_> = channels
        .into_iter()
        .map(|c| {
            json!({
                "id": c.id,
                "topic": c.topic,
                "encoding": c.encoding,
                "schemaName": c.schema_name,
                "schema": &*c.schema,
                "schemaEncoding": c.schema_encoding,
            })
        })
        .collect();
    json!({"op": "advertise", "channels": channels}).to_string()
}

/// A Message Data frame: opcode, subscription id and log time (little-endian), the message.
pub fn message_data(subscription: u32, log_ns: u64, data: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(13 + data.len());
    out.push(MESSAGE_DATA);
    out.extend_from_slice(&subscription.to_le_bytes());
    out.extend_from_slice(&log_ns.to_le_bytes());
    out.extend_from_slice(data);
    out
}

/// One subscription a client asks for.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "camelCase")]
pub struct Subscription {
    /// The client's id for it.
    pub id: u32,
    /// The channel.
    pub channel_id: u32,
}

/// What a client may ask.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Request {
    /// Subscribe to channels.
    Subscribe(Vec<Subscription>),
    /// End subscriptions.
    Unsubscribe(Vec<u32>),
}

/// The fields of the requests taken (any other field is ignored, as the spec allows).
#[derive(Deserialize)]
#[serde(tag = "op", rename_all = "camelCase")]
enum Wire {
    Subscribe {
        subscriptions: Vec<Subscription>,
    },
    #[serde(rename_all = "camelCase")]
    Unsubscribe {
        subscription_ids: Vec<u32>,
    },
}

/// Parses a client's text message; the error says what is wrong, for a status message.
pub fn request(text: &str) -> Result<Request, String> {
    let v: serde_json::Value = serde_json::from_str(text).map_err(|e| format!("not JSON: {e}"))?;
    let op = match v.get("op").and_then(|o| o.as_str()) {
        Some(op) => op.to_string(),
        None => return Err("a JSON object with a string \"op\" was expected".into()),
    };
    if op != "subscribe" && op != "unsubscribe" {
        return Err(format!("op {op:?} is not supported by this server"));
    }
    match serde_json::from_value(v) {
        Ok(Wire::Subscribe { subscriptions }) => Ok(Request::Subscribe(subscriptions)),
        Ok(Wire::Unsubscribe { subscription_ids }) => Ok(Request::Unsubscribe(subscription_ids)),
        Err(e) => Err(format!("{op}: {e}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn subscribe_and_unsubscribe_parse_and_anything_else_says_why_not() {
        assert_eq!(
            request(r#"{"op":"subscribe","subscriptions":[{"id":0,"channelId":3}]}"#),
            Ok(Request::Subscribe(vec![Subscription {
                id: 0,
                channel_id: 3
            }]))
        );
        assert_eq!(
            request(r#"{"op":"unsubscribe","subscriptionIds":[0,7]}"#),
            Ok(Request::Unsubscribe(vec![0, 7]))
        );
        let e = request("{nope").expect_err("not JSON");
        assert!(e.starts_with("not JSON"), "{e}");
        let e = request(r#"{"op":"setParameters","parameters":[]}"#).expect_err("unsupported");
        assert!(e.contains("setParameters"), "{e}");
        let e = request(r#"[1,2]"#).expect_err("no op");
        assert!(e.contains("\"op\""), "{e}");
        let e = request(r#"{"op":"subscribe","subscriptions":[{"id":-1,"channelId":3}]}"#)
            .expect_err("a negative id");
        assert!(e.starts_with("subscribe: "), "{e}");
    }

    #[test]
    fn a_message_data_frame_is_opcode_subscription_and_log_time_little_endian() {
        let f = message_data(0x0102_0304, 0x1122_3344_5566_7788, b"cdr");
        assert_eq!(
            f,
            [1, 4, 3, 2, 1, 0x88, 0x77, 0x66, 0x55, 0x44, 0x33, 0x22, 0x11, b'c', b'd', b'r']
        );
    }
}
