//! Tests of the global search: against the brute force, in slices, with the heading
//! windows and the full turn, with a work budget and refused inputs.

use super::beams::prepare;
use super::bound::leaf_score;
use super::tables::{Rotations, end_cells};
use super::*;
use crate::geometry::Pose2;
use crate::grid::{GridGeometry, GridView, MaxPoolLayers};
use crate::pf::ScanPoints;
use crate::pf::correlation::ScanPoint;
use crate::sensors::lidar::{LidarGeometry, LidarScan};
use rand::{Rng, SeedableRng};

/// A random `w × h` map: free inside, rectangles of wall, unknown cells sprinkled.
fn random_map(rng: &mut rand::rngs::StdRng, w: usize, h: usize) -> Vec<i8> {
    let mut cells = vec![-60i8; w * h];
    for _ in 0..(w * h / 150).max(3) {
        let (x0, y0) = (rng.random_range(0..w), rng.random_range(0..h));
        let (lx, ly) = (rng.random_range(1..8), rng.random_range(1..3));
        let (lx, ly) = if rng.random_bool(0.5) {
            (lx, ly)
        } else {
            (ly, lx)
        };
        for y in y0..(y0 + ly).min(h) {
            for x in x0..(x0 + lx).min(w) {
                cells[y * w + x] = 60;
            }
        }
    }
    for c in cells.iter_mut() {
        if *c < 0 && rng.random_bool(0.1) {
            *c = 0;
        }
    }
    cells
}

/// A random pose at the centre of a free cell of the `w × h` map `cells`.
fn free_pose(
    rng: &mut rand::rngs::StdRng,
    cells: &[i8],
    w: usize,
    h: usize,
    g: &GridGeometry,
) -> Pose2<f32> {
    loop {
        let (x, y) = (rng.random_range(0..w), rng.random_range(0..h));
        if cells[y * w + x] < -20 {
            let (px, py) = g.cell_centre(x as i32, y as i32);
            return Pose2::new(px, py, rng.random_range(-3.1..3.1));
        }
    }
}

const LIDAR: LidarGeometry = LidarGeometry {
    first_angle: -3.0,
    angle_increment: 6.0 / 60.0,
    min_range: 0.05,
    max_range: 5.0,
    no_return_range: 5.0,
    mount: Pose2::new(0.0, 0.0, 0.0),
};

/// Ranges seen from `pose` on `view` (out to 4 m).
fn ray_cast(view: &GridView<'_>, pose: &Pose2<f32>) -> Vec<f32> {
    (0..60)
        .map(|i| {
            let a = pose.theta + LIDAR.beam_angle(i);
            view.ray_range(pose.x, pose.y, a, 4.0)
                .unwrap_or(f32::INFINITY)
        })
        .collect()
}

/// Every heading (the brute force searches them all).
fn config() -> GlobalSearchConfig {
    GlobalSearchConfig {
        heading_step: 0.25,
        work_budget: u32::MAX,
        heading_peaks: 0,
        ..GlobalSearchConfig::DEFAULT
    }
}

/// Score of `pose` recomputed the brute-force way (its heading and cell).
fn rescore(
    view: &GridView<'_>,
    layers: &MaxPoolLayers<'_>,
    points: &[ScanPoint],
    c: &GlobalSearchConfig,
    h: &Hypothesis,
) -> u32 {
    let (sel, step, headings) = prepare(view, layers, points, c).unwrap();
    let j = (h.pose.theta.rem_euclid(2.0 * std::f32::consts::PI) / step).round() as u32;
    let mut cells = [(0, 0, 0); MAX_SEARCH_BEAMS];
    end_cells(&sel, Rotations::new(step).at(j % headings), &mut cells);
    let (x, y) = view.geometry().world_to_cell(h.pose.x, h.pose.y).unwrap();
    leaf_score(view, &cells[..sel.len], x as i32, y as i32)
}

#[test]
fn exact_search_equals_brute_force_on_random_maps() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(11);
    let mut pruned = 0u64;
    let mut total = 0u64;
    for trial in 0..40 {
        let (w, h) = (rng.random_range(20..56), rng.random_range(16..48));
        let cells = random_map(&mut rng, w, h);
        let g = GridGeometry::centred(w, h, 0.05);
        let view = GridView::new(&cells, g, 20).unwrap();
        let levels = rng.random_range(1..=5);
        let mut buf = vec![0u8; MaxPoolLayers::bytes_for(w, h, levels).unwrap()];
        let layers = MaxPoolLayers::build(&view, -20, levels, &mut buf).unwrap();
        // A scan from a random free cell: its own pose scores all its hits.
        let pose = free_pose(&mut rng, &cells, w, h, &g);
        let ranges = ray_cast(&view, &pose);
        let mut pts = ScanPoints::<60>::new();
        pts.load(&LidarScan::new(&ranges, LIDAR), 1, [0.0, 1.0][trial % 2]);
        if pts.as_slice().is_empty() {
            continue;
        }
        let c = GlobalSearchConfig {
            min_score_fraction: [0.0, 0.3, 0.6][trial % 3],
            ..config()
        };
        let (mut fast, mut slow) = (Hypotheses::<3>::new(), Hypotheses::<3>::new());
        let rf = search(&view, &layers, pts.as_slice(), &c, &mut fast).unwrap();
        let rs = search_brute_force(&view, &layers, pts.as_slice(), &c, &mut slow).unwrap();
        assert!(rf.complete);
        assert_eq!(rf.headings, rs.headings);
        assert_eq!(
            fast.best().map(|b| b.score),
            slow.best().map(|b| b.score),
            "trial {trial}: {fast:?} vs {slow:?}"
        );
        for hyp in fast.as_slice() {
            assert_eq!(
                rescore(&view, &layers, pts.as_slice(), &c, hyp),
                hyp.score,
                "trial {trial}"
            );
            assert!(hyp.score >= rf.min_score.max(1));
        }
        assert!(!fast.is_empty() || slow.is_empty());
        pruned += u64::from(rs.nodes.saturating_sub(rf.leaves));
        total += u64::from(rs.nodes);
    }
    // Branch and bound must skip most of the leaves the brute force scores.
    assert!(pruned * 2 > total, "{pruned} of {total}");
}

/// A random map of `w × h` cells, its layers (`levels`, as bytes) and a scan ray-cast
/// from a random free cell of it.
fn random_scene(
    rng: &mut rand::rngs::StdRng,
    w: usize,
    h: usize,
    levels: u8,
) -> (Vec<i8>, GridGeometry, Vec<u8>, ScanPoints<60>) {
    let cells = random_map(rng, w, h);
    let g = GridGeometry::centred(w, h, 0.05);
    let view = GridView::new(&cells, g, 20).unwrap();
    let mut buf = vec![0u8; MaxPoolLayers::bytes_for(w, h, levels).unwrap()];
    MaxPoolLayers::build(&view, -20, levels, &mut buf).unwrap();
    let pose = free_pose(rng, &cells, w, h, &g);
    let ranges = ray_cast(&view, &pose);
    let mut pts = ScanPoints::<60>::new();
    pts.load(&LidarScan::new(&ranges, LIDAR), 1, 0.0);
    (cells, g, buf, pts)
}

/// A search run in slices of random sizes finds what one run with their sum as its
/// budget finds, node for node: complete searches, searches the budget stops, with
/// and without heading windows and the full turn after them.
#[test]
fn slices_find_what_one_search_finds() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(31);
    let (mut stopped, mut sliced) = (0, 0);
    for trial in 0..40 {
        let (w, h) = (rng.random_range(20..56), rng.random_range(16..48));
        let levels = rng.random_range(1..=5);
        let (cells, g, buf, pts) = random_scene(&mut rng, w, h, levels);
        let view = GridView::new(&cells, g, 20).unwrap();
        let layers = MaxPoolLayers::from_bytes(&buf).unwrap();
        if pts.as_slice().is_empty() {
            continue;
        }
        let c = match trial % 3 {
            0 => config(),
            1 => GlobalSearchConfig {
                min_score_fraction: 0.3,
                heading_peaks: 1,
                heading_window: 0.01,
                full_turn_below: 1.0,
                ..config()
            },
            _ => GlobalSearchConfig {
                min_score_fraction: 0.6,
                heading_peaks: 2,
                heading_window: 0.05,
                full_turn_below: 0.9,
                ..config()
            },
        };
        let mut whole = Hypotheses::<3>::new();
        let all = search(&view, &layers, pts.as_slice(), &c, &mut whole).unwrap();
        assert!(all.complete);
        // A budget that stops the search, or one that lets it finish.
        let budget = if trial % 4 == 3 {
            all.work + 3
        } else {
            rng.random_range(1..=all.work.max(1))
        };
        let c = GlobalSearchConfig {
            work_budget: budget,
            ..c
        };
        let mut one = Hypotheses::<3>::new();
        let r_one = search(&view, &layers, pts.as_slice(), &c, &mut one).unwrap();
        let mut run = GlobalSearch::<3>::start(&view, &layers, None, pts.as_slice(), &c).unwrap();
        let mut left = budget;
        let mut slices = 0;
        while left > 0 && !run.is_done() {
            let n = rng.random_range(1..=40).min(left);
            let over = run.resume(&view, &layers, n).unwrap();
            assert_eq!(over, run.is_done());
            left -= n;
            slices += 1;
        }
        run.conclude();
        let r_run = *run.report();
        stopped += usize::from(!r_one.complete);
        sliced += usize::from(slices > 1);
        assert_eq!(run.hypotheses().as_slice(), one.as_slice(), "trial {trial}");
        assert_eq!(
            (
                r_run.nodes,
                r_run.work,
                r_run.leaves,
                r_run.nodes_per_level,
                r_run.passes
            ),
            (
                r_one.nodes,
                r_one.work,
                r_one.leaves,
                r_one.nodes_per_level,
                r_one.passes
            ),
            "trial {trial}"
        );
        assert_eq!(
            (r_run.complete, r_run.full_turn, r_run.min_score),
            (r_one.complete, r_one.full_turn, r_one.min_score),
            "trial {trial}"
        );
        // Resuming a search that is over does nothing.
        assert_eq!(run.resume(&view, &layers, 100), Ok(true));
        assert_eq!(run.report().nodes, r_one.nodes);
    }
    assert!(
        stopped >= 10 && sliced >= 20,
        "{stopped} stopped, {sliced} sliced"
    );
}

/// A slice is refused on a map of another size or with layers of another map.
#[test]
fn a_slice_on_another_map_is_refused() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    let (cells, g, buf, pts) = random_scene(&mut rng, 32, 24, 3);
    let view = GridView::new(&cells, g, 20).unwrap();
    let layers = MaxPoolLayers::from_bytes(&buf).unwrap();
    let mut run =
        GlobalSearch::<3>::start(&view, &layers, None, pts.as_slice(), &config()).unwrap();
    let (other_cells, other_g, other_buf, _) = random_scene(&mut rng, 40, 24, 3);
    let other = GridView::new(&other_cells, other_g, 20).unwrap();
    let other_layers = MaxPoolLayers::from_bytes(&other_buf).unwrap();
    assert_eq!(
        run.resume(&other, &other_layers, 10),
        Err(GlobalError::LayersMismatch)
    );
    assert_eq!(
        run.resume(&view, &other_layers, 10),
        Err(GlobalError::LayersMismatch)
    );
    assert_eq!(run.report().nodes, 0);
    assert_eq!(run.resume(&view, &layers, u32::MAX), Ok(true));
}

/// Windows one peak wide miss the robot's heading on some maps; the full turn after
/// them then finds what the brute force finds.
#[test]
fn a_full_turn_after_the_windows_finds_the_brute_force_best() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(23);
    let (mut windowed, mut missed) = (0, 0);
    for trial in 0..60 {
        let (w, h) = (rng.random_range(24..56), rng.random_range(20..48));
        let cells = random_map(&mut rng, w, h);
        let g = GridGeometry::centred(w, h, 0.05);
        let view = GridView::new(&cells, g, 20).unwrap();
        let mut buf = vec![0u8; MaxPoolLayers::bytes_for(w, h, 3).unwrap()];
        let layers = MaxPoolLayers::build(&view, -20, 3, &mut buf).unwrap();
        let pose = free_pose(&mut rng, &cells, w, h, &g);
        let ranges = ray_cast(&view, &pose);
        let mut pts = ScanPoints::<60>::new();
        pts.load(&LidarScan::new(&ranges, LIDAR), 1, 0.0);
        if pts.as_slice().is_empty() {
            continue;
        }
        let every = GlobalSearchConfig {
            min_score_fraction: 0.3,
            ..config()
        };
        let narrow = GlobalSearchConfig {
            heading_peaks: 1,
            heading_window: 0.01,
            full_turn_below: 0.0,
            ..every
        };
        let turn = GlobalSearchConfig {
            full_turn_below: 1.0,
            ..narrow
        };
        let mut brute = Hypotheses::<3>::new();
        search_brute_force(&view, &layers, pts.as_slice(), &every, &mut brute).unwrap();
        let mut only = Hypotheses::<3>::new();
        let r_only = search(&view, &layers, pts.as_slice(), &narrow, &mut only).unwrap();
        let mut both = Hypotheses::<3>::new();
        let r_both = search(&view, &layers, pts.as_slice(), &turn, &mut both).unwrap();
        assert!(!r_only.full_turn && r_both.complete, "trial {trial}");
        if r_only.heading_windows == 1 {
            continue; // too few wall lines: every heading searched anyway
        }
        windowed += 1;
        let best = |h: &Hypotheses<3>| h.best().map(|b| b.score);
        if best(&only) < best(&brute) {
            missed += 1;
        }
        assert_eq!(r_both.full_turn, best(&brute) < Some(r_both.total_weight));
        assert_eq!(
            best(&both),
            best(&brute),
            "trial {trial}: {both:?} vs {brute:?} {r_both:?} {r_only:?}"
        );
        for hyp in both.as_slice() {
            assert_eq!(
                rescore(&view, &layers, pts.as_slice(), &turn, hyp),
                hyp.score
            );
        }
    }
    // The case the fallback exists for arises, on more than a few maps.
    assert!(
        windowed >= 10 && missed >= 3,
        "{windowed} windowed, {missed} missed"
    );
}

#[test]
fn budget_stops_the_search_and_bad_inputs_are_refused() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    let cells = random_map(&mut rng, 40, 40);
    let g = GridGeometry::centred(40, 40, 0.05);
    let view = GridView::new(&cells, g, 20).unwrap();
    let mut buf = vec![0u8; MaxPoolLayers::bytes_for(40, 40, 3).unwrap()];
    let layers = MaxPoolLayers::build(&view, -20, 3, &mut buf).unwrap();
    let ranges = ray_cast(&view, &Pose2::new(0.0, 0.0, 0.3));
    let mut pts = ScanPoints::<60>::new();
    pts.load(&LidarScan::new(&ranges, LIDAR), 1, 0.0);
    let mut out = Hypotheses::<2>::new();
    let c = GlobalSearchConfig {
        work_budget: 50,
        ..config()
    };
    let r = search(&view, &layers, pts.as_slice(), &c, &mut out).unwrap();
    // It stops at the first node evaluation that finds the work spent, so it
    // overruns by less than one node's work; each node counts NODE_WORK and at
    // least one and at most every beam.
    let most_per_node = u32::from(r.beams) + NODE_WORK;
    assert!(
        !r.complete && r.work >= 50 && r.work < 50 + most_per_node,
        "{r:?}"
    );
    assert!(
        r.work >= r.nodes * (NODE_WORK + 1) && r.work <= r.nodes * most_per_node,
        "{r:?}"
    );
    // No beam, bad settings, layers of another map.
    assert_eq!(
        search(&view, &layers, &[], &config(), &mut out).err(),
        Some(GlobalError::EmptyScan)
    );
    let far: Vec<_> = pts
        .as_slice()
        .iter()
        .map(|p| ScanPoint { range: 9.0, ..*p })
        .collect();
    assert_eq!(
        search(&view, &layers, &far, &config(), &mut out).err(),
        Some(GlobalError::EmptyScan)
    );
    let nan: Vec<_> = pts
        .as_slice()
        .iter()
        .map(|p| ScanPoint {
            range: f32::NAN,
            ..*p
        })
        .collect();
    assert_eq!(
        search(&view, &layers, &nan, &config(), &mut out).err(),
        Some(GlobalError::EmptyScan)
    );
    for bad in [
        GlobalSearchConfig {
            max_range: f32::NAN,
            ..config()
        },
        GlobalSearchConfig {
            max_beams: 0,
            ..config()
        },
        GlobalSearchConfig {
            max_beams: 500,
            ..config()
        },
        GlobalSearchConfig {
            min_score_fraction: 1.5,
            ..config()
        },
        GlobalSearchConfig {
            heading_step: -1.0,
            ..config()
        },
        GlobalSearchConfig {
            work_budget: 0,
            ..config()
        },
    ] {
        assert_eq!(
            search(&view, &layers, pts.as_slice(), &bad, &mut out).err(),
            Some(GlobalError::InvalidConfig)
        );
    }
    let other_cells = vec![0i8; 40 * 41];
    let other = GridView::new(&other_cells, GridGeometry::centred(40, 41, 0.05), 20).unwrap();
    assert_eq!(
        search(&other, &layers, pts.as_slice(), &config(), &mut out).err(),
        Some(GlobalError::LayersMismatch)
    );
}

#[test]
fn heading_step_follows_the_extent() {
    // One cell at 8 m: 0.05 / 8 rad (to first order).
    let s = heading_step_for(0.05, 8.0);
    assert!((s - 0.05 / 8.0).abs() < 1e-4, "{s}");
    assert!(heading_step_for(0.05, 2.0) > 3.9 * s);
}
