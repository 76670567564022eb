//! Reader models: named sets of defaults for the fields of antennas and of the tags'
//! variation (`"reader_model": "impinj-r420"`), applied to the scenario's JSON before it is
//! read, so a value the file gives always wins. docs/measurement.md "Reader models" gives the
//! source of every figure.

use serde_json::{json, Map, Value};

use super::ScenarioError;

/// The reader models a scenario can name.
pub const MODELS: [&str; 3] = ["ideal", "impinj-r420", "impinj-r420-stationary"];

/// The reader's, its antennas' and the tags' variation defaults of `model`.
struct Defaults {
    reader: Value,
    antenna: Value,
    tags: Value,
}

/// The defaults of `model`; `None` for an unknown name.
fn defaults(model: &str) -> Option<Defaults> {
    let (antenna, tags) = match model {
        // The built-in defaults: clean reads (what every scenario got before reader models).
        "ideal" => {
            return Some(Defaults {
                reader: json!({}),
                antenna: json!({}),
                tags: json!({}),
            })
        }
        // Fitted to an Impinj reader's reads of the parked rail (real-reads.md) where no
        // datasheet gives the figure; docs/measurement.md gives each one's source. Its angle-
        // dependent phase error: a small field growing off boresight (fitted to the 24 real
        // runs' residual against the angle) and each tag's own curvature a·θ² (fitted to the
        // real tags' range offsets, ±12 cm RMS).
        "impinj-r420" => (
            r420_antenna(json!({
                "phase_pattern_rad": 0.08,
                "phase_pattern_deg": 4.0,
                "phase_pattern_growth_deg": 25.0
            })),
            r420_tags(json!({
                "phase_pattern_rad": 0.17,
                "phase_pattern_deg": 4.0,
                "phase_curvature_sigma_rad": 2.3
            })),
        ),
        // `impinj-r420` until 2026-12-08: a stationary phase error the same size at every
        // angle and no per-tag curvature.
        "impinj-r420-stationary" => (
            r420_antenna(json!({ "phase_pattern_rad": 0.2, "phase_pattern_deg": 6.0 })),
            r420_tags(json!({ "phase_pattern_rad": 0.45, "phase_pattern_deg": 6.0 })),
        ),
        _ => return None,
    };
    Some(Defaults {
        // Fitted: an R420 whose AISpec ends at each tag rereads one tag every 14.1 ms; the
        // setup plus one round of the default mode (4.3 ms) makes that period. R420s reading
        // continuously read a lone tag 63 times a second (Tagwatch) and, in mode 0, each of 6
        // to 21 tags 35–53 times (Tagbeat): a 15 ms pause after every round.
        reader: json!({ "aispec_setup_ms": 9.8, "round_gap_ms": 15.0 }),
        antenna,
        tags,
    })
}

/// The antenna defaults both Impinj R420 models share, with `pattern`'s phase error.
fn r420_antenna(pattern: Value) -> Value {
    let mut a = json!({
        "beamwidth_deg": 120.0,
        "cable_delay_ns": 35.0,
        "phase_noise_rad": 0.011,
        "phase_noise_ref_dbm": -42.0,
        "noise_exponent": 0.75,
        "rssi_sigma_db": 0.05,
        "rssi_sigma_grows": true,
        "phase_noise_dof": 8.0,
        "phase_outlier_rate": 0.001,
        "rssi_outlier_rate": 0.0005,
        "phase_resolution_bits": 10,
        "backscatter_compression": 0.95,
        "compression_knee_db": 3.0,
        "rssi_tilt_db_per_mhz": 0.17
    });
    fill_from(&mut a, &pattern);
    a
}

/// The tags' variation both Impinj R420 models share, with `pattern`'s phase error.
fn r420_tags(pattern: Value) -> Value {
    let mut t = json!({
        "backscatter_sigma_db": 2.8,
        "delay_sigma_ns": 1.8,
        "channel_phase_sigma_rad": 0.014,
        "channel_rssi_sigma_db": 0.2
    });
    fill_from(&mut t, &pattern);
    t
}

/// Adds `extra`'s keys to the object `v`.
fn fill_from(v: &mut Value, extra: &Value) {
    if let Some(obj) = v.as_object_mut() {
        fill(obj, extra);
    }
}

/// Fills `obj`'s missing keys from `defaults`.
fn fill(obj: &mut Map<String, Value>, defaults: &Value) {
    if let Some(d) = defaults.as_object() {
        for (k, v) in d {
            obj.entry(k.clone()).or_insert_with(|| v.clone());
        }
    }
}

fn model_at(value: Option<&Value>, path: &str) -> Result<Option<Defaults>, ScenarioError> {
    let Some(v) = value else {
        return Ok(None);
    };
    let name = v.as_str().ok_or_else(|| ScenarioError::Json {
        path: path.to_string(),
        reason: format!(
            "must be a reader model's name ({}), got {v}",
            MODELS.join(", ")
        ),
    })?;
    defaults(name)
        .map(Some)
        .ok_or_else(|| ScenarioError::Invalid {
            path: path.to_string(),
            reason: format!(
                "unknown reader model `{name}`; known: {}",
                MODELS.join(", ")
            ),
        })
}

/// Applies the scenario's `reader_model` (to its tags' variation and every reader without
/// its own) and each reader's `reader_model` (to its antennas) to the JSON `scenario`.
pub fn apply(scenario: &mut Value) -> Result<(), ScenarioError> {
    let Some(root) = scenario.as_object_mut() else {
        return Ok(());
    };
    let top = model_at(root.get("reader_model"), "reader_model")?;
    if let Some(d) = &top {
        let v = root
            .entry("tag_variation")
            .or_insert_with(|| Value::Object(Map::new()));
        if let Some(obj) = v.as_object_mut() {
            fill(obj, &d.tags);
        }
    }
    let Some(readers) = root.get_mut("readers").and_then(Value::as_array_mut) else {
        return Ok(());
    };
    for (r, reader) in readers.iter_mut().enumerate() {
        let Some(reader) = reader.as_object_mut() else {
            continue;
        };
        let own = model_at(
            reader.get("reader_model"),
            &format!("readers[{r}].reader_model"),
        )?;
        let Some(d) = own.as_ref().or(top.as_ref()) else {
            continue;
        };
        if let Some(antennas) = reader.get_mut("antennas").and_then(Value::as_array_mut) {
            for a in antennas.iter_mut().filter_map(Value::as_object_mut) {
                fill(a, &d.antenna);
            }
        }
        fill(reader, &d.reader);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_model_fills_only_what_the_file_leaves_out() {
        let mut v = json!({
            "reader_model": "impinj-r420",
            "readers": [
                {"antennas": [{"cable_delay_ns": 10.0}, {}]},
                {"reader_model": "ideal", "antennas": [{}]}
            ]
        });
        apply(&mut v).expect("known models");
        assert_eq!(v["readers"][0]["antennas"][0]["cable_delay_ns"], 10.0);
        assert_eq!(v["readers"][0]["antennas"][1]["cable_delay_ns"], 35.0);
        assert_eq!(v["readers"][0]["antennas"][1]["phase_resolution_bits"], 10);
        // The reader's own model wins over the scenario's.
        assert!(v["readers"][1]["antennas"][0]
            .get("cable_delay_ns")
            .is_none());
        assert_eq!(v["tag_variation"]["backscatter_sigma_db"], 2.8);
        assert_eq!(v["readers"][0]["aispec_setup_ms"], 9.8);
        assert_eq!(v["readers"][0]["round_gap_ms"], 15.0);
        assert!(v["readers"][1].get("aispec_setup_ms").is_none());
    }

    #[test]
    fn the_stationary_r420_keeps_the_old_phase_error_and_the_new_one_curves_each_tag() {
        let of = |model: &str| {
            let mut v = json!({"reader_model": model, "readers": [{"antennas": [{}]}]});
            apply(&mut v).expect("known model");
            v
        };
        let (new, old) = (of("impinj-r420"), of("impinj-r420-stationary"));
        assert_eq!(new["tag_variation"]["phase_curvature_sigma_rad"], 2.3);
        assert_eq!(
            new["readers"][0]["antennas"][0]["phase_pattern_growth_deg"],
            25.0
        );
        assert!(old["tag_variation"]
            .get("phase_curvature_sigma_rad")
            .is_none());
        assert!(old["readers"][0]["antennas"][0]
            .get("phase_pattern_growth_deg")
            .is_none());
        assert_eq!(old["tag_variation"]["phase_pattern_rad"], 0.45);
        assert_eq!(old["readers"][0]["antennas"][0]["phase_pattern_rad"], 0.2);
        // Everything else is shared.
        for m in [&new, &old] {
            assert_eq!(m["readers"][0]["antennas"][0]["cable_delay_ns"], 35.0);
            assert_eq!(m["tag_variation"]["backscatter_sigma_db"], 2.8);
        }
    }

    #[test]
    fn an_unknown_model_is_named_with_the_known_ones() {
        let mut v = json!({"readers": [{"reader_model": "acme-9000", "antennas": []}]});
        let e = apply(&mut v).expect_err("unknown");
        let text = e.to_string();
        assert!(
            text.contains("readers[0].reader_model") && text.contains("impinj-r420"),
            "{text}"
        );
        let mut v = json!({"reader_model": 3});
        assert!(apply(&mut v)
            .expect_err("not a name")
            .to_string()
            .starts_with("reader_model"));
    }
}
