//! Prediction: the differential-drive model of Du (n.d., eq. 6) driven by a noisy input.
//!
//! The input of one step is the arc the robot drove: distance `d` along the arc and
//! heading change `Δθ` (from encoders: `d = v·τ`, `Δθ = ω·τ`; from odometry poses:
//! [`arc_between`]). Each particle draws its own input
//! `d̃ = d + σ_d·n₁`, `Δθ̃ = Δθ + σ_θ·n₂` (and an optional sideways slip `σ_s·n₃`), then
//! moves along the arc: chord `d̃·sinc(Δθ̃/2)` in the direction `θ + Δθ̃/2`.
//!
//! The noise of Du (n.d., §III-C) is `σ = 0.5·|input|`, which is zero when driving
//! straight and lets the heading drift uncorrected between turns; [`MotionNoise`] adds
//! floors and noise that grows with the distance driven (see `DESIGN.md`).
//!
//! # References
//!
//! - Du, C. (n.d.). *ECE 276 Project: Particle Filter SLAM*. Undated report, University of
//!   California, San Diego. The motion model, eq. 6, and its input noise, §III-C.

use crate::error::InvalidSetting;
use crate::geometry::Pose2;

/// Standard deviations of the input noise of one step.
///
/// σ_d = `distance_std` + `distance_std_per_metre`·|d| + `distance_std_per_radian`·|Δθ|,
/// σ_θ = `heading_std` + `heading_std_per_radian`·|Δθ| + `heading_std_per_metre`·|d|,
/// σ_s = `sideways_std_per_metre`·|d|.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct MotionNoise {
    /// Distance noise per step, metres.
    pub distance_std: f32,
    /// Distance noise per metre driven.
    pub distance_std_per_metre: f32,
    /// Distance noise per radian turned, metres per radian.
    pub distance_std_per_radian: f32,
    /// Heading noise per step, radians.
    pub heading_std: f32,
    /// Heading noise per radian turned.
    pub heading_std_per_radian: f32,
    /// Heading noise per metre driven, radians per metre.
    pub heading_std_per_metre: f32,
    /// Sideways slip per metre driven.
    pub sideways_std_per_metre: f32,
}

impl MotionNoise {
    /// Noise proportional to the input and nothing else: σ = 0.5·|input|, no floors, no
    /// heading noise per metre, no slip. It reproduces the setting of Du (n.d.); diverges on
    /// the Intel log (see `DESIGN.md`).
    pub const PROPORTIONAL: Self = Self {
        distance_std: 0.0,
        distance_std_per_metre: 0.5,
        distance_std_per_radian: 0.0,
        heading_std: 0.0,
        heading_std_per_radian: 0.5,
        heading_std_per_metre: 0.0,
        sideways_std_per_metre: 0.0,
    };

    /// Realistic noise for a wheeled indoor robot at ~5–10 Hz scan rate (tuned on the
    /// Intel log): 2 mm + 10 %/m distance, 0.2° per step + 10 % of the turn + 3°/m
    /// heading, 2 % sideways.
    pub const INDOOR: Self = Self {
        distance_std: 0.002,
        distance_std_per_metre: 0.1,
        distance_std_per_radian: 0.0,
        heading_std: 0.0035,
        heading_std_per_radian: 0.1,
        heading_std_per_metre: 0.05,
        sideways_std_per_metre: 0.02,
    };

    /// `true` when every figure is finite and non-negative.
    pub fn is_valid(&self) -> bool {
        self.invalid_setting().is_none()
    }

    /// The first figure that is negative or not finite, `None` when every one is valid.
    #[inline]
    pub fn invalid_setting(&self) -> Option<InvalidSetting> {
        let non_negative = InvalidSetting::non_negative;
        InvalidSetting::first([
            non_negative("distance_std", self.distance_std),
            non_negative("distance_std_per_metre", self.distance_std_per_metre),
            non_negative("distance_std_per_radian", self.distance_std_per_radian),
            non_negative("heading_std", self.heading_std),
            non_negative("heading_std_per_radian", self.heading_std_per_radian),
            non_negative("heading_std_per_metre", self.heading_std_per_metre),
            non_negative("sideways_std_per_metre", self.sideways_std_per_metre),
        ])
    }

    /// `(σ_d, σ_θ, σ_s)` for one step.
    #[inline]
    pub fn std_devs(&self, distance: f32, heading_change: f32) -> (f32, f32, f32) {
        let d = distance.abs();
        let t = heading_change.abs();
        (
            self.distance_std + self.distance_std_per_metre * d + self.distance_std_per_radian * t,
            self.heading_std + self.heading_std_per_radian * t + self.heading_std_per_metre * d,
            self.sideways_std_per_metre * d,
        )
    }
}

/// `sin(h)/h`, exact near 0.
#[inline]
fn sinc(h: f32) -> f32 {
    if h.abs() < 1e-3 {
        1.0 - h * h / 6.0
    } else {
        crate::geometry::sin_cos_f32(h).0 / h
    }
}

/// Wraps to (−π, π] (cheap when already inside, libm otherwise: same on every target).
/// `sincosf` gives bit for bit what `sinf` and `cosf` give (checked over every `f32`), and
/// a firmware that calls only it carries one copy of the kernels (3.3 KB less flash).
#[inline]
pub fn wrap(a: f32) -> f32 {
    use core::f32::consts::PI;
    if a > -PI && a <= PI {
        a
    } else {
        let (s, c) = libm::sincosf(a);
        libm::atan2f(s, c)
    }
}

/// Moves `pose` along the arc `(distance, heading_change)` plus a sideways slip (Du
/// n.d., eq. 6 with τ = 1).
#[inline]
pub fn drive_arc(
    pose: &Pose2<f32>,
    distance: f32,
    heading_change: f32,
    sideways: f32,
) -> Pose2<f32> {
    let half = 0.5 * heading_change;
    let chord = distance * sinc(half);
    let (s, c) = crate::geometry::sin_cos_f32(pose.theta + half);
    Pose2::new(
        pose.x + chord * c - sideways * s,
        pose.y + chord * s + sideways * c,
        wrap(pose.theta + heading_change),
    )
}

/// The arc `(distance, heading_change)` that takes odometry pose `from` to `to`: the inverse
/// of [`drive_arc`] (the sideways part of the odometry step is dropped: tiny for steps a
/// few centimetres long, tens of millimetres for steps a metre long). Signed: driving
/// backwards gives a negative distance.
pub fn arc_between(from: &Pose2<f32>, to: &Pose2<f32>) -> (f32, f32) {
    let dth = wrap(to.theta - from.theta);
    let (s, c) = libm::sincosf(from.theta + 0.5 * dth);
    let chord = c * (to.x - from.x) + s * (to.y - from.y);
    (chord / sinc(0.5 * dth), dth)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arc_round_trip() {
        let from = Pose2::new(1.0, -2.0, 3.0f32);
        for (d, t) in [(0.3f32, 0.2f32), (-0.2, -0.5), (0.0, 1.0), (0.5, 0.0)] {
            let to = drive_arc(&from, d, t, 0.0);
            let (d2, t2) = arc_between(&from, &to);
            assert!(
                (d - d2).abs() < 1e-5 && (t - t2).abs() < 1e-5,
                "{d} {t} → {d2} {t2}"
            );
        }
        // A quarter circle of radius 1 from the origin ends at (1, 1) facing +y.
        let end = drive_arc(
            &Pose2::IDENTITY,
            core::f32::consts::FRAC_PI_2,
            core::f32::consts::FRAC_PI_2,
            0.0,
        );
        assert!((end.x - 1.0).abs() < 1e-6 && (end.y - 1.0).abs() < 1e-6);
    }

    #[test]
    fn noise_model() {
        let (sd, st, ss) = MotionNoise::PROPORTIONAL.std_devs(0.2, 0.0);
        assert!((sd - 0.1).abs() < 1e-7 && st == 0.0 && ss == 0.0);
        let (sd, st, ss) = MotionNoise::INDOOR.std_devs(-1.0, 0.5);
        assert!((sd - 0.102).abs() < 1e-6);
        assert!((st - (0.0035 + 0.05 + 0.05)).abs() < 1e-6);
        assert!((ss - 0.02).abs() < 1e-7);
        assert!(
            !MotionNoise {
                heading_std: f32::NAN,
                ..MotionNoise::PROPORTIONAL
            }
            .is_valid()
        );
        assert!(wrap(4.0) < 0.0 && (wrap(4.0) - (4.0 - 2.0 * core::f32::consts::PI)).abs() < 1e-6);
    }
}
