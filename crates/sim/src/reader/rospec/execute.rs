//! Running the active ROSpec over simulated time: antenna slices, the physics of each (from
//! the prefetch), stop triggers, report triggers and the events they raise.

use super::schedule::next_start;
use super::stops::*;
use super::*;

impl Specs {
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
        let report_spec: &RoReportSpec = spec
            .ro_report_spec
            .as_ref()
            .unwrap_or(&ctx.config.ro_report_spec);
        let content = report_content(report_spec, ctx.impinj);
        // Taken out for the step (its `seen` set would be costly to clone) and put back below.
        let Some(mut run) = self.specs[a].run.take() else {
            return to;
        };
        let stop = &spec.ro_boundary_spec.ro_spec_stop_trigger;
        let ro_end = ro_stop_end(stop, run.started_us);
        // Validation admits only AISpecs; anything else ends the ROSpec.
        let Some(SpecParameter::AiSpec(ai)) = spec.specs.get(run.spec_idx) else {
            self.specs[a].run = Some(run);
            self.finish_ro(a, t, report_spec, out);
            return t;
        };
        let trig = &ai.ai_spec_stop_trigger;
        let obs = trig.tag_observation_trigger.clone().unwrap_or_default();
        let ai_end = ai_stop_end(trig, &obs, &run);
        let mut end = self.step_bound(t, to, &run, ro_end, ai_end);
        // An Impinj-class reader does not hold the reads of an inventory that nothing ends
        // (neither its AISpec nor its ROSpec has a stop condition that can fire) forever when
        // ROReportTrigger 1 has N = 0: it reports them at the profile's interval.
        let interval = ctx.profile.report_interval_us;
        let periodic = interval > 0 && never_ends(report_spec, trig, stop, ai_end, ro_end);
        if periodic {
            end = end.min(run.last_report_us + interval);
        }
        // Phase and Doppler are worked out only when reported.
        let want = Want {
            phase: content.impinj.phase,
            doppler: content.impinj.doppler,
        };
        let until = [ai_end, ro_end].into_iter().flatten().min();
        let plan = Plan::new(ctx, &run, ai, (want, t, end, until), &mut self.selections);
        let end = plan.slice.t1_us;
        let rep = Reporting::new(spec.ro_spec_id, plan.ips, &content, report_spec, trig, &obs);
        self.buffer.expect(rep.every_n);

        let mut ai_done = ai_end.is_some_and(|e| end >= e);
        let ro_done = ro_end.is_some_and(|e| end >= e);
        let (reached, seen_enough) = self.run_slice(ctx, &mut run, &plan, &rep, t, out);
        ai_done |= seen_enough;
        if periodic {
            self.report_on_interval(&mut run, reached, interval, out);
        }
        run.rotate(reached, plan.antennas.len());
        ai_done |= observation_done(trig, &obs, &run, reached);
        self.specs[a].run = Some(run);
        if ro_done {
            self.end_ai(a, reached, report_spec, out);
            self.finish_ro(a, reached, report_spec, out);
        } else if ai_done {
            self.next_ai(a, reached, report_spec, out);
        }
        reached
    }

    /// Runs the slice of `plan` from `t`: one empty round if its antenna faces no tag, else
    /// its reads, reported until the AISpec has seen the tags it stops at; the time reached
    /// and whether it has.
    fn run_slice(
        &mut self,
        ctx: &mut RunContext<'_>,
        run: &mut Run,
        plan: &Plan<'_>,
        rep: &Reporting<'_>,
        t: u64,
        out: &mut Vec<Produced>,
    ) -> (u64, bool) {
        let slice = &plan.slice;
        let end = slice.t1_us;
        if let Some(idle) = self.idle_round(ctx, run, slice, plan.channel, t) {
            // The dwell ends after the empty round whatever the caller's steps are.
            run.slice_end_us = t + idle;
            run.slice_idle = true;
            return ((t + idle).min(end), false);
        }
        // The rest of an empty round, nothing to run before the AISpec's setup is over, or an
        // unplugged port or one with nothing connected (its dwell passes, no tag answers).
        if run.slice_idle
            || end <= slice.t0_us
            || !ctx.faults.connected(slice.antenna)
            || !wired(ctx, slice.antenna)
        {
            return (end, false);
        }
        let reads = match plan.channel {
            // A single-target inventory carries the reader's flags from epoch to epoch, so it
            // runs here, in time order, an epoch at a time.
            _ if slice.air.suppresses() => self.take_flagged(slice.antenna, end),
            Some(_) => ctx.model.inventory_with(
                slice.antenna,
                slice.t0_us,
                end,
                slice.power_dbm,
                plan.channel,
                slice.want,
                &slice.air,
            ),
            None => self.prefetched(ctx, slice, run, &plan.antennas, plan.ips, plan.until),
        };
        for r in &reads {
            if self.report_read(ctx, r, run, rep, slice, out) {
                return ((r.time_us + 1).clamp(t + 1, end), true);
            }
        }
        (end, false)
    }

    /// The end of a step from `t`: the caller's `to`, the slice's end, the stop triggers and
    /// the next spec due, whichever comes first.
    fn step_bound(
        &self,
        t: u64,
        to: u64,
        run: &Run,
        ro_end: Option<u64>,
        ai_end: Option<u64>,
    ) -> u64 {
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
        end
    }

    /// Whether the antenna of `slice` faces no tag (by the field's bounds, or in a
    /// single-target inventory with no tag left in A): then the length of the one empty
    /// round it gets before the reader moves to the next.
    fn idle_round(
        &mut self,
        ctx: &mut RunContext<'_>,
        run: &mut Run,
        slice: &Slice,
        channel: Option<u16>,
        t: u64,
    ) -> Option<u64> {
        let (antenna, power, air) = (slice.antenna, slice.power_dbm, &slice.air);
        let (air_t, end) = (slice.t0_us, slice.t1_us);
        if !wired(ctx, antenna) {
            // Nothing connected: no field to look at (the dwell passes in `step`).
            return None;
        }
        let fresh = !run.slice_checked && end > t;
        let mut idle = None;
        if fresh {
            run.slice_checked = true;
            idle = ctx.model.idle_us(antenna, t, power, channel, air);
            let port = usize::from(antenna);
            if self.idle_antennas.len() <= port {
                self.idle_antennas.resize(port + 1, false);
            }
            self.idle_antennas[port] = idle.is_some();
        }
        if air.suppresses() && end > air_t && idle.is_none() && !run.slice_idle {
            let none_in_a =
                self.flagged_epoch(ctx, antenna, air_t, power, channel, slice.want, air);
            if fresh && none_in_a {
                idle = Some(air.empty_round_us());
            }
        }
        idle
    }

    /// Reports read `r` of `slice` (its flag, AccessSpecs, the buffer, the N trigger) and
    /// notes its tag as seen; whether the AISpec has now seen the tags it stops at.
    #[inline]
    fn report_read(
        &mut self,
        ctx: &mut RunContext<'_>,
        r: &Read,
        run: &mut Run,
        rep: &Reporting<'_>,
        slice: &Slice,
        out: &mut Vec<Produced>,
    ) -> bool {
        // A killed tag never answers (its air time in the round is still spent).
        let Some((epc, pc)) = ctx.memory.epc(ctx.model, r.tag) else {
            return false;
        };
        if slice.air.suppresses() {
            // Reported, so in B now (a read the stop trigger cuts off stays A).
            ctx.flags.read(r.tag, slice.air.session, r.time_us);
        }
        let applied = ctx.access.apply(
            &crate::reader::access::Tag {
                model: ctx.model,
                memory: ctx.memory,
                tag: r.tag,
                version: ctx.version,
                antenna: r.antenna,
                time_us: r.time_us,
                margin_db: r.margin_db,
            },
            slice.antenna,
            rep.ro_id,
            ctx.config.access_report_spec.access_report_trigger,
        );
        let mut o = Observation {
            // The EPC the tag was singulated with, whatever its operations wrote.
            epc,
            pc,
            ro_spec_id: rep.ro_id,
            spec_index: (run.spec_idx + 1) as u16,
            inventory_parameter_spec_id: rep.ips_id,
            antenna_id: r.antenna,
            channel_index: r.channel_index,
            rssi_dbm: r.rssi_dbm,
            phase_rad: r.phase_rad,
            doppler_hz: r.doppler_hz,
            utc_us: ctx.utc_epoch_us + r.time_us,
            uptime_us: r.time_us,
            op_spec_results: applied.results,
            access_spec_id: applied.access_spec_id,
            tid: if rep.content.impinj.serialized_tid {
                ctx.model.tag_tid(r.tag)
            } else {
                Vec::new()
            },
            // A tag matching a truncating Select sent only part of its EPC.
            truncated: slice.air.select.as_ref().and_then(|s| s.truncated(r.tag)),
        };
        if applied.at_once && applied.access_spec_id != 0 {
            // The access results go out now, in a report of their own with the ROSpec's
            // content; the read itself waits for the ROSpec's report trigger.
            out.push(Produced::Reports(vec![crate::reader::report::build(
                &o,
                rep.content,
            )]));
            o.op_spec_results = Vec::new();
            o.access_spec_id = 0;
        }
        self.buffer.add(&o, rep.content, rep.aggregate);
        if run.seen.insert(r.tag) {
            run.last_new_us = r.time_us;
        }
        if rep.every_n > 0 && self.buffer.len() >= rep.every_n {
            out.push(Produced::Reports(self.buffer.take()));
        }
        rep.stop_at_tags.is_some_and(|n| run.seen.len() >= n)
    }

    /// Reports what is buffered if the step reached the end of the report interval.
    fn report_on_interval(
        &mut self,
        run: &mut Run,
        reached: u64,
        interval: u64,
        out: &mut Vec<Produced>,
    ) {
        if reached >= run.last_report_us + interval {
            run.last_report_us = reached;
            if !self.buffer.is_empty() {
                out.push(Produced::Reports(self.buffer.take()));
            }
        }
    }

    /// Ends the current AISpec of active spec `a` at `at` and moves to its next (ending the
    /// ROSpec after its last).
    pub(super) fn next_ai(
        &mut self,
        a: usize,
        at: u64,
        report: &RoReportSpec,
        out: &mut Vec<Produced>,
    ) {
        self.end_ai(a, at, report, out);
        let s = &mut self.specs[a];
        let run = s
            .run
            .as_mut()
            .expect("an active spec has a run (set by begin)");
        run.spec_idx += 1;
        run.spec_started_us = at;
        run.seen.clear();
        run.last_new_us = at;
        run.rounds = 0;
        run.last_report_us = at;
        run.antenna_pos = 0;
        run.slice_end_us = dwell_end(at);
        run.slice_checked = false;
        run.slice_idle = false;
        if run.spec_idx >= s.spec.specs.len() {
            self.finish_ro(a, at, report, out);
        }
    }

    /// The reads of `slice`, from the physics computed ahead, with the look-ahead hint of
    /// this run: the current antenna to the end of its dwell, then the antennas in turn, a
    /// dwell each, up to the AISpec's or ROSpec's end when known (and up to an antenna whose
    /// channel list is pinned, computed when asked for).
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
        // An antenna the reader never leaves is computed a block at a time (its rounds run
        // on from its anchor).
        let anchor = slice.air.anchor_us;
        let end_of = |t_us: u64| match anchor {
            Some(a) => crate::physics::rounds::block_end(a, t_us),
            None => dwell_end(t_us),
        };
        let dwell = Slice {
            t1_us: if anchor.is_some() {
                end_of(slice.t0_us)
            } else {
                run.slice_end_us
            }
            .max(slice.t1_us),
            ..slice.clone()
        };
        let config = ctx.config;
        let gap_us = ctx.profile.round_gap_us as f64;
        let idle = &self.idle_antennas;
        let selections = &mut self.selections;
        let (model, memory) = (ctx.model, ctx.memory);
        // The antennas in turn from the one after this, a dwell each, except those whose
        // field was empty when last looked at: one empty round, then the next.
        let mut k = run.antenna_pos;
        let mut t0_us = dwell.t1_us;
        let upcoming = std::iter::from_fn(move || {
            let n = antennas.len().max(1);
            for _ in 0..n {
                k += 1;
                let antenna = antennas[k % n];
                if until.is_some_and(|u| t0_us >= u)
                    || !fixed_channel_list(ips, config, antenna).is_empty()
                    || antenna > model.antenna_count()
                {
                    return None;
                }
                let mut air = super::air::air_for(ips, config, antenna);
                air.anchor_us = anchor.filter(|_| n == 1);
                air.gap_us = gap_us;
                if air.suppresses() {
                    return None;
                }
                let query = super::air::select_query(ips, config, antenna, &air);
                air.select = selections.get(model, memory, query);
                if idle.get(usize::from(antenna)).copied().unwrap_or(false) {
                    t0_us += air.empty_round_us();
                    continue;
                }
                let s = Slice {
                    antenna,
                    air,
                    power_dbm: antenna_power(ips, config, antenna),
                    want: slice.want,
                    t0_us,
                    t1_us: end_of(t0_us),
                };
                t0_us = s.t1_us;
                return Some(s);
            }
            None
        });
        self.prefetch.reads(ctx.model, slice, dwell, upcoming)
    }

    pub(super) fn end_ai(
        &mut self,
        a: usize,
        at: u64,
        report: &RoReportSpec,
        out: &mut Vec<Produced>,
    ) {
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

    pub(super) fn finish_ro(
        &mut self,
        a: usize,
        at: u64,
        report: &RoReportSpec,
        out: &mut Vec<Produced>,
    ) {
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

impl Run {
    /// Moves to the next antenna if the step reached the end of the current one's slice
    /// (a round of the AISpec when back at the first).
    fn rotate(&mut self, reached: u64, antennas: usize) {
        if reached >= self.slice_end_us {
            self.antenna_pos += 1;
            if self.antenna_pos.is_multiple_of(antennas.max(1)) {
                self.rounds += 1;
            }
            self.slice_end_us = dwell_end(reached);
            self.slice_checked = false;
            self.slice_idle = false;
        }
    }
}

/// What a step runs: the slice of the current antenna and what its reads depend on.
struct Plan<'s> {
    /// The antenna, its power and air settings, from the end of the AISpec's setup to the
    /// step's end.
    slice: Slice,
    /// The channel the antenna is pinned to, if its channel list is.
    channel: Option<u16>,
    /// The AISpec's antennas in turn.
    antennas: Vec<u16>,
    /// The AISpec's InventoryParameterSpec.
    ips: Option<&'s InventoryParameterSpec>,
    /// The AISpec's or ROSpec's end, when known.
    until: Option<u64>,
}

impl<'s> Plan<'s> {
    /// The plan of a step of `ai` from `t` to `end` (at most) on the run's current antenna.
    fn new(
        ctx: &RunContext<'_>,
        run: &Run,
        ai: &'s AiSpec,
        (want, t, end, until): (Want, u64, u64, Option<u64>),
        selections: &mut Selections,
    ) -> Self {
        let antennas = ai_antennas(ai, ctx.profile.antennas);
        let antenna = antennas[run.antenna_pos % antennas.len().max(1)];
        let ips = ai.inventory_parameter_specs.first();
        let power = antenna_power(ips, ctx.config, antenna);
        let hop = ctx.model.hop_schedule();
        let channel = pinned_channel(ips, ctx.config, antenna, &hop, t);
        let mut end = end.max(t);
        if channel.is_some() {
            end = end.min(hop.dwell_start(t) + hop.dwell_us).max(t);
        }
        // The reader's setup at the AISpec's start: no round before it is over.
        let ready = run
            .spec_started_us
            .saturating_add(ctx.profile.aispec_setup_us);
        // The reader never leaves an AISpec's only antenna: its rounds run on from the first.
        let anchor_us = (antennas.len() == 1).then_some(ready);
        let slice = Slice {
            antenna,
            power_dbm: power,
            t0_us: t.max(ready),
            t1_us: end,
            want,
            air: step_air(ctx, ips, antenna, anchor_us, selections),
        };
        Plan {
            slice,
            channel,
            antennas,
            ips,
            until,
        }
    }
}

/// How a step reports its reads: the IDs they carry, what they carry and the triggers that
/// count them.
struct Reporting<'c> {
    ro_id: u32,
    ips_id: u16,
    content: &'c Content,
    /// Whether reads of the same tag are aggregated into one TagReportData.
    aggregate: bool,
    /// Reports each time this many reads are buffered (0: not on a count).
    every_n: usize,
    /// Ends the AISpec once it has seen this many tags.
    stop_at_tags: Option<usize>,
}

impl<'c> Reporting<'c> {
    /// The reporting of the AISpec with these stop triggers under `report_spec`.
    fn new(
        ro_id: u32,
        ips: Option<&InventoryParameterSpec>,
        content: &'c Content,
        report_spec: &RoReportSpec,
        trig: &AiSpecStopTrigger,
        obs: &TagObservationTrigger,
    ) -> Self {
        let reports_on_n = report_spec.ro_report_trigger != RoReportTriggerType::None;
        Reporting {
            ro_id,
            ips_id: ips.map_or(0, |p| p.inventory_parameter_spec_id),
            content,
            aggregate: !(reports_on_n && report_spec.n == 1),
            every_n: if reports_on_n {
                usize::from(report_spec.n)
            } else {
                0
            },
            stop_at_tags: (trig.ai_spec_stop_trigger_type == AiSpecStopTriggerType::TagObservation
                && obs.trigger_type == TagObservationTriggerType::UponSeeingNTagsOrTimeout
                && obs.number_of_tags > 0)
                .then(|| usize::from(obs.number_of_tags)),
        }
    }
}
