//! The grid particle filter in the simulator's lidar world (`host-sim sim`), against
//! ground truth: grid SLAM and the localizer on the true map, with the host settings
//! (`GridPfConfig::DEFAULT`, P = 200, all 180 beams) and the firmware's
//! (`GridPfConfig::MICROCONTROLLER`, P = 32, 90 beams, a 256 × 256 grid), all in f32.
//!
//! Bounds are the ATEs measured on these seeds (noted next to each) plus at most 5 %.
//! Re-measure with `cargo test -p microslam-replay-tests --test grid_sim -- --nocapture`.

use host_sim::drivers::grid::{self, GridRun, GridRunOptions, f32_pose, sim_inputs};
use host_sim::inputs::sim::lidar_world::{
    LidarRecording, LidarWorld, SIM_GRID_BITMAP, SIM_GRID_CELLS, simulate, true_map,
};
use host_sim::metrics::grid::{ate_m, odometry_ate_m};
use microslam::grid::GridView;
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

fn options(rec: &LidarRecording, particles: usize, config: GridPfConfig) -> GridRunOptions {
    GridRunOptions {
        particles,
        config,
        lidar: rec.lidar,
        loop_closure: None,
        grid_origin: None,
        max_odometry_step_m: host_sim::domain::grid::MAX_ODOMETRY_STEP_M,
    }
}

/// Grid SLAM on the firmware's 256 × 256 grid from the true start pose.
fn run_slam(rec: &LidarRecording, particles: usize, config: GridPfConfig) -> GridRun {
    let start = f32_pose(&rec.scans[0].truth);
    let opts = options(rec, particles, config);
    grid::run_slam::<SIM_GRID_CELLS, SIM_GRID_BITMAP>(&sim_inputs(rec), start, &opts, &|_| {})
        .unwrap()
}

/// The localizer on `map` from the true start pose.
fn run_localizer(
    rec: &LidarRecording,
    map: &GridView<'_>,
    particles: usize,
    config: GridPfConfig,
) -> GridRun {
    let start = f32_pose(&rec.scans[0].truth);
    let opts = options(rec, particles, config);
    grid::run_localizer(&sim_inputs(rec), map, start, &opts, &|_| {}).unwrap()
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
    let run = run_slam(&rec, 200, GridPfConfig::DEFAULT);
    check(&rec, &run, "SLAM DEFAULT P=200", 0.153); // measured 0.1461 m
}

#[test]
fn slam_microcontroller_settings_p32() {
    let rec = recording(3);
    let run = run_slam(&rec, 32, mcu());
    check(&rec, &run, "SLAM MICROCONTROLLER P=32", 0.0799); // measured 0.0761 m (0.108 m without the shift prior)
}

#[test]
fn localizer_on_the_true_map() {
    let rec = recording(2);
    let host = GridPfConfig::DEFAULT;
    let map = true_map(&rec.world.walls, &host);
    let run = run_localizer(&rec, &map.view(), 200, host);
    check(&rec, &run, "localizer DEFAULT P=200", 0.034); // measured 0.0328 m
    let map = true_map(&rec.world.walls, &mcu());
    let run = run_localizer(&rec, &map.view(), 32, mcu());
    check(&rec, &run, "localizer MICROCONTROLLER P=32", 0.035); // measured 0.0337 m
}

#[test]
fn same_seed_same_estimate() {
    let rec = recording(4);
    let a = run_slam(&rec, 32, mcu());
    let b = run_slam(&rec, 32, mcu());
    assert_eq!(a.trajectory, b.trajectory);
    assert_eq!(a.cells, b.cells);
}

#[test]
fn end_points_off_the_grid_are_counted_not_written() {
    let rec = recording(1);
    let start = f32_pose(&rec.scans[0].truth);
    let inputs = sim_inputs(&rec);
    let run_with = |grid_origin| {
        let opts = GridRunOptions {
            grid_origin,
            ..options(&rec, 16, mcu())
        };
        grid::run_slam::<SIM_GRID_CELLS, SIM_GRID_BITMAP>(&inputs, start, &opts, &|_| {}).unwrap()
    };
    // The office on its grid centred on the world's origin, as `host-sim sim` runs it:
    // every end point is written.
    let centred = run_with(None);
    assert_eq!(
        (centred.off_grid_end_points, centred.scans_off_grid),
        (0, 0)
    );
    // The grid moved 6 m to the east (half its width): what lies west of x = −0.4 m is
    // off it, end points there are counted, scan by scan, and the map holds none of them.
    let moved = run_with(Some([-0.4, -6.4]));
    println!(
        "off the grid: {} end points in {} of {} scans",
        moved.off_grid_end_points,
        moved.scans_off_grid,
        rec.scans.len()
    );
    assert!(moved.off_grid_end_points > 0 && moved.scans_off_grid > 0);
    assert!(moved.scans_off_grid <= rec.scans.len());
    assert_eq!(moved.geometry.origin_x, -0.4);
}

#[test]
fn a_localizer_counts_the_end_points_outside_its_map() {
    let rec = recording(2);
    let config = mcu();
    let map = true_map(&rec.world.walls, &config);
    let full = map.view();
    // The whole office: every end point lies on the map.
    let run = run_localizer(&rec, &full, 32, config);
    assert_eq!((run.off_grid_end_points, run.scans_off_grid), (0, 0));
    // The map's southern half (its first rows, the same origin): what the robot sees
    // north of the cut lies outside it and is counted, scan by scan.
    let mut half = *full.geometry();
    half.height /= 2;
    let cut = half.origin_y + half.height as f32 * half.resolution;
    let cells = &full.cells()[..half.width * half.height];
    let south = GridView::new(cells, half, full.occupied_above()).unwrap();
    let run = run_localizer(&rec, &south, 32, config);
    let north_of_cut = rec
        .world
        .walls
        .iter()
        .any(|w| w.a[1].max(w.b[1]) > f64::from(cut));
    assert!(north_of_cut, "the office must reach north of y = {cut} m");
    println!(
        "outside the southern half: {} end points in {} of {} scans",
        run.off_grid_end_points,
        run.scans_off_grid,
        rec.scans.len()
    );
    assert!(run.off_grid_end_points > 0 && run.scans_off_grid > 0);
    assert!(run.scans_off_grid <= rec.scans.len());
}
