//! AccessSpecs: C1G2Read of a tag's TID and user memory (from the scenario) on the tags an
//! AccessSpec's tag spec selects; other access operations are refused as unsupported.

use llrp::codec::BitVec;
use llrp::enums::*;
use llrp::params::*;
use llrp::StatusCode;

use super::config::param_field_error;
use super::{field_error, ReaderProfile, MAX_ACCESS_SPECS};
use crate::physics::Model;
use crate::scenario::tagmem::TagEpc;

/// C1G2ReadOpSpecResult result: success.
const READ_SUCCESS: u8 = 0;
/// C1G2ReadOpSpecResult result: memory overrun (words beyond the bank).
const READ_MEMORY_OVERRUN: u8 = 3;

/// One AccessSpec and its counters.
#[derive(Clone, Debug)]
struct Entry {
    spec: AccessSpec,
    enabled: bool,
    /// Times its operations ran (for the operation-count stop trigger).
    executed: u32,
}

/// All AccessSpecs of the reader.
#[derive(Debug, Default)]
pub struct AccessSpecs {
    entries: Vec<Entry>,
}

impl AccessSpecs {
    /// ADD_ACCESSSPEC.
    pub fn add(&mut self, p: &ReaderProfile, spec: AccessSpec) -> LlrpStatus {
        if spec.access_spec_id == 0 {
            return param_field_error(207, 0, 0, StatusCode::A_Invalid);
        }
        if spec.current_state {
            let mut e = param_field_error(207, 0, 3, StatusCode::A_Invalid);
            e.error_description = "a new AccessSpec must be Disabled".into();
            return e;
        }
        if spec.antenna_id > p.antennas {
            return param_field_error(207, 0, 1, StatusCode::A_OutOfRange);
        }
        if spec.protocol_id != AirProtocol::EpcGlobalClass1Gen2 {
            return param_field_error(207, 0, 2, StatusCode::A_OutOfRange);
        }
        if self
            .entries
            .iter()
            .any(|e| e.spec.access_spec_id == spec.access_spec_id)
        {
            let mut e = param_field_error(207, 0, 0, StatusCode::A_Invalid);
            e.error_description = format!("AccessSpec {} already exists", spec.access_spec_id);
            return e;
        }
        if self.entries.len() >= MAX_ACCESS_SPECS as usize {
            return LlrpStatus::new(StatusCode::M_OverflowParameter, "too many AccessSpecs");
        }
        for op in &spec.access_command.op_specs {
            let ty = match op {
                OpSpec::C1g2Read(r) => {
                    if r.mb == 0 {
                        // Reserved memory (passwords) is not readable in the simulation.
                        Some(341)
                    } else {
                        None
                    }
                }
                OpSpec::C1g2Write(_) => Some(342),
                OpSpec::C1g2Kill(_) => Some(343),
                OpSpec::C1g2Lock(_) => Some(344),
                OpSpec::C1g2BlockErase(_) => Some(346),
                OpSpec::C1g2BlockWrite(_) => Some(347),
                OpSpec::ClientRequestOpSpec(_) => Some(210),
                OpSpec::Custom(_) => Some(1023),
            };
            if let Some(ty) = ty {
                let mut cmd = ParameterError::new(209, StatusCode::P_ParameterError);
                cmd.parameter_error = Some(Box::new(ParameterError::new(
                    ty,
                    StatusCode::P_UnsupportedParameter,
                )));
                let mut pe = ParameterError::new(207, StatusCode::P_ParameterError);
                pe.parameter_error = Some(Box::new(cmd));
                let mut s = LlrpStatus::new(
                    StatusCode::M_ParameterError,
                    format!("access operation type {ty} is not supported (C1G2Read of EPC, TID and user memory is)"),
                );
                s.parameter_error = Some(pe);
                return s;
            }
        }
        self.entries.push(Entry {
            spec,
            enabled: false,
            executed: 0,
        });
        LlrpStatus::success()
    }

    fn select(&self, id: u32) -> Result<Vec<usize>, LlrpStatus> {
        if id == 0 {
            return Ok((0..self.entries.len()).collect());
        }
        match self
            .entries
            .iter()
            .position(|e| e.spec.access_spec_id == id)
        {
            Some(i) => Ok(vec![i]),
            None => {
                let mut s = field_error(0, StatusCode::A_Invalid, "AccessSpecID");
                s.error_description = format!("no AccessSpec {id}");
                Err(s)
            }
        }
    }

    /// DELETE_ACCESSSPEC (0: all).
    pub fn delete(&mut self, id: u32) -> LlrpStatus {
        match self.select(id) {
            Ok(idx) => {
                let mut k = 0;
                self.entries.retain(|_| {
                    let keep = !idx.contains(&k);
                    k += 1;
                    keep
                });
                LlrpStatus::success()
            }
            Err(s) => s,
        }
    }

    /// ENABLE_ACCESSSPEC / DISABLE_ACCESSSPEC (0: all).
    pub fn set_enabled(&mut self, id: u32, enabled: bool) -> LlrpStatus {
        match self.select(id) {
            Ok(idx) => {
                for i in idx {
                    self.entries[i].enabled = enabled;
                }
                LlrpStatus::success()
            }
            Err(s) => s,
        }
    }

    /// The AccessSpecs as GET_ACCESSSPECS reports them.
    pub fn list(&self) -> Vec<AccessSpec> {
        self.entries
            .iter()
            .map(|e| {
                let mut s = e.spec.clone();
                s.current_state = e.enabled;
                s
            })
            .collect()
    }

    /// Runs the first enabled AccessSpec that matches this read; returns its results and ID.
    pub fn apply(
        &mut self,
        model: &Model,
        tag: usize,
        antenna: u16,
        ro_spec_id: u32,
    ) -> (Vec<OpSpecResult>, u32) {
        if !self.entries.iter().any(|e| e.enabled) {
            return (Vec::new(), 0);
        }
        let epc = model.tag_epc(tag);
        let pos = self.entries.iter().position(|e| {
            e.enabled
                && (e.spec.antenna_id == 0 || e.spec.antenna_id == antenna)
                && (e.spec.ro_spec_id == 0 || e.spec.ro_spec_id == ro_spec_id)
                && tag_matches(&e.spec.access_command.c1g2_tag_spec, model, tag, &epc)
        });
        let Some(i) = pos else {
            return (Vec::new(), 0);
        };
        let e = &mut self.entries[i];
        let results = e
            .spec
            .access_command
            .op_specs
            .iter()
            .filter_map(|op| match op {
                OpSpec::C1g2Read(r) => Some(OpSpecResult::C1g2Read(read(model, tag, &epc, r))),
                _ => None,
            })
            .collect();
        let id = e.spec.access_spec_id;
        e.executed += 1;
        let t = &e.spec.access_spec_stop_trigger;
        if t.access_spec_stop_trigger_type == AccessSpecStopTriggerType::OperationCount
            && t.operation_count_value > 0
            && e.executed >= u32::from(t.operation_count_value)
        {
            // Operation count reached: the AccessSpec is deleted, as the spec says.
            self.entries.remove(i);
        }
        (results, id)
    }
}

/// Memory bank contents as 16-bit words: 1 EPC (CRC, PC, EPC), 2 TID, 3 user.
fn bank(model: &Model, tag: usize, epc: &TagEpc, mb: u8) -> Vec<u16> {
    match mb {
        1 => {
            let pc = epc.pc();
            let mut w = vec![super::report::gen2_crc(pc, epc.as_bytes()), pc];
            w.extend(
                epc.as_bytes()
                    .chunks_exact(2)
                    .map(|c| u16::from_be_bytes([c[0], c[1]])),
            );
            w
        }
        2 => model.tag_tid(tag),
        3 => model.tag_user(tag),
        _ => Vec::new(),
    }
}

fn read(model: &Model, tag: usize, epc: &TagEpc, r: &C1g2Read) -> C1g2ReadOpSpecResult {
    let words = bank(model, tag, epc, r.mb);
    let start = usize::from(r.word_pointer);
    // WordCount 0 reads to the end of the bank.
    let end = if r.word_count == 0 {
        words.len()
    } else {
        start + usize::from(r.word_count)
    };
    match words.get(start..end) {
        Some(w) if start < end || r.word_count == 0 => C1g2ReadOpSpecResult {
            result: READ_SUCCESS,
            op_spec_id: r.op_spec_id,
            read_data: w.to_vec(),
            ..Default::default()
        },
        _ => C1g2ReadOpSpecResult {
            result: READ_MEMORY_OVERRUN,
            op_spec_id: r.op_spec_id,
            read_data: Vec::new(),
            ..Default::default()
        },
    }
}

/// Whether a tag satisfies a C1G2TagSpec (first target tag; the second, if any, must too).
fn tag_matches(spec: &C1g2TagSpec, model: &Model, tag: usize, epc: &TagEpc) -> bool {
    spec.c1g2_target_tag.iter().all(|t| {
        let words = bank(model, tag, epc, t.mb);
        let bits: Vec<bool> = words
            .iter()
            .flat_map(|w| (0..16).rev().map(move |b| w >> b & 1 == 1))
            .collect();
        let hit = masked_equal(&bits, usize::from(t.pointer), &t.tag_mask, &t.tag_data);
        hit == t.is_match
    })
}

fn bit(v: &BitVec, i: usize) -> bool {
    v.bytes
        .get(i / 8)
        .is_some_and(|b| b >> (7 - i % 8) & 1 == 1)
}

/// Compares memory bits from `pointer` with `data` under `mask` (an empty mask matches all).
fn masked_equal(mem: &[bool], pointer: usize, mask: &BitVec, data: &BitVec) -> bool {
    let n = usize::from(data.bits.max(mask.bits));
    (0..n).all(|i| {
        let m = mask.bits == 0 || bit(mask, i);
        !m || mem.get(pointer + i).copied() == Some(bit(data, i))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn masks_compare_only_masked_bits() {
        let mem: Vec<bool> = [true, false, true, true, false, false, false, true].to_vec();
        let data = BitVec {
            bits: 4,
            bytes: vec![0b1011_0000],
        };
        let all = BitVec {
            bits: 4,
            bytes: vec![0xF0],
        };
        assert!(masked_equal(&mem, 0, &all, &data));
        assert!(!masked_equal(&mem, 1, &all, &data));
        let partial = BitVec {
            bits: 4,
            bytes: vec![0b1000_0000],
        };
        let other = BitVec {
            bits: 4,
            bytes: vec![0b1100_0000],
        };
        assert!(masked_equal(&mem, 0, &partial, &other));
        // Beyond the end of memory nothing matches.
        assert!(!masked_equal(&mem, 6, &all, &data));
    }
}
