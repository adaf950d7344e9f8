//! The grid particle filter in the simulator's lidar world ([`super::lidar_world`]):
//! grid SLAM from the true start pose, and the localizer on the true map rasterised from
//! the wall segments (what a map in flash would hold), both scored against ground truth.
//!
//! ATE here is the RMSE of the robot position with **no alignment**: both filters start
//! at the true start pose in the world frame, so the estimate's frame is the truth's.

use super::lidar_world::{LidarRecording, Wall};
use crate::grid_replay::{GridRun, MAX_BEAMS};
use anyhow::{Result, anyhow, bail};
use microslam::geometry::Pose2;
use microslam::grid::{GridView, OccupancyGrid};
use microslam::pf::{GridLocalizer, GridPfConfig, GridSlam};
use microslam::sensors::lidar::LidarScan;
use std::path::Path;
use std::time::Instant;

/// Grid edge in cells: 256 × 256 (12.8 m at 5 cm, 64 KB — the firmware's map size).
pub const SIM_GRID_CELLS: usize = 256;

/// The simulator's grid.
pub type SimGrid = OccupancyGrid<SIM_GRID_CELLS, SIM_GRID_CELLS>;

fn f32_pose(p: &Pose2<f64>) -> Pose2<f32> {
    Pose2::new(p.x as f32, p.y as f32, p.theta as f32)
}

/// Grid SLAM with `P` particles and at most `B` beams per scan over the recording, from
/// the true start pose.
pub fn run_slam<const P: usize, const B: usize>(
    rec: &LidarRecording,
    config: GridPfConfig,
) -> Result<GridRun> {
    let first = rec.scans.first().ok_or_else(|| anyhow!("no scans"))?;
    let mut grid = Box::new(SimGrid::centred(config.resolution, config.log_odds));
    let mut run = GridRun {
        trajectory: Vec::with_capacity(rec.scans.len()),
        cells: Vec::new(),
        geometry: *grid.geometry(),
        filter_time_s: 0.0,
        skipped_scans: 0,
        refused_odometry: 0,
        non_finite_beams: 0,
    };
    let t0 = Instant::now();
    {
        let mut slam = GridSlam::<SIM_GRID_CELLS, SIM_GRID_CELLS, P, B>::new(
            &mut grid,
            config,
            f32_pose(&first.truth),
        )
        .map_err(|e| anyhow!("grid SLAM: {e}"))?;
        let mut previous: Option<Pose2<f32>> = None;
        for (i, s) in rec.scans.iter().enumerate() {
            let odom = f32_pose(&s.odometry);
            if let Some(p) = previous {
                slam.predict_odometry(&p, &odom)
                    .map_err(|e| anyhow!("scan {i}: {e}"))?;
            }
            previous = Some(odom);
            match slam.observe(&LidarScan::new(&s.ranges, rec.lidar)) {
                Ok(r) => run.trajectory.push((s.stamp, r.pose)),
                Err(_) => {
                    run.skipped_scans += 1;
                    run.trajectory.push((s.stamp, slam.pose()));
                }
            }
        }
    }
    run.filter_time_s = t0.elapsed().as_secs_f64();
    run.cells = grid.cells().to_vec();
    Ok(run)
}

/// The true map: every wall segment drawn into a grid as saturated occupied cells
/// (everything else unknown), sampled every quarter cell along each wall.
pub fn true_map(walls: &[Wall], config: &GridPfConfig) -> Box<SimGrid> {
    let mut grid = Box::new(SimGrid::centred(config.resolution, config.log_odds));
    let g = *grid.geometry();
    let step = f64::from(g.resolution) / 4.0;
    for w in walls {
        let len = (w.b[0] - w.a[0]).hypot(w.b[1] - w.a[1]);
        let n = (len / step).ceil().max(1.0) as usize;
        for i in 0..=n {
            let f = i as f64 / n as f64;
            let x = w.a[0] + f * (w.b[0] - w.a[0]);
            let y = w.a[1] + f * (w.b[1] - w.a[1]);
            if let Some((ix, iy)) = g.world_to_cell(x as f32, y as f32) {
                grid.set_cell(ix as i32, iy as i32, config.log_odds.max);
            }
        }
    }
    grid
}

/// The localizer with `P` particles and at most `B` beams on `map`, from the true start.
pub fn run_localizer<const P: usize, const B: usize>(
    rec: &LidarRecording,
    map: &GridView<'_>,
    config: GridPfConfig,
) -> Result<GridRun> {
    let first = rec.scans.first().ok_or_else(|| anyhow!("no scans"))?;
    let mut run = GridRun {
        trajectory: Vec::with_capacity(rec.scans.len()),
        cells: map.cells().to_vec(),
        geometry: *map.geometry(),
        filter_time_s: 0.0,
        skipped_scans: 0,
        refused_odometry: 0,
        non_finite_beams: 0,
    };
    let t0 = Instant::now();
    let mut loc = GridLocalizer::<P, B>::new(*map, config, f32_pose(&first.truth))
        .map_err(|e| anyhow!("grid localizer: {e}"))?;
    let mut previous: Option<Pose2<f32>> = None;
    for (i, s) in rec.scans.iter().enumerate() {
        let odom = f32_pose(&s.odometry);
        if let Some(p) = previous {
            loc.predict_odometry(&p, &odom)
                .map_err(|e| anyhow!("scan {i}: {e}"))?;
        }
        previous = Some(odom);
        match loc.observe(&LidarScan::new(&s.ranges, rec.lidar)) {
            Ok(r) => run.trajectory.push((s.stamp, r.pose)),
            Err(_) => {
                run.skipped_scans += 1;
                run.trajectory.push((s.stamp, loc.pose()));
            }
        }
    }
    run.filter_time_s = t0.elapsed().as_secs_f64();
    Ok(run)
}

/// Position RMSE of `trajectory` against the recording's truth (same length, no
/// alignment), metres.
pub fn ate_m(rec: &LidarRecording, trajectory: &[(f64, Pose2<f32>)]) -> f64 {
    let n = trajectory.len().min(rec.scans.len()).max(1);
    let sum: f64 = trajectory
        .iter()
        .zip(&rec.scans)
        .map(|((_, e), s)| {
            (f64::from(e.x) - s.truth.x).powi(2) + (f64::from(e.y) - s.truth.y).powi(2)
        })
        .sum();
    (sum / n as f64).sqrt()
}

/// Heading RMSE against the truth, degrees.
pub fn yaw_rmse_deg(rec: &LidarRecording, trajectory: &[(f64, Pose2<f32>)]) -> f64 {
    let n = trajectory.len().min(rec.scans.len()).max(1);
    let sum: f64 = trajectory
        .iter()
        .zip(&rec.scans)
        .map(|((_, e), s)| {
            microslam::geometry::wrap_angle(f64::from(e.theta) - s.truth.theta).powi(2)
        })
        .sum();
    (sum / n as f64).sqrt().to_degrees()
}

/// Dead-reckoning ATE (the odometry poses against the truth), metres.
pub fn odometry_ate_m(rec: &LidarRecording) -> f64 {
    let traj: Vec<(f64, Pose2<f32>)> = rec
        .scans
        .iter()
        .map(|s| (s.stamp, f32_pose(&s.odometry)))
        .collect();
    ate_m(rec, &traj)
}

/// Particle counts `host-sim sim --grid-particles` accepts.
pub const SIM_PARTICLES: [usize; 4] = [16, 32, 64, 200];

/// Runs SLAM and the localizer with `particles` particles, writing
/// `out/slam/` and `out/localize/` (map.pgm, map.yaml, map.png, trajectory.tum,
/// groundtruth.tum, metrics.json). Returns the two metrics documents.
pub fn run_and_write(
    rec: &LidarRecording,
    config: GridPfConfig,
    particles: usize,
    out: &Path,
) -> Result<(serde_json::Value, serde_json::Value)> {
    let started = Instant::now();
    let slam = match particles {
        16 => run_slam::<16, MAX_BEAMS>(rec, config),
        32 => run_slam::<32, MAX_BEAMS>(rec, config),
        64 => run_slam::<64, MAX_BEAMS>(rec, config),
        200 => run_slam::<200, MAX_BEAMS>(rec, config),
        other => bail!("--grid-particles {other} is not compiled in; use one of {SIM_PARTICLES:?}"),
    }?;
    let slam_wall = started.elapsed().as_secs_f64();
    let map = true_map(&rec.world.walls, &config);
    let view = map.view();
    let started = Instant::now();
    let loc = match particles {
        16 => run_localizer::<16, MAX_BEAMS>(rec, &view, config),
        32 => run_localizer::<32, MAX_BEAMS>(rec, &view, config),
        64 => run_localizer::<64, MAX_BEAMS>(rec, &view, config),
        _ => run_localizer::<200, MAX_BEAMS>(rec, &view, config),
    }?;
    let loc_wall = started.elapsed().as_secs_f64();
    let truth: Vec<(f64, Pose2<f32>)> = rec
        .scans
        .iter()
        .map(|s| (s.stamp, f32_pose(&s.truth)))
        .collect();
    let odometry_ate = odometry_ate_m(rec);
    let mut docs = Vec::new();
    for (name, run, wall, what) in [
        (
            "slam",
            &slam,
            slam_wall,
            "grid SLAM from the true start pose",
        ),
        (
            "localize",
            &loc,
            loc_wall,
            "grid localizer on the true map (walls rasterised)",
        ),
    ] {
        let dir = out.join(name);
        let scans = run.trajectory.len();
        let metrics = serde_json::json!({
            "dataset": rec.name,
            "estimator": what,
            "scans": scans,
            "particles": particles,
            "beams": rec.lidar_beams(),
            "ate_rmse_m": ate_m(rec, &run.trajectory),
            "ate_alignment": "none (the filter starts at the true start pose)",
            "yaw_rmse_deg": yaw_rmse_deg(rec, &run.trajectory),
            "odometry_ate_rmse_m": odometry_ate,
            "wall_time_s": wall,
            "filter_time_s": run.filter_time_s,
            "ms_per_scan": 1e3 * run.filter_time_s / scans.max(1) as f64,
            "skipped_scans": run.skipped_scans,
            "window": 2 * u32::from(config.filter.shift_window_cells) + 1,
            "beam_decimation": config.beam_decimation,
            "range_weight_exponent": config.range_weight_exponent,
            "seed": config.filter.seed,
        });
        crate::grid_replay::write_outputs(&dir, run, &config, &metrics)?;
        crate::output::grid_map::write_tum(&dir.join("groundtruth.tum"), &truth)?;
        docs.push(metrics);
    }
    let loc_doc = docs.pop().unwrap_or_default();
    let slam_doc = docs.pop().unwrap_or_default();
    Ok((slam_doc, loc_doc))
}

impl LidarRecording {
    /// Beams per sweep.
    pub fn lidar_beams(&self) -> usize {
        self.scans.first().map_or(0, |s| s.ranges.len())
    }
}
