//! The tags a reader's Select commands leave taking part in its inventory rounds.
//!
//! A Gen2 reader sends Selects before its Query; they set each tag's SL flag or inventoried
//! flag by whether its memory matches a mask, and the Query's Sel and Target then decide
//! which tags answer (GS1 EPC UHF Gen2 v2.0.1 §6.3.2.12.1.1 Select, §6.3.2.12.2.1 Query).
//! The reader works out which tags that leaves (from their memory, which the physics does not
//! hold); the rounds run among those only, so a smaller population gets more slots each.

/// Which of a scenario's tags (by index) take part in the rounds; the others never answer.
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash)]
pub struct Selected {
    words: Vec<u64>,
}

impl Selected {
    /// The tags `0..tags` for which `takes_part` holds.
    pub fn from_fn(tags: usize, mut takes_part: impl FnMut(usize) -> bool) -> Selected {
        let mut words = vec![0u64; tags.div_ceil(64)];
        for tag in 0..tags {
            if takes_part(tag) {
                words[tag / 64] |= 1 << (tag % 64);
            }
        }
        Selected { words }
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
}
