//! The observation model of Du (n.d.): map correlation of a scan's end points with the occupied
//! cells, optionally range-weighted, over a `(2k+1) × (2k+1)` window of cell shifts
//! (Du n.d., eqs. 21 and 24).
//!
//! `corr(shift) = Σ_i w_i · 1[cell(end point i) + shift is occupied]`, with
//! `w_i = range_i^γ` (γ = 0: the plain count). Weights are fixed point
//! ([`WEIGHT_ONE`] = 1.0) and sums are integers, so every evaluation order gives the same
//! score — the fast search and the brute-force reference agree exactly, on every target.
//!
//! The fast search ([`search_window`]) converts each end point to its cell once per
//! particle (not once per shift), treats the shifts as index offsets into the `2k+1` rows
//! of `2k+1` bytes around it, and adds the beam's weight masked by the occupancy test to
//! all shifts of a row at once: no per-shift coordinate arithmetic, no bounds check per
//! cell, no branch on the map's content, so the compiler vectorises the row. Windows that
//! reach over the grid's edge take a checked path. Identical particles are scored once
//! (in [`ParticleFilter::update`](super::ParticleFilter::update)).
//!
//! Over a map with an occupied-cell bitmap ([`GridView::with_occupancy_bits`], or an
//! [`crate::grid::OccupancyGrid`] with a `BITMAP`) the search is sparse
//! ([`search_window_sparse`]): each window row is cut from the bitmap by one 4-byte read
//! and only its set bits add the beam's weight. Walls are thin, so most rows are empty
//! and the rest hold a few bits (what that saves against the byte-wise search is measured
//! in `docs/speed.md`). [`search_window_brute_force`] is the plain triple loop, kept as
//! the reference.
//!
//! # References
//!
//! - Du, C. (n.d.). *ECE 276 Project: Particle Filter SLAM*. Department of Electrical
//!   Computer Engineering, University of California, San Diego.

#[cfg(all(feature = "std", target_arch = "x86_64"))]
mod avx512;
mod brute_force;
mod bytewise;
mod checked;
mod points;
mod sparse;
mod sums;
#[cfg(test)]
mod tests;

pub use brute_force::search_window_brute_force;
pub use points::{ScanPoint, ScanPoints};
pub use sparse::{search_window_packed, search_window_sparse, search_window_sparse_rows};

use crate::geometry::Pose2;
use crate::grid::{GridView, floor_i32};
use bytewise::search_fixed;

/// The fixed-point weight that stands for 1.0 (a beam of the unweighted count).
pub const WEIGHT_ONE: u32 = 256;
/// Largest weight of one beam (2²⁰ = range^γ of 4096): keeps sums of up to 4096 beams
/// inside a `u32`.
pub const MAX_WEIGHT: u32 = 1 << 20;
/// Largest half-width `k` of the shift window (15 × 15 shifts).
pub const MAX_SHIFT_WINDOW: u8 = 7;
/// Number of shifts of the largest window.
pub const MAX_SHIFTS: usize =
    (2 * MAX_SHIFT_WINDOW as usize + 1) * (2 * MAX_SHIFT_WINDOW as usize + 1);

/// The best shift of one particle's scan.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ShiftScore {
    /// Best shift along x, cells.
    pub dx: i32,
    /// Best shift along y, cells.
    pub dy: i32,
    /// Correlation at the best shift (fixed point, [`WEIGHT_ONE`] = 1.0).
    pub score: u32,
}

/// Continuous grid coordinates of a robot-frame point seen from `pose` (`sin`, `cos` of
/// its heading) — the one formula every search uses.
#[inline]
pub fn end_grid(
    map: &GridView<'_>,
    pose: &Pose2<f32>,
    sin: f32,
    cos: f32,
    p: &ScanPoint,
) -> (f32, f32) {
    let wx = pose.x + cos * p.x - sin * p.y;
    let wy = pose.y + sin * p.x + cos * p.y;
    map.geometry().world_to_grid(wx, wy)
}

/// The cell of a robot-frame point seen from `pose`: the floor of [`end_grid`].
#[inline]
pub fn end_cell(
    map: &GridView<'_>,
    pose: &Pose2<f32>,
    sin: f32,
    cos: f32,
    p: &ScanPoint,
) -> (i32, i32) {
    let (u, v) = end_grid(map, pose, sin, cos, p);
    (floor_i32(u), floor_i32(v))
}

/// Picks the best shift from the scores of a `(2k+1)²` window (row-major, `dy` outer):
/// the highest score; on a tie the unshifted particle if it is among the best, otherwise
/// the first in row-major order.
pub fn best_shift(scores: &[u32], half_width: u8) -> ShiftScore {
    let k = i32::from(half_width.min(MAX_SHIFT_WINDOW));
    let n = (2 * k + 1) as usize;
    let centre = n * n / 2;
    let mut best = (centre, scores.get(centre).copied().unwrap_or(0));
    for (i, s) in scores.iter().take(n * n).enumerate() {
        if *s > best.1 {
            best = (i, *s);
        }
    }
    ShiftScore {
        dx: (best.0 % n) as i32 - k,
        dy: (best.0 / n) as i32 - k,
        score: best.1,
    }
}

/// [`best_shift`] with a Gaussian prior on the shift: the shift that maximises
/// `score − penalty · (dx² + dy²)` (`penalty` in score units per cell², 0: plain
/// [`best_shift`]); the returned score is the correlation at that shift. Ties: the
/// unshifted particle, then the first in row-major order.
///
/// Without a prior, a shift that gains a single hit wins however far it moves the
/// particle; where the scan constrains a direction weakly (a corridor, the frontier of
/// the map where the end points ahead fall on unknown cells and shifting back puts them
/// on mapped ones) that biases every step the same way and the pose slides.
pub fn best_shift_with_prior(scores: &[u32], half_width: u8, penalty: f32) -> ShiftScore {
    if penalty.is_nan() || penalty <= 0.0 {
        return best_shift(scores, half_width);
    }
    let k = i32::from(half_width.min(MAX_SHIFT_WINDOW));
    let n = (2 * k + 1) as usize;
    let first = scores.get(n * n / 2).copied().unwrap_or(0);
    // (dx, dy, score, value), the unshifted particle first.
    let mut best = (0, 0, first, first as f32);
    let mut rows = scores.chunks_exact(n).take(n);
    for dy in -k..=k {
        let Some(row) = rows.next() else { break };
        for (dx, s) in (-k..=k).zip(row) {
            // The penalty only lowers a score: one no higher than the best value cannot win.
            if *s as f32 > best.3 {
                let v = *s as f32 - penalty * (dx * dx + dy * dy) as f32;
                if v > best.3 {
                    best = (dx, dy, *s, v);
                }
            }
        }
    }
    ShiftScore {
        dx: best.0,
        dy: best.1,
        score: best.2,
    }
}

/// Correlation of the scan seen from `pose` for every shift of the window of half-width
/// `half_width` (clamped to [`MAX_SHIFT_WINDOW`]); writes the `(2k+1)²` scores into
/// `scores` (row-major, `dy` outer) and returns the best. The fast search.
pub fn search_window(
    map: &GridView<'_>,
    pose: &Pose2<f32>,
    points: &[ScanPoint],
    half_width: u8,
    scores: &mut [u32; MAX_SHIFTS],
) -> ShiftScore {
    let hw = half_width.min(MAX_SHIFT_WINDOW);
    if map.occupancy_bits().is_some() {
        return search_window_sparse(map, pose, points, half_width, scores);
    }
    match hw {
        0 => search_fixed::<1>(map, pose, points, scores),
        1 => search_fixed::<3>(map, pose, points, scores),
        2 => search_fixed::<5>(map, pose, points, scores),
        3 => search_fixed::<7>(map, pose, points, scores),
        4 => search_fixed::<9>(map, pose, points, scores),
        5 => search_fixed::<11>(map, pose, points, scores),
        6 => search_fixed::<13>(map, pose, points, scores),
        _ => search_fixed::<15>(map, pose, points, scores),
    }
}
