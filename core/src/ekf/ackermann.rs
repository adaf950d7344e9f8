//! Prediction of a car: speed and steering angle through the bicycle model
//! ([`Ackermann`]), with its own noise.

use super::EkfSlam;
use crate::error::EkfError;
use crate::motion::Ackermann;
use crate::scalar::Real;

impl<T: Real, const N: usize, const P: usize> EkfSlam<T, N, P> {
    /// Prediction of a car whose rear-axle centre is the robot frame: speed `v` (m/s) and
    /// front steering angle `steering` (rad, counter-clockwise) held for `dt` seconds,
    /// through `car`'s bicycle model and with its [`AckermannNoise`](crate::motion::AckermannNoise)
    /// (see [`crate::motion::ackermann`]). The sensor's offset ahead of the rear axle is
    /// the configured sensor mount ([`EkfConfig::sensor`](super::EkfConfig::sensor)).
    ///
    /// With the odometry scale factors estimated ([`EkfSlam::estimate_odometry_scale`])
    /// the car moves with `(s_v v, s_ω ω)`, `ω = v tan φ / L`, as a velocity prediction.
    /// Costs what [`EkfSlam::predict_velocity`] does.
    ///
    /// `dt = 0` is a no-op. Errors (state unchanged): [`EkfError::NegativeTimeStep`] for
    /// `dt < 0`; [`EkfError::NonFiniteInput`] for a non-finite input or a steering angle
    /// beyond `car.max_steering` (where `tan φ` runs away: a corrupt reading);
    /// [`EkfError::InvalidNoise`] when `car` is not valid
    /// ([`Ackermann::invalid_setting`]).
    ///
    /// ```
    /// use microslam::ekf::{factor_len, state_dim, EkfConfig, EkfSlam};
    /// use microslam::motion::{Ackermann, AckermannNoise};
    ///
    /// let car = Ackermann {
    ///     wheelbase: 2.5,
    ///     max_steering: 0.6,
    ///     noise: AckermannNoise { speed_std: 0.05, speed_std_per_mps: 0.02, steering_std: 0.01, steering_std_per_mps: 0.0 },
    /// };
    /// let mut slam = EkfSlam::<f32, { state_dim(8) }, { factor_len(8) }>::new(EkfConfig::DEFAULT_F32);
    /// slam.predict_ackermann(&car, 2.0, 0.0, 0.5)?;
    /// assert!((slam.pose().x - 1.0).abs() < 1e-6);
    /// assert!(slam.predict_ackermann(&car, 2.0, 0.9, 0.5).is_err());
    /// # Ok::<(), microslam::EkfError>(())
    /// ```
    pub fn predict_ackermann(
        &mut self,
        car: &Ackermann<T>,
        v: T,
        steering: T,
        dt: T,
    ) -> Result<(), EkfError> {
        if !(v.finite() && steering.finite() && dt.finite()) {
            return self.reject(EkfError::NonFiniteInput);
        }
        if !car.is_valid() {
            return self.reject(EkfError::InvalidNoise);
        }
        if dt < T::ZERO {
            return self.reject(EkfError::NegativeTimeStep);
        }
        if dt == T::ZERO {
            return Ok(());
        }
        let q = car.covariance(v, dt);
        let q = [q[(0, 0)], q[(1, 1)]];
        let Some((sv, sw)) = self.odometry_scale() else {
            let Some(step) = car.step(&self.pose(), v, steering, dt) else {
                return self.reject(EkfError::NonFiniteInput);
            };
            return self.apply_motion(&step, &q, None);
        };
        let Some((step, fs)) = car.scaled_step(&self.pose(), v, steering, dt, (sv, sw)) else {
            return self.reject(EkfError::NonFiniteInput);
        };
        let wrt_scale = [0, 1, 2].map(|a| [fs[(a, 0)], fs[(a, 1)]]);
        self.apply_motion(&step, &q, Some(&wrt_scale))
    }
}

#[cfg(test)]
mod tests {
    use super::super::{EkfConfig, factor_len, state_dim};
    use super::*;
    use crate::geometry::Pose2;
    use crate::motion::AckermannNoise;
    use crate::testing::central_difference;
    use nalgebra::{DVector, Matrix2};

    type Slam = EkfSlam<f64, { state_dim(4) }, { factor_len(4) }>;

    const CAR: Ackermann<f64> = Ackermann {
        wheelbase: 2.5,
        max_steering: 0.6,
        noise: AckermannNoise {
            speed_std: 0.1,
            speed_std_per_mps: 0.05,
            steering_std: 0.02,
            steering_std_per_mps: 0.0,
        },
    };

    /// From a known pose, one step's covariance is `G Q Gᵀ` with `G` by central
    /// differences of the model and `Q` written out from the documented noise model;
    /// the mean is where the geometry puts the rear axle.
    #[test]
    fn one_step_covariance_is_g_q_gt() {
        let mut slam = Slam::new(EkfConfig::DEFAULT_F64);
        let (v, phi, dt) = (3.0, 0.2, 0.4);
        slam.predict_ackermann(&CAR, v, phi, dt).unwrap();
        // The arc of radius R = L / tan φ about (0, R).
        let r = 2.5 / phi.tan();
        let turned = v * dt / r;
        let pose = slam.pose();
        assert!((pose.x - r * turned.sin()).abs() < 1e-12);
        assert!((pose.y - r * (1.0 - turned.cos())).abs() < 1e-12);
        assert!((pose.theta - turned).abs() < 1e-12);
        let f = |x: &DVector<f64>| {
            CAR.step(&Pose2::IDENTITY, x[0], x[1], dt)
                .unwrap()
                .pose
                .to_vector()
        };
        let g = central_difference(f, &DVector::from_row_slice(&[v, phi]), &[2]);
        let sv: f64 = 0.1 + 0.05 * v;
        let q = Matrix2::new(sv * sv / dt, 0.0, 0.0, 0.02f64.powi(2) / dt);
        let expected = &g * q * g.transpose();
        let p = slam.pose_covariance();
        for i in 0..3 {
            for j in 0..3 {
                let (a, e) = (p[(i, j)], expected[(i, j)]);
                assert!((a - e).abs() <= 1e-8 * (1.0 + e.abs()), "({i},{j}) {a} {e}");
            }
        }
    }

    #[test]
    fn bad_steps_are_refused_and_change_nothing() {
        let mut slam = Slam::new(EkfConfig::DEFAULT_F64);
        slam.predict_ackermann(&CAR, 1.0, 0.1, 0.5).unwrap();
        let before = (slam.pose(), slam.pose_covariance());
        for (v, phi, dt, e) in [
            (1.0, 0.7, 0.1, EkfError::NonFiniteInput),
            (f64::NAN, 0.1, 0.1, EkfError::NonFiniteInput),
            (1.0, 0.1, f64::INFINITY, EkfError::NonFiniteInput),
            (1.0, 0.1, -0.1, EkfError::NegativeTimeStep),
        ] {
            assert_eq!(slam.predict_ackermann(&CAR, v, phi, dt), Err(e));
        }
        let bad = Ackermann {
            wheelbase: -1.0,
            ..CAR
        };
        assert_eq!(
            slam.predict_ackermann(&bad, 1.0, 0.1, 0.1),
            Err(EkfError::InvalidNoise)
        );
        slam.predict_ackermann(&CAR, 1.0, 0.1, 0.0).unwrap();
        assert_eq!((slam.pose(), slam.pose_covariance()), before);
        assert_eq!(slam.counters().rejected, 5);
    }

    /// With the scale factors as states, the car moves with the scaled speed and turn
    /// rate: at their initial value 1 as without them; the pose couples to them.
    #[test]
    fn scale_factors_drive_the_car_as_velocities() {
        let mut plain = Slam::new(EkfConfig::DEFAULT_F64);
        let mut scaled = Slam::new(EkfConfig::DEFAULT_F64);
        scaled.estimate_odometry_scale(0.05, 0.05).unwrap();
        for _ in 0..5 {
            plain.predict_ackermann(&CAR, 2.0, 0.3, 0.2).unwrap();
            scaled.predict_ackermann(&CAR, 2.0, 0.3, 0.2).unwrap();
        }
        let (a, b) = (plain.pose(), scaled.pose());
        assert!((a.x - b.x).abs() < 1e-12 && (a.y - b.y).abs() < 1e-12);
        // The scale factors' uncertainty adds to the pose's.
        assert!(scaled.pose_covariance()[(2, 2)] > plain.pose_covariance()[(2, 2)]);
    }
}
