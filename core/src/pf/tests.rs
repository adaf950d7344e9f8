//! Whole-filter tests: a simulated world (walls + a ray-cast lidar + drifting odometry,
//! written here) for SLAM and localization against ground truth, determinism, and
//! robustness to bad input.

use super::*;
use crate::geometry::{Pose2, ray_to_segments};
use crate::grid::{GridGeometry, GridView, OccupancyGrid};
use crate::sensors::lidar::{LidarGeometry, LidarScan};
use crate::testing::{BrokenSetting, each_broken_setting_is_named};
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};

/// Wall segments of a 8 m × 6 m room with a partition and two boxes.
const WALLS: [[f32; 4]; 13] = [
    [-4.0, -3.0, 4.0, -3.0],
    [4.0, -3.0, 4.0, 3.0],
    [4.0, 3.0, -4.0, 3.0],
    [-4.0, 3.0, -4.0, -3.0],
    [0.5, -3.0, 0.5, -0.8], // partition from the south wall
    [-1.8, 0.6, -1.0, 0.6], // box 1
    [-1.0, 0.6, -1.0, 1.3],
    [-1.0, 1.3, -1.8, 1.3],
    [-1.8, 1.3, -1.8, 0.6],
    [2.2, 1.0, 2.9, 1.6], // a slanted box
    [2.9, 1.6, 2.4, 2.2],
    [2.4, 2.2, 1.7, 1.6],
    [1.7, 1.6, 2.2, 1.0],
];

pub(super) const LIDAR: LidarGeometry = LidarGeometry {
    first_angle: -2.35,
    angle_increment: 4.7 / 180.0,
    min_range: 0.1,
    max_range: 10.0,
    no_return_range: 10.0,
    mount: Pose2::new(0.1, 0.0, 0.0),
};

/// Distance along a ray to the nearest wall (∞ when none).
fn cast(x: f32, y: f32, a: f32) -> f32 {
    ray_to_segments((x, y), (a.cos(), a.sin()), WALLS).unwrap_or(f32::INFINITY)
}

pub(super) struct Sim {
    pub(super) truth: Vec<Pose2<f32>>,
    pub(super) odometry: Vec<Pose2<f32>>,
    pub(super) scans: Vec<Vec<f32>>,
}

/// One and a half laps of a loop around the partition, 10 cm steps, with odometry that drifts
/// (heading bias 2°/m plus noise) and 1 cm range noise.
pub(super) fn simulate(seed: u64) -> Sim {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let range_noise = Normal::new(0.0f32, 0.01).unwrap();
    let step_noise = Normal::new(0.0f32, 0.01).unwrap();
    let corners = [(-2.8f32, -2.0f32), (2.8, -2.0), (2.8, 0.0), (-2.8, 2.0)];
    let mut waypoints = corners.to_vec();
    waypoints.extend_from_slice(&corners[..3]);
    let mut pose = Pose2::new(-2.8f32, -2.0, 0.0);
    let mut odom = pose;
    let mut sim = Sim {
        truth: vec![],
        odometry: vec![],
        scans: vec![],
    };
    for &(wx, wy) in waypoints.iter().skip(1) {
        loop {
            let (dx, dy) = (wx - pose.x, wy - pose.y);
            let dist = dx.hypot(dy);
            if dist < 0.05 {
                break;
            }
            let want = dy.atan2(dx);
            let turn = crate::pf::prediction::wrap(want - pose.theta).clamp(-0.2, 0.2);
            let d = if turn.abs() > 0.15 {
                0.0
            } else {
                dist.min(0.1)
            };
            let next = prediction::drive_arc(&pose, d, turn, 0.0);
            // Odometry: the same step seen with a heading bias and noise.
            let (od, ot) = (
                d * (1.0 + step_noise.sample(&mut rng)),
                turn + 0.035 * d + 0.2 * step_noise.sample(&mut rng) * (d + turn.abs()),
            );
            odom = prediction::drive_arc(&odom, od, ot, 0.0);
            pose = next;
            let sensor = crate::sensors::lidar::sensor_pose(&pose, &LIDAR.mount);
            let ranges = (0..180)
                .map(|i| {
                    let r = cast(sensor.x, sensor.y, sensor.theta + LIDAR.beam_angle(i));
                    if rng.random_bool(0.02) {
                        50.0
                    } else {
                        r + range_noise.sample(&mut rng)
                    }
                })
                .collect();
            sim.truth.push(pose);
            sim.odometry.push(odom);
            sim.scans.push(ranges);
        }
    }
    sim
}

fn ate(est: &[Pose2<f32>], truth: &[Pose2<f32>]) -> f32 {
    let s: f32 = est
        .iter()
        .zip(truth)
        .map(|(e, t)| (e.x - t.x).powi(2) + (e.y - t.y).powi(2))
        .sum();
    (s / est.len() as f32).sqrt()
}

pub(super) type Grid = OccupancyGrid<256, 256>;

fn run_slam(sim: &Sim, config: GridPfConfig) -> (Vec<Pose2<f32>>, Box<Grid>) {
    let mut grid = Box::new(Grid::centred(config.resolution, config.log_odds));
    let mut est = Vec::new();
    {
        let mut slam = GridSlam::<256, 256, 32, 180>::new(&mut grid, config, sim.truth[0]).unwrap();
        for i in 0..sim.scans.len() {
            if i > 0 {
                slam.predict_odometry(&sim.odometry[i - 1], &sim.odometry[i])
                    .unwrap();
            }
            let r = slam.observe(&LidarScan::new(&sim.scans[i], LIDAR)).unwrap();
            assert!(r.pose.is_finite());
            est.push(r.pose);
        }
    }
    (est, grid)
}

#[test]
fn simulated_slam_beats_odometry_and_stays_within_bound() {
    let sim = simulate(3);
    assert!(sim.truth.len() > 250, "{}", sim.truth.len());
    let odom_ate = {
        // Odometry expressed from the true start.
        let o0 = sim.odometry[0];
        let est: Vec<_> = sim
            .odometry
            .iter()
            .map(|o| sim.truth[0].compose(&o0.between(o)))
            .collect();
        ate(&est, &sim.truth)
    };
    let (est, grid) = run_slam(&sim, GridPfConfig::DEFAULT);
    let slam_ate = ate(&est, &sim.truth);
    std::println!("odometry ATE {odom_ate:.4} m, SLAM ATE {slam_ate:.4} m");
    assert!(
        odom_ate > 0.3,
        "the simulated odometry must drift: {odom_ate}"
    );
    assert!(slam_ate < 0.079, "SLAM ATE {slam_ate}"); // measured 0.0761 m, + 3.8 %
    // The map has the south wall where it is: cells on y = −3 m occupied along x.
    let view = grid.view();
    let occupied = (-70..70)
        .filter(|i| {
            let x = *i as f32 * 0.05;
            let (ix, iy) = (
                crate::grid::floor_i32((x - view.geometry().origin_x) / 0.05),
                crate::grid::floor_i32((-3.0 - view.geometry().origin_y) / 0.05),
            );
            (-1..=1).any(|d| view.is_occupied(ix, iy + d))
        })
        .count();
    assert!(occupied > 110, "{occupied} of 140 wall cells");
}

/// The simulated room's map with `config`'s cells, drawn from every fifth scan of `sim`
/// at its true poses (what a localizer's map in flash would hold).
pub(super) fn true_map(sim: &Sim, config: &GridPfConfig) -> Box<Grid> {
    let mut map = Box::new(Grid::centred(config.resolution, config.log_odds));
    for (p, r) in sim.truth.iter().zip(&sim.scans).step_by(5) {
        map.integrate_scan(p, &LidarScan::new(r, LIDAR), 1).unwrap();
    }
    map
}

#[test]
fn simulated_localizer_on_a_true_map() {
    let sim = simulate(5);
    let config = GridPfConfig::DEFAULT;
    let map = true_map(&sim, &config);
    // The map as a borrowed slice, as a flash map would be.
    let cells: &[i8] = map.cells();
    let view = GridView::new(cells, *map.geometry(), config.log_odds.occupied_above).unwrap();
    let mut loc = GridLocalizer::<32, 180>::new(view, config, sim.truth[0]).unwrap();
    loc.reset_around(sim.truth[0], 0.1, 0.05).unwrap();
    let mut est = Vec::new();
    for i in 0..sim.scans.len() {
        if i > 0 {
            loc.predict_odometry(&sim.odometry[i - 1], &sim.odometry[i])
                .unwrap();
        }
        est.push(
            loc.observe(&LidarScan::new(&sim.scans[i], LIDAR))
                .unwrap()
                .pose,
        );
    }
    let e = ate(&est, &sim.truth);
    std::println!("localizer ATE {e:.4} m");
    assert!(e < 0.0252, "localizer ATE {e}"); // measured 0.0241 m, + 4.6 %

    // The same flash map with its occupied-cell bitmap (the sparse search): the same
    // estimates, bit for bit.
    let mut bits = std::vec![0u8; crate::grid::occupancy_bytes(256, 256)];
    crate::grid::fill_occupancy_bits(cells, 256, 256, config.log_odds.occupied_above, &mut bits)
        .unwrap();
    let sparse_view = view.with_occupancy_bits(&bits).unwrap();
    assert!(view.with_occupancy_bits(&bits[1..]).is_err());
    let mut sparse = GridLocalizer::<32, 180>::new(sparse_view, config, sim.truth[0]).unwrap();
    sparse.reset_around(sim.truth[0], 0.1, 0.05).unwrap();
    for (i, (scan, want)) in sim.scans.iter().zip(&est).enumerate() {
        if i > 0 {
            sparse
                .predict_odometry(&sim.odometry[i - 1], &sim.odometry[i])
                .unwrap();
        }
        let pose = sparse.observe(&LidarScan::new(scan, LIDAR)).unwrap().pose;
        assert_eq!(pose, *want, "scan {i}");
    }
}

#[test]
fn same_inputs_and_seed_give_the_same_output() {
    let sim = simulate(9);
    let short = Sim {
        truth: sim.truth[..150].to_vec(),
        odometry: sim.odometry[..150].to_vec(),
        scans: sim.scans[..150].to_vec(),
    };
    let (a, ga) = run_slam(&short, GridPfConfig::DEFAULT);
    let (b, gb) = run_slam(&short, GridPfConfig::DEFAULT);
    assert_eq!(a, b);
    assert_eq!(ga.cells(), gb.cells());
    // Golden end pose (bit pattern) of this run: a change indicator, and the check that
    // `--features parallel` (multi-core scoring) gives exactly the single-core result.
    let end = a.last().unwrap();
    let bits = (end.x.to_bits(), end.y.to_bits(), end.theta.to_bits());
    assert_eq!(bits, (0xc031_e042, 0x4000_4afa, 0x403f_fda4), "{end:?}");
    let mut other = GridPfConfig::DEFAULT;
    other.filter.seed = 1;
    let (c, _) = run_slam(&short, other);
    assert_ne!(a, c, "the seed must matter");
}

#[test]
fn bad_inputs_never_panic_and_leave_the_filter_usable() {
    let config = GridPfConfig::DEFAULT;
    let mut grid = Box::new(OccupancyGrid::<64, 64>::centred(
        config.resolution,
        config.log_odds,
    ));
    let mut slam = GridSlam::<64, 64, 8, 32>::new(&mut grid, config, Pose2::IDENTITY).unwrap();
    let mut rng = rand::rngs::StdRng::seed_from_u64(11);
    let specials = [
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        0.0,
        -1.0,
        1e30,
        -1e30,
        1e-30,
    ];
    for step in 0..400 {
        let pick = |rng: &mut rand::rngs::StdRng| {
            if rng.random_bool(0.3) {
                specials[rng.random_range(0..specials.len())]
            } else {
                rng.random_range(-3.0..3.0)
            }
        };
        let d = pick(&mut rng);
        let t = pick(&mut rng);
        match slam.predict(d, t) {
            Ok(()) => assert!(d.is_finite() && t.is_finite()),
            Err(e) => assert_eq!(e, PfError::NonFiniteInput),
        }
        let _ = slam.predict_velocity(pick(&mut rng), pick(&mut rng), pick(&mut rng));
        let n = rng.random_range(0..40);
        let ranges: Vec<f32> = (0..n).map(|_| pick(&mut rng).abs()).collect();
        let mut geometry = LidarGeometry::CARMEN_SICK_180;
        if step % 17 == 0 {
            geometry.first_angle = f32::NAN;
        }
        match slam.observe(&LidarScan::new(&ranges, geometry)) {
            Ok(r) => assert!(r.pose.is_finite()),
            Err(e) => assert!(
                matches!(e, PfError::EmptyScan | PfError::InvalidScan),
                "{e:?}"
            ),
        }
        for p in slam.filter().poses() {
            assert!(p.is_finite());
        }
        assert!(slam.filter().log_weights().iter().all(|w| w.is_finite()));
    }
    // The robot far off the grid: scans are scored (nothing occupied) and counted off-grid.
    slam.predict(1.0e6, 0.0).unwrap();
    let ranges = [1.0f32; 30];
    let r = slam
        .observe(&LidarScan::new(&ranges, LidarGeometry::CARMEN_SICK_180))
        .unwrap();
    assert_eq!(r.map.hits, 0);
    assert!(r.map.off_grid + r.map.rays_skipped == 30);
}

#[test]
fn invalid_settings_are_refused() {
    let mut grid = Box::new(OccupancyGrid::<16, 16>::centred(
        0.05,
        crate::grid::LogOdds::SYMMETRIC,
    ));
    let mut c = GridPfConfig::UNTUNED;
    c.filter.shift_window_cells = 8;
    assert!(GridSlam::<16, 16, 4, 8>::new(&mut grid, c, Pose2::IDENTITY).is_err());
    let mut c = GridPfConfig::UNTUNED;
    c.resolution = 0.1;
    assert_eq!(
        GridSlam::<16, 16, 4, 8>::new(&mut grid, c, Pose2::IDENTITY).err(),
        Some(PfError::MapMismatch)
    );
    assert_eq!(
        ParticleFilter::<0>::new(GridPfConfig::UNTUNED.filter, Pose2::IDENTITY).err(),
        Some(PfError::NoParticles)
    );
    let g = GridGeometry::centred(4, 4, 0.05);
    let cells = [0i8; 16];
    let view = GridView::new(&cells, g, 20).unwrap();
    let mut l = GridLocalizer::<4, 8>::new(view, GridPfConfig::UNTUNED, Pose2::IDENTITY).unwrap();
    assert_eq!(
        l.predict_velocity(1.0, 0.0, -0.1),
        Err(PfError::NegativeTimeStep)
    );
    assert_eq!(
        l.observe(&LidarScan::new(&[], LIDAR)).err(),
        Some(PfError::EmptyScan)
    );
}

#[test]
fn memory_per_capacity_is_as_documented() {
    use core::mem::size_of;
    let filter = size_of::<ParticleFilter<32>>();
    let slam = size_of::<GridSlam<'static, 256, 256, 32, 90>>();
    let loc = size_of::<GridLocalizer<'static, 32, 90>>();
    std::println!(
        "ParticleFilter<32> {filter} B, GridSlam<256,256,32,90> {slam} B, GridLocalizer<32,90> {loc} B"
    );
    // Documented: 28·P + 40 bytes plus the config; the SLAM/localizer add 24·B + ~100.
    let config = size_of::<FilterConfig>();
    assert!(filter <= 28 * 32 + 40 + config, "{filter}");
    assert!(
        slam <= filter + 24 * 90 + 100 + size_of::<GridPfConfig>(),
        "{slam}"
    );
    // The localizer's lost detection and relocalization state add ~400 B, the map's
    // wall-direction histogram 724 B, a global search spanning scans 4 656 B (measured
    // 9080).
    assert!(slam < 3400 && loc < 9150, "{slam} {loc}");
}

#[test]
fn pose_covariance_is_the_cloud_spread_across_the_heading_seam() {
    let config = GridPfConfig::DEFAULT.filter;
    // A cloud straddling ±π: headings near π and near −π are 0.1 rad apart, not 2π.
    let centre = Pose2::new(1.0, -2.0, core::f32::consts::PI - 0.02);
    let mut pf = ParticleFilter::<2000>::new(config, centre).unwrap();
    assert_eq!(pf.pose_covariance(), [0.0; 6], "coinciding particles");
    pf.reset_around(centre, 0.1, 0.05).unwrap();
    assert!(
        pf.poses().iter().any(|p| p.theta < 0.0),
        "the cloud crosses the seam"
    );
    let c = pf.pose_covariance();
    // Sample variances of 2000 draws: relative standard error ≈ √(2/2000) ≈ 3 %.
    for (got, want) in [(c[0], 0.01), (c[3], 0.01), (c[5], 0.0025)] {
        assert!((got / want - 1.0).abs() < 0.12, "{c:?}");
    }
    for cross in [c[1], c[2], c[4]] {
        assert!(cross.abs() < 0.0015, "{c:?}");
    }
}

#[test]
fn a_correction_moves_every_particle_and_a_rebuild_redraws_the_map() {
    let sim = simulate(3);
    let config = GridPfConfig::DEFAULT;
    let mut grid = Box::new(Grid::centred(config.resolution, config.log_odds));
    let mut slam = GridSlam::<256, 256, 32, 180>::new(&mut grid, config, sim.truth[0]).unwrap();
    for i in 0..20 {
        if i > 0 {
            slam.predict_odometry(&sim.odometry[i - 1], &sim.odometry[i])
                .unwrap();
        }
        slam.observe(&LidarScan::new(&sim.scans[i], LIDAR)).unwrap();
    }
    // A quarter turn about the origin and a shift.
    let correction = Pose2::new(0.5, -0.25, core::f32::consts::FRAC_PI_2);
    let before = *slam.filter().poses();
    let estimate = slam.pose();
    slam.correct(&correction).unwrap();
    for (p, q) in before.iter().zip(slam.filter().poses()) {
        // (x, y) → (0.5 − y, −0.25 + x), heading + 90°.
        assert!((q.x - (0.5 - p.y)).abs() < 1e-5 && (q.y - (-0.25 + p.x)).abs() < 1e-5);
        assert!(
            crate::geometry::wrap_angle(q.theta - p.theta - core::f32::consts::FRAC_PI_2).abs()
                < 1e-5
        );
    }
    assert!((slam.pose().x - (0.5 - estimate.y)).abs() < 1e-5);
    // Refused when it would not be finite; nothing moves.
    let poses = *slam.filter().poses();
    assert_eq!(
        slam.correct(&Pose2::new(f32::NAN, 0.0, 0.0)),
        Err(PfError::NonFiniteInput)
    );
    assert_eq!(*slam.filter().poses(), poses);

    // The map rebuilt from the first scan alone at its true pose holds the end points that
    // scan wrote, and none of the others'.
    let occupied = |g: &Grid| g.cells().iter().filter(|&&c| c > 0).count();
    let all = occupied(slam.map());
    slam.rebuild_map([(sim.truth[0], LidarScan::new(&sim.scans[0], LIDAR))])
        .unwrap();
    let one = occupied(slam.map());
    assert!(one > 50 && one < all, "{one} of {all}");
    // A non-finite pose stops the rebuild with an error.
    assert_eq!(
        slam.rebuild_map([(
            Pose2::new(f32::NAN, 0.0, 0.0),
            LidarScan::new(&sim.scans[0], LIDAR)
        )]),
        Err(PfError::NonFiniteInput)
    );
}

#[test]
fn an_invalid_setting_is_named_with_its_rule() {
    for valid in [
        GridPfConfig::UNTUNED,
        GridPfConfig::DEFAULT,
        GridPfConfig::MICROCONTROLLER,
        GridPfConfig::DEFAULT.for_localizer(),
    ] {
        assert_eq!(valid.invalid_setting(), None);
        assert!(valid.is_valid());
    }
    let cases: [BrokenSetting<GridPfConfig>; 9] = [
        (|c| c.resolution = 0.0, "resolution", "finite and positive"),
        (|c| c.log_odds.miss = -1, "miss", "0 or more"),
        (|c| c.log_odds.min = 5, "min", "0 or less"),
        (
            |c| c.range_weight_exponent = f32::NAN,
            "range_weight_exponent",
            "finite and non-negative",
        ),
        (
            |c| c.filter.motion_noise.sideways_std_per_metre = -0.1,
            "sideways_std_per_metre",
            "finite and non-negative",
        ),
        (
            |c| c.filter.shift_window_cells = correlation::MAX_SHIFT_WINDOW + 1,
            "shift_window_cells",
            "at most 7 (a 15 × 15 window)",
        ),
        (
            |c| c.filter.log_likelihood_per_unit = f32::INFINITY,
            "log_likelihood_per_unit",
            "finite and non-negative",
        ),
        (
            |c| c.filter.resample_neff_fraction = 1.5,
            "resample_neff_fraction",
            "within 0 ..= 1",
        ),
        (
            |c| c.shift_prior_std_cells = -1.0,
            "shift_prior_std_cells",
            "finite and non-negative",
        ),
    ];
    each_broken_setting_is_named(GridPfConfig::DEFAULT, &cases, |c| {
        (c.is_valid(), c.invalid_setting())
    });
    // Two at once: the first in the order the settings are checked.
    let mut c = GridPfConfig::DEFAULT;
    c.filter.resample_neff_fraction = 2.0;
    c.resolution = -1.0;
    assert_eq!(c.invalid_setting().map(|i| i.name), Some("resolution"));
}

#[test]
fn an_invalid_relocalization_setting_is_named_with_its_rule() {
    assert_eq!(RelocalizationConfig::DEFAULT.invalid_setting(), None);
    let cases: [BrokenSetting<RelocalizationConfig>; 6] = [
        (|c| c.search.max_beams = 0, "max_beams", "within 1 ..= 128"),
        (
            |c| c.search.min_score_fraction = f32::NAN,
            "min_score_fraction",
            "within 0 ..= 1",
        ),
        (|c| c.search.work_budget = 0, "work_budget", "1 or more"),
        (
            |c| c.lost.learning_rate = 0.0,
            "learning_rate",
            "within (0, 1]",
        ),
        (|c| c.hypotheses = 9, "hypotheses", "within 1 ..= 8"),
        (
            |c| c.pull_in_window_cells = 8,
            "pull_in_window_cells",
            "at most 7",
        ),
    ];
    each_broken_setting_is_named(RelocalizationConfig::DEFAULT, &cases, |c| {
        (c.is_valid(), c.invalid_setting())
    });
}
