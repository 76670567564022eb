//! Events and reports held for a client that asked for it (EventsAndReports'
//! HoldEventsAndReportsUponReconnect, LLRP 1.1 §13.2.6.4): what the reader would send from a
//! reconnect until ENABLE_EVENTS_AND_REPORTS, and the events of the time no client was
//! connected, which the next client gets then too. The ConnectionAttemptEvent is never held.

use llrp::message::ReaderEventNotification;
use llrp::params::ReaderEventNotificationData;
use llrp::Message;

use super::{Output, Reader, MAX_HELD};

impl Reader {
    /// Whether the reader, with no client connected, keeps its events for the next one:
    /// the last client set HoldEventsAndReportsUponReconnect.
    pub(super) fn holds_while_away(&self) -> bool {
        !self.connected
            && self
                .config
                .events_and_reports
                .hold_events_and_reports_upon_reconnect
    }

    /// Sends `m` to the client, or holds it: while the client has not yet sent
    /// ENABLE_EVENTS_AND_REPORTS after a reconnect, and while no client is connected when the
    /// last one asked for holding. Without a client otherwise, it is lost as on hardware.
    pub(super) fn deliver(&mut self, m: Message, out: &mut Vec<Output>) {
        if self.holding || self.holds_while_away() {
            if self.held.len() >= MAX_HELD {
                // A real reader's buffer is finite too: the oldest held message is lost.
                self.held.remove(0);
            }
            self.held.push(m);
        } else if self.connected {
            out.push(Output::Send(m));
        }
    }

    /// A READER_EVENT_NOTIFICATION of `data`, delivered (or held) as [`Reader::deliver`]
    /// says; nothing when no client is connected and none asked for holding.
    pub(super) fn notify(&mut self, data: ReaderEventNotificationData, out: &mut Vec<Output>) {
        if !self.connected && !self.holds_while_away() {
            return;
        }
        let m = self.message(ReaderEventNotification {
            reader_event_notification_data: data,
            ..Default::default()
        });
        self.deliver(m, out);
    }
}
