//! The reader device a simulated reader presents itself as: its identity (manufacturer,
//! model, firmware), its capability tables (transmit power, receive sensitivity, RF modes,
//! GPIO, LLRP maximums) and which vendor extensions it has. The scenario names one per reader
//! (`"device"`); docs/simulator.md "Vendor profiles" gives the source of every value.
//!
//! Not to be confused with the scenario's `reader_model` (`scenario::profile`), which sets
//! how the radio behaves (noise, phase distortion, timing), nor with
//! [`ReaderProfile`](super::ReaderProfile), the reader's whole fixed description, which holds
//! its device.

use crate::physics::gen2::RfMode;

/// Impinj's IANA private enterprise number.
pub const IMPINJ_PEN: u32 = 25882;
/// The IANA private enterprise number Zebra's FX readers report (Motorola's, from the
/// Symbol/Motorola Solutions line Zebra took over).
pub const MOTOROLA_PEN: u32 = 161;

/// The transmit power table: indices `first_index..=last_index`, each `step_cdbm` above the
/// one before.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PowerTable {
    /// Lowest index.
    pub first_index: u16,
    /// Highest index.
    pub last_index: u16,
    /// Power of the lowest index, hundredths of dBm.
    pub first_cdbm: i16,
    /// Step between two indices, hundredths of dBm.
    pub step_cdbm: i16,
}

impl PowerTable {
    /// Power of `index` in hundredths of dBm; `None` outside the table.
    pub fn cdbm(&self, index: u16) -> Option<i16> {
        (self.first_index..=self.last_index)
            .contains(&index)
            .then(|| self.first_cdbm + (index - self.first_index) as i16 * self.step_cdbm)
    }

    /// Power of `index` in dBm; `None` outside the table.
    pub fn dbm(&self, index: u16) -> Option<f64> {
        self.cdbm(index).map(|c| f64::from(c) / 100.0)
    }

    /// The index whose power is closest to `dbm` (the table's ends beyond it).
    pub fn index(&self, dbm: f64) -> u16 {
        let steps = ((dbm * 100.0 - f64::from(self.first_cdbm)) / f64::from(self.step_cdbm))
            .round()
            .clamp(0.0, f64::from(self.last_index - self.first_index));
        // Clamped to the table's span, which fits u16.
        self.first_index + steps as u16
    }

    /// The indices of the table, lowest first.
    pub fn indices(&self) -> std::ops::RangeInclusive<u16> {
        self.first_index..=self.last_index
    }
}

/// One entry of the C1G2 UHF RF mode table, as advertised, with the link the physics runs it
/// with.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModeEntry {
    /// ModeIdentifier (what C1G2RFControl's ModeIndex names).
    pub id: u32,
    /// EPCHAGTCConformance flag.
    pub conformance: bool,
    /// M: 0 FM0, 1 Miller 2, 2 Miller 4, 3 Miller 8.
    pub m_value: u8,
    /// Forward link modulation: 0 PR-ASK, 1 SSB-ASK, 2 DSB-ASK.
    pub modulation: u8,
    /// Spectral mask: 1 single, 2 multi-interrogator, 3 dense interrogator.
    pub mask: u8,
    /// BDRValue as the reader advertises it.
    pub bdr: u32,
    /// PIEValue (× 1000).
    pub pie: u32,
    /// Tari range, ns.
    pub tari_ns: (u32, u32),
    /// StepTariValue, ns.
    pub step_tari_ns: u32,
    /// The link parameters inventory rounds in this mode run with.
    pub link: RfMode,
}

/// A reader device: identity, capability tables and extensions.
#[derive(Debug, PartialEq)]
pub struct Device {
    /// The name a scenario gives it (`"device"`).
    pub name: &'static str,
    /// The product's name, as its maker writes it.
    pub display_name: &'static str,
    /// DeviceManufacturerName (IANA private enterprise number).
    pub manufacturer: u32,
    /// ModelName.
    pub model: u32,
    /// ReaderFirmwareVersion.
    pub firmware: &'static str,
    /// Antenna ports of the device (the scenario's antennas may use fewer).
    pub antenna_ports: u16,
    /// Transmit power table.
    pub power: PowerTable,
    /// Entries of the receive sensitivity table.
    pub sensitivity_levels: u16,
    /// The RF mode table.
    pub modes: &'static [ModeEntry],
    /// ModeIndex of the factory configuration.
    pub default_mode: u32,
    /// General purpose inputs.
    pub gpis: u16,
    /// General purpose outputs.
    pub gpos: u16,
    /// MaxNumROSpecs (and the number of ROSpecs the reader holds).
    pub max_rospecs: u32,
    /// MaxNumAccessSpecs (and the number of AccessSpecs the reader holds).
    pub max_access_specs: u32,
    /// MaxNumPriorityLevelsSupported.
    pub max_priority_levels: u8,
    /// MaxNumSpecsPerROSpec.
    pub max_specs_per_rospec: u32,
    /// MaxNumOpSpecsPerAccessSpec.
    pub max_op_specs_per_access_spec: u32,
    /// Whether the Impinj extensions (vendor 25882 messages and parameters) exist.
    pub impinj_extensions: bool,
}

impl Device {
    /// The RF mode table entry `id`, if the device has it.
    pub fn mode(&self, id: u32) -> Option<&ModeEntry> {
        self.modes.iter().find(|m| m.id == id)
    }

    /// The device named `name`; `None` for an unknown name.
    pub fn named(name: &str) -> Option<&'static Device> {
        DEVICES.iter().copied().find(|d| d.name == name)
    }
}

/// Every device a scenario can name.
pub const DEVICES: [&Device; 3] = [&IMPINJ_R420, &IMPINJ_R700, &ZEBRA_FX9600];

/// The device of a reader whose scenario names none.
pub const DEFAULT: &Device = &IMPINJ_R420;

/// An Impinj-style entry: the physics' link `link` advertised as Impinj readers do (BDR is
/// the link frequency; Miller 1–2 with DSB-ASK and the multi-interrogator mask, Miller 4–8
/// with PR-ASK and the dense mask).
const fn impinj_entry(id: u32, link: RfMode, tari_ns: (u32, u32)) -> ModeEntry {
    let m_value = match link.miller {
        1 => 0,
        2 => 1,
        4 => 2,
        _ => 3,
    };
    let (modulation, mask) = if link.miller <= 2 { (2, 2) } else { (0, 3) };
    ModeEntry {
        id,
        conformance: false,
        m_value,
        modulation,
        mask,
        bdr: (link.blf_khz * 1000.0 + 0.5) as u32,
        pie: (link.pie * 1000.0 + 0.5) as u32,
        tari_ns,
        step_tari_ns: 0,
        link,
    }
}

/// A link of the physics.
const fn link(miller: u8, blf_khz: f64, pie: f64, tari_us: f64) -> RfMode {
    RfMode {
        tari_us,
        pie,
        blf_khz,
        miller,
        trext: false,
    }
}

/// Impinj's modes 0–3 as the simulator has always run them, and the AutoSet link.
const M0: RfMode = link(1, 640.0, 1.5, 7.14);
const M1: RfMode = link(2, 640.0, 1.5, 6.25);
const M2: RfMode = link(4, 274.0, 2.0, 20.0);
const M3: RfMode = link(8, 170.6, 2.0, 20.0);
const AUTOSET: RfMode = link(4, 250.0, 2.0, 20.0);

/// Impinj Speedway R420, as the simulator has always presented it.
pub const IMPINJ_R420: Device = Device {
    name: "impinj-r420",
    display_name: "Speedway R420",
    manufacturer: IMPINJ_PEN,
    model: 2001002,
    firmware: "5.12.0.240",
    antenna_ports: 4,
    power: PowerTable {
        first_index: 1,
        last_index: 91,
        first_cdbm: 1000,
        step_cdbm: 25,
    },
    sensitivity_levels: 42,
    modes: &[
        impinj_entry(0, M0, (7140, 7140)),
        impinj_entry(1, M1, (6250, 6250)),
        impinj_entry(2, M2, (20000, 20000)),
        impinj_entry(3, M3, (20000, 20000)),
        // Modes 4 (Max Miller) and 5 (Dense Reader M4 Two), Miller 4, and AutoSet 1002–1004,
        // which Impinj's "Reader Modes (RF Modes) Made Easy" lists for Speedway readers (1005,
        // "Impinj Internal, Do Not Use", is not advertised); no link rate is published for 4
        // and 5: they run as mode 2, the AutoSet modes as 1000 (as the R700's).
        impinj_entry(4, M2, (20000, 20000)),
        impinj_entry(5, M2, (20000, 20000)),
        impinj_entry(1000, AUTOSET, (20000, 25000)),
        impinj_entry(1002, AUTOSET, (20000, 25000)),
        impinj_entry(1003, AUTOSET, (20000, 25000)),
        impinj_entry(1004, AUTOSET, (20000, 25000)),
    ],
    default_mode: 1000,
    gpis: 4,
    gpos: 4,
    max_rospecs: 32,
    max_access_specs: 64,
    max_priority_levels: 8,
    max_specs_per_rospec: 32,
    max_op_specs_per_access_spec: 8,
    impinj_extensions: true,
};

/// Impinj R700 (Impinj Reader firmware 8).
pub const IMPINJ_R700: Device = Device {
    name: "impinj-r700",
    display_name: "Impinj R700",
    model: 2001052,
    firmware: "8.4.1",
    power: PowerTable {
        first_index: 1,
        last_index: 93,
        first_cdbm: 1000,
        step_cdbm: 25,
    },
    modes: &[
        impinj_entry(0, M0, (7140, 7140)),
        impinj_entry(1, M1, (6250, 6250)),
        impinj_entry(2, M2, (20000, 20000)),
        impinj_entry(3, M3, (20000, 20000)),
        // Modes 4 (Max Miller) and 5 (Dense Reader M4 Two) are Miller 4; Impinj publishes no
        // link rate for them: run as mode 2.
        impinj_entry(4, M2, (20000, 20000)),
        impinj_entry(5, M2, (20000, 20000)),
        impinj_entry(1002, AUTOSET, (20000, 25000)),
        impinj_entry(1003, AUTOSET, (20000, 25000)),
        impinj_entry(1004, AUTOSET, (20000, 25000)),
    ],
    default_mode: 1002,
    // Two inputs, three outputs: Impinj, "Connecting GPIO Devices to Impinj R700 RAIN RFID
    // Readers".
    gpis: 2,
    gpos: 3,
    ..IMPINJ_R420
};

/// A Zebra FX9600 entry: conformance and dense mask as its table gives them, PR-ASK; the
/// physics' link frequency is BDR × the Miller factor (LLRP's BDR is the data rate).
const fn zebra_entry(
    id: u32,
    m_value: u8,
    bdr: u32,
    pie: u32,
    tari_ns: (u32, u32),
    step: u32,
) -> ModeEntry {
    let miller = 1u8 << m_value;
    ModeEntry {
        id,
        conformance: true,
        m_value,
        modulation: 0,
        mask: 3,
        bdr,
        pie,
        tari_ns,
        step_tari_ns: step,
        link: link(
            miller,
            bdr as f64 * miller as f64 / 1000.0,
            pie as f64 / 1000.0,
            tari_ns.0 as f64 / 1000.0,
        ),
    }
}

/// Zebra FX9600 (8 ports), with Zebra's own LLRP tables and no Impinj extensions.
pub const ZEBRA_FX9600: Device = Device {
    name: "zebra-fx9600",
    display_name: "FX9600",
    manufacturer: MOTOROLA_PEN,
    model: 96008,
    firmware: "3.32.37.0",
    antenna_ports: 8,
    power: PowerTable {
        first_index: 0,
        last_index: 200,
        first_cdbm: 1000,
        step_cdbm: 10,
    },
    sensitivity_levels: 1,
    modes: &[
        // Mode 23 heads the FX9600's table with 668 in BDR, PIE and Tari: no fixed Gen2 link.
        // The simulator runs it with its automatic link, as Impinj's AutoSet.
        ModeEntry {
            id: 23,
            conformance: true,
            m_value: 0,
            modulation: 0,
            mask: 3,
            bdr: 668,
            pie: 668,
            tari_ns: (668, 668),
            step_tari_ns: 668,
            link: AUTOSET,
        },
        zebra_entry(1, 0, 640_000, 1500, (6250, 6250), 0),
        zebra_entry(2, 0, 640_000, 2000, (6250, 6250), 0),
        zebra_entry(3, 1, 120_000, 1500, (25000, 25000), 0),
        zebra_entry(4, 1, 120_000, 1500, (12500, 23000), 2100),
        zebra_entry(5, 1, 120_000, 2000, (25000, 25000), 0),
        zebra_entry(6, 1, 120_000, 2000, (12500, 23000), 2100),
        zebra_entry(7, 1, 128_000, 1500, (25000, 25000), 0),
        zebra_entry(8, 1, 128_000, 1500, (12500, 23000), 2100),
        zebra_entry(9, 1, 128_000, 2000, (25000, 25000), 0),
        zebra_entry(10, 1, 128_000, 2000, (12500, 23000), 2100),
        zebra_entry(11, 1, 160_000, 1500, (12500, 18800), 2100),
    ],
    default_mode: 23,
    gpis: 4,
    gpos: 4,
    impinj_extensions: false,
    ..IMPINJ_R420
};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn power_tables_round_trip_indices() {
        for d in DEVICES {
            let p = d.power;
            for i in p.indices() {
                let dbm = p.dbm(i).expect("index in table");
                assert_eq!(p.index(dbm), i, "{}", d.name);
            }
            assert_eq!(p.dbm(p.last_index + 1), None, "{}", d.name);
        }
        assert_eq!(IMPINJ_R420.power.dbm(0), None);
        assert_eq!(IMPINJ_R420.power.dbm(91), Some(32.5));
        assert_eq!(IMPINJ_R700.power.dbm(93), Some(33.0));
        assert_eq!(ZEBRA_FX9600.power.dbm(0), Some(10.0));
        assert_eq!(ZEBRA_FX9600.power.dbm(200), Some(30.0));
    }

    #[test]
    fn every_default_mode_is_in_its_table_and_names_are_unique() {
        for d in DEVICES {
            assert!(d.mode(d.default_mode).is_some(), "{}", d.name);
            assert_eq!(Device::named(d.name), Some(d));
        }
        assert_eq!(Device::named("acme-9000"), None);
    }

    #[test]
    fn the_scenario_knows_the_same_devices_with_their_ports() {
        let here: Vec<(&str, usize, u16, u16)> = DEVICES
            .iter()
            .map(|d| (d.name, usize::from(d.antenna_ports), d.gpis, d.gpos))
            .collect();
        assert_eq!(here, crate::scenario::device::DEVICES.to_vec());
        assert_eq!(DEFAULT.name, crate::scenario::device::DEVICES[0].0);
    }

    #[test]
    fn a_scenario_reader_without_gpio_counts_gets_its_devices() {
        let none = crate::scenario::gpio::GpioSpec::default();
        for d in DEVICES {
            assert_eq!(none.ports(Some(d.name)), (d.gpis, d.gpos), "{}", d.name);
        }
        assert_eq!(none.ports(None), (DEFAULT.gpis, DEFAULT.gpos));
        assert_eq!(none.ports(Some("impinj-r700")), (2, 3));
        let given = crate::scenario::gpio::GpioSpec {
            gpis: Some(1),
            ..none
        };
        assert_eq!(given.ports(Some("impinj-r700")), (1, 3));
    }

    #[test]
    fn zebra_links_run_at_bdr_times_miller() {
        let m = ZEBRA_FX9600.mode(4).expect("mode 4");
        assert_eq!((m.link.miller, m.link.blf_khz), (2, 240.0));
        let fm0 = ZEBRA_FX9600.mode(1).expect("mode 1");
        assert_eq!((fm0.link.miller, fm0.link.blf_khz), (1, 640.0));
    }
}
