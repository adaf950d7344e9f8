//! The end points of one scan ([`ScanPoints`]), converted to the robot frame and weighted
//! once per scan for every particle's search.

use super::{MAX_WEIGHT, WEIGHT_ONE};
use crate::sensors::lidar::{BeamDirections, LidarScan};

/// A usable lidar end point in the robot frame with its correlation weight.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ScanPoint {
    /// x in the robot frame, metres.
    pub x: f32,
    /// y in the robot frame, metres.
    pub y: f32,
    /// Fixed-point weight `range^γ` ([`WEIGHT_ONE`] = 1.0).
    pub weight: u32,
    /// Measured range, metres.
    pub range: f32,
}

/// Up to `B` end points of one scan, prepared once per scan for all particles.
///
/// RAM: 24 · B bytes + 40 (the end points and the beam directions of the lidar,
/// [`BeamDirections`], kept from scan to scan).
#[derive(Clone, Debug)]
pub struct ScanPoints<const B: usize> {
    points: [ScanPoint; B],
    len: usize,
    thinned: bool,
    directions: BeamDirections<B>,
}

impl<const B: usize> Default for ScanPoints<B> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const B: usize> ScanPoints<B> {
    /// No points; all zero bytes (a `static` of it lives in `.bss`).
    pub const fn new() -> Self {
        Self {
            points: [ScanPoint {
                x: 0.0,
                y: 0.0,
                weight: 0,
                range: 0.0,
            }; B],
            len: 0,
            thinned: false,
            directions: BeamDirections::new(),
        }
    }

    /// Replaces the content with the usable beams of `scan`, every `decimation`-th one,
    /// weighted by `range^range_weight_exponent`. When more than `B` beams would be used,
    /// the decimation is raised until they fit ([`ScanPoints::was_thinned`] tells).
    /// Returns the number of points.
    pub fn load(
        &mut self,
        scan: &LidarScan<'_>,
        decimation: usize,
        range_weight_exponent: f32,
    ) -> usize {
        let mut dec = decimation.max(1);
        if B > 0 && scan.ranges.len().div_ceil(dec) > B {
            dec = scan.ranges.len().div_ceil(B);
        }
        self.thinned = dec != decimation.max(1);
        self.len = 0;
        if B == 0 {
            return 0;
        }
        let gamma = if range_weight_exponent.is_finite() {
            range_weight_exponent
        } else {
            0.0
        };
        for (slot, beam) in self
            .points
            .iter_mut()
            .zip(scan.beams_cached(dec, &mut self.directions))
        {
            let w = if gamma == 0.0 {
                1.0
            } else {
                libm::powf(beam.range, gamma)
            };
            let fixed = libm::roundf(w * WEIGHT_ONE as f32);
            let weight = if fixed.is_nan() || fixed < 1.0 {
                1
            } else if fixed >= MAX_WEIGHT as f32 {
                MAX_WEIGHT
            } else {
                fixed as u32
            };
            *slot = ScanPoint {
                x: beam.robot_point.0,
                y: beam.robot_point.1,
                weight,
                range: beam.range,
            };
            self.len += 1;
        }
        self.len
    }

    /// The points loaded.
    pub fn as_slice(&self) -> &[ScanPoint] {
        self.points.get(..self.len).unwrap_or(&[])
    }

    /// The robot-frame end points `(x, y)` loaded, in beam order (what
    /// [`crate::grid::OccupancyGrid::integrate_points`] writes).
    pub fn robot_points(&self) -> impl Iterator<Item = (f32, f32)> + Clone + '_ {
        self.as_slice().iter().map(|p| (p.x, p.y))
    }

    /// `true` when the last [`ScanPoints::load`] had to raise the decimation to fit `B`.
    pub fn was_thinned(&self) -> bool {
        self.thinned
    }
}
