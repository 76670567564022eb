//! The EPC Gen2 air interface as a reader runs it: link timing from an RF mode, and
//! slotted-ALOHA inventory rounds under the Q algorithm, with the capture effect.
//!
//! Timing (GS1 EPC UHF Gen2 air interface, v2.0.0, §6.3.1; command and reply lengths as
//! reproduced in docs/measurement.md): reader symbols data-0 = Tari and data-1 = PIE·Tari
//! (an average bit of (1 + PIE)/2·Tari), RTcal = data-0 + data-1, TRcal = DR/BLF with
//! DR = 64/3; a Query is preceded by a preamble (delimiter 12.5 µs, data-0, RTcal, TRcal), every
//! other command by a frame-sync (delimiter, data-0, RTcal). Tag bits last M/BLF (M = 1 for FM0,
//! 2/4/8 for Miller); a reply carries a preamble (FM0 6 bits, Miller 10; 12 and 16 pilot bits more
//! with TRext) and a dummy bit. T1 = max(RTcal, 10/BLF), T2 = 10/BLF (the middle of 3–20),
//! T3 = max(0, 2·RTcal − T1). Slots: empty = QueryRep + T1 + T3; collided = QueryRep + T1 +
//! RN16 + T2; successful = QueryRep + T1 + RN16 + T2 + ACK + T1 + PC/EPC/CRC + T2.
//!
//! Q algorithm (the standard's Annex D): Qfp ∈ [0, 15], −C after an empty slot, +C after a
//! collision, unchanged after a single reply; when round(Qfp) changes the reader sends a
//! QueryAdjust and the tags not yet read draw new slots among 2^Q.

use std::sync::Arc;

use rand::{Rng, RngCore};

mod selected;
pub use selected::{Reply, Selected, FULL_REPLY_BITS};

/// Bits of a Query command.
pub const QUERY_BITS: u32 = 22;
/// Bits of a QueryRep command.
pub const QUERY_REP_BITS: u32 = 4;
/// Bits of a QueryAdjust command.
pub const QUERY_ADJUST_BITS: u32 = 9;
/// Bits of an ACK command.
pub const ACK_BITS: u32 = 18;
/// Bits of the RN16 reply.
pub const RN16_BITS: u32 = 16;
/// Delimiter before every reader command (µs).
pub const DELIMITER_US: f64 = 12.5;
/// Divide ratio DR of TRcal (64/3, as every Impinj mode uses).
pub const DIVIDE_RATIO: f64 = 64.0 / 3.0;
/// The Q algorithm's step C (Annex D gives 0.1 < C < 0.5).
pub const Q_STEP: f64 = 0.3;
/// Largest Q.
pub const MAX_Q: u8 = 15;
/// A colliding reply this many dB above every other reply in its slot is decoded anyway (the
/// capture effect; ours).
pub const CAPTURE_MARGIN_DB: f64 = 6.0;

/// Most frames (Query or QueryAdjust) one round runs.
pub const MAX_FRAMES: u64 = 1 << 12;

/// An RF mode's air-interface parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RfMode {
    /// Reader data-0 symbol (µs).
    pub tari_us: f64,
    /// data-1 / data-0 (1.5–2.0).
    pub pie: f64,
    /// Backscatter link frequency (kHz).
    pub blf_khz: f64,
    /// Symbols per tag bit: 1 (FM0), 2, 4 or 8 (Miller).
    pub miller: u8,
    /// Extended (pilot) preamble on tag replies.
    pub trext: bool,
}

/// Which inventoried flag the reader singulates.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Target {
    /// A to B, then B to A, and so on: every tag is read in every round.
    #[default]
    Dual,
    /// A only: a tag read goes to B and is not read again until its flag persistence ends.
    Single,
}

/// How the reader inventories on an antenna: RF mode, session, search target and the tags its
/// Selects leave in the rounds.
#[derive(Clone, Debug, PartialEq)]
pub struct Air {
    /// The RF mode's link parameters.
    pub mode: RfMode,
    /// Gen2 session, 0–3.
    pub session: u8,
    /// Search target.
    pub target: Target,
    /// Where the reader never leaves this antenna (its AISpec's only one): when its first
    /// round began (µs); its rounds run back to back from there ([`super::rounds`]).
    pub anchor_us: Option<u64>,
    /// The reader's pause after each inventory round before its next Query (µs): its own
    /// processing, which a real reader's continuous inventory of one tag shows.
    pub gap_us: f64,
    /// The tags the reader's Select commands (LLRP C1G2Filters) leave taking part in the
    /// rounds; `None`: every tag in the field.
    pub select: Option<Arc<Selected>>,
}

impl Default for Air {
    /// The reader's defaults: mode 1000 (AutoSet, as advertised), session 2, dual target.
    fn default() -> Air {
        Air {
            mode: RfMode::impinj(1000).unwrap_or(RfMode::IMPINJ_MODE_2),
            session: 2,
            target: Target::Dual,
            anchor_us: None,
            gap_us: 0.0,
            select: None,
        }
    }
}

impl Air {
    /// Whether a tag read once keeps out of later rounds: single target in sessions 1–3 (a
    /// session-0 flag reverts as soon as the tag loses power, which it does between rounds
    /// on an Impinj reader, so session 0 rereads: our reading).
    pub fn suppresses(&self) -> bool {
        self.target == Target::Single && self.session != 0
    }

    /// A round nobody answers (a Query and one empty slot at Q = 0) and the pause after it, in
    /// whole µs: what an antenna facing no tag costs before the reader moves on.
    pub fn empty_round_us(&self) -> u64 {
        let times = self.mode.slot_times(96);
        (times.query_extra_us + times.empty_us + self.gap_us.max(0.0))
            .ceil()
            .max(1.0) as u64
    }
}

/// Durations (µs) of the parts of an inventory round in one RF mode.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SlotTimes {
    /// The Query that opens a round, with its preamble, up to the end of the first slot's T1.
    pub query_extra_us: f64,
    /// A QueryAdjust's extra time over a QueryRep.
    pub adjust_extra_us: f64,
    /// A slot nobody answers.
    pub empty_us: f64,
    /// A slot two or more tags answer and nobody is decoded.
    pub collided_us: f64,
    /// A slot that ends with a tag's EPC read.
    pub success_us: f64,
}

impl RfMode {
    /// Impinj's Mode 2 (Dense Reader M4) as a real R220 advertises it: Miller 4, BLF 274 kHz,
    /// Tari 20 µs, PIE 2.0 (sllurp `examples/caps.txt`).
    pub const IMPINJ_MODE_2: RfMode = RfMode {
        tari_us: 20.0,
        pie: 2.0,
        blf_khz: 274.0,
        miller: 4,
        trext: false,
    };

    /// Impinj's Mode 0 (Max Throughput) as an FCC R420 advertises it: FM0, BLF 640 kHz,
    /// Tari 7.14 µs, PIE 1.5.
    pub const IMPINJ_MODE_0: RfMode = RfMode {
        tari_us: 7.14,
        pie: 1.5,
        blf_khz: 640.0,
        miller: 1,
        trext: false,
    };

    /// The RF mode the simulated reader advertises under ModeIdentifier `id` (its C1G2 UHF
    /// RF mode table): 0 FM0 at 640 kHz (Tari 7.14 µs, as an FCC R420), 1 Miller 2 at 640 kHz
    /// (Tari 6.25 µs, as an R420 in sllurp issue #19), 2 Miller 4 at 274 kHz and 3 Miller 8 at
    /// 170.6 kHz (as an R220), 1000 (AutoSet) Miller 4 at 250 kHz; `None` for another.
    pub fn impinj(id: u32) -> Option<RfMode> {
        let (miller, blf_khz, pie, tari_us) = match id {
            0 => (1, 640.0, 1.5, 7.14),
            1 => (2, 640.0, 1.5, 6.25),
            2 => (4, 274.0, 2.0, 20.0),
            3 => (8, 170.6, 2.0, 20.0),
            1000 => (4, 250.0, 2.0, 20.0),
            _ => return None,
        };
        Some(RfMode {
            tari_us,
            pie,
            blf_khz,
            miller,
            trext: false,
        })
    }

    /// The durations of an inventory round's parts, for tags with `epc_bits` of EPC.
    pub fn slot_times(&self, epc_bits: u32) -> SlotTimes {
        self.slot_times_replying(16 + epc_bits + 16)
    }

    /// The durations of an inventory round's parts, for tags that answer an ACK with
    /// `reply_bits` (PC, EPC and CRC-16; fewer when they truncate their reply).
    pub fn slot_times_replying(&self, reply_bits: u32) -> SlotTimes {
        let data0 = self.tari_us;
        let data1 = self.pie * self.tari_us;
        let rtcal = data0 + data1;
        let trcal = DIVIDE_RATIO / self.blf_khz * 1e3;
        let reader_bit = (data0 + data1) / 2.0;
        let frame_sync = DELIMITER_US + data0 + rtcal;
        let command = |bits: u32| frame_sync + f64::from(bits) * reader_bit;
        let tpri = 1e3 / self.blf_khz;
        let tag_bit = f64::from(self.miller.max(1)) * tpri;
        let preamble_bits = match (self.miller <= 1, self.trext) {
            (true, false) => 6.0,
            (true, true) => 18.0,
            (false, false) => 10.0,
            (false, true) => 26.0,
        };
        let reply = |bits: u32| (preamble_bits + f64::from(bits) + 1.0) * tag_bit;
        let t1 = rtcal.max(10.0 * tpri);
        let t2 = 10.0 * tpri;
        let t3 = (2.0 * rtcal - t1).max(0.0);
        let query_rep = command(QUERY_REP_BITS);
        let rn16 = reply(RN16_BITS);
        let epc_reply = reply(reply_bits);
        SlotTimes {
            query_extra_us: command(QUERY_BITS) + trcal - query_rep,
            adjust_extra_us: command(QUERY_ADJUST_BITS) - query_rep,
            empty_us: query_rep + t1 + t3,
            collided_us: query_rep + t1 + rn16 + t2,
            success_us: query_rep + t1 + rn16 + t2 + command(ACK_BITS) + t1 + epc_reply + t2,
        }
    }
}

/// What a round asks of the channel: how strong a tag's reply is, and whether the reader
/// decodes it (the caller computes the read then, at that instant).
pub trait Radio {
    /// Level (dBm) of `tag`'s reply at `t_us` µs into the round, for the capture effect.
    fn level(&mut self, tag: usize, t_us: f64) -> f64;
    /// Whether the reader decodes `tag`'s EPC reply ending at `t_us` µs into the round
    /// (false: it is not powered, out of reach, or too weak; the reader hears nothing).
    fn reply(&mut self, tag: usize, t_us: f64) -> bool;
}

/// What one inventory round gave.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Round {
    /// Each tag read, with the time (µs from the round's start) its EPC was received.
    pub reads: Vec<(f64, usize)>,
    /// Duration of the round (µs).
    pub duration_us: f64,
    /// Qfp at the end of the round.
    pub qfp: f64,
    /// Slots by outcome: empty (or not decoded), collided, read.
    pub slots: [u32; 3],
}

/// The Qfp a reader settles on for `n` tags: log2 n (a frame as long as the population,
/// where framed ALOHA reads most per slot).
pub fn settled_qfp(n: usize) -> f64 {
    (n.max(1) as f64).log2().min(f64::from(MAX_Q))
}

/// Runs one inventory round over `tags` from Qfp `qfp`, until every tag has been read, a frame
/// passes with nothing read and no collision (the tags left do not answer), or `budget_us` is
/// spent (the round is cut there, as when the reader leaves the antenna). Each tag is read at
/// most once. A collided slot is read anyway when one reply stands [`CAPTURE_MARGIN_DB`] above
/// every other (capture effect).
pub fn round<R: RngCore + ?Sized>(
    rng: &mut R,
    times: &SlotTimes,
    tags: &[usize],
    qfp: f64,
    budget_us: f64,
    radio: &mut impl Radio,
) -> Round {
    round_in(
        rng,
        times,
        tags,
        qfp,
        budget_us,
        radio,
        &mut Scratch::default(),
    )
}

/// Buffers [`round_in`] reuses from round to round.
#[derive(Clone, Debug, Default)]
pub struct Scratch {
    waiting: Vec<usize>,
    /// The replies in the current slot (indices into `waiting`).
    answering: Vec<usize>,
    read_now: Vec<usize>,
}

/// A uniform index in [0, n) (n > 0) from exactly one draw (the top of n·u64), so that a slot
/// always costs the same draws; its bias, at most n/2⁶⁴, is far below anything measured.
/// (`gen_range` rejects and redraws a varying number of times.)
fn below<R: RngCore + ?Sized>(rng: &mut R, n: usize) -> usize {
    ((u128::from(rng.next_u64()) * n as u128) >> 64) as usize
}

/// How many of `m` tags not yet placed in this frame pick the next slot when `left` slots
/// remain (each tag's slot uniform among the frame's: Binomial(m, 1/left)).
fn in_next_slot<R: RngCore + ?Sized>(rng: &mut R, m: usize, left: u64) -> usize {
    if left <= 1 || m == 0 {
        return m;
    }
    let p = 1.0 / left as f64;
    let mut prob = (1.0 - p).powi(m.min(i32::MAX as usize) as i32);
    if prob < 1e-200 {
        // Far too many tags for the frame (a collision for certain): one draw each.
        return (0..m).filter(|_| rng.gen::<f64>() < p).count();
    }
    // Inversion: the smallest k whose cumulative probability reaches the draw.
    let u: f64 = rng.gen();
    let (mut k, mut cdf) = (0usize, prob);
    let ratio = p / (1.0 - p);
    while u >= cdf && k < m {
        prob *= (m - k) as f64 / (k + 1) as f64 * ratio;
        k += 1;
        cdf += prob;
    }
    k
}

/// [`round`] with the caller's buffers.
///
/// Each tag's slot is uniform among the frame's and independent of the others'; the slots are
/// drawn as the reader reaches them (how many of the tags not yet placed pick this one, then
/// which), so a frame that a QueryAdjust or the budget ends a few slots in costs those slots,
/// not a draw for every tag in the field.
pub fn round_in<R: RngCore + ?Sized>(
    rng: &mut R,
    times: &SlotTimes,
    tags: &[usize],
    qfp: f64,
    budget_us: f64,
    radio: &mut impl Radio,
    scratch: &mut Scratch,
) -> Round {
    let mut out = Round {
        qfp: qfp.clamp(0.0, f64::from(MAX_Q)),
        ..Round::default()
    };
    let Scratch {
        waiting,
        answering,
        read_now,
    } = scratch;
    waiting.clear();
    waiting.extend_from_slice(tags);
    read_now.clear();
    let mut t = times.query_extra_us;
    let mut frames = 0u64;
    'frames: while frames < MAX_FRAMES {
        frames += 1;
        let q = out.qfp.round() as u32;
        let frame = 1u64 << q;
        // waiting[..free] have no slot yet in this frame; the slots reached keep theirs past it.
        let mut free = waiting.len();
        let mut progressed = false;
        let mut collided = false;
        for slot in 0..frame {
            draw_slot(rng, waiting, answering, &mut free, frame - slot);
            // The reply the reader may decode: a lone one, or a captured one.
            let (candidate, collision) = match answering.as_slice() {
                [] => (None, false),
                [i] => (Some(*i), false),
                many => (captured(waiting, many, t, radio), true),
            };
            let decoded = candidate
                .filter(|_| t + times.success_us <= budget_us)
                .filter(|&i| radio.reply(waiting[i], t + times.success_us));
            let (dt, outcome) = slot_outcome(times, decoded.is_some(), collision);
            if t + dt > budget_us {
                break 'frames;
            }
            t += dt;
            out.slots[outcome] += 1;
            collided |= collision;
            if let Some(i) = decoded {
                read_now.push(i);
                progressed = true;
                out.reads.push((t, waiting[i]));
            }
            out.qfp = adjusted_qfp(out.qfp, outcome, decoded.is_some());
            if out.qfp.round() as u32 != q && slot + 1 < frame {
                // QueryAdjust: the tags not yet read draw again among 2^Q' slots.
                t += times.adjust_extra_us;
                remove_read(waiting, read_now);
                if waiting.is_empty() {
                    break 'frames;
                }
                continue 'frames;
            }
        }
        remove_read(waiting, read_now);
        if waiting.is_empty() || !(progressed || collided) {
            break;
        }
        // The next frame opens with a QueryAdjust (the tags left wait at 7FFFh for it).
        t += times.adjust_extra_us;
    }
    out.duration_us = t.min(budget_us.max(0.0));
    out
}

/// Draws which of the `free` tags of `waiting` without a slot answer in the next of the
/// frame's `left` slots: they leave the free ones (`waiting[..free]`), their indices go to
/// `answering`.
#[inline]
fn draw_slot<R: RngCore + ?Sized>(
    rng: &mut R,
    waiting: &mut [usize],
    answering: &mut Vec<usize>,
    free: &mut usize,
    left: u64,
) {
    answering.clear();
    let k = if *free == 0 {
        0
    } else {
        in_next_slot(rng, *free, left)
    };
    for _ in 0..k {
        let i = below(rng, *free);
        *free -= 1;
        waiting.swap(i, *free);
        answering.push(*free);
    }
}

/// What a slot costs (µs) and its outcome index: 0 nothing heard, 1 collided, 2 read.
#[inline]
fn slot_outcome(times: &SlotTimes, decoded: bool, collision: bool) -> (f64, usize) {
    match (decoded, collision) {
        (true, _) => (times.success_us, 2),
        (false, true) => (times.collided_us, 1),
        (false, false) => (times.empty_us, 0),
    }
}

/// The Q algorithm's Qfp after a slot with `outcome` (see [`slot_outcome`]): down after an
/// empty slot, up after a collision nothing was decoded from.
#[inline]
fn adjusted_qfp(qfp: f64, outcome: usize, decoded: bool) -> f64 {
    match outcome {
        0 => (qfp - Q_STEP).max(0.0),
        1 if !decoded => (qfp + Q_STEP).min(f64::from(MAX_Q)),
        _ => qfp,
    }
}

/// Drops the tags read in this frame from `waiting` (indices into it).
fn remove_read(waiting: &mut Vec<usize>, read: &mut Vec<usize>) {
    read.sort_unstable();
    for &i in read.iter().rev() {
        waiting.swap_remove(i);
    }
    read.clear();
}

/// The index (into `waiting`) of the reply the reader may decode in a collided slot: the
/// strongest, if it stands [`CAPTURE_MARGIN_DB`] above all others.
fn captured(
    waiting: &[usize],
    answering: &[usize],
    t_us: f64,
    radio: &mut impl Radio,
) -> Option<usize> {
    let mut best: Option<(f64, usize)> = None;
    let mut second = f64::NEG_INFINITY;
    for &i in answering {
        let r = radio.level(waiting[i], t_us);
        match best {
            Some((b, _)) if r <= b => second = second.max(r),
            Some((b, _)) => {
                second = second.max(b);
                best = Some((r, i));
            }
            None => best = Some((r, i)),
        }
    }
    let (b, i) = best?;
    (b - second >= CAPTURE_MARGIN_DB).then_some(i)
}

#[cfg(test)]
mod tests;
