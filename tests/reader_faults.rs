//! Faults injected into the simulated reader, in process on a virtual clock
//! (tests/common/virtual_reader.rs): what a client sees of an antenna unplugged and plugged
//! back, a dropped connection, a reboot (state lost or kept), delayed responses, lost
//! keepalives, a ReaderExceptionEvent, and the scenario's fault timeline. The report buffer
//! held full is the server's and is tested over TCP (tests/sim_faults.rs).

mod common;

use common::virtual_reader::{VirtualReader, UTC_EPOCH_US};
use common::*;
use llrp::message::*;
use llrp::params::*;
use llrp::{Message, MessageBody};
use llrp_gateway::reader::faults::Fault;
use llrp_gateway::scenario::faults::ScheduledFault;
use llrp_gateway::scenario::Scenario;

/// S1 with a second antenna beside its first (both see the tags).
fn two_antennas() -> Scenario {
    let mut s = Scenario::default_s1();
    let first = s.readers[0].antennas[0].clone();
    s.readers[0].antennas.push(first);
    s
}

/// Turns on the notifications of `types`.
fn enable_events(v: &mut VirtualReader, types: &[NotificationEventType]) {
    let set = SetReaderConfig {
        reader_event_notification_spec: Some(ReaderEventNotificationSpec {
            event_notification_state: (types.iter())
                .map(|&t| EventNotificationState {
                    event_type: t,
                    notification_state: true,
                    ..Default::default()
                })
                .collect(),
            ..Default::default()
        }),
        ..Default::default()
    };
    assert_eq!(v.status(set), StatusCode::M_Success);
}

/// ADD_ROSPEC then ENABLE_ROSPEC of an immediate ROSpec `id` on `antennas`.
fn inventory(v: &mut VirtualReader, id: u32, antennas: Vec<u16>) {
    let add = AddRospec {
        ro_spec: RoSpec::immediate(id, antennas),
        ..Default::default()
    };
    assert_eq!(v.status(add), StatusCode::M_Success);
    let enable = EnableRospec {
        ro_spec_id: id,
        ..Default::default()
    };
    assert_eq!(v.status(enable), StatusCode::M_Success);
}

/// The event data of a READER_EVENT_NOTIFICATION.
fn event(m: &Message) -> Option<&ReaderEventNotificationData> {
    match &m.body {
        MessageBody::ReaderEventNotification(n) => Some(&n.reader_event_notification_data),
        _ => None,
    }
}

/// The AntennaEvent of `m`, as (connected, antenna).
fn antenna_event(m: &Message) -> Option<(bool, u16)> {
    let a = event(m)?.antenna_event.as_ref()?;
    Some((
        a.event_type == AntennaEventType::AntennaConnected,
        a.antenna_id,
    ))
}

/// The antennas of the reads in `messages`' reports.
fn read_antennas(messages: &[Message]) -> Vec<u16> {
    let mut antennas: Vec<u16> = (messages.iter())
        .filter_map(|m| match &m.body {
            MessageBody::RoAccessReport(r) => Some(r.tag_report_data.iter()),
            _ => None,
        })
        .flatten()
        .map(|t| t.antenna_id.map_or(0, |a| a.0))
        .collect();
    antennas.sort_unstable();
    antennas.dedup();
    antennas
}

/// AntennaProperties.AntennaConnected of every antenna, from GET_READER_CONFIG.
fn connected(v: &mut VirtualReader) -> Vec<(u16, bool)> {
    let get = GetReaderConfig {
        requested_data: ConfigRequest::AntennaProperties,
        ..Default::default()
    };
    match v.request(get).body {
        MessageBody::GetReaderConfigResponse(r) => (r.antenna_properties.iter())
            .map(|p| (p.antenna_id, p.antenna_connected))
            .collect(),
        other => panic!("expected GET_READER_CONFIG_RESPONSE, got {other:?}"),
    }
}

#[test]
fn an_unplugged_antenna_says_so_reads_nothing_and_reads_again_once_plugged_back() {
    let mut v = VirtualReader::new(&two_antennas());
    enable_events(&mut v, &[NotificationEventType::AntennaEvent]);
    inventory(&mut v, 1, vec![0]);
    v.run_for(2_000_000);
    assert_eq!(read_antennas(&v.take()), [1, 2], "both antennas read");

    v.inject(Fault::AntennaDisconnect { antenna: 1 });
    let told = v.take();
    assert_eq!(
        told.iter().filter_map(antenna_event).collect::<Vec<_>>(),
        [(false, 1)],
        "the client is told at once"
    );
    // What was read before the cable was pulled may still come; a full dwell later, not.
    v.run_for(1_000_000);
    v.take();
    v.run_for(3_000_000);
    assert_eq!(
        read_antennas(&v.take()),
        [2],
        "no read on the unplugged port"
    );
    // Ports 3 and 4 of the device have nothing connected throughout.
    assert_eq!(
        connected(&mut v),
        [(1, false), (2, true), (3, false), (4, false)]
    );

    v.inject(Fault::AntennaReconnect { antenna: 1 });
    let told = v.take();
    assert_eq!(
        told.iter().filter_map(antenna_event).collect::<Vec<_>>(),
        [(true, 1)]
    );
    v.run_for(3_000_000);
    assert_eq!(read_antennas(&v.take()), [1, 2], "port 1 reads again");
    assert_eq!(
        connected(&mut v),
        [(1, true), (2, true), (3, false), (4, false)]
    );
}

#[test]
fn a_rospec_on_unplugged_antennas_only_runs_and_reads_nothing() {
    let mut v = VirtualReader::new(&Scenario::default_s1());
    enable_events(&mut v, &[NotificationEventType::RoSpecEvent]);
    // AntennaEvent is off: pulling the cable is silent.
    v.inject(Fault::AntennaDisconnect { antenna: 1 });
    assert!(v.take().iter().all(|m| antenna_event(m).is_none()));
    inventory(&mut v, 7, vec![1]);
    v.run_for(3_000_000);
    let seen = v.take();
    let started = seen.iter().filter_map(event).any(|e| {
        (e.ro_spec_event.as_ref())
            .is_some_and(|r| r.event_type == RoSpecEventType::StartOfRoSpec && r.ro_spec_id == 7)
    });
    assert!(started, "the ROSpec starts: {seen:?}");
    assert_eq!(read_antennas(&seen), Vec::<u16>::new(), "and reads nothing");
    assert!(v.session().reader().inventorying(), "it is still running");
    v.inject(Fault::AntennaReconnect { antenna: 1 });
    v.run_for(2_000_000);
    assert_eq!(read_antennas(&v.take()), [1]);
}

#[test]
fn a_dropped_connection_is_a_reset_without_connection_close_event_and_state_stays() {
    let mut v = VirtualReader::new(&Scenario::default_s1());
    inventory(&mut v, 3, vec![0]);
    v.run_for(500_000);
    v.take();
    v.inject(Fault::DropConnection);
    assert!(
        v.is_closed() && v.was_reset(),
        "the reader resets the connection"
    );
    assert!(
        v.take().iter().all(|m| !m.body.is_connection_close()),
        "nothing is said before"
    );
    // The reader is still there, with its ROSpec.
    assert!(v.listening());
    assert!(v.try_connect(), "a new connection is taken at once");
    let greeting = v.take();
    assert_eq!(
        greeting[0].body.connection_attempt(),
        Some(ConnectionAttemptStatus::Success)
    );
    assert_eq!(
        v.session().reader().rospec_state(3),
        Some(llrp_gateway::reader::SpecState::Active)
    );
}

/// The ROSpec IDs GET_ROSPECS lists.
fn rospecs(v: &mut VirtualReader) -> Vec<u32> {
    match v.request(GetRospecs::default()).body {
        MessageBody::GetRospecsResponse(r) => r.ro_specs.iter().map(|s| s.ro_spec_id).collect(),
        other => panic!("expected GET_ROSPECS_RESPONSE, got {other:?}"),
    }
}

/// The keepalive trigger GET_READER_CONFIG reports.
fn keepalive(v: &mut VirtualReader) -> KeepaliveTriggerType {
    let get = GetReaderConfig {
        requested_data: ConfigRequest::KeepaliveSpec,
        ..Default::default()
    };
    match v.request(get).body {
        MessageBody::GetReaderConfigResponse(r) => {
            r.keepalive_spec.expect("asked for").keepalive_trigger_type
        }
        other => panic!("expected GET_READER_CONFIG_RESPONSE, got {other:?}"),
    }
}

/// Periodic keepalives every `ms`.
fn keepalives_every(v: &mut VirtualReader, ms: u32) {
    let set = SetReaderConfig {
        keepalive_spec: Some(KeepaliveSpec {
            keepalive_trigger_type: KeepaliveTriggerType::Periodic,
            periodic_trigger_value: ms,
            ..Default::default()
        }),
        ..Default::default()
    };
    assert_eq!(v.status(set), StatusCode::M_Success);
}

/// A reader with a ROSpec and periodic keepalives is rebooted (`keep_state`) with a boot of
/// 2 s: the connection closes without a reset or a ConnectionCloseEvent, no connection is
/// taken during the boot, and a client connecting after it is greeted. The ROSpecs and the
/// keepalive trigger it finds are returned.
fn reboot(s: &Scenario, keep_state: Option<bool>) -> (Vec<u32>, KeepaliveTriggerType) {
    let mut v = VirtualReader::new(s);
    inventory(&mut v, 5, vec![0]);
    keepalives_every(&mut v, 10_000);
    v.run_for(300_000);
    v.take();
    v.inject(Fault::Reboot {
        keep_state,
        boot_ms: 2_000,
    });
    assert!(v.is_closed(), "the reboot closes the connection");
    assert!(!v.was_reset(), "closed, not reset");
    assert!(v.take().iter().all(|m| !m.body.is_connection_close()));
    assert!(!v.listening());
    assert!(!v.try_connect(), "nothing answers during the boot");
    v.idle_for(1_000_000);
    assert!(!v.try_connect(), "still booting");
    v.idle_for(1_000_000);
    assert!(v.listening(), "back after the boot time");
    assert!(v.try_connect());
    let greeting = v.take();
    assert_eq!(
        greeting[0].body.connection_attempt(),
        Some(ConnectionAttemptStatus::Success)
    );
    (rospecs(&mut v), keepalive(&mut v))
}

#[test]
fn a_reboot_closes_nothing_listens_during_the_boot_and_the_state_is_lost() {
    let (specs, keepalive) = reboot(&Scenario::default_s1(), None);
    assert_eq!(specs, Vec::<u32>::new(), "ROSpecs are gone");
    assert_eq!(
        keepalive,
        KeepaliveTriggerType::Null,
        "factory configuration"
    );
}

#[test]
fn a_reboot_keeps_the_state_of_a_reader_that_persists_it_unless_the_fault_says_not() {
    let mut s = Scenario::default_s1();
    s.readers[0].persist_state = true;
    assert_eq!(
        reboot(&s, None),
        (vec![5], KeepaliveTriggerType::Periodic),
        "persist_state keeps ROSpecs and configuration"
    );
    assert_eq!(
        reboot(&s, Some(false)).0,
        Vec::<u32>::new(),
        "keep_state false overrides it"
    );
    let plain = Scenario::default_s1();
    assert_eq!(
        reboot(&plain, Some(true)).0,
        vec![5],
        "and true the reverse"
    );
}

#[test]
fn delayed_requests_are_answered_late_in_order_and_on_time_once_the_fault_ends() {
    let mut v = VirtualReader::new(&Scenario::default_s1());
    v.take();
    v.inject(Fault::DelayResponses {
        ms: 1_500,
        for_ms: 5_000,
    });
    let first = v.send(GetRospecs::default());
    v.run_for(200_000);
    let second = v.send(GetReaderCapabilities::default());
    v.run_for(1_200_000);
    let early = v.take();
    assert!(
        early.is_empty(),
        "1.4 s on, nothing answered yet: {early:?}"
    );
    v.run_for(200_000);
    let answered: Vec<u32> = v.take().iter().map(|m| m.id).collect();
    assert_eq!(answered, [first], "the first, 1.5 s after it was sent");
    v.run_for(200_000);
    let answered: Vec<u32> = v.take().iter().map(|m| m.id).collect();
    assert_eq!(answered, [second]);
    v.run_for(4_000_000);
    // The fault is over: answered at once.
    assert_eq!(v.status(GetRospecs::default()), StatusCode::M_Success);
}

/// The virtual ms at which KEEPALIVEs arrive over `ms`, each acknowledged.
fn keepalives_over(v: &mut VirtualReader, ms: u64) -> Vec<u64> {
    let mut at = Vec::new();
    for _ in 0..ms / 100 {
        v.run_for(100_000);
        for m in v.take() {
            if matches!(m.body, MessageBody::Keepalive(_)) {
                at.push(v.now_us() / 1000);
                v.send(KeepaliveAck::default());
            }
        }
    }
    at
}

#[test]
fn lost_keepalives_leave_a_silence_then_resume_and_the_reader_keeps_the_client() {
    let mut v = VirtualReader::new(&Scenario::default_s1());
    keepalives_every(&mut v, 1_000);
    assert_eq!(keepalives_over(&mut v, 2_050), [1_000, 2_000]);
    v.inject(Fault::LoseKeepalives { count: 4 });
    // Four periods without one: past the three a client's watchdog allows.
    assert_eq!(keepalives_over(&mut v, 5_000), [7_000]);
    assert!(!v.is_closed(), "a keepalive not sent is not one unanswered");
    assert_eq!(keepalives_over(&mut v, 1_000), [8_000]);
}

#[test]
fn a_reader_exception_reaches_a_client_that_enabled_it_with_its_message() {
    let mut v = VirtualReader::new(&Scenario::default_s1());
    let exception =
        |m: &Message| (event(m)?.reader_exception_event.as_ref()).map(|e| e.message.clone());
    v.inject(Fault::ReaderException {
        message: "unheard".into(),
    });
    assert!(
        v.take().iter().all(|m| exception(m).is_none()),
        "not enabled"
    );
    enable_events(&mut v, &[NotificationEventType::ReaderExceptionEvent]);
    v.inject(Fault::ReaderException {
        message: "RF synthesizer unlocked".into(),
    });
    let got: Vec<_> = v.take().iter().filter_map(exception).collect();
    assert_eq!(got, ["RF synthesizer unlocked"]);
}

#[test]
fn the_scenarios_timeline_applies_each_fault_at_its_simulated_time() {
    let mut s = two_antennas();
    s.readers[0].faults = vec![
        ScheduledFault {
            t_ms: 1_500,
            fault: Fault::AntennaDisconnect { antenna: 2 },
        },
        ScheduledFault {
            t_ms: 2_500,
            fault: Fault::ReaderException {
                message: "scheduled".into(),
            },
        },
        ScheduledFault {
            t_ms: 4_000,
            fault: Fault::DropConnection,
        },
    ];
    let mut v = VirtualReader::new(&s);
    enable_events(
        &mut v,
        &[
            NotificationEventType::AntennaEvent,
            NotificationEventType::ReaderExceptionEvent,
        ],
    );
    v.run_for(5_000_000);
    let at = |m: &Message| match &event(m)?.timestamp {
        Timestamp::Utc(t) => Some((t.microseconds - UTC_EPOCH_US) / 1000),
        _ => None,
    };
    let seen: Vec<_> = (v.take().iter())
        .filter(|m| {
            event(m)
                .is_some_and(|e| e.antenna_event.is_some() || e.reader_exception_event.is_some())
        })
        .map(|m| (at(m), antenna_event(m)))
        .collect();
    assert_eq!(
        seen,
        [(Some(1_500), Some((false, 2))), (Some(2_500), None)],
        "each at its time"
    );
    assert!(
        v.is_closed() && v.was_reset(),
        "then the connection drops at 4 s"
    );
}

/// Events of the time no client was connected (a cable pulled, a reader exception) reach the
/// next client at its ENABLE_EVENTS_AND_REPORTS when the last client set
/// HoldEventsAndReportsUponReconnect (LLRP 1.1 §13.2.6.4), and are lost otherwise.
#[test]
fn events_with_no_client_reach_the_next_client_only_when_held() {
    let exception =
        |m: &Message| (event(m)?.reader_exception_event.as_ref()).map(|e| e.message.clone());
    for hold in [false, true] {
        let mut v = VirtualReader::new(&two_antennas());
        enable_events(
            &mut v,
            &[
                NotificationEventType::AntennaEvent,
                NotificationEventType::ReaderExceptionEvent,
            ],
        );
        let set = SetReaderConfig {
            events_and_reports: Some(EventsAndReports {
                hold_events_and_reports_upon_reconnect: hold,
                ..Default::default()
            }),
            ..Default::default()
        };
        assert_eq!(v.status(set), StatusCode::M_Success);
        v.disconnect();
        v.inject(Fault::AntennaDisconnect { antenna: 1 });
        v.inject(Fault::ReaderException {
            message: "RF synthesizer unlocked".into(),
        });
        v.idle_for(1_000_000);
        v.connect();
        let greeting = v.take();
        assert!(
            greeting
                .iter()
                .all(|m| antenna_event(m).is_none() && exception(m).is_none()),
            "hold {hold}: nothing before ENABLE_EVENTS_AND_REPORTS"
        );
        v.send(EnableEventsAndReports::default());
        let released = v.take();
        let antennas: Vec<_> = released.iter().filter_map(antenna_event).collect();
        let exceptions: Vec<_> = released.iter().filter_map(exception).collect();
        if hold {
            assert_eq!(antennas, [(false, 1)]);
            assert_eq!(exceptions, ["RF synthesizer unlocked"]);
        } else {
            assert!(antennas.is_empty() && exceptions.is_empty(), "{released:?}");
        }
        assert_eq!(connected(&mut v)[0], (1, false), "unplugged either way");
    }
}
