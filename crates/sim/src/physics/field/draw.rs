//! A bucket's draw state and the draw itself: the candidates of the bucket's classification,
//! a uniform draw among them that settles each undecided one when it is hit, and the links of
//! the tags drawn.

use std::sync::Arc;

use super::cache::{Kept, Memo};
use super::grid::Classified;
use super::near::Near;
use super::{amplitude_threshold, reach_m};
use crate::physics::geometry::distance;
use crate::physics::multipath::{power_gain_with, Aim, Channel};
use crate::physics::Model;

/// Whether a candidate tag is in the bucket's field.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Known {
    In,
    Out,
    Unknown,
}

/// One bucket's draw state: the tags that may be in its field, and what is known of each.
#[derive(Clone, Debug, Default)]
pub(in crate::physics) struct Bucket {
    pub(super) antenna: u16,
    pub(super) t_us: u64,
    /// Time since this antenna's previous bucket (0 when unknown): a kept decision shorter
    /// than that is never asked for again, so it is not worth proving.
    pub(super) revisit_us: u64,
    pub(super) wavelength_m: f64,
    /// The field needs g₀·|1 + Σ Hᵢ|²/D² at least this (the tag sensitivity at this power and
    /// wavelength).
    pub(super) threshold: f64,
    /// The same threshold on the amplitude √g₀·|1 + Σ Hᵢ|/D (its square root, up to rounding).
    pub(super) amplitude: f64,
    /// Reach of the antenna (m).
    pub(super) reach: f64,
    /// Candidates in tag order.
    pub(super) pool: Vec<(usize, Known)>,
    /// How many candidates are known not to be in the field.
    pub(super) out: usize,
    /// The antenna at the bucket start, once an undecided tag needed it.
    pub(super) aim: Option<Aim>,
    /// The same, prepared for the fast field test (valid while `aim` is set).
    pub(super) near: Near,
    /// The classification when nothing moves any more (its links serve the replies).
    pub(super) rest: Option<Arc<Classified>>,
    /// The antenna, power bits and [`amplitude_threshold`] of the last bucket prepared (its
    /// `powf` once per antenna and power rather than once per bucket).
    pub(super) base: Option<(u16, u64, f64)>,
    /// The bucket's channel.
    pub(super) channel: u16,
    /// The antenna's decisions kept from earlier buckets (see [`Memo`]).
    pub(in crate::physics) memo: Memo,
}

impl Model {
    /// Prepares `bucket` for draws in the field of `antenna` at bucket start `t_us` on
    /// `channel`, with the antenna's classification for it in `held` (replaced if it does not
    /// hold there).
    pub(in crate::physics) fn open_bucket(
        &self,
        antenna: u16,
        tx_power_dbm: f64,
        t_us: u64,
        channel: u16,
        held: &mut Option<Arc<Classified>>,
        bucket: &mut Bucket,
    ) {
        if !held.as_ref().is_some_and(|c| c.holds(t_us, tx_power_dbm)) {
            *held = Some(self.classification(antenna, tx_power_dbm, t_us));
        }
        self.prepare(bucket, antenna, tx_power_dbm, t_us, channel);
        let Some(c) = held.as_deref() else {
            return;
        };
        if let Some(field) = c.at_rest.get(usize::from(channel).wrapping_sub(1)) {
            bucket.pool.extend(field.iter().map(|&t| (t, Known::In)));
            bucket.rest = held.clone();
            return;
        }
        bucket.pool.extend_from_slice(&c.pool);
    }

    /// Empties `bucket` for the field of `antenna` at `t_us` on `channel`.
    pub(super) fn prepare(
        &self,
        bucket: &mut Bucket,
        antenna: u16,
        tx_power_dbm: f64,
        t_us: u64,
        channel: u16,
    ) {
        let spec = &self.antennas[usize::from(antenna) - 1].spec;
        bucket.revisit_us = if bucket.antenna == antenna && bucket.t_us < t_us {
            t_us - bucket.t_us
        } else {
            0
        };
        bucket.antenna = antenna;
        bucket.t_us = t_us;
        bucket.channel = channel;
        bucket.wavelength_m = self.wavelength_m(channel);
        let key = (antenna, tx_power_dbm.to_bits());
        let base = match bucket.base {
            Some((a, tx, base)) if (a, tx) == key => base,
            _ => {
                let base = amplitude_threshold(spec, tx_power_dbm);
                bucket.base = Some((key.0, key.1, base));
                base
            }
        };
        bucket.amplitude = base / bucket.wavelength_m;
        bucket.threshold = bucket.amplitude.powi(2);
        bucket.reach = reach_m(spec);
        bucket.aim = None;
        bucket.pool.clear();
        bucket.out = 0;
        bucket.rest = None;
    }

    /// The channel and forward-link margin (dB) of `tag` from `antenna` at `t_us` on channel
    /// `channel`: those of [`Model::margin_with`] at the antenna's pose then (the delay only
    /// if `delay`), taken from `bucket`'s classification once nothing moves any more.
    #[allow(clippy::too_many_arguments)]
    pub(in crate::physics) fn link(
        &self,
        bucket: &Bucket,
        antenna: u16,
        tag: usize,
        t_us: u64,
        channel: u16,
        tx_power_dbm: f64,
        delay: bool,
    ) -> (Channel, f64) {
        let lambda = self.wavelength_m(channel);
        let compute = |delay| {
            let aim = self.aim(antenna, t_us);
            let position = self.tag_position(tag, t_us);
            self.margin_with(antenna, tag, &aim, position, lambda, tx_power_dbm, delay)
        };
        // A kept link serves every later request, so it has its delay.
        let cached = bucket.rest.as_ref().and_then(|c| {
            let ch = usize::from(channel).checked_sub(1)?;
            // The field at rest is in tag order.
            let k = c.at_rest.get(ch)?.binary_search(&tag).ok()?;
            let slot = c.links.get(ch)?.get(k)?;
            (t_us >= c.t0_us && c.tx_bits == tx_power_dbm.to_bits())
                .then(|| *slot.get_or_init(|| compute(true)))
        });
        cached.unwrap_or_else(|| compute(delay))
    }

    /// How many candidates `bucket` has.
    pub(in crate::physics) fn candidates(bucket: &Bucket) -> usize {
        bucket.pool.len()
    }

    /// The tag of candidate `i` of the bucket if it is in the field (an undecided one is
    /// settled and remembered as a draw would).
    pub(in crate::physics) fn settle(&self, bucket: &mut Bucket, i: usize) -> Option<usize> {
        let (tag, known) = *bucket.pool.get(i)?;
        match known {
            Known::In => Some(tag),
            Known::Out => None,
            Known::Unknown => {
                if self.in_field(bucket, tag) {
                    bucket.pool[i].1 = Known::In;
                    Some(tag)
                } else {
                    bucket.pool[i].1 = Known::Out;
                    bucket.out += 1;
                    None
                }
            }
        }
    }

    /// Whether `tag` is in the field at the bucket start: within reach and powered.
    pub(super) fn in_field(&self, bucket: &mut Bucket, tag: usize) -> bool {
        let antenna = bucket.antenna;
        let t_us = bucket.t_us;
        if let Some(k) = bucket.memo.kept.get(tag) {
            if k.channel == bucket.channel && k.from_us <= t_us && t_us <= k.until_us {
                return k.inside;
            }
        }
        let a = &self.antennas[usize::from(antenna) - 1];
        let aim = match bucket.aim {
            Some(aim) => aim,
            None => {
                let aim = self.aim(antenna, t_us);
                bucket.near.prepare(&aim, &self.planes, bucket.wavelength_m);
                bucket.aim = Some(aim);
                aim
            }
        };
        let position = self.tag_position(tag, t_us);
        let dist = distance(aim.position, position);
        if dist > bucket.reach {
            return false;
        }
        let radio = &self.tags[tag].radio;
        let scale = radio.amplitude_scale;
        if radio.axis.is_some() {
            // An oriented tag's own pattern is outside the bounds: always the exact sum.
            let gain = power_gain_with(
                &aim,
                &a.pattern,
                position,
                &self.planes,
                bucket.wavelength_m,
            );
            return gain * radio.gain_factor(aim.position, position)
                >= bucket.threshold * scale * scale;
        }
        if let Some((known, margin)) =
            bucket
                .near
                .decide(&a.gains, position, dist, bucket.amplitude * scale)
        {
            if let (Some(rates), Some(k)) = (a.rates, bucket.memo.kept.get_mut(tag)) {
                let tag_speed = self.tags[tag].motion.speed();
                let room = known.then_some(bucket.reach - dist);
                let hold = bucket.near.steady(
                    &a.gains,
                    margin,
                    (rates.speed, tag_speed, rates.turn),
                    room,
                    bucket.memo.exhaustive,
                    bucket.revisit_us,
                );
                if hold > 0 {
                    *k = Kept {
                        from_us: t_us,
                        until_us: t_us.saturating_add(hold),
                        channel: bucket.channel,
                        inside: known,
                    };
                }
            }
            return known;
        }
        power_gain_with(
            &aim,
            &a.pattern,
            position,
            &self.planes,
            bucket.wavelength_m,
        ) >= bucket.threshold * scale * scale
    }
}
