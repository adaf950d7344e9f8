//! Grid runs on input they could not use fail, naming the file and the reason (issue 62):
//! every scan skipped, every odometry pose refused, a metric that cannot be computed, a
//! stamp that is not finite. None of them may exit 0 or write a `NaN` or `null` figure.

mod common;

use common::{host_sim, succeeds};
use std::path::{Path, PathBuf};

/// Scans in the logs written below.
const SCANS: usize = 20;

/// A CARMEN log of `SCANS` front scans of 180 beams, each of range `range`, the robot
/// moving 2 cm a scan with odometry `odometry(i)`, stamps 0.1 s apart from 100 s.
fn write_log(path: &Path, range: &str, odometry: impl Fn(usize) -> String) {
    let beams = vec![range; 180].join(" ");
    let mut text = String::from("PARAM robot_front_laser_max 81.9\n");
    for i in 0..SCANS {
        let stamp = 100.0 + 0.1 * i as f64;
        let odom = odometry(i);
        text += &format!("FLASER 180 {beams} {odom} {odom} {stamp:.3} host {stamp:.3}\n");
    }
    std::fs::write(path, text).unwrap();
}

/// Odometry that moves 2 cm a scan along x.
fn moving(i: usize) -> String {
    format!("{:.3} 0 0", 0.02 * i as f64)
}

/// A usable log (every beam 2 m, good odometry) at `dir/good.clf`.
fn good_log(dir: &Path) -> PathBuf {
    let log = dir.join("good.clf");
    write_log(&log, "2.0", moving);
    log
}

/// Runs `host-sim args… --quiet --particles 16 --out dir/out`; returns its standard
/// error, failing the test when it succeeds.
fn fails(dir: &Path, args: &[&str]) -> String {
    let out = host_sim()
        .args(args)
        .args(["--quiet", "--particles", "16", "--out"])
        .arg(dir.join("out"))
        .output()
        .expect("host-sim starts");
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(
        !out.status.success(),
        "{args:?} exited 0 on unusable input; stdout: {}; stderr: {err}",
        String::from_utf8_lossy(&out.stdout)
    );
    err
}

fn carmen(log: &Path) -> String {
    format!("carmen:{}", log.display())
}

/// A map from grid SLAM on the good log (for the localizer).
fn map(dir: &Path) -> PathBuf {
    let out = dir.join("slam");
    let dataset = carmen(&good_log(dir));
    succeeds(
        host_sim()
            .args(["replay", "--filter", "grid-slam", "--dataset", &dataset])
            .args(["--quiet", "--no-plots", "--particles", "16", "--out"])
            .arg(&out),
    );
    out.join("map.yaml")
}

#[test]
fn a_log_whose_every_scan_is_skipped_fails_in_replay_and_localize() {
    let dir = tempfile::tempdir().unwrap();
    let map = map(dir.path());
    for range in ["-1.0", "nan"] {
        let log = dir.path().join("no-beam.clf");
        write_log(&log, range, moving);
        let dataset = carmen(&log);
        let expected = format!(
            "{dataset}: none of the {SCANS} scans could be used ({SCANS} skipped: no usable beam)"
        );
        let replay = ["replay", "--filter", "grid-slam", "--dataset", &dataset];
        let err = fails(dir.path(), &replay);
        assert!(err.contains(&expected), "ranges {range}: {err}");
        let localize = ["localize", "--map", map.to_str().unwrap(), "--dataset"];
        let err = fails(dir.path(), &[&localize[..], &[&dataset]].concat());
        assert!(err.contains(&expected), "ranges {range}: {err}");
    }
}

#[test]
fn a_log_whose_every_odometry_pose_is_refused_fails_in_replay_and_localize() {
    let dir = tempfile::tempdir().unwrap();
    let map = map(dir.path());
    let log = dir.path().join("no-odometry.clf");
    write_log(&log, "2.0", |_| "nan nan nan".to_string());
    let dataset = carmen(&log);
    let expected = format!(
        "{dataset}: none of the {SCANS} odometry poses could be used ({SCANS} refused: not finite)"
    );
    let err = fails(
        dir.path(),
        &["replay", "--filter", "grid-slam", "--dataset", &dataset],
    );
    assert!(err.contains(&expected), "{err}");
    let localize = ["localize", "--map", map.to_str().unwrap(), "--dataset"];
    let err = fails(dir.path(), &[&localize[..], &[&dataset]].concat());
    assert!(err.contains(&expected), "{err}");
}

#[test]
fn a_log_with_only_rear_scans_fails() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("rear.clf");
    let text = std::fs::read_to_string(good_log(dir.path()))
        .unwrap()
        .replace("FLASER", "RLASER");
    std::fs::write(&log, text).unwrap();
    let dataset = carmen(&log);
    let err = fails(
        dir.path(),
        &["replay", "--filter", "grid-slam", "--dataset", &dataset],
    );
    assert!(
        err.contains(&format!(
            "{}: no front laser scans (FLASER); its {SCANS} rear laser scans (RLASER) are not used",
            log.display()
        )),
        "{err}"
    );
}

#[test]
fn a_relation_error_that_cannot_be_computed_fails_naming_the_relations_file() {
    let dir = tempfile::tempdir().unwrap();
    let dataset = carmen(&good_log(dir.path()));
    // One relation, between stamps no scan has.
    let relations = dir.path().join("other.relations");
    std::fs::write(&relations, "5000.0 5001.0 0.1 0 0 0 0 0\n").unwrap();
    let err = fails(
        dir.path(),
        &[
            "replay",
            "--filter",
            "grid-slam",
            "--dataset",
            &dataset,
            "--relations",
            relations.to_str().unwrap(),
        ],
    );
    let expected = format!(
        "{}: the relation error cannot be computed: none of its 1 relations has both stamps \
         within 1 ms of a processed scan",
        relations.display()
    );
    assert!(err.contains(&expected), "{err}");
    assert!(!err.contains("NaN"), "{err}");
}

#[test]
fn a_reference_ate_that_cannot_be_computed_fails_naming_the_reference() {
    let dir = tempfile::tempdir().unwrap();
    let dataset = carmen(&good_log(dir.path()));
    // One reference pose at the first scan's stamp: no SE(2) alignment from one pose.
    let reference = dir.path().join("one.tum");
    std::fs::write(&reference, "100.0 0 0 0 0 0 0 1\n").unwrap();
    let err = fails(
        dir.path(),
        &[
            "replay",
            "--filter",
            "grid-slam",
            "--dataset",
            &dataset,
            "--reference",
            reference.to_str().unwrap(),
        ],
    );
    let expected = format!(
        "{}: the ATE against the reference cannot be computed: its ate_m.se2 needs at least 2 \
         matched poses, 1 matched",
        reference.display()
    );
    assert!(err.contains(&expected), "{err}");
    assert!(!dir.path().join("out").join("metrics.json").exists());
}

#[test]
fn a_stamp_that_is_not_finite_is_refused_with_the_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let log = good_log(dir.path());
    let text = std::fs::read_to_string(&log).unwrap();
    // The third scan (line 4) stamped `nan`.
    let lines: Vec<String> = text
        .lines()
        .enumerate()
        .map(|(i, l)| {
            if i == 3 {
                l.replace("100.200 host", "nan host")
            } else {
                l.to_string()
            }
        })
        .collect();
    assert!(lines[3].contains("nan host"), "{}", lines[3]);
    std::fs::write(&log, lines.join("\n") + "\n").unwrap();
    let dataset = carmen(&log);
    let err = fails(
        dir.path(),
        &["replay", "--filter", "grid-slam", "--dataset", &dataset],
    );
    let expected = format!(
        "{}: CARMEN log line 4: ipc_timestamp NaN is not finite",
        log.display()
    );
    assert!(err.contains(&expected), "{err}");
}

#[test]
fn an_odometry_jump_is_taken_as_a_reset_and_counted() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("jump.clf");
    // Half-way the odometry jumps 5 km (a restarted odometry node, a corrupt pose).
    write_log(&log, "2.0", |i| {
        let x = 0.02 * i as f64 + if i < SCANS / 2 { 0.0 } else { 5000.0 };
        format!("{x:.3} 0 0")
    });
    let out = dir.path().join("out");
    let run = succeeds(
        host_sim()
            .args(["replay", "--quiet", "--no-plots", "--filter", "grid-slam"])
            .args(["--particles", "16", "--dataset", &carmen(&log), "--out"])
            .arg(&out),
    );
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(
        err.contains("1 odometry steps longer than the settings' max_odometry_step_m, taken as odometry resets"),
        "{err}"
    );
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(metrics["input_loss"]["odometry"]["resets"], 1, "{metrics}");
    // The map stays where the robot is: no end point off the grid, the estimate within
    // a metre of where the 19 good steps of 2 cm take it.
    assert_eq!(metrics["grid"]["off_grid_end_points"], 0, "{metrics}");
    let tum = std::fs::read_to_string(out.join("trajectory.tum")).unwrap();
    let last: Vec<f64> = tum
        .lines()
        .last()
        .unwrap()
        .split_whitespace()
        .map(|v| v.parse().unwrap())
        .collect();
    assert!(last[1].abs() < 1.0 && last[2].abs() < 1.0, "{last:?}");
    // A limit that is not a positive length is refused naming the file.
    let config = dir.path().join("grid.toml");
    std::fs::write(&config, "max_odometry_step_m = 0.0\n").unwrap();
    let err = fails(
        dir.path(),
        &[
            "replay",
            "--filter",
            "grid-slam",
            "--config",
            config.to_str().unwrap(),
            "--dataset",
            &carmen(&log),
        ],
    );
    assert!(
        err.contains("grid.toml")
            && err.contains("`max_odometry_step_m` = 0 must be a positive number of metres"),
        "{err}"
    );
}
