//! ROSpecs: the lifecycle (add, enable, start, stop, disable, delete), start and stop triggers,
//! priorities and the execution of AISpecs over simulated time.

use std::collections::HashSet;
use std::sync::Arc;

use llrp::enums::*;
use llrp::params::*;
use llrp::StatusCode;

use super::access::AccessSpecs;
use super::config::{param_field_error, validate_antenna_config, ReaderConfig};
use super::prefetch::{Prefetch, Slice, AHEAD_DEPTH};
use super::report::{Content, ImpinjContent, Observation, ReportBuffer};
use super::{field_error, ReaderProfile, MAX_ROSPECS};
use crate::physics::{Model, Read, Want};

/// Simulated time each antenna of an AISpec gets before the reader moves to the next, µs.
pub const ANTENNA_DWELL_US: u64 = 25_000;
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
    /// UTC of simulated time 0, µs.
    pub utc_epoch_us: u64,
    /// Impinj extensions enabled on the connection.
    pub impinj: bool,
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
    prefetch: Prefetch,
    /// Computes every slice on the spot (tests compare both ways).
    no_prefetch: bool,
    /// Rotation position and start of the slice after the last one prefetched.
    ahead_from: (usize, u64),
}

fn start_type(s: &RoSpec) -> RoSpecStartTriggerType {
    s.ro_boundary_spec
        .ro_spec_start_trigger
        .ro_spec_start_trigger_type
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
        if self.specs.len() >= MAX_ROSPECS as usize {
            return LlrpStatus::new(
                StatusCode::M_OverflowParameter,
                format!("at most {MAX_ROSPECS} ROSpecs"),
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
            slice_end_us: now + ANTENNA_DWELL_US,
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

    /// Simulated time something is next due, if any spec is active or waiting to start.
    pub fn next_deadline(&self, now: u64) -> Option<u64> {
        let mut best: Option<u64> = None;
        for s in &self.specs {
            let t = match (&s.run, s.next_start_us) {
                (Some(r), _) => Some(r.slice_end_us.min(now + ANTENNA_DWELL_US)),
                (None, Some(t)) if s.state == SpecState::Inactive => Some(t),
                _ => None,
            };
            if let Some(t) = t {
                best = Some(best.map_or(t, |b| b.min(t)));
            }
        }
        best
    }

    /// The spec (index) whose start is due by `t` with the best priority.
    fn due(&self, t: u64) -> Option<usize> {
        self.specs
            .iter()
            .enumerate()
            .filter(|(_, s)| {
                s.state == SpecState::Inactive && s.next_start_us.is_some_and(|n| n <= t)
            })
            .min_by_key(|(_, s)| (s.spec.priority, s.next_start_us))
            .map(|(i, _)| i)
    }

    fn next_start_after(&self, t: u64) -> Option<u64> {
        self.specs
            .iter()
            .filter(|s| s.state == SpecState::Inactive)
            .filter_map(|s| s.next_start_us)
            .filter(|&n| n > t)
            .min()
    }

    /// Runs the specs over simulated time [from, to).
    pub fn run(&mut self, mut ctx: RunContext<'_>, from: u64, to: u64) -> Vec<Produced> {
        let mut out = Vec::new();
        let mut t = from;
        // Bounded: each pass either advances time or changes a spec's state.
        let mut guard = 0u32;
        while t < to && guard < 1_000_000 {
            guard += 1;
            let mut events = Vec::new();
            match self.active_idx() {
                None => match self.due(t) {
                    Some(i) => self.begin(i, t, &mut events),
                    None => match self.next_start_after(t) {
                        Some(n) if n < to => t = n,
                        _ => break,
                    },
                },
                Some(a) => {
                    if let Some(i) = self.due(t) {
                        if self.specs[i].spec.priority < self.specs[a].spec.priority {
                            let by = self.specs[i].spec.ro_spec_id;
                            self.preempt(a, by, t, &mut events);
                            self.begin(i, t, &mut events);
                        }
                    }
                    if events.is_empty() {
                        let a = self.active_idx().unwrap_or(a);
                        t = self.step(&mut ctx, a, t, to, &mut out);
                    }
                }
            }
            out.extend(events.into_iter().map(Produced::Event));
        }
        out
    }

    /// Runs active spec `a` from `t` to its next boundary (at most `to`); returns the time
    /// reached.
    fn step(
        &mut self,
        ctx: &mut RunContext<'_>,
        a: usize,
        t: u64,
        to: u64,
        out: &mut Vec<Produced>,
    ) -> u64 {
        let spec = Arc::clone(&self.specs[a].spec);
        let ro_id = spec.ro_spec_id;
        let config = ctx.config;
        let report_spec: &RoReportSpec = spec
            .ro_report_spec
            .as_ref()
            .unwrap_or(&config.ro_report_spec);
        let content = Content {
            selector: report_spec.tag_report_content_selector.clone(),
            impinj: if ctx.impinj {
                ImpinjContent::from_report_spec(report_spec)
            } else {
                ImpinjContent::default()
            },
        };
        // Taken out for the step (its `seen` set would be costly to clone) and put back below.
        let Some(run) = self.specs[a].run.take() else {
            return to;
        };
        let stop = &spec.ro_boundary_spec.ro_spec_stop_trigger;
        let ro_end = match stop.ro_spec_stop_trigger_type {
            RoSpecStopTriggerType::Duration => {
                Some(run.started_us + u64::from(stop.duration_trigger_value) * 1000)
            }
            RoSpecStopTriggerType::GpiWithTimeout => stop
                .gpi_trigger_value
                .as_ref()
                .filter(|g| g.timeout > 0)
                .map(|g| run.started_us + u64::from(g.timeout) * 1000),
            _ => None,
        };
        let ai = match spec.specs.get(run.spec_idx) {
            Some(SpecParameter::AiSpec(ai)) => ai,
            // Validation admits only AISpecs; anything else ends the ROSpec.
            _ => {
                self.specs[a].run = Some(run);
                self.finish_ro(a, t, report_spec, out);
                return t;
            }
        };
        let trig = &ai.ai_spec_stop_trigger;
        let obs = trig.tag_observation_trigger.clone().unwrap_or_default();
        let ai_end = match trig.ai_spec_stop_trigger_type {
            AiSpecStopTriggerType::Duration => {
                Some(run.spec_started_us + u64::from(trig.duration_trigger) * 1000)
            }
            AiSpecStopTriggerType::GpiWithTimeout => trig
                .gpi_trigger_value
                .as_ref()
                .filter(|g| g.timeout > 0)
                .map(|g| run.spec_started_us + u64::from(g.timeout) * 1000),
            AiSpecStopTriggerType::TagObservation => {
                let timeout =
                    (obs.timeout > 0).then(|| run.spec_started_us + u64::from(obs.timeout) * 1000);
                let quiet = (obs.trigger_type
                    == TagObservationTriggerType::UponSeeingNoMoreNewTagsForTmsOrTimeout)
                    .then(|| run.last_new_us + u64::from(obs.t) * 1000);
                match (timeout, quiet) {
                    (Some(x), Some(y)) => Some(x.min(y)),
                    (x, y) => x.or(y),
                }
            }
            _ => None,
        };
        let mut end = to.min(run.slice_end_us);
        if let Some(e) = ro_end {
            end = end.min(e);
        }
        if let Some(e) = ai_end {
            end = end.min(e);
        }
        if let Some(n) = self.next_start_after(t) {
            end = end.min(n.max(t + 1));
        }
        // An Impinj-class reader does not hold the reads of an inventory that nothing ends
        // (neither its AISpec nor its ROSpec has a stop condition that can fire) forever when
        // ROReportTrigger 1 has N = 0: it reports them at the profile's interval.
        let interval = ctx.profile.report_interval_us;
        let periodic = interval > 0
            && report_spec.ro_report_trigger == RoReportTriggerType::UponNTagsOrEndOfAiSpec
            && report_spec.n == 0
            && ai_end.is_none()
            && ro_end.is_none()
            && matches!(
                trig.ai_spec_stop_trigger_type,
                AiSpecStopTriggerType::Null | AiSpecStopTriggerType::GpiWithTimeout
            )
            && matches!(
                stop.ro_spec_stop_trigger_type,
                RoSpecStopTriggerType::Null | RoSpecStopTriggerType::GpiWithTimeout
            );
        if periodic {
            end = end.min(run.last_report_us + interval);
        }
        let mut end = end.max(t);

        let antennas: Vec<u16> = if ai.antenna_ids.contains(&0) {
            (1..=ctx.profile.antennas).collect()
        } else {
            ai.antenna_ids.clone()
        };
        let antenna = antennas[run.antenna_pos % antennas.len().max(1)];
        let ips = ai.inventory_parameter_specs.first();
        let ips_id = ips.map_or(0, |p| p.inventory_parameter_spec_id);
        let power = antenna_power(ips, ctx.config, antenna);
        // ImpinjFixedFrequencyList (mode 2, channel list) in the ROSpec's or the reader's
        // antenna configuration restricts the channels, which rotate at the region's dwell.
        let channels = fixed_channel_list(ips, ctx.config, antenna);
        let hop = ctx.model.hop_schedule();
        let channel = (!channels.is_empty())
            .then(|| channels[((t / hop.dwell_us) % channels.len() as u64) as usize]);
        if channel.is_some() {
            end = end.min(hop.dwell_start(t) + hop.dwell_us).max(t);
        }
        let reports_on_n = report_spec.ro_report_trigger != RoReportTriggerType::None;
        let aggregate = !(reports_on_n && report_spec.n == 1);
        let n_trigger = usize::from(report_spec.n);
        self.buffer.expect(if reports_on_n { n_trigger } else { 0 });

        let mut reached = end;
        let mut ai_done = ai_end.is_some_and(|e| end >= e);
        let ro_done = ro_end.is_some_and(|e| end >= e);
        let mut run = run;
        if end > t {
            // Phase and Doppler are worked out only when reported.
            let want = Want {
                phase: content.impinj.phase,
                doppler: content.impinj.doppler,
            };
            let slice = Slice {
                antenna,
                power_dbm: power,
                t0_us: t,
                t1_us: end,
                want,
            };
            let reads = match channel {
                Some(_) => ctx
                    .model
                    .inventory_with(antenna, t, end, power, channel, want),
                None => {
                    let until = [ai_end, ro_end].into_iter().flatten().min();
                    self.prefetched(ctx, &slice, &run, &antennas, ips, until)
                }
            };
            for r in reads {
                let (op_spec_results, access_spec_id) =
                    ctx.access.apply(ctx.model, r.tag, antenna, ro_id);
                let o = Observation {
                    epc: ctx.model.tag_epc(r.tag),
                    ro_spec_id: ro_id,
                    spec_index: (run.spec_idx + 1) as u16,
                    inventory_parameter_spec_id: ips_id,
                    antenna_id: r.antenna,
                    channel_index: r.channel_index,
                    rssi_dbm: r.rssi_dbm,
                    phase_rad: r.phase_rad,
                    doppler_hz: r.doppler_hz,
                    utc_us: ctx.utc_epoch_us + r.time_us,
                    uptime_us: r.time_us,
                    op_spec_results,
                    access_spec_id,
                    tid: if content.impinj.serialized_tid {
                        ctx.model.tag_tid(r.tag)
                    } else {
                        Vec::new()
                    },
                };
                self.buffer.add(&o, &content, aggregate);
                if run.seen.insert(r.tag) {
                    run.last_new_us = r.time_us;
                }
                if reports_on_n && n_trigger > 0 && self.buffer.len() >= n_trigger {
                    out.push(Produced::Reports(self.buffer.take()));
                }
                if trig.ai_spec_stop_trigger_type == AiSpecStopTriggerType::TagObservation
                    && obs.trigger_type == TagObservationTriggerType::UponSeeingNTagsOrTimeout
                    && obs.number_of_tags > 0
                    && run.seen.len() >= usize::from(obs.number_of_tags)
                {
                    reached = (r.time_us + 1).clamp(t + 1, end);
                    ai_done = true;
                    break;
                }
            }
        }
        if periodic && reached >= run.last_report_us + interval {
            run.last_report_us = reached;
            if !self.buffer.is_empty() {
                out.push(Produced::Reports(self.buffer.take()));
            }
        }
        // Antenna rotation.
        if reached >= run.slice_end_us {
            run.antenna_pos += 1;
            if run.antenna_pos % antennas.len().max(1) == 0 {
                run.rounds += 1;
            }
            run.slice_end_us = reached + ANTENNA_DWELL_US;
        }
        if trig.ai_spec_stop_trigger_type == AiSpecStopTriggerType::TagObservation
            && obs.trigger_type == TagObservationTriggerType::NAttemptsToSeeAllTagsInFovOrTimeout
            && obs.number_of_attempts > 0
            && run.rounds >= u32::from(obs.number_of_attempts)
        {
            ai_done = true;
        }
        if trig.ai_spec_stop_trigger_type == AiSpecStopTriggerType::TagObservation
            && obs.trigger_type == TagObservationTriggerType::UponSeeingNoMoreNewTagsForTmsOrTimeout
            && reached >= run.last_new_us + u64::from(obs.t) * 1000
        {
            ai_done = true;
        }
        self.specs[a].run = Some(run);
        if ro_done {
            self.end_ai(a, reached, report_spec, out);
            self.finish_ro(a, reached, report_spec, out);
        } else if ai_done {
            self.end_ai(a, reached, report_spec, out);
            let s = &mut self.specs[a];
            let run = s
                .run
                .as_mut()
                .expect("an active spec has a run (set by begin)");
            run.spec_idx += 1;
            run.spec_started_us = reached;
            run.seen.clear();
            run.last_new_us = reached;
            run.rounds = 0;
            run.last_report_us = reached;
            run.antenna_pos = 0;
            run.slice_end_us = reached + ANTENNA_DWELL_US;
            if run.spec_idx >= s.spec.specs.len() {
                self.finish_ro(a, reached, report_spec, out);
            }
        }
        reached
    }

    /// The reads of `slice` from the prefetch. On a miss, takes the oldest batch computed in
    /// the background if it covers it, else computes the slices the run will ask for next
    /// (this one first, then the antennas in turn, up to the AISpec's or ROSpec's end when
    /// known) on every core; either way keeps [`AHEAD_DEPTH`] batches after them computing in
    /// the background.
    fn prefetched(
        &mut self,
        ctx: &RunContext<'_>,
        slice: &Slice,
        run: &Run,
        antennas: &[u16],
        ips: Option<&InventoryParameterSpec>,
        until: Option<u64>,
    ) -> Vec<Read> {
        if self.no_prefetch {
            return slice.compute(ctx.model);
        }
        if let Some(reads) = self.prefetch.take(slice) {
            return reads;
        }
        let plan = |pos: usize, t0: u64, count: usize| -> Vec<Slice> {
            let mut out = Vec::with_capacity(count);
            let mut t0 = t0;
            for k in 0..count {
                if until.is_some_and(|u| t0 >= u) {
                    break;
                }
                let antenna = antennas[(pos + k) % antennas.len().max(1)];
                // A pinned channel list is computed when asked for.
                if !fixed_channel_list(ips, ctx.config, antenna).is_empty() {
                    break;
                }
                out.push(Slice {
                    antenna,
                    power_dbm: antenna_power(ips, ctx.config, antenna),
                    want: slice.want,
                    t0_us: t0,
                    t1_us: t0 + ANTENNA_DWELL_US,
                });
                t0 += ANTENNA_DWELL_US;
            }
            out
        };
        let batch = self.prefetch.batch_after_miss(slice.t0_us);
        let reads = if self.prefetch.finish_ahead() {
            self.prefetch.take(slice)
        } else {
            None
        };
        let (reads, mut next) = match reads {
            Some(reads) => (reads, self.ahead_from),
            None => {
                let first = Slice {
                    t1_us: run.slice_end_us.max(slice.t1_us),
                    ..*slice
                };
                let mut p = vec![first];
                p.extend(plan(run.antenna_pos + 1, first.t1_us, batch - 1));
                let next = (
                    run.antenna_pos + p.len(),
                    first.t1_us + (p.len() as u64 - 1) * ANTENNA_DWELL_US,
                );
                self.prefetch.fill(ctx.model, p);
                let reads = self
                    .prefetch
                    .take(slice)
                    .unwrap_or_else(|| slice.compute(ctx.model));
                (reads, next)
            }
        };
        // The batches after: computed while this one's reads are reported.
        while self.prefetch.ahead_count() < AHEAD_DEPTH {
            let ahead = plan(next.0, next.1, batch);
            if ahead.is_empty() {
                break;
            }
            next = (
                next.0 + ahead.len(),
                next.1 + ahead.len() as u64 * ANTENNA_DWELL_US,
            );
            self.prefetch.start_ahead(ctx.model, ahead);
        }
        self.ahead_from = next;
        reads
    }

    fn end_ai(&mut self, a: usize, at: u64, report: &RoReportSpec, out: &mut Vec<Produced>) {
        let s = &self.specs[a];
        let idx = s.run.as_ref().map_or(0, |r| r.spec_idx);
        if report.ro_report_trigger == RoReportTriggerType::UponNTagsOrEndOfAiSpec
            && !self.buffer.is_empty()
        {
            out.push(Produced::Reports(self.buffer.take()));
        }
        out.push(Produced::Event(Event {
            at_us: at,
            kind: EventKind::AiSpecEnd {
                ro_spec_id: s.spec.ro_spec_id,
                spec_index: (idx + 1) as u16,
            },
        }));
    }

    fn finish_ro(&mut self, a: usize, at: u64, report: &RoReportSpec, out: &mut Vec<Produced>) {
        if ends_report(report.ro_report_trigger) && !self.buffer.is_empty() {
            out.push(Produced::Reports(self.buffer.take()));
        }
        let s = &mut self.specs[a];
        let started = s.run.as_ref().map_or(at, |r| r.started_us);
        s.state = SpecState::Inactive;
        s.run = None;
        s.next_start_us = next_start(&s.spec, started, at);
        out.push(Produced::Event(Event {
            at_us: at,
            kind: EventKind::RoSpec {
                event_type: RoSpecEventType::EndOfRoSpec,
                ro_spec_id: s.spec.ro_spec_id,
                preempting: 0,
            },
        }));
    }
}

/// Transmit power of `antenna`: the ROSpec's RFTransmitter for it, else the reader's
/// configuration (`None`: the scenario's).
fn antenna_power(
    ips: Option<&InventoryParameterSpec>,
    config: &ReaderConfig,
    antenna: u16,
) -> Option<f64> {
    ips.and_then(|p| {
        p.antenna_configuration
            .iter()
            .find(|c| c.antenna_id == antenna || c.antenna_id == 0)
            .and_then(|c| c.rf_transmitter.as_ref())
            .and_then(|tx| super::caps::power_dbm(tx.transmit_power))
    })
    .or_else(|| config.tx_power_dbm(antenna))
}

/// The channel list of an ImpinjFixedFrequencyList in mode 2 (Channel_List) configured for
/// `antenna`, in the ROSpec's InventoryParameterSpec or else in the reader configuration.
fn fixed_channel_list(
    ips: Option<&InventoryParameterSpec>,
    config: &ReaderConfig,
    antenna: u16,
) -> Vec<u16> {
    let in_spec = ips.into_iter().flat_map(|p| {
        p.antenna_configuration
            .iter()
            .filter(move |c| c.antenna_id == antenna || c.antenna_id == 0)
    });
    let in_config = config.antennas.get(usize::from(antenna).saturating_sub(1));
    in_spec
        .chain(in_config)
        .flat_map(|c| c.c1g2_inventory_command.iter())
        .flat_map(|cmd| cmd.custom.iter())
        .find_map(|p| match p {
            Custom::ImpinjFixedFrequencyList(l)
                if l.fixed_frequency_mode == 2 && !l.channel_list.is_empty() =>
            {
                Some(l.channel_list.clone())
            }
            _ => None,
        })
        .unwrap_or_default()
}

/// Whether a report trigger reports what is buffered when its AISpec or ROSpec ends.
fn ends_report(t: RoReportTriggerType) -> bool {
    matches!(
        t,
        RoReportTriggerType::UponNTagsOrEndOfAiSpec | RoReportTriggerType::UponNTagsOrEndOfRoSpec
    )
}

/// When an enabled spec first starts: Immediate now, Periodic after its offset, else never
/// (it waits for START_ROSPEC).
fn first_start(s: &RoSpec, enabled_at: u64) -> Option<u64> {
    let st = &s.ro_boundary_spec.ro_spec_start_trigger;
    match st.ro_spec_start_trigger_type {
        RoSpecStartTriggerType::Immediate => Some(enabled_at),
        RoSpecStartTriggerType::Periodic => st
            .periodic_trigger_value
            .as_ref()
            .map(|p| enabled_at + u64::from(p.offset) * 1000),
        _ => None,
    }
}

/// When a spec that ran from `started` and ended at `ended` starts again by itself:
/// Immediate at once (as Impinj readers loop an Immediate ROSpec), Periodic one period after
/// the previous start.
fn next_start(s: &RoSpec, started: u64, ended: u64) -> Option<u64> {
    let st = &s.ro_boundary_spec.ro_spec_start_trigger;
    match st.ro_spec_start_trigger_type {
        RoSpecStartTriggerType::Immediate => Some(ended.max(started + MIN_RESTART_US)),
        RoSpecStartTriggerType::Periodic => st
            .periodic_trigger_value
            .as_ref()
            .filter(|p| p.period > 0)
            .map(|p| {
                let period = u64::from(p.period) * 1000;
                let mut n = started + period;
                while n < ended {
                    n += period;
                }
                n
            }),
        _ => None,
    }
}

/// Checks an ROSpec against what the reader supports.
fn validate(p: &ReaderProfile, s: &RoSpec, version: u8) -> Result<(), LlrpStatus> {
    if s.ro_spec_id == 0 {
        return Err(param_field_error(177, 0, 0, StatusCode::A_Invalid));
    }
    if s.current_state != RoSpecState::Disabled {
        let mut e = param_field_error(177, 0, 2, StatusCode::A_Invalid);
        e.error_description = "a new ROSpec must be Disabled".into();
        return Err(e);
    }
    let b = &s.ro_boundary_spec;
    let st = &b.ro_spec_start_trigger;
    if st.ro_spec_start_trigger_type == RoSpecStartTriggerType::Periodic
        && st.periodic_trigger_value.is_none()
    {
        return Err(missing(178, 179, 180));
    }
    if st.ro_spec_start_trigger_type == RoSpecStartTriggerType::Gpi
        && st.gpi_trigger_value.is_none()
    {
        return Err(missing(178, 179, 181));
    }
    let sp = &b.ro_spec_stop_trigger;
    if sp.ro_spec_stop_trigger_type == RoSpecStopTriggerType::GpiWithTimeout
        && sp.gpi_trigger_value.is_none()
    {
        return Err(missing(178, 182, 181));
    }
    for spec in &s.specs {
        match spec {
            SpecParameter::AiSpec(ai) => validate_ai(p, ai)?,
            SpecParameter::RfSurveySpec(_) => {
                let mut e =
                    LlrpStatus::new(StatusCode::M_ParameterError, "RF survey is not supported");
                let mut pe = ParameterError::new(177, StatusCode::P_ParameterError);
                pe.parameter_error = Some(Box::new(ParameterError::new(
                    187,
                    StatusCode::P_UnsupportedParameter,
                )));
                e.parameter_error = Some(pe);
                return Err(e);
            }
            SpecParameter::Custom(_) => {
                let mut e = LlrpStatus::new(
                    StatusCode::M_ParameterError,
                    "vendor specs are not supported",
                );
                let mut pe = ParameterError::new(177, StatusCode::P_ParameterError);
                pe.parameter_error = Some(Box::new(ParameterError::new(
                    1023,
                    StatusCode::P_UnsupportedParameter,
                )));
                e.parameter_error = Some(pe);
                return Err(e);
            }
        }
    }
    if let Some(r) = &s.ro_report_spec {
        // LLRP 1.1's triggers 3..=6 are not implemented in either version.
        let _ = version;
        if !matches!(
            r.ro_report_trigger,
            RoReportTriggerType::None
                | RoReportTriggerType::UponNTagsOrEndOfAiSpec
                | RoReportTriggerType::UponNTagsOrEndOfRoSpec
        ) {
            let mut e = param_field_error(177, 237, 0, StatusCode::A_OutOfRange);
            e.error_description = format!(
                "ROReportTrigger {} is not supported",
                r.ro_report_trigger.value()
            );
            return Err(e);
        }
    }
    Ok(())
}

fn validate_ai(p: &ReaderProfile, ai: &AiSpec) -> Result<(), LlrpStatus> {
    let bad_antenna = ai.antenna_ids.is_empty()
        || ai.antenna_ids.iter().any(|&a| a > p.antennas)
        || (ai.antenna_ids.contains(&0) && ai.antenna_ids.len() > 1);
    if bad_antenna {
        let mut e = nested_field_error(&[177, 183], 0, StatusCode::A_OutOfRange);
        e.error_description = format!(
            "AntennaIDs {:?}: the reader has antennas 1..={} (0 = all)",
            ai.antenna_ids, p.antennas
        );
        return Err(e);
    }
    let t = &ai.ai_spec_stop_trigger;
    if t.ai_spec_stop_trigger_type == AiSpecStopTriggerType::TagObservation {
        match &t.tag_observation_trigger {
            None => return Err(missing(183, 184, 185)),
            Some(o) if o.trigger_type.value() > 2 => {
                let mut e = nested_field_error(&[177, 183, 184, 185], 0, StatusCode::A_OutOfRange);
                e.error_description = format!(
                    "TagObservationTrigger type {} is not supported",
                    o.trigger_type.value()
                );
                return Err(e);
            }
            _ => {}
        }
    }
    if t.ai_spec_stop_trigger_type == AiSpecStopTriggerType::GpiWithTimeout
        && t.gpi_trigger_value.is_none()
    {
        return Err(missing(183, 184, 181));
    }
    if ai.inventory_parameter_specs.len() > 1 {
        return Err(LlrpStatus::new(
            StatusCode::M_OverflowParameter,
            "one InventoryParameterSpec per AISpec",
        ));
    }
    for ips in &ai.inventory_parameter_specs {
        if ips.protocol_id != AirProtocol::EpcGlobalClass1Gen2 {
            let mut e = nested_field_error(&[177, 183, 186], 1, StatusCode::A_OutOfRange);
            e.error_description = "only EPCGlobal Class 1 Gen 2 (ProtocolID 1)".into();
            return Err(e);
        }
        for c in &ips.antenna_configuration {
            validate_antenna_config(p, c).map_err(|mut e| {
                // Re-root the antenna error under ROSpec/AISpec/InventoryParameterSpec.
                if let Some(inner) = e.parameter_error.take() {
                    let mut ips_e = ParameterError::new(186, StatusCode::P_ParameterError);
                    ips_e.parameter_error = Some(Box::new(inner));
                    let mut ai_e = ParameterError::new(183, StatusCode::P_ParameterError);
                    ai_e.parameter_error = Some(Box::new(ips_e));
                    let mut ro_e = ParameterError::new(177, StatusCode::P_ParameterError);
                    ro_e.parameter_error = Some(Box::new(ai_e));
                    e.parameter_error = Some(ro_e);
                }
                e
            })?;
        }
    }
    Ok(())
}

/// M_ParameterError with the chain `path` (outermost first) and a field error at the end.
fn nested_field_error(path: &[u16], field: u16, code: StatusCode) -> LlrpStatus {
    let mut inner: Option<ParameterError> = None;
    for (k, ty) in path.iter().enumerate().rev() {
        let last = k == path.len() - 1;
        let mut pe = ParameterError::new(
            *ty,
            if last {
                StatusCode::P_FieldError
            } else {
                StatusCode::P_ParameterError
            },
        );
        if last {
            pe.field_error = Some(FieldError {
                field_num: field,
                error_code: code,
                ..Default::default()
            });
        }
        pe.parameter_error = inner.take().map(Box::new);
        inner = Some(pe);
    }
    let mut s = LlrpStatus::new(StatusCode::M_ParameterError, "invalid parameter value");
    s.parameter_error = inner;
    s
}

/// M_ParameterError: parameter `a`/`b` lacks required sub-parameter `missing`.
fn missing(a: u16, b: u16, missing: u16) -> LlrpStatus {
    let mut inner = ParameterError::new(b, StatusCode::P_ParameterError);
    inner.parameter_error = Some(Box::new(ParameterError::new(
        missing,
        StatusCode::P_MissingParameter,
    )));
    let mut outer = ParameterError::new(a, StatusCode::P_ParameterError);
    outer.parameter_error = Some(Box::new(inner));
    let mut s = LlrpStatus::new(
        StatusCode::M_ParameterError,
        format!("parameter type {missing} missing"),
    );
    s.parameter_error = Some(outer);
    s
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
