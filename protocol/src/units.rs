//! Unit conversions for report fields: phase angle, RSSI, Doppler and channel frequency.
//!
//! The one place that converts between physical values and the numbers on the wire; the
//! simulated reader reports through these functions and clients read through them.
//!
//! ```
//! use llrp::units::{dbm_to_centi_dbm, dbm_to_peak_rssi, HopTable};
//!
//! // PeakRSSI is the reported ImpinjPeakRSSI truncated toward zero (an R420 reports
//! // ImpinjPeakRSSI -6850 with PeakRSSI -68).
//! assert_eq!(dbm_to_centi_dbm(-68.5), -6850);
//! assert_eq!(dbm_to_peak_rssi(-68.5), -68);
//! // ChannelIndex is 1-based into the table the reader advertises.
//! let etsi = HopTable::etsi();
//! assert_eq!(etsi.frequency_khz(1), Some(865_700));
//! ```

use std::f64::consts::TAU;

use crate::params::RegulatoryCapabilities;

/// The ETSI EN 302 208 four-channel plan, kHz (ChannelIndex 1..4).
pub const ETSI_CHANNELS_KHZ: [u32; 4] = [865_700, 866_300, 866_900, 867_500];

/// The FCC Part 15 plan (902.75 + 0.5·k MHz, k = 0..49) in the hop order llrp-gateway's
/// simulated reader advertises and hops through: a fixed pseudo-random order (a Fisher–Yates
/// shuffle drawn once with SplitMix64), since a real reader also lists its table in hop order,
/// not ascending. Another reader's order is its own: read it with
/// [`HopTable::from_capabilities`].
pub const FCC_HOP_TABLE_KHZ: [u32; 50] = [
    920_250, 904_750, 903_750, 912_750, 904_250, 922_750, 919_250, 918_250, 922_250, 913_750,
    923_250, 914_250, 909_750, 903_250, 924_250, 905_750, 925_250, 907_250, 902_750, 924_750,
    915_750, 915_250, 917_250, 912_250, 916_750, 921_750, 927_250, 907_750, 910_750, 917_750,
    918_750, 911_750, 921_250, 909_250, 925_750, 908_750, 906_250, 926_750, 910_250, 920_750,
    919_750, 913_250, 906_750, 911_250, 914_750, 916_250, 908_250, 926_250, 905_250, 923_750,
];

/// Raw Impinj phase (0..4095 over one turn) to radians in [0, 2π).
pub fn phase_to_radians(raw: u16) -> f64 {
    f64::from(raw & 0x0FFF) * TAU / 4096.0
}

/// Radians (any value) to raw Impinj phase 0..4095, rounded to the nearest step.
pub fn radians_to_phase(rad: f64) -> u16 {
    let turns = rad.rem_euclid(TAU) / TAU;
    ((turns * 4096.0).round() as u32 % 4096) as u16
}

/// Hundredths of dBm (ImpinjPeakRSSI) to dBm.
pub fn centi_dbm_to_dbm(raw: i16) -> f64 {
    f64::from(raw) / 100.0
}

/// dBm to hundredths of dBm, rounded and saturated to the i16 range.
pub fn dbm_to_centi_dbm(dbm: f64) -> i16 {
    (dbm * 100.0)
        .round()
        .clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
}

/// dBm to the whole-dBm PeakRSSI field as Impinj readers report it: the ImpinjPeakRSSI value
/// ([`dbm_to_centi_dbm`]) truncated toward zero, so the two fields of one read never disagree
/// (an R420 reports ImpinjPeakRSSI −6850 with PeakRSSI −68).
pub fn dbm_to_peak_rssi(dbm: f64) -> i8 {
    let whole = i32::from(dbm_to_centi_dbm(dbm)) / 100; // integer division truncates toward 0
    whole.clamp(i32::from(i8::MIN), i32::from(i8::MAX)) as i8
}

/// Raw ImpinjRFDopplerFrequency (Hz × 16) to Hz.
pub fn doppler_to_hz(raw: i16) -> f64 {
    f64::from(raw) / 16.0
}

/// Hz to raw ImpinjRFDopplerFrequency, rounded and saturated.
pub fn hz_to_doppler(hz: f64) -> i16 {
    (hz * 16.0)
        .round()
        .clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
}

/// A reader's channel table: frequencies in kHz, indexed by the 1-based ChannelIndex.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct HopTable {
    /// HopTableID (1 for most readers).
    pub id: u8,
    /// Channel frequencies in kHz, in table (hop) order.
    pub frequencies_khz: Vec<u32>,
}

impl HopTable {
    /// FCC Part 15: 50 channels 902.75..927.25 MHz, 500 kHz apart, in the hop order
    /// llrp-gateway's simulated reader advertises ([`FCC_HOP_TABLE_KHZ`]).
    pub fn fcc() -> Self {
        HopTable {
            id: 1,
            frequencies_khz: FCC_HOP_TABLE_KHZ.to_vec(),
        }
    }

    /// ETSI EN 302 208 4-channel plan: 865.7, 866.3, 866.9, 867.5 MHz.
    pub fn etsi() -> Self {
        HopTable {
            id: 1,
            frequencies_khz: ETSI_CHANNELS_KHZ.to_vec(),
        }
    }

    /// The table a reader advertises in its RegulatoryCapabilities: the FrequencyHopTable
    /// with `hop_table_id` in a hopping region, the FixedFrequencyTable otherwise (whose ID
    /// is reported as 0); `None` if the capabilities carry no such table.
    pub fn from_capabilities(caps: &RegulatoryCapabilities, hop_table_id: u8) -> Option<Self> {
        let info = &caps.uhf_band_capabilities.as_ref()?.frequency_information;
        if info.hopping {
            let t = info
                .frequency_hop_table
                .iter()
                .find(|t| t.hop_table_id == hop_table_id)?;
            Some(HopTable {
                id: t.hop_table_id,
                frequencies_khz: t.frequencies.clone(),
            })
        } else {
            let t = info.fixed_frequency_table.as_ref()?;
            Some(HopTable {
                id: 0,
                frequencies_khz: t.frequencies.clone(),
            })
        }
    }

    /// Frequency in kHz of 1-based `channel_index`, if it is in the table.
    pub fn frequency_khz(&self, channel_index: u16) -> Option<u32> {
        let k = usize::from(channel_index).checked_sub(1)?;
        self.frequencies_khz.get(k).copied()
    }

    /// Wavelength in metres of 1-based `channel_index`.
    pub fn wavelength_m(&self, channel_index: u16) -> Option<f64> {
        const C: f64 = 299_792_458.0;
        self.frequency_khz(channel_index)
            .map(|f| C / (f64::from(f) * 1e3))
    }

    /// 1-based ChannelIndex of a frequency in kHz, if the table has it.
    pub fn channel_index(&self, khz: u32) -> Option<u16> {
        let k = self.frequencies_khz.iter().position(|&f| f == khz)?;
        u16::try_from(k + 1).ok()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn phase_round_trips_every_step() {
        for raw in 0..4096u16 {
            assert_eq!(radians_to_phase(phase_to_radians(raw)), raw);
        }
        assert_eq!(radians_to_phase(TAU), 0);
        assert_eq!(radians_to_phase(-TAU / 4.0), 3072);
        assert!((phase_to_radians(1024) - TAU / 4.0).abs() < 1e-12);
    }

    #[test]
    fn rssi_and_doppler_scales() {
        assert_eq!(centi_dbm_to_dbm(-6850), -68.5);
        assert_eq!(dbm_to_centi_dbm(-68.504), -6850);
        assert_eq!(dbm_to_peak_rssi(-68.5), -68);
        // The hundredths are rounded first: -68.996 dBm is reported as -6900, so -69.
        assert_eq!(dbm_to_peak_rssi(-68.996), -69);
        assert_eq!(dbm_to_peak_rssi(-68.994), -68);
        assert_eq!(dbm_to_peak_rssi(-300.0), -128);
        assert_eq!(doppler_to_hz(-320), -20.0);
        assert_eq!(hz_to_doppler(2.5), 40);
    }

    #[test]
    fn channel_index_is_one_based() {
        let fcc = HopTable::fcc();
        assert_eq!(fcc.frequency_khz(1), Some(920_250));
        assert_eq!(fcc.frequency_khz(50), Some(923_750));
        assert_eq!(fcc.frequency_khz(0), None);
        assert_eq!(fcc.frequency_khz(51), None);
        assert_eq!(fcc.channel_index(902_750), Some(19));
        let mut sorted = fcc.frequencies_khz.clone();
        sorted.sort_unstable();
        let ascending: Vec<u32> = (0..50).map(|i| 902_750 + 500 * i).collect();
        assert_eq!(sorted, ascending, "every FCC channel once");
        let etsi = HopTable::etsi();
        assert_eq!(etsi.frequency_khz(4), Some(867_500));
        let l = etsi.wavelength_m(1).unwrap();
        assert!((l - 0.346_30).abs() < 1e-4, "{l}");
    }
}
