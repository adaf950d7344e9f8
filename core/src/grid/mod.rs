//! Occupancy grids of saturating integer log-odds (Du n.d., §II-B).
//!
//! - [`GridGeometry`]: size in cells, resolution and the world position of the grid's
//!   lower-left corner (the ROS `map_server` convention: cell `(0, 0)` spans
//!   `[origin_x, origin_x + resolution) × [origin_y, origin_y + resolution)`, rows grow
//!   with y). World ↔ cell conversions are bounds-checked.
//! - [`LogOdds`]: the integer log-odds arithmetic: +log 4 per hit, −log 4 per pass of a
//!   free ray, saturating at configurable limits, occupied/free thresholds ±2 log 4.
//! - [`OccupancyGrid`]: a fixed `W × H` grid of `i8` cells (one byte per cell: a 256 × 256
//!   grid is 64 KB), built in place with a `const fn` so it can live in a `static`; writes
//!   scans with Bresenham rays; end points off the grid are skipped and counted. Optionally
//!   it keeps a bitmap of its occupied cells ([`occupancy_bytes`]; 8 KB more for
//!   256 × 256), which makes the particle filter's shift search sparse.
//! - [`OccupancyBitmap`]: a fixed `W × H` bitmap of occupied cells placed in the world
//!   (an eighth of the bytes of log-odds cells), which scrolls with the robot like an
//!   [`OccupancyGrid`] ([`OccupancyGrid::scroll`]): the far part of grid SLAM's local map.
//! - [`GridView`]: a borrowed read-only map (`&[i8]` + geometry), e.g. a `&'static` map in
//!   flash, which is what the particle filter scores scans against.
//! - [`MaxPoolLayers`]: max-pooled copies of a map (any occupied cell in each `2^k × 2^k`
//!   window) and its free blocks, in one byte image for flash or RAM: the bounds of the
//!   global search ([`crate::pf::global`]).
//! - `map_image` (feature `map-image`): a map as one versioned, checksummed binary image
//!   for flash, read in place.
//! - `ros_map` (feature `std`): reading a ROS `map_server` map (`map.yaml` + PGM).
//!
//! # References
//!
//! - Du, C. (n.d.). *ECE 276 Project: Particle Filter SLAM*. Undated report, University of
//!   California, San Diego. The log-odds occupancy grid, §II-B.

mod bitmap;
mod bresenham;
pub mod layers;
#[cfg(feature = "map-image")]
pub mod map_image;
mod occupancy;
#[cfg(feature = "std")]
pub mod ros_map;
mod scroll;
mod view;

pub use bitmap::OccupancyBitmap;
pub use bresenham::Bresenham;
pub use layers::{LayersError, MaxPoolLayers};
#[cfg(feature = "map-image")]
pub use map_image::{MapImage, MapImageError};
pub use occupancy::{OccupancyGrid, ScanIntegration};
pub use view::{GridView, fill_occupancy_bits};

use core::fmt;

/// Size, resolution and placement of a grid in the world.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GridGeometry {
    /// Number of columns (cells along x).
    pub width: usize,
    /// Number of rows (cells along y).
    pub height: usize,
    /// Edge length of a cell, metres (Du n.d.: 0.05).
    pub resolution: f32,
    /// World x of the left edge of column 0, metres.
    pub origin_x: f32,
    /// World y of the bottom edge of row 0, metres.
    pub origin_y: f32,
}

impl GridGeometry {
    /// `0 × 0` cells of size 0 at the origin: every cell off the map; the zero bytes of
    /// a grid in a `static` until its geometry is set.
    pub const ZEROED: Self = Self {
        width: 0,
        height: 0,
        resolution: 0.0,
        origin_x: 0.0,
        origin_y: 0.0,
    };

    /// A `width × height` grid of `resolution`-metre cells centred on the world origin.
    pub const fn centred(width: usize, height: usize, resolution: f32) -> Self {
        Self {
            width,
            height,
            resolution,
            origin_x: -(width as f32) * resolution * 0.5,
            origin_y: -(height as f32) * resolution * 0.5,
        }
    }

    /// `true` when the resolution is positive and finite and the origin finite.
    pub fn is_valid(&self) -> bool {
        self.resolution.is_finite()
            && self.resolution > 0.0
            && self.origin_x.is_finite()
            && self.origin_y.is_finite()
            && self.width > 0
            && self.height > 0
            && self.width <= i32::MAX as usize
            && self.height <= i32::MAX as usize
    }

    /// Continuous cell coordinates of a world point (cell `(i, j)` spans `[i, i+1) × [j, j+1)`).
    #[inline]
    pub fn world_to_grid(&self, x: f32, y: f32) -> (f32, f32) {
        (
            (x - self.origin_x) / self.resolution,
            (y - self.origin_y) / self.resolution,
        )
    }

    /// The cell containing a world point, or `None` when it is off the grid or not finite.
    #[inline]
    pub fn world_to_cell(&self, x: f32, y: f32) -> Option<(usize, usize)> {
        let (u, v) = self.world_to_grid(x, y);
        if !(u.is_finite() && v.is_finite()) {
            return None;
        }
        let (ix, iy) = (floor_i32(u), floor_i32(v));
        self.contains(ix, iy).then_some((ix as usize, iy as usize))
    }

    /// World coordinates of the centre of cell `(ix, iy)` (any integer, also off the grid).
    #[inline]
    pub fn cell_centre(&self, ix: i32, iy: i32) -> (f32, f32) {
        (
            self.origin_x + (ix as f32 + 0.5) * self.resolution,
            self.origin_y + (iy as f32 + 0.5) * self.resolution,
        )
    }

    /// `true` when `(ix, iy)` is a cell of the grid.
    #[inline]
    pub fn contains(&self, ix: i32, iy: i32) -> bool {
        ix >= 0 && iy >= 0 && (ix as usize) < self.width && (iy as usize) < self.height
    }
}

/// Size in bytes of the occupied-cell bitmap of a `width × height` grid: `⌈width / 8⌉`
/// bytes per row, bit `x % 8` of byte `y · ⌈width/8⌉ + x / 8` for cell `(x, y)` (the
/// `BITMAP` of [`OccupancyGrid`], the length [`GridView::with_occupancy_bits`] expects).
pub const fn occupancy_bytes(width: usize, height: usize) -> usize {
    width.div_ceil(8) * height
}

/// `floor(v)` as an `i32`: exact for |v| < 2³¹, saturating beyond, 0 for NaN.
#[inline]
pub fn floor_i32(v: f32) -> i32 {
    let t = v as i32;
    if (t as f32) > v {
        t.saturating_sub(1)
    } else {
        t
    }
}

/// Integer log-odds arithmetic of the grid cells.
///
/// The unit is a tenth of log 4 (0.1386 nats) by default: a hit adds `hit` (10 = +log 4),
/// a free ray subtracts `miss` (10 = −log 4), cells saturate at `[min, max]`, a cell is
/// *occupied* when its value is above `occupied_above` (20 = 2 log 4) and *free* when below
/// `free_below` (−20 = −2 log 4): the model of Du (n.d.) with `p(hit | occupied) = 0.8`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct LogOdds {
    /// Added to the cell a beam ends in.
    pub hit: i8,
    /// Subtracted from each cell a beam passes through.
    pub miss: i8,
    /// A cell is occupied when its value is strictly above this.
    pub occupied_above: i8,
    /// A cell is free when its value is strictly below this.
    pub free_below: i8,
    /// Lower saturation limit.
    pub min: i8,
    /// Upper saturation limit.
    pub max: i8,
}

impl LogOdds {
    /// Every setting zero: not valid, only the zero bytes of a grid or estimator in a
    /// `static` until its settings replace them.
    pub const ZEROED: Self = Self {
        hit: 0,
        miss: 0,
        occupied_above: 0,
        free_below: 0,
        min: 0,
        max: 0,
    };

    /// The symmetric model: ±log 4 per observation (a hit adds as much as a free ray
    /// takes away), thresholds ±2 log 4, in units of log 4 / 10; saturation at ±100
    /// (≈ ±13.9 nats; in hits needed to flip a cell, about the ±20 clamp of the numpy
    /// re-implementation of Du (n.d.), `../shared/reference/seed_pf.py`). It reproduces
    /// the log-odds settings of Du (n.d.).
    pub const SYMMETRIC: Self = Self {
        hit: 10,
        miss: 10,
        occupied_above: 20,
        free_below: -20,
        min: -100,
        max: 100,
    };

    /// Log-odds represented by one integer unit, nats (for pictures and exports).
    pub fn nats_per_unit(&self) -> f32 {
        core::f32::consts::LN_2 * 2.0 / f32::from(self.hit.max(1))
    }

    /// `true` when the limits are ordered (`min ≤ 0 ≤ max`) and the steps not negative.
    pub fn is_valid(&self) -> bool {
        self.invalid_setting().is_none()
    }

    /// The first field out of range, `None` when the model is valid.
    #[inline]
    pub fn invalid_setting(&self) -> Option<crate::error::InvalidSetting> {
        crate::error::InvalidSetting::first([
            ("hit", "0 or more", self.hit >= 0),
            ("miss", "0 or more", self.miss >= 0),
            ("min", "0 or less", self.min <= 0),
            ("max", "0 or more", self.max >= 0),
        ])
    }

    /// The value after a hit.
    #[inline]
    pub fn after_hit(&self, value: i8) -> i8 {
        value.saturating_add(self.hit).clamp(self.min, self.max)
    }

    /// The value after a free ray passed.
    #[inline]
    pub fn after_miss(&self, value: i8) -> i8 {
        value.saturating_sub(self.miss).clamp(self.min, self.max)
    }

    /// [`LogOdds::after_miss`] of every cell value, indexed by the value's byte
    /// (`value as u8`): one load per cell in a map update's innermost loop instead of a
    /// subtraction and two comparisons.
    pub(crate) fn miss_table(&self) -> [i8; 256] {
        core::array::from_fn(|b| self.after_miss(b as u8 as i8))
    }
}

/// Why a map could not be built or used.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum GridError {
    /// Resolution not positive, origin not finite, or a zero size.
    InvalidGeometry,
    /// The borrowed cells are not `width × height` long.
    SizeMismatch,
    /// The pose or a setting is NaN or ±∞.
    NonFinite,
}

impl fmt::Display for GridError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::InvalidGeometry => "grid geometry is invalid",
            Self::SizeMismatch => "cell slice length differs from width × height",
            Self::NonFinite => "pose or setting is not finite",
        })
    }
}

impl core::error::Error for GridError {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn world_cell_round_trip_and_bounds() {
        let g = GridGeometry {
            width: 10,
            height: 20,
            resolution: 0.05,
            origin_x: -0.25,
            origin_y: 1.0,
        };
        assert_eq!(g.world_to_cell(-0.25, 1.0), Some((0, 0)));
        assert_eq!(g.world_to_cell(-0.2501, 1.0), None);
        assert_eq!(g.world_to_cell(0.2499, 1.9999), Some((9, 19)));
        assert_eq!(g.world_to_cell(0.25, 1.5), None);
        assert_eq!(g.world_to_cell(f32::NAN, 1.5), None);
        assert_eq!(g.world_to_cell(0.0, f32::INFINITY), None);
        let (x, y) = g.cell_centre(3, 7);
        assert_eq!(g.world_to_cell(x, y), Some((3, 7)));
        assert!((x - (-0.25 + 0.175)).abs() < 1e-6);
        let c = GridGeometry::centred(256, 256, 0.05);
        assert_eq!(c.world_to_cell(0.0, 0.0), Some((128, 128)));
        assert_eq!(c.world_to_cell(-0.001, -0.001), Some((127, 127)));
    }

    #[test]
    fn floor_matches_std() {
        for v in [-2.5f32, -1.0, -0.2, 0.0, 0.7, 3.0, 1e9, -1e9] {
            assert_eq!(floor_i32(v), v.floor() as i32, "{v}");
        }
        assert_eq!(floor_i32(f32::NAN), 0);
        assert_eq!(floor_i32(1e20), i32::MAX);
    }

    #[test]
    fn log_odds_saturate() {
        let l = LogOdds::SYMMETRIC;
        let mut v = 0i8;
        for _ in 0..50 {
            v = l.after_hit(v);
        }
        assert_eq!(v, 100);
        for _ in 0..50 {
            v = l.after_miss(v);
        }
        assert_eq!(v, -100);
        let wide = LogOdds {
            hit: 100,
            miss: 100,
            min: -128,
            max: 127,
            ..l
        };
        assert_eq!(wide.after_hit(100), 127);
        assert_eq!(wide.after_miss(-100), -128);
        assert!((l.nats_per_unit() * 10.0 - 4f32.ln()).abs() < 1e-6);
    }
}
