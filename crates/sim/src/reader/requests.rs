//! The reader's answers to client requests, grouped by what they are about: the session
//! (versions, closing, keepalives, held events), the reader's capabilities and configuration,
//! ROSpecs and their reports, and AccessSpecs.

use llrp::message::*;
use llrp::params::*;
use llrp::{Message, Response, StatusCode};

use super::{caps, error_message, field_error, impinj_requested, rospec, Output, Reader};

/// Where an answer goes: the request's ID and version.
#[derive(Clone, Copy)]
struct Reply {
    id: u32,
    version: u8,
}

impl Reply {
    fn to(self, body: impl Into<MessageBody>) -> Output {
        Output::Send(Message {
            version: self.version,
            id: self.id,
            body: body.into(),
        })
    }
}

impl Reader {
    /// Handles one decoded request at simulated time `now_us` (wall clock `wall_ms`).
    pub fn handle(&mut self, msg: Message, now_us: u64, wall_ms: u64) -> Vec<Output> {
        let mut out = self.advance(now_us, wall_ms);
        let reply = Reply {
            id: msg.id,
            version: msg.version,
        };
        let negotiation = matches!(
            msg.body,
            MessageBody::GetSupportedVersion(_) | MessageBody::SetProtocolVersion(_)
        );
        if msg.version != self.version && !negotiation {
            out.push(reply.to(self.wrong_version(&msg.body)));
            return out;
        }
        if !self.profile.device.impinj_extensions {
            if let Some(answer) = super::vendor::refuse(&msg.body) {
                out.push(reply.to(answer));
                return out;
            }
        }
        self.specs.default_trigger = self.config.ro_report_spec.ro_report_trigger;
        let unhandled = self
            .session_request(msg.body, reply, &mut out)
            .and_then(|body| self.config_request(body, reply, wall_ms, &mut out))
            .and_then(|body| self.rospec_request(body, reply, &mut out))
            .and_then(|body| self.access_request(body, reply, &mut out));
        if let Some(other) = unhandled {
            out.push(reply.to(unsupported(&other, msg.version)));
        }
        out
    }

    /// The answer to a message in another version than the session's: LLRP 1.1 says answer
    /// with M_UnsupportedVersion (and a 1.0.1 reader does not know 1.1 at all).
    fn wrong_version(&self, body: &MessageBody) -> MessageBody {
        let status = LlrpStatus::new(
            StatusCode::M_UnsupportedVersion,
            format!("session uses LLRP version {}", self.version),
        );
        body.kind()
            .error_response(status.clone())
            .unwrap_or_else(|| MessageBody::ErrorMessage(error_message(status)))
    }

    /// Answers a request about the session (versions, closing, keepalives, held events,
    /// extensions); any other request is handed back.
    fn session_request(
        &mut self,
        body: MessageBody,
        reply: Reply,
        out: &mut Vec<Output>,
    ) -> Option<MessageBody> {
        let ok = LlrpStatus::success;
        use MessageBody as B;
        match body {
            B::GetSupportedVersion(_) => out.push(reply.to(GetSupportedVersionResponse {
                current_version: self.version,
                supported_version: 2,
                llrp_status: ok(),
                ..Default::default()
            })),
            B::SetProtocolVersion(m) => {
                let status = self.set_protocol_version(m.protocol_version);
                out.push(reply.to(SetProtocolVersionResponse::with_status(status)));
            }
            B::CloseConnection(_) => {
                out.push(reply.to(CloseConnectionResponse::with_status(ok())));
                out.push(Output::Close);
            }
            B::KeepaliveAck(_) => self.keepalive_unanswered = 0,
            B::EnableEventsAndReports(_) => {
                // No response message: release what was held.
                self.holding = false;
                out.extend(std::mem::take(&mut self.held).into_iter().map(Output::Send));
            }
            B::ImpinjEnableExtensions(_) => {
                self.impinj = true;
                out.push(reply.to(ImpinjEnableExtensionsResponse::with_status(ok())));
            }
            other => return Some(other),
        }
        None
    }

    /// Answers a request about the reader's capabilities or configuration; any other request
    /// is handed back.
    fn config_request(
        &mut self,
        body: MessageBody,
        reply: Reply,
        wall_ms: u64,
        out: &mut Vec<Output>,
    ) -> Option<MessageBody> {
        use MessageBody as B;
        match body {
            B::GetReaderCapabilities(m) => out.push(reply.to(self.capabilities(&m))),
            B::GetReaderConfig(m) => out.push(reply.to(self.configuration(&m))),
            B::SetReaderConfig(m) => {
                let status = self.set_configuration(*m, wall_ms);
                out.push(reply.to(SetReaderConfigResponse::with_status(status)));
            }
            B::ImpinjSaveSettings(_) => out.push(reply.to(
                ImpinjSaveSettingsResponse::with_status(LlrpStatus::success()),
            )),
            other => return Some(other),
        }
        None
    }

    /// Answers a request about ROSpecs or their reports; any other request is handed back.
    fn rospec_request(
        &mut self,
        body: MessageBody,
        reply: Reply,
        out: &mut Vec<Output>,
    ) -> Option<MessageBody> {
        use MessageBody as B;
        match body {
            B::AddRospec(m) => {
                let status = self.specs.add(&self.profile, m.ro_spec, self.version);
                out.push(reply.to(AddRospecResponse::with_status(status)));
            }
            B::DeleteRospec(m) => {
                self.change_rospecs::<DeleteRospecResponse>(reply, out, |s, now| {
                    s.delete(m.ro_spec_id, now)
                })
            }
            B::StartRospec(m) => {
                self.change_rospecs::<StartRospecResponse>(reply, out, |s, now| {
                    s.start(m.ro_spec_id, now)
                })
            }
            B::StopRospec(m) => self.change_rospecs::<StopRospecResponse>(reply, out, |s, now| {
                s.stop(m.ro_spec_id, now)
            }),
            B::EnableRospec(m) => {
                self.change_rospecs::<EnableRospecResponse>(reply, out, |s, now| {
                    s.enable(m.ro_spec_id, now)
                })
            }
            B::DisableRospec(m) => {
                self.change_rospecs::<DisableRospecResponse>(reply, out, |s, now| {
                    s.disable(m.ro_spec_id, now)
                })
            }
            B::GetRospecs(_) => out.push(reply.to(GetRospecsResponse {
                llrp_status: LlrpStatus::success(),
                ro_specs: self.specs.list(),
                ..Default::default()
            })),
            B::GetReport(_) => {
                // No response message: the buffered reports are the answer.
                let reports = self.specs.take_reports();
                self.send_reports(reports, out, true);
            }
            other => return Some(other),
        }
        None
    }

    /// Answers a request about AccessSpecs; any other request is handed back.
    fn access_request(
        &mut self,
        body: MessageBody,
        reply: Reply,
        out: &mut Vec<Output>,
    ) -> Option<MessageBody> {
        use MessageBody as B;
        match body {
            B::AddAccessspec(m) => {
                let status = self.access.add(&self.profile, m.access_spec);
                out.push(reply.to(AddAccessspecResponse::with_status(status)));
            }
            B::DeleteAccessspec(m) => {
                let status = self.access.delete(m.access_spec_id);
                out.push(reply.to(DeleteAccessspecResponse::with_status(status)));
            }
            B::EnableAccessspec(m) => {
                let status = self.access.set_enabled(m.access_spec_id, true);
                out.push(reply.to(EnableAccessspecResponse::with_status(status)));
            }
            B::DisableAccessspec(m) => {
                let status = self.access.set_enabled(m.access_spec_id, false);
                out.push(reply.to(DisableAccessspecResponse::with_status(status)));
            }
            B::GetAccessspecs(_) => out.push(reply.to(GetAccessspecsResponse {
                llrp_status: LlrpStatus::success(),
                access_specs: self.access.list(),
                ..Default::default()
            })),
            other => return Some(other),
        }
        None
    }

    /// SET_PROTOCOL_VERSION: the response goes out in the request's version, later messages
    /// in the new one.
    fn set_protocol_version(&mut self, version: u8) -> LlrpStatus {
        if matches!(version, 1 | 2) {
            self.version = version;
            LlrpStatus::success()
        } else {
            field_error(0, StatusCode::A_OutOfRange, "ProtocolVersion")
        }
    }

    /// GET_READER_CAPABILITIES_RESPONSE, with the Impinj capabilities asked for once the
    /// extensions are on.
    fn capabilities(&self, m: &GetReaderCapabilities) -> GetReaderCapabilitiesResponse {
        let mut body = caps::capabilities(&self.profile, m.requested_data).unwrap_or_else(|| {
            GetReaderCapabilitiesResponse::with_status(field_error(
                0,
                StatusCode::A_OutOfRange,
                "RequestedData",
            ))
        });
        if body.llrp_status.is_success() && self.impinj {
            for r in impinj_requested(&m.custom) {
                body.custom
                    .extend(caps::impinj_capabilities(&self.profile, r));
            }
        }
        body
    }

    /// GET_READER_CONFIG_RESPONSE, with the Impinj configuration asked for once the
    /// extensions are on.
    fn configuration(&self, m: &GetReaderConfig) -> GetReaderConfigResponse {
        let mut body = self.config.get(
            &self.profile,
            m,
            self.lines.levels(),
            &self.faults.connected_ports(self.profile.antennas),
        );
        if body.llrp_status.is_success() && self.impinj {
            for r in impinj_requested(&m.custom) {
                body.custom
                    .extend(caps::impinj_configuration(&self.profile, r));
            }
        }
        body
    }

    /// SET_READER_CONFIG: all of it or nothing; a new keepalive period starts now.
    fn set_configuration(&mut self, m: SetReaderConfig, wall_ms: u64) -> LlrpStatus {
        let gpos = self.config.gpos.clone();
        let status = self.config.set(&self.profile, m);
        if status.is_success() {
            self.keepalive_due_ms = self.config.keepalive_period_ms().map(|p| wall_ms + p);
            self.log_gpo_writes(&gpos);
            self.publish_gpio();
        }
        status
    }

    /// A request that changes ROSpec states: the reads a halted spec reports and the events
    /// go out before the response `R`, as on a reader.
    fn change_rospecs<R: Response>(
        &mut self,
        reply: Reply,
        out: &mut Vec<Output>,
        change: impl FnOnce(&mut rospec::Specs, u64) -> (LlrpStatus, Vec<rospec::Event>),
    ) {
        let (status, events) = change(&mut self.specs, self.now_us);
        let reports = self.specs.take_halt_reports();
        self.send_reports(reports, out, false);
        self.emit(events, out);
        out.push(reply.to(R::with_status(status)));
    }
}

/// The ERROR_MESSAGE for a request the reader does not take: reader-to-client messages,
/// CLIENT_REQUEST_OP answers without a request, other vendors' CUSTOM_MESSAGEs and unknown
/// types.
fn unsupported(body: &MessageBody, version: u8) -> MessageBody {
    let code = if version >= 2 && body.kind().is_from_reader() {
        StatusCode::M_UnexpectedMessage
    } else {
        StatusCode::M_UnsupportedMessage
    };
    let status = LlrpStatus::new(
        code,
        format!("message {} is not supported here", body.name()),
    );
    MessageBody::ErrorMessage(error_message(status))
}
