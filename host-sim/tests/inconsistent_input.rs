//! Input whose counts, geometry or values disagree with themselves, or with any physical
//! range, is refused naming the file and the line, message or field at fault (issue 62):
//! a CARMEN beam count that disagrees with the fields that follow, scans of different
//! lengths, scans of no reading, a pose beyond 100 km, options that do not apply; and a
//! `.log.gz` of several gzip members is read to its end. Lines of a message type CARMEN
//! does not have are counted and warned of.

mod common;

use common::{host_sim, succeeds};
use std::io::Write;
use std::path::Path;

/// `SCANS` front scans of 180 beams of 2 m, the robot moving 2 cm a scan, one a line
/// from line 1, stamps 0.1 s apart from 100 s.
const SCANS: usize = 20;

fn line(i: usize) -> String {
    let beams = vec!["2.0"; 180].join(" ");
    let stamp = 100.0 + 0.1 * i as f64;
    let odom = format!("{:.3} 0 0", 0.02 * i as f64);
    format!("FLASER 180 {beams} {odom} {odom} {stamp:.3} host {stamp:.3}\n")
}

/// The good log with line `bad` (1-based) replaced by `with(line)`.
fn log_with(path: &Path, bad: usize, with: impl Fn(String) -> String) {
    let text: String = (0..SCANS)
        .map(|i| if i + 1 == bad { with(line(i)) } else { line(i) })
        .collect();
    std::fs::write(path, text).unwrap();
}

/// Runs `host-sim args…` with a quiet 16-particle grid run into `dir/out`; its standard
/// error, failing the test when it exits 0.
fn fails(dir: &Path, args: &[&str]) -> String {
    let out = host_sim()
        .args(args)
        .args(["--quiet", "--no-plots", "--particles", "16", "--out"])
        .arg(dir.join("out"))
        .output()
        .expect("host-sim starts");
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(
        !out.status.success(),
        "{args:?} exited 0 on bad input; stderr: {err}"
    );
    err
}

fn replay_fails(dir: &Path, log: &Path) -> String {
    let dataset = format!("carmen:{}", log.display());
    fails(dir, &["replay", "--dataset", &dataset])
}

#[test]
fn a_beam_count_that_disagrees_with_its_fields_is_refused_with_the_line() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("count.clf");
    // Line 5 declares 179 readings and carries 180: x would be read from a reading.
    log_with(&log, 5, |l| l.replacen("FLASER 180", "FLASER 179", 1));
    let err = replay_fails(dir.path(), &log);
    let expected = format!(
        "{}: CARMEN log line 5: FLASER declares 179 readings but 189 fields follow",
        log.display()
    );
    assert!(err.contains(&expected), "{err}");
}

#[test]
fn scans_of_different_lengths_are_refused_with_the_line() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("lengths.clf");
    log_with(&log, 7, |l| l.replacen("FLASER 180", "FLASER 181 2.0", 1));
    let err = replay_fails(dir.path(), &log);
    let expected = format!(
        "{}: CARMEN log line 7: FLASER declares 181 readings, the log's first FLASER (line 1) 180",
        log.display()
    );
    assert!(err.contains(&expected), "{err}");
}

#[test]
fn scans_of_no_reading_are_refused_as_such_not_as_beams_0() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("empty.clf");
    let text: String = (0..SCANS)
        .map(|i| format!("FLASER 0 0 0 0 0 0 0 {0}.0 host {0}.0\n", 100 + i))
        .collect();
    std::fs::write(&log, text).unwrap();
    let err = replay_fails(dir.path(), &log);
    let expected = format!(
        "{}: CARMEN log line 1: FLASER declares 0 readings: a scan needs at least one",
        log.display()
    );
    assert!(err.contains(&expected), "{err}");
    assert!(!err.contains("--beams"), "{err}");
}

#[test]
fn an_odometry_jump_beyond_100_km_is_refused_with_the_line_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("jump.clf");
    // Line 9's odometry jumps 10 000 km along x.
    log_with(&log, 9, |l| l.replace(" 0.160 0 0 ", " 1e7 0 0 "));
    let err = replay_fails(dir.path(), &log);
    let expected = format!(
        "{}: CARMEN log line 9: x = 10000000 m is beyond 100 km of the origin",
        log.display()
    );
    assert!(err.contains(&expected), "{err}");
}

#[test]
fn bag_options_on_a_carmen_log_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("good.clf");
    log_with(&log, 0, |l| l);
    let dataset = format!("carmen:{}", log.display());
    let expected = "--lidar-mount applies to `rosbag:` datasets only, not to a `carmen:` dataset";
    let err = fails(
        dir.path(),
        &["replay", "--dataset", &dataset, "--lidar-mount", "0.1,0,0"],
    );
    assert!(err.contains(expected), "{err}");
    let map = dir.path().join("no-map.yaml");
    let err = fails(
        dir.path(),
        &[
            "localize",
            "--map",
            map.to_str().unwrap(),
            "--dataset",
            &dataset,
            "--lidar-mount",
            "0.1,0,0",
            "--scan-topic",
            "/front",
        ],
    );
    assert!(
        err.contains("--lidar-mount, --scan-topic applies to `rosbag:` datasets only"),
        "{err}"
    );
}

#[test]
fn a_log_gz_of_several_gzip_members_is_read_to_the_end() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("parts.log.gz");
    let mut bytes = Vec::new();
    for half in [0..SCANS / 2, SCANS / 2..SCANS] {
        let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        for i in half {
            gz.write_all(line(i).as_bytes()).unwrap();
        }
        bytes.extend(gz.finish().unwrap());
    }
    std::fs::write(&log, bytes).unwrap();
    let out = dir.path().join("out");
    let dataset = format!("carmen:{}", log.display());
    succeeds(
        host_sim()
            .args(["replay", "--dataset", &dataset, "--quiet", "--no-plots"])
            .args(["--particles", "16", "--out"])
            .arg(&out),
    );
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(metrics["scans"], SCANS);
}

/// A full disk under `--animate` (`/dev/full` takes no byte) names the animation's file.
#[cfg(target_os = "linux")]
#[test]
fn a_write_failure_under_animate_names_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("good.clf");
    log_with(&log, 0, |l| l);
    let dataset = format!("carmen:{}", log.display());
    let err = fails(
        dir.path(),
        &["replay", "--dataset", &dataset, "--animate", "/dev/full"],
    );
    assert!(err.contains("writing /dev/full"), "{err}");
}

/// A run that skips a large share of its scans succeeds, but says so on stderr and in
/// `metrics.json`; the threshold is the settings' `loss_warning_fraction`.
#[test]
fn a_run_that_skips_a_large_share_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("lossy.clf");
    // 5 of the 20 scans (lines 3, 6, 9, 12, 15) have no usable beam.
    let text: String = (0..SCANS)
        .map(|i| {
            if i % 3 == 2 && i < 15 {
                line(i).replace(" 2.0", " -1.0")
            } else {
                line(i)
            }
        })
        .collect();
    std::fs::write(&log, text).unwrap();
    let dataset = format!("carmen:{}", log.display());
    let run = |config: Option<&Path>| {
        let out = dir.path().join("out");
        let mut command = host_sim();
        command
            .args(["replay", "--dataset", &dataset, "--quiet", "--no-plots"])
            .args(["--particles", "16", "--out"])
            .arg(&out);
        if let Some(c) = config {
            command.arg("--config").arg(c);
        }
        let stderr = String::from_utf8_lossy(&succeeds(&mut command).stderr).to_string();
        let metrics: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap())
                .unwrap();
        (stderr, metrics)
    };
    let (stderr, metrics) = run(None);
    let expected = format!(
        "warning: {dataset}: 5 of 20 scans (25.0 %) skipped: no usable beam; more than the settings' loss_warning_fraction 0.1"
    );
    assert!(stderr.contains(&expected), "{stderr}");
    let loss = &metrics["input_loss"];
    assert_eq!(loss["scans"]["skipped"], 5);
    assert_eq!(loss["scans"]["used"], 15);
    assert_eq!(loss["scans"]["reason"], "no usable beam");
    assert_eq!(loss["odometry"]["refused"], 0);
    assert_eq!(loss["warnings"].as_array().unwrap().len(), 1);
    // A threshold of one half: no warning.
    let config = dir.path().join("lenient.toml");
    std::fs::write(&config, "loss_warning_fraction = 0.5\n").unwrap();
    let (stderr, metrics) = run(Some(&config));
    assert!(!stderr.contains("warning"), "{stderr}");
    assert_eq!(metrics["input_loss"]["warning_fraction"], 0.5);
    assert!(
        metrics["input_loss"]["warnings"]
            .as_array()
            .unwrap()
            .is_empty()
    );
    // Out of range: refused, naming the file and the key.
    std::fs::write(&config, "loss_warning_fraction = 2.0\n").unwrap();
    let err = fails(
        dir.path(),
        &[
            "replay",
            "--dataset",
            &dataset,
            "--config",
            config.to_str().unwrap(),
        ],
    );
    assert!(
        err.contains("lenient.toml: `loss_warning_fraction` = 2 must be within 0 ..= 1"),
        "{err}"
    );
}

/// A line of a message type CARMEN does not have (here a misspelt `FLASER`: its scan is
/// lost) is skipped, counted and warned of with its first line; CARMEN's own messages the
/// reader does not use (`SYNC`) are counted only.
#[test]
fn a_line_of_an_unknown_message_type_is_counted_and_warned_of_with_its_line() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("misspelt.clf");
    log_with(&log, 7, |l| {
        format!("SYNC 1\n{}", l.replacen("FLASER", "FLASR", 1))
    });
    let dataset = format!("carmen:{}", log.display());
    let out = dir.path().join("out");
    let run = succeeds(
        host_sim()
            .args(["replay", "--dataset", &dataset, "--quiet", "--no-plots"])
            .args(["--particles", "16", "--out"])
            .arg(&out),
    );
    let stderr = String::from_utf8_lossy(&run.stderr);
    let expected = format!(
        "warning: {dataset}: 1 line of a message type CARMEN does not have skipped: `FLASR` (first at line 8)"
    );
    assert!(stderr.contains(&expected), "{stderr}");
    assert!(!stderr.contains("SYNC"), "{stderr}");
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap();
    let loss = &metrics["input_loss"];
    assert_eq!(
        loss["skipped_lines"],
        serde_json::json!({ "FLASR": 1, "SYNC": 1 })
    );
    assert_eq!(loss["scans"]["read"], SCANS - 1);
    assert_eq!(loss["warnings"].as_array().unwrap().len(), 1);
}

/// A log whose only lasers are of a type the reader does not take is refused naming them.
#[test]
fn a_log_of_lasers_the_reader_does_not_take_is_refused_naming_them() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("robotlaser.clf");
    std::fs::write(
        &log,
        "# a log\nROBOTLASER1 0 -1.57 3.14 0.01 30 0.01 0 1 2.0 0\nROBOTLASER1 0\n",
    )
    .unwrap();
    let err = replay_fails(dir.path(), &log);
    assert!(
        err.contains("robotlaser.clf: no laser scans this reader takes (FLASER or RLASER lines); it has 2 ROBOTLASER1, which it does not read"),
        "{err}"
    );
}

#[test]
fn ekf_options_on_a_grid_replay_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("good.clf");
    log_with(&log, 0, |l| l);
    let dataset = format!("carmen:{}", log.display());
    let err = fails(
        dir.path(),
        &[
            "replay",
            "--dataset",
            &dataset,
            "--association",
            "jcbb",
            "--precision",
            "f32",
        ],
    );
    assert!(
        err.contains(
            "--association, --precision applies to the landmark EKF-SLAM (`--filter ekf-slam`), which this replay of `carmen:` does not run"
        ),
        "{err}"
    );
}
