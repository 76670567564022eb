//! Gen2 inventoried flags, as a single-target inventory needs them: which tags are in state
//! A (they answer) in each session, and when a tag's B flag persists no longer.
//!
//! Persistence (GS1 EPC Gen2 v2.0.0, Table 6.14, nominal temperature): session 1
//! 0.5 s < persistence < 5 s, whether energised or not; sessions 2 and 3: indefinite while the
//! tag is energised, more than 2 s once it is not. Each tag draws its own times from the seed
//! (uniform in 0.5–5 s for session 1, 2–5 s after power loss for sessions 2 and 3; ours,
//! inside the standard's bounds). A tag counts as energised from the start of an epoch in which
//! it is in the field of one of the reader's antennas to that epoch's end (between a reader's
//! antennas it is off for less than 2 s, so its session-2 flag holds).

use super::inventory::FIELD_BUCKET_US;
use super::seed;

/// One tag's flag in one session.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Flag {
    /// When it went to B (µs), if it is B.
    b_since: Option<u64>,
    /// End of the last epoch the tag was energised in (µs).
    energised_until: u64,
}

/// The inventoried flags of every tag in sessions 1–3, for one reader (stored only once a
/// single-target inventory has touched them: a reader that never runs one holds nothing).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Flags {
    seed: u64,
    tags: usize,
    /// `flags[tag][session - 1]`, grown toward `tags` as tags are touched.
    flags: Vec<[Flag; 3]>,
}

impl Flags {
    /// Every tag of a scenario with `tags` tags in state A; persistence times seeded by `seed`.
    pub fn new(seed: u64, tags: usize) -> Flags {
        Flags {
            seed,
            tags,
            flags: Vec::new(),
        }
    }

    /// `tag`'s session-1 persistence and its sessions-2/3 persistence after power loss (µs).
    fn persistence(&self, tag: usize) -> (u64, u64) {
        let h = seed::mix(&[self.seed, seed::domain::FLAGS, tag as u64]);
        let u1 = seed::unit(h);
        let u2 = seed::unit(seed::splitmix64(h));
        (
            (500_000.0 + 4_500_000.0 * u1) as u64,
            (2_000_000.0 + 3_000_000.0 * u2) as u64,
        )
    }

    /// Whether `tag` is in state A in `session` (1–3) at `t_us` (session 0, and an unknown
    /// tag or session, always are).
    pub fn is_a(&self, tag: usize, session: u8, t_us: u64) -> bool {
        let Some(f) = self.flag(tag, session) else {
            return true;
        };
        let Some(since) = f.b_since else {
            return true;
        };
        let (p1, p23) = self.persistence(tag);
        match session {
            1 => t_us >= since.saturating_add(p1),
            _ => t_us >= since.max(f.energised_until).saturating_add(p23),
        }
    }

    /// `tag` was read in `session` at `t_us`: it goes to B.
    pub fn read(&mut self, tag: usize, session: u8, t_us: u64) {
        if let Some(f) = self.flag_mut(tag, session) {
            f.b_since = Some(t_us);
        }
    }

    /// `tag` is energised during the epoch starting at `t_us`, in every session.
    pub fn energise(&mut self, tag: usize, t_us: u64) {
        let until = t_us.saturating_add(FIELD_BUCKET_US);
        self.grow(tag);
        if let Some(fs) = self.flags.get_mut(tag) {
            for f in fs {
                f.energised_until = f.energised_until.max(until);
            }
        }
    }

    /// Forgets reads whose persistence has run out by `t_us` (their tags are A again), so a
    /// later read counts from then.
    pub fn settle(&mut self, tag: usize, session: u8, t_us: u64) {
        if self.is_a(tag, session, t_us) {
            if let Some(f) = self.flag_mut(tag, session) {
                f.b_since = None;
            }
        }
    }

    fn flag(&self, tag: usize, session: u8) -> Option<&Flag> {
        let s = usize::from(session).checked_sub(1).filter(|&s| s < 3)?;
        self.flags.get(tag).map(|f| &f[s])
    }

    fn flag_mut(&mut self, tag: usize, session: u8) -> Option<&mut Flag> {
        let s = usize::from(session).checked_sub(1).filter(|&s| s < 3)?;
        self.grow(tag);
        self.flags.get_mut(tag).map(|f| &mut f[s])
    }

    /// Makes room for `tag` (a tag of the scenario) and every tag before it.
    fn grow(&mut self, tag: usize) {
        if tag < self.tags && self.flags.len() <= tag {
            self.flags.resize(tag + 1, [Flag::default(); 3]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn session_1_reverts_after_its_persistence_powered_or_not() {
        let mut f = Flags::new(1, 3);
        let (p1, _) = f.persistence(0);
        assert!((500_000..5_000_000).contains(&p1));
        assert!(f.is_a(0, 1, 0));
        f.read(0, 1, 1_000_000);
        assert!(!f.is_a(0, 1, 1_000_000));
        f.energise(0, 1_000_000 + p1);
        assert!(!f.is_a(0, 1, 1_000_000 + p1 - 1));
        assert!(f.is_a(0, 1, 1_000_000 + p1));
        // Other sessions and tags are untouched.
        assert!(f.is_a(0, 2, 1_000_001) && f.is_a(1, 1, 1_000_001));
        assert!(f.is_a(0, 0, 1_000_001));
    }

    #[test]
    fn sessions_2_and_3_hold_while_energised_and_2_s_after() {
        let mut f = Flags::new(2, 1);
        let (_, p) = f.persistence(0);
        assert!((2_000_000..5_000_000).contains(&p));
        f.read(0, 2, 0);
        // Energised for a minute: still B throughout.
        for k in 0..2400u64 {
            f.energise(0, k * FIELD_BUCKET_US);
            assert!(!f.is_a(0, 2, k * FIELD_BUCKET_US));
        }
        let off = 2400 * FIELD_BUCKET_US;
        assert!(!f.is_a(0, 2, off + p - 1));
        assert!(f.is_a(0, 2, off + p));
        f.settle(0, 2, off + p);
        assert_eq!(f.flags[0][1].b_since, None);
    }

    #[test]
    fn persistence_times_are_seeded_per_tag() {
        let (a, b) = (Flags::new(7, 50), Flags::new(8, 50));
        let times = |f: &Flags| (0..50).map(|t| f.persistence(t)).collect::<Vec<_>>();
        assert_eq!(times(&a), times(&Flags::new(7, 50)));
        assert_ne!(times(&a), times(&b));
        assert!(times(&a).windows(2).any(|w| w[0] != w[1]));
        // Nothing is stored until a flag is touched, and never beyond the scenario's tags.
        let mut c = Flags::new(7, 50);
        assert!(c.flags.is_empty());
        c.read(60, 2, 0);
        assert!(c.flags.is_empty());
        c.read(3, 2, 0);
        assert_eq!(c.flags.len(), 4);
    }
}
