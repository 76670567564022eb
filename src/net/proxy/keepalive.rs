//! Watching a proxied reader's KEEPALIVEs (sans IO: the caller passes the time): the period
//! is the one the client asked for in SET_READER_CONFIG's KeepaliveSpec, or else the interval
//! seen between two KEEPALIVEs; after [`MISSES`] periods without one the link is lost, and
//! the next KEEPALIVE restores it.

use crate::reads::ReaderName;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Periods without a KEEPALIVE after which the link is taken for lost (as the inventory
/// client takes a reader silent for three intervals for gone).
pub const MISSES: u32 = 3;

/// Shortest period watched: a KeepaliveSpec of less is taken as this.
pub const MIN_PERIOD: Duration = Duration::from_millis(10);

/// A change of a reader's keepalive link.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Change {
    /// No KEEPALIVE for `silent`, [`MISSES`] periods of `period`.
    Lost {
        /// The period expected.
        period: Duration,
        /// Time since the last KEEPALIVE (or since the period was set).
        silent: Duration,
    },
    /// A KEEPALIVE again after a loss, `silent` after the one before.
    Restored {
        /// The period expected.
        period: Duration,
        /// Time without a KEEPALIVE.
        silent: Duration,
    },
}

/// One connection's keepalive link.
#[derive(Clone, Debug, Default)]
pub struct Watch {
    /// The period expected; `None`: not watched (no keepalives asked for, or none seen yet).
    period: Option<Duration>,
    /// The client set the period (a KeepaliveSpec), rather than it being seen.
    configured: bool,
    /// The last KEEPALIVE, or when the period was set.
    last: Option<Instant>,
    /// The link is down.
    lost: bool,
    /// A restoration not yet polled.
    restored: Option<Change>,
}

impl Watch {
    /// The client asked for a KEEPALIVE every `period` (`None`: none) at `now`.
    pub fn spec(&mut self, period: Option<Duration>, now: Instant) {
        self.configured = true;
        self.period = period.map(|p| p.max(MIN_PERIOD));
        if self.period.is_some() && !self.lost {
            self.last = Some(now);
        }
    }

    /// A KEEPALIVE came at `now`.
    pub fn keepalive(&mut self, now: Instant) -> Option<Change> {
        let before = self.last.replace(now);
        if !self.configured {
            if let Some(b) = before.filter(|_| !self.lost) {
                self.period = Some(now.duration_since(b).max(MIN_PERIOD));
            }
        }
        if std::mem::take(&mut self.lost) {
            let silent = before.map_or(Duration::ZERO, |b| now.duration_since(b));
            let change = self
                .period
                .map(|period| Change::Restored { period, silent });
            self.restored = change;
            return change;
        }
        None
    }

    /// When the link is lost if no KEEPALIVE comes before.
    pub fn deadline(&self) -> Option<Instant> {
        if self.lost {
            return None;
        }
        Some(self.last? + self.period? * MISSES)
    }

    /// Time is `now`: a restoration not yet polled, or the loss if the deadline has passed.
    pub fn poll(&mut self, now: Instant) -> Option<Change> {
        if let Some(r) = self.restored.take() {
            return Some(r);
        }
        let deadline = self.deadline()?;
        if now < deadline {
            return None;
        }
        self.lost = true;
        Some(Change::Lost {
            period: self.period?,
            silent: now.duration_since(self.last?),
        })
    }
}

/// What a proxy session tells of its keepalive link.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LinkNote {
    /// The reader sent a KEEPALIVE.
    Keepalive,
    /// The client asked for a KEEPALIVE every so often (SET_READER_CONFIG; `None`: none).
    Spec(Option<Duration>),
}

/// The keepalive links of a proxy's sessions, shared between the sessions, which note what
/// they see, and whoever polls them for changes (never through the bounded tap, so a tap
/// full of reads cannot make a link look lost).
#[derive(Clone, Debug, Default)]
pub struct Links(Arc<Mutex<HashMap<u64, (ReaderName, Watch)>>>);

impl Links {
    /// Session `session` of reader `reader` saw `note` at `now`.
    pub fn note(&self, session: u64, reader: &ReaderName, note: LinkNote, now: Instant) {
        let mut links = self.lock();
        let (_, w) = links
            .entry(session)
            .or_insert_with(|| (reader.clone(), Watch::default()));
        match note {
            LinkNote::Keepalive => {
                w.keepalive(now);
            }
            LinkNote::Spec(period) => w.spec(period, now),
        }
    }

    /// Session `session` ended: its link is no longer watched.
    pub fn end(&self, session: u64) {
        self.lock().remove(&session);
    }

    /// The changes of every link at `now`, with their readers' names.
    pub fn poll(&self, now: Instant) -> Vec<(ReaderName, Change)> {
        self.lock()
            .values_mut()
            .filter_map(|(reader, w)| w.poll(now).map(|c| (reader.clone(), c)))
            .collect()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<u64, (ReaderName, Watch)>> {
        // A panicked holder leaves watches still worth using.
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: Duration = Duration::from_millis(1);

    #[test]
    fn the_asked_period_missed_three_times_is_a_loss_and_the_next_keepalive_restores() {
        let t = Instant::now();
        let mut w = Watch::default();
        assert_eq!(w.deadline(), None, "nothing asked, nothing seen");
        w.spec(Some(200 * MS), t);
        assert_eq!(w.deadline(), Some(t + 600 * MS));
        assert_eq!(w.keepalive(t + 200 * MS), None);
        assert_eq!(
            w.poll(t + 700 * MS),
            None,
            "600 ms after the last one only at 800"
        );
        let lost = w.poll(t + 800 * MS);
        assert_eq!(
            lost,
            Some(Change::Lost {
                period: 200 * MS,
                silent: 600 * MS
            })
        );
        assert_eq!(w.poll(t + 900 * MS), None, "lost once");
        assert_eq!(w.deadline(), None);
        assert_eq!(
            w.keepalive(t + 1500 * MS),
            Some(Change::Restored {
                period: 200 * MS,
                silent: 1300 * MS
            })
        );
        assert_eq!(w.deadline(), Some(t + 2100 * MS));
    }

    #[test]
    fn without_a_spec_the_period_is_the_interval_seen() {
        let t = Instant::now();
        let mut w = Watch::default();
        w.keepalive(t);
        assert_eq!(w.deadline(), None, "one KEEPALIVE tells no period");
        w.keepalive(t + 1000 * MS);
        assert_eq!(w.deadline(), Some(t + 4000 * MS));
        assert!(matches!(w.poll(t + 4000 * MS), Some(Change::Lost { .. })));
        // The long silence is not taken for the period.
        w.keepalive(t + 9000 * MS);
        assert_eq!(w.deadline(), Some(t + 12_000 * MS));
    }

    #[test]
    fn keepalives_turned_off_are_not_watched() {
        let t = Instant::now();
        let mut w = Watch::default();
        w.spec(Some(100 * MS), t);
        w.spec(None, t + 50 * MS);
        assert_eq!(w.deadline(), None);
        assert_eq!(w.poll(t + 10_000 * MS), None);
        // A KEEPALIVE the reader still sends does not make a period of its own.
        w.keepalive(t + 11_000 * MS);
        w.keepalive(t + 12_000 * MS);
        assert_eq!(w.deadline(), None);
    }

    #[test]
    fn links_report_each_sessions_loss_and_return_once_and_forget_ended_sessions() {
        let t = Instant::now();
        let links = Links::default();
        let name = |n: &str| -> ReaderName { n.parse().expect("a reader name") };
        let (a, b) = (name("a"), name("b"));
        links.note(0, &a, LinkNote::Spec(Some(100 * MS)), t);
        links.note(1, &b, LinkNote::Spec(Some(1000 * MS)), t);
        assert!(links.poll(t + 200 * MS).is_empty());
        let lost = links.poll(t + 300 * MS);
        assert_eq!(lost.len(), 1);
        assert_eq!(lost[0].0, "a");
        assert!(matches!(lost[0].1, Change::Lost { .. }));
        links.note(0, &a, LinkNote::Keepalive, t + 400 * MS);
        let back = links.poll(t + 400 * MS);
        assert!(
            matches!(back.as_slice(), [(_, Change::Restored { .. })]),
            "{back:?}"
        );
        assert!(links.poll(t + 450 * MS).is_empty(), "reported once");
        links.end(1);
        assert!(links.poll(t + 10_000 * MS).iter().all(|(r, _)| r == "a"));
    }
}
