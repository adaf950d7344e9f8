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
//! # Models
//!
//! The filter is the landmark EKF-SLAM of El Masri El Chaarani et al. (n.d.): the robot
//! moves by an odometry increment composed with its pose (their eqs. 4–8) or by
//! velocities held for a time step (Du n.d., eq. 6), and a new landmark is placed by the
//! inverse observation model (their eqs. 20–24). A sighting is predicted in the form it is
//! measured, range and bearing from the sensor (their eq. 12 predicts Cartesian
//! coordinates instead). All noise is configured ([`EkfConfig`]): the odometry's grows
//! with the motion, a sighting's is its own covariance or the configured one.
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
//! # Why `P` stays positive semi-definite
//!
//! `P = L D Lᵀ` is positive semi-definite for *any* `L` as long as `D ≥ 0`, and every
//! step computes the new `D` in a way that cannot be negative, rounding included:
//! - a prediction `P' = F P Fᵀ + G Q Gᵀ` leaves the landmark rows alone, multiplies the
//!   robot's coupling to the landmarks by `F`, and re-factors the robot's own block
//!   `[F L_rr | G] diag(D_r, Q) [F L_rr | G]ᵀ` by a modified weighted Gram–Schmidt
//!   (Thornton and Bierman 1977): each new pivot is a sum of weighted squares;
//! - a new landmark `l = g(robot, z)` gets the rows `G_r L_rm` and, together with the
//!   robot, a 5 × 5 block re-factored the same way from `[[G_r L_rr, G_z L_R], [L_rr, 0]]`
//!   with weights `diag(D_r, D_R)` (`R = L_R D_R L_Rᵀ`);
//! - an update is processed as two scalar measurements (range, then bearing, both
//!   linearised at the prior; a correlated `R` is decorrelated first). Bierman's (1977)
//!   scalar update sets `Dⱼ' = Dⱼ αⱼ₋₁ / αⱼ` with `α` a running sum of `r` and
//!   non-negative terms `Dⱼ fⱼ²`: a product and quotient of non-negative numbers.
//!
//! There is no diagonal loading and no symmetrisation. The variances are capped, but not
//! for definiteness: without the caps a sighting could move a lost robot or landmark by
//! thousands of kilometres and `f32` variances could overflow (see
//! [`MAX_POSITION_VARIANCE`]). A prediction, or [`EkfSlam::inflate_pose_covariance`], that
//! would leave the robot's x or y variance above [`MAX_POSITION_VARIANCE`] or its heading
//! variance above [`MAX_HEADING_VARIANCE`] is made again with the robot's rows scaled by
//! `S = diag(s_x, s_y, s_θ)`, `s = √(cap / v)` for a variance `v` above its cap and 1 for
//! the others; a new landmark whose x or y variance, `G_r P_RR G_rᵀ + G_z R G_zᵀ`, would
//! exceed [`MAX_POSITION_VARIANCE`] has its rows scaled the same way. The covariance is
//! then `S P' Sᵀ` for the `P'` the step would have given: the capped variances come down
//! to their cap, every correlation coefficient stays, and the scaled Jacobians go through
//! the same steps as above, so `D ≥ 0` holds as before. Each scalar update treats the sighting as no more precise than `ε · H P Hᵀ`
//! (`ε` the machine epsilon), which keeps its gain finite; it is not needed for `D ≥ 0`.
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
//!
//! # References
//!
//! - El Masri El Chaarani, A., Ashraf, J., and Abu Hara, R. (n.d.). *EKF-SLAM with
//!   Traffic sign images*. Undated report. The filter: its state, the prediction by an
//!   odometry increment (eqs. 4–8), the inverse observation model (eqs. 20–24).
//! - Du, C. (n.d.). *ECE 276 Project: Particle Filter SLAM*. Undated report, University of
//!   California, San Diego. The prediction by velocities (eq. 6).
//! - Bierman, G. J. (1977). *Factorization Methods for Discrete Sequential Estimation*.
//!   Academic Press. The scalar measurement update of a `U D Uᵀ` factorisation, applied
//!   here to `L D Lᵀ`.
//! - Thornton, C. L., and Bierman, G. J. (1977). Gram–Schmidt algorithms for covariance
//!   propagation. *International Journal of Control* 25(2), 243–260. The modified
//!   weighted Gram–Schmidt that re-factors the robot's block after a prediction and the
//!   block of a new landmark.

use crate::error::EkfError;
use crate::geometry::{Pose2, wrap_angle};
use crate::scalar::Real;
use covariance::row_start;
use deferred::DeferredMotion;
use nalgebra::{ArrayStorage, SVector};

// One concern a file; the filter's steps are `impl EkfSlam` blocks spread over them.
mod ackermann; // prediction of a car: speed and steering through the bicycle model
mod bierman; // the kernels of Bierman's scalar update
mod calibration; // calibration slots: odometry scale factors, range bias
mod config; // `EkfConfig`: noise, sensor mount, gate
pub mod covariance; // the packed factor `P = L D Lᵀ` and its readers
mod deferred; // a run of predictions, deferred on the robot's coupling rows
mod estimate; // reading the estimate: pose, landmarks, mean, covariance
pub mod health; // the update supervisor
mod landmark; // a new landmark, by the inverse observation model
mod measurement; // a sighting against a landmark: checks, measurement rows, innovation
mod outcome; // what the filter reports: update outcome, counters, innovation
mod predict; // prediction: increments, velocities, pose covariance inflation
mod robot_rows; // the robot's rows of the factor: its own block, the deferred predictions
mod update; // the update: planned in O(n), applied in one O(n²) pass

pub use config::EkfConfig;
pub use covariance::{CovarianceView, factor_len};
pub use outcome::{EkfCounters, Innovation, UpdateOutcome};

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
pub const MAX_COORDINATE: f64 = crate::geometry::MAX_COORDINATE_M;

/// Bytes an `f32` filter uses beyond its mean and covariance factor (configuration,
/// counters, the deferred predictions).
pub const EKF_OVERHEAD_BYTES_F32: usize = 280;

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
    /// Which calibration slots come before the landmarks, as bits:
    /// [`SCALE_SLOT`](calibration::SCALE_SLOT) (the odometry scale factors, then slot 0)
    /// and [`BIAS_SLOT`](calibration::BIAS_SLOT) (the range bias, after them).
    calibration: u16,
    config: EkfConfig<T>,
    counters: EkfCounters,
    /// The predictions since the last write of the factor whose effect on the robot's
    /// coupling rows is not applied yet ([`deferred`]): the true rows are
    /// `A · stored + B`. Every write of the factor but a prediction's goes through
    /// [`EkfSlam::factor_mut`], which applies and clears it; readers apply it on the fly.
    deferred: Option<DeferredMotion<T>>,
}

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

    fn reject<R>(&mut self, e: EkfError) -> Result<R, EkfError> {
        crate::log::debug!("ekf: step refused: {}", e);
        self.counters.rejected = self.counters.rejected.saturating_add(1);
        Err(e)
    }
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

#[cfg(test)]
mod tests;
