//! GPI and GPO on the simulated reader, in process on a virtual clock
//! (tests/common/virtual_reader.rs): GPI start and stop triggers of ROSpecs and AISpecs,
//! their timeouts, GPIEvent notifications, disabled ports, GPO writes read back, the errors
//! for ports the reader lacks, and the scenario's GPI timeline and photo-eyes.

mod common;

use common::virtual_reader::{VirtualReader, UTC_EPOCH_US};
use common::*;
use llrp::message::*;
use llrp::params::*;
use llrp::Message;
use llrp_gateway::scenario::gpio::{GpiChange, GpioSpec, Level, PhotoEye};
use llrp_gateway::scenario::Scenario;

/// S1 with `gpio` on its reader.
fn s1_with(gpio: GpioSpec) -> Scenario {
    let mut s = Scenario::default_s1();
    s.readers[0].gpio = gpio;
    s
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

/// What a notification says, simplified, with its UTC µs since the virtual epoch.
#[derive(Debug, PartialEq)]
enum Note {
    Gpi(u16, bool, u64),
    Start(u32, u64),
    End(u32, u64),
    AiEnd(u32, u16, u64),
}

fn note(m: &Message) -> Option<Note> {
    let MessageBody::ReaderEventNotification(n) = &m.body else {
        return None;
    };
    let d = &n.reader_event_notification_data;
    let Timestamp::Utc(t) = &d.timestamp else {
        return None;
    };
    let at = t.microseconds - UTC_EPOCH_US;
    if let Some(g) = &d.gpi_event {
        return Some(Note::Gpi(g.gpi_port_number, g.gpi_event, at));
    }
    if let Some(e) = &d.ai_spec_event {
        return Some(Note::AiEnd(e.ro_spec_id, e.spec_index, at));
    }
    let e = d.ro_spec_event.as_ref()?;
    match e.event_type {
        RoSpecEventType::StartOfRoSpec => Some(Note::Start(e.ro_spec_id, at)),
        RoSpecEventType::EndOfRoSpec => Some(Note::End(e.ro_spec_id, at)),
        _ => None,
    }
}

/// The notifications in the inbox, in order; reports are counted.
fn notes(v: &mut VirtualReader) -> (Vec<Note>, usize) {
    let mut reports = 0;
    let mut out = Vec::new();
    for m in v.take() {
        if matches!(m.body, MessageBody::RoAccessReport(_)) {
            reports += 1;
        }
        out.extend(note(&m));
    }
    (out, reports)
}

/// A ROSpec reading every antenna that starts on GPI 1 going high and stops on it going low.
fn gated(id: u32, stop_timeout_ms: u32) -> RoSpec {
    RoSpec::immediate(id, vec![0])
        .with_start(RoSpecStartTrigger::gpi(1, true))
        .with_stop(RoSpecStopTrigger::gpi(1, false, stop_timeout_ms))
}

const EVENTS: &[NotificationEventType] = &[
    NotificationEventType::GpiEvent,
    NotificationEventType::RoSpecEvent,
];

#[test]
fn a_gpi_start_trigger_starts_the_rospec_on_its_event_only() {
    let mut v = VirtualReader::new(&Scenario::default_s1());
    v.enable_events(EVENTS);
    // Starts on GPI 1 falling (event false); rising is the other edge.
    let spec = RoSpec::immediate(1, vec![0]).with_start(RoSpecStartTrigger::gpi(1, false));
    add_and_enable(&mut v, spec);
    v.run_for(2_000_000);
    v.set_gpi(1, true);
    v.run_for(1_000_000);
    let (before, reports_before) = notes(&mut v);
    assert_eq!(
        (before, reports_before),
        (vec![Note::Gpi(1, true, 2_000_000)], 0),
        "nothing runs before the event"
    );
    v.set_gpi(1, false);
    v.run_for(3_000_000);
    let (after, reports) = notes(&mut v);
    assert_eq!(
        after[..2],
        [Note::Gpi(1, false, 3_000_000), Note::Start(1, 3_000_000)]
    );
    assert!(reports > 0, "the started ROSpec reads: {after:?}");
}

#[test]
fn a_gpi_stop_trigger_ends_the_rospec_on_its_event_and_the_start_trigger_rearms() {
    let mut v = VirtualReader::new(&Scenario::default_s1());
    v.enable_events(EVENTS);
    add_and_enable(&mut v, gated(1, 0));
    v.set_gpi(1, true);
    v.run_for(700_000);
    v.set_gpi(1, false);
    v.run_for(500_000);
    v.set_gpi(1, true);
    v.run_for(10_000);
    let (n, _) = notes(&mut v);
    assert_eq!(
        n,
        [
            Note::Gpi(1, true, 0),
            Note::Start(1, 0),
            Note::Gpi(1, false, 700_000),
            Note::End(1, 700_000),
            Note::Gpi(1, true, 1_200_000),
            Note::Start(1, 1_200_000),
        ]
    );
}

#[test]
fn a_gpi_stop_trigger_times_out_and_a_start_triggers_timeout_is_ignored() {
    let mut v = VirtualReader::new(&Scenario::default_s1());
    v.enable_events(EVENTS);
    // The start trigger's 100 ms timeout is ignored (LLRP 1.0.1 §10.2.1.1.1.2): no start.
    let mut spec = gated(1, 400);
    if let Some(g) = &mut spec
        .ro_boundary_spec
        .ro_spec_start_trigger
        .gpi_trigger_value
    {
        g.timeout = 100;
    }
    add_and_enable(&mut v, spec);
    v.run_for(1_000_000);
    assert_eq!(notes(&mut v).0, []);
    v.set_gpi(1, true);
    v.run_for(1_000_000);
    let (n, _) = notes(&mut v);
    assert_eq!(
        n,
        [
            Note::Gpi(1, true, 1_000_000),
            Note::Start(1, 1_000_000),
            Note::End(1, 1_400_000),
        ]
    );
}

#[test]
fn an_aispec_gpi_stop_trigger_moves_on_to_the_next_aispec() {
    let mut v = VirtualReader::new(&Scenario::default_s1());
    v.enable_events(&[NotificationEventType::AiSpecEvent]);
    let mut spec = RoSpec::immediate(1, vec![0]).with_start(RoSpecStartTrigger::null());
    let second = spec.specs[0].clone();
    spec.specs.push(second);
    if let SpecParameter::AiSpec(ai) = &mut spec.specs[0] {
        ai.ai_spec_stop_trigger = AiSpecStopTrigger::gpi(2, true, 0);
    }
    if let SpecParameter::AiSpec(ai) = &mut spec.specs[1] {
        ai.ai_spec_stop_trigger = AiSpecStopTrigger::duration(300);
    }
    add_and_enable(&mut v, spec);
    let start = StartRospec {
        ro_spec_id: 1,
        ..Default::default()
    };
    assert_eq!(v.status(start), StatusCode::M_Success);
    v.run_for(500_000);
    assert_eq!(notes(&mut v).0, [], "the first AISpec waits for GPI 2");
    v.set_gpi(2, true);
    v.run_for(1_000_000);
    assert_eq!(
        notes(&mut v).0,
        [Note::AiEnd(1, 1, 500_000), Note::AiEnd(1, 2, 800_000)]
    );
}

#[test]
fn a_disabled_port_raises_no_event_and_fires_no_trigger_and_reads_unknown() {
    let mut v = VirtualReader::new(&Scenario::default_s1());
    v.enable_events(EVENTS);
    add_and_enable(&mut v, gated(1, 0));
    let disable = SetReaderConfig {
        gpi_port_current_state: vec![GpiPortCurrentState {
            gpi_port_num: 1,
            config: false,
            // Ignored on a set.
            state: 1,
            ..Default::default()
        }],
        ..Default::default()
    };
    assert_eq!(v.status(disable), StatusCode::M_Success);
    v.set_gpi(1, true);
    v.run_for(1_000_000);
    assert_eq!(notes(&mut v), (vec![], 0));
    let states = gpi_states(&mut v);
    assert_eq!(
        states[0],
        (1, false, 2),
        "disabled: Config 0, State unknown"
    );
    assert_eq!(states[1], (2, true, 0), "the others enabled and low");
}

/// (port, Config, State) of every GPI, from GET_READER_CONFIG.
fn gpi_states(v: &mut VirtualReader) -> Vec<(u16, bool, u8)> {
    let get = GetReaderConfig {
        requested_data: ConfigRequest::GpiPortCurrentState,
        ..Default::default()
    };
    let MessageBody::GetReaderConfigResponse(r) = v.request(get).body else {
        panic!("a GET_READER_CONFIG_RESPONSE")
    };
    (r.gpi_port_current_state.iter())
        .map(|g| (g.gpi_port_num, g.config, g.state))
        .collect()
}

/// The GPO levels GET_READER_CONFIG reports, by port.
fn gpo_levels(v: &mut VirtualReader) -> Vec<(u16, bool)> {
    let get = GetReaderConfig {
        requested_data: ConfigRequest::GpoWriteData,
        ..Default::default()
    };
    let MessageBody::GetReaderConfigResponse(r) = v.request(get).body else {
        panic!("a GET_READER_CONFIG_RESPONSE")
    };
    (r.gpo_write_data.iter())
        .map(|g| (g.gpo_port_number, g.gpo_data))
        .collect()
}

fn gpo(port: u16, high: bool) -> GpoWriteData {
    GpoWriteData {
        gpo_port_number: port,
        gpo_data: high,
        ..Default::default()
    }
}

#[test]
fn a_gpo_write_reads_back_and_a_port_the_reader_lacks_changes_nothing() {
    let mut v = VirtualReader::new(&Scenario::default_s1());
    let write = SetReaderConfig {
        gpo_write_data: vec![gpo(2, true)],
        ..Default::default()
    };
    assert_eq!(v.status(write), StatusCode::M_Success);
    assert_eq!(
        gpo_levels(&mut v),
        [(1, false), (2, true), (3, false), (4, false)]
    );
    // Port 5 of a four-GPO reader: M_ParameterError on GPOWriteData's port field, and the
    // valid part of the request is not applied either.
    let bad = SetReaderConfig {
        gpo_write_data: vec![gpo(1, true), gpo(5, true)],
        ..Default::default()
    };
    let r = v.request(bad);
    let status = r.body.status().expect("a status");
    assert_eq!(status.status_code, StatusCode::M_ParameterError);
    let pe = status.parameter_error.as_ref().expect("a parameter error");
    assert_eq!(pe.parameter_type, 219);
    assert_eq!(
        pe.field_error.as_ref().map(|f| (f.field_num, f.error_code)),
        Some((0, StatusCode::A_OutOfRange))
    );
    assert_eq!(
        gpo_levels(&mut v),
        [(1, false), (2, true), (3, false), (4, false)]
    );
}

#[test]
fn the_gpi_level_reads_back_in_get_reader_config() {
    let mut v = VirtualReader::new(&Scenario::default_s1());
    v.set_gpi(3, true);
    assert_eq!(
        gpi_states(&mut v),
        [(1, true, 0), (2, true, 0), (3, true, 1), (4, true, 0)]
    );
}

#[test]
fn gpi_triggers_on_ports_the_reader_lacks_are_refused() {
    let mut v = VirtualReader::new(&s1_with(GpioSpec {
        gpis: Some(2),
        ..GpioSpec::default()
    }));
    let refused = |v: &mut VirtualReader, spec: RoSpec| {
        let r = v.request(AddRospec {
            ro_spec: spec,
            ..Default::default()
        });
        r.body.status().expect("a status").clone()
    };
    for port in [0, 3] {
        let start = RoSpec::immediate(1, vec![0]).with_start(RoSpecStartTrigger::gpi(port, true));
        let s = refused(&mut v, start);
        assert_eq!(s.status_code, StatusCode::M_ParameterError, "{s:?}");
        assert_eq!(s.parameter_error.map(|p| p.parameter_type), Some(177));
    }
    let stop = RoSpec::immediate(1, vec![0]).with_stop(RoSpecStopTrigger::gpi(3, false, 0));
    assert_eq!(
        refused(&mut v, stop).status_code,
        StatusCode::M_ParameterError
    );
    let ai = RoSpec::immediate(1, vec![0]).with_ai_stop(AiSpecStopTrigger::gpi(9, true, 0));
    assert_eq!(
        refused(&mut v, ai).status_code,
        StatusCode::M_ParameterError
    );
    let MessageBody::GetRospecsResponse(list) = v.request(GetRospecs::default()).body else {
        panic!("a GET_ROSPECS_RESPONSE")
    };
    assert!(list.ro_specs.is_empty(), "no refused ROSpec was added");
    // GET_READER_CONFIG for a GPI port it lacks: its GPIPortNum field is out of range.
    let get = GetReaderConfig {
        requested_data: ConfigRequest::GpiPortCurrentState,
        gpi_port_num: 3,
        ..Default::default()
    };
    let r = v.request(get);
    let s = r.body.status().expect("a status");
    assert_eq!(
        s.field_error.as_ref().map(|f| (f.field_num, f.error_code)),
        Some((2, StatusCode::A_OutOfRange))
    );
}

#[test]
fn the_capabilities_report_the_scenarios_port_counts() {
    let mut v = VirtualReader::new(&s1_with(GpioSpec {
        gpis: Some(2),
        gpos: Some(0),
        ..GpioSpec::default()
    }));
    let get = GetReaderCapabilities {
        requested_data: CapabilitiesRequest::GeneralDeviceCapabilities,
        ..Default::default()
    };
    let MessageBody::GetReaderCapabilitiesResponse(r) = v.request(get).body else {
        panic!("a GET_READER_CAPABILITIES_RESPONSE")
    };
    let g = r
        .general_device_capabilities
        .expect("general device capabilities")
        .gpio_capabilities;
    assert_eq!((g.num_gpis, g.num_gpos), (2, 0));
    // A reader without GPOs refuses any GPO write.
    let write = SetReaderConfig {
        gpo_write_data: vec![gpo(1, true)],
        ..Default::default()
    };
    assert_eq!(v.status(write), StatusCode::M_ParameterError);
}

#[test]
fn the_scenario_timeline_starts_and_stops_a_gated_rospec_at_its_times() {
    let change = |t_ms, state| GpiChange {
        t_ms,
        port: 1,
        state,
    };
    let mut v = VirtualReader::new(&s1_with(GpioSpec {
        gpi_timeline: vec![change(200, Level::High), change(700, Level::Low)],
        ..GpioSpec::default()
    }));
    v.enable_events(EVENTS);
    add_and_enable(&mut v, gated(1, 0));
    v.run_for(1_000_000);
    assert_eq!(
        notes(&mut v).0,
        [
            Note::Gpi(1, true, 200_000),
            Note::Start(1, 200_000),
            Note::Gpi(1, false, 700_000),
            Note::End(1, 700_000),
        ]
    );
}

#[test]
fn a_photo_eye_gates_one_run_per_pulse() {
    let mut v = VirtualReader::new(&s1_with(GpioSpec {
        photo_eyes: vec![PhotoEye {
            port: 1,
            start_ms: 100,
            period_ms: 1000,
            width_ms: 300,
            count: Some(2),
            active: Level::High,
        }],
        ..GpioSpec::default()
    }));
    v.enable_events(&[NotificationEventType::RoSpecEvent]);
    add_and_enable(&mut v, gated(1, 0));
    v.run_for(5_000_000);
    assert_eq!(
        notes(&mut v).0,
        [
            Note::Start(1, 100_000),
            Note::End(1, 400_000),
            Note::Start(1, 1_100_000),
            Note::End(1, 1_400_000),
        ]
    );
}

/// Sets EventsAndReports' HoldEventsAndReportsUponReconnect to `hold`.
fn hold_upon_reconnect(v: &mut VirtualReader, hold: bool) {
    let set = SetReaderConfig {
        events_and_reports: Some(EventsAndReports {
            hold_events_and_reports_upon_reconnect: hold,
            ..Default::default()
        }),
        ..Default::default()
    };
    assert_eq!(v.status(set), StatusCode::M_Success);
}

/// A GPI that changes while no client is connected: the next client hears of it at its
/// ENABLE_EVENTS_AND_REPORTS when the last one set HoldEventsAndReportsUponReconnect, never
/// otherwise; no trigger fires meanwhile.
#[test]
fn gpi_changes_with_no_client_reach_the_next_client_only_when_held() {
    for hold in [false, true] {
        let mut v = VirtualReader::new(&Scenario::default_s1());
        v.enable_events(EVENTS);
        add_and_enable(&mut v, gated(1, 0));
        hold_upon_reconnect(&mut v, hold);
        v.run_for(1_000_000);
        v.take();
        v.disconnect();
        v.set_gpi(1, true);
        v.idle_for(500_000);
        v.set_gpi(1, false);
        v.idle_for(500_000);
        v.connect();
        assert_eq!(notes(&mut v), (vec![], 0), "hold {hold}: nothing unasked");
        v.send(EnableEventsAndReports::default());
        let want = if hold {
            vec![
                Note::Gpi(1, true, 1_000_000),
                Note::Gpi(1, false, 1_500_000),
            ]
        } else {
            vec![]
        };
        assert_eq!(notes(&mut v), (want, 0), "hold {hold}");
        // The lines are where the changes left them.
        assert_eq!(gpi_states(&mut v)[0], (1, true, 0), "hold {hold}");
    }
}
