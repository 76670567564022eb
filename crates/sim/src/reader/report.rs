//! Tag reports: turning physics reads into TagReportData as the content selectors ask, and
//! aggregating reads of the same tag between two reports as an LLRP reader does.

use std::collections::hash_map::{Entry, HashMap};
use std::hash::{BuildHasherDefault, Hash, Hasher};

use llrp::codec::BitVec;
use llrp::params::*;
use llrp::units;

use crate::scenario::tagmem::TagEpc;

/// One tag read as the reader saw it (the physics read plus LLRP context).
#[derive(Clone, Debug, PartialEq)]
pub struct Observation {
    /// EPC of the tag.
    pub epc: TagEpc,
    /// The tag's PC word (its EPC length, and the other bits as written).
    pub pc: u16,
    /// ROSpec that produced the read.
    pub ro_spec_id: u32,
    /// 1-based index of the AISpec in its ROSpec.
    pub spec_index: u16,
    /// InventoryParameterSpec that produced the read.
    pub inventory_parameter_spec_id: u16,
    /// 1-based antenna.
    pub antenna_id: u16,
    /// 1-based channel index into the advertised table.
    pub channel_index: u16,
    /// Received power, dBm (unrounded).
    pub rssi_dbm: f64,
    /// RF phase, radians in [0, 2π).
    pub phase_rad: f64,
    /// Doppler shift, Hz.
    pub doppler_hz: f64,
    /// Time of the read, µs since the Unix epoch.
    pub utc_us: u64,
    /// Time of the read, µs since the reader booted.
    pub uptime_us: u64,
    /// Access results to carry with this read.
    pub op_spec_results: Vec<OpSpecResult>,
    /// AccessSpec that produced `op_spec_results` (0: none).
    pub access_spec_id: u32,
    /// TID words (for Impinj serialized TID).
    pub tid: Vec<u16>,
    /// The leading EPC bits the tag left out of a truncated reply (a Select with Truncate);
    /// `None`: it sent its whole EPC.
    pub truncated: Option<u16>,
}

/// Which Impinj fields to add (from ImpinjTagReportContentSelector; all off when absent).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ImpinjContent {
    /// ImpinjRFPhaseAngle.
    pub phase: bool,
    /// ImpinjPeakRSSI.
    pub peak_rssi: bool,
    /// ImpinjRFDopplerFrequency.
    pub doppler: bool,
    /// ImpinjSerializedTID.
    pub serialized_tid: bool,
}

impl ImpinjContent {
    /// The Impinj content asked for in an ROReportSpec's Custom parameters.
    pub fn from_report_spec(spec: &RoReportSpec) -> Self {
        let mut c = ImpinjContent::default();
        for p in &spec.custom {
            if let Custom::ImpinjTagReportContentSelector(s) = p {
                c.phase = s
                    .enable_rf_phase_angle
                    .as_ref()
                    .is_some_and(|m| m.rf_phase_angle_mode == 1);
                c.peak_rssi = s
                    .enable_peak_rssi
                    .as_ref()
                    .is_some_and(|m| m.peak_rssi_mode == 1);
                c.doppler = s
                    .enable_rf_doppler_frequency
                    .as_ref()
                    .is_some_and(|m| m.rf_doppler_frequency_mode == 1);
                c.serialized_tid = s
                    .enable_serialized_tid
                    .as_ref()
                    .is_some_and(|m| m.serialized_tid_mode == 1);
            }
        }
        c
    }
}

/// Gen2 CRC-16 (ISO/IEC 18000-63: polynomial 0x1021, preset 0xFFFF, ones' complement) of
/// the PC word and the EPC, as the tag backscatters it.
pub fn gen2_crc(pc: u16, epc: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for b in pc.to_be_bytes().iter().chain(epc) {
        crc ^= u16::from(*b) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x1021
            } else {
                crc << 1
            };
        }
    }
    !crc
}

/// The EPC parameter of a TagReportData: EPC-96 for a 96-bit EPC (as readers send it),
/// EPCData of the EPC's bit count otherwise.
pub fn epc_parameter(epc: &TagEpc) -> Epc {
    match epc.as_epc96() {
        Some(bytes) => Epc::Epc96(Epc96(bytes)),
        None => Epc::EpcData(EpcData {
            epc: BitVec::from_bytes(epc.as_bytes()),
            ..Default::default()
        }),
    }
}

/// What one TagReportData carries: the standard selector and the Impinj one.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Content {
    /// The standard selector.
    pub selector: TagReportContentSelector,
    /// The Impinj selector (honoured only when extensions are enabled).
    pub impinj: ImpinjContent,
}

/// Reads waiting to be reported, aggregated per tag and per enabled distinguishing field.
#[derive(Debug, Default)]
pub struct ReportBuffer {
    entries: Vec<TagReportData>,
    index: HashMap<Key, usize, BuildHasherDefault<FxHasher>>,
    /// EPCs longer than 96 bits in `index`, numbered in order: a Key carries the number.
    long_epcs: HashMap<TagEpc, u64, BuildHasherDefault<FxHasher>>,
    /// How many entries a report is expected to hold (see [`ReportBuffer::expect`]).
    expect: usize,
}

/// Most entries reserved at once for an expected report size.
const MAX_EXPECTED_ENTRIES: usize = 1024;

/// A fast non-cryptographic hasher for [`ReportBuffer`]'s index (the multiply-rotate scheme of
/// rustc's FxHash, written here): the keys are EPCs and a few small fields from the reader's
/// own scenario, so hash flooding is no concern, and SipHash cost a noticeable share of the
/// report path. The index only finds entries; the report order never depends on it.
#[derive(Clone, Copy, Debug, Default)]
struct FxHasher {
    hash: u64,
}

impl FxHasher {
    /// Folds one word into the hash.
    fn add(&mut self, word: u64) {
        const K: u64 = 0x517c_c1b7_2722_0a95;
        self.hash = (self.hash.rotate_left(5) ^ word).wrapping_mul(K);
    }
}

impl Hasher for FxHasher {
    fn write(&mut self, bytes: &[u8]) {
        let mut chunks = bytes.chunks_exact(8);
        for c in &mut chunks {
            let mut w = [0u8; 8];
            w.copy_from_slice(c);
            self.add(u64::from_le_bytes(w));
        }
        let rest = chunks.remainder();
        if !rest.is_empty() {
            let mut w = [0u8; 8];
            w[..rest.len()].copy_from_slice(rest);
            self.add(u64::from_le_bytes(w));
        }
    }

    fn write_u8(&mut self, i: u8) {
        self.add(u64::from(i));
    }

    fn write_u16(&mut self, i: u16) {
        self.add(u64::from(i));
    }

    fn write_u32(&mut self, i: u32) {
        self.add(u64::from(i));
    }

    fn write_u64(&mut self, i: u64) {
        self.add(i);
    }

    fn write_usize(&mut self, i: usize) {
        self.add(i as u64);
    }

    fn finish(&self) -> u64 {
        self.hash
    }
}

/// What makes two reads the same TagReportData: the EPC and every enabled field that could
/// differ between them, packed into four words (a field left out is 0 and its flag clear), so
/// that hashing and comparing it are a few word operations.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Key([u64; 4]);

impl Key {
    /// The key of observation `o` under selector `s`; `long_id` numbers `o`'s EPC if it is
    /// longer than 96 bits.
    fn new(o: &Observation, s: &TagReportContentSelector, long_id: u64) -> Key {
        // An EPC of up to 96 bits is its (zero-padded) bytes, a longer one its number; the
        // length in bytes, in the second word, keeps the two kinds and the lengths apart.
        let len = o.epc.as_bytes().len();
        let [e0, e1, e2, e3, e4, e5, e6, e7, e8, e9, e10, e11, ..] = *o.epc.padded();
        let (head, tail) = if len <= 12 {
            let head = u64::from_le_bytes([e0, e1, e2, e3, e4, e5, e6, e7]);
            (head, u64::from(u32::from_le_bytes([e8, e9, e10, e11])))
        } else {
            (long_id, 0)
        };
        let field = |on: bool, bit: u32, v: u64| (u64::from(on) << bit, if on { v } else { 0 });
        // A truncated read (skip + 1, up to 497) is not the whole EPC's read.
        let trunc = o.truncated.map_or(0, |skip| u64::from(skip) + 1);
        let (f0, ro) = field(s.enable_ro_spec_id, 32, u64::from(o.ro_spec_id));
        let (f1, si) = field(s.enable_spec_index, 33, u64::from(o.spec_index));
        let (f2, ips) = field(
            s.enable_inventory_parameter_spec_id,
            34,
            u64::from(o.inventory_parameter_spec_id),
        );
        let (f3, ant) = field(s.enable_antenna_id, 35, u64::from(o.antenna_id));
        let (f4, ch) = field(s.enable_channel_index, 36, u64::from(o.channel_index));
        let (f5, acc) = field(s.enable_access_spec_id, 37, u64::from(o.access_spec_id));
        Key([
            head,
            tail | f0 | f1 | f2 | f3 | f4 | f5 | (len as u64) << 40 | trunc << 48,
            ro | si << 32 | ips << 48,
            ant | ch << 16 | acc << 32,
        ])
    }
}

impl Hash for Key {
    fn hash<H: Hasher>(&self, state: &mut H) {
        for w in self.0 {
            state.write_u64(w);
        }
    }
}

impl ReportBuffer {
    /// Number of TagReportData waiting.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// True when nothing waits.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Sets how many TagReportData a report is expected to hold (the N of its trigger; 0 when
    /// unknown), so that a report's entries are allocated once.
    pub fn expect(&mut self, n: usize) {
        self.expect = n;
    }

    /// Adds a read: a new TagReportData, or folded into the one for the same tag.
    /// `aggregate` false (report every read) keeps each read separate.
    pub fn add(&mut self, o: &Observation, c: &Content, aggregate: bool) {
        if aggregate && o.op_spec_results.is_empty() {
            let long_id = if o.epc.as_bytes().len() > 12 {
                let next = self.long_epcs.len() as u64;
                *self.long_epcs.entry(o.epc).or_insert(next)
            } else {
                0
            };
            match self.index.entry(Key::new(o, &c.selector, long_id)) {
                Entry::Occupied(e) => {
                    merge(&mut self.entries[*e.get()], o, c);
                    return;
                }
                Entry::Vacant(e) => {
                    e.insert(self.entries.len());
                }
            }
        }
        if self.entries.capacity() == 0 {
            // Room for the report's expected size at once: growing one TagReportData at a
            // time copies them over and over (with N = 1, the usual trigger, the default
            // first growth would allocate four).
            self.entries
                .reserve_exact(self.expect.clamp(1, MAX_EXPECTED_ENTRIES));
        }
        self.entries.push(build(o, c));
    }

    /// Takes everything waiting, in the order first seen.
    pub fn take(&mut self) -> Vec<TagReportData> {
        self.index.clear();
        self.long_epcs.clear();
        std::mem::take(&mut self.entries)
    }
}

/// A TagReportData for one read, with exactly the fields the selectors enable, in spec order.
pub fn build(o: &Observation, c: &Content) -> TagReportData {
    let s = &c.selector;
    let epc = match o.truncated {
        // The bits the tag sent, in EPCData with their length (never EPC-96).
        Some(skip) => Epc::EpcData(EpcData {
            epc: super::select::truncated_epc(&o.epc, skip),
            ..Default::default()
        }),
        None => epc_parameter(&o.epc),
    };
    let mut t = TagReportData {
        epc,
        ..Default::default()
    };
    if s.enable_ro_spec_id {
        t.ro_spec_id = Some(RoSpecId(o.ro_spec_id));
    }
    if s.enable_spec_index {
        t.spec_index = Some(SpecIndex(o.spec_index));
    }
    if s.enable_inventory_parameter_spec_id {
        t.inventory_parameter_spec_id =
            Some(InventoryParameterSpecId(o.inventory_parameter_spec_id));
    }
    if s.enable_antenna_id {
        t.antenna_id = Some(AntennaId(o.antenna_id));
    }
    if s.enable_peak_rssi {
        t.peak_rssi = Some(PeakRssi(units::dbm_to_peak_rssi(o.rssi_dbm)));
    }
    if s.enable_channel_index {
        t.channel_index = Some(ChannelIndex(o.channel_index));
    }
    if s.enable_first_seen_timestamp {
        t.first_seen_timestamp_utc = Some(FirstSeenTimestampUtc(o.utc_us));
    }
    if s.enable_last_seen_timestamp {
        t.last_seen_timestamp_utc = Some(LastSeenTimestampUtc(o.utc_us));
    }
    if s.enable_tag_seen_count {
        t.tag_seen_count = Some(TagSeenCount(1));
    }
    add_air_protocol_data(&mut t.air_protocol_tag_data, o, s);
    if s.enable_access_spec_id && o.access_spec_id != 0 {
        t.access_spec_id = Some(AccessSpecId(o.access_spec_id));
    }
    t.op_spec_results = o.op_spec_results.clone();
    add_impinj_fields(&mut t.custom, o, &c.impinj);
    t
}

/// Adds the PC bits and CRC of the read's EPC that the air protocol selectors enable.
#[inline]
fn add_air_protocol_data(
    data: &mut Vec<AirProtocolTagData>,
    o: &Observation,
    s: &TagReportContentSelector,
) {
    if o.truncated.is_some() {
        // A truncated reply carries no PC word; its CRC is not modelled.
        return;
    }
    for m in &s.air_protocol_epc_memory_selector {
        if m.enable_pc_bits {
            data.push(AirProtocolTagData::C1g2Pc(C1g2Pc(o.pc)));
        }
        if m.enable_crc {
            data.push(AirProtocolTagData::C1g2Crc(C1g2Crc(gen2_crc(
                o.pc,
                o.epc.as_bytes(),
            ))));
        }
    }
}

/// Adds the Impinj fields `i` enables, in the order Impinj readers send them.
#[inline]
fn add_impinj_fields(custom: &mut Vec<Custom>, o: &Observation, i: &ImpinjContent) {
    if i.serialized_tid {
        custom.push(Custom::ImpinjSerializedTid(ImpinjSerializedTid {
            tid: o.tid.clone(),
            ..Default::default()
        }));
    }
    if i.phase {
        custom.push(Custom::ImpinjRfPhaseAngle(ImpinjRfPhaseAngle {
            phase_angle: units::radians_to_phase(o.phase_rad),
            ..Default::default()
        }));
    }
    if i.peak_rssi {
        custom.push(Custom::ImpinjPeakRssi(ImpinjPeakRssi {
            rssi: units::dbm_to_centi_dbm(o.rssi_dbm),
            ..Default::default()
        }));
    }
    if i.doppler {
        custom.push(Custom::ImpinjRfDopplerFrequency(ImpinjRfDopplerFrequency {
            doppler_frequency: units::hz_to_doppler(o.doppler_hz),
            ..Default::default()
        }));
    }
}

/// Folds a later read of the same tag into its TagReportData: peak RSSI is the maximum, the
/// last-seen time and the count advance, the Impinj phase and Doppler are the latest.
fn merge(t: &mut TagReportData, o: &Observation, c: &Content) {
    if let Some(p) = &mut t.peak_rssi {
        p.0 = p.0.max(units::dbm_to_peak_rssi(o.rssi_dbm));
    }
    if let Some(l) = &mut t.last_seen_timestamp_utc {
        l.0 = l.0.max(o.utc_us);
    }
    if let Some(n) = &mut t.tag_seen_count {
        n.0 = n.0.saturating_add(1);
    }
    for p in &mut t.custom {
        match p {
            Custom::ImpinjRfPhaseAngle(a) if c.impinj.phase => {
                a.phase_angle = units::radians_to_phase(o.phase_rad)
            }
            Custom::ImpinjPeakRssi(r) if c.impinj.peak_rssi => {
                r.rssi = r.rssi.max(units::dbm_to_centi_dbm(o.rssi_dbm))
            }
            Custom::ImpinjRfDopplerFrequency(d) if c.impinj.doppler => {
                d.doppler_frequency = units::hz_to_doppler(o.doppler_hz)
            }
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn obs(epc0: u8, antenna: u16, rssi: f64, t: u64) -> Observation {
        let mut epc = [0u8; 12];
        epc[0] = epc0;
        Observation {
            epc: epc.into(),
            pc: 0x3000,
            ro_spec_id: 1,
            spec_index: 1,
            inventory_parameter_spec_id: 1,
            antenna_id: antenna,
            channel_index: 3,
            rssi_dbm: rssi,
            phase_rad: 1.0,
            doppler_hz: -2.5,
            utc_us: t,
            uptime_us: t,
            op_spec_results: vec![],
            access_spec_id: 0,
            tid: vec![],
            truncated: None,
        }
    }

    #[test]
    fn gen2_crc_matches_known_value() {
        // CRC-16/GENIBUS check value of "123456789" is 0xD64E; with the PC word prepended the
        // same algorithm runs over two more bytes, so check the bare algorithm via an empty PC.
        let mut crc: u16 = 0xFFFF;
        for b in b"123456789" {
            crc ^= u16::from(*b) << 8;
            for _ in 0..8 {
                crc = if crc & 0x8000 != 0 {
                    (crc << 1) ^ 0x1021
                } else {
                    crc << 1
                };
            }
        }
        assert_eq!(!crc, 0xD64E);
        assert_eq!(gen2_crc(0x3132, b"3456789"), 0xD64E);
    }

    #[test]
    fn aggregation_follows_enabled_fields() {
        let c = Content {
            selector: TagReportContentSelector {
                enable_antenna_id: true,
                enable_peak_rssi: true,
                enable_tag_seen_count: true,
                enable_last_seen_timestamp: true,
                ..Default::default()
            },
            impinj: ImpinjContent::default(),
        };
        let mut b = ReportBuffer::default();
        b.add(&obs(1, 1, -60.0, 10), &c, true);
        b.add(&obs(1, 1, -55.0, 20), &c, true);
        b.add(&obs(1, 2, -50.0, 30), &c, true);
        b.add(&obs(2, 1, -70.0, 40), &c, true);
        let r = b.take();
        assert_eq!(r.len(), 3);
        assert_eq!(r[0].tag_seen_count, Some(TagSeenCount(2)));
        assert_eq!(r[0].peak_rssi, Some(PeakRssi(-55)));
        assert_eq!(r[0].last_seen_timestamp_utc, Some(LastSeenTimestampUtc(20)));
        assert_eq!(r[1].antenna_id, Some(AntennaId(2)));
        assert!(b.is_empty());
        // Without the antenna in the selector, reads on two antennas fold together.
        let c2 = Content {
            selector: TagReportContentSelector {
                enable_tag_seen_count: true,
                ..Default::default()
            },
            ..c
        };
        b.add(&obs(1, 1, -60.0, 10), &c2, true);
        b.add(&obs(1, 2, -60.0, 11), &c2, true);
        assert_eq!(b.len(), 1);
        b.add(&obs(1, 2, -60.0, 12), &c2, false);
        assert_eq!(b.len(), 2);
    }

    #[test]
    fn aggregation_tells_epcs_of_every_length_apart() {
        let c = Content {
            selector: TagReportContentSelector {
                enable_tag_seen_count: true,
                ..Default::default()
            },
            impinj: ImpinjContent::default(),
        };
        let with = |bytes: &[u8]| Observation {
            epc: TagEpc::from_bytes(bytes).expect("whole words"),
            pc: TagEpc::from_bytes(bytes).expect("whole words").pc(),
            ..obs(0, 1, -60.0, 10)
        };
        let mut long = [0xE2u8; 16];
        let a128 = with(&long);
        long[15] = 0x01;
        let b128 = with(&long);
        // The same leading bytes, then zeros, at 64, 96 and 496 bits.
        let a64 = with(&[0xE2; 8]);
        let mut e96 = [0u8; 12];
        e96[..8].copy_from_slice(&[0xE2; 8]);
        let a96 = with(&e96);
        let mut e496 = [0u8; 62];
        e496[..8].copy_from_slice(&[0xE2; 8]);
        let a496 = with(&e496);
        let mut b = ReportBuffer::default();
        for o in [&a128, &b128, &a64, &a96, &a496, &a128, &a64, &a496, &b128] {
            b.add(o, &c, true);
        }
        let r = b.take();
        let seen: Vec<(usize, Option<TagSeenCount>)> = r
            .iter()
            .map(|t| (t.epc_bytes().len(), t.tag_seen_count))
            .collect();
        let n = |k| Some(TagSeenCount(k));
        assert_eq!(
            seen,
            [(16, n(2)), (16, n(2)), (8, n(2)), (12, n(1)), (62, n(2))]
        );
        assert_eq!(r[1].epc_bytes(), long);
        // After a report, a long EPC is new again.
        b.add(&b128, &c, true);
        b.add(&a128, &c, true);
        let r = b.take();
        assert_eq!(r.len(), 2);
        assert_eq!(r[0].epc_bytes(), long);
    }

    #[test]
    fn impinj_fields_appear_only_when_selected() {
        let mut c = Content::default();
        let t = build(&obs(1, 1, -61.23, 5), &c);
        assert!(t.custom.is_empty());
        c.impinj.phase = true;
        c.impinj.peak_rssi = true;
        let t = build(&obs(1, 1, -61.23, 5), &c);
        assert_eq!(t.impinj_phase_angle(), Some(units::radians_to_phase(1.0)));
        assert_eq!(t.impinj_peak_rssi(), Some(-6123));
        assert_eq!(t.impinj_doppler(), None);
    }
}
