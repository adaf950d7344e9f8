//! Localization against a fixed map: the grid filter without map writes.

use super::correlation::ScanPoints;
use super::prediction::arc_between;
use super::{GridPfConfig, ParticleFilter, PfError, StepReport};
use crate::geometry::Pose2;
use crate::grid::{GridView, ScanIntegration};
use crate::sensors::lidar::LidarScan;

/// Localizer with `P` particles and at most `B` beams per scan on a borrowed map (owned
/// grid's [`crate::grid::OccupancyGrid::view`] or a `&'static` map in flash).
///
/// On a microcontroller give the map its occupied-cell bitmap
/// ([`GridView::with_occupancy_bits`], computed once with
/// [`crate::grid::fill_occupancy_bits`] into a RAM buffer of
/// [`crate::grid::occupancy_bytes`] bytes, or kept in flash next to the map): the shift
/// search is then the sparse one, a third of the instructions for the same scores.
///
/// RAM: `28·P + 24·B` bytes plus ~100; the map is not copied.
///
/// ```
/// use core::f32::consts::PI;
/// use microslam::geometry::Pose2;
/// use microslam::grid::{GridGeometry, GridView};
/// use microslam::pf::{GridLocalizer, GridPfConfig};
/// use microslam::sensors::lidar::{LidarGeometry, LidarScan};
///
/// // A map of 64 × 64 cells of 5 cm (e.g. a `static` array in flash, or a SLAM run's
/// // `OccupancyGrid::cells`): a round wall of radius 1.5 m around the origin.
/// let geometry = GridGeometry::centred(64, 64, 0.05);
/// let mut cells = [0_i8; 64 * 64];
/// for (i, cell) in cells.iter_mut().enumerate() {
///     let (x, y) = geometry.cell_centre((i % 64) as i32, (i / 64) as i32);
///     if ((x * x + y * y).sqrt() - 1.5).abs() < 0.04 {
///         *cell = 100;
///     }
/// }
/// let config = GridPfConfig::MICROCONTROLLER;
/// let map = GridView::new(&cells, geometry, config.log_odds.occupied_above)?;
///
/// // Told the robot is 10 cm off the centre; it is at the centre.
/// let mut localizer = GridLocalizer::<32, 90>::new(map, config, Pose2::new(0.1, 0.0, 0.0))?;
/// let lidar = LidarGeometry {
///     first_angle: -PI,
///     angle_increment: 2.0 * PI / 90.0,
///     min_range: 0.1,
///     max_range: 8.0,
///     no_return_range: f32::INFINITY,
///     mount: Pose2::new(0.0, 0.0, 0.0),
/// };
/// let report = localizer.observe(&LidarScan::new(&[1.5_f32; 90], lidar))?;
/// assert!(report.pose.x.abs() < 0.05 && report.pose.y.abs() < 0.05);
/// # Ok::<(), Box<dyn core::error::Error>>(())
/// ```
pub struct GridLocalizer<'m, const P: usize, const B: usize> {
    map: GridView<'m>,
    filter: ParticleFilter<P>,
    points: ScanPoints<B>,
    config: GridPfConfig,
    pose: Pose2<f32>,
}

impl<'m, const P: usize, const B: usize> GridLocalizer<'m, P, B> {
    /// A localizer on `map` with all particles at `start` (see
    /// [`GridLocalizer::reset_around`] for an uncertain start).
    pub fn new(
        map: GridView<'m>,
        config: GridPfConfig,
        start: Pose2<f32>,
    ) -> Result<Self, PfError> {
        if !config.is_valid() {
            return Err(PfError::InvalidConfig);
        }
        Ok(Self {
            map,
            filter: ParticleFilter::new(config.filter, start)?,
            points: ScanPoints::new(),
            config,
            pose: start,
        })
    }

    /// Spreads the particles around `pose` (Gaussian, `std_xy` m, `std_theta` rad).
    pub fn reset_around(
        &mut self,
        pose: Pose2<f32>,
        std_xy: f32,
        std_theta: f32,
    ) -> Result<(), PfError> {
        self.filter.reset_around(pose, std_xy, std_theta)?;
        self.pose = pose;
        Ok(())
    }

    /// The estimate (heaviest particle after the last scan).
    pub fn pose(&self) -> Pose2<f32> {
        self.pose
    }

    /// The particles.
    pub fn filter(&self) -> &ParticleFilter<P> {
        &self.filter
    }

    /// The map.
    pub fn map(&self) -> &GridView<'m> {
        &self.map
    }

    /// Prediction with the arc `(distance, heading_change)`.
    pub fn predict(&mut self, distance: f32, heading_change: f32) -> Result<(), PfError> {
        self.filter.predict(distance, heading_change)
    }

    /// Prediction with `(v, ω)` held for `dt` seconds.
    pub fn predict_velocity(&mut self, v: f32, omega: f32, dt: f32) -> Result<(), PfError> {
        self.filter.predict_velocity(v, omega, dt)
    }

    /// Prediction with odometry poses before and after the step.
    pub fn predict_odometry(&mut self, from: &Pose2<f32>, to: &Pose2<f32>) -> Result<(), PfError> {
        if !(from.is_finite() && to.is_finite()) {
            return Err(PfError::NonFiniteInput);
        }
        let (d, t) = arc_between(from, to);
        self.filter.predict(d, t)
    }

    /// Scores the scan against the map, shifts, reweights and resamples.
    pub fn observe(&mut self, scan: &LidarScan<'_>) -> Result<StepReport, PfError> {
        if !scan.geometry.is_valid() {
            return Err(PfError::InvalidScan);
        }
        let beams = self.points.load(
            scan,
            self.config.beam_decimation,
            self.config.range_weight_exponent,
        );
        if beams == 0 {
            return Err(PfError::EmptyScan);
        }
        let u = self.filter.update(&self.map, self.points.as_slice())?;
        self.pose = u.best_pose;
        Ok(StepReport {
            pose: u.best_pose,
            n_eff: u.n_eff,
            resampled: u.resampled,
            beams,
            score: u.best_shift.score,
            map: ScanIntegration::default(),
        })
    }
}
