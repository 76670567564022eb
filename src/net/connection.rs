//! One framed LLRP connection: a TCP stream, a bounded read buffer (the codec's [`Deframer`])
//! and a write buffer. Reads whole frames and writes encoded messages; it decodes nothing, so
//! the reader's server, the LLRP client and a byte-exact proxy share it.

use std::io;
use std::net::SocketAddr;

use bytes::{Buf, BytesMut};
use llrp::{Deframer, FrameSplitter, Message};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

pub use llrp::Inbound;

/// What [`Connection::read_or_flush`] saw first.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Io {
    /// A frame arrived.
    Frame(Inbound),
    /// The peer closed the stream between frames.
    Closed,
    /// Everything queued has been sent.
    Flushed,
}

/// A TCP stream carrying LLRP frames.
#[derive(Debug)]
pub struct Connection {
    stream: TcpStream,
    read: Deframer,
    write: BytesMut,
}

impl Connection {
    /// Wraps a connected stream with the codec's default frame limit (4 MiB); sets TCP_NODELAY,
    /// since LLRP requests and responses are small and latency-bound.
    pub fn new(stream: TcpStream) -> Self {
        Self::with_splitter(stream, FrameSplitter::default())
    }

    /// Wraps a connected stream with the given frame limits.
    pub fn with_splitter(stream: TcpStream, splitter: FrameSplitter) -> Self {
        // Best effort: without it the connection still works, only with Nagle's delay.
        let _ = stream.set_nodelay(true);
        Connection {
            stream,
            read: Deframer::new(splitter),
            write: BytesMut::new(),
        }
    }

    /// Connects to `addr`.
    pub async fn connect(addr: impl tokio::net::ToSocketAddrs) -> io::Result<Self> {
        Ok(Self::new(TcpStream::connect(addr).await?))
    }

    /// The peer's address.
    pub fn peer_addr(&self) -> io::Result<SocketAddr> {
        self.stream.peer_addr()
    }

    /// The next frame (or the framing error that ended the stream); `Ok(None)` once the peer
    /// has closed cleanly between frames.
    ///
    /// Cancel-safe: bytes read before a cancellation stay buffered for the next call.
    pub async fn read_frame(&mut self) -> io::Result<Option<Inbound>> {
        loop {
            if let Some(inbound) = self.read.next_frame() {
                return Ok(Some(inbound));
            }
            if self.stream.read_buf(self.read.buffer_mut()).await? == 0 {
                return self.end_of_stream().map(|()| None);
            }
        }
    }

    /// The next frame while sending what is queued (when `flush` is set): returns on a frame,
    /// at the end of the stream, or once the write buffer has been sent.
    ///
    /// Cancel-safe: bytes read stay buffered, bytes not yet written stay queued.
    pub async fn read_or_flush(&mut self, flush: bool) -> io::Result<Io> {
        let mut flush = flush && !self.write.is_empty();
        loop {
            if let Some(inbound) = self.read.next_frame() {
                return Ok(Io::Frame(inbound));
            }
            let (mut rd, mut wr) = self.stream.split();
            tokio::select! {
                biased;
                n = rd.read_buf(self.read.buffer_mut()) => {
                    if n? == 0 {
                        return self.end_of_stream().map(|()| Io::Closed);
                    }
                }
                n = wr.write(&self.write), if flush => {
                    let n = n?;
                    if n == 0 {
                        return Err(io::ErrorKind::WriteZero.into());
                    }
                    self.write.advance(n);
                    if self.write.is_empty() {
                        return Ok(Io::Flushed);
                    }
                    flush = true;
                }
            }
        }
    }

    /// `Ok` if the peer closed between frames, an error if in the middle of one.
    fn end_of_stream(&self) -> io::Result<()> {
        let left = self.read.buffered();
        if left == 0 {
            Ok(())
        } else {
            Err(io::Error::new(
                io::ErrorKind::UnexpectedEof,
                format!("peer closed in the middle of a frame ({left} bytes)"),
            ))
        }
    }

    /// Appends an encoded message to the write buffer (sent by [`Connection::flush`]).
    pub fn queue(&mut self, message: &Message) {
        message.encode(&mut self.write);
    }

    /// Appends raw bytes to the write buffer (sent by [`Connection::flush`]).
    pub fn queue_bytes(&mut self, bytes: &[u8]) {
        self.write.extend_from_slice(bytes);
    }

    /// Moves `bytes` to the end of the write buffer, leaving `bytes` empty (without copying
    /// when nothing else is queued: the two buffers are swapped).
    pub fn queue_buf(&mut self, bytes: &mut BytesMut) {
        if self.write.is_empty() {
            std::mem::swap(&mut self.write, bytes);
        } else {
            self.write.extend_from_slice(bytes);
            bytes.clear();
        }
    }

    /// Bytes waiting in the write buffer.
    pub fn queued(&self) -> usize {
        self.write.len()
    }

    /// Sends everything in the write buffer.
    ///
    /// Cancel-safe in the sense that bytes not yet written stay queued.
    pub async fn flush(&mut self) -> io::Result<()> {
        while self.write.has_remaining() {
            let n = self.stream.write(&self.write).await?;
            if n == 0 {
                return Err(io::ErrorKind::WriteZero.into());
            }
            self.write.advance(n);
        }
        Ok(())
    }

    /// Sends one message now (after anything already queued).
    pub async fn write_message(&mut self, message: &Message) -> io::Result<()> {
        self.queue(message);
        self.flush().await
    }

    /// Sends raw bytes now (after anything already queued).
    pub async fn write_bytes(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.queue_bytes(bytes);
        self.flush().await
    }

    /// Sends what is queued, then closes the sending side.
    pub async fn shutdown(&mut self) -> io::Result<()> {
        self.flush().await?;
        self.stream.shutdown().await
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use llrp::message::KeepaliveAck;
    use tokio::net::TcpListener;

    async fn pair() -> (Connection, TcpStream) {
        let l = TcpListener::bind("127.0.0.1:0")
            .await
            .expect("bind loopback");
        let addr = l.local_addr().expect("bound");
        let (a, b) = tokio::join!(TcpStream::connect(addr), l.accept());
        (Connection::new(a.expect("connect")), b.expect("accept").0)
    }

    #[tokio::test]
    async fn frames_split_across_writes_come_out_whole_and_byte_exact() {
        let (mut conn, mut peer) = pair().await;
        let one = Message::new(5, KeepaliveAck::default()).to_bytes();
        let mut two = one.clone();
        two[0] = 0x08; // header version 2, as an LLRP 1.1 peer sends
        let mut wire = one.to_vec();
        wire.extend_from_slice(&two);
        peer.write_all(&wire[..3]).await.expect("write");
        peer.write_all(&wire[3..15]).await.expect("write");
        peer.write_all(&wire[15..]).await.expect("write");
        peer.shutdown().await.expect("shutdown");
        let got = conn.read_frame().await.expect("read");
        assert_eq!(got, Some(Inbound::Frame(one.freeze())));
        let got = conn.read_frame().await.expect("read");
        assert_eq!(got, Some(Inbound::Frame(two.freeze())));
        assert_eq!(conn.read_frame().await.expect("clean end"), None);
    }

    #[tokio::test]
    async fn a_length_below_the_header_leaves_the_stream_unsynced() {
        let (mut conn, mut peer) = pair().await;
        peer.write_all(&[0x04, 0x48, 0, 0, 0, 4, 0, 0, 0, 9, 0xAA])
            .await
            .expect("write");
        for _ in 0..2 {
            match conn.read_frame().await.expect("read") {
                Some(Inbound::Unsynced(llrp::FrameError::TooShort { len: 4, id: 9, .. })) => {}
                other => panic!("expected TooShort, got {other:?}"),
            }
        }
    }

    #[tokio::test]
    async fn an_unsupported_version_is_still_a_whole_frame() {
        let (mut conn, mut peer) = pair().await;
        let mut m = Message::new(3, KeepaliveAck::default()).to_bytes();
        m[0] = (m[0] & 0xE3) | (5 << 2); // header version 5
        peer.write_all(&m).await.expect("write");
        assert_eq!(
            conn.read_frame().await.expect("read"),
            Some(Inbound::Frame(m.freeze()))
        );
    }

    #[tokio::test]
    async fn a_frame_cut_by_the_peer_is_an_error_not_a_clean_end() {
        let (mut conn, mut peer) = pair().await;
        let m = Message::new(3, KeepaliveAck::default()).to_bytes();
        peer.write_all(&m[..7]).await.expect("write");
        peer.shutdown().await.expect("shutdown");
        let e = conn.read_frame().await.expect_err("truncated");
        assert_eq!(e.kind(), io::ErrorKind::UnexpectedEof);
    }
}
