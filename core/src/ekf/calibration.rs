//! Calibration slots: systematic sensor errors estimated as states, the odometry's speed
//! and turn-rate scale factors and the sightings' range bias. Each takes one two-state slot
//! before the landmarks (in the mean after the pose, in the factor first); the slot bits
//! and the indices of slots, landmarks and states are here.

use super::EkfSlam;
use super::covariance::{row_start, strict_row};
use crate::error::EkfError;
use crate::scalar::Real;

/// Bit of the odometry scale factors' calibration slot.
pub(super) const SCALE_SLOT: u16 = 1;
/// Bit of the range bias' calibration slot.
pub(super) const BIAS_SLOT: u16 = 2;
/// Calibration slots there can be (odometry scale, range bias).
pub(super) const MAX_CALIBRATION_SLOTS: usize = 2;

impl<T: Real, const N: usize, const P: usize> EkfSlam<T, N, P> {
    /// Number of calibration slots before the landmarks.
    pub(super) fn calibration_slots(&self) -> usize {
        self.calibration.count_ones() as usize
    }

    /// Index of landmark `index` inside the factor (see [`super::covariance`]).
    pub(super) fn landmark_slot(&self, index: usize) -> usize {
        index + self.calibration_slots()
    }

    /// The slot of the range bias, when it is estimated.
    pub(super) fn bias_slot(&self) -> Option<usize> {
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

    /// The range bias' first factor index `bi` and its two rows of `L` (unit diagonal
    /// included) over columns `0..=bi + 1`, when the bias is estimated.
    pub(super) fn bias_rows(&self) -> Option<(usize, [[T; 2 * MAX_CALIBRATION_SLOTS]; 2])> {
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
}
