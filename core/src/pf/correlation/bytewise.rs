//! The byte-wise search over a map without an occupied-cell bitmap: each window row is
//! read as bytes and every shift of the row adds the beam's weight masked by the occupancy
//! test, without a branch on the map's content, so the compiler vectorises it.

use super::checked::add_checked;
use super::{MAX_SHIFTS, ScanPoint, ShiftScore, best_shift, end_cell};
use crate::geometry::{Pose2, sin_cos_f32};
use crate::grid::GridView;

/// End points whose window rows are summed together in [`search_fixed`] (on a 32-bit
/// target, 128 bytes of stack for their cell indices and 128 for their weights).
const POINT_CHUNK: usize = 32;

/// [`search_window`] for a window of `N = 2k+1` cells: each window row is `N` bytes read
/// once, and every shift's score grows by the beam's weight masked by the occupancy
/// test — no branches on the map's content, so the compiler vectorises the row.
///
/// The end points are taken in chunks of [`POINT_CHUNK`]: their cells are computed first,
/// then each of the `N` accumulator rows is loaded once per chunk and kept in registers
/// while the chunk's points add into it (instead of loading and storing it once per point).
/// The sums are the same integers added in another order, so the scores are identical.
///
/// [`search_window`]: super::search_window
pub(super) fn search_fixed<const N: usize>(
    map: &GridView<'_>,
    pose: &Pose2<f32>,
    points: &[ScanPoint],
    scores: &mut [u32; MAX_SHIFTS],
) -> ShiftScore {
    let k = (N / 2) as i32;
    let mut acc = [[0u32; N]; N];
    let (sin, cos) = sin_cos_f32(pose.theta);
    let g = map.geometry();
    let (w, h) = (g.width, g.height);
    let cells = map.cells();
    let t = map.occupied_above();
    let mut bases = [0usize; POINT_CHUNK];
    let mut weights = [0u32; POINT_CHUNK];
    for chunk in points.chunks(POINT_CHUNK) {
        // Pass 1: window origins of the points whose window lies inside the grid; the
        // others take the checked path now.
        let mut n = 0;
        for p in chunk {
            let (cx, cy) = end_cell(map, pose, sin, cos, p);
            let (x0, y0) = (cx.saturating_sub(k), cy.saturating_sub(k));
            let inside = x0 >= 0 && y0 >= 0 && (x0 as usize) + N <= w && (y0 as usize) + N <= h;
            if inside {
                if let (Some(b), Some(wt)) = (bases.get_mut(n), weights.get_mut(n)) {
                    *b = y0 as usize * w + x0 as usize;
                    *wt = p.weight;
                    n += 1;
                }
            } else {
                add_checked(map, x0, y0, N, p.weight, acc.as_flattened_mut());
            }
        }
        // Pass 2: row by row, all inside points of the chunk.
        let (chunk_bases, chunk_weights) = (
            bases.get(..n).unwrap_or(&[]),
            weights.get(..n).unwrap_or(&[]),
        );
        for (r, row_acc) in acc.iter_mut().enumerate() {
            let mut local = *row_acc;
            let offset = r * w;
            for (base, weight) in chunk_bases.iter().zip(chunk_weights) {
                let start = base + offset;
                let Some(Ok(row)) = cells.get(start..start + N).map(<&[i8; N]>::try_from) else {
                    continue;
                };
                for (s, c) in local.iter_mut().zip(row) {
                    *s = s.wrapping_add(weight & 0u32.wrapping_sub(u32::from(*c > t)));
                }
            }
            *row_acc = local;
        }
    }
    for (dst, src) in scores.iter_mut().zip(acc.as_flattened()) {
        *dst = *src;
    }
    best_shift(&scores[..N * N], (N / 2) as u8)
}
