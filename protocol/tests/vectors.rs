//! Golden vectors (`protocol/vectors/*.json`): hex frames written by hand from the spec tables,
//! with the JSON the decoder must produce (and re-encode to the same bytes), or the error
//! (offset, parameter path, LLRPStatus code) it must report.

use std::path::PathBuf;

use llrp::raw::from_hex;
use llrp::Message;
use serde_json::Value;

fn vector_files() -> Vec<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("vectors");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .expect("protocol/vectors exists")
        .map(|e| e.expect("dir entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .collect();
    files.sort();
    files
}

fn check(path: &PathBuf) -> Result<(), String> {
    let text = std::fs::read_to_string(path).map_err(|e| e.to_string())?;
    let v: Value = serde_json::from_str(&text).map_err(|e| format!("bad JSON: {e}"))?;
    let hex = v["hex"].as_str().ok_or("no \"hex\"")?;
    let bytes = from_hex(hex).map_err(|e| e.to_string())?;
    match (v.get("message"), v.get("error")) {
        (Some(expected), None) => {
            let msg = Message::decode(&bytes).map_err(|e| format!("decode failed: {e}"))?;
            let got = serde_json::to_value(&msg).map_err(|e| e.to_string())?;
            if &got != expected {
                return Err(format!(
                    "decoded JSON differs\n expected: {expected}\n      got: {got}"
                ));
            }
            let again = msg.to_bytes();
            if again[..] != bytes[..] {
                return Err(format!(
                    "re-encoded bytes differ\n expected: {}\n      got: {}",
                    llrp::raw::to_hex(&bytes),
                    llrp::raw::to_hex(&again)
                ));
            }
            Ok(())
        }
        (None, Some(expected)) => {
            let err = match Message::decode(&bytes) {
                Ok(m) => return Err(format!("decoded but should fail: {m:?}")),
                Err(e) => e,
            };
            let got = serde_json::json!({
                "offset": err.offset,
                "path": err.path_string(),
                "status": err.status_code().to_string(),
            });
            let mut want = expected.clone();
            // Optional: the full LLRPStatus detail, as JSON.
            if let Some(detail) = want.as_object_mut().and_then(|o| o.remove("llrp_status")) {
                let status = serde_json::to_value(err.to_status()).map_err(|e| e.to_string())?;
                let mut status = status;
                if let Some(o) = status.as_object_mut() {
                    o.remove("error_description");
                }
                if status != detail {
                    return Err(format!(
                        "LLRPStatus differs\n expected: {detail}\n      got: {status}"
                    ));
                }
            }
            if got != want {
                return Err(format!(
                    "error differs\n expected: {want}\n      got: {got}\n ({err})"
                ));
            }
            Ok(())
        }
        _ => Err("needs exactly one of \"message\" or \"error\"".into()),
    }
}

#[test]
fn golden_vectors() {
    let files = vector_files();
    assert!(!files.is_empty(), "no vectors found");
    let failures: Vec<String> = files
        .iter()
        .filter_map(|p| check(p).err().map(|e| format!("{}: {e}", p.display())))
        .collect();
    assert!(
        failures.is_empty(),
        "{} of {} vectors failed:\n{}",
        failures.len(),
        files.len(),
        failures.join("\n\n")
    );
}
