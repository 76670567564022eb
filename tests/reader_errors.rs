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

/// A parameter of LLRP 1.1 that the reader does not know (LoopSpec, TLV 355, LLRP 1.1
/// §17.2.4.4, at the end of an ROSpec) is refused as unsupported, not ignored, and adds
/// nothing.
#[tokio::test]
async fn an_llrp_1_1_parameter_the_reader_does_not_know_is_refused() {
    let sim = start(&s1(), Speed::Factor(1.0)).await;
    let mut c = connect(&sim).await;
    let add = llrp::Message {
        version: 1,
        id: 9,
        body: AddRospec {
            ro_spec: RoSpec::immediate(1, vec![0]),
            ..Default::default()
        }
        .into(),
    };
    let mut frame = add.to_bytes().to_vec();
    // The ROSpec is the message's only parameter: LoopSpec (LoopCount 1) goes at its end,
    // and the ROSpec's and the message's lengths grow by its 8 bytes.
    frame.extend_from_slice(&hex("0163 0008 00000001"));
    grow(&mut frame, 2, 4, 8);
    grow(&mut frame, 12, 2, 8);
    c.send_raw(&frame).await.expect("send");
    let r = c.wait_for(|m| m.id == 9, T).await.expect("answer");
    assert_eq!(r.name(), "ADD_ROSPEC_RESPONSE");
    let st = status(&r);
    assert_eq!(st.status_code, StatusCode::M_ParameterError, "{st:?}");
    let inner = st.parameter_error.and_then(|p| p.parameter_error);
    assert_eq!(
        inner.map(|p| (p.parameter_type, p.error_code)),
        Some((355, StatusCode::P_UnsupportedParameter))
    );
    let MessageBody::GetRospecsResponse(g) = c
        .request(GetRospecs::default(), T)
        .await
        .expect("answer")
        .body
    else {
        panic!("GET_ROSPECS_RESPONSE")
    };
    assert!(g.ro_specs.is_empty(), "nothing was added");
    sim.shutdown().await;
}

/// Adds `by` to the big-endian length field of `width` bytes at `at`.
fn grow(frame: &mut [u8], at: usize, width: usize, by: u32) {
    let field = &mut frame[at..at + width];
    let n = field.iter().fold(0u32, |n, &b| (n << 8) | u32::from(b)) + by;
    for (k, b) in field.iter_mut().enumerate() {
        *b = n.to_be_bytes()[4 - width + k];
    }
}

/// An AccessCommand holding a parameter the codec does not know (type 900, unassigned:
/// standing for LLRP 1.1's C1G2BlockPermalock, which it does not know either) is refused as
/// unsupported, not run without it, and adds nothing.
#[tokio::test]
async fn an_access_command_parameter_the_reader_does_not_know_is_refused() {
    let sim = start(&s1(), Speed::Factor(1.0)).await;
    let mut c = connect(&sim).await;
    let access = AccessSpec {
        access_spec_id: 3,
        protocol_id: AirProtocol::EpcGlobalClass1Gen2,
        access_command: AccessCommand {
            c1g2_tag_spec: C1g2TagSpec {
                c1g2_target_tag: vec![C1g2TargetTag {
                    mb: 1,
                    is_match: true,
                    ..Default::default()
                }],
                ..Default::default()
            },
            op_specs: vec![OpSpec::C1g2Read(C1g2Read {
                op_spec_id: 1,
                mb: 3,
                word_count: 1,
                ..Default::default()
            })],
            ..Default::default()
        },
        ..Default::default()
    };
    let add = llrp::Message {
        version: 1,
        id: 11,
        body: AddAccessspec {
            access_spec: access,
            ..Default::default()
        }
        .into(),
    };
    let mut frame = add.to_bytes().to_vec();
    // The AccessCommand (type 209) ends the AccessSpec (207), which ends the message: the
    // unknown parameter goes at the end, and all three lengths grow by its 8 bytes.
    let len = |frame: &[u8], at: usize| usize::from(u16::from_be_bytes([frame[at], frame[at + 1]]));
    let command = (10..frame.len() - 4)
        .find(|&p| frame[p..p + 2] == [0x00, 0xD1] && p + len(&frame, p + 2) == frame.len())
        .expect("the AccessCommand ends the frame");
    assert_eq!(
        (&frame[10..12], 10 + len(&frame, 12)),
        (&[0x00, 0xCF][..], frame.len())
    );
    frame.extend_from_slice(&hex("0384 0008 00000001"));
    grow(&mut frame, 2, 4, 8);
    grow(&mut frame, 12, 2, 8);
    grow(&mut frame, command + 2, 2, 8);
    c.send_raw(&frame).await.expect("send");
    let r = c.wait_for(|m| m.id == 11, T).await.expect("answer");
    assert_eq!(r.name(), "ADD_ACCESSSPEC_RESPONSE");
    let st = status(&r);
    assert_eq!(st.status_code, StatusCode::M_ParameterError, "{st:?}");
    let mut path = Vec::new();
    let mut pe = st.parameter_error.as_ref();
    while let Some(p) = pe {
        path.push((p.parameter_type, p.error_code));
        pe = p.parameter_error.as_deref();
    }
    assert_eq!(
        path.last(),
        Some(&(900, StatusCode::P_UnsupportedParameter)),
        "{path:?}"
    );
    let MessageBody::GetAccessspecsResponse(g) = c
        .request(GetAccessspecs::default(), T)
        .await
        .expect("answer")
        .body
    else {
        panic!("GET_ACCESSSPECS_RESPONSE")
    };
    assert!(g.access_specs.is_empty(), "nothing was added");
    sim.shutdown().await;
}

/// Puts a parameter somewhere in an AISpec.
type Put = fn(&mut AiSpec, llrp::raw::Extra);

/// A parameter the codec does not know inside an AISpec, an InventoryParameterSpec or an
/// AntennaConfiguration of an ROSpec is refused as unsupported too, with the path to it.
#[tokio::test]
async fn unknown_parameters_deeper_in_an_rospec_are_refused_with_their_path() {
    let sim = start(&s1(), Speed::Factor(1.0)).await;
    let mut c = connect(&sim).await;
    let unknown = || llrp::raw::Extra {
        at: 0,
        param: llrp::raw::RawParam::new(hex("0384 0008 00000001")),
    };
    let place: [(&str, Put, Vec<u16>); 3] = [
        ("AISpec", |ai, x| ai.extra.push(x), vec![177, 183, 900]),
        (
            "InventoryParameterSpec",
            |ai, x| ai.inventory_parameter_specs[0].extra.push(x),
            vec![177, 183, 186, 900],
        ),
        (
            "AntennaConfiguration",
            |ai, x| {
                let ips = &mut ai.inventory_parameter_specs[0];
                ips.antenna_configuration.push(AntennaConfiguration {
                    antenna_id: 1,
                    ..Default::default()
                });
                ips.antenna_configuration[0].extra.push(x);
            },
            vec![177, 183, 186, 222, 900],
        ),
    ];
    for (id, (what, put, want)) in (1u32..).zip(place) {
        let mut spec = RoSpec::immediate(id, vec![0]);
        let SpecParameter::AiSpec(ai) = &mut spec.specs[0] else {
            panic!("an immediate ROSpec has an AISpec")
        };
        put(ai, unknown());
        let r = c
            .request(
                AddRospec {
                    ro_spec: spec,
                    ..Default::default()
                },
                T,
            )
            .await
            .expect("answer");
        let st = status(&r);
        assert_eq!(
            st.status_code,
            StatusCode::M_ParameterError,
            "{what}: {st:?}"
        );
        let mut path = Vec::new();
        let mut pe = st.parameter_error.as_ref();
        while let Some(p) = pe {
            path.push(p.parameter_type);
            pe = p.parameter_error.as_deref();
        }
        assert_eq!(path, want, "{what}");
    }
    let MessageBody::GetRospecsResponse(g) = c
        .request(GetRospecs::default(), T)
        .await
        .expect("answer")
        .body
    else {
        panic!("GET_ROSPECS_RESPONSE")
    };
    assert!(g.ro_specs.is_empty(), "nothing was added");
    sim.shutdown().await;
}
