//! The hub, and the server against tokio-tungstenite's client: a stalled client dropped, one
//! client too many refused.

use super::*;
use crate::record::mcap::McapOut;

#[test]
fn a_channel_is_advertised_once_and_a_client_behind_the_backlog_skips_messages() {
    let hub = Hub::new(Limits {
        backlog: 2,
        ..Limits::default()
    });
    let (before, mut rx) = hub.join();
    assert!(before.is_empty());
    let mut out = McapOut::tap_only(hub.tap()).expect("starts");
    for i in 0..3 {
        out.event("r", 1, "connect", "", i, i).expect("written");
    }
    // Two channels (/llrp/r/events, /log), each advertised once, ids from 1.
    let channels = hub.channels();
    let topics: Vec<(u32, &str)> = channels.iter().map(|c| (c.id, c.topic.as_str())).collect();
    assert_eq!(topics, [(1, "/llrp/r/events"), (2, "/log")]);
    assert_eq!(channels[0].schema_name, "llrp_gateway_msgs/msg/ReaderEvent");
    assert!(channels[0].schema.contains("MSG: std_msgs/msg/Header"));
    // 2 adverts + 6 messages through a queue of 2: the receiver is told what it missed.
    match rx.try_recv() {
        Err(broadcast::error::TryRecvError::Lagged(n)) => assert_eq!(n, 6),
        other => panic!("expected a lag, got {other:?}"),
    }
    assert!(matches!(
        rx.try_recv(),
        Ok(Event::Message(Latest {
            channel: 1,
            log_ns: 2,
            ..
        }))
    ));
    assert!(matches!(
        rx.try_recv(),
        Ok(Event::Message(Latest {
            channel: 2,
            log_ns: 2,
            ..
        }))
    ));
    // Each channel's latest message is kept for new subscribers.
    assert_eq!(hub.latest(1).map(|l| (l.seq, l.log_ns)), Some((5, 2)));
    assert_eq!(hub.latest(2).map(|l| l.seq), Some(6));
    // A client joining now gets both channels in the list, none twice.
    assert_eq!(hub.join().0.len(), 2);
}

/// A client of `server` (tokio-tungstenite's) offering `foxglove.websocket.v1`; the
/// handshake's error when refused.
async fn connect(
    server: &LiveServer,
) -> Result<
    tokio_tungstenite::WebSocketStream<tokio::net::TcpStream>,
    tokio_tungstenite::tungstenite::Error,
> {
    use tokio_tungstenite::tungstenite::client::IntoClientRequest;
    let tcp = tokio::net::TcpStream::connect(server.local_addr())
        .await
        .expect("connects");
    let mut req = format!("ws://{}/", server.local_addr())
        .into_client_request()
        .expect("a request");
    let protocol = proto::SUBPROTOCOL.parse().expect("a header value");
    req.headers_mut().insert("sec-websocket-protocol", protocol);
    tokio_tungstenite::client_async(req, tcp)
        .await
        .map(|(ws, _)| ws)
}

/// A client of `server` once one is accepted (a slot comes free when a client's task has
/// ended), at most [`GUARD`] from now.
async fn connect_when_free(
    server: &LiveServer,
) -> tokio_tungstenite::WebSocketStream<tokio::net::TcpStream> {
    let end = tokio::time::Instant::now() + GUARD;
    loop {
        if let Ok(ws) = connect(server).await {
            return ws;
        }
        assert!(
            tokio::time::Instant::now() < end,
            "the slot never came free"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// The next text message of `ws`, parsed.
async fn next_json(
    ws: &mut tokio_tungstenite::WebSocketStream<tokio::net::TcpStream>,
) -> serde_json::Value {
    use futures_util::StreamExt;
    loop {
        let m = tokio::time::timeout(GUARD, ws.next())
            .await
            .expect("a message in time")
            .expect("open")
            .expect("a message");
        if let tokio_tungstenite::tungstenite::Message::Text(t) = m {
            return serde_json::from_str(t.as_str()).expect("JSON");
        }
    }
}

/// Longest a wait below may take (a hang guard, not a measurement).
const GUARD: Duration = Duration::from_secs(30);

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stalled_client_is_dropped_while_the_writer_never_waits() {
    use futures_util::SinkExt;
    let limits = Limits {
        max_clients: 1,
        backlog: 64,
        send_timeout: Duration::from_millis(300),
    };
    let server = LiveServer::bind_with("127.0.0.1:0", limits)
        .await
        .expect("listens");
    let mut out = McapOut::tap_only(server.tap()).expect("starts");
    out.event("r", 1, "connect", "", 1, 1).expect("written");
    let mut ws = connect(&server).await.expect("accepted");
    assert_eq!(next_json(&mut ws).await["op"], "serverInfo");
    let adv = next_json(&mut ws).await;
    assert_eq!(adv["channels"][0]["topic"], "/llrp/r/events");
    let sub = r#"{"op":"subscribe","subscriptions":[{"id":7,"channelId":1}]}"#;
    ws.send(tokio_tungstenite::tungstenite::Message::text(sub))
        .await
        .expect("sent");
    // The client reads nothing more: 64 KiB events until its socket is full and the server
    // drops it; every write returns at once all the same (this task never waits on it).
    let detail = "x".repeat(64 * 1024);
    let hub = server.hub().clone();
    let mut written = 0u64;
    while hub.stats.dropped.load(Ordering::Relaxed) == 0 {
        for _ in 0..50 {
            written += 1;
            out.event("r", 1, "report", &detail, written, written)
                .expect("written");
        }
        assert!(written < 1_000_000, "the stalled client was never dropped");
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    // Its slot (the only one) is free again: another client is served.
    let mut again = connect_when_free(&server).await;
    assert_eq!(next_json(&mut again).await["op"], "serverInfo");
    drop(ws);
    server.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn one_client_more_than_the_limit_is_refused_with_503_until_one_leaves() {
    let limits = Limits {
        max_clients: 1,
        ..Limits::default()
    };
    let server = LiveServer::bind_with("127.0.0.1:0", limits)
        .await
        .expect("listens");
    let mut first = connect(&server).await.expect("accepted");
    assert_eq!(next_json(&mut first).await["op"], "serverInfo");
    match connect(&server).await {
        Err(tokio_tungstenite::tungstenite::Error::Http(r)) => assert_eq!(r.status(), 503),
        other => panic!("expected HTTP 503, got {:?}", other.map(|_| "a WebSocket")),
    }
    assert_eq!(server.hub().stats.refused.load(Ordering::Relaxed), 1);
    drop(first);
    // Its task ends once it sees the connection gone; a new client is served then.
    let end = tokio::time::Instant::now() + GUARD;
    let mut ws = loop {
        if let Ok(ws) = connect(&server).await {
            break ws;
        }
        assert!(
            tokio::time::Instant::now() < end,
            "the slot never came free"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    };
    assert_eq!(next_json(&mut ws).await["op"], "serverInfo");
    server.shutdown().await;
}
