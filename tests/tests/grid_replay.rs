//! The grid particle filter on real lidar logs: the Intel Research Lab CARMEN log against
//! the benchmark relations, the localizer on the map SLAM built, and THOR's Hokuyo scan
//! geometry. Bounds are what was measured (noted next to each) plus at most 5 %; counts
//! are exact. Re-measure with `cargo test -p microslam-replay-tests --test grid_replay --
//! --nocapture` (docs/testing.md).

use host_sim::domain::datasets::dataset_path;
use host_sim::domain::grid::carmen_lidar;
use host_sim::domain::grid::{GRID_BITMAP, GRID_CELLS};
use host_sim::drivers::grid::{GridRun, GridRunOptions, carmen_inputs, run_localizer, run_slam};
use host_sim::inputs::readers::carmen::{LaserMessage, front_scans, read_log};
use host_sim::metrics::relations::{self, relation_error};
use microslam::geometry::Pose2;
use microslam::grid::GridView;
use microslam::pf::GridPfConfig;
use microslam::sensors::lidar::{LidarGeometry, LidarScan};
use microslam::slam::GraphSlamConfig;

fn intel() -> (
    host_sim::inputs::readers::carmen::CarmenLog,
    Vec<relations::Relation>,
) {
    let log =
        read_log(&dataset_path("intel/intel-raw-part.clf").expect("Intel log")).expect("read");
    let rels =
        relations::read(&dataset_path("intel/intel.relations").expect("relations")).expect("read");
    (log, rels)
}

/// Grid SLAM on the Intel log's `scans` from the origin with `particles` particles,
/// `config` and the log's 180-beam lidar; the options with the run.
fn intel_slam(
    scans: &[&LaserMessage],
    particles: usize,
    config: GridPfConfig,
) -> (GridRunOptions, GridRun) {
    intel_slam_closing(scans, particles, config, None)
}

/// [`intel_slam`] with grid SLAM's loop closure when `loop_closure` is given.
fn intel_slam_closing(
    scans: &[&LaserMessage],
    particles: usize,
    config: GridPfConfig,
    loop_closure: Option<GraphSlamConfig>,
) -> (GridRunOptions, GridRun) {
    let options = GridRunOptions {
        particles,
        config,
        lidar: carmen_lidar(180),
        loop_closure,
        grid_origin: None,
        max_odometry_step_m: host_sim::domain::grid::MAX_ODOMETRY_STEP_M,
    };
    let run = run_slam::<GRID_CELLS, GRID_BITMAP>(
        &carmen_inputs(scans),
        Pose2::IDENTITY,
        &options,
        &|_| {},
    )
    .expect("the run completes");
    (options, run)
}

#[test]
fn intel_log_is_read_in_file_order() {
    let (log, rels) = intel();
    let scans: Vec<_> = log.lasers().collect();
    assert_eq!(scans.len(), 5505);
    assert!(scans.iter().all(|s| s.ranges.len() == 180 && !s.rear));
    // Real data: the stamps go backwards 265 times in file order (see the datasets README).
    let backwards = scans.windows(2).filter(|w| w[1].stamp < w[0].stamp).count();
    assert_eq!(backwards, 265);
    assert_eq!(rels.len(), 2984);
}

#[test]
fn intel_grid_slam_relation_error() {
    let (log, rels) = intel();
    let (options, run) = intel_slam(&front_scans(&log), 200, GridPfConfig::DEFAULT);
    let e = relation_error(&run, &rels);
    println!("P=200, 180 beams: {e:?}");
    assert_eq!(e.used, 1030);
    // Measured: 0.02428 ± 0.0280 m, 0.2895 ± 0.272° (seeds 1–3: 0.0265–0.0282 m).
    assert!(e.trans_mean_m < 0.0254, "{e:?}");
    assert!(e.rot_mean_deg < 0.30, "{e:?}");

    // Localization on the map SLAM built, from the first scan's pose.
    let view = GridView::new(
        &run.cells,
        run.geometry,
        options.config.log_odds.occupied_above,
    )
    .expect("map");
    let loc = run_localizer(
        &carmen_inputs(&front_scans(&log)),
        &view,
        Pose2::IDENTITY,
        &options,
        &|_| {},
    )
    .expect("localize");
    let el = relation_error(&loc, &rels);
    println!("localizer on that map: {el:?}");
    // Measured: 0.03260 ± 0.0455 m, 0.3096 ± 0.324°.
    assert_eq!(el.used, 1030);
    assert!(el.trans_mean_m < 0.034, "{el:?}");
    assert!(el.rot_mean_deg < 0.32, "{el:?}");
    // The localizer's lost detection over the run (SLAM has none). Measured: one lost
    // event (a stretch of low hit fractions; without layers it does not search) and
    // tracking again at the end.
    assert_eq!(run.localizer, None);
    let summary = loc.localizer.expect("a localizer's summary");
    assert!(summary.lost_events <= 1, "{summary:?}");
    assert_eq!(summary.final_state, "tracking", "{summary:?}");
}

/// ATE (SE(2) alignment) of a run against the GMapping-corrected poses of the log.
fn ate_against_gmapping(run: &GridRun) -> f64 {
    let reference = dataset_path("intel/intel.gfs.log").expect("GMapping-corrected poses");
    let ate = host_sim::metrics::reference::grid_run_ate(run, &reference, 976_052_857.337)
        .expect("reference");
    ate.ate_m.se2.expect("SE(2) ATE")
}

#[test]
fn intel_building_scale_slam_closes_the_loops_with_the_firmware_settings() {
    // The device's grid SLAM (`microslam::slam::GraphSlam`: a local map that follows the
    // robot, keyframes, a pose graph closing loops) with the firmware's settings: P = 32,
    // 90 of the 180 beams. Without loop closure the one-map grid SLAM bends the map on
    // some filter seeds (docs/results-grid.md).
    let (log, rels) = intel();
    let scans = front_scans(&log);
    let config = GridPfConfig {
        beam_decimation: 2,
        ..GridPfConfig::MICROCONTROLLER
    };
    let (_, with) = intel_slam_closing(&scans, 32, config, Some(GraphSlamConfig::MICROCONTROLLER));
    let e = relation_error(&with, &rels);
    let a = ate_against_gmapping(&with);
    let summary = with.loop_closure.expect("a loop closure summary");
    println!("filter seed 0: {e:?}, ATE {a:.4} m, {summary:?}");
    // Measured with the board profile's sizes (microslam::profile::Slam): relation
    // 0.0204 m, ATE 0.0665 m; counts exact.
    assert!(e.trans_mean_m < 0.0214, "{e:?}");
    assert!(a < 0.0698, "ATE {a}");
    assert_eq!(with.trajectory.len(), scans.len());
    assert_eq!(
        (summary.keyframes, summary.attempts, summary.closures),
        (492, 230, 143),
        "{summary:?}"
    );
}

#[test]
fn intel_grid_slam_microcontroller_settings() {
    // P = 32 particles, 90 of the 180 beams: the firmware's settings.
    let (log, rels) = intel();
    let mut config = GridPfConfig::MICROCONTROLLER;
    config.beam_decimation = 2;
    let (_, run) = intel_slam(&front_scans(&log), 32, config);
    let e = relation_error(&run, &rels);
    println!("P=32, 90 beams: {e:?}");
    assert_eq!(e.used, 1030);
    assert!(e.trans_mean_m < 0.0302, "{e:?}"); // measured 0.0287 (seeds 1–4: 0.0265–0.0307 m)
}

#[test]
fn intel_grid_slam_with_faults_refuses_exactly_what_was_injected() {
    // `host-sim replay --faults all=0.01` on the Intel log: drops, duplicates, swaps,
    // NaN odometry and ranges, range spikes, a stuck lidar, stamps one second back.
    let (log, rels) = intel();
    let clean = front_scans(&log);
    let rates: host_sim::inputs::faults::FaultRates = "all=0.01".parse().expect("rates");
    let (faulty, injected) = host_sim::inputs::faults::inject_scans(&clean, &rates, 1);
    assert!(injected.total() > 300 && injected.stuck > 0, "{injected:?}");
    let scans: Vec<_> = faulty.iter().collect();
    let (_, run) = intel_slam(&scans, 200, GridPfConfig::DEFAULT);
    // The log itself has no NaN: every refusal is an injected fault, and every injected
    // NaN (with the copies made by duplication and the stuck lidar) is refused.
    assert_eq!(run.refused_odometry, injected.nan_odometry, "{injected:?}");
    assert_eq!(run.non_finite_beams, injected.nan_ranges, "{injected:?}");
    assert_eq!(run.trajectory.len(), scans.len());
    let e = relation_error(&run, &rels);
    println!("all=0.01: {injected:?} {e:?}");
    // Measured: 0.02704 ± 0.0348 m over 989 relations (0.0243 m without faults).
    assert!(e.trans_mean_m < 0.028, "{e:?}");
    assert_eq!(e.used, 989, "{e:?}");
}

#[test]
fn thor_hokuyo_scan_geometry() {
    let path = dataset_path("thor/test_ranges.npy").expect("THOR scan");
    let bytes = std::fs::read(&path).expect("read");
    let npy = npyz::NpyFile::new(&bytes[..]).expect("npy");
    let ranges: Vec<f32> = match npy.dtype() {
        npyz::DType::Plain(t) if t.size_field() == 8 => npy
            .into_vec::<f64>()
            .expect("f64")
            .into_iter()
            .map(|v| v as f32)
            .collect(),
        _ => npy.into_vec::<f32>().expect("f32"),
    };
    // 1081 beams from −135° to +135° in 0.25° steps: the last beam looks at +135°.
    assert_eq!(ranges.len(), 1081);
    let g = LidarGeometry::THOR_HOKUYO;
    assert!((g.beam_angle(1080).to_degrees() - 135.0).abs() < 1e-3);
    assert!((g.beam_angle(540)).abs() < 1e-6);
    let scan = LidarScan::new(&ranges, g);
    let (valid, not_finite, no_return, out_of_range) = scan.census();
    println!(
        "THOR scan: {valid} valid, {not_finite} not finite, {no_return} no return, {out_of_range} out of range"
    );
    assert_eq!(valid + not_finite + no_return + out_of_range, 1081);
    assert!(valid > 900, "{valid}");
    // Every end point lies within 30 m of the sensor, which sits 0.298 m ahead of the axle.
    for b in scan.beams(1) {
        let (dx, dy) = (b.robot_point.0 - 0.29833, b.robot_point.1);
        assert!(((dx * dx + dy * dy).sqrt() - b.range).abs() < 1e-3);
        assert!(b.range < 30.0);
    }
}
