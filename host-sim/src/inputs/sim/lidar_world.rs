//! The simulator's lidar world: walls as line segments (a floor of rooms around a
//! corridor loop, with pillars and door frames), a robot driving laps of the corridor,
//! noisy wheel odometry (pose increments with a heading bias) and a ray-cast 2-D lidar,
//! with ground truth.
//!
//! Everything is deterministic: one xoshiro256++ generator seeded by the caller draws all
//! noise, so the same [`LidarWorld`] and seed give the same scans on every machine.
//! The world fits a 256 × 256 grid of 5 cm cells (12.8 m, the firmware's 64 KB map), so
//! the host and the microcontroller settings run on the same map size.
//!
//! Scans travel beside the odometry (one [`SimScan`] per lidar sweep with the cumulative
//! odometry pose at that instant, like a CARMEN log), not in the
//! [`microslam::event::Event`] stream: see the module documentation of `microslam::event`.

use anyhow::{Result, bail};
use microslam::geometry::{Pose2, ray_to_segments, wrap_angle};
use microslam::grid::OccupancyGrid;
use microslam::motion::integrate_velocity;
use microslam::pf::GridPfConfig;
use microslam::sensors::lidar::LidarGeometry;
use rand_core::SeedableRng;
use rand_distr::{Distribution, Normal, Uniform};
use rand_xoshiro::Xoshiro256PlusPlus;

/// A wall segment from `a` to `b`, metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Wall {
    /// One end `(x, y)`.
    pub a: [f64; 2],
    /// The other end.
    pub b: [f64; 2],
}

const fn wall(x1: f64, y1: f64, x2: f64, y2: f64) -> Wall {
    Wall {
        a: [x1, y1],
        b: [x2, y2],
    }
}

/// The simulated 2-D lidar.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SimLidar {
    /// Beams per sweep.
    pub beams: usize,
    /// Field of view, degrees, centred on the sensor's x axis.
    pub fov_deg: f64,
    /// Shortest usable range, metres.
    pub min_range_m: f64,
    /// Longest range: beyond it nothing is returned (the reading is `max_range_m`, which
    /// the geometry's `no_return_range` marks as "no return").
    pub max_range_m: f64,
    /// Standard deviation of the range noise, metres.
    pub range_std_m: f64,
    /// Probability that a beam returns nothing although a wall is in range.
    pub dropout: f64,
    /// Mount pose on the robot `(x, y, yaw)`.
    pub mount: [f64; 3],
}

impl SimLidar {
    /// The geometry the filters are given for these scans.
    pub fn geometry(&self) -> LidarGeometry {
        let fov = self.fov_deg.to_radians();
        let inc = if self.beams > 1 {
            fov / (self.beams - 1) as f64
        } else {
            0.0
        };
        LidarGeometry {
            first_angle: (-fov / 2.0) as f32,
            angle_increment: inc as f32,
            min_range: self.min_range_m as f32,
            max_range: self.max_range_m as f32,
            no_return_range: self.max_range_m as f32,
            mount: Pose2::new(
                self.mount[0] as f32,
                self.mount[1] as f32,
                self.mount[2] as f32,
            ),
        }
    }
}

/// Wheel odometry noise: the reported step is the true one with a scale error, heading
/// noise and a heading bias per metre driven (the Intel log's odometry drifts the same way).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OdometryNoise {
    /// Relative standard deviation of each step's distance.
    pub distance_rel_std: f64,
    /// Relative standard deviation of each step's heading change.
    pub turn_rel_std: f64,
    /// Heading random walk, rad per √metre.
    pub heading_std_per_sqrt_m: f64,
    /// Heading bias, rad per metre driven.
    pub heading_bias_per_m: f64,
}

/// The world, the drive and the sensors.
#[derive(Clone, Debug, PartialEq)]
pub struct LidarWorld {
    /// Wall segments.
    pub walls: Vec<Wall>,
    /// Corners of the driven loop, visited in order and back to the first.
    pub waypoints: Vec<[f64; 2]>,
    /// Laps of the loop.
    pub laps: u32,
    /// Cruise speed, m/s.
    pub speed_mps: f64,
    /// Largest turn rate, rad/s.
    pub max_turn_radps: f64,
    /// Odometry (and control) rate, Hz.
    pub odometry_rate_hz: f64,
    /// Lidar sweep rate, Hz.
    pub scan_rate_hz: f64,
    /// Odometry noise.
    pub odometry: OdometryNoise,
    /// The lidar.
    pub lidar: SimLidar,
}

impl LidarWorld {
    /// A 12 m × 8 m office floor: outer walls, a block of three rooms in the middle with
    /// doors onto the corridor that loops around it, pillars and door frames along the
    /// corridor. Two laps at 0.5 m/s (about 60 m, 2 minutes), 20 Hz odometry drifting
    /// 1°/m, a 270° lidar with 180 beams, 10 m range and 1 cm noise at 5 Hz.
    pub fn office() -> Self {
        let mut walls = vec![
            // Outer walls.
            wall(-6.0, -4.0, 6.0, -4.0),
            wall(6.0, -4.0, 6.0, 4.0),
            wall(6.0, 4.0, -6.0, 4.0),
            wall(-6.0, 4.0, -6.0, -4.0),
            // Central block x ∈ [−3.5, 3.5], y ∈ [−1.5, 1.5], doors 0.9 m wide.
            wall(-3.5, -1.5, -2.4, -1.5),
            wall(-1.5, -1.5, 1.0, -1.5),
            wall(1.9, -1.5, 3.5, -1.5),
            wall(3.5, -1.5, 3.5, 1.5),
            wall(3.5, 1.5, 0.4, 1.5),
            wall(-0.5, 1.5, -3.5, 1.5),
            wall(-3.5, 1.5, -3.5, -1.5),
            // Room partitions.
            wall(-1.2, -1.5, -1.2, 1.5),
            wall(1.4, -1.5, 1.4, 0.3),
            // Furniture inside the rooms (seen through the doors).
            wall(-3.0, 0.6, -2.2, 0.6),
            wall(-2.2, 0.6, -2.2, 1.1),
            wall(2.2, -0.6, 2.9, 0.2),
            // A slanted cabinet in the east corridor and one in the west.
            wall(5.3, -0.5, 5.9, 0.1),
            wall(-5.9, 1.2, -5.4, 1.8),
        ];
        // Pillars (0.3 m squares) along the outer walls and the central block, so that
        // no stretch of corridor is a featureless pair of parallel walls.
        for &(cx, cy) in &[
            (-3.0, -3.85),
            (0.5, -3.85),
            (3.5, -3.85),
            (-2.0, 3.85),
            (2.0, 3.85),
            (5.85, -2.5),
            (-5.85, -1.0),
            (0.0, -1.65),
            (2.7, -1.65),
            (-3.0, -1.65),
            (2.0, 1.65),
            (-2.0, 1.65),
            (3.65, 0.0),
            (-3.65, 0.5),
        ] {
            let h = 0.15;
            walls.extend([
                wall(cx - h, cy - h, cx + h, cy - h),
                wall(cx + h, cy - h, cx + h, cy + h),
                wall(cx + h, cy + h, cx - h, cy + h),
                wall(cx - h, cy + h, cx - h, cy - h),
            ]);
        }
        Self {
            walls,
            waypoints: vec![[-4.75, -2.75], [4.75, -2.75], [4.75, 2.75], [-4.75, 2.75]],
            laps: 2,
            speed_mps: 0.5,
            max_turn_radps: 0.8,
            odometry_rate_hz: 20.0,
            scan_rate_hz: 5.0,
            odometry: OdometryNoise {
                distance_rel_std: 0.02,
                turn_rel_std: 0.02,
                heading_std_per_sqrt_m: 0.01,
                heading_bias_per_m: 1f64.to_radians(),
            },
            lidar: SimLidar {
                beams: 180,
                fov_deg: 270.0,
                min_range_m: 0.1,
                max_range_m: 10.0,
                range_std_m: 0.01,
                dropout: 0.01,
                mount: [0.1, 0.0, 0.0],
            },
        }
    }

    /// The pose the robot starts at: the first waypoint, facing the second.
    pub fn start_pose(&self) -> Pose2<f64> {
        match (self.waypoints.first(), self.waypoints.get(1)) {
            (Some(a), Some(b)) => Pose2::new(a[0], a[1], (b[1] - a[1]).atan2(b[0] - a[0])),
            (Some(a), None) => Pose2::new(a[0], a[1], 0.0),
            _ => Pose2::new(0.0, 0.0, 0.0),
        }
    }

    /// Distance from `(x, y)` along heading `angle` to the nearest wall (`None`: no wall).
    pub fn cast(&self, x: f64, y: f64, angle: f64) -> Option<f64> {
        let walls = self.walls.iter().map(|w| [w.a[0], w.a[1], w.b[0], w.b[1]]);
        ray_to_segments((x, y), (angle.cos(), angle.sin()), walls)
    }
}

/// One lidar sweep with the truth and the odometry at that instant.
#[derive(Clone, Debug, PartialEq)]
pub struct SimScan {
    /// Time, seconds from the start.
    pub stamp: f64,
    /// True robot pose.
    pub truth: Pose2<f64>,
    /// Cumulative wheel-odometry pose (starts at the true start pose and drifts).
    pub odometry: Pose2<f64>,
    /// Ranges, beam 0 first (`max_range_m`: no return).
    pub ranges: Vec<f32>,
}

/// A simulated run.
#[derive(Clone, Debug, PartialEq)]
pub struct LidarRecording {
    /// `sim-lidar/seed<N>`.
    pub name: String,
    /// The world it was taken in.
    pub world: LidarWorld,
    /// Lidar geometry for the filters.
    pub lidar: LidarGeometry,
    /// The sweeps, in time order.
    pub scans: Vec<SimScan>,
}

/// Drives the laps of `world` and records odometry and scans with noise seed `seed`.
pub fn simulate(world: &LidarWorld, seed: u64) -> Result<LidarRecording> {
    if !(world.odometry_rate_hz > 0.0
        && world.scan_rate_hz > 0.0
        && world.speed_mps > 0.0
        && world.max_turn_radps > 0.0)
    {
        bail!("lidar world rates and speeds must be positive");
    }
    if world.waypoints.len() < 2 || world.lidar.beams == 0 {
        bail!("lidar world needs two waypoints and at least one beam");
    }
    if !(world.lidar.max_range_m > world.lidar.min_range_m && world.lidar.min_range_m >= 0.0) {
        bail!("lidar range limits out of order");
    }
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let unit = Normal::new(0.0, 1.0)?;
    let uniform = Uniform::new(0.0, 1.0)?;
    let dt = 1.0 / world.odometry_rate_hz;
    let scan_every = (world.odometry_rate_hz / world.scan_rate_hz)
        .round()
        .max(1.0) as usize;
    let geometry = world.lidar.geometry();
    let mount = Pose2::new(
        world.lidar.mount[0],
        world.lidar.mount[1],
        world.lidar.mount[2],
    );
    let fov = world.lidar.fov_deg.to_radians();
    let inc = if world.lidar.beams > 1 {
        fov / (world.lidar.beams - 1) as f64
    } else {
        0.0
    };
    let noise = world.odometry;
    let mut pose = world.start_pose();
    let mut odom = pose;
    let mut target = 1usize;
    let legs = world.waypoints.len() * world.laps as usize;
    let mut legs_done = 0usize;
    let mut scans = Vec::new();
    // A generous cap on the steps: twice the time the laps take at cruise speed.
    let perimeter: f64 = world
        .waypoints
        .iter()
        .zip(world.waypoints.iter().cycle().skip(1))
        .map(|(a, b)| (b[0] - a[0]).hypot(b[1] - a[1]))
        .sum();
    let max_steps =
        (2.0 * perimeter * f64::from(world.laps.max(1)) / world.speed_mps / dt).ceil() as usize;
    for k in 0..max_steps {
        if legs_done >= legs {
            break;
        }
        let t = k as f64 * dt;
        if k % scan_every == 0 {
            let sensor = pose.compose(&mount);
            let ranges = (0..world.lidar.beams)
                .map(|i| {
                    let a = sensor.theta - fov / 2.0 + inc * i as f64;
                    let hit = world.cast(sensor.x, sensor.y, a);
                    let dropped = uniform.sample(&mut rng) < world.lidar.dropout;
                    let n = world.lidar.range_std_m * unit.sample(&mut rng);
                    match hit {
                        Some(r) if !dropped && r < world.lidar.max_range_m => {
                            (r + n).clamp(0.0, world.lidar.max_range_m) as f32
                        }
                        _ => world.lidar.max_range_m as f32,
                    }
                })
                .collect();
            scans.push(SimScan {
                stamp: t,
                truth: pose,
                odometry: odom,
                ranges,
            });
        }
        // Steer towards the next corner; slow down while the heading error is large.
        let Some(wp) = world.waypoints.get(target % world.waypoints.len()) else {
            break;
        };
        let (dx, dy) = (wp[0] - pose.x, wp[1] - pose.y);
        if dx.hypot(dy) < 0.35 {
            target += 1;
            legs_done += 1;
            continue;
        }
        let err = wrap_angle(dy.atan2(dx) - pose.theta);
        let omega = (2.0 * err).clamp(-world.max_turn_radps, world.max_turn_radps);
        let v = world.speed_mps * err.cos().max(0.0).powi(4);
        let next = integrate_velocity(&pose, v, omega, dt).pose;
        // What the wheels report for this step.
        let d = v * dt;
        let turn = omega * dt;
        let d_meas = d * (1.0 + noise.distance_rel_std * unit.sample(&mut rng));
        let turn_meas = turn * (1.0 + noise.turn_rel_std * unit.sample(&mut rng))
            + noise.heading_bias_per_m * d
            + noise.heading_std_per_sqrt_m * d.sqrt() * unit.sample(&mut rng);
        odom = integrate_velocity(&odom, d_meas / dt, turn_meas / dt, dt).pose;
        pose = next;
    }
    if legs_done < legs {
        bail!("the robot did not finish its laps (stuck steering towards a waypoint)");
    }
    Ok(LidarRecording {
        name: format!("sim-lidar/seed{seed}"),
        world: world.clone(),
        lidar: geometry,
        scans,
    })
}

/// Grid edge in cells: 256 × 256 (12.8 m at 5 cm, 64 KB — the firmware's map size).
pub const SIM_GRID_CELLS: usize = 256;
/// Bytes of the simulator grid's occupied-cell bitmap (8 KB, as on the firmware).
pub const SIM_GRID_BITMAP: usize = microslam::grid::occupancy_bytes(SIM_GRID_CELLS, SIM_GRID_CELLS);

/// The simulator's grid.
pub type SimGrid = OccupancyGrid<SIM_GRID_CELLS, SIM_GRID_CELLS>;

/// The true map: every wall segment drawn into a grid as saturated occupied cells
/// (everything else unknown), sampled every quarter cell along each wall.
pub fn true_map(walls: &[Wall], config: &GridPfConfig) -> Box<SimGrid> {
    let mut grid = Box::new(SimGrid::centred(config.resolution, config.log_odds));
    let g = *grid.geometry();
    let step = f64::from(g.resolution) / 4.0;
    for w in walls {
        let len = (w.b[0] - w.a[0]).hypot(w.b[1] - w.a[1]);
        let n = (len / step).ceil().max(1.0) as usize;
        for i in 0..=n {
            let f = i as f64 / n as f64;
            let x = w.a[0] + f * (w.b[0] - w.a[0]);
            let y = w.a[1] + f * (w.b[1] - w.a[1]);
            if let Some((ix, iy)) = g.world_to_cell(x as f32, y as f32) {
                grid.set_cell(ix as i32, iy as i32, config.log_odds.max);
            }
        }
    }
    grid
}

impl LidarRecording {
    /// Beams per sweep.
    pub fn lidar_beams(&self) -> usize {
        self.scans.first().map_or(0, |s| s.ranges.len())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ray_cast_hits_the_nearest_wall() {
        let w = LidarWorld::office();
        // From the start corner looking east along the south corridor: the east wall
        // (x = 6) is 10.75 m away, but the pillar at (3.5, −3.85) is not in the way, and
        // looking south the outer wall is 1.25 m away.
        let south = w.cast(-4.75, -2.75, -std::f64::consts::FRAC_PI_2).unwrap();
        assert!((south - 1.25).abs() < 1e-9, "{south}");
        let north = w.cast(-4.75, -2.75, std::f64::consts::FRAC_PI_2).unwrap();
        // North: the west cabinet (−5.9..−5.4, 1.2..1.8) is not on x = −4.75; the outer
        // north wall at y = 4 is 6.75 m away.
        assert!((north - 6.75).abs() < 1e-9, "{north}");
        // Looking east at y = −1.0 from x = 4: the slanted cabinet's face.
        let cab = w.cast(4.0, -0.2, 0.0).unwrap();
        assert!((cab - 1.6).abs() < 1e-9, "{cab}");
    }

    #[test]
    fn same_seed_same_run_and_laps_are_driven() {
        let w = LidarWorld::office();
        let a = simulate(&w, 4).unwrap();
        let b = simulate(&w, 4).unwrap();
        let c = simulate(&w, 5).unwrap();
        assert_eq!(a, b);
        assert_ne!(a.scans, c.scans);
        // Two laps of a 30 m loop at 0.5 m/s, 5 Hz: about 600 sweeps.
        assert!((550..800).contains(&a.scans.len()), "{}", a.scans.len());
        let last = a.scans.last().unwrap();
        let start = w.start_pose();
        assert!((last.truth.x - start.x).hypot(last.truth.y - start.y) < 1.0);
        // The odometry drifts away from the truth.
        let drift = (last.odometry.x - last.truth.x).hypot(last.odometry.y - last.truth.y);
        assert!(drift > 0.5, "odometry drift {drift}");
        // Every sweep has returns, and some beams see nothing (dropouts).
        let g = a.lidar;
        let valid = a.scans[0]
            .ranges
            .iter()
            .filter(|r| **r < g.no_return_range)
            .count();
        assert!(valid > 150, "{valid}");
    }
}
