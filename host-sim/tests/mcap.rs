//! MCAP recordings (`--mcap`) read back with the `mcap` crate: channels, schemas, message
//! counts, time range, and messages that decode (Foxglove's own protobuf types) to the
//! values written.

use foxglove::Decode;
use foxglove::messages::{FrameTransforms, Grid, LaserScan, PosesInFrame, SceneUpdate};
use host_sim::commands::sim::{SimOptions, run_cli};
use host_sim::domain::datasets::dataset_path;
use host_sim::domain::grid::{GRID_BITMAP, GRID_CELLS, carmen_lidar};
use host_sim::drivers::grid::{GridRunOptions, carmen_inputs, run_slam_observed};
use host_sim::inputs::readers::carmen::{front_scans, read_log};
use host_sim::output::mcap::McapFile;
use host_sim::output::mcap::scene::{GridRecording, RunRecorder, Throttle, every};
use microslam::geometry::Pose2;
use microslam::pf::GridPfConfig;
use std::collections::BTreeMap;
use std::path::Path;

/// Per topic: schema name, schema encoding, message count.
fn channels(
    path: &Path,
) -> (
    BTreeMap<String, (String, String, u64)>,
    mcap::records::Statistics,
) {
    let bytes = std::fs::read(path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().expect("a summary");
    let stats = summary.stats.clone().expect("statistics");
    let mut out = BTreeMap::new();
    for (id, ch) in &summary.channels {
        let schema = ch.schema.as_ref().expect("schema");
        let count = stats.channel_message_counts.get(id).copied().unwrap_or(0);
        out.insert(
            ch.topic.clone(),
            (schema.name.clone(), schema.encoding.clone(), count),
        );
    }
    // The counts in the summary are the messages really in the file.
    let streamed = mcap::MessageStream::new(&bytes).unwrap().count() as u64;
    assert_eq!(streamed, stats.message_count);
    (out, stats)
}

/// The messages on `topic`, in file order.
fn messages(path: &Path, topic: &str) -> Vec<(u64, Vec<u8>)> {
    let bytes = std::fs::read(path).unwrap();
    mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(|m| m.unwrap())
        .filter(|m| m.channel.topic == topic)
        .map(|m| (m.log_time, m.data.into_owned()))
        .collect()
}

#[test]
fn an_intel_grid_slam_recording_reads_back() {
    let log = read_log(&dataset_path("intel/intel-raw-part.clf").expect("Intel log")).unwrap();
    let scans: Vec<_> = front_scans(&log).into_iter().take(300).collect();
    let inputs = carmen_inputs(&scans);
    let options = GridRunOptions {
        particles: 32,
        config: GridPfConfig::MICROCONTROLLER,
        lidar: carmen_lidar(180),
        loop_closure: None,
        grid_origin: None,
        max_odometry_step_m: host_sim::domain::grid::MAX_ODOMETRY_STEP_M,
    };
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("intel.mcap");
    let mut file = McapFile::create(&path, "").unwrap();
    let throttle = Throttle::default();
    let mut rec = GridRecording {
        recorder: RunRecorder::new(&mut file, "", inputs.len(), throttle),
        log_odds: options.config.log_odds,
        truth: &[],
        growing_map: true,
    };
    let run = run_slam_observed::<GRID_CELLS, GRID_BITMAP>(
        &inputs,
        Pose2::IDENTITY,
        &options,
        &|_| {},
        Some(&mut rec),
        0,
    )
    .unwrap();
    file.finish().unwrap();

    let (ch, stats) = channels(&path);
    let n = 300u64;
    let counted =
        |every: usize| n.div_ceil(every as u64) + u64::from(!(n - 1).is_multiple_of(every as u64));
    let expected = [
        ("/tf", "foxglove.FrameTransforms", n),
        ("/pose", "foxglove.PoseInFrame", n),
        ("/odometry", "foxglove.Odometry", n),
        ("/scan", "foxglove.LaserScan", n),
        (
            "/particles",
            "foxglove.PosesInFrame",
            counted(every(300, throttle.clouds)),
        ),
        (
            "/uncertainty",
            "foxglove.SceneUpdate",
            counted(every(300, throttle.clouds)),
        ),
        (
            "/trajectory",
            "foxglove.PosesInFrame",
            counted(every(300, throttle.trajectories)),
        ),
        ("/map", "foxglove.Grid", counted(every(300, throttle.grids))),
    ];
    assert_eq!(ch.len(), expected.len(), "{ch:?}");
    for (topic, schema, count) in expected {
        let got = &ch[topic];
        assert_eq!(
            (got.0.as_str(), got.1.as_str(), got.2),
            (schema, "protobuf", count),
            "{topic}"
        );
    }
    assert_eq!(counted(5), 61, "every 5th of 300 steps and the last");
    // Time range: the first scan to the latest (log times never go back).
    let ns = |t: f64| (t * 1e9).round() as u64;
    let latest = scans.iter().map(|s| ns(s.stamp)).max().unwrap();
    assert_eq!(stats.message_start_time, ns(scans[0].stamp));
    assert_eq!(stats.message_end_time, latest);

    // Scan 10 decodes to the ranges read from the log, in the `laser` frame.
    let (t, data) = &messages(&path, "/scan")[10];
    let scan = LaserScan::decode(data.as_slice()).unwrap();
    let before = scans[..=10].iter().map(|s| ns(s.stamp)).max().unwrap();
    assert_eq!(*t, before);
    assert_eq!(scan.frame_id, "laser");
    let ranges: Vec<f64> = scans[10].ranges.iter().map(|r| f64::from(*r)).collect();
    assert_eq!(scan.ranges.len(), 180);
    for (a, b) in scan.ranges.iter().zip(&ranges) {
        assert!(a == b || (a.is_infinite() && *b >= 81.8), "{a} vs {b}");
    }
    assert!((scan.start_angle + core::f64::consts::FRAC_PI_2).abs() < 1e-6);
    // The last trajectory holds every estimate, equal to the run's.
    let (_, data) = messages(&path, "/trajectory").pop().unwrap();
    let traj = PosesInFrame::decode(data.as_slice()).unwrap();
    assert_eq!(traj.poses.len(), 300);
    let last = traj.poses[299].position.unwrap();
    let est = run.trajectory[299].1;
    assert_eq!((last.x, last.y), (f64::from(est.x), f64::from(est.y)));
    // The transforms chain map → odom → base_link → laser and compose to the estimate.
    let (_, data) = &messages(&path, "/tf")[299];
    let tf = FrameTransforms::decode(data.as_slice()).unwrap();
    let names: Vec<_> = tf
        .transforms
        .iter()
        .map(|t| (t.parent_frame_id.as_str(), t.child_frame_id.as_str()))
        .collect();
    assert_eq!(
        names,
        [
            ("map", "odom"),
            ("odom", "base_link"),
            ("base_link", "laser")
        ]
    );
    let pose = |k: usize| {
        let t = &tf.transforms[k];
        let (v, q) = (t.translation.unwrap(), t.rotation.unwrap());
        Pose2::new(v.x, v.y, 2.0 * q.z.atan2(q.w))
    };
    let composed = pose(0).compose(&pose(1));
    assert!(
        (composed.x - f64::from(est.x)).abs() < 1e-5,
        "{composed:?} {est:?}"
    );
    assert!(
        (composed.y - f64::from(est.y)).abs() < 1e-5,
        "{composed:?} {est:?}"
    );
    // The last grid is the final map, cropped: every known cell drawn opaque.
    let (_, data) = messages(&path, "/map").pop().unwrap();
    let grid = Grid::decode(data.as_slice()).unwrap();
    let opaque = grid.data.chunks(4).filter(|c| c[3] == 255).count();
    let known = run.cells.iter().filter(|c| **c != 0).count();
    assert_eq!(opaque, known);
    assert_eq!(grid.cell_stride, 4);
    assert_eq!(
        grid.data.len() as u32,
        grid.row_stride * (grid.data.len() as u32 / grid.row_stride)
    );
}

#[test]
fn a_sim_recording_has_the_landmark_and_the_grid_runs() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("short.toml");
    std::fs::write(&cfg, "[scenario]\nduration_s = 20.0\n").unwrap();
    let path = dir.path().join("sim.mcap");
    let options = SimOptions {
        out: dir.path().join("out"),
        config: Some(cfg),
        no_plots: true,
        grid_particles: 16,
        mcap: Some(path.clone()),
        ..SimOptions::default()
    };
    run_cli(&options, true).unwrap();
    let (ch, _) = channels(&path);
    for topic in [
        "/ekf/pose",
        "/ekf/odometry",
        "/ekf/ground_truth",
        "/ekf/landmarks",
        "/ekf/true_landmarks",
        "/grid_slam/scan",
        "/grid_slam/map",
        "/grid_slam/particles",
        "/grid_slam/ground_truth",
        "/grid_localize/scan",
        "/grid_localize/map",
    ] {
        assert!(ch.get(topic).is_some_and(|c| c.2 > 0), "{topic}: {ch:?}");
    }
    // The localizer's map is fixed: written once.
    assert_eq!(ch["/grid_localize/map"].2, 1);
    assert_eq!(ch["/grid_slam/scan"].2, ch["/grid_localize/scan"].2);
    // The true landmarks decode to the simulator's, with their ids, in the `ekf/map` frame.
    let settings = host_sim::domain::config::Settings::load_for(
        "sim",
        Some(&dir.path().join("short.toml")),
        None,
    )
    .unwrap();
    let truth = host_sim::inputs::sim::simulate(&settings, 1)
        .unwrap()
        .landmarks;
    let (_, data) = &messages(&path, "/ekf/true_landmarks")[0];
    let update = SceneUpdate::decode(data.as_slice()).unwrap();
    assert_eq!(update.entities.len(), truth.len());
    for (e, l) in update.entities.iter().zip(&truth) {
        assert_eq!(e.frame_id, "ekf/map");
        assert_eq!(e.texts[0].text, l.id.to_string());
        let p = e.spheres[0].pose.unwrap().position.unwrap();
        assert_eq!((p.x, p.y), (l.position[0], l.position[1]));
    }
    // The estimated landmarks grow in number as the map is built, each with a 3σ ellipse.
    let updates: Vec<SceneUpdate> = messages(&path, "/ekf/landmarks")
        .iter()
        .map(|(_, d)| SceneUpdate::decode(d.as_slice()).unwrap())
        .collect();
    assert!(updates.len() > 10, "{} map snapshots", updates.len());
    let counts: Vec<usize> = updates.iter().map(|u| u.entities.len()).collect();
    assert!(counts.windows(2).all(|w| w[0] <= w[1]), "{counts:?}");
    assert!(counts[0] < counts[counts.len() - 1], "{counts:?}");
    let last = updates.last().unwrap();
    assert!(last.entities.iter().all(|e| e.cylinders.len() == 1));
}
