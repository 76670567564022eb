//! A server's LLRP session, sans IO: the connections that come and go, the frames they bring
//! and the time that passes, in; the bytes to send, whether to close, and when to be run
//! next, out. The simulated reader's session and the replay's are sessions; one loop in the
//! application (`net::drive`) serves any session on a socket, and tests drive one with a
//! virtual clock and no sockets.
//!
//! A session owns every connection of its server: it decides who is its client and who is
//! refused (an LLRP reader takes one client at a time), and it speaks to one client at once.

use bytes::BytesMut;
use llrp::Inbound;

/// A connection of a session.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ClientId(u64);

impl ClientId {
    /// The first connection's id.
    pub const FIRST: ClientId = ClientId(0);

    /// The id after this one.
    pub fn next(self) -> ClientId {
        ClientId(self.0.wrapping_add(1))
    }
}

/// What became of a new connection.
#[derive(Debug, PartialEq)]
pub enum Accepted {
    /// It is the session's client now; its greeting, if any, is in [`ServerSession::transmit`].
    Client(ClientId),
    /// The session already has a client: send these bytes (the refusal), then close. What
    /// the connected client is told of it, if anything, is in its transmit buffer.
    Refused(BytesMut),
}

/// What to send to the connected client.
#[derive(Debug)]
pub struct Transmit<'a> {
    /// The client.
    pub to: ClientId,
    /// Encoded messages, whole frames, in order; the caller sends and clears them.
    pub bytes: &'a mut BytesMut,
    /// Close the connection once `bytes` are sent.
    pub close: bool,
}

/// One server's LLRP session, sans IO (see the module's documentation).
pub trait ServerSession {
    /// The time the session runs on (what [`ServerSession::advance`] and the others are given).
    type Now: Copy;
    /// When the session next needs [`ServerSession::advance`], in terms its driver turns into a
    /// wake-up (with its clock).
    type Deadline: Copy;

    /// A connection arrived at `now`.
    fn connect(&mut self, now: Self::Now) -> Accepted;
    /// What connection `id` received, at `now`.
    fn receive(&mut self, id: ClientId, inbound: Inbound, now: Self::Now);
    /// Runs the session up to `now`: what falls due is added to its output.
    fn advance(&mut self, now: Self::Now);
    /// What to send to the connected client now, if anything.
    fn transmit(&mut self) -> Option<Transmit<'_>>;
    /// Bytes waiting for the connected client.
    fn pending(&self) -> usize;
    /// When the session next needs [`ServerSession::advance`] if nothing arrives before.
    fn deadline(&self) -> Self::Deadline;
    /// Connection `id` is gone (closed by the peer, or after the session asked to close it).
    fn disconnect(&mut self, id: ClientId);
    /// The server is stopping: the client is told as the session's server tells it, and
    /// closed.
    fn shutdown(&mut self);
}
