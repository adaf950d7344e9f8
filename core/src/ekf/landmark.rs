//! A new landmark, placed by the inverse observation model from the robot pose and a
//! sighting: its mean, and its two rows of the factor inserted before the robot's, which
//! move two rows down. Its x and y variances are capped at [`MAX_POSITION_VARIANCE`].

use super::covariance::{mwgs, row_start};
use super::{EkfSlam, MAX_COORDINATE, MAX_POSITION_VARIANCE, all_finite, capped, max_abs};
use crate::error::EkfError;
use crate::scalar::Real;
use crate::sensors::range_bearing::RangeBearing;
use nalgebra::{Matrix2, Matrix3};

impl<T: Real, const N: usize, const P: usize> EkfSlam<T, N, P> {
    /// Adds a landmark seen at `z`, with the configured measurement noise. See
    /// [`EkfSlam::add_landmark_with_covariance`].
    pub fn add_landmark(&mut self, z: &RangeBearing<T>) -> Result<usize, EkfError> {
        self.add_inner(z, None)
    }

    /// Adds a landmark seen at `z` with measurement covariance `r`, by the inverse
    /// observation model `g` (El Masri El Chaarani et al. n.d., eqs. 20–24): mean
    /// `g(x_R, z)`, covariance `P_pp = G_R P_RR G_Rᵀ + G_z R G_zᵀ`,
    /// `P_pX = G_R [P_RR P_RM]`, kept factorised: the landmark's rows `G_R L_rm`, and the
    /// 5 × 5 block of the landmark and the robot re-factored from
    /// `[[G_R L_rr, G_z L_R], [L_rr, 0]]` with weights `(D_r, D_R)`. Returns its index.
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
