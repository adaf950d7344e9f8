//! Where, near a guess, does a scan fit a map best? A correlative scan matcher (Olson
//! 2009) over a window of headings and positions around the guess, exact by branch and
//! bound on max-pooled copies of the map (Hess et al. 2016), in fixed memory.
//!
//! **Score.** A candidate pose scores the number of the scan's end points that fall on an
//! occupied cell of the map (an [`OccupancyBitmap`]).
//!
//! **Candidates.** Headings `guess.θ + j·δ` for `|j·δ| ≤` the window's half angle, tried
//! in the order 0, −δ, +δ, −2δ, …; positions: the guess moved by whole cells, up to the
//! window's half width each way.
//!
//! **Bound.** Level `k` of a [`MatcherLevels`] holds, for each cell, whether any cell of
//! the `b × b` block starting there is occupied (`b = 4^k`): a scan scored against it at
//! a translation bounds its score at every one of the `b × b` translations starting
//! there. Per heading, the window's translations are covered by blocks of the top level;
//! a block whose bound does not beat the best score so far is dropped with all its
//! translations, the others are split into 16 blocks of the level below, best bound
//! first, down to exact scores. The answer is the best candidate of the whole window, the
//! first found among equals (the same as trying every candidate: a test checks it).
//! Scores below what a match needs to be accepted (`min_hit_fraction` of the end points)
//! are pruned from the start, and the runner-up pass looks only for a candidate above
//! `max_runner_up` of the best and stops at the first: both decide the same as a full
//! search, for far less work where nothing fits.
//!
//! **Uncertainty.** Around the best candidate the exact scores of its neighbours (± a few
//! cells and heading steps) weighted by `exp((score − best) / τ)` give a covariance:
//! long along a corridor, where moving along it scores the same, short across it.
//!
//! # References
//!
//! - Olson 2009: E. Olson, "Real-time correlative scan matching", IEEE ICRA 2009,
//!   pp. 4387–4393.
//! - Hess et al. 2016: W. Hess, D. Kohler, H. Rapp, D. Andor, "Real-time loop closure in
//!   2D LIDAR SLAM", IEEE ICRA 2016, pp. 1271–1278.

use crate::geometry::{Pose2, sin_cos_f32, wrap_angle};
use crate::grid::{GridGeometry, OccupancyBitmap, floor_i32};
use core::fmt;

/// Most end points a match uses (more are thinned evenly).
pub const MAX_MATCH_POINTS: usize = 128;
/// Most levels of max-pooled copies ([`MatcherLevels`]).
pub const MAX_LEVELS: usize = 4;

/// The window of candidates around the guess.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct MatchWindow {
    /// Positions up to this many cells from the guess along x and along y.
    pub half_width_cells: u16,
    /// Headings up to this far from the guess's, radians.
    pub half_angle: f32,
    /// Step between headings, radians (> 0).
    pub angle_step: f32,
    /// A match is reported only when at least this fraction of the end points hit (0..1).
    pub min_hit_fraction: f32,
    /// Work after which the search stops (end points looked up, all levels): bounds the
    /// instructions of one match (each of its two passes).
    pub work_budget: u32,
    /// The runner-up is the best candidate at least this many cells (along x or y) or
    /// heading steps from the best one …
    pub distinct_cells: u16,
    /// … and a match is reported only when the runner-up scores at most this fraction of
    /// the best (0..1; 1: no test): in a corridor whose doors repeat, two places fit.
    pub max_runner_up: f32,
}

/// Why a match was not made.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MatchError {
    /// A setting is out of range or not finite, or the guess is not finite.
    InvalidInput,
    /// No end point to match (all non-finite or none given).
    NoPoints,
    /// The levels were made for another map (size or placement): call
    /// [`MatcherLevels::build`] for this one first.
    StaleLevels,
}

impl fmt::Display for MatchError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::InvalidInput => "a match window setting or the guess is out of range",
            Self::NoPoints => "no usable end point to match",
            Self::StaleLevels => "the matcher's levels were built for another map",
        })
    }
}

impl core::error::Error for MatchError {}

/// The best candidate of a window.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ScanMatch {
    /// The scan's pose at the best candidate (the guess when no candidate has
    /// `min_hit_fraction` of the end points on occupied cells).
    pub pose: Pose2<f32>,
    /// The mean of the candidates around the best one weighted as for
    /// [`ScanMatch::covariance`]: the best candidate refined below a cell and a heading
    /// step.
    pub centroid: Pose2<f32>,
    /// End points on occupied cells at the best candidate; 0 when no candidate reaches
    /// `min_hit_fraction` of them (the search prunes every candidate below it).
    pub hits: u32,
    /// End points used.
    pub points: u32,
    /// The score of a candidate distinct from the best (see
    /// [`MatchWindow::distinct_cells`]) above `max_runner_up` of the best, the first one
    /// found (the search stops there: it decides); 0 when there is none or the test is
    /// off.
    pub runner_up: u32,
    /// `true` when `hits ≥ min_hit_fraction · points` and the search covered the whole
    /// window within its work budget.
    pub accepted: bool,
    /// `false` when the work budget ran out (the best found so far is reported).
    pub complete: bool,
    /// Work done by the search (end points looked up); the covariance adds
    /// `5 · 7 · 7 = 245` scores of the end points.
    pub work: u32,
    /// Covariance of the position (m²: xx, xy, yy) and the heading (rad²) from the scores
    /// around the best candidate (see the module).
    pub covariance: [f32; 4],
}

/// Max-pooled copies of an `N × N` map, levels `1..=LEVELS` with blocks of `4^k` cells,
/// each `BYTES = occupancy_bytes(N, N)` bytes: `LEVELS · BYTES` of RAM (256 × 256 cells,
/// 2 levels: 16 KB), built from a map with [`MatcherLevels::build`].
#[derive(Clone, Debug)]
pub struct MatcherLevels<const N: usize, const BYTES: usize, const LEVELS: usize> {
    levels: [[u8; BYTES]; LEVELS],
    geometry: GridGeometry,
}

impl<const N: usize, const BYTES: usize, const LEVELS: usize> MatcherLevels<N, BYTES, LEVELS> {
    const LEVELS_OK: () = assert!(
        LEVELS >= 1 && LEVELS <= MAX_LEVELS && BYTES == crate::grid::occupancy_bytes(N, N),
        "MatcherLevels<N, BYTES, LEVELS>: 1 ≤ LEVELS ≤ MAX_LEVELS, BYTES = occupancy_bytes(N, N)"
    );

    /// Zero bytes only, for a `static` in `.bss`.
    pub const fn zeroed() -> Self {
        let () = Self::LEVELS_OK;
        Self {
            levels: [[0; BYTES]; LEVELS],
            geometry: GridGeometry {
                width: 0,
                height: 0,
                resolution: 0.0,
                origin_x: 0.0,
                origin_y: 0.0,
            },
        }
    }

    /// Makes the levels of `map`: level `k` is the map with every set bit spread to the
    /// `4^k × 4^k` block ending there (each cell: any set bit in the block starting at
    /// it). O(`LEVELS · BYTES`) word operations.
    pub fn build(&mut self, map: &OccupancyBitmap<N, N, BYTES>) {
        self.geometry = *map.geometry();
        let mut source: &[u8] = map.bits();
        let mut block = 1usize;
        for level in self.levels.iter_mut() {
            level.copy_from_slice(source);
            // Two doublings per level: blocks of 4× the size of the level below.
            for _ in 0..2 {
                spread(level, N, block);
                block *= 2;
            }
            source = level;
        }
    }

    /// Matches `points` (robot frame, metres) on `map` around `guess` over `window`, all
    /// at once ([`MatcherLevels::start`], then [`MatcherLevels::resume`] with no limit).
    /// `map` must be the one the levels were built from.
    pub fn search(
        &self,
        map: &OccupancyBitmap<N, N, BYTES>,
        points: &[(f32, f32)],
        guess: &Pose2<f32>,
        window: &MatchWindow,
    ) -> Result<ScanMatch, MatchError> {
        let mut progress = self.start(map, points, guess, window)?;
        loop {
            if let Some(m) = self.resume(map, &mut progress, window, u32::MAX)? {
                return Ok(m);
            }
        }
    }

    /// Starts a match of `points` (robot frame, metres) on `map` around `guess` over
    /// `window`, to be run by [`MatcherLevels::resume`] (in slices, e.g. one a scan).
    pub fn start(
        &self,
        map: &OccupancyBitmap<N, N, BYTES>,
        points: &[(f32, f32)],
        guess: &Pose2<f32>,
        window: &MatchWindow,
    ) -> Result<MatchProgress, MatchError> {
        let valid = guess.is_finite()
            && window.half_angle.is_finite()
            && window.half_angle >= 0.0
            && window.angle_step.is_finite()
            && window.angle_step > 0.0
            && (0.0..=1.0).contains(&window.min_hit_fraction);
        if !valid {
            return Err(MatchError::InvalidInput);
        }
        if *map.geometry() != self.geometry || self.geometry.width != N {
            return Err(MatchError::StaleLevels);
        }
        let mut used = [(0.0f32, 0.0f32); MAX_MATCH_POINTS];
        let n = thin(points, &mut used);
        if n == 0 {
            return Err(MatchError::NoPoints);
        }
        // Only a candidate with at least `need` hits can be accepted: scores below it
        // are pruned like those below the best so far.
        let need = ceil_u32(window.min_hit_fraction * n as f32);
        Ok(MatchProgress {
            points: used,
            n,
            guess: *guess,
            next: 0,
            runner_up_pass: false,
            best: Candidate::default(),
            first: Candidate::default(),
            floor: need.saturating_sub(1),
            pass_work: 0,
            work: 0,
            complete: true,
        })
    }

    /// Runs the match `progress` holds for about `quantum` end-point look-ups (it stops at
    /// the first boundary of a top-level block of translations past `quantum`), on the `map`
    /// and `window` it was started with. `Some` with the match when it is done; `None`
    /// when it paused (call again). The answer does not depend on how it was sliced.
    pub fn resume(
        &self,
        map: &OccupancyBitmap<N, N, BYTES>,
        progress: &mut MatchProgress,
        window: &MatchWindow,
        quantum: u32,
    ) -> Result<Option<ScanMatch>, MatchError> {
        if *map.geometry() != self.geometry || self.geometry.width != N {
            return Err(MatchError::StaleLevels);
        }
        let n = progress.n;
        let used = progress.points.get(..n).unwrap_or(&[]);
        let guess = progress.guess;
        let mut search = Search {
            levels: &self.levels,
            base: map.bits(),
            geometry: &self.geometry,
            work: progress.pass_work,
            budget: window.work_budget,
            best: progress.best,
            floor: progress.floor,
            stop_when_found: progress.runner_up_pass,
            found: false,
            exclude: progress
                .runner_up_pass
                .then_some((progress.first, i32::from(window.distinct_cells))),
            cells: [(0, 0); MAX_MATCH_POINTS],
            n,
        };
        let mut spent = 0u32;
        loop {
            let before = search.work;
            let end = search.pass_from(
                &mut progress.next,
                used,
                &guess,
                window,
                quantum - spent.min(quantum),
            );
            spent = spent.saturating_add(search.work.saturating_sub(before));
            let Some(complete) = end else {
                // Paused at a block boundary.
                progress.pass_work = search.work;
                progress.best = search.best;
                return Ok(None);
            };
            progress.complete &= complete;
            progress.work = progress.work.saturating_add(search.work);
            if progress.runner_up_pass {
                break;
            }
            // The first pass is done. The runner-up: the same search with the best
            // candidate's neighbourhood left out, looking only for a candidate above
            // `max_runner_up` of the best (the first one found decides: no match).
            progress.first = search.best;
            if !(window.max_runner_up < 1.0 && search.best.score > 0) {
                break;
            }
            progress.runner_up_pass = true;
            progress.next = 0;
            progress.floor = (window.max_runner_up * search.best.score as f32) as u32;
            search.work = 0;
            search.best = Candidate::default();
            search.floor = progress.floor;
            search.stop_when_found = true;
            search.found = false;
            search.exclude = Some((progress.first, i32::from(window.distinct_cells)));
            if spent >= quantum {
                progress.pass_work = 0;
                progress.best = search.best;
                return Ok(None);
            }
        }
        let best = progress.first;
        let runner_up = if progress.runner_up_pass {
            search.best.score
        } else {
            0
        };
        let theta = wrap_angle(guess.theta + best.heading as f32 * window.angle_step);
        let res = self.geometry.resolution;
        let pose = Pose2::new(
            guess.x + best.dx as f32 * res,
            guess.y + best.dy as f32 * res,
            theta,
        );
        let work = progress.work;
        let (mean, covariance) = if best.score > 0 {
            search.spread(used, &guess, window, &best)
        } else {
            ([0.0; 3], [0.0; 4])
        };
        let centroid = Pose2::new(
            pose.x + mean[0],
            pose.y + mean[1],
            wrap_angle(pose.theta + mean[2]),
        );
        let points = n as u32;
        let complete = progress.complete;
        Ok(Some(ScanMatch {
            pose,
            centroid,
            hits: best.score,
            points,
            accepted: complete
                && best.score as f32 >= window.min_hit_fraction * points as f32
                && runner_up as f32 <= window.max_runner_up * best.score as f32,
            runner_up,
            complete,
            work,
            covariance,
        }))
    }
}

/// A match in progress ([`MatcherLevels::start`], [`MatcherLevels::resume`]): its end
/// points and guess and where the search stands, as plain data kept between calls (the
/// map and its levels must not change in between).
#[derive(Clone, Debug)]
pub struct MatchProgress {
    points: [(f32, f32); MAX_MATCH_POINTS],
    n: usize,
    guess: Pose2<f32>,
    /// The next heading (in the order 0, −1, +1, …) of the current pass.
    next: i32,
    /// The current pass is the runner-up's.
    runner_up_pass: bool,
    /// The current pass's best so far.
    best: Candidate,
    /// The first pass's answer.
    first: Candidate,
    /// The current pass's floor.
    floor: u32,
    /// Work of the current pass (against the budget).
    pass_work: u32,
    /// Work of the passes done.
    work: u32,
    /// No pass ran out of its budget.
    complete: bool,
}

/// `⌈x⌉` for `x ≥ 0` (0 for NaN or below 0).
fn ceil_u32(x: f32) -> u32 {
    let t = x as u32;
    t + u32::from((t as f32) < x)
}

/// Thins `points` evenly to at most [`MAX_MATCH_POINTS`] finite ones into `out`; the
/// number kept.
fn thin(points: &[(f32, f32)], out: &mut [(f32, f32); MAX_MATCH_POINTS]) -> usize {
    let finite = points
        .iter()
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .count();
    let stride = finite.div_ceil(MAX_MATCH_POINTS).max(1);
    let mut n = 0;
    for p in points
        .iter()
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .step_by(stride)
    {
        if let Some(slot) = out.get_mut(n) {
            *slot = *p;
            n += 1;
        }
    }
    n
}

/// In place: every set bit also sets the `shift` cells before it along x and the `shift`
/// rows below it (so that a cell holds the OR of the `2·shift`-wide block starting at it,
/// when it held that of the `shift`-wide block).
fn spread(bits: &mut [u8], width: usize, shift: usize) {
    let bpr = width.div_ceil(8);
    // Rows: row y |= row y + shift, in increasing y (row y + shift not yet changed).
    let rows = bits.len() / bpr.max(1);
    for y in 0..rows.saturating_sub(shift) {
        for b in 0..bpr {
            let above = bits.get((y + shift) * bpr + b).copied().unwrap_or(0);
            if let Some(v) = bits.get_mut(y * bpr + b) {
                *v |= above;
            }
        }
    }
    // Columns: bit x |= bit x + shift.
    for row in bits.chunks_exact_mut(bpr) {
        let bytes = shift / 8;
        let s = (shift % 8) as u32;
        for i in 0..row.len() {
            let a = row.get(i + bytes).copied().unwrap_or(0);
            let b = row.get(i + bytes + 1).copied().unwrap_or(0);
            let moved = if s == 0 { a } else { (a >> s) | (b << (8 - s)) };
            if let Some(v) = row.get_mut(i) {
                *v |= moved;
            }
        }
    }
}

/// Widens every set bit of `bits` (rows of `width` bits) to the 3 × 3 cells around it:
/// one pass of [`spread`] towards `+x, +y`, then one towards `−x, −y`.
pub(crate) fn dilate(bits: &mut [u8], width: usize) {
    spread(bits, width, 1);
    let bpr = width.div_ceil(8);
    // Rows: row y |= row y − 1, in decreasing y (row y − 1 not yet changed).
    let rows = bits.len() / bpr.max(1);
    for y in (1..rows).rev() {
        for b in 0..bpr {
            let below = bits.get((y - 1) * bpr + b).copied().unwrap_or(0);
            if let Some(v) = bits.get_mut(y * bpr + b) {
                *v |= below;
            }
        }
    }
    // Columns: bit x |= bit x − 1, in decreasing bytes (byte i − 1 not yet changed).
    for row in bits.chunks_exact_mut(bpr) {
        for i in (0..row.len()).rev() {
            let carry = i
                .checked_sub(1)
                .and_then(|j| row.get(j))
                .map_or(0, |p| p >> 7);
            if let Some(v) = row.get_mut(i) {
                *v |= (*v << 1) | carry;
            }
        }
    }
}

/// A candidate: heading index, cell offsets from the guess, its score.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Candidate {
    heading: i32,
    dx: i32,
    dy: i32,
    score: u32,
}

/// One search's state.
struct Search<'a, const BYTES: usize, const LEVELS: usize> {
    levels: &'a [[u8; BYTES]; LEVELS],
    base: &'a [u8],
    geometry: &'a GridGeometry,
    work: u32,
    budget: u32,
    /// The best candidate above `floor` (score 0: none yet).
    best: Candidate,
    /// Scores at or below this are no candidates (pruned like those below the best).
    floor: u32,
    /// Stop at the first candidate above `floor` (the runner-up pass: one decides).
    stop_when_found: bool,
    /// Set when a stop at the first candidate happened.
    found: bool,
    /// Candidates within this many cells or heading steps of this one are not scored (the
    /// runner-up pass).
    exclude: Option<(Candidate, i32)>,
    /// End cells of the points at the current heading, the robot at the guess.
    cells: [(i32, i32); MAX_MATCH_POINTS],
    n: usize,
}

impl<const BYTES: usize, const LEVELS: usize> Search<'_, BYTES, LEVELS> {
    /// The window's headings in the order 0, −1, +1, −2, … steps, and at each the
    /// top-level blocks of its translations, from block `*next` (counted over the whole
    /// pass) on, until `quantum` look-ups were spent (then it stops at the next block
    /// boundary and returns `None`, `*next` the block to go on with). At the end of the
    /// pass `Some(complete)`: `false` when the work budget ran out.
    fn pass_from(
        &mut self,
        next: &mut i32,
        points: &[(f32, f32)],
        guess: &Pose2<f32>,
        window: &MatchWindow,
        quantum: u32,
    ) -> Option<bool> {
        let steps = (window.half_angle / window.angle_step) as i32;
        let half = i32::from(window.half_width_cells);
        let block = 1i32 << (2 * LEVELS);
        let blocks = (2 * half + 1 + block - 1) / block;
        let per_heading = blocks * blocks;
        let start = self.work;
        let mut cells_of = None;
        while *next < (2 * steps + 1) * per_heading {
            if self.work.saturating_sub(start) >= quantum {
                return None;
            }
            let (k, b) = (*next / per_heading, *next % per_heading);
            let j = if k % 2 == 0 { -(k / 2) } else { (k + 1) / 2 };
            if cells_of != Some(j) {
                let theta = guess.theta + j as f32 * window.angle_step;
                self.end_cells(points, guess, theta);
                cells_of = Some(j);
            }
            *next += 1;
            let (x0, y0) = (-half + (b % blocks) * block, -half + (b / blocks) * block);
            if !self.top_block(j, x0, y0, half) {
                // Out of budget, or stopped at the first candidate (a complete answer).
                return Some(self.found);
            }
        }
        Some(true)
    }

    /// What a bound or score must beat: the best so far, or the floor.
    fn threshold(&self) -> u32 {
        self.best.score.max(self.floor)
    }

    /// `true` when the runner-up pass leaves this candidate out.
    fn excluded(&self, j: i32, dx: i32, dy: i32) -> bool {
        self.exclude.is_some_and(|(c, r)| {
            (j - c.heading).abs() < r && (dx - c.dx).abs() < r && (dy - c.dy).abs() < r
        })
    }

    fn end_cells(&mut self, points: &[(f32, f32)], guess: &Pose2<f32>, theta: f32) {
        let (s, c) = sin_cos_f32(theta);
        let g = self.geometry;
        for (cell, (px, py)) in self.cells.iter_mut().zip(points) {
            let (x, y) = (guess.x + c * px - s * py, guess.y + s * px + c * py);
            let (u, v) = g.world_to_grid(x, y);
            *cell = (floor_i32(u), floor_i32(v));
        }
    }

    /// Score of the end cells moved by `(dx, dy)` on `bits` (level or base).
    fn score(&mut self, bits: &[u8], dx: i32, dy: i32) -> u32 {
        let w = self.geometry.width as u32;
        let h = self.geometry.height as u32;
        let bpr = (w as usize).div_ceil(8);
        let mut hits = 0u32;
        // Offsets are within the window (`u16` cells) and end cells saturate at `i32`'s
        // ends ([`floor_i32`]): a sum that wraps lands near 2³¹, never in the grid, and
        // one unsigned comparison per axis tests both of the grid's edges.
        for &(cx, cy) in self.cells.get(..self.n).unwrap_or(&[]) {
            let (x, y) = (cx.wrapping_add(dx) as u32, cy.wrapping_add(dy) as u32);
            if x < w && y < h {
                let byte = bits
                    .get(y as usize * bpr + (x >> 3) as usize)
                    .copied()
                    .unwrap_or(0);
                hits += u32::from(byte >> (x & 7) & 1);
            }
        }
        self.work = self.work.saturating_add(self.n as u32);
        hits
    }

    /// The translations of the top-level block starting at `(x0, y0)` at heading index
    /// `j`, by branch and bound; `false` when the work budget ran out (or the search
    /// stopped at its first candidate).
    fn top_block(&mut self, j: i32, x0: i32, y0: i32, half: i32) -> bool {
        let top = LEVELS;
        let levels = self.levels;
        let Some(bits) = levels.get(top - 1) else {
            return true;
        };
        let bound = self.score(bits, x0, y0);
        if bound > self.threshold() && !self.expand(j, top, x0, y0, half) {
            return false;
        }
        self.work < self.budget
    }

    /// The 16 blocks of the level below the block of level `level` starting at `(x0, y0)`
    /// (those inside the window): at level 0 their exact scores, above it their bounds,
    /// then each whose bound beats the best so far, best bound first (equal bounds in row
    /// order). `false` when the work budget ran out.
    fn expand(&mut self, j: i32, level: usize, x0: i32, y0: i32, half: i32) -> bool {
        if self.work >= self.budget {
            return false;
        }
        let below = level - 1;
        let child = 1i32 << (2 * below);
        let levels = self.levels;
        let bits = if below == 0 {
            self.base
        } else {
            match levels.get(below - 1) {
                Some(b) => &b[..],
                None => return true,
            }
        };
        let mut children = [(0u32, 0i32, 0i32); 16];
        let mut count = 0;
        for cy in 0..4 {
            for cx in 0..4 {
                let (x, y) = (x0 + cx * child, y0 + cy * child);
                if x > half || y > half {
                    continue;
                }
                if below == 0 && self.excluded(j, x, y) {
                    continue;
                }
                let score = self.score(bits, x, y);
                if below == 0 {
                    if score > self.threshold() {
                        self.best = Candidate {
                            heading: j,
                            dx: x,
                            dy: y,
                            score,
                        };
                        if self.stop_when_found {
                            self.found = true;
                            return false;
                        }
                    }
                } else if let Some(slot) = children.get_mut(count) {
                    *slot = (score, x, y);
                    count += 1;
                }
            }
        }
        let children = children.get_mut(..count).unwrap_or(&mut []);
        // Insertion sort by decreasing bound, stable (16 at most).
        for i in 1..children.len() {
            let mut k = i;
            while k > 0 && children.get(k - 1).map(|c| c.0) < children.get(k).map(|c| c.0) {
                children.swap(k - 1, k);
                k -= 1;
            }
        }
        for &(bound, x, y) in children.iter() {
            if bound <= self.threshold() {
                break;
            }
            if !self.expand(j, below, x, y, half) {
                return false;
            }
        }
        true
    }

    /// Mean offset `[x, y, θ]` from the best candidate and covariance from the exact
    /// scores of its neighbours (see the module): ±3 cells and ±2 heading steps, weights
    /// `exp((score − top) / τ)` with `top` the best score among them and τ a tenth of it
    /// (at least 1). Zero when no end point hits there.
    fn spread(
        &mut self,
        points: &[(f32, f32)],
        guess: &Pose2<f32>,
        window: &MatchWindow,
        best: &Candidate,
    ) -> ([f32; 3], [f32; 4]) {
        const CELLS: i32 = 3;
        const STEPS: i32 = 2;
        const SIDE: usize = (2 * CELLS + 1) as usize;
        let mut scores = [0u32; (2 * STEPS + 1) as usize * SIDE * SIDE];
        let mut k = 0;
        for dj in -STEPS..=STEPS {
            let theta = guess.theta + (best.heading + dj) as f32 * window.angle_step;
            self.end_cells(points, guess, theta);
            for dy in -CELLS..=CELLS {
                for dx in -CELLS..=CELLS {
                    let base = self.base;
                    let s = self.score(base, best.dx + dx, best.dy + dy);
                    if let Some(slot) = scores.get_mut(k) {
                        *slot = s;
                    }
                    k += 1;
                }
            }
        }
        let top = scores.iter().copied().max().unwrap_or(0);
        if top == 0 {
            return ([0.0; 3], [0.0; 4]);
        }
        let tau = (top as f32 * 0.1).max(1.0);
        let res = self.geometry.resolution;
        let (mut sw, mut sx, mut sy, mut st) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
        let (mut sxx, mut sxy, mut syy, mut stt) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
        let mut k = 0;
        for dj in -STEPS..=STEPS {
            for dy in -CELLS..=CELLS {
                for dx in -CELLS..=CELLS {
                    let s = scores.get(k).copied().unwrap_or(0);
                    k += 1;
                    let w = libm::expf((s as f32 - top as f32) / tau);
                    let (x, y, t) = (
                        dx as f32 * res,
                        dy as f32 * res,
                        dj as f32 * window.angle_step,
                    );
                    sw += w;
                    sx += w * x;
                    sy += w * y;
                    st += w * t;
                    sxx += w * x * x;
                    sxy += w * x * y;
                    syy += w * y * y;
                    stt += w * t * t;
                }
            }
        }
        let (mx, my, mt) = (sx / sw, sy / sw, st / sw);
        let c = [
            sxx / sw - mx * mx,
            sxy / sw - mx * my,
            syy / sw - my * my,
            stt / sw - mt * mt,
        ];
        if c.iter().all(|v| v.is_finite()) && [mx, my, mt].iter().all(|v| v.is_finite()) {
            ([mx, my, mt], c)
        } else {
            ([0.0; 3], [0.0; 4])
        }
    }
}

#[cfg(test)]
mod tests;
