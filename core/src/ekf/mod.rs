//! Landmark EKF-SLAM with a fixed, compile-time maximum number of landmarks.
//!
//! The state is `[x, y, θ, x₁, y₁, …, x_L, y_L]` (robot pose, then point landmarks) with
//! dimension `N = 3 + 2·L` ([`state_dim`]). Storage for the whole `N × N` covariance is
//! reserved up front, but only the *active* block `(3 + 2n) × (3 + 2n)` of the `n`
//! landmarks added so far is ever read or written:
//!
//! | step | what it touches | cost |
//! | --- | --- | --- |
//! | [`EkfSlam::predict_increment`], [`EkfSlam::predict_velocity`] | robot mean, `P_RR`, `P_RM` | O(n) |
//! | [`EkfSlam::update`] | the active block | O(n²) |
//! | [`EkfSlam::add_landmark`] | one new row/column pair | O(n) |
//!
//! Nothing decomposes the covariance: the only inverse is of the 2 × 2 innovation
//! covariance. Corrections to seed 1: the covariance update is `P − K S Kᵀ` (its eq. 19 has
//! the wrong sign), the measurement model is polar on both sides (eq. 12 mixes a Cartesian
//! prediction with a polar measurement), and all noise is configuration (eq. 9's constant
//! `Q` is gone).
//!
//! # Numerical safeguards
//!
//! Written down as PX4's EKF2 does, and exercised by the fuzz targets in `fuzz/`:
//! - every step checks its inputs and the finiteness of what it would write *before*
//!   writing; an update, prediction or new landmark that would leave a negative
//!   variance is refused ([`EkfError::NumericalFailure`]) — the state is then exactly
//!   what it was;
//! - the covariance is symmetric by construction: only its upper triangle is stored and
//!   computed ([`covariance`] module; read it through [`EkfSlam::active_covariance`]);
//! - the robot and landmarks stay within [`MAX_COORDINATE`] of the origin, where `f32`
//!   coordinates are still finer than a centimetre;
//! - the Joseph update treats a sighting as no more precise than the rounding level of
//!   `H P Hᵀ`, and gives rows whose terms cancel heavily their rounding error back as
//!   variance ([`CovarianceUpdate::Joseph`]): positive semi-definite additions that
//!   keep `f32` rounding from making `P` indefinite when it holds 10⁴ m² next to 10⁻⁴;
//! - as a last resort, a prediction caps the robot's variances at
//!   [`MAX_POSITION_VARIANCE`] and [`MAX_HEADING_VARIANCE`], and a new landmark's at
//!   [`MAX_POSITION_VARIANCE`], by scaling their rows and columns (a congruence, which
//!   keeps `P` positive semi-definite). A robot or landmark that uncertain is lost;
//!   without the cap, `f32` cancellation in the next update would break the covariance.
//!
//! # Memory
//!
//! `size_of::<EkfSlam<T, N>>() = (N² + N) · size_of::<T>() + EKF_OVERHEAD_BYTES(T)`; for
//! `f32` the overhead is [`EKF_OVERHEAD_BYTES_F32`]. With `f32`:
//!
//! | landmarks | N | bytes |
//! | --- | --- | --- |
//! | 16 | 35 | 5 128 |
//! | 32 | 67 | 18 312 |
//! | 64 | 131 | 69 256 |
//!
//! Such a filter belongs in a `static` on a microcontroller: [`EkfSlam::new`] is a
//! `const fn`, so `static`s are laid out by the linker (`.bss`/`.data`) and never pass
//! through the stack; [`EkfSlam::init`] re-initialises in place. An update uses
//! `6 · N · size_of::<T>()` bytes of stack for its per-row terms, the Joseph form
//! `N · size_of::<T>()` more for the size of each row's rounding. The strict lower
//! triangle of the storage is never used (see [`covariance`]).
//!
//! A state dimension that is not `3 + 2k` is rejected at compile time:
//!
//! ```compile_fail
//! use microslam::ekf::{EkfConfig, EkfSlam};
//! // 4 = 3 + 2·0.5: no whole number of landmarks fits.
//! let ekf = EkfSlam::<f32, 4>::new(EkfConfig::DEFAULT_F32);
//! ```

use crate::error::EkfError;
use crate::gate::ChiSquareGate;
use crate::geometry::{Pose2, wrap_angle, wrap_near};
use crate::motion::{
    IncrementNoise, MotionStep, OdometryIncrement, VelocityNoise, compose_increment,
    integrate_velocity,
};
use crate::scalar::Real;
use crate::sensors::range_bearing::{RangeBearing, RangeBearingSensor};
use nalgebra::{ArrayStorage, Matrix2, Matrix2x3, Matrix3, SMatrix, SVector, Vector2};

pub mod covariance;
pub mod health;

pub use covariance::CovarianceView;
use covariance::{
    UpdateRow, block, entry, joseph_entry, load_diagonal, set_diagonal_block, symmetric_entry,
    update_upper,
};

/// State dimension for a maximum of `max_landmarks` point landmarks: `3 + 2 · max_landmarks`.
///
/// ```
/// use microslam::ekf::{state_dim, EkfSlam};
/// type Slam32 = EkfSlam<f32, { state_dim(32) }>;
/// assert_eq!(Slam32::MAX_LANDMARKS, 32);
/// ```
pub const fn state_dim(max_landmarks: usize) -> usize {
    3 + 2 * max_landmarks
}

/// Cap on the robot's heading variance, rad² (π²: beyond it the heading is unknown and
/// the linearisation meaningless).
pub const MAX_HEADING_VARIANCE: f64 = core::f64::consts::PI * core::f64::consts::PI;

/// Cap on the robot's and a new landmark's x and y variances, m² (a standard deviation of
/// 100 m). An `f32` covariance holding 10⁴ m² next to 10⁻² m² sightings loses about
/// 10⁴ · 6·10⁻⁸ = 6·10⁻⁴ m² to rounding in an update, well below the sighting noise;
/// at 10⁶ m² the fuzzer found updates that left `P` clearly indefinite.
pub const MAX_POSITION_VARIANCE: f64 = 1.0e4;

/// Largest |x| or |y| of the robot and of landmarks, metres. Beyond it an `f32`
/// coordinate is coarser than 8 mm, so landmark − robot differences lose the precision
/// the observation model needs; predictions and new landmarks that would go further are
/// refused ([`EkfError::NumericalFailure`]). Keep the map origin near the work area.
pub const MAX_COORDINATE: f64 = 1.0e5;

/// Diagonal loading of the Joseph update, in machine epsilons per state: variance `i`
/// gets `JOSEPH_LOADING · k · ε · (wᵢ − CANCELLATION_RATIO · Pᵢᵢ)` added when positive,
/// `wᵢ` being the size of row `i`'s update terms (see [`CovarianceUpdate::Joseph`]).
const JOSEPH_LOADING: f64 = 16.0;

/// A Joseph update row whose terms exceed its variance this many times cancels heavily
/// enough to be loaded (see `JOSEPH_LOADING`).
const CANCELLATION_RATIO: f64 = 16.0;

/// Floor on the sighting variances of a Joseph update, in machine epsilons of the
/// magnitude of `H P Hᵀ`'s terms (see [`CovarianceUpdate::Joseph`]).
const ROUNDING_FLOOR: f64 = 16.0;

/// Bytes an `f32` filter uses beyond its mean and covariance (configuration, counters).
pub const EKF_OVERHEAD_BYTES_F32: usize = 88;

/// How the covariance is updated after a measurement (as in adskalman-rs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CovarianceUpdate {
    /// Joseph form `(I − KH) P (I − KH)ᵀ + K R Kᵀ`, evaluated in place in one pass over
    /// the upper triangle (`P − K Mᵀ + D Kᵀ`, `M = P Hᵀ`): keeps `P` positive
    /// semi-definite in `f32` even when `K` carries rounding errors.
    ///
    /// Two guards keep it so when `f32` cannot resolve what the update computes — a lost
    /// robot (10⁴ m² variances, heading at the π² cap) seeing a landmark it has just
    /// added, whose position relative to the robot is known to centimetres:
    /// - the sighting's variances are raised, where smaller, to `16 ε (|H| |P| |H|ᵀ)ᵢᵢ`,
    ///   the rounding level of `H P Hᵀ`: otherwise `S` there is mostly rounding, and the
    ///   gain it gives can be thousands of times too large;
    /// - a row `i` whose update terms cancel heavily — `wᵢ = |Kᵢ| · (|P| |H|ᵀ)ᵢ`, the
    ///   size of the products that cancel in `M`, `A` and the pass, more than 16 times
    ///   its variance `Pᵢᵢ` — gets its rounding error back as variance after the pass:
    ///   `16 k ε (wᵢ − 16 Pᵢᵢ)` is added to `Pᵢᵢ` (`k = 3 + 2n`), a diagonal loading.
    ///   Without it the pass rounds away the smallest eigenvalues of a `P` that holds
    ///   10⁴ next to 10⁻⁴, and the next updates amplify the negative ones (−0.03 to
    ///   −0.9 in one update).
    ///
    /// Both only ever add a positive semi-definite term, cost O(1) and O(k), and leave
    /// ordinary updates untouched: the MRCLAM replays give the same figures to the
    /// printed digits in `f32` and `f64`.
    #[default]
    Joseph,
    /// The optimal-gain form `P − K S Kᵀ` on the upper triangle, mirrored (exactly
    /// symmetric): one pass over half the block, the cheapest choice. It keeps variances
    /// non-negative (steps that would leave a negative one are refused, predictions and
    /// new landmarks included) but, unlike the Joseph form, not `P`
    /// positive semi-definite when an `f32` update shrinks variances by many orders of
    /// magnitude (found by the fuzzer after the variance caps): prefer Joseph unless the
    /// instruction budget forbids it.
    Symmetric,
}

/// Settings of the landmark EKF: noise, sensor mount, gate and update form.
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
    /// Form of the covariance update.
    pub covariance_update: CovarianceUpdate,
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
            covariance_update: CovarianceUpdate::Joseph,
        }
    };
}

impl EkfConfig<f32> {
    /// Generic defaults for `f32`: 5 % odometry noise, 0.1 m / 2° sightings, a 99.9 % gate.
    /// Tune them per robot and dataset.
    pub const DEFAULT_F32: Self = default_config!(f32);

    /// [`EkfConfig::DEFAULT_F32`] with the optimal-gain covariance update
    /// ([`CovarianceUpdate::Symmetric`]): what the example firmware runs. On a Cortex-M4F
    /// an update at 64 landmarks costs about 64 k instructions this way against 104 k
    /// for the Joseph form (2 instead of 4 multiply-adds per covariance entry); both
    /// forms refuse an update that would leave a negative variance.
    pub const MICROCONTROLLER: Self = Self {
        covariance_update: CovarianceUpdate::Symmetric,
        ..Self::DEFAULT_F32
    };
}

impl EkfConfig<f64> {
    /// The same defaults as [`EkfConfig::DEFAULT_F32`], in `f64`.
    pub const DEFAULT_F64: Self = default_config!(f64);
}

impl<T: Real> EkfConfig<T> {
    /// `true` when every noise figure is finite and non-negative and the gate positive.
    pub fn is_valid(&self) -> bool {
        self.increment_noise.is_valid()
            && self.velocity_noise.is_valid()
            && self.range_std.finite()
            && self.bearing_std.finite()
            && self.range_std >= T::ZERO
            && self.bearing_std >= T::ZERO
            && self.sensor.mount.is_finite()
            && self.gate.threshold > T::ZERO
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
            covariance_update: self.covariance_update,
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
}

/// Landmark EKF-SLAM over `f32` or `f64` with state dimension `N = 3 + 2·L`.
///
/// ```
/// use microslam::ekf::{state_dim, EkfConfig, EkfSlam, UpdateOutcome};
/// use microslam::geometry::Pose2;
/// use microslam::sensors::range_bearing::RangeBearing;
///
/// let mut slam = EkfSlam::<f64, { state_dim(8) }>::new(EkfConfig::DEFAULT_F64);
/// let sign = slam.add_landmark(&RangeBearing::new(2.0, 0.5))?;
/// slam.predict_velocity(0.5, 0.1, 0.1)?;
/// let outcome = slam.update(sign, &RangeBearing::new(1.96, 0.51))?;
/// assert!(matches!(outcome, UpdateOutcome::Accepted { .. }));
/// assert_eq!(slam.landmark_count(), 1);
/// # Ok::<(), microslam::EkfError>(())
/// ```
#[derive(Clone, Debug)]
pub struct EkfSlam<T: Real, const N: usize> {
    mean: SVector<T, N>,
    /// Upper triangle only (see [`covariance`]); the strict lower triangle stays zero.
    covariance: SMatrix<T, N, N>,
    /// Number of active landmarks (`u32` keeps the layout the same on 32- and 64-bit).
    landmarks: u32,
    config: EkfConfig<T>,
    counters: EkfCounters,
}

impl<T: Real, const N: usize> EkfSlam<T, N> {
    /// Checked at compile time wherever the type is constructed.
    const DIMENSION_IS_VALID: () = assert!(
        N >= 3 && (N - 3).is_multiple_of(2),
        "EkfSlam state dimension must be 3 + 2 * max_landmarks: use state_dim()"
    );

    /// Maximum number of landmarks, `(N − 3) / 2`.
    pub const MAX_LANDMARKS: usize = (N - 3) / 2;

    /// A filter with the robot at the origin, known exactly, and no landmarks.
    ///
    /// A `const fn`: use it to initialise a `static`, so the covariance is placed by the
    /// linker and never copied through the stack.
    pub const fn new(config: EkfConfig<T>) -> Self {
        let () = Self::DIMENSION_IS_VALID;
        Self {
            mean: SVector::from_array_storage(ArrayStorage([[T::ZERO; N]; 1])),
            covariance: SMatrix::from_array_storage(ArrayStorage([[T::ZERO; N]; N])),
            landmarks: 0,
            config,
            counters: EkfCounters {
                predictions: 0,
                updates: 0,
                gated: 0,
                rejected: 0,
            },
        }
    }

    /// Re-initialises in place: robot at `pose` with zero covariance, no landmarks, new
    /// configuration, counters cleared. Only the previously active block is cleared.
    pub fn init(&mut self, config: EkfConfig<T>, pose: Pose2<T>) -> Result<(), EkfError> {
        if !config.is_valid() {
            return Err(EkfError::InvalidNoise);
        }
        if !pose.is_finite() {
            return Err(EkfError::NonFiniteInput);
        }
        let k = self.active_dim();
        self.covariance.view_mut((0, 0), (k, k)).fill(T::ZERO);
        self.mean.rows_mut(0, k).fill(T::ZERO);
        self.mean[0] = pose.x;
        self.mean[1] = pose.y;
        self.mean[2] = wrap_angle(pose.theta);
        self.landmarks = 0;
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
        self.landmarks as usize
    }

    /// Dimension of the active part of the state, `3 + 2n`.
    pub fn active_dim(&self) -> usize {
        3 + 2 * self.landmark_count()
    }

    /// Current robot pose estimate.
    pub fn pose(&self) -> Pose2<T> {
        Pose2::new(self.mean[0], self.mean[1], self.mean[2])
    }

    /// Covariance of the robot pose, `P_RR`.
    pub fn pose_covariance(&self) -> Matrix3<T> {
        block(&self.covariance, 0, 0)
    }

    /// Adds `added`, a symmetric positive semi-definite 3 × 3 matrix, to the robot's pose
    /// covariance `P_RR` (a congruence-free PSD addition: `P` stays positive
    /// semi-definite). Used to re-open a filter that has become overconfident.
    ///
    /// Refused, state unchanged: non-finite entries ([`EkfError::NonFiniteInput`]), a
    /// matrix that is not symmetric or has a negative principal minor
    /// ([`EkfError::InvalidNoise`]), a result beyond [`MAX_POSITION_VARIANCE`] or
    /// [`MAX_HEADING_VARIANCE`] ([`EkfError::NumericalFailure`]).
    pub fn inflate_pose_covariance(&mut self, added: &Matrix3<T>) -> Result<(), EkfError> {
        if added.iter().any(|v| !v.finite()) {
            return Err(EkfError::NonFiniteInput);
        }
        let a = |r: usize, c: usize| added[(r, c)];
        let symmetric = a(0, 1) == a(1, 0) && a(0, 2) == a(2, 0) && a(1, 2) == a(2, 1);
        let minors = [
            a(0, 0),
            a(1, 1),
            a(2, 2),
            a(0, 0) * a(1, 1) - a(0, 1) * a(0, 1),
            a(0, 0) * a(2, 2) - a(0, 2) * a(0, 2),
            a(1, 1) * a(2, 2) - a(1, 2) * a(1, 2),
            added.determinant(),
        ];
        if !symmetric || minors.iter().any(|&m| m < T::ZERO) {
            return Err(EkfError::InvalidNoise);
        }
        let sum = self.pose_covariance() + added;
        let position_cap = T::lit(MAX_POSITION_VARIANCE);
        let heading_cap = T::lit(MAX_HEADING_VARIANCE);
        // Finite: both terms are.
        if sum[(0, 0)] > position_cap || sum[(1, 1)] > position_cap || sum[(2, 2)] > heading_cap {
            return Err(EkfError::NumericalFailure);
        }
        set_diagonal_block(&mut self.covariance, 0, &sum);
        Ok(())
    }

    /// Position of landmark `index`, or `None` when there is no such landmark.
    pub fn landmark(&self, index: usize) -> Option<Vector2<T>> {
        (index < self.landmark_count())
            .then(|| self.mean.fixed_rows::<2>(3 + 2 * index).into_owned())
    }

    /// 2 × 2 covariance of landmark `index`, or `None` when there is no such landmark.
    pub fn landmark_covariance(&self, index: usize) -> Option<Matrix2<T>> {
        let i = 3 + 2 * index;
        (index < self.landmark_count()).then(|| block(&self.covariance, i, i))
    }

    /// The active part of the mean, `[x, y, θ, x₁, y₁, …]`.
    pub fn active_mean(&self) -> &[T] {
        let k = self.active_dim();
        self.mean.as_slice().get(..k).unwrap_or(&[])
    }

    /// The active block of the covariance, as a symmetric view (no copy).
    pub fn active_covariance(&self) -> CovarianceView<'_, T, N> {
        CovarianceView::new(&self.covariance, self.active_dim())
    }

    /// The whole mean, active or not (for tests and diagnostics).
    pub fn full_mean(&self) -> &SVector<T, N> {
        &self.mean
    }

    /// The raw covariance storage, active or not (for tests and diagnostics): the upper
    /// triangle of the active block holds the covariance, everything else is zero. Read
    /// the covariance through [`EkfSlam::active_covariance`].
    pub fn covariance_storage(&self) -> &SMatrix<T, N, N> {
        &self.covariance
    }

    /// The largest variance of the active block: bounds every covariance entry (P is PSD).
    fn max_variance(&self) -> T {
        let diagonal = self.covariance.as_slice().iter().step_by(N + 1);
        max_abs(diagonal.take(self.active_dim()).copied())
    }

    fn reject<R>(&mut self, e: EkfError) -> Result<R, EkfError> {
        crate::log::debug!("ekf: step refused: {}", e);
        self.counters.rejected = self.counters.rejected.saturating_add(1);
        Err(e)
    }

    /// Prediction with an odometry increment `(dx, dy, dθ)` in the previous robot frame
    /// (seed 1, eqs. 4–8), with the configured [`IncrementNoise`].
    ///
    /// Touches only the robot mean, `P_RR` and `P_RM`. Non-finite input →
    /// [`EkfError::NonFiniteInput`], state unchanged.
    pub fn predict_increment(&mut self, increment: &OdometryIncrement<T>) -> Result<(), EkfError> {
        if !increment.is_finite() {
            return self.reject(EkfError::NonFiniteInput);
        }
        let step = compose_increment(&self.pose(), increment);
        let q = self.config.increment_noise.covariance(increment);
        let q = step.wrt_input * q * step.wrt_input.transpose();
        self.apply_motion(&step, &q)
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
        let step = integrate_velocity(&self.pose(), v, omega, dt);
        let q = self.config.velocity_noise.covariance(v, omega, dt);
        let q = step.wrt_input * q * step.wrt_input.transpose();
        self.apply_motion(&step, &q)
    }

    /// `P_RR ← A P_RR Aᵀ + W Q Wᵀ`, `P_RM ← A P_RM`, mean ← new pose.
    fn apply_motion<const U: usize>(
        &mut self,
        step: &MotionStep<T, U>,
        q: &Matrix3<T>,
    ) -> Result<(), EkfError> {
        let a = &step.wrt_pose;
        let p_rr: Matrix3<T> = block(&self.covariance, 0, 0);
        let new_rr = a * p_rr * a.transpose() + q;
        // |P_RM| ≤ max variance (P is PSD), so A P_RM is bounded by 3 · max|A| · max variance.
        let cross_bound = T::lit(3.0) * max_abs(a.iter().copied()) * self.max_variance();
        let far = T::lit(MAX_COORDINATE);
        let inside = step.pose.x.abs() <= far && step.pose.y.abs() <= far;
        // A negative variance can only come from a `P` that is no longer positive
        // semi-definite (the optimal-gain form allows that): refused like such updates.
        let negative = (0..3).any(|i| new_rr[(i, i)] < T::ZERO);
        if !inside
            || negative
            || !step.pose.is_finite()
            || !new_rr.iter().all(|v| v.finite())
            || !cross_bound.finite()
        {
            return self.reject(EkfError::NumericalFailure);
        }
        // Last-resort variance caps (see the module docs): scale the robot's rows and
        // columns by D = diag(s) — a congruence, so P stays positive semi-definite.
        let caps = [
            T::lit(MAX_POSITION_VARIANCE),
            T::lit(MAX_POSITION_VARIANCE),
            T::lit(MAX_HEADING_VARIANCE),
        ];
        let mut scale = [T::ONE; 3];
        for (i, (s, cap)) in scale.iter_mut().zip(caps).enumerate() {
            if new_rr[(i, i)] > cap {
                *s = (cap / new_rr[(i, i)]).sqrt();
            }
        }
        let d = Matrix3::from_diagonal(&nalgebra::Vector3::new(scale[0], scale[1], scale[2]));
        let mut new_rr = d * new_rr * d;
        symmetrise3(&mut new_rr);
        let a = d * a;
        set_diagonal_block(&mut self.covariance, 0, &new_rr);
        // P_RM ← A P_RM: rows 0..3 of every landmark column (all above the diagonal).
        let k = self.active_dim();
        for j in 3..k {
            let col = self.covariance.fixed_view::<3, 1>(0, j).into_owned();
            let new = a * col;
            self.covariance.fixed_view_mut::<3, 1>(0, j).copy_from(&new);
        }
        self.mean[0] = step.pose.x;
        self.mean[1] = step.pose.y;
        self.mean[2] = step.pose.theta;
        self.counters.predictions = self.counters.predictions.saturating_add(1);
        Ok(())
    }

    /// The innovation of sighting `z` (covariance `r`) against landmark `index`, without
    /// changing anything, and the measurement covariance it used: `r` itself, or for the
    /// Joseph form `r` with its variances raised to the rounding level of `H P Hᵀ`
    /// ([`rounding_floor`]).
    fn innovation_with(
        &self,
        index: usize,
        z: &RangeBearing<T>,
        r: &Matrix2<T>,
    ) -> Result<(Innovation<T>, Matrix2<T>), EkfError> {
        if index >= self.landmark_count() {
            return Err(EkfError::UnknownLandmark);
        }
        let li = 3 + 2 * index;
        let landmark = self.mean.fixed_rows::<2>(li).into_owned();
        let pred = self
            .config
            .sensor
            .predict(&self.pose(), &landmark)
            .ok_or(EkfError::LandmarkOnSensor)?;
        let (hr, hl) = (pred.wrt_robot, pred.wrt_landmark);
        // S = H P Hᵀ + R, from the robot and landmark blocks only.
        let p_rr: Matrix3<T> = block(&self.covariance, 0, 0);
        let p_rl = self.covariance.fixed_view::<3, 2>(0, li); // above the diagonal: li ≥ 3
        let p_ll: Matrix2<T> = block(&self.covariance, li, li);
        let r = match self.config.covariance_update {
            CovarianceUpdate::Joseph => {
                rounding_floor(r, &hr, &hl, &p_rr, &p_rl.into_owned(), &p_ll)
            }
            CovarianceUpdate::Symmetric => *r,
        };
        let hphr = hr * p_rl * hl.transpose();
        let mut s =
            hr * p_rr * hr.transpose() + hphr + hphr.transpose() + hl * p_ll * hl.transpose() + r;
        let off = (s[(0, 1)] + s[(1, 0)]) * T::lit(0.5);
        s[(0, 1)] = off;
        s[(1, 0)] = off;
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
        let inn = Innovation {
            nu,
            s,
            s_inv,
            mahalanobis_squared: d2,
            jacobian_robot: hr,
            jacobian_landmark: hl,
        };
        Ok((inn, r))
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

    /// The innovation of sighting `z` against landmark `index` (for data association),
    /// with the configured measurement noise, without changing the state.
    pub fn innovation(&self, index: usize, z: &RangeBearing<T>) -> Result<Innovation<T>, EkfError> {
        let r = self.checked_measurement(z, None)?;
        self.innovation_with(index, z, &r).map(|(inn, _)| inn)
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
        let (inn, r) = match self.innovation_with(index, z, &r) {
            Ok(found) => found,
            Err(e) => return self.reject(e),
        };
        let nis = inn.mahalanobis_squared;
        if !self.config.gate.accepts(nis) {
            self.counters.gated = self.counters.gated.saturating_add(1);
            return Ok(UpdateOutcome::Gated { nis });
        }
        let k = self.active_dim();
        let li = 3 + 2 * index;
        let mut storage = [UpdateRow {
            m: [T::ZERO; 2],
            k: [T::ZERO; 2],
            a: [T::ZERO; 2],
        }; N];
        let rows = storage.get_mut(..k).unwrap_or(&mut []);
        self.cross_covariance(li, &inn, rows);
        let form = self.config.covariance_update;
        // One monomorphised pass per form (a function pointer would cost a call per entry).
        match form {
            CovarianceUpdate::Joseph => {
                // The size of each row's rounding in the covariance pass (Joseph only).
                let mut scales = [T::ZERO; N];
                let scales = scales.get_mut(..k).unwrap_or(&mut []);
                if let Err(e) = self.gain_and_terms(li, &inn, &r, rows, form, scales) {
                    return self.reject(e);
                }
                self.correct_mean(rows, &inn.nu);
                update_upper(&mut self.covariance, rows, joseph_entry);
                let loading = T::lit(JOSEPH_LOADING * k as f64) * T::default_epsilon();
                load_diagonal(&mut self.covariance, scales, loading);
            }
            CovarianceUpdate::Symmetric => {
                if let Err(e) = self.gain_and_terms(li, &inn, &r, rows, form, &mut []) {
                    return self.reject(e);
                }
                self.correct_mean(rows, &inn.nu);
                update_upper(&mut self.covariance, rows, symmetric_entry)
            }
        }
        self.counters.updates = self.counters.updates.saturating_add(1);
        Ok(UpdateOutcome::Accepted { nis })
    }

    /// `x ← x + K ν`, heading wrapped.
    #[inline(always)]
    fn correct_mean(&mut self, rows: &[UpdateRow<T>], nu: &Vector2<T>) {
        for (x, row) in self.mean.as_mut_slice().iter_mut().zip(rows.iter()) {
            *x += row.k[0] * nu[0] + row.k[1] * nu[1];
        }
        self.mean[2] = wrap_near(self.mean[2]);
    }

    /// Fills the gain `K = M S⁻¹` and the form's terms (`K S`, or the Joseph form's `D`)
    /// of every row, and refuses (before anything is written) an update that would not
    /// stay finite or would leave a negative variance.
    fn gain_and_terms(
        &self,
        li: usize,
        inn: &Innovation<T>,
        r: &Matrix2<T>,
        rows: &mut [UpdateRow<T>],
        form: CovarianceUpdate,
        scales: &mut [T],
    ) -> Result<(), EkfError> {
        let s = inn.s;
        match form {
            CovarianceUpdate::Joseph => {
                // A Hᵀ reads M at the five columns where H is nonzero.
                let (hr, hl) = (&inn.jacobian_robot, &inn.jacobian_landmark);
                let h = [
                    [hr[(0, 0)], hr[(0, 1)], hr[(0, 2)], hl[(0, 0)], hl[(0, 1)]],
                    [hr[(1, 0)], hr[(1, 1)], hr[(1, 2)], hl[(1, 0)], hl[(1, 1)]],
                ];
                let m_at =
                    [0, 1, 2, li, li + 1].map(|c| rows.get(c).map_or([T::ZERO; 2], |row| row.m));
                let data = self.covariance.as_slice();
                let mut scales = scales.iter_mut();
                let terms = |i: usize, [k0, k1]: [T; 2]| {
                    let (robot, landmark) = self.observed_entries(i, li);
                    let p_at = [robot[0], robot[1], robot[2], landmark[0], landmark[1]];
                    let (mut b0, mut b1) = (T::ZERO, T::ZERO);
                    // |P| |H|ᵀ on this row: the size of the terms that cancel in M and A.
                    let (mut u0, mut u1) = (T::ZERO, T::ZERO);
                    for (c, (&p, mc)) in p_at.iter().zip(&m_at).enumerate() {
                        let a = p - (k0 * mc[0] + k1 * mc[1]);
                        b0 += a * h[0][c];
                        b1 += a * h[1][c];
                        u0 += p.abs() * h[0][c].abs();
                        u1 += p.abs() * h[1][c].abs();
                    }
                    // Row i's loading scale (see `JOSEPH_LOADING`): terms beyond 16 Pᵢᵢ.
                    if let Some(scale) = scales.next() {
                        let p_ii = data.get(i * (N + 1)).copied().unwrap_or(T::ZERO);
                        let terms = k0.abs() * u0 + k1.abs() * u1;
                        let excess = terms - T::lit(CANCELLATION_RATIO) * p_ii;
                        *scale = if excess > T::ZERO { excess } else { T::ZERO };
                    }
                    [
                        k0 * r[(0, 0)] + k1 * r[(1, 0)] - b0,
                        k0 * r[(0, 1)] + k1 * r[(1, 1)] - b1,
                    ]
                };
                self.checked_terms(inn, r, rows, terms, joseph_entry)
            }
            CovarianceUpdate::Symmetric => {
                let terms = |_: usize, [k0, k1]: [T; 2]| {
                    [
                        k0 * s[(0, 0)] + k1 * s[(1, 0)],
                        k0 * s[(0, 1)] + k1 * s[(1, 1)],
                    ]
                };
                self.checked_terms(inn, r, rows, terms, symmetric_entry)
            }
        }
    }

    /// The pass behind [`EkfSlam::gain_and_terms`] for one form: `terms(i, K_i)` gives row
    /// `i`'s form terms and `new_entry` the form's covariance entry.
    ///
    /// Every new variance is computed here exactly as the covariance pass will compute it
    /// (`f32` cancellation after absurd inputs can make one negative). The off-diagonal
    /// entries are bounded instead: with `D = K R − A Hᵀ` bounded by
    /// `2|K|(|R| + |S|) + |M|`, every new entry is at most
    /// `max var + 2|K|·(|M| + |K|(|R| + |S|))` in size, with `|·|` entrywise maxima — here
    /// over-estimated by sums over the rows (the trace for the largest variance), which is
    /// cheaper and still finite whenever the update is sane.
    #[inline(always)]
    fn checked_terms(
        &self,
        inn: &Innovation<T>,
        r: &Matrix2<T>,
        rows: &mut [UpdateRow<T>],
        mut terms: impl FnMut(usize, [T; 2]) -> [T; 2],
        new_entry: impl Fn(T, &UpdateRow<T>, &UpdateRow<T>) -> T,
    ) -> Result<(), EkfError> {
        let (si, nu) = (inn.s_inv, inn.nu);
        let data = self.covariance.as_slice();
        let (mut gsum, mut msum, mut trace, mut poison) = (T::ZERO, T::ZERO, T::ZERO, T::ZERO);
        let means = self.mean.as_slice();
        for (i, (row, &mean)) in rows.iter_mut().zip(means).enumerate() {
            let [m0, m1] = row.m;
            let k = [
                m0 * si[(0, 0)] + m1 * si[(1, 0)],
                m0 * si[(0, 1)] + m1 * si[(1, 1)],
            ];
            row.k = k;
            row.a = terms(i, k);
            let p_ii = data.get(i * (N + 1)).copied().unwrap_or(T::ZERO);
            let new = new_entry(p_ii, row, row);
            if new < T::ZERO {
                return Err(EkfError::NumericalFailure);
            }
            trace += p_ii;
            gsum += k[0].abs() + k[1].abs();
            msum += m0.abs() + m1.abs();
            // `x · 0` is 0 for a finite x and NaN otherwise (NaN variances included), so
            // `poison` stays 0 only while everything is finite (a non-finite M makes K
            // non-finite too; a sum of finite values that overflows is refused as well).
            let moved = mean + (k[0] * nu[0] + k[1] * nu[1]);
            poison += (new + moved + k[0] + k[1]) * T::ZERO;
        }
        let sr = max_abs(inn.s.iter().chain(r.iter()).copied());
        let bound = trace + T::lit(16.0) * gsum * (msum + gsum * sr);
        if poison != T::ZERO || !bound.finite() {
            return Err(EkfError::NumericalFailure);
        }
        Ok(())
    }

    /// Row `i`'s entries in the columns where `H` is nonzero: the robot's (0..3) and the
    /// landmark's (`li`, `li + 1`), read straight from the stored triangle: for `i ≥ 3`
    /// the robot entries are rows 0..3 of column `i`; the landmark entries are row `i` of
    /// columns `li`, `li + 1` above the landmark and rows `li`, `li + 1` of column `i`
    /// below it.
    #[inline(always)]
    fn observed_entries(&self, i: usize, li: usize) -> ([T; 3], [T; 2]) {
        let data = self.covariance.as_slice();
        let at = |n: usize| data.get(n).copied().unwrap_or(T::ZERO);
        let robot = if i >= 3 {
            [at(i * N), at(i * N + 1), at(i * N + 2)]
        } else {
            [0, 1, 2].map(|c| entry(&self.covariance, i, c))
        };
        let landmark = if i < li {
            [at(li * N + i), at((li + 1) * N + i)]
        } else if i >= li + 2 {
            [at(i * N + li), at(i * N + li + 1)]
        } else {
            [
                entry(&self.covariance, i, li),
                entry(&self.covariance, i, li + 1),
            ]
        };
        (robot, landmark)
    }

    /// Fills `m` of each row `i` with row `i` of `M = P Hᵀ`, where `H` is nonzero only on
    /// the robot's columns (`∂h/∂robot`) and the landmark's columns `li`, `li + 1`.
    ///
    /// Row by row from the stored triangle: rows 3.. take the robot entries from rows 0..3
    /// of their own column; rows above the landmark take the landmark entries from row `i`
    /// of columns `li`, `li + 1`, rows below it from rows `li`, `li + 1` of their own
    /// column. The five rows of the robot and the landmark go through [`entry`].
    fn cross_covariance(&self, li: usize, inn: &Innovation<T>, rows: &mut [UpdateRow<T>]) {
        let (hr, hl) = (&inn.jacobian_robot, &inn.jacobian_landmark);
        let m = |robot: [T; 3], landmark: [T; 2]| -> [T; 2] {
            [0, 1].map(|r| {
                robot[0] * hr[(r, 0)]
                    + robot[1] * hr[(r, 1)]
                    + robot[2] * hr[(r, 2)]
                    + landmark[0] * hl[(r, 0)]
                    + landmark[1] * hl[(r, 1)]
            })
        };
        let data = self.covariance.as_slice();
        let (lm0, lm1) = (data.get(li * N..), data.get((li + 1) * N..));
        let (Some(lm0), Some(lm1)) = (lm0, lm1) else {
            return;
        };
        let columns = data.chunks_exact(N);
        for (i, (row, column)) in rows.iter_mut().zip(columns).enumerate() {
            let robot = match column {
                [a, b, c, ..] if i >= 3 => [*a, *b, *c],
                _ => [0, 1, 2].map(|c| entry(&self.covariance, i, c)),
            };
            let landmark = if i < li {
                [lm0.get(i), lm1.get(i)].map(|v| v.copied().unwrap_or(T::ZERO))
            } else if i >= li + 2 {
                [column.get(li), column.get(li + 1)].map(|v| v.copied().unwrap_or(T::ZERO))
            } else {
                [
                    entry(&self.covariance, i, li),
                    entry(&self.covariance, i, li + 1),
                ]
            };
            row.m = m(robot, landmark);
        }
    }

    /// Adds a landmark seen at `z`, with the configured measurement noise. See
    /// [`EkfSlam::add_landmark_with_covariance`].
    pub fn add_landmark(&mut self, z: &RangeBearing<T>) -> Result<usize, EkfError> {
        self.add_inner(z, None)
    }

    /// Adds a landmark seen at `z` with measurement covariance `r`, by the inverse
    /// observation model `g` (seed 1, eqs. 20–24): mean `g(x_R, z)`,
    /// `P_pp = G_R P_RR G_Rᵀ + G_z R G_zᵀ`, `P_pX = G_R [P_RR P_RM]`. Returns its index.
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
        if self.landmark_count() >= Self::MAX_LANDMARKS {
            return self.reject(EkfError::MapFull);
        }
        let g = self.config.sensor.landmark_from(&self.pose(), z);
        let k = self.active_dim();
        let p_rr: Matrix3<T> = block(&self.covariance, 0, 0);
        let p_pp = g.wrt_robot * p_rr * g.wrt_robot.transpose()
            + g.wrt_measurement * r * g.wrt_measurement.transpose();
        // Last-resort cap, as for the robot: scale the new rows and columns (a congruence).
        let cap = T::lit(MAX_POSITION_VARIANCE);
        let scale = Vector2::new(
            if p_pp[(0, 0)] > cap {
                (cap / p_pp[(0, 0)]).sqrt()
            } else {
                T::ONE
            },
            if p_pp[(1, 1)] > cap {
                (cap / p_pp[(1, 1)]).sqrt()
            } else {
                T::ONE
            },
        );
        let d = Matrix2::from_diagonal(&scale);
        let mut p_pp = d * p_pp * d;
        let off = (p_pp[(0, 1)] + p_pp[(1, 0)]) * T::lit(0.5);
        p_pp[(0, 1)] = off;
        p_pp[(1, 0)] = off;
        let g_robot = d * g.wrt_robot;
        let cross_bound = T::lit(3.0) * max_abs(g_robot.iter().copied()) * self.max_variance();
        let far = T::lit(MAX_COORDINATE);
        let inside = g.landmark.iter().all(|c| c.abs() <= far);
        // As in a prediction: negative only when `P_RR` is no longer PSD; refused.
        let negative = p_pp[(0, 0)] < T::ZERO || p_pp[(1, 1)] < T::ZERO;
        if !inside
            || negative
            || !g.landmark.iter().chain(p_pp.iter()).all(|v| v.finite())
            || !cross_bound.finite()
        {
            return self.reject(EkfError::NumericalFailure);
        }
        // P_Xp = (G_R P[0..3, 0..k])ᵀ: rows 0..k of the two new columns (above the diagonal).
        for j in 0..k {
            let col: nalgebra::Vector3<T> = block(&self.covariance, 0, j);
            let v = g_robot * col;
            self.covariance
                .fixed_view_mut::<1, 2>(j, k)
                .copy_from(&v.transpose());
        }
        set_diagonal_block(&mut self.covariance, k, &p_pp);
        self.mean.fixed_rows_mut::<2>(k).copy_from(&g.landmark);
        let index = self.landmark_count();
        self.landmarks += 1;
        Ok(index)
    }
}

/// The largest absolute value (NaN propagates as NaN, an empty sequence gives 0).
fn max_abs<T: Real>(values: impl Iterator<Item = T>) -> T {
    values.fold(T::ZERO, |acc, v| {
        let a = v.abs();
        if a > acc || !a.finite() { a } else { acc }
    })
}

/// The measurement covariance of a Joseph update: `r` with each variance raised, where it
/// is smaller, to `ROUNDING_FLOOR · ε · (|H| |P| |H|ᵀ)ᵢᵢ`, the rounding level of
/// `(H P Hᵀ)ᵢᵢ` computed in `T` from the robot and landmark blocks of `P`.
fn rounding_floor<T: Real>(
    r: &Matrix2<T>,
    hr: &Matrix2x3<T>,
    hl: &Matrix2<T>,
    p_rr: &Matrix3<T>,
    p_rl: &SMatrix<T, 3, 2>,
    p_ll: &Matrix2<T>,
) -> Matrix2<T> {
    let abs = |v: T| v.abs();
    let (hr, hl) = (hr.map(abs), hl.map(abs));
    let cross = hr * p_rl.map(abs) * hl.transpose();
    let scale = hr * p_rr.map(abs) * hr.transpose()
        + cross
        + cross.transpose()
        + hl * p_ll.map(abs) * hl.transpose();
    let unit = T::lit(ROUNDING_FLOOR) * T::default_epsilon();
    let mut r = *r;
    for i in 0..2 {
        let floor = unit * scale[(i, i)];
        if floor > r[(i, i)] {
            r[(i, i)] = floor;
        }
    }
    r
}

/// `x > 0`, false for NaN.
fn is_positive<T: Real>(x: T) -> bool {
    x > T::ZERO
}

fn symmetrise3<T: Real>(m: &mut Matrix3<T>) {
    for i in 0..3 {
        for j in 0..i {
            let v = (m[(i, j)] + m[(j, i)]) * T::lit(0.5);
            m[(i, j)] = v;
            m[(j, i)] = v;
        }
    }
}
