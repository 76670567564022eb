//! The radio link an access runs over. An access follows the read that singulated the tag, on
//! the same forward link: each exchange with the tag (a word of a Write, a BlockWrite, a
//! BlockErase, a Lock, a Kill, a Read) is answered with the read's own chance at the tag's
//! margin, else the tag is lost for the rest of the access (it faded out of the field). A
//! command that writes the tag's memory needs more power than a read: Impinj's Monza 4 reads
//! at −19.5 dBm and writes at −16.7 dBm (Monza 4 Tag Chip Datasheet, features), so a write
//! needs [`WRITE_EXTRA_DB`] more margin; short of it the tag answers with Gen2's
//! insufficient-power error (error code 0x0B, Gen2 v2.0.1 Annex I) and writes nothing.

use rand::Rng;

use crate::physics::schedule::read_probability;
use crate::physics::seed::Stream;

/// How much more forward-link power a write needs than a read, dB: Monza 4's write
/// sensitivity (−16.7 dBm) over its read sensitivity (−19.5 dBm).
pub const WRITE_EXTRA_DB: f64 = 2.8;

/// What one exchange with the tag gave.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Exchange {
    /// The tag answered and had the power the command needs.
    Done,
    /// The tag answered with the insufficient-power error: nothing was written.
    InsufficientPower,
    /// The tag did not answer: it is lost for the rest of the access.
    Lost,
}

/// The forward link of one access: the margin of the read that singulated the tag, and the
/// draws of its fades.
#[derive(Clone, Debug)]
pub struct Link {
    margin_db: f64,
    draws: Stream,
    lost: bool,
}

impl Link {
    /// A link with `margin_db` of forward margin over the tag's read sensitivity, drawing
    /// from `draws`.
    pub fn new(margin_db: f64, draws: Stream) -> Link {
        Link {
            margin_db,
            draws,
            lost: false,
        }
    }

    /// One exchange; `writes` when the command programs the tag's memory.
    pub fn exchange(&mut self, writes: bool) -> Exchange {
        if self.lost || self.draws.gen::<f64>() >= read_probability(self.margin_db) {
            self.lost = true;
            return Exchange::Lost;
        }
        if writes && self.draws.gen::<f64>() >= read_probability(self.margin_db - WRITE_EXTRA_DB) {
            return Exchange::InsufficientPower;
        }
        Exchange::Done
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::seed;

    /// The share of writes done, short of power and lost at `margin_db`, over many accesses.
    fn shares(margin_db: f64) -> [f64; 3] {
        let n = 20_000;
        let mut counts = [0u32; 3];
        for i in 0..n {
            let mut link = Link::new(margin_db, seed::stream(&[42, i]));
            let k = match link.exchange(true) {
                Exchange::Done => 0,
                Exchange::InsufficientPower => 1,
                Exchange::Lost => 2,
            };
            counts[k] += 1;
        }
        counts.map(|c| f64::from(c) / f64::from(n as u32))
    }

    #[test]
    fn a_tag_that_reads_well_but_is_marginal_for_writes_fails_them_for_want_of_power() {
        // 3 dB over the read sensitivity: a read succeeds 98 % of the time; a write has
        // 0.2 dB over the write sensitivity, so most writes fail.
        let [done, short, lost] = shares(3.0);
        assert!(lost < 0.03, "lost {lost}");
        assert!(short > 0.7, "short of power {short}");
        assert!(done > 0.05 && done < 0.3, "done {done}");
        // 10 dB: every write goes through.
        let [done, ..] = shares(10.0);
        assert!(done > 0.999, "done {done}");
    }

    #[test]
    fn a_lost_tag_stays_lost_for_the_rest_of_the_access() {
        let mut link = Link::new(-1.0, seed::stream(&[1]));
        assert_eq!(link.exchange(false), Exchange::Lost);
        assert!(link.lost);
        let mut strong = Link::new(30.0, seed::stream(&[1]));
        strong.lost = true;
        assert_eq!(strong.exchange(false), Exchange::Lost);
    }
}
