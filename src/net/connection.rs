//! One framed LLRP connection: a stream (plain TCP or TLS, [`Stream`]), a bounded read buffer
//! (the codec's [`Deframer`]) and a write buffer. Reads whole frames and writes encoded
//! messages; it decodes nothing, so the reader's server, the LLRP client and a byte-exact proxy
//! share it.

use std::io;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::{Mutex, PoisonError};
use std::task::{Context, Poll};

use bytes::{Buf, BytesMut};
use llrp::{Deframer, FrameSplitter, Message};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt, ReadBuf};
use tokio::net::TcpStream;

pub use super::stream::Stream;
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

/// A stream (TCP or TLS) carrying LLRP frames.
#[derive(Debug)]
pub struct Connection {
    stream: Stream,
    read: Deframer,
    write: BytesMut,
    /// TLS only: bytes were handed to TLS since its last flush, so encrypted records may still
    /// wait inside rustls for the socket.
    unflushed: bool,
}

/// What the write side does during one turn of [`Connection::read_or_flush`].
#[derive(Clone, Copy, PartialEq, Eq)]
enum Want {
    /// Only read.
    Read,
    /// Also write from the write buffer.
    Write,
    /// Also push the records TLS still holds to the socket.
    Flush,
}

/// What one turn of [`Connection::read_or_flush`] did.
enum Step {
    /// Read this many bytes into the read buffer (0: end of stream).
    Read(usize),
    /// Wrote this many bytes of the write buffer.
    Wrote(usize),
    /// TLS has no record left to send.
    Flushed,
}

impl Connection {
    /// Wraps a connected TCP stream with the codec's default frame limit (4 MiB); sets
    /// TCP_NODELAY, since LLRP requests and responses are small and latency-bound.
    pub fn new(stream: TcpStream) -> Self {
        Self::with_splitter(stream, FrameSplitter::default())
    }

    /// Wraps a connected stream, plain or TLS (after its handshake), with the codec's default
    /// frame limit; sets TCP_NODELAY.
    pub fn from_stream(stream: impl Into<Stream>) -> Self {
        Self::with_splitter(stream, FrameSplitter::default())
    }

    /// Wraps a connected stream with the given frame limits.
    pub fn with_splitter(stream: impl Into<Stream>, splitter: FrameSplitter) -> Self {
        let stream = stream.into();
        // Best effort: without it the connection still works, only with Nagle's delay.
        let _ = stream.set_nodelay(true);
        Connection {
            stream,
            read: Deframer::new(splitter),
            write: BytesMut::new(),
            unflushed: false,
        }
    }

    /// Connects to `addr` (plain TCP).
    pub async fn connect(addr: impl tokio::net::ToSocketAddrs) -> io::Result<Self> {
        Ok(Self::new(TcpStream::connect(addr).await?))
    }

    /// The peer's address.
    pub fn peer_addr(&self) -> io::Result<SocketAddr> {
        self.stream.peer_addr()
    }

    /// Whether the connection runs over TLS.
    pub fn is_tls(&self) -> bool {
        self.stream.is_tls()
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
    /// at the end of the stream, or once the write buffer has been sent. Over TLS, records
    /// that TLS still holds from earlier writes are pushed to the socket in any case.
    ///
    /// Cancel-safe: bytes read stay buffered, bytes not yet written stay queued. Each turn
    /// polls one read and at most one write (or TLS flush) of the same stream in this task,
    /// and applies what finished before the next await: a cancelled turn has done nothing
    /// that is not recorded. Over TCP the two are the borrowed halves of
    /// [`TcpStream::split`]; over TLS both must drive one TLS state, so they share it behind a
    /// [`Mutex`] that lives for the turn and is held only inside a single poll. As both are
    /// polled by this task, it is never contended, and whichever side TLS makes wait (a read
    /// may have to write, and a write to read) wakes this same task.
    pub async fn read_or_flush(&mut self, flush: bool) -> io::Result<Io> {
        let asked = flush && (!self.write.is_empty() || self.unflushed);
        loop {
            if let Some(inbound) = self.read.next_frame() {
                return Ok(Io::Frame(inbound));
            }
            let want = if asked && !self.write.is_empty() {
                Want::Write
            } else if self.unflushed {
                Want::Flush
            } else {
                Want::Read
            };
            let read = self.read.buffer_mut();
            let step = if let Stream::Tcp(s) = &mut self.stream {
                let (rd, wr) = s.split();
                turn(rd, wr, read, &self.write, want).await?
            } else {
                let shared = Mutex::new(&mut self.stream);
                turn(Shared(&shared), Shared(&shared), read, &self.write, want).await?
            };
            match step {
                Step::Read(0) => return self.end_of_stream().map(|()| Io::Closed),
                Step::Read(_) => {}
                Step::Wrote(0) => return Err(io::ErrorKind::WriteZero.into()),
                Step::Wrote(n) => {
                    self.write.advance(n);
                    self.unflushed = self.stream.is_tls();
                    if self.write.is_empty() && !self.unflushed {
                        return Ok(Io::Flushed);
                    }
                }
                Step::Flushed => {
                    self.unflushed = false;
                    if asked && self.write.is_empty() {
                        return Ok(Io::Flushed);
                    }
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

    /// Sends everything in the write buffer (over TLS, to the socket: TLS is flushed too).
    ///
    /// Cancel-safe in the sense that bytes not yet written stay queued.
    pub async fn flush(&mut self) -> io::Result<()> {
        while self.write.has_remaining() {
            let n = self.stream.write(&self.write).await?;
            if n == 0 {
                return Err(io::ErrorKind::WriteZero.into());
            }
            self.write.advance(n);
            self.unflushed = self.stream.is_tls();
        }
        if self.unflushed {
            self.stream.flush().await?;
            self.unflushed = false;
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

    /// Drops the connection at once: what is queued is lost, and the peer gets a TCP reset
    /// (SO_LINGER 0) rather than an orderly end.
    pub fn reset(self) {
        // Best effort: without it the peer gets an orderly end of stream instead.
        let _ = self.stream.tcp().set_zero_linger();
        drop(self);
    }

    /// Sends what is queued, then closes the sending side (over TLS with a close_notify
    /// first).
    pub async fn shutdown(&mut self) -> io::Result<()> {
        self.flush().await?;
        self.stream.shutdown().await
    }
}

/// One turn of [`Connection::read_or_flush`]: the first of a read into `read` and, as `want`
/// says, a write of `write` or a flush. Each branch is cancel-safe on its own.
async fn turn<R, W>(
    mut rd: R,
    mut wr: W,
    read: &mut BytesMut,
    write: &[u8],
    want: Want,
) -> io::Result<Step>
where
    R: AsyncRead + Unpin,
    W: AsyncWrite + Unpin,
{
    // One await each, so each branch is as cancel-safe as the call it awaits.
    let out = async {
        match want {
            Want::Write => wr.write(write).await.map(Step::Wrote),
            Want::Flush => wr.flush().await.map(|()| Step::Flushed),
            Want::Read => std::future::pending().await,
        }
    };
    tokio::select! {
        biased;
        n = rd.read_buf(read) => Ok(Step::Read(n?)),
        r = out => r,
    }
}

/// One of the two handles [`Connection::read_or_flush`] makes on a TLS stream: each poll
/// locks the stream for the length of that poll only.
struct Shared<'a, 's, S>(&'a Mutex<&'s mut S>);

impl<S> Shared<'_, '_, S> {
    /// Runs `f` on the stream. The lock is never contended (both handles are polled by one
    /// task, one after the other); a poisoned lock (a panic inside a poll) still holds a
    /// stream whose own state says what it can do, so it is used as it is.
    fn with<T>(&self, f: impl FnOnce(Pin<&mut S>) -> T) -> T
    where
        S: Unpin,
    {
        let mut s = self.0.lock().unwrap_or_else(PoisonError::into_inner);
        f(Pin::new(&mut **s))
    }
}

impl<S: AsyncRead + Unpin> AsyncRead for Shared<'_, '_, S> {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        self.with(|s| s.poll_read(cx, buf))
    }
}

impl<S: AsyncWrite + Unpin> AsyncWrite for Shared<'_, '_, S> {
    fn poll_write(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        self.with(|s| s.poll_write(cx, buf))
    }

    fn poll_flush(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        self.with(|s| s.poll_flush(cx))
    }

    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        self.with(|s| s.poll_shutdown(cx))
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
