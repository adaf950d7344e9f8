//! The candidate headings and the tables a search keeps of them: the rotation of every
//! heading from a few computed once, the beams' end cells at the heading last used, and
//! how far each end may move over a node's span of headings (the dilations of the
//! bound).

#[cfg(doc)]
use super::MAX_HEADINGS;
use super::beams::Selected;
use super::{MAX_SEARCH_BEAMS, SearchReport};
use crate::geometry::{wrap_angle, wrap_near};
use crate::grid::floor_i32;

/// `(sin, cos)` of every heading `j · step` without a trigonometric call per heading
/// (libm's `sincosf` works in `f64`, which the Cortex-M4F computes in software: several
/// thousand instructions a call): the rotations by `2^b · step` are computed once per
/// search and heading `j`'s is the product of those of its set bits.
pub(super) struct Rotations {
    powers: [(f32, f32); HEADING_LEVELS],
}

impl Rotations {
    pub(super) fn new(step: f32) -> Self {
        let mut powers = [(0.0, 1.0); HEADING_LEVELS];
        for (b, p) in powers.iter_mut().enumerate() {
            *p = libm::sincosf(wrap_angle((1u32 << b) as f32 * step));
        }
        Self { powers }
    }

    /// `(sin, cos)` of heading `j` (`j < 2^HEADING_LEVELS`).
    pub(super) fn at(&self, j: u32) -> (f32, f32) {
        let (mut s, mut c) = (0.0f32, 1.0f32);
        for (b, (sb, cb)) in self.powers.iter().enumerate() {
            if (j >> b) & 1 == 1 {
                (s, c) = (s * cb + c * sb, c * cb - s * sb);
            }
        }
        (s, c)
    }
}

/// End cells of the selected beams for the robot at the centre of cell (0, 0) facing
/// the heading of rotation `(sin, cos)`, with their weights.
///
/// The robot at the centre of cell (0, 0) puts a robot-frame point `p` at grid
/// coordinates `0.5 + R(θ) p / r` (cells of `r` metres): two products and a sum per
/// axis, with `p / r` computed once per search.
pub(super) fn end_cells(
    sel: &Selected,
    (sin, cos): (f32, f32),
    out: &mut [(i32, i32, u32); MAX_SEARCH_BEAMS],
) {
    for ((slot, w), (u, v)) in out
        .iter_mut()
        .zip(sel.weights.iter().take(sel.len))
        .zip(sel.scaled.iter())
    {
        let cx = floor_i32(0.5 + (cos * u - sin * v));
        let cy = floor_i32(0.5 + (sin * u + cos * v));
        *slot = (cx, cy, *w);
    }
}

/// The beams' end cells for one reference heading, recomputed only when the heading
/// changes (the depth-first search visits many nodes of one heading in a row).
pub(super) struct EndCells {
    heading: u32,
    rotations: Rotations,
    cells: [(i32, i32, u32); MAX_SEARCH_BEAMS],
}

impl EndCells {
    pub(super) fn new(step: f32) -> Self {
        Self {
            heading: u32::MAX,
            rotations: Rotations::new(step),
            cells: [(0, 0, 0); MAX_SEARCH_BEAMS],
        }
    }

    /// The end cells for heading index `j` (computed when not held already).
    pub(super) fn at(
        &mut self,
        sel: &Selected,
        j: u32,
        report: &mut SearchReport,
    ) -> &[(i32, i32, u32)] {
        if self.heading != j {
            end_cells(sel, self.rotations.at(j), &mut self.cells);
            self.heading = j;
            report.rotations += 1;
        }
        self.cells.get(..sel.len).unwrap_or(&[])
    }
}

/// Heading `j` of the candidate set, radians in (−π, π] (`j · step` is within one turn:
/// no trigonometry).
pub(super) fn heading_angle(j: u32, step: f32) -> f32 {
    wrap_near(j as f32 * step)
}

/// Cells an end cell may move, at most, when the heading moves by up to `delta` radians
/// from the reference: the end moves along a chord of at most `ρ · δ` cells, and
/// `|⌊u⌋ − ⌊v⌋| ≤ ⌈|u − v|⌉`; 0.01 cell more covers the float rounding.
#[inline]
pub(super) fn dilation(rho_cells: f32, delta: f32) -> i32 {
    // trunc(v) + 1 ≥ ⌈v⌉ (equal unless v is a whole number), without a call to ceilf.
    (rho_cells * delta + 0.01) as i32 + 1
}

/// Most heading levels of a node (`2^a` headings, `a` ≤ 13 for [`MAX_HEADINGS`]).
const HEADING_LEVELS: usize = 14;

/// [`dilation`] of every selected beam for every heading level `a ≥ 1` of a node
/// (`δ = 2^(a−1)` steps), saturated at 255 cells (a window that wide covers every level),
/// computed once per search: the bound's inner loop then only looks it up.
pub(super) struct Dilations {
    pub(super) cells: [[u8; MAX_SEARCH_BEAMS]; HEADING_LEVELS],
}

impl Dilations {
    pub(super) fn new(sel: &Selected, step: f32) -> Self {
        let mut d = Self {
            cells: [[0; MAX_SEARCH_BEAMS]; HEADING_LEVELS],
        };
        for (a, row) in d.cells.iter_mut().enumerate().skip(1) {
            let delta = (1u32 << (a - 1)) as f32 * step;
            for (e, rho) in row.iter_mut().zip(sel.rho_cells.iter().take(sel.len)) {
                *e = dilation(*rho, delta).clamp(0, 255) as u8;
            }
        }
        d
    }
}
