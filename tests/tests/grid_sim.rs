//! The grid particle filter in the simulator's lidar world (`host-sim sim`), against
//! ground truth: grid SLAM and the localizer on the true map, with the host settings
//! (`GridPfConfig::DEFAULT`, P = 200, all 180 beams) and the firmware's
//! (`GridPfConfig::MICROCONTROLLER`, P = 32, 90 beams, a 256 × 256 grid), all in f32.
//!
//! Bounds are the ATEs measured on these seeds (noted next to each) plus at most 5 %.
//! Re-measure with `cargo test -p microslam-replay-tests --test grid_sim -- --nocapture`.

use host_sim::grid_replay::GridRun;
use host_sim::sim::grid::{ate_m, odometry_ate_m, run_localizer, run_slam, true_map};
use host_sim::sim::lidar_world::{LidarRecording, LidarWorld, simulate};
use microslam::pf::GridPfConfig;

fn recording(seed: u64) -> LidarRecording {
    simulate(&LidarWorld::office(), seed).unwrap()
}

/// The firmware's settings: MICROCONTROLLER with every second beam (90 of 180).
fn mcu() -> GridPfConfig {
    GridPfConfig {
        beam_decimation: 2,
        ..GridPfConfig::MICROCONTROLLER
    }
}

fn check(rec: &LidarRecording, run: &GridRun, what: &str, bound: f64) -> f64 {
    assert_eq!(run.trajectory.len(), rec.scans.len(), "{what}");
    assert_eq!(run.skipped_scans, 0, "{what}");
    let ate = ate_m(rec, &run.trajectory);
    let odo = odometry_ate_m(rec);
    println!("{what}: ATE {ate:.4} m (dead reckoning {odo:.3} m)");
    assert!(odo > 0.5, "the simulated odometry must drift: {odo}");
    assert!(ate < bound, "{what}: ATE {ate:.4} m ≥ {bound} m");
    ate
}

#[test]
fn slam_host_settings_p200() {
    let rec = recording(3);
    let run = run_slam::<200, 180>(&rec, GridPfConfig::DEFAULT).unwrap();
    check(&rec, &run, "SLAM DEFAULT P=200", 0.153); // measured 0.1461 m
}

#[test]
fn slam_microcontroller_settings_p32() {
    let rec = recording(3);
    let run = run_slam::<32, 90>(&rec, mcu()).unwrap();
    check(&rec, &run, "SLAM MICROCONTROLLER P=32", 0.113); // measured 0.1085 m
}

#[test]
fn localizer_on_the_true_map() {
    let rec = recording(2);
    let host = GridPfConfig::DEFAULT;
    let map = true_map(&rec.world.walls, &host);
    let run = run_localizer::<200, 180>(&rec, &map.view(), host).unwrap();
    check(&rec, &run, "localizer DEFAULT P=200", 0.034); // measured 0.0328 m
    let map = true_map(&rec.world.walls, &mcu());
    let run = run_localizer::<32, 90>(&rec, &map.view(), mcu()).unwrap();
    check(&rec, &run, "localizer MICROCONTROLLER P=32", 0.035); // measured 0.0337 m
}

#[test]
fn same_seed_same_estimate() {
    let rec = recording(4);
    let a = run_slam::<32, 90>(&rec, mcu()).unwrap();
    let b = run_slam::<32, 90>(&rec, mcu()).unwrap();
    assert_eq!(a.trajectory, b.trajectory);
    assert_eq!(a.cells, b.cells);
}
