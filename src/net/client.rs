//! A small async LLRP client over a [`Connection`]: connect, send typed messages, receive and
//! match responses by message ID. Used by the tests and benchmarks; unsolicited messages
//! (reports, events, keepalives) are queued for the caller.

use std::collections::VecDeque;
use std::io;
use std::time::Duration;

use llrp::message::MessageBody;
use llrp::{Inbound, Message, Request};
use tokio::net::ToSocketAddrs;

use super::connection::Connection;

/// Errors of the client.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// Socket error.
    #[error("i/o: {0}")]
    Io(#[from] io::Error),
    /// The peer sent bytes that are not LLRP.
    #[error("bad frame from peer: {0}")]
    Frame(#[from] llrp::FrameError),
    /// The peer sent a message that does not decode.
    #[error("undecodable message from peer: {0}")]
    Decode(#[from] llrp::DecodeError),
    /// Nothing arrived in time.
    #[error("timed out waiting for {0}")]
    Timeout(&'static str),
    /// The peer closed the connection.
    #[error("connection closed by peer")]
    Closed,
    /// The peer answered a request with another message (e.g. ERROR_MESSAGE).
    #[error("unexpected answer {0}")]
    Unexpected(&'static str),
}

/// An LLRP client connection.
pub struct Client {
    conn: Connection,
    next_id: u32,
    version: u8,
    /// Messages received but not yet taken.
    pending: VecDeque<Message>,
}

impl Client {
    /// Connects to a reader.
    pub async fn connect(addr: impl ToSocketAddrs) -> Result<Client, ClientError> {
        Ok(Client {
            conn: Connection::connect(addr).await?,
            next_id: 1000,
            version: 1,
            pending: VecDeque::new(),
        })
    }

    /// Sets the header version of messages sent from now on.
    pub fn set_version(&mut self, version: u8) {
        self.version = version;
    }

    /// Sends a message with a fresh ID; returns the ID.
    pub async fn send(&mut self, body: impl Into<MessageBody>) -> Result<u32, ClientError> {
        let id = self.next_id;
        self.next_id = self.next_id.wrapping_add(1);
        let m = Message {
            version: self.version,
            id,
            body: body.into(),
        };
        self.conn.write_message(&m).await?;
        Ok(id)
    }

    /// Sends raw bytes (for malformed-input tests).
    pub async fn send_raw(&mut self, bytes: &[u8]) -> Result<(), ClientError> {
        self.conn.write_bytes(bytes).await?;
        Ok(())
    }

    /// The next message from the peer, waiting at most `timeout`.
    pub async fn recv(&mut self, timeout: Duration) -> Result<Message, ClientError> {
        if let Some(m) = self.pending.pop_front() {
            return Ok(m);
        }
        self.read_one(timeout).await
    }

    async fn read_one(&mut self, timeout: Duration) -> Result<Message, ClientError> {
        let frame = self.read_frame(timeout, "a message").await?;
        Ok(Message::decode(&frame)?)
    }

    async fn read_frame(
        &mut self,
        timeout: Duration,
        what: &'static str,
    ) -> Result<bytes::Bytes, ClientError> {
        match tokio::time::timeout(timeout, self.conn.read_frame())
            .await
            .map_err(|_| ClientError::Timeout(what))??
        {
            Some(Inbound::Frame(f)) => Ok(f),
            Some(Inbound::Unsynced(e)) => Err(ClientError::Frame(e)),
            None => Err(ClientError::Closed),
        }
    }

    /// The next frame as raw bytes, whatever its version (for checking what a peer sends to
    /// a version it does not speak).
    pub async fn recv_raw(&mut self, timeout: Duration) -> Result<Vec<u8>, ClientError> {
        Ok(self.read_frame(timeout, "a frame").await?.to_vec())
    }

    /// Sends a request and waits for its response, typed.
    pub async fn transact<R: Request>(
        &mut self,
        request: R,
        timeout: Duration,
    ) -> Result<R::Response, ClientError> {
        let m = self.request(request, timeout).await?;
        let name = m.name();
        R::Response::try_from(m.body).map_err(|_| ClientError::Unexpected(name))
    }

    /// Sends a request and waits for the message answering it (same ID); other messages
    /// arriving meanwhile are kept for [`Client::recv`].
    pub async fn request(
        &mut self,
        body: impl Into<MessageBody>,
        timeout: Duration,
    ) -> Result<Message, ClientError> {
        let id = self.send(body).await?;
        // Reader-initiated messages have their own ID sequence: match the ID on answers only.
        self.wait_for(|m| m.id == id && !is_unsolicited(m), timeout)
            .await
    }

    /// Waits for the first message satisfying `pred`, keeping the others.
    pub async fn wait_for(
        &mut self,
        pred: impl Fn(&Message) -> bool,
        timeout: Duration,
    ) -> Result<Message, ClientError> {
        if let Some(i) = self.pending.iter().position(&pred) {
            return Ok(self.pending.remove(i).expect("index from position"));
        }
        let deadline = tokio::time::Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(tokio::time::Instant::now());
            let m = self.read_one(left).await?;
            if pred(&m) {
                return Ok(m);
            }
            self.pending.push_back(m);
        }
    }

    /// Takes the queued messages.
    pub fn drain_pending(&mut self) -> Vec<Message> {
        self.pending.drain(..).collect()
    }

    /// Closes the sending side and waits (at most `timeout`) for the peer to close too, so
    /// that the peer has seen the close when this returns; messages still arriving meanwhile
    /// are dropped.
    pub async fn close(mut self, timeout: Duration) -> Result<(), ClientError> {
        self.conn.shutdown().await?;
        self.until_closed(timeout).await
    }

    /// Waits (at most `timeout`) until the peer closes the connection, by end-of-stream or a
    /// reset; messages arriving meanwhile are dropped. `Err(Timeout)` if it stays open.
    pub async fn until_closed(&mut self, timeout: Duration) -> Result<(), ClientError> {
        self.pending.clear();
        let deadline = tokio::time::Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(tokio::time::Instant::now());
            match self.read_frame(left, "the peer to close").await {
                Ok(_) => continue,
                Err(ClientError::Closed) => return Ok(()),
                Err(ClientError::Io(e)) if e.kind() == io::ErrorKind::ConnectionReset => {
                    return Ok(())
                }
                Err(e) => return Err(e),
            }
        }
    }
}

/// Whether a message is one a reader sends on its own (reports, events, keepalives).
pub fn is_unsolicited(m: &Message) -> bool {
    matches!(
        m.body,
        MessageBody::RoAccessReport(_)
            | MessageBody::ReaderEventNotification(_)
            | MessageBody::Keepalive(_)
    )
}
