//! Replays every input kept under `fuzz/regressions/<target>/` (crashes the fuzzers found,
//! then fixed, and a few hand-made edge cases) through the fuzz targets' checks.

use microslam_replay_tests::fuzzing::TARGETS;
use std::path::Path;

#[test]
fn kept_fuzz_inputs_pass() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/regressions");
    let mut replayed = 0;
    for (name, check) in TARGETS {
        let dir = root.join(name);
        let entries = std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
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
    }
    assert!(
        replayed >= TARGETS.len(),
        "expected at least one kept input per target, replayed {replayed}"
    );
}
