//! The sparse search over a map with an occupied-cell bitmap: each window row is cut from
//! the bitmap and only its set bits, the occupied cells, add the beam's weight; the public
//! entry points for each build's choice of window and row length.

use super::sums::{NineByNineSums, PackedSums, RowSums, WindowSums};
use super::{MAX_SHIFT_WINDOW, MAX_SHIFTS, ScanPoint, ShiftScore, best_shift, end_grid};
use crate::geometry::{Pose2, sin_cos_f32};
use crate::grid::{GridView, floor_i32};

/// [`search_window`] with the sparse search only, so that a build that always has a
/// bitmap carries no byte-wise search: over a view without a bitmap every window takes
/// the checked per-cell path (same scores, slowly).
///
/// [`search_window`]: super::search_window
pub fn search_window_sparse(
    map: &GridView<'_>,
    pose: &Pose2<f32>,
    points: &[ScanPoint],
    half_width: u8,
    scores: &mut [u32; MAX_SHIFTS],
) -> ShiftScore {
    // The 9 × 9 window (every preset's for SLAM) gets its own constant-size copy; the
    // other sizes share one.
    if half_width.min(MAX_SHIFT_WINDOW) == 4 {
        search_sparse::<NineByNineSums, 0>(map, map.occupancy_bits(), pose, points, 9, scores)
    } else {
        search_window_sparse_rows::<0>(map, pose, points, half_width, scores)
    }
}

/// [`search_window_sparse`] for a map whose occupied-cell bitmap has `S` bytes a row
/// (`⌈width / 8⌉`), known when the program is built: the 9 × 9 window's row offsets are
/// then constants — no bounds check per row, the offsets inside the load instructions:
/// fewer instructions per grid step on the Cortex-M4F, less time on the host (measured in
/// `docs/speed.md`). Same scores. Another window size, or a map of another width, takes
/// the general sparse path for any window size (correct, slower); `S = 0` is that path
/// alone. [`search_window_packed`] is the same for a 3 × 3 or 5 × 5 window.
///
/// A build uses only the copies it names: [`crate::pf::GridSlam`] takes this for its
/// grid of compile-time width, [`crate::pf::GridLocalizer::with_bitmap_row_bytes`] for a
/// map in flash.
pub fn search_window_sparse_rows<const S: usize>(
    map: &GridView<'_>,
    pose: &Pose2<f32>,
    points: &[ScanPoint],
    half_width: u8,
    scores: &mut [u32; MAX_SHIFTS],
) -> ShiftScore {
    #[cfg(all(feature = "std", target_arch = "x86_64"))]
    if let Some(best) = super::avx512::search_rows::<S>(map, pose, points, half_width, scores) {
        return best;
    }
    search_rows::<NineByNineSums, S>(map, pose, points, half_width, scores)
}

/// [`search_window_sparse_rows`] for a window of `N × N` cells with `N² ≤ 32` (`N` = 3 or
/// 5: a localizer's, [`GridPfConfig::for_localizer`](crate::pf::GridPfConfig::for_localizer))
/// and a map whose bitmap rows have `S` bytes, both known when the program is built: each
/// end point's window is packed into one 32-bit mask (`PackedSums`). Same scores;
/// another window size or row length takes the general sparse path.
pub fn search_window_packed<const N: usize, const S: usize>(
    map: &GridView<'_>,
    pose: &Pose2<f32>,
    points: &[ScanPoint],
    half_width: u8,
    scores: &mut [u32; MAX_SHIFTS],
) -> ShiftScore {
    search_rows::<PackedSums<N>, S>(map, pose, points, half_width, scores)
}

/// The search with accumulator `A` (for windows of `A::ROWS` rows) when the window is
/// `A::ROWS` wide and the map's bitmap rows `S` bytes long, else the general sparse path.
/// (Inlined on a host CPU, so that [`avx512`] compiles it with the vector unit's
/// instructions; the microcontroller keeps one copy.)
///
/// [`avx512`]: super::avx512
#[cfg_attr(not(target_os = "none"), inline(always))]
pub(super) fn search_rows<A: WindowSums, const S: usize>(
    map: &GridView<'_>,
    pose: &Pose2<f32>,
    points: &[ScanPoint],
    half_width: u8,
    scores: &mut [u32; MAX_SHIFTS],
) -> ShiftScore {
    let hw = half_width.min(MAX_SHIFT_WINDOW);
    let n = 2 * usize::from(hw) + 1;
    let bits = map.occupancy_bits();
    if n == A::ROWS && S > 0 && map.geometry().width.div_ceil(8) == S {
        search_sparse::<A, S>(map, bits, pose, points, n, scores)
    } else {
        search_sparse::<RowSums<{ 2 * MAX_SHIFT_WINDOW as usize + 1 }>, 0>(
            map, bits, pose, points, n, scores,
        )
    }
}

/// End points whose grid coordinates [`search_sparse`] computes in one pass before it
/// reads their windows: on a host CPU the pass runs several points per vector
/// instruction; a microcontroller has no vector unit, and a point at a time saves it the
/// stores and loads of the buffers.
const END_POINT_CHUNK: usize = if cfg!(target_os = "none") { 1 } else { 32 };

/// [`search_window`] over a map with an occupied-cell bitmap: for each end point, each of
/// the `n = 2k+1` window rows is cut out of the bitmap as `n` bits (one 4-byte read and
/// two shifts) and only its set bits — the occupied cells — add the point's weight to
/// their shift in the accumulator `A` ([`RowSums`], or [`PackedSums`] for a window of at
/// most 5 × 5); a window without any occupied cell costs its `n` reads and one test.
/// Same integer sums as the other searches, in another order, so the scores are
/// identical.
///
/// The end cell's `floor` is taken as a truncation: the two agree whenever the window's
/// corner is at least one cell inside the grid (then the coordinate is ≥ 1), which is
/// the only case the bitmap path takes; windows at or over the grid's edge take the
/// checked path with the exact `floor`.
///
/// `S` is the bitmap's stride in bytes when the caller has checked it equals
/// `⌈width / 8⌉`, so that the compiler sees the row offsets; 0 reads it from the map.
///
/// [`search_window`]: super::search_window
#[cfg_attr(not(target_os = "none"), inline(always))]
pub(super) fn search_sparse<A: WindowSums, const S: usize>(
    map: &GridView<'_>,
    bits: Option<&[u8]>,
    pose: &Pose2<f32>,
    points: &[ScanPoint],
    n: usize,
    scores: &mut [u32; MAX_SHIFTS],
) -> ShiftScore {
    let n = n.min(A::ROWS);
    let k = (n / 2) as i32;
    let mut acc = A::new();
    let (sin, cos) = sin_cos_f32(pose.theta);
    let g = map.geometry();
    let (w, h) = (g.width, g.height);
    let stride = if S == 0 { w.div_ceil(8) } else { S };
    // The bitmap path needs 1 ≤ x0 ≤ w − n and 1 ≤ y0 ≤ h − n: `(x0 − 1) as u32 <
    // x_limit` (an empty range when the grid is narrower than the window).
    let x_limit = w.saturating_sub(n) as u32;
    let y_limit = h.saturating_sub(n) as u32;
    // Bit `x0 % 8 + t` of a row read is column `x0 + t`: shifted up to the top `n` bits,
    // then down to bits `0..n`.
    let down = 32 - n as u32;
    let bits = bits.unwrap_or(&[]);
    // A window is read as `n` rows of 4 bytes one stride apart from the byte holding
    // column x0 (its bits are in those 4 bytes: x0 % 8 + n ≤ 22).
    let span = (n - 1) * stride + 4;
    let inside = |x0: i32, y0: i32| {
        (x0.wrapping_sub(1) as u32) < x_limit && (y0.wrapping_sub(1) as u32) < y_limit
    };
    // One end point: `(u, v)` in grid coordinates, `(x0, y0)` its window's corner.
    let mut add_point = |p: &ScanPoint, u: f32, v: f32, x0: i32, y0: i32| {
        let window = if inside(x0, y0) {
            let first = y0 as usize * stride + (x0 as usize >> 3);
            bits.get(first..first + span)
        } else {
            None
        };
        let Some(window) = window else {
            // At or over the grid's edge, or no bitmap: exact floor, cell by cell.
            let (x0, y0) = (
                floor_i32(u).saturating_sub(k),
                floor_i32(v).saturating_sub(k),
            );
            acc.add_checked(map, x0, y0, n, p.weight);
            return;
        };
        // Bit `first_bit` of a row read is column `x0`.
        let first_bit = x0 as u32 & 7;
        acc.add_rows(p.weight, |r| {
            let offset = r * stride;
            match window.get(offset..offset + 4) {
                Some(&[a, b, c, d]) if r < n => {
                    let word = u32::from_le_bytes([a, b, c, d]);
                    if A::WIDE_ROWS {
                        word >> first_bit
                    } else {
                        (word << (down - first_bit)) >> down
                    }
                }
                _ => 0,
            }
        });
    };
    let corner = |u: f32, v: f32| ((u as i32).saturating_sub(k), (v as i32).saturating_sub(k));
    if END_POINT_CHUNK == 1 {
        for p in points {
            let (u, v) = end_grid(map, pose, sin, cos, p);
            let (x0, y0) = corner(u, v);
            add_point(p, u, v, x0, y0);
        }
    } else {
        // Two passes per chunk: first the end points' coordinates and corners
        // (straight-line work that vector units do several points at a time), then the
        // windows. Neighbouring beams often end in the same cell (1° apart, up to
        // ~1.5 m away with 5 cm cells: 19 % of the Intel log's end points at 180 beams),
        // and then their windows are the same: a point whose successor in the chunk has
        // its corner, inside the grid, passes its weight on, and the window is read once
        // with the sum (wrapping additions commute: the same scores). On the M4F, one
        // point at a time, the test costs more than it saves at 90 beams (6 % merged).
        let mut grid = [(0f32, 0f32); END_POINT_CHUNK];
        let mut corners = [(0i32, 0i32); END_POINT_CHUNK];
        for chunk in points.chunks(END_POINT_CHUNK) {
            for (p, g) in chunk.iter().zip(grid.iter_mut()) {
                *g = end_grid(map, pose, sin, cos, p);
            }
            for (&(u, v), c) in grid.iter().zip(corners.iter_mut()) {
                *c = corner(u, v);
            }
            let mut carried = 0u32;
            for (i, ((p, &(u, v)), &(x0, y0))) in chunk
                .iter()
                .zip(grid.iter())
                .zip(corners.iter())
                .enumerate()
            {
                let weight = carried.wrapping_add(p.weight);
                let successor = corners.get(i + 1).filter(|_| i + 1 < chunk.len());
                if successor == Some(&(x0, y0)) && inside(x0, y0) {
                    carried = weight;
                } else {
                    carried = 0;
                    add_point(&ScanPoint { weight, ..*p }, u, v, x0, y0);
                }
            }
        }
    }
    acc.write(n, scores);
    best_shift(scores.get(..n * n).unwrap_or(&[]), k as u8)
}
