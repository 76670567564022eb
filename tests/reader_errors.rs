//! The simulated reader's answers to malformed and unsupported requests over loopback: the
//! response type or ERROR_MESSAGE with the codec's LLRPStatus, M_UnsupportedVersion, and an
//! unrecoverable length field closing the connection.

mod common;

use common::*;
use llrp::message::*;
use llrp::params::*;
use llrp::{FrameHeader, StatusCode};
use llrp_gateway::net::clock::Speed;

#[tokio::test]
async fn malformed_and_unsupported_requests_get_llrp_answers() {
    let sim = start(&s1(), Speed::Factor(1.0)).await;
    let mut c = connect(&sim).await;
    // A truncated ADD_ROSPEC: the ADD_ROSPEC_RESPONSE carries the decoder's status.
    c.send_raw(&hex("0414 0000000f 00000007 00b1 0005 00"))
        .await
        .expect("send");
    let r = c.wait_for(|m| m.id == 7, T).await.expect("answer");
    assert_eq!(r.name(), "ADD_ROSPEC_RESPONSE");
    let st = status(&r);
    assert_eq!(st.status_code, StatusCode::M_ParameterError);
    assert_eq!(st.parameter_error.map(|p| p.parameter_type), Some(177));
    // An unknown message type: ERROR_MESSAGE M_UnsupportedMessage with the same ID.
    c.send_raw(&hex("0555 0000000a 00000031"))
        .await
        .expect("send");
    let r = c.wait_for(|m| m.id == 0x31, T).await.expect("answer");
    assert_eq!(r.name(), "ERROR_MESSAGE");
    assert_eq!(status(&r).status_code, StatusCode::M_UnsupportedMessage);
    // A version-3 header: ERROR_MESSAGE M_UnsupportedVersion echoing version and ID.
    let mut frame = Vec::new();
    FrameHeader {
        version: 3,
        msg_type: 1,
        length: 11,
        id: 77,
    }
    .encode(&mut frame);
    frame.push(0);
    c.send_raw(&frame).await.expect("send");
    let mut raw = c.recv_raw(T).await.expect("answer");
    let h = FrameHeader::peek(&raw).expect("header");
    assert_eq!((h.version, h.msg_type, h.id), (3, 100, 77));
    raw[0] = (raw[0] & 0x03) | (1 << 2);
    let r = llrp::Message::decode(&raw).expect("ERROR_MESSAGE body");
    assert_eq!(status(&r).status_code, StatusCode::M_UnsupportedVersion);
    // A reader-to-client message sent to the reader.
    let code = request_status(&mut c, Keepalive::default()).await;
    assert_eq!(code, StatusCode::M_UnsupportedMessage);
    // Unsupported access operations are refused with the right status.
    let access = AccessSpec {
        access_spec_id: 3,
        antenna_id: 0,
        protocol_id: AirProtocol::EpcGlobalClass1Gen2,
        current_state: false,
        ro_spec_id: 0,
        access_command: AccessCommand {
            c1g2_tag_spec: C1g2TagSpec {
                c1g2_target_tag: vec![C1g2TargetTag {
                    mb: 1,
                    is_match: true,
                    pointer: 32,
                    ..Default::default()
                }],
                ..Default::default()
            },
            op_specs: vec![OpSpec::ClientRequestOpSpec(ClientRequestOpSpec {
                op_spec_id: 1,
                ..Default::default()
            })],
            ..Default::default()
        },
        ..Default::default()
    };
    let r = c
        .request(
            AddAccessspec {
                access_spec: access,
                ..Default::default()
            },
            T,
        )
        .await
        .expect("answer");
    let st = status(&r);
    assert_eq!(st.status_code, StatusCode::M_ParameterError);
    let inner = st
        .parameter_error
        .and_then(|p| p.parameter_error)
        .and_then(|p| p.parameter_error);
    assert_eq!(
        inner.map(|p| (p.parameter_type, p.error_code)),
        Some((210, StatusCode::P_UnsupportedParameter))
    );
    // The connection survived all of it.
    assert_eq!(
        request_status(&mut c, GetReaderCapabilities::default()).await,
        StatusCode::M_Success
    );
    // A length field below 10 cannot be resynchronised: ERROR_MESSAGE, then close.
    c.send_raw(&hex("0401 00000004 00000099"))
        .await
        .expect("send");
    let r = c.recv(T).await.expect("answer");
    assert_eq!(r.name(), "ERROR_MESSAGE");
    c.until_closed(T)
        .await
        .expect("closed after an unrecoverable frame");
    // The simulator itself is fine.
    let _again = connect(&sim).await;
    sim.shutdown().await;
}

fn hex(s: &str) -> Vec<u8> {
    let s: String = s.split_whitespace().collect();
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).expect("hex"))
        .collect()
}
