//! A small async LLRP client: connect, send typed messages, receive and match responses by
//! message ID. Used by the tests and the gateway; unsolicited messages (reports, events,
//! keepalives) are queued for the caller.

use std::collections::VecDeque;
use std::io;
use std::time::Duration;

use bytes::BytesMut;
use llrp::message::MessageBody;
use llrp::{FrameSplitter, Message, Split};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpStream, ToSocketAddrs};

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
}

/// An LLRP client connection.
pub struct Client {
    stream: TcpStream,
    buf: BytesMut,
    splitter: FrameSplitter,
    next_id: u32,
    version: u8,
    /// Messages received but not yet taken.
    pending: VecDeque<Message>,
}

impl Client {
    /// Connects to a reader.
    pub async fn connect(addr: impl ToSocketAddrs) -> Result<Client, ClientError> {
        let stream = TcpStream::connect(addr).await?;
        stream.set_nodelay(true)?;
        Ok(Client {
            stream,
            buf: BytesMut::with_capacity(64 * 1024),
            splitter: FrameSplitter::default(),
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
        self.stream.write_all(&m.to_bytes()).await?;
        Ok(id)
    }

    /// Sends raw bytes (for malformed-input tests).
    pub async fn send_raw(&mut self, bytes: &[u8]) -> Result<(), ClientError> {
        self.stream.write_all(bytes).await?;
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
        let deadline = tokio::time::Instant::now() + timeout;
        loop {
            if let Split::Frame(h) = self.splitter.split(&self.buf)? {
                let frame = self.buf.split_to(h.length as usize);
                return Ok(Message::decode(&frame)?);
            }
            let n = tokio::time::timeout_at(deadline, self.stream.read_buf(&mut self.buf))
                .await
                .map_err(|_| ClientError::Timeout("a message"))??;
            if n == 0 {
                return Err(ClientError::Closed);
            }
        }
    }

    /// The next frame as raw bytes, whatever its version (for checking what a peer sends to
    /// a version it does not speak).
    pub async fn recv_raw(&mut self, timeout: Duration) -> Result<Vec<u8>, ClientError> {
        let deadline = tokio::time::Instant::now() + timeout;
        loop {
            if let Some(h) = llrp::FrameHeader::peek(&self.buf) {
                let len = (h.length as usize).max(llrp::frame::HEADER_LEN);
                if self.buf.len() >= len {
                    return Ok(self.buf.split_to(len).to_vec());
                }
            }
            let n = tokio::time::timeout_at(deadline, self.stream.read_buf(&mut self.buf))
                .await
                .map_err(|_| ClientError::Timeout("a frame"))??;
            if n == 0 {
                return Err(ClientError::Closed);
            }
        }
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

    /// Closes the connection.
    pub async fn close(mut self) -> Result<(), ClientError> {
        self.stream.shutdown().await?;
        Ok(())
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
