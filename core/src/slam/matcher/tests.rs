use super::*;
use crate::grid::occupancy_bytes;

const N: usize = 128;
const B: usize = occupancy_bytes(N, N);
type Map = OccupancyBitmap<N, N, B>;
type Levels2 = MatcherLevels<N, B, 2>;

fn window(half_width_cells: u16, half_angle: f32) -> MatchWindow {
    MatchWindow {
        half_width_cells,
        half_angle,
        angle_step: 0.01,
        min_hit_fraction: 0.5,
        work_budget: u32::MAX,
        distinct_cells: 10,
        max_runner_up: 1.0,
    }
}

/// A 6.4 m map centred on the origin with the walls of a room (a 4 × 3 m box with an
/// inner pillar), drawn cell by cell.
fn room() -> Box<Map> {
    let mut map = Box::new(Map::zeroed());
    map.init(0.05, -3.2, -3.2, 20).unwrap();
    for i in 0..=80 {
        let x = -2.0 + 0.05 * i as f32;
        map.set_world(x + 0.01, -1.5 + 0.01);
        map.set_world(x + 0.01, 1.5 + 0.01);
    }
    for i in 0..=60 {
        let y = -1.5 + 0.05 * i as f32;
        map.set_world(-2.0 + 0.01, y + 0.01);
        map.set_world(2.0 + 0.01, y + 0.01);
    }
    for i in 0..8 {
        map.set_world(0.8 + 0.05 * i as f32 + 0.01, 0.5 + 0.01);
        map.set_world(0.8 + 0.01, 0.5 + 0.05 * i as f32 + 0.01);
    }
    map
}

/// End points (robot frame) of a ray-cast scan of `map` from `pose`: 90 beams over the
/// full turn, marching in 1 cm steps to the first set bit.
fn cast(map: &Map, pose: &Pose2<f32>) -> Vec<(f32, f32)> {
    let g = *map.geometry();
    let mut points = Vec::new();
    for i in 0..90 {
        let a = i as f32 * core::f32::consts::TAU / 90.0;
        let (s, c) = ((pose.theta + a).sin(), (pose.theta + a).cos());
        for k in 1..600 {
            let r = 0.01 * k as f32;
            let (x, y) = (pose.x + r * c, pose.y + r * s);
            let (u, v) = g.world_to_grid(x, y);
            if map.is_set(u.floor() as i32, v.floor() as i32) {
                points.push((r * a.cos(), r * a.sin()));
                break;
            }
        }
    }
    points
}

/// Hits of `points` at `pose`, cell by cell (the reference for the matcher's score).
fn hits(map: &Map, points: &[(f32, f32)], pose: &Pose2<f32>) -> u32 {
    let g = *map.geometry();
    let (s, c) = sin_cos_f32(pose.theta);
    points
        .iter()
        .filter(|(px, py)| {
            let (u, v) = g.world_to_grid(pose.x + c * px - s * py, pose.y + s * px + c * py);
            map.is_set(floor_i32(u), floor_i32(v))
        })
        .count() as u32
}

#[test]
fn a_scan_is_found_where_it_was_taken() {
    let map = room();
    let mut levels = Box::new(Levels2::zeroed());
    levels.build(&map);
    let truth = Pose2::new(-0.4, 0.3, 0.2);
    let points = cast(&map, &truth);
    assert!(points.len() > 80, "{}", points.len());
    for (dx, dy, dt) in [
        (0.3f32, -0.2f32, 0.05f32),
        (-0.5, 0.4, -0.12),
        (0.0, 0.0, 0.0),
    ] {
        let guess = Pose2::new(truth.x + dx, truth.y + dy, truth.theta + dt);
        let m = levels
            .search(&map, &points, &guess, &window(16, 0.15))
            .unwrap();
        assert!(m.accepted && m.complete, "{m:?}");
        assert!(
            (m.pose.x - truth.x).abs() <= 0.05 && (m.pose.y - truth.y).abs() <= 0.05,
            "{m:?}"
        );
        assert!((m.pose.theta - truth.theta).abs() <= 0.011, "{m:?}");
        assert!(m.hits >= points.len() as u32 * 9 / 10, "{m:?}");
    }
}

#[test]
fn branch_and_bound_finds_the_best_score_of_the_whole_window() {
    // Random maps and scans: the best score equals the largest over every candidate,
    // scored one by one in the test.
    let mut state = 99u32;
    let mut next = || {
        state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        state >> 8
    };
    for round in 0..12 {
        let mut map = Box::new(Map::zeroed());
        map.init(0.05, -3.2, -3.2, 20).unwrap();
        for _ in 0..(300 + round * 50) {
            map.set((next() % N as u32) as i32, (next() % N as u32) as i32);
        }
        let points: Vec<(f32, f32)> = (0..40)
            .map(|_| {
                (
                    (next() % 4000) as f32 / 1000.0 - 2.0,
                    (next() % 4000) as f32 / 1000.0 - 2.0,
                )
            })
            .collect();
        let mut levels = Box::new(MatcherLevels::<N, B, 2>::zeroed());
        levels.build(&map);
        let guess = Pose2::new(0.013, -0.021, 0.3);
        // Every candidate counts (no minimum), so the answer is the best of the window.
        let w = MatchWindow {
            half_angle: 0.03,
            min_hit_fraction: 0.0,
            ..window(9 + round as u16, 0.0)
        };
        let m = levels.search(&map, &points, &guess, &w).unwrap();
        let mut best = 0;
        for j in -3..=3 {
            let theta = guess.theta + j as f32 * w.angle_step;
            for dy in -(w.half_width_cells as i32)..=w.half_width_cells as i32 {
                for dx in -(w.half_width_cells as i32)..=w.half_width_cells as i32 {
                    let p = Pose2::new(
                        guess.x + dx as f32 * 0.05,
                        guess.y + dy as f32 * 0.05,
                        theta,
                    );
                    best = best.max(hits(&map, &points, &p));
                }
            }
        }
        assert_eq!(m.hits, best, "round {round}: {m:?}");
        assert_eq!(
            hits(&map, &points, &m.pose),
            m.hits,
            "round {round}: the pose scores its hits"
        );
        // With a minimum, candidates below it are pruned: the same best when it reaches
        // the minimum, none (0 hits, no match) when it does not.
        for need in [best, best + 1] {
            let w_min = MatchWindow {
                min_hit_fraction: need as f32 / points.len() as f32,
                ..w
            };
            let m_min = levels.search(&map, &points, &guess, &w_min).unwrap();
            let expected = if need <= best { best } else { 0 };
            assert_eq!(
                m_min.hits, expected,
                "round {round}, need {need}: {m_min:?}"
            );
            assert!(
                m_min.work <= m.work,
                "round {round}: pruning never adds work"
            );
            assert!(m_min.complete);
        }
    }
}

#[test]
fn one_level_gives_the_same_match_as_two() {
    let map = room();
    let truth = Pose2::new(0.5, -0.3, -0.4);
    let points = cast(&map, &truth);
    let guess = Pose2::new(0.7, -0.1, -0.33);
    let mut one = Box::new(MatcherLevels::<N, B, 1>::zeroed());
    one.build(&map);
    let mut two = Box::new(Levels2::zeroed());
    two.build(&map);
    let a = one.search(&map, &points, &guess, &window(12, 0.1)).unwrap();
    let b = two.search(&map, &points, &guess, &window(12, 0.1)).unwrap();
    assert_eq!(a.hits, b.hits);
    assert!(
        b.work < a.work,
        "two levels prune more: {} against {}",
        b.work,
        a.work
    );
}

#[test]
fn a_corridor_is_uncertain_along_and_certain_across() {
    let mut map = Box::new(Map::zeroed());
    map.init(0.05, -3.2, -3.2, 20).unwrap();
    for i in 0..128 {
        map.set(i, 54);
        map.set(i, 74);
    }
    let mut levels = Box::new(Levels2::zeroed());
    levels.build(&map);
    let truth = Pose2::new(0.0, 0.0, 0.0);
    let points = cast(&map, &truth);
    let m = levels
        .search(&map, &points, &Pose2::new(0.1, 0.1, 0.0), &window(8, 0.05))
        .unwrap();
    let [xx, _, yy, _] = m.covariance;
    assert!(xx > 10.0 * yy, "along {xx}, across {yy}");
}

#[test]
fn refused_inputs_and_budgets() {
    let map = room();
    let mut levels = Box::new(Levels2::zeroed());
    let points = cast(&map, &Pose2::new(0.0, 0.0, 0.0));
    let guess = Pose2::new(0.0, 0.0, 0.0);
    assert_eq!(
        levels.search(&map, &points, &guess, &window(8, 0.1)),
        Err(MatchError::StaleLevels)
    );
    levels.build(&map);
    assert_eq!(
        levels.search(
            &map,
            &points,
            &Pose2::new(f32::NAN, 0.0, 0.0),
            &window(8, 0.1)
        ),
        Err(MatchError::InvalidInput)
    );
    let bad_step = MatchWindow {
        angle_step: 0.0,
        ..window(8, 0.1)
    };
    assert_eq!(
        levels.search(&map, &points, &guess, &bad_step),
        Err(MatchError::InvalidInput)
    );
    assert_eq!(
        levels.search(&map, &[(f32::NAN, 1.0)], &guess, &window(8, 0.1)),
        Err(MatchError::NoPoints)
    );
    let tight = MatchWindow {
        work_budget: 500,
        ..window(8, 0.1)
    };
    let m = levels.search(&map, &points, &guess, &tight).unwrap();
    assert!(!m.complete && !m.accepted, "{m:?}");
    assert!(m.work < 500 + 2 * 128 * 17, "{m:?}");
}

#[test]
fn two_places_that_fit_alike_are_no_match() {
    // A row of identical pillars 1 m apart: a scan fits at every pillar alike.
    let mut map = Box::new(Map::zeroed());
    map.init(0.05, -3.2, -3.2, 20).unwrap();
    for k in -3..=3 {
        for dx in 0..4 {
            for dy in 0..4 {
                map.set(64 + 20 * k + dx, 70 + dy);
            }
        }
    }
    for i in 0..128 {
        map.set(i, 50);
    }
    let mut levels = Box::new(Levels2::zeroed());
    levels.build(&map);
    let truth = Pose2::new(0.02, 0.0, 0.0);
    let points = cast(&map, &truth);
    let guess = Pose2::new(0.0, 0.0, 0.0);
    let unique = levels
        .search(&map, &points, &guess, &window(30, 0.05))
        .unwrap();
    assert!(unique.accepted, "without the runner-up test: {unique:?}");
    let strict = MatchWindow {
        max_runner_up: 0.85,
        ..window(30, 0.05)
    };
    let m = levels.search(&map, &points, &guess, &strict).unwrap();
    assert_eq!(m.hits, unique.hits);
    assert!(m.runner_up as f32 > 0.85 * m.hits as f32, "{m:?}");
    assert!(!m.accepted, "{m:?}");
    // With the window around one pillar only, the match is unique again.
    let narrow = levels
        .search(
            &map,
            &points,
            &guess,
            &MatchWindow {
                half_width_cells: 6,
                ..strict
            },
        )
        .unwrap();
    assert!(narrow.accepted, "{narrow:?}");
}

#[test]
fn a_match_run_in_slices_gives_the_same_answer() {
    // The room's scan, and the pillars' (whose runner-up pass decides): resumed a few
    // hundred look-ups at a time, the answer is the one of the search all at once.
    let map = room();
    let mut levels = Box::new(Levels2::zeroed());
    levels.build(&map);
    let truth = Pose2::new(0.31, -0.12, 0.05);
    let points = cast(&map, &truth);
    let guess = Pose2::new(0.0, 0.0, 0.0);
    for w in [
        window(12, 0.1),
        MatchWindow {
            max_runner_up: 0.85,
            ..window(12, 0.1)
        },
        MatchWindow {
            work_budget: 3000,
            ..window(12, 0.1)
        },
    ] {
        let whole = levels.search(&map, &points, &guess, &w).unwrap();
        for quantum in [1, 300, 5000] {
            let mut progress = levels.start(&map, &points, &guess, &w).unwrap();
            let mut calls = 0;
            let sliced = loop {
                calls += 1;
                if let Some(m) = levels.resume(&map, &mut progress, &w, quantum).unwrap() {
                    break m;
                }
                assert!(calls < 100_000, "never ends");
            };
            assert_eq!(sliced, whole, "quantum {quantum}");
            if quantum == 1 && w.work_budget == u32::MAX {
                assert!(calls > 10, "one block a call: {calls} calls");
            }
        }
    }
}

#[test]
fn dilate_sets_the_three_by_three_cells_around_each_bit() {
    // 24 × 6 cells, bits at (7, 1), (8, 4) (either side of a byte boundary) and (0, 0)
    // (a corner: nothing outside the grid).
    const W: usize = 24;
    let mut bits = [0u8; 3 * 6];
    let set = |bits: &mut [u8], x: usize, y: usize| bits[y * 3 + x / 8] |= 1 << (x % 8);
    let is_set = |bits: &[u8], x: usize, y: usize| bits[y * 3 + x / 8] >> (x % 8) & 1 == 1;
    for (x, y) in [(7, 1), (8, 4), (0, 0)] {
        set(&mut bits, x, y);
    }
    super::dilate(&mut bits, W);
    let near =
        |x: usize, y: usize, cx: usize, cy: usize| x.abs_diff(cx) <= 1 && y.abs_diff(cy) <= 1;
    for y in 0..6 {
        for x in 0..W {
            let expected = [(7, 1), (8, 4), (0, 0)]
                .iter()
                .any(|&(cx, cy)| near(x, y, cx, cy));
            assert_eq!(is_set(&bits, x, y), expected, "cell ({x}, {y})");
        }
    }
}
