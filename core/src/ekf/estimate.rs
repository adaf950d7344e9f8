//! Reading the estimate: the robot pose and its covariance, the landmarks and theirs, the
//! active mean and covariance, the sizes and state indices, and the raw storage for tests and
//! diagnostics. Nothing here writes: a reader that meets deferred predictions applies them
//! on the fly.

use super::EkfSlam;
use super::covariance::{CovarianceView, internal_entry};
use crate::geometry::Pose2;
use crate::scalar::Real;
use nalgebra::{Matrix2, Matrix3, SVector, Vector2};

impl<T: Real, const N: usize, const P: usize> EkfSlam<T, N, P> {
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
    /// `k (k + 1) / 2` scalars hold the active factor ([`covariance`](super::covariance)),
    /// the rest is zero.
    /// After predictions the robot's coupling rows are stored as they were before them
    /// (the predictions are applied at the next update or new landmark); read the factor
    /// through [`EkfSlam::active_covariance`].
    pub fn factor_storage(&self) -> &[T; P] {
        &self.factor
    }
}
