//! The vendor profiles end to end in the state machine: what each device advertises, the
//! power table it checks indices against, what the Zebra FX9600 answers to Impinj's messages
//! and parameters, and a scenario that gives each reader its own device.

use std::sync::Arc;

use llrp::enums::*;
use llrp::message::*;
use llrp::params::*;
use llrp::{Message, StatusCode};

use super::{Output, Reader, ReaderProfile};
use crate::physics::Model;
use crate::scenario::Scenario;

/// A scenario of one reader per entry of `devices` (`None`: no `device` field), each with
/// `antennas` antennas, one tag before them.
fn scenario(devices: &[Option<&str>], antennas: usize) -> Result<Scenario, String> {
    let antenna = r#"{ "mount": { "type": "fixed", "pose": { "position": [0, 0, 1] } } }"#;
    let antennas = vec![antenna; antennas].join(",");
    let readers: Vec<String> = devices
        .iter()
        .enumerate()
        .map(|(i, d)| {
            let device = d
                .map(|d| format!(r#""device": "{d}","#))
                .unwrap_or_default();
            let port = 5084 + i;
            format!(
                r#"{{ "name": "r{i}", "listen": "127.0.0.1:{port}", "region": "fcc", {device}
                      "antennas": [{antennas}] }}"#
            )
        })
        .collect();
    let json = format!(
        r#"{{ "name": "devices", "seed": 7,
              "world": {{ "min": [-2, -2, 0], "max": [3, 2, 2] }},
              "tags": [{{ "epc": "E20000000000000000000001", "position": [1.0, 0, 1.0] }}],
              "readers": [{}] }}"#,
        readers.join(",")
    );
    Scenario::from_json(&json).map_err(|e| e.to_string())
}

/// A connected reader for reader `index` of `s`.
fn reader(s: &Scenario, index: usize) -> Reader {
    let model = Arc::new(Model::new(s, index));
    let mut r = Reader::new(
        ReaderProfile::from_scenario(s, index, &model),
        model,
        1_700_000_000_000_000,
    );
    r.connect(0, 0);
    r
}

/// A connected reader presenting `device`, with four antennas.
fn device(name: &str) -> Reader {
    reader(&scenario(&[Some(name)], 4).expect("valid scenario"), 0)
}

/// The one message the reader answers `body` with.
fn ask(r: &mut Reader, body: impl Into<MessageBody>) -> MessageBody {
    let sent: Vec<MessageBody> = r
        .handle(
            Message {
                version: 1,
                id: 7,
                body: body.into(),
            },
            0,
            0,
        )
        .into_iter()
        .filter_map(|o| match o {
            Output::Send(m) => Some(m.body),
            Output::Close => None,
        })
        .collect();
    assert_eq!(sent.len(), 1, "one answer: {sent:?}");
    sent.into_iter().next().expect("checked above")
}

fn code(body: &MessageBody) -> StatusCode {
    body.status().expect("a status").status_code
}

fn capabilities(r: &mut Reader) -> GetReaderCapabilitiesResponse {
    match ask(r, GetReaderCapabilities::default()) {
        MessageBody::GetReaderCapabilitiesResponse(c) => *c,
        other => panic!("not capabilities: {other:?}"),
    }
}

/// SET_READER_CONFIG setting antenna 1's transmit power index.
fn set_power(index: u16) -> SetReaderConfig {
    SetReaderConfig {
        antenna_configuration: vec![AntennaConfiguration {
            antenna_id: 1,
            rf_transmitter: Some(RfTransmitter {
                hop_table_id: 1,
                transmit_power: index,
                ..Default::default()
            }),
            ..Default::default()
        }],
        ..Default::default()
    }
}

/// ADD_ROSPEC of an ROSpec with antenna 1 at transmit power index `index`.
fn add_with_power(id: u32, index: u16) -> AddRospec {
    let cfg = set_power(index).antenna_configuration;
    AddRospec {
        ro_spec: RoSpec::immediate(id, vec![1]).with_antenna_configuration(cfg),
        ..Default::default()
    }
}

#[test]
fn each_device_advertises_its_identity_and_tables() {
    // (device, manufacturer, model, firmware, lowest index and power, highest index and power,
    // RF mode IDs, GPIs, GPOs): docs/simulator.md "Vendor profiles".
    type Row = (
        &'static str,
        u32,
        u32,
        &'static str,
        (u16, i16),
        (u16, i16),
        Vec<u32>,
        (u16, u16),
    );
    let rows: [Row; 3] = [
        (
            "impinj-r420",
            25882,
            2001002,
            "5.12.0.240",
            (1, 1000),
            (91, 3250),
            vec![0, 1, 2, 3, 4, 5, 1000, 1002, 1003, 1004],
            (4, 4),
        ),
        (
            "impinj-r700",
            25882,
            2001052,
            "8.4.1",
            (1, 1000),
            (93, 3300),
            vec![0, 1, 2, 3, 4, 5, 1002, 1003, 1004],
            (2, 3),
        ),
        (
            "zebra-fx9600",
            161,
            96008,
            "3.32.37.0",
            (0, 1000),
            (200, 3000),
            vec![23, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11],
            (4, 4),
        ),
    ];
    for (name, manufacturer, model, firmware, low, high, modes, gpio) in rows {
        let c = capabilities(&mut device(name));
        let g = c.general_device_capabilities.expect("general");
        assert_eq!(
            (
                g.device_manufacturer_name,
                g.model_name,
                g.reader_firmware_version.as_str()
            ),
            (manufacturer, model, firmware),
            "{name}"
        );
        assert_eq!(
            (g.gpio_capabilities.num_gpis, g.gpio_capabilities.num_gpos),
            gpio,
            "{name}"
        );
        let band = c
            .regulatory_capabilities
            .and_then(|r| r.uhf_band_capabilities)
            .expect("band capabilities");
        let power = &band.transmit_power_level_table_entry;
        let ends =
            [power.first(), power.last()].map(|e| e.map(|e| (e.index, e.transmit_power_value)));
        assert_eq!(ends, [Some(low), Some(high)], "{name}");
        let ids: Vec<u32> = band.c1g2_uhf_rf_mode_table[0]
            .entries
            .iter()
            .map(|e| e.mode_identifier)
            .collect();
        assert_eq!(ids, modes, "{name}");
    }
}

#[test]
fn transmit_power_indices_outside_the_device_table_are_refused() {
    // (device, an index below its table or None, its highest index)
    for (name, below, top) in [
        ("impinj-r420", Some(0), 91),
        ("impinj-r700", Some(0), 93),
        ("zebra-fx9600", None, 200),
    ] {
        let mut r = device(name);
        let ok = StatusCode::M_Success;
        assert_eq!(code(&ask(&mut r, set_power(top))), ok, "{name}");
        assert_ne!(code(&ask(&mut r, set_power(top + 1))), ok, "{name}");
        assert_eq!(code(&ask(&mut r, add_with_power(1, top))), ok, "{name}");
        assert_ne!(code(&ask(&mut r, add_with_power(2, top + 1))), ok, "{name}");
        match below {
            Some(i) => assert_ne!(code(&ask(&mut r, set_power(i))), ok, "{name}"),
            // The FX9600's table starts at index 0 (10.00 dBm).
            None => assert_eq!(code(&ask(&mut r, set_power(0))), ok, "{name}"),
        }
    }
}

/// The requests carrying Impinj's extensions a client such as sllurp sends.
fn impinj_requests() -> Vec<(&'static str, MessageBody)> {
    let search_mode = AntennaConfiguration {
        antenna_id: 1,
        c1g2_inventory_command: vec![C1g2InventoryCommand {
            custom: vec![Custom::ImpinjInventorySearchMode(
                ImpinjInventorySearchMode {
                    inventory_search_mode: 2,
                    ..Default::default()
                },
            )],
            ..Default::default()
        }],
        ..Default::default()
    };
    let report = RoReportSpec::new(RoReportTriggerType::UponNTagsOrEndOfRoSpec, 1)
        .with_content(TagReportContentSelector::all())
        .with_impinj(true, true, false);
    let requested = vec![Custom::ImpinjRequestedData(ImpinjRequestedData {
        requested_data: 1000,
        ..Default::default()
    })];
    vec![
        (
            "SET_READER_CONFIG",
            SetReaderConfig {
                antenna_configuration: vec![search_mode],
                ..Default::default()
            }
            .into(),
        ),
        (
            "ADD_ROSPEC",
            AddRospec {
                ro_spec: RoSpec::immediate(5, vec![1]).with_report(report),
                ..Default::default()
            }
            .into(),
        ),
        (
            "GET_READER_CAPABILITIES",
            GetReaderCapabilities {
                custom: requested,
                ..Default::default()
            }
            .into(),
        ),
    ]
}

#[test]
fn the_zebra_refuses_impinj_messages_and_parameters() {
    let mut zebra = device("zebra-fx9600");
    let answer = ask(&mut zebra, ImpinjEnableExtensions::default());
    assert!(matches!(answer, MessageBody::ErrorMessage(_)), "{answer:?}");
    assert_eq!(code(&answer), StatusCode::M_UnsupportedMessage);
    let answer = ask(&mut zebra, ImpinjSaveSettings::default());
    assert_eq!(code(&answer), StatusCode::M_UnsupportedMessage);
    for (what, body) in impinj_requests() {
        let kind = body.kind();
        let answer = ask(&mut zebra, body);
        assert_eq!(kind.response(), Some(answer.kind()), "{what}: {answer:?}");
        let status = answer.status().expect("status");
        match &status.parameter_error {
            // Nested: the path ends at the Impinj Custom parameter.
            Some(outer) => {
                assert_eq!(status.status_code, StatusCode::M_ParameterError, "{what}");
                let mut e = outer;
                while let Some(inner) = e.parameter_error.as_deref() {
                    e = inner;
                }
                assert_eq!(
                    (e.parameter_type, e.error_code),
                    (1023, StatusCode::P_UnsupportedParameter),
                    "{what}"
                );
            }
            None => assert_eq!(
                status.status_code,
                StatusCode::M_UnsupportedParameter,
                "{what}"
            ),
        }
        if let MessageBody::GetReaderCapabilitiesResponse(c) = &answer {
            assert!(c.custom.is_empty(), "no Impinj capabilities: {c:?}");
        }
    }
    // The Impinj readers take the same requests.
    for name in ["impinj-r420", "impinj-r700"] {
        let mut impinj = device(name);
        let answer = ask(&mut impinj, ImpinjEnableExtensions::default());
        assert_eq!(code(&answer), StatusCode::M_Success, "{name}");
        for (what, body) in impinj_requests() {
            assert_eq!(
                code(&ask(&mut impinj, body)),
                StatusCode::M_Success,
                "{name} {what}"
            );
        }
    }
}

#[test]
fn a_scenario_gives_each_reader_its_own_device() {
    let s = scenario(&[Some("zebra-fx9600"), Some("impinj-r700"), None], 2).expect("valid");
    let identity = |i: usize| {
        let g = capabilities(&mut reader(&s, i))
            .general_device_capabilities
            .expect("general");
        (g.device_manufacturer_name, g.model_name)
    };
    assert_eq!(identity(0), (161, 96008));
    assert_eq!(identity(1), (25882, 2001052));
    // A reader that names no device is the default, the Speedway R420 it always was.
    assert_eq!(identity(2), (25882, 2001002));

    let e = scenario(&[Some("acme-9000")], 1).expect_err("unknown device");
    assert!(
        e.contains("readers[0].device") && e.contains("zebra-fx9600"),
        "{e}"
    );
    let e = scenario(&[Some("impinj-r700")], 5).expect_err("five antennas on four ports");
    assert!(e.contains("readers[0].antennas"), "{e}");
    assert!(scenario(&[Some("zebra-fx9600")], 8).is_ok());
}
