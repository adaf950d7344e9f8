//! A planar scanning range finder (2-D lidar): scan geometry, mount pose, which readings
//! are usable, and the transforms scan → robot → world.
//!
//! A [`LidarScan`] borrows its ranges (no copy, no allocation): beam `i` points at
//! `first_angle + i · angle_increment` in the sensor frame (counter-clockwise positive,
//! x forward). A reading is used when it is finite and inside `[min_range, max_range)`;
//! readings at or above `no_return_range` mean "nothing was hit" (CARMEN/SICK: 81.8 m)
//! and are skipped like every other unusable reading ([`BeamStatus`] says why).
//!
//! The grid filter works in `f32` (5 cm cells need no more), so this module does too.

use crate::geometry::Pose2;

/// Fixed geometry of a lidar: beam angles, usable ranges and where it sits on the robot.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LidarGeometry {
    /// Angle of the first beam in the sensor frame, radians.
    pub first_angle: f32,
    /// Angle between consecutive beams, radians (negative for clockwise scanners).
    pub angle_increment: f32,
    /// Shorter readings are dropped (the sensor's blind zone, the robot's own body), metres.
    pub min_range: f32,
    /// Readings at or beyond this are dropped (unreliable), metres.
    pub max_range: f32,
    /// Readings at or beyond this mean "no return" (CARMEN: 81.8 m), metres.
    pub no_return_range: f32,
    /// Pose of the sensor in the robot frame.
    pub mount: Pose2<f32>,
}

impl LidarGeometry {
    /// The SICK LMS of the Intel Research Lab and ACES CARMEN logs: 180 beams from −90°,
    /// 1° apart, no return at ≥ 81.8 m, mounted at the robot origin.
    pub const CARMEN_SICK_180: Self = Self {
        first_angle: -core::f32::consts::FRAC_PI_2,
        angle_increment: core::f32::consts::PI / 180.0,
        min_range: 0.1,
        max_range: 81.8,
        no_return_range: 81.8,
        mount: Pose2::new(0.0, 0.0, 0.0),
    };

    /// THOR's Hokuyo UTM-30LX: 1081 beams from −135° in 0.25° steps, ranges kept in
    /// 0.1–30 m, mounted 0.29833 m ahead of the rear axle (the robot origin), yaw 0.
    pub const THOR_HOKUYO: Self = Self {
        first_angle: -135.0 * core::f32::consts::PI / 180.0,
        angle_increment: 0.25 * core::f32::consts::PI / 180.0,
        min_range: 0.1,
        max_range: 30.0,
        no_return_range: f32::INFINITY,
        mount: Pose2::new(0.29833, 0.0, 0.0),
    };

    /// Angle of beam `index` in the sensor frame, radians.
    #[inline]
    pub fn beam_angle(&self, index: usize) -> f32 {
        self.first_angle + self.angle_increment * index as f32
    }

    /// Whether a reading can be used, and if not, why.
    #[inline]
    pub fn classify(&self, range: f32) -> BeamStatus {
        if !range.is_finite() {
            BeamStatus::NotFinite
        } else if range >= self.no_return_range {
            BeamStatus::NoReturn
        } else if range < self.min_range || range >= self.max_range {
            BeamStatus::OutOfRange
        } else {
            BeamStatus::Valid
        }
    }

    /// `true` when every field is finite (the no-return range may be +∞) and the range
    /// limits are ordered.
    pub fn is_valid(&self) -> bool {
        self.first_angle.is_finite()
            && self.angle_increment.is_finite()
            && self.min_range.is_finite()
            && self.min_range >= 0.0
            && self.max_range > self.min_range
            && !self.no_return_range.is_nan()
            && self.mount.is_finite()
    }
}

/// Why a reading is used or skipped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BeamStatus {
    /// Usable.
    Valid,
    /// NaN or ±∞.
    NotFinite,
    /// At or beyond the no-return range: nothing was hit.
    NoReturn,
    /// Shorter than `min_range` or at/beyond `max_range`.
    OutOfRange,
}

/// One scan: borrowed ranges (metres) and the geometry they were taken with.
#[derive(Clone, Copy, Debug)]
pub struct LidarScan<'a> {
    /// Ranges, beam 0 first.
    pub ranges: &'a [f32],
    /// Beam angles, range limits and mount pose.
    pub geometry: LidarGeometry,
}

/// A usable reading: its beam index, range and end point in the sensor and robot frames.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Beam {
    /// Index of the beam in the scan.
    pub index: usize,
    /// Measured range, metres.
    pub range: f32,
    /// End point in the sensor frame `(x, y)`, metres.
    pub sensor_point: (f32, f32),
    /// End point in the robot frame `(x, y)`, metres.
    pub robot_point: (f32, f32),
}

impl<'a> LidarScan<'a> {
    /// A scan over borrowed ranges.
    #[inline]
    pub const fn new(ranges: &'a [f32], geometry: LidarGeometry) -> Self {
        Self { ranges, geometry }
    }

    /// The usable beams, taking every `decimation`-th beam (1 or 0 = all), in beam order.
    pub fn beams(&self, decimation: usize) -> impl Iterator<Item = Beam> + Clone + '_ {
        let g = self.geometry;
        self.beams_with(decimation, move |index| libm::sincosf(g.beam_angle(index)))
    }

    /// [`LidarScan::beams`] with the beam directions `(sin, cos)` looked up in a table
    /// prepared for this geometry and decimation ([`BeamDirections::prepare`]) instead of
    /// computed per beam: the same beams, bit for bit, without one `sincosf` per beam.
    /// A table prepared for another geometry or decimation is prepared anew here.
    pub fn beams_cached<'s, const B: usize>(
        &'s self,
        decimation: usize,
        table: &'s mut BeamDirections<B>,
    ) -> impl Iterator<Item = Beam> + Clone + 's {
        table.prepare(&self.geometry, self.ranges.len(), decimation);
        let table: &'s BeamDirections<B> = table;
        let g = self.geometry;
        let dec = decimation.max(1);
        self.beams_with(decimation, move |index| {
            table
                .get(index / dec)
                .unwrap_or_else(|| libm::sincosf(g.beam_angle(index)))
        })
    }

    /// The usable beams with the direction `(sin, cos)` of beam `index` given by
    /// `direction`: the one place where ranges become end points.
    fn beams_with<'s>(
        &'s self,
        decimation: usize,
        direction: impl Fn(usize) -> (f32, f32) + Clone + 's,
    ) -> impl Iterator<Item = Beam> + Clone + 's {
        let g = self.geometry;
        let (ms, mc) = libm::sincosf(g.mount.theta);
        self.ranges
            .iter()
            .enumerate()
            .step_by(decimation.max(1))
            .filter(move |(_, r)| g.classify(**r) == BeamStatus::Valid)
            .map(move |(index, &range)| {
                let (s, c) = direction(index);
                let sensor_point = (range * c, range * s);
                let robot_point = (
                    g.mount.x + mc * sensor_point.0 - ms * sensor_point.1,
                    g.mount.y + ms * sensor_point.0 + mc * sensor_point.1,
                );
                Beam {
                    index,
                    range,
                    sensor_point,
                    robot_point,
                }
            })
    }

    /// How many readings of the whole scan fall in each [`BeamStatus`]:
    /// `(valid, not_finite, no_return, out_of_range)`.
    pub fn census(&self) -> (usize, usize, usize, usize) {
        let mut n = (0, 0, 0, 0);
        for r in self.ranges {
            match self.geometry.classify(*r) {
                BeamStatus::Valid => n.0 += 1,
                BeamStatus::NotFinite => n.1 += 1,
                BeamStatus::NoReturn => n.2 += 1,
                BeamStatus::OutOfRange => n.3 += 1,
            }
        }
        n
    }
}

/// The directions `(sin, cos)` of the beams of one lidar geometry, every `decimation`-th
/// beam, for up to `B` beams: computed once, then looked up for every scan of that
/// geometry ([`LidarScan::beams_cached`]). On a Cortex-M4F each `sincosf` costs
/// about a thousand instructions (its kernels use `f64`, which the FPU lacks), so a
/// 90-beam scan saves ~10⁵ instructions per use.
///
/// RAM: `8 · B` bytes plus 20.
#[derive(Clone, Debug)]
pub struct BeamDirections<const B: usize> {
    directions: [(f32, f32); B],
    len: usize,
    key: Option<(u32, u32, usize)>,
}

impl<const B: usize> Default for BeamDirections<B> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const B: usize> BeamDirections<B> {
    /// An empty table (prepared on first use), of all zero bytes (a `static` of it lives
    /// in `.bss`).
    pub const fn new() -> Self {
        Self {
            directions: [(0.0, 0.0); B],
            len: 0,
            key: None,
        }
    }

    /// Fills the table for a scan of `count` readings taken with `geometry`, every
    /// `decimation`-th one (nothing is recomputed when it already holds them). Beams past
    /// the first `B` are left out of the table ([`BeamDirections::get`] answers `None`).
    pub fn prepare(&mut self, geometry: &LidarGeometry, count: usize, decimation: usize) {
        let dec = decimation.max(1);
        let key = (
            geometry.first_angle.to_bits(),
            geometry.angle_increment.to_bits(),
            dec,
        );
        let len = count.div_ceil(dec).min(B);
        if self.key == Some(key) && self.len >= len {
            return;
        }
        for (slot, d) in self.directions.iter_mut().take(len).enumerate() {
            *d = libm::sincosf(geometry.beam_angle(slot * dec));
        }
        self.len = len;
        self.key = Some(key);
    }

    /// `(sin, cos)` of the `slot`-th beam taken (beam index `slot · decimation`), `None`
    /// past the prepared ones.
    #[inline]
    pub fn get(&self, slot: usize) -> Option<(f32, f32)> {
        if slot < self.len {
            self.directions.get(slot).copied()
        } else {
            None
        }
    }
}

/// Takes a point from the robot frame to the world frame, the robot being at `pose`.
#[inline]
pub fn robot_to_world(pose: &Pose2<f32>, point: (f32, f32)) -> (f32, f32) {
    let (s, c) = libm::sincosf(pose.theta);
    (
        pose.x + c * point.0 - s * point.1,
        pose.y + s * point.0 + c * point.1,
    )
}

/// Pose of the sensor in the world frame, the robot being at `pose`.
#[inline]
pub fn sensor_pose(pose: &Pose2<f32>, mount: &Pose2<f32>) -> Pose2<f32> {
    let (x, y) = robot_to_world(pose, (mount.x, mount.y));
    Pose2::new(x, y, pose.theta + mount.theta)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cached_directions_give_the_same_beams() {
        let g = LidarGeometry {
            mount: Pose2::new(0.1, 0.02, 0.05),
            ..LidarGeometry::CARMEN_SICK_180
        };
        let ranges: Vec<f32> = (0..181).map(|i| 0.5 + (i % 13) as f32 * 0.4).collect();
        let mut table = BeamDirections::<100>::new();
        for dec in [2, 3, 2, 1] {
            let scan = LidarScan::new(&ranges, g);
            let plain: Vec<Beam> = scan.beams(dec).collect();
            let cached: Vec<Beam> = scan.beams_cached(dec, &mut table).collect();
            assert_eq!(plain, cached, "decimation {dec}");
        }
        // A table too small for the scan falls back to computing the rest.
        let mut small = BeamDirections::<10>::new();
        let scan = LidarScan::new(&ranges, g);
        let cached: Vec<Beam> = scan.beams_cached(1, &mut small).collect();
        assert_eq!(cached, scan.beams(1).collect::<Vec<_>>());
        assert_eq!(small.get(10), None);
        // Another geometry prepares the table anew.
        let other = LidarScan::new(
            &ranges,
            LidarGeometry {
                first_angle: 0.3,
                ..g
            },
        );
        let cached: Vec<Beam> = other.beams_cached(2, &mut table).collect();
        assert_eq!(cached, other.beams(2).collect::<Vec<_>>());
    }

    #[test]
    fn classification_and_decimation() {
        let g = LidarGeometry::CARMEN_SICK_180;
        let ranges = [1.0, f32::NAN, 81.9, 0.05, 2.0, f32::INFINITY, 3.0];
        let scan = LidarScan::new(&ranges, g);
        assert_eq!(scan.census(), (3, 2, 1, 1));
        let idx: Vec<usize> = scan.beams(1).map(|b| b.index).collect();
        assert_eq!(idx, vec![0, 4, 6]);
        let idx: Vec<usize> = scan.beams(2).map(|b| b.index).collect();
        assert_eq!(idx, vec![0, 4, 6]);
        let idx: Vec<usize> = scan.beams(3).map(|b| b.index).collect();
        assert_eq!(idx, vec![0, 6]);
        assert_eq!(scan.beams(0).count(), 3);
    }

    #[test]
    fn geometry_of_points() {
        // Beam 90 of the SICK scan looks straight ahead; beam 0 to the right (−y).
        let mut g = LidarGeometry::CARMEN_SICK_180;
        let mut ranges = [0.0f32; 181];
        ranges[0] = 2.0;
        ranges[90] = 3.0;
        let scan = LidarScan::new(&ranges, g);
        let beams: Vec<Beam> = scan.beams(1).collect();
        assert!(
            (beams[0].sensor_point.0).abs() < 1e-6 && (beams[0].sensor_point.1 + 2.0).abs() < 1e-6
        );
        assert!(
            (beams[1].sensor_point.0 - 3.0).abs() < 1e-6 && beams[1].sensor_point.1.abs() < 1e-6
        );
        // Mounted 0.3 m ahead and turned left by 90°: straight ahead of the sensor is +y.
        g.mount = Pose2::new(0.3, 0.0, core::f32::consts::FRAC_PI_2);
        let scan = LidarScan::new(&ranges, g);
        let b = scan.beams(1).nth(1).unwrap();
        assert!((b.robot_point.0 - 0.3).abs() < 1e-6 && (b.robot_point.1 - 3.0).abs() < 1e-6);
        // Robot at (1, 2) facing −x: the point lands at (0.7, −1).
        let w = robot_to_world(&Pose2::new(1.0, 2.0, core::f32::consts::PI), b.robot_point);
        assert!(
            (w.0 - 0.7).abs() < 1e-5 && (w.1 + 1.0).abs() < 1e-5,
            "{w:?}"
        );
        let s = sensor_pose(&Pose2::new(1.0, 2.0, core::f32::consts::PI), &g.mount);
        assert!((s.x - 0.7).abs() < 1e-6 && (s.y - 2.0).abs() < 1e-5);
    }

    #[test]
    fn invalid_geometry_is_detected() {
        let mut g = LidarGeometry::THOR_HOKUYO;
        assert!(g.is_valid());
        g.max_range = 0.0;
        assert!(!g.is_valid());
        g = LidarGeometry::THOR_HOKUYO;
        g.first_angle = f32::NAN;
        assert!(!g.is_valid());
    }
}
