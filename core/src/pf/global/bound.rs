//! A node scored against the map and its max-pooled layers: the bound of a block of
//! positions over a span of headings, the exact score of a leaf, and whether the robot
//! may stand in a block.

#[cfg(doc)]
use super::GlobalSearchConfig;
use super::tables::Dilations;
use crate::grid::{GridView, MaxPoolLayers};

/// Bound of the node `(headings [j0, j0 + 2^a), block 2^k × 2^k at (x, y))` given the
/// end cells at the reference heading `j0 + 2^(a−1)` (`j0` for `a = 0`): each beam counts
/// when any cell is occupied in its window grown by the cells its end may move over the
/// headings of the node. With `a = 0` and `k = 0`: the exact score.
///
/// Stops as soon as the beams still to look at cannot lift the bound above `thr` (the
/// node is dropped then): the value returned is then some number ≤ `thr`. Returns the
/// bound and the beams looked at (the work of [`GlobalSearchConfig::work_budget`]).
#[allow(clippy::too_many_arguments)]
pub(super) fn bound(
    map: &GridView<'_>,
    levels: &Levels<'_>,
    dilations: &Dilations,
    cells: &[(i32, i32, u32)],
    total: u32,
    thr: u32,
    a: u8,
    k: u8,
    x: i32,
    y: i32,
) -> (u32, u32) {
    // The most the node can still score: the total less the beams that missed.
    let mut possible = total;
    let mut looked = 0u32;
    if a == 0 {
        for (cx, cy, w) in cells {
            looked += 1;
            let (u, v) = (cx.wrapping_add(x), cy.wrapping_add(y));
            let hit = if k == 0 {
                map.is_occupied(u, v)
            } else {
                levels.any(k, u, v)
            };
            if !hit {
                possible = possible.wrapping_sub(*w);
                if possible <= thr {
                    return (possible, looked);
                }
            }
        }
        return (possible, looked);
    }
    let Some(row) = dilations.cells.get(usize::from(a)) else {
        return (total, looked);
    };
    let block = 1i32 << k;
    for ((cx, cy, w), e) in cells.iter().zip(row.iter()) {
        let e = i32::from(*e);
        looked += 1;
        let missed = !levels.any_in_square(
            cx.wrapping_add(x).wrapping_sub(e),
            cy.wrapping_add(y).wrapping_sub(e),
            block + 2 * e,
        );
        if missed {
            possible = possible.wrapping_sub(*w);
            if possible <= thr {
                return (possible, looked);
            }
        }
    }
    (possible, looked)
}

/// The occupied levels' bitmaps, looked up once per search (the bound's inner loop).
pub(super) struct Levels<'a> {
    bits: [&'a [u8]; crate::grid::layers::MAX_LEVELS as usize + 1],
    stride: usize,
    width: i32,
    height: i32,
    top: u8,
}

impl<'a> Levels<'a> {
    pub(super) fn new(layers: &MaxPoolLayers<'a>) -> Self {
        let mut bits: [&'a [u8]; crate::grid::layers::MAX_LEVELS as usize + 1] =
            [&[]; crate::grid::layers::MAX_LEVELS as usize + 1];
        for (k, b) in bits.iter_mut().enumerate().skip(1) {
            *b = layers.occupied_level(k as u8).unwrap_or(&[]);
        }
        Self {
            bits,
            stride: layers.width().div_ceil(8),
            width: layers.width() as i32,
            height: layers.height() as i32,
            top: layers.levels(),
        }
    }

    /// `true` when a cell of the `size × size` square at `(x, y)` may be occupied (also
    /// when the square is wider than the top level's windows: then it is not looked at).
    ///
    /// The square is covered by the four windows of the level below the one whose
    /// window holds it (`2^(l−1) < size ≤ 2^l`: windows of `2^(l−1)` at its four corners),
    /// not by one window of `2^l`, up to four times its area: on the Intel map that
    /// halves the nodes of a search (`docs/global-localization.md`). The one window of
    /// `2^l` is looked at first: it rules most squares out alone.
    #[inline]
    fn any_in_square(&self, x: i32, y: i32, size: i32) -> bool {
        let level = (32 - (size.max(1) as u32 - 1).leading_zeros()) as u8;
        if level > self.top.saturating_add(1) {
            return true;
        }
        if level <= self.top && !self.any(level, x, y) {
            return false;
        }
        let fine = level.saturating_sub(1);
        if fine == 0 {
            // Level 0 is the map, not a layer (the bound's squares are ≥ 3 cells wide).
            return true;
        }
        let o = size - (1i32 << fine);
        self.any(fine, x, y)
            || self.any(fine, x.wrapping_add(o), y)
            || self.any(fine, x, y.wrapping_add(o))
            || self.any(fine, x.wrapping_add(o), y.wrapping_add(o))
    }

    /// [`MaxPoolLayers::any_occupied`] without recomputing the level's place.
    #[inline]
    fn any(&self, k: u8, x: i32, y: i32) -> bool {
        let size = 1i32 << (k & 15);
        if x >= self.width || y >= self.height || x <= -size || y <= -size {
            return false;
        }
        let (x, y) = (x.max(0) as usize, y.max(0) as usize);
        self.bits
            .get(usize::from(k))
            .and_then(|b| b.get(y * self.stride + x / 8))
            .is_some_and(|b| (b >> (x % 8)) & 1 == 1)
    }
}

/// Exact score of the robot at cell `(x, y)` given the end cells (level 0).
pub(super) fn leaf_score(map: &GridView<'_>, cells: &[(i32, i32, u32)], x: i32, y: i32) -> u32 {
    let mut s = 0u32;
    for (cx, cy, w) in cells {
        if map.is_occupied(cx.wrapping_add(x), cy.wrapping_add(y)) {
            s = s.wrapping_add(*w);
        }
    }
    s
}

/// `true` when the robot may stand somewhere in the level-`k` block at `(x, y)`.
///
/// At level 0 that is a free cell (its log-odds, or the free bitmap of a map image that
/// has one). A map kept as its occupied-cell bitmap alone (a map
/// image in flash: [`GridView::from_occupancy_bits`], no log-odds) cannot tell a free
/// cell from an unknown one; there a candidate is a cell that is not occupied in a
/// 2 × 2 block of level 1 holding a free cell, the finest free information the layers
/// carry (without it no leaf would ever be a candidate, and the search on a device
/// could never find a pose).
pub(super) fn block_free(
    map: &GridView<'_>,
    layers: &MaxPoolLayers<'_>,
    k: u8,
    x: i32,
    y: i32,
) -> bool {
    if k == 0 && (!map.cells().is_empty() || map.free_bits().is_some()) {
        return map.is_free(x, y, layers.free_below());
    }
    if k == 0 {
        return map.geometry().contains(x, y)
            && !map.is_occupied(x, y)
            && layers.any_free(1, (x >> 1) as usize, (y >> 1) as usize);
    }
    x >= 0 && y >= 0 && layers.any_free(k, (x >> k) as usize, (y >> k) as usize)
}
