//! Wheel encoders of a four-wheel differential (skid-steer) drive → travelled distances →
//! linear and angular velocity `(v, ω)` (Du n.d., §III: "velocity from the encoders").
//!
//! Each side's distance is the mean of its two wheels: right = (FR + RR)/2 · metres per
//! tick, left = (FL + RL)/2 · metres per tick. Over an interval of `dt` seconds,
//! `v = (right + left) / (2 dt)` and `ω = (right − left) / (track · dt)`.
//! The geometry is configuration; [`DiffDriveGeometry::THOR`] holds the UCSD THOR robot.
//!
//! # References
//!
//! - Du, C. (n.d.). *ECE 276 Project: Particle Filter SLAM*. Undated report, University of
//!   California, San Diego. The velocity from the encoders, §III.

use crate::scalar::Real;
use core::fmt;

/// Encoder ticks of the four wheels counted over one interval.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct WheelTicks {
    /// Front right.
    pub front_right: i32,
    /// Front left.
    pub front_left: i32,
    /// Rear right.
    pub rear_right: i32,
    /// Rear left.
    pub rear_left: i32,
}

impl WheelTicks {
    /// Ticks in THOR's `.npz` order `[FR, FL, RR, RL]`.
    #[inline]
    pub const fn from_thor_order(counts: [i32; 4]) -> Self {
        Self {
            front_right: counts[0],
            front_left: counts[1],
            rear_right: counts[2],
            rear_left: counts[3],
        }
    }
}

/// Geometry of a differential drive.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DiffDriveGeometry<T> {
    /// Distance a wheel rolls per encoder tick, metres.
    pub metres_per_tick: T,
    /// Distance between the left and right wheel centres (effective track), metres.
    pub track_width: T,
}

impl DiffDriveGeometry<f64> {
    /// THOR: wheel diameter 0.254 m, 360 ticks per revolution → 0.0022 m per tick (the
    /// robot's documentation rounds π·0.254/360 = 0.002217 to 0.0022); track ≈ 0.3937 m,
    /// the mean of the 311.15 mm inner and 476.25 mm outer widths.
    pub const THOR: Self = Self {
        metres_per_tick: 0.0022,
        track_width: 0.3937,
    };
}

/// Why encoder ticks could not be turned into a motion.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum OdometryError {
    /// The interval is not a positive finite number of seconds.
    InvalidInterval,
    /// The geometry has a non-positive or non-finite tick size or track width.
    InvalidGeometry,
}

impl fmt::Display for OdometryError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::InvalidInterval => "odometry interval is not positive and finite",
            Self::InvalidGeometry => "wheel geometry is not positive and finite",
        })
    }
}

impl core::error::Error for OdometryError {}

/// Distance travelled and heading change over one encoder interval.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct WheelMotion<T> {
    /// Distance of the left side, metres.
    pub left: T,
    /// Distance of the right side, metres.
    pub right: T,
    /// Distance of the robot centre `(left + right)/2`, metres.
    pub distance: T,
    /// Heading change `(right − left)/track`, radians.
    pub heading_change: T,
}

impl<T: Real> DiffDriveGeometry<T> {
    /// `true` when both lengths are positive and finite.
    pub fn is_valid(&self) -> bool {
        self.metres_per_tick.finite()
            && self.track_width.finite()
            && self.metres_per_tick > T::ZERO
            && self.track_width > T::ZERO
    }

    /// Side distances, centre distance and heading change of one interval.
    pub fn motion(&self, ticks: &WheelTicks) -> Result<WheelMotion<T>, OdometryError> {
        if !self.is_valid() {
            return Err(OdometryError::InvalidGeometry);
        }
        let half = T::lit(0.5);
        let right = T::lit(f64::from(ticks.front_right) + f64::from(ticks.rear_right))
            * half
            * self.metres_per_tick;
        let left = T::lit(f64::from(ticks.front_left) + f64::from(ticks.rear_left))
            * half
            * self.metres_per_tick;
        Ok(WheelMotion {
            left,
            right,
            distance: (left + right) * half,
            heading_change: (right - left) / self.track_width,
        })
    }

    /// Linear and angular velocity `(v, ω)` over an interval of `dt` seconds.
    pub fn velocity(&self, ticks: &WheelTicks, dt: T) -> Result<(T, T), OdometryError> {
        if !dt.finite() || dt <= T::ZERO {
            return Err(OdometryError::InvalidInterval);
        }
        let m = self.motion(ticks)?;
        Ok((m.distance / dt, m.heading_change / dt))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn straight_and_turning() {
        let g = DiffDriveGeometry::THOR;
        // 100 ticks on every wheel in 0.025 s: 0.22 m straight ahead.
        let t = WheelTicks::from_thor_order([100, 100, 100, 100]);
        let m = g.motion(&t).unwrap();
        assert!((m.distance - 0.22).abs() < 1e-12 && m.heading_change == 0.0);
        let (v, w) = g.velocity(&t, 0.025).unwrap();
        assert!((v - 8.8).abs() < 1e-9 && w == 0.0);
        // Right side forward, left side back by the same amount: a turn on the spot, left.
        let t = WheelTicks::from_thor_order([10, -10, 12, -12]);
        let m = g.motion(&t).unwrap();
        assert!(m.distance.abs() < 1e-15);
        assert!((m.right - 0.0242).abs() < 1e-12 && (m.left + 0.0242).abs() < 1e-12);
        assert!((m.heading_change - 2.0 * 0.0242 / 0.3937).abs() < 1e-12);
    }

    #[test]
    fn bad_inputs_are_errors() {
        let g = DiffDriveGeometry::<f32> {
            metres_per_tick: 0.0022,
            track_width: 0.39,
        };
        let t = WheelTicks::default();
        assert_eq!(g.velocity(&t, 0.0), Err(OdometryError::InvalidInterval));
        assert_eq!(
            g.velocity(&t, f32::NAN),
            Err(OdometryError::InvalidInterval)
        );
        let bad = DiffDriveGeometry {
            track_width: 0.0,
            ..g
        };
        assert_eq!(bad.velocity(&t, 0.1), Err(OdometryError::InvalidGeometry));
        // Extreme tick counts stay finite.
        let huge = WheelTicks::from_thor_order([i32::MAX, i32::MIN, i32::MAX, i32::MIN]);
        let (v, w) = g.velocity(&huge, 0.025).unwrap();
        assert!(v.is_finite() && w.is_finite());
    }
}
