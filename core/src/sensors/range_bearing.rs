//! Range and bearing of a 2-D point landmark, seen by a sensor mounted on the robot.
//!
//! The sensor sits at `mount = (x_c, y_c, γ_c)` in the robot frame; its pose in the world
//! is `s = robot ⊕ mount`. For a landmark `l = (l_x, l_y)` and `d = l − (s_x, s_y)`:
//!
//! ```text
//! h(robot, l) = [ r ]  = [ |d|                      ]
//!               [ b ]    [ atan2(d_y, d_x) − s_θ    ]   (wrapped)
//! g(robot, z) = (s_x, s_y) + r · (cos(s_θ + b), sin(s_θ + b))
//! ```
//!
//! The bearing is **counter-clockwise positive** (to the robot's left), zero straight
//! ahead of the sensor. Both `h` and its inverse `g` are written in polar form; eq. 12 of
//! El Masri El Chaarani et al. (n.d.) compares a Cartesian prediction with a polar
//! measurement and is not used.
//! Every Jacobian here is checked against central finite differences in the tests.
//!
//! # References
//!
//! - El Masri El Chaarani, A., Ashraf, J., and Abu Hara, R. (n.d.). *EKF-SLAM with
//!   Traffic sign images*. Undated report. The observation model this one replaces, eq. 12.

use crate::geometry::{Pose2, wrap_near};
use crate::scalar::Real;
use nalgebra::{Matrix2, Matrix2x3, Vector2};

/// Shortest range the model accepts, metres. Closer than this the bearing's Jacobian
/// (∝ 1/range) makes the update ill-conditioned — a landmark a few millimetres away with
/// 0.1 m range noise gives a new covariance `f32` cannot keep positive semi-definite — and
/// no camera or reflector sensor measures there, so such sightings and predictions are
/// refused.
pub const MIN_RANGE: f64 = 0.05;

/// Longest range the model accepts, metres. Far beyond any landmark sensor; it keeps the
/// new landmark's covariance, whose across-ray variance grows as range², representable
/// next to its along-ray variance in `f32` (a 50 km sighting is not).
pub const MAX_RANGE: f64 = 1.0e3;

/// Largest bearing magnitude the model accepts, radians: one turn either way, so that
/// sensors reporting in (−π, π] or [0, 2π) both fit. A larger bearing is no sensor's
/// reading but a corrupted value — in `f32` a bearing of 10⁸ rad has no fractional part
/// at all — and such sightings are refused (the fuzzer drove a lost robot's `f32`
/// covariance indefinite with a stream of them).
pub const MAX_BEARING: f64 = core::f64::consts::TAU;

/// A range-bearing measurement: range in metres, bearing in radians (CCW positive).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RangeBearing<T> {
    /// Distance from the sensor to the landmark, metres (> 0).
    pub range: T,
    /// Angle from the sensor's forward axis to the landmark, radians, CCW positive.
    pub bearing: T,
}

impl<T: Real> RangeBearing<T> {
    /// A measurement from range (m) and bearing (rad).
    pub const fn new(range: T, bearing: T) -> Self {
        Self { range, bearing }
    }

    /// The measurement as a vector `[r, b]`.
    pub fn to_vector(&self) -> Vector2<T> {
        Vector2::new(self.range, self.bearing)
    }

    /// `true` when both components are finite, the range within
    /// [`MIN_RANGE`]`..=`[`MAX_RANGE`] and the bearing within ±[`MAX_BEARING`].
    pub fn is_valid(&self) -> bool {
        self.range.finite()
            && self.bearing.finite()
            && self.range >= T::lit(MIN_RANGE)
            && self.range <= T::lit(MAX_RANGE)
            && self.bearing.abs() <= T::lit(MAX_BEARING)
    }
}

/// The predicted measurement and its Jacobians (`h`, ∂h/∂robot, ∂h/∂landmark).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Prediction<T: Real> {
    /// Predicted `(range, bearing)`.
    pub z: RangeBearing<T>,
    /// ∂h/∂(x, y, θ) of the robot, 2 × 3.
    pub wrt_robot: Matrix2x3<T>,
    /// ∂h/∂(l_x, l_y) of the landmark, 2 × 2.
    pub wrt_landmark: Matrix2<T>,
}

/// A landmark position recovered from a measurement, with the Jacobians of `g`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InverseObservation<T: Real> {
    /// Landmark position in the world.
    pub landmark: Vector2<T>,
    /// ∂g/∂(x, y, θ) of the robot, 2 × 3.
    pub wrt_robot: Matrix2x3<T>,
    /// ∂g/∂(r, b) of the measurement, 2 × 2.
    pub wrt_measurement: Matrix2<T>,
}

/// A range-bearing sensor mounted on the robot at `mount` (robot frame).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RangeBearingSensor<T> {
    /// Pose of the sensor in the robot frame.
    pub mount: Pose2<T>,
}

impl<T: Real> RangeBearingSensor<T> {
    /// A sensor at the robot's origin, looking forward.
    pub const fn at_robot_origin() -> Self {
        Self {
            mount: Pose2::IDENTITY,
        }
    }

    /// A sensor at `mount` in the robot frame.
    pub const fn new(mount: Pose2<T>) -> Self {
        Self { mount }
    }

    /// Sensor pose in the world and ∂(s_x, s_y)/∂θ of the robot.
    fn sensor_pose(&self, robot: &Pose2<T>) -> (T, T, T, T, T) {
        let (s, c) = robot.theta.sin_cos_native();
        let m = &self.mount;
        let sx = robot.x + c * m.x - s * m.y;
        let sy = robot.y + s * m.x + c * m.y;
        let dsx_dth = -s * m.x - c * m.y;
        let dsy_dth = c * m.x - s * m.y;
        (sx, sy, robot.theta + m.theta, dsx_dth, dsy_dth)
    }

    /// The observation model `h`: expected range and bearing of `landmark` from `robot`,
    /// with its Jacobians. `None` when the landmark is closer to the sensor than
    /// [`MIN_RANGE`] (the bearing is undefined at the sensor).
    pub fn predict(&self, robot: &Pose2<T>, landmark: &Vector2<T>) -> Option<Prediction<T>> {
        let (sx, sy, sth, dsx_dth, dsy_dth) = self.sensor_pose(robot);
        let dx = landmark[0] - sx;
        let dy = landmark[1] - sy;
        let q = dx * dx + dy * dy;
        let r = q.sqrt();
        if !r.finite() || r < T::lit(MIN_RANGE) {
            return None;
        }
        // ∂r/∂d = d/r, ∂b/∂d = (−d_y, d_x)/q; ∂d/∂(x, y) = −I, ∂d/∂θ = −∂s/∂θ; ∂b/∂θ has −1.
        let wrt_landmark = Matrix2::new(dx / r, dy / r, -dy / q, dx / q);
        let ddx_dth = -dsx_dth;
        let ddy_dth = -dsy_dth;
        let wrt_robot = Matrix2x3::new(
            -dx / r,
            -dy / r,
            (dx * ddx_dth + dy * ddy_dth) / r,
            dy / q,
            -dx / q,
            (-dy * ddx_dth + dx * ddy_dth) / q - T::ONE,
        );
        Some(Prediction {
            z: RangeBearing::new(r, wrap_near(dy.atan2(dx) - sth)),
            wrt_robot,
            wrt_landmark,
        })
    }

    /// The inverse observation model `g`: the landmark position seen at `z` from `robot`,
    /// with its Jacobians.
    pub fn landmark_from(&self, robot: &Pose2<T>, z: &RangeBearing<T>) -> InverseObservation<T> {
        let (sx, sy, sth, dsx_dth, dsy_dth) = self.sensor_pose(robot);
        let (sp, cp) = (sth + z.bearing).sin_cos_native();
        let r = z.range;
        InverseObservation {
            landmark: Vector2::new(sx + r * cp, sy + r * sp),
            wrt_robot: Matrix2x3::new(
                T::ONE,
                T::ZERO,
                dsx_dth - r * sp,
                T::ZERO,
                T::ONE,
                dsy_dth + r * cp,
            ),
            wrt_measurement: Matrix2::new(cp, -r * sp, sp, r * cp),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{assert_jacobian, central_difference};
    use nalgebra::{DVector, Vector2};

    fn sensors() -> [RangeBearingSensor<f64>; 3] {
        [
            RangeBearingSensor::at_robot_origin(),
            RangeBearingSensor::new(Pose2::new(0.2, -0.05, 0.0)),
            RangeBearingSensor::new(Pose2::new(-0.1, 0.3, 0.7)),
        ]
    }

    #[test]
    fn bearing_is_counter_clockwise_positive() {
        let s = RangeBearingSensor::<f64>::at_robot_origin();
        let p = s
            .predict(&Pose2::IDENTITY, &Vector2::new(1.0, 1.0))
            .unwrap();
        assert!((p.z.bearing - core::f64::consts::FRAC_PI_4).abs() < 1e-12);
        assert!((p.z.range - 2f64.sqrt()).abs() < 1e-12);
        // A robot facing +y sees a landmark on +x to its right: negative bearing.
        let p = s
            .predict(
                &Pose2::new(0.0, 0.0, core::f64::consts::FRAC_PI_2),
                &Vector2::new(2.0, 0.0),
            )
            .unwrap();
        assert!((p.z.bearing + core::f64::consts::FRAC_PI_2).abs() < 1e-12);
    }

    #[test]
    fn inverse_model_inverts_the_model() {
        let robot = Pose2::new(1.0, 2.0, -2.5);
        for s in sensors() {
            let l = Vector2::new(-0.7, 4.1);
            let z = s.predict(&robot, &l).unwrap().z;
            let back = s.landmark_from(&robot, &z).landmark;
            assert!((back - l).norm() < 1e-12, "{back} vs {l}");
        }
    }

    #[test]
    fn observation_jacobians_match_finite_differences() {
        let robot = [0.5, -1.0, 2.8];
        let l = [3.0, -2.5];
        for s in sensors() {
            let p = s
                .predict(
                    &Pose2::new(robot[0], robot[1], robot[2]),
                    &Vector2::new(l[0], l[1]),
                )
                .unwrap();
            let f_r = |x: &DVector<f64>| {
                s.predict(&Pose2::new(x[0], x[1], x[2]), &Vector2::new(l[0], l[1]))
                    .unwrap()
                    .z
                    .to_vector()
            };
            assert_jacobian(
                &p.wrt_robot,
                &central_difference(f_r, &DVector::from_row_slice(&robot), &[1]),
                1e-7,
            );
            let f_l = |x: &DVector<f64>| {
                s.predict(
                    &Pose2::new(robot[0], robot[1], robot[2]),
                    &Vector2::new(x[0], x[1]),
                )
                .unwrap()
                .z
                .to_vector()
            };
            assert_jacobian(
                &p.wrt_landmark,
                &central_difference(f_l, &DVector::from_row_slice(&l), &[1]),
                1e-7,
            );
        }
    }

    #[test]
    fn inverse_jacobians_match_finite_differences() {
        let robot = [0.5, -1.0, -0.3];
        let z = [2.2, 0.9];
        for s in sensors() {
            let pose = Pose2::new(robot[0], robot[1], robot[2]);
            let g = s.landmark_from(&pose, &RangeBearing::new(z[0], z[1]));
            let f_r = |x: &DVector<f64>| {
                s.landmark_from(
                    &Pose2::new(x[0], x[1], x[2]),
                    &RangeBearing::new(z[0], z[1]),
                )
                .landmark
            };
            assert_jacobian(
                &g.wrt_robot,
                &central_difference(f_r, &DVector::from_row_slice(&robot), &[]),
                1e-8,
            );
            let f_z = |x: &DVector<f64>| {
                s.landmark_from(&pose, &RangeBearing::new(x[0], x[1]))
                    .landmark
            };
            assert_jacobian(
                &g.wrt_measurement,
                &central_difference(f_z, &DVector::from_row_slice(&z), &[]),
                1e-8,
            );
        }
    }

    #[test]
    fn landmark_on_the_sensor_has_no_prediction() {
        let s = RangeBearingSensor::new(Pose2::new(0.2, 0.0, 0.0));
        assert!(
            s.predict(&Pose2::IDENTITY, &Vector2::new(0.2, 0.0))
                .is_none()
        );
        assert!(!RangeBearing::new(0.0, 0.1).is_valid());
        assert!(!RangeBearing::new(1.0, f64::NAN).is_valid());
        assert!(RangeBearing::new(1.0, -6.2).is_valid());
        assert!(!RangeBearing::new(1.0, 6.3).is_valid());
        assert!(!RangeBearing::new(1.0, -4.9e13).is_valid());
    }
}
