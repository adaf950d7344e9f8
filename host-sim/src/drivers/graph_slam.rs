//! The device's building-scale grid SLAM ([`microslam::slam::GraphSlam`]) over a lidar
//! log: the particle filter on the local map that follows the robot, keyframes in a
//! store in memory, loop closure by the pose graph. The same code and sizes as the
//! board profile's ([`microslam::profile::Slam`]: local map, graph, beams; the particles
//! are the run's), so the host's figures are what the board computes.
//!
//! The trajectory written is the graph's at the end of the run: every scan at its
//! keyframe's final pose composed with the filter's motion from that keyframe to it.
//! The map is every keyframe's scan written at its final pose into a grid as large as
//! the host's (the device keeps only its local map and the keyframes).

use super::grid_run::{GraphSummary, GridInput, GridRun, GridRunOptions};
use super::scan_odometry::{OdometryStep, ScanOdometry};
use crate::domain::grid::ScanSpacing;
use anyhow::{Result, anyhow, bail};
use microslam::geometry::Pose2;
use microslam::grid::{OccupancyGrid, occupancy_bytes};
use microslam::profile;
use microslam::sensors::lidar::LidarScan;
use microslam::slam::graph::scratch_len;
use microslam::slam::keyframes::{KeyframeStorage, KeyframeStore, StoreError};
use microslam::slam::{GraphSlam, GraphSlamConfig};
use std::time::Instant;

/// Beams a scan the filter scores at most (the board profile's).
pub const GRAPH_BEAMS: usize = profile::GRID_BEAMS;
/// The local map's near log-odds window, cells (the board profile's).
pub const NEAR: usize = profile::SLAM_NEAR;
/// The local map's far bitmap, cells (the board profile's).
pub const FAR: usize = profile::SLAM_FAR;
/// Keyframes the graph holds (the board profile's).
pub const NODES: usize = profile::SLAM_NODES;
/// Loop edges the graph holds (the board profile's).
pub const LOOPS: usize = profile::SLAM_LOOPS;
const SCRATCH: usize = scratch_len(NODES, LOOPS);

/// The estimator with the sizes above and `P` particles.
pub type HostGraphSlam<const P: usize> = GraphSlam<
    P,
    GRAPH_BEAMS,
    NEAR,
    { occupancy_bytes(NEAR, NEAR) },
    FAR,
    { occupancy_bytes(FAR, FAR) },
    NODES,
    LOOPS,
    SCRATCH,
>;

/// Bytes of keyframe store the host gives a run (the keyframes of the largest logs with
/// room to spare; the firmware's is its flash region).
const STORE_BYTES: usize = 4 << 20;

/// A keyframe store's bytes in a `Vec` (the host's stand-in for a flash region: erased
/// bytes are `0xFF`).
pub struct VecStorage(Vec<u8>);

impl VecStorage {
    /// `bytes` bytes, erased.
    pub fn new(bytes: usize) -> Self {
        Self(vec![0xFF; bytes])
    }
}

impl KeyframeStorage for VecStorage {
    fn capacity(&self) -> usize {
        self.0.len()
    }
    fn read(&self, offset: usize, bytes: &mut [u8]) -> Result<(), StoreError> {
        let src = offset
            .checked_add(bytes.len())
            .and_then(|end| self.0.get(offset..end))
            .ok_or(StoreError::OutOfBounds)?;
        bytes.copy_from_slice(src);
        Ok(())
    }
    fn write(&mut self, offset: usize, bytes: &[u8]) -> Result<(), StoreError> {
        let dst = offset
            .checked_add(bytes.len())
            .and_then(|end| self.0.get_mut(offset..end))
            .ok_or(StoreError::OutOfBounds)?;
        dst.copy_from_slice(bytes);
        Ok(())
    }
    fn erase_all(&mut self) -> Result<(), StoreError> {
        self.0.fill(0xFF);
        Ok(())
    }
}

/// A run of [`GraphSlam`] over `inputs` from `start`, with the particle count and filter
/// settings of `options` and the rest of `graph`; the map drawn on an `N × N` grid placed
/// as `options.grid_origin` says (centred on the start without).
pub fn run_graph_slam<const N: usize, const BITMAP: usize>(
    inputs: &[GridInput<'_>],
    start: Pose2<f32>,
    options: &GridRunOptions,
    graph: &GraphSlamConfig,
    progress: &dyn Fn(usize),
) -> Result<(GridRun, GraphSummary)> {
    let config = GraphSlamConfig {
        grid: options.config,
        ..*graph
    };
    match options.particles {
        8 => run_p::<N, BITMAP, 8>(inputs, start, options, &config, progress),
        16 => run_p::<N, BITMAP, 16>(inputs, start, options, &config, progress),
        32 => run_p::<N, BITMAP, 32>(inputs, start, options, &config, progress),
        64 => run_p::<N, BITMAP, 64>(inputs, start, options, &config, progress),
        100 => run_p::<N, BITMAP, 100>(inputs, start, options, &config, progress),
        128 => run_p::<N, BITMAP, 128>(inputs, start, options, &config, progress),
        200 => run_p::<N, BITMAP, 200>(inputs, start, options, &config, progress),
        400 => run_p::<N, BITMAP, 400>(inputs, start, options, &config, progress),
        other => bail!(
            "--particles {other} is not compiled in; use one of {:?}",
            crate::domain::grid::SUPPORTED_PARTICLES
        ),
    }
}

fn run_p<const N: usize, const BITMAP: usize, const P: usize>(
    inputs: &[GridInput<'_>],
    start: Pose2<f32>,
    options: &GridRunOptions,
    config: &GraphSlamConfig,
    progress: &dyn Fn(usize),
) -> Result<(GridRun, GraphSummary)> {
    let lidar = options.lidar;
    let scan_len = inputs.iter().map(|i| i.ranges.len()).max().unwrap_or(0);
    // The filter thins a scan to at most GRAPH_BEAMS beams (`ScanPoints::load`): the store
    // keeps the same beams.
    let decimation = config
        .grid
        .beam_decimation
        .max(1)
        .max(scan_len.div_ceil(GRAPH_BEAMS));
    let beams = scan_len.div_ceil(decimation);
    let mut store = KeyframeStore::create(VecStorage::new(STORE_BYTES), &lidar, decimation, beams)
        .map_err(|e| anyhow!("keyframe store: {e}"))?;
    let mut slam: Box<HostGraphSlam<P>> = Box::new(GraphSlam::zeroed());
    slam.init(*config, start)
        .map_err(|e| anyhow!("graph SLAM: {e}"))?;
    let mut run = GridRun::empty(Vec::new(), *slam.map().geometry(), inputs.len());
    run.scan_spacing = ScanSpacing::of(inputs.iter().map(|input| input.odometry));
    // Per scan: the newest keyframe then and the filter's motion since it.
    let mut offsets: Vec<Option<(u16, Pose2<f32>)>> = Vec::with_capacity(inputs.len());
    let t0 = Instant::now();
    let mut odometry = ScanOdometry::new(options.max_odometry_step_m);
    for (i, input) in inputs.iter().enumerate() {
        let odom = input.odometry;
        if let OdometryStep::Move(from, to) = odometry.step(odom) {
            slam.predict_odometry(&from, &to)
                .map_err(|e| anyhow!("scan {i}: {e}"))?;
        }
        (run.refused_odometry, run.odometry_resets) = (odometry.refused, odometry.resets);
        let scan = LidarScan::new(input.ranges, lidar);
        run.non_finite_beams += scan.census().1;
        match slam.observe(&scan, &mut store) {
            Ok(step) => {
                run.off_grid_end_points += u64::from(step.map.off_grid);
                run.scans_off_grid += usize::from(step.map.off_grid > 0);
            }
            Err(microslam::slam::SlamError::Filter(
                microslam::pf::PfError::EmptyScan | microslam::pf::PfError::InvalidScan,
            )) => run.skipped_scans += 1,
            Err(e) => bail!("scan {i}: {e}"),
        }
        offsets.push(
            slam.newest_keyframe()
                .map(|(node, estimate)| (node, estimate.between(&slam.filter_pose()))),
        );
        run.trajectory.push((input.stamp, slam.filter_pose()));
        progress(i);
    }
    run.filter_time_s = t0.elapsed().as_secs_f64();
    // The graph's trajectory: every scan at its keyframe's final pose ⊕ its offset.
    for ((_, pose), offset) in run.trajectory.iter_mut().zip(&offsets) {
        if let Some((node, motion)) = offset
            && let Some(g) = slam.graph().pose(usize::from(*node))
        {
            *pose = g.compose(motion);
        }
    }
    let (cells, geometry) = draw_map::<N, BITMAP, P, _>(&slam, &store, options.grid_origin)?;
    run.cells = cells;
    run.geometry = geometry;
    let counters = slam.counters();
    run.map_image = map_image(&mut slam, &store)?;
    if counters.keyframes_refused > 0 {
        // Every scan was still tracked; only the keyframes beyond the graph's size were
        // not kept, so the path after them closes no loops and is not in the map.
        eprintln!(
            "warning: the pose graph is full: {} keyframes kept (the board profile's \
             SLAM_NODES = {NODES}), {} more not kept; the map and the loop closure stop \
             at the {}th keyframe",
            counters.keyframes, counters.keyframes_refused, counters.keyframes
        );
    }
    Ok((run, counters.into()))
}

/// The map image the board writes at the end of the run
/// ([`GraphSlam::write_map_image`]: every keyframe at its final graph pose, drawn tile by
/// tile in the local map's near window, occupied and free bitmaps); `None` without a
/// keyframe. Ends the run.
pub fn map_image<const P: usize, S: KeyframeStorage>(
    slam: &mut HostGraphSlam<P>,
    store: &KeyframeStore<S>,
) -> Result<Option<Vec<u8>>> {
    let (_, len) = match slam.map_image_size(store) {
        Ok(size) => size,
        Err(microslam::slam::SlamError::NoKeyframes) => return Ok(None),
        Err(e) => bail!("map image: {e}"),
    };
    let mut out = VecStorage::new(len);
    let free_below = slam.config().grid.log_odds.free_below;
    slam.write_map_image(store, &mut out, free_below)
        .map_err(|e| anyhow!("map image: {e}"))?;
    Ok(Some(out.0))
}

/// Every stored keyframe's scan written at its final graph pose into an `N × N` grid
/// whose lower-left corner is at `grid_origin` (centred on the origin without).
pub fn draw_map<const N: usize, const BITMAP: usize, const P: usize, S: KeyframeStorage>(
    slam: &HostGraphSlam<P>,
    store: &KeyframeStore<S>,
    grid_origin: Option<[f32; 2]>,
) -> Result<(Vec<i8>, microslam::grid::GridGeometry)> {
    let c = slam.config().grid;
    let mut grid = Box::new(match grid_origin {
        Some([x, y]) => OccupancyGrid::<N, N, BITMAP>::new(c.resolution, x, y, c.log_odds),
        None => OccupancyGrid::<N, N, BITMAP>::centred(c.resolution, c.log_odds),
    });
    let geometry = store.beam_geometry();
    let mut ranges = vec![0.0f32; store.beams()];
    for k in 0..store.len() {
        let Some(pose) = slam.graph().pose(k as usize) else {
            break;
        };
        store
            .read(k, &mut ranges)
            .map_err(|e| anyhow!("keyframe {k}: {e}"))?;
        grid.integrate_scan(&pose, &LidarScan::new(&ranges, geometry), 1)
            .map_err(|e| anyhow!("keyframe {k}: {e}"))?;
    }
    Ok((grid.cells().to_vec(), *grid.geometry()))
}
