//! The camera's simulated world: a square room with a procedurally textured floor, striped
//! walls and sign plates, and a ray caster that renders RGB-D frames of it.
//!
//! Everything is a pure function of world coordinates, so the true floor texture can be
//! evaluated anywhere (for scoring the texture map) and every rendered pixel can be checked
//! against the geometry that produced it.

use microslam::geometry::Pose2;
use microslam::sensors::camera::{Camera, CameraMount, PinholeIntrinsics, kinect_v1};
use rand_distr::{Distribution, Normal};
use rand_xoshiro::Xoshiro256PlusPlus;

/// Floor tile edge, metres.
pub const TILE_M: f64 = 1.0;

/// Tile colours (the tile index picks one through a hash).
const PALETTE: [[f64; 3]; 6] = [
    [200.0, 60.0, 50.0],
    [60.0, 160.0, 70.0],
    [50.0, 90.0, 200.0],
    [220.0, 190.0, 60.0],
    [150.0, 70.0, 170.0],
    [70.0, 180.0, 190.0],
];

/// The true colour of the floor at world `(x, y)`: 1 m tiles whose colour is picked by a
/// hash of the tile index, each with a brightness ramp along x (75 % → 100 %) and a
/// weaker one along y, so that a map shifted by a few centimetres shows an error.
pub fn floor_colour(x: f64, y: f64) -> [u8; 3] {
    let (i, j) = ((x / TILE_M).floor() as i64, (y / TILE_M).floor() as i64);
    // A splitmix-style mix of the tile index (a plain xor of products shows diagonals).
    let mut h = (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (j as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
    h ^= h >> 29;
    h = h.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    h ^= h >> 32;
    let hash = (h % PALETTE.len() as u64) as usize;
    let base = PALETTE[hash];
    let fx = x / TILE_M - i as f64;
    let fy = y / TILE_M - j as f64;
    let gain = 0.65 + 0.3 * fx + 0.05 * fy;
    base.map(|c| (c * gain).round().clamp(0.0, 255.0) as u8)
}

/// The colour of a wall point: grey with darker vertical stripes every 0.5 m along the
/// wall (`along` is the coordinate along the wall) and a dark skirting board below 0.1 m.
pub fn wall_colour(along: f64, z: f64) -> [u8; 3] {
    if z < 0.1 {
        return [60, 50, 40];
    }
    if (along / 0.5).floor().rem_euclid(2.0) == 0.0 {
        [200, 200, 205]
    } else {
        [150, 150, 165]
    }
}

/// A sign: a square plate standing at a known place, always turned to face the camera
/// (a billboard), so that its centre is the point a detector's box centre measures.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sign {
    /// True identity (landmark id) and class.
    pub id: u32,
    /// Centre of the plate in the world, metres.
    pub position: [f64; 3],
    /// Half the plate's edge, metres.
    pub half_size: f64,
}

/// The room: floor at z = 0, four walls at `±half_size`, and the signs in it.
#[derive(Clone, Debug, PartialEq)]
pub struct Room {
    /// Walls stand at x = ±half_size and y = ±half_size, metres.
    pub half_size: f64,
    /// Wall height, metres; rays passing above it see nothing (no depth).
    pub wall_height: f64,
    /// Signs (rendered as coloured plates).
    pub signs: Vec<Sign>,
}

impl Default for Room {
    fn default() -> Self {
        Self {
            half_size: 7.0,
            wall_height: 2.5,
            signs: Vec::new(),
        }
    }
}

/// A camera with an image size. The default is a 160 × 120 image with a 77° horizontal
/// field of view (f = 100 px), on the THOR robot's Kinect mount (0.18, 0.005, 0.36) m,
/// pitched 0.36 rad down, yawed 0.021 rad.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SimCamera {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Intrinsics and mount. Pixel `(c, r)` has its centre at `u = c, v = r`.
    pub camera: Camera<f64>,
}

impl Default for SimCamera {
    fn default() -> Self {
        Self::with_mount(kinect_v1::thor_mount())
    }
}

impl SimCamera {
    /// The default 160 × 120 camera on another mount.
    pub fn with_mount(mount: CameraMount<f64>) -> Self {
        Self {
            width: 160,
            height: 120,
            camera: Camera {
                intrinsics: PinholeIntrinsics {
                    fx: 100.0,
                    fy: 100.0,
                    cx: 79.5,
                    cy: 59.5,
                },
                mount,
            },
        }
    }

    /// `true` when pixel `(u, v)` lies inside the image.
    pub fn contains(&self, u: f64, v: f64) -> bool {
        u >= -0.5 && v >= -0.5 && u < self.width as f64 - 0.5 && v < self.height as f64 - 0.5
    }
}

/// What a pixel sees.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Surface {
    /// Nothing within the room (above the walls): no depth.
    Nothing,
    /// The floor.
    Floor,
    /// A wall.
    Wall,
    /// The sign with this id.
    Sign(u32),
}

/// A rendered RGB-D frame, rows top to bottom.
#[derive(Clone, Debug, PartialEq)]
pub struct RgbdFrame {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Depth along the optical axis, metres; 0 where nothing was hit.
    pub depth: Vec<f32>,
    /// Colour of each pixel.
    pub rgb: Vec<[u8; 3]>,
    /// What each pixel sees (ground truth for tests and for the detector).
    pub surface: Vec<Surface>,
}

impl RgbdFrame {
    /// Index of pixel `(col, row)`.
    pub fn index(&self, col: u32, row: u32) -> usize {
        (row * self.width + col) as usize
    }
}

/// Sign colour by class.
pub fn sign_colour(id: u32) -> [u8; 3] {
    const C: [[u8; 3]; 4] = [[255, 0, 0], [255, 255, 255], [0, 0, 255], [255, 200, 0]];
    C[(id % 4) as usize]
}

/// Ray caster: the camera's optical-frame ray of each pixel, carried into the world once
/// per frame.
struct Rays {
    origin: [f64; 3],
    /// World rotation of optical vectors (row-major).
    rot: [[f64; 3]; 3],
}

impl Rays {
    fn new(cam: &Camera<f64>, pose: &Pose2<f64>) -> Self {
        let r = cam.mount.robot_from_optical();
        let (s, c) = pose.theta.sin_cos();
        // world_from_optical = R_z(heading) · robot_from_optical.
        let mut rot = [[0.0; 3]; 3];
        for j in 0..3 {
            let (rx, ry, rz) = (r[(0, j)], r[(1, j)], r[(2, j)]);
            rot[0][j] = c * rx - s * ry;
            rot[1][j] = s * rx + c * ry;
            rot[2][j] = rz;
        }
        let t = cam.mount.translation();
        let origin = [
            pose.x + c * t[0] - s * t[1],
            pose.y + s * t[0] + c * t[1],
            t[2],
        ];
        Self { origin, rot }
    }

    /// World direction of the ray through `(u, v)`, scaled so that its optical z is 1:
    /// the hit distance along it is the depth.
    fn direction(&self, k: &PinholeIntrinsics<f64>, u: f64, v: f64) -> [f64; 3] {
        let d = [(u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0];
        self.rot
            .map(|row| row[0] * d[0] + row[1] * d[1] + row[2] * d[2])
    }
}

/// Casts one ray: depth (the ray parameter, with optical z = 1) and the surface hit.
fn cast(room: &Room, o: &[f64; 3], d: &[f64; 3]) -> (f64, Surface, [u8; 3]) {
    let h = room.half_size;
    let mut best = (f64::INFINITY, Surface::Nothing, [0, 0, 0]);
    if d[2] < 0.0 {
        let t = -o[2] / d[2];
        let (x, y) = (o[0] + t * d[0], o[1] + t * d[1]);
        if x.abs() <= h && y.abs() <= h {
            best = (t, Surface::Floor, floor_colour(x, y));
        }
    }
    for axis in 0..2 {
        if d[axis] == 0.0 {
            continue;
        }
        let wall = h * d[axis].signum();
        let t = (wall - o[axis]) / d[axis];
        if t <= 0.0 || t >= best.0 {
            continue;
        }
        let other = 1 - axis;
        let along = o[other] + t * d[other];
        let z = o[2] + t * d[2];
        if along.abs() <= h && (0.0..=room.wall_height).contains(&z) {
            best = (t, Surface::Wall, wall_colour(along, z));
        }
    }
    for sign in &room.signs {
        let [sx, sy, sz] = sign.position;
        // Billboard normal: horizontal, from the sign towards the camera.
        let (nx, ny) = (o[0] - sx, o[1] - sy);
        let n = nx.hypot(ny);
        if n < 1e-9 {
            continue;
        }
        let (nx, ny) = (nx / n, ny / n);
        let denom = d[0] * nx + d[1] * ny;
        if denom.abs() < 1e-12 {
            continue;
        }
        let t = ((sx - o[0]) * nx + (sy - o[1]) * ny) / denom;
        if t <= 0.0 || t >= best.0 {
            continue;
        }
        let p = [o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]];
        let lateral = -(p[0] - sx) * ny + (p[1] - sy) * nx;
        if lateral.abs() <= sign.half_size && (p[2] - sz).abs() <= sign.half_size {
            best = (t, Surface::Sign(sign.id), sign_colour(sign.id));
        }
    }
    best
}

/// Renders the frame seen by `cam` from robot pose `pose`. With `depth_noise = Some((rng,
/// k))`, Gaussian noise of standard deviation `k · depth²` is added to each depth (the
/// colour stays that of the true surface point, as with a registered RGB-D sensor).
pub fn render(
    cam: &SimCamera,
    room: &Room,
    pose: &Pose2<f64>,
    mut depth_noise: Option<(&mut Xoshiro256PlusPlus, f64)>,
) -> RgbdFrame {
    let rays = Rays::new(&cam.camera, pose);
    let n = (cam.width * cam.height) as usize;
    let mut frame = RgbdFrame {
        width: cam.width,
        height: cam.height,
        depth: Vec::with_capacity(n),
        rgb: Vec::with_capacity(n),
        surface: Vec::with_capacity(n),
    };
    let unit = Normal::new(0.0, 1.0).ok();
    for row in 0..cam.height {
        for col in 0..cam.width {
            let d = rays.direction(&cam.camera.intrinsics, col as f64, row as f64);
            let (t, surface, rgb) = cast(room, &rays.origin, &d);
            let mut depth = if t.is_finite() { t } else { 0.0 };
            if depth > 0.0
                && let (Some((rng, k)), Some(unit)) = (depth_noise.as_mut(), unit)
            {
                depth = (depth + *k * depth * depth * unit.sample(*rng)).max(1e-3);
            }
            frame.depth.push(depth as f32);
            frame.rgb.push(rgb);
            frame.surface.push(surface);
        }
    }
    frame
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floor_texture_varies_within_and_between_tiles() {
        assert_ne!(floor_colour(0.05, 0.5), floor_colour(0.95, 0.5));
        let tiles: std::collections::BTreeSet<_> = (0..8)
            .flat_map(|i| (0..8).map(move |j| floor_colour(i as f64 + 0.5, j as f64 + 0.5)))
            .collect();
        assert!(tiles.len() >= 5, "{tiles:?}");
    }
}
