//! Global localization: where in the whole map was this scan taken? An exact
//! correlative search (Olson 2009, "Real-time correlative scan matching"; Cartographer's
//! fast correlative scan matcher, Hess et al. 2016) by branch and bound.
//!
//! **Score.** The particle filter's correlation ([`super::correlation`]): a candidate
//! pose's score is `Σ_i w_i · 1[end cell of beam i is occupied]`, with the beams' fixed
//! point weights ([`ScanPoint::weight`]). For each candidate heading `θ_j` the end cells
//! `c_i` are computed once for the robot at the centre of cell `(0, 0)`; the robot at the
//! centre of cell `(x, y)` then scores `Σ_i w_i · occ(c_i + (x, y))` — the shift search's
//! formula, over every cell of the map.
//!
//! **Candidates.** Headings `θ_j = j · δ` over the full turn, with
//! `δ = acos(1 − r² / (2 d²))` for cells of `r` metres and the farthest beam used at `d`
//! metres (that beam's end then moves by at most one cell between neighbouring headings),
//! unless a step is configured; positions: every cell of the map whose log-odds is below
//! the free threshold (the robot stands in free space).
//!
//! **Branch and bound.** A node is a heading and an aligned block of `2^k × 2^k` positions.
//! Its bound is the score against max-pooled level `k` of the map
//! ([`MaxPoolLayers`]): each beam counts when any cell of its `2^k` window is occupied,
//! which no position of the block can beat. Per heading, the blocks of the top level are
//! visited in row order, depth first, the four children of a node in decreasing order of
//! bound; a node whose bound does not exceed the acceptance threshold is dropped with all
//! its positions, and so is a block without a free cell. Leaves (`k = 0`) are exact
//! scores. The threshold is the larger of the minimum score and, once `N` hypotheses are
//! held, the `N`-th best score. With the work budget not exhausted
//! ([`SearchReport::complete`]), the best hypothesis is the highest-scoring candidate of
//! the whole map (the first found among equal scores) — the same answer as the
//! brute-force reference [`search_brute_force`].
//!
//! **Heading windows.** With [`GlobalSearchConfig::heading_peaks`] set, only the headings
//! within [`GlobalSearchConfig::heading_window`] of the peaks of the scan's wall
//! directions correlated with the map's ([`super::orientation`]) are searched, best peak
//! first (each peak `s` as `s` and `s + π`); a scan with too few line-like points searches
//! every heading. Exact within the windows. Every heading outside them is searched too,
//! one minimum score behind the windows (windows at the first pass's minimum, windows one
//! step lower, the rest at the first minimum, …; see [`GlobalSearchConfig::full_turn_below`]),
//! until a pass finds a hypothesis scoring `full_turn_below`: a robot whose local walls
//! the correlation does not pick out is still found, before the windows have been
//! searched down to the lowest minimum, where they prune least.
//!
//! **Hypotheses.** The `N` best candidates that are pairwise apart by more than the
//! configured separation (a better candidate nearby replaces a worse one), best first.
//!
//! **Cost.** A node's bound looks its beams up one at a time (one to five bitmap reads
//! each) and stops at the beam that rules the node out; a new heading costs a rotation and
//! a floor per beam. The unit of work is one beam looked at, and a node evaluation counts
//! [`NODE_WORK`] more for making, bounding and stacking it: so counted, a unit costs no
//! more on the Cortex-M4F when the nodes look at few beams than when they look at many
//! (measured in `docs/global-localization.md`), and the work budget
//! ([`GlobalSearchConfig::work_budget`]) bounds a search's instructions however its nodes
//! are pruned. When the budget is spent the search stops (the best found so far is
//! returned, [`SearchReport::complete`] is `false`).
//!
//! **Slices.** [`GlobalSearch`] runs the same search in slices of work, paused
//! and resumed where it stopped (the depth-first stack and the node being expanded are
//! kept): a robot spends a work budget per scan on one search over several scans
//! ([`super::RelocalizationConfig::search_scans`]).
//!
//! No allocation: a search's state (the selected beams, at most [`MAX_SEARCH_BEAMS`], and
//! the depth-first stack) lives in a [`GlobalSearch`]; a slice adds the end cells and the
//! tabled dilations on the stack (the sizes of both: `docs/global-localization.md`).
//!
//! # References
//!
//! - Olson 2009: E. Olson, "Real-time correlative scan matching", IEEE International
//!   Conference on Robotics and Automation (ICRA), 2009, pp. 4387–4393. The exhaustive
//!   correlative search over a grid of candidate poses, with a low-resolution look-up
//!   table (each cell the maximum of the cells it covers) that bounds the fine search.
//! - Hess et al. 2016: W. Hess, D. Kohler, H. Rapp, D. Andor, "Real-time loop closure in
//!   2D LIDAR SLAM", IEEE ICRA 2016, pp. 1271–1278. Branch and bound over the
//!   precomputation grids (Cartographer's fast correlative scan matcher), depth first,
//!   children in decreasing order of bound.

// The search over one map and its layers: the beams a scan gives (`beams`), the
// per-heading tables (`tables`), a node's bound and exact score against the map
// (`bound`), the depth-first nodes (`node`). The relocalization around it: the settings
// (`config`), what a pass covers (`plan`), the hypotheses kept (`hypotheses`), the
// state machine that runs the passes over the nodes in slices (`search`), what it reports
// (`report`). The brute-force reference (`brute_force`) checks it in the tests.
mod beams;
mod bound;
mod brute_force;
mod config;
mod hypotheses;
mod node;
mod plan;
mod report;
mod search;
mod tables;
#[cfg(test)]
mod tests;

pub use beams::heading_step_for;
pub use brute_force::search_brute_force;
pub use config::{
    GlobalSearchConfig, MAX_HEADING_PEAKS, MAX_HEADINGS, MAX_SEARCH_BEAMS, NODE_WORK,
};
pub use hypotheses::{Hypotheses, Hypothesis};
pub use report::{GlobalError, SearchReport};
pub use search::{GlobalSearch, search, search_with_walls};

#[cfg(doc)]
use super::correlation::ScanPoint;
#[cfg(doc)]
use crate::grid::MaxPoolLayers;
