//! JSON reports (`metrics.json` and the like), written only when every figure in them is
//! a number.
//!
//! `serde_json` writes a NaN or an infinity as `null`, so a figure that could not be
//! computed would reach the file looking like an absent one. Every command writes its
//! report through [`write_report`], which refuses any `null` and names its key: a figure
//! that does not apply to a run is left out of the document (`skip_serializing_if`, or not
//! inserted), never written as `null`.

use anyhow::{Result, bail};
use serde::Serialize;
use serde_json::Value;
use std::path::Path;

/// Writes `value` to `path` as pretty-printed JSON, refusing (nothing written) a document
/// with a `null` anywhere: the error names the file and the key of the first one
/// (`relations.trans_mean_m`, `robots[2].ate_m`).
pub fn write_report(path: &Path, value: &impl Serialize) -> Result<()> {
    let document = serde_json::to_value(value)?;
    if let Some(key) = first_null(&document, String::new()) {
        bail!(
            "{}: the figure `{key}` is not a finite number (it could not be computed); \
             nothing written",
            path.display()
        );
    }
    super::write_file(path, serde_json::to_string_pretty(&document)? + "\n")
}

/// Removes the entries `keys` of the object `document` whose value is `null`: the parts
/// of a report built with `serde_json::json!` that do not apply to a run (no relations
/// file, no loop closure). Only the keys named: a `null` anywhere else is a figure that
/// could not be computed, which [`write_report`] refuses.
pub fn drop_absent(document: &mut Value, keys: &[&str]) {
    if let Value::Object(map) = document {
        for key in keys {
            if map.get(*key).is_some_and(Value::is_null) {
                map.remove(*key);
            }
        }
    }
}

/// The key path of the first `null` in `value` (depth first, in document order), if any.
fn first_null(value: &Value, at: String) -> Option<String> {
    match value {
        Value::Null => Some(if at.is_empty() {
            "(the document)".into()
        } else {
            at
        }),
        Value::Array(items) => items
            .iter()
            .enumerate()
            .find_map(|(i, v)| first_null(v, format!("{at}[{i}]"))),
        Value::Object(map) => map.iter().find_map(|(k, v)| {
            let key = if at.is_empty() {
                k.clone()
            } else {
                format!("{at}.{k}")
            };
            first_null(v, key)
        }),
        Value::Bool(_) | Value::Number(_) | Value::String(_) => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_nan_figure_is_refused_naming_its_key_and_nothing_is_written() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("metrics.json");
        let doc = serde_json::json!({
            "scans": 3,
            "relations": { "used": 2, "trans_mean_m": f64::NAN },
        });
        let err = write_report(&path, &doc).unwrap_err().to_string();
        assert!(err.contains("`relations.trans_mean_m`"), "{err}");
        assert!(err.contains("metrics.json"), "{err}");
        assert!(!path.exists());
        let inside =
            serde_json::json!({ "robots": [{ "ate_m": 0.1 }, { "ate_m": f64::INFINITY }] });
        let err = write_report(&path, &inside).unwrap_err().to_string();
        assert!(err.contains("`robots[1].ate_m`"), "{err}");
    }

    #[test]
    fn only_the_named_absent_parts_are_dropped() {
        let mut doc = serde_json::json!({ "relations": null, "loop_closure": null, "ate": null });
        drop_absent(&mut doc, &["relations", "loop_closure", "faults"]);
        assert_eq!(doc, serde_json::json!({ "ate": null }));
    }

    #[test]
    fn a_document_of_numbers_is_written_as_it_was() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("metrics.json");
        let doc = serde_json::json!({ "scans": 3, "ate": { "se2": 0.25 }, "name": "x" });
        write_report(&path, &doc).unwrap();
        let back: Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        assert_eq!(back, doc);
    }
}
