//! The brute-force reference search: every shift, every end point, one map lookup each.

use super::{MAX_SHIFT_WINDOW, MAX_SHIFTS, ScanPoint, ShiftScore, best_shift, end_cell};
use crate::geometry::{Pose2, sin_cos_f32};
use crate::grid::GridView;

/// The brute-force reference of [`search_window`]: for every shift, for every point,
/// look the shifted end cell up. Same result, (2k+1)² lookups per point.
///
/// [`search_window`]: super::search_window
pub fn search_window_brute_force(
    map: &GridView<'_>,
    pose: &Pose2<f32>,
    points: &[ScanPoint],
    half_width: u8,
    scores: &mut [u32; MAX_SHIFTS],
) -> ShiftScore {
    let hw = half_width.min(MAX_SHIFT_WINDOW);
    let k = i32::from(hw);
    let n = (2 * k + 1) as usize;
    let (sin, cos) = sin_cos_f32(pose.theta);
    for dy in -k..=k {
        for dx in -k..=k {
            let mut sum = 0u32;
            for p in points {
                let (cx, cy) = end_cell(map, pose, sin, cos, p);
                if map.is_occupied(cx.saturating_add(dx), cy.saturating_add(dy)) {
                    sum = sum.wrapping_add(p.weight);
                }
            }
            if let Some(s) = scores.get_mut((dy + k) as usize * n + (dx + k) as usize) {
                *s = sum;
            }
        }
    }
    best_shift(&scores[..n * n], hw)
}
