//! Start/stop triggers, priorities, report triggers, held reports and keepalives, driven in
//! process with a virtual clock (tests/common/virtual_reader.rs): exact simulated times, no
//! sockets, no sleeps.

mod common;

use common::virtual_reader::{VirtualReader, UTC_EPOCH_US};
use common::*;
use llrp::message::*;
use llrp::params::*;
use llrp::Message;

/// (event type, ROSpec, preempting ROSpec, UTC µs) of a ROSpecEvent.
fn rospec_event(m: &Message) -> Option<(RoSpecEventType, u32, u32, u64)> {
    let MessageBody::ReaderEventNotification(n) = &m.body else {
        return None;
    };
    let d = &n.reader_event_notification_data;
    let e = d.ro_spec_event.as_ref()?;
    let Timestamp::Utc(t) = &d.timestamp else {
        return None;
    };
    Some((
        e.event_type,
        e.ro_spec_id,
        e.preempting_ro_spec_id,
        t.microseconds,
    ))
}

/// ADD_ROSPEC then ENABLE_ROSPEC, both of which must succeed.
fn add_and_enable(v: &mut VirtualReader, spec: RoSpec) {
    let id = spec.ro_spec_id;
    let add = AddRospec {
        ro_spec: spec,
        ..Default::default()
    };
    assert_eq!(v.status(add), StatusCode::M_Success);
    let enable = EnableRospec {
        ro_spec_id: id,
        ..Default::default()
    };
    assert_eq!(v.status(enable), StatusCode::M_Success);
}

/// The states GET_ROSPECS reports, by ROSpec ID.
fn states(v: &mut VirtualReader) -> Vec<(u32, RoSpecState)> {
    let r = v.request(GetRospecs::default());
    let MessageBody::GetRospecsResponse(list) = r.body else {
        panic!("{r:?}")
    };
    list.ro_specs
        .iter()
        .map(|s| (s.ro_spec_id, s.current_state))
        .collect()
}

fn last_seen(report: &[TagReportData]) -> u64 {
    report
        .iter()
        .filter_map(|t| t.last_seen_timestamp_utc.map(|s| s.0))
        .max()
        .expect("reports carry LastSeenTimestampUTC")
}

#[test]
fn periodic_start_with_duration_stop() {
    let mut v = VirtualReader::new(&s1());
    v.enable_events(&[NotificationEventType::RoSpecEvent]);
    let spec = rospec(
        5,
        vec![1],
        ro_duration(200),
        ai_null(),
        full_report(RoReportTriggerType::UponNTagsOrEndOfRoSpec, 0),
    )
    .with_start(RoSpecStartTrigger::periodic(500, 1000));
    add_and_enable(&mut v, spec);
    v.run_for(4_000_000);
    let mut starts = Vec::new();
    let mut ends = Vec::new();
    for m in v.take() {
        if let Some((ty, id, _, t)) = rospec_event(&m) {
            assert_eq!(id, 5);
            match ty {
                RoSpecEventType::StartOfRoSpec => starts.push(t - UTC_EPOCH_US),
                RoSpecEventType::EndOfRoSpec => ends.push(t - UTC_EPOCH_US),
                _ => panic!("unexpected event {ty:?}"),
            }
        }
    }
    // Enabled at 0: starts at the 500 ms offset and every 1000 ms period after it, each
    // stopped by its 200 ms duration.
    assert_eq!(starts, [500_000, 1_500_000, 2_500_000, 3_500_000]);
    assert_eq!(ends, [700_000, 1_700_000, 2_700_000, 3_700_000]);
}

#[test]
fn higher_priority_preempts_and_immediate_resumes() {
    let mut v = VirtualReader::new(&s1());
    v.enable_events(&[NotificationEventType::RoSpecEvent]);
    let low = rospec(
        1,
        vec![1],
        ro_null(),
        ai_null(),
        full_report(RoReportTriggerType::None, 0),
    )
    .with_priority(3);
    add_and_enable(&mut v, low);
    let high = rospec(
        2,
        vec![1],
        ro_null(),
        ai_null(),
        full_report(RoReportTriggerType::None, 0),
    )
    .with_priority(1)
    .with_start(RoSpecStartTrigger::null());
    add_and_enable(&mut v, high);
    let started = |id| {
        move |m: &Message| {
            rospec_event(m).is_some_and(|e| e.0 == RoSpecEventType::StartOfRoSpec && e.1 == id)
        }
    };
    v.run_until(1_000_000, started(1))
        .expect("the low-priority Immediate spec starts");
    let start2 = StartRospec {
        ro_spec_id: 2,
        ..Default::default()
    };
    assert_eq!(v.status(start2), StatusCode::M_Success);
    v.run_until(1_000_000, |m| {
        rospec_event(m)
            .is_some_and(|e| (e.0, e.1, e.2) == (RoSpecEventType::PreemptionOfRoSpec, 1, 2))
    })
    .expect("spec 1 preempted by spec 2");
    assert_eq!(
        states(&mut v),
        [(1, RoSpecState::Inactive), (2, RoSpecState::Active)]
    );
    // A lower priority cannot preempt: starting spec 1 by hand leaves it waiting.
    let start1 = StartRospec {
        ro_spec_id: 1,
        ..Default::default()
    };
    assert_eq!(v.status(start1), StatusCode::M_Success);
    v.run_for(500_000);
    assert_eq!(
        states(&mut v),
        [(1, RoSpecState::Inactive), (2, RoSpecState::Active)]
    );
    let stop2 = StopRospec {
        ro_spec_id: 2,
        ..Default::default()
    };
    assert_eq!(v.status(stop2), StatusCode::M_Success);
    v.run_until(1_000_000, started(1))
        .expect("the Immediate spec resumes once the preempting one stops");
}

/// What a reader sends from a reconnect on, with or without HoldEventsAndReportsUponReconnect:
/// the reports of one second of inventory on the first connection, then those of the two
/// seconds after a reconnect, then those sent after ENABLE_EVENTS_AND_REPORTS.
fn reconnect_run(hold: bool) -> (Vec<Message>, Vec<Message>, Vec<Message>) {
    let reports = |ms: Vec<Message>| -> Vec<Message> {
        ms.into_iter()
            .filter(|m| matches!(m.body, MessageBody::RoAccessReport(_)))
            .collect()
    };
    let mut v = VirtualReader::new(&s1());
    let set = SetReaderConfig {
        events_and_reports: Some(EventsAndReports {
            hold_events_and_reports_upon_reconnect: hold,
            ..Default::default()
        }),
        ..Default::default()
    };
    assert_eq!(v.status(set), StatusCode::M_Success);
    add_and_enable(
        &mut v,
        rospec(
            1,
            vec![0],
            ro_null(),
            ai_null(),
            full_report(RoReportTriggerType::UponNTagsOrEndOfRoSpec, 1),
        ),
    );
    v.run_for(1_000_000);
    let first = reports(v.take());
    v.disconnect();
    v.connect();
    v.run_for(2_000_000);
    let during = reports(v.take());
    v.send(EnableEventsAndReports::default());
    let released = reports(v.take());
    (first, during, released)
}

#[test]
fn reports_are_held_after_a_reconnect_and_released_as_they_were() {
    let (first, held_during, released) = reconnect_run(true);
    assert!(!first.is_empty(), "reports flow on the first connection");
    assert!(
        held_during.is_empty(),
        "{} reports leaked while held",
        held_during.len()
    );
    // The same run without holding sends, in those two seconds, exactly what the held run
    // releases (same messages, same IDs, same order): nothing lost, nothing made up.
    let (first_unheld, sent_unheld, after_unheld) = reconnect_run(false);
    assert_eq!(first, first_unheld);
    assert!(after_unheld.is_empty());
    assert!(
        !sent_unheld.is_empty(),
        "the ROSpec inventories after a reconnect"
    );
    assert_eq!(released, sent_unheld);
}

/// Reads a ROSpec gathered for a client that left before they were reported (report trigger
/// None: only GET_REPORT reports) are not reported to the next client, unless
/// HoldEventsAndReportsUponReconnect keeps them for it.
#[test]
fn unreported_reads_of_a_departed_client_reach_the_next_only_when_held() {
    for hold in [false, true] {
        let mut v = VirtualReader::new(&s1());
        let set = SetReaderConfig {
            events_and_reports: Some(EventsAndReports {
                hold_events_and_reports_upon_reconnect: hold,
                ..Default::default()
            }),
            ..Default::default()
        };
        assert_eq!(v.status(set), StatusCode::M_Success);
        add_and_enable(
            &mut v,
            rospec(
                1,
                vec![0],
                ro_null(),
                ai_null(),
                full_report(RoReportTriggerType::None, 0),
            ),
        );
        v.run_for(1_000_000);
        assert!(
            v.take_reports().is_empty(),
            "trigger None reports nothing by itself"
        );
        v.disconnect();
        v.connect();
        v.send(GetReport::default());
        v.send(EnableEventsAndReports::default());
        let reads: usize = v.take_reports().iter().map(Vec::len).sum();
        if hold {
            assert!(reads > 0, "held for the next connection, then reported");
        } else {
            assert_eq!(reads, 0, "the departed client's reads reached the next one");
        }
        // The ROSpec itself stays, as on an Impinj reader.
        let m = v.request(GetRospecs::default());
        let MessageBody::GetRospecsResponse(r) = &m.body else {
            panic!("{m:?}")
        };
        assert_eq!(r.ro_specs.len(), 1, "hold {hold}");
    }
}

#[test]
fn an_aispec_without_end_reports_at_the_reader_interval() {
    // sllurp's default ROSpec: Null stop triggers, ROReportTrigger 1 with N = 0. Impinj
    // readers report such an AISpec while it runs; the scenario's reader says how often.
    let mut scenario = s1();
    scenario.readers[0].report_interval_ms = 500;
    let mut v = VirtualReader::new(&scenario);
    add_and_enable(
        &mut v,
        rospec(
            1,
            vec![0],
            ro_null(),
            ai_null(),
            full_report(RoReportTriggerType::UponNTagsOrEndOfAiSpec, 0),
        ),
    );
    v.run_for(3_250_000);
    let reports = v.take_reports();
    assert_eq!(
        reports.len(),
        6,
        "one report per 500 ms while the AISpec runs"
    );
    for r in &reports {
        let mut epcs: Vec<_> = r.iter().map(|t| format!("{:?}", t.epc)).collect();
        let n = epcs.len();
        epcs.sort();
        epcs.dedup();
        assert_eq!(epcs.len(), n, "one aggregated entry per tag in each report");
        assert!(
            r.iter().any(|t| t.tag_seen_count.map_or(0, |n| n.0) > 1),
            "reads aggregate between reports"
        );
    }
    // Each report holds the reads of its own 500 ms window of simulated time.
    for (k, r) in reports.iter().enumerate() {
        let end = UTC_EPOCH_US + 500_000 * (k as u64 + 1);
        assert!(
            last_seen(r) < end && last_seen(r) >= end - 500_000,
            "report {k}: last read at {} µs",
            last_seen(r) - UTC_EPOCH_US
        );
    }
}

#[test]
fn report_interval_zero_holds_reads_until_the_rospec_ends() {
    let mut scenario = s1();
    scenario.readers[0].report_interval_ms = 0;
    let mut v = VirtualReader::new(&scenario);
    add_and_enable(
        &mut v,
        rospec(
            1,
            vec![0],
            ro_null(),
            ai_null(),
            full_report(RoReportTriggerType::UponNTagsOrEndOfAiSpec, 0),
        ),
    );
    v.run_for(12_000_000);
    assert!(
        v.take_reports().is_empty(),
        "reads wait for the end of the ROSpec"
    );
    // The reader is running all the while: its ROSpec is Active.
    assert_eq!(states(&mut v), [(1, RoSpecState::Active)]);
    let stop = StopRospec {
        ro_spec_id: 1,
        ..Default::default()
    };
    assert_eq!(v.status(stop), StatusCode::M_Success);
    let end = v.take_reports();
    assert_eq!(end.len(), 1, "stopping the ROSpec reports what it held");
    assert!(
        end[0]
            .iter()
            .map(|t| u32::from(t.tag_seen_count.map_or(0, |n| n.0)))
            .sum::<u32>()
            > 100,
        "the held report aggregates seconds of reads"
    );
}

#[test]
fn a_rospec_duration_keeps_reads_until_its_end() {
    // The interval applies only when nothing can end the inventory: with a 3 s ROSpec the
    // reads of trigger 1, N = 0 wait for its end, as LLRP says.
    let mut v = VirtualReader::new(&s1());
    add_and_enable(
        &mut v,
        rospec(
            1,
            vec![0],
            ro_duration(3000),
            ai_null(),
            full_report(RoReportTriggerType::UponNTagsOrEndOfAiSpec, 0),
        ),
    );
    v.run_for(2_900_000);
    assert!(
        v.take_reports().is_empty(),
        "nothing before the ROSpec ends"
    );
    v.run_for(200_000);
    let reports = v.take_reports();
    assert_eq!(reports.len(), 1, "one report when the ROSpec ends");
    let first = reports[0]
        .iter()
        .filter_map(|t| t.first_seen_timestamp_utc.map(|s| s.0))
        .min()
        .expect("FirstSeenTimestampUTC");
    let span = last_seen(&reports[0]) - first;
    assert!(
        span > 2_000_000,
        "the report spans the whole run, not one interval ({span} µs)"
    );
}

/// An ROSpec without its own ROReportSpec reports as the reader's default one (set with
/// SET_READER_CONFIG) says: its trigger and its content selector.
#[test]
fn a_rospec_without_a_report_spec_follows_the_reader_default() {
    let mut v = VirtualReader::new(&s1());
    let default = RoReportSpec::new(RoReportTriggerType::UponNTagsOrEndOfRoSpec, 1).with_content(
        TagReportContentSelector {
            enable_antenna_id: true,
            ..Default::default()
        },
    );
    let set = SetReaderConfig {
        ro_report_spec: Some(default),
        ..Default::default()
    };
    assert_eq!(v.status(set), StatusCode::M_Success);
    let mut spec = rospec(
        1,
        vec![0],
        ro_null(),
        ai_null(),
        full_report(RoReportTriggerType::UponNTagsOrEndOfRoSpec, 100),
    );
    spec.ro_report_spec = None;
    add_and_enable(&mut v, spec);
    v.run_for(2_000_000);
    let reports = v.take_reports();
    let tags: Vec<&TagReportData> = reports.iter().flatten().collect();
    assert!(tags.len() >= 20, "only {} tag reports", tags.len());
    assert!(
        reports.iter().all(|r| r.len() == 1),
        "the default trigger's N = 1, not the ROSpec's ignored 100"
    );
    for t in &tags {
        assert!(
            t.antenna_id.is_some(),
            "the default selector enables AntennaID"
        );
        assert!(
            t.peak_rssi.is_none()
                && t.channel_index.is_none()
                && t.ro_spec_id.is_none()
                && t.first_seen_timestamp_utc.is_none()
                && t.tag_seen_count.is_none(),
            "fields the default selector leaves out: {t:?}"
        );
    }
}

#[test]
fn keepalives_run_on_the_wall_clock_and_a_silent_client_is_dropped() {
    let mut v = VirtualReader::new(&s1());
    v.take();
    let set = SetReaderConfig {
        keepalive_spec: Some(KeepaliveSpec {
            keepalive_trigger_type: KeepaliveTriggerType::Periodic,
            periodic_trigger_value: 100,
            ..Default::default()
        }),
        ..Default::default()
    };
    assert_eq!(v.status(set), StatusCode::M_Success);
    v.run_for(100_000);
    let names: Vec<&str> = v.take().iter().map(|m| m.name()).collect();
    assert_eq!(names, ["KEEPALIVE"], "one keepalive per 100 ms");
    v.send(KeepaliveAck::default());
    // Three more go unanswered; at the fourth period the reader says why and closes.
    v.run_for(350_000);
    assert!(!v.is_closed(), "three unanswered keepalives are tolerated");
    let names: Vec<String> = v.take().iter().map(|m| m.name().to_string()).collect();
    assert_eq!(names, ["KEEPALIVE", "KEEPALIVE", "KEEPALIVE"]);
    v.run_for(100_000);
    assert!(v.is_closed(), "the reader closed the connection");
    let last = v.take();
    match &last[..] {
        [m] => assert!(m.body.is_connection_close(), "{m:?}"),
        other => panic!("expected one message, got {other:?}"),
    }
}
