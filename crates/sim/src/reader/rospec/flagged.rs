//! A single-target inventory's epochs (sessions 1–3, `Air::suppresses`): each antenna epoch's
//! rounds run once, from the moment the antenna gets the carrier to the epoch's end, and its
//! reads are handed out as simulated time reaches them, so the reads do not depend on how the
//! caller steps time; a tag goes to B only when its read is reported.

use super::*;
use crate::physics::gen2::Air;
use crate::physics::inventory_epoch_us;

/// One antenna epoch of a single-target inventory, computed once.
#[derive(Clone, Debug)]
pub(super) struct FlaggedEpoch {
    key: (u16, u64, u64, Want),
    air: Air,
    reads: Vec<Read>,
    next: usize,
    none_in_a: bool,
}

impl Specs {
    /// Makes sure the epoch of `antenna` holding `t` is computed (from `t`); whether no tag
    /// was in A when its rounds began.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn flagged_epoch(
        &mut self,
        ctx: &mut RunContext<'_>,
        antenna: u16,
        t: u64,
        power: Option<f64>,
        channel: Option<u16>,
        want: Want,
        air: &Air,
    ) -> bool {
        let epoch = t / inventory_epoch_us();
        let key = (antenna, epoch, power.map_or(u64::MAX, f64::to_bits), want);
        let port = usize::from(antenna);
        if self.flagged.len() <= port {
            self.flagged.resize(port + 1, None);
        }
        if let Some(f) = &self.flagged[port] {
            if f.key == key && f.air == *air {
                return f.none_in_a;
            }
        }
        let end = (epoch + 1) * inventory_epoch_us();
        let (reads, none_in_a) = ctx
            .model
            .inventory_flagged(antenna, t, end, power, channel, want, air, ctx.flags);
        self.flagged[port] = Some(FlaggedEpoch {
            key,
            air: air.clone(),
            reads,
            next: 0,
            none_in_a,
        });
        none_in_a
    }

    /// The reads of `antenna`'s computed epoch not handed out yet that come before `end`.
    pub(super) fn take_flagged(&mut self, antenna: u16, end: u64) -> Vec<Read> {
        let Some(f) = self
            .flagged
            .get_mut(usize::from(antenna))
            .and_then(Option::as_mut)
        else {
            return Vec::new();
        };
        let from = f.next;
        while f.next < f.reads.len() && f.reads[f.next].time_us < end {
            f.next += 1;
        }
        f.reads[from..f.next].to_vec()
    }
}
