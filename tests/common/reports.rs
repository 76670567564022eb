//! A large RO_ACCESS_REPORT for the capture tests: far larger than any MSS, so it spans many
//! TCP segments. Included by path where a test needs only this.

use llrp::message::RoAccessReport;
use llrp::params::{AntennaId, Epc, Epc96, TagReportData};

/// A report of `n` reads on antenna 1, of the EPC-96s 3000…0000 to 3000…(n − 1).
pub fn many_reads(n: u32) -> RoAccessReport {
    let read = |k: u32| {
        let mut epc = [0u8; 12];
        epc[0] = 0x30;
        epc[10] = (k >> 8) as u8;
        epc[11] = k as u8;
        TagReportData {
            epc: Epc::Epc96(Epc96(epc)),
            antenna_id: Some(AntennaId(1)),
            ..Default::default()
        }
    };
    RoAccessReport {
        tag_report_data: (0..n).map(read).collect(),
        ..Default::default()
    }
}
