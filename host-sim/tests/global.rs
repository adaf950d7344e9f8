//! Global localization on the Intel map (`docs/global-localization.md`): 20 starts without
//! a pose on the map of a host grid-SLAM run, P = 64, with a search of 160 M units of
//! work (about 4 M nodes), with and without the full turn after the heading windows, and
//! with the device's settings and work budget; and on the simulated office with the device's settings. Deterministic:
//! the counts are the measured ones (the bar is 19 of 20; trial seed 1 is the
//! draw pinned here, the other draws are in the document), and no trial may track a
//! wrong pose (`tracking_a_wrong_pose`: confirmed outside the tolerance) unless stated.

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
        &["--work-budget", "160000000", "--full-turn-below", "0.6"],
    );
    assert_eq!(with["trials"], 20);
    assert_eq!(with["successes"], 20, "{:?}", with["scans_to_converge"]);
    assert_eq!(with["searches_complete"], 20);
    assert_eq!(with["tracking_a_wrong_pose"], 0);
    // The starts whose wall directions put the true heading outside every window.
    assert_eq!(full_turn_starts(&with), [389, 407, 450, 795]);

    let without = global(
        &dir.path().join("without"),
        &map,
        &["--work-budget", "160000000", "--full-turn-below", "0"],
    );
    assert_eq!(
        without["successes"], 18,
        "{:?}",
        without["scans_to_converge"]
    );
    assert!(full_turn_starts(&without).is_empty());
    // Without it start 389 settles on a hypothesis 9 m and 140° off (0.52 of the beam
    // weight) and confirms it: the one trial that tracks a wrong pose.
    assert_eq!(without["tracking_a_wrong_pose"], 1);

    // The device's settings and search budget (830 000 units of work of 30 beams a scan,
    // up to 10 scans) on the map's bitmap, as the localizer firmware holds it.
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
    assert_eq!(device["search"]["work_budget"], 830_000);
    assert_eq!(device["successes"], 19, "{:?}", device["scans_to_converge"]);
    assert_eq!(device["searches_complete"], 19);
    // 407, 450 and 795 are found by the rest of the turn, searched one minimum score
    // behind the windows, in 110 000-160 000 nodes (2.9 M-4.7 M units of work): 4-6
    // scans of the device's budget.
    assert_eq!(full_turn_starts(&device), [407, 450, 795]);
    // The start it misses (389) ends lost, still searching: none tracks a wrong pose.
    assert_eq!(device["tracking_a_wrong_pose"], 0);
    assert_eq!(device["final_states"]["lost"], 1);
    assert_eq!(device["final_states"]["relocalized"], 0);
    assert_eq!(device["final_states"]["tracking"], 19);
}

#[test]
fn office_global_localization_with_the_devices_settings() {
    let dir = tempfile::tempdir().expect("temporary folder");
    succeeds(
        host_sim()
            .args([
                "sim",
                "--grid-particles",
                "64",
                "--grid-preset",
                "microcontroller",
                "--levels",
                "5",
                "--bitmap-only",
                "--global",
                "--trials",
                "20",
                "--out",
            ])
            .arg(dir.path()),
    );
    let path = dir.path().join("grid/global/metrics.json");
    let text = std::fs::read_to_string(path).expect("metrics.json");
    let g = &serde_json::from_str::<serde_json::Value>(&text).expect("JSON")["global"];
    assert_eq!(g["trials"], 20);
    assert_eq!(g["successes"], 20, "{:?}", g["scans_to_converge"]);
    assert_eq!(g["tracking_a_wrong_pose"], 0);
    assert_eq!(g["final_states"]["tracking"], 20);
}

/// The board's own map: the building-scale SLAM with the firmware's sizes and settings
/// (P = 32, 90 beams, loop closure) writes at the end of the run the map image it would
/// write to flash (`map.bin`: every keyframe at its final graph pose, occupied and free
/// bitmaps); the device's localizer settings then track the log on it and find
/// themselves in it from 20 starts without a pose.
#[test]
fn intel_device_map_image_localizes_and_relocalizes() {
    let dir = tempfile::tempdir().expect("temporary folder");
    let slam = dir.path().join("slam");
    succeeds(
        host_sim()
            .args([
                "replay",
                "--dataset",
                "carmen:intel/intel-raw-part.clf",
                "--particles",
                "32",
                "--loop-closure",
                "--no-plots",
                "--out",
            ])
            .arg(&slam),
    );
    let map = slam.join("map.bin");
    let bytes = std::fs::read(&map).expect("map.bin");
    // 640 × 640 cells of 5 cm (whole tiles of the 128-cell near window): two bitmaps.
    assert_eq!(&bytes[..4], b"MSMP");
    assert_eq!(bytes.len(), 102_456);

    let device = &[
        "--particles",
        "64",
        "--beams",
        "90",
        "--preset",
        "microcontroller",
    ];
    let loc = dir.path().join("localize");
    succeeds(
        host_sim()
            .args(["localize", "--map"])
            .arg(&map)
            .args(["--dataset", "carmen:intel/intel-raw-part.clf", "--no-plots"])
            .args(device)
            .arg("--out")
            .arg(&loc),
    );
    let text = std::fs::read_to_string(loc.join("metrics.json")).expect("metrics.json");
    let m: serde_json::Value = serde_json::from_str(&text).expect("JSON");
    let relation = m["relations"]["trans_mean_m"]
        .as_f64()
        .expect("relation error");
    // Measured: 0.0256 m over 1 030 relations (the bar: 0.035 m).
    assert_eq!(m["relations"]["used"], 1030);
    assert!(relation < 0.027, "{relation}");

    // Trial seed 1 with the device's search budget on the image as the firmware reads
    // it (the free bitmap included). Measured: 20 of 20, none on a wrong pose (trial
    // seeds 1-12: 232 of 240, one on a wrong pose, docs/results-grid.md).
    let g = global(
        &dir.path().join("global"),
        &map,
        &[
            "--beams",
            "90",
            "--preset",
            "microcontroller",
            "--levels",
            "5",
        ],
    );
    assert_eq!(g["successes"], 20, "{:?}", g["scans_to_converge"]);
    assert_eq!(g["tracking_a_wrong_pose"], 0);
}
