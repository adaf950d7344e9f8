//! Global localization and lost detection in the simulated room of [`super::tests`]: the
//! map is drawn from one simulated run's true poses, the scans come from another run with
//! other noise.

use super::global::{self, GlobalSearchConfig, Hypotheses};
use super::tests::{Grid, LIDAR, Sim, simulate, true_map};
use super::*;
use crate::geometry::{Pose2, wrap_angle};
use crate::grid::{GridView, MaxPoolLayers};
use crate::sensors::lidar::LidarScan;

const LEVELS: u8 = 6;

/// The room's map (from run 5's true poses) and its max-pooled layers.
fn room_map() -> (Box<Grid>, Vec<u8>) {
    let config = GridPfConfig::DEFAULT;
    let map = true_map(&simulate(5), &config);
    let view = map.view();
    let mut layers = vec![0u8; MaxPoolLayers::bytes_for(256, 256, LEVELS).unwrap()];
    MaxPoolLayers::build(&view, config.log_odds.free_below, LEVELS, &mut layers).unwrap();
    (map, layers)
}

fn close(a: &Pose2<f32>, b: &Pose2<f32>, m: f32, rad: f32) -> bool {
    (a.x - b.x).hypot(a.y - b.y) <= m && wrap_angle(a.theta - b.theta).abs() <= rad
}

#[test]
fn known_pose_is_found_from_a_simulated_scan() {
    let (map, layers) = room_map();
    let view = map.view();
    let layers = MaxPoolLayers::from_bytes(&layers).unwrap();
    let sim = simulate(7);
    let mut worst_nodes = 0;
    for k in (0..sim.scans.len()).step_by(37) {
        let mut pts = ScanPoints::<180>::new();
        pts.load(&LidarScan::new(&sim.scans[k], LIDAR), 1, 1.0);
        let mut found = Hypotheses::<4>::new();
        let r = global::search(
            &view,
            &layers,
            pts.as_slice(),
            // 60 beams: with 45 the room's near point symmetry makes the mirrored pose
            // of scan 111 score higher (the search is exact; the scan is ambiguous).
            &GlobalSearchConfig {
                work_budget: u32::MAX,
                max_beams: 60,
                ..GlobalSearchConfig::DEFAULT
            },
            &mut found,
        )
        .unwrap();
        let best = found.best().unwrap();
        std::println!(
            "scan {k}: {:?} truth {:?}; {} nodes {:?}, {} headings, complete {}",
            best,
            sim.truth[k],
            r.nodes,
            r.nodes_per_level,
            r.headings,
            r.complete
        );
        assert!(
            close(&best.pose, &sim.truth[k], 0.1, 0.05),
            "scan {k}: {best:?} vs {:?}",
            sim.truth[k]
        );
        worst_nodes = worst_nodes.max(r.nodes);
    }
    std::println!("most nodes {worst_nodes}");
}

/// The same search on the map's occupied-cell bitmap alone (what a map image in flash
/// holds: no log-odds, so level 0 cannot tell free from unknown and takes the cells that
/// are not occupied in a free 2 × 2 block of level 1): the same poses are found.
#[test]
fn known_pose_is_found_on_the_occupied_bitmap_alone() {
    let (map, layers) = room_map();
    let view = map.view();
    let g = *view.geometry();
    let mut bits = std::vec![0u8; crate::grid::occupancy_bytes(g.width, g.height)];
    crate::grid::fill_occupancy_bits(
        view.cells(),
        g.width,
        g.height,
        view.occupied_above(),
        &mut bits,
    )
    .unwrap();
    let bitmap_only = GridView::from_occupancy_bits(&bits, g, view.occupied_above()).unwrap();
    assert!(bitmap_only.cells().is_empty());
    let layers = MaxPoolLayers::from_bytes(&layers).unwrap();
    let sim = simulate(7);
    for k in (0..sim.scans.len()).step_by(37) {
        let mut pts = ScanPoints::<180>::new();
        pts.load(&LidarScan::new(&sim.scans[k], LIDAR), 1, 1.0);
        let config = GlobalSearchConfig {
            work_budget: u32::MAX,
            max_beams: 60,
            ..GlobalSearchConfig::DEFAULT
        };
        let (mut found, mut with_cells) = (Hypotheses::<4>::new(), Hypotheses::<4>::new());
        let r = global::search(&bitmap_only, &layers, pts.as_slice(), &config, &mut found).unwrap();
        global::search(&view, &layers, pts.as_slice(), &config, &mut with_cells).unwrap();
        let best = found.best().expect("a hypothesis on the bitmap alone");
        std::println!(
            "scan {k}: {best:?}, {} nodes; with the cells {:?}",
            r.nodes,
            with_cells.best()
        );
        assert!(
            close(&best.pose, &sim.truth[k], 0.1, 0.05),
            "scan {k}: {best:?} vs {:?}",
            sim.truth[k]
        );
        assert!(r.complete);
    }
}

/// Runs a localizer over scans `from..to` of `sim` (odometry between them).
/// A localizer with 64 particles and the default settings on `map`, given no pose: lost,
/// its global search pending.
fn lost_on<'m>(map: &'m Grid, layers: MaxPoolLayers<'m>) -> GridLocalizer<'m, 64, 180> {
    let loc = GridLocalizer::<64, 180>::without_pose(
        map.view(),
        GridPfConfig::DEFAULT,
        layers,
        RelocalizationConfig::DEFAULT,
    )
    .unwrap();
    assert_eq!(loc.state(), LocalizerState::Lost);
    loc
}

fn drive<const P: usize>(loc: &mut GridLocalizer<'_, P, 180>, sim: &Sim, from: usize, to: usize) {
    for i in from..to {
        if i > from {
            loc.predict_odometry(&sim.odometry[i - 1], &sim.odometry[i])
                .unwrap();
        }
        loc.observe(&LidarScan::new(&sim.scans[i], LIDAR)).unwrap();
    }
}

#[test]
fn global_localization_converges_within_ten_scans() {
    let (map, layers) = room_map();
    let layers = MaxPoolLayers::from_bytes(&layers).unwrap();
    let sim = simulate(7);
    for start in (0..sim.scans.len() - 10).step_by(29) {
        let mut loc = lost_on(&map, layers);
        drive(&mut loc, &sim, start, start + 10);
        let (pose, truth) = (loc.pose(), sim.truth[start + 9]);
        std::println!("start {start}: {pose:?} truth {truth:?} {:?}", loc.status());
        assert!(
            close(&pose, &truth, 0.3, 10f32.to_radians()),
            "start {start}: {pose:?} vs {truth:?}"
        );
        assert_eq!(loc.status().relocalizations, 1);
        assert_ne!(loc.state(), LocalizerState::Lost);
    }
}

/// A search that spans scans (5 000 units of work a scan): the localizer stays lost and does not
/// filter while it runs, then seeds the particles at the hypotheses moved by the odometry
/// since the search's scan — where the robot is at the scan that ends the search.
#[test]
fn a_search_spanning_scans_seeds_where_the_robot_is_now() {
    let (map, layers) = room_map();
    let layers = MaxPoolLayers::from_bytes(&layers).unwrap();
    let sim = simulate(7);
    let reloc = RelocalizationConfig {
        search: GlobalSearchConfig {
            work_budget: 5_000,
            ..GlobalSearchConfig::DEFAULT
        },
        search_scans: 40,
        ..RelocalizationConfig::DEFAULT
    };
    let mut spanned = 0;
    for start in (0..sim.scans.len() - 40).step_by(29) {
        let mut loc = GridLocalizer::<64, 180>::without_pose(
            map.view(),
            GridPfConfig::DEFAULT,
            layers,
            reloc,
        )
        .unwrap();
        let mut seeded_at = None;
        for (n, i) in (start..start + 40).enumerate() {
            if i > start {
                loc.predict_odometry(&sim.odometry[i - 1], &sim.odometry[i])
                    .unwrap();
            }
            loc.observe(&LidarScan::new(&sim.scans[i], LIDAR)).unwrap();
            let s = *loc.status();
            if !s.search_pending {
                assert_eq!(loc.search_scans_run(), 0, "no search under way once seeded");
                seeded_at = Some(i);
                break;
            }
            assert_eq!(loc.search_scans_run(), n as u8 + 1, "one slice a scan");
            assert_eq!(s.state, LocalizerState::Lost);
            assert_eq!(loc.filter().update_count(), 0, "no update while searching");
            let report = s.last_search.expect("a slice ran");
            // The work granted adds up over the slices; a slice overruns by less than
            // one node's work.
            let granted = 5_000 * (n as u32 + 1);
            let node = u32::from(report.beams) + global::NODE_WORK;
            assert!(
                report.work >= granted && report.work < granted + node,
                "{report:?}"
            );
            assert!(!report.complete);
        }
        let i = seeded_at.expect("the search ends within 40 scans");
        let s = *loc.status();
        let slices = i - start + 1;
        std::println!(
            "start {start}: seeded at scan {i} ({slices} slices), {:?}, truth {:?}",
            loc.hypotheses(),
            sim.truth[i]
        );
        assert_eq!(s.state, LocalizerState::Relocalized);
        assert_eq!(s.relocalizations, 1);
        assert!(s.last_search.is_some_and(|r| r.complete));
        assert!(
            loc.hypotheses()
                .iter()
                .any(|h| close(&h.pose, &sim.truth[i], 0.1, 0.05)),
            "start {start}: {:?} vs {:?}",
            loc.hypotheses(),
            sim.truth[i]
        );
        spanned += usize::from(slices >= 3);
    }
    // The robot drove 10 cm a scan: at 3 slices and more, hypotheses left where the
    // search's scan was taken would be 20 cm or more off.
    assert!(spanned >= 3, "{spanned} searches spanned 3 scans or more");
}

#[test]
fn lost_detection_fires_on_a_kidnapped_robot_and_not_on_a_normal_run() {
    let (map, layers) = room_map();
    let layers = MaxPoolLayers::from_bytes(&layers).unwrap();
    let sim = simulate(7);
    // A normal run: never lost.
    let mut loc = GridLocalizer::<64, 180>::new(map.view(), GridPfConfig::DEFAULT, sim.truth[0])
        .unwrap()
        .with_layers(layers, RelocalizationConfig::DEFAULT)
        .unwrap();
    let mut lowest = 1.0f32;
    for i in 0..sim.scans.len() {
        if i > 0 {
            loc.predict_odometry(&sim.odometry[i - 1], &sim.odometry[i])
                .unwrap();
        }
        loc.observe(&LidarScan::new(&sim.scans[i], LIDAR)).unwrap();
        lowest = lowest.min(loc.status().hit_fraction);
    }
    let s = *loc.status();
    std::println!("normal run: {s:?}, lowest hit fraction {lowest}");
    assert_eq!(s.lost_events, 0, "{s:?}");
    assert_eq!(s.state, LocalizerState::Tracking);

    // Kidnapped after scan 99: the scans jump to the other side of the room (scan 200
    // on), the odometry goes on as if nothing happened.
    let mut loc = GridLocalizer::<64, 180>::new(map.view(), GridPfConfig::DEFAULT, sim.truth[0])
        .unwrap()
        .with_layers(layers, RelocalizationConfig::DEFAULT)
        .unwrap();
    drive(&mut loc, &sim, 0, 100);
    assert_eq!(loc.state(), LocalizerState::Tracking);
    let mut lost_at = None;
    let mut odom = sim.odometry[99];
    for (n, i) in (200..260).enumerate() {
        let next = odom.compose(&sim.odometry[i - 1].between(&sim.odometry[i]));
        loc.predict_odometry(&odom, &next).unwrap();
        odom = next;
        loc.observe(&LidarScan::new(&sim.scans[i], LIDAR)).unwrap();
        if lost_at.is_none() && loc.status().lost_events > 0 {
            lost_at = Some(n);
        }
    }
    let s = *loc.status();
    std::println!(
        "kidnapped: lost after {lost_at:?} scans, {s:?}, pose {:?} truth {:?}",
        loc.pose(),
        sim.truth[259]
    );
    assert!(lost_at.is_some_and(|n| n < 10), "{lost_at:?}");
    assert!(s.relocalizations >= 1);
    assert_eq!(s.state, LocalizerState::Tracking);
    assert!(close(&loc.pose(), &sim.truth[259], 0.3, 10f32.to_radians()));
}

#[test]
fn bad_inputs_give_errors() {
    let (map, layers) = room_map();
    let view = map.view();
    let config = GridPfConfig::DEFAULT;
    let good = MaxPoolLayers::from_bytes(&layers).unwrap();
    // No layers: no relocalization.
    let mut plain = GridLocalizer::<8, 180>::new(view, config, Pose2::IDENTITY).unwrap();
    assert_eq!(plain.relocalize(), Err(global::GlobalError::NoLayers));
    // Layers of another map (another occupied threshold).
    let other = GridView::new(map.cells(), *map.geometry(), 5).unwrap();
    let mut other_layers = vec![0u8; layers.len()];
    let other_layers = MaxPoolLayers::build(
        &other,
        config.log_odds.free_below,
        LEVELS,
        &mut other_layers,
    )
    .unwrap();
    assert_eq!(
        GridLocalizer::<8, 180>::new(view, config, Pose2::IDENTITY)
            .unwrap()
            .with_layers(other_layers, RelocalizationConfig::DEFAULT)
            .err(),
        Some(global::GlobalError::LayersMismatch)
    );
    // Bad settings.
    let bad = RelocalizationConfig {
        hypotheses: 0,
        ..RelocalizationConfig::DEFAULT
    };
    assert_eq!(
        GridLocalizer::<8, 180>::without_pose(view, config, good, bad).err(),
        Some(global::GlobalError::InvalidConfig)
    );
    // Empty and NaN scans: refused, the search stays pending.
    let mut loc =
        GridLocalizer::<8, 180>::without_pose(view, config, good, RelocalizationConfig::DEFAULT)
            .unwrap();
    for ranges in [vec![], vec![f32::NAN; 180], vec![f32::INFINITY; 180]] {
        assert_eq!(
            loc.observe(&LidarScan::new(&ranges, LIDAR)).err(),
            Some(PfError::EmptyScan)
        );
        assert_eq!(loc.state(), LocalizerState::Lost);
        assert!(loc.status().search_pending);
    }
    // Truncated layers image.
    assert!(MaxPoolLayers::from_bytes(&layers[..layers.len() - 3]).is_err());
}

#[test]
fn a_reset_to_a_given_pose_clears_the_lost_state() {
    let (map, layers) = room_map();
    let layers = MaxPoolLayers::from_bytes(&layers).unwrap();
    let sim = simulate(7);
    let mut loc = lost_on(&map, layers);
    assert!(loc.status().search_pending);
    // The pose is given: tracking, and the next scan runs no global search.
    loc.reset_around(sim.truth[0], 0.0, 0.0).unwrap();
    assert_eq!(loc.state(), LocalizerState::Tracking);
    assert!(!loc.status().search_pending);
    drive(&mut loc, &sim, 0, 5);
    let s = *loc.status();
    assert_eq!(s.relocalizations, 0, "{s:?}");
    assert!(s.last_search.is_none(), "{s:?}");
    assert_eq!(s.state, LocalizerState::Tracking);
    assert!(close(&loc.pose(), &sim.truth[4], 0.1, 3f32.to_radians()));
    // The same after a relocalization request.
    loc.relocalize().unwrap();
    assert_eq!(loc.state(), LocalizerState::Lost);
    loc.reset_around(sim.truth[5], 0.0, 0.0).unwrap();
    assert_eq!(loc.state(), LocalizerState::Tracking);
    assert!(!loc.status().search_pending);
}
