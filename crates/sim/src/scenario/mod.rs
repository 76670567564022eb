//! Scenarios: the world a simulated reader lives in — tags, readers, antennas and how they
//! move — read from JSON files and checked before use.

mod defaults;
pub mod device;
pub mod faults;
mod format;
pub mod gpio;
mod hardware_checks;
mod mount;
pub mod profile;
pub mod recorded;
pub mod region;
pub mod tagmem;
mod validate;

use serde::{Deserialize, Serialize};

pub use format::{
    AntennaSpec, Mount, NoiseDist, Path, PhaseOffsets, Pose, ReaderSpec, Reflector, Region,
    RobotSpec, RssiModel, TagSpec, TagVariation, VerticalAxis, WorldBounds, DEFAULT_RSSI_NOISE,
};
pub use format::{PoseEstimate, PoseEstimateKind};

/// A complete simulation scenario.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Short name.
    pub name: String,
    /// What the scenario models and where its geometry comes from.
    #[serde(default)]
    pub description: String,
    /// Seed of every random draw of the simulation.
    pub seed: u64,
    /// Box containing everything.
    pub world: WorldBounds,
    /// Reflecting planes (image method); none means free space.
    #[serde(default)]
    pub reflectors: Vec<Reflector>,
    /// The tags.
    pub tags: Vec<TagSpec>,
    /// Spread of the tags' sensitivity and backscatter strength.
    #[serde(default)]
    pub tag_variation: TagVariation,
    /// The reader model (docs/measurement.md "Reader models") whose defaults the tags'
    /// variation and every reader without its own model took.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reader_model: Option<String>,
    /// The readers.
    pub readers: Vec<ReaderSpec>,
    /// One line for each field the file gives that the models no longer use, saying what
    /// replaced it (filled in by loading).
    #[serde(skip)]
    pub notices: Vec<String>,
}

/// Why a scenario could not be loaded. Displays as `<path>: <reason>`.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    /// A file could not be read.
    #[error("{file}: {source}")]
    Io {
        /// The file.
        file: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The JSON is malformed or does not fit the format (unknown field, wrong type ...).
    #[error("{path}: {reason}")]
    Json {
        /// JSON path of the offending value, e.g. `readers[0].antennas[1].gain_dbi`.
        path: String,
        /// What is wrong.
        reason: String,
    },
    /// A value is out of range or inconsistent.
    #[error("{path}: {reason}")]
    Invalid {
        /// JSON path of the offending value.
        path: String,
        /// What is wrong, with the value found.
        reason: String,
    },
}

impl Scenario {
    /// Parses and validates a scenario; relative recorded-pose files resolve against the
    /// current directory.
    pub fn from_json(text: &str) -> Result<Scenario, ScenarioError> {
        Self::from_json_in(text, std::path::Path::new("."))
    }

    /// Reads, parses and validates a scenario file; relative recorded-pose files resolve
    /// against the file's directory.
    pub fn load(path: &std::path::Path) -> Result<Scenario, ScenarioError> {
        Self::load_with(path, None)
    }

    /// [`Scenario::load`] with the scenario-wide reader model `model` when given
    /// ([`Scenario::from_json_with`]).
    pub fn load_with(
        path: &std::path::Path,
        model: Option<&str>,
    ) -> Result<Scenario, ScenarioError> {
        let text = std::fs::read_to_string(path).map_err(|source| ScenarioError::Io {
            file: path.display().to_string(),
            source,
        })?;
        let dir = path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(std::path::Path::new("."));
        Self::from_json_with(&text, dir, model)
    }

    /// The embedded default scenario S1 with the reader model `model` when given.
    pub fn default_s1_with(model: Option<&str>) -> Result<Scenario, ScenarioError> {
        Self::from_json_with(
            include_str!("../../../../fixtures/scenarios/s1.json"),
            std::path::Path::new("."),
            model,
        )
    }

    /// The embedded default scenario S1 (`fixtures/scenarios/s1.json`).
    pub fn default_s1() -> Scenario {
        Scenario::from_json(include_str!("../../../../fixtures/scenarios/s1.json"))
            // The embedded file is validated by the unit test `default_s1_is_valid`.
            .expect("embedded s1.json is a valid scenario")
    }

    /// Parses and validates, resolving relative files against `dir`.
    pub fn from_json_in(text: &str, dir: &std::path::Path) -> Result<Scenario, ScenarioError> {
        Self::from_json_with(text, dir, None)
    }

    /// [`Scenario::from_json_in`] with the scenario-wide `reader_model` set to `model` when
    /// given (in place of the file's own; readers that name their own keep it).
    pub fn from_json_with(
        text: &str,
        dir: &std::path::Path,
        model: Option<&str>,
    ) -> Result<Scenario, ScenarioError> {
        let mut value: serde_json::Value =
            serde_json::from_str(text).map_err(|e| ScenarioError::Json {
                path: "(root)".to_string(),
                reason: e.to_string(),
            })?;
        if let (Some(m), Some(root)) = (model, value.as_object_mut()) {
            root.insert("reader_model".to_string(), serde_json::Value::from(m));
        }
        profile::apply(&mut value)?;
        let mut scenario: Scenario = serde_path_to_error::deserialize(value).map_err(|e| {
            let path = json_path(&e.path().to_string());
            let reason = e.into_inner().to_string();
            // A mount reports the path inside it at the start of its message.
            match reason
                .strip_prefix(mount::INNER_PATH_MARK)
                .and_then(|r| r.split_once(": "))
            {
                Some((inner, rest)) => ScenarioError::Json {
                    path: format!("{path}.{inner}"),
                    reason: rest.to_string(),
                },
                None => ScenarioError::Json { path, reason },
            }
        })?;
        scenario.fill_defaults();
        validate::validate(&scenario)?;
        validate::load_recorded(&mut scenario, dir)?;
        Ok(scenario)
    }

    /// Replaces defaults that depend on other fields (the region's dwell time) and notes the
    /// fields given that the chosen models do not use.
    fn fill_defaults(&mut self) {
        for (r, reader) in self.readers.iter_mut().enumerate() {
            if reader.hop_dwell_ms.is_nan() {
                reader.hop_dwell_ms = reader.region.default_dwell_ms();
            }
            if let Some(rate) = reader.reads_per_second {
                self.notices.push(format!(
                    "readers[{r}].reads_per_second ({rate}) no longer sets anything: the Gen2 \
                     inventory model (RF mode, Q algorithm, sessions) sets the read rate"
                ));
            }
            for (a, antenna) in reader.antennas.iter().enumerate() {
                if antenna.rssi_noise.is_some() && antenna.rssi_model == RssiModel::Reader {
                    self.notices.push(format!(
                        "readers[{r}].antennas[{a}].rssi_noise is used only with \
                         \"rssi_model\": \"gazebo_eq5\"; the default reader model takes its \
                         noise from rssi_sigma_db ({} dB)",
                        antenna.rssi_sigma_db
                    ));
                }
            }
        }
    }
}

/// serde_path_to_error writes the root as `.`; say `(root)` instead.
fn json_path(path: &str) -> String {
    if path == "." || path.is_empty() {
        "(root)".to_string()
    } else {
        path.to_string()
    }
}

#[cfg(test)]
mod tests;
