//! The map grid SLAM tracks the robot on: two windows that move with it, so that a map of
//! any extent costs fixed RAM.
//!
//! - **Near**: an [`OccupancyGrid`] of `i8` log-odds (`NEAR × NEAR` cells) around the
//!   robot. Scans are written here as everywhere in this crate: free rays lower the cells
//!   they cross, end points raise theirs.
//! - **Far**: an [`OccupancyBitmap`] (`FAR × FAR` cells, the same resolution) around the
//!   near window, which is what the particle filter scores scans against. Over the near
//!   window it holds the near grid's occupancy (copied after every scan); outside it, the
//!   end points of the scans set its bits (no free rays, no log-odds).
//!
//! Why two: scoring needs the walls far from the robot, which keep it from sliding
//! along a corridor, but the log-odds that make a map robust to a passing person or a
//! grazing ray are only needed where the robot sees well. A 512 × 512 bitmap with a
//! 192 × 192 near grid takes 36 KB + 32 KB, where log-odds over the same 25.6 m would
//! take 256 KB (`docs/results-grid.md` measures what each size costs in accuracy).
//!
//! When the robot nears a window's edge the window scrolls by whole bytes of the bitmap
//! (multiples of 8 cells). Cells that leave the near window keep their occupancy in the
//! far bitmap; cells that enter it start from the far bitmap (an occupied bit becomes the
//! log-odds of a cell seen occupied once more than the threshold needs, a clear one is
//! unknown). Cells that leave the far bitmap are forgotten: what the robot saw long ago
//! and far away is the pose graph's business ([`super::GraphSlam`] closes loops against
//! the stored keyframes), not the tracking map's.

use crate::geometry::Pose2;
use crate::grid::{
    GridError, GridGeometry, GridView, LogOdds, OccupancyBitmap, OccupancyGrid, ScanIntegration,
    floor_i32, occupancy_bytes,
};

/// Cells a window moves by at least (and always a multiple of): one byte of the bitmap.
const STEP: i32 = 8;

/// The near log-odds window and the far bitmap around it (see the module).
///
/// `NEAR_BITS = occupancy_bytes(NEAR, NEAR)` and `FAR_BITS = occupancy_bytes(FAR, FAR)`;
/// `NEAR` and `FAR` are multiples of 8 with `NEAR + 16 ≤ FAR` (checked when the program
/// is built). RAM: `NEAR² + NEAR²/8 + FAR²/8` bytes plus about 100 (192 and 512: 74 KB).
/// Build it with [`LocalMap::zeroed`] (all zero bytes: a `static` in `.bss`) and place it
/// with [`LocalMap::init`].
#[derive(Clone, Debug)]
pub struct LocalMap<
    const NEAR: usize,
    const NEAR_BITS: usize,
    const FAR: usize,
    const FAR_BITS: usize,
> {
    near: OccupancyGrid<NEAR, NEAR, NEAR_BITS>,
    far: OccupancyBitmap<FAR, FAR, FAR_BITS>,
    /// The near window scrolls when the robot is farther than this from its centre, cells.
    near_margin: i32,
    /// The far bitmap scrolls when the near window would leave it, or the robot is
    /// farther than this from its centre, cells.
    far_margin: i32,
}

impl<const NEAR: usize, const NEAR_BITS: usize, const FAR: usize, const FAR_BITS: usize>
    LocalMap<NEAR, NEAR_BITS, FAR, FAR_BITS>
{
    const SIZES_OK: () = assert!(
        NEAR.is_multiple_of(8)
            && FAR.is_multiple_of(8)
            && NEAR + 16 <= FAR
            && NEAR_BITS == occupancy_bytes(NEAR, NEAR)
            && FAR_BITS == occupancy_bytes(FAR, FAR),
        "LocalMap<NEAR, NEAR_BITS, FAR, FAR_BITS>: NEAR and FAR multiples of 8, NEAR + 16 <= FAR, \
         NEAR_BITS = occupancy_bytes(NEAR, NEAR), FAR_BITS = occupancy_bytes(FAR, FAR)"
    );

    /// A map of zero bytes only, for a `static` in `.bss`; [`LocalMap::init`] places it.
    pub const fn zeroed() -> Self {
        let () = Self::SIZES_OK;
        Self {
            near: OccupancyGrid::zeroed(),
            far: OccupancyBitmap::zeroed(),
            near_margin: 0,
            far_margin: 0,
        }
    }

    /// Clears the map and centres both windows on `(x, y)` (within a byte of the bitmap),
    /// with cells of `resolution` metres and the log-odds model `log_odds`. Refused
    /// (nothing changed) for a non-finite position or an invalid model or resolution.
    pub fn init(
        &mut self,
        resolution: f32,
        log_odds: LogOdds,
        x: f32,
        y: f32,
    ) -> Result<(), GridError> {
        if !(x.is_finite() && y.is_finite() && resolution.is_finite()) {
            return Err(GridError::NonFinite);
        }
        if resolution <= 0.0 || !log_odds.is_valid() {
            return Err(GridError::InvalidGeometry);
        }
        let half = 0.5 * FAR as f32 * resolution;
        self.far
            .init(resolution, x - half, y - half, log_odds.occupied_above)?;
        let g = *self.far.geometry();
        let offset = Self::near_offset_centred();
        self.near.init(
            resolution,
            g.origin_x + offset as f32 * resolution,
            g.origin_y + offset as f32 * resolution,
            log_odds,
        )?;
        // Both windows keep the robot within a byte's width (8 cells) of their centre, so
        // that the far bitmap reaches as far ahead of the robot as behind it, whichever
        // way it drives: the beams that look far ahead are what keep the filter from
        // sliding along a corridor.
        self.near_margin = STEP;
        self.far_margin = STEP;
        Ok(())
    }

    /// The near window's column (and row) in the far bitmap when both are centred: half
    /// the difference of their sizes, rounded down to a whole byte.
    const fn near_offset_centred() -> i32 {
        ((FAR - NEAR) / 2 / 8 * 8) as i32
    }

    /// The far bitmap's geometry: what scans are scored on.
    pub fn geometry(&self) -> &GridGeometry {
        self.far.geometry()
    }

    /// The near window's log-odds grid.
    pub fn near(&self) -> &OccupancyGrid<NEAR, NEAR, NEAR_BITS> {
        &self.near
    }

    /// The near window's log-odds grid to draw in (a finished run's whole map, tile by
    /// tile: `GraphSlam::write_map_image`); the local map is not usable for tracking after.
    #[cfg(feature = "map-image")]
    pub(crate) fn near_mut(&mut self) -> &mut OccupancyGrid<NEAR, NEAR, NEAR_BITS> {
        &mut self.near
    }

    /// The far bitmap.
    pub fn far(&self) -> &OccupancyBitmap<FAR, FAR, FAR_BITS> {
        &self.far
    }

    /// The far bitmap as a read-only view: what the particle filter scores scans against.
    pub fn view(&self) -> GridView<'_> {
        self.far.view()
    }

    /// Clears both windows where they are (for a rebuild from stored scans).
    pub fn clear(&mut self) {
        self.near.reset();
        self.far.clear();
    }

    /// Writes one scan taken at `pose` (end points in the robot frame, the sensor mounted
    /// at `mount`): free rays and end points into the near window's log-odds, the end
    /// points outside it into the far bitmap, then the near window's occupancy into the
    /// far bitmap. The report counts end points off both windows as off the grid.
    pub fn integrate(
        &mut self,
        pose: &Pose2<f32>,
        mount: &Pose2<f32>,
        points: impl Iterator<Item = (f32, f32)> + Clone,
    ) -> Result<ScanIntegration, GridError> {
        let mut report = self.near.integrate_points(pose, mount, points.clone())?;
        report.off_grid = self.set_far_points(pose, points);
        self.far.copy_grid(&self.near)?;
        Ok(report)
    }

    /// Sets the far bits of the end points (robot frame, the robot at `pose`) that fall
    /// outside the near window; returns how many fell off the far bitmap too.
    fn set_far_points(
        &mut self,
        pose: &Pose2<f32>,
        points: impl Iterator<Item = (f32, f32)>,
    ) -> u32 {
        let (s, c) = libm::sincosf(pose.theta);
        let near = *self.near.geometry();
        let mut off = 0u32;
        for (px, py) in points {
            let (x, y) = (pose.x + c * px - s * py, pose.y + s * px + c * py);
            let (u, v) = near.world_to_grid(x, y);
            if u.is_finite() && v.is_finite() && near.contains(floor_i32(u), floor_i32(v)) {
                continue;
            }
            if !self.far.set_world(x, y) {
                off = off.saturating_add(1);
            }
        }
        off
    }

    /// Moves the windows so that `(x, y)` stays within 8 cells (a byte of the bitmap) of
    /// both centres, by multiples of 8 cells. Returns `true` when the far bitmap moved (the cells it uncovered are
    /// empty). A non-finite point moves nothing.
    pub fn follow(&mut self, x: f32, y: f32) -> bool {
        if !(x.is_finite() && y.is_finite()) || self.far.geometry().width == 0 {
            return false;
        }
        let far_moved = self.follow_far(x, y);
        self.follow_near(x, y);
        far_moved
    }

    /// Cells (rounded to multiples of [`STEP`]) by which a window centred at cell
    /// `centre` must move so that the point at cell `at` is within `margin` of its centre.
    fn steps(at: f32, centre: f32, margin: i32) -> i32 {
        let off = at - centre;
        if off.abs() <= margin as f32 {
            return 0;
        }
        let cells = libm::roundf(off / STEP as f32) as i32 * STEP;
        if cells == 0 {
            off.signum() as i32 * STEP
        } else {
            cells
        }
    }

    fn follow_far(&mut self, x: f32, y: f32) -> bool {
        let g = *self.far.geometry();
        let (u, v) = g.world_to_grid(x, y);
        let centre = 0.5 * FAR as f32;
        let (dx, dy) = (
            Self::steps(u, centre, self.far_margin),
            Self::steps(v, centre, self.far_margin),
        );
        if dx == 0 && dy == 0 {
            return false;
        }
        self.far.scroll(dx, dy);
        true
    }

    fn follow_near(&mut self, x: f32, y: f32) {
        let g = *self.near.geometry();
        let (u, v) = g.world_to_grid(x, y);
        let centre = 0.5 * NEAR as f32;
        let (mut dx, mut dy) = (
            Self::steps(u, centre, self.near_margin),
            Self::steps(v, centre, self.near_margin),
        );
        // The near window stays inside the far bitmap.
        let far = *self.far.geometry();
        let (fu, fv) = far.world_to_grid(g.origin_x, g.origin_y);
        let (col, row) = (libm::roundf(fu) as i32, libm::roundf(fv) as i32);
        let limit = (FAR - NEAR) as i32;
        dx = (col + dx).clamp(0, limit) - col;
        dy = (row + dy).clamp(0, limit) - row;
        // A far move can have put the near window off the byte grid's multiples of 8 only
        // if it was off before: keep it on them.
        dx -= (col + dx).rem_euclid(STEP);
        dy -= (row + dy).rem_euclid(STEP);
        if dx == 0 && dy == 0 {
            return;
        }
        self.near.scroll(dx, dy);
        self.fill_near_from_far(dx, dy);
    }

    /// After the near window moved by `(dx, dy)`: its uncovered cells take what the far
    /// bitmap knows of them (occupied: one unit above the occupied threshold; else
    /// unknown).
    fn fill_near_from_far(&mut self, dx: i32, dy: i32) {
        let n = NEAR as i32;
        let uncovered = |ix: i32, iy: i32| {
            (dx > 0 && ix >= n - dx)
                || (dx < 0 && ix < -dx)
                || (dy > 0 && iy >= n - dy)
                || (dy < 0 && iy < -dy)
        };
        let near = *self.near.geometry();
        let far = *self.far.geometry();
        let (fu, fv) = far.world_to_grid(near.origin_x, near.origin_y);
        let (col, row) = (libm::roundf(fu) as i32, libm::roundf(fv) as i32);
        let occupied = self.near.log_odds_model().occupied_above.saturating_add(1);
        for iy in 0..n {
            for ix in 0..n {
                if uncovered(ix, iy) && self.far.is_set(col + ix, row + iy) {
                    self.near.set_cell(ix, iy, occupied);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests;
