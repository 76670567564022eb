//! Running the active ROSpec over simulated time: antenna slices, the physics of each (from
//! the prefetch), stop triggers, report triggers and the events they raise.

use super::schedule::next_start;
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
        // The reader's setup at the AISpec's start: no round before it is over.
        let ready = run
            .spec_started_us
            .saturating_add(ctx.profile.aispec_setup_us);
        let air_t = t.max(ready);
        let mut air = super::air::air_for(ips, ctx.config, antenna);
        air.gap_us = ctx.profile.round_gap_us as f64;
        // The reader never leaves an AISpec's only antenna: its rounds run on from the first.
        air.anchor_us = (antennas.len() == 1).then_some(ready);
        let want = Want {
            phase: content.impinj.phase,
            doppler: content.impinj.doppler,
        };
        // An antenna facing no tag (by the field's bounds, or in a single-target inventory
        // with no tag left in A) gets one empty round, then the reader moves to the next.
        let fresh = !run.slice_checked && end > t;
        let mut idle = None;
        if fresh {
            run.slice_checked = true;
            idle = ctx.model.idle_us(antenna, t, power, channel, &air);
            let port = usize::from(antenna);
            if self.idle_antennas.len() <= port {
                self.idle_antennas.resize(port + 1, false);
            }
            self.idle_antennas[port] = idle.is_some();
        }
        if air.suppresses() && end > air_t && idle.is_none() && !run.slice_idle {
            let none_in_a = self.flagged_epoch(ctx, antenna, air_t, power, channel, want, &air);
            if fresh && none_in_a {
                idle = Some(air.empty_round_us());
            }
        }
        if let Some(idle) = idle {
            // The dwell ends after the empty round whatever the caller's steps are.
            run.slice_end_us = t + idle;
            run.slice_idle = true;
            reached = (t + idle).min(end);
        } else if run.slice_idle {
            // The rest of an empty round.
        } else if end > air_t {
            // Phase and Doppler are worked out only when reported.
            let slice = Slice {
                antenna,
                power_dbm: power,
                t0_us: air_t,
                t1_us: end,
                want,
                air,
            };
            let reads = match channel {
                // A single-target inventory carries the reader's flags from epoch to epoch,
                // so it runs here, in time order, an epoch at a time.
                _ if air.suppresses() => self.take_flagged(antenna, end),
                Some(_) => ctx
                    .model
                    .inventory_with(antenna, air_t, end, power, channel, want, &air),
                None => {
                    let until = [ai_end, ro_end].into_iter().flatten().min();
                    self.prefetched(ctx, &slice, &run, &antennas, ips, until)
                }
            };
            for r in reads {
                if air.suppresses() {
                    // Reported, so in B now (a read the stop trigger cuts off stays A).
                    ctx.flags.read(r.tag, air.session, r.time_us);
                }
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
            run.slice_end_us = dwell_end(reached);
            run.slice_checked = false;
            run.slice_idle = false;
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
            run.slice_end_us = dwell_end(reached);
            run.slice_checked = false;
            run.slice_idle = false;
            if run.spec_idx >= s.spec.specs.len() {
                self.finish_ro(a, reached, report_spec, out);
            }
        }
        reached
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
            ..*slice
        };
        let config = ctx.config;
        let gap_us = ctx.profile.round_gap_us as f64;
        let idle = &self.idle_antennas;
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
                {
                    return None;
                }
                let mut air = super::air::air_for(ips, config, antenna);
                air.anchor_us = anchor.filter(|_| n == 1);
                air.gap_us = gap_us;
                if air.suppresses() {
                    return None;
                }
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
pub(super) fn antenna_power(
    ips: Option<&InventoryParameterSpec>,
    config: &ReaderConfig,
    antenna: u16,
) -> Option<f64> {
    ips.and_then(|p| {
        p.antenna_configuration
            .iter()
            .find(|c| c.antenna_id == antenna || c.antenna_id == 0)
            .and_then(|c| c.rf_transmitter.as_ref())
            .and_then(|tx| crate::reader::caps::power_dbm(tx.transmit_power))
    })
    .or_else(|| config.tx_power_dbm(antenna))
}

/// The channel list of an ImpinjFixedFrequencyList in mode 2 (Channel_List) configured for
/// `antenna`, in the ROSpec's InventoryParameterSpec or else in the reader configuration.
pub(super) fn fixed_channel_list(
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
