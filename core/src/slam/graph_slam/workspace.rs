//! The memory a loop closure works in: the matcher's map and its max-pooled levels while
//! a match is searched, then the pose graph solver's scratch. The two are never needed at
//! once, so they share one block (the larger of the two) instead of taking both.

use crate::grid::OccupancyBitmap;
use crate::slam::matcher::MatcherLevels;

use super::{MATCH_BYTES, MATCH_CELLS, MATCH_LEVELS};

/// The old map a new keyframe is matched against, with the matcher's levels over it.
#[derive(Clone, Debug)]
pub(super) struct MatchBuffers {
    pub(super) map: OccupancyBitmap<MATCH_CELLS, MATCH_CELLS, MATCH_BYTES>,
    pub(super) levels: MatcherLevels<MATCH_CELLS, MATCH_BYTES, MATCH_LEVELS>,
}

/// One block of memory that holds either the matcher's buffers or `S` floats of solver
/// scratch. Switching clears the block; neither side keeps anything between calls.
#[derive(Clone, Debug)]
// The variants are meant to share one block of memory: that is the point of the enum
// (both sides are sized for it, no heap to box one into).
#[allow(clippy::large_enum_variant)]
// `Solve` is the first variant: rustc gives it tag 0, so that `Workspace::zeroed` is all
// zero bytes. Not a language guarantee (`.ci/firmware.sh` holds the building-slam
// firmware's `.data` at 0 bytes, which a non-zero tag would fill); `#[repr(u8)]` would
// guarantee it but makes `matching` build the match buffers on the stack (the
// building-slam firmware's stack then overflows at its first loop closure).
pub(super) enum Workspace<const S: usize> {
    /// The pose graph solver's scratch.
    Solve([f32; S]),
    /// The matcher's map and levels.
    Match(MatchBuffers),
}

impl<const S: usize> Workspace<S> {
    /// A workspace of zero bytes (the solver's side, zero floats), for a `static`.
    pub(super) const fn zeroed() -> Self {
        Self::Solve([0.0; S])
    }

    /// The matcher's buffers (contents unspecified: the caller initialises the map).
    pub(super) fn matching(&mut self) -> &mut MatchBuffers {
        loop {
            match self {
                Self::Match(buffers) => return buffers,
                Self::Solve(_) => {
                    *self = Self::Match(MatchBuffers {
                        map: OccupancyBitmap::zeroed(),
                        levels: MatcherLevels::zeroed(),
                    });
                }
            }
        }
    }

    /// The solver's scratch (contents unspecified).
    pub(super) fn solving(&mut self) -> &mut [f32; S] {
        loop {
            match self {
                Self::Solve(scratch) => return scratch,
                Self::Match(_) => *self = Self::Solve([0.0; S]),
            }
        }
    }
}

/// Bytes the workspace takes for `scratch` floats: the larger of its two sides (plus the
/// enum's tag and padding, at most 8 bytes).
pub const fn workspace_bytes(scratch: usize) -> usize {
    let solve = 4 * scratch;
    let matching = core::mem::size_of::<MatchBuffers>();
    if solve > matching { solve } else { matching }
}
