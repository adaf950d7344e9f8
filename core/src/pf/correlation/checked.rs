//! The checked per-cell path of the searches: a window at or over the grid's edge, every
//! cell looked up with a bounds check.

use crate::grid::GridView;

/// Adds `weight` to every shift of the `n × n` window at `(x0, y0)` (scores row-major in
/// `acc`) whose cell is occupied, with a bounds check per cell: the path for windows that
/// reach over the grid's edge.
pub(super) fn add_checked(
    map: &GridView<'_>,
    x0: i32,
    y0: i32,
    n: usize,
    weight: u32,
    acc: &mut [u32],
) {
    for (r, row_acc) in acc.chunks_exact_mut(n).take(n).enumerate() {
        for (b, s) in row_acc.iter_mut().enumerate() {
            if map.is_occupied(x0.saturating_add(b as i32), y0.saturating_add(r as i32)) {
                *s = s.wrapping_add(weight);
            }
        }
    }
}
