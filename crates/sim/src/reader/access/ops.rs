//! The C1G2 access operations of one AccessSpec on one tag, and their results with the codes
//! of the session's LLRP version.
//!
//! LLRP 1.1 (§16.2.1.5) gives each failure of the tag its own code; LLRP 1.0.1 has none for a
//! wrong password, nor for a read's overrun or lock. There the tag's behaviour decides: a
//! Gen2 tag given a wrong access or kill password does not reply (Gen2 v2.0.1 §6.3.2.11.3.5,
//! .4.4), so the reader sees no response; an error code the tag backscatters is a
//! nonspecific tag error.

use llrp::params::*;
use llrp::StatusCode;

use super::link::{Exchange, Link};
use super::Tag;
use crate::reader::memory::{Fault, Privilege, LOCK_FIELDS};

/// What ADD_ACCESSSPEC refuses of an operation: ClientRequestOpSpec and vendor operations
/// (unsupported), and a Lock payload whose privilege or data field is out of range.
pub(super) fn check(op: &OpSpec) -> Result<(), LlrpStatus> {
    let unsupported = match op {
        OpSpec::ClientRequestOpSpec(_) => Some(210),
        OpSpec::Custom(_) => Some(1023),
        OpSpec::C1g2Lock(l) => {
            for p in &l.c1g2_lock_payload {
                let bad_field = if Privilege::from_llrp(p.privilege).is_none() {
                    Some(0)
                } else if usize::from(p.data_field) >= LOCK_FIELDS {
                    Some(1)
                } else {
                    None
                };
                if let Some(field) = bad_field {
                    let mut inner = ParameterError::new(345, StatusCode::P_FieldError);
                    inner.field_error = Some(FieldError {
                        field_num: field,
                        error_code: StatusCode::A_OutOfRange,
                        ..Default::default()
                    });
                    return Err(nested(
                        344,
                        inner,
                        "a C1G2LockPayload's Privilege (0–3) or DataField (0–4) is out of range",
                    ));
                }
            }
            None
        }
        _ => None,
    };
    match unsupported {
        Some(ty) => Err(nested(
            ty,
            ParameterError::new(ty, StatusCode::P_UnsupportedParameter),
            &format!("access operation type {ty} is not supported (the C1G2 Read, Write, BlockWrite, BlockErase, Lock and Kill are)"),
        )),
        None => Ok(()),
    }
}

/// What ADD_ACCESSSPEC refuses among the AccessCommand's parameters the codec does not know
/// (LLRP 1.1's C1G2BlockPermalock, say; a vendor's Custom aside): unsupported, rather than
/// ignored.
pub(super) fn check_unknown(extra: &[llrp::raw::Extra]) -> Result<(), LlrpStatus> {
    let unknown = (extra.iter())
        .filter_map(|x| x.param.header())
        .map(|h| h.ty())
        .find(|&ty| ty != 1023);
    match unknown {
        Some(ty) => Err(nested(
            ty,
            ParameterError::new(ty, StatusCode::P_UnsupportedParameter),
            &format!("parameter type {ty} in an AccessCommand is not supported"),
        )),
        None => Ok(()),
    }
}

/// An M_ParameterError whose detail is AccessSpec → AccessCommand → `inner` (the
/// operation's own error, or the operation's parameter holding it when `op` differs).
fn nested(op: u16, inner: ParameterError, why: &str) -> LlrpStatus {
    let op_error = if inner.parameter_type == op {
        inner
    } else {
        let mut e = ParameterError::new(op, StatusCode::P_ParameterError);
        e.parameter_error = Some(Box::new(inner));
        e
    };
    let mut cmd = ParameterError::new(209, StatusCode::P_ParameterError);
    cmd.parameter_error = Some(Box::new(op_error));
    let mut pe = ParameterError::new(207, StatusCode::P_ParameterError);
    pe.parameter_error = Some(Box::new(cmd));
    let mut s = LlrpStatus::new(StatusCode::M_ParameterError, why);
    s.parameter_error = Some(pe);
    s
}

/// Runs `ops` in order on `tag`; an operation that fails ends the sequence, its result the
/// last one reported (ours: after a failure the tag's state is not what the later operations
/// were written for).
pub(super) fn run(ops: &[OpSpec], tag: &Tag<'_>, link: &mut Link) -> Vec<OpSpecResult> {
    let mut results = Vec::with_capacity(ops.len());
    for op in ops {
        let (result, ok) = tag
            .memory
            .with_chip(tag.model, tag.tag, |chip| one(op, chip, tag.version, link));
        results.extend(result);
        if !ok {
            break;
        }
    }
    results
}

/// One operation on `chip` over `link`: its result, and whether it succeeded.
fn one(
    op: &OpSpec,
    chip: &mut crate::reader::memory::Chip,
    v: u8,
    link: &mut Link,
) -> (Option<OpSpecResult>, bool) {
    if chip.killed {
        // Killed by an earlier operation of the same AccessSpec: it answers nothing more.
        return (None, false);
    }
    let (result, ok) = match op {
        OpSpec::C1g2Read(r) => {
            let got = match link.exchange(false) {
                Exchange::Done => chip.read(r.mb, r.word_pointer, r.word_count, r.access_password),
                _ => Err(Fault::Ignored),
            };
            let ok = got.is_ok();
            let (result, read_data) = match got {
                Ok(words) => (0, words),
                Err(f) => (read_code(f, v), Vec::new()),
            };
            let r = C1g2ReadOpSpecResult {
                result,
                op_spec_id: r.op_spec_id,
                read_data,
                ..Default::default()
            };
            (OpSpecResult::C1g2Read(r), ok)
        }
        OpSpec::C1g2Write(w) => {
            let (n, fault) = write_words(chip, w, link);
            let r = C1g2WriteOpSpecResult {
                result: fault.map_or(0, |f| write_code(f, v)),
                op_spec_id: w.op_spec_id,
                num_words_written: n,
                ..Default::default()
            };
            (OpSpecResult::C1g2Write(r), fault.is_none())
        }
        OpSpec::C1g2BlockWrite(w) => {
            let got = powered(link).and_then(|()| {
                chip.block_write(w.mb, w.word_pointer, &w.write_data, w.access_password)
            });
            let r = C1g2BlockWriteOpSpecResult {
                result: got.err().map_or(0, |f| write_code(f, v)),
                op_spec_id: w.op_spec_id,
                num_words_written: got.unwrap_or(0),
                ..Default::default()
            };
            (OpSpecResult::C1g2BlockWrite(r), got.is_ok())
        }
        OpSpec::C1g2BlockErase(e) => {
            let got = powered(link)
                .and_then(|()| chip.erase(e.mb, e.word_pointer, e.word_count, e.access_password));
            let r = C1g2BlockEraseOpSpecResult {
                result: got.err().map_or(0, |f| write_code(f, v)),
                op_spec_id: e.op_spec_id,
                ..Default::default()
            };
            (OpSpecResult::C1g2BlockErase(r), got.is_ok())
        }
        OpSpec::C1g2Lock(l) => {
            let got = powered(link).and_then(|()| chip.lock(&payloads(l), l.access_password));
            let r = C1g2LockOpSpecResult {
                result: got.err().map_or(0, |f| lock_code(f, v)),
                op_spec_id: l.op_spec_id,
                ..Default::default()
            };
            (OpSpecResult::C1g2Lock(r), got.is_ok())
        }
        OpSpec::C1g2Kill(k) => {
            let got = powered(link).and_then(|()| chip.kill(k.kill_password));
            let r = C1g2KillOpSpecResult {
                result: got.err().map_or(0, |f| kill_code(f, v)),
                op_spec_id: k.op_spec_id,
                ..Default::default()
            };
            (OpSpecResult::C1g2Kill(r), got.is_ok())
        }
        // Refused when the AccessSpec was added (`check`).
        OpSpec::ClientRequestOpSpec(_) | OpSpec::Custom(_) => return (None, false),
    };
    (Some(result), ok)
}

/// A Write, a word at a time, each word one exchange over `link` (Gen2 writes one word per
/// Write command): the words written, and the fault that stopped it.
fn write_words(
    chip: &mut crate::reader::memory::Chip,
    w: &C1g2Write,
    link: &mut Link,
) -> (u16, Option<Fault>) {
    let mut written = 0u16;
    for (i, word) in w.write_data.iter().enumerate() {
        if let Err(f) = powered(link) {
            return (written, Some(f));
        }
        // The pointer of a word past the 16-bit address space is an overrun.
        let Some(pointer) = u16::try_from(i)
            .ok()
            .and_then(|i| w.word_pointer.checked_add(i))
        else {
            return (written, Some(Fault::Overrun));
        };
        let (n, fault) = chip.write(w.mb, pointer, std::slice::from_ref(word), w.access_password);
        written += n;
        if fault.is_some() {
            return (written, fault);
        }
    }
    (written, None)
}

/// One exchange of a command that programs the tag's memory: the fault it ends in, if any.
fn powered(link: &mut Link) -> Result<(), Fault> {
    match link.exchange(true) {
        Exchange::Done => Ok(()),
        Exchange::InsufficientPower => Err(Fault::Power),
        Exchange::Lost => Err(Fault::Ignored),
    }
}

/// A Lock's payloads as (privilege, field), every one in range (`check` refused the others).
fn payloads(l: &C1g2Lock) -> Vec<(Privilege, usize)> {
    l.c1g2_lock_payload
        .iter()
        .filter_map(|p| {
            Some((
                Privilege::from_llrp(p.privilege)?,
                usize::from(p.data_field),
            ))
        })
        .collect()
}

/// C1G2ReadResultType: 1 Nonspecific_Tag_Error, 2 No_Response_From_Tag; LLRP 1.1 adds
/// 4 Memory_Overrun_Error, 5 Memory_Locked_Error, 6 Incorrect_Password_Error.
fn read_code(f: Fault, v: u8) -> u8 {
    match (f, v >= 2) {
        (Fault::Overrun, true) => 4,
        (Fault::Locked, true) => 5,
        (Fault::Password, true) => 6,
        (Fault::Password, false) | (Fault::Ignored, _) => 2,
        _ => 1,
    }
}

/// C1G2WriteResultType (also BlockWrite's and BlockErase's): 1 Tag_Memory_Overrun_Error,
/// 2 Tag_Memory_Locked_Error, 3 Insufficient_Power, 4 Nonspecific_Tag_Error,
/// 5 No_Response_From_Tag; LLRP 1.1 adds 7 Incorrect_Password_Error.
fn write_code(f: Fault, v: u8) -> u8 {
    match (f, v >= 2) {
        (Fault::Overrun, _) => 1,
        (Fault::Locked, _) => 2,
        (Fault::Power, _) => 3,
        (Fault::Password, true) => 7,
        (Fault::Password, false) | (Fault::Ignored, _) => 5,
        _ => 4,
    }
}

/// C1G2LockResultType: 1 Insufficient_Power, 2 Nonspecific_Tag_Error, 3 No_Response_From_Tag;
/// LLRP 1.1 adds 5 Incorrect_Password_Error, 6 Tag_Memory_Overrun_Error,
/// 7 Tag_Memory_Locked_Error.
fn lock_code(f: Fault, v: u8) -> u8 {
    match (f, v >= 2) {
        (Fault::Power, _) => 1,
        (Fault::Password, true) => 5,
        (Fault::Overrun, true) => 6,
        (Fault::Locked, true) => 7,
        (Fault::Password, false) | (Fault::Ignored, _) => 3,
        _ => 2,
    }
}

/// C1G2KillResultType: 1 Zero_Kill_Password_Error, 2 Insufficient_Power,
/// 3 Nonspecific_Tag_Error, 4 No_Response_From_Tag; LLRP 1.1 adds 6 Incorrect_Password_Error.
fn kill_code(f: Fault, v: u8) -> u8 {
    match (f, v >= 2) {
        (Fault::ZeroKillPassword, _) => 1,
        (Fault::Power, _) => 2,
        (Fault::Password, true) => 6,
        (Fault::Password, false) | (Fault::Ignored, _) => 4,
        _ => 3,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::seed;
    use crate::reader::memory::Chip;

    #[test]
    fn llrp_1_0_1_has_no_password_codes_and_a_wrong_password_gets_no_response() {
        assert_eq!(write_code(Fault::Password, 2), 7);
        assert_eq!(write_code(Fault::Password, 1), 5);
        assert_eq!(read_code(Fault::Overrun, 2), 4);
        assert_eq!(read_code(Fault::Overrun, 1), 1);
        assert_eq!(kill_code(Fault::ZeroKillPassword, 1), 1);
        assert_eq!(kill_code(Fault::Password, 2), 6);
        assert_eq!(lock_code(Fault::Locked, 2), 7);
        assert_eq!(lock_code(Fault::Locked, 1), 2);
    }

    #[test]
    fn a_tag_lost_mid_write_keeps_the_words_before_and_gives_no_response() {
        let w = C1g2Write {
            op_spec_id: 1,
            mb: 3,
            word_pointer: 0,
            write_data: vec![0x1111, 0x2222, 0x3333, 0x4444],
            ..Default::default()
        };
        // A link with a 3 dB margin fades out now and then; among many accesses, find those
        // it lost after some words went through.
        let mut mid_write = 0;
        for i in 0..4_000 {
            let mut chip = Chip::shipped((0, 0), vec![0x3000; 8], vec![0xE280], vec![0; 4]);
            let mut link = Link::new(3.0, seed::stream(&[43, i]));
            let (written, fault) = write_words(&mut chip, &w, &mut link);
            if fault != Some(Fault::Ignored) || written == 0 {
                continue;
            }
            mid_write += 1;
            let n = usize::from(written);
            assert_eq!(
                chip.bank(3)[..n],
                w.write_data[..n],
                "the words before stay"
            );
            assert!(chip.bank(3)[n..].iter().all(|&x| x == 0), "none after");
            // No_Response_From_Tag in both versions.
            assert_eq!(
                (write_code(Fault::Ignored, 1), write_code(Fault::Ignored, 2)),
                (5, 5)
            );
        }
        assert!(mid_write > 0, "no access lost its tag mid-write");
    }
}
