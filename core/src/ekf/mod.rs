//! Landmark EKF-SLAM with a fixed, compile-time maximum number of landmarks.
//!
//! The state is `[x, y, θ, x₁, y₁, …, x_L, y_L]` (robot pose, then point landmarks) with
//! dimension `N = 3 + 2·L` ([`state_dim`]). The covariance is kept factorised,
//! `P = L D Lᵀ` with `L` unit lower triangular and `D ≥ 0` diagonal, packed into
//! `N (N + 1) / 2` scalars ([`factor_len`], the [`covariance`] module). Only the *active*
//! part of the factor, for the `n` landmarks added so far, is ever read or written:
//!
//! | step | what it touches | cost |
//! | --- | --- | --- |
//! | [`EkfSlam::predict_increment`], [`EkfSlam::predict_velocity`], [`EkfSlam::inflate_pose_covariance`] | robot mean, the robot's own 3 × 3 block of `L`; its coupling rows are deferred | O(1) (O(n) for the first after another step) |
//! | [`EkfSlam::update`] | applies the deferred predictions, then two scalar (Bierman) updates of the whole factor | O(n²) |
//! | [`EkfSlam::add_landmark`] | applies the deferred predictions; two new rows, the robot rows move down | O(n) |
//! | [`EkfSlam::innovation`], one entry of [`EkfSlam::active_covariance`] | reads | O(n) |
//! | [`EkfSlam::pose_covariance`] | reads | O(1) after a prediction, O(n) otherwise |
//!
//! A run of predictions keeps the product of their Jacobians (3 × 3) instead of applying
//! each to the robot's coupling rows of `L` (three rows as long as the state): the next
//! update or new landmark applies it once, and the readers in between apply it on the fly
//! (the `deferred` module). A robot driving for a minute between two sightings pays one
//! O(n) pass, not one per odometry sample.
//!
//! # Self-calibration
//!
//! Systematic sensor errors can be estimated as states instead of being covered by
//! noise: [`EkfSlam::estimate_odometry_scale`] (speed and turn-rate scale factors,
//! `(s_v v, s_ω ω)` drive the prediction) and [`EkfSlam::estimate_range_bias`] (sightings
//! measure `r + b₀ + b₂ β²`). Each takes one two-state *calibration slot* before the
//! landmarks — in the mean after the pose, in the factor first — so it costs a landmark
//! slot and no memory; [`EkfSlam::landmark_state`] gives a landmark's place in the public
//! state. Prediction stays O(1): the robot's rows gain `F_s L_s` in the slot's columns,
//! left of the robot block (deferred with the rest of the coupling rows), so the factor
//! stays triangular and `D` is computed as before.
//!
//! Corrections to seed 1: the measurement model is polar on both sides (eq. 12 mixes a
//! Cartesian prediction with a polar measurement), and all noise is configuration (eq. 9's
//! constant `Q` is gone).
//!
//! # Why `P` stays positive semi-definite
//!
//! `P = L D Lᵀ` is positive semi-definite for *any* `L` as long as `D ≥ 0`, and every
//! step computes the new `D` in a way that cannot be negative, rounding included:
//! - a prediction `P' = F P Fᵀ + G Q Gᵀ` leaves the landmark rows alone, multiplies the
//!   robot's coupling to the landmarks by `F`, and re-factors the robot's own block
//!   `[F L_rr | G] diag(D_r, Q) [F L_rr | G]ᵀ` by a modified weighted Gram–Schmidt
//!   (Thornton): each new pivot is a sum of weighted squares;
//! - a new landmark `l = g(robot, z)` gets the rows `G_r L_rm` and, together with the
//!   robot, a 5 × 5 block re-factored the same way from `[[G_r L_rr, G_z L_R], [L_rr, 0]]`
//!   with weights `diag(D_r, D_R)` (`R = L_R D_R L_Rᵀ`);
//! - an update is processed as two scalar measurements (range, then bearing, both
//!   linearised at the prior; a correlated `R` is decorrelated first). Bierman's scalar
//!   update sets `Dⱼ' = Dⱼ αⱼ₋₁ / αⱼ` with `α` a running sum of `r` and non-negative
//!   terms `Dⱼ fⱼ²`: a product and quotient of non-negative numbers.
//!
//! There are no variance caps, no diagonal loading and no symmetrisation: a lost robot
//! with 10⁸ m² variances next to millimetre landmarks stays positive semi-definite. Each
//! scalar update treats the sighting as no more precise than `ε · H P Hᵀ` (`ε` the
//! machine epsilon), which keeps its gain finite; it is not needed for `D ≥ 0`.
//!
//! # Numerical safeguards
//!
//! Exercised by the fuzz targets in `fuzz/`: every step checks its inputs, and the
//! finiteness of what it would write, *before* writing (an update checks its O(n)
//! quantities — pivots, gains' denominators — before the O(n²) pass); a refused step
//! returns an [`EkfError`] and leaves the state as it was. The robot and landmarks stay
//! within [`MAX_COORDINATE`] of the origin, where `f32` coordinates are still finer than
//! a centimetre.
//!
//! # Memory
//!
//! `size_of::<EkfSlam<T, N, P>>() = (N + P) · size_of::<T>() + EKF_OVERHEAD_BYTES(T)`
//! with `P = N (N + 1) / 2`; for `f32` the overhead is [`EKF_OVERHEAD_BYTES_F32`]. With
//! `f32`:
//!
//! | landmarks | N | P | bytes |
//! | --- | --- | --- | --- |
//! | 16 | 35 | 630 | 2 940 |
//! | 32 | 67 | 2 278 | 9 660 |
//! | 64 | 131 | 8 646 | 35 388 |
//!
//! Such a filter belongs in a `static` on a microcontroller: [`EkfSlam::new`] is a
//! `const fn`, so `static`s are laid out by the linker (`.bss`/`.data`) and never pass
//! through the stack; [`EkfSlam::init`] re-initialises in place. An update uses
//! `6 · N · size_of::<T>()` bytes of stack for its per-state terms.
//!
//! The two const parameters are the state dimension and the packed factor length; write
//! them with [`state_dim`] and [`factor_len`] (stable Rust cannot compute one from the
//! other in a type). A pair that does not match is rejected at compile time:
//!
//! ```compile_fail
//! use microslam::ekf::{state_dim, EkfConfig, EkfSlam};
//! // The factor of N = 7 needs 28 scalars, not 49.
//! let ekf = EkfSlam::<f32, { state_dim(2) }, 49>::new(EkfConfig::DEFAULT_F32);
//! ```
//!
//! and so is a state dimension that is not `3 + 2k`:
//!
//! ```compile_fail,E0080
//! use microslam::ekf::{EkfConfig, EkfSlam};
//! // 4 = 3 + 2·0.5: no whole number of landmarks fits.
//! let ekf = EkfSlam::<f32, 4, 10>::new(EkfConfig::DEFAULT_F32);
//! ```

use crate::error::{EkfError, InvalidSetting};
use crate::gate::ChiSquareGate;
use crate::geometry::{Pose2, wrap_angle, wrap_near};
use crate::motion::{
    IncrementNoise, MotionStep, OdometryIncrement, VelocityNoise, compose_increment,
    integrate_velocity,
};
use crate::scalar::Real;
use crate::sensors::range_bearing::{RangeBearing, RangeBearingSensor};
use deferred::{DeferredMotion, product, pull_back};
use nalgebra::{ArrayStorage, Matrix2, Matrix2x3, Matrix3, SVector, Vector2};

pub mod covariance;
mod deferred;
pub mod health;

pub use covariance::{CovarianceView, factor_len};
use covariance::{internal_entry, ldl, ldl_product, mwgs, pivot, row_start, strict_row};

/// State dimension for a maximum of `max_landmarks` point landmarks: `3 + 2 · max_landmarks`.
///
/// ```
/// use microslam::ekf::{factor_len, state_dim, EkfSlam};
/// type Slam32 = EkfSlam<f32, { state_dim(32) }, { factor_len(32) }>;
/// assert_eq!(Slam32::MAX_LANDMARKS, 32);
/// ```
pub const fn state_dim(max_landmarks: usize) -> usize {
    3 + 2 * max_landmarks
}

/// Cap on the robot's heading variance, rad² (π²: beyond it the heading is unknown and
/// the linearisation meaningless).
pub const MAX_HEADING_VARIANCE: f64 = core::f64::consts::PI * core::f64::consts::PI;

/// Cap on the robot's and a new landmark's x and y variances, m² (a standard deviation of
/// 100 m). A robot or landmark that uncertain is lost: without the cap a sighting could
/// move it by thousands of kilometres, beyond [`MAX_COORDINATE`], and `f32` variances
/// could overflow. Positive semi-definiteness does not depend on it.
pub const MAX_POSITION_VARIANCE: f64 = 1.0e4;

/// Largest |x| or |y| of the robot and of landmarks, metres. Beyond it an `f32`
/// coordinate is coarser than 8 mm, so landmark − robot differences lose the precision
/// the observation model needs; predictions and new landmarks that would go further are
/// refused ([`EkfError::NumericalFailure`]). Keep the map origin near the work area.
pub const MAX_COORDINATE: f64 = 1.0e5;

/// Bit of the odometry scale factors' calibration slot.
const SCALE_SLOT: u16 = 1;
/// Bit of the range bias' calibration slot.
const BIAS_SLOT: u16 = 2;
/// Calibration slots there can be (odometry scale, range bias).
const MAX_CALIBRATION_SLOTS: usize = 2;

/// Bytes an `f32` filter uses beyond its mean and covariance factor (configuration,
/// counters, the deferred predictions).
pub const EKF_OVERHEAD_BYTES_F32: usize = 280;

/// Settings of the landmark EKF: noise, sensor mount and gate.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct EkfConfig<T> {
    /// Noise of odometry increments (used by [`EkfSlam::predict_increment`]).
    pub increment_noise: IncrementNoise<T>,
    /// Noise of velocity odometry (used by [`EkfSlam::predict_velocity`]).
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
    /// (of `sensor`) and `gate` — `None` when every one is valid. [`EkfSlam::init`] and
    /// [`EkfSlam::set_config`] refuse an invalid configuration with
    /// [`EkfError::InvalidNoise`]; this says which setting it was.
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

/// What [`EkfSlam::update`] did with a sighting.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum UpdateOutcome<T> {
    /// The sighting passed the gate and corrected the state; the normalised innovation
    /// squared (NIS, `νᵀ S⁻¹ ν`) is reported.
    Accepted {
        /// Normalised innovation squared.
        nis: T,
    },
    /// The sighting failed the gate and was not used; the state is unchanged.
    Gated {
        /// Normalised innovation squared.
        nis: T,
    },
}

impl<T: Copy> UpdateOutcome<T> {
    /// The normalised innovation squared, accepted or not.
    pub fn nis(&self) -> T {
        match *self {
            Self::Accepted { nis } | Self::Gated { nis } => nis,
        }
    }
}

/// Counters of what the filter did, for status reports.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct EkfCounters {
    /// Prediction steps applied.
    pub predictions: u32,
    /// Sightings that corrected the state.
    pub updates: u32,
    /// Sightings refused by the innovation gate.
    pub gated: u32,
    /// Steps refused for bad input (any [`EkfError`]).
    pub rejected: u32,
}

/// Innovation of one sighting against one landmark: everything the association and the
/// update need.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Innovation<T: Real> {
    /// `z − h(x)`, bearing wrapped.
    pub nu: Vector2<T>,
    /// Innovation covariance `H P Hᵀ + R`.
    pub s: Matrix2<T>,
    /// Its inverse.
    pub s_inv: Matrix2<T>,
    /// Squared Mahalanobis distance `νᵀ S⁻¹ ν`.
    pub mahalanobis_squared: T,
    /// ∂h/∂robot at the current estimate.
    pub jacobian_robot: Matrix2x3<T>,
    /// ∂h/∂landmark at the current estimate.
    pub jacobian_landmark: Matrix2<T>,
    /// ∂h/∂(b₀, b₂), the range bias' states (`[[1, β²], [0, 0]]`), when they are estimated
    /// ([`EkfSlam::estimate_range_bias`], at [`EkfSlam::range_bias_state`]); zero when not.
    pub jacobian_bias: Matrix2<T>,
}

/// Landmark EKF-SLAM over `f32` or `f64` with state dimension `N = 3 + 2·L` and a
/// covariance factor of `P = N (N + 1) / 2` scalars (write them with [`state_dim`] and
/// [`factor_len`]).
///
/// ```
/// use microslam::ekf::{factor_len, state_dim, EkfConfig, EkfSlam, UpdateOutcome};
/// use microslam::geometry::Pose2;
/// use microslam::sensors::range_bearing::RangeBearing;
///
/// let mut slam = EkfSlam::<f64, { state_dim(8) }, { factor_len(8) }>::new(EkfConfig::DEFAULT_F64);
/// let sign = slam.add_landmark(&RangeBearing::new(2.0, 0.5))?;
/// slam.predict_velocity(0.5, 0.1, 0.1)?;
/// let outcome = slam.update(sign, &RangeBearing::new(1.96, 0.51))?;
/// assert!(matches!(outcome, UpdateOutcome::Accepted { .. }));
/// assert_eq!(slam.landmark_count(), 1);
/// # Ok::<(), microslam::EkfError>(())
/// ```
#[derive(Clone, Debug)]
pub struct EkfSlam<T: Real, const N: usize, const P: usize> {
    mean: SVector<T, N>,
    /// `L` and `D`, packed (see [`covariance`]); beyond the active part it stays zero.
    factor: [T; P],
    /// Number of active two-state slots: the calibration slots, then the landmarks
    /// (fixed-size integers keep the layout the same on 32- and 64-bit).
    slots: u16,
    /// Which calibration slots come before the landmarks, as bits: [`SCALE_SLOT`] (the
    /// odometry scale factors, then slot 0) and [`BIAS_SLOT`] (the range bias, after them).
    calibration: u16,
    config: EkfConfig<T>,
    counters: EkfCounters,
    /// The predictions since the last write of the factor whose effect on the robot's
    /// coupling rows is not applied yet ([`deferred`]): the true rows are
    /// `A · stored + B`. Every write of the factor but a prediction's goes through
    /// [`EkfSlam::factor_mut`], which applies and clears it; readers apply it on the fly.
    deferred: Option<DeferredMotion<T>>,
}

/// One scalar measurement row: `(index inside the factor, coefficient)` for the five
/// states a sighting depends on, and the two of the range bias (zero when not estimated).
type SparseRow<T> = [(usize, T); 7];

impl<T: Real, const N: usize, const P: usize> EkfSlam<T, N, P> {
    /// Checked at compile time wherever the type is constructed.
    const DIMENSIONS_ARE_VALID: () = assert!(
        N >= 3 && (N - 3).is_multiple_of(2) && P == N * (N + 1) / 2 && N < 2 * u16::MAX as usize,
        "EkfSlam<T, N, P> needs N = 3 + 2 * max_landmarks and P = N (N + 1) / 2: \
         use state_dim() and factor_len()"
    );

    /// Maximum number of landmarks, `(N − 3) / 2`.
    pub const MAX_LANDMARKS: usize = (N - 3) / 2;

    /// A filter with the robot at the origin, known exactly, and no landmarks.
    ///
    /// A `const fn`: use it to initialise a `static`, so the covariance is placed by the
    /// linker and never copied through the stack. Being `const`, it cannot check
    /// `config`: give it a constant one, and pass a configuration read at run time (a
    /// file, the wire) through [`EkfSlam::init`] or [`EkfSlam::set_config`], which refuse
    /// an invalid one ([`EkfConfig::invalid_setting`] names it).
    pub const fn new(config: EkfConfig<T>) -> Self {
        let () = Self::DIMENSIONS_ARE_VALID;
        Self {
            mean: SVector::from_array_storage(ArrayStorage([[T::ZERO; N]; 1])),
            factor: [T::ZERO; P],
            slots: 0,
            calibration: 0,
            config,
            counters: EkfCounters {
                predictions: 0,
                updates: 0,
                gated: 0,
                rejected: 0,
            },
            deferred: None,
        }
    }

    /// Re-initialises in place: robot at `pose` with zero covariance, no landmarks, new
    /// configuration, counters cleared. Only the previously active part is cleared.
    pub fn init(&mut self, config: EkfConfig<T>, pose: Pose2<T>) -> Result<(), EkfError> {
        if !config.is_valid() {
            return Err(EkfError::InvalidNoise);
        }
        if !pose.is_finite() {
            return Err(EkfError::NonFiniteInput);
        }
        let k = self.active_dim();
        // Cleared, not applied: nothing of the old factor stays.
        self.deferred = None;
        if let Some(active) = self.factor_mut().get_mut(..row_start(k)) {
            active.fill(T::ZERO);
        }
        self.mean.rows_mut(0, k).fill(T::ZERO);
        self.mean[0] = pose.x;
        self.mean[1] = pose.y;
        self.mean[2] = wrap_angle(pose.theta);
        self.slots = 0;
        self.calibration = 0;
        self.config = config;
        self.counters = EkfCounters::default();
        Ok(())
    }

    /// The configuration in use.
    pub fn config(&self) -> &EkfConfig<T> {
        &self.config
    }

    /// Replaces the configuration (noise, gate, sensor). Refused when not valid.
    pub fn set_config(&mut self, config: EkfConfig<T>) -> Result<(), EkfError> {
        if !config.is_valid() {
            return Err(EkfError::InvalidNoise);
        }
        self.config = config;
        Ok(())
    }

    /// Counters of applied, gated and refused steps.
    pub fn counters(&self) -> EkfCounters {
        self.counters
    }

    /// Number of landmarks in the state.
    pub fn landmark_count(&self) -> usize {
        usize::from(self.slots.saturating_sub(self.calibration_slots() as u16))
    }

    /// Dimension of the active part of the state, `3 + 2n` for `n` active slots (the
    /// landmarks and the calibration slots, [`EkfSlam::estimate_odometry_scale`] and
    /// [`EkfSlam::estimate_range_bias`]).
    pub fn active_dim(&self) -> usize {
        3 + 2 * usize::from(self.slots)
    }

    /// Index of landmark `index`'s x in the public state order (`[x, y, θ, …]`, as in
    /// [`EkfSlam::active_mean`] and [`EkfSlam::active_covariance`]); its y follows.
    pub fn landmark_state(&self, index: usize) -> usize {
        3 + 2 * self.landmark_slot(index)
    }

    /// Number of calibration slots before the landmarks.
    fn calibration_slots(&self) -> usize {
        self.calibration.count_ones() as usize
    }

    /// Index of landmark `index` inside the factor (see [`covariance`]).
    fn landmark_slot(&self, index: usize) -> usize {
        index + self.calibration_slots()
    }

    /// The slot of the range bias, when it is estimated.
    fn bias_slot(&self) -> Option<usize> {
        (self.calibration & BIAS_SLOT != 0).then(|| usize::from(self.calibration & SCALE_SLOT != 0))
    }

    /// Appends a calibration slot (flag `bit`) with mean `mean` and independent priors of
    /// standard deviations `stds`; only before the first landmark. The robot rows move two
    /// rows down.
    fn add_calibration_slot(
        &mut self,
        bit: u16,
        mean: [T; 2],
        stds: [T; 2],
    ) -> Result<(), EkfError> {
        let valid = |v: T| v.finite() && v >= T::ZERO;
        if !stds.iter().all(|&v| valid(v)) {
            return self.reject(EkfError::InvalidNoise);
        }
        let slot = self.calibration_slots();
        if usize::from(self.slots) != slot
            || self.calibration & bit != 0
            || slot >= Self::MAX_LANDMARKS
        {
            return self.reject(EkfError::MapFull);
        }
        // The coupling rows are read below: apply the deferred predictions first.
        self.settle();
        let (l, d) = self.robot_block();
        let r0 = 2 * slot;
        // The robot rows' columns 0..r0 (coupling to the earlier calibration slots).
        let mut coupling = [[T::ZERO; 3]; 2 * MAX_CALIBRATION_SLOTS];
        for (c, row) in coupling.iter_mut().enumerate().take(r0) {
            for (a, v) in row.iter_mut().enumerate() {
                *v = strict_row(&self.factor, r0 + a)
                    .get(c)
                    .copied()
                    .unwrap_or(T::ZERO);
            }
        }
        if let Some(rows) = self.factor_mut().get_mut(row_start(r0)..row_start(r0 + 5)) {
            rows.fill(T::ZERO);
        }
        for (i, std) in stds.iter().enumerate() {
            if let Some(p) = self.factor_mut().get_mut(row_start(r0 + i) + r0 + i) {
                *p = *std * *std;
            }
        }
        self.mean[3 + r0] = mean[0];
        self.mean[3 + r0 + 1] = mean[1];
        self.slots += 1;
        self.calibration |= bit;
        for (c, row) in coupling.iter().enumerate().take(r0) {
            for (a, v) in row.iter().enumerate() {
                if let Some(e) = self.factor_mut().get_mut(row_start(r0 + 2 + a) + c) {
                    *e = *v;
                }
            }
        }
        self.set_robot_block(&l, &d);
        Ok(())
    }

    /// Makes the range bias of the sightings two more states, `b₀` and `b₂`: the sensor
    /// then measures `r + b₀ + b₂ β²` for a landmark at range `r` and bearing `β` (a
    /// camera whose ranges are too long straight ahead and too short at the image edges
    /// has `b₀ > 0`, `b₂ < 0`). Both start at 0 with standard deviations `offset_std` (m)
    /// and `curvature_std` (m/rad²) and are constant; every sighting of a landmark from
    /// another bearing makes them observable. They take the next slot (after the
    /// odometry scale factors, when those are estimated): one landmark less.
    ///
    /// Only before the first landmark, once after [`EkfSlam::init`]. Errors (state
    /// unchanged): [`EkfError::InvalidNoise`] for a negative or non-finite figure,
    /// [`EkfError::MapFull`] when a landmark exists, the bias is already estimated or
    /// there is no slot.
    pub fn estimate_range_bias(&mut self, offset_std: T, curvature_std: T) -> Result<(), EkfError> {
        self.estimate_range_bias_from((T::ZERO, T::ZERO), offset_std, curvature_std)
    }

    /// [`EkfSlam::estimate_range_bias`] starting from a prior mean `(b₀, b₂)` instead of
    /// zero, e.g. a calibration made beforehand on a recording with known landmarks. A
    /// non-finite mean is refused with [`EkfError::NonFiniteInput`] (state unchanged).
    pub fn estimate_range_bias_from(
        &mut self,
        mean: (T, T),
        offset_std: T,
        curvature_std: T,
    ) -> Result<(), EkfError> {
        if !(mean.0.finite() && mean.1.finite()) {
            return self.reject(EkfError::NonFiniteInput);
        }
        self.add_calibration_slot(BIAS_SLOT, [mean.0, mean.1], [offset_std, curvature_std])
    }

    /// Index of the range bias' `b₀` in the public state order (as
    /// [`EkfSlam::landmark_state`]; `b₂` follows), when it is estimated.
    pub fn range_bias_state(&self) -> Option<usize> {
        self.bias_slot().map(|s| 3 + 2 * s)
    }

    /// The estimated range bias `(b₀, b₂)`, or `None` when it is not estimated
    /// ([`EkfSlam::estimate_range_bias`]).
    pub fn range_bias(&self) -> Option<(T, T)> {
        let s = self.bias_slot()?;
        Some((self.mean[3 + 2 * s], self.mean[4 + 2 * s]))
    }

    /// Makes the odometry's speed and turn-rate scale factors `(s_v, s_ω)` two more
    /// states, estimated with the landmarks: [`EkfSlam::predict_velocity`] then moves the
    /// robot by `(s_v v, s_ω ω)`, and every sighting corrects the factors through their
    /// correlation with the pose. They start at 1 with standard deviations `speed_std`
    /// and `turn_std` and are constant (no process noise). They take the first
    /// landmark slot: [`EkfSlam::MAX_LANDMARKS`] − 1 landmarks remain.
    ///
    /// Only before the first landmark and before [`EkfSlam::estimate_range_bias`], once
    /// after [`EkfSlam::init`]. Errors (state unchanged): [`EkfError::InvalidNoise`] for a
    /// negative or non-finite figure, [`EkfError::MapFull`] when a landmark or a
    /// calibration slot exists or there is no slot.
    pub fn estimate_odometry_scale(&mut self, speed_std: T, turn_std: T) -> Result<(), EkfError> {
        if self.calibration != 0 {
            return self.reject(EkfError::MapFull);
        }
        self.add_calibration_slot(SCALE_SLOT, [T::ONE, T::ONE], [speed_std, turn_std])
    }

    /// The estimated odometry scale factors `(s_v, s_ω)`, or `None` when they are not
    /// estimated ([`EkfSlam::estimate_odometry_scale`]).
    pub fn odometry_scale(&self) -> Option<(T, T)> {
        (self.calibration & SCALE_SLOT != 0).then(|| (self.mean[3], self.mean[4]))
    }

    /// Current robot pose estimate.
    pub fn pose(&self) -> Pose2<T> {
        Pose2::new(self.mean[0], self.mean[1], self.mean[2])
    }

    /// Covariance of the robot pose, `P_RR` (O(1) after a prediction, O(n) after any
    /// other step).
    pub fn pose_covariance(&self) -> Matrix3<T> {
        match &self.deferred {
            Some(run) => run.robot_covariance(),
            None => self.start_deferral().robot_covariance(),
        }
    }

    /// Position of landmark `index`, or `None` when there is no such landmark.
    pub fn landmark(&self, index: usize) -> Option<Vector2<T>> {
        (index < self.landmark_count()).then(|| {
            self.mean
                .fixed_rows::<2>(self.landmark_state(index))
                .into_owned()
        })
    }

    /// 2 × 2 covariance of landmark `index`, or `None` when there is no such landmark
    /// (O(index)).
    pub fn landmark_covariance(&self, index: usize) -> Option<Matrix2<T>> {
        let i = 2 * self.landmark_slot(index);
        (index < self.landmark_count())
            .then(|| Matrix2::from_fn(|r, c| internal_entry(&self.factor, i + r, i + c)))
    }

    /// The active part of the mean, `[x, y, θ, x₁, y₁, …]`.
    pub fn active_mean(&self) -> &[T] {
        let k = self.active_dim();
        self.mean.as_slice().get(..k).unwrap_or(&[])
    }

    /// The active block of the covariance, as a symmetric view computed from the factor
    /// (no copy; O(n) per entry). After predictions, an entry in the robot's rows applies
    /// the deferred predictions as it reads them (a few times slower):
    /// [`EkfSlam::flush_predictions`] first when reading many.
    pub fn active_covariance(&self) -> CovarianceView<'_, T> {
        CovarianceView::new(
            &self.factor,
            self.active_dim(),
            self.deferred.as_ref().map(|run| run.map()),
        )
    }

    /// The whole mean, active or not (for tests and diagnostics).
    pub fn full_mean(&self) -> &SVector<T, N> {
        &self.mean
    }

    /// The packed factor storage, active or not (for tests and diagnostics): the first
    /// `k (k + 1) / 2` scalars hold the active factor ([`covariance`]), the rest is zero.
    /// After predictions the robot's coupling rows are stored as they were before them
    /// (the predictions are applied at the next update or new landmark); read the factor
    /// through [`EkfSlam::active_covariance`].
    /// Read the covariance through [`EkfSlam::active_covariance`].
    pub fn factor_storage(&self) -> &[T; P] {
        &self.factor
    }

    fn reject<R>(&mut self, e: EkfError) -> Result<R, EkfError> {
        crate::log::debug!("ekf: step refused: {}", e);
        self.counters.rejected = self.counters.rejected.saturating_add(1);
        Err(e)
    }

    /// The robot's own block of the factor: `L_rr` (unit lower) and `D_r`.
    #[allow(clippy::needless_range_loop)] // matrix indices read best as indices
    fn robot_block(&self) -> ([[T; 3]; 3], [T; 3]) {
        let r0 = self.active_dim() - 3;
        let mut l = [[T::ZERO; 3]; 3];
        let mut d = [T::ZERO; 3];
        for a in 0..3 {
            let row = strict_row(&self.factor, r0 + a);
            for b in 0..a {
                l[a][b] = row.get(r0 + b).copied().unwrap_or(T::ZERO);
            }
            l[a][a] = T::ONE;
            d[a] = pivot(&self.factor, r0 + a);
        }
        (l, d)
    }

    /// Writes the robot's own block of the factor (the robot rows' entries in the robot
    /// columns and their pivots), which no deferred prediction concerns: the coupling rows
    /// stay as they are stored.
    fn set_robot_block(&mut self, l: &[[T; 3]; 3], d: &[T; 3]) {
        let r0 = self.active_dim() - 3;
        for a in 0..3 {
            let start = row_start(r0 + a) + r0;
            if let Some(row) = self.factor.get_mut(start..=start + a) {
                for (b, slot) in row.iter_mut().enumerate() {
                    *slot = if b == a { d[a] } else { l[a][b] };
                }
            }
        }
    }

    /// `P_RR` and a bound on the largest |L_rc| of the robot rows over the columns left of
    /// the robot (non-finite when an entry may be): O(1) during a run of predictions,
    /// otherwise one pass over the robot's three rows.
    fn robot_summary(&self) -> (Matrix3<T>, T) {
        let run = self.deferred.unwrap_or_else(|| self.start_deferral());
        (run.robot_covariance(), run.largest())
    }

    /// `L_rr D_r L_rrᵀ`: the robot's own block's part of `P_RR`.
    fn own_covariance(&self) -> Matrix3<T> {
        let (lrr, dr) = self.robot_block();
        ldl_product(&lrr, &dr)
    }

    /// A run of deferred predictions starting from the factor as stored (one pass over the
    /// robot's three rows). (A plain maximum in its loop saves a third of its host
    /// instructions but, unrolled, costs the firmware 4 KB of flash.)
    fn start_deferral(&self) -> DeferredMotion<T> {
        let r0 = self.active_dim() - 3;
        let rows = [0, 1, 2].map(|a| {
            let row = strict_row(&self.factor, r0 + a);
            row.get(..r0).unwrap_or(&[])
        });
        let mut diag = 0;
        let pivots = (0..r0).map(move |c| {
            let d = self.factor.get(diag).copied().unwrap_or(T::ZERO);
            diag += c + 2;
            d
        });
        DeferredMotion::start(rows, pivots, &self.own_covariance())
    }

    /// Applies the predictions made since the last update or new landmark to the stored
    /// factor now (O(n), once). The next update or new landmark does it anyway; call it
    /// before reading many entries of [`EkfSlam::active_covariance`] (a JCBB batch),
    /// whose reads otherwise apply the deferred predictions to every robot entry they
    /// compute. Nothing the filter shows changes.
    pub fn flush_predictions(&mut self) {
        self.settle();
    }

    /// The factor, to write: applies the deferred predictions first. (Inlined: the loops
    /// of an update and a new landmark call it per row or entry, and after the first call
    /// it is one test.)
    #[inline(always)]
    fn factor_mut(&mut self) -> &mut [T; P] {
        self.settle();
        &mut self.factor
    }

    /// Applies the deferred predictions to the robot's coupling rows (O(n)), so that the
    /// stored factor is the true one.
    #[inline(always)]
    fn settle(&mut self) {
        if self.deferred.is_some() {
            self.apply_deferred();
        }
    }

    /// [`EkfSlam::settle`] when predictions are deferred.
    #[inline(never)]
    fn apply_deferred(&mut self) {
        // The map only (not `take`: the whole run is ten times its size).
        let Some(map) = self.deferred.as_ref().map(|run| run.map()) else {
            return;
        };
        self.deferred = None;
        let r0 = self.active_dim() - 3;
        let s0 = row_start(r0);
        let Some(all) = self.factor.get_mut(s0..row_start(r0 + 3)) else {
            return;
        };
        let (ra, rest) = all.split_at_mut(r0 + 1);
        let (rb, rc) = rest.split_at_mut(r0 + 2);
        let rows = ra.iter_mut().zip(rb.iter_mut()).zip(rc.iter_mut()).take(r0);
        for (c, ((x, y), z)) in rows.enumerate() {
            [*x, *y, *z] = map.apply([*x, *y, *z]);
            if c < 2 {
                *x += map.near(0, c);
                *y += map.near(1, c);
                *z += map.near(2, c);
            }
        }
    }

    /// The range bias' first factor index `bi` and its two rows of `L` (unit diagonal
    /// included) over columns `0..=bi + 1`, when the bias is estimated.
    fn bias_rows(&self) -> Option<(usize, [[T; 2 * MAX_CALIBRATION_SLOTS]; 2])> {
        let bi = 2 * self.bias_slot()?;
        let mut rows = [[T::ZERO; 2 * MAX_CALIBRATION_SLOTS]; 2];
        for (a, row) in rows.iter_mut().enumerate() {
            for (c, v) in row.iter_mut().enumerate().take(bi + a) {
                *v = strict_row(&self.factor, bi + a)
                    .get(c)
                    .copied()
                    .unwrap_or(T::ZERO);
            }
            if let Some(v) = row.get_mut(bi + a) {
                *v = T::ONE;
            }
        }
        Some((bi, rows))
    }

    /// Prediction with an odometry increment `(dx, dy, dθ)` in the previous robot frame
    /// (seed 1, eqs. 4–8), with the configured [`IncrementNoise`].
    ///
    /// Touches only the robot mean and the robot's rows of the factor. Non-finite input →
    /// [`EkfError::NonFiniteInput`], state unchanged.
    pub fn predict_increment(&mut self, increment: &OdometryIncrement<T>) -> Result<(), EkfError> {
        if !increment.is_finite() {
            return self.reject(EkfError::NonFiniteInput);
        }
        let step = compose_increment(&self.pose(), increment);
        let q = self.config.increment_noise.covariance(increment);
        self.apply_motion(&step, &[q[(0, 0)], q[(1, 1)], q[(2, 2)]], None)
    }

    /// Prediction with velocities `(v, ω)` held for `dt` seconds (seed 2, eq. 6), with the
    /// configured [`VelocityNoise`].
    ///
    /// `dt = 0` is a no-op; `dt < 0` (out-of-order stamps) → [`EkfError::NegativeTimeStep`];
    /// non-finite input → [`EkfError::NonFiniteInput`]; the state is unchanged on error.
    pub fn predict_velocity(&mut self, v: T, omega: T, dt: T) -> Result<(), EkfError> {
        if !(v.finite() && omega.finite() && dt.finite()) {
            return self.reject(EkfError::NonFiniteInput);
        }
        if dt < T::ZERO {
            return self.reject(EkfError::NegativeTimeStep);
        }
        if dt == T::ZERO {
            return Ok(());
        }
        let q = self.config.velocity_noise.covariance(v, omega, dt);
        let Some((sv, sw)) = self.odometry_scale() else {
            let step = integrate_velocity(&self.pose(), v, omega, dt);
            return self.apply_motion(&step, &[q[(0, 0)], q[(1, 1)]], None);
        };
        let step = integrate_velocity(&self.pose(), sv * v, sw * omega, dt);
        // ∂pose'/∂(s_v, s_ω): the input Jacobian's columns times the measured v and ω.
        let g = &step.wrt_input;
        let wrt_scale = [0, 1, 2].map(|a| [g[(a, 0)] * v, g[(a, 1)] * omega]);
        self.apply_motion(&step, &[q[(0, 0)], q[(1, 1)]], Some(&wrt_scale))
    }

    /// Adds the positive semi-definite `added` to the robot pose covariance, `P_RR`,
    /// leaving the mean and every other covariance entry as they are: a prediction with
    /// `F = I` and noise `added` (O(n), like a prediction). For recovery logic that
    /// declares the robot lost. The robot's variances stay within
    /// [`MAX_POSITION_VARIANCE`] and [`MAX_HEADING_VARIANCE`] as after any prediction.
    ///
    /// Errors (state unchanged): [`EkfError::NonFiniteInput`] for a non-finite `added`,
    /// [`EkfError::InvalidNoise`] when it is not symmetric positive semi-definite (its
    /// `L D Lᵀ` factorisation has a negative pivot), [`EkfError::NumericalFailure`] when
    /// the result would not be finite.
    ///
    /// ```
    /// use microslam::ekf::{factor_len, state_dim, EkfConfig, EkfSlam};
    /// use nalgebra::Matrix3;
    ///
    /// let mut slam = EkfSlam::<f64, { state_dim(4) }, { factor_len(4) }>::new(EkfConfig::DEFAULT_F64);
    /// slam.inflate_pose_covariance(&Matrix3::from_diagonal_element(0.5))?;
    /// assert_eq!(slam.pose_covariance(), Matrix3::from_diagonal_element(0.5));
    /// let indefinite = Matrix3::new(1.0, 2.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 1.0);
    /// assert!(slam.inflate_pose_covariance(&indefinite).is_err());
    /// # Ok::<(), microslam::EkfError>(())
    /// ```
    pub fn inflate_pose_covariance(&mut self, added: &Matrix3<T>) -> Result<(), EkfError> {
        if !added.iter().all(|v| v.finite()) {
            return self.reject(EkfError::NonFiniteInput);
        }
        let Some((la, da)) = ldl(added) else {
            return self.reject(EkfError::InvalidNoise);
        };
        let g = Matrix3::from_fn(|i, j| la[i][j]);
        match self.robot_map(&Matrix3::identity(), &g, &da, None) {
            Ok(()) => Ok(()),
            Err(e) => self.reject(e),
        }
    }

    /// `P' = F P Fᵀ + G Q Gᵀ` for a motion step, mean ← new pose; `wrt_scale` is
    /// ∂pose'/∂(s_v, s_ω) when the odometry scale factors are states.
    fn apply_motion<const U: usize>(
        &mut self,
        step: &MotionStep<T, U>,
        q: &[T; U],
        wrt_scale: Option<&[[T; 2]; 3]>,
    ) -> Result<(), EkfError> {
        let far = T::lit(MAX_COORDINATE);
        let inside = step.pose.x.abs() <= far && step.pose.y.abs() <= far;
        if !inside || !step.pose.is_finite() {
            return self.reject(EkfError::NumericalFailure);
        }
        // Inputs padded to three (zero weight).
        let mut g = Matrix3::zeros();
        let mut weights = [T::ZERO; 3];
        for (u, &qu) in q.iter().enumerate().take(3) {
            g.set_column(u, &step.wrt_input.column(u));
            weights[u] = qu;
        }
        if let Err(e) = self.robot_map(&step.wrt_pose, &g, &weights, wrt_scale) {
            return self.reject(e);
        }
        self.mean[0] = step.pose.x;
        self.mean[1] = step.pose.y;
        self.mean[2] = step.pose.theta;
        self.counters.predictions = self.counters.predictions.saturating_add(1);
        Ok(())
    }

    /// `P' = F P Fᵀ + G diag(q) Gᵀ` with `F`, `G` acting on the robot only, on the factor:
    /// the robot's coupling rows `L_rm ← S F L_rm` (deferred: [`deferred`]), and its own
    /// block re-factored from `S [F L_rr | G]` with weights `(D_r, q)`. `S` is the diagonal congruence that
    /// caps the robot's variances (see [`MAX_POSITION_VARIANCE`]); it is the identity
    /// unless a cap is exceeded. Checks everything before writing.
    ///
    /// The caps are tested on the robot covariance the step leaves with `S = I` (the run's
    /// coupled part plus the new own block, what [`EkfSlam::pose_covariance`] reads next):
    /// no `F P Fᵀ` is formed beside the factor. A step that exceeds a cap is made again
    /// with its `S`.
    ///
    /// With the odometry scale factors as states (slot 0, factor rows 0 and 1, before
    /// every other state) the map also has `F_s = ∂pose'/∂s` (`wrt_scale`): the robot's
    /// rows gain `S F_s L_s`, with `L_s = [[1, 0], [l₁₀, 1]]` the scale rows of `L`; they
    /// lie in columns 0 and 1, left of the robot's own block, which stays as above.
    fn robot_map(
        &mut self,
        f: &Matrix3<T>,
        g: &Matrix3<T>,
        q: &[T; 3],
        wrt_scale: Option<&[[T; 2]; 3]>,
    ) -> Result<(), EkfError> {
        // A run that starts here starts with the identity map: the true rows are the
        // stored ones, so starting it changes nothing the filter shows.
        if self.deferred.is_none() {
            self.deferred = Some(self.start_deferral());
        }
        let Some(run) = self.deferred.as_ref() else {
            return Err(EkfError::NumericalFailure);
        };
        let (lrr, dr) = self.robot_block();
        let lrr = Matrix3::from_fn(|i, j| lrr[i][j]);
        let l10 = self.factor.get(1).copied().unwrap_or(T::ZERO);
        let estimated = self.calibration & SCALE_SLOT != 0;
        // The step for the row scales `s` (the diagonal of `S`): the own block's new
        // factor, the run after it, and the robot covariance they give.
        let step = |s: [T; 3]| {
            let f = Matrix3::from_fn(|i, j| s[i] * f[(i, j)]);
            let flrr = product(&f, &lrr);
            let mut w = [[T::ZERO; 6]; 3];
            let mut weights = [T::ZERO; 6];
            for a in 0..3 {
                for c in 0..3 {
                    w[a][c] = flrr[(a, c)];
                    w[a][3 + c] = s[a] * g[(a, c)];
                }
                weights[a] = dr[a];
                weights[3 + a] = q[a];
            }
            let (l, d) = mwgs(w, &weights);
            // S F_s L_s, rows of the robot over columns 0 and 1.
            let scale_terms = wrt_scale.map(|fs| {
                Matrix3::from_fn(|a, c| {
                    let (f0, f1) = (s[a] * fs[a][0], s[a] * fs[a][1]);
                    match c {
                        0 => f0 + f1 * l10,
                        1 => f1,
                        _ => T::ZERO,
                    }
                })
            });
            let own = ldl_product(&l, &d);
            let next = run.then(&f, scale_terms.as_ref().filter(|_| estimated), &own);
            (l, d, next, next.robot_covariance(), scale_terms)
        };
        let (mut l, mut d, mut next, p_rr, mut scale_terms) = step([T::ONE; 3]);
        let scale = capped([
            (p_rr[(0, 0)], MAX_POSITION_VARIANCE),
            (p_rr[(1, 1)], MAX_POSITION_VARIANCE),
            (p_rr[(2, 2)], MAX_HEADING_VARIANCE),
        ]);
        if scale.iter().any(|&s| s != T::ONE) {
            (l, d, next, _, scale_terms) = step(scale);
        }
        let scale_ok = scale_terms.is_none_or(|t| t.iter().all(|v| v.finite()));
        if !p_rr.iter().all(|v| v.finite())
            || !all_finite(&l, &d)
            || !run.is_finite(&next)
            || !scale_ok
        {
            return Err(EkfError::NumericalFailure);
        }
        self.set_robot_block(&l, &d);
        if let Some(run) = self.deferred.as_mut() {
            run.advance(next);
        }
        Ok(())
    }

    /// The two measurement rows of a sighting of the landmark in slot `index` with Jacobians
    /// `hr` (robot) and `hl` (landmark), as sparse rows over the factor's order.
    fn sparse_rows(
        &self,
        index: usize,
        hr: &Matrix2x3<T>,
        hl: &Matrix2<T>,
        hb: [T; 2],
    ) -> [SparseRow<T>; 2] {
        let r0 = self.active_dim() - 3;
        let li = 2 * index;
        let bi = 2 * self.bias_slot().unwrap_or(0);
        [0, 1].map(|r| {
            let hb = if r == 0 { hb } else { [T::ZERO; 2] };
            [
                (bi, hb[0]),
                (bi + 1, hb[1]),
                (li, hl[(r, 0)]),
                (li + 1, hl[(r, 1)]),
                (r0, hr[(r, 0)]),
                (r0 + 1, hr[(r, 1)]),
                (r0 + 2, hr[(r, 2)]),
            ]
        })
    }

    /// `f = Lᵀ hᵀ` over the first `f.len()` states, for a sparse row `h`. With deferred
    /// predictions the robot's coefficients `h_r` act on the stored coupling rows as
    /// `Aᵀ h_r` and on columns 0 and 1 as `Bᵀ h_r` ([`deferred`]).
    fn project(&self, h: &SparseRow<T>, f: &mut [T]) {
        f.fill(T::ZERO);
        let r0 = self.active_dim() - 3;
        let deferred = self.deferred.as_ref().map(|run| run.map());
        let mut robot = [T::ZERO; 3];
        for &(s, hs) in h {
            if deferred.is_some()
                && let Some(v) = robot.get_mut(s.wrapping_sub(r0))
            {
                *v += hs;
                continue;
            }
            add_scaled(f, strict_row(&self.factor, s), hs);
            if let Some(fs) = f.get_mut(s) {
                *fs += hs;
            }
        }
        let Some(map) = deferred else {
            return;
        };
        let (on_stored, on_near) = pull_back(&map, robot);
        for (b, (&hr, &hs)) in robot.iter().zip(on_stored.iter()).enumerate() {
            let row = strict_row(&self.factor, r0 + b);
            let (coupling, own) = row.split_at(r0.min(row.len()));
            add_scaled(f, coupling, hs);
            add_scaled(f.get_mut(r0..).unwrap_or(&mut []), own, hr);
            if let Some(fs) = f.get_mut(r0 + b) {
                *fs += hr;
            }
        }
        if r0 >= 2 {
            add_scaled(f, &on_near, T::ONE);
        }
    }

    /// The innovation of sighting `z` (covariance `r`) against landmark `index`, without
    /// changing anything: `S = H P Hᵀ + R` with `H P Hᵀ = Fᵀ D F`, `F = Lᵀ Hᵀ` (O(n)).
    /// `f0`, `f1` (at least the active dimension long) receive the two columns of `F`.
    fn innovation_into(
        &self,
        index: usize,
        z: &RangeBearing<T>,
        r: &Matrix2<T>,
        f0: &mut [T],
        f1: &mut [T],
    ) -> Result<Innovation<T>, EkfError> {
        if index >= self.landmark_count() {
            return Err(EkfError::UnknownLandmark);
        }
        let landmark = self
            .mean
            .fixed_rows::<2>(self.landmark_state(index))
            .into_owned();
        let mut pred = self
            .config
            .sensor
            .predict(&self.pose(), &landmark)
            .ok_or(EkfError::LandmarkOnSensor)?;
        // With the range bias: r + b₀ + b₂ β², its Jacobian by the chain rule.
        let mut hb = [T::ZERO; 2];
        if let Some((b0, b2)) = self.range_bias() {
            let beta = pred.z.bearing;
            pred.z.range += b0 + b2 * beta * beta;
            let k = T::lit(2.0) * b2 * beta;
            for c in 0..3 {
                let below = pred.wrt_robot[(1, c)];
                pred.wrt_robot[(0, c)] += k * below;
            }
            for c in 0..2 {
                let below = pred.wrt_landmark[(1, c)];
                pred.wrt_landmark[(0, c)] += k * below;
            }
            hb = [T::ONE, beta * beta];
        }
        let (hr, hl) = (pred.wrt_robot, pred.wrt_landmark);
        let [h0, h1] = self.sparse_rows(self.landmark_slot(index), &hr, &hl, hb);
        let k = self.active_dim();
        let (Some(f0), Some(f1)) = (f0.get_mut(..k), f1.get_mut(..k)) else {
            return Err(EkfError::NumericalFailure);
        };
        self.project(&h0, f0);
        self.project(&h1, f1);
        let (mut s00, mut s01, mut s11) = (T::ZERO, T::ZERO, T::ZERO);
        let mut diag = 0;
        for (c, (&a, &b)) in f0.iter().zip(f1.iter()).enumerate() {
            let d = self.factor.get(diag).copied().unwrap_or(T::ZERO);
            diag += c + 2;
            let (da, db) = (d * a, d * b);
            s00 += da * a;
            s01 += da * b;
            s11 += db * b;
        }
        let off = s01 + (r[(0, 1)] + r[(1, 0)]) * T::lit(0.5);
        let s = Matrix2::new(s00 + r[(0, 0)], off, off, s11 + r[(1, 1)]);
        let det = s[(0, 0)] * s[(1, 1)] - off * off;
        if !is_positive(det) || !is_positive(s[(0, 0)]) || !det.finite() {
            return Err(EkfError::SingularInnovation);
        }
        let s_inv = Matrix2::new(s[(1, 1)] / det, -off / det, -off / det, s[(0, 0)] / det);
        let nu = Vector2::new(
            z.range - pred.z.range,
            wrap_near(z.bearing - pred.z.bearing),
        );
        let d2 = (nu.transpose() * s_inv * nu)[(0, 0)];
        if !d2.finite() {
            return Err(EkfError::NumericalFailure);
        }
        Ok(Innovation {
            nu,
            s,
            s_inv,
            mahalanobis_squared: d2,
            jacobian_robot: hr,
            jacobian_landmark: hl,
            jacobian_bias: Matrix2::new(hb[0], hb[1], T::ZERO, T::ZERO),
        })
    }

    /// [`EkfSlam::innovation_into`] with its own scratch.
    fn innovation_with(
        &self,
        index: usize,
        z: &RangeBearing<T>,
        r: &Matrix2<T>,
    ) -> Result<Innovation<T>, EkfError> {
        let (mut f0, mut f1) = ([T::ZERO; N], [T::ZERO; N]);
        self.innovation_into(index, z, r, &mut f0, &mut f1)
    }

    /// Checks a sighting and its covariance; returns the covariance to use.
    fn checked_measurement(
        &self,
        z: &RangeBearing<T>,
        r: Option<&Matrix2<T>>,
    ) -> Result<Matrix2<T>, EkfError> {
        if !(z.range.finite() && z.bearing.finite()) {
            return Err(EkfError::NonFiniteInput);
        }
        if z.bearing.abs() > T::lit(crate::sensors::range_bearing::MAX_BEARING) {
            return Err(EkfError::InvalidBearing);
        }
        if !z.is_valid() {
            return Err(EkfError::InvalidRange);
        }
        let r = r
            .copied()
            .unwrap_or_else(|| self.config.measurement_covariance());
        let det = r[(0, 0)] * r[(1, 1)] - r[(0, 1)] * r[(1, 0)];
        if !r.iter().all(|v| v.finite())
            || r[(0, 0)] < T::ZERO
            || r[(1, 1)] < T::ZERO
            || det < T::ZERO
        {
            return Err(EkfError::InvalidNoise);
        }
        Ok(r)
    }

    /// `R = L_R D_R L_Rᵀ` of a checked 2 × 2 measurement covariance: `(l₁₀, [d₀, d₁])`,
    /// `d ≥ 0` (the second pivot is `det R / r₀₀`, clamped at zero against rounding).
    fn decorrelate(r: &Matrix2<T>) -> (T, [T; 2]) {
        let r00 = r[(0, 0)];
        let off = (r[(0, 1)] + r[(1, 0)]) * T::lit(0.5);
        if r00 > T::ZERO {
            let l = off / r00;
            let d1 = r[(1, 1)] - l * off;
            (l, [r00, if d1 > T::ZERO { d1 } else { T::ZERO }])
        } else {
            // r₀₀ = 0 and det ≥ 0 force the off-diagonal to zero.
            (T::ZERO, [T::ZERO, r[(1, 1)]])
        }
    }

    /// The innovation of sighting `z` against landmark `index` (for data association),
    /// with the configured measurement noise, without changing the state.
    pub fn innovation(&self, index: usize, z: &RangeBearing<T>) -> Result<Innovation<T>, EkfError> {
        let r = self.checked_measurement(z, None)?;
        self.innovation_with(index, z, &r)
    }

    /// Corrects the state with a sighting `z` of landmark `index`, using the configured
    /// measurement noise. See [`EkfSlam::update_with_covariance`].
    pub fn update(
        &mut self,
        index: usize,
        z: &RangeBearing<T>,
    ) -> Result<UpdateOutcome<T>, EkfError> {
        self.update_inner(index, z, None)
    }

    /// Corrects the state with a sighting `z` of landmark `index` whose measurement
    /// covariance is `r` (range, bearing).
    ///
    /// Gating: when `νᵀ S⁻¹ ν` exceeds the configured gate the state is left unchanged and
    /// [`UpdateOutcome::Gated`] is returned. Errors (state unchanged): non-finite input,
    /// non-positive range, invalid covariance, unknown landmark, landmark on the sensor, a
    /// non-positive-definite innovation covariance.
    ///
    /// The correction is two scalar updates (range, then bearing; both rows linearised
    /// at the prior, a correlated `r` decorrelated first), which together equal the
    /// joint linear update.
    pub fn update_with_covariance(
        &mut self,
        index: usize,
        z: &RangeBearing<T>,
        r: &Matrix2<T>,
    ) -> Result<UpdateOutcome<T>, EkfError> {
        self.update_inner(index, z, Some(r))
    }

    fn update_inner(
        &mut self,
        index: usize,
        z: &RangeBearing<T>,
        r: Option<&Matrix2<T>>,
    ) -> Result<UpdateOutcome<T>, EkfError> {
        let r = match self.checked_measurement(z, r) {
            Ok(r) => r,
            Err(e) => return self.reject(e),
        };
        // f0, f1: the columns of Lᵀ Hᵀ; later f0 holds the new pivots.
        let (mut f0, mut f1) = ([T::ZERO; N], [T::ZERO; N]);
        let inn = match self.innovation_into(index, z, &r, &mut f0, &mut f1) {
            Ok(found) => found,
            Err(e) => return self.reject(e),
        };
        let nis = inn.mahalanobis_squared;
        if !self.config.gate.accepts(nis) {
            self.counters.gated = self.counters.gated.saturating_add(1);
            return Ok(UpdateOutcome::Gated { nis });
        }
        let mut terms = [[T::ZERO; 4]; N];
        let plan = match self.plan_update(&r, &inn.nu, &mut f0, &f1, &mut terms) {
            Ok(plan) => plan,
            Err(e) => return self.reject(e),
        };
        if self.apply_update(&plan, &f0, &terms).is_err() {
            return self.reject(EkfError::NumericalFailure);
        }
        self.counters.updates = self.counters.updates.saturating_add(1);
        Ok(UpdateOutcome::Accepted { nis })
    }

    /// Everything of an update but the O(n²) pass, in O(n), checked before anything is
    /// written: two scalar (Bierman) updates, range then bearing, both linearised at the
    /// prior, with `r` decorrelated first (`R = L_R D_R L_Rᵀ`, second row `h₁ − l h₀`).
    ///
    /// Scalar update `s` with `f = Lᵀ hᵀ`, `vⱼ = Dⱼ fⱼ` and `α` running from `r` over
    /// `j = k−1 … 0` (`α ← α + vⱼ fⱼ`) sets `Dⱼ' = Dⱼ α_before / α_after ≥ 0` and, row by
    /// row from the last entry to the first, `L_ij' = L_ij + bᵢ pⱼ`, `bᵢ ← bᵢ + L_ij vⱼ`,
    /// with `bᵢ = vᵢ` at the start and `pⱼ = −fⱼ / α_before`; `bᵢ` ends as `(P hᵀ)ᵢ`, so
    /// the gain is `b / α_total`. The second update's `f` after the first is
    /// `f₂ⱼ = f̃₁ⱼ + p₁ⱼ Σ_{t>j} v₁ₜ f̃₁ₜ` (no pass over `L` needed), so both run in one
    /// pass. On return `f0` holds the final pivots and `terms[j] = [p₁ⱼ, v₁ⱼ, p₂ⱼ, v₂ⱼ]`.
    fn plan_update(
        &self,
        r: &Matrix2<T>,
        nu: &Vector2<T>,
        f0: &mut [T; N],
        f1: &[T; N],
        terms: &mut [[T; 4]; N],
    ) -> Result<UpdatePlan<T>, EkfError> {
        let k = self.active_dim();
        let (l, d) = Self::decorrelate(r);
        let (Some(f0), Some(f1), Some(terms)) = (f0.get_mut(..k), f1.get(..k), terms.get_mut(..k))
        else {
            return Err(EkfError::NumericalFailure);
        };
        // First scalar: v₁ = D f₀.
        let mut hph = T::ZERO;
        let mut diag = 0;
        for (c, (t, &fc)) in terms.iter_mut().zip(f0.iter()).enumerate() {
            let dc = self.factor.get(diag).copied().unwrap_or(T::ZERO);
            diag += c + 2;
            t[1] = dc * fc;
            hph += t[1] * fc;
        }
        let r0 = sighting_floor(d[0], hph);
        let total0 = hph + r0;
        // Descending: D', p₁, and f₂ = f̃₁ + p₁ β with β the suffix sum of v₁ f̃₁.
        let mut alpha = r0;
        let mut beta = T::ZERO;
        let mut hph = T::ZERO;
        for c in (0..k).rev() {
            let (Some(t), Some(fc), Some(&g)) = (terms.get_mut(c), f0.get_mut(c), f1.get(c)) else {
                return Err(EkfError::NumericalFailure);
            };
            let g = g - l * *fc;
            let next = alpha + t[1] * *fc;
            let dc = pivot(&self.factor, c);
            let (new_d, p) = bierman_step(dc, *fc, alpha, next);
            t[0] = p;
            let f2 = g + p * beta;
            beta += t[1] * g;
            t[3] = new_d * f2;
            hph += t[3] * f2;
            // f0 now carries f₂ until the second chain below.
            *fc = f2;
            // The first update's pivot, kept in t[2] until the second chain.
            t[2] = new_d;
            alpha = next;
        }
        let r1 = sighting_floor(d[1], hph);
        let total1 = hph + r1;
        let mut alpha = r1;
        let mut poison = T::ZERO;
        for c in (0..k).rev() {
            let (Some(t), Some(fc)) = (terms.get_mut(c), f0.get_mut(c)) else {
                return Err(EkfError::NumericalFailure);
            };
            let next = alpha + t[3] * *fc;
            let (new_d, p) = bierman_step(t[2], *fc, alpha, next);
            t[2] = p;
            *fc = new_d;
            poison += (t[0] + t[1] + t[2] + t[3] + new_d) * T::ZERO;
            alpha = next;
        }
        // ν̃₁ = ν₁ − l ν₀, minus what the first correction explains: h̃₁ K₀ ν₀.
        let scale0 = if total0 > T::ZERO {
            nu[0] / total0
        } else {
            T::ZERO
        };
        let nu1 = nu[1] - l * nu[0] - beta * scale0;
        let scale1 = if total1 > T::ZERO {
            nu1 / total1
        } else {
            T::ZERO
        };
        poison += (total0 + total1 + scale0 + scale1) * T::ZERO;
        if poison != T::ZERO {
            return Err(EkfError::NumericalFailure);
        }
        Ok(UpdatePlan { scale0, scale1 })
    }

    /// The O(n²) pass of an update planned by [`EkfSlam::plan_update`]: each row of `L`
    /// once, both scalar updates per entry, and `x ← x + K₀ ν₀ + K₁ ν̃₁` (heading wrapped).
    /// `Err` when the result is not finite (the state is then no longer what it was).
    fn apply_update(
        &mut self,
        plan: &UpdatePlan<T>,
        pivots: &[T; N],
        terms: &[[T; 4]; N],
    ) -> Result<(), ()> {
        let k = self.active_dim();
        let mut poison = T::ZERO;
        // Rows two at a time: rows i and i + 1 share the terms of columns 0..i, loaded once.
        let mut i = 0;
        while i < k {
            let pair = i + 1 < k;
            let len = if pair { 2 * i + 3 } else { i + 1 };
            let start = row_start(i);
            let (Some(rows), Some(head), Some(&[_, va, _, vb])) = (
                self.factor_mut().get_mut(start..start + len),
                terms.get(..i),
                terms.get(i),
            ) else {
                return Err(());
            };
            let (row_a, rest) = rows.split_at_mut(i + 1);
            let Some((diag_a, row_a)) = row_a.split_last_mut() else {
                return Err(());
            };
            *diag_a = pivots.get(i).copied().unwrap_or(T::ZERO);
            let (ba, bb) = if let Some((diag_b, row_b)) = rest.split_last_mut() {
                *diag_b = pivots.get(i + 1).copied().unwrap_or(T::ZERO);
                let Some((last_b, row_b)) = row_b.split_last_mut() else {
                    return Err(());
                };
                let (Some(&[_, wa, _, wb]), Some(own)) = (terms.get(i + 1), terms.get(i..=i))
                else {
                    return Err(());
                };
                // Row i + 1's entry in column i first (its last), then both rows together.
                let b = bierman_row(core::slice::from_mut(last_b), own, wa, wb);
                bierman_rows(row_a, row_b, head, (va, vb), b)
            } else {
                (bierman_row(row_a, head, va, vb), (T::ZERO, T::ZERO))
            };
            for (r, (b0, b1)) in [(i, ba), (i + 1, bb)]
                .into_iter()
                .take(if pair { 2 } else { 1 })
            {
                let dx = b0 * plan.scale0 + b1 * plan.scale1;
                if let Some(x) = self.mean.as_mut_slice().get_mut(internal_to_public(r, k)) {
                    *x += dx;
                }
                poison += dx * T::ZERO;
            }
            i += 2;
        }
        self.mean[2] = wrap_near(self.mean[2]);
        if poison != T::ZERO { Err(()) } else { Ok(()) }
    }

    /// Adds a landmark seen at `z`, with the configured measurement noise. See
    /// [`EkfSlam::add_landmark_with_covariance`].
    pub fn add_landmark(&mut self, z: &RangeBearing<T>) -> Result<usize, EkfError> {
        self.add_inner(z, None)
    }

    /// Adds a landmark seen at `z` with measurement covariance `r`, by the inverse
    /// observation model `g` (seed 1, eqs. 20–24): mean `g(x_R, z)`, covariance
    /// `P_pp = G_R P_RR G_Rᵀ + G_z R G_zᵀ`, `P_pX = G_R [P_RR P_RM]`, kept factorised:
    /// the landmark's rows `G_R L_rm`, and the 5 × 5 block of the landmark and the robot
    /// re-factored from `[[G_R L_rr, G_z L_R], [L_rr, 0]]` with weights `(D_r, D_R)`.
    /// Returns its index.
    ///
    /// Errors (state unchanged): [`EkfError::MapFull`] when all `L` slots are used (the
    /// filter goes on with the landmarks it has), non-finite input, non-positive range,
    /// invalid covariance.
    pub fn add_landmark_with_covariance(
        &mut self,
        z: &RangeBearing<T>,
        r: &Matrix2<T>,
    ) -> Result<usize, EkfError> {
        self.add_inner(z, Some(r))
    }

    fn add_inner(
        &mut self,
        z: &RangeBearing<T>,
        r: Option<&Matrix2<T>>,
    ) -> Result<usize, EkfError> {
        let r = match self.checked_measurement(z, r) {
            Ok(r) => r,
            Err(e) => return self.reject(e),
        };
        if usize::from(self.slots) >= Self::MAX_LANDMARKS {
            return self.reject(EkfError::MapFull);
        }
        // With the range bias, the landmark is placed at the corrected range
        // r − b₀ − b₂ β; its Jacobians gain ∂/∂β of the correction and ∂/∂(b₀, b₂).
        let bias = self.range_bias();
        let corrected = match bias {
            Some((b0, b2)) => {
                RangeBearing::new(z.range - b0 - b2 * z.bearing * z.bearing, z.bearing)
            }
            None => *z,
        };
        if !corrected.is_valid() {
            return self.reject(EkfError::InvalidRange);
        }
        let mut g = self.config.sensor.landmark_from(&self.pose(), &corrected);
        let mut g_bias = Matrix2::zeros();
        if let Some((_, b2)) = bias {
            let beta = z.bearing;
            let k = T::lit(-2.0) * b2 * beta;
            for a in 0..2 {
                let dr = g.wrt_measurement[(a, 0)];
                g.wrt_measurement[(a, 1)] += dr * k;
                g_bias[(a, 0)] = -dr;
                g_bias[(a, 1)] = -dr * beta * beta;
            }
        }
        // Last-resort cap, as for the robot: scale the new rows (a congruence).
        let (p_rr, coupling) = self.robot_summary();
        let p_ll = g.wrt_robot * p_rr * g.wrt_robot.transpose()
            + g.wrt_measurement * r * g.wrt_measurement.transpose();
        let scale = capped([
            (p_ll[(0, 0)], MAX_POSITION_VARIANCE),
            (p_ll[(1, 1)], MAX_POSITION_VARIANCE),
        ]);
        let s = Matrix2::from_diagonal(&scale.into());
        let (gr, gz, g_bias) = (s * g.wrt_robot, s * g.wrt_measurement, s * g_bias);
        let bias_rows = self.bias_rows();
        let (lr, dr_meas) = Self::decorrelate(&r);
        let gz_lr = gz * Matrix2::new(T::ONE, T::ZERO, lr, T::ONE);
        let (lrr, dr) = self.robot_block();
        let gr_lrr = gr * Matrix3::from_fn(|i, j| lrr[i][j]);
        let mut w = [[T::ZERO; 5]; 5];
        for a in 0..2 {
            for c in 0..3 {
                w[a][c] = gr_lrr[(a, c)];
            }
            w[a][3] = gz_lr[(a, 0)];
            w[a][4] = gz_lr[(a, 1)];
        }
        for a in 0..3 {
            w[2 + a][..3].copy_from_slice(&lrr[a]);
        }
        let weights = [dr[0], dr[1], dr[2], dr_meas[0], dr_meas[1]];
        let (l5, d5) = mwgs(w, &weights);
        let coupling_bound = T::lit(3.0) * max_abs(gr.iter().copied()) * coupling;
        let far = T::lit(MAX_COORDINATE);
        let inside = g.landmark.iter().all(|c| c.abs() <= far);
        if !inside
            || !g.landmark.iter().all(|v| v.finite())
            || !p_ll.iter().all(|v| v.finite())
            || !all_finite(&l5, &d5)
            || !coupling_bound.finite()
        {
            return self.reject(EkfError::NumericalFailure);
        }
        let k = self.active_dim();
        let r0 = k - 3;
        if row_start(k + 2) > P {
            return self.reject(EkfError::MapFull);
        }
        // Move the robot rows two slots down (last first: each destination lies beyond
        // every source not yet moved), keeping their landmark columns 0..r0.
        for a in (0..3).rev() {
            let from = row_start(r0 + a);
            let to = row_start(r0 + 2 + a);
            self.factor_mut().copy_within(from..from + r0, to);
        }
        // The landmark rows r0, r0 + 1: G_R L_rm, then l5's own block.
        let new_robot = [0, 1, 2].map(|a| row_start(r0 + 2 + a));
        for c in 0..r0 {
            let col = [0, 1, 2].map(|a| {
                self.factor
                    .get(new_robot[a] + c)
                    .copied()
                    .unwrap_or(T::ZERO)
            });
            for a in 0..2 {
                let v = gr[(a, 0)] * col[0] + gr[(a, 1)] * col[1] + gr[(a, 2)] * col[2];
                if let Some(slot) = self.factor_mut().get_mut(row_start(r0 + a) + c) {
                    *slot = v;
                }
            }
        }
        // The range bias' part, G_b L_b, in the columns of the bias and before.
        if let Some((bi, lb)) = bias_rows {
            for c in 0..=bi + 1 {
                let (l0, l1) = (
                    lb[0].get(c).copied().unwrap_or(T::ZERO),
                    lb[1].get(c).copied().unwrap_or(T::ZERO),
                );
                for a in 0..2 {
                    if let Some(slot) = self.factor_mut().get_mut(row_start(r0 + a) + c) {
                        *slot += g_bias[(a, 0)] * l0 + g_bias[(a, 1)] * l1;
                    }
                }
            }
        }
        // The new 5 × 5 block: rows r0 … r0 + 4, columns r0 ….
        for a in 0..5 {
            let start = row_start(r0 + a) + r0;
            if let Some(row) = self.factor_mut().get_mut(start..=start + a) {
                for (b, slot) in row.iter_mut().enumerate() {
                    *slot = if b == a { d5[a] } else { l5[a][b] };
                }
            }
        }
        self.mean.fixed_rows_mut::<2>(k).copy_from(&g.landmark);
        let index = self.landmark_count();
        self.slots = self.slots.saturating_add(1);
        Ok(index)
    }
}

/// The O(n) results of [`EkfSlam::plan_update`]: the mean moves by
/// `b₀ · scale0 + b₁ · scale1` per state (`K ν` of the two scalar updates).
struct UpdatePlan<T> {
    scale0: T,
    scale1: T,
}

/// The measurement variance a scalar update uses: `r`, but at least `ε · h P hᵀ` (no
/// sighting is more precise than the rounding of its prediction; keeps the gain finite).
#[inline(always)]
fn sighting_floor<T: Real>(r: T, hph: T) -> T {
    let floor = T::default_epsilon() * hph;
    if r > floor { r } else { floor }
}

/// One step of Bierman's chain: the new pivot `D α / α_next` and the column factor
/// `−f / α` (both zero when nothing before carried information; `D` kept when the
/// state does not enter the measurement).
#[inline(always)]
fn bierman_step<T: Real>(d: T, f: T, alpha: T, next: T) -> (T, T) {
    if next <= T::ZERO {
        (d, T::ZERO)
    } else if alpha <= T::ZERO {
        (T::ZERO, T::ZERO)
    } else {
        (d * (alpha / next), -f / alpha)
    }
}

/// Both scalar updates on one row of `L` (its strict part), from its last entry to its
/// first: returns `(b₀, b₁)`, row `i` of `P h₀ᵀ` and of `P' h̃₁ᵀ`. The hot loop of the
/// update; not inlined, so the row and the terms keep their no-alias guarantees.
#[inline(never)]
fn bierman_row<T: Real>(row: &mut [T], terms: &[[T; 4]], v1: T, v2: T) -> (T, T) {
    let (mut b0, mut b1) = (v1, v2);
    for (l, &[p1, w1, p2, w2]) in row.iter_mut().rev().zip(terms.iter().rev()) {
        let old = *l;
        let once = old + b0 * p1;
        b0 += old * w1;
        *l = once + b1 * p2;
        b1 += once * w2;
    }
    (b0, b1)
}

/// [`bierman_row`] on two rows at once over the same columns (each column's terms loaded
/// once for both): `a` and `b` are the rows' running `(b₀, b₁)` at the start; returns
/// both at the end.
#[inline(never)]
fn bierman_rows<T: Real>(
    row_a: &mut [T],
    row_b: &mut [T],
    terms: &[[T; 4]],
    a: (T, T),
    b: (T, T),
) -> ((T, T), (T, T)) {
    let ((mut a0, mut a1), (mut b0, mut b1)) = (a, b);
    let rows = row_a.iter_mut().zip(row_b.iter_mut());
    for ((la, lb), &[p1, w1, p2, w2]) in rows.zip(terms).rev() {
        let (old_a, old_b) = (*la, *lb);
        let once_a = old_a + a0 * p1;
        let once_b = old_b + b0 * p1;
        a0 += old_a * w1;
        b0 += old_b * w1;
        *la = once_a + a1 * p2;
        *lb = once_b + b1 * p2;
        a1 += once_a * w2;
        b1 += once_b * w2;
    }
    ((a0, a1), (b0, b1))
}

/// Public state index (robot first) of index `i` inside the factor (robot last), for an
/// active dimension `k`.
#[inline(always)]
fn internal_to_public(i: usize, k: usize) -> usize {
    if i + 3 >= k { i + 3 - k } else { i + 3 }
}

/// Per-variance scale factors `√(cap / v)` for the variances `v` above their cap, 1 for
/// the others.
fn capped<T: Real, const R: usize>(variances: [(T, f64); R]) -> [T; R] {
    variances.map(|(v, cap)| {
        let cap = T::lit(cap);
        if v > cap { (cap / v).sqrt() } else { T::ONE }
    })
}

/// `true` when every entry of a small factor (`L`, `D`) is finite.
fn all_finite<T: Real, const R: usize>(l: &[[T; R]; R], d: &[T; R]) -> bool {
    l.iter().flatten().chain(d).all(|v| v.finite())
}

/// The largest absolute value (NaN propagates as NaN, an empty sequence gives 0).
fn max_abs<T: Real>(values: impl Iterator<Item = T>) -> T {
    values.fold(T::ZERO, |acc, v| {
        let a = v.abs();
        if a > acc || !a.finite() { a } else { acc }
    })
}

/// `f += a · row` over the shorter of the two (not inlined on a microcontroller: one copy
/// in the firmware's flash for every row a projection adds).
#[cfg_attr(target_os = "none", inline(never))]
fn add_scaled<T: Real>(f: &mut [T], row: &[T], a: T) {
    for (fc, &l) in f.iter_mut().zip(row) {
        *fc += a * l;
    }
}

/// `x > 0`, false for NaN.
fn is_positive<T: Real>(x: T) -> bool {
    x > T::ZERO
}

#[cfg(test)]
mod tests {
    use super::*;
    use covariance::internal;

    type Slam = EkfSlam<f64, { state_dim(6) }, { factor_len(6) }>;

    /// A filter with both calibration slots and three landmarks, after some updates.
    fn calibrated_with_landmarks() -> Slam {
        let mut slam = Slam::new(EkfConfig::DEFAULT_F64);
        slam.estimate_odometry_scale(0.05, 0.04).unwrap();
        slam.estimate_range_bias(0.1, 0.3).unwrap();
        for (i, z) in [(2.0, 0.4), (3.0, -0.7), (1.5, 1.2)]
            .into_iter()
            .enumerate()
        {
            slam.predict_velocity(0.4, 0.3, 0.5).unwrap();
            slam.add_landmark(&RangeBearing::new(z.0, z.1)).unwrap();
            slam.predict_velocity(0.3, -0.2, 0.5).unwrap();
            slam.update(i, &RangeBearing::new(z.0 - 0.1, z.1 + 0.05))
                .unwrap();
        }
        slam
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-12 * (1.0 + a.abs().max(b.abs()))
    }

    /// Predictions deferred ([`deferred`]) and predictions applied one by one give the
    /// same covariance, innovations and update: every reader of a deferred filter sees
    /// the true factor.
    #[test]
    fn deferred_predictions_read_and_update_like_applied_ones() {
        let mut deferred = calibrated_with_landmarks();
        let mut applied = deferred.clone();
        for k in 0..40 {
            let (v, w) = (0.2 + 0.01 * f64::from(k), 0.3 - 0.02 * f64::from(k));
            deferred.predict_velocity(v, w, 0.1).unwrap();
            applied.predict_velocity(v, w, 0.1).unwrap();
            applied.flush_predictions();
        }
        deferred
            .inflate_pose_covariance(&Matrix3::from_diagonal_element(0.01))
            .unwrap();
        applied
            .inflate_pose_covariance(&Matrix3::from_diagonal_element(0.01))
            .unwrap();
        applied.flush_predictions();
        assert!(deferred.deferred.is_some() && applied.deferred.is_none());
        // The stored robot rows differ; what the filter shows does not.
        assert_ne!(deferred.factor_storage(), applied.factor_storage());
        let (pd, pa) = (deferred.active_covariance(), applied.active_covariance());
        // Two calibration slots, three landmarks.
        assert_eq!(pd.dim(), 13);
        for i in 0..13 {
            for j in 0..13 {
                let (a, b) = (pd.get(i, j).unwrap(), pa.get(i, j).unwrap());
                assert!(close(a, b), "({i}, {j}): {a} vs {b}");
            }
            let (da, ra) = pd.factor_row(i).unwrap();
            let (db, rb) = pa.factor_row(i).unwrap();
            assert_eq!(da, db);
            assert!(ra.zip(rb).all(|(a, b)| close(a, b)), "factor row {i}");
        }
        let (cd, ca) = (deferred.pose_covariance(), applied.pose_covariance());
        assert!(
            cd.iter().zip(ca.iter()).all(|(a, b)| close(*a, *b)),
            "{cd} vs {ca}"
        );
        // A sighting near the predicted one, so that the gate accepts it.
        let guess = RangeBearing::new(2.0, 0.0);
        let nu = applied.innovation(1, &guess).unwrap().nu;
        let z = RangeBearing::new(2.0 - nu[0] + 0.05, -nu[1] - 0.02);
        let (id, ia) = (
            deferred.innovation(1, &z).unwrap(),
            applied.innovation(1, &z).unwrap(),
        );
        assert!(close(id.mahalanobis_squared, ia.mahalanobis_squared));
        assert!(id.s.iter().zip(ia.s.iter()).all(|(a, b)| close(*a, *b)));
        // The update applies the deferred predictions, then both filters agree.
        let accepted = |o: UpdateOutcome<f64>| matches!(o, UpdateOutcome::Accepted { .. });
        assert!(accepted(deferred.update(1, &z).unwrap()));
        assert!(accepted(applied.update(1, &z).unwrap()));
        assert!(deferred.deferred.is_none());
        for (a, b) in deferred
            .factor_storage()
            .iter()
            .zip(applied.factor_storage())
        {
            assert!(close(*a, *b), "{a} vs {b}");
        }
        for (a, b) in deferred.active_mean().iter().zip(applied.active_mean()) {
            assert!(close(*a, *b), "{a} vs {b}");
        }
    }

    /// A new landmark after deferred predictions moves the true robot rows.
    #[test]
    fn a_new_landmark_applies_the_deferred_predictions() {
        let mut deferred = calibrated_with_landmarks();
        let mut applied = deferred.clone();
        for _ in 0..10 {
            deferred.predict_velocity(0.5, 0.2, 0.1).unwrap();
            applied.predict_velocity(0.5, 0.2, 0.1).unwrap();
            applied.flush_predictions();
        }
        let z = RangeBearing::new(2.5, -0.3);
        assert_eq!(deferred.add_landmark(&z), applied.add_landmark(&z));
        for (a, b) in deferred
            .factor_storage()
            .iter()
            .zip(applied.factor_storage())
        {
            assert!(close(*a, *b), "{a} vs {b}");
        }
    }

    #[test]
    fn public_and_internal_indices_are_inverse() {
        for k in [3, 5, 9] {
            for s in 0..k {
                assert_eq!(internal_to_public(internal(s, k), k), s);
            }
        }
    }

    #[test]
    fn an_invalid_setting_is_named_with_its_rule() {
        use crate::testing::{BrokenSetting, each_broken_setting_is_named};
        let valid = EkfConfig::<f64>::DEFAULT_F64;
        assert_eq!(valid.invalid_setting(), None);
        assert_eq!(EkfConfig::<f32>::MICROCONTROLLER.invalid_setting(), None);
        let cases: [BrokenSetting<EkfConfig<f64>>; 7] = [
            (
                |c| c.increment_noise.rotation_std_per_metre = -0.1,
                "rotation_std_per_metre",
                "finite and non-negative",
            ),
            (
                |c| c.velocity_noise.linear_std = f64::NAN,
                "linear_std",
                "finite and non-negative",
            ),
            (
                |c| c.velocity_noise.angular_std_per_mps = f64::INFINITY,
                "angular_std_per_mps",
                "finite and non-negative",
            ),
            (
                |c| c.range_std = -1.0,
                "range_std",
                "finite and non-negative",
            ),
            (
                |c| c.bearing_std = f64::NEG_INFINITY,
                "bearing_std",
                "finite and non-negative",
            ),
            (|c| c.sensor.mount.theta = f64::NAN, "mount", "finite"),
            (
                |c| c.gate = ChiSquareGate::from_threshold(0.0),
                "gate",
                "a positive threshold",
            ),
        ];
        each_broken_setting_is_named(valid, &cases, |c| (c.is_valid(), c.invalid_setting()));
        // The filter refuses each of them and keeps its own.
        for (break_it, name, _) in cases {
            let mut c = valid;
            break_it(&mut c);
            let mut slam = Slam::new(valid);
            assert_eq!(slam.set_config(c), Err(EkfError::InvalidNoise), "{name}");
            assert_eq!(slam.config(), &valid, "{name}");
            assert_eq!(
                slam.init(c, Pose2::new(1.0, 0.0, 0.0)),
                Err(EkfError::InvalidNoise)
            );
        }
    }
}
