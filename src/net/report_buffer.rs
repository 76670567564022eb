//! The simulated reader's report buffer: what it has sent waits in the connection's write
//! queue while the client does not read, up to [`REPORT_BUFFER_BYTES`]. Past that, the
//! RO_ACCESS_REPORTs of the moment are dropped (responses and events never are: a client
//! must get its answers), and the client is told as LLRP defines it: a
//! ReportBufferOverflowErrorEvent (mandatory), and before that a ReportBufferLevelWarningEvent
//! at [`WARN_PERCENT`] when the client enabled it. Sans-IO: it sees the bytes queued and the
//! frames to send, and says what goes out (`docs/simulator.md`, "The report buffer").

use bytes::BytesMut;
use llrp::message::MessageDef as _;

/// The report buffer's size: queued bytes past which reports are dropped. Impinj publishes no
/// figure; a megabyte holds about 15,000 one-tag reports, minutes of a busy reader's output
/// for a client that reads late, and bounds the memory a stalled client costs.
pub const REPORT_BUFFER_BYTES: usize = 1 << 20;

/// Fill level of the ReportBufferLevelWarningEvent.
pub const WARN_PERCENT: u8 = 75;

/// Fill level under which a warning or an overflow may be reported again.
const REARM_PERCENT: usize = 50;

/// The state of one connection's report buffer.
#[derive(Debug)]
pub struct ReportBuffer {
    limit: usize,
    warned: bool,
    overflowed: bool,
    /// Reports and tag reads dropped since the buffer last overflowed.
    dropped: (u64, u64),
}

/// What goes out of one [`ReportBuffer::admit`].
#[derive(Debug, Default)]
pub struct Admitted {
    /// The frames to send (reports that fit, every other frame).
    pub bytes: BytesMut,
    /// A warning is due, at this fill level (percent).
    pub warn: Option<u8>,
    /// The buffer has just overflowed: reports were dropped.
    pub overflow: bool,
    /// Reports and tag reads dropped by this call.
    pub dropped: (u64, u64),
}

impl ReportBuffer {
    /// A buffer of `limit` bytes.
    pub fn new(limit: usize) -> ReportBuffer {
        ReportBuffer {
            limit,
            warned: false,
            overflowed: false,
            dropped: (0, 0),
        }
    }

    /// The frames of `out` that go out, with `queued` bytes already waiting for the client;
    /// `held_full`: the buffer counts as full whatever is queued (the fill_report_buffer
    /// fault: as if the client had stopped reading).
    pub fn admit(&mut self, queued: usize, out: BytesMut, held_full: bool) -> Admitted {
        let queued = if held_full {
            queued.max(self.limit)
        } else {
            queued
        };
        let mut a = Admitted::default();
        if queued * 100 < self.limit * REARM_PERCENT {
            self.warned = false;
            if self.overflowed {
                tracing::info!(
                    "the client reads again: {} reports ({} tag reads) were dropped while the \
                     report buffer was full",
                    self.dropped.0,
                    self.dropped.1
                );
                self.overflowed = false;
                self.dropped = (0, 0);
            }
        }
        let after = queued + out.len();
        let warn_at = self.limit * usize::from(WARN_PERCENT) / 100;
        if after <= self.limit && (self.warned || after < warn_at) {
            // Everything fits and nothing is to be said: sent as it is, without a copy.
            a.bytes = out;
            return a;
        }
        let mut level = queued;
        let mut at = 0;
        while let Some(h) = llrp::FrameHeader::peek(&out[at..]) {
            let len = (h.length as usize).clamp(llrp::frame::HEADER_LEN, out.len() - at);
            let frame = &out[at..at + len];
            at += len;
            let report = h.msg_type == llrp::message::RoAccessReport::TYPE;
            if report && level + len > self.limit {
                let reads = llrp::reads::tag_reads(frame).map_or(0, |r| r.count() as u64);
                a.dropped.0 += 1;
                a.dropped.1 += reads;
                if !self.overflowed {
                    self.overflowed = true;
                    a.overflow = true;
                    tracing::warn!(
                        "the client does not read: the report buffer ({} bytes) is full, \
                         reports are dropped",
                        self.limit
                    );
                }
                continue;
            }
            a.bytes.extend_from_slice(frame);
            level += len;
        }
        // Bytes after the last whole frame (none from the session) go out as they are.
        a.bytes.extend_from_slice(&out[at..]);
        if !self.warned && level * 100 >= self.limit * usize::from(WARN_PERCENT) {
            self.warned = true;
            a.warn = Some((level * 100 / self.limit).min(100) as u8);
        }
        self.dropped.0 += a.dropped.0;
        self.dropped.1 += a.dropped.1;
        a
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use llrp::message::{GetReaderCapabilitiesResponse, Keepalive, RoAccessReport};
    use llrp::Message;

    fn report(epc: u8) -> Vec<u8> {
        let mut r = RoAccessReport::default();
        r.tag_report_data.push(llrp::params::TagReportData {
            epc: llrp::params::Epc::Epc96(llrp::params::Epc96([epc; 12])),
            ..Default::default()
        });
        Message::new(1, r).to_bytes().to_vec()
    }

    #[test]
    fn reports_past_the_limit_are_dropped_and_the_rest_goes_out() {
        let one = report(1);
        let mut b = ReportBuffer::new(10 * one.len());
        let answer = Message::new(2, GetReaderCapabilitiesResponse::default())
            .to_bytes()
            .to_vec();
        let keepalive = Message::new(3, Keepalive::default()).to_bytes().to_vec();
        // Eight reports already wait; four more, an answer and a keepalive come.
        let mut out = Vec::new();
        for _ in 0..2 {
            out.extend_from_slice(&one);
        }
        out.extend_from_slice(&answer);
        out.extend_from_slice(&one);
        out.extend_from_slice(&one);
        out.extend_from_slice(&keepalive);
        let a = b.admit(8 * one.len(), BytesMut::from(&out[..]), false);
        let mut want = Vec::new();
        want.extend_from_slice(&one);
        want.extend_from_slice(&one);
        want.extend_from_slice(&answer);
        want.extend_from_slice(&keepalive);
        assert_eq!(
            &a.bytes[..],
            &want[..],
            "two reports fit, the answer and keepalive always go"
        );
        assert_eq!(a.dropped, (2, 2));
        assert!(a.overflow);
        assert!(a.warn.is_some(), "full is past the warning level");
        // Still full: dropped again, but the overflow was told once.
        let again = b.admit(10 * one.len(), BytesMut::from(&one[..]), false);
        assert!(again.bytes.is_empty() && !again.overflow && again.warn.is_none());
        // Drained under half: a report goes out, and the next overflow is told again.
        let later = b.admit(one.len(), BytesMut::from(&one[..]), false);
        assert_eq!(&later.bytes[..], &one[..]);
        let full = b.admit(10 * one.len(), BytesMut::from(&one[..]), false);
        assert!(full.overflow && full.bytes.is_empty());
    }

    #[test]
    fn the_warning_comes_once_past_three_quarters() {
        let one = report(1);
        let mut b = ReportBuffer::new(100 * one.len());
        assert_eq!(
            b.admit(70 * one.len(), BytesMut::from(&one[..]), false)
                .warn,
            None
        );
        let w = b
            .admit(75 * one.len(), BytesMut::from(&one[..]), false)
            .warn;
        assert_eq!(w, Some(76));
        assert_eq!(
            b.admit(80 * one.len(), BytesMut::from(&one[..]), false)
                .warn,
            None,
            "once"
        );
        assert_eq!(
            b.admit(10 * one.len(), BytesMut::from(&one[..]), false)
                .warn,
            None,
            "drained: re-armed"
        );
        assert_eq!(
            b.admit(90 * one.len(), BytesMut::from(&one[..]), false)
                .warn,
            Some(91)
        );
    }

    #[test]
    fn a_buffer_held_full_warns_drops_reports_and_recovers_once_released() {
        let one = report(1);
        let mut b = ReportBuffer::new(100 * one.len());
        let answer = Message::new(2, GetReaderCapabilitiesResponse::default())
            .to_bytes()
            .to_vec();
        let mut out = one.clone();
        out.extend_from_slice(&answer);
        // Nothing queued, but held full: the report is dropped, the answer goes.
        let a = b.admit(0, BytesMut::from(&out[..]), true);
        assert_eq!(&a.bytes[..], &answer[..]);
        assert_eq!((a.warn, a.overflow, a.dropped), (Some(100), true, (1, 1)));
        // Released: it reads again.
        let later = b.admit(0, BytesMut::from(&one[..]), false);
        assert_eq!(&later.bytes[..], &one[..]);
        assert!(!later.overflow && later.warn.is_none());
    }
}
