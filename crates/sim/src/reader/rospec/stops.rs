//! The free parts of running an ROSpec: each antenna's transmit power and pinned channels,
//! what the reads carry, when the ROSpec's and the AISpec's stop triggers end them, and the
//! antennas an AISpec names.

use super::*;
use crate::physics::gen2::Air;
use crate::physics::hopping::HopSchedule;

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
            .and_then(|tx| config.device.power.dbm(tx.transmit_power))
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

/// What the reads carry under `report_spec` (the Impinj part only with extensions enabled).
pub(super) fn report_content(report_spec: &RoReportSpec, impinj: bool) -> Content {
    Content {
        selector: report_spec.tag_report_content_selector.clone(),
        impinj: if impinj {
            ImpinjContent::from_report_spec(report_spec)
        } else {
            ImpinjContent::default()
        },
    }
}

/// When the ROSpec's stop trigger ends a run that started at `started_us`, if it can.
pub(super) fn ro_stop_end(stop: &RoSpecStopTrigger, started_us: u64) -> Option<u64> {
    match stop.ro_spec_stop_trigger_type {
        RoSpecStopTriggerType::Duration => {
            Some(started_us + u64::from(stop.duration_trigger_value) * 1000)
        }
        RoSpecStopTriggerType::GpiWithTimeout => stop
            .gpi_trigger_value
            .as_ref()
            .filter(|g| g.timeout > 0)
            .map(|g| started_us + u64::from(g.timeout) * 1000),
        _ => None,
    }
}

/// When the AISpec's stop trigger ends its current run, if it can (as known so far).
pub(super) fn ai_stop_end(
    trig: &AiSpecStopTrigger,
    obs: &TagObservationTrigger,
    run: &Run,
) -> Option<u64> {
    match trig.ai_spec_stop_trigger_type {
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
    }
}

/// Whether an inventory reports on ROReportTrigger 1 with N = 0 and nothing ends it
/// (neither its AISpec nor its ROSpec has a stop condition that can fire).
pub(super) fn never_ends(
    report_spec: &RoReportSpec,
    trig: &AiSpecStopTrigger,
    stop: &RoSpecStopTrigger,
    ai_end: Option<u64>,
    ro_end: Option<u64>,
) -> bool {
    report_spec.ro_report_trigger == RoReportTriggerType::UponNTagsOrEndOfAiSpec
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
        )
}

/// Whether the AISpec's tag observation trigger fires on its attempts or its quiet time
/// once the step has reached `reached`.
pub(super) fn observation_done(
    trig: &AiSpecStopTrigger,
    obs: &TagObservationTrigger,
    run: &Run,
    reached: u64,
) -> bool {
    let observing = trig.ai_spec_stop_trigger_type == AiSpecStopTriggerType::TagObservation;
    let attempts = observing
        && obs.trigger_type == TagObservationTriggerType::NAttemptsToSeeAllTagsInFovOrTimeout
        && obs.number_of_attempts > 0
        && run.rounds >= u32::from(obs.number_of_attempts);
    let quiet = observing
        && obs.trigger_type == TagObservationTriggerType::UponSeeingNoMoreNewTagsForTmsOrTimeout
        && reached >= run.last_new_us + u64::from(obs.t) * 1000;
    attempts || quiet
}

/// Whether an antenna is connected to port `antenna` (the scenario's antennas take the first
/// ports; the device's others have nothing connected and never read).
pub(super) fn wired(ctx: &RunContext<'_>, antenna: u16) -> bool {
    (1..=ctx.model.antenna_count()).contains(&antenna)
}

/// The antenna ports of `ai` (0: all the reader's `count`).
pub(super) fn ai_antennas(ai: &AiSpec, count: u16) -> Vec<u16> {
    if ai.antenna_ids.contains(&0) {
        (1..=count).collect()
    } else {
        ai.antenna_ids.clone()
    }
}

/// The channel `antenna` is pinned to at `t`, if an ImpinjFixedFrequencyList (mode 2,
/// channel list) in the ROSpec's or the reader's antenna configuration restricts its
/// channels: they rotate at the region's dwell.
pub(super) fn pinned_channel(
    ips: Option<&InventoryParameterSpec>,
    config: &ReaderConfig,
    antenna: u16,
    hop: &HopSchedule,
    t: u64,
) -> Option<u16> {
    let channels = fixed_channel_list(ips, config, antenna);
    (!channels.is_empty()).then(|| channels[((t / hop.dwell_us) % channels.len() as u64) as usize])
}

/// How the reader inventories on `antenna` in this step: the spec's air settings, the
/// profile's pause between rounds, the anchor of an antenna it never leaves and the tags its
/// Select filters leave in the rounds (from `selections`, worked out again when the tags'
/// memory has changed).
pub(super) fn step_air(
    ctx: &RunContext<'_>,
    ips: Option<&InventoryParameterSpec>,
    antenna: u16,
    anchor_us: Option<u64>,
    selections: &mut Selections,
) -> Air {
    let mut air = super::air::air_for(ips, ctx.config, antenna);
    air.gap_us = ctx.profile.round_gap_us as f64;
    air.anchor_us = anchor_us;
    let query = super::air::select_query(ips, ctx.config, antenna, &air);
    air.select = selections.get(ctx.model, ctx.memory, query);
    air
}
