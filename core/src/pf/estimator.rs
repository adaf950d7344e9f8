//! [`GridEstimator`]: the one interface to a grid filter that a drive loop needs, for
//! [`GridSlam`] and [`GridLocalizer`] alike.

use super::{GridLocalizer, GridSlam, PfError, StepReport};
use crate::geometry::Pose2;
use crate::sensors::lidar::LidarScan;

/// A grid filter as a drive loop runs it — the firmware's wire session and the host's
/// replay alike: object-safe, so that the caller's type does not depend on the grid's
/// size or particle count. Implemented by [`GridSlam`] and [`GridLocalizer`].
pub trait GridEstimator {
    /// Starts over at `start`: SLAM clears its map and re-draws its particles from the
    /// seed; the localizer puts every particle at `start` and tracks.
    fn reset(&mut self, start: Pose2<f32>) -> Result<(), PfError>;
    /// Prediction with the odometry poses before and after the step (only their
    /// difference is used). Not in the trait object (`Self: Sized`): a wire session sends
    /// increments, and a firmware's flash carries only what it calls.
    fn predict_odometry(&mut self, from: &Pose2<f32>, to: &Pose2<f32>) -> Result<(), PfError>
    where
        Self: Sized;
    /// Prediction with a pose increment in the previous robot frame.
    fn predict_increment(&mut self, increment: &Pose2<f32>) -> Result<(), PfError>;
    /// Prediction with the arc `(distance, heading_change)`.
    fn predict_arc(&mut self, distance: f32, heading_change: f32) -> Result<(), PfError>;
    /// Prediction with `(v, ω)` held for `dt` seconds.
    fn predict_velocity(&mut self, v: f32, omega: f32, dt: f32) -> Result<(), PfError>;
    /// One scan.
    fn observe(&mut self, scan: &LidarScan<'_>) -> Result<StepReport, PfError>;
    /// The estimate.
    fn pose(&self) -> Pose2<f32>;
    /// How often the particles were resampled.
    fn resamples(&self) -> u32;
    /// Covariance of the particle cloud, upper triangle `[xx, xy, xθ, yy, yθ, θθ]`
    /// ([`crate::pf::ParticleFilter::pose_covariance`]).
    fn pose_covariance(&self) -> [f32; 6];
    /// Ends a SLAM run and writes its whole map where the estimator keeps it (a map image
    /// in flash: `microslam::slam::GraphSlam::write_map_image`): the image's length and
    /// CRC-32, or why not. `None` (the default): this estimator keeps no map of its own.
    fn save_map(&mut self) -> Option<Result<SavedMap, PfError>> {
        None
    }
    /// Reads the saved map image's bytes from `offset` into `out`: how many (fewer at
    /// its end, 0 past it). `None` (the default) when no map was saved.
    fn read_map(&self, offset: u32, out: &mut [u8]) -> Option<usize> {
        let _ = (offset, out);
        None
    }
}

/// A map image an estimator wrote ([`GridEstimator::save_map`]).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SavedMap {
    /// Length of the image, bytes.
    pub bytes: u32,
    /// Its CRC-32 (`microslam::grid::MapImage::checksum`).
    pub checksum: u32,
    /// Where the robot is in the map, at the end of the run: where a localizer on it
    /// starts.
    pub pose: Pose2<f32>,
}

/// The methods both filters forward to their inherent methods of the same name (or to
/// their [`crate::pf::ParticleFilter`]): written once for the two implementations.
macro_rules! forward_to {
    ($filter:ident) => {
        fn predict_odometry(&mut self, from: &Pose2<f32>, to: &Pose2<f32>) -> Result<(), PfError> {
            $filter::predict_odometry(self, from, to)
        }
        fn predict_increment(&mut self, increment: &Pose2<f32>) -> Result<(), PfError> {
            $filter::predict_odometry(self, &Pose2::new(0.0, 0.0, 0.0), increment)
        }
        fn predict_arc(&mut self, distance: f32, heading_change: f32) -> Result<(), PfError> {
            $filter::predict(self, distance, heading_change)
        }
        fn predict_velocity(&mut self, v: f32, omega: f32, dt: f32) -> Result<(), PfError> {
            $filter::predict_velocity(self, v, omega, dt)
        }
        fn observe(&mut self, scan: &LidarScan<'_>) -> Result<StepReport, PfError> {
            $filter::observe(self, scan)
        }
        fn pose(&self) -> Pose2<f32> {
            $filter::pose(self)
        }
        fn resamples(&self) -> u32 {
            self.filter().resample_count()
        }
        fn pose_covariance(&self) -> [f32; 6] {
            self.filter().pose_covariance()
        }
    };
}

impl<const W: usize, const H: usize, const P: usize, const B: usize, const BITMAP: usize>
    GridEstimator for GridSlam<'_, W, H, P, B, BITMAP>
{
    fn reset(&mut self, start: Pose2<f32>) -> Result<(), PfError> {
        GridSlam::reset(self, start)
    }
    forward_to!(GridSlam);
}

impl<const P: usize, const B: usize> GridEstimator for GridLocalizer<'_, P, B> {
    fn reset(&mut self, start: Pose2<f32>) -> Result<(), PfError> {
        self.reset_around(start, 0.0, 0.0)
    }
    forward_to!(GridLocalizer);
}
