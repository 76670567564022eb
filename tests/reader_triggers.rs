//! Start/stop triggers, priorities and ground truth, with simulated time running at `max`.

mod common;

use std::time::Duration;

use common::*;
use llrp::message::*;
use llrp::params::*;
use llrp::Message;
use llrp_gateway::net::client::Client;
use llrp_gateway::net::clock::Speed;
use llrp_gateway::sim::{self, SimOptions};

async fn enable_rospec_events(c: &mut Client) {
    let set = SetReaderConfig {
        reader_event_notification_spec: Some(ReaderEventNotificationSpec {
            event_notification_state: vec![EventNotificationState {
                event_type: NotificationEventType::RoSpecEvent,
                notification_state: true,
                ..Default::default()
            }],
            ..Default::default()
        }),
        ..Default::default()
    };
    assert_eq!(request_status(c, set).await, StatusCode::M_Success);
}

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

/// ENABLE_ROSPEC `id`, which must succeed.
async fn enable(c: &mut Client, id: u32) {
    let enable = EnableRospec {
        ro_spec_id: id,
        ..Default::default()
    };
    assert_eq!(request_status(c, enable).await, StatusCode::M_Success);
}

async fn add(c: &mut Client, spec: RoSpec) {
    let code = request_status(
        c,
        AddRospec {
            ro_spec: spec,
            ..Default::default()
        },
    )
    .await;
    assert_eq!(code, StatusCode::M_Success);
}

#[tokio::test]
async fn periodic_start_with_duration_stop() {
    let sim = start(&s1(), Speed::Max).await;
    let mut c = connect(&sim).await;
    enable_rospec_events(&mut c).await;
    let mut spec = rospec(
        5,
        vec![1],
        ro_duration(200),
        ai_null(),
        full_report(RoReportTriggerType::UponNTagsOrEndOfRoSpec, 0),
    );
    spec.ro_boundary_spec.ro_spec_start_trigger = RoSpecStartTrigger {
        ro_spec_start_trigger_type: RoSpecStartTriggerType::Periodic,
        periodic_trigger_value: Some(PeriodicTriggerValue {
            offset: 500,
            period: 1000,
            ..Default::default()
        }),
        ..Default::default()
    };
    add(&mut c, spec).await;
    enable(&mut c, 5).await;
    let mut starts = Vec::new();
    let mut ends = Vec::new();
    while starts.len() < 4 {
        let m = c.recv(T).await.expect("events keep coming");
        if let Some((ty, id, _, t)) = rospec_event(&m) {
            assert_eq!(id, 5);
            match ty {
                RoSpecEventType::StartOfRoSpec => starts.push(t),
                RoSpecEventType::EndOfRoSpec => ends.push(t),
                _ => panic!("unexpected event {ty:?}"),
            }
        }
    }
    for w in starts.windows(2) {
        assert_eq!(w[1] - w[0], 1_000_000, "one start per 1000 ms period");
    }
    for (s, e) in starts.iter().zip(&ends) {
        assert_eq!(e - s, 200_000, "the duration trigger stops it after 200 ms");
    }
    sim.shutdown().await;
}

#[tokio::test]
async fn higher_priority_preempts_and_immediate_resumes() {
    let sim = start(&s1(), Speed::Max).await;
    let mut c = connect(&sim).await;
    enable_rospec_events(&mut c).await;
    let mut low = rospec(
        1,
        vec![1],
        ro_null(),
        ai_null(),
        full_report(RoReportTriggerType::None, 0),
    );
    low.priority = 3;
    add(&mut c, low).await;
    let mut high = rospec(
        2,
        vec![1],
        ro_null(),
        ai_null(),
        full_report(RoReportTriggerType::None, 0),
    );
    high.priority = 1;
    high.ro_boundary_spec.ro_spec_start_trigger = RoSpecStartTrigger::default();
    add(&mut c, high).await;
    for id in [1, 2] {
        enable(&mut c, id).await;
    }
    c.wait_for(
        |m| rospec_event(m).is_some_and(|e| e.0 == RoSpecEventType::StartOfRoSpec && e.1 == 1),
        T,
    )
    .await
    .expect("low-priority spec starts");
    let start2 = StartRospec {
        ro_spec_id: 2,
        ..Default::default()
    };
    assert_eq!(request_status(&mut c, start2).await, StatusCode::M_Success);
    c.wait_for(
        |m| rospec_event(m).is_some_and(|e| e == (RoSpecEventType::PreemptionOfRoSpec, 1, 2, e.3)),
        T,
    )
    .await
    .expect("spec 1 preempted by spec 2");
    let r = c.request(GetRospecs::default(), T).await.expect("list");
    let MessageBody::GetRospecsResponse(list) = r.body else {
        panic!("{r:?}")
    };
    let state = |id: u32| {
        list.ro_specs
            .iter()
            .find(|s| s.ro_spec_id == id)
            .map(|s| s.current_state)
    };
    assert_eq!(
        (state(1), state(2)),
        (Some(RoSpecState::Inactive), Some(RoSpecState::Active))
    );
    // A lower priority cannot preempt: starting spec 1 by hand leaves it waiting.
    let start1 = StartRospec {
        ro_spec_id: 1,
        ..Default::default()
    };
    assert_eq!(request_status(&mut c, start1).await, StatusCode::M_Success);
    tokio::time::sleep(Duration::from_millis(100)).await;
    let r = c.request(GetRospecs::default(), T).await.expect("list");
    let MessageBody::GetRospecsResponse(list) = r.body else {
        panic!("{r:?}")
    };
    let states: Vec<(u32, RoSpecState)> = list
        .ro_specs
        .iter()
        .map(|s| (s.ro_spec_id, s.current_state))
        .collect();
    assert_eq!(
        states,
        vec![(1, RoSpecState::Inactive), (2, RoSpecState::Active)]
    );
    let stop2 = StopRospec {
        ro_spec_id: 2,
        ..Default::default()
    };
    assert_eq!(request_status(&mut c, stop2).await, StatusCode::M_Success);
    c.wait_for(
        |m| rospec_event(m).is_some_and(|e| e.0 == RoSpecEventType::StartOfRoSpec && e.1 == 1),
        T,
    )
    .await
    .expect("the Immediate spec resumes once the preempting one stops");
    sim.shutdown().await;
}

#[tokio::test]
async fn ground_truth_is_written_as_jsonl() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("truth.jsonl");
    let scenario = s1();
    let opts = SimOptions {
        speed: Speed::Max,
        truth: Some(path.clone()),
        ..Default::default()
    };
    let sim = sim::start(&scenario, &opts).await.expect("starts");
    let mut c = connect(&sim).await;
    add(
        &mut c,
        rospec(
            1,
            vec![0],
            ro_null(),
            ai_null(),
            full_report(RoReportTriggerType::UponNTagsOrEndOfRoSpec, 100),
        ),
    )
    .await;
    enable(&mut c, 1).await;
    let _ = collect_reports(&mut c, Duration::from_secs(3), |t| t.len() >= 200).await;
    c.close().await.expect("close");
    sim.shutdown().await;
    let text = std::fs::read_to_string(&path).expect("truth written");
    let lines: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).expect("json line"))
        .collect();
    assert!(lines.len() >= 10, "{} lines", lines.len());
    let first = &lines[0];
    assert_eq!(first["t_us"], 0);
    let tags = first["tags"].as_array().expect("tags");
    assert_eq!(tags.len(), scenario.tags.len());
    for (t, spec) in tags.iter().zip(&scenario.tags) {
        assert_eq!(t["epc"].as_str(), Some(spec.epc.to_lowercase().as_str()));
        let p: Vec<f64> = serde_json::from_value(t["position"].clone()).expect("position");
        assert_eq!(p, spec.position.to_vec());
    }
    for w in lines.windows(2) {
        let dt = w[1]["t_us"].as_u64().expect("t") - w[0]["t_us"].as_u64().expect("t");
        assert_eq!(dt, 100_000);
    }
    // S1's antenna rides a robot: its true pose changes over time.
    let pos = |l: &serde_json::Value| l["antennas"][0]["pose"]["position"].clone();
    assert_ne!(pos(&lines[0]), pos(lines.last().expect("lines")));
}

#[tokio::test]
async fn reports_are_held_after_a_reconnect_until_enabled() {
    let sim = start(&s1(), Speed::Max).await;
    let mut c = connect(&sim).await;
    let hold = SetReaderConfig {
        events_and_reports: Some(EventsAndReports {
            hold_events_and_reports_upon_reconnect: true,
            ..Default::default()
        }),
        ..Default::default()
    };
    assert_eq!(request_status(&mut c, hold).await, StatusCode::M_Success);
    add(
        &mut c,
        rospec(
            1,
            vec![0],
            ro_null(),
            ai_null(),
            full_report(RoReportTriggerType::UponNTagsOrEndOfRoSpec, 1),
        ),
    )
    .await;
    enable(&mut c, 1).await;
    let (first, _) = collect_reports(&mut c, T, |t| !t.is_empty()).await;
    assert!(!first.is_empty(), "reports flow on the first connection");
    c.close().await.expect("close");
    tokio::time::sleep(Duration::from_millis(200)).await;
    // Reconnect: the ROSpec still runs, but reports wait for ENABLE_EVENTS_AND_REPORTS.
    let mut c = connect(&sim).await;
    let (held, _) = collect_reports(&mut c, Duration::from_millis(500), |_| false).await;
    assert!(held.is_empty(), "{} reports leaked while held", held.len());
    c.send(EnableEventsAndReports::default())
        .await
        .expect("send");
    let (released, _) = collect_reports(&mut c, T, |t| !t.is_empty()).await;
    assert!(!released.is_empty(), "held reports arrive once enabled");
    sim.shutdown().await;
}

#[tokio::test]
async fn every_reader_of_a_scenario_listens() {
    let mut scenario = s1();
    let mut second = scenario.readers[0].clone();
    second.name = "reader-2".into();
    scenario.readers.push(second);
    let sim = start(&scenario, Speed::Factor(1.0)).await;
    assert_eq!(sim.addrs.len(), 2);
    assert_ne!(sim.addrs[0], sim.addrs[1]);
    for addr in &sim.addrs {
        let mut c = Client::connect(*addr).await.expect("connects");
        let m = c.recv(T).await.expect("greeting");
        assert_eq!(
            connection_status(&m),
            Some(ConnectionAttemptStatus::Success)
        );
    }
    sim.shutdown().await;
}

/// The TagReportData of each RO_ACCESS_REPORT received within `limit`, one Vec per report.
async fn reports_by_message(
    c: &mut Client,
    limit: Duration,
    want: usize,
) -> Vec<Vec<TagReportData>> {
    let deadline = tokio::time::Instant::now() + limit;
    let mut out = Vec::new();
    while out.len() < want {
        let left = deadline.saturating_duration_since(tokio::time::Instant::now());
        if left.is_zero() {
            break;
        }
        match c.recv(left).await {
            Ok(Message {
                body: MessageBody::RoAccessReport(r),
                ..
            }) => out.push(r.tag_report_data),
            Ok(_) => {}
            Err(_) => break,
        }
    }
    out
}

fn last_seen(report: &[TagReportData]) -> u64 {
    report
        .iter()
        .filter_map(|t| t.last_seen_timestamp_utc.map(|s| s.0))
        .max()
        .expect("reports carry LastSeenTimestampUTC")
}

#[tokio::test]
async fn an_aispec_without_end_reports_at_the_reader_interval() {
    // sllurp's default ROSpec: Null stop triggers, ROReportTrigger 1 with N = 0. Impinj
    // readers report such an AISpec while it runs; the scenario's reader says how often.
    let mut scenario = s1();
    scenario.readers[0].report_interval_ms = 500;
    let sim = start(&scenario, Speed::Max).await;
    let mut c = connect(&sim).await;
    add(
        &mut c,
        rospec(
            1,
            vec![0],
            ro_null(),
            ai_null(),
            full_report(RoReportTriggerType::UponNTagsOrEndOfAiSpec, 0),
        ),
    )
    .await;
    enable(&mut c, 1).await;
    let reports = reports_by_message(&mut c, T, 6).await;
    assert_eq!(
        reports.len(),
        6,
        "reports keep coming while the AISpec runs"
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
    // Consecutive reports cover consecutive 500 ms windows of simulated time.
    for w in reports.windows(2) {
        let gap = last_seen(&w[1]) - last_seen(&w[0]);
        assert!(
            (250_000..=750_000).contains(&gap),
            "last reads {gap} µs apart, expected about 500 ms"
        );
    }
    sim.shutdown().await;
}

#[tokio::test]
async fn report_interval_zero_holds_reads_until_the_rospec_ends() {
    let mut scenario = s1();
    scenario.readers[0].report_interval_ms = 0;
    let sim = start(&scenario, Speed::Factor(20.0)).await;
    let mut c = connect(&sim).await;
    add(
        &mut c,
        rospec(
            1,
            vec![0],
            ro_null(),
            ai_null(),
            full_report(RoReportTriggerType::UponNTagsOrEndOfAiSpec, 0),
        ),
    )
    .await;
    enable(&mut c, 1).await;
    // 0.6 s at 20× is 12 s of simulated inventory.
    let held = reports_by_message(&mut c, Duration::from_millis(600), 1).await;
    assert!(held.is_empty(), "reads must wait for the end of the ROSpec");
    c.send(StopRospec {
        ro_spec_id: 1,
        ..Default::default()
    })
    .await
    .expect("send");
    let end = reports_by_message(&mut c, T, 1).await;
    assert_eq!(end.len(), 1, "stopping the ROSpec reports what it held");
    assert!(
        end[0]
            .iter()
            .map(|t| u32::from(t.tag_seen_count.map_or(0, |n| n.0)))
            .sum::<u32>()
            > 100,
        "the held report aggregates seconds of reads"
    );
    sim.shutdown().await;
}

#[tokio::test]
async fn a_rospec_duration_keeps_reads_until_its_end() {
    // The interval applies only when nothing can end the inventory: with a 3 s ROSpec the
    // reads of trigger 1, N = 0 wait for its end, as LLRP says.
    let sim = start(&s1(), Speed::Max).await;
    let mut c = connect(&sim).await;
    add(
        &mut c,
        rospec(
            1,
            vec![0],
            ro_duration(3000),
            ai_null(),
            full_report(RoReportTriggerType::UponNTagsOrEndOfAiSpec, 0),
        ),
    )
    .await;
    enable(&mut c, 1).await;
    let reports = reports_by_message(&mut c, T, 1).await;
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
    sim.shutdown().await;
}

/// An ROSpec without its own ROReportSpec reports as the reader's default one (set with
/// SET_READER_CONFIG) says: its trigger and its content selector.
#[tokio::test]
async fn a_rospec_without_a_report_spec_follows_the_reader_default() {
    let sim = start(&s1(), Speed::Max).await;
    let mut c = connect(&sim).await;
    let default = RoReportSpec {
        tag_report_content_selector: TagReportContentSelector {
            enable_antenna_id: true,
            ..Default::default()
        },
        ..full_report(RoReportTriggerType::UponNTagsOrEndOfRoSpec, 1)
    };
    let set = SetReaderConfig {
        ro_report_spec: Some(default),
        ..Default::default()
    };
    assert_eq!(request_status(&mut c, set).await, StatusCode::M_Success);
    let mut spec = rospec(
        1,
        vec![0],
        ro_null(),
        ai_null(),
        full_report(RoReportTriggerType::UponNTagsOrEndOfRoSpec, 100),
    );
    spec.ro_report_spec = None;
    add(&mut c, spec).await;
    enable(&mut c, 1).await;
    let (tags, _) = collect_reports(&mut c, T, |t| t.len() >= 20).await;
    assert!(tags.len() >= 20, "only {} tag reports", tags.len());
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
    sim.shutdown().await;
}
