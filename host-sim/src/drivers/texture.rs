//! The coloured floor map from RGB-D frames and poses (Du n.d., §II-C and §III-C).
//!
//! Each pixel with a depth is carried pixel + depth → optical → camera body → robot →
//! world by [`Camera::pixel_to_world`]; points whose height lies in the floor band are kept
//! and their colour is averaged into the cell of the map they fall in. Du (n.d.) keeps
//! heights in −0.5 … 0.25 m; here the default band is −0.10 … +0.10 m, because the
//! simulated room has walls down to the floor: that band would paint the bottom 25 cm of
//! every wall into the border cells of the floor map (the Kinect of Du n.d. looked at a
//! floor bounded by obstacles it did not need to colour). Both are options.
//!
//! # References
//!
//! - Du, C. (n.d.). *ECE 276 Project: Particle Filter SLAM*. Undated report, University of
//!   California, San Diego. Texture mapping, §II-C and §III-C.

use crate::domain::recording::TruePose;
use crate::domain::recording::interpolate_pose;
use crate::inputs::camera::world::{Room, SimCamera, floor_colour, render};
use microslam::geometry::Pose2;
use microslam::sensors::camera::Camera;
use rand_core::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use serde::Serialize;

/// How the texture map is built.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TextureSettings {
    /// Map cell edge, metres.
    pub resolution_m: f64,
    /// Points whose world height lies in `[band.0, band.1]` are floor, metres.
    pub band: (f64, f64),
    /// Pixels deeper than this are ignored (their footprint and noise grow with depth).
    pub max_depth_m: f64,
    /// Frames rendered per second of the trajectory.
    pub frame_rate_hz: f64,
    /// Use every `pixel_stride`-th pixel in both directions.
    pub pixel_stride: u32,
    /// Depth noise of the simulated sensor: standard deviation `k · depth²`, k in 1/m.
    pub depth_noise_per_m2: f64,
}

impl Default for TextureSettings {
    fn default() -> Self {
        Self {
            resolution_m: 0.05,
            band: (-0.10, 0.10),
            max_depth_m: 4.0,
            frame_rate_hz: 2.0,
            pixel_stride: 1,
            depth_noise_per_m2: 0.003,
        }
    }
}

/// A square colour map centred on the origin: the mean colour of the points in each cell.
#[derive(Clone, Debug, PartialEq)]
pub struct TextureMap {
    /// Cells per side.
    pub size: usize,
    /// Cell edge, metres.
    pub resolution_m: f64,
    /// Colour sums and counts, row 0 at the largest y (image order).
    sums: Vec<[f64; 3]>,
    counts: Vec<u32>,
}

impl TextureMap {
    /// An empty map covering `[-half, half]²`.
    pub fn new(half_size_m: f64, resolution_m: f64) -> Self {
        let size = ((2.0 * half_size_m) / resolution_m).ceil().max(1.0) as usize;
        Self {
            size,
            resolution_m,
            sums: vec![[0.0; 3]; size * size],
            counts: vec![0; size * size],
        }
    }

    /// Cell index of world `(x, y)`, `None` off the map.
    pub fn cell(&self, x: f64, y: f64) -> Option<usize> {
        let half = self.size as f64 * self.resolution_m / 2.0;
        let c = ((x + half) / self.resolution_m).floor();
        let r = ((half - y) / self.resolution_m).floor();
        let n = self.size as f64;
        (c >= 0.0 && r >= 0.0 && c < n && r < n).then(|| r as usize * self.size + c as usize)
    }

    /// World `(x, y)` of the centre of cell `index`.
    pub fn centre(&self, index: usize) -> (f64, f64) {
        let half = self.size as f64 * self.resolution_m / 2.0;
        let (r, c) = (index / self.size, index % self.size);
        (
            -half + (c as f64 + 0.5) * self.resolution_m,
            half - (r as f64 + 0.5) * self.resolution_m,
        )
    }

    /// Adds a coloured point; `false` when it is off the map.
    pub fn add(&mut self, x: f64, y: f64, rgb: [u8; 3]) -> bool {
        let Some(i) = self.cell(x, y) else {
            return false;
        };
        if let (Some(s), Some(n)) = (self.sums.get_mut(i), self.counts.get_mut(i)) {
            for (a, b) in s.iter_mut().zip(rgb) {
                *a += f64::from(b);
            }
            *n += 1;
        }
        true
    }

    /// Mean colour of cell `index`, `None` when nothing fell in it.
    pub fn colour(&self, index: usize) -> Option<[u8; 3]> {
        let n = *self.counts.get(index)?;
        let s = self.sums.get(index)?;
        (n > 0).then(|| s.map(|v| (v / f64::from(n)).round() as u8))
    }

    /// The map as an RGB image, unknown cells black.
    pub fn to_rgb(&self) -> Vec<u8> {
        (0..self.size * self.size)
            .flat_map(|i| self.colour(i).unwrap_or([0, 0, 0]))
            .collect()
    }

    /// The true floor texture at each cell centre, as an RGB image of the same layout.
    pub fn truth_rgb(&self) -> Vec<u8> {
        (0..self.size * self.size)
            .flat_map(|i| {
                let (x, y) = self.centre(i);
                floor_colour(x, y)
            })
            .collect()
    }

    /// Colour error against the true floor texture at the cell centres.
    pub fn error(&self, room: &Room) -> TextureError {
        let mut sum = 0.0;
        let mut covered = 0usize;
        let mut floor_cells = 0usize;
        let mut within_10 = 0usize;
        for i in 0..self.size * self.size {
            let (x, y) = self.centre(i);
            let on_floor = x.abs() < room.half_size && y.abs() < room.half_size;
            floor_cells += usize::from(on_floor);
            let Some(c) = self.colour(i) else { continue };
            covered += 1;
            let t = floor_colour(x, y);
            let e = c
                .iter()
                .zip(t)
                .map(|(a, b)| (f64::from(*a) - f64::from(b)).abs())
                .sum::<f64>()
                / 3.0;
            sum += e;
            within_10 += usize::from(e <= 10.0);
        }
        TextureError {
            mean_abs_rgb_error: (covered > 0).then(|| sum / covered as f64),
            covered_cells: covered,
            floor_cells,
            coverage: covered as f64 / floor_cells.max(1) as f64,
            share_within_10: (covered > 0).then(|| within_10 as f64 / covered as f64),
        }
    }
}

/// How far the texture map is from the true floor.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct TextureError {
    /// Mean over covered cells of the mean absolute R, G, B difference (0–255 scale).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mean_abs_rgb_error: Option<f64>,
    /// Cells with at least one floor point.
    pub covered_cells: usize,
    /// Cells inside the room.
    pub floor_cells: usize,
    /// `covered_cells / floor_cells`.
    pub coverage: f64,
    /// Share of covered cells whose error is at most 10.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub share_within_10: Option<f64>,
}

/// Counts of the points of a texture run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct PointCounts {
    /// Frames rendered.
    pub frames: usize,
    /// Pixels with a depth inside the range limit.
    pub with_depth: usize,
    /// Of them, inside the height band (floor).
    pub in_band: usize,
    /// Pixels outside the band (walls, signs) or refused by the conversion.
    pub rejected: usize,
}

/// Adds one frame seen from `pose` (the pose used for mapping, estimated or true).
pub fn add_frame(
    map: &mut TextureMap,
    camera: &Camera<f64>,
    frame: &crate::inputs::camera::world::RgbdFrame,
    pose: &Pose2<f64>,
    settings: &TextureSettings,
    counts: &mut PointCounts,
) {
    let stride = settings.pixel_stride.max(1);
    counts.frames += 1;
    for row in (0..frame.height).step_by(stride as usize) {
        for col in (0..frame.width).step_by(stride as usize) {
            let i = frame.index(col, row);
            let (Some(&depth), Some(&rgb)) = (frame.depth.get(i), frame.rgb.get(i)) else {
                continue;
            };
            let depth = f64::from(depth);
            if depth <= 0.0 || depth > settings.max_depth_m {
                continue;
            }
            counts.with_depth += 1;
            match camera.pixel_to_world(pose, col as f64, row as f64, depth) {
                Ok(p) if (settings.band.0..=settings.band.1).contains(&p[2]) => {
                    map.add(p[0], p[1], rgb);
                    counts.in_band += 1;
                }
                _ => counts.rejected += 1,
            }
        }
    }
}

/// Renders frames along `truth` (at the settings' frame rate) and maps each with the pose
/// `mapping_pose(stamp)` gives (the true pose, or an estimate). Frames without a mapping
/// pose are skipped. The depth noise is seeded by `seed`.
pub fn build(
    camera: &SimCamera,
    room: &Room,
    truth: &[TruePose],
    settings: &TextureSettings,
    seed: u64,
    mut mapping_pose: impl FnMut(f64) -> Option<Pose2<f64>>,
) -> (TextureMap, PointCounts) {
    let mut map = TextureMap::new(room.half_size, settings.resolution_m);
    let mut counts = PointCounts::default();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed ^ 0x7e57_u64);
    let (Some(first), Some(last)) = (truth.first(), truth.last()) else {
        return (map, counts);
    };
    let period = 1.0 / settings.frame_rate_hz.max(1e-6);
    let mut t = first.stamp;
    while t <= last.stamp {
        if let (Some(true_pose), Some(pose)) = (interpolate_pose(truth, t), mapping_pose(t)) {
            let noise = (settings.depth_noise_per_m2 > 0.0)
                .then_some((&mut rng, settings.depth_noise_per_m2));
            let frame = render(camera, room, &true_pose, noise);
            add_frame(
                &mut map,
                &camera.camera,
                &frame,
                &pose,
                settings,
                &mut counts,
            );
        }
        t += period;
    }
    (map, counts)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_and_centres_agree_and_off_map_points_are_skipped() {
        let mut map = TextureMap::new(1.0, 0.5);
        assert_eq!(map.size, 4);
        // Row 0 is the largest y: (−0.75, 0.75) is the top-left cell.
        assert_eq!(map.cell(-0.9, 0.9), Some(0));
        assert_eq!(map.centre(0), (-0.75, 0.75));
        assert_eq!(map.cell(0.9, -0.9), Some(15));
        assert_eq!(map.cell(1.01, 0.0), None);
        assert!(!map.add(f64::NAN, 0.0, [1, 2, 3]));
        assert!(map.add(0.1, 0.1, [10, 20, 30]));
        assert!(map.add(0.2, 0.2, [20, 40, 60]));
        let i = map.cell(0.1, 0.1).unwrap();
        assert_eq!(map.colour(i), Some([15, 30, 45]));
        assert_eq!(map.colour(0), None);
    }
}
