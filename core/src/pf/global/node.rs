//! The nodes of the depth-first branch and bound: a span of headings and a block of
//! positions, the children of a node being evaluated, and the stack's depth.

#[cfg(doc)]
use super::GlobalSearch;

/// A node of the search: headings `[j0, j0 + 2^a)`, positions `[x, x + 2^k) × [y, y + 2^k)`.
#[derive(Clone, Copy, Default)]
pub(super) struct Node {
    pub(super) x: i32,
    pub(super) y: i32,
    pub(super) j0: u32,
    pub(super) bound: u32,
    pub(super) a: u8,
    pub(super) k: u8,
}

impl Node {
    /// The heading the node's end cells are computed at.
    pub(super) fn reference(&self) -> u32 {
        if self.a == 0 {
            self.j0
        } else {
            self.j0 + (1 << (self.a - 1))
        }
    }
}

/// Deepest stack of the search: four children per level of headings and of positions.
pub(super) const STACK: usize = 4 * (14 + crate::grid::layers::MAX_LEVELS as usize + 1);

/// The children of a node being evaluated: kept across a pause of the search (see
/// [`GlobalSearch::resume`]), so that a search run in slices visits exactly the nodes of
/// one run with the same number of node evaluations.
#[derive(Clone, Copy, Default)]
pub(super) struct Expansion {
    pub(super) children: [Node; 4],
    /// Children made.
    pub(super) made: u8,
    /// Children evaluated.
    pub(super) evaluated: u8,
    /// Children kept (their bound is above the threshold), at the front of `children`.
    pub(super) kept: u8,
}

/// Stable insertion sort by decreasing bound.
pub(super) fn sort_decreasing(nodes: &mut [Node]) {
    for i in 1..nodes.len() {
        let mut j = i;
        while j > 0 {
            let (Some(a), Some(b)) = (nodes.get(j - 1), nodes.get(j)) else {
                break;
            };
            if a.bound >= b.bound {
                break;
            }
            nodes.swap(j - 1, j);
            j -= 1;
        }
    }
}
