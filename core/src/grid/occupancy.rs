//! The owned, fixed-size occupancy grid that SLAM writes scans into.

use super::{Bresenham, GridError, GridGeometry, GridView, LogOdds, floor_i32};
use crate::geometry::Pose2;
use crate::sensors::lidar::{LidarScan, robot_to_world, sensor_pose};

/// A `W × H` grid of `i8` log-odds cells (see [`LogOdds`]).
///
/// RAM: `W · H` bytes plus 40 bytes (256 × 256: 65,576 bytes). Build it in place in a
/// `static` with the `const fn` [`OccupancyGrid::new`], or, so that the static is all
/// zero bytes and lands in `.bss` (no flash for initial values), with
/// [`OccupancyGrid::zeroed`] followed by [`OccupancyGrid::init`] at start-up. No method
/// moves the cells through the stack.
#[derive(Clone, Debug)]
pub struct OccupancyGrid<const W: usize, const H: usize> {
    cells: [[i8; W]; H],
    geometry: GridGeometry,
    log_odds: LogOdds,
    off_grid: u32,
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

impl<const W: usize, const H: usize> OccupancyGrid<W, H> {
    /// An unknown (all-zero) grid whose lower-left corner is at `(origin_x, origin_y)`.
    pub const fn new(resolution: f32, origin_x: f32, origin_y: f32, log_odds: LogOdds) -> Self {
        Self {
            cells: [[0; W]; H],
            geometry: GridGeometry {
                width: W,
                height: H,
                resolution,
                origin_x,
                origin_y,
            },
            log_odds,
            off_grid: 0,
        }
    }

    /// A grid of zero bytes only, for a `static` in `.bss`: geometry `0 × 0` (every cell
    /// reads as off the grid and nothing is written) until [`OccupancyGrid::init`] sets
    /// the real geometry in place.
    pub const fn zeroed() -> Self {
        Self {
            cells: [[0; W]; H],
            geometry: GridGeometry {
                width: 0,
                height: 0,
                resolution: 0.0,
                origin_x: 0.0,
                origin_y: 0.0,
            },
            log_odds: LogOdds {
                hit: 0,
                miss: 0,
                occupied_above: 0,
                free_below: 0,
                min: 0,
                max: 0,
            },
            off_grid: 0,
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
        self.off_grid = 0;
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
        Ok(())
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

    /// A read-only view for scoring scans.
    #[inline]
    pub fn view(&self) -> GridView<'_> {
        GridView::from_trusted(
            self.cells.as_flattened(),
            self.geometry,
            self.log_odds.occupied_above,
        )
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
        if !self.geometry.contains(ix, iy) {
            return false;
        }
        match self
            .cells
            .get_mut(iy as usize)
            .and_then(|r| r.get_mut(ix as usize))
        {
            Some(c) => {
                *c = value;
                true
            }
            None => false,
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
        if !pose.is_finite() {
            return Err(GridError::NonFinite);
        }
        let sensor = sensor_pose(pose, &scan.geometry.mount);
        let g = self.geometry;
        let (su, sv) = g.world_to_grid(sensor.x, sensor.y);
        let (sx, sy) = (floor_i32(su), floor_i32(sv));
        let max_cells = 4 * (W as u64 + H as u64);
        let mut report = ScanIntegration::default();
        for pass in 0..2 {
            for beam in scan.beams(decimation) {
                let (wx, wy) = robot_to_world(pose, beam.robot_point);
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
                    report.beams += 1;
                    let lo = self.log_odds;
                    for (cx, cy) in Bresenham::new(sx, sy, ex, ey) {
                        if (cx, cy) == (ex, ey) {
                            break;
                        }
                        if let Some(c) = self.cell_mut(cx, cy) {
                            *c = lo.after_miss(*c);
                        }
                    }
                } else {
                    let lo = self.log_odds;
                    if let Some(c) = self.cell_mut(ex, ey) {
                        *c = lo.after_hit(*c);
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

    #[inline]
    fn cell_mut(&mut self, ix: i32, iy: i32) -> Option<&mut i8> {
        if !self.geometry.contains(ix, iy) {
            return None;
        }
        self.cells
            .get_mut(iy as usize)
            .and_then(|r| r.get_mut(ix as usize))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensors::lidar::LidarGeometry;

    fn lidar_ahead() -> LidarGeometry {
        LidarGeometry {
            first_angle: 0.0,
            angle_increment: 0.1,
            min_range: 0.05,
            max_range: 50.0,
            no_return_range: 50.0,
            mount: Pose2::new(0.0, 0.0, 0.0),
        }
    }

    #[test]
    fn one_beam_marks_free_ray_and_hit() {
        let mut grid = OccupancyGrid::<40, 20>::new(0.1, 0.0, 0.0, LogOdds::SEED);
        let ranges = [1.0f32];
        let pose = Pose2::new(0.05, 0.55, 0.0); // centre of cell (0, 5)
        let r = grid
            .integrate_scan(&pose, &LidarScan::new(&ranges, lidar_ahead()), 1)
            .unwrap();
        assert_eq!((r.beams, r.hits, r.off_grid), (1, 1, 0));
        // End point (1.05, 0.55) is cell (10, 5); cells 0..10 of row 5 are free.
        for ix in 0..10 {
            assert_eq!(grid.cell(ix, 5), Some(-10), "{ix}");
        }
        assert_eq!(grid.cell(10, 5), Some(10));
        assert_eq!(grid.cell(11, 5), Some(0));
        assert_eq!(grid.cell(5, 4), Some(0));
        // Three hits make it occupied (> 2 log 4), and saturation holds at +100.
        for _ in 0..20 {
            grid.integrate_scan(&pose, &LidarScan::new(&ranges, lidar_ahead()), 1)
                .unwrap();
        }
        assert_eq!(grid.cell(10, 5), Some(100));
        assert_eq!(grid.cell(3, 5), Some(-100));
        assert!(grid.view().is_occupied(10, 5));
    }

    #[test]
    fn off_grid_points_are_counted_not_written() {
        let mut grid = OccupancyGrid::<10, 10>::new(0.1, 0.0, 0.0, LogOdds::SEED);
        let ranges = [5.0f32, 0.5];
        let mut g = lidar_ahead();
        g.angle_increment = core::f32::consts::FRAC_PI_2;
        let pose = Pose2::new(0.55, 0.25, 0.0);
        let r = grid
            .integrate_scan(&pose, &LidarScan::new(&ranges, g), 1)
            .unwrap();
        assert_eq!((r.beams, r.hits, r.off_grid), (2, 1, 1));
        assert_eq!(grid.off_grid_points(), 1);
        assert_eq!(grid.cell(9, 2), Some(-10)); // the free ray reaches the border
        assert_eq!(grid.cell(5, 7), Some(10)); // (0.55, 0.75)
        // Robot far away: nothing on the grid changes, no panic, no hang.
        let before = grid.cells().to_vec();
        let far = Pose2::new(1.0e30, -3.0e29, 1.0);
        let r = grid
            .integrate_scan(&far, &LidarScan::new(&ranges, g), 1)
            .unwrap();
        assert_eq!((r.hits, r.off_grid + r.rays_skipped), (0, 2));
        assert_eq!(grid.cells(), &before[..]);
        let nan = Pose2::new(f32::NAN, 0.0, 0.0);
        assert_eq!(
            grid.integrate_scan(&nan, &LidarScan::new(&ranges, g), 1),
            Err(GridError::NonFinite)
        );
        grid.reset();
        assert!(grid.cells().iter().all(|c| *c == 0) && grid.off_grid_points() == 0);
    }

    #[test]
    fn const_construction_for_statics() {
        static GRID: OccupancyGrid<8, 4> = OccupancyGrid::centred(0.05, LogOdds::SEED);
        assert_eq!(GRID.cells().len(), 32);
        assert_eq!(GRID.geometry().origin_x, -0.2);
        assert!(core::mem::size_of::<OccupancyGrid<256, 256>>() <= 256 * 256 + 48);
    }

    #[test]
    fn zeroed_then_init_equals_new() {
        let mut grid = OccupancyGrid::<8, 4>::zeroed();
        assert_eq!(grid.geometry().width, 0);
        assert_eq!(grid.cell(0, 0), None, "nothing is on a zeroed grid");
        assert!(!grid.set_cell(0, 0, 5));
        assert_eq!(
            grid.init(f32::NAN, 0.0, 0.0, LogOdds::SEED),
            Err(GridError::NonFinite)
        );
        assert_eq!(grid.geometry().width, 0, "a refused init changes nothing");
        grid.init_centred(0.05, LogOdds::SEED).unwrap();
        let made = OccupancyGrid::<8, 4>::centred(0.05, LogOdds::SEED);
        assert_eq!(grid.geometry(), made.geometry());
        assert_eq!(grid.log_odds_model(), made.log_odds_model());
        assert!(grid.set_cell(7, 3, 5));
        assert_eq!(grid.cell(7, 3), Some(5));
    }
}
