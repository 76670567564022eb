//! The tags a reader's Select commands leave taking part in its inventory rounds.
//!
//! A Gen2 reader sends Selects before its Query; they set each tag's SL flag or inventoried
//! flag by whether its memory matches a mask, and the Query's Sel and Target then decide
//! which tags answer (GS1 EPC UHF Gen2 v2.0.1 §6.3.2.12.1.1 Select, §6.3.2.12.2.1 Query).
//! The reader works out which tags that leaves (from their memory, which the physics does not
//! hold); the rounds run among those only, so a smaller population gets more slots each.
//!
//! A Select with Truncate asserted (the last before the Query, on the EPC bank) makes each
//! matching tag answer the reader's ACK with `00000`, the part of its EPC after the Select's
//! mask and a CRC-16 instead of PC, EPC and CRC-16 (Gen2 v2.0.1 §6.3.2.12.1.1 Select and
//! §6.3.2.12.2 ACK reply): a shorter reply, so a shorter successful slot.

/// Bits of a tag's reply to an ACK the rounds assume without truncation: PC, an EPC-96 and
/// the CRC-16.
pub const FULL_REPLY_BITS: u32 = 16 + 96 + 16;

/// How a tag that takes part answers the reader's ACK.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reply {
    /// PC, EPC and CRC-16.
    Full,
    /// Truncated: `00000`, its EPC from bit `skip` (the bits after the Select's mask), `bits`
    /// of it, and a CRC-16.
    Truncated {
        /// Leading EPC bits left out (the mask's end past the EPC's start).
        skip: u16,
        /// EPC bits sent.
        bits: u16,
    },
}

/// Which of a scenario's tags (by index) take part in the rounds; the others never answer.
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash)]
pub struct Selected {
    words: Vec<u64>,
    /// Per tag, the EPC bits its truncated reply leaves out ([`NOT_TRUNCATED`]: a full reply);
    /// empty when no tag truncates.
    skips: Vec<u16>,
    /// Mean bits the taking-part tags send after an ACK, when some truncate.
    reply_bits: Option<u32>,
}

/// In [`Selected::skips`]: the tag replies in full.
const NOT_TRUNCATED: u16 = u16::MAX;

impl Selected {
    /// The tags `0..tags` for which `takes_part` holds.
    pub fn from_fn(tags: usize, mut takes_part: impl FnMut(usize) -> bool) -> Selected {
        let mut words = vec![0u64; tags.div_ceil(64)];
        for tag in 0..tags {
            if takes_part(tag) {
                words[tag / 64] |= 1 << (tag % 64);
            }
        }
        Selected {
            words,
            ..Selected::default()
        }
    }

    /// The tags `0..tags` for which `reply` gives how they answer (`None`: they take no part).
    pub fn from_replies(tags: usize, mut reply: impl FnMut(usize) -> Option<Reply>) -> Selected {
        let mut words = vec![0u64; tags.div_ceil(64)];
        let mut skips = Vec::new();
        let (mut taking, mut total_bits) = (0u64, 0u64);
        for tag in 0..tags {
            let Some(r) = reply(tag) else {
                continue;
            };
            words[tag / 64] |= 1 << (tag % 64);
            taking += 1;
            total_bits += u64::from(match r {
                Reply::Full => FULL_REPLY_BITS,
                // 00000, the EPC's bits after the mask, CRC-16.
                Reply::Truncated { bits, .. } => 5 + u32::from(bits) + 16,
            });
            if let Reply::Truncated { skip, .. } = r {
                if skips.is_empty() {
                    skips = vec![NOT_TRUNCATED; tags];
                }
                skips[tag] = skip;
            }
        }
        let reply_bits = (!skips.is_empty() && taking > 0)
            .then(|| u32::try_from(total_bits.div_ceil(taking)).unwrap_or(FULL_REPLY_BITS));
        Selected {
            words,
            skips,
            reply_bits,
        }
    }

    /// The leading EPC bits `tag` leaves out of its reply when it truncates it; `None` when it
    /// replies in full.
    #[inline]
    pub fn truncated(&self, tag: usize) -> Option<u16> {
        self.skips
            .get(tag)
            .copied()
            .filter(|&s| s != NOT_TRUNCATED && self.contains(tag))
    }

    /// Mean bits the taking-part tags send in reply to an ACK, when some truncate their reply
    /// (`None`: every tag sends [`FULL_REPLY_BITS`]).
    pub fn reply_bits(&self) -> Option<u32> {
        self.reply_bits
    }

    /// Whether `tag` takes part (a tag beyond the set does not).
    #[inline]
    pub fn contains(&self, tag: usize) -> bool {
        self.words
            .get(tag / 64)
            .is_some_and(|w| w >> (tag % 64) & 1 == 1)
    }

    /// How many tags take part.
    pub fn count(&self) -> usize {
        self.words.iter().map(|w| w.count_ones() as usize).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn holds_exactly_the_tags_it_was_given() {
        let s = Selected::from_fn(130, |t| t % 3 == 0);
        assert!((0..130).all(|t| s.contains(t) == (t % 3 == 0)));
        assert!(!s.contains(130) && !s.contains(10_000));
        assert_eq!(s.count(), 44);
        assert_eq!(Selected::from_fn(0, |_| true).count(), 0);
    }

    #[test]
    fn truncating_tags_send_shorter_replies_and_say_what_they_leave_out() {
        // Tags 0 and 2 truncate after 16 bits of an EPC-96 (80 bits sent), tag 1 replies in
        // full, tag 3 takes no part.
        let s = Selected::from_replies(4, |t| match t {
            0 | 2 => Some(Reply::Truncated { skip: 16, bits: 80 }),
            1 => Some(Reply::Full),
            _ => None,
        });
        assert_eq!(s.count(), 3);
        assert_eq!((s.truncated(0), s.truncated(1)), (Some(16), None));
        assert_eq!((s.truncated(2), s.truncated(3)), (Some(16), None));
        // (101 + 128 + 101) / 3 = 110 bits.
        assert_eq!(s.reply_bits(), Some(110));
        assert!(s.reply_bits() < Some(FULL_REPLY_BITS));
        // Without truncation nothing changes from from_fn.
        let full = Selected::from_replies(4, |t| (t != 3).then_some(Reply::Full));
        assert_eq!(full, Selected::from_fn(4, |t| t != 3));
        assert_eq!(full.reply_bits(), None);
    }
}
