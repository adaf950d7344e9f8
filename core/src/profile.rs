//! The reference board profile: the sizes and settings `firmware-example` runs with on a
//! 128 KB Cortex-M4F (STM32F411 class), in one place, so that the firmware and the host
//! reference that checks it bit for bit (`host-sim hil`) cannot drift apart.
//!
//! A firmware of your own is free to choose other sizes; this profile is a tested
//! starting point that fits 128 KB of RAM with the EKF and the grid side by side.
//!
//! ```
//! use microslam::profile::{Ekf, EKF_CONFIG, EKF_LANDMARKS};
//! // The 64-landmark EKF of the profile (35 KB as a packed factor), on the heap here; on
//! // a board, in a `static` (see `core/examples/statics.rs`).
//! let ekf = Box::new(Ekf::new(EKF_CONFIG));
//! assert_eq!(EKF_LANDMARKS, 64);
//! assert_eq!(ekf.landmark_count(), 0);
//! ```

use crate::ekf::{EkfConfig, EkfSlam, factor_len, state_dim};
use crate::gate::ChiSquareGate;
use crate::geometry::Pose2;
use crate::grid::{OccupancyGrid, occupancy_bytes};
use crate::motion::{IncrementNoise, VelocityNoise};
use crate::pf::{GridLocalizer, GridPfConfig, GridSlam, RelocalizationConfig};
use crate::sensors::range_bearing::RangeBearingSensor;

/// Landmarks the EKF holds.
pub const EKF_LANDMARKS: usize = 64;

/// The EKF of the profile: `f32`, 64 landmarks (35 KB: the covariance is kept as a
/// packed triangular factor, see `docs/ekf-covariance.md`).
pub type Ekf = EkfSlam<f32, { state_dim(EKF_LANDMARKS) }, { factor_len(EKF_LANDMARKS) }>;

/// The settings the EKF runs with: [`EkfConfig::MICROCONTROLLER`].
pub const EKF_CONFIG: EkfConfig<f32> = EkfConfig::MICROCONTROLLER;

/// A configuration of all-zero bytes, used only to build the filter in a `static`: a
/// value of zero bytes lands in `.bss`, so the 35 KB filter costs no flash for initial
/// values. The wire session (`microslam::wire::Session::new`) then sets [`EKF_CONFIG`]
/// in place.
pub const ZEROED_EKF_CONFIG: EkfConfig<f32> = EkfConfig {
    increment_noise: IncrementNoise {
        translation_std: 0.0,
        translation_std_per_metre: 0.0,
        rotation_std: 0.0,
        rotation_std_per_radian: 0.0,
        rotation_std_per_metre: 0.0,
    },
    velocity_noise: VelocityNoise {
        linear_std: 0.0,
        linear_std_per_mps: 0.0,
        angular_std: 0.0,
        angular_std_per_radps: 0.0,
        angular_std_per_mps: 0.0,
    },
    range_std: 0.0,
    bearing_std: 0.0,
    sensor: RangeBearingSensor::new(Pose2::new(0.0, 0.0, 0.0)),
    gate: ChiSquareGate::from_threshold(0.0),
};

/// Particles of the grid estimator.
pub const GRID_PARTICLES: usize = 32;
/// Most beams per scan the grid estimators score (more are decimated).
pub const GRID_BEAMS: usize = 90;
/// Grid edge, cells (256 × 256 `i8` = 64 KB, 12.8 m square at 5 cm).
pub const GRID_CELLS: usize = 256;

/// Bytes of the grid's occupied-cell bitmap (8 KB for 256 × 256): it makes the shift
/// search visit only occupied cells (a third of the instructions per particle, same
/// result).
pub const GRID_BITMAP: usize = occupancy_bytes(GRID_CELLS, GRID_CELLS);

/// The occupancy grid with its bitmap, built with [`Grid::zeroed`] in a `static` (`.bss`)
/// and given its geometry in place with [`Grid::init_centred`].
pub type Grid = OccupancyGrid<GRID_CELLS, GRID_CELLS, GRID_BITMAP>;

/// The grid estimator on [`Grid`].
pub type GridEstimator<'g> =
    GridSlam<'g, GRID_CELLS, GRID_CELLS, GRID_PARTICLES, GRID_BEAMS, GRID_BITMAP>;

/// Settings of the grid estimator.
pub const GRID_CONFIG: GridPfConfig = GridPfConfig::MICROCONTROLLER;

/// Lidar and wheels as the wire session hands them to the grid estimator.
#[cfg(feature = "wire")]
pub const GRID_SETUP: crate::wire::GridSetup = crate::wire::GridSetup::EXAMPLE;

/// Particles of the localizer on a map in flash. Without the 64 KB grid in RAM far more
/// would fit (28 bytes each); the instruction budget per scan is what limits them.
pub const LOCALIZER_PARTICLES: usize = 64;

/// Settings of the localizer: the grid estimator's (the map image is made with its
/// log-odds thresholds) with the localizer's 3 × 3 shift window
/// ([`GridPfConfig::for_localizer`]).
pub const LOCALIZER_CONFIG: GridPfConfig = GridPfConfig::MICROCONTROLLER.for_localizer();

/// Lost detection and global relocalization of the localizer (used when the map image
/// carries max-pooled layers).
pub const RELOCALIZATION: RelocalizationConfig = RelocalizationConfig::DEFAULT;

/// The localizer on a map image (`&'m` bytes in flash on the board).
pub type Localizer<'m> = GridLocalizer<'m, LOCALIZER_PARTICLES, GRID_BEAMS>;
