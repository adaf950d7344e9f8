//! One grid particle-filter step (prediction + correlation with the 9 × 9 shift search +
//! reweighting/resampling) for P = 32, 64, 200 particles and 90 / 180 beams, on a
//! 256 × 256 map of a simulated office (walls drawn by ray-cast scans). `localize` scores
//! against a fixed map; `slam` also writes the scan into the grid; `slam_bitmap` does so on
//! a grid with an occupied-cell bitmap (the sparse shift search the firmware runs).

use core::hint::black_box;
use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use microslam::geometry::{Pose2, ray_to_segments};
use microslam::grid::{OccupancyGrid, occupancy_bytes};
use microslam::pf::{GridLocalizer, GridPfConfig, GridSlam};
use microslam::sensors::lidar::{LidarGeometry, LidarScan};

const WALLS: [[f32; 4]; 9] = [
    [-5.0, -4.0, 5.0, -4.0],
    [5.0, -4.0, 5.0, 4.0],
    [5.0, 4.0, -5.0, 4.0],
    [-5.0, 4.0, -5.0, -4.0],
    [-1.0, -4.0, -1.0, -1.0],
    [2.0, 1.0, 5.0, 1.0],
    [-3.5, 1.5, -2.0, 1.5],
    [-2.0, 1.5, -2.0, 2.5],
    [1.0, 2.5, 0.0, 3.2],
];

/// Range from `(x, y)` along `a` to the nearest of [`WALLS`] (81.9 m, the SICK's "no
/// return", when none).
fn cast(x: f32, y: f32, a: f32) -> f32 {
    ray_to_segments((x, y), (a.cos(), a.sin()), WALLS).unwrap_or(81.9)
}

fn scan_at(pose: &Pose2<f32>, beams: usize) -> (Vec<f32>, LidarGeometry) {
    let geometry = LidarGeometry {
        angle_increment: core::f32::consts::PI / beams as f32,
        ..LidarGeometry::CARMEN_SICK_180
    };
    let ranges = (0..beams)
        .map(|i| cast(pose.x, pose.y, pose.theta + geometry.beam_angle(i)))
        .collect();
    (ranges, geometry)
}

fn config() -> GridPfConfig {
    GridPfConfig::DEFAULT
}

const BITMAP: usize = occupancy_bytes(256, 256);

fn map<const BITMAP: usize>() -> Box<OccupancyGrid<256, 256, BITMAP>> {
    let c = config();
    let mut grid = Box::new(OccupancyGrid::<256, 256, BITMAP>::centred(
        c.resolution,
        c.log_odds,
    ));
    for k in 0..40 {
        let pose = Pose2::new(
            -3.0 + 0.15 * k as f32,
            -2.5 + 0.1 * k as f32,
            0.15 * k as f32,
        );
        let (r, g) = scan_at(&pose, 360);
        grid.integrate_scan(&pose, &LidarScan::new(&r, g), 1)
            .unwrap();
    }
    grid
}

macro_rules! bench_p {
    ($group:expr, $grid:expr, $p:literal, $beams:expr) => {{
        let pose = Pose2::new(0.5f32, -0.5, 0.3);
        let (ranges, geometry) = scan_at(&pose, $beams);
        let scan = LidarScan::new(&ranges, geometry);
        let mut loc = GridLocalizer::<$p, 180>::new($grid.view(), config(), pose).unwrap();
        loc.reset_around(pose, 0.05, 0.02).unwrap();
        $group.bench_function(BenchmarkId::new(format!("localize/P{}", $p), $beams), |b| {
            b.iter(|| {
                loc.predict(black_box(0.0), black_box(0.0)).unwrap();
                black_box(loc.observe(&scan).unwrap())
            })
        });
    }};
}

fn grid_step(c: &mut Criterion) {
    let grid = map::<0>();
    let mut group = c.benchmark_group("grid_step");
    group
        .measurement_time(std::time::Duration::from_secs(2))
        .warm_up_time(std::time::Duration::from_millis(500));
    for beams in [90usize, 180] {
        bench_p!(group, grid, 32, beams);
        bench_p!(group, grid, 64, beams);
        bench_p!(group, grid, 200, beams);
    }
    // SLAM: the same step plus writing the scan into the grid (firmware and host sizes).
    for beams in [90usize, 180] {
        let pose = Pose2::new(0.5f32, -0.5, 0.3);
        let (ranges, geometry) = scan_at(&pose, beams);
        let scan = LidarScan::new(&ranges, geometry);
        let mut g = map::<0>();
        let mut slam = GridSlam::<256, 256, 32, 180>::new(&mut g, config(), pose).unwrap();
        slam.observe(&scan).unwrap();
        group.bench_function(BenchmarkId::new("slam/P32", beams), |b| {
            b.iter(|| {
                slam.predict(black_box(0.0), black_box(0.0)).unwrap();
                black_box(slam.observe(&scan).unwrap())
            })
        });
        let mut g = map::<BITMAP>();
        let mut slam = GridSlam::<256, 256, 32, 180, BITMAP>::new(&mut g, config(), pose).unwrap();
        slam.observe(&scan).unwrap();
        group.bench_function(BenchmarkId::new("slam_bitmap/P32", beams), |b| {
            b.iter(|| {
                slam.predict(black_box(0.0), black_box(0.0)).unwrap();
                black_box(slam.observe(&scan).unwrap())
            })
        });
    }
    group.finish();
}

criterion_group!(benches, grid_step);
criterion_main!(benches);
