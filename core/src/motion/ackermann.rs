//! Car-like motion: the kinematic bicycle (Ackermann) model from the speed of the
//! rear-axle centre and the front steering angle.
//!
//! The robot frame of a car is the centre of its **rear axle**, x forward: the rear wheels
//! do not slip sideways, so that point moves along the car's heading. With wheelbase `L`
//! (rear to front axle), speed `v` and the steering angle `φ` of the (virtual, middle)
//! front wheel, the car turns about a point on the rear axle's line at radius `L / tan φ`:
//!
//! ```text
//! ω = v · tan(φ) / L
//! ```
//!
//! Held for `dt` seconds, `(v, φ)` is the arc of constant `(v, ω)`, moved exactly by
//! [`integrate_velocity`]; the Jacobian with respect to the inputs `(v, φ)` is the
//! velocity model's times `∂(v, ω)/∂(v, φ) = [[1, 0], [tan φ / L, v / (L cos² φ)]]`.
//!
//! A sensor mounted ahead of the rear axle (a front camera or laser at `(a, 0)`) needs
//! nothing here: the EKF's sensor mount ([`RangeBearingSensor`]) is relative to the same
//! robot frame, so its offset is the mount's `x`.
//!
//! # Noise
//!
//! [`AckermannNoise`]: white noise on the speed and on the steering angle, each figure
//! the standard deviation of the *one-second average*, so the variance over `dt` seconds
//! is the figure squared over `dt` (as [`VelocityNoise`](super::VelocityNoise): the pose
//! uncertainty after a drive does not depend on the odometry rate):
//!
//! ```text
//! σ_v = speed_std + speed_std_per_mps · |v|,   σ_φ = steering_std + steering_std_per_mps · |v|
//! Q = diag(σ_v², σ_φ²) / dt
//! ```
//!
//! A steering error is seen in the pose as a turn-rate error of `v σ_φ / (L cos² φ)`: it
//! grows with speed, as a car's heading drift does; a fixed steering offset (a mis-set
//! centre) is a bias this white noise only covers.
//!
//! Everything is fixed-size and allocation-free (`no_std`): [`Ackermann`] is four scalars
//! and a step is two 3 × 3 matrix products.
//!
//! # References
//!
//! - Rajamani, R. (2012). *Vehicle Dynamics and Control*, 2nd ed., Springer, §2.2: the
//!   kinematic bicycle model, here with its reference point at the rear axle.

use super::{MotionStep, integrate_velocity};
use crate::error::InvalidSetting;
use crate::geometry::Pose2;
use crate::scalar::Real;
#[cfg(doc)]
use crate::sensors::range_bearing::RangeBearingSensor;
use nalgebra::{Matrix2, Matrix3x2};

/// Noise of a car's speed and steering readings (see the [module docs](self)).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AckermannNoise<T> {
    /// Standard deviation of the 1-s mean speed, m/s.
    pub speed_std: T,
    /// Additional standard deviation of the speed per m/s of speed.
    pub speed_std_per_mps: T,
    /// Standard deviation of the 1-s mean steering angle, rad.
    pub steering_std: T,
    /// Additional standard deviation of the steering angle per m/s of speed, rad per m/s.
    pub steering_std_per_mps: T,
}

/// A car: its wheelbase, the largest steering angle it accepts and the noise of its
/// readings. The robot frame is the rear-axle centre.
///
/// ```
/// use microslam::geometry::Pose2;
/// use microslam::motion::{Ackermann, AckermannNoise};
///
/// let car = Ackermann {
///     wheelbase: 2.5,
///     max_steering: 0.6,
///     noise: AckermannNoise { speed_std: 0.05, speed_std_per_mps: 0.02, steering_std: 0.01, steering_std_per_mps: 0.0 },
/// };
/// // 1 s at 2 m/s, steered 0.2 rad: ω = 2 · tan 0.2 / 2.5.
/// let step = car.step(&Pose2::IDENTITY, 2.0, 0.2, 1.0).unwrap();
/// assert!((step.pose.theta - 2.0 * 0.2f64.tan() / 2.5).abs() < 1e-12);
/// assert!(car.step(&Pose2::IDENTITY, 2.0, 0.7, 1.0).is_none()); // beyond max_steering
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Ackermann<T> {
    /// Distance from the rear to the front axle, metres (positive).
    pub wheelbase: T,
    /// Largest |steering angle| accepted, rad (positive, below π/2 where `tan φ` is
    /// unbounded). A larger reading is refused as corrupt.
    pub max_steering: T,
    /// Noise of the speed and steering readings.
    pub noise: AckermannNoise<T>,
}

impl<T: Real> Ackermann<T> {
    /// Turn rate `ω = v tan φ / L`, rad/s, or `None` when `φ` is beyond
    /// [`Ackermann::max_steering`] or an input is not finite.
    pub fn turn_rate(&self, v: T, steering: T) -> Option<T> {
        self.turn(v, steering).map(|(omega, _, _)| omega)
    }

    /// `(ω, ∂ω/∂v, ∂ω/∂φ)`.
    fn turn(&self, v: T, steering: T) -> Option<(T, T, T)> {
        if !(v.finite() && steering.finite()) || steering.abs() > self.max_steering {
            return None;
        }
        let (s, c) = steering.sin_cos_native();
        let tan = s / c;
        let omega = v * tan / self.wheelbase;
        let domega_dv = tan / self.wheelbase;
        let domega_dphi = v / (self.wheelbase * c * c);
        (omega.finite() && domega_dphi.finite()).then_some((omega, domega_dv, domega_dphi))
    }

    /// Moves `pose` (the rear-axle centre) for `dt` seconds at speed `v` with the front
    /// wheel steered `steering` rad, and returns the Jacobians with respect to the pose
    /// and to the inputs `(v, φ)`. `None` when the steering is beyond
    /// [`Ackermann::max_steering`] or an input is not finite.
    pub fn step(&self, pose: &Pose2<T>, v: T, steering: T, dt: T) -> Option<MotionStep<T, 2>> {
        let (omega, domega_dv, domega_dphi) = self.turn(v, steering)?;
        let arc = integrate_velocity(pose, v, omega, dt);
        Some(MotionStep {
            wrt_input: arc.wrt_input * input_map(domega_dv, domega_dphi),
            ..arc
        })
    }

    /// The same step with the speed and turn rate scaled by `(s_v, s_ω)` (odometry scale
    /// factors estimated as states): the pose moves with `(s_v v, s_ω ω)`; returns the
    /// step (input Jacobian with respect to the measured `(v, φ)`) and
    /// `∂pose'/∂(s_v, s_ω)`.
    pub fn scaled_step(
        &self,
        pose: &Pose2<T>,
        v: T,
        steering: T,
        dt: T,
        scale: (T, T),
    ) -> Option<(MotionStep<T, 2>, Matrix3x2<T>)> {
        let (omega, domega_dv, domega_dphi) = self.turn(v, steering)?;
        let (sv, sw) = scale;
        let arc = integrate_velocity(pose, sv * v, sw * omega, dt);
        let g = arc.wrt_input;
        let wrt_scale = Matrix3x2::from_fn(|a, c| {
            if c == 0 {
                g[(a, 0)] * v
            } else {
                g[(a, 1)] * omega
            }
        });
        let map = Matrix2::new(sv, T::ZERO, sw * domega_dv, sw * domega_dphi);
        Some((
            MotionStep {
                wrt_input: g * map,
                ..arc
            },
            wrt_scale,
        ))
    }

    /// Covariance of the inputs `(v, φ)` averaged over `dt` seconds (`dt > 0`).
    pub fn covariance(&self, v: T, dt: T) -> Matrix2<T> {
        let n = &self.noise;
        let sv = n.speed_std + n.speed_std_per_mps * v.abs();
        let sp = n.steering_std + n.steering_std_per_mps * v.abs();
        Matrix2::new(sv * sv / dt, T::ZERO, T::ZERO, sp * sp / dt)
    }

    /// `true` when every setting is valid ([`Ackermann::invalid_setting`]).
    pub fn is_valid(&self) -> bool {
        self.invalid_setting().is_none()
    }

    /// The first setting that is out of range: the wheelbase must be positive, the
    /// largest steering angle positive and below 1.5 rad, the noise finite and
    /// non-negative. `None` when every one is valid.
    pub fn invalid_setting(&self) -> Option<InvalidSetting> {
        let non_negative = InvalidSetting::non_negative;
        let n = &self.noise;
        InvalidSetting::first([
            InvalidSetting::positive("wheelbase", self.wheelbase),
            InvalidSetting::positive("max_steering", self.max_steering),
            (
                "max_steering",
                "below 1.5 rad",
                self.max_steering < T::lit(1.5),
            ),
            non_negative("speed_std", n.speed_std),
            non_negative("speed_std_per_mps", n.speed_std_per_mps),
            non_negative("steering_std", n.steering_std),
            non_negative("steering_std_per_mps", n.steering_std_per_mps),
        ])
    }
}

/// `∂(v, ω)/∂(v, φ)`.
fn input_map<T: Real>(domega_dv: T, domega_dphi: T) -> Matrix2<T> {
    Matrix2::new(T::ONE, T::ZERO, domega_dv, domega_dphi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{assert_jacobian, central_difference};
    use nalgebra::DVector;

    fn car() -> Ackermann<f64> {
        Ackermann {
            wheelbase: 2.7,
            max_steering: 0.6,
            noise: AckermannNoise {
                speed_std: 0.05,
                speed_std_per_mps: 0.02,
                steering_std: 0.01,
                steering_std_per_mps: 0.001,
            },
        }
    }

    /// Tolerance of the Jacobian checks: the analytic entries agree with central
    /// differences (h = 1e-6) to 1e-8 relative, as the other motion models (measured: all
    /// within 1e-9, not all within 3e-10).
    const JACOBIAN_TOL: f64 = 1e-8;

    #[test]
    fn jacobians_match_finite_differences() {
        let car = car();
        let poses = [(1.0, -0.5, 2.9), (0.0, 0.0, 0.0), (-3.0, 4.0, -3.1)];
        // Straight, both turns, reversing, near the steering limit, the Taylor branch.
        let inputs = [
            (2.0, 0.0, 0.1),
            (1.5, 0.3, 0.2),
            (3.0, -0.55, 0.5),
            (-1.0, 0.2, 0.3),
            (0.5, 1e-6, 0.05),
            (8.0, 0.59, 1.0),
        ];
        for p in poses {
            for (v, phi, dt) in inputs {
                let pose = Pose2::new(p.0, p.1, p.2);
                let step = car.step(&pose, v, phi, dt).unwrap();
                let f_pose = |x: &DVector<f64>| {
                    car.step(&Pose2::new(x[0], x[1], x[2]), v, phi, dt)
                        .unwrap()
                        .pose
                        .to_vector()
                };
                let num =
                    central_difference(f_pose, &DVector::from_row_slice(&[p.0, p.1, p.2]), &[2]);
                assert_jacobian(&step.wrt_pose, &num, JACOBIAN_TOL);
                let f_in =
                    |x: &DVector<f64>| car.step(&pose, x[0], x[1], dt).unwrap().pose.to_vector();
                let num = central_difference(f_in, &DVector::from_row_slice(&[v, phi]), &[2]);
                assert_jacobian(&step.wrt_input, &num, JACOBIAN_TOL);
                // The scaled step: inputs and scale factors.
                let scale = (1.03, 0.97);
                let (scaled, wrt_scale) = car.scaled_step(&pose, v, phi, dt, scale).unwrap();
                let f_in = |x: &DVector<f64>| {
                    car.scaled_step(&pose, x[0], x[1], dt, scale)
                        .unwrap()
                        .0
                        .pose
                        .to_vector()
                };
                let num = central_difference(f_in, &DVector::from_row_slice(&[v, phi]), &[2]);
                assert_jacobian(&scaled.wrt_input, &num, JACOBIAN_TOL);
                let f_s = |x: &DVector<f64>| {
                    car.scaled_step(&pose, v, phi, dt, (x[0], x[1]))
                        .unwrap()
                        .0
                        .pose
                        .to_vector()
                };
                let num =
                    central_difference(f_s, &DVector::from_row_slice(&[scale.0, scale.1]), &[2]);
                assert_jacobian(&wrt_scale, &num, JACOBIAN_TOL);
            }
        }
    }

    /// A full circle: steered φ, the rear axle turns on the radius L / tan φ (written
    /// here from the geometry, not from the model), and comes back to its start.
    #[test]
    fn steady_steering_drives_the_geometric_circle() {
        let car = car();
        let phi: f64 = 0.25;
        let radius = 2.7 / phi.tan();
        let v = 1.2;
        let lap = 2.0 * core::f64::consts::PI * radius / v;
        let (mut pose, n) = (Pose2::IDENTITY, 1000);
        let mut farthest: f64 = 0.0;
        for _ in 0..n {
            pose = car.step(&pose, v, phi, lap / f64::from(n)).unwrap().pose;
            // Distance from the centre of the turn, (0, R), stays R.
            let r = (pose.x * pose.x + (pose.y - radius) * (pose.y - radius)).sqrt();
            farthest = farthest.max((r - radius).abs());
        }
        assert!(farthest < 1e-9, "{farthest}");
        assert!(
            pose.x.abs() < 1e-9 && pose.y.abs() < 1e-9 && pose.theta.abs() < 1e-9,
            "{pose:?}"
        );
    }

    #[test]
    fn bad_inputs_and_settings_are_refused() {
        let car = car();
        assert!(car.step(&Pose2::IDENTITY, 1.0, 0.61, 0.1).is_none());
        assert!(car.step(&Pose2::IDENTITY, f64::NAN, 0.1, 0.1).is_none());
        assert!(
            car.step(&Pose2::IDENTITY, 1.0, f64::INFINITY, 0.1)
                .is_none()
        );
        assert!(car.is_valid());
        let named = |c: Ackermann<f64>| c.invalid_setting().map(|s| s.name);
        assert_eq!(
            named(Ackermann {
                wheelbase: 0.0,
                ..car
            }),
            Some("wheelbase")
        );
        assert_eq!(
            named(Ackermann {
                wheelbase: f64::NAN,
                ..car
            }),
            Some("wheelbase")
        );
        assert_eq!(
            named(Ackermann {
                max_steering: 1.6,
                ..car
            }),
            Some("max_steering")
        );
        assert_eq!(
            named(Ackermann {
                max_steering: f64::NAN,
                ..car
            }),
            Some("max_steering")
        );
        let noise = AckermannNoise {
            steering_std: -0.1,
            ..car.noise
        };
        assert_eq!(named(Ackermann { noise, ..car }), Some("steering_std"));
    }

    /// Rate independence: ten steps of 0.1 s straight ahead add the heading variance of
    /// one step of 1 s, and the heading variance of a step is `(v σ_φ dt / L)² / dt`
    /// (the steering's effect written out by hand, at φ = 0).
    #[test]
    fn noise_is_rate_independent_and_acts_through_the_wheelbase() {
        let car = car();
        let v = 2.0;
        let heading_var = |dt: f64| {
            let s = car.step(&Pose2::IDENTITY, v, 0.0, dt).unwrap();
            (s.wrt_input * car.covariance(v, dt) * s.wrt_input.transpose())[(2, 2)]
        };
        assert!((heading_var(1.0) - 10.0 * heading_var(0.1)).abs() < 1e-15);
        let sp: f64 = 0.01 + 0.001 * v;
        let expected = (v * sp / 2.7).powi(2);
        assert!(
            (heading_var(1.0) - expected).abs() < 1e-15,
            "{}",
            heading_var(1.0)
        );
    }
}
