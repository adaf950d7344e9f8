use super::*;
use crate::grid::OccupancyGrid;

const NEAR: usize = 64;
const FAR: usize = 160;
type Map = LocalMap<NEAR, { occupancy_bytes(NEAR, NEAR) }, FAR, { occupancy_bytes(FAR, FAR) }>;

fn model() -> LogOdds {
    LogOdds {
        miss: 3,
        ..LogOdds::SYMMETRIC
    }
}

/// End points (robot frame) of a ring of `n` beams at `range` metres.
fn ring(n: usize, range: f32) -> Vec<(f32, f32)> {
    (0..n)
        .map(|i| {
            let a = i as f32 * core::f32::consts::TAU / n as f32;
            (range * libm::cosf(a), range * libm::sinf(a))
        })
        .collect()
}

fn map_at(x: f32, y: f32) -> Box<Map> {
    let mut map = Box::new(Map::zeroed());
    map.init(0.05, model(), x, y).unwrap();
    map
}

#[test]
fn a_scan_writes_log_odds_near_and_bits_far() {
    let mut map = map_at(0.0, 0.0);
    let pose = Pose2::new(0.1, -0.2, 0.3);
    let mount = Pose2::new(0.0, 0.0, 0.0);
    // 1.2 m lands in the near window (3.2 m wide), 3.5 m only in the far one (8 m),
    // 6 m off both (the far bitmap's corners are 5.7 m away).
    let mut points = ring(90, 1.2);
    points.extend(ring(45, 3.5));
    points.extend(ring(10, 6.0));
    for _ in 0..3 {
        let r = map
            .integrate(&pose, &mount, points.iter().copied())
            .unwrap();
        assert_eq!(r.off_grid, 10, "{r:?}");
    }
    // The near window holds what a plain grid at its place holds after the same scans.
    let g = *map.near().geometry();
    let mut plain = OccupancyGrid::<NEAR, NEAR>::new(0.05, g.origin_x, g.origin_y, model());
    for _ in 0..3 {
        plain
            .integrate_points(&pose, &mount, points.iter().copied())
            .unwrap();
    }
    assert_eq!(map.near().cells(), plain.cells());
    // The far bitmap: the near window's occupancy where it lies, the 3.5 m ring outside.
    let far = *map.geometry();
    let (col, row) = (
        libm::roundf((g.origin_x - far.origin_x) / 0.05) as i32,
        libm::roundf((g.origin_y - far.origin_y) / 0.05) as i32,
    );
    let view = map.view();
    for y in 0..NEAR as i32 {
        for x in 0..NEAR as i32 {
            assert_eq!(
                view.is_occupied(col + x, row + y),
                plain.view().is_occupied(x, y),
                "({x}, {y})"
            );
        }
    }
    let (s, c) = libm::sincosf(pose.theta);
    for (px, py) in ring(45, 3.5) {
        let (x, y) = (pose.x + c * px - s * py, pose.y + s * px + c * py);
        let (u, v) = far.world_to_grid(x, y);
        assert!(view.is_occupied(floor_i32(u), floor_i32(v)), "({x}, {y})");
    }
}

#[test]
fn the_windows_follow_the_robot_and_keep_what_the_near_window_knew() {
    let mut map = map_at(0.0, 0.0);
    let mount = Pose2::new(0.0, 0.0, 0.0);
    let points = ring(120, 1.01);
    map.integrate(&Pose2::new(0.0, 0.0, 0.0), &mount, points.iter().copied())
        .unwrap();
    map.integrate(&Pose2::new(0.0, 0.0, 0.0), &mount, points.iter().copied())
        .unwrap();
    map.integrate(&Pose2::new(0.0, 0.0, 0.0), &mount, points.iter().copied())
        .unwrap();
    // The cell of the beam ending at (1.01, 0), named by a point inside it (y = 0 is on
    // a cell boundary).
    let wall = (1.01f32, -0.025f32);
    let occupied_at = |map: &Map, (x, y): (f32, f32)| {
        let g = map.geometry();
        let (u, v) = g.world_to_grid(x, y);
        map.view().is_occupied(floor_i32(u), floor_i32(v))
    };
    assert!(occupied_at(&map, wall));
    // Drive 4 m along +x in 5 cm steps: both windows move, by whole bytes.
    let mut far_moves = 0;
    for i in 1..=80 {
        let x = 0.05 * i as f32;
        if map.follow(x, 0.0) {
            far_moves += 1;
        }
        let near = map.near().geometry();
        let far = map.geometry();
        let col = (near.origin_x - far.origin_x) / 0.05;
        assert!((col - libm::roundf(col)).abs() < 1e-3 && libm::roundf(col) as i32 % 8 == 0);
        assert!(
            col >= 0.0 && col as usize + NEAR <= FAR,
            "near inside far: column {col}"
        );
        let (u, _) = near.world_to_grid(x, 0.0);
        assert!(
            (u - 0.5 * NEAR as f32).abs() <= NEAR as f32 / 8.0 + 8.0,
            "robot near the centre: {u}"
        );
    }
    assert!(far_moves > 0, "the far bitmap never moved");
    // The wall left the near window long ago but is still in the far bitmap.
    let near = *map.near().geometry();
    assert!(near.world_to_cell(wall.0, wall.1).is_none());
    assert!(occupied_at(&map, wall));
    // Back at the start, the near window takes the wall from the far bitmap as occupied.
    for i in (0..80).rev() {
        map.follow(0.05 * i as f32, 0.0);
    }
    let near = *map.near().geometry();
    let (cx, cy) = near
        .world_to_cell(wall.0, wall.1)
        .expect("the wall in the near window");
    let v = map.near().cell(cx as i32, cy as i32).unwrap();
    assert_eq!(v, model().occupied_above + 1);
}

#[test]
fn refused_inputs_change_nothing() {
    let mut map = map_at(1.0, 2.0);
    let before = *map.geometry();
    assert_eq!(
        map.init(0.05, model(), f32::NAN, 0.0),
        Err(GridError::NonFinite)
    );
    assert_eq!(
        map.init(-0.05, model(), 0.0, 0.0),
        Err(GridError::InvalidGeometry)
    );
    assert!(!map.follow(f32::INFINITY, 0.0));
    assert_eq!(
        map.integrate(
            &Pose2::new(f32::NAN, 0.0, 0.0),
            &Pose2::new(0.0, 0.0, 0.0),
            ring(4, 1.0).into_iter()
        ),
        Err(GridError::NonFinite)
    );
    assert_eq!(map.geometry(), &before);
    assert!(map.view().occupancy_bits().unwrap().iter().all(|b| *b == 0));
}
