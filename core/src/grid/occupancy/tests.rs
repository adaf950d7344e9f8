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

/// The bitmap a grid keeps equals the one computed from its cells.
fn assert_bitmap_matches<const W: usize, const H: usize, const BITMAP: usize>(
    grid: &OccupancyGrid<W, H, BITMAP>,
) {
    let mut want = [0u8; BITMAP];
    crate::grid::fill_occupancy_bits(
        grid.cells(),
        W,
        H,
        grid.log_odds_model().occupied_above,
        &mut want,
    )
    .unwrap();
    assert_eq!(grid.occupancy_bits(), &want[..]);
}

#[test]
fn scroll_keeps_what_the_grid_knows_of_the_world() {
    // Random cells (across the occupied threshold), scrolled by shifts that move whole
    // bytes of the bitmap and shifts that do not, on a width that is not a multiple of
    // 8: every cell holds what the cell at the same world position held, the bitmap
    // matches the cells, and the origin moves by whole cells.
    const BITMAP: usize = crate::grid::occupancy_bytes(61, 37);
    let model = LogOdds::SYMMETRIC;
    let mut before = OccupancyGrid::<61, 37, BITMAP>::new(0.05, -1.5, 2.0, model);
    let mut state = 7u32;
    for y in 0..37 {
        for x in 0..61 {
            state = state.wrapping_mul(1_103_515_245).wrapping_add(12_345);
            before.set_cell(x, y, (((state >> 8) % 200) as i32 - 100) as i8);
        }
    }
    for (dx, dy) in [
        (8, 0),
        (-16, 8),
        (3, -5),
        (-7, 2),
        (24, -36),
        (0, 1),
        (61, 0),
        (-2, -40),
    ] {
        let mut grid = before.clone();
        grid.scroll(dx, dy);
        for y in 0..37 {
            for x in 0..61 {
                let want = before.cell(x + dx, y + dy).unwrap_or(0);
                assert_eq!(grid.cell(x, y), Some(want), "({dx}, {dy}): cell ({x}, {y})");
            }
        }
        assert_bitmap_matches(&grid);
        let g = grid.geometry();
        assert!(
            (g.origin_x - (-1.5 + 0.05 * dx as f32)).abs() < 1e-5,
            "{g:?}"
        );
        assert!(
            (g.origin_y - (2.0 + 0.05 * dy as f32)).abs() < 1e-5,
            "{g:?}"
        );
        // Back where it started: the same origin bit for bit.
        grid.scroll(-dx, -dy);
        assert_eq!(grid.geometry(), before.geometry());
    }
}

#[test]
fn miss_ray_writes_the_cells_of_the_walk() {
    // Rays from inside, from outside (crossing the grid or not), along the borders,
    // degenerate and long, against the cell-by-cell writes they stand for.
    const BITMAP: usize = crate::grid::occupancy_bytes(37, 23);
    let model = LogOdds::SYMMETRIC;
    let mut fast = OccupancyGrid::<37, 23, BITMAP>::new(0.1, 0.0, 0.0, model);
    let mut slow = OccupancyGrid::<37, 23, BITMAP>::new(0.1, 0.0, 0.0, model);
    for x in 0..37 {
        for y in 0..23 {
            // −100 (the floor) to 39, across the occupied threshold (20).
            let v = ((x * 7 + y * 13) % 140 - 100) as i8;
            fast.set_cell(x, y, v);
            slow.set_cell(x, y, v);
        }
    }
    let mut state = 12345u32;
    let mut next = |range: i32| {
        state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (state >> 8) as i32 % range - range / 4
    };
    let mut rays = vec![(0, 0, 36, 22), (36, 22, 0, 0), (-5, 3, 50, 3), (3, 3, 3, 3)];
    rays.extend([
        (0, -1, 36, -1),
        (-1, 0, -1, 22),
        (18, 11, 18, 400),
        (-9, -9, -2, -1),
    ]);
    for _ in 0..400 {
        rays.push((next(60), next(40), next(60), next(40)));
    }
    for (x0, y0, x1, y1) in rays {
        let drawn = fast.miss_ray(x0, y0, x1, y1, &model.miss_table());
        let lo = slow.log_odds;
        let walked = walk_to_end(x0, y0, x1, y1, |cx, cy| {
            slow.update_cell(cx, cy, |c| lo.after_miss(c));
        });
        assert_eq!(drawn, walked);
        assert_eq!(fast.cells(), slow.cells(), "ray {x0},{y0} → {x1},{y1}");
        assert_eq!(fast.occupancy_bits(), slow.occupancy_bits());
    }
    assert_bitmap_matches(&fast);
    assert!(
        fast.occupancy_bits().iter().any(|w| *w != 0),
        "some cells stay occupied"
    );
    // A zeroed grid (0 × 0 until `init`) takes no write.
    let mut zeroed = OccupancyGrid::<37, 23, BITMAP>::zeroed();
    zeroed.miss_ray(0, 0, 36, 22, &model.miss_table());
    assert!(zeroed.cells().iter().all(|c| *c == 0));
}

#[test]
fn on_grid_walk_is_the_walk_to_end() {
    // Every end cell of a 41 × 33 grid from a centre, a corner and an edge start: the
    // major-axis walk over flat indices writes once each the cells `walk_to_end`
    // visits (a cell written twice or missed would differ by one miss).
    let model = LogOdds::SYMMETRIC;
    let misses = model.miss_table();
    for (x0, y0) in [(20, 16), (0, 0), (40, 7)] {
        for x1 in 0..41 {
            for y1 in 0..33 {
                let mut fast = OccupancyGrid::<41, 33>::new(0.1, 0.0, 0.0, model);
                let mut slow = fast.clone();
                fast.miss_ray_on_grid(x0, y0, x1, y1, &misses);
                walk_to_end(x0, y0, x1, y1, |cx, cy| {
                    slow.update_cell(cx, cy, |c| model.after_miss(c));
                });
                assert_eq!(fast.cells(), slow.cells(), "ray {x0},{y0} → {x1},{y1}");
            }
        }
    }
}

#[test]
fn miss_table_is_after_miss() {
    let wide = LogOdds {
        hit: 3,
        miss: 90,
        occupied_above: 5,
        free_below: -5,
        min: -128,
        max: 127,
    };
    for model in [LogOdds::SYMMETRIC, wide] {
        let table = model.miss_table();
        for v in i8::MIN..=i8::MAX {
            assert_eq!(table[usize::from(v as u8)], model.after_miss(v), "{v}");
        }
    }
}

#[test]
fn occupancy_bitmap_follows_every_write() {
    const BITMAP: usize = crate::grid::occupancy_bytes(40, 20);
    let mut grid = OccupancyGrid::<40, 20, BITMAP>::new(0.1, 0.0, 0.0, LogOdds::SYMMETRIC);
    let mut plain = OccupancyGrid::<40, 20>::new(0.1, 0.0, 0.0, LogOdds::SYMMETRIC);
    assert_bitmap_matches(&grid);
    let g = LidarGeometry {
        first_angle: -3.0,
        angle_increment: 0.15,
        ..lidar_ahead()
    };
    // Ranges that end inside the grid, on its border and beyond it.
    let ranges: Vec<f32> = (0..40).map(|i| 0.3 + (i * 7 % 23) as f32 * 0.12).collect();
    for step in 0..30 {
        // Each pose three times, so that end cells collect hits above the threshold.
        let k = (step / 3) as f32;
        let pose = Pose2::new(1.0 + 0.07 * k, 0.9 + 0.02 * k, 0.2 * k);
        let scan = LidarScan::new(&ranges, g);
        let a = grid.integrate_scan(&pose, &scan, 1 + step % 3).unwrap();
        let b = plain.integrate_scan(&pose, &scan, 1 + step % 3).unwrap();
        assert_eq!(a, b);
        assert_eq!(grid.cells(), plain.cells(), "the bitmap changes no cell");
        assert_bitmap_matches(&grid);
    }
    assert!(grid.occupancy_bits().iter().any(|w| *w != 0));
    assert!(grid.set_cell(39, 19, 50) && !grid.set_cell(40, 0, 50));
    assert!(grid.set_cell(5, 5, -50));
    assert_bitmap_matches(&grid);
    assert_eq!(grid.view().occupancy_bits(), Some(grid.occupancy_bits()));
    assert_eq!(plain.view().occupancy_bits(), None);
    // A threshold below zero makes unknown cells occupied: the bitmap says so too.
    let low = LogOdds {
        occupied_above: -1,
        ..LogOdds::SYMMETRIC
    };
    let mut unknown_occupied = OccupancyGrid::<40, 20, BITMAP>::new(0.1, 0.0, 0.0, low);
    assert_bitmap_matches(&unknown_occupied);
    unknown_occupied
        .integrate_scan(&Pose2::new(2.0, 1.0, 0.0), &LidarScan::new(&ranges, g), 1)
        .unwrap();
    assert_bitmap_matches(&unknown_occupied);
    unknown_occupied.reset();
    assert_bitmap_matches(&unknown_occupied);
    assert!(grid.init(0.1, 0.0, 0.0, low).is_ok());
    assert_bitmap_matches(&grid);
}

#[test]
fn points_write_what_the_scan_writes() {
    let g = LidarGeometry {
        first_angle: -1.5,
        angle_increment: 0.1,
        mount: Pose2::new(0.2, -0.05, 0.3),
        ..lidar_ahead()
    };
    let ranges: Vec<f32> = (0..30).map(|i| 0.4 + (i % 7) as f32 * 0.3).collect();
    let scan = LidarScan::new(&ranges, g);
    let pose = Pose2::new(2.0, 1.0, 0.7);
    let mut a = OccupancyGrid::<40, 20>::new(0.1, 0.0, 0.0, LogOdds::SYMMETRIC);
    let mut b = OccupancyGrid::<40, 20>::new(0.1, 0.0, 0.0, LogOdds::SYMMETRIC);
    let ra = a.integrate_scan(&pose, &scan, 2).unwrap();
    let points: Vec<(f32, f32)> = scan.beams(2).map(|b| b.robot_point).collect();
    let rb = b
        .integrate_points(&pose, &g.mount, points.iter().copied())
        .unwrap();
    assert_eq!(ra, rb);
    assert_eq!(a.cells(), b.cells());
    assert!(ra.hits > 0);
}

#[test]
fn one_beam_marks_free_ray_and_hit() {
    let mut grid = OccupancyGrid::<40, 20>::new(0.1, 0.0, 0.0, LogOdds::SYMMETRIC);
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
    let mut grid = OccupancyGrid::<10, 10>::new(0.1, 0.0, 0.0, LogOdds::SYMMETRIC);
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
    static GRID: OccupancyGrid<8, 4> = OccupancyGrid::centred(0.05, LogOdds::SYMMETRIC);
    assert_eq!(GRID.cells().len(), 32);
    assert_eq!(GRID.geometry().origin_x, -0.2);
    // Documented: W · H + BITMAP + 48 bytes on a 32-bit target, 64 on a 64-bit host.
    let overhead = if cfg!(target_pointer_width = "32") {
        48
    } else {
        64
    };
    assert_eq!(
        core::mem::size_of::<OccupancyGrid<256, 256>>(),
        256 * 256 + overhead
    );
    assert_eq!(
        core::mem::size_of::<OccupancyGrid<256, 256, { occupancy_bytes(256, 256) }>>(),
        256 * 256 + 8192 + overhead
    );
}

#[test]
fn zeroed_then_init_equals_new() {
    let mut grid = OccupancyGrid::<8, 4>::zeroed();
    assert_eq!(grid.geometry().width, 0);
    assert_eq!(grid.cell(0, 0), None, "nothing is on a zeroed grid");
    assert!(!grid.set_cell(0, 0, 5));
    assert_eq!(
        grid.init(f32::NAN, 0.0, 0.0, LogOdds::SYMMETRIC),
        Err(GridError::NonFinite)
    );
    assert_eq!(grid.geometry().width, 0, "a refused init changes nothing");
    grid.init_centred(0.05, LogOdds::SYMMETRIC).unwrap();
    let made = OccupancyGrid::<8, 4>::centred(0.05, LogOdds::SYMMETRIC);
    assert_eq!(grid.geometry(), made.geometry());
    assert_eq!(grid.log_odds_model(), made.log_odds_model());
    assert!(grid.set_cell(7, 3, 5));
    assert_eq!(grid.cell(7, 3), Some(5));
}
