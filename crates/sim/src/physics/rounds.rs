//! Inventory as a Gen2 reader runs it ([`super::gen2`]): each antenna's time is cut into
//! epochs on a fixed 25 ms grid of absolute time (`FIELD_BUCKET_US`, one antenna dwell); in
//! each, the tags in the antenna's field at the epoch's start take part in back-to-back
//! inventory rounds under the Q algorithm, from a Qfp settled on their number, and each tag
//! that answers alone (or is captured) becomes a read if the channel at that instant lets the
//! reader decode it (`Model::reply_at`).
//!
//! An antenna the reader never leaves (its AISpec's only one, [`Air::anchor_us`]) is not cut
//! into epochs: its rounds run back to back from the anchor (when the AISpec's first round
//! began), each with the field of the epoch it starts in, in blocks of [`BLOCK_US`] whose end
//! cuts the round in progress (as a hop would); so every tag is read once a round, as a real
//! reader reads a few tags (docs/measurement.md "Read rate"). A block depends only on the
//! anchor and its own start (`Model::chained_rounds`).
//!
//! An epoch depends only on (seed, reader, antenna, epoch, power, pinned channel, air), so
//! the reads of a window are those of the epochs it overlaps that fall inside it: a window
//! split in two gives the same reads as the whole, and windows may be computed in any order
//! and on any thread. A single-target inventory (sessions 1–3) is the exception: it depends on
//! the reader's flags, so the reader runs each of its epochs once, in time order, from when the
//! antenna gets the carrier (`reader::rospec`), never through the look-ahead.

use super::field::{Bucket, Classified};
use super::flags::Flags;
use super::gen2::{self, Air, Radio};
use super::geometry::distance;
use super::inventory::FIELD_BUCKET_US;
use super::seed::{self, Stream};
use super::{Model, Read, Want};
use std::sync::Arc;

/// Most epochs one window covers (a longer one is cut short: about seven hours).
pub const MAX_EPOCHS: u64 = 1 << 20;

/// EPC length the slot durations are worked out for (the common 96 bits).
const EPC_BITS: u32 = 96;

/// A block of an antenna the reader never leaves (µs; about a hop's dwell).
pub const BLOCK_US: u64 = 200_000;

/// The end (µs) of the block holding `t_us` when blocks start at `anchor_us`.
pub fn block_end(anchor_us: u64, t_us: u64) -> u64 {
    let k = t_us.saturating_sub(anchor_us) / BLOCK_US + 1;
    anchor_us.saturating_add(k.saturating_mul(BLOCK_US))
}

/// The channel of each instant, looked up again only when the time leaves the hop dwell.
pub(super) struct ChannelClock {
    pinned: Option<u16>,
    /// The dwell [start, end) last looked up, and its channel.
    dwell: (u64, u64, u16),
}

impl ChannelClock {
    /// A clock on `pinned` for every instant when given, else on the hop schedule.
    pub(super) fn new(pinned: Option<u16>) -> ChannelClock {
        ChannelClock {
            pinned,
            dwell: (1, 0, 1),
        }
    }

    /// The channel (1-based) at `t_us`.
    pub(super) fn at(&mut self, model: &Model, t_us: u64) -> u16 {
        if let Some(c) = self.pinned {
            return c;
        }
        if !(self.dwell.0 <= t_us && t_us < self.dwell.1) {
            let start = model.hops.dwell_start(t_us);
            self.dwell = (
                start,
                start.saturating_add(model.hops.dwell_us),
                model.channel_at(t_us),
            );
        }
        self.dwell.2
    }
}

/// What one epoch's rounds need of the channel: the [`Radio`] of an antenna from an instant.
struct EpochRadio<'a> {
    model: &'a Model,
    antenna: u16,
    tx_power_dbm: f64,
    want: Want,
    /// Absolute start of the current round (µs, fractional).
    round_start_us: f64,
    bucket: &'a mut Bucket,
    clock: &'a mut ChannelClock,
    /// Seed prefix of the replies' streams, and the epoch.
    prefix: u64,
    epoch: u64,
    /// Where in the epoch its rounds began (µs; the epoch's start unless a single-target
    /// window began later).
    from_epoch_us: u64,
    /// Replies asked for so far in the epoch (names each reply's stream).
    replies: u64,
    /// The epoch's field (tags in order) and each one's free-space level at the epoch's start
    /// (dBm up to a constant), NaN until a collision needs it.
    field: &'a [usize],
    levels: &'a mut [f64],
    /// Start of the epoch (µs).
    epoch_start_us: u64,
    /// The tags read so far in a single-target inventory (they sit out later rounds; the
    /// caller sends them to B as it reports them).
    read_here: Option<&'a mut Vec<usize>>,
    /// Reads of the epoch inside [from, until).
    from_us: u64,
    until_us: u64,
    out: &'a mut Vec<Read>,
}

impl EpochRadio<'_> {
    fn instant(&self, t_us: f64) -> u64 {
        let t = self.round_start_us + t_us;
        if t.is_finite() && t > 0.0 {
            t as u64
        } else {
            0
        }
    }
}

impl Radio for EpochRadio<'_> {
    fn level(&mut self, tag: usize, _t_us: f64) -> f64 {
        // Taken at the epoch's start (within 25 ms a level changes by far less than the
        // capture margin): −40 dB a decade and the tag's own strength.
        let Some(slot) = self
            .field
            .binary_search(&tag)
            .ok()
            .and_then(|i| self.levels.get_mut(i))
        else {
            return f64::NEG_INFINITY;
        };
        if slot.is_nan() {
            let t = self.epoch_start_us;
            let here = self.model.antenna_position(self.antenna, t);
            let d = distance(here, self.model.tag_position(tag, t)).max(0.01);
            *slot = -40.0 * d.log10() + self.model.tags[tag].radio.backscatter_db;
        }
        *slot
    }

    fn reply(&mut self, tag: usize, t_us: f64) -> bool {
        let t = self.instant(t_us);
        let mut rng: Stream =
            seed::stream_on(self.prefix, &[self.epoch, self.from_epoch_us, self.replies]);
        self.replies += 1;
        let channel = self.clock.at(self.model, t);
        let read = self.model.reply_at(
            self.antenna,
            self.tx_power_dbm,
            channel,
            tag,
            t,
            &mut rng,
            self.bucket,
            self.want,
        );
        match read {
            Some(r) => {
                if (self.from_us..self.until_us).contains(&r.time_us) {
                    self.out.push(r);
                }
                if let Some(read) = self.read_here.as_mut() {
                    read.push(tag);
                }
                true
            }
            None => false,
        }
    }
}

impl Model {
    /// The reads of `antenna` in `[t0_us, t1_us)` at power `tx` (dBm) on the pinned channel
    /// if any, under `air`: those of every epoch the window overlaps that fall in it. With
    /// `flags` (a single-target inventory in session 1–3, [`Air::suppresses`]) rounds start at
    /// `t0_us` rather than at the epoch's start, only tags in state A take part (each read at
    /// most once in the call), and every tag in the field is energised; the flag is left to
    /// the caller. The second value says that no tag was in A when the first round began.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn rounds(
        &self,
        antenna: u16,
        t0_us: u64,
        t1_us: u64,
        tx: f64,
        pinned: Option<u16>,
        want: Want,
        air: &Air,
        bucket: &mut Bucket,
        mut flags: Option<&mut Flags>,
    ) -> (Vec<Read>, bool) {
        let mut reads = Vec::new();
        let mut none_in_a = flags.is_some();
        let mut first_round = true;
        let mut read_here = Vec::new();
        if t1_us <= t0_us {
            return (reads, none_in_a);
        }
        if let Some(anchor) = air
            .anchor_us
            .filter(|_| pinned.is_none() && flags.is_none())
        {
            return (
                self.chained_rounds(antenna, anchor, t0_us, t1_us, tx, want, air, bucket),
                false,
            );
        }
        let times = air.mode.slot_times(EPC_BITS);
        let prefix = self.gen2_prefix(antenna);
        let mut clock = ChannelClock::new(pinned);
        let mut classified: Option<Arc<Classified>> = None;
        let first = t0_us / FIELD_BUCKET_US;
        let last = ((t1_us - 1) / FIELD_BUCKET_US).min(first.saturating_add(MAX_EPOCHS));
        let mut field = Vec::new();
        let mut levels = Vec::new();
        let mut scratch = gen2::Scratch::default();
        for epoch in first..=last {
            let start = epoch * FIELD_BUCKET_US;
            let ch = clock.at(self, start);
            self.open_bucket(antenna, tx, start, ch, &mut classified, bucket);
            self.field_of(bucket, &mut field);
            if field.is_empty() {
                first_round = false;
                continue;
            }
            levels.clear();
            levels.resize(field.len(), f64::NAN);
            let session = air.session;
            let mut taking_part = Vec::new();
            if let Some(f) = flags.as_deref_mut() {
                for &tag in &field {
                    f.settle(tag, session, start);
                    f.energise(tag, start);
                }
            }
            let mut radio = EpochRadio {
                model: self,
                antenna,
                tx_power_dbm: tx,
                want,
                round_start_us: start as f64,
                bucket: &mut *bucket,
                clock: &mut clock,
                prefix,
                epoch,
                from_epoch_us: 0,
                replies: 0,
                field: &field,
                levels: &mut levels,
                epoch_start_us: start,
                read_here: flags.is_some().then_some(&mut read_here),
                from_us: t0_us,
                until_us: t1_us,
                out: &mut reads,
            };
            let mut qfp = gen2::settled_qfp(field.len());
            // Pure epochs run whole (their reads are filtered to the window); a single-target
            // inventory, which carries flags from call to call, runs only inside the window,
            // so that no read outside it changes a flag.
            let flagged = flags.as_deref();
            let (from, to) = if flagged.is_some() {
                (start.max(t0_us), (start + FIELD_BUCKET_US).min(t1_us))
            } else {
                (start, start + FIELD_BUCKET_US)
            };
            let length = to.saturating_sub(from) as f64;
            radio.from_epoch_us = from - start;
            let mut rng = seed::stream_on(prefix, &[epoch, from - start]);
            let mut spent = 0.0;
            while spent < length {
                radio.round_start_us = from as f64 + spent;
                // Single target: only the tags still in A at the round's start answer.
                let part: &[usize] = match (flagged, radio.read_here.as_deref()) {
                    (Some(f), Some(done)) => {
                        let now = radio.instant(0.0);
                        taking_part.clear();
                        taking_part.extend(
                            field
                                .iter()
                                .copied()
                                .filter(|&t| f.is_a(t, session, now) && !done.contains(&t)),
                        );
                        if first_round {
                            none_in_a = taking_part.is_empty();
                            qfp = gen2::settled_qfp(taking_part.len());
                        }
                        first_round = false;
                        if taking_part.is_empty() {
                            break;
                        }
                        &taking_part
                    }
                    _ => &field,
                };
                let r = gen2::round_in(
                    &mut rng,
                    &times,
                    part,
                    qfp,
                    length - spent,
                    &mut radio,
                    &mut scratch,
                );
                if r.duration_us <= 0.0 {
                    break;
                }
                spent += r.duration_us + air.gap_us.max(0.0);
                qfp = r.qfp;
            }
        }
        (reads, none_in_a)
    }

    /// The reads in `[t0_us, t1_us)` of an antenna the reader never leaves, whose rounds began
    /// at `anchor_us` (see the module's doc): those of the blocks the window overlaps, each
    /// run from its start. Rounds run back to back, each with the field of the epoch it
    /// starts in (an empty field waits for the next epoch); a block's end cuts the last.
    #[allow(clippy::too_many_arguments)]
    fn chained_rounds(
        &self,
        antenna: u16,
        anchor_us: u64,
        t0_us: u64,
        t1_us: u64,
        tx: f64,
        want: Want,
        air: &Air,
        bucket: &mut Bucket,
    ) -> Vec<Read> {
        let mut reads = Vec::new();
        let t0_us = t0_us.max(anchor_us);
        if t1_us <= t0_us {
            return reads;
        }
        let times = air.mode.slot_times(EPC_BITS);
        let prefix = self.gen2_prefix(antenna);
        let mut clock = ChannelClock::new(None);
        let mut classified: Option<Arc<Classified>> = None;
        let mut field = Vec::new();
        let mut levels = Vec::new();
        let mut scratch = gen2::Scratch::default();
        let mut block_start = block_end(anchor_us, t0_us) - BLOCK_US;
        // Bounded as the epochs are (about seven hours).
        let last = t1_us.min(block_start.saturating_add(MAX_EPOCHS * FIELD_BUCKET_US));
        while block_start < last {
            let end = block_start + BLOCK_US;
            let mut now = block_start as f64;
            let mut open = None;
            let mut qfp = 0.0;
            while now < end as f64 {
                let t = now as u64;
                let epoch = t / FIELD_BUCKET_US;
                let start = epoch * FIELD_BUCKET_US;
                if open != Some(epoch) {
                    open = Some(epoch);
                    self.open_bucket(
                        antenna,
                        tx,
                        start,
                        clock.at(self, start),
                        &mut classified,
                        bucket,
                    );
                    self.field_of(bucket, &mut field);
                    levels.clear();
                    levels.resize(field.len(), f64::NAN);
                    qfp = gen2::settled_qfp(field.len());
                }
                if field.is_empty() {
                    now = (start + FIELD_BUCKET_US).min(end) as f64;
                    continue;
                }
                // Each round's draws are named by the epoch and where in it the round began.
                let offset = t - start;
                let mut rng = seed::stream_on(prefix, &[epoch, offset, 1]);
                let mut radio = EpochRadio {
                    model: self,
                    antenna,
                    tx_power_dbm: tx,
                    want,
                    round_start_us: now,
                    bucket: &mut *bucket,
                    clock: &mut clock,
                    prefix,
                    epoch,
                    from_epoch_us: offset,
                    replies: 0,
                    field: &field,
                    levels: &mut levels,
                    epoch_start_us: start,
                    read_here: None,
                    from_us: t0_us,
                    until_us: t1_us,
                    out: &mut reads,
                };
                let r = gen2::round_in(
                    &mut rng,
                    &times,
                    &field,
                    qfp,
                    end as f64 - now,
                    &mut radio,
                    &mut scratch,
                );
                if r.duration_us <= 0.0 {
                    break;
                }
                now += r.duration_us + air.gap_us.max(0.0);
                qfp = r.qfp;
            }
            block_start = end;
        }
        reads
    }

    /// How long `antenna` spends on the epoch holding `t_us` when no tag can be in its field at
    /// power `tx_power_dbm` (`None`: the scenario's) on the pinned channel if any: one round
    /// with one empty slot, after which the reader moves on (µs); `None` when a tag is or may
    /// be in it (the field's bounds, without settling undecided tags: exact once nothing
    /// moves).
    pub fn idle_us(
        &self,
        antenna: u16,
        t_us: u64,
        tx_power_dbm: Option<f64>,
        channel: Option<u16>,
        air: &Air,
    ) -> Option<u64> {
        let a = usize::from(antenna)
            .checked_sub(1)
            .and_then(|i| self.antennas.get(i))?;
        let tx = tx_power_dbm
            .filter(|p| p.is_finite())
            .unwrap_or(a.spec.tx_power_dbm);
        let pinned = channel.filter(|c| (1..=self.table.len()).contains(&usize::from(*c)));
        let start = t_us / FIELD_BUCKET_US * FIELD_BUCKET_US;
        let ch = ChannelClock::new(pinned).at(self, start);
        let occupied = self.may_be_occupied(antenna, tx, start, ch);
        if occupied {
            return None;
        }
        Some(air.empty_round_us())
    }

    /// The seed prefix of `antenna`'s rounds and replies.
    fn gen2_prefix(&self, antenna: u16) -> u64 {
        seed::mix(&[
            self.seed,
            seed::domain::GEN2,
            self.reader as u64,
            u64::from(antenna),
        ])
    }

    /// Every tag of `bucket`'s field, in tag order, into `field` (settling each undecided
    /// candidate).
    fn field_of(&self, bucket: &mut Bucket, field: &mut Vec<usize>) {
        field.clear();
        for i in 0..Model::candidates(bucket) {
            if let Some(tag) = self.settle(bucket, i) {
                field.push(tag);
            }
        }
    }
}

#[cfg(test)]
mod tests;
