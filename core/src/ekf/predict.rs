//! Prediction: an odometry increment or velocities move the robot mean, and
//! `P' = F P Fᵀ + G Q Gᵀ` is written to the robot's rows of the factor (its own block
//! re-factored by a modified weighted Gram–Schmidt, its coupling rows deferred); the same
//! for an inflation of the pose covariance. The robot's variances are capped here
//! ([`MAX_POSITION_VARIANCE`], [`MAX_HEADING_VARIANCE`]).

use super::calibration::SCALE_SLOT;
use super::covariance::{ldl, ldl_product, mwgs};
use super::deferred::product;
use super::{
    EkfSlam, MAX_COORDINATE, MAX_HEADING_VARIANCE, MAX_POSITION_VARIANCE, all_finite, capped,
};
use crate::error::EkfError;
use crate::motion::{MotionStep, OdometryIncrement, compose_increment, integrate_velocity};
use crate::scalar::Real;
use nalgebra::Matrix3;

impl<T: Real, const N: usize, const P: usize> EkfSlam<T, N, P> {
    /// Prediction with an odometry increment `(dx, dy, dθ)` in the previous robot frame
    /// (El Masri El Chaarani et al. n.d., eqs. 4–8), with the configured
    /// [`IncrementNoise`](crate::motion::IncrementNoise).
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

    /// Prediction with velocities `(v, ω)` held for `dt` seconds (Du n.d., eq. 6), with the
    /// configured [`VelocityNoise`](crate::motion::VelocityNoise).
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
    /// `F = I` and noise `added`, as cheap as one (O(1), O(n) for the first after another
    /// step). For recovery logic that declares the robot lost. The robot's variances stay
    /// within [`MAX_POSITION_VARIANCE`] and [`MAX_HEADING_VARIANCE`] as after any
    /// prediction.
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
    pub(super) fn apply_motion<const U: usize>(
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
    /// the robot's coupling rows `L_rm ← S F L_rm` (deferred: [`super::deferred`]), and its own
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
}
