//! AccessSpecs: the C1G2 access operations (Read, Write, BlockWrite, BlockErase, Lock, Kill)
//! on the tags an AccessSpec's tag spec selects, against the tags' memory shared by the run's
//! readers ([`super::memory`]); ClientRequestOpSpec and vendor operations are refused as
//! unsupported.

pub mod link;
mod ops;

use llrp::codec::BitVec;
use llrp::enums::*;
use llrp::params::*;
use llrp::StatusCode;

use super::config::param_field_error;
use super::memory::TagMemory;
use super::{field_error, ReaderProfile};
use crate::physics::Model;

/// The tag a read singulated, as the AccessSpecs see it.
pub struct Tag<'a> {
    /// The reader's physics (the scenario's tag memory).
    pub model: &'a Model,
    /// The tags' memory as the run has changed it.
    pub memory: &'a TagMemory,
    /// The tag's index in the scenario.
    pub tag: usize,
    /// The session's LLRP version (result codes differ between 1.0.1 and 1.1).
    pub version: u8,
    /// The antenna whose read singulated the tag.
    pub antenna: u16,
    /// The time of that read, µs of simulated time.
    pub time_us: u64,
    /// That read's forward-link margin over the tag's read sensitivity, dB ([`link`]).
    pub margin_db: f64,
}

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
        if spec.antenna_id > p.ports {
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
        if self.entries.len() >= p.device.max_access_specs as usize {
            return LlrpStatus::new(StatusCode::M_OverflowParameter, "too many AccessSpecs");
        }
        if let Err(status) = ops::check_unknown(&spec.access_command.extra) {
            return status;
        }
        for op in &spec.access_command.op_specs {
            if let Err(status) = ops::check(op) {
                return status;
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

    /// Runs the first enabled AccessSpec that matches this read: its results, ID and when
    /// they are reported (the AccessSpec's own AccessReportSpec, else `default_report`, the
    /// reader's).
    pub fn apply(
        &mut self,
        tag: &Tag<'_>,
        antenna: u16,
        ro_spec_id: u32,
        default_report: AccessReportTriggerType,
    ) -> Applied {
        if !self.entries.iter().any(|e| e.enabled) {
            return Applied::default();
        }
        let pos = self.entries.iter().position(|e| {
            e.enabled
                && (e.spec.antenna_id == 0 || e.spec.antenna_id == antenna)
                && (e.spec.ro_spec_id == 0 || e.spec.ro_spec_id == ro_spec_id)
                && tag_matches(&e.spec.access_command.c1g2_tag_spec, tag)
        });
        let Some(i) = pos else {
            return Applied::default();
        };
        let e = &mut self.entries[i];
        let mut link = link::Link::new(
            tag.margin_db,
            tag.model.access_stream(tag.tag, tag.antenna, tag.time_us),
        );
        let results = ops::run(&e.spec.access_command.op_specs, tag, &mut link);
        let id = e.spec.access_spec_id;
        let report = e
            .spec
            .access_report_spec
            .as_ref()
            .map_or(default_report, |r| r.access_report_trigger);
        e.executed += 1;
        let t = &e.spec.access_spec_stop_trigger;
        if t.access_spec_stop_trigger_type == AccessSpecStopTriggerType::OperationCount
            && t.operation_count_value > 0
            && e.executed >= u32::from(t.operation_count_value)
        {
            // Operation count reached: the AccessSpec is deleted, as the spec says.
            self.entries.remove(i);
        }
        Applied {
            results,
            access_spec_id: id,
            at_once: report == AccessReportTriggerType::EndOfAccessSpec,
        }
    }
}

/// What an AccessSpec did on a tag.
#[derive(Debug, Default)]
pub struct Applied {
    /// The results of its operations (none when no AccessSpec ran).
    pub results: Vec<OpSpecResult>,
    /// The AccessSpec that ran (0: none).
    pub access_spec_id: u32,
    /// Reported at once, in an RO_ACCESS_REPORT of their own (AccessReportTrigger End of
    /// AccessSpec), not with the ROSpec's reports.
    pub at_once: bool,
}

/// Whether a tag satisfies a C1G2TagSpec (first target tag; the second, if any, must too).
fn tag_matches(spec: &C1g2TagSpec, tag: &Tag<'_>) -> bool {
    tag.memory
        .inspect(tag.model, tag.tag, |chip| spec_matches(spec, chip))
}

/// Whether `chip` satisfies every target tag of `spec`.
fn spec_matches(spec: &C1g2TagSpec, chip: &super::memory::Chip) -> bool {
    spec.c1g2_target_tag.iter().all(|t| {
        let words = chip.bank(t.mb);
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
