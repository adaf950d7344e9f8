//! Global localization on the Intel map (`docs/global-localization.md`): 20 starts without
//! a pose on the map of a host grid-SLAM run, P = 64, with a 4 000 000-node search, with
//! and without the full turn after the heading windows, and with the device's settings
//! and node budget. Deterministic: the counts are the measured ones (the bar is
//! 19 of 20).

mod common;

use common::{host_sim, succeeds};
use std::path::Path;

fn global(dir: &Path, map: &Path, settings: &[&str]) -> serde_json::Value {
    succeeds(
        host_sim()
            .args(["localize", "--map"])
            .arg(map)
            .args([
                "--dataset",
                "carmen:intel/intel-raw-part.clf",
                "--global",
                "--trials",
                "20",
                "--particles",
                "64",
            ])
            .args(settings)
            .arg("--out")
            .arg(dir),
    );
    let text = std::fs::read_to_string(dir.join("metrics.json")).expect("metrics.json");
    serde_json::from_str::<serde_json::Value>(&text).expect("JSON")["global"].clone()
}

fn full_turn_starts(g: &serde_json::Value) -> Vec<u64> {
    let mut starts: Vec<u64> = g["per_trial"]
        .as_array()
        .expect("trials")
        .iter()
        .filter(|t| t["search"]["full_turn"].as_bool() == Some(true))
        .map(|t| t["start"].as_u64().expect("start"))
        .collect();
    starts.sort_unstable();
    starts
}

#[test]
fn intel_global_localization_with_a_large_budget_and_with_the_devices() {
    let dir = tempfile::tempdir().expect("temporary folder");
    let slam = dir.path().join("slam");
    succeeds(
        host_sim()
            .args([
                "replay",
                "--filter",
                "grid-slam",
                "--dataset",
                "carmen:intel/intel-raw-part.clf",
                "--no-plots",
                "--out",
            ])
            .arg(&slam),
    );
    let map = slam.join("map.yaml");

    let with = global(
        &dir.path().join("with"),
        &map,
        &["--node-budget", "4000000", "--full-turn-below", "0.6"],
    );
    assert_eq!(with["trials"], 20);
    assert_eq!(with["successes"], 20, "{:?}", with["scans_to_converge"]);
    assert_eq!(with["searches_complete"], 20);
    // The starts whose wall directions put the true heading outside every window.
    assert_eq!(full_turn_starts(&with), [389, 407, 450, 795]);

    let without = global(
        &dir.path().join("without"),
        &map,
        &["--node-budget", "4000000", "--full-turn-below", "0"],
    );
    assert_eq!(
        without["successes"], 18,
        "{:?}",
        without["scans_to_converge"]
    );
    assert!(full_turn_starts(&without).is_empty());

    // The device's settings and search budget (21 000 nodes of 30 beams a scan, up to 5
    // scans) on the map's bitmap, as the localizer firmware holds it.
    let device = global(
        &dir.path().join("device"),
        &map,
        &[
            "--beams",
            "90",
            "--preset",
            "microcontroller",
            "--levels",
            "5",
            "--bitmap-only",
        ],
    );
    assert_eq!(device["search"]["node_budget"], 21_000);
    assert_eq!(device["successes"], 17, "{:?}", device["scans_to_converge"]);
    assert_eq!(device["searches_complete"], 13);
}
