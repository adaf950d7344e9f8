//! Estimator settings of the firmware; the host reference uses the same values.

use microslam::ekf::{CovarianceUpdate, EkfConfig, EkfSlam, state_dim};
use microslam::gate::ChiSquareGate;
use microslam::geometry::Pose2;
use microslam::motion::{IncrementNoise, VelocityNoise};
use microslam::sensors::range_bearing::RangeBearingSensor;

/// Landmarks the EKF holds.
pub const EKF_LANDMARKS: usize = 32;

/// The EKF of the firmware: `f32`, 32 landmarks (18 KB).
pub type Ekf = EkfSlam<f32, { state_dim(EKF_LANDMARKS) }>;

/// The settings the EKF runs with (the session re-initialises the filter with them).
pub const EKF_CONFIG: EkfConfig<f32> = EkfConfig::DEFAULT_F32;

/// A configuration of all-zero bytes, used only to build the filter in a `static`: a
/// value of zero bytes lands in `.bss`, so the 18 KB filter costs no flash for initial
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
    covariance_update: CovarianceUpdate::Joseph,
};
