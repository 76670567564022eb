//! A subscriber's view of one topic's sequence numbers from one reader, as a reorder buffer
//! (sans IO: the caller passes the time). Messages are handed back for filing in sequence
//! order, from the first this subscriber sees (those before it that come later, as the first
//! messages of a broker's redelivery may, are filed once each, out of order): one that comes
//! ahead of a missing number is held until the gap fills (brokers such as NATS JetStream may
//! redeliver out of order, and a tag's reads filed out of order give another estimate), for
//! at most [`HOLD`] and [`MAX_HELD`] messages; then the gap is skipped, and a message that
//! still comes late into it is filed out of order. A missing number counts as lost once it
//! is [`REORDER_WINDOW`] behind, or [`CLOSE_GRACE`] after the publisher's clean close named a
//! last number at or past it. Numbers count from 1 in each publisher run (the messages'
//! `run`): a newer run starts the count again, and a message of an older run that comes late
//! is filed out of order.

use std::collections::{BTreeMap, BTreeSet};
use std::time::{Duration, Instant};

/// A skipped number this far behind the next expected one is counted as lost.
pub const REORDER_WINDOW: u64 = 10_000;

/// How long a message waits for an earlier missing one before the gap is skipped: a broker
/// redelivers what it held back after its acknowledgement wait (NATS JetStream: `ack_wait`,
/// 30 s by default, 1 s in the tests), and on a busy host that took more than 2 s.
pub const HOLD: Duration = Duration::from_secs(5);

/// At most this many messages are held for a gap; one more skips it.
pub const MAX_HELD: usize = 1_000;

/// How long after the publisher's close messages before its last number may still come
/// (a broker delivers topics independently: the close may overtake the last batches).
pub const CLOSE_GRACE: Duration = Duration::from_secs(5);

/// What one arrival or tick makes of the messages.
#[derive(Debug)]
pub struct Step<T> {
    /// To file now, in this order.
    pub file: Vec<T>,
    /// The arrival, when it was seen already (QoS 1 redelivery): skip it.
    pub duplicate: Option<T>,
    /// Numbers now counted as lost.
    pub lost: u64,
    /// The arrival came ahead of a missing number and is held.
    pub held: bool,
    /// The arrival is filed behind messages that follow it (late into a skipped gap, from
    /// before the first number seen, or of an earlier run).
    pub late: bool,
}

impl<T> Default for Step<T> {
    fn default() -> Self {
        Step {
            file: Vec::new(),
            duplicate: None,
            lost: 0,
            held: false,
            late: false,
        }
    }
}

/// One topic's numbers and the messages held for a gap.
#[derive(Debug)]
pub struct Seq<T> {
    /// The publisher run whose numbers these are (0: the publisher names none).
    run: u64,
    /// The next number to file; 0 before the first message.
    next: u64,
    /// Numbers below `next` skipped over and not seen yet.
    missing: BTreeSet<u64>,
    /// Messages above `next`, with when they came.
    held: BTreeMap<u64, (T, Instant)>,
    /// The publisher's last number and when its gaps count as lost.
    close: Option<(u64, Instant)>,
    /// The first number this subscriber saw, when its count began mid-run (0 otherwise).
    first: u64,
    /// Numbers below `first` that came since (filed once each), at most [`REORDER_WINDOW`].
    early: BTreeSet<u64>,
}

impl<T> Default for Seq<T> {
    fn default() -> Self {
        Seq {
            run: 0,
            next: 0,
            missing: BTreeSet::new(),
            held: BTreeMap::new(),
            close: None,
            first: 0,
            early: BTreeSet::new(),
        }
    }
}

impl<T> Seq<T> {
    /// Message `seq` of publisher run `run` came at `now`. The first number seen is where
    /// this subscriber's session began (no loss before it; what comes from before it is filed
    /// once). A newer run counts from 1 again:
    /// what the last one left missing is lost, and what it held is filed. From a publisher
    /// that names no run (`run` 0), 1 again after higher numbers is taken for a new run.
    pub fn arrive(&mut self, run: u64, seq: u64, item: T, now: Instant) -> Step<T> {
        let mut step = Step::default();
        if self.next != 0 && run != 0 && run < self.run {
            // Late from an earlier run: its numbers are no longer kept.
            step.file.push(item);
            step.late = true;
            return step;
        }
        if self.next != 0 && run > self.run {
            self.new_run(&mut step);
            self.next = 1;
        }
        self.run = run;
        if self.next == 0 {
            self.next = seq + 1;
            self.first = seq;
            step.file.push(item);
        } else if run == 0 && seq == 1 && self.next > 2 && !self.missing.contains(&1) {
            self.new_run(&mut step);
            self.next = 2;
            step.file.push(item);
        } else if seq < self.next {
            if self.missing.remove(&seq) || (seq < self.first && self.early.insert(seq)) {
                step.file.push(item);
                step.late = true;
                if self.early.len() > REORDER_WINDOW as usize {
                    self.early.pop_first();
                }
            } else {
                step.duplicate = Some(item);
            }
        } else if seq == self.next {
            self.next += 1;
            step.file.push(item);
            self.drain(&mut step);
        } else if let std::collections::btree_map::Entry::Vacant(slot) = self.held.entry(seq) {
            slot.insert((item, now));
            step.held = true;
            while self.held.len() > MAX_HELD
                || self
                    .held
                    .last_key_value()
                    .is_some_and(|(&high, _)| high - self.next >= REORDER_WINDOW)
            {
                self.release_first(&mut step);
            }
        } else {
            step.duplicate = Some(item);
        }
        self.settle(&mut step);
        step
    }

    /// Time passed: skips the gaps messages have waited on for [`HOLD`], and counts what is
    /// still missing [`CLOSE_GRACE`] after a close.
    pub fn tick(&mut self, now: Instant) -> Step<T> {
        let mut step = Step::default();
        while self
            .held
            .first_key_value()
            .is_some_and(|(_, (_, at))| now.duration_since(*at) >= HOLD)
        {
            self.release_first(&mut step);
        }
        if let Some((last, at)) = self.close {
            if now >= at {
                while self.held.first_key_value().is_some_and(|(&s, _)| s <= last) {
                    self.release_first(&mut step);
                }
                if self.next <= last {
                    self.missing.extend(self.next..=last);
                    self.next = last + 1;
                }
                step.lost += std::mem::take(&mut self.missing).len() as u64;
                self.close = None;
            }
        }
        self.settle(&mut step);
        step
    }

    /// The publisher's run `run` ended at number `last` (its reader's clean `offline`) at
    /// `now`: what is still missing up to it counts as lost unless it comes within
    /// [`CLOSE_GRACE`]. The close of another run than the one being counted changes nothing.
    pub fn close(&mut self, run: u64, last: u64, now: Instant) {
        if self.next != 0 && run == self.run {
            self.close = Some((last, now + CLOSE_GRACE));
            self.end_complete_close();
        }
    }

    /// The next number to file (0 before the first message).
    pub fn expected(&self) -> u64 {
        self.next
    }

    /// The message held as number `seq`, if it is.
    pub fn held_mut(&mut self, seq: u64) -> Option<&mut T> {
        self.held.get_mut(&seq).map(|(item, _)| item)
    }

    /// Messages held now.
    pub fn held(&self) -> usize {
        self.held.len()
    }

    /// Files the held messages that now follow on.
    fn drain(&mut self, step: &mut Step<T>) {
        while let Some(entry) = self.held.first_entry() {
            if *entry.key() != self.next {
                break;
            }
            step.file.push(entry.remove().0);
            self.next += 1;
        }
    }

    /// Skips the gap before the first held message, files it and what follows on.
    fn release_first(&mut self, step: &mut Step<T>) {
        if let Some((seq, (item, _))) = self.held.pop_first() {
            self.missing.extend(self.next..seq);
            self.next = seq + 1;
            step.file.push(item);
            self.drain(step);
        }
    }

    /// Ends the run being counted: files what it held, counts what it left missing.
    fn new_run(&mut self, step: &mut Step<T>) {
        self.release_all(step);
        self.first = 0;
        self.early.clear();
        step.lost += std::mem::take(&mut self.missing).len() as u64;
        self.close = None;
    }

    /// Files everything held, gaps skipped.
    fn release_all(&mut self, step: &mut Step<T>) {
        while !self.held.is_empty() {
            self.release_first(step);
        }
    }

    /// Counts the numbers now too far behind, and ends a close whose numbers have all come.
    fn settle(&mut self, step: &mut Step<T>) {
        while let Some(&first) = self.missing.first() {
            if first + REORDER_WINDOW >= self.next {
                break;
            }
            self.missing.pop_first();
            step.lost += 1;
        }
        self.end_complete_close();
    }

    /// Forgets a close whose numbers have all come.
    fn end_complete_close(&mut self) {
        if let Some((last, _)) = self.close {
            if self.next > last && self.missing.range(..=last).next().is_none() {
                self.close = None;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A publisher run.
    const R: u64 = 1_796_000_000_000_000;

    fn filed(step: &Step<u64>) -> Vec<u64> {
        step.file.clone()
    }

    #[test]
    fn a_message_ahead_of_a_gap_waits_for_it_and_both_are_filed_in_order() {
        let t = Instant::now();
        let mut s = Seq::default();
        assert_eq!(filed(&s.arrive(R, 5, 5, t)), [5]);
        let ahead = s.arrive(R, 7, 7, t);
        assert!(ahead.held && ahead.file.is_empty());
        let ahead = s.arrive(R, 8, 8, t);
        assert!(ahead.held && ahead.file.is_empty());
        let late = s.arrive(R, 6, 6, t);
        assert_eq!(filed(&late), [6, 7, 8]);
        assert_eq!(late.lost, 0);
        assert_eq!(s.arrive(R, 7, 7, t).duplicate, Some(7));
        assert_eq!(s.held(), 0);
    }

    #[test]
    fn a_gap_that_does_not_fill_in_time_is_skipped_and_a_later_arrival_still_filed() {
        let t = Instant::now();
        let mut s = Seq::default();
        s.arrive(R, 1, 1, t);
        assert!(s.arrive(R, 3, 3, t).held);
        assert!(s.tick(t + HOLD / 2).file.is_empty());
        let step = s.tick(t + HOLD);
        assert_eq!(filed(&step), [3]);
        assert_eq!(step.lost, 0, "skipped, not yet lost");
        // 2 comes late after all: filed out of order, once.
        assert_eq!(filed(&s.arrive(R, 2, 2, t + HOLD)), [2]);
        assert_eq!(s.arrive(R, 2, 2, t + HOLD).duplicate, Some(2));
    }

    #[test]
    fn a_close_overtaken_by_its_last_messages_loses_nothing() {
        let t = Instant::now();
        let mut s = Seq::default();
        s.arrive(R, 1, 1, t);
        s.close(R, 3, t);
        assert_eq!(filed(&s.arrive(R, 2, 2, t)), [2]);
        assert_eq!(filed(&s.arrive(R, 3, 3, t)), [3]);
        assert_eq!(s.tick(t + CLOSE_GRACE).lost, 0);
    }

    #[test]
    fn what_never_comes_is_lost_after_the_close_grace() {
        let t = Instant::now();
        let mut s = Seq::default();
        s.arrive(R, 5, 5, t);
        s.arrive(R, 8, 8, t);
        s.close(R, 10, t);
        let early = s.tick(t + CLOSE_GRACE - Duration::from_millis(1));
        assert_eq!(early.lost, 0);
        let step = s.tick(t + CLOSE_GRACE);
        // 8 is filed (once its hold is over, or at the close); 6, 7, 9 and 10 never came.
        assert_eq!([filed(&early), filed(&step)].concat(), [8]);
        assert_eq!(step.lost, 4);
        assert_eq!(s.arrive(R, 11, 11, t + CLOSE_GRACE).lost, 0);
    }

    #[test]
    fn numbers_far_behind_are_lost() {
        let t = Instant::now();
        let mut s = Seq::default();
        s.arrive(R, 1, 1, t);
        let far = s.arrive(R, 2 + REORDER_WINDOW, 0, t);
        assert_eq!(
            filed(&far),
            [0],
            "released at once: too far ahead to wait for"
        );
        assert_eq!(far.lost, 1);
    }

    #[test]
    fn a_newer_run_counts_from_one_again_and_a_late_message_of_the_old_run_is_filed() {
        let t = Instant::now();
        let mut r = Seq::default();
        r.arrive(R, 10, 10, t);
        r.arrive(R, 12, 12, t);
        // The new run's first message to come is its second: it waits for its first.
        let second = r.arrive(R + 1, 2, 2, t);
        assert_eq!(filed(&second), [12], "the old run's held message is filed");
        assert_eq!(second.lost, 1, "11 never came");
        assert!(second.held);
        assert_eq!(filed(&r.arrive(R + 1, 1, 1, t)), [1, 2]);
        // A redelivery of the old run's 10, after the new run began: filed out of order
        // (that run's numbers are no longer kept), the new run's count untouched.
        let late = r.arrive(R, 10, 10, t);
        assert_eq!(
            (filed(&late), late.lost, late.duplicate),
            (vec![10], 0, None)
        );
        assert_eq!(r.expected(), 3);
        // Within one run, 1 again is a redelivery, not a new run.
        assert_eq!(r.arrive(R + 1, 1, 1, t).duplicate, Some(1));
        // The old run's close does not close the new run's count.
        r.close(R, 12, t);
        r.arrive(R + 1, 5, 5, t);
        assert_eq!(r.tick(t + CLOSE_GRACE).lost, 0);
    }

    #[test]
    fn from_a_publisher_naming_no_run_one_again_is_a_new_run() {
        let t = Instant::now();
        let mut r = Seq::default();
        r.arrive(0, 10, 10, t);
        r.arrive(0, 12, 12, t);
        let run = r.arrive(0, 1, 1, t);
        assert_eq!(filed(&run), [12, 1], "the old run's held message first");
        assert_eq!(run.lost, 1);
        assert_eq!(filed(&r.arrive(0, 2, 2, t)), [2]);
    }

    #[test]
    fn messages_before_the_first_seen_that_come_later_are_filed_once() {
        let t = Instant::now();
        let mut s = Seq::default();
        // The broker delivered 3 first, then 1 and 2 (and 1 again).
        assert_eq!(filed(&s.arrive(R, 3, 3, t)), [3]);
        assert_eq!(filed(&s.arrive(R, 1, 1, t)), [1]);
        assert_eq!(s.arrive(R, 1, 1, t).duplicate, Some(1));
        assert_eq!(filed(&s.arrive(R, 2, 2, t)), [2]);
        assert_eq!(filed(&s.arrive(R, 4, 4, t)), [4]);
        assert_eq!(s.arrive(R, 3, 3, t).duplicate, Some(3));
        assert_eq!(s.tick(t + CLOSE_GRACE).lost, 0);
        // A new run counts from its own first message.
        assert_eq!(filed(&s.arrive(R + 1, 1, 1, t)), [1]);
        assert_eq!(s.arrive(R + 1, 1, 1, t).duplicate, Some(1));
    }

    #[test]
    fn no_more_than_max_held_wait_for_one_gap() {
        let t = Instant::now();
        let mut s = Seq::default();
        s.arrive(R, 1, 1, t);
        for n in 3..3 + MAX_HELD as u64 {
            assert!(s.arrive(R, n, n, t).file.is_empty());
        }
        let over = s.arrive(R, 3 + MAX_HELD as u64, 0, t);
        assert_eq!(over.file.len(), MAX_HELD + 1);
        assert_eq!(s.held(), 0);
    }
}
