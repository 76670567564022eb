//! The tags' memory as a file (`sim --tag-memory FILE`): every tag an operation has touched,
//! with its four banks, lock bits and killed state, keyed by the EPC the scenario gives it, so
//! that what a run wrote is there in the next. JSON, words in hexadecimal:
//!
//! ```json
//! {"format": "llrp-gateway tag memory 1",
//!  "tags": [{"scenario_epc": "E2000000000000000000000001",
//!            "reserved": "0000000000000000", "epc": "3000E200…", "tid": "E2801160…",
//!            "user": "BEEF…", "locks": ["unlocked", "unlocked", "unlocked",
//!            "permalocked", "unlocked"], "killed": false}]}
//! ```
//!
//! `epc` is EPC memory from the PC word on (the StoredCRC is the tag's own); `locks` follow
//! LLRP's C1G2LockDataField order (kill password, access password, EPC, TID, user). The text
//! is made and read here; the application does the file's IO.

use serde::{Deserialize, Serialize};

use super::memory::{Chip, Lock, TagMemory, LOCK_FIELDS};
use crate::physics::Model;

/// The value of the file's `format` field.
pub const FORMAT: &str = "llrp-gateway tag memory 1";

/// A tag memory file that cannot be used: the field and why.
#[derive(Debug, thiserror::Error)]
#[error("{field}: {reason}")]
pub struct MemoryFileError {
    /// The field's path, e.g. `tags[2].user`.
    pub field: String,
    /// What is wrong with it.
    pub reason: String,
}

fn bad(field: impl Into<String>, reason: impl Into<String>) -> MemoryFileError {
    MemoryFileError {
        field: field.into(),
        reason: reason.into(),
    }
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    format: String,
    tags: Vec<SavedTag>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct SavedTag {
    scenario_epc: String,
    reserved: String,
    epc: String,
    tid: String,
    user: String,
    locks: [String; LOCK_FIELDS],
    killed: bool,
}

fn hex_words(words: &[u16]) -> String {
    words.iter().map(|w| format!("{w:04X}")).collect()
}

fn words_of(text: &str, field: &str) -> Result<Vec<u16>, MemoryFileError> {
    if !text.len().is_multiple_of(4) || !text.is_ascii() {
        return Err(bad(field, "not whole 16-bit words of hexadecimal digits"));
    }
    (0..text.len())
        .step_by(4)
        .map(|i| {
            u16::from_str_radix(&text[i..i + 4], 16)
                .map_err(|_| bad(field, format!("{:?} is not hexadecimal", &text[i..i + 4])))
        })
        .collect()
}

fn lock_name(l: Lock) -> &'static str {
    match (l.locked, l.perma) {
        (false, false) => "unlocked",
        (true, false) => "locked",
        (true, true) => "permalocked",
        (false, true) => "permaunlocked",
    }
}

fn lock_of(name: &str, field: &str) -> Result<Lock, MemoryFileError> {
    let (locked, perma) = match name {
        "unlocked" => (false, false),
        "locked" => (true, false),
        "permalocked" => (true, true),
        "permaunlocked" => (false, true),
        other => {
            return Err(bad(
                field,
                format!("{other:?}: one of unlocked, locked, permalocked, permaunlocked"),
            ))
        }
    };
    Ok(Lock { locked, perma })
}

/// The file's text for every tag of `memory` an operation has touched.
pub fn to_json(model: &Model, memory: &TagMemory) -> String {
    let tags = memory
        .snapshot()
        .into_iter()
        .map(|(tag, c)| SavedTag {
            scenario_epc: llrp_gateway_vocab::reads::hex_upper(model.tag_epc(tag).as_bytes()),
            reserved: hex_words(&c.reserved),
            epc: hex_words(&c.epc),
            tid: hex_words(&c.tid),
            user: hex_words(&c.user),
            locks: c.locks.map(|l| lock_name(l).to_string()),
            killed: c.killed,
        })
        .collect();
    let file = File {
        format: FORMAT.into(),
        tags,
    };
    // Strings, booleans and arrays only: serde_json cannot fail on them.
    serde_json::to_string_pretty(&file).unwrap_or_default() + "\n"
}

/// Puts the tags of the file's `text` into `memory`; every tag must be one of `model`'s
/// scenario (by its scenario EPC), and nothing is changed unless the whole file is good.
pub fn restore(model: &Model, memory: &TagMemory, text: &str) -> Result<usize, MemoryFileError> {
    let file: File = serde_json::from_str(text).map_err(|e| bad("(file)", e.to_string()))?;
    if file.format != FORMAT {
        return Err(bad(
            "format",
            format!("{:?}, expected {FORMAT:?}", file.format),
        ));
    }
    let by_epc: std::collections::HashMap<String, usize> = (0..model.tag_count())
        .map(|k| {
            (
                llrp_gateway_vocab::reads::hex_upper(model.tag_epc(k).as_bytes()),
                k,
            )
        })
        .collect();
    let mut chips = Vec::with_capacity(file.tags.len());
    for (i, t) in file.tags.iter().enumerate() {
        let at = |f: &str| format!("tags[{i}].{f}");
        let key = t.scenario_epc.to_ascii_uppercase();
        let Some(&tag) = by_epc.get(&key) else {
            return Err(bad(
                at("scenario_epc"),
                format!("{key}: no tag of the scenario"),
            ));
        };
        let shipped = Chip::from_model(model, tag);
        let reserved = words_of(&t.reserved, &at("reserved"))?;
        let reserved: [u16; 4] = reserved
            .try_into()
            .map_err(|_| bad(at("reserved"), "must be 4 words (the two passwords)"))?;
        let epc = words_of(&t.epc, &at("epc"))?;
        if epc.len() != shipped.epc.len() {
            return Err(bad(
                at("epc"),
                format!(
                    "{} words, the tag's EPC memory has {}",
                    epc.len(),
                    shipped.epc.len()
                ),
            ));
        }
        let (tid, user) = (
            words_of(&t.tid, &at("tid"))?,
            words_of(&t.user, &at("user"))?,
        );
        for (name, got, want) in [("tid", &tid, &shipped.tid), ("user", &user, &shipped.user)] {
            if got.len() != want.len() {
                return Err(bad(
                    at(name),
                    format!("{} words, the tag's bank has {}", got.len(), want.len()),
                ));
            }
        }
        let mut locks = [Lock::default(); LOCK_FIELDS];
        for (k, (slot, name)) in locks.iter_mut().zip(&t.locks).enumerate() {
            *slot = lock_of(name, &at(&format!("locks[{k}]")))?;
        }
        let chip = Chip {
            reserved,
            epc,
            tid,
            user,
            locks,
            killed: t.killed,
        };
        chips.push((tag, chip));
    }
    let n = chips.len();
    memory.restore(chips);
    Ok(n)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::Scenario;

    fn model() -> Model {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../fixtures/scenarios/s1.json"
        );
        let s = Scenario::load(std::path::Path::new(path)).expect("S1 loads");
        Model::new(&s, 0)
    }

    #[test]
    fn what_a_run_wrote_comes_back_in_the_next() {
        let model = model();
        let memory = TagMemory::new();
        memory.with_chip(&model, 2, |c| {
            c.user[0] = 0xBEEF;
            c.locks[4] = Lock {
                locked: true,
                perma: false,
            };
        });
        memory.with_chip(&model, 0, |c| c.killed = true);
        let text = to_json(&model, &memory);
        let next = TagMemory::new();
        assert_eq!(restore(&model, &next, &text).expect("a good file"), 2);
        assert_eq!(next.snapshot(), memory.snapshot());
        assert_eq!(next.epc(&model, 0), None, "killed stays killed");
        assert_eq!(next.chip(&model, 2).user[0], 0xBEEF);
        assert!(next.generation() > 0);
    }

    #[test]
    fn a_bad_file_names_the_field_and_changes_nothing() {
        let model = model();
        let memory = TagMemory::new();
        memory.with_chip(&model, 1, |c| c.user[0] = 1);
        let good = to_json(&model, &memory);
        let cases = [
            (good.replace("\"unlocked\"", "\"open\""), "tags[0].locks[0]"),
            (good.replace(FORMAT, "other"), "format"),
            (
                good.replacen("\"user\": \"0001", "\"user\": \"01", 1),
                "tags[0].user",
            ),
            (
                good.replacen("\"scenario_epc\": \"", "\"scenario_epc\": \"FF", 1),
                "tags[0].scenario_epc",
            ),
        ];
        for (text, field) in cases {
            let fresh = TagMemory::new();
            let e = restore(&model, &fresh, &text).expect_err(field);
            assert_eq!(e.field, field, "{e}");
            assert!(fresh.snapshot().is_empty(), "{field}: nothing restored");
        }
    }
}
