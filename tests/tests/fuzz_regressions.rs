//! Replays every input kept under `fuzz/regressions/<target>/` (crashes the fuzzers found,
//! then fixed, and a few hand-made edge cases) through the fuzz targets' checks.

use microslam_replay_tests::fuzzing::TARGETS;
use std::path::Path;

#[test]
fn kept_fuzz_inputs_pass() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/regressions");
    for (name, check) in TARGETS {
        let dir = root.join(name);
        let entries = std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
        let mut replayed = 0;
        for entry in entries {
            let path = entry.expect("directory entry").path();
            if path.extension().is_some_and(|e| e == "md") {
                continue;
            }
            let data = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            let outcome = std::panic::catch_unwind(|| check(&data));
            assert!(outcome.is_ok(), "{name}: {} fails again", path.display());
            replayed += 1;
        }
        assert!(
            replayed >= 1,
            "{name}: expected at least one kept input in {}",
            dir.display()
        );
    }
}

/// Every fuzz target of `fuzz/Cargo.toml` has its check in `TARGETS` (so its kept
/// inputs are replayed above), and every check names a fuzz target.
#[test]
fn every_fuzz_target_is_replayed() {
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/Cargo.toml");
    let text = std::fs::read_to_string(&manifest).expect("fuzz/Cargo.toml");
    let mut bins: Vec<&str> = text
        .lines()
        .filter_map(|l| l.trim().strip_prefix("name = \""))
        .filter_map(|l| l.strip_suffix('"'))
        .filter(|n| *n != "microslam-fuzz")
        .collect();
    let mut checked: Vec<&str> = TARGETS.iter().map(|(name, _)| *name).collect();
    bins.sort_unstable();
    checked.sort_unstable();
    assert_eq!(
        bins, checked,
        "fuzz targets against the checks in fuzzing::TARGETS"
    );
}
