//! What a model keeps between inventories, none of which ever changes a result: each
//! antenna's classification and draw state, and the field decisions kept from earlier
//! buckets with the bounds on antenna motion that prove them.

use std::sync::{Arc, Mutex, MutexGuard};

use super::draw::Bucket;
use super::grid::Classified;

/// Per-antenna classifications of a model (a cache: the field never depends on it). The lock
/// is held only to look one up or to store one, so several threads share it freely.
#[derive(Debug, Default)]
pub(in crate::physics) struct FieldCache {
    classified: Vec<Mutex<Option<Arc<Classified>>>>,
    /// Per antenna, the classification the reader's idle checks use (kept apart from the
    /// inventories', which run ahead of them on other threads).
    idle: Vec<Mutex<Option<Arc<Classified>>>>,
    /// Per antenna, the draw state of its last inventory: the decisions kept from earlier
    /// buckets, and buffers to reuse.
    buckets: Vec<Mutex<Bucket>>,
}

impl Clone for FieldCache {
    fn clone(&self) -> Self {
        FieldCache::new(self.classified.len())
    }
}

impl FieldCache {
    /// An empty cache for `antennas` antennas.
    pub(in crate::physics) fn new(antennas: usize) -> FieldCache {
        FieldCache {
            classified: (0..antennas).map(|_| Mutex::new(None)).collect(),
            idle: (0..antennas).map(|_| Mutex::new(None)).collect(),
            buckets: (0..antennas)
                .map(|_| Mutex::new(Bucket::default()))
                .collect(),
        }
    }

    /// The draw state of antenna index `i` (0-based), taken out of the cache for one
    /// inventory (a fresh one when another thread holds it, or for no such antenna).
    pub(in crate::physics) fn take_bucket(&self, i: usize) -> Bucket {
        self.buckets.get(i).map_or_else(Bucket::default, |m| {
            // A panic while holding the lock leaves at worst a state of the same kind, which
            // every use checks or resets.
            std::mem::take(&mut *m.lock().unwrap_or_else(|e| e.into_inner()))
        })
    }

    /// Gives the draw state of antenna index `i` back to the cache.
    pub(in crate::physics) fn put_bucket(&self, i: usize, bucket: Bucket) {
        if let Some(m) = self.buckets.get(i) {
            *m.lock().unwrap_or_else(|e| e.into_inner()) = bucket;
        }
    }

    /// The classification slot of antenna index `i` (0-based), if there is such an antenna.
    pub(super) fn slot(&self, i: usize) -> Option<MutexGuard<'_, Option<Arc<Classified>>>> {
        Self::lock(&self.classified, i)
    }

    /// The idle checks' classification slot of antenna index `i`.
    pub(super) fn idle_slot(&self, i: usize) -> Option<MutexGuard<'_, Option<Arc<Classified>>>> {
        Self::lock(&self.idle, i)
    }

    fn lock(
        slots: &[Mutex<Option<Arc<Classified>>>],
        i: usize,
    ) -> Option<MutexGuard<'_, Option<Arc<Classified>>>> {
        // A panic while holding the lock leaves at worst a stale entry, which is checked for
        // validity before use; the cache can always be rebuilt.
        slots
            .get(i)
            .map(|m| m.lock().unwrap_or_else(|e| e.into_inner()))
    }
}

/// Upper bounds, at any time, on how fast an antenna moves (m/s) and its boresight turns
/// (rad/s), when they are known.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(in crate::physics) struct Rates {
    /// m/s.
    pub(in crate::physics) speed: f64,
    /// rad/s.
    pub(in crate::physics) turn: f64,
}

/// A field decision kept for later bucket starts.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Kept {
    /// Valid for bucket starts in `[from_us, until_us]`.
    pub(super) from_us: u64,
    pub(super) until_us: u64,
    /// On this channel (0: nothing kept).
    pub(super) channel: u16,
    pub(super) inside: bool,
}

/// The field decisions of one antenna kept from earlier buckets, per tag (a cache: a decision
/// is kept only as long as [`Near::steady`](super::near::Near::steady) proves it holds, so it
/// never changes a result).
#[derive(Clone, Debug, Default)]
pub(in crate::physics) struct Memo {
    tx_bits: u64,
    pub(super) kept: Vec<Kept>,
    /// Prove holds from the longest down instead of from a guess (tests: every hold is then
    /// as long as the proof alone allows).
    pub(super) exhaustive: bool,
}

impl Memo {
    /// Makes the memo one for `tags` tags at `tx_power_dbm` (emptied if it was not).
    pub(in crate::physics) fn fit(&mut self, tags: usize, tx_power_dbm: f64) {
        let bits = tx_power_dbm.to_bits();
        if self.tx_bits != bits || self.kept.len() != tags {
            self.tx_bits = bits;
            self.kept.clear();
            self.kept.resize(tags, Kept::default());
        }
    }
}
