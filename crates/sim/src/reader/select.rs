//! C1G2Filter: the Gen2 Select commands a reader sends before each inventory round, and which
//! tags they leave answering its Query.
//!
//! LLRP 1.1 §16.2.1.2.1.1 (C1G2Filter, C1G2TagInventoryMask and the two filter actions) maps
//! onto the Gen2 Select (GS1 EPC UHF Gen2 v2.0.1 §6.3.2.12.1.1): a tag matches when the bits
//! of bank MB from bit Pointer equal TagMask (an empty mask matches every tag; a mask that runs
//! past the end of the bank matches none). A state-unaware filter acts on the SL flag (LLRP's
//! C1G2StateUnawareAction: Select asserts SL, Unselect deasserts it) and the reader's Query
//! then takes the tags with SL asserted (Sel = SL); a state-aware one acts, as Gen2 Table
//! 6.30's Action, on the target it names (an inventoried flag S0–S3, or SL), and the Query's
//! Sel and Target come from C1G2SingulationControl's C1G2TagInventoryStateAwareSingulationAction
//! (S: SL or not SL; I: state A or B; without it Sel = All and the reader's own target).
//!
//! Each round starts from the tag's power-up state (SL deasserted, A in every session) and
//! the filters act in order. Repeating a Select before every round leaves the same state for
//! every action but the negations (state-aware actions 3 and 7), which are applied once here
//! where a real tag would alternate; an SL a tag kept from Selects before a write to its
//! memory is not kept either (ours). The masks compare the tag's memory as it is now
//! ([`TagMemory`]), so an EPC written earlier filters as written.
//!
//! Truncation (C1G2Filter T = 2) sets the Select's Truncate bit. Gen2 lets an interrogator
//! assert it only in the last Select before the Query, only on the EPC bank, only with target
//! SL and only with a mask that ends in the EPC (§6.3.2.12.1.1); a filter that breaks one of
//! those is refused (A_Invalid on T), as the reader cannot send it. A tag that takes part and
//! matches the truncating filter, under a Query whose Sel is SL or not SL, answers with the
//! EPC bits after the mask only ([`Reply::Truncated`]); a tag whose EPC ends before the
//! mask's end answers in full (ours: it cannot truncate its EPC there). T = 0 (the reader
//! decides) does not truncate.

use std::sync::Arc;

use llrp::codec::BitVec;
use llrp::params::*;
use llrp::StatusCode;

use super::caps::MAX_SELECT_FILTERS;
use super::memory::{Chip, TagMemory};
use crate::physics::gen2::{Air, Reply, Selected, Target};
use crate::physics::Model;
use crate::scenario::tagmem::TagEpc;

/// Longest TagMask a Select carries: its Length field has 8 bits (Gen2 v2.0.1 Table 6.29).
pub const MAX_MASK_BITS: u16 = 255;

/// C1G2Filter T: truncate (LLRP C1G2TruncateAction 2; 0 is unspecified, 1 do not truncate).
pub const TRUNCATE: u8 = 2;

/// Bit address of the EPC in the EPC bank (after StoredCRC and PC).
const EPC_START: u32 = 0x20;

/// Whether a state-aware filter's Target names SL: LLRP's C1G2StateAwareTarget is 0 SL, 1–4
/// the inventoried flag of S0–S3 (LLRP 1.1 §16.2.1.2.1.1.2, the LTK's enumeration; Gen2's
/// own Target field numbers them the other way, S0–S3 then SL).
fn targets_sl(target: u8) -> bool {
    target == 0
}

/// LLRP parameter types the errors name.
mod ty {
    pub const INVENTORY_COMMAND: u16 = 330;
    pub const FILTER: u16 = 331;
    pub const MASK: u16 = 332;
    pub const STATE_AWARE: u16 = 333;
    pub const STATE_UNAWARE: u16 = 334;
}

/// What the reader's Query asks of the tags after the Selects, and the Selects.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Query<'a> {
    /// The filters in order.
    pub filters: &'a [C1g2Filter],
    /// C1G2InventoryCommand's TagInventoryStateAware.
    pub state_aware: bool,
    /// Sel: `Some(true)` SL, `Some(false)` not SL, `None` all (state-aware only; state-unaware
    /// filtering always asks for SL).
    pub sel: Option<bool>,
    /// Target state B (else A) in `session` (state-aware only).
    pub target_b: bool,
    /// The Query's session.
    pub session: u8,
    /// Dual target: the reader flips its target every round, so the inventoried flags never
    /// keep a tag out.
    pub dual: bool,
}

impl<'a> Query<'a> {
    /// The Query of `cmd` (the inventory command whose filters apply) on an antenna inventoried
    /// under `air`, with `singulation` the state-aware singulation action if any; `None` when
    /// it selects nothing (no filter, state-unaware): every tag takes part.
    pub fn of(
        cmd: Option<&'a C1g2InventoryCommand>,
        singulation: Option<&C1g2TagInventoryStateAwareSingulationAction>,
        air: &Air,
    ) -> Option<Query<'a>> {
        let cmd = cmd?;
        if cmd.c1g2_filter.is_empty() && !cmd.tag_inventory_state_aware {
            return None;
        }
        let aware = cmd.tag_inventory_state_aware;
        Some(Query {
            filters: &cmd.c1g2_filter,
            state_aware: aware,
            // LLRP's S: 0 = SL, 1 = not SL; I: 0 = state A, 1 = state B.
            sel: singulation.filter(|_| aware).map(|s| !s.s),
            target_b: aware && singulation.is_some_and(|s| s.i),
            session: air.session,
            dual: air.target == Target::Dual,
        })
    }

    /// Whether the tag whose memory is `chip` answers this Query after the Selects.
    pub fn takes_part(&self, chip: &Chip) -> bool {
        if chip.killed {
            return false;
        }
        // SL and the four inventoried flags, true for "asserted" / A: the power-up state.
        let mut sl = false;
        let mut inventoried = [true; 4];
        for f in self.filters {
            let m = matches(&f.c1g2_tag_inventory_mask, chip);
            if self.state_aware {
                let Some(a) = &f.state_aware_action else {
                    continue;
                };
                let flag = if targets_sl(a.target) {
                    &mut sl
                } else {
                    // Validated 1–4: S0–S3.
                    &mut inventoried[usize::from(a.target - 1).min(3)]
                };
                apply(flag, aware_effect(a.action, m));
            } else {
                let action = f.state_unaware_action.as_ref().map_or(0, |a| a.action);
                apply(&mut sl, unaware_effect(action, m));
            }
        }
        if !self.state_aware {
            return sl;
        }
        let sel_ok = self.sel.is_none_or(|want| sl == want);
        let in_target = inventoried[usize::from(self.session.min(3))] != self.target_b;
        sel_ok && (self.dual || in_target)
    }

    /// How the tag whose memory is `chip` answers this Query's ACKs: `None` when it takes no
    /// part, truncated when the last filter truncates and it matches that filter's mask.
    pub fn reply(&self, chip: &Chip) -> Option<Reply> {
        self.takes_part(chip)
            .then(|| self.truncation(chip).unwrap_or(Reply::Full))
    }

    /// The truncated reply of `chip` if the last filter truncates, it matches that filter and
    /// the Query's Sel is SL or not SL (state-unaware filtering asks for SL).
    fn truncation(&self, chip: &Chip) -> Option<Reply> {
        let last = self.filters.last().filter(|f| f.t == TRUNCATE)?;
        if self.state_aware && self.sel.is_none() {
            return None;
        }
        let mask = &last.c1g2_tag_inventory_mask;
        if mask.mb != 1 || !matches(mask, chip) {
            return None;
        }
        let end = u32::from(mask.pointer) + u32::from(mask.tag_mask.bits);
        let skip = end.checked_sub(EPC_START)?;
        let epc_bits = chip.reported_epc().as_bytes().len() as u32 * 8;
        let bits = epc_bits.checked_sub(skip)?;
        Some(Reply::Truncated {
            // At most 496 bits (31 words) each.
            skip: skip as u16,
            bits: bits as u16,
        })
    }
}

/// What a Select does to a flag of a tag (Gen2 Table 6.30).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Effect {
    /// Assert SL, or set the inventoried flag to A.
    Up,
    /// Deassert SL, or set the inventoried flag to B.
    Down,
    /// Negate SL, or A to B and B to A.
    Flip,
    /// Do nothing.
    Keep,
}

fn apply(flag: &mut bool, e: Effect) {
    match e {
        Effect::Up => *flag = true,
        Effect::Down => *flag = false,
        Effect::Flip => *flag = !*flag,
        Effect::Keep => {}
    }
}

/// State-aware Action 0–7 (LLRP C1G2StateAwareAction, Gen2 Table 6.30) on a matching tag
/// (`m`) or a non-matching one.
fn aware_effect(action: u8, m: bool) -> Effect {
    use Effect::*;
    let (on_match, on_other) = match action {
        0 => (Up, Down),
        1 => (Up, Keep),
        2 => (Keep, Down),
        3 => (Flip, Keep),
        4 => (Down, Up),
        5 => (Down, Keep),
        6 => (Keep, Up),
        _ => (Keep, Flip),
    };
    if m {
        on_match
    } else {
        on_other
    }
}

/// State-unaware Action 0–5 on SL (LLRP C1G2StateUnawareAction: Select_Unselect,
/// Select_DoNothing, DoNothing_Unselect, Unselect_DoNothing, Unselect_Select,
/// DoNothing_Select).
fn unaware_effect(action: u8, m: bool) -> Effect {
    use Effect::*;
    let (on_match, on_other) = match action {
        0 => (Up, Down),
        1 => (Up, Keep),
        2 => (Keep, Down),
        3 => (Down, Keep),
        4 => (Down, Up),
        _ => (Keep, Up),
    };
    if m {
        on_match
    } else {
        on_other
    }
}

/// Whether `chip`'s bank MB holds TagMask from bit Pointer: a mask running past the end of
/// the bank does not match (the EPC bank starts with StoredCRC at 00h, PC at 10h, EPC at 20h).
pub fn matches(mask: &C1g2TagInventoryMask, chip: &Chip) -> bool {
    let words = chip.bank(mask.mb);
    let start = usize::from(mask.pointer);
    let len = usize::from(mask.tag_mask.bits);
    if start + len > words.len() * 16 {
        return false;
    }
    (0..len).all(|i| memory_bit(&words, start + i) == mask_bit(&mask.tag_mask, i))
}

/// The bits of `epc` from bit `skip` on, as a truncated reply sends them (an empty string
/// when `skip` reaches the end).
pub fn truncated_epc(epc: &TagEpc, skip: u16) -> BitVec {
    let bytes = epc.as_bytes();
    let total = bytes.len() * 8;
    let skip = usize::from(skip).min(total);
    let bits = total - skip;
    let mut out = vec![0u8; bits.div_ceil(8)];
    for i in 0..bits {
        if mask_bit_of(bytes, skip + i) {
            out[i / 8] |= 0x80 >> (i % 8);
        }
    }
    BitVec {
        // At most 496 bits (31 words).
        bits: bits as u16,
        bytes: out,
    }
}

fn mask_bit_of(bytes: &[u8], i: usize) -> bool {
    bytes.get(i / 8).is_some_and(|b| b >> (7 - i % 8) & 1 == 1)
}

fn memory_bit(words: &[u16], i: usize) -> bool {
    words
        .get(i / 16)
        .is_some_and(|w| w >> (15 - i % 16) & 1 == 1)
}

fn mask_bit(v: &BitVec, i: usize) -> bool {
    mask_bit_of(&v.bytes, i)
}

/// The participating sets worked out so far, each with the memory generation it holds for.
#[derive(Debug, Default)]
pub struct Selections {
    entries: Vec<Entry>,
    /// Without a filter: the tags not killed, for the memory generation it holds for (`None`
    /// inside while no tag is killed: every tag takes part).
    unfiltered: Option<(u64, Option<Arc<Selected>>)>,
}

#[derive(Debug)]
struct Entry {
    filters: Vec<C1g2Filter>,
    key: (bool, Option<bool>, bool, u8, bool),
    generation: u64,
    selected: Arc<Selected>,
}

/// Entries kept (one per distinct filter set in use; a reader rarely has more than one).
const KEPT: usize = 8;

impl Selections {
    /// The tags that answer `query` now (`None`: every tag), from the tags' current memory.
    pub fn get(
        &mut self,
        model: &Model,
        memory: &TagMemory,
        query: Option<Query<'_>>,
    ) -> Option<Arc<Selected>> {
        let Some(q) = query else {
            return self.unfiltered(model, memory);
        };
        let key = (q.state_aware, q.sel, q.target_b, q.session, q.dual);
        let generation = memory.generation();
        if let Some(e) = self
            .entries
            .iter()
            .find(|e| e.key == key && e.filters == q.filters)
        {
            if e.generation == generation {
                return Some(Arc::clone(&e.selected));
            }
        }
        let selected = Selected::from_replies(model.tag_count(), |tag| {
            memory.inspect(model, tag, |chip| q.reply(chip))
        });
        let selected = Arc::new(selected);
        self.entries
            .retain(|e| !(e.key == key && e.filters == q.filters));
        if self.entries.len() >= KEPT {
            self.entries.remove(0);
        }
        self.entries.push(Entry {
            filters: q.filters.to_vec(),
            key,
            generation,
            selected: Arc::clone(&selected),
        });
        Some(selected)
    }
}

impl Selections {
    /// The tags that take part without a filter: all but the killed ones (a killed tag does
    /// not answer a Query, so it spends no slot); `None` while no tag is killed.
    fn unfiltered(&mut self, model: &Model, memory: &TagMemory) -> Option<Arc<Selected>> {
        let generation = memory.generation();
        if let Some((g, selected)) = &self.unfiltered {
            if *g == generation {
                return selected.clone();
            }
        }
        let selected = memory.any_killed().then(|| {
            Arc::new(Selected::from_fn(model.tag_count(), |tag| {
                memory.epc(model, tag).is_some()
            }))
        });
        self.unfiltered = Some((generation, selected.clone()));
        selected
    }
}

/// Checks the filters of an inventory command against what the reader does: at most
/// [`MAX_SELECT_FILTERS`] (MaxNumSelectFiltersPerQuery), truncation only as Gen2 allows it,
/// no Select on Reserved memory, masks of at most [`MAX_MASK_BITS`] bits, actions and targets
/// in range, and a state-aware action on each filter of a state-aware inventory.
pub fn validate(cmd: &C1g2InventoryCommand) -> Result<(), LlrpStatus> {
    use ty::*;
    let n = cmd.c1g2_filter.len();
    if n > usize::from(MAX_SELECT_FILTERS) {
        return Err(error(
            &[INVENTORY_COMMAND, FILTER],
            Last::Status(StatusCode::P_OverflowParameter),
            format!("{n} C1G2Filters: the reader takes at most {MAX_SELECT_FILTERS} per query"),
        ));
    }
    for (k, f) in cmd.c1g2_filter.iter().enumerate() {
        validate_filter(f, cmd.tag_inventory_state_aware, k + 1 == n)?;
    }
    Ok(())
}

/// Why truncating filter `f` cannot be sent as a Select with Truncate (Gen2 v2.0.1
/// §6.3.2.12.1.1), if it cannot; `last`: it is the last filter, the Select before the Query.
fn truncation_refused(f: &C1g2Filter, last: bool) -> Option<String> {
    let mask = &f.c1g2_tag_inventory_mask;
    let end = u32::from(mask.pointer) + u32::from(mask.tag_mask.bits);
    let why = if !last {
        "only the last C1G2Filter (the Select before the Query) may truncate".to_string()
    } else if mask.mb != 1 {
        format!(
            "truncation needs a mask on the EPC bank (MB 1), not MB {}",
            mask.mb
        )
    } else if end < EPC_START {
        format!("truncation needs a mask that ends in the EPC (from bit 20h), this one ends at bit {end}")
    } else if f
        .state_aware_action
        .as_ref()
        .is_some_and(|a| !targets_sl(a.target))
    {
        "truncation needs a filter whose target is SL".to_string()
    } else {
        return None;
    };
    Some(format!("C1G2Filter T 2: {why}"))
}

fn validate_filter(f: &C1g2Filter, state_aware: bool, last: bool) -> Result<(), LlrpStatus> {
    use ty::*;
    use StatusCode::{A_Invalid, A_OutOfRange};
    let field = |inner: u16, field: u16, code: StatusCode, what: String| {
        let last = Last::Field(field, code);
        Err(if inner == FILTER {
            error(&[INVENTORY_COMMAND, FILTER], last, what)
        } else {
            error(&[INVENTORY_COMMAND, FILTER, inner], last, what)
        })
    };
    match f.t {
        0 | 1 => {}
        TRUNCATE => {
            if let Some(what) = truncation_refused(f, last) {
                return field(FILTER, 0, A_Invalid, what);
            }
        }
        t => return field(FILTER, 0, A_OutOfRange, format!("C1G2Filter T {t}: 0-2")),
    }
    let mask = &f.c1g2_tag_inventory_mask;
    if mask.mb == 0 {
        let what = "C1G2TagInventoryMask MB 0: a Select cannot address Reserved memory";
        return field(MASK, 0, A_Invalid, what.to_string());
    }
    if mask.tag_mask.bits > MAX_MASK_BITS {
        let what = format!(
            "C1G2TagInventoryMask of {} bits: a Select's mask has at most {MAX_MASK_BITS}",
            mask.tag_mask.bits
        );
        return field(MASK, 2, A_OutOfRange, what);
    }
    if let Some(a) = &f.state_aware_action {
        let name = "C1G2TagInventoryStateAwareFilterAction";
        if a.target > 4 {
            let what = format!("{name} Target {}: 0-4", a.target);
            return field(STATE_AWARE, 0, A_OutOfRange, what);
        }
        if a.action > 7 {
            let what = format!("{name} Action {}: 0-7", a.action);
            return field(STATE_AWARE, 1, A_OutOfRange, what);
        }
    } else if state_aware {
        return Err(error(
            &[INVENTORY_COMMAND, FILTER, STATE_AWARE],
            Last::Status(StatusCode::P_MissingParameter),
            "a state-aware inventory's C1G2Filter needs its state-aware action".into(),
        ));
    }
    match &f.state_unaware_action {
        Some(a) if a.action > 5 => {
            let what = format!(
                "C1G2TagInventoryStateUnawareFilterAction Action {}: 0-5",
                a.action
            );
            field(STATE_UNAWARE, 0, A_OutOfRange, what)
        }
        _ => Ok(()),
    }
}

/// What is wrong with the innermost parameter of an error's path.
enum Last {
    /// Its field number and the field's error code (P_FieldError).
    Field(u16, StatusCode),
    /// The parameter's own status (missing, overflow).
    Status(StatusCode),
}

/// M_ParameterError through the parameter types of `path` (outermost first), `last` saying
/// what is wrong with the innermost.
fn error(path: &[u16], last: Last, what: String) -> LlrpStatus {
    let mut inner: Option<ParameterError> = None;
    for (k, &ty) in path.iter().enumerate().rev() {
        let mut pe = ParameterError::new(ty, StatusCode::P_ParameterError);
        if k + 1 == path.len() {
            match last {
                Last::Field(field_num, error_code) => {
                    pe.error_code = StatusCode::P_FieldError;
                    pe.field_error = Some(FieldError {
                        field_num,
                        error_code,
                        ..Default::default()
                    });
                }
                Last::Status(code) => pe.error_code = code,
            }
        }
        pe.parameter_error = inner.take().map(Box::new);
        inner = Some(pe);
    }
    let mut s = LlrpStatus::new(StatusCode::M_ParameterError, what);
    s.parameter_error = inner;
    s
}

#[cfg(test)]
mod tests;
