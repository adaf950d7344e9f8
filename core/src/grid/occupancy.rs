//! The owned, fixed-size occupancy grid that SLAM writes scans into.

use super::bresenham::walk_to_end;
use super::scroll::{ScrollOrigin, shift_row, shift_rows};
use super::{Bresenham, GridError, GridGeometry, GridView, LogOdds, floor_i32, occupancy_bytes};
use crate::geometry::Pose2;
use crate::sensors::lidar::LidarScan;

/// A `W × H` grid of `i8` log-odds cells (see [`LogOdds`]), optionally with a bitmap of
/// its occupied cells.
///
/// `BITMAP` is the bitmap's size in bytes: `0` (the default) for none, or
/// [`occupancy_bytes`]`(W, H)` (`⌈W/8⌉ · H`, any other value does not compile). The
/// grid keeps the bitmap equal to `value > occupied_above` on every write, and
/// [`OccupancyGrid::view`] hands it to the shift search, which then visits only the
/// occupied cells of each window (on a Cortex-M4 about a third of the instructions of the
/// byte-wise search; same scores). Write the type as
/// `OccupancyGrid<256, 256, { occupancy_bytes(256, 256) }>`.
///
/// RAM: `W · H + BITMAP` bytes plus 48 bytes on a 32-bit microcontroller (256 × 256:
/// 65,584 bytes without the bitmap, 73,776 with it; 64 bytes on a 64-bit host). On a microcontroller, put it in a `static` built with
/// [`OccupancyGrid::zeroed`] — all zero bytes, so it lands in `.bss` and costs no flash —
/// and set its geometry in place at start-up with [`OccupancyGrid::init_centred`] (or
/// [`OccupancyGrid::init`] for another origin). The `const fn`s [`OccupancyGrid::new`] and
/// [`OccupancyGrid::centred`] give the same grid in one step, but a `static` built with
/// them has non-zero bytes and goes to `.data` (its whole image in flash): use them on
/// the host. No method moves the cells through the stack.
///
/// ```
/// use microslam::grid::{LogOdds, OccupancyGrid};
///
/// type Grid = OccupancyGrid<128, 128>; // 16 KB
/// // On a microcontroller: `static GRID: ConstStaticCell<Grid> =
/// // ConstStaticCell::new(Grid::zeroed());` (`core/examples/statics.rs`).
/// let mut grid = Box::new(Grid::zeroed());
/// assert_eq!(grid.cell(0, 0), None, "no geometry yet: every cell is off the grid");
///
/// grid.init_centred(0.05, LogOdds::SYMMETRIC)?; // 6.4 m × 6.4 m around the origin
/// assert_eq!(grid.geometry().origin_x, -3.2);
/// assert!(grid.set_cell(10, 20, 60));
/// assert_eq!(grid.cell(10, 20), Some(60));
/// assert!(grid.view().is_occupied(10, 20), "60 is above the threshold of 20");
/// # Ok::<(), microslam::grid::GridError>(())
/// ```
#[derive(Clone, Debug)]
pub struct OccupancyGrid<const W: usize, const H: usize, const BITMAP: usize = 0> {
    cells: [[i8; W]; H],
    occupied: [u8; BITMAP],
    geometry: GridGeometry,
    log_odds: LogOdds,
    off_grid: u32,
    /// The origin the grid was given and the cells it has scrolled since.
    scroll: ScrollOrigin,
}

/// Sets the bitmap of a `width`-cell-wide grid whose cells are all occupied (`on`) or
/// all not: the `width` valid bits of each row set, or every bit clear. In place, so
/// that no bitmap-sized temporary lands on a microcontroller's stack.
const fn set_uniform_bits(bits: &mut [u8], width: usize, on: bool) {
    let bytes_per_row = width.div_ceil(8);
    let mut i = 0;
    while i < bits.len() {
        let used = if on && bytes_per_row > 0 {
            width - (i % bytes_per_row) * 8
        } else {
            0
        };
        bits[i] = if used >= 8 {
            u8::MAX
        } else {
            (1u8 << used) - 1
        };
        i += 1;
    }
}

/// What writing one scan did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ScanIntegration {
    /// Usable beams written.
    pub beams: u32,
    /// End points that fell on the grid (+hit).
    pub hits: u32,
    /// End points off the grid: skipped (their free ray is still written where on the grid).
    pub off_grid: u32,
    /// Beams skipped entirely because the ray would be longer than the grid is wide.
    pub rays_skipped: u32,
}

impl<const W: usize, const H: usize, const BITMAP: usize> OccupancyGrid<W, H, BITMAP> {
    /// Compile-time check of the bitmap size.
    const BITMAP_SIZE_OK: () = assert!(
        BITMAP == 0 || BITMAP == occupancy_bytes(W, H),
        "OccupancyGrid<W, H, BITMAP>: BITMAP must be 0 or occupancy_bytes(W, H)"
    );

    /// An unknown (all-zero) grid whose lower-left corner is at `(origin_x, origin_y)`.
    pub const fn new(resolution: f32, origin_x: f32, origin_y: f32, log_odds: LogOdds) -> Self {
        let () = Self::BITMAP_SIZE_OK;
        let mut occupied = [0; BITMAP];
        set_uniform_bits(&mut occupied, W, 0 > log_odds.occupied_above);
        Self {
            cells: [[0; W]; H],
            occupied,
            geometry: GridGeometry {
                width: W,
                height: H,
                resolution,
                origin_x,
                origin_y,
            },
            log_odds,
            off_grid: 0,
            scroll: ScrollOrigin::new(origin_x, origin_y),
        }
    }

    /// A grid of zero bytes only, for a `static` in `.bss`: geometry `0 × 0` (every cell
    /// reads as off the grid and nothing is written) until [`OccupancyGrid::init`] sets
    /// the real geometry in place.
    pub const fn zeroed() -> Self {
        let () = Self::BITMAP_SIZE_OK;
        Self {
            cells: [[0; W]; H],
            occupied: [0; BITMAP],
            geometry: GridGeometry::ZEROED,
            log_odds: LogOdds::ZEROED,
            off_grid: 0,
            scroll: ScrollOrigin::new(0.0, 0.0),
        }
    }

    /// Sets the geometry (`W × H` cells of `resolution` metres, lower-left corner at
    /// `(origin_x, origin_y)`) and the log-odds model in place, and clears the grid: the
    /// in-place equivalent of [`OccupancyGrid::new`]. Refused (nothing changed) when a
    /// number is not finite, the resolution is not positive or the model is invalid.
    pub fn init(
        &mut self,
        resolution: f32,
        origin_x: f32,
        origin_y: f32,
        log_odds: LogOdds,
    ) -> Result<(), GridError> {
        if !(resolution.is_finite() && origin_x.is_finite() && origin_y.is_finite()) {
            return Err(GridError::NonFinite);
        }
        if resolution <= 0.0 || !log_odds.is_valid() {
            return Err(GridError::InvalidGeometry);
        }
        self.geometry = GridGeometry {
            width: W,
            height: H,
            resolution,
            origin_x,
            origin_y,
        };
        self.scroll = ScrollOrigin::new(origin_x, origin_y);
        self.log_odds = log_odds;
        self.reset();
        Ok(())
    }

    /// [`OccupancyGrid::init`] with the grid centred on the world origin.
    pub fn init_centred(&mut self, resolution: f32, log_odds: LogOdds) -> Result<(), GridError> {
        let g = GridGeometry::centred(W, H, resolution);
        self.init(resolution, g.origin_x, g.origin_y, log_odds)
    }

    /// An unknown grid centred on the world origin.
    pub const fn centred(resolution: f32, log_odds: LogOdds) -> Self {
        let g = GridGeometry::centred(W, H, resolution);
        Self::new(resolution, g.origin_x, g.origin_y, log_odds)
    }

    /// Sets every cell back to unknown and the counters to zero (in place).
    pub fn reset(&mut self) {
        for row in self.cells.iter_mut() {
            row.fill(0);
        }
        set_uniform_bits(&mut self.occupied, W, 0 > self.log_odds.occupied_above);
        self.off_grid = 0;
    }

    /// The bitmap of occupied cells (`⌈W/8⌉` bytes per row, bit `x % 8` of byte
    /// `y · ⌈W/8⌉ + x / 8` for cell `(x, y)`); empty when `BITMAP = 0`.
    #[inline]
    pub fn occupancy_bits(&self) -> &[u8] {
        &self.occupied
    }

    /// Size, resolution and origin.
    #[inline]
    pub fn geometry(&self) -> &GridGeometry {
        &self.geometry
    }

    /// Moves the grid in the world (the cells keep their values); refused when not finite.
    pub fn set_origin(&mut self, origin_x: f32, origin_y: f32) -> Result<(), GridError> {
        if !(origin_x.is_finite() && origin_y.is_finite()) {
            return Err(GridError::NonFinite);
        }
        self.geometry.origin_x = origin_x;
        self.geometry.origin_y = origin_y;
        self.scroll = ScrollOrigin::new(origin_x, origin_y);
        Ok(())
    }

    /// Moves the grid by `(dx, dy)` cells over the world, keeping what it knows: the
    /// origin moves by `(dx, dy)` cells and cell `(x, y)` takes the value of the cell
    /// that was at `(x + dx, y + dy)`; cells the grid did not cover before are unknown
    /// (0). A grid that follows the robot (a window over a larger world) calls this when
    /// the robot nears its edge. The bitmap follows: rows move whole, and a column shift
    /// that is a multiple of 8 moves whole bytes; any other shift recomputes the bits of
    /// each row from its cells. In place, O(W · H).
    ///
    /// The origin is the one the grid was given plus the cells scrolled since, rounded
    /// once: scrolling accumulates no rounding, and a grid moved there and back is where
    /// it started, bit for bit. A shift of a whole width or more clears the grid.
    ///
    /// ```
    /// use microslam::grid::{LogOdds, OccupancyGrid};
    ///
    /// let mut grid = OccupancyGrid::<16, 16>::new(0.5, 0.0, 0.0, LogOdds::SYMMETRIC);
    /// grid.set_cell(10, 3, 60);
    /// grid.scroll(8, -2); // 4 m right, 1 m down
    /// assert_eq!(grid.geometry().origin_x, 4.0);
    /// assert_eq!(grid.geometry().origin_y, -1.0);
    /// assert_eq!(grid.cell(2, 5), Some(60), "the same place in the world");
    /// assert_eq!(grid.cell(10, 3), Some(0), "unknown: seen before only from the old cell");
    /// ```
    pub fn scroll(&mut self, dx: i32, dy: i32) {
        if dx == 0 && dy == 0 || self.geometry.width == 0 {
            return;
        }
        let (w, h) = (W as i64, H as i64);
        let (dx64, dy64) = (i64::from(dx), i64::from(dy));
        self.scroll.scroll(dx, dy, &mut self.geometry);
        if dx64.abs() >= w || dy64.abs() >= h {
            self.clear_cells();
            return;
        }
        let (sx, sy) = (dx64 as isize, dy64 as isize);
        // Rows: new row y is old row y + dy.
        let cells = self.cells.as_flattened_mut();
        shift_rows(cells, W, sy);
        for row in self.cells.iter_mut() {
            shift_row(row, sx);
        }
        if BITMAP > 0 {
            let bytes_per_row = W.div_ceil(8);
            let t = self.log_odds.occupied_above;
            if sx % 8 == 0 && t >= 0 {
                // Whole bytes move; what comes from off the grid is unknown, not occupied.
                shift_rows(&mut self.occupied, bytes_per_row, sy);
                let padding = (8 - W % 8) % 8;
                for row in self.occupied.chunks_exact_mut(bytes_per_row) {
                    shift_row(row, sx / 8);
                    // Bits past the last column stay clear.
                    if let Some(last) = row.last_mut() {
                        *last &= u8::MAX >> padding;
                    }
                }
            } else {
                // The cells and the bitmap have this grid's own sizes: this cannot fail.
                let _ = super::fill_occupancy_bits(
                    self.cells.as_flattened(),
                    W,
                    H,
                    t,
                    &mut self.occupied,
                );
            }
        }
    }

    /// Sets every cell unknown and the bitmap to match, leaving the counters.
    fn clear_cells(&mut self) {
        for row in self.cells.iter_mut() {
            row.fill(0);
        }
        set_uniform_bits(&mut self.occupied, W, 0 > self.log_odds.occupied_above);
    }

    /// The log-odds model.
    #[inline]
    pub fn log_odds_model(&self) -> &LogOdds {
        &self.log_odds
    }

    /// All cells, row-major (row 0 at the bottom edge).
    #[inline]
    pub fn cells(&self) -> &[i8] {
        self.cells.as_flattened()
    }

    /// A read-only view for scoring scans (with the occupied-cell bitmap when `BITMAP > 0`).
    #[inline]
    pub fn view(&self) -> GridView<'_> {
        let view = GridView::from_trusted(
            self.cells.as_flattened(),
            self.geometry,
            self.log_odds.occupied_above,
        );
        if BITMAP > 0 && self.geometry.width == W && self.geometry.height == H {
            view.with_trusted_bits(&self.occupied)
        } else {
            view
        }
    }

    /// Log-odds of cell `(ix, iy)`, `None` off the grid.
    #[inline]
    pub fn cell(&self, ix: i32, iy: i32) -> Option<i8> {
        if !self.geometry.contains(ix, iy) {
            return None;
        }
        self.cells
            .get(iy as usize)
            .and_then(|r| r.get(ix as usize))
            .copied()
    }

    /// Sets cell `(ix, iy)`; returns `false` (and writes nothing) off the grid.
    pub fn set_cell(&mut self, ix: i32, iy: i32, value: i8) -> bool {
        self.update_cell(ix, iy, |_| value)
    }

    /// Replaces the value of cell `(ix, iy)` by `f(value)` and keeps the bitmap in step;
    /// `false` (nothing written) off the grid.
    #[inline]
    fn update_cell(&mut self, ix: i32, iy: i32, f: impl FnOnce(i8) -> i8) -> bool {
        if !self.geometry.contains(ix, iy) {
            return false;
        }
        let (x, y) = (ix as usize, iy as usize);
        let Some(c) = self.cells.get_mut(y).and_then(|r| r.get_mut(x)) else {
            return false;
        };
        let (old, new) = (*c, f(*c));
        *c = new;
        let t = self.log_odds.occupied_above;
        if BITMAP > 0
            && (old > t) != (new > t)
            && let Some(bits) = self.occupied.get_mut(y * W.div_ceil(8) + x / 8)
        {
            *bits ^= 1u8 << (x % 8);
        }
        true
    }

    /// −miss on every cell of the free ray from `(x0, y0)` to `(x1, y1)` that lies on the
    /// grid, the end cell excluded: the cells [`walk_to_end`] visits, each written as
    /// [`OccupancyGrid::update_cell`] would, in the map update's innermost loop. The
    /// geometry of a grid is either `W × H` or, [`OccupancyGrid::zeroed`], `0 × 0` (nothing
    /// written), so the bounds are the constants. `false` when the ray is too long to draw.
    fn miss_ray(&mut self, x0: i32, y0: i32, x1: i32, y1: i32, misses: &[i8; 256]) -> bool {
        let lo = self.log_odds;
        let t = lo.occupied_above;
        let live = self.geometry.width != 0;
        // Negative coordinates wrap to large unsigned ones.
        let on_grid = |x: i32, y: i32| (x as u32) < W as u32 && (y as u32) < H as u32;
        if live && on_grid(x0, y0) && on_grid(x1, y1) {
            self.miss_ray_on_grid(x0, y0, x1, y1, misses);
            return true;
        }
        let cells = self.cells.as_flattened_mut();
        let occupied = &mut self.occupied;
        walk_to_end(x0, y0, x1, y1, |x, y| {
            // Negative coordinates wrap to large unsigned ones.
            if !live || x as u32 >= W as u32 || y as u32 >= H as u32 {
                return;
            }
            let (x, y) = (x as usize, y as usize);
            let Some(c) = cells.get_mut(y * W + x) else {
                return;
            };
            let old = *c;
            let new = lo.after_miss(old);
            *c = new;
            // A miss only lowers a cell: it can only leave the occupied set.
            if BITMAP > 0
                && old > t
                && new <= t
                && let Some(bits) = occupied.get_mut(y * W.div_ceil(8) + x / 8)
            {
                *bits ^= 1u8 << (x % 8);
            }
        })
    }

    /// [`OccupancyGrid::miss_ray`] for a ray whose two ends are on the grid (the common
    /// case: a robot inside its map), so that every cell between them is too. The same
    /// cells as [`walk_to_end`]: its error term steps the major axis (the longer one) on
    /// every cell and the minor axis when `2 · err ≤ major`, for `major` cells (test
    /// `on_grid_walk_is_the_walk_to_end`), walked here over the cells' flat index with
    /// one table load per cell (`misses`: [`LogOdds::miss_table`]).
    fn miss_ray_on_grid(&mut self, x0: i32, y0: i32, x1: i32, y1: i32, misses: &[i8; 256]) {
        let t = self.log_odds.occupied_above;
        let cells = self.cells.as_flattened_mut();
        let occupied = &mut self.occupied;
        // Both ends are on a grid of at most 2³¹ cells a side: no difference overflows.
        let (dx, dy) = ((x1 - x0).abs(), (y1 - y0).abs());
        let step_x: isize = if x0 < x1 { 1 } else { -1 };
        let step_y: isize = if y0 < y1 { W as isize } else { -(W as isize) };
        let (major, minor, step_major, step_minor) = if dx >= dy {
            (dx, dy, step_x, step_y)
        } else {
            (dy, dx, step_y, step_x)
        };
        let mut i = (y0 as usize * W + x0 as usize) as isize;
        let mut err = major - minor;
        for _ in 0..major {
            if let Some(c) = cells.get_mut(i as usize) {
                let old = *c;
                let new = misses.get(usize::from(old as u8)).copied().unwrap_or(old);
                *c = new;
                // A miss only lowers a cell: it can only leave the occupied set.
                if BITMAP > 0 && old > t && new <= t {
                    let (x, y) = (i as usize % W, i as usize / W);
                    if let Some(bits) = occupied.get_mut(y * W.div_ceil(8) + x / 8) {
                        *bits ^= 1u8 << (x % 8);
                    }
                }
            }
            let e2 = 2 * err;
            err -= minor;
            i += step_major;
            if e2 <= major {
                err += major;
                i += step_minor;
            }
        }
    }

    /// End points counted off the grid since the last [`OccupancyGrid::reset`].
    pub fn off_grid_points(&self) -> u32 {
        self.off_grid
    }

    /// Writes one scan taken with the robot at `pose`, using every `decimation`-th beam:
    /// first −miss along every beam's free ray (Bresenham, end cell excluded), then +hit on
    /// every end cell, so that a wall seen in this scan is not erased by it.
    ///
    /// Cells off the grid are never written; end points off the grid are counted. A
    /// non-finite pose is refused with [`GridError::NonFinite`] and nothing is written.
    pub fn integrate_scan(
        &mut self,
        pose: &Pose2<f32>,
        scan: &LidarScan<'_>,
        decimation: usize,
    ) -> Result<ScanIntegration, GridError> {
        let points = scan.beams(decimation).map(|b| b.robot_point);
        self.integrate_points(pose, &scan.geometry.mount, points)
    }

    /// [`OccupancyGrid::integrate_scan`] for end points already in the robot frame (e.g.
    /// [`crate::pf::ScanPoints::robot_points`], so that a scan's trigonometry is done
    /// once for scoring and mapping): rays start at the sensor, mounted at `mount` on the
    /// robot; `points` is walked twice (free rays, then hits).
    pub fn integrate_points(
        &mut self,
        pose: &Pose2<f32>,
        mount: &Pose2<f32>,
        points: impl Iterator<Item = (f32, f32)> + Clone,
    ) -> Result<ScanIntegration, GridError> {
        if !pose.is_finite() {
            return Err(GridError::NonFinite);
        }
        let (s, c) = libm::sincosf(pose.theta);
        let to_world = |p: (f32, f32)| (pose.x + c * p.0 - s * p.1, pose.y + s * p.0 + c * p.1);
        let sensor = to_world((mount.x, mount.y));
        let g = self.geometry;
        let (su, sv) = g.world_to_grid(sensor.0, sensor.1);
        let (sx, sy) = (floor_i32(su), floor_i32(sv));
        let max_cells = 4 * (W as u64 + H as u64);
        let misses = self.log_odds.miss_table();
        let mut report = ScanIntegration::default();
        for pass in 0..2 {
            for point in points.clone() {
                let (wx, wy) = to_world(point);
                let (u, v) = g.world_to_grid(wx, wy);
                if !(u.is_finite() && v.is_finite()) {
                    continue;
                }
                let (ex, ey) = (floor_i32(u), floor_i32(v));
                if Bresenham::cell_count(sx, sy, ex, ey) > max_cells {
                    if pass == 0 {
                        report.rays_skipped += 1;
                    }
                    continue;
                }
                if pass == 0 {
                    if self.miss_ray(sx, sy, ex, ey, &misses) {
                        report.beams += 1;
                    } else {
                        report.rays_skipped += 1;
                    }
                } else {
                    let lo = self.log_odds;
                    if self.update_cell(ex, ey, |c| lo.after_hit(c)) {
                        report.hits += 1;
                    } else {
                        report.off_grid += 1;
                    }
                }
            }
        }
        self.off_grid = self.off_grid.saturating_add(report.off_grid);
        Ok(report)
    }
}

#[cfg(test)]
mod tests;
