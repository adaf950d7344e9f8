//! `replay --dataset landmarks:<file>` from the command line: a good log is replayed and
//! scored, a log it cannot use fails naming the file and line, never exiting 0.

mod common;

use common::{host_sim, succeeds};
use std::path::Path;

/// A short car run among three posts, with ground truth and the posts' positions.
const CAR: &str = "# a car\n\
    ackermann 0.0 2.0 0.0\n\
    truth 0.0 0 0 0\n\
    sighting 0.0 5.0 0.2 1\n\
    sighting 0.0 6.0 -0.3 2\n\
    ackermann 1.0 2.0 0.0\n\
    truth 1.0 2 0 0\n\
    sighting 1.0 3.1 0.33 1\n\
    sighting 1.0 4.2 -0.45 2\n\
    ackermann 2.0 2.0 0.0\n\
    truth 2.0 4 0 0\n\
    landmark 1 4.9 1.0\n\
    landmark 2 5.7 -1.8\n";

fn replay(dir: &Path, text: &str) -> std::process::Output {
    let log = dir.join("run.txt");
    std::fs::write(&log, text).unwrap();
    host_sim()
        .args(["replay", "--quiet", "--no-plots", "--dataset"])
        .arg(format!("landmarks:{}", log.display()))
        .arg("--out")
        .arg(dir.join("out"))
        .output()
        .expect("host-sim starts")
}

#[test]
fn a_plain_log_is_replayed_and_scored() {
    let dir = tempfile::tempdir().unwrap();
    let out = replay(dir.path(), CAR);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let metrics: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("out/metrics.json")).unwrap(),
    )
    .unwrap();
    assert!(metrics["ate_rmse_m"]["se2"].is_number(), "{metrics}");
    assert!(metrics["landmark_rmse_m"]["se2"].is_number(), "{metrics}");
    assert_eq!(metrics["landmarks_created"], 2);
    // Every record accounted for: 3 ackermann records, 4 sightings.
    let inputs = &metrics["inputs"];
    assert_eq!(inputs["odometry"]["read"], 3, "{inputs}");
    assert_eq!(inputs["odometry"]["used"], 3, "{inputs}");
    let s = &inputs["sightings"];
    assert_eq!(s["read"], 4, "{inputs}");
    let lost: u64 = [
        "reader_dropped",
        "out_of_range",
        "gated",
        "ambiguous",
        "refused",
    ]
    .iter()
    .map(|k| s[k].as_u64().unwrap())
    .sum();
    assert_eq!(s["used"].as_u64().unwrap() + lost, 4, "{inputs}");
    assert!(!metrics.to_string().contains("null"), "{metrics}");
}

#[test]
fn an_unusable_log_fails_naming_the_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    for (text, expected) in [
        ("sighting 1 2 0.1 7\n", "run.txt:1: no motion record"),
        ("velocity 1 0.5 0\n", "run.txt:1: no sighting to use"),
        (
            "velocity 1 0.5 0\nsighting 1 2 0.1 7\nodometry 2 1 1\n",
            "run.txt:3: unknown record type `odometry`",
        ),
        (
            "velocity 1 0.5 0\nsighting 1 -2 0.1 7\n",
            "run.txt:2: sighting field 3 (range): -2 m is not a positive range",
        ),
        // Read without a fault, but nothing of it can be used (issue 62).
        (
            "velocity 1 0.5 0\nsighting 1 200 0.1 7\nsighting 2 250 0.1 7\nvelocity 3 0 0\n",
            "none of the 2 landmark sightings could be used (2 outside the settings' min_range ..= max_range)",
        ),
        (
            "velocity 1 90 0\nsighting 1 2 0.1 7\nvelocity 2 80 0\n",
            "none of the 2 odometry records could be used (2 refused as not finite or beyond the settings' max_speed_mps",
        ),
        // True landmarks none of which was sighted: the map cannot be scored.
        (
            &CAR.replace("landmark 1 ", "landmark 8 ")
                .replace("landmark 2 ", "landmark 9 "),
            "none of the sighted landmark ids (1, 2) is among the true landmarks' (8, 9): the map cannot be scored",
        ),
    ] {
        let out = replay(dir.path(), text);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{text:?} exited 0");
        assert!(err.contains(expected), "{text:?}: {err}");
    }
}

/// A sighted id the true landmarks do not list is mapped, not scored: the run says so on
/// stderr and in `metrics.json`.
#[test]
fn a_sighted_id_the_true_landmarks_do_not_list_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let text = CAR.replace("sighting 1.0 4.2 -0.45 2", "sighting 1.0 4.2 -0.45 5");
    let out = replay(dir.path(), &text);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains("warning: landmarks/run.txt: sighted landmark ids that the recording's true landmarks do not list: 5 (mapped, not scored)"),
        "{err}"
    );
    let metrics: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("out").join("metrics.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(
        metrics["inputs"]["sightings"]["unlisted_ids"],
        serde_json::json!([5])
    );
}

#[test]
fn export_landmarks_writes_a_log_that_reads_back() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("run.txt");
    std::fs::write(&log, CAR).unwrap();
    let copy = dir.path().join("copy.txt");
    succeeds(
        host_sim()
            .args(["export-landmarks", "--quiet", "--dataset"])
            .arg(format!("landmarks:{}", log.display()))
            .arg("--out")
            .arg(&copy),
    );
    let text = std::fs::read_to_string(&copy).unwrap();
    assert_eq!(
        text.lines().filter(|l| l.starts_with("ackermann")).count(),
        3
    );
    assert_eq!(
        text.lines().filter(|l| l.starts_with("landmark")).count(),
        2
    );
}

#[test]
fn a_run_that_loses_a_large_share_says_so_and_a_bad_threshold_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    // One of the three velocity records is implausible (90 m/s): 33 % of the odometry.
    let lossy = CAR
        .replace("ackermann 1.0 2.0 0.0", "velocity 1.0 90 0.0")
        .replace("ackermann 0.0 2.0 0.0", "velocity 0.0 2.0 0.0")
        .replace("ackermann 2.0 2.0 0.0", "velocity 2.0 2.0 0.0");
    let out = replay(dir.path(), &lossy);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    let expected = "1 of 3 odometry records refused (not finite, implausible, or by the filter) (33.3 %), more than the settings' loss_warning_fraction 0.1";
    assert!(
        err.contains(&format!("warning: run.txt: {expected}")) || err.contains(expected),
        "{err}"
    );
    let metrics: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("out/metrics.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(metrics["inputs"]["warnings"][0], expected);
    // A threshold outside 0 ..= 1 is refused naming the file and the key.
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/landmarks.toml");
    let settings = dir.path().join("loss.toml");
    std::fs::write(
        &settings,
        format!(
            "loss_warning_fraction = 2.0\n{}",
            std::fs::read_to_string(shipped).unwrap()
        ),
    )
    .unwrap();
    let log = dir.path().join("run.txt");
    let out = host_sim()
        .args(["replay", "--quiet", "--no-plots", "--config"])
        .arg(&settings)
        .arg("--dataset")
        .arg(format!("landmarks:{}", log.display()))
        .arg("--out")
        .arg(dir.path().join("out2"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("loss.toml")
            && err.contains("loss_warning_fraction = 2 must be within 0 ..= 1"),
        "{err}"
    );
}
