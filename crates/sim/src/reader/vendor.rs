//! What a device without the Impinj extensions (a Zebra FX9600) answers to Impinj's: an
//! IMPINJ_* custom message is a message it does not support (M_UnsupportedMessage), and an
//! Impinj Custom parameter anywhere in a request is a parameter it does not support
//! (M_UnsupportedParameter when the message holds it, else M_ParameterError with the path to
//! it, ending in P_UnsupportedParameter). docs/simulator.md "Vendor profiles".

use llrp::message::MessageBody;
use llrp::params::*;
use llrp::StatusCode;

use super::device::IMPINJ_PEN;

/// Custom parameter type.
const CUSTOM: u16 = 1023;

/// Whether a Custom parameter is Impinj's (a typed one, or a raw one of vendor 25882).
fn is_impinj(c: &Custom) -> bool {
    match c {
        Custom::Other(raw) => raw
            .0
            .vendor_subtype()
            .is_some_and(|(vendor, _)| vendor == IMPINJ_PEN),
        _ => true,
    }
}

fn any_impinj(custom: &[Custom]) -> bool {
    custom.iter().any(is_impinj)
}

/// The path (parameter types, outermost first, the Custom last) to the first Impinj Custom
/// parameter under an AntennaConfiguration.
fn in_antenna(c: &AntennaConfiguration) -> Option<Vec<u16>> {
    if any_impinj(&c.custom) {
        return Some(vec![222, CUSTOM]);
    }
    c.c1g2_inventory_command
        .iter()
        .any(|cmd| any_impinj(&cmd.custom))
        .then(|| vec![222, 330, CUSTOM])
}

/// The same under an ROReportSpec.
fn in_report_spec(r: &RoReportSpec) -> Option<Vec<u16>> {
    if any_impinj(&r.custom) {
        return Some(vec![237, CUSTOM]);
    }
    any_impinj(&r.tag_report_content_selector.custom).then(|| vec![237, 238, CUSTOM])
}

/// The same under an ROSpec.
fn in_rospec(s: &RoSpec) -> Option<Vec<u16>> {
    let within = |mut inner: Vec<u16>, outer: &[u16]| {
        let mut p = outer.to_vec();
        p.append(&mut inner);
        p
    };
    for spec in &s.specs {
        match spec {
            SpecParameter::Custom(c) if is_impinj(c) => return Some(vec![177, CUSTOM]),
            SpecParameter::AiSpec(ai) => {
                if any_impinj(&ai.custom) {
                    return Some(vec![177, 183, CUSTOM]);
                }
                for ips in &ai.inventory_parameter_specs {
                    if any_impinj(&ips.custom) {
                        return Some(vec![177, 183, 186, CUSTOM]);
                    }
                    if let Some(p) = ips.antenna_configuration.iter().find_map(in_antenna) {
                        return Some(within(p, &[177, 183, 186]));
                    }
                }
            }
            _ => {}
        }
    }
    s.ro_report_spec
        .as_ref()
        .and_then(in_report_spec)
        .map(|p| within(p, &[177]))
}

/// Where the first Impinj Custom parameter of a request sits: `Some(vec![])` when the message
/// itself holds it, the path of parameter types to it otherwise.
fn impinj_parameter(body: &MessageBody) -> Option<Vec<u16>> {
    use MessageBody as B;
    let (top, nested) = match body {
        B::GetReaderCapabilities(m) => (&m.custom, None),
        B::GetReaderConfig(m) => (&m.custom, None),
        B::AddRospec(m) => (&m.custom, in_rospec(&m.ro_spec)),
        B::AddAccessspec(m) => {
            let a = &m.access_spec;
            let nested = any_impinj(&a.custom).then(|| vec![207, CUSTOM]);
            (&m.custom, nested)
        }
        B::SetReaderConfig(m) => {
            let nested = m
                .antenna_configuration
                .iter()
                .find_map(in_antenna)
                .or_else(|| m.ro_report_spec.as_ref().and_then(in_report_spec));
            (&m.custom, nested)
        }
        _ => return None,
    };
    if any_impinj(top) {
        Some(Vec::new())
    } else {
        nested
    }
}

/// The status refusing an Impinj parameter at `path` (empty: the message's own).
fn refusal(path: &[u16]) -> LlrpStatus {
    let why = "Impinj extensions (vendor 25882) are not supported by this reader";
    let Some((&last, outer)) = path.split_last() else {
        return LlrpStatus::new(StatusCode::M_UnsupportedParameter, why);
    };
    let mut error = ParameterError::new(last, StatusCode::P_UnsupportedParameter);
    for &ty in outer.iter().rev() {
        let mut pe = ParameterError::new(ty, StatusCode::P_ParameterError);
        pe.parameter_error = Some(Box::new(error));
        error = pe;
    }
    let mut s = LlrpStatus::new(StatusCode::M_ParameterError, why);
    s.parameter_error = Some(error);
    s
}

/// For a device without the Impinj extensions: the answer to an Impinj message or to a
/// request carrying an Impinj parameter (`None`: the request is the device's to handle).
pub(super) fn refuse(body: &MessageBody) -> Option<MessageBody> {
    if matches!(
        body,
        MessageBody::ImpinjEnableExtensions(_) | MessageBody::ImpinjSaveSettings(_)
    ) {
        let status = LlrpStatus::new(
            StatusCode::M_UnsupportedMessage,
            format!("message {} is not supported here", body.name()),
        );
        return Some(MessageBody::ErrorMessage(super::error_message(status)));
    }
    let status = refusal(&impinj_parameter(body)?);
    body.kind()
        .error_response(status.clone())
        .or_else(|| Some(MessageBody::ErrorMessage(super::error_message(status))))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_nested_impinj_parameter_is_refused_along_its_path() {
        let s = refusal(&[177, 183, 186, 222, 330, CUSTOM]);
        assert_eq!(s.status_code, StatusCode::M_ParameterError);
        let mut path = Vec::new();
        let mut e = s.parameter_error.as_ref();
        while let Some(pe) = e {
            path.push((pe.parameter_type, pe.error_code));
            e = pe.parameter_error.as_deref();
        }
        assert_eq!(path.len(), 6);
        assert_eq!(
            path.last(),
            Some(&(CUSTOM, StatusCode::P_UnsupportedParameter))
        );
        assert!(path[..5]
            .iter()
            .all(|&(_, c)| c == StatusCode::P_ParameterError));
        assert_eq!(refusal(&[]).status_code, StatusCode::M_UnsupportedParameter);
    }
}
