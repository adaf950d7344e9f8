//! Pinhole and RGB-D camera geometry: from a detection's pixel and depth to a
//! range-bearing sighting, and from any pixel and depth back to the robot and the world.
//!
//! Frames (all right-handed):
//! - **robot**: x forward, y left, z up, origin on the floor under the robot's reference
//!   point;
//! - **camera body**: the camera's own x forward, y left, z up, placed on the robot by a
//!   [`CameraMount`] (translation, then yaw–pitch–roll, Z-Y-X); a positive pitch tilts the
//!   camera down towards the floor;
//! - **optical**: z along the optical axis, x to the right in the image, y down (the pinhole
//!   convention): `optical → body` is the fixed rotation [`BODY_FROM_OPTICAL`] (`R_oc`
//!   of Du n.d., eq. 29, is its transpose).
//!
//! Two mistakes that are easy to copy from El Masri El Chaarani et al. (n.d., §II-C,
//! eq. 26) are handled here:
//! - `θ = atan((u − u₀)/f)` is positive for a detection to the **right** of the image
//!   centre, while bearings in this crate are counter-clockwise positive (to the left); and
//!   it ignores a pitched camera, where the horizontal direction depends on `v` too;
//! - an RGB-D depth is the coordinate along the optical axis, not the distance: the range
//!   to a detection off the image centre is longer than its depth.
//!
//! [`Camera::sighting`] does the full conversion: back-project the pixel at its depth,
//! carry it to the robot frame, and measure range and bearing in the horizontal plane from
//! the camera's planar pose [`Camera::planar_mount`] — the mount to give the EKF's
//! [`RangeBearingSensor`](crate::sensors::range_bearing::RangeBearingSensor).
//!
//! # References
//!
//! - El Masri El Chaarani, A., Ashraf, J., and Abu Hara, R. (n.d.). *EKF-SLAM with
//!   Traffic sign images*. Undated report. The bearing from a detection's pixel, §II-C,
//!   eqs. 25–26.
//! - Du, C. (n.d.). *ECE 276 Project: Particle Filter SLAM*. Undated report, University of
//!   California, San Diego. The RGB-D registration and the pixel-to-world chain, eqs.
//!   26–30.

use crate::geometry::Pose2;
use crate::scalar::Real;
use crate::sensors::range_bearing::RangeBearing;
use core::fmt;
use nalgebra::{Matrix2, Matrix2x3, Matrix3, Vector2, Vector3};

/// Why a pixel could not be converted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CameraError {
    /// A pixel coordinate, depth or noise figure is NaN or infinite.
    NonFiniteInput,
    /// The depth is zero or negative (no return, or a point behind the camera).
    InvalidDepth,
    /// The point lies on the camera's vertical axis: its bearing is undefined.
    OnCameraAxis,
    /// A Kinect disparity outside the range where the depth model is defined.
    InvalidDisparity,
}

impl fmt::Display for CameraError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::NonFiniteInput => "pixel, depth or noise is NaN or infinite",
            Self::InvalidDepth => "depth is not positive",
            Self::OnCameraAxis => "point is straight above or below the camera",
            Self::InvalidDisparity => "disparity outside the depth model's range",
        })
    }
}

impl core::error::Error for CameraError {}

/// `optical → camera body`: optical z (forward) is body x, optical x (right) is body −y,
/// optical y (down) is body −z.
pub fn body_from_optical<T: Real>() -> Matrix3<T> {
    let (o, l) = (T::ZERO, T::ONE);
    Matrix3::new(o, o, l, -l, o, o, o, -l, o)
}

/// The rotation of [`body_from_optical`] as a constant table (row-major), for reference.
pub const BODY_FROM_OPTICAL: [[i8; 3]; 3] = [[0, 0, 1], [-1, 0, 0], [0, -1, 0]];

/// Pinhole intrinsics: focal lengths and principal point, in pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PinholeIntrinsics<T> {
    /// Focal length along the image x axis (columns), pixels.
    pub fx: T,
    /// Focal length along the image y axis (rows), pixels.
    pub fy: T,
    /// Principal point, x (column), pixels.
    pub cx: T,
    /// Principal point, y (row), pixels.
    pub cy: T,
}

impl<T: Real> PinholeIntrinsics<T> {
    /// The optical-frame point seen at pixel `(u, v)` with depth `depth` along the optical
    /// axis (Du n.d., eq. 27, with zero skew).
    pub fn back_project(&self, u: T, v: T, depth: T) -> Vector3<T> {
        Vector3::new(
            (u - self.cx) * depth / self.fx,
            (v - self.cy) * depth / self.fy,
            depth,
        )
    }

    /// The pixel `(u, v)` and depth of an optical-frame point; `None` behind the camera.
    pub fn project(&self, p: &Vector3<T>) -> Option<(T, T, T)> {
        (p[2] > T::ZERO).then(|| {
            (
                self.cx + self.fx * p[0] / p[2],
                self.cy + self.fy * p[1] / p[2],
                p[2],
            )
        })
    }

    /// `true` when every parameter is finite and the focal lengths positive.
    pub fn is_valid(&self) -> bool {
        self.fx.finite()
            && self.fy.finite()
            && self.cx.finite()
            && self.cy.finite()
            && self.fx > T::ZERO
            && self.fy > T::ZERO
    }
}

/// Where the camera sits on the robot: translation (m) of the camera centre in the robot
/// frame, and its orientation as yaw, pitch, roll (rad, applied Z-Y-X). Positive pitch
/// looks down.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CameraMount<T> {
    /// Forward offset, metres.
    pub x: T,
    /// Leftward offset, metres.
    pub y: T,
    /// Height above the robot frame's origin (the floor), metres.
    pub z: T,
    /// Rotation about the camera's forward axis, radians.
    pub roll: T,
    /// Rotation about the leftward axis, radians; positive tilts the view down.
    pub pitch: T,
    /// Rotation about the vertical axis, radians, counter-clockwise positive.
    pub yaw: T,
}

impl<T: Real> CameraMount<T> {
    /// `camera body → robot` rotation `R_z(yaw) R_y(pitch) R_x(roll)`.
    pub fn robot_from_body(&self) -> Matrix3<T> {
        let (sr, cr) = self.roll.sin_cos();
        let (sp, cp) = self.pitch.sin_cos();
        let (sy, cy) = self.yaw.sin_cos();
        let rz = Matrix3::new(cy, -sy, T::ZERO, sy, cy, T::ZERO, T::ZERO, T::ZERO, T::ONE);
        let ry = Matrix3::new(cp, T::ZERO, sp, T::ZERO, T::ONE, T::ZERO, -sp, T::ZERO, cp);
        let rx = Matrix3::new(T::ONE, T::ZERO, T::ZERO, T::ZERO, cr, -sr, T::ZERO, sr, cr);
        rz * ry * rx
    }

    /// `optical → robot` rotation.
    pub fn robot_from_optical(&self) -> Matrix3<T> {
        self.robot_from_body() * body_from_optical()
    }

    /// The camera centre in the robot frame.
    pub fn translation(&self) -> Vector3<T> {
        Vector3::new(self.x, self.y, self.z)
    }

    /// `true` when every component is finite.
    pub fn is_finite(&self) -> bool {
        [self.x, self.y, self.z, self.roll, self.pitch, self.yaw]
            .iter()
            .all(|v| v.finite())
    }
}

/// Noise of a detection: pixel standard deviations and a depth noise that grows with the
/// square of the depth, as for structured-light and stereo sensors.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DetectionNoise<T> {
    /// Standard deviation of the detection's column, pixels.
    pub u_std: T,
    /// Standard deviation of the detection's row, pixels.
    pub v_std: T,
    /// Depth standard deviation at zero depth, metres.
    pub depth_std: T,
    /// Additional depth standard deviation per square metre of depth (1/m).
    pub depth_std_per_m2: T,
}

impl DetectionNoise<f64> {
    /// A detector without noise: a sighting's geometry alone (simulations, tests).
    pub const NONE: Self = Self {
        u_std: 0.0,
        v_std: 0.0,
        depth_std: 0.0,
        depth_std_per_m2: 0.0,
    };
}

/// A range-bearing sighting with its covariance, ready for the EKF.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraSighting<T: Real> {
    /// Range and bearing in the horizontal plane from [`Camera::planar_mount`].
    pub z: RangeBearing<T>,
    /// First-order covariance of `(range, bearing)` from the detection noise.
    pub covariance: Matrix2<T>,
    /// Height of the detected point above the floor, metres (useful to reject detections).
    pub height: T,
}

/// A calibrated camera on the robot.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Camera<T> {
    /// Intrinsics.
    pub intrinsics: PinholeIntrinsics<T>,
    /// Mount on the robot.
    pub mount: CameraMount<T>,
}

impl<T: Real> Camera<T> {
    /// The point seen at pixel `(u, v)` with optical-axis depth `depth`, in the robot frame.
    pub fn pixel_to_robot(&self, u: T, v: T, depth: T) -> Result<Vector3<T>, CameraError> {
        if !(u.finite() && v.finite() && depth.finite()) {
            return Err(CameraError::NonFiniteInput);
        }
        if depth <= T::ZERO {
            return Err(CameraError::InvalidDepth);
        }
        let p = self.intrinsics.back_project(u, v, depth);
        Ok(self.mount.robot_from_optical() * p + self.mount.translation())
    }

    /// The point seen at `(u, v, depth)` in the world, for a robot at planar pose `robot`
    /// (Du n.d., eqs. 27–30).
    pub fn pixel_to_world(
        &self,
        robot: &Pose2<T>,
        u: T,
        v: T,
        depth: T,
    ) -> Result<Vector3<T>, CameraError> {
        let p = self.pixel_to_robot(u, v, depth)?;
        let xy = robot.transform_point(&Vector2::new(p[0], p[1]));
        Ok(Vector3::new(xy[0], xy[1], p[2]))
    }

    /// Pixel and depth of a robot-frame point; `None` when it is behind the camera.
    pub fn robot_to_pixel(&self, p: &Vector3<T>) -> Option<(T, T, T)> {
        let optical = self.mount.robot_from_optical().transpose() * (p - self.mount.translation());
        self.intrinsics.project(&optical)
    }

    /// The camera's pose in the robot's plane: `(x, y, yaw)` of the mount. Give it to the
    /// EKF's range-bearing sensor so that predicted and converted sightings agree.
    pub fn planar_mount(&self) -> Pose2<T> {
        Pose2::new(self.mount.x, self.mount.y, self.mount.yaw)
    }

    /// Range, bearing and height of the point at `(u, v, depth)`, and the Jacobian of
    /// `(range, bearing)` with respect to `(u, v, depth)`.
    fn polar_with_jacobian(
        &self,
        u: T,
        v: T,
        depth: T,
    ) -> Result<(RangeBearing<T>, T, Matrix2x3<T>), CameraError> {
        let p = self.pixel_to_robot(u, v, depth)?;
        // Horizontal offset from the camera centre, in the planar mount's frame.
        let (s, c) = self.mount.yaw.sin_cos();
        let (ox, oy) = (p[0] - self.mount.x, p[1] - self.mount.y);
        let q = Vector2::new(c * ox + s * oy, -s * ox + c * oy);
        let r2 = q.norm_squared();
        let r = r2.sqrt();
        if !r.finite() || r <= T::lit(1e-9) {
            return Err(CameraError::OnCameraAxis);
        }
        // q = C · p_optical + const: the first two rows of R_z(−yaw) · R_robot←optical.
        let rot = Matrix3::new(c, s, T::ZERO, -s, c, T::ZERO, T::ZERO, T::ZERO, T::ONE)
            * self.mount.robot_from_optical();
        let cmat: Matrix2x3<T> = rot.fixed_rows::<2>(0).into_owned();
        let k = &self.intrinsics;
        // ∂p_optical/∂(u, v, depth).
        let dp = Matrix3::new(
            depth / k.fx,
            T::ZERO,
            (u - k.cx) / k.fx,
            T::ZERO,
            depth / k.fy,
            (v - k.cy) / k.fy,
            T::ZERO,
            T::ZERO,
            T::ONE,
        );
        let polar = Matrix2::new(q[0] / r, q[1] / r, -q[1] / r2, q[0] / r2);
        Ok((
            RangeBearing::new(r, q[1].atan2(q[0])),
            p[2],
            polar * cmat * dp,
        ))
    }

    /// Converts a detection (bounding-box centre `(u, v)` and the depth sampled there) to
    /// range and bearing in the horizontal plane from [`Camera::planar_mount`], bearing
    /// counter-clockwise positive, with its first-order covariance `J Σ Jᵀ`.
    pub fn sighting(
        &self,
        u: T,
        v: T,
        depth: T,
        noise: &DetectionNoise<T>,
    ) -> Result<CameraSighting<T>, CameraError> {
        let noise_ok = [
            noise.u_std,
            noise.v_std,
            noise.depth_std,
            noise.depth_std_per_m2,
        ]
        .iter()
        .all(|s| s.finite());
        if !noise_ok {
            return Err(CameraError::NonFiniteInput);
        }
        let (z, height, jac) = self.polar_with_jacobian(u, v, depth)?;
        let sd = noise.depth_std + noise.depth_std_per_m2 * depth * depth;
        let sigma = Matrix3::from_diagonal(&Vector3::new(
            noise.u_std * noise.u_std,
            noise.v_std * noise.v_std,
            sd * sd,
        ));
        let mut cov = jac * sigma * jac.transpose();
        let off = (cov[(0, 1)] + cov[(1, 0)]) * T::lit(0.5);
        cov[(0, 1)] = off;
        cov[(1, 0)] = off;
        Ok(CameraSighting {
            z,
            covariance: cov,
            height,
        })
    }

    /// Jacobian of [`Camera::sighting`]'s `(range, bearing)` with respect to
    /// `(u, v, depth)`, for custom noise models.
    pub fn sighting_jacobian(&self, u: T, v: T, depth: T) -> Result<Matrix2x3<T>, CameraError> {
        self.polar_with_jacobian(u, v, depth).map(|(_, _, jac)| jac)
    }
}

/// The Kinect v1 of the UCSD THOR robot (`../shared/datasets/README.md`): disparity model,
/// disparity → RGB registration, intrinsics and mount.
pub mod kinect_v1 {
    use super::{Camera, CameraError, CameraMount, PinholeIntrinsics};
    use crate::scalar::Real;

    /// Intrinsics of the THOR Kinect's RGB camera as published with the dataset.
    pub fn thor_intrinsics<T: Real>() -> PinholeIntrinsics<T> {
        PinholeIntrinsics {
            fx: T::lit(585.05),
            fy: T::lit(585.05),
            cx: T::lit(242.94),
            cy: T::lit(315.84),
        }
    }

    /// Mount of the THOR Kinect: (0.18, 0.005, 0.36) m, roll 0, pitch 0.36 rad, yaw 0.021 rad.
    pub fn thor_mount<T: Real>() -> CameraMount<T> {
        CameraMount {
            x: T::lit(0.18),
            y: T::lit(0.005),
            z: T::lit(0.36),
            roll: T::ZERO,
            pitch: T::lit(0.36),
            yaw: T::lit(0.021),
        }
    }

    /// The THOR camera: intrinsics and mount.
    pub fn thor_camera<T: Real>() -> Camera<T> {
        Camera {
            intrinsics: thor_intrinsics(),
            mount: thor_mount(),
        }
    }

    /// The intermediate `dd = −0.00304 · d + 3.31` of a raw disparity `d`.
    pub fn disparity_dd<T: Real>(disparity: T) -> T {
        T::lit(-0.00304) * disparity + T::lit(3.31)
    }

    /// Depth in metres of a raw disparity value: `1.03 / dd`. Refused when `dd ≤ 0`
    /// (disparity ≥ 1088.8, no valid depth) or the input is not finite.
    pub fn disparity_to_depth<T: Real>(disparity: T) -> Result<T, CameraError> {
        if !disparity.finite() {
            return Err(CameraError::NonFiniteInput);
        }
        let dd = disparity_dd(disparity);
        if dd <= T::ZERO {
            return Err(CameraError::InvalidDisparity);
        }
        Ok(T::lit(1.03) / dd)
    }

    /// The RGB pixel `(rgb_i, rgb_j)` registered to disparity pixel `(i, j)` with raw
    /// disparity `d` (Du n.d., eq. 26, with −4.5 · 1750.46 = −7877.07):
    /// `rgb_i = (526.37 i + 19276 − 7877.07 dd) / 585.051`, `rgb_j = (526.37 j + 16662) / 585.051`.
    /// `i` and `j` index the image's first and second array axes, as in the dataset.
    pub fn disparity_pixel_to_rgb<T: Real>(i: T, j: T, disparity: T) -> (T, T) {
        let dd = disparity_dd(disparity);
        let f = T::lit(585.051);
        (
            (T::lit(526.37) * i + T::lit(19276.0) - T::lit(7877.07) * dd) / f,
            (T::lit(526.37) * j + T::lit(16662.0)) / f,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::kinect_v1::*;
    use super::*;
    use crate::geometry::wrap_angle;
    use crate::sensors::range_bearing::RangeBearingSensor;
    use crate::testing::{assert_jacobian, central_difference};
    use nalgebra::DVector;

    fn cameras() -> [Camera<f64>; 3] {
        let k = PinholeIntrinsics {
            fx: 520.0,
            fy: 515.0,
            cx: 320.0,
            cy: 240.0,
        };
        let level = CameraMount {
            x: 0.1,
            y: 0.0,
            z: 0.3,
            roll: 0.0,
            pitch: 0.0,
            yaw: 0.0,
        };
        [
            Camera {
                intrinsics: k,
                mount: level,
            },
            Camera {
                intrinsics: k,
                mount: CameraMount {
                    pitch: 0.3,
                    yaw: -0.2,
                    y: 0.05,
                    ..level
                },
            },
            thor_camera(),
        ]
    }

    /// Ground truth: a sign at a known world position is projected into the camera, and
    /// the conversion must give back the true range and bearing.
    #[test]
    fn sighting_matches_truth_for_level_and_pitched_cameras() {
        let robot = Pose2::new(1.0, -2.0, 0.6);
        let signs = [(3.0, -1.0, 0.5), (2.0, -0.2, 0.1), (4.0, -3.5, 1.2)];
        for cam in cameras() {
            let sensor = RangeBearingSensor::new(cam.planar_mount());
            for (x, y, h) in signs {
                let local = robot.inverse_transform_point(&Vector2::new(x, y));
                let (u, v, depth) = cam
                    .robot_to_pixel(&Vector3::new(local[0], local[1], h))
                    .unwrap();
                let noise = DetectionNoise {
                    u_std: 1.0,
                    v_std: 1.0,
                    depth_std: 0.01,
                    depth_std_per_m2: 0.003,
                };
                let got = cam.sighting(u, v, depth, &noise).unwrap();
                let truth = sensor.predict(&robot, &Vector2::new(x, y)).unwrap().z;
                assert!(
                    (got.z.range - truth.range).abs() < 1e-9,
                    "{got:?} vs {truth:?}"
                );
                assert!(wrap_angle(got.z.bearing - truth.bearing).abs() < 1e-9);
                assert!((got.height - h).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn the_published_bearing_has_the_opposite_sign_and_confuses_depth_with_range() {
        let cam = cameras()[0];
        // A sign to the robot's left (positive y) appears left of the image centre.
        let (u, v, depth) = cam.robot_to_pixel(&Vector3::new(3.0, 1.0, 0.3)).unwrap();
        assert!(u < cam.intrinsics.cx);
        // θ = atan((u − u₀)/f) (El Masri El Chaarani et al. n.d., eq. 26).
        let published_theta = libm::atan((u - cam.intrinsics.cx) / cam.intrinsics.fx);
        let ours = cam.sighting(u, v, depth, &DetectionNoise::NONE).unwrap();
        assert!(published_theta < 0.0 && ours.z.bearing > 0.0);
        assert!(
            (published_theta + ours.z.bearing).abs() < 1e-12,
            "level camera: only the sign differs"
        );
        // Depth is along the optical axis: 2.9 m, while the range is √(2.9² + 1²).
        assert!((depth - 2.9).abs() < 1e-12);
        assert!((ours.z.range - (2.9f64.powi(2) + 1.0).sqrt()).abs() < 1e-12);
    }

    #[test]
    fn covariance_is_first_order_propagation() {
        for cam in cameras() {
            let (u, v, d) = (200.0, 300.0, 2.5);
            let f = |x: &DVector<f64>| {
                let s = cam
                    .sighting(x[0], x[1], x[2], &DetectionNoise::NONE)
                    .unwrap();
                s.z.to_vector()
            };
            let num = central_difference(f, &DVector::from_row_slice(&[u, v, d]), &[1]);
            let noise = DetectionNoise {
                u_std: 2.0,
                v_std: 1.5,
                depth_std: 0.02,
                depth_std_per_m2: 0.004,
            };
            let got = cam.sighting(u, v, d, &noise).unwrap().covariance;
            let sd = 0.02 + 0.004 * d * d;
            let sigma =
                nalgebra::DMatrix::from_diagonal(&DVector::from_row_slice(&[4.0, 2.25, sd * sd]));
            let want = &num * sigma * num.transpose();
            for i in 0..2 {
                for j in 0..2 {
                    assert!(
                        (got[(i, j)] - want[(i, j)]).abs() < 1e-7 * (1.0 + want[(i, j)].abs()),
                        "{got} vs {want}"
                    );
                }
            }
            assert_jacobian(&cam.sighting_jacobian(u, v, d).unwrap(), &num, 1e-6);
        }
    }

    #[test]
    fn pixel_round_trip_and_world_transform() {
        let cam = thor_camera::<f64>();
        let p = cam.pixel_to_robot(100.0, 400.0, 1.7).unwrap();
        let (u, v, d) = cam.robot_to_pixel(&p).unwrap();
        assert!((u - 100.0).abs() < 1e-9 && (v - 400.0).abs() < 1e-9 && (d - 1.7).abs() < 1e-12);
        let robot = Pose2::new(2.0, 1.0, core::f64::consts::FRAC_PI_2);
        let w = cam.pixel_to_world(&robot, 100.0, 400.0, 1.7).unwrap();
        assert!(
            (w[0] - (2.0 - p[1])).abs() < 1e-12
                && (w[1] - (1.0 + p[0])).abs() < 1e-12
                && (w[2] - p[2]).abs() < 1e-12
        );
        // The pitched THOR camera sees the floor below the image centre row.
        let centre = cam
            .pixel_to_robot(cam.intrinsics.cx, cam.intrinsics.cy, 1.0)
            .unwrap();
        assert!(centre[2] < 0.36, "optical axis points down: {centre}");
    }

    #[test]
    fn kinect_disparity_model() {
        assert!((disparity_to_depth(0.0f64).unwrap() - 1.03 / 3.31).abs() < 1e-12);
        assert!((disparity_to_depth(700.0f64).unwrap() - 1.03 / (3.31 - 2.128)).abs() < 1e-12);
        assert_eq!(
            disparity_to_depth(1089.0f64),
            Err(CameraError::InvalidDisparity)
        );
        assert_eq!(
            disparity_to_depth(f64::NAN),
            Err(CameraError::NonFiniteInput)
        );
        let (ri, rj) = disparity_pixel_to_rgb(0.0f64, 0.0, 0.0);
        assert!((ri - (19276.0 - 7877.07 * 3.31) / 585.051).abs() < 1e-9);
        assert!((rj - 16662.0 / 585.051).abs() < 1e-9);
    }

    #[test]
    fn bad_pixels_are_refused() {
        let cam = thor_camera::<f32>();
        let n = DetectionNoise {
            u_std: 1.0,
            v_std: 1.0,
            depth_std: 0.01,
            depth_std_per_m2: 0.0,
        };
        assert_eq!(
            cam.sighting(f32::NAN, 1.0, 1.0, &n).unwrap_err(),
            CameraError::NonFiniteInput
        );
        assert_eq!(
            cam.sighting(1.0, 1.0, 0.0, &n).unwrap_err(),
            CameraError::InvalidDepth
        );
        assert_eq!(
            cam.sighting(1.0, 1.0, -2.0, &n).unwrap_err(),
            CameraError::InvalidDepth
        );
        let bad = DetectionNoise {
            u_std: f32::INFINITY,
            ..n
        };
        assert_eq!(
            cam.sighting(1.0, 1.0, 1.0, &bad).unwrap_err(),
            CameraError::NonFiniteInput
        );
    }
}
