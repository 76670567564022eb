//! A subscriber's view of one topic's sequence numbers from one reader: which message is
//! new, late (it fills a gap: brokers such as NATS JetStream may redeliver out of order) or
//! a duplicate, and how many are missing for good.

use std::collections::BTreeSet;

/// A missing number this far behind the highest one seen is counted as lost.
pub const REORDER_WINDOW: u64 = 10_000;

/// What a message's sequence number makes of it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Arrival {
    /// New, or late into a gap: file it.
    File,
    /// Seen already (QoS 1 redelivery): skip it.
    Duplicate,
}

/// One topic's numbers.
#[derive(Clone, Debug, Default)]
pub struct Seq {
    high: u64,
    missing: BTreeSet<u64>,
}

impl Seq {
    /// Message `seq` came; the arrival and the numbers now counted as lost. The first number
    /// seen is where this subscriber's session began (no loss before it); 1 again after
    /// higher ones is a new gateway run.
    pub fn arrive(&mut self, seq: u64) -> (Arrival, u64) {
        if self.high == 0 {
            self.high = seq;
            return (Arrival::File, 0);
        }
        if seq == 1 && !self.missing.contains(&1) {
            let lost = self.missing.len() as u64;
            *self = Seq {
                high: 1,
                missing: BTreeSet::new(),
            };
            return (Arrival::File, lost);
        }
        if seq > self.high {
            self.missing.extend(self.high + 1..seq);
            self.high = seq;
            let mut lost = 0;
            while let Some(&first) = self.missing.first() {
                if first + REORDER_WINDOW >= self.high {
                    break;
                }
                self.missing.pop_first();
                lost += 1;
            }
            return (Arrival::File, lost);
        }
        if self.missing.remove(&seq) {
            (Arrival::File, 0)
        } else {
            (Arrival::Duplicate, 0)
        }
    }

    /// The publisher's last number was `last` (its reader's clean `offline`): everything
    /// still missing up to it is lost.
    pub fn close(&mut self, last: u64) -> u64 {
        if self.high == 0 {
            return 0;
        }
        let lost = self.missing.len() as u64 + last.saturating_sub(self.high);
        self.missing.clear();
        self.high = self.high.max(last);
        lost
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn late_messages_fill_their_gap_and_only_what_never_comes_is_lost() {
        let mut s = Seq::default();
        assert_eq!(s.arrive(5), (Arrival::File, 0));
        assert_eq!(s.arrive(8), (Arrival::File, 0));
        // 6 comes late: filed, not a duplicate; 8 again is one.
        assert_eq!(s.arrive(6), (Arrival::File, 0));
        assert_eq!(s.arrive(8), (Arrival::Duplicate, 0));
        assert_eq!(s.arrive(6), (Arrival::Duplicate, 0));
        // 7 never comes: lost at the close, with 9 and 10 after the last one seen.
        assert_eq!(s.close(10), 3);
    }

    #[test]
    fn numbers_far_behind_are_lost_and_one_again_is_a_new_run() {
        let mut s = Seq::default();
        s.arrive(1);
        assert_eq!(s.arrive(3 + REORDER_WINDOW), (Arrival::File, 1));
        let mut r = Seq::default();
        r.arrive(10);
        r.arrive(12);
        assert_eq!(r.arrive(1), (Arrival::File, 1));
        assert_eq!(r.arrive(2), (Arrival::File, 0));
    }
}
