//! Planar rigid-body geometry: poses in SE(2), composition, inversion, angle wrapping.
//!
//! Conventions used throughout the crate: x forward, y left, angles counter-clockwise
//! positive, in radians, wrapped to (−π, π].

use crate::scalar::Real;
/// `(sin x, cos x)` in `f32` arithmetic only: [`crate::scalar::sin_cos_f32`], which the
/// scalar type's own `sin_cos` uses too.
pub use crate::scalar::sin_cos_f32;

/// Largest |x| or |y| of a position the library works with, metres (100 km): beyond it
/// an `f32` coordinate is coarser than 8 mm. The EKF refuses steps that would go further
/// ([`crate::ekf::MAX_COORDINATE`]), and readers refuse positions and map origins beyond it.
pub const MAX_COORDINATE_M: f64 = 1.0e5;
use nalgebra::{Vector2, Vector3};

/// Wraps an angle to (−π, π].
///
/// Uses `atan2(sin a, cos a)`, which is exact at the branch cut's neighbourhood and needs no
/// loop for large inputs. A non-finite input gives NaN.
#[inline]
pub fn wrap_angle<T: Real>(angle: T) -> T {
    let (s, c) = angle.sin_cos();
    s.atan2(c)
}

/// Wraps an angle to (−π, π] without trigonometry when it is at most one turn outside:
/// an angle already in range comes back unchanged, one within (−3π, 3π] gains or loses
/// one turn (`2π`, one rounding); anything else goes through [`wrap_angle`].
///
/// For differences and small increments of wrapped angles (bearing innovations, a
/// heading after a correction) on a microcontroller, where `sin`, `cos` and `atan2` cost
/// thousands of instructions. A non-finite input gives NaN.
///
/// ```
/// use microslam::geometry::wrap_near;
/// use core::f64::consts::PI;
/// assert_eq!(wrap_near(0.5_f64), 0.5);
/// assert!((wrap_near(1.5 * PI) + 0.5 * PI).abs() < 1e-15);
/// assert!((wrap_near(-1.5 * PI) - 0.5 * PI).abs() < 1e-15);
/// assert_eq!(wrap_near(PI), PI);
/// assert!((wrap_near(-PI) - PI).abs() < 1e-15);
/// assert!((wrap_near(101.0 * PI) - PI).abs() < 1e-12);
/// ```
#[inline]
pub fn wrap_near<T: Real>(angle: T) -> T {
    let pi = T::lit(core::f64::consts::PI);
    let tau = T::lit(core::f64::consts::TAU);
    if angle > -pi && angle <= pi {
        angle
    } else if angle > pi && angle <= T::lit(3.0) * pi {
        let a = angle - tau;
        if a > -pi { a } else { pi }
    } else if angle <= -pi && angle > T::lit(-3.0) * pi {
        let a = angle + tau;
        if a <= pi { a } else { pi }
    } else {
        wrap_angle(angle)
    }
}

/// Distance from `origin` along the unit direction `(cos θ, sin θ)` to the nearest of
/// `walls`, each a segment `[x1, y1, x2, y2]`; `None` when the ray hits none.
///
/// The ray caster of simulated worlds (the simulator, tests, benchmarks and the cost
/// measurements of the firmware): a sensor model, not used by the estimators. A wall
/// parallel to the ray is never hit; a ray starting on a wall sees the next one.
///
/// ```
/// use microslam::geometry::ray_to_segments;
/// // A wall at x = 2 from y = −1 to 1, and one behind the origin.
/// let walls = [[2.0, -1.0, 2.0, 1.0], [-1.0, -1.0, -1.0, 1.0]];
/// assert_eq!(ray_to_segments((0.0_f64, 0.5), (1.0, 0.0), walls), Some(2.0));
/// assert_eq!(ray_to_segments((0.0_f64, 0.0), (0.0, 1.0), walls), None);
/// ```
pub fn ray_to_segments<T: Real>(
    origin: (T, T),
    direction: (T, T),
    walls: impl IntoIterator<Item = [T; 4]>,
) -> Option<T> {
    let (x, y) = origin;
    let (dx, dy) = direction;
    let mut nearest: Option<T> = None;
    for [x1, y1, x2, y2] in walls {
        let (ex, ey) = (x2 - x1, y2 - y1);
        let den = dx * ey - dy * ex;
        if den.abs() < T::lit(1e-12) {
            continue;
        }
        let (wx, wy) = (x1 - x, y1 - y);
        let t = (wx * ey - wy * ex) / den;
        let u = (wx * dy - wy * dx) / den;
        if t > T::ZERO && u >= T::ZERO && u <= T::lit(1.0) && nearest.is_none_or(|n| t < n) {
            nearest = Some(t);
        }
    }
    nearest
}

/// A pose in the plane: position `(x, y)` and heading `theta` (radians, CCW positive).
///
/// Read `a.compose(&b)` as "`b` expressed in frame `a`, taken to the frame `a` lives in":
/// the ⊕ operator of Smith, Self and Cheeseman.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Pose2<T> {
    /// Position along the x axis, metres.
    pub x: T,
    /// Position along the y axis, metres.
    pub y: T,
    /// Heading, radians, counter-clockwise from the x axis.
    pub theta: T,
}

impl<T: Real> Pose2<T> {
    /// The identity pose (origin, heading 0), usable in `const` contexts.
    pub const IDENTITY: Self = Self {
        x: T::ZERO,
        y: T::ZERO,
        theta: T::ZERO,
    };

    /// A pose from its components; the heading is stored as given (see [`Pose2::wrapped`]).
    #[inline]
    pub const fn new(x: T, y: T, theta: T) -> Self {
        Self { x, y, theta }
    }

    /// The pose as a column vector `[x, y, θ]`.
    #[inline]
    pub fn to_vector(&self) -> Vector3<T> {
        Vector3::new(self.x, self.y, self.theta)
    }

    /// A pose from a column vector `[x, y, θ]`.
    #[inline]
    pub fn from_vector(v: &Vector3<T>) -> Self {
        Self::new(v[0], v[1], v[2])
    }

    /// The same pose with its heading wrapped to (−π, π].
    #[inline]
    pub fn wrapped(&self) -> Self {
        Self::new(self.x, self.y, wrap_angle(self.theta))
    }

    /// The pose in another scalar type, through `f64` (exact from `f32` to `f64`; `f64` to
    /// `f32` rounds to nearest).
    #[inline]
    pub fn cast<U: Real>(&self) -> Pose2<U> {
        Pose2::new(
            U::lit(self.x.to_f64()),
            U::lit(self.y.to_f64()),
            U::lit(self.theta.to_f64()),
        )
    }

    /// `true` when all three components are finite.
    #[inline]
    pub fn is_finite(&self) -> bool {
        self.x.finite() && self.y.finite() && self.theta.finite()
    }

    /// Composition `self ⊕ other`: `other`, given in the frame of `self`, in the frame that
    /// `self` is expressed in. The heading of the result is wrapped.
    #[inline]
    pub fn compose(&self, other: &Self) -> Self {
        let p = self.compose_unwrapped(other, self.theta.sin_cos());
        Self::new(p.x, p.y, wrap_angle(p.theta))
    }

    /// [`Pose2::compose`] with `(sin θ, cos θ)` of `self`'s heading given (for a caller that
    /// has them already, e.g. for the Jacobians of the composition) and the heading of the
    /// result the plain sum, not wrapped.
    #[inline]
    pub fn compose_unwrapped(&self, other: &Self, (s, c): (T, T)) -> Self {
        Self::new(
            self.x + c * other.x - s * other.y,
            self.y + s * other.x + c * other.y,
            self.theta + other.theta,
        )
    }

    /// Inverse `⊖self`: the pose of the outer frame seen from `self`.
    #[inline]
    pub fn inverse(&self) -> Self {
        let (s, c) = self.theta.sin_cos();
        Self::new(
            -c * self.x - s * self.y,
            s * self.x - c * self.y,
            wrap_angle(-self.theta),
        )
    }

    /// The relative pose `⊖self ⊕ other`: `other` seen from `self`.
    #[inline]
    pub fn between(&self, other: &Self) -> Self {
        self.inverse().compose(other)
    }

    /// Transforms a point given in this pose's frame into the outer frame.
    #[inline]
    pub fn transform_point(&self, p: &Vector2<T>) -> Vector2<T> {
        let (s, c) = self.theta.sin_cos();
        Vector2::new(self.x + c * p[0] - s * p[1], self.y + s * p[0] + c * p[1])
    }

    /// Transforms a point given in the outer frame into this pose's frame.
    #[inline]
    pub fn inverse_transform_point(&self, p: &Vector2<T>) -> Vector2<T> {
        let (s, c) = self.theta.sin_cos();
        let dx = p[0] - self.x;
        let dy = p[1] - self.y;
        Vector2::new(c * dx + s * dy, -s * dx + c * dy)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sin_cos_f32_matches_f64() {
        let mut worst = 0.0f64;
        for i in -200_000..=200_000 {
            let x = i as f32 * 5e-4; // −100 … 100 rad
            let (s, c) = sin_cos_f32(x);
            let (es, ec) = f64::from(x).sin_cos();
            worst = worst
                .max((f64::from(s) - es).abs())
                .max((f64::from(c) - ec).abs());
        }
        assert!(worst < 2e-7, "worst error {worst}");
        for x in [
            0.0f32,
            core::f32::consts::FRAC_PI_2,
            core::f32::consts::PI,
            -3.0,
        ] {
            let (s, c) = sin_cos_f32(x);
            assert!((s * s + c * c - 1.0).abs() < 4e-7, "{x}");
        }
        assert!(sin_cos_f32(f32::NAN).0.is_nan() && sin_cos_f32(f32::INFINITY).1.is_nan());
    }
    use core::f64::consts::PI;

    fn close(a: &Pose2<f64>, b: &Pose2<f64>) -> bool {
        (a.x - b.x).abs() < 1e-12
            && (a.y - b.y).abs() < 1e-12
            && wrap_angle(a.theta - b.theta).abs() < 1e-12
    }

    #[test]
    fn wrap_angle_range() {
        for k in -20..=20 {
            let a = 0.3 + f64::from(k) * 2.0 * PI;
            assert!((wrap_angle(a) - 0.3).abs() < 1e-9, "{k}");
        }
        assert!((wrap_angle(PI) - PI).abs() < 1e-15);
        assert!(wrap_angle(-PI + 1e-9) > -PI);
        assert!(wrap_angle(f64::NAN).is_nan());
    }

    #[test]
    fn compose_known_values() {
        let a = Pose2::new(1.0, 2.0, PI / 2.0);
        let b = Pose2::new(1.0, 0.0, 0.0);
        // One metre forward while facing +y moves along +y.
        assert!(close(&a.compose(&b), &Pose2::new(1.0, 3.0, PI / 2.0)));
    }

    #[test]
    fn inverse_and_between() {
        let a = Pose2::new(1.0, -2.0, 0.7);
        let b = Pose2::new(-3.0, 0.5, -2.9);
        assert!(close(&a.compose(&a.inverse()), &Pose2::IDENTITY));
        assert!(close(&a.compose(&a.between(&b)), &b));
        let p = Vector2::new(0.3, -1.1);
        let q = a.inverse_transform_point(&a.transform_point(&p));
        assert!((p - q).norm() < 1e-12);
    }
}
