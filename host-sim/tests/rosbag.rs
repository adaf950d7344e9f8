//! ROS 2 bags (`--dataset rosbag:<file.mcap>`): the Intel CARMEN log written as a bag
//! (`export-rosbag`) replays to the same trajectory as the log itself; bad bags are
//! refused with the file and the topic named.

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
