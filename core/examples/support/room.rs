//! The world the grid examples drive in: a 5 m × 4 m room with a round pillar in the
//! middle, a 90-beam lidar that sees its walls, and a robot circling the pillar.
//! (Example support, not part of the library: a real robot reads its lidar instead.)

#![allow(dead_code)] // each example uses only part of the room

use microslam::geometry::Pose2;
use microslam::motion::integrate_velocity;
use microslam::sensors::lidar::LidarGeometry;

/// Beams per scan.
pub const BEAMS: usize = 90;

/// A 360° lidar at the robot's centre, 4° between beams, ranges 0.1–8 m.
pub const LIDAR: LidarGeometry = LidarGeometry {
    first_angle: -core::f32::consts::PI,
    angle_increment: 2.0 * core::f32::consts::PI / BEAMS as f32,
    min_range: 0.1,
    max_range: 8.0,
    no_return_range: f32::INFINITY,
    mount: Pose2::new(0.0, 0.0, 0.0),
};

/// Half the room's width and height, metres (walls at x = ±2.5, y = ±2).
const HALF: (f32, f32) = (2.5, 2.0);
/// The pillar: centre and radius, metres.
const PILLAR: (f32, f32, f32) = (0.0, 0.0, 0.3);

/// Distance from `(x, y)` along the unit direction `(dx, dy)` to the first wall or the
/// pillar.
fn range_along(x: f32, y: f32, dx: f32, dy: f32) -> f32 {
    // The walls: the ray leaves the box through one of them.
    let to_wall = |p: f32, d: f32, half: f32| {
        if d > 0.0 {
            (half - p) / d
        } else if d < 0.0 {
            (-half - p) / d
        } else {
            f32::INFINITY
        }
    };
    let mut range = to_wall(x, dx, HALF.0).min(to_wall(y, dy, HALF.1));
    // The pillar: the nearer root of |p + t·d − c|² = r².
    let (px, py) = (x - PILLAR.0, y - PILLAR.1);
    let b = px * dx + py * dy;
    let disc = b * b - (px * px + py * py - PILLAR.2 * PILLAR.2);
    if disc >= 0.0 {
        let t = -b - disc.sqrt();
        if t > 0.0 {
            range = range.min(t);
        }
    }
    range
}

/// The ranges a lidar at `pose` measures.
pub fn scan(pose: &Pose2<f32>) -> [f32; BEAMS] {
    let mut ranges = [0.0; BEAMS];
    for (i, r) in ranges.iter_mut().enumerate() {
        let angle = pose.theta + LIDAR.mount.theta + LIDAR.beam_angle(i);
        *r = range_along(pose.x, pose.y, angle.cos(), angle.sin());
    }
    ranges
}

/// Forward speed (m/s) and turn rate (rad/s) of the drive: a 1.2 m circle.
pub const DRIVE: (f32, f32) = (0.3, 0.25);
/// Odometry period, seconds.
pub const DT: f32 = 0.1;
/// Where the drive starts.
pub const START: Pose2<f32> = Pose2::new(1.2, 0.0, core::f32::consts::FRAC_PI_2);

/// The true poses at every odometry period, from [`START`].
pub fn drive(steps: usize) -> Vec<Pose2<f32>> {
    let mut poses = Vec::with_capacity(steps);
    let mut pose = START;
    for _ in 0..steps {
        poses.push(pose);
        pose = integrate_velocity(&pose, DRIVE.0, DRIVE.1, DT).pose;
    }
    poses
}

/// Width and height of [`map`], cells of [`MAP_RESOLUTION`] metres centred on the origin.
pub const MAP_SIZE: usize = 128;
/// Cell edge of [`map`], metres.
pub const MAP_RESOLUTION: f32 = 0.05;

/// The room drawn as a map at compile time (a `static` of it lives in flash): cells on a
/// wall or on the pillar's rim hold `occupied`, all others 0 (unknown). Row-major, row 0
/// at the bottom, as [`microslam::grid::GridView`] reads it.
pub const fn map(occupied: i8) -> [i8; MAP_SIZE * MAP_SIZE] {
    let mut cells = [0; MAP_SIZE * MAP_SIZE];
    let origin = -(MAP_SIZE as f32) * MAP_RESOLUTION * 0.5;
    let r = MAP_RESOLUTION;
    let mut iy = 0;
    while iy < MAP_SIZE {
        let mut ix = 0;
        while ix < MAP_SIZE {
            // The cell's extent [x0, x0 + r] × [y0, y0 + r].
            let x0 = origin + ix as f32 * r;
            let y0 = origin + iy as f32 * r;
            let inside_x = x0 + r >= -HALF.0 && x0 <= HALF.0;
            let inside_y = y0 + r >= -HALF.1 && y0 <= HALF.1;
            let wall = ((spans(x0, r, HALF.0) || spans(x0, r, -HALF.0)) && inside_y)
                || ((spans(y0, r, HALF.1) || spans(y0, r, -HALF.1)) && inside_x);
            // The pillar's rim: the cell centre within 3/4 of a cell of the circle.
            let (cx, cy) = (x0 + 0.5 * r - PILLAR.0, y0 + 0.5 * r - PILLAR.1);
            let d2 = cx * cx + cy * cy;
            let (inner, outer) = (PILLAR.2 - 0.75 * r, PILLAR.2 + 0.75 * r);
            let rim = inner * inner <= d2 && d2 <= outer * outer;
            if wall || rim {
                cells[iy * MAP_SIZE + ix] = occupied;
            }
            ix += 1;
        }
        iy += 1;
    }
    cells
}

/// `true` when `[lo, lo + width]` contains `v`.
const fn spans(lo: f32, width: f32, v: f32) -> bool {
    lo <= v && v <= lo + width
}
