//! Estimator settings of the firmware; the host reference uses the same values.

use microslam::ekf::{EkfConfig, EkfSlam, factor_len, state_dim};
use microslam::gate::ChiSquareGate;
use microslam::geometry::Pose2;
use microslam::grid::{OccupancyGrid, occupancy_bytes};
use microslam::motion::{IncrementNoise, VelocityNoise};
use microslam::pf::{GridLocalizer, GridPfConfig, GridSlam, RelocalizationConfig};
use microslam::sensors::range_bearing::RangeBearingSensor;
use microslam::wire::GridSetup;

/// Landmarks the EKF holds.
pub const EKF_LANDMARKS: usize = 64;

/// The EKF of the firmware: `f32`, 64 landmarks (35 KB: the covariance is kept as a
/// packed triangular factor, see `docs/ekf-covariance.md`).
pub type Ekf = EkfSlam<f32, { state_dim(EKF_LANDMARKS) }, { factor_len(EKF_LANDMARKS) }>;

/// The settings the EKF runs with (the session re-initialises the filter with them): the
/// generic defaults.
pub const EKF_CONFIG: EkfConfig<f32> = EkfConfig::MICROCONTROLLER;

/// A configuration of all-zero bytes, used only to build the filter in a `static`: a
/// value of zero bytes lands in `.bss`, so the 35 KB filter costs no flash for initial
/// values. [`microslam::wire::Session::new`] then sets [`EKF_CONFIG`] in place.
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
/// Most beams per scan the grid estimator scores (more are decimated).
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
pub type GridEstimator =
    GridSlam<'static, GRID_CELLS, GRID_CELLS, GRID_PARTICLES, GRID_BEAMS, GRID_BITMAP>;

/// Settings of the grid estimator.
pub const GRID_CONFIG: GridPfConfig = GridPfConfig::MICROCONTROLLER;

/// Lidar and wheels as the session hands them to the grid estimator.
pub const GRID_SETUP: GridSetup = GridSetup::EXAMPLE;

// ---- Localizer on the map in flash (built with MICROSLAM_MAP=<map.yaml>) ----

/// Particles of the localizer. Without the 64 KB grid in RAM far more would fit (28 bytes
/// each); the instruction budget per scan is what limits them.
pub const LOCALIZER_PARTICLES: usize = 64;

/// Settings of the localizer: the grid estimator's (the map image is made with its
/// log-odds thresholds by `build.rs`).
pub const LOCALIZER_CONFIG: GridPfConfig = GridPfConfig::MICROCONTROLLER;

/// Lost detection and global relocalization of the localizer (used when the map image
/// carries max-pooled layers).
pub const RELOCALIZATION: RelocalizationConfig = RelocalizationConfig::DEFAULT;

/// The localizer on the `&'static` map image in flash.
pub type Localizer = GridLocalizer<'static, LOCALIZER_PARTICLES, GRID_BEAMS>;

/// The map image embedded by `build.rs` (`MICROSLAM_MAP`), in `.rodata`: empty when the
/// firmware was built without a map. Checked at boot with
/// [`microslam::grid::MapImage::parse`].
pub static MAP_IMAGE: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/map.bin"));
