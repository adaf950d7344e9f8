//! Capacity edges of the grid particle filter, through the public API: all particles with
//! zero likelihood, a zero-length time step, an empty scan, and a robot driving off the
//! map — each must leave the filter finite, normalised and able to go on — and scan end
//! points off the grid, which SLAM skips and counts.

use microslam::geometry::Pose2;
use microslam::grid::{GridGeometry, GridView, OccupancyGrid};
use microslam::pf::{GridLocalizer, GridPfConfig, GridSlam, PfError};
use microslam::sensors::lidar::{LidarGeometry, LidarScan};

const SIDE: usize = 64;

/// A 3.2 m square room: walls on the border cells, free inside.
fn room() -> Vec<i8> {
    let mut cells = vec![-40i8; SIDE * SIDE];
    for i in 0..SIDE {
        for (x, y) in [(i, 0), (i, SIDE - 1), (0, i), (SIDE - 1, i)] {
            cells[y * SIDE + x] = 100;
        }
    }
    cells
}

fn assert_normalised<const P: usize>(l: &GridLocalizer<'_, P, 64>) {
    let w = l.filter().log_weights();
    assert!(w.iter().all(|v| v.is_finite()), "{w:?}");
    let max = w.iter().fold(f32::NEG_INFINITY, |m, &v| m.max(v));
    let sum: f32 = w.iter().map(|&v| (v - max).exp()).sum();
    assert!((max + sum.ln()).abs() < 1e-4, "Σ w ≠ 1: {w:?}");
    assert!(l.pose().is_finite());
}

#[test]
fn zero_likelihood_everywhere_keeps_uniform_weights_then_recovers() {
    let geometry = GridGeometry::centred(SIDE, SIDE, 0.05);
    let empty = vec![-40i8; SIDE * SIDE];
    let map = GridView::new(&empty, geometry, 20).expect("valid map");
    let config = GridPfConfig::MICROCONTROLLER;
    let mut l =
        GridLocalizer::<16, 64>::new(map, config, Pose2::new(0.0, 0.0, 0.0)).expect("valid");
    l.reset_around(Pose2::new(0.0, 0.0, 0.0), 0.05, 0.05)
        .expect("finite");
    // No occupied cell anywhere: every particle scores zero.
    let ranges = [1.0f32; 64];
    let scan = LidarScan::new(
        &ranges,
        LidarGeometry {
            first_angle: -3.1,
            angle_increment: 0.098,
            ..LidarGeometry::CARMEN_SICK_180
        },
    );
    for _ in 0..5 {
        let report = l.observe(&scan).expect("a usable scan");
        assert_eq!(report.score, 0);
        assert_normalised(&l);
        assert!(
            (l.filter().n_eff() - 16.0).abs() < 1e-3,
            "uniform weights: N_eff = P"
        );
    }
    // The same filter on a map with walls: scores come back and the weights stay sane.
    let walls = room();
    let map = GridView::new(&walls, geometry, 20).expect("valid map");
    let mut l =
        GridLocalizer::<16, 64>::new(map, config, Pose2::new(0.0, 0.0, 0.0)).expect("valid");
    let near_walls = [1.55f32; 64];
    let scan = LidarScan::new(
        &near_walls,
        LidarGeometry {
            first_angle: -3.1,
            angle_increment: 0.098,
            ..LidarGeometry::CARMEN_SICK_180
        },
    );
    let report = l.observe(&scan).expect("a usable scan");
    assert!(report.score > 0);
    assert_normalised(&l);
}

#[test]
fn zero_time_step_empty_scan_and_leaving_the_map() {
    let geometry = GridGeometry::centred(SIDE, SIDE, 0.05);
    let walls = room();
    let map = GridView::new(&walls, geometry, 20).expect("valid map");
    let mut l = GridLocalizer::<16, 64>::new(
        map,
        GridPfConfig::MICROCONTROLLER,
        Pose2::new(0.0, 0.0, 0.0),
    )
    .expect("valid");
    let before = *l.filter().poses();
    l.predict_velocity(0.5, 0.1, 0.0)
        .expect("a zero-length step is a no-op");
    assert_eq!(*l.filter().poses(), before);
    assert_eq!(
        l.observe(&LidarScan::new(&[], LidarGeometry::CARMEN_SICK_180))
            .err(),
        Some(PfError::EmptyScan)
    );
    // Drive 100 m away: off the map nothing scores, the filter stays finite.
    l.predict(100.0, 0.0).expect("finite");
    let ranges = [1.0f32; 64];
    l.observe(&LidarScan::new(&ranges, LidarGeometry::CARMEN_SICK_180))
        .expect("a usable scan, off the map too");
    assert_normalised(&l);
    let poses = l.filter().poses();
    assert!(poses.iter().all(|p| p.is_finite()), "{poses:?}");
    // Most particles are now off the 3.2 m map (the 100 m arc's noise spreads them widely).
    assert!(
        poses.iter().filter(|p| p.x.hypot(p.y) > 10.0).count() >= 8,
        "{poses:?}"
    );
}

#[test]
fn slam_at_the_edge_of_the_grid_counts_its_off_grid_points() {
    let config = GridPfConfig::MICROCONTROLLER;
    let mut grid = Box::new(OccupancyGrid::<SIDE, SIDE>::centred(
        config.resolution,
        config.log_odds,
    ));
    // The grid spans ±1.6 m. The robot at x = 1.5 m sees a wall 1 m away all around: the
    // end points at x ≥ 1.6 m fall off the grid, the others on it.
    let geometry = LidarGeometry {
        first_angle: -3.1,
        angle_increment: 0.098,
        ..LidarGeometry::CARMEN_SICK_180
    };
    let ranges = [1.0f32; 64];
    let used: Vec<f64> = (0..64)
        .step_by(config.beam_decimation)
        .map(|i| -3.1 + 0.098 * i as f64)
        .collect();
    // From the beam angles alone; no end point lies within 1 cm of the edge.
    let off = used.iter().filter(|a| 1.5 + a.cos() >= 1.6).count() as u32;
    assert!(used.iter().all(|a| (1.5 + a.cos() - 1.6).abs() > 0.01));
    assert!(off > 0 && (off as usize) < used.len());
    let map = {
        let mut slam =
            GridSlam::<SIDE, SIDE, 16, 64>::new(&mut grid, config, Pose2::new(1.5, 0.0, 0.0))
                .expect("valid");
        slam.observe(&LidarScan::new(&ranges, geometry))
            .expect("a usable scan")
            .map
    };
    assert_eq!(map.beams as usize, used.len(), "{map:?}");
    assert_eq!(map.off_grid, off, "{map:?}");
    assert_eq!(map.hits, map.beams - off, "{map:?}");
    assert_eq!(map.rays_skipped, 0, "{map:?}");
    assert_eq!(grid.off_grid_points(), off);
}
