//! A simulated building for the grid SLAM tests: walls as segments, a lidar ray-cast
//! against them, a robot driven along waypoints, and wheel odometry that drifts.

use crate::geometry::{Pose2, ray_to_segments};
use crate::pf::prediction::{drive_arc, wrap};
use crate::sensors::lidar::{LidarGeometry, sensor_pose};
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};

/// A lidar of 180 beams over 270°, 0.1–10 m, at the robot's centre.
pub const LIDAR_270: LidarGeometry = LidarGeometry {
    first_angle: -2.35,
    angle_increment: 4.7 / 180.0,
    min_range: 0.1,
    max_range: 10.0,
    no_return_range: 10.0,
    mount: Pose2::new(0.0, 0.0, 0.0),
};

/// A ring corridor 2 m wide around a 16 m × 10 m block (outer walls 20 m × 14 m, centred
/// on the origin), with boxes along its outer walls and pillars of varied sizes along its
/// inner ones, so that no stretch of it looks like the next.
pub fn ring_corridor() -> Vec<[f32; 4]> {
    let mut w = vec![
        // Outer walls.
        [-10.0, -7.0, 10.0, -7.0],
        [10.0, -7.0, 10.0, 7.0],
        [10.0, 7.0, -10.0, 7.0],
        [-10.0, 7.0, -10.0, -7.0],
        // The inner block.
        [-8.0, -5.0, 8.0, -5.0],
        [8.0, -5.0, 8.0, 5.0],
        [8.0, 5.0, -8.0, 5.0],
        [-8.0, 5.0, -8.0, -5.0],
    ];
    // Boxes against the outer walls at uneven spacing.
    for (x, y, sx, sy) in [
        (-6.5, -6.6, 0.6, 0.4),
        (-1.2, -6.5, 0.9, 0.5),
        (4.3, -6.7, 0.5, 0.3),
        (9.5, -3.2, 0.5, 0.8),
        (9.6, 1.9, 0.4, 0.5),
        (5.1, 6.6, 0.7, 0.4),
        (-0.4, 6.5, 0.5, 0.5),
        (-7.3, 6.7, 1.0, 0.3),
        (-9.6, 2.5, 0.4, 0.9),
        (-9.5, -2.8, 0.5, 0.4),
    ] {
        let (x0, y0, x1, y1) = (x - sx / 2.0, y - sy / 2.0, x + sx / 2.0, y + sy / 2.0);
        w.extend([
            [x0, y0, x1, y0],
            [x1, y0, x1, y1],
            [x1, y1, x0, y1],
            [x0, y1, x0, y0],
        ]);
    }
    // Pillars along the inner block's walls every 1.3–2.1 m, of sizes that vary.
    let mut k = 0u32;
    let mut pillar = |x: f32, y: f32, w: &mut Vec<[f32; 4]>| {
        k += 1;
        let h = 0.1 + 0.05 * (k % 4) as f32;
        w.extend([
            [x - h, y - h, x + h, y - h],
            [x + h, y - h, x + h, y + h],
            [x + h, y + h, x - h, y + h],
            [x - h, y + h, x - h, y - h],
        ]);
    };
    let mut t = -7.0f32;
    while t < 7.5 {
        pillar(t, -4.85, &mut w);
        pillar(-t + 0.4, 4.85, &mut w);
        t += 1.3 + 0.2 * ((t * 7.0) as i32 % 5) as f32;
    }
    let mut t = -4.0f32;
    while t < 4.5 {
        pillar(7.85, t, &mut w);
        pillar(-7.85, -t + 0.3, &mut w);
        t += 1.4 + 0.2 * ((t * 3.0) as i32 % 4).abs() as f32;
    }
    w
}

/// The middle of [`ring_corridor`]'s corridor, corner by corner, starting at the south-west
/// corner and driving anticlockwise.
pub const RING_WAYPOINTS: [(f32, f32); 4] = [(-9.0, -6.0), (9.0, -6.0), (9.0, 6.0), (-9.0, 6.0)];

/// A simulated drive.
pub struct Drive {
    /// True pose at each scan.
    pub truth: Vec<Pose2<f32>>,
    /// Odometry pose at each scan.
    pub odometry: Vec<Pose2<f32>>,
    /// The lidar's ranges at each scan.
    pub scans: Vec<Vec<f32>>,
}

/// `waypoints` driven `laps` times round, then on through the first `extra` of them and
/// back to the first.
pub fn laps(waypoints: &[(f32, f32)], laps: usize, extra: usize) -> Vec<(f32, f32)> {
    let mut route: Vec<(f32, f32)> = Vec::new();
    for _ in 0..laps {
        route.extend_from_slice(waypoints);
    }
    route.extend(waypoints.iter().take(extra));
    route.extend(waypoints.first());
    route
}

/// Drives along `route` (at least two points), 10 cm or 0.2 rad a step, scanning `walls`
/// with `beams` beams of `lidar` at every step (1 cm range noise, 2 % of the beams
/// without a return). The odometry sees every step with 1 % noise and its heading drifts
/// by `heading_bias` radians per metre.
pub fn drive(
    walls: &[[f32; 4]],
    route: &[(f32, f32)],
    lidar: &LidarGeometry,
    beams: usize,
    heading_bias: f32,
    seed: u64,
) -> Drive {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let noise = Normal::new(0.0f32, 0.01).unwrap();
    let (x0, y0) = route[0];
    let (x1, y1) = route[1];
    let mut pose = Pose2::new(x0, y0, (y1 - y0).atan2(x1 - x0));
    let mut odom = pose;
    let mut out = Drive {
        truth: vec![],
        odometry: vec![],
        scans: vec![],
    };
    for &(wx, wy) in route.iter().skip(1) {
        loop {
            let (dx, dy) = (wx - pose.x, wy - pose.y);
            let dist = dx.hypot(dy);
            if dist < 0.05 {
                break;
            }
            let turn = wrap(dy.atan2(dx) - pose.theta).clamp(-0.2, 0.2);
            let d = if turn.abs() > 0.15 {
                0.0
            } else {
                dist.min(0.1)
            };
            pose = drive_arc(&pose, d, turn, 0.0);
            let od = d * (1.0 + noise.sample(&mut rng));
            let ot = turn + heading_bias * d + 0.2 * noise.sample(&mut rng) * (d + turn.abs());
            odom = drive_arc(&odom, od, ot, 0.0);
            let sensor = sensor_pose(&pose, &lidar.mount);
            let ranges = (0..beams)
                .map(|i| {
                    let a = sensor.theta + lidar.beam_angle(i);
                    let r = ray_to_segments(
                        (sensor.x, sensor.y),
                        (a.cos(), a.sin()),
                        walls.iter().copied(),
                    )
                    .unwrap_or(f32::INFINITY);
                    if rng.random_bool(0.02) {
                        f32::INFINITY
                    } else {
                        r + noise.sample(&mut rng)
                    }
                })
                .collect();
            out.truth.push(pose);
            out.odometry.push(odom);
            out.scans.push(ranges);
        }
    }
    out
}

/// Position RMSE of `est` against `truth` (paired in order), metres.
pub fn position_rmse(est: &[Pose2<f32>], truth: &[Pose2<f32>]) -> f32 {
    let n = est.len().min(truth.len()).max(1);
    let s: f32 = est
        .iter()
        .zip(truth)
        .map(|(e, t)| (e.x - t.x).powi(2) + (e.y - t.y).powi(2))
        .sum();
    (s / n as f32).sqrt()
}

/// Distance from `(x, y)` to the nearest of `walls` (segments `[x0, y0, x1, y1]`), metres.
#[cfg(feature = "map-image")]
pub fn distance_to_walls(walls: &[[f32; 4]], x: f32, y: f32) -> f32 {
    walls
        .iter()
        .map(|&[x0, y0, x1, y1]| {
            let (dx, dy) = (x1 - x0, y1 - y0);
            let len2 = dx * dx + dy * dy;
            let t = if len2 > 0.0 {
                (((x - x0) * dx + (y - y0) * dy) / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            libm::hypotf(x - (x0 + t * dx), y - (y0 + t * dy))
        })
        .fold(f32::INFINITY, f32::min)
}
