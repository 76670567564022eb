//! Frequency plans: the ETSI 4-channel plan, the FCC 50-channel plan in hop order, custom tables.

use serde::de::{self, Deserializer};
use serde::ser::{SerializeMap, Serializer};
use serde::{Deserialize, Serialize};

use super::format::Region;

pub use llrp::units::{ETSI_CHANNELS_KHZ, FCC_HOP_TABLE_KHZ};

/// Default dwell per channel for hopping tables (FCC part 15's 0.4 s maximum), in ms.
pub const DEFAULT_HOP_DWELL_MS: f64 = 400.0;
/// Default dwell per channel for the ETSI plan (EN 302 208: at most 4 s of continuous
/// transmission on one channel), in ms.
pub const DEFAULT_ETSI_DWELL_MS: f64 = 4000.0;

impl Region {
    /// The channel table in hop order: ChannelIndex k (1-based) is `table[k - 1]`.
    pub fn frequencies_khz(&self) -> Vec<u32> {
        match self {
            Region::Etsi => ETSI_CHANNELS_KHZ.to_vec(),
            Region::Fcc => FCC_HOP_TABLE_KHZ.to_vec(),
            Region::Custom { hop_table_khz } => hop_table_khz.clone(),
        }
    }

    /// Whether LLRP advertises a FrequencyHopTable (true) or a FixedFrequencyTable (ETSI).
    pub fn hopping(&self) -> bool {
        !matches!(self, Region::Etsi)
    }

    /// LLRP CommunicationsStandard: 1 FCC part 15, 2 ETSI 302.208, 0 unspecified.
    pub fn communications_standard(&self) -> u16 {
        match self {
            Region::Fcc => 1,
            Region::Etsi => 2,
            Region::Custom { .. } => 0,
        }
    }

    /// ISO 3166 numeric country code a reader reports: 840 (USA) for FCC, 0 otherwise (the
    /// ETSI plan is not one country's; 0 = unspecified).
    pub fn country_code(&self) -> u16 {
        match self {
            Region::Fcc => 840,
            Region::Etsi | Region::Custom { .. } => 0,
        }
    }

    /// Default dwell per channel in ms when the scenario gives none.
    pub fn default_dwell_ms(&self) -> f64 {
        match self {
            Region::Etsi => DEFAULT_ETSI_DWELL_MS,
            Region::Fcc | Region::Custom { .. } => DEFAULT_HOP_DWELL_MS,
        }
    }
}

impl Serialize for Region {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        match self {
            Region::Etsi => serializer.serialize_str("etsi"),
            Region::Fcc => serializer.serialize_str("fcc"),
            Region::Custom { hop_table_khz } => {
                let mut map = serializer.serialize_map(Some(1))?;
                map.serialize_entry("hop_table_khz", hop_table_khz)?;
                map.end()
            }
        }
    }
}

/// The JSON object form of a custom region.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CustomRegion {
    hop_table_khz: Vec<u32>,
}

/// Either a plan name or a custom table.
#[derive(Deserialize)]
#[serde(untagged)]
enum RegionRepr {
    Name(String),
    Custom(CustomRegion),
}

impl<'de> Deserialize<'de> for Region {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        const EXPECTED: &str = "expected \"etsi\", \"fcc\" or {\"hop_table_khz\": [kHz, ...]}";
        let repr = RegionRepr::deserialize(deserializer)
            .map_err(|_| de::Error::custom(format!("invalid region: {EXPECTED}")))?;
        match repr {
            RegionRepr::Name(name) => match name.to_ascii_lowercase().as_str() {
                "etsi" => Ok(Region::Etsi),
                "fcc" => Ok(Region::Fcc),
                _ => Err(de::Error::custom(format!(
                    "unknown region \"{name}\": {EXPECTED}"
                ))),
            },
            RegionRepr::Custom(c) => Ok(Region::Custom {
                hop_table_khz: c.hop_table_khz,
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn region_codes() {
        assert!(!Region::Etsi.hopping());
        assert!(Region::Fcc.hopping());
        assert_eq!(Region::Fcc.communications_standard(), 1);
        assert_eq!(Region::Etsi.communications_standard(), 2);
        assert_eq!(Region::Fcc.country_code(), 840);
        assert_eq!(Region::Etsi.frequencies_khz().len(), 4);
    }

    #[test]
    fn region_json_forms_round_trip() {
        for (json, region) in [
            ("\"etsi\"", Region::Etsi),
            ("\"fcc\"", Region::Fcc),
            (
                "{\"hop_table_khz\":[867000]}",
                Region::Custom {
                    hop_table_khz: vec![867_000],
                },
            ),
        ] {
            let parsed: Region = serde_json::from_str(json).expect("valid region JSON");
            assert_eq!(parsed, region);
            assert_eq!(serde_json::to_string(&region).expect("serializable"), json);
        }
        assert!(serde_json::from_str::<Region>("\"mars\"").is_err());
        assert!(serde_json::from_str::<Region>("{\"hop_table\":[1]}").is_err());
    }
}
