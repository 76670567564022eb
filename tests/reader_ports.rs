//! The device's antenna ports on the simulated reader, in process on a virtual clock: it
//! reports the ports its device has (MaxNumberOfAntennaSupported), not the scenario's antenna
//! count; the ports the scenario leaves empty exist but have nothing connected
//! (AntennaConnected false), take an AntennaConfiguration and a ROSpec, and read nothing;
//! AISpec antenna 0 inventories the connected antennas.

mod common;

use common::virtual_reader::VirtualReader;
use common::*;
use llrp::enums::ConfigRequest;
use llrp::message::*;
use llrp::params::*;
use llrp::StatusCode;
use llrp_gateway::scenario::Scenario;

/// One antenna (port 1) with two tags before it, presenting `device` (`None`: the default).
fn one_antenna(device: Option<&str>) -> Scenario {
    let mut s = line_scenario(&[1.0, 1.3]);
    s.readers[0].device = device.map(str::to_string);
    s
}

fn max_antennas(v: &mut VirtualReader) -> u16 {
    let MessageBody::GetReaderCapabilitiesResponse(r) =
        v.request(GetReaderCapabilities::default()).body
    else {
        panic!("GET_READER_CAPABILITIES_RESPONSE")
    };
    let g = r.general_device_capabilities.expect("general capabilities");
    // Every port has its receive sensitivity range and air protocol.
    assert_eq!(
        g.per_antenna_receive_sensitivity_range.len(),
        usize::from(g.max_number_of_antenna_supported)
    );
    assert_eq!(
        g.per_antenna_air_protocol.len(),
        usize::from(g.max_number_of_antenna_supported)
    );
    g.max_number_of_antenna_supported
}

/// (AntennaID, AntennaConnected) of every port, from GET_READER_CONFIG.
fn connected(v: &mut VirtualReader) -> Vec<(u16, bool)> {
    let get = GetReaderConfig {
        requested_data: ConfigRequest::AntennaProperties,
        ..Default::default()
    };
    let MessageBody::GetReaderConfigResponse(r) = v.request(get).body else {
        panic!("GET_READER_CONFIG_RESPONSE")
    };
    r.antenna_properties
        .iter()
        .map(|p| (p.antenna_id, p.antenna_connected))
        .collect()
}

/// The antennas the reads of a one-second ROSpec on `antennas` came from.
fn read_on(v: &mut VirtualReader, antennas: Vec<u16>) -> Vec<u16> {
    let report = full_report(RoReportTriggerType::UponNTagsOrEndOfRoSpec, 0);
    let spec = rospec(1, antennas, ro_duration(1000), ai_null(), report);
    let tags = v.run_rospec(spec, 3_000_000, |t| !t.is_empty());
    let mut ids: Vec<u16> = tags
        .iter()
        .filter_map(|t| t.antenna_id.map(|a| a.0))
        .collect();
    ids.sort_unstable();
    ids.dedup();
    ids
}

#[test]
fn the_reader_reports_its_devices_ports_not_the_scenarios_antennas() {
    for (device, ports) in [
        (None, 4),
        (Some("impinj-r420"), 4),
        (Some("impinj-r700"), 4),
        (Some("zebra-fx9600"), 8),
    ] {
        let mut v = VirtualReader::new(&one_antenna(device));
        assert_eq!(max_antennas(&mut v), ports, "{device:?}");
        let mut want = vec![(1, true)];
        want.extend((2..=ports).map(|a| (a, false)));
        assert_eq!(connected(&mut v), want, "{device:?}");
    }
}

#[test]
fn a_port_with_nothing_connected_is_configured_and_inventoried_but_reads_nothing() {
    let mut v = VirtualReader::new(&one_antenna(None));
    // An AntennaConfiguration for empty port 3 is accepted and echoed.
    let set = SetReaderConfig {
        antenna_configuration: vec![AntennaConfiguration {
            antenna_id: 3,
            rf_transmitter: Some(RfTransmitter {
                hop_table_id: 1,
                transmit_power: 20,
                ..Default::default()
            }),
            ..Default::default()
        }],
        ..Default::default()
    };
    assert_eq!(v.status(set), StatusCode::M_Success);
    let get = GetReaderConfig {
        requested_data: ConfigRequest::AntennaConfiguration,
        antenna_id: 3,
        ..Default::default()
    };
    let MessageBody::GetReaderConfigResponse(r) = v.request(get).body else {
        panic!("GET_READER_CONFIG_RESPONSE")
    };
    let tx = r.antenna_configuration[0].rf_transmitter.as_ref();
    assert_eq!(tx.map(|t| t.transmit_power), Some(20));
    // A ROSpec on it alone runs and reads nothing; with port 1, only port 1 reads.
    assert_eq!(read_on(&mut v, vec![3]), Vec::<u16>::new());
    assert_eq!(read_on(&mut v, vec![1, 3]), [1]);
    // Antenna 0 (all) reads on the connected antenna.
    assert_eq!(read_on(&mut v, vec![0]), [1]);
    // A port the device does not have is refused.
    let add = AddRospec {
        ro_spec: rospec(
            2,
            vec![5],
            ro_duration(100),
            ai_null(),
            full_report(RoReportTriggerType::UponNTagsOrEndOfRoSpec, 0),
        ),
        ..Default::default()
    };
    assert_eq!(v.status(add), StatusCode::M_ParameterError);
}
