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

/// What every round of one call shares: the antenna, its power, the air and its slot
/// times, what the reads carry, the seed prefix of the replies and the window whose reads
/// are kept.
#[derive(Clone, Copy)]
struct Scope<'a> {
    model: &'a Model,
    antenna: u16,
    tx_power_dbm: f64,
    air: &'a Air,
    times: gen2::SlotTimes,
    want: Want,
    /// Seed prefix of the rounds' and replies' streams.
    prefix: u64,
    /// Reads inside [from, until) are kept.
    from_us: u64,
    until_us: u64,
}

/// What one epoch's rounds need of the channel: the [`Radio`] of an antenna from an instant.
struct EpochRadio<'a> {
    scope: Scope<'a>,
    /// Absolute start of the current round (µs, fractional).
    round_start_us: f64,
    bucket: &'a mut Bucket,
    clock: &'a mut ChannelClock,
    /// The epoch (names the replies' streams with the scope's prefix).
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
    /// Reads of the epoch inside the scope's window.
    out: &'a mut Vec<Read>,
}

impl<'a> EpochRadio<'a> {
    /// A radio on `epoch`, which starts at `start_us` with the tags of `field` (their levels
    /// unknown in `levels`), its rounds from the epoch's start.
    #[allow(clippy::too_many_arguments)]
    fn new(
        scope: Scope<'a>,
        epoch: u64,
        start_us: u64,
        field: &'a [usize],
        levels: &'a mut [f64],
        bucket: &'a mut Bucket,
        clock: &'a mut ChannelClock,
        out: &'a mut Vec<Read>,
    ) -> Self {
        EpochRadio {
            scope,
            round_start_us: start_us as f64,
            bucket,
            clock,
            epoch,
            from_epoch_us: 0,
            replies: 0,
            field,
            levels,
            epoch_start_us: start_us,
            read_here: None,
            out,
        }
    }
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
            let (t, model) = (self.epoch_start_us, self.scope.model);
            let here = model.antenna_position(self.scope.antenna, t);
            let d = distance(here, model.tag_position(tag, t)).max(0.01);
            *slot = -40.0 * d.log10() + model.tags[tag].radio.backscatter_db;
        }
        *slot
    }

    fn reply(&mut self, tag: usize, t_us: f64) -> bool {
        let t = self.instant(t_us);
        let scope = &self.scope;
        let mut rng: Stream = seed::stream_on(
            scope.prefix,
            &[self.epoch, self.from_epoch_us, self.replies],
        );
        self.replies += 1;
        let channel = self.clock.at(scope.model, t);
        let read = scope.model.reply_at(
            scope.antenna,
            scope.tx_power_dbm,
            channel,
            tag,
            t,
            &mut rng,
            self.bucket,
            scope.want,
        );
        match read {
            Some(r) => {
                if (scope.from_us..scope.until_us).contains(&r.time_us) {
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
        let mut carry = Carry::new(pinned, flags.is_some());
        if t1_us <= t0_us {
            return (carry.reads, carry.none_in_a);
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
        let scope = self.scope(antenna, tx, air, want, (t0_us, t1_us));
        let first = t0_us / FIELD_BUCKET_US;
        let last = ((t1_us - 1) / FIELD_BUCKET_US).min(first.saturating_add(MAX_EPOCHS));
        for epoch in first..=last {
            self.epoch_rounds(&scope, epoch, &mut carry, bucket, flags.as_deref_mut());
        }
        (carry.reads, carry.none_in_a)
    }

    /// Runs the rounds of `epoch` for [`Model::rounds`]: back to back over the whole epoch,
    /// or with `flags` only inside the window and among the tags still in A.
    fn epoch_rounds(
        &self,
        scope: &Scope<'_>,
        epoch: u64,
        carry: &mut Carry,
        bucket: &mut Bucket,
        mut flags: Option<&mut Flags>,
    ) {
        let start = epoch * FIELD_BUCKET_US;
        self.open_epoch(scope, start, carry, bucket);
        if carry.field.is_empty() {
            carry.first_round = false;
            return;
        }
        let (air, times) = (scope.air, &scope.times);
        let session = air.session;
        let mut taking_part = Vec::new();
        if let Some(f) = flags.as_deref_mut() {
            settle_field(f, &carry.field, session, start);
        }
        let Carry {
            reads,
            clock,
            field,
            levels,
            scratch,
            read_here,
            first_round,
            none_in_a,
            ..
        } = carry;
        let mut radio = EpochRadio::new(*scope, epoch, start, field, levels, bucket, clock, reads);
        radio.read_here = flags.is_some().then_some(read_here);
        let mut qfp = gen2::settled_qfp(field.len());
        let flagged = flags.as_deref();
        let (from, to) = epoch_span(scope, start, flagged.is_some());
        let length = to.saturating_sub(from) as f64;
        radio.from_epoch_us = from - start;
        let mut rng = seed::stream_on(scope.prefix, &[epoch, from - start]);
        let mut spent = 0.0;
        while spent < length {
            radio.round_start_us = from as f64 + spent;
            // Single target: only the tags still in A at the round's start answer.
            let part: &[usize] = match (flagged, radio.read_here.as_deref()) {
                (Some(f), Some(done)) => {
                    let now = radio.instant(0.0);
                    still_in_a(&mut taking_part, field, f, session, now, done);
                    if *first_round {
                        *none_in_a = taking_part.is_empty();
                        qfp = gen2::settled_qfp(taking_part.len());
                    }
                    *first_round = false;
                    if taking_part.is_empty() {
                        break;
                    }
                    &taking_part
                }
                _ => field,
            };
            let r = gen2::round_in(
                &mut rng,
                times,
                part,
                qfp,
                length - spent,
                &mut radio,
                scratch,
            );
            if r.duration_us <= 0.0 {
                break;
            }
            spent += r.duration_us + air.gap_us.max(0.0);
            qfp = r.qfp;
        }
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
        let t0_us = t0_us.max(anchor_us);
        if t1_us <= t0_us {
            return Vec::new();
        }
        let scope = self.scope(antenna, tx, air, want, (t0_us, t1_us));
        let mut carry = Carry::new(None, false);
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
                    self.open_epoch(&scope, start, &mut carry, bucket);
                    qfp = gen2::settled_qfp(carry.field.len());
                }
                if carry.field.is_empty() {
                    now = (start + FIELD_BUCKET_US).min(end) as f64;
                    continue;
                }
                // Each round's draws are named by the epoch and where in it the round began.
                let offset = t - start;
                let mut rng = seed::stream_on(scope.prefix, &[epoch, offset, 1]);
                let c = &mut carry;
                let mut radio = EpochRadio::new(
                    scope,
                    epoch,
                    start,
                    &c.field,
                    &mut c.levels,
                    &mut *bucket,
                    &mut c.clock,
                    &mut c.reads,
                );
                radio.round_start_us = now;
                radio.from_epoch_us = offset;
                let r = gen2::round_in(
                    &mut rng,
                    &scope.times,
                    &c.field,
                    qfp,
                    end as f64 - now,
                    &mut radio,
                    &mut c.scratch,
                );
                if r.duration_us <= 0.0 {
                    break;
                }
                now += r.duration_us + air.gap_us.max(0.0);
                qfp = r.qfp;
            }
            block_start = end;
        }
        carry.reads
    }

    /// Opens `antenna`'s field for the epoch starting at `start_us`: its tags that take part
    /// ([`Air::select`]) into `carry.field`, their levels not known yet.
    fn open_epoch(&self, scope: &Scope<'_>, start_us: u64, carry: &mut Carry, bucket: &mut Bucket) {
        let ch = carry.clock.at(self, start_us);
        let (antenna, tx) = (scope.antenna, scope.tx_power_dbm);
        self.open_bucket(antenna, tx, start_us, ch, &mut carry.classified, bucket);
        self.field_of(bucket, &mut carry.field);
        // Tags the reader's Selects leave out never answer: the rounds run among the rest.
        if let Some(selected) = &scope.air.select {
            carry.field.retain(|&tag| selected.contains(tag));
        }
        carry.levels.clear();
        carry.levels.resize(carry.field.len(), f64::NAN);
    }

    /// What the rounds of a call on `antenna` at `tx` dBm under `air` share, keeping the
    /// reads in `window` [from, until).
    fn scope<'a>(
        &'a self,
        antenna: u16,
        tx: f64,
        air: &'a Air,
        want: Want,
        window: (u64, u64),
    ) -> Scope<'a> {
        Scope {
            model: self,
            antenna,
            tx_power_dbm: tx,
            air,
            // Tags that truncate their replies (a Select with Truncate) spend less on each.
            times: match air.select.as_ref().and_then(|s| s.reply_bits()) {
                Some(bits) => air.mode.slot_times_replying(bits),
                None => air.mode.slot_times(EPC_BITS),
            },
            want,
            prefix: self.gen2_prefix(antenna),
            from_us: window.0,
            until_us: window.1,
        }
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

/// What [`Model::rounds`] carries from epoch to epoch: the window's reads, the buffers the
/// epochs reuse and, in a single-target inventory, the tags read and whether no tag was in
/// A when the first round began.
struct Carry {
    reads: Vec<Read>,
    clock: ChannelClock,
    classified: Option<Arc<Classified>>,
    field: Vec<usize>,
    levels: Vec<f64>,
    scratch: gen2::Scratch,
    read_here: Vec<usize>,
    first_round: bool,
    none_in_a: bool,
}

impl Carry {
    /// Nothing read yet, on the `pinned` channel if any; `flagged`: a single-target
    /// inventory (no tag in A until a round finds one).
    fn new(pinned: Option<u16>, flagged: bool) -> Carry {
        Carry {
            reads: Vec::new(),
            clock: ChannelClock::new(pinned),
            classified: None,
            field: Vec::new(),
            levels: Vec::new(),
            scratch: gen2::Scratch::default(),
            read_here: Vec::new(),
            first_round: true,
            none_in_a: flagged,
        }
    }
}

/// The span of the epoch starting at `start` its rounds run over: all of it (its reads are
/// filtered to the window), or, in a single-target inventory (`flagged`), which carries
/// flags from call to call, only its part inside the window, so that no read outside it
/// changes a flag.
fn epoch_span(scope: &Scope<'_>, start: u64, flagged: bool) -> (u64, u64) {
    if flagged {
        (
            start.max(scope.from_us),
            (start + FIELD_BUCKET_US).min(scope.until_us),
        )
    } else {
        (start, start + FIELD_BUCKET_US)
    }
}

/// Brings the flags of the tags of `field` in `session` up to `start_us` and energises them.
fn settle_field(flags: &mut Flags, field: &[usize], session: u8, start_us: u64) {
    for &tag in field {
        flags.settle(tag, session, start_us);
        flags.energise(tag, start_us);
    }
}

/// The tags of `field` in A in `session` at `now_us` and not in `done`, into `taking_part`.
#[inline]
fn still_in_a(
    taking_part: &mut Vec<usize>,
    field: &[usize],
    flags: &Flags,
    session: u8,
    now_us: u64,
    done: &[usize],
) {
    taking_part.clear();
    taking_part.extend(
        field
            .iter()
            .copied()
            .filter(|&t| flags.is_a(t, session, now_us) && !done.contains(&t)),
    );
}

#[cfg(test)]
mod tests;
