//! Reader configuration: what GET_READER_CONFIG reports and SET_READER_CONFIG changes
//! (antenna settings, default report spec, event notifications, keepalive, event holding).

use llrp::enums::*;
use llrp::message::{GetReaderConfig, GetReaderConfigResponse, SetReaderConfig};
use llrp::params::*;
use llrp::StatusCode;

use super::device::Device;
use super::{field_error, ReaderProfile};

/// The reader event types a client can turn on and off (hopping … antenna, and LLRP 1.1's
/// SpecLoop).
pub const EVENT_TYPES: &[NotificationEventType] = NotificationEventType::ALL;

/// The reader's current configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct ReaderConfig {
    /// The device whose tables the configuration indexes (power, RF modes).
    pub device: &'static Device,
    /// Per antenna (index = antenna ID − 1): its configuration as last set.
    pub antennas: Vec<AntennaConfiguration>,
    /// Default ROReportSpec, used by ROSpecs that carry none.
    pub ro_report_spec: RoReportSpec,
    /// When access results are reported.
    pub access_report_spec: AccessReportSpec,
    /// Notification state per event type.
    pub events: Vec<bool>,
    /// Keepalive settings.
    pub keepalive: KeepaliveSpec,
    /// Hold events and reports after a reconnect until ENABLE_EVENTS_AND_REPORTS.
    pub events_and_reports: EventsAndReports,
    /// Opaque configuration-state value the client may compare.
    pub state_value: u32,
    /// Per GPI port (index = port − 1): whether it is enabled (GPIPortCurrentState.Config).
    pub gpi_enabled: Vec<bool>,
    /// Per GPO port (index = port − 1): the level last written (GPOWriteData.GPOData).
    pub gpos: Vec<bool>,
}

impl ReaderConfig {
    /// Factory defaults (what ResetToFactoryDefault restores).
    pub fn factory(p: &ReaderProfile) -> Self {
        let antennas = (1..=p.ports)
            .map(|a| AntennaConfiguration {
                antenna_id: a,
                rf_receiver: Some(RfReceiver {
                    receiver_sensitivity: 1,
                    ..Default::default()
                }),
                rf_transmitter: Some(RfTransmitter {
                    hop_table_id: 1,
                    channel_index: if p.hopping { 0 } else { 1 },
                    transmit_power: p
                        .default_power_index
                        .get(usize::from(a - 1))
                        .copied()
                        .unwrap_or(p.device.power.last_index),
                    ..Default::default()
                }),
                c1g2_inventory_command: vec![C1g2InventoryCommand {
                    tag_inventory_state_aware: false,
                    c1g2_rf_control: Some(C1g2RfControl {
                        // ModeIndex is u16 on the wire; every device's default fits.
                        mode_index: p.device.default_mode as u16,
                        tari: 0,
                        ..Default::default()
                    }),
                    c1g2_singulation_control: Some(C1g2SingulationControl {
                        session: 2,
                        tag_population: 32,
                        tag_transit_time: 0,
                        ..Default::default()
                    }),
                    ..Default::default()
                }],
                ..Default::default()
            })
            .collect();
        ReaderConfig {
            device: p.device,
            antennas,
            ro_report_spec: RoReportSpec {
                ro_report_trigger: RoReportTriggerType::UponNTagsOrEndOfRoSpec,
                n: 1,
                tag_report_content_selector: TagReportContentSelector {
                    enable_ro_spec_id: true,
                    enable_antenna_id: true,
                    enable_peak_rssi: true,
                    enable_first_seen_timestamp: true,
                    enable_last_seen_timestamp: true,
                    enable_tag_seen_count: true,
                    ..Default::default()
                },
                ..Default::default()
            },
            access_report_spec: AccessReportSpec {
                access_report_trigger: AccessReportTriggerType::WheneverRoReportIsGenerated,
                ..Default::default()
            },
            events: vec![false; EVENT_TYPES.len()],
            keepalive: KeepaliveSpec {
                keepalive_trigger_type: KeepaliveTriggerType::Null,
                periodic_trigger_value: 0,
                ..Default::default()
            },
            events_and_reports: EventsAndReports::default(),
            state_value: 0,
            // Enabled: the LLRP leaves the factory state to the reader (a client enables the
            // ports its triggers use, LLRP 1.0.1 §12.2.6.3); outputs low.
            gpi_enabled: vec![true; usize::from(p.gpis)],
            gpos: vec![false; usize::from(p.gpos)],
        }
    }

    /// Whether GPI `port` is enabled (false for a port the reader lacks).
    pub fn gpi_enabled(&self, port: u16) -> bool {
        (self.gpi_enabled.get(usize::from(port).wrapping_sub(1))).is_some_and(|&e| e)
    }

    /// Keepalive period in ms, when periodic keepalives are on.
    pub fn keepalive_period_ms(&self) -> Option<u64> {
        (self.keepalive.keepalive_trigger_type == KeepaliveTriggerType::Periodic
            && self.keepalive.periodic_trigger_value > 0)
            .then_some(u64::from(self.keepalive.periodic_trigger_value))
    }

    /// Whether notifications of event type `ty` are on.
    pub fn event_enabled(&self, ty: NotificationEventType) -> bool {
        self.events
            .get(usize::from(ty.value()))
            .copied()
            .unwrap_or(false)
    }

    /// Configured transmit power of `antenna` in dBm.
    pub fn tx_power_dbm(&self, antenna: u16) -> Option<f64> {
        let a = self.antennas.get(usize::from(antenna).checked_sub(1)?)?;
        self.device
            .power
            .dbm(a.rf_transmitter.as_ref()?.transmit_power)
    }

    /// GET_READER_CONFIG_RESPONSE for a request; `levels` are the GPI lines' (index = port
    /// − 1, true: high), `connected` the antenna ports' (index = port − 1).
    pub fn get(
        &self,
        p: &ReaderProfile,
        m: &GetReaderConfig,
        levels: &[bool],
        connected: &[bool],
    ) -> GetReaderConfigResponse {
        let mut r = GetReaderConfigResponse {
            llrp_status: LlrpStatus::success(),
            ..Default::default()
        };
        let want =
            |k: ConfigRequest| m.requested_data == ConfigRequest::All || m.requested_data == k;
        if let Some(status) = get_error(p, m) {
            r.llrp_status = status;
            return r;
        }
        let antenna_ok = |id: u16| m.antenna_id == 0 || m.antenna_id == id;
        if want(ConfigRequest::Identification) {
            r.identification = Some(Identification {
                id_type: IdentificationType::MacAddress,
                reader_id: p.reader_id.clone(),
                ..Default::default()
            });
        }
        if want(ConfigRequest::AntennaProperties) {
            r.antenna_properties = antenna_properties(p, antenna_ok, connected);
        }
        if want(ConfigRequest::AntennaConfiguration) {
            r.antenna_configuration = self
                .antennas
                .iter()
                .filter(|a| antenna_ok(a.antenna_id))
                .cloned()
                .collect();
        }
        if want(ConfigRequest::RoReportSpec) {
            r.ro_report_spec = Some(self.ro_report_spec.clone());
        }
        if want(ConfigRequest::ReaderEventNotificationSpec) {
            r.reader_event_notification_spec = Some(self.event_notification_spec());
        }
        if want(ConfigRequest::AccessReportSpec) {
            r.access_report_spec = Some(self.access_report_spec.clone());
        }
        if want(ConfigRequest::LlrpConfigurationStateValue) {
            r.llrp_configuration_state_value = Some(LlrpConfigurationStateValue {
                llrp_configuration_state_value: self.state_value,
                ..Default::default()
            });
        }
        if want(ConfigRequest::KeepaliveSpec) {
            r.keepalive_spec = Some(self.keepalive.clone());
        }
        if want(ConfigRequest::GpiPortCurrentState) {
            r.gpi_port_current_state = self.gpi_port_states(m.gpi_port_num, levels);
        }
        if want(ConfigRequest::GpoWriteData) {
            r.gpo_write_data = self.gpo_write_data(m.gpo_port_num);
        }
        if want(ConfigRequest::EventsAndReports) {
            r.events_and_reports = Some(self.events_and_reports.clone());
        }
        r
    }

    /// The state of GPI port `port` (0: of every port): its Config, and its level if it is
    /// enabled (2, unknown, if not: a disabled input is not watched).
    fn gpi_port_states(&self, port: u16, levels: &[bool]) -> Vec<GpiPortCurrentState> {
        (1..=self.gpi_enabled.len() as u16)
            .filter(|&g| port == 0 || port == g)
            .map(|g| {
                let enabled = self.gpi_enabled(g);
                let high = levels.get(usize::from(g - 1)).is_some_and(|&h| h);
                GpiPortCurrentState {
                    gpi_port_num: g,
                    config: enabled,
                    state: match (enabled, high) {
                        (false, _) => 2,
                        (true, false) => 0,
                        (true, true) => 1,
                    },
                    ..Default::default()
                }
            })
            .collect()
    }

    /// The data last written to GPO port `port` (0: to every port).
    fn gpo_write_data(&self, port: u16) -> Vec<GpoWriteData> {
        (self.gpos.iter().enumerate())
            .map(|(i, &level)| (i as u16 + 1, level))
            .filter(|&(g, _)| port == 0 || port == g)
            .map(|(g, level)| GpoWriteData {
                gpo_port_number: g,
                gpo_data: level,
                ..Default::default()
            })
            .collect()
    }

    /// The notification state of the event types GET_READER_CONFIG reports.
    fn event_notification_spec(&self) -> ReaderEventNotificationSpec {
        ReaderEventNotificationSpec {
            event_notification_state: EVENT_TYPES[..9]
                .iter()
                .map(|&t| EventNotificationState {
                    event_type: t,
                    notification_state: self.event_enabled(t),
                    ..Default::default()
                })
                .collect(),
            ..Default::default()
        }
    }

    /// Applies SET_READER_CONFIG; nothing changes unless the whole request is valid.
    pub fn set(&mut self, p: &ReaderProfile, m: SetReaderConfig) -> LlrpStatus {
        let mut next = if m.reset_to_factory_default {
            ReaderConfig::factory(p)
        } else {
            self.clone()
        };
        if let Err(status) = next.apply(p, &m) {
            return status;
        }
        next.state_value = next.state_value.wrapping_add(1);
        *self = next;
        LlrpStatus::success()
    }

    /// Applies the parts of SET_READER_CONFIG in turn; the error of the first invalid one.
    fn apply(&mut self, p: &ReaderProfile, m: &SetReaderConfig) -> Result<(), LlrpStatus> {
        if let Some(spec) = &m.reader_event_notification_spec {
            self.set_events(spec)?;
        }
        for c in &m.antenna_configuration {
            self.set_antenna(p, c)?;
        }
        if !m.antenna_properties.is_empty() {
            // CanSetAntennaProperties is 0, as on Impinj readers.
            let mut s = LlrpStatus::new(
                StatusCode::M_ParameterError,
                "antenna properties cannot be set",
            );
            s.parameter_error = Some(ParameterError::new(221, StatusCode::P_UnsupportedParameter));
            return Err(s);
        }
        if let Some(r) = &m.ro_report_spec {
            if r.ro_report_trigger.value() > 2 {
                return Err(param_field_error(237, 0, 0, StatusCode::A_OutOfRange));
            }
            self.ro_report_spec = r.clone();
        }
        if let Some(a) = &m.access_report_spec {
            if !a.access_report_trigger.is_known() {
                return Err(param_field_error(239, 0, 0, StatusCode::A_OutOfRange));
            }
            self.access_report_spec = a.clone();
        }
        if let Some(k) = &m.keepalive_spec {
            if !k.keepalive_trigger_type.is_known() {
                return Err(param_field_error(220, 0, 0, StatusCode::A_OutOfRange));
            }
            self.keepalive = k.clone();
        }
        check_gpio(p, m)?;
        for g in &m.gpi_port_current_state {
            // The State field is ignored on a set (LLRP 1.0.1 §12.2.6.3).
            self.gpi_enabled[usize::from(g.gpi_port_num - 1)] = g.config;
        }
        for g in &m.gpo_write_data {
            self.gpos[usize::from(g.gpo_port_number - 1)] = g.gpo_data;
        }
        if let Some(e) = &m.events_and_reports {
            self.events_and_reports = e.clone();
        }
        Ok(())
    }

    /// Turns the event notifications of `spec` on or off.
    fn set_events(&mut self, spec: &ReaderEventNotificationSpec) -> Result<(), LlrpStatus> {
        for s in &spec.event_notification_state {
            if !s.event_type.is_known() {
                return Err(param_field_error(244, 245, 0, StatusCode::A_OutOfRange));
            }
            self.events[usize::from(s.event_type.value())] = s.notification_state;
        }
        Ok(())
    }

    /// Sets the antennas `c` is for (0: all) to the parts of `c` it carries.
    fn set_antenna(
        &mut self,
        p: &ReaderProfile,
        c: &AntennaConfiguration,
    ) -> Result<(), LlrpStatus> {
        validate_antenna_config(p, c)?;
        let targets: Vec<u16> = if c.antenna_id == 0 {
            (1..=p.ports).collect()
        } else {
            vec![c.antenna_id]
        };
        for a in targets {
            let slot = &mut self.antennas[usize::from(a - 1)];
            if let Some(rx) = &c.rf_receiver {
                slot.rf_receiver = Some(rx.clone());
            }
            if let Some(tx) = &c.rf_transmitter {
                slot.rf_transmitter = Some(tx.clone());
            }
            if !c.c1g2_inventory_command.is_empty() {
                slot.c1g2_inventory_command = c.c1g2_inventory_command.clone();
            }
        }
        Ok(())
    }
}

/// What makes a GET_READER_CONFIG invalid: an unknown RequestedData, an antenna the reader
/// lacks, or a GPI/GPO port it lacks when ports are asked for.
fn get_error(p: &ReaderProfile, m: &GetReaderConfig) -> Option<LlrpStatus> {
    let want = |k: ConfigRequest| m.requested_data == ConfigRequest::All || m.requested_data == k;
    if !m.requested_data.is_known() {
        return Some(field_error(1, StatusCode::A_OutOfRange, "RequestedData"));
    }
    if m.antenna_id > p.ports {
        return Some(field_error(0, StatusCode::A_OutOfRange, "AntennaID"));
    }
    if m.gpi_port_num > p.gpis && want(ConfigRequest::GpiPortCurrentState) {
        return Some(field_error(2, StatusCode::A_OutOfRange, "GPIPortNum"));
    }
    if m.gpo_port_num > p.gpos && want(ConfigRequest::GpoWriteData) {
        return Some(field_error(3, StatusCode::A_OutOfRange, "GPOPortNum"));
    }
    None
}

/// The AntennaProperties of the reader's ports that `antenna_ok` selects; `connected` per
/// port (index = port − 1; a port it does not list is connected), and a port past the
/// scenario's antennas has nothing connected.
fn antenna_properties(
    p: &ReaderProfile,
    antenna_ok: impl Fn(u16) -> bool,
    connected: &[bool],
) -> Vec<AntennaProperties> {
    (1..=p.ports)
        .filter(|&a| antenna_ok(a))
        .map(|a| AntennaProperties {
            antenna_connected: a <= p.antennas
                && connected.get(usize::from(a - 1)).copied().unwrap_or(true),
            antenna_id: a,
            antenna_gain: p
                .antenna_gain_dbi
                .get(usize::from(a - 1))
                .map(|g| (g * 100.0).round() as i16)
                .unwrap_or(0),
            ..Default::default()
        })
        .collect()
}

/// Checks the GPO data and GPI states of a SET_READER_CONFIG name ports the reader has
/// (M_ParameterError, the parameter's field 0 A_OutOfRange; a reader without GPOs or GPIs
/// refuses any, LLRP 1.0.1 §12.2.6.3, §12.2.3).
fn check_gpio(p: &ReaderProfile, m: &SetReaderConfig) -> Result<(), LlrpStatus> {
    for g in &m.gpo_write_data {
        if g.gpo_port_number == 0 || g.gpo_port_number > p.gpos {
            let mut e = param_field_error(219, 0, 0, StatusCode::A_OutOfRange);
            e.error_description = format!(
                "GPOPortNumber {}: the reader has GPO ports 1..={}",
                g.gpo_port_number, p.gpos
            );
            return Err(e);
        }
    }
    for g in &m.gpi_port_current_state {
        if g.gpi_port_num == 0 || g.gpi_port_num > p.gpis {
            let mut e = param_field_error(225, 0, 0, StatusCode::A_OutOfRange);
            e.error_description = format!(
                "GPIPortNum {}: the reader has GPI ports 1..={}",
                g.gpi_port_num, p.gpis
            );
            return Err(e);
        }
    }
    Ok(())
}

/// Checks an AntennaConfiguration against the reader (antenna, power index, hop table).
pub fn validate_antenna_config(
    p: &ReaderProfile,
    c: &AntennaConfiguration,
) -> Result<(), LlrpStatus> {
    if c.antenna_id > p.ports {
        return Err(param_field_error(222, 0, 0, StatusCode::A_OutOfRange));
    }
    if let Some(tx) = &c.rf_transmitter {
        if p.device.power.dbm(tx.transmit_power).is_none() {
            return Err(param_field_error(222, 224, 2, StatusCode::A_OutOfRange));
        }
        if p.hopping && tx.hop_table_id != 1 {
            return Err(param_field_error(222, 224, 0, StatusCode::A_OutOfRange));
        }
        if !p.hopping && usize::from(tx.channel_index) > p.frequencies_khz.len() {
            return Err(param_field_error(222, 224, 1, StatusCode::A_OutOfRange));
        }
    }
    if let Some(rx) = &c.rf_receiver {
        if rx.receiver_sensitivity == 0 || rx.receiver_sensitivity > p.device.sensitivity_levels {
            return Err(param_field_error(222, 223, 0, StatusCode::A_OutOfRange));
        }
    }
    for cmd in &c.c1g2_inventory_command {
        super::select::validate(cmd)?;
        for custom in &cmd.custom {
            if let Custom::ImpinjFixedFrequencyList(l) = custom {
                let channels = p.frequencies_khz.len();
                let bad = l.fixed_frequency_mode > 2
                    || l.channel_list
                        .iter()
                        .any(|&ch| ch == 0 || usize::from(ch) > channels);
                if bad {
                    let mut e = param_field_error(330, 1023, 1, StatusCode::A_OutOfRange);
                    e.error_description = format!(
                        "ImpinjFixedFrequencyList: mode {} with channels {:?} (the table has 1..={channels})",
                        l.fixed_frequency_mode, l.channel_list
                    );
                    return Err(e);
                }
            }
        }
        if let Some(rf) = &cmd.c1g2_rf_control {
            let Some(mode) = p.device.mode(u32::from(rf.mode_index)) else {
                return Err(param_field_error(330, 335, 0, StatusCode::A_OutOfRange));
            };
            // Tari 0 asks for the mode's own; another must lie in the mode's Tari range.
            let (min, max) = mode.tari_ns;
            let tari = u32::from(rf.tari);
            if tari != 0 && !(min..=max).contains(&tari) {
                let mut e = param_field_error(330, 335, 1, StatusCode::A_OutOfRange);
                e.error_description = format!(
                    "C1G2RFControl: Tari {tari} ns outside mode {}'s {min}..={max} ns",
                    rf.mode_index
                );
                return Err(e);
            }
        }
    }
    Ok(())
}

/// M_ParameterError for field `field` of parameter `inner` (0: of `outer` itself) inside
/// parameter `outer`.
pub(crate) fn param_field_error(
    outer: u16,
    inner: u16,
    field: u16,
    code: StatusCode,
) -> LlrpStatus {
    let fe = FieldError {
        field_num: field,
        error_code: code,
        ..Default::default()
    };
    let mut pe = ParameterError::new(
        outer,
        if inner == 0 {
            StatusCode::P_FieldError
        } else {
            StatusCode::P_ParameterError
        },
    );
    if inner == 0 {
        pe.field_error = Some(fe);
    } else {
        let mut ie = ParameterError::new(inner, StatusCode::P_FieldError);
        ie.field_error = Some(fe);
        pe.parameter_error = Some(Box::new(ie));
    }
    let mut s = LlrpStatus::new(StatusCode::M_ParameterError, "invalid parameter value");
    s.parameter_error = Some(pe);
    s
}
