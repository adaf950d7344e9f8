//! Motion models of a planar robot, with the Jacobians the EKF needs.
//!
//! Two forms of odometry:
//! - an **increment** `u = (dx, dy, dθ)` measured in the previous robot frame (wheel
//!   odometry that reports poses; El Masri El Chaarani et al. n.d., eqs. 4–7):
//!   `x_k = x_{k−1} ⊕ u`;
//! - **velocities** `(v, ω)` held over `dt` (odometry that reports speeds, e.g. MRCLAM;
//!   Du n.d., eq. 6): the exact arc, written with `sinc` so that it stays exact for ω → 0:
//!
//! ```text
//! x' = x + v·dt·sinc(ω·dt/2)·cos(θ + ω·dt/2)
//! y' = y + v·dt·sinc(ω·dt/2)·sin(θ + ω·dt/2)
//! θ' = θ + ω·dt
//! ```
//!
//! The noise of each form is configuration ([`IncrementNoise`], [`VelocityNoise`]); nothing
//! here hard-codes a covariance.
//!
//! A car reports neither: its speed and steering angle drive the bicycle model of
//! [`Ackermann`] (module [`ackermann`]), which moves along the same exact arc.
//!
//! # References
//!
//! - El Masri El Chaarani, A., Ashraf, J., and Abu Hara, R. (n.d.). *EKF-SLAM with
//!   Traffic sign images*. Undated report. The increment form and its Jacobians `A` and
//!   `W`, eqs. 4–7.
//! - Du, C. (n.d.). *ECE 276 Project: Particle Filter SLAM*. Undated report, University of
//!   California, San Diego. The velocity form, eq. 6.

use crate::error::InvalidSetting;
use crate::geometry::{Pose2, wrap_near};
use crate::scalar::Real;
use nalgebra::{Matrix2, Matrix3, Matrix3x2};

pub mod ackermann;
pub use ackermann::{Ackermann, AckermannNoise};

/// A pose increment `(dx, dy, dθ)` expressed in the previous robot frame.
pub type OdometryIncrement<T> = Pose2<T>;

/// Result of a motion model: the new pose and the Jacobians of the model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotionStep<T: Real, const U: usize> {
    /// The predicted pose (heading wrapped).
    pub pose: Pose2<T>,
    /// ∂pose'/∂pose (`A` of El Masri El Chaarani et al. n.d., eq. 6).
    pub wrt_pose: Matrix3<T>,
    /// ∂pose'/∂input (`W` of El Masri El Chaarani et al. n.d., eq. 7), 3 × U.
    pub wrt_input: nalgebra::SMatrix<T, 3, U>,
}

/// Compounds `pose ⊕ increment` and returns the Jacobians with respect to the pose (A)
/// and to the increment (W). The pose and the Jacobians share one `sin`/`cos` of the
/// heading, in the scalar's own arithmetic ([`Real::sin_cos_native`]), and the heading is
/// wrapped without trigonometry ([`wrap_near`]), as in [`integrate_velocity`].
pub fn compose_increment<T: Real>(pose: &Pose2<T>, inc: &OdometryIncrement<T>) -> MotionStep<T, 3> {
    let (s, c) = pose.theta.sin_cos_native();
    let moved = pose.compose_unwrapped(inc, (s, c));
    let wrt_pose = Matrix3::new(
        T::ONE,
        T::ZERO,
        -s * inc.x - c * inc.y,
        T::ZERO,
        T::ONE,
        c * inc.x - s * inc.y,
        T::ZERO,
        T::ZERO,
        T::ONE,
    );
    let wrt_input = Matrix3::new(c, -s, T::ZERO, s, c, T::ZERO, T::ZERO, T::ZERO, T::ONE);
    MotionStep {
        pose: Pose2::new(moved.x, moved.y, wrap_near(moved.theta)),
        wrt_pose,
        wrt_input,
    }
}

/// `sin(h)/h` and its derivative, with Taylor series near zero.
fn sinc_and_derivative<T: Real>(h: T) -> (T, T) {
    if h.abs() < T::lit(1e-3) {
        let h2 = h * h;
        (
            T::ONE - h2 / T::lit(6.0) + h2 * h2 / T::lit(120.0),
            -h / T::lit(3.0) + h * h2 / T::lit(30.0),
        )
    } else {
        let (s, c) = h.sin_cos_native();
        (s / h, (h * c - s) / (h * h))
    }
}

/// Moves `pose` along the arc of constant `(v, ω)` for `dt` seconds (Du n.d., eq. 6) and
/// returns the Jacobians with respect to the pose and to the inputs `(v, ω)`.
pub fn integrate_velocity<T: Real>(pose: &Pose2<T>, v: T, omega: T, dt: T) -> MotionStep<T, 2> {
    let half = omega * dt / T::lit(2.0);
    let (sinc, dsinc) = sinc_and_derivative(half);
    let chord = v * dt * sinc;
    let phi = pose.theta + half;
    let (sp, cp) = phi.sin_cos_native();
    let dchord_dv = dt * sinc;
    let dchord_dw = v * dt * dsinc * dt / T::lit(2.0);
    let half_dt = dt / T::lit(2.0);
    let wrt_pose = Matrix3::new(
        T::ONE,
        T::ZERO,
        -chord * sp,
        T::ZERO,
        T::ONE,
        chord * cp,
        T::ZERO,
        T::ZERO,
        T::ONE,
    );
    let wrt_input = Matrix3x2::new(
        dchord_dv * cp,
        dchord_dw * cp - chord * sp * half_dt,
        dchord_dv * sp,
        dchord_dw * sp + chord * cp * half_dt,
        T::ZERO,
        dt,
    );
    MotionStep {
        pose: Pose2::new(
            pose.x + chord * cp,
            pose.y + chord * sp,
            wrap_near(pose.theta + omega * dt),
        ),
        wrt_pose,
        wrt_input,
    }
}

/// Noise of odometry increments: independent errors on `dx`, `dy` and `dθ` whose standard
/// deviations grow with the distance and the turn of the step.
///
/// σ_xy = `translation_std` + `translation_std_per_metre` · |(dx, dy)|,
/// σ_θ = `rotation_std` + `rotation_std_per_radian` · |dθ| + `rotation_std_per_metre` · |(dx, dy)|.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct IncrementNoise<T> {
    /// Standard deviation of `dx` and `dy` per step, metres.
    pub translation_std: T,
    /// Additional standard deviation of `dx`, `dy` per metre travelled.
    pub translation_std_per_metre: T,
    /// Standard deviation of `dθ` per step, radians.
    pub rotation_std: T,
    /// Additional standard deviation of `dθ` per radian turned.
    pub rotation_std_per_radian: T,
    /// Additional standard deviation of `dθ` per metre travelled (radians per metre).
    pub rotation_std_per_metre: T,
}

impl<T: Real> IncrementNoise<T> {
    /// Covariance of the increment `(dx, dy, dθ)` (`Q` of El Masri El Chaarani et al. n.d.,
    /// eq. 9, here from configuration).
    pub fn covariance(&self, inc: &OdometryIncrement<T>) -> Matrix3<T> {
        let dist = (inc.x * inc.x + inc.y * inc.y).sqrt();
        let sxy = self.translation_std + self.translation_std_per_metre * dist;
        let sth = self.rotation_std
            + self.rotation_std_per_radian * inc.theta.abs()
            + self.rotation_std_per_metre * dist;
        Matrix3::from_diagonal(&nalgebra::Vector3::new(sxy * sxy, sxy * sxy, sth * sth))
    }

    /// `true` when every parameter is finite and non-negative.
    pub fn is_valid(&self) -> bool {
        self.invalid_setting().is_none()
    }

    /// The first parameter that is negative or not finite, `None` when every one is valid.
    #[inline]
    pub fn invalid_setting(&self) -> Option<InvalidSetting> {
        let non_negative = InvalidSetting::non_negative;
        InvalidSetting::first([
            non_negative("translation_std", self.translation_std),
            non_negative("translation_std_per_metre", self.translation_std_per_metre),
            non_negative("rotation_std", self.rotation_std),
            non_negative("rotation_std_per_radian", self.rotation_std_per_radian),
            non_negative("rotation_std_per_metre", self.rotation_std_per_metre),
        ])
    }
}

/// Noise of velocity odometry, modelled as white noise on `v` and `ω`.
///
/// Each figure is the standard deviation of the *one-second average* of the velocity; the
/// average over `dt` seconds has a standard deviation `√(1/dt)` times larger, so that the
/// pose uncertainty after a given time does not depend on the odometry rate.
///
/// σ_v = `linear_std` + `linear_std_per_mps` · |v|, σ_ω = `angular_std` +
/// `angular_std_per_radps` · |ω| + `angular_std_per_mps` · |v|.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct VelocityNoise<T> {
    /// Standard deviation of the 1-s mean linear velocity, m/s.
    pub linear_std: T,
    /// Additional standard deviation of the linear velocity per m/s of speed.
    pub linear_std_per_mps: T,
    /// Standard deviation of the 1-s mean angular velocity, rad/s.
    pub angular_std: T,
    /// Additional standard deviation of the angular velocity per rad/s of turn rate.
    pub angular_std_per_radps: T,
    /// Additional standard deviation of the angular velocity per m/s of speed.
    pub angular_std_per_mps: T,
}

impl<T: Real> VelocityNoise<T> {
    /// Covariance of the inputs `(v, ω)` averaged over `dt` seconds (`dt > 0`).
    pub fn covariance(&self, v: T, omega: T, dt: T) -> Matrix2<T> {
        let sv = self.linear_std + self.linear_std_per_mps * v.abs();
        let sw = self.angular_std
            + self.angular_std_per_radps * omega.abs()
            + self.angular_std_per_mps * v.abs();
        Matrix2::new(sv * sv / dt, T::ZERO, T::ZERO, sw * sw / dt)
    }

    /// `true` when every parameter is finite and non-negative.
    pub fn is_valid(&self) -> bool {
        self.invalid_setting().is_none()
    }

    /// The first parameter that is negative or not finite, `None` when every one is valid.
    #[inline]
    pub fn invalid_setting(&self) -> Option<InvalidSetting> {
        let non_negative = InvalidSetting::non_negative;
        InvalidSetting::first([
            non_negative("linear_std", self.linear_std),
            non_negative("linear_std_per_mps", self.linear_std_per_mps),
            non_negative("angular_std", self.angular_std),
            non_negative("angular_std_per_radps", self.angular_std_per_radps),
            non_negative("angular_std_per_mps", self.angular_std_per_mps),
        ])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{assert_jacobian, central_difference};
    use nalgebra::{DVector, Vector3};

    /// The increment model's pose is `Pose2::compose`'s (which uses `libm` and
    /// `wrap_angle`), across the ±π seam too: to rounding in `f64`, and within the `f32`
    /// sine and cosine's error in `f32`.
    #[test]
    fn increment_pose_is_the_composition() {
        let poses = [
            (0.3, -1.2, 0.4),
            (2.0, 1.0, -2.8),
            (-5.0, 7.0, 3.1),
            (1.0, 1.0, -3.13),
        ];
        let incs = [
            (0.5, 0.1, 0.2),
            (-0.2, 0.3, -1.0),
            (0.02, 0.0005, 0.1),
            (0.0, 0.0, 0.0),
        ];
        for p in poses {
            for u in incs {
                let (pose, inc): (Pose2<f64>, Pose2<f64>) =
                    (Pose2::new(p.0, p.1, p.2), Pose2::new(u.0, u.1, u.2));
                let (a, b) = (compose_increment(&pose, &inc).pose, pose.compose(&inc));
                let dt = crate::geometry::wrap_angle(a.theta - b.theta);
                assert!(
                    (a.x - b.x).abs() < 1e-12 && (a.y - b.y).abs() < 1e-12,
                    "{a:?} {b:?}"
                );
                let pi = core::f64::consts::PI;
                assert!(
                    dt.abs() < 1e-12 && a.theta > -pi && a.theta <= pi,
                    "{a:?} {b:?}"
                );
                let (pose, inc) = (pose.cast::<f32>(), inc.cast::<f32>());
                let (a, b) = (compose_increment(&pose, &inc).pose, pose.compose(&inc));
                let dt = crate::geometry::wrap_angle(a.theta - b.theta);
                assert!(
                    (a.x - b.x).abs() < 1e-5 && (a.y - b.y).abs() < 1e-5,
                    "{a:?} {b:?}"
                );
                assert!(
                    dt.abs() < 1e-6 && a.theta > -core::f32::consts::PI,
                    "{a:?} {b:?}"
                );
                assert!(a.theta <= core::f32::consts::PI, "{a:?}");
            }
        }
    }

    #[test]
    fn increment_jacobians_match_finite_differences() {
        let poses = [(0.3, -1.2, 0.4), (2.0, 1.0, -2.8), (0.0, 0.0, 3.1)];
        let incs = [(0.5, 0.1, 0.2), (-0.2, 0.3, -1.0), (0.0, 0.0, 0.0)];
        for p in poses {
            for u in incs {
                let pose = Pose2::new(p.0, p.1, p.2);
                let inc = Pose2::new(u.0, u.1, u.2);
                let step = compose_increment(&pose, &inc);
                let f_pose = |x: &DVector<f64>| {
                    compose_increment(&Pose2::new(x[0], x[1], x[2]), &inc)
                        .pose
                        .to_vector()
                };
                let num =
                    central_difference(f_pose, &DVector::from_row_slice(&[p.0, p.1, p.2]), &[2]);
                assert_jacobian(&step.wrt_pose, &num, 1e-8);
                let f_inc = |x: &DVector<f64>| {
                    compose_increment(&pose, &Pose2::new(x[0], x[1], x[2]))
                        .pose
                        .to_vector()
                };
                let num =
                    central_difference(f_inc, &DVector::from_row_slice(&[u.0, u.1, u.2]), &[2]);
                assert_jacobian(&step.wrt_input, &num, 1e-8);
            }
        }
    }

    #[test]
    fn velocity_jacobians_match_finite_differences() {
        let pose = Pose2::new(1.0, -0.5, 2.9);
        // Includes ω·dt/2 inside and outside the Taylor branch.
        for (v, w, dt) in [
            (0.4, 0.8, 0.1),
            (1.2, -2.0, 0.5),
            (0.3, 1e-5, 0.2),
            (-0.5, 0.0, 0.3),
        ] {
            let step = integrate_velocity(&pose, v, w, dt);
            let f_pose = |x: &DVector<f64>| {
                integrate_velocity(&Pose2::new(x[0], x[1], x[2]), v, w, dt)
                    .pose
                    .to_vector()
            };
            let num = central_difference(f_pose, &DVector::from_row_slice(&[1.0, -0.5, 2.9]), &[2]);
            assert_jacobian(&step.wrt_pose, &num, 1e-8);
            let f_in =
                |x: &DVector<f64>| integrate_velocity(&pose, x[0], x[1], dt).pose.to_vector();
            let num = central_difference(f_in, &DVector::from_row_slice(&[v, w]), &[2]);
            assert_jacobian(&step.wrt_input, &num, 1e-8);
        }
    }

    #[test]
    fn velocity_arc_is_exact() {
        // A quarter circle of radius 1: v = 1, ω = 1, dt = π/2, starting at the origin.
        let end = integrate_velocity(&Pose2::IDENTITY, 1.0, 1.0, core::f64::consts::FRAC_PI_2).pose;
        assert!((end.x - 1.0).abs() < 1e-12 && (end.y - 1.0).abs() < 1e-12);
        assert!((end.theta - core::f64::consts::FRAC_PI_2).abs() < 1e-12);
        // Straight line and the small-angle branch agree with the closed form.
        let straight = integrate_velocity(&Pose2::new(0.0, 0.0, 0.5), 2.0, 0.0, 1.5).pose;
        assert!((straight.x - 3.0 * 0.5f64.cos()).abs() < 1e-12);
        let tiny = integrate_velocity(&Pose2::IDENTITY, 1.0, 1e-4, 1.0).pose;
        let exact_x = (1e-4f64).sin() / 1e-4;
        assert!((tiny.x - exact_x).abs() < 1e-14);
    }

    #[test]
    fn noise_grows_with_motion_and_rate_independence() {
        let n = VelocityNoise {
            linear_std: 0.1,
            linear_std_per_mps: 0.0,
            angular_std: 0.05,
            angular_std_per_radps: 0.0,
            angular_std_per_mps: 0.0,
        };
        // Ten steps of 0.1 s accumulate the same variance of θ as one of 1 s.
        let one = integrate_velocity(&Pose2::<f64>::IDENTITY, 0.0, 0.0, 1.0);
        let q1 = one.wrt_input * n.covariance(0.0, 0.0, 1.0) * one.wrt_input.transpose();
        let tenth = integrate_velocity(&Pose2::<f64>::IDENTITY, 0.0, 0.0, 0.1);
        let q10 = tenth.wrt_input * n.covariance(0.0, 0.0, 0.1) * tenth.wrt_input.transpose();
        assert!((q1[(2, 2)] - 10.0 * q10[(2, 2)]).abs() < 1e-15);
        let inc = IncrementNoise {
            translation_std: 0.01,
            translation_std_per_metre: 0.1,
            rotation_std: 0.0,
            rotation_std_per_radian: 0.1,
            rotation_std_per_metre: 0.0,
        };
        let q = inc.covariance(&Pose2::new(1.0, 0.0, 0.5));
        assert!((q[(0, 0)] - 0.11f64.powi(2)).abs() < 1e-15);
        assert!((q[(2, 2)] - 0.05f64.powi(2)).abs() < 1e-15);
        assert_eq!(q.diagonal(), Vector3::new(q[(0, 0)], q[(1, 1)], q[(2, 2)]));
        assert!(
            !IncrementNoise {
                rotation_std: -1.0,
                ..inc
            }
            .is_valid()
        );
    }
}
