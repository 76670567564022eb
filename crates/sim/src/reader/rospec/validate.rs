//! What ADD_ROSPEC accepts: the checks of an ROSpec against the reader, and the LLRPStatus
//! (with its parameter path) of what fails.

use super::*;

/// Checks an ROSpec against what the reader supports.
pub(super) fn validate(p: &ReaderProfile, s: &RoSpec, version: u8) -> Result<(), LlrpStatus> {
    if s.ro_spec_id == 0 {
        return Err(param_field_error(177, 0, 0, StatusCode::A_Invalid));
    }
    if s.current_state != RoSpecState::Disabled {
        let mut e = param_field_error(177, 0, 2, StatusCode::A_Invalid);
        e.error_description = "a new ROSpec must be Disabled".into();
        return Err(e);
    }
    let b = &s.ro_boundary_spec;
    let st = &b.ro_spec_start_trigger;
    if st.ro_spec_start_trigger_type == RoSpecStartTriggerType::Periodic
        && st.periodic_trigger_value.is_none()
    {
        return Err(missing(178, 179, 180));
    }
    if st.ro_spec_start_trigger_type == RoSpecStartTriggerType::Gpi
        && st.gpi_trigger_value.is_none()
    {
        return Err(missing(178, 179, 181));
    }
    let sp = &b.ro_spec_stop_trigger;
    if sp.ro_spec_stop_trigger_type == RoSpecStopTriggerType::GpiWithTimeout
        && sp.gpi_trigger_value.is_none()
    {
        return Err(missing(178, 182, 181));
    }
    if st.ro_spec_start_trigger_type == RoSpecStartTriggerType::Gpi {
        gpi_port(p, st.gpi_trigger_value.as_ref(), &[177, 178, 179, 181])?;
    }
    if sp.ro_spec_stop_trigger_type == RoSpecStopTriggerType::GpiWithTimeout {
        gpi_port(p, sp.gpi_trigger_value.as_ref(), &[177, 178, 182, 181])?;
    }
    unknown_in(&[177], &s.extra)?;
    for spec in &s.specs {
        match spec {
            SpecParameter::AiSpec(ai) => validate_ai(p, ai)?,
            SpecParameter::RfSurveySpec(_) => {
                let mut e =
                    LlrpStatus::new(StatusCode::M_ParameterError, "RF survey is not supported");
                let mut pe = ParameterError::new(177, StatusCode::P_ParameterError);
                pe.parameter_error = Some(Box::new(ParameterError::new(
                    187,
                    StatusCode::P_UnsupportedParameter,
                )));
                e.parameter_error = Some(pe);
                return Err(e);
            }
            SpecParameter::Custom(_) => {
                let mut e = LlrpStatus::new(
                    StatusCode::M_ParameterError,
                    "vendor specs are not supported",
                );
                let mut pe = ParameterError::new(177, StatusCode::P_ParameterError);
                pe.parameter_error = Some(Box::new(ParameterError::new(
                    1023,
                    StatusCode::P_UnsupportedParameter,
                )));
                e.parameter_error = Some(pe);
                return Err(e);
            }
        }
    }
    if let Some(r) = &s.ro_report_spec {
        // LLRP 1.1's triggers 3..=6 are not implemented in either version.
        let _ = version;
        if !matches!(
            r.ro_report_trigger,
            RoReportTriggerType::None
                | RoReportTriggerType::UponNTagsOrEndOfAiSpec
                | RoReportTriggerType::UponNTagsOrEndOfRoSpec
        ) {
            let mut e = param_field_error(177, 237, 0, StatusCode::A_OutOfRange);
            e.error_description = format!(
                "ROReportTrigger {} is not supported",
                r.ro_report_trigger.value()
            );
            return Err(e);
        }
    }
    Ok(())
}

/// The first parameter in `extra` that the codec did not know (LLRP 1.1's LoopSpec, say; a
/// vendor's Custom aside), kept as it came: the reader cannot do what it asks, so it refuses
/// it as unsupported, with the path `path` of parameter types to it, rather than ignore it.
fn unknown_in(path: &[u16], extra: &[llrp::raw::Extra]) -> Result<(), LlrpStatus> {
    let unknown = (extra.iter())
        .filter_map(|x| x.param.header())
        .map(|h| h.ty())
        .find(|&ty| ty != 1023);
    let Some(ty) = unknown else {
        return Ok(());
    };
    let mut inner = ParameterError::new(ty, StatusCode::P_UnsupportedParameter);
    for &outer in path.iter().rev() {
        let mut pe = ParameterError::new(outer, StatusCode::P_ParameterError);
        pe.parameter_error = Some(Box::new(inner));
        inner = pe;
    }
    let mut e = LlrpStatus::new(
        StatusCode::M_ParameterError,
        format!("parameter type {ty} is not supported"),
    );
    e.parameter_error = Some(inner);
    Err(e)
}

fn validate_ai(p: &ReaderProfile, ai: &AiSpec) -> Result<(), LlrpStatus> {
    unknown_in(&[177, 183], &ai.extra)?;
    for ips in &ai.inventory_parameter_specs {
        unknown_in(&[177, 183, 186], &ips.extra)?;
        for ac in &ips.antenna_configuration {
            unknown_in(&[177, 183, 186, 222], &ac.extra)?;
        }
    }
    let bad_antenna = ai.antenna_ids.is_empty()
        || ai.antenna_ids.iter().any(|&a| a > p.ports)
        || (ai.antenna_ids.contains(&0) && ai.antenna_ids.len() > 1);
    if bad_antenna {
        let mut e = nested_field_error(&[177, 183], 0, StatusCode::A_OutOfRange);
        e.error_description = format!(
            "AntennaIDs {:?}: the reader has antenna ports 1..={} (0 = all)",
            ai.antenna_ids, p.ports
        );
        return Err(e);
    }
    let t = &ai.ai_spec_stop_trigger;
    if t.ai_spec_stop_trigger_type == AiSpecStopTriggerType::TagObservation {
        match &t.tag_observation_trigger {
            None => return Err(missing(183, 184, 185)),
            Some(o) if o.trigger_type.value() > 2 => {
                let mut e = nested_field_error(&[177, 183, 184, 185], 0, StatusCode::A_OutOfRange);
                e.error_description = format!(
                    "TagObservationTrigger type {} is not supported",
                    o.trigger_type.value()
                );
                return Err(e);
            }
            _ => {}
        }
    }
    if t.ai_spec_stop_trigger_type == AiSpecStopTriggerType::GpiWithTimeout {
        if t.gpi_trigger_value.is_none() {
            return Err(missing(183, 184, 181));
        }
        gpi_port(p, t.gpi_trigger_value.as_ref(), &[177, 183, 184, 181])?;
    }
    if ai.inventory_parameter_specs.len() > 1 {
        return Err(LlrpStatus::new(
            StatusCode::M_OverflowParameter,
            "one InventoryParameterSpec per AISpec",
        ));
    }
    for ips in &ai.inventory_parameter_specs {
        if ips.protocol_id != AirProtocol::EpcGlobalClass1Gen2 {
            let mut e = nested_field_error(&[177, 183, 186], 1, StatusCode::A_OutOfRange);
            e.error_description = "only EPCGlobal Class 1 Gen 2 (ProtocolID 1)".into();
            return Err(e);
        }
        for c in &ips.antenna_configuration {
            validate_antenna_config(p, c).map_err(|mut e| {
                // Re-root the antenna error under ROSpec/AISpec/InventoryParameterSpec.
                if let Some(inner) = e.parameter_error.take() {
                    let mut ips_e = ParameterError::new(186, StatusCode::P_ParameterError);
                    ips_e.parameter_error = Some(Box::new(inner));
                    let mut ai_e = ParameterError::new(183, StatusCode::P_ParameterError);
                    ai_e.parameter_error = Some(Box::new(ips_e));
                    let mut ro_e = ParameterError::new(177, StatusCode::P_ParameterError);
                    ro_e.parameter_error = Some(Box::new(ai_e));
                    e.parameter_error = Some(ro_e);
                }
                e
            })?;
        }
    }
    Ok(())
}

/// A GPITriggerValue (at `path`) must name a GPI port the reader has: GPIPortNum 0 is
/// invalid, and a reader with no GPIs refuses any GPI trigger (LLRP 1.0.1 §10.2.1.1.1.2).
fn gpi_port(
    p: &ReaderProfile,
    g: Option<&GpiTriggerValue>,
    path: &[u16],
) -> Result<(), LlrpStatus> {
    let Some(g) = g else {
        return Ok(());
    };
    if g.gpi_port_num == 0 || g.gpi_port_num > p.gpis {
        let mut e = nested_field_error(path, 0, StatusCode::A_OutOfRange);
        e.error_description = format!(
            "GPITriggerValue: GPIPortNum {} (the reader has GPI ports 1..={})",
            g.gpi_port_num, p.gpis
        );
        return Err(e);
    }
    Ok(())
}

/// M_ParameterError with the chain `path` (outermost first) and a field error at the end.
fn nested_field_error(path: &[u16], field: u16, code: StatusCode) -> LlrpStatus {
    let mut inner: Option<ParameterError> = None;
    for (k, ty) in path.iter().enumerate().rev() {
        let last = k == path.len() - 1;
        let mut pe = ParameterError::new(
            *ty,
            if last {
                StatusCode::P_FieldError
            } else {
                StatusCode::P_ParameterError
            },
        );
        if last {
            pe.field_error = Some(FieldError {
                field_num: field,
                error_code: code,
                ..Default::default()
            });
        }
        pe.parameter_error = inner.take().map(Box::new);
        inner = Some(pe);
    }
    let mut s = LlrpStatus::new(StatusCode::M_ParameterError, "invalid parameter value");
    s.parameter_error = inner;
    s
}

/// M_ParameterError: parameter `a`/`b` lacks required sub-parameter `missing`.
fn missing(a: u16, b: u16, missing: u16) -> LlrpStatus {
    let mut inner = ParameterError::new(b, StatusCode::P_ParameterError);
    inner.parameter_error = Some(Box::new(ParameterError::new(
        missing,
        StatusCode::P_MissingParameter,
    )));
    let mut outer = ParameterError::new(a, StatusCode::P_ParameterError);
    outer.parameter_error = Some(Box::new(inner));
    let mut s = LlrpStatus::new(
        StatusCode::M_ParameterError,
        format!("parameter type {missing} missing"),
    );
    s.parameter_error = Some(outer);
    s
}
