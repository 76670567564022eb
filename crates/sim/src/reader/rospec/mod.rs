//! ROSpecs: the lifecycle (add, enable, start, stop, disable, delete), start and stop triggers,
//! priorities and the execution of AISpecs over simulated time.
//!
//! Split by what each part does: this file holds the specs, their states and lifecycle;
//! `schedule` when a spec starts and what is next due; `execute` running the active spec over
//! simulated time; `validate` what ADD_ROSPEC accepts.

mod air;
mod execute;
mod flagged;
mod gpi;
mod schedule;
mod stops;
mod validate;

use schedule::{first_start, start_type};
use validate::validate;

use std::collections::HashSet;
use std::sync::Arc;

use llrp::enums::*;
use llrp::params::*;
use llrp::StatusCode;

use super::access::AccessSpecs;
use super::config::{param_field_error, validate_antenna_config, ReaderConfig};
use super::report::{Content, ImpinjContent, Observation, ReportBuffer};
use super::select::Selections;
use super::{field_error, ReaderProfile};
use crate::physics::lookahead::{Lookahead, Slice};
use crate::physics::{Model, Read, Want};

/// Simulated time each antenna of an AISpec gets before the reader moves to the next, µs.
pub const ANTENNA_DWELL_US: u64 = 25_000;

/// End of the antenna dwell that starts at `t_us`: the next point of the fixed dwell grid
/// (the physics' epoch grid, so that a dwell is one epoch of inventory rounds).
pub fn dwell_end(t_us: u64) -> u64 {
    (t_us / ANTENNA_DWELL_US + 1).saturating_mul(ANTENNA_DWELL_US)
}
/// Earliest restart of an Immediate ROSpec after its previous run began, µs (so a spec that
/// completes at once cannot spin).
const MIN_RESTART_US: u64 = 1_000;

/// ROSpec state (what GET_ROSPECS reports as CurrentState).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SpecState {
    /// Added, not enabled.
    Disabled,
    /// Enabled, waiting for its start trigger.
    Inactive,
    /// Executing.
    Active,
}

impl SpecState {
    fn code(self) -> RoSpecState {
        match self {
            SpecState::Disabled => RoSpecState::Disabled,
            SpecState::Inactive => RoSpecState::Inactive,
            SpecState::Active => RoSpecState::Active,
        }
    }
}

/// An event for the client (sent if its notification is enabled).
#[derive(Clone, Debug, PartialEq)]
pub struct Event {
    /// When it happened, simulated µs.
    pub at_us: u64,
    /// What happened.
    pub kind: EventKind,
}

/// The kinds of event the ROSpec machinery raises.
#[derive(Clone, Debug, PartialEq)]
pub enum EventKind {
    /// ROSpecEvent: start, end, preempted.
    RoSpec {
        /// Event type.
        event_type: RoSpecEventType,
        /// The ROSpec.
        ro_spec_id: u32,
        /// The ROSpec that preempted it (type 2), else 0.
        preempting: u32,
    },
    /// AISpecEvent: end of an AISpec.
    AiSpecEnd {
        /// The ROSpec.
        ro_spec_id: u32,
        /// 1-based index of the AISpec.
        spec_index: u16,
    },
}

impl Event {
    /// The ReaderEventNotificationSpec event type that enables this event.
    pub fn notification_type(&self) -> NotificationEventType {
        match self.kind {
            EventKind::RoSpec { .. } => NotificationEventType::RoSpecEvent,
            EventKind::AiSpecEnd { .. } => NotificationEventType::AiSpecEvent,
        }
    }
}

/// What running the specs produced, in order.
#[derive(Clone, Debug, PartialEq)]
pub enum Produced {
    /// An RO_ACCESS_REPORT's worth of tag reports.
    Reports(Vec<TagReportData>),
    /// An event.
    Event(Event),
}

/// Everything a run needs from the rest of the reader.
pub struct RunContext<'a> {
    /// Physics of this reader.
    pub model: &'a Arc<Model>,
    /// The reader's description.
    pub profile: &'a ReaderProfile,
    /// Current configuration (antenna power, default report spec).
    pub config: &'a ReaderConfig,
    /// AccessSpecs to apply to each read.
    pub access: &'a mut AccessSpecs,
    /// The tags' memory (what their EPCs are now, which are killed).
    pub memory: &'a super::memory::TagMemory,
    /// The session's LLRP version (1 = 1.0.1, 2 = 1.1): the result codes of access
    /// operations differ.
    pub version: u8,
    /// The reader's inventoried flags (single-target inventories in sessions 1–3).
    pub flags: &'a mut crate::physics::flags::Flags,
    /// UTC of simulated time 0, µs.
    pub utc_epoch_us: u64,
    /// Impinj extensions enabled on the connection.
    pub impinj: bool,
    /// The faults in force (antenna ports unplugged).
    pub faults: &'a super::faults::State,
}

/// One ROSpec and its execution state.
#[derive(Clone, Debug)]
pub struct Spec {
    /// Shared so each execution step can hold it while the spec list changes.
    spec: Arc<RoSpec>,
    /// Current state.
    pub state: SpecState,
    /// When its start trigger next fires (Immediate restarts, periodic starts).
    next_start_us: Option<u64>,
    run: Option<Run>,
}

#[derive(Clone, Debug)]
struct Run {
    started_us: u64,
    spec_idx: usize,
    spec_started_us: u64,
    antenna_pos: usize,
    slice_end_us: u64,
    /// Whether the current antenna's field has been looked at since the reader moved to it.
    slice_checked: bool,
    /// Whether the current antenna found no tag to read: it spends one empty round.
    slice_idle: bool,
    seen: TagSet,
    last_new_us: u64,
    rounds: u32,
    /// When the current AISpec last reported on its own interval (see `report_interval_us`).
    last_report_us: u64,
}

/// The scenario tags (by index) an AISpec has seen: a bitset, as tag indices are dense.
#[derive(Clone, Debug, Default)]
struct TagSet {
    words: Vec<u64>,
    len: usize,
}

impl TagSet {
    /// Adds `tag`; whether it was new.
    fn insert(&mut self, tag: usize) -> bool {
        let (w, bit) = (tag / 64, 1u64 << (tag % 64));
        if w >= self.words.len() {
            self.words.resize(w + 1, 0);
        }
        let new = self.words[w] & bit == 0;
        self.words[w] |= bit;
        self.len += usize::from(new);
        new
    }

    fn len(&self) -> usize {
        self.len
    }

    fn clear(&mut self) {
        self.words.fill(0);
        self.len = 0;
    }
}

/// All ROSpecs of the reader and the report buffer they fill.
#[derive(Debug, Default)]
pub struct Specs {
    specs: Vec<Spec>,
    buffer: ReportBuffer,
    /// ROReportTrigger of the reader's default ROReportSpec (for specs without their own).
    pub default_trigger: RoReportTriggerType,
    /// A halted spec's report trigger asks for its buffered reads to be reported now.
    flush_on_halt: bool,
    /// Physics of the coming antenna slices, computed ahead in parallel.
    prefetch: Lookahead,
    /// Computes every slice on the spot (tests compare both ways).
    no_prefetch: bool,
    /// Per antenna port, whether its field was empty when last looked at: the look-ahead
    /// plans it as one empty round.
    idle_antennas: Vec<bool>,
    /// Per antenna port, the current epoch of a single-target inventory.
    flagged: Vec<Option<flagged::FlaggedEpoch>>,
    /// The tags the Select filters in use leave in the rounds.
    selections: Selections,
}

impl Specs {
    /// The ROSpec with this ID.
    pub fn get(&self, id: u32) -> Option<&Spec> {
        self.specs.iter().find(|s| s.spec.ro_spec_id == id)
    }

    /// The executing ROSpec.
    pub fn active(&self) -> Option<&Spec> {
        self.specs.iter().find(|s| s.state == SpecState::Active)
    }

    fn active_idx(&self) -> Option<usize> {
        self.specs.iter().position(|s| s.state == SpecState::Active)
    }

    /// The ROSpecs as GET_ROSPECS reports them (CurrentState up to date).
    pub fn list(&self) -> Vec<RoSpec> {
        self.specs
            .iter()
            .map(|s| {
                let mut r = RoSpec::clone(&s.spec);
                r.current_state = s.state.code();
                r
            })
            .collect()
    }

    /// Computes antenna slices ahead in parallel (the default) or each on the spot.
    #[cfg(test)]
    pub fn set_prefetch(&mut self, on: bool) {
        self.no_prefetch = !on;
    }

    /// Reads buffered so far, for GET_REPORT.
    pub fn take_reports(&mut self) -> Vec<TagReportData> {
        self.buffer.take()
    }

    /// Reads to report because STOP/DISABLE/DELETE ended a spec whose trigger reports at the
    /// end of its AISpec or ROSpec (empty otherwise).
    pub fn take_halt_reports(&mut self) -> Vec<TagReportData> {
        if std::mem::take(&mut self.flush_on_halt) {
            self.buffer.take()
        } else {
            Vec::new()
        }
    }

    /// Moves pending start times forward to `now_us` (after time without a client).
    pub fn skip_to(&mut self, now_us: u64) {
        for s in &mut self.specs {
            if let Some(t) = &mut s.next_start_us {
                *t = (*t).max(now_us);
            }
            if let Some(r) = &mut s.run {
                r.slice_end_us = r.slice_end_us.max(now_us);
            }
        }
    }

    /// ADD_ROSPEC.
    pub fn add(&mut self, p: &ReaderProfile, spec: RoSpec, version: u8) -> LlrpStatus {
        if let Err(s) = validate(p, &spec, version) {
            return s;
        }
        if self.get(spec.ro_spec_id).is_some() {
            let mut s = param_field_error(177, 0, 0, StatusCode::A_Invalid);
            s.error_description = format!("ROSpec {} already exists", spec.ro_spec_id);
            return s;
        }
        let max = p.device.max_rospecs;
        if self.specs.len() >= max as usize {
            return LlrpStatus::new(
                StatusCode::M_OverflowParameter,
                format!("at most {max} ROSpecs"),
            );
        }
        self.specs.push(Spec {
            spec: Arc::new(spec),
            state: SpecState::Disabled,
            next_start_us: None,
            run: None,
        });
        LlrpStatus::success()
    }

    fn ids(&self, id: u32) -> Result<Vec<usize>, LlrpStatus> {
        if id == 0 {
            return Ok((0..self.specs.len()).collect());
        }
        match self.specs.iter().position(|s| s.spec.ro_spec_id == id) {
            Some(i) => Ok(vec![i]),
            None => {
                let mut s = field_error(0, StatusCode::A_Invalid, "ROSpecID");
                s.error_description = format!("no ROSpec {id}");
                Err(s)
            }
        }
    }

    /// DELETE_ROSPEC (0: all).
    pub fn delete(&mut self, id: u32, now: u64) -> (LlrpStatus, Vec<Event>) {
        let idx = match self.ids(id) {
            Ok(i) => i,
            Err(s) => return (s, vec![]),
        };
        let mut events = Vec::new();
        for &i in &idx {
            self.halt(i, now, &mut events);
        }
        let doomed: HashSet<usize> = idx.into_iter().collect();
        let mut k = 0;
        self.specs.retain(|_| {
            let keep = !doomed.contains(&k);
            k += 1;
            keep
        });
        (LlrpStatus::success(), events)
    }

    /// ENABLE_ROSPEC (0: all).
    pub fn enable(&mut self, id: u32, now: u64) -> (LlrpStatus, Vec<Event>) {
        let idx = match self.ids(id) {
            Ok(i) => i,
            Err(s) => return (s, vec![]),
        };
        for i in idx {
            let s = &mut self.specs[i];
            if s.state != SpecState::Disabled {
                continue;
            }
            s.state = SpecState::Inactive;
            s.next_start_us = first_start(&s.spec, now);
        }
        // Immediate specs start on the next run; report success first, as a reader does.
        (LlrpStatus::success(), vec![])
    }

    /// DISABLE_ROSPEC (0: all).
    pub fn disable(&mut self, id: u32, now: u64) -> (LlrpStatus, Vec<Event>) {
        let idx = match self.ids(id) {
            Ok(i) => i,
            Err(s) => return (s, vec![]),
        };
        let mut events = Vec::new();
        for i in idx {
            self.halt(i, now, &mut events);
            self.specs[i].state = SpecState::Disabled;
            self.specs[i].next_start_us = None;
        }
        (LlrpStatus::success(), events)
    }

    /// START_ROSPEC.
    pub fn start(&mut self, id: u32, now: u64) -> (LlrpStatus, Vec<Event>) {
        let i = match self.specs.iter().position(|s| s.spec.ro_spec_id == id) {
            Some(i) => i,
            None => return (field_error(0, StatusCode::A_Invalid, "ROSpecID"), vec![]),
        };
        match self.specs[i].state {
            SpecState::Inactive => {
                let mut events = Vec::new();
                if let Some(a) = self.active_idx() {
                    if self.specs[a].spec.priority <= self.specs[i].spec.priority {
                        // A spec of the same or higher priority runs: wait for it to end.
                        self.specs[i].next_start_us = Some(now);
                        return (LlrpStatus::success(), events);
                    }
                    self.preempt(a, self.specs[i].spec.ro_spec_id, now, &mut events);
                }
                self.begin(i, now, &mut events);
                (LlrpStatus::success(), events)
            }
            SpecState::Disabled => {
                let mut s = field_error(0, StatusCode::A_Invalid, "ROSpecID");
                s.error_description = format!("ROSpec {id} is disabled");
                (s, vec![])
            }
            SpecState::Active => {
                let mut s = field_error(0, StatusCode::A_Invalid, "ROSpecID");
                s.error_description = format!("ROSpec {id} is already active");
                (s, vec![])
            }
        }
    }

    /// STOP_ROSPEC.
    pub fn stop(&mut self, id: u32, now: u64) -> (LlrpStatus, Vec<Event>) {
        let i = match self.specs.iter().position(|s| s.spec.ro_spec_id == id) {
            Some(i) => i,
            None => return (field_error(0, StatusCode::A_Invalid, "ROSpecID"), vec![]),
        };
        if self.specs[i].state != SpecState::Active {
            let mut s = field_error(0, StatusCode::A_Invalid, "ROSpecID");
            s.error_description = format!("ROSpec {id} is not active");
            return (s, vec![]);
        }
        let mut events = Vec::new();
        self.halt(i, now, &mut events);
        // A stopped spec waits for its start trigger again, except Immediate, which only
        // restarts by being enabled again.
        if start_type(&self.specs[i].spec) == RoSpecStartTriggerType::Immediate {
            self.specs[i].next_start_us = None;
        }
        (LlrpStatus::success(), events)
    }

    /// Ends the run of spec `i` (if active), as STOP/DISABLE/DELETE do: the AISpec and the
    /// ROSpec end there, so a spec reporting at either end has its reads reported
    /// ([`Self::take_halt_reports`]); with trigger None they wait for GET_REPORT.
    fn halt(&mut self, i: usize, now: u64, events: &mut Vec<Event>) {
        let default_trigger = self.default_trigger;
        let s = &mut self.specs[i];
        if s.state == SpecState::Active {
            let trigger = s
                .spec
                .ro_report_spec
                .as_ref()
                .map_or(default_trigger, |r| r.ro_report_trigger);
            if ends_report(trigger) {
                self.flush_on_halt = true;
            }
            s.state = SpecState::Inactive;
            s.run = None;
            events.push(Event {
                at_us: now,
                kind: EventKind::RoSpec {
                    event_type: RoSpecEventType::EndOfRoSpec,
                    ro_spec_id: s.spec.ro_spec_id,
                    preempting: 0,
                },
            });
        }
    }

    fn preempt(&mut self, i: usize, by: u32, now: u64, events: &mut Vec<Event>) {
        let s = &mut self.specs[i];
        s.state = SpecState::Inactive;
        s.run = None;
        if start_type(&s.spec) == RoSpecStartTriggerType::Immediate {
            // An Immediate spec resumes once the preempting one is done.
            s.next_start_us = Some(now);
        }
        events.push(Event {
            at_us: now,
            kind: EventKind::RoSpec {
                event_type: RoSpecEventType::PreemptionOfRoSpec,
                ro_spec_id: s.spec.ro_spec_id,
                preempting: by,
            },
        });
    }

    fn begin(&mut self, i: usize, now: u64, events: &mut Vec<Event>) {
        let s = &mut self.specs[i];
        s.state = SpecState::Active;
        s.next_start_us = None;
        s.run = Some(Run {
            started_us: now,
            spec_idx: 0,
            spec_started_us: now,
            antenna_pos: 0,
            slice_end_us: dwell_end(now),
            slice_checked: false,
            slice_idle: false,
            seen: TagSet::default(),
            last_new_us: now,
            rounds: 0,
            last_report_us: now,
        });
        events.push(Event {
            at_us: now,
            kind: EventKind::RoSpec {
                event_type: RoSpecEventType::StartOfRoSpec,
                ro_spec_id: s.spec.ro_spec_id,
                preempting: 0,
            },
        });
    }
}

/// Whether a report trigger reports what is buffered when its AISpec or ROSpec ends.
fn ends_report(t: RoReportTriggerType) -> bool {
    matches!(
        t,
        RoReportTriggerType::UponNTagsOrEndOfAiSpec | RoReportTriggerType::UponNTagsOrEndOfRoSpec
    )
}

#[cfg(test)]
mod tests {
    use super::TagSet;

    #[test]
    fn tag_set_counts_each_tag_once_and_clears() {
        let mut s = TagSet::default();
        assert!(s.insert(3));
        assert!(s.insert(200));
        assert!(!s.insert(3));
        assert!(s.insert(64));
        assert_eq!(s.len(), 3);
        s.clear();
        assert_eq!(s.len(), 0);
        assert!(s.insert(200), "a cleared set forgets its tags");
    }
}
