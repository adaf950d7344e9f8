//! Tests of the correlation searches: tie rules, the shift prior, every search against
//! the brute-force reference, a planted offset, and the loading of end points.

use super::sparse::search_sparse;
use super::sums::{RowSums, WideSums};
use super::*;
use crate::geometry::sin_cos_f32;
use crate::grid::GridGeometry;
use crate::sensors::lidar::{LidarGeometry, LidarScan};
use rand::{Rng, SeedableRng};

#[test]
fn best_shift_tie_rules() {
    // 3 × 3 window: centre tied with a corner → centre wins.
    let s = [5, 0, 0, 0, 5, 0, 0, 0, 0];
    assert_eq!(
        best_shift(&s, 1),
        ShiftScore {
            dx: 0,
            dy: 0,
            score: 5
        }
    );
    // Two off-centre maxima → the first in row-major order.
    let s = [0, 0, 7, 0, 5, 0, 7, 0, 0];
    assert_eq!(
        best_shift(&s, 1),
        ShiftScore {
            dx: 1,
            dy: -1,
            score: 7
        }
    );
}

#[test]
fn shift_prior_trades_score_for_distance() {
    // 3 × 3 window: centre 100, corner (+1, +1) 103. Without a prior the corner wins;
    // with 2 units per cell² it costs 4 and the centre wins; with 1 per cell² it costs
    // 2 and the corner still wins, reporting its own score.
    let s = [0, 0, 0, 0, 100, 0, 0, 0, 103];
    let corner = ShiftScore {
        dx: 1,
        dy: 1,
        score: 103,
    };
    let centre = ShiftScore {
        dx: 0,
        dy: 0,
        score: 100,
    };
    assert_eq!(best_shift_with_prior(&s, 1, 0.0), corner);
    assert_eq!(best_shift_with_prior(&s, 1, f32::NAN), corner);
    assert_eq!(best_shift_with_prior(&s, 1, 2.0), centre);
    assert_eq!(best_shift_with_prior(&s, 1, 1.0), corner);
    // A tie after the penalty keeps the unshifted particle.
    assert_eq!(best_shift_with_prior(&s, 1, 1.5), centre);
    // A far shift with a big gain wins over a near one with a small gain.
    let mut w = [0u32; 25];
    w[12] = 50; // centre of 5 × 5
    w[13] = 52; // (+1, 0): 52 − 1 = 51
    w[0] = 70; // (−2, −2): 70 − 8 = 62
    assert_eq!(
        best_shift_with_prior(&w, 2, 1.0),
        ShiftScore {
            dx: -2,
            dy: -2,
            score: 70
        }
    );
}

/// Asserts that `search` over `maps.0` (with a bitmap) gives the brute force's scores
/// over `maps.1` and its best shift, for windows of half-width 1, 2, 4 and 7.
fn assert_as_brute_force(
    search: crate::pf::filter::ShiftSearch,
    maps: (&GridView<'_>, &GridView<'_>),
    pose: &Pose2<f32>,
    points: &[ScanPoint],
    label: &str,
) {
    for k in [1u8, 2, 4, 7] {
        let n = (2 * k as usize + 1).pow(2);
        let (mut a, mut b) = ([0u32; MAX_SHIFTS], [0u32; MAX_SHIFTS]);
        let fast = search(maps.0, pose, points, k, &mut a);
        let slow = search_window_brute_force(maps.1, pose, points, k, &mut b);
        assert_eq!(a[..n], b[..n], "{label}, k {k}");
        assert_eq!(fast, slow, "{label}, k {k}");
    }
}

/// The occupied-cell bitmap of `cells` (threshold 20, as the tests' views).
fn occupied_bits(cells: &[i8], g: &GridGeometry) -> Vec<u8> {
    let mut bits = vec![0u8; crate::grid::occupancy_bytes(g.width, g.height)];
    crate::grid::fill_occupancy_bits(cells, g.width, g.height, 20, &mut bits).unwrap();
    bits
}

fn random_map(seed: u64, w: usize, h: usize, density: f64) -> (Vec<i8>, GridGeometry) {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let cells = (0..w * h)
        .map(|_| {
            if rng.random_bool(density) {
                40
            } else {
                rng.random_range(-30..20)
            }
        })
        .collect();
    (cells, GridGeometry::centred(w, h, 0.05))
}

#[test]
fn fast_search_equals_brute_force() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(7);
    for trial in 0..60 {
        let (cells, g) = random_map(trial, 64 + trial as usize % 9, 48, 0.15);
        let view = GridView::new(&cells, g, 20).unwrap();
        let ranges: Vec<f32> = (0..90).map(|_| rng.random_range(0.05..2.5)).collect();
        let mut pts = ScanPoints::<90>::new();
        let geometry = LidarGeometry {
            first_angle: -3.0,
            angle_increment: 6.0 / 90.0,
            ..LidarGeometry::CARMEN_SICK_180
        };
        pts.load(
            &LidarScan::new(&ranges, geometry),
            1,
            [0.0, 2.0, 0.7][trial as usize % 3],
        );
        // Poses inside, near the border and off the grid.
        let pose = Pose2::new(
            rng.random_range(-2.5..2.5),
            rng.random_range(-1.8..1.8),
            rng.random_range(-4.0..4.0),
        );
        let k = (trial % 8) as u8;
        let (mut a, mut b) = ([0u32; MAX_SHIFTS], [0u32; MAX_SHIFTS]);
        let fast = search_window(&view, &pose, pts.as_slice(), k, &mut a);
        let slow = search_window_brute_force(&view, &pose, pts.as_slice(), k, &mut b);
        let n = (2 * k as usize + 1).pow(2);
        assert_eq!(a[..n], b[..n], "trial {trial}");
        assert_eq!(fast, slow, "trial {trial}");
        assert!(fast.score > 0 || trial % 8 == 0);
        // The same search over the occupied-cell bitmap (the sparse path).
        let bits = occupied_bits(&cells, &g);
        let with_bits = view.with_occupancy_bits(&bits).unwrap();
        let mut c = [0u32; MAX_SHIFTS];
        let sparse = search_window(&with_bits, &pose, pts.as_slice(), k, &mut c);
        assert_eq!(c[..n], b[..n], "sparse, trial {trial}");
        assert_eq!(sparse, slow, "sparse, trial {trial}");
        // The sparse-only search over a view without a bitmap: every window checked.
        let mut d = [0u32; MAX_SHIFTS];
        let checked = search_window_sparse(&view, &pose, pts.as_slice(), k, &mut d);
        assert_eq!(d[..n], b[..n], "checked, trial {trial}");
        assert_eq!(checked, slow, "checked, trial {trial}");
        if k == 4 {
            // The 9 × 9 window's two accumulators: the microcontroller's and the host's.
            let mut e = [0u32; MAX_SHIFTS];
            let rows = search_sparse::<RowSums<9>, 0>(
                &view,
                Some(&bits),
                &pose,
                pts.as_slice(),
                9,
                &mut e,
            );
            assert_eq!((&e[..n], rows), (&b[..n], slow), "row sums, trial {trial}");
            let mut f = [0u32; MAX_SHIFTS];
            let wide =
                search_sparse::<WideSums, 0>(&view, Some(&bits), &pose, pts.as_slice(), 9, &mut f);
            assert_eq!((&f[..n], wide), (&b[..n], slow), "wide sums, trial {trial}");
        }
    }
}

#[test]
fn end_points_sharing_a_window_score_as_apart() {
    // 200 beams over 0.6 rad at 0.3–0.9 m: runs of consecutive end points in one cell
    // (read once by the sparse search, with their weights summed), runs across the
    // host's chunks of end points, and weights of every size.
    let mut rng = rand::rngs::StdRng::seed_from_u64(11);
    for trial in 0..20 {
        let (cells, g) = random_map(100 + trial, 80, 64, 0.2);
        let view = GridView::new(&cells, g, 20).unwrap();
        let bits = occupied_bits(&cells, &g);
        let with_bits = view.with_occupancy_bits(&bits).unwrap();
        let ranges: Vec<f32> = (0..200)
            .map(|i| 0.3 + 0.6 * (i / 25) as f32 / 8.0 + rng.random_range(0.0..0.01))
            .collect();
        let geometry = LidarGeometry {
            first_angle: -0.3,
            angle_increment: 0.6 / 200.0,
            ..LidarGeometry::CARMEN_SICK_180
        };
        let mut pts = ScanPoints::<200>::new();
        pts.load(
            &LidarScan::new(&ranges, geometry),
            1,
            [0.0, 2.0][trial as usize % 2],
        );
        let pose = Pose2::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-0.8..0.8),
            rng.random_range(-4.0..4.0),
        );
        let (sin, cos) = sin_cos_f32(pose.theta);
        let cells_of: Vec<_> = pts
            .as_slice()
            .iter()
            .map(|p| end_cell(&view, &pose, sin, cos, p))
            .collect();
        let shared = cells_of.windows(2).filter(|w| w[0] == w[1]).count();
        assert!(
            shared > 50,
            "trial {trial}: only {shared} neighbours share a cell"
        );
        let label = format!("trial {trial}");
        let search = search_window_sparse;
        assert_as_brute_force(search, (&with_bits, &view), &pose, pts.as_slice(), &label);
    }
}

#[test]
fn searches_with_constant_row_offsets_score_as_the_brute_force() {
    // 256 and 1024 cells wide (32 and 128 bytes a bitmap row: the copies with constant
    // row offsets, 9 × 9, 3 × 3 and 5 × 5), next to 248 and 1016 (31 and 127: the
    // fallback).
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    for (trial, width) in [256usize, 1024, 248, 1016, 250].into_iter().enumerate() {
        let (cells, g) = random_map(200 + trial as u64, width, 40, 0.15);
        let view = GridView::new(&cells, g, 20).unwrap();
        let bits = occupied_bits(&cells, &g);
        let with_bits = view.with_occupancy_bits(&bits).unwrap();
        let ranges: Vec<f32> = (0..90).map(|_| rng.random_range(0.05..1.5)).collect();
        let mut pts = ScanPoints::<90>::new();
        pts.load(
            &LidarScan::new(&ranges, LidarGeometry::CARMEN_SICK_180),
            1,
            1.0,
        );
        for _ in 0..10 {
            // Inside, near the edges and over them.
            let half = (width as f32 * 0.05) / 2.0;
            let pose = Pose2::new(
                rng.random_range(-half - 0.5..half + 0.5),
                rng.random_range(-1.2..1.2),
                rng.random_range(-4.0..4.0),
            );
            let label = format!("width {width}, pose {pose:?}");
            let maps = (&with_bits, &view);
            let pts = pts.as_slice();
            assert_as_brute_force(search_window_sparse_rows::<32>, maps, &pose, pts, &label);
            assert_as_brute_force(search_window_sparse_rows::<128>, maps, &pose, pts, &label);
            // The packed 3 × 3 and 5 × 5 copies (k = 1 and 2 run them, other windows
            // the fallback).
            assert_as_brute_force(search_window_packed::<3, 32>, maps, &pose, pts, &label);
            assert_as_brute_force(search_window_packed::<5, 32>, maps, &pose, pts, &label);
            assert_as_brute_force(search_window_packed::<5, 128>, maps, &pose, pts, &label);
        }
    }
}

#[test]
fn planted_offset_is_found() {
    // Walls of a ~2 m × 1.5 m room; the scan is taken at the true pose and scored from a
    // pose off by (+3, −2) cells: the search must answer (−3, +2).
    let g = GridGeometry::centred(100, 100, 0.05);
    let mut cells = vec![0i8; 100 * 100];
    let truth = Pose2::new(0.12, -0.07, 0.3f32);
    let mut ranges = Vec::new();
    let geometry = LidarGeometry {
        first_angle: -3.1,
        angle_increment: 6.2 / 120.0,
        ..LidarGeometry::CARMEN_SICK_180
    };
    for i in 0..120 {
        // Ray cast against the axis-aligned room [-1, 1] × [-0.75, 0.75].
        let a = truth.theta + geometry.beam_angle(i);
        let (s, c) = a.sin_cos();
        // Walls kept off the cell borders (which fall on multiples of 5 cm).
        let tx = if c > 0.0 {
            (1.012 - truth.x) / c
        } else {
            (-1.012 - truth.x) / c
        };
        let ty = if s > 0.0 {
            (0.763 - truth.y) / s
        } else {
            (-0.763 - truth.y) / s
        };
        ranges.push(tx.min(ty));
    }
    for (i, r) in ranges.iter().enumerate() {
        let a = truth.theta + geometry.beam_angle(i);
        let (x, y) = (truth.x + r * a.cos(), truth.y + r * a.sin());
        if let Some((ix, iy)) = g.world_to_cell(x, y) {
            cells[iy * 100 + ix] = 50;
        }
    }
    let view = GridView::new(&cells, g, 20).unwrap();
    let mut pts = ScanPoints::<180>::new();
    pts.load(&LidarScan::new(&ranges, geometry), 1, 0.0);
    let off = Pose2::new(truth.x + 3.0 * 0.05, truth.y - 2.0 * 0.05, truth.theta);
    let mut s = [0u32; MAX_SHIFTS];
    let best = search_window(&view, &off, pts.as_slice(), 4, &mut s);
    assert_eq!((best.dx, best.dy), (-3, 2), "{best:?}");
    let at_truth = search_window(&view, &truth, pts.as_slice(), 4, &mut s);
    assert_eq!((at_truth.dx, at_truth.dy), (0, 0));
    assert!(best.score >= 100 * WEIGHT_ONE, "{best:?}");
}

#[test]
fn weights_and_thinning() {
    let ranges = [1.0f32, 2.0, 0.01, 3.0, 1e5];
    let g = LidarGeometry::CARMEN_SICK_180;
    let mut pts = ScanPoints::<8>::new();
    assert_eq!(pts.load(&LidarScan::new(&ranges, g), 1, 2.0), 3);
    let w: Vec<u32> = pts.as_slice().iter().map(|p| p.weight).collect();
    assert_eq!(w, vec![256, 1024, 2304]);
    let mut few = ScanPoints::<2>::new();
    few.load(&LidarScan::new(&ranges, g), 1, 0.0);
    assert!(few.was_thinned());
    assert_eq!(few.as_slice().len(), 2); // beams 0 and 3 (decimation raised to 3)
    let mut none = ScanPoints::<0>::new();
    assert_eq!(none.load(&LidarScan::new(&ranges, g), 1, 0.0), 0);
}
