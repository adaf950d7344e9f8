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
use crate::slam::graph::scratch_len;
use crate::slam::{GraphSlam, GraphSlamConfig};

/// Landmarks the EKF holds.
pub const EKF_LANDMARKS: usize = 64;

/// The EKF of the profile: `f32`, 64 landmarks (35 KB: the covariance is kept as a
/// packed triangular factor, see `docs/ekf-covariance.md`).
pub type Ekf = EkfSlam<f32, { state_dim(EKF_LANDMARKS) }, { factor_len(EKF_LANDMARKS) }>;

/// The settings the EKF runs with: [`EkfConfig::MICROCONTROLLER`].
pub const EKF_CONFIG: EkfConfig<f32> = EkfConfig::MICROCONTROLLER;

/// A configuration of all-zero bytes, used only to build the filter in a `static`: a
/// value of zero bytes lands in `.bss`, so the 35 KB filter costs no flash for initial
/// values. The wire session (`microslam::device::Session::new`) then sets [`EKF_CONFIG`]
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
pub const GRID_SETUP: crate::device::GridSetup = crate::device::GridSetup::EXAMPLE;

/// Beams of a revolution of the lidar a board reads itself (an LD06 on a UART,
/// `microslam-hal`'s `Ld06Uart`): one a degree, the LD06's own spacing.
pub const LIDAR_BINS: usize = 360;

/// How the board's own LD06 turns its points into beams: upright (angles clockwise, as
/// the datasheet's), every return kept, the ranges and mount of [`GRID_SETUP`]'s lidar.
#[cfg(feature = "wire")]
pub const LIDAR_SETUP: crate::sensors::ld06::Ld06Setup = crate::sensors::ld06::Ld06Setup {
    direction: crate::sensors::ld06::AngleDirection::Clockwise,
    min_intensity: 0,
    min_range: GRID_SETUP.lidar.min_range,
    max_range: GRID_SETUP.lidar.max_range,
    mount: GRID_SETUP.lidar.mount,
};

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

/// Edge of the building-scale SLAM's near log-odds window, cells (128 × 128 `i8` = 16 KB,
/// 6.4 m square at 5 cm): the window the filter scores and writes scans in.
pub const SLAM_NEAR: usize = 128;
/// Edge of its far occupancy bitmap, cells (512 × 512 bits = 32 KB, 25.6 m square): what
/// the robot saw around it beyond the near window, and what the filter scores on.
pub const SLAM_FAR: usize = 512;
/// Keyframes its pose graph holds (one each 0.65 m or 0.35 rad of travel: about 400 m of
/// a robot's path; the Intel lab's raw log makes 490, MIT CSAIL's 615).
pub const SLAM_NODES: usize = 640;
/// Loop edges its pose graph holds.
pub const SLAM_LOOPS: usize = 192;

/// Grid SLAM at the scale of a building ([`GraphSlam`]) as the profile sizes it: the
/// grid estimator's particles and beams on a [`SLAM_NEAR`]/[`SLAM_FAR`] local map, a
/// graph of [`SLAM_NODES`] keyframes and [`SLAM_LOOPS`] loop edges (112 KB on a 32-bit
/// target, see `docs/firmware.md`). The keyframes' scans live in a
/// [`KeyframeStore`](crate::slam::keyframes::KeyframeStore) of the caller's (flash).
pub type Slam = GraphSlam<
    GRID_PARTICLES,
    GRID_BEAMS,
    SLAM_NEAR,
    { occupancy_bytes(SLAM_NEAR, SLAM_NEAR) },
    SLAM_FAR,
    { occupancy_bytes(SLAM_FAR, SLAM_FAR) },
    SLAM_NODES,
    SLAM_LOOPS,
    { scratch_len(SLAM_NODES, SLAM_LOOPS) },
>;

/// Settings of [`Slam`]: [`GraphSlamConfig::MICROCONTROLLER`].
pub const SLAM_CONFIG: GraphSlamConfig = GraphSlamConfig::MICROCONTROLLER;

/// Bytes of flash the [`Slam`]'s keyframe store takes: one 128 KB sector of the
/// STM32F411 (sector 7), room for 606 keyframes of 90 beams (216 bytes each after the
/// store's header). The Intel raw part makes about 490; a longer run (MIT CSAIL's 374 m make
/// about 615) has its last keyframes refused and counted, short of the graph's
/// [`SLAM_NODES`].
pub const SLAM_KEYFRAME_BYTES: u32 = 128 * 1024;

/// Bytes of flash for the map image the [`Slam`] writes at the end of a run
/// (`GraphSlam::write_map_image`, feature `map-image`: two bitmaps of the map's whole
/// tiles): one 128 KB sector of the STM32F411 (sector 6), at most 31 tiles of 128 × 128
/// cells (e.g. 6 × 5, 38.4 m × 32 m at 5 cm); the Intel lab's (25 tiles) takes 102 456.
pub const SLAM_MAP_BYTES: u32 = 128 * 1024;

/// Bytes of each of the two flash sectors the robot's saved pose takes
/// (`microslam::device::PoseStore`, feature `wire`): 128 records of 32 bytes a sector at
/// 4 KB (on an STM32F411, whose smallest sectors are 16 KB, 512).
pub const POSE_SECTOR_BYTES: u32 = 4 * 1024;

/// [`Slam`] with the storage `S` of its keyframes, as a grid estimator
/// ([`crate::pf::GridEstimator`]): what a wire session drives.
pub type SlamEstimator<'a, S> = crate::slam::WithKeyframes<
    'a,
    S,
    GRID_PARTICLES,
    GRID_BEAMS,
    SLAM_NEAR,
    { occupancy_bytes(SLAM_NEAR, SLAM_NEAR) },
    SLAM_FAR,
    { occupancy_bytes(SLAM_FAR, SLAM_FAR) },
    SLAM_NODES,
    SLAM_LOOPS,
    { scratch_len(SLAM_NODES, SLAM_LOOPS) },
>;

/// Landmarks of the EKF beside [`Slam`]: the 112 KB SLAM leaves no room for the 35 KB
/// 64-landmark EKF in 128 KB, so a firmware carrying it keeps a small EKF (its requests
/// work, with at most this many landmarks; more are refused).
pub const SLAM_EKF_LANDMARKS: usize = 4;

/// The EKF beside [`Slam`] ([`SLAM_EKF_LANDMARKS`] landmarks).
pub type SlamEkf =
    EkfSlam<f32, { state_dim(SLAM_EKF_LANDMARKS) }, { factor_len(SLAM_EKF_LANDMARKS) }>;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_building_scale_slam_fits_beside_a_firmware_in_128_kb() {
        // On a 32-bit target the sizes are a little smaller (no 8-byte words); the
        // firmware's budget.txt holds those. Measured here (64-bit host): 111 952 bytes.
        let bytes = core::mem::size_of::<Slam>();
        let parts = SLAM_NEAR * SLAM_NEAR
            + occupancy_bytes(SLAM_NEAR, SLAM_NEAR)
            + occupancy_bytes(SLAM_FAR, SLAM_FAR)
            + crate::slam::graph::graph_bytes(SLAM_NODES, SLAM_LOOPS)
            + crate::slam::workspace_bytes(scratch_len(SLAM_NODES, SLAM_LOOPS));
        assert!(bytes >= parts, "{bytes} < {parts}");
        // What is not the maps, the graph and the workspace (particles, scan points, the
        // settings, the loop closure under way) stays small: measured 7 240 bytes on a
        // 64-bit host.
        assert!(bytes - parts <= 7400, "{bytes} - {parts}");
        // With the stack its drive peaks at on the board (10 088 bytes, `cost_slam` in
        // budget.txt), at least 8 KB of a 128 KB board stay for a firmware's buffers.
        assert!(bytes + 10_088 + 8 * 1024 <= 128 * 1024, "{bytes}");
    }
}
