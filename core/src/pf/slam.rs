//! The grid SLAM of Du (n.d., §III-C): one shared occupancy grid, written by the best
//! particle.
//!
//! # References
//!
//! - Du, C. (n.d.). *ECE 276 Project: Particle Filter SLAM*. Undated report, University of
//!   California, San Diego.

use super::correlation::{
    ScanPoints, search_window, search_window_sparse, search_window_sparse_rows,
};
use super::filter::{HeadingSearch, ShiftSearch};
use super::{GridPfConfig, ParticleFilter, PfError};
use crate::geometry::Pose2;
use crate::grid::{GridView, OccupancyGrid, ScanIntegration};
use crate::sensors::lidar::LidarScan;

/// Grid SLAM with `P` particles, at most `B` beams per scan, on a borrowed `W × H` grid
/// (with an occupied-cell bitmap of `BITMAP` bytes when `BITMAP > 0`, see
/// [`OccupancyGrid`]: the shift search is then the sparse one).
///
/// The grid is borrowed so that it can live in a `static` (all zero bytes with
/// [`OccupancyGrid::zeroed`], given its geometry in place with
/// [`OccupancyGrid::init_centred`]); the filter itself is small: `28·P + 24·B` bytes plus
/// ~100 (P = 32, B = 90: ~3.2 KB).
///
/// The first scan builds the map at the start pose; every later scan is scored by all
/// particles (each moved to its best shift) and then written into the grid at the pose of
/// the heaviest particle, which is the estimate.
///
/// ```
/// use core::f32::consts::PI;
/// use microslam::geometry::Pose2;
/// use microslam::grid::OccupancyGrid;
/// use microslam::pf::{GridPfConfig, GridSlam};
/// use microslam::sensors::lidar::{LidarGeometry, LidarScan};
///
/// let config = GridPfConfig::MICROCONTROLLER;
/// // 128 × 128 cells of 5 cm (16 KB): on a microcontroller a `static`
/// // (`core/examples/statics.rs`), here a box.
/// let mut grid = Box::new(OccupancyGrid::<128, 128>::zeroed());
/// grid.init_centred(config.resolution, config.log_odds)?;
/// // 32 particles, scans of at most 90 beams.
/// let mut slam = GridSlam::<_, _, 32, 90>::new(&mut grid, config, Pose2::new(0.0, 0.0, 0.0))?;
///
/// // A 360° lidar at the robot's centre in a round room of radius 2 m.
/// let lidar = LidarGeometry {
///     first_angle: -PI,
///     angle_increment: 2.0 * PI / 90.0,
///     min_range: 0.1,
///     max_range: 8.0,
///     no_return_range: f32::INFINITY,
///     mount: Pose2::new(0.0, 0.0, 0.0),
/// };
/// let ranges = [2.0_f32; 90];
/// slam.observe(&LidarScan::new(&ranges, lidar))?; // the first scan starts the map
/// slam.predict_velocity(0.1, 0.0, 0.1)?; // odometry says: 1 cm forward
/// let report = slam.observe(&LidarScan::new(&ranges, lidar))?; // ...the walls say: no
/// assert!(report.pose.x.abs() < 0.05 && report.pose.y.abs() < 0.05);
/// assert_eq!(slam.scans(), 2);
/// # Ok::<(), Box<dyn core::error::Error>>(())
/// ```
pub struct GridSlam<
    'g,
    const W: usize,
    const H: usize,
    const P: usize,
    const B: usize,
    const BITMAP: usize = 0,
> {
    map: &'g mut OccupancyGrid<W, H, BITMAP>,
    filter: ParticleFilter<P>,
    points: ScanPoints<B>,
    config: GridPfConfig,
    scans: u32,
    pose: Pose2<f32>,
}

/// What one scan did.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StepReport {
    /// The estimate after the scan (heaviest particle).
    pub pose: Pose2<f32>,
    /// Effective number of particles before resampling (P for the first scan).
    pub n_eff: f32,
    /// `true` when the particles were resampled.
    pub resampled: bool,
    /// Beams used for scoring and mapping.
    pub beams: usize,
    /// Correlation of the best particle at its best shift (fixed point).
    pub score: u32,
    /// Map writing (SLAM only; zero for the localizer).
    pub map: ScanIntegration,
}

impl<'g, const W: usize, const H: usize, const P: usize, const B: usize, const BITMAP: usize>
    GridSlam<'g, W, H, P, B, BITMAP>
{
    /// SLAM on `map` (cleared here) starting at `start`. The map's resolution must be
    /// the configured one.
    pub fn new(
        map: &'g mut OccupancyGrid<W, H, BITMAP>,
        config: GridPfConfig,
        start: Pose2<f32>,
    ) -> Result<Self, PfError> {
        if !config.is_valid() {
            return Err(PfError::InvalidConfig);
        }
        if map.geometry().resolution != config.resolution {
            return Err(PfError::MapMismatch);
        }
        let filter = ParticleFilter::new(config.filter, start)?;
        map.reset();
        Ok(Self {
            map,
            filter,
            points: ScanPoints::new(),
            config,
            scans: 0,
            pose: start,
        })
    }

    /// Starts over at `start` in place: the map is cleared, the particles are drawn anew
    /// from the configured seed, the scan count is zero. A non-finite `start` is refused
    /// and nothing changes.
    pub fn reset(&mut self, start: Pose2<f32>) -> Result<(), PfError> {
        self.filter = ParticleFilter::new(self.config.filter, start)?;
        self.map.reset();
        self.scans = 0;
        self.pose = start;
        Ok(())
    }

    /// The estimate: the heaviest particle's pose after the last scan (or the prediction
    /// of the last estimate's particle set before any scan).
    pub fn pose(&self) -> Pose2<f32> {
        self.pose
    }

    /// The map.
    pub fn map(&self) -> &OccupancyGrid<W, H, BITMAP> {
        self.map
    }

    /// The particles.
    pub fn filter(&self) -> &ParticleFilter<P> {
        &self.filter
    }

    /// The settings.
    pub fn config(&self) -> &GridPfConfig {
        &self.config
    }

    /// Scans processed.
    pub fn scans(&self) -> u32 {
        self.scans
    }

    /// Prediction with the arc `(distance, heading_change)` driven since the last step.
    pub fn predict(&mut self, distance: f32, heading_change: f32) -> Result<(), PfError> {
        self.filter.predict(distance, heading_change)
    }

    /// Prediction with `(v, ω)` held for `dt` seconds.
    pub fn predict_velocity(&mut self, v: f32, omega: f32, dt: f32) -> Result<(), PfError> {
        self.filter.predict_velocity(v, omega, dt)
    }

    /// Prediction with the odometry poses before and after the step (only their
    /// difference is used, so the odometry frame does not matter).
    pub fn predict_odometry(&mut self, from: &Pose2<f32>, to: &Pose2<f32>) -> Result<(), PfError> {
        self.filter.predict_odometry(from, to)
    }

    /// Moves the particles and the estimate by the rigid motion `correction` of the world
    /// frame (`pose ← correction ⊕ pose`), for a loop closure that has re-placed the map
    /// ([`GridSlam::rebuild_map`]). A non-finite result is refused and nothing changes.
    pub fn correct(&mut self, correction: &Pose2<f32>) -> Result<(), PfError> {
        let pose = correction.compose(&self.pose);
        if !pose.is_finite() {
            return Err(PfError::NonFiniteInput);
        }
        self.filter.transform(correction)?;
        self.pose = pose;
        Ok(())
    }

    /// Clears the map and writes `scans` into it, each at its pose (for a loop closure
    /// that has moved the poses of the scans the map was built from). Scans without a
    /// usable beam are skipped; a non-finite pose stops the rebuild with
    /// [`PfError::NonFiniteInput`] (the map then holds the scans before it).
    pub fn rebuild_map<'s>(
        &mut self,
        scans: impl IntoIterator<Item = (Pose2<f32>, LidarScan<'s>)>,
    ) -> Result<(), PfError> {
        self.map.reset();
        for (pose, scan) in scans {
            if self.config.load_scan(&mut self.points, &scan).is_err() {
                continue;
            }
            self.map
                .integrate_points(&pose, &scan.geometry.mount, self.points.robot_points())
                .map_err(|_| PfError::NonFiniteInput)?;
        }
        Ok(())
    }

    /// Processes one scan: scores all particles (except for the first scan), moves them
    /// to their best shifts, resamples if needed, and writes the scan into the map at the
    /// estimate.
    pub fn observe(&mut self, scan: &LidarScan<'_>) -> Result<StepReport, PfError> {
        let search: ShiftSearch = const { shift_search::<W, BITMAP>() };
        let (mut report, _) = score_scan(
            &mut self.filter,
            &mut self.points,
            &self.config,
            scan,
            (self.scans > 0).then(|| (self.map.view(), search)),
            None,
        )?;
        report.map = self
            .map
            .integrate_points(
                &report.pose,
                &scan.geometry.mount,
                self.points.robot_points(),
            )
            .map_err(|_| PfError::NonFiniteInput)?;
        self.pose = report.pose;
        self.scans = self.scans.saturating_add(1);
        Ok(report)
    }
}

/// The scoring half of a SLAM step: loads `scan` into `points` and, with a map to score
/// on (`None` for the first scan, which only starts the map), scores and moves the
/// particles ([`ParticleFilter::update_with_prior`] with the configured shift prior),
/// after turning them all by what a `heading` search around their mean pose found (the
/// turn is returned, 0 without one). The report's pose is the heaviest particle's; its
/// map part is left for the caller, which writes the scan.
pub(crate) fn score_scan<const P: usize, const B: usize>(
    filter: &mut ParticleFilter<P>,
    points: &mut ScanPoints<B>,
    config: &GridPfConfig,
    scan: &LidarScan<'_>,
    map: Option<(GridView<'_>, ShiftSearch)>,
    heading: Option<HeadingSearch>,
) -> Result<(StepReport, f32), PfError> {
    let beams = config.load_scan(points, scan)?;
    let mut report = StepReport {
        pose: filter.best_pose(),
        n_eff: P as f32,
        resampled: false,
        beams,
        score: 0,
        map: ScanIntegration::default(),
    };
    let mut turn = 0.0;
    if let Some((view, search)) = map {
        if let Some(h) = heading {
            let (delta, best, none) = ParticleFilter::<P>::search_heading(
                &view,
                &filter.mean_pose(),
                points.as_slice(),
                config.filter.shift_window_cells,
                search,
                &h,
            );
            if delta != 0.0 && best as f32 > (1.0 + h.min_gain) * none as f32 {
                filter.turn(delta)?;
                turn = delta;
            }
        }
        let u =
            filter.update_with_prior(&view, points.as_slice(), search, config.shift_penalty())?;
        report.pose = u.best_pose;
        report.n_eff = u.n_eff;
        report.resampled = u.resampled;
        report.score = u.best_shift.score;
    }
    Ok((report, turn))
}

/// The shift search of a grid `W` cells wide, chosen when the program is built, so that
/// a build carries only the one it uses: without a bitmap the byte-wise search; with one
/// the sparse search, with the bitmap's row offsets as constants for grids 256, 512 and
/// 1024 cells wide (the firmware's and the host's grids;
/// [`search_window_sparse_rows`]), else reading them from the map.
pub(crate) const fn shift_search<const W: usize, const BITMAP: usize>() -> ShiftSearch {
    if BITMAP == 0 {
        return search_window;
    }
    match W.div_ceil(8) {
        32 => search_window_sparse_rows::<32>,
        64 => search_window_sparse_rows::<64>,
        128 => search_window_sparse_rows::<128>,
        _ => search_window_sparse,
    }
}
