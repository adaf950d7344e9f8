//! Readers on the real MRCLAM files and on damaged copies: a bad line is an error that
//! names the file and the line number.

use host_sim::inputs::readers::{self, DatasetSpec, mrclam};
use microslam::event::EventKind;
use std::path::Path;

fn dataset6() -> std::path::PathBuf {
    host_sim::domain::datasets::resolve("mrclam", "dataset6").expect("MRCLAM dataset 6")
}

#[test]
fn dataset6_robot1_events_are_time_ordered_and_robots_dropped() {
    let rec = readers::read(&DatasetSpec::Mrclam("dataset6".into()), 1).unwrap();
    assert!(rec.events.windows(2).all(|w| w[0].stamp <= w[1].stamp));
    let odometry = rec
        .events
        .iter()
        .filter(|e| matches!(e.kind, EventKind::Velocity { .. }))
        .count();
    let sightings: Vec<u32> = rec.sighted_ids().collect();
    // Line counts of the files minus their 4 header lines.
    assert_eq!(odometry, 61_789 - 4);
    // 1942 sightings: 407 of robots (barcodes 14, 41, 32, 23) and 1 of barcode 43,
    // which Barcodes.dat does not list.
    assert_eq!(sightings.len(), 1942 - 408);
    assert_eq!(rec.dropped_sightings, 408);
    assert!(sightings.iter().all(|id| (6..=20).contains(id)));
    assert_eq!(rec.landmarks.len(), 15);
    // Ground truth ends before the odometry on dataset 6.
    let gt_end = rec.ground_truth.last().unwrap().stamp;
    assert!(gt_end < rec.events.last().unwrap().stamp - 100.0);
    assert!(rec.initial_pose.is_some());
}

/// Copies dataset 6 into a temp folder with one file replaced by `edit(text)`.
fn damaged(file: &str, edit: impl Fn(&str) -> String) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for name in [
        "Barcodes.dat",
        "Landmark_Groundtruth.dat",
        "Robot1_Groundtruth.dat",
        "Robot1_Measurement.dat",
        "Robot1_Odometry.dat",
    ] {
        let text = std::fs::read_to_string(dataset6().join(name)).unwrap();
        let text = if name == file { edit(&text) } else { text };
        std::fs::write(dir.path().join(name), text).unwrap();
    }
    dir
}

fn error_of(dir: &Path) -> String {
    format!("{:#}", mrclam::read(dir, 1).unwrap_err())
}

#[test]
fn truncated_last_line_names_file_and_line() {
    // Cut the odometry file in the middle of its last line.
    let dir = damaged("Robot1_Odometry.dat", |t| {
        let cut = t.trim_end().rfind('\t').unwrap();
        t[..cut].to_owned()
    });
    let e = error_of(dir.path());
    assert!(e.contains("Robot1_Odometry.dat:61789:"), "{e}");
    assert!(e.contains("truncated line: 2 of 3 fields"), "{e}");
}

#[test]
fn empty_odometry_is_an_error_naming_the_file() {
    // The header comments only: no sample.
    let dir = damaged("Robot1_Odometry.dat", |t| {
        t.lines()
            .filter(|l| l.starts_with('#'))
            .map(|l| format!("{l}\n"))
            .collect()
    });
    let e = error_of(dir.path());
    assert!(
        e.contains("Robot1_Odometry.dat") && e.contains("no odometry samples"),
        "{e}"
    );
}

#[test]
fn corrupt_number_names_file_line_and_field() {
    let dir = damaged("Robot1_Measurement.dat", |t| {
        let mut lines: Vec<String> = t.lines().map(str::to_owned).collect();
        lines[9] = lines[9].replacen('.', ",", 1); // line 10: "1248444189,828 …"
        lines.join("\n")
    });
    let e = error_of(dir.path());
    assert!(
        e.contains("Robot1_Measurement.dat:10: field 1 is not a number"),
        "{e}"
    );
}

#[test]
fn bad_values_are_errors_with_line_numbers() {
    let dir = damaged("Robot1_Measurement.dat", |t| {
        let mut lines: Vec<String> = t.lines().map(str::to_owned).collect();
        lines[5] = "1248444189.9 \t 63 \t -1.0 \t 0.1".into(); // negative range, line 6
        lines.join("\n")
    });
    let e = error_of(dir.path());
    assert!(
        e.contains("Robot1_Measurement.dat:6: range -1 is not positive"),
        "{e}"
    );

    let dir = damaged("Barcodes.dat", |t| {
        format!("{}\n 21 \t 4.5\n", t.trim_end())
    });
    let e = error_of(dir.path());
    assert!(
        e.contains("Barcodes.dat:25: barcode `4.5` is not a whole number"),
        "{e}"
    );

    let dir = damaged("Robot1_Groundtruth.dat", |t| {
        let mut lines: Vec<String> = t.lines().map(str::to_owned).collect();
        lines[100] = "1248444176 \t 1.0 \t inf \t 0.0".into();
        lines.join("\n")
    });
    let e = error_of(dir.path());
    assert!(
        e.contains("Robot1_Groundtruth.dat:101: field 3 is not finite"),
        "{e}"
    );
}

#[test]
fn missing_file_is_named() {
    let dir = damaged("Robot1_Odometry.dat", |t| t.to_owned());
    std::fs::remove_file(dir.path().join("Robot1_Odometry.dat")).unwrap();
    let e = error_of(dir.path());
    assert!(e.contains("Robot1_Odometry.dat"), "{e}");
}

#[test]
fn a_robot_is_named_in_the_dataset_or_by_number() {
    let by_name = readers::read(&DatasetSpec::Mrclam("dataset6/robot3".into()), 1).unwrap();
    assert_eq!(by_name.name, "mrclam/dataset6/robot3");
    let by_number = readers::read(&DatasetSpec::Mrclam("dataset6".into()), 3).unwrap();
    assert_eq!(by_name.events.len(), by_number.events.len());
    // A robot the folder lacks: the error names the file and the robots present.
    let err = readers::read(&DatasetSpec::Mrclam("dataset6".into()), 7).unwrap_err();
    let text = format!("{err:#}");
    assert!(text.contains("Robot7_Odometry.dat"), "{text}");
    assert!(text.contains("[1, 2, 3, 4, 5]"), "{text}");
    let err = readers::read(&DatasetSpec::Mrclam("dataset6/robot0".into()), 1).unwrap_err();
    assert!(format!("{err:#}").contains("robot1 … robot5"), "{err:#}");
}
