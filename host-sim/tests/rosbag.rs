//! ROS 2 bags (`--dataset rosbag:<file.mcap>`): the Intel CARMEN log written as a bag
//! (`export-rosbag`) replays to the same trajectory as the log itself; bad bags are
//! refused with the file and the topic named.

#[path = "common/cases.rs"]
mod cases;
mod common;

use common::{host_sim, succeeds};
use host_sim::domain::datasets::dataset_path;
use host_sim::domain::grid::{GRID_BITMAP, GRID_CELLS, carmen_lidar};
use host_sim::drivers::grid::{GridRunOptions, carmen_inputs, run_slam};
use host_sim::inputs::readers::carmen::{LaserMessage, front_scans, read_log};
use host_sim::inputs::readers::rosbag::{self, BagOptions, MountSource, msg};
use host_sim::output::mcap::McapFile;
use host_sim::output::rosbag::{export, imu_schema, laser_scan_schema, odometry_schema, write_ros};
use microslam::geometry::Pose2;
use microslam::pf::GridPfConfig;
use std::path::Path;

fn intel() -> Vec<LaserMessage> {
    let log = read_log(&dataset_path("intel/intel-raw-part.clf").expect("Intel log")).unwrap();
    front_scans(&log).into_iter().cloned().collect()
}

#[test]
fn the_intel_bag_replays_like_the_carmen_log() {
    let scans = intel();
    let refs: Vec<&LaserMessage> = scans.iter().collect();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("intel.mcap");
    let lidar = carmen_lidar(180);
    let written = export(&path, &refs, &lidar, &BagOptions::default()).unwrap();
    assert_eq!(
        written,
        1 + 2 * 5505,
        "tf_static, then odometry and scan per scan"
    );
    let bag = rosbag::read(&path, &BagOptions::default()).unwrap();
    assert_eq!(bag.scans.len(), 5505);
    assert_eq!(bag.odometry_messages, 5505);
    assert_eq!(bag.mount_source, MountSource::TfStatic);
    assert_eq!(bag.lidar, lidar, "the geometry comes back from the scans");
    for (a, b) in bag.scans.iter().zip(&scans) {
        assert_eq!(a.ranges, b.ranges);
        assert!(
            (a.stamp - b.stamp).abs() < 1e-6,
            "{} vs {}",
            a.stamp,
            b.stamp
        );
        for k in 0..3 {
            assert!(
                (a.odom[k] - b.odom[k]).abs() < 1e-12,
                "{:?} vs {:?}",
                a.odom,
                b.odom
            );
        }
    }
    let options = GridRunOptions {
        particles: 32,
        config: GridPfConfig::MICROCONTROLLER,
        lidar,
        loop_closure: None,
        grid_origin: None,
        max_odometry_step_m: host_sim::domain::grid::MAX_ODOMETRY_STEP_M,
    };
    let from_bag: Vec<&LaserMessage> = bag.scans.iter().collect();
    let a = run_slam::<GRID_CELLS, GRID_BITMAP>(
        &carmen_inputs(&refs),
        Pose2::IDENTITY,
        &options,
        &|_| {},
    )
    .unwrap();
    let b = run_slam::<GRID_CELLS, GRID_BITMAP>(
        &carmen_inputs(&from_bag),
        Pose2::IDENTITY,
        &GridRunOptions {
            lidar: bag.lidar,
            ..options
        },
        &|_| {},
    )
    .unwrap();
    assert_eq!(a.trajectory.len(), b.trajectory.len());
    for ((_, p), (_, q)) in a.trajectory.iter().zip(&b.trajectory) {
        assert_eq!(p, q, "the same estimate at every scan");
    }
    assert_eq!(a.cells, b.cells, "the same map");
}

#[test]
fn the_mount_comes_from_tf_static_or_the_settings() {
    let scans = intel();
    let refs: Vec<&LaserMessage> = scans.iter().take(20).collect();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("mounted.mcap");
    let mut lidar = carmen_lidar(180);
    lidar.mount = Pose2::new(0.25, -0.05, 0.1);
    export(&path, &refs, &lidar, &BagOptions::default()).unwrap();
    let bag = rosbag::read(&path, &BagOptions::default()).unwrap();
    assert_eq!(bag.mount_source, MountSource::TfStatic);
    let m = bag.lidar.mount;
    assert!((m.x - 0.25).abs() < 1e-6 && (m.y + 0.05).abs() < 1e-6 && (m.theta - 0.1).abs() < 1e-6);
    let settings = BagOptions {
        lidar_mount: Some([0.5, 0.0, 0.0]),
        ..BagOptions::default()
    };
    let bag = rosbag::read(&path, &settings).unwrap();
    assert_eq!(bag.mount_source, MountSource::Settings);
    assert_eq!(bag.lidar.mount, Pose2::new(0.5, 0.0, 0.0));
}

/// A bag with one odometry message and one scan, plus `extra` written by the caller.
fn small_bag(path: &Path, extra: impl FnOnce(&mut McapFile)) {
    let mut bag = McapFile::create(path, "ros2").unwrap();
    let odom = msg::Odometry {
        child_frame_id: "base_link".into(),
        ..Default::default()
    };
    write_ros(&mut bag, "/odom", odometry_schema, 1.0, &odom).unwrap();
    extra(&mut bag);
    bag.finish().unwrap();
}

fn scan() -> msg::LaserScan {
    msg::LaserScan {
        header: msg::Header {
            stamp: msg::Time::from_seconds(1.0),
            frame_id: "laser".into(),
        },
        angle_min: -1.0,
        angle_max: 1.0,
        angle_increment: 0.5,
        range_min: 0.1,
        range_max: 10.0,
        ranges: vec![1.0, f32::INFINITY, 3.0, 4.0, 5.0],
        ..Default::default()
    }
}

fn error(path: &Path, options: &BagOptions) -> String {
    format!("{:#}", rosbag::read(path, options).unwrap_err())
}

#[test]
fn a_small_bag_with_an_imu_is_read() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("imu.mcap");
    small_bag(&path, |bag| {
        write_ros(bag, "/scan", laser_scan_schema, 1.0, &scan()).unwrap();
        let imu = msg::Imu {
            angular_velocity: msg::Vector3 {
                x: 0.0,
                y: 0.0,
                z: 0.25,
            },
            linear_acceleration: msg::Vector3 {
                x: 0.5,
                y: 0.0,
                z: 9.81,
            },
            ..Default::default()
        };
        write_ros(bag, "/imu", imu_schema, 1.0, &imu).unwrap();
    });
    let bag = rosbag::read(&path, &BagOptions::default()).unwrap();
    assert_eq!(bag.imu.len(), 1);
    assert_eq!(bag.imu[0].yaw_rate, 0.25);
    assert_eq!(bag.imu[0].acceleration, [0.5, 0.0, 9.81]);
    assert_eq!(bag.mount_source, MountSource::Origin);
    // +∞ is "no return": the no-return range.
    assert_eq!(bag.scans[0].ranges, [1.0, 10.0, 3.0, 4.0, 5.0]);
    assert_eq!(bag.lidar.first_angle, -1.0);
}

#[test]
fn bad_bags_name_the_file_and_the_topic() {
    let dir = tempfile::tempdir().unwrap();
    let defaults = BagOptions::default();

    // No scan topic at all.
    let missing = dir.path().join("no_scan.mcap");
    small_bag(&missing, |_| {});
    let e = error(&missing, &defaults);
    assert!(
        e.contains("no_scan.mcap") && e.contains("/scan") && e.contains("/odom"),
        "{e}"
    );
    // A topic named that the bag does not have.
    let scanned = dir.path().join("scanned.mcap");
    small_bag(&scanned, |bag| {
        write_ros(bag, "/scan", laser_scan_schema, 1.0, &scan()).unwrap();
    });
    let e = error(
        &scanned,
        &BagOptions {
            odom_topic: "/wheel_odom".into(),
            ..BagOptions::default()
        },
    );
    assert!(
        e.contains("/wheel_odom") && e.contains("scanned.mcap") && e.contains("/odom, /scan"),
        "{e}"
    );

    // Another message type on the scan topic.
    let foreign = dir.path().join("pointcloud.mcap");
    small_bag(&foreign, |bag| {
        let schema = || host_sim::output::mcap::SchemaDef {
            name: "sensor_msgs/msg/PointCloud2".into(),
            encoding: "ros2msg".into(),
            data: Vec::new(),
        };
        bag.write_raw("/scan", &schema, "cdr", 1.0, &[0, 1, 0, 0])
            .unwrap();
    });
    let e = error(&foreign, &defaults);
    assert!(
        e.contains("pointcloud.mcap") && e.contains("/scan") && e.contains("PointCloud2"),
        "{e}"
    );

    // A scan message that does not decode.
    let corrupt = dir.path().join("corrupt.mcap");
    small_bag(&corrupt, |bag| {
        bag.write_raw("/scan", &laser_scan_schema, "cdr", 1.0, &[0, 1, 0, 0, 7, 7])
            .unwrap();
    });
    let e = error(&corrupt, &defaults);
    assert!(
        e.contains("corrupt.mcap") && e.contains("topic /scan, message 1"),
        "{e}"
    );

    // A truncated file.
    let whole = dir.path().join("whole.mcap");
    small_bag(&whole, |bag| {
        for _ in 0..50 {
            write_ros(bag, "/scan", laser_scan_schema, 1.0, &scan()).unwrap();
        }
    });
    let bytes = std::fs::read(&whole).unwrap();
    let cut = dir.path().join("truncated.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let e = error(&cut, &defaults);
    assert!(
        e.contains("truncated.mcap") && e.contains("truncated or corrupt"),
        "{e}"
    );
    // Not an MCAP file at all.
    let text = dir.path().join("notes.mcap");
    std::fs::write(&text, "not a bag").unwrap();
    let e = error(&text, &defaults);
    assert!(e.contains("notes.mcap"), "{e}");
}

#[test]
fn replay_and_localize_take_a_bag_and_write_an_mcap() {
    let scans = intel();
    let refs: Vec<&LaserMessage> = scans.iter().take(150).collect();
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("part.mcap");
    export(&bag, &refs, &carmen_lidar(180), &BagOptions::default()).unwrap();
    let run = |args: &[&str]| {
        succeeds(host_sim().args(args));
    };
    let dataset = format!("rosbag:{}", bag.display());
    let out = dir.path().join("replay");
    let rec = dir.path().join("replay.mcap");
    run(&[
        "replay",
        "-q",
        "--dataset",
        &dataset,
        "--particles",
        "16",
        "--out",
        out.to_str().unwrap(),
        "--mcap",
        rec.to_str().unwrap(),
    ]);
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(metrics["scans"], 150);
    // The Intel log's stamps go back now and then; the bag keeps them as they are and the
    // run counts the scans whose stamp went back (counted here from the messages).
    let back = refs.windows(2).filter(|w| w[1].stamp < w[0].stamp).count();
    assert!(back > 0);
    assert_eq!(metrics["input_loss"]["scans"]["stamps_going_back"], back);
    let bytes = std::fs::read(&rec).unwrap();
    let stats = mcap::Summary::read(&bytes).unwrap().unwrap().stats.unwrap();
    assert!(stats.message_count > 4 * 150, "{stats:?}");
    let loc = dir.path().join("localize.mcap");
    run(&[
        "localize",
        "-q",
        "--map",
        out.join("map.yaml").to_str().unwrap(),
        "--dataset",
        &dataset,
        "--particles",
        "16",
        "--out",
        dir.path().join("loc").to_str().unwrap(),
        "--mcap",
        loc.to_str().unwrap(),
    ]);
    assert!(std::fs::metadata(&loc).unwrap().len() > 0);
}

#[test]
fn the_geometry_of_every_bag_scan_is_checked() {
    let dir = tempfile::tempdir().unwrap();
    let defaults = BagOptions::default();
    // A good first scan, then `second`.
    let bag = |name: &str, second: msg::LaserScan| {
        let path = dir.path().join(name);
        small_bag(&path, |bag| {
            write_ros(bag, "/scan", laser_scan_schema, 1.0, &scan()).unwrap();
            write_ros(bag, "/scan", laser_scan_schema, 1.1, &second).unwrap();
        });
        error(&path, &defaults)
    };
    let e = bag(
        "zero.mcap",
        msg::LaserScan {
            angle_increment: 0.0,
            ..scan()
        },
    );
    assert!(
        e.ends_with("zero.mcap: topic /scan, scan 1: angle_increment is 0: the beams would all point one way"),
        "{e}"
    );
    // Five ranges over a span that holds nine beams.
    let e = bag(
        "span.mcap",
        msg::LaserScan {
            angle_max: 3.0,
            ..scan()
        },
    );
    assert!(
        e.ends_with("span.mcap: topic /scan, scan 1: 5 ranges, but angle_min -1 … angle_max 3 by angle_increment 0.5 holds 9.0 beams"),
        "{e}"
    );
    // The same count over another span: another lidar.
    let e = bag(
        "turned.mcap",
        msg::LaserScan {
            angle_min: -0.5,
            angle_max: 1.5,
            ..scan()
        },
    );
    assert!(
        e.ends_with("turned.mcap: topic /scan, scan 1: angle_min -0.5 differs from the first scan's -1: one lidar geometry a bag"),
        "{e}"
    );
    let e = bag(
        "range.mcap",
        msg::LaserScan {
            range_max: 30.0,
            ..scan()
        },
    );
    assert!(
        e.contains("range.mcap: topic /scan, scan 1: range_max 30 differs"),
        "{e}"
    );
    // A full-turn lidar's count (one fewer than the span's) is read.
    let path = dir.path().join("full-turn.mcap");
    small_bag(&path, |bag| {
        let s = msg::LaserScan {
            angle_max: 1.5,
            ..scan()
        };
        write_ros(bag, "/scan", laser_scan_schema, 1.0, &s).unwrap();
    });
    assert!(rosbag::read(&path, &defaults).is_ok());
}

#[test]
fn an_odometry_pose_beyond_100_km_is_refused_with_its_message_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("far.mcap");
    small_bag(&path, |bag| {
        let mut far = msg::Odometry {
            child_frame_id: "base_link".into(),
            ..Default::default()
        };
        far.pose.pose.position.y = -3e6;
        write_ros(bag, "/odom", odometry_schema, 1.05, &far).unwrap();
        write_ros(bag, "/scan", laser_scan_schema, 1.1, &scan()).unwrap();
    });
    let e = error(&path, &BagOptions::default());
    assert!(
        e.contains("far.mcap: topic /odom, message 1")
            && e.ends_with("pose.pose.position.y = -3000000 m is beyond 100 km of the origin"),
        "{e}"
    );
}

/// One field of one message of a small bag made wrong (structure-aware fuzzing, issue 62):
/// the bag itself is well formed, the message decodes, its content is what is wrong.
#[derive(Clone, Debug)]
enum BagMutation {
    /// One more or one fewer range than the angle span holds.
    RangesOffByOne(bool),
    /// A geometry field of a scan set to a value (`angle_min`, `angle_max`,
    /// `angle_increment`, `range_min`, `range_max` by index).
    Geometry(usize, f32),
    /// One range set to a value.
    Range(usize, f32),
    /// A scan's header stamp moved by seconds.
    ScanStamp(f64),
    /// An odometry position coordinate set to a value.
    OdometryPosition(bool, f64),
    /// An odometry orientation set to a non-unit or non-finite quaternion component.
    OdometryOrientation(f64),
    /// A scan in another frame.
    Frame,
}

fn bag_mutation() -> impl proptest::strategy::Strategy<Value = BagMutation> {
    use proptest::prelude::*;
    let f32s = prop::sample::select(vec![f32::NAN, f32::INFINITY, -1.0, 0.0, 1e30, 1e-30, 7.0]);
    let f64s = prop::sample::select(vec![f64::NAN, f64::INFINITY, -1e30, 1e6, 5e3, 0.0]);
    prop_oneof![
        any::<bool>().prop_map(BagMutation::RangesOffByOne),
        (0usize..5, f32s.clone()).prop_map(|(i, v)| BagMutation::Geometry(i, v)),
        (0usize..5, f32s).prop_map(|(i, v)| BagMutation::Range(i, v)),
        prop::sample::select(vec![-10.0, -0.5, 1e9, f64::MAX]).prop_map(BagMutation::ScanStamp),
        (any::<bool>(), f64s.clone()).prop_map(|(x, v)| BagMutation::OdometryPosition(x, v)),
        f64s.prop_map(BagMutation::OdometryOrientation),
        Just(BagMutation::Frame),
    ]
}

/// A bag of 8 scans (every 0.1 s) with odometry moving 2 cm between them; `mutation`
/// applied to message `which` (of the scans or of the odometry).
fn mutated_bag(path: &Path, which: usize, mutation: &BagMutation) {
    let mut bag = McapFile::create(path, "ros2").unwrap();
    for i in 0..8usize {
        let t = 1.0 + 0.1 * i as f64;
        let mut odom = msg::Odometry {
            child_frame_id: "base_link".into(),
            ..Default::default()
        };
        odom.header.stamp = msg::Time::from_seconds(t);
        odom.pose.pose.orientation.w = 1.0;
        odom.pose.pose.position.x = 0.02 * i as f64;
        let mut s = msg::LaserScan {
            header: msg::Header {
                stamp: msg::Time::from_seconds(t),
                frame_id: "laser".into(),
            },
            ..scan()
        };
        if i == which % 8 {
            match *mutation {
                BagMutation::RangesOffByOne(more) => {
                    if more {
                        s.ranges.push(2.0);
                    } else {
                        s.ranges.pop();
                    }
                }
                BagMutation::Geometry(field, v) => match field {
                    0 => s.angle_min = v,
                    1 => s.angle_max = v,
                    2 => s.angle_increment = v,
                    3 => s.range_min = v,
                    _ => s.range_max = v,
                },
                BagMutation::Range(k, v) => {
                    let n = s.ranges.len();
                    s.ranges[k % n] = v;
                }
                BagMutation::ScanStamp(dt) => {
                    s.header.stamp = msg::Time::from_seconds((t + dt).clamp(0.0, 4e9));
                }
                BagMutation::OdometryPosition(x, v) => {
                    if x {
                        odom.pose.pose.position.x = v;
                    } else {
                        odom.pose.pose.position.y = v;
                    }
                }
                BagMutation::OdometryOrientation(v) => odom.pose.pose.orientation.z = v,
                BagMutation::Frame => s.header.frame_id = "other_laser".into(),
            }
        }
        write_ros(&mut bag, "/odom", odometry_schema, t, &odom).unwrap();
        write_ros(&mut bag, "/scan", laser_scan_schema, t + 0.01, &s).unwrap();
    }
    bag.finish().unwrap();
}

#[test]
fn a_bag_with_one_wrong_message_fails_naming_it_or_is_used_whole() {
    use proptest::test_runner::TestCaseError;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("wrong.mcap");
    let dataset = format!("rosbag:{}", path.display());
    cases::run_cases(128, &(0usize..8, bag_mutation()), |(which, m)| {
        mutated_bag(&path, which, &m);
        let out = dir.path().join("out");
        let o = host_sim()
            .args([
                "replay",
                "--quiet",
                "--no-plots",
                "--particles",
                "8",
                "--dataset",
            ])
            .arg(&dataset)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        if o.status.code() == Some(101) {
            return Err(TestCaseError::fail(format!("panicked: {err}")));
        }
        if o.status.success() {
            let json = std::fs::read_to_string(out.join("metrics.json")).unwrap();
            if json.contains("null") {
                return Err(TestCaseError::fail(format!("a null figure: {json}")));
            }
            let m: serde_json::Value = serde_json::from_str(&json).unwrap();
            let scans = &m["input_loss"]["scans"];
            let accounted = scans["used"].as_u64().zip(scans["skipped"].as_u64());
            if scans["read"] != 8 || accounted.map(|(u, s)| u + s) != Some(8) {
                return Err(TestCaseError::fail(format!(
                    "8 scans not accounted for: {scans}"
                )));
            }
        } else if !err.contains("wrong.mcap") {
            return Err(TestCaseError::fail(format!(
                "the error names no bag: {err}"
            )));
        }
        Ok(o.status.code())
    });
}
