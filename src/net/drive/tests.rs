//! The loop with a toy session over real sockets.

use super::*;
use bytes::BytesMut;
use tokio::io::AsyncReadExt;
use tokio::net::TcpStream;

/// A session that greets its one client with "hi", refuses others with "no", echoes each
/// frame's length as one byte, and says "bye" at the stop.
#[derive(Default)]
struct Echo {
    client: Option<ClientId>,
    next: Option<ClientId>,
    out: BytesMut,
    close: bool,
}

impl ServerSession for Echo {
    type Now = ();
    type Deadline = ();

    fn connect(&mut self, _: ()) -> Accepted {
        if self.client.is_some() {
            return Accepted::Refused(BytesMut::from(&b"no"[..]));
        }
        let id = self.next.unwrap_or(ClientId::FIRST);
        self.next = Some(id.next());
        self.client = Some(id);
        self.out.extend_from_slice(b"hi");
        Accepted::Client(id)
    }
    fn receive(&mut self, _: ClientId, inbound: llrp::Inbound, _: ()) {
        if let llrp::Inbound::Frame(f) = inbound {
            self.out.extend_from_slice(&[f.len() as u8]);
        }
    }
    fn advance(&mut self, _: ()) {}
    fn transmit(&mut self) -> Option<llrp_gateway_vocab::session::Transmit<'_>> {
        let to = self.client?;
        (!self.out.is_empty() || self.close).then_some(llrp_gateway_vocab::session::Transmit {
            to,
            bytes: &mut self.out,
            close: self.close,
        })
    }
    fn pending(&self) -> usize {
        self.out.len()
    }
    fn deadline(&self) {}
    fn disconnect(&mut self, id: ClientId) {
        if self.client == Some(id) {
            self.client = None;
            self.close = false;
        }
    }
    fn shutdown(&mut self) {
        self.out.extend_from_slice(b"bye");
        self.close = true;
    }
}

struct EchoHost(Echo);

impl Host for EchoHost {
    type Session = Echo;
    fn session_mut(&mut self) -> &mut Echo {
        &mut self.0
    }
    fn now(&self) {}
    fn wake_at(&self) -> Option<Instant> {
        None
    }
    fn utc_now_us(&self) -> u64 {
        0
    }
    fn inventorying(&self) -> bool {
        false
    }
}

async fn read_n(s: &mut TcpStream, n: usize) -> Vec<u8> {
    let mut buf = vec![0u8; n];
    s.read_exact(&mut buf).await.expect("reads");
    buf
}

#[tokio::test]
async fn the_session_decides_who_is_served_and_says_its_last_words_at_the_stop() {
    let listener = TcpListener::bind("127.0.0.1:0").await.expect("binds");
    let addr = listener.local_addr().expect("bound");
    let (stop, shutdown) = watch::channel(false);
    let limits = Limits {
        handshakes: 1,
        refusals: 1,
        refusal_write: Duration::from_secs(1),
        close_flush: Duration::from_secs(1),
    };
    let server = tokio::spawn(drive(
        listener,
        None,
        EchoHost(Echo::default()),
        Wire::default(),
        limits,
        shutdown,
    ));
    let mut first = TcpStream::connect(addr).await.expect("connects");
    assert_eq!(read_n(&mut first, 2).await, b"hi");
    // A second connection gets the session's refusal and is closed.
    let mut second = TcpStream::connect(addr).await.expect("connects");
    let mut refused = Vec::new();
    second.read_to_end(&mut refused).await.expect("reads");
    assert_eq!(refused, b"no");
    // The first is served on: a 10-byte LLRP frame (a KEEPALIVE_ACK) is answered.
    let ack = llrp::Message::new(1, llrp::message::KeepaliveAck::default()).to_bytes();
    tokio::io::AsyncWriteExt::write_all(&mut first, &ack)
        .await
        .expect("writes");
    assert_eq!(read_n(&mut first, 1).await, [ack.len() as u8]);
    // At the stop the client is told, then closed.
    stop.send(true).expect("the loop listens");
    let mut last = Vec::new();
    first.read_to_end(&mut last).await.expect("reads");
    assert_eq!(last, b"bye");
    server.await.expect("joins").expect("serves");
}
