//! ROS 2 bags of landmark detections (`replay --dataset rosbag:<bag>` with ArucoMarkers
//! or Detection3DArray): an MRCLAM run written as a bag replays as the MRCLAM files do,
//! and each bad input is an error naming the file, topic and message.

mod common;

use common::{host_sim, succeeds};
use host_sim::domain::datasets::dataset_path;
use host_sim::inputs::readers::detections_bag::{self, msg};
use host_sim::inputs::readers::mrclam;
use host_sim::inputs::readers::rosbag::{BagOptions, MountSource, msg as ros};
use host_sim::output::detections_bag::{
    CameraMount, DetectionFormat, aruco_markers_schema, export,
};
use host_sim::output::mcap::McapFile;
use host_sim::output::rosbag::{odometry_schema, tf_message_schema, write_ros};
use std::path::{Path, PathBuf};

/// A mount that is not trivial: ahead, to the right, above, turned left and tilted down.
const MOUNT: CameraMount = CameraMount {
    position: [0.12, -0.04, 0.3],
    rpy: [0.02, 0.05, 0.1],
};

fn config() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/mrclam.toml")
}

/// Replays `dataset` and returns its metrics.json.
fn replay(dataset: &str, out: &Path, extra: &[&str]) -> serde_json::Value {
    let output = host_sim()
        .args(["replay", "--quiet", "--no-plots", "--dataset", dataset])
        .arg("--config")
        .arg(config())
        .arg("--out")
        .arg(out)
        .args(extra)
        .output()
        .expect("host-sim starts");
    assert!(
        output.status.success(),
        "{dataset}: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap()
}

fn ate(m: &serde_json::Value) -> f64 {
    m["ate_rmse_m"]["se2"].as_f64().expect("an ATE")
}

fn mrclam_bag(dir: &Path, format: &DetectionFormat) -> PathBuf {
    mrclam_bag_as(dir, format, true, "run.mcap")
}

/// [`mrclam_bag`], its odometry with the twist or with the poses only.
fn mrclam_bag_as(dir: &Path, format: &DetectionFormat, twist: bool, name: &str) -> PathBuf {
    let folder = dataset_path("mrclam/dataset6").unwrap();
    let recording = mrclam::read(&folder, 1).unwrap();
    let path = dir.join(name);
    export(&path, &recording, format, &MOUNT, twist).unwrap();
    path
}

/// MRCLAM dataset 6 robot 1 as a bag (odometry integrated from its velocities, sightings
/// as ArucoMarkers in an optical frame mounted by /tf_static) replays with known ids within
/// 5 mm of the MRCLAM files under the same settings.
#[test]
fn an_mrclam_run_as_an_aruco_bag_replays_as_the_files_do() {
    let dir = tempfile::tempdir().unwrap();
    let bag = mrclam_bag(dir.path(), &DetectionFormat::Aruco);
    let files = replay("mrclam:dataset6/robot1", &dir.path().join("files"), &[]);
    let from_bag = replay(
        &format!("rosbag:{}", bag.display()),
        &dir.path().join("bag"),
        &[],
    );
    let (a, b) = (ate(&files), ate(&from_bag));
    println!("ATE MRCLAM files {a:.6} m, ArucoMarkers bag (twist) {b:.6} m");
    assert!((a - b).abs() < 0.005, "files {a} m, bag {b} m");
    assert_eq!(
        files["inputs"]["sightings"]["used"], from_bag["inputs"]["sightings"]["used"],
        "{}",
        from_bag["inputs"]
    );
    // The poses' increments instead of the twist: another motion model, measured.
    let poses = replay(
        &format!("rosbag:{}", bag.display()),
        &dir.path().join("poses"),
        &["--odom-motion", "pose"],
    );
    let c = ate(&poses);
    println!("ATE ArucoMarkers bag, pose increments {c:.4} m");
    assert!(c.is_finite() && c < 1.2, "{c}");
    // An odometry that publishes no twist: the velocities between its poses drive the
    // filter, as the twist would.
    let pose_only = mrclam_bag_as(dir.path(), &DetectionFormat::Aruco, false, "poses.mcap");
    let from_poses = replay(
        &format!("rosbag:{}", pose_only.display()),
        &dir.path().join("pose-only"),
        &[],
    );
    let d = ate(&from_poses);
    println!("ATE ArucoMarkers bag, poses only (velocities between them) {d:.6} m");
    assert!((a - d).abs() < 0.005, "files {a} m, poses-only bag {d} m");
}

/// `export-landmarks` writes a bag's detections as a plain landmark log on the robot's
/// frame (mounted through the bag's /tf_static): replayed with a settings file of no
/// sensor mount, it gives the bag's result.
#[test]
fn a_bag_exported_as_a_plain_landmark_log_replays_as_the_bag_does() {
    let dir = tempfile::tempdir().unwrap();
    let bag = mrclam_bag(dir.path(), &DetectionFormat::Aruco);
    let log = dir.path().join("run.txt");
    let out = host_sim()
        .args(["export-landmarks", "--quiet", "--dataset"])
        .arg(format!("rosbag:{}", bag.display()))
        .arg("--out")
        .arg(&log)
        .output()
        .expect("host-sim starts");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(&log).unwrap();
    assert!(
        text.lines().any(|l| l.starts_with("sighting ")),
        "{text:.400}"
    );
    let from_bag = replay(
        &format!("rosbag:{}", bag.display()),
        &dir.path().join("bag"),
        &[],
    );
    let from_log = replay(
        &format!("landmarks:{}", log.display()),
        &dir.path().join("log"),
        &[],
    );
    let (a, b) = (ate(&from_bag), ate(&from_log));
    println!("ATE ArucoMarkers bag {a:.6} m, its plain landmark log {b:.6} m");
    assert!((a - b).abs() < 0.005, "bag {a} m, plain log {b} m");
    assert_eq!(
        from_bag["inputs"]["sightings"]["used"], from_log["inputs"]["sightings"]["used"],
        "{}",
        from_log["inputs"]
    );
}

/// Every landmark of one class (Detection3DArray): JCBB decides which landmark.
#[test]
fn a_detection3d_bag_with_one_class_runs_jcbb() {
    let dir = tempfile::tempdir().unwrap();
    let class = DetectionFormat::Detection3d {
        class: "marker".into(),
    };
    let bag = mrclam_bag(dir.path(), &class);
    let m = replay(
        &format!("rosbag:{}", bag.display()),
        &dir.path().join("out"),
        &["--association", "jcbb"],
    );
    let a = ate(&m);
    println!(
        "ATE Detection3DArray bag, one class, JCBB {a:.4} m, {} landmarks",
        m["landmarks_created"]
    );
    assert!(a.is_finite(), "{m}");
    assert!(m["landmarks_created"].as_u64().unwrap() > 0, "{m}");
    // The firmware's landmark session pairs sightings by id: `hil` refuses such a bag
    // before it talks to a device, naming the count, instead of streaming no sighting.
    let out = host_sim()
        .args(["hil", "--serial", "/nonexistent/tty", "--dataset"])
        .arg(format!("rosbag:{}", bag.display()))
        .arg("--out")
        .arg(dir.path().join("hil"))
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{e}");
    assert!(
        e.contains("sightings carry no landmark id") && e.contains("-a jcbb"),
        "{e}"
    );
}

// --- bad input -------------------------------------------------------------------------

fn header(stamp: f64, frame: &str) -> ros::Header {
    ros::Header {
        stamp: ros::Time::from_seconds(stamp),
        frame_id: frame.into(),
    }
}

fn odom(stamp: f64, x: f64) -> ros::Odometry {
    let mut o = ros::Odometry {
        header: header(stamp, "odom"),
        child_frame_id: "base_link".into(),
        ..Default::default()
    };
    o.pose.pose.position.x = x;
    o.twist.twist.linear.x = 0.1;
    o
}

fn transform(parent: &str, child: &str, rotation: ros::Quaternion) -> ros::TransformStamped {
    ros::TransformStamped {
        header: header(0.0, parent),
        child_frame_id: child.into(),
        transform: ros::Transform {
            translation: ros::Vector3 {
                x: 0.1,
                ..Default::default()
            },
            rotation,
        },
    }
}

/// The optical frame's rotation in the link frame (z forward, x right, y down).
fn optical() -> ros::Quaternion {
    ros::Quaternion {
        x: -0.5,
        y: 0.5,
        z: -0.5,
        w: 0.5,
    }
}

fn markers(stamp: f64, ids: &[i64], at: [f64; 3]) -> msg::ArucoMarkers {
    let mut m = msg::ArucoMarkers {
        header: header(stamp, "camera_optical_frame"),
        ..Default::default()
    };
    for id in ids {
        m.marker_ids.push(*id);
        let p = ros::Pose {
            position: ros::Vector3 {
                x: at[0],
                y: at[1],
                z: at[2],
            },
            ..Default::default()
        };
        m.poses.push(p);
    }
    m
}

/// What a good small bag holds; each case changes one part.
struct Parts {
    tf: Vec<ros::TransformStamped>,
    odometry: bool,
    detections: Vec<(i32, msg::ArucoMarkers)>,
}

fn good() -> Parts {
    Parts {
        tf: vec![
            transform("base_link", "camera_link", ros::Quaternion::default()),
            transform("camera_link", "camera_optical_frame", optical()),
        ],
        odometry: true,
        detections: (1..5)
            .map(|k| {
                let t = f64::from(k);
                (k, markers(t, &[3, 4], [0.1, 0.05, 2.0 - 0.1 * t]))
            })
            .collect(),
    }
}

fn write(path: &Path, parts: &Parts) {
    let mut bag = McapFile::create(path, "ros2").unwrap();
    let tf = ros::TfMessage {
        transforms: parts.tf.clone(),
    };
    write_ros(&mut bag, "/tf_static", tf_message_schema, 0.0, &tf).unwrap();
    for k in 0..6 {
        let t = f64::from(k);
        if parts.odometry {
            write_ros(&mut bag, "/odom", odometry_schema, t, &odom(t, 0.1 * t)).unwrap();
        }
        for (_, d) in parts.detections.iter().filter(|(slot, _)| *slot == k) {
            write_ros(&mut bag, "/aruco_markers", aruco_markers_schema, t, d).unwrap();
        }
    }
    bag.finish().unwrap();
}

fn read_error(parts: &Parts) -> String {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.mcap");
    write(&path, parts);
    match detections_bag::read(&path, &BagOptions::default(), None) {
        Ok(_) => panic!("read"),
        Err(e) => format!("{e:#}"),
    }
}

#[test]
fn a_good_small_bag_reads_in_the_robot_frame() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("good.mcap");
    write(&path, &good());
    let bag = detections_bag::read(&path, &BagOptions::default(), None).unwrap();
    assert_eq!(bag.topic.0, "/aruco_markers");
    let r = &bag.recording;
    let sightings: Vec<_> = r
        .events
        .iter()
        .filter_map(|e| match e.kind {
            microslam::event::EventKind::Sighting(s) => Some(s),
            _ => None,
        })
        .collect();
    assert_eq!(sightings.len(), 8);
    // Optical (0.1, 0.05, 1.9): 1.9 m ahead of the camera and 0.1 m right of it; the
    // optical frame 0.1 m ahead of camera_link, 0.1 m ahead of base_link.
    let s = sightings[0];
    assert_eq!(s.identity, microslam::event::Identity::Unique(3));
    let (x, y) = (2.1_f64, -0.1_f64);
    assert!((s.z.range - x.hypot(y)).abs() < 1e-9, "{:?}", s.z);
    assert!((s.z.bearing - y.atan2(x)).abs() < 1e-9, "{:?}", s.z);
    // The settings' mount wins: the sighting is taken in the camera's frame (x forward),
    // the filter mounts it.
    let bag = detections_bag::read(&path, &BagOptions::default(), Some([0.3, 0.0, 0.0])).unwrap();
    assert_eq!(bag.mount_source, MountSource::Settings);
    let s = bag
        .recording
        .events
        .iter()
        .find_map(|e| match e.kind {
            microslam::event::EventKind::Sighting(s) => Some(s),
            _ => None,
        })
        .unwrap();
    let (x, y) = (1.9_f64, -0.1_f64);
    assert!((s.z.range - x.hypot(y)).abs() < 1e-9, "{:?}", s.z);
    assert!((s.z.bearing - y.atan2(x)).abs() < 1e-9, "{:?}", s.z);
}

#[test]
fn bad_input_is_named_by_file_topic_and_message() {
    let mut cases: Vec<(Parts, &str)> = Vec::new();
    let mut p = good();
    p.tf.pop();
    cases.push((
        p,
        "no transform from base_link to camera_optical_frame in /tf_static",
    ));
    let mut p = good();
    p.detections[1].1.poses[0].position.y = f64::NAN;
    cases.push((
        p,
        "bad.mcap: topic /aruco_markers, message 5, detection 0: position (0.1, NaN, 1.8) is not finite",
    ));
    let mut p = good();
    p.detections[2].1.poses[1].position.z = -1.0;
    cases.push((
        p,
        "detection 1: position (0.1, 0.05, -1) in camera_optical_frame is behind the camera",
    ));
    let mut p = good();
    p.tf[1].transform.rotation = ros::Quaternion::default(); // optical z = base z: straight up
    p.detections[0].1.poses[0].position = ros::Vector3 {
        x: -0.2,
        y: 0.0,
        z: 2.0,
    };
    cases.push((p, "no finite range in the robot's plane"));
    let mut p = good();
    p.odometry = false;
    cases.push((p, "no odometry: no messages on topic /odom"));
    let mut p = good();
    p.detections[2].1.header.stamp = ros::Time::from_seconds(1.5); // sent at 3 s
    cases.push((
        p,
        "message 7 (log time 3000000000 ns): stamp 1.5 s goes back before message 5's 2 s",
    ));
    let mut p = good();
    p.detections[0].1.marker_ids[0] = -3;
    cases.push((p, "marker 0: id -3 is not a landmark id"));
    let mut p = good();
    p.detections[0].1.marker_ids.pop();
    cases.push((p, "1 marker_ids but 2 poses"));
    let mut p = good();
    p.tf[0].transform.rotation.w = f64::NAN;
    cases.push((
        p,
        "the transform base_link → camera_link has a non-finite number",
    ));
    let mut p = good();
    for (_, d) in &mut p.detections {
        d.header.stamp.sec -= 10;
    }
    cases.push((
        p,
        "no detection to use: all 8 come before the first odometry message",
    ));
    for (parts, expected) in cases {
        let e = read_error(&parts);
        assert!(e.contains("bad.mcap"), "{e}");
        assert!(e.contains(expected), "expected {expected:?} in {e}");
    }
}

/// From the command line: a topic of another type, a bag whose sightings are all out of
/// range (a run that uses no sighting), and a bag without detections taken as a lidar bag.
#[test]
fn the_command_line_refuses_what_it_cannot_use() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("good.mcap");
    write(&path, &good());
    let run = |args: &[&str]| {
        let out = host_sim()
            .args(["replay", "--quiet", "--no-plots", "--out"])
            .arg(dir.path().join("out"))
            .arg("--dataset")
            .arg(format!("rosbag:{}", path.display()))
            .args(args)
            .output()
            .unwrap();
        (
            out.status.success(),
            String::from_utf8_lossy(&out.stderr).to_string(),
        )
    };
    let (ok, e) = run(&["--detections-topic", "/odom"]);
    assert!(!ok);
    assert!(
        e.contains("topic /odom carries `nav_msgs/msg/Odometry`, expected"),
        "{e}"
    );
    let (ok, e) = run(&["--detections-topic", "/none"]);
    assert!(!ok && e.contains("no messages on topic /none"), "{e}");
    // The settings' max_range below every sighting's range: nothing used.
    let cfg = dir.path().join("near.toml");
    std::fs::write(&cfg, "[sighting]\nmax_range = 0.5\n").unwrap();
    let (ok, e) = run(&["--config", cfg.to_str().unwrap()]);
    assert!(!ok, "{e}");
    assert!(e.contains("sighting"), "{e}");
    // The good bag replays (no ground truth: no ATE, but it runs).
    succeeds(
        host_sim()
            .args(["replay", "--quiet", "--no-plots", "--out"])
            .arg(dir.path().join("out"))
            .arg("--dataset")
            .arg(format!("rosbag:{}", path.display())),
    );
    // A bag without detections is a lidar bag: the EKF refuses it.
    let lidar = dir.path().join("lidar.mcap");
    let mut bag = McapFile::create(&lidar, "ros2").unwrap();
    write_ros(&mut bag, "/odom", odometry_schema, 0.0, &odom(0.0, 0.0)).unwrap();
    bag.finish().unwrap();
    let out = host_sim()
        .args(["replay", "--quiet", "--filter", "ekf-slam", "--dataset"])
        .arg(format!("rosbag:{}", lidar.display()))
        .arg("--out")
        .arg(dir.path().join("out2"))
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && e.contains("needs range-bearing sightings"),
        "{e}"
    );
}
