//! The simulated reader's LLRP behaviour over loopback, driven by the crate's own client:
//! connection rules, capabilities, configuration, the ROSpec lifecycle and error answers.

mod common;

use common::*;
use llrp::message::*;
use llrp::params::*;
use llrp::StatusCode;
use llrp_gateway::net::client::Client;
use llrp_gateway::net::clock::Speed;

#[tokio::test]
async fn second_client_is_refused_and_first_is_told() {
    let sim = start(&s1(), Speed::Factor(1.0)).await;
    let mut first = connect(&sim).await;
    let mut second = Client::connect(sim.addrs[0]).await.expect("tcp connects");
    let m = second.recv(T).await.expect("refusal");
    assert_eq!(
        connection_status(&m),
        Some(ConnectionAttemptStatus::FailedClientInitiatedConnectionExists),
        "{m:?}"
    );
    second
        .until_closed(T)
        .await
        .expect("the refused client is closed");
    let told = first.recv(T).await.expect("notice");
    assert_eq!(
        connection_status(&told),
        Some(ConnectionAttemptStatus::AnotherConnectionAttempted),
        "{told:?}"
    );
    // The first client is undisturbed.
    let code = request_status(&mut first, GetReaderCapabilities::default()).await;
    assert_eq!(code, StatusCode::M_Success);
    // Once it leaves, a new client is accepted.
    first
        .close(T)
        .await
        .expect("the reader closes its side too");
    let _third = connect(&sim).await;
    sim.shutdown().await;
}

#[tokio::test]
async fn capabilities_follow_the_scenario() {
    let scenario = s1();
    let sim = start(&scenario, Speed::Factor(1.0)).await;
    let mut c = connect(&sim).await;
    let r = c
        .request(GetReaderCapabilities::default(), T)
        .await
        .expect("response");
    let MessageBody::GetReaderCapabilitiesResponse(caps) = r.body else {
        panic!("unexpected {r:?}")
    };
    let g = caps.general_device_capabilities.expect("general");
    // The default device's ports (a Speedway R420's four), whatever the scenario connects.
    assert!(scenario.readers[0].antennas.len() <= 4);
    assert_eq!(g.max_number_of_antenna_supported, 4);
    assert_eq!(g.device_manufacturer_name, 25882);
    let reg = caps.regulatory_capabilities.expect("regulatory");
    let band = reg.uhf_band_capabilities.expect("band");
    let table = &band.transmit_power_level_table_entry;
    assert!(
        table
            .iter()
            .enumerate()
            .all(|(i, e)| usize::from(e.index) == i + 1),
        "contiguous power table"
    );
    let freqs = match &band.frequency_information {
        f if f.hopping => f.frequency_hop_table[0].frequencies.clone(),
        f => f
            .fixed_frequency_table
            .as_ref()
            .expect("fixed table")
            .frequencies
            .clone(),
    };
    assert_eq!(freqs, scenario.readers[0].region.frequencies_khz());
    assert!(!band.c1g2_uhf_rf_mode_table[0].entries.is_empty());
    // An unknown RequestedData is a field error, not a crash.
    let bad = c
        .request(
            GetReaderCapabilities {
                requested_data: CapabilitiesRequest::Unknown(9),
                ..Default::default()
            },
            T,
        )
        .await
        .expect("response");
    assert_eq!(status(&bad).status_code, StatusCode::M_FieldError);
    sim.shutdown().await;
}

#[tokio::test]
async fn configuration_round_trips_and_resets() {
    let sim = start(&s1(), Speed::Factor(1.0)).await;
    let mut c = connect(&sim).await;
    let set = SetReaderConfig {
        keepalive_spec: Some(KeepaliveSpec {
            keepalive_trigger_type: KeepaliveTriggerType::Periodic,
            periodic_trigger_value: 60_000,
            ..Default::default()
        }),
        antenna_configuration: vec![AntennaConfiguration {
            antenna_id: 1,
            rf_transmitter: Some(RfTransmitter {
                hop_table_id: 1,
                channel_index: 1,
                transmit_power: 5,
                ..Default::default()
            }),
            ..Default::default()
        }],
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
    assert_eq!(request_status(&mut c, set).await, StatusCode::M_Success);
    let r = c
        .request(GetReaderConfig::default(), T)
        .await
        .expect("config");
    let MessageBody::GetReaderConfigResponse(cfg) = r.body else {
        panic!("{r:?}")
    };
    assert_eq!(
        cfg.keepalive_spec
            .as_ref()
            .map(|k| k.periodic_trigger_value),
        Some(60_000)
    );
    let a1 = &cfg.antenna_configuration[0];
    assert_eq!(
        a1.rf_transmitter.as_ref().map(|t| t.transmit_power),
        Some(5)
    );
    let ev = cfg.reader_event_notification_spec.expect("events");
    assert!(ev
        .event_notification_state
        .iter()
        .any(|s| s.event_type == NotificationEventType::RoSpecEvent && s.notification_state));
    // A power index outside the table is refused and changes nothing.
    let bad = SetReaderConfig {
        antenna_configuration: vec![AntennaConfiguration {
            antenna_id: 1,
            rf_transmitter: Some(RfTransmitter {
                hop_table_id: 1,
                channel_index: 1,
                transmit_power: 999,
                ..Default::default()
            }),
            ..Default::default()
        }],
        ..Default::default()
    };
    let r = c.request(bad, T).await.expect("response");
    let st = status(&r);
    assert_eq!(st.status_code, StatusCode::M_ParameterError);
    assert_eq!(
        st.parameter_error.as_ref().map(|p| p.parameter_type),
        Some(222)
    );
    // Factory reset restores the defaults.
    let reset = SetReaderConfig {
        reset_to_factory_default: true,
        ..Default::default()
    };
    assert_eq!(request_status(&mut c, reset).await, StatusCode::M_Success);
    let r = c
        .request(GetReaderConfig::default(), T)
        .await
        .expect("config");
    let MessageBody::GetReaderConfigResponse(cfg) = r.body else {
        panic!("{r:?}")
    };
    assert_ne!(
        cfg.antenna_configuration[0]
            .rf_transmitter
            .as_ref()
            .map(|t| t.transmit_power),
        Some(5)
    );
    assert_eq!(
        cfg.keepalive_spec
            .as_ref()
            .map(|k| k.keepalive_trigger_type),
        Some(KeepaliveTriggerType::Null)
    );
    sim.shutdown().await;
}

#[tokio::test]
async fn rospec_lifecycle_and_its_errors() {
    let sim = start(&s1(), Speed::Factor(1.0)).await;
    let mut c = connect(&sim).await;
    // Deleting everything when there is nothing succeeds (sllurp relies on it).
    assert_eq!(
        request_status(&mut c, DeleteAccessspec::default()).await,
        StatusCode::M_Success
    );
    assert_eq!(
        request_status(&mut c, DeleteRospec::default()).await,
        StatusCode::M_Success
    );
    let spec = rospec(
        7,
        vec![1],
        ro_null(),
        ai_null(),
        full_report(RoReportTriggerType::None, 0),
    );
    assert_eq!(
        request_status(
            &mut c,
            AddRospec {
                ro_spec: spec.clone(),
                ..Default::default()
            }
        )
        .await,
        StatusCode::M_Success
    );
    // Same ID twice, and a spec not added Disabled, are refused.
    assert_eq!(
        request_status(
            &mut c,
            AddRospec {
                ro_spec: spec.clone(),
                ..Default::default()
            }
        )
        .await,
        StatusCode::M_ParameterError
    );
    let mut active = spec.clone();
    active.ro_spec_id = 8;
    active.current_state = RoSpecState::Active;
    assert_eq!(
        request_status(
            &mut c,
            AddRospec {
                ro_spec: active,
                ..Default::default()
            }
        )
        .await,
        StatusCode::M_ParameterError
    );
    // Antenna 99 does not exist.
    let mut far = spec.clone();
    far.ro_spec_id = 9;
    far.specs = vec![SpecParameter::AiSpec(AiSpec {
        antenna_ids: vec![99],
        ai_spec_stop_trigger: ai_null(),
        inventory_parameter_specs: vec![InventoryParameterSpec {
            inventory_parameter_spec_id: 1,
            protocol_id: AirProtocol::EpcGlobalClass1Gen2,
            ..Default::default()
        }],
        ..Default::default()
    })];
    let r = c
        .request(
            AddRospec {
                ro_spec: far,
                ..Default::default()
            },
            T,
        )
        .await
        .expect("response");
    let st = status(&r);
    assert_eq!(st.status_code, StatusCode::M_ParameterError);
    let pe = st.parameter_error.expect("detail");
    assert_eq!(pe.parameter_type, 177);
    assert_eq!(pe.parameter_error.map(|p| p.parameter_type), Some(183));
    // START before ENABLE is refused; unknown IDs are field errors.
    assert_eq!(
        request_status(
            &mut c,
            StartRospec {
                ro_spec_id: 7,
                ..Default::default()
            }
        )
        .await,
        StatusCode::M_FieldError
    );
    assert_eq!(
        request_status(
            &mut c,
            EnableRospec {
                ro_spec_id: 42,
                ..Default::default()
            }
        )
        .await,
        StatusCode::M_FieldError
    );
    assert_eq!(
        request_status(
            &mut c,
            EnableRospec {
                ro_spec_id: 7,
                ..Default::default()
            }
        )
        .await,
        StatusCode::M_Success
    );
    // Immediate start: the spec becomes Active without START_ROSPEC.
    // (The reader runs before it answers a request, so the spec is Active by the next one;
    // ask until it is, within the deadline.)
    let deadline = tokio::time::Instant::now() + T;
    loop {
        let r = c.request(GetRospecs::default(), T).await.expect("list");
        let MessageBody::GetRospecsResponse(list) = r.body else {
            panic!("{r:?}")
        };
        assert_eq!(list.ro_specs.len(), 1);
        if list.ro_specs[0].current_state == RoSpecState::Active {
            break;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "the Immediate spec never became Active"
        );
    }
    assert_eq!(
        request_status(
            &mut c,
            StopRospec {
                ro_spec_id: 7,
                ..Default::default()
            }
        )
        .await,
        StatusCode::M_Success
    );
    assert_eq!(
        request_status(
            &mut c,
            StopRospec {
                ro_spec_id: 7,
                ..Default::default()
            }
        )
        .await,
        StatusCode::M_FieldError,
        "stopping an inactive spec"
    );
    assert_eq!(
        request_status(
            &mut c,
            StartRospec {
                ro_spec_id: 7,
                ..Default::default()
            }
        )
        .await,
        StatusCode::M_Success
    );
    assert_eq!(
        request_status(
            &mut c,
            DisableRospec {
                ro_spec_id: 7,
                ..Default::default()
            }
        )
        .await,
        StatusCode::M_Success
    );
    let r = c.request(GetRospecs::default(), T).await.expect("list");
    let MessageBody::GetRospecsResponse(list) = r.body else {
        panic!("{r:?}")
    };
    assert_eq!(
        list.ro_specs[0].current_state,
        RoSpecState::Disabled,
        "disabled"
    );
    assert_eq!(
        request_status(
            &mut c,
            DeleteRospec {
                ro_spec_id: 7,
                ..Default::default()
            }
        )
        .await,
        StatusCode::M_Success
    );
    let r = c.request(GetRospecs::default(), T).await.expect("list");
    let MessageBody::GetRospecsResponse(list) = r.body else {
        panic!("{r:?}")
    };
    assert!(list.ro_specs.is_empty());
    sim.shutdown().await;
}

#[tokio::test]
async fn keepalives_flow_and_a_silent_client_is_dropped() {
    let sim = start(&s1(), Speed::Factor(1.0)).await;
    let mut c = connect(&sim).await;
    let set = SetReaderConfig {
        keepalive_spec: Some(KeepaliveSpec {
            keepalive_trigger_type: KeepaliveTriggerType::Periodic,
            periodic_trigger_value: 100,
            ..Default::default()
        }),
        ..Default::default()
    };
    assert_eq!(request_status(&mut c, set).await, StatusCode::M_Success);
    let k = c
        .wait_for(|m| m.name() == "KEEPALIVE", T)
        .await
        .expect("keepalive");
    c.send(KeepaliveAck::default()).await.expect("ack");
    let _ = k;
    // Stop answering: after a few unanswered keepalives the reader says goodbye and closes.
    let bye = c
        .wait_for(|m| m.body.is_connection_close(), T)
        .await
        .expect("connection close event");
    assert_eq!(bye.name(), "READER_EVENT_NOTIFICATION");
    c.until_closed(T)
        .await
        .expect("the reader closes after its ConnectionCloseEvent");
    sim.shutdown().await;
}

#[tokio::test]
async fn close_connection_is_answered_then_closed() {
    let sim = start(&s1(), Speed::Factor(1.0)).await;
    let mut c = connect(&sim).await;
    let r = c
        .request(CloseConnection::default(), T)
        .await
        .expect("answer");
    assert_eq!(status(&r).status_code, StatusCode::M_Success);
    c.until_closed(T)
        .await
        .expect("the reader closes after its response");
    sim.shutdown().await;
}

#[tokio::test]
async fn supported_version_and_impinj_extensions() {
    let sim = start(&s1(), Speed::Factor(1.0)).await;
    let mut c = connect(&sim).await;
    c.set_version(2);
    let r = c
        .request(GetSupportedVersion::default(), T)
        .await
        .expect("answer");
    let MessageBody::GetSupportedVersionResponse(v) = &r.body else {
        panic!("{r:?}")
    };
    assert_eq!((v.current_version, v.supported_version), (1, 2));
    // Version-2 requests are refused until the session switches to LLRP 1.1.
    let r = c
        .request(GetReaderConfig::default(), T)
        .await
        .expect("answer");
    assert_eq!(status(&r).status_code, StatusCode::M_UnsupportedVersion);
    let set = SetProtocolVersion {
        protocol_version: 2,
        ..Default::default()
    };
    assert_eq!(request_status(&mut c, set).await, StatusCode::M_Success);
    let r = c
        .request(GetReaderConfig::default(), T)
        .await
        .expect("answer");
    assert_eq!(
        (r.version, status(&r).status_code),
        (2, StatusCode::M_Success)
    );
    let back = SetProtocolVersion {
        protocol_version: 1,
        ..Default::default()
    };
    assert_eq!(request_status(&mut c, back).await, StatusCode::M_Success);
    c.set_version(1);
    let r = c
        .request(ImpinjEnableExtensions::default(), T)
        .await
        .expect("answer");
    assert_eq!(r.name(), "IMPINJ_ENABLE_EXTENSIONS_RESPONSE");
    assert_eq!(status(&r).status_code, StatusCode::M_Success);
    // With the extensions on, ImpinjRequestedData adds Impinj's own parameters.
    let ask = |n: u32| {
        vec![Custom::ImpinjRequestedData(ImpinjRequestedData {
            requested_data: n,
            ..Default::default()
        })]
    };
    let caps = GetReaderCapabilities {
        custom: ask(1000),
        ..Default::default()
    };
    let r = c.request(caps, T).await.expect("answer");
    let MessageBody::GetReaderCapabilitiesResponse(caps) = r.body else {
        panic!("{r:?}")
    };
    let mut table = s1().readers[0].region.frequencies_khz();
    table.sort_unstable();
    assert!(caps
        .custom
        .iter()
        .any(|p| matches!(p, Custom::ImpinjDetailedVersion(_))));
    assert!(caps
        .custom
        .iter()
        .any(|p| matches!(p, Custom::ImpinjFrequencyCapabilities(f) if f.frequency_list == table)));
    let cfg = GetReaderConfig {
        custom: ask(2000),
        ..Default::default()
    };
    let r = c.request(cfg, T).await.expect("answer");
    let MessageBody::GetReaderConfigResponse(cfg) = r.body else {
        panic!("{r:?}")
    };
    assert!(cfg
        .custom
        .iter()
        .any(|p| matches!(p, Custom::ImpinjSubRegulatoryRegion(r) if r.regulatory_region == 7)));
    sim.shutdown().await;
}
