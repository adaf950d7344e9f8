//! [`EkfConfig`], the filter's settings: odometry and sighting noise, the sensor's mount on
//! the robot and the innovation gate, with their defaults, their check and their conversion
//! to another scalar type.

use crate::error::InvalidSetting;
use crate::gate::ChiSquareGate;
use crate::geometry::Pose2;
use crate::motion::{IncrementNoise, VelocityNoise};
use crate::scalar::Real;
use crate::sensors::range_bearing::RangeBearingSensor;
use nalgebra::Matrix2;

/// Settings of the landmark EKF: noise, sensor mount and gate.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct EkfConfig<T> {
    /// Noise of odometry increments (used by
    /// [`EkfSlam::predict_increment`](super::EkfSlam::predict_increment)).
    pub increment_noise: IncrementNoise<T>,
    /// Noise of velocity odometry (used by
    /// [`EkfSlam::predict_velocity`](super::EkfSlam::predict_velocity)).
    pub velocity_noise: VelocityNoise<T>,
    /// Standard deviation of measured ranges, metres (when a sighting brings no covariance).
    pub range_std: T,
    /// Standard deviation of measured bearings, radians.
    pub bearing_std: T,
    /// The range-bearing sensor and its mount on the robot.
    pub sensor: RangeBearingSensor<T>,
    /// Innovation gate on the squared Mahalanobis distance (2 degrees of freedom).
    pub gate: ChiSquareGate<T>,
}

macro_rules! default_config {
    ($t:ty) => {
        EkfConfig {
            increment_noise: IncrementNoise {
                translation_std: 0.0,
                translation_std_per_metre: 0.05,
                rotation_std: 0.0,
                rotation_std_per_radian: 0.05,
                rotation_std_per_metre: 0.02,
            },
            velocity_noise: VelocityNoise {
                linear_std: 0.01,
                linear_std_per_mps: 0.1,
                angular_std: 0.01,
                angular_std_per_radps: 0.1,
                angular_std_per_mps: 0.0,
            },
            range_std: 0.1,
            bearing_std: 0.035,
            sensor: RangeBearingSensor::at_robot_origin(),
            // χ²₂ quantile at 0.999.
            gate: ChiSquareGate::from_threshold(13.815_511),
        }
    };
}

impl EkfConfig<f32> {
    /// Generic defaults for `f32`: 5 % odometry noise, 0.1 m / 2° sightings, a 99.9 % gate.
    /// Tune them per robot and dataset.
    pub const DEFAULT_F32: Self = default_config!(f32);

    /// What the example firmware runs: the generic defaults ([`EkfConfig::DEFAULT_F32`]).
    pub const MICROCONTROLLER: Self = Self::DEFAULT_F32;
}

impl EkfConfig<f64> {
    /// The same defaults as [`EkfConfig::DEFAULT_F32`], in `f64`.
    pub const DEFAULT_F64: Self = default_config!(f64);
}

impl<T: Real> EkfConfig<T> {
    /// `true` when every noise figure is finite and non-negative, the sensor mount finite
    /// and the gate positive. One copy (not inlined), which keeps none of the names.
    #[inline(never)]
    pub fn is_valid(&self) -> bool {
        self.invalid_setting().is_none()
    }

    /// The first setting out of range — a field of its [`IncrementNoise`] or
    /// [`VelocityNoise`] by the field's own name, then `range_std`, `bearing_std`, `mount`
    /// (of `sensor`) and `gate` — `None` when every one is valid.
    /// [`EkfSlam::init`](super::EkfSlam::init) and
    /// [`EkfSlam::set_config`](super::EkfSlam::set_config) refuse an invalid configuration
    /// with [`EkfError::InvalidNoise`](crate::error::EkfError::InvalidNoise); this says which
    /// setting it was.
    #[inline(always)]
    pub fn invalid_setting(&self) -> Option<InvalidSetting> {
        self.increment_noise
            .invalid_setting()
            .or_else(|| self.velocity_noise.invalid_setting())
            .or_else(|| {
                InvalidSetting::first([
                    InvalidSetting::non_negative("range_std", self.range_std),
                    InvalidSetting::non_negative("bearing_std", self.bearing_std),
                    ("mount", "finite", self.sensor.mount.is_finite()),
                    (
                        "gate",
                        "a positive threshold",
                        self.gate.threshold > T::ZERO,
                    ),
                ])
            })
    }

    /// The same settings in another scalar type (e.g. a host `f64` configuration for an
    /// `f32` target).
    pub fn cast<U: Real>(&self) -> EkfConfig<U> {
        let c = |v: T| U::lit(v.to_f64());
        let i = &self.increment_noise;
        let v = &self.velocity_noise;
        let m = &self.sensor.mount;
        EkfConfig {
            increment_noise: IncrementNoise {
                translation_std: c(i.translation_std),
                translation_std_per_metre: c(i.translation_std_per_metre),
                rotation_std: c(i.rotation_std),
                rotation_std_per_radian: c(i.rotation_std_per_radian),
                rotation_std_per_metre: c(i.rotation_std_per_metre),
            },
            velocity_noise: VelocityNoise {
                linear_std: c(v.linear_std),
                linear_std_per_mps: c(v.linear_std_per_mps),
                angular_std: c(v.angular_std),
                angular_std_per_radps: c(v.angular_std_per_radps),
                angular_std_per_mps: c(v.angular_std_per_mps),
            },
            range_std: c(self.range_std),
            bearing_std: c(self.bearing_std),
            sensor: RangeBearingSensor::new(Pose2::new(c(m.x), c(m.y), c(m.theta))),
            gate: ChiSquareGate::from_threshold(c(self.gate.threshold)),
        }
    }

    /// The measurement covariance `diag(σ_r², σ_b²)` from the configured noise.
    pub fn measurement_covariance(&self) -> Matrix2<T> {
        Matrix2::new(
            self.range_std * self.range_std,
            T::ZERO,
            T::ZERO,
            self.bearing_std * self.bearing_std,
        )
    }
}
