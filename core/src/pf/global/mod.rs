//! Global localization: where in the whole map was this scan taken? An exact
//! correlative search (Olson 2009, "Real-time correlative scan matching"; Cartographer's
//! fast correlative scan matcher) by branch and bound.
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
//! (29 instructions a unit at 1 beam to 55 at 45, measured), and the work budget
//! ([`GlobalSearchConfig::work_budget`]) bounds a search's instructions however its nodes
//! are pruned. When the budget is spent the search stops (the best found so far is
//! returned, [`SearchReport::complete`] is `false`).
//!
//! **Slices.** [`GlobalSearch`] runs the same search in slices of work, paused
//! and resumed where it stopped (the depth-first stack and the node being expanded are
//! kept): a robot spends a work budget per scan on one search over several scans
//! ([`super::RelocalizationConfig::search_scans`]).
//!
//! No allocation: a search's state (the selected beams and the depth-first stack, ≈ 4.5 KB
//! at [`MAX_SEARCH_BEAMS`]) lives in a [`GlobalSearch`]; a slice adds the end cells and
//! the tabled dilations (≈ 3.5 KB of stack).

mod beams;
mod bound;
mod config;
mod hypotheses;
mod node;
mod report;
mod tables;

pub use beams::heading_step_for;
pub use config::{
    GlobalSearchConfig, MAX_HEADING_PEAKS, MAX_HEADINGS, MAX_SEARCH_BEAMS, NODE_WORK,
};
pub use hypotheses::{Hypotheses, Hypothesis};
pub use report::{GlobalError, SearchReport};

use super::correlation::ScanPoint;
use crate::geometry::Pose2;
use crate::grid::{GridView, MaxPoolLayers};
use beams::{Selected, prepare};
use bound::{Levels, block_free, bound, leaf_score};
use hypotheses::below_relative;
use node::{Expansion, Node, STACK, sort_decreasing};
use tables::{Dilations, EndCells, Rotations, dilation, end_cells, heading_angle};

/// Most heading windows: two headings per peak, each split in two at most where it
/// wraps around.
const MAX_WINDOWS: usize = 4 * MAX_HEADING_PEAKS;
/// A scan whose line-like end points weigh less than this in all (about as many
/// points) searches every heading: its wall directions say too little.
const MIN_SCAN_LINES: f32 = 8.0;

/// The heading windows `(first, last)` (indices into the `headings` candidates of
/// `step`) the search visits, best peak first; their number. One window of every
/// heading when the prior is off or the scan shows too few lines.
fn heading_windows(
    map: &GridView<'_>,
    walls: Option<&super::orientation::DirectionHistogram>,
    points: &[ScanPoint],
    config: &GlobalSearchConfig,
    step: f32,
    headings: u32,
    out: &mut [(u32, u32); MAX_WINDOWS],
) -> usize {
    use super::orientation::{BINS, DirectionHistogram, correlate, peaks};
    let last = headings.saturating_sub(1);
    let every = |out: &mut [(u32, u32); MAX_WINDOWS]| {
        if let Some(w) = out.first_mut() {
            *w = (0, last);
        }
        1
    };
    if config.heading_peaks == 0 {
        return every(out);
    }
    let scan = DirectionHistogram::of_scan(points);
    if scan.total.is_nan() || scan.total < MIN_SCAN_LINES {
        return every(out);
    }
    let computed;
    let walls = match walls {
        Some(w) => w,
        None => {
            computed = DirectionHistogram::of_map(map);
            &computed
        }
    };
    if walls.total.is_nan() || walls.total <= 0.0 {
        return every(out);
    }
    let c = correlate(&scan, walls);
    let bin = core::f32::consts::PI / BINS as f32;
    let separation = (libm::ceilf(2.0 * config.heading_window / bin) as usize).clamp(3, BINS / 4);
    let (found, n) = peaks::<MAX_HEADING_PEAKS>(&c, separation);
    let n = n.min(usize::from(config.heading_peaks));
    let count = headings as f32;
    let half = config.heading_window / step;
    if half.is_nan() || 2.0 * half + 1.0 >= count {
        return every(out);
    }
    let mut len = 0;
    let mut push = |lo: u32, hi: u32| {
        if let Some(slot) = out.get_mut(len) {
            *slot = (lo, hi);
            len += 1;
        }
    };
    for &(b, _) in found.iter().take(n) {
        for turn in [0.0, core::f32::consts::PI] {
            let centre = (b as f32 * bin + turn) / step;
            let lo = libm::floorf(centre - half) as i64;
            let hi = libm::ceilf(centre + half) as i64;
            let n = i64::from(headings);
            let clamp = |v: i64| v.clamp(0, n - 1) as u32;
            if lo < 0 {
                push(clamp(lo + n), last);
                push(0, clamp(hi));
            } else if hi >= n {
                push(clamp(lo), last);
                push(0, clamp(hi - n));
            } else {
                push(clamp(lo), clamp(hi));
            }
        }
    }
    if len == 0 {
        return every(out);
    }
    len
}

/// The global search: the best `N` hypotheses for the scan `points` (robot frame, as
/// [`super::ScanPoints`] loads them) anywhere in `map`, bounded by `layers` (built from
/// the same map). See the module documentation for the method and its guarantees.
pub fn search<const N: usize>(
    map: &GridView<'_>,
    layers: &MaxPoolLayers<'_>,
    points: &[ScanPoint],
    config: &GlobalSearchConfig,
    out: &mut Hypotheses<N>,
) -> Result<SearchReport, GlobalError> {
    search_with_walls(map, layers, None, points, config, out)
}

/// [`search`] with the map's wall directions computed beforehand
/// ([`super::orientation::DirectionHistogram::of_map`], one pass over the map that
/// [`search`] makes every time when [`GlobalSearchConfig::heading_peaks`] is set).
pub fn search_with_walls<const N: usize>(
    map: &GridView<'_>,
    layers: &MaxPoolLayers<'_>,
    walls: Option<&super::orientation::DirectionHistogram>,
    points: &[ScanPoint],
    config: &GlobalSearchConfig,
    out: &mut Hypotheses<N>,
) -> Result<SearchReport, GlobalError> {
    let mut run = GlobalSearch::<N>::start(map, layers, walls, points, config)?;
    run.resume(map, layers, config.work_budget)?;
    run.conclude();
    *out = run.hypotheses;
    Ok(run.report)
}

/// What one slice of the search reads and does not keep: the occupied levels, the
/// tabled dilations and the end cells of the heading last computed (rebuilt per slice).
struct Slice<'a> {
    levels: Levels<'a>,
    dilations: Dilations,
    end: EndCells,
}

/// A global search that runs in slices of node evaluations: the search of
/// [`search_with_walls`], paused when a slice's nodes are spent and resumed where it
/// stopped. A robot that cannot spend a whole search on one scan (a microcontroller
/// between two scans) runs a slice per scan; the hypotheses are poses of the robot when
/// the search's scan was taken. Split in any way, the slices visit the same nodes in the
/// same order as one run with their sum as its [`GlobalSearchConfig::work_budget`], and
/// find the same hypotheses.
///
/// About 5.6 KB (the selected beams and the depth-first stack); a slice adds about
/// 3.5 KB of stack. Every slice must be given the map and layers the search started on.
#[derive(Clone)]
pub struct GlobalSearch<const N: usize> {
    config: GlobalSearchConfig,
    sel: Selected,
    step: f32,
    headings: u32,
    width: i32,
    height: i32,
    /// Farthest selected beam, cells.
    rho_max: f32,
    /// The heading windows around the wall-direction peaks (one window of every heading
    /// when there are none).
    peaks: [(u32, u32); MAX_WINDOWS],
    n_peaks: usize,
    /// The heading intervals of the pass under way: the windows, or every heading
    /// outside them (at most one more interval than windows).
    windows: [(u32, u32); MAX_WINDOWS + 1],
    n_windows: usize,
    /// Position of the pass under way in [`pass_plan`].
    pass_index: u8,
    /// The lowest minimum score each heading set (windows, the rest of the turn) has
    /// been searched at (`u32::MAX`: not yet).
    searched_at: [u32; 2],
    /// A pass found a hypothesis (below `full_turn_below`: the search goes on only for
    /// a better one outside the windows).
    found: bool,
    /// The pass's minimum score as a fraction of the total weight.
    fraction: f32,
    /// The pass's minimum score.
    pass_min: u32,
    /// Pruning threshold: a node must bound above it.
    thr: u32,
    /// The best score when the pass started: only a better hypothesis counts as found.
    beaten: u32,
    /// Cursor: the heading window and the next top-level block of the pass.
    window: usize,
    rx: i32,
    ry: i32,
    stack: [Node; STACK],
    sp: usize,
    pending: Option<Expansion>,
    /// Work granted by the slices so far (their sum).
    granted: u32,
    hypotheses: Hypotheses<N>,
    report: SearchReport,
    done: bool,
}

impl<const N: usize> GlobalSearch<N> {
    /// Prepares a search for the scan `points` (robot frame) in `map` bounded by
    /// `layers` (made from it), with the map's wall directions when known (see
    /// [`search_with_walls`]). Nothing is searched yet: see [`GlobalSearch::resume`].
    pub fn start(
        map: &GridView<'_>,
        layers: &MaxPoolLayers<'_>,
        walls: Option<&super::orientation::DirectionHistogram>,
        points: &[ScanPoint],
        config: &GlobalSearchConfig,
    ) -> Result<Self, GlobalError> {
        let (sel, step, headings) = prepare(map, layers, points, config)?;
        let min_score = libm::ceilf(config.min_score_fraction * sel.total as f32) as u32;
        let mut report = SearchReport {
            beams: sel.len as u16,
            extent_m: sel.extent,
            heading_step: step,
            headings,
            heading_windows: 1,
            headings_searched: headings,
            nodes: 0,
            work: 0,
            leaves: 0,
            rotations: 0,
            nodes_per_level: [0; crate::grid::layers::MAX_LEVELS as usize + 1],
            total_weight: sel.total,
            min_score,
            passes: 0,
            full_turn: false,
            // Until the search is over.
            complete: false,
        };
        let rho_max = sel
            .rho_cells
            .iter()
            .take(sel.len)
            .copied()
            .fold(0.0f32, f32::max);
        let mut peaks = [(0u32, 0u32); MAX_WINDOWS];
        let n_peaks = heading_windows(map, walls, points, config, step, headings, &mut peaks);
        report.heading_windows = n_peaks as u8;
        report.headings_searched = peaks.iter().take(n_peaks).map(|(lo, hi)| hi - lo + 1).sum();
        let g = map.geometry();
        let mut run = Self {
            config: *config,
            sel,
            step,
            headings,
            width: g.width as i32,
            height: g.height as i32,
            rho_max,
            peaks,
            n_peaks,
            windows: [(0, 0); MAX_WINDOWS + 1],
            n_windows: 0,
            pass_index: 0,
            searched_at: [u32::MAX; 2],
            found: false,
            fraction: first_fraction(config),
            pass_min: 0,
            thr: 0,
            beaten: 0,
            window: 0,
            rx: 0,
            ry: 0,
            stack: [Node::default(); STACK],
            sp: 0,
            pending: None,
            granted: 0,
            hypotheses: Hypotheses::new(),
            report,
            done: false,
        };
        run.select_headings(false);
        run.start_pass();
        if let Some(m) = run.searched_at.first_mut() {
            *m = run.pass_min;
        }
        Ok(run)
    }

    /// Runs the search for `work` more units of [`GlobalSearchConfig::work_budget`];
    /// `Ok(true)` when it is over (then
    /// [`GlobalSearchReport::complete`](SearchReport::complete) holds unless
    /// [`GlobalSearch::conclude`] stopped it before), `Ok(false)` when the work granted
    /// is spent. The work granted adds up over the slices: a node evaluation started at
    /// the end of one slice (it may overrun by up to one node's work) is paid for by the
    /// next. Refused when `layers` do not belong to `map` or `map` is not the size
    /// of the one the search started on.
    pub fn resume(
        &mut self,
        map: &GridView<'_>,
        layers: &MaxPoolLayers<'_>,
        work: u32,
    ) -> Result<bool, GlobalError> {
        if self.done {
            return Ok(true);
        }
        let g = *map.geometry();
        if !layers.matches(map) || g.width as i32 != self.width || g.height as i32 != self.height {
            return Err(GlobalError::LayersMismatch);
        }
        self.granted = self.granted.saturating_add(work);
        let limit = self.granted;
        let top = layers.levels();
        let mut slice = Slice {
            levels: Levels::new(layers),
            dilations: Dilations::new(&self.sel, self.step),
            end: EndCells::new(self.step),
        };
        loop {
            if let Some(mut e) = self.pending.take() {
                if !self.evaluate(map, &mut slice, &mut e, limit) {
                    self.pending = Some(e);
                    return Ok(false);
                }
                self.push_kept(&mut e);
            }
            while self.sp > 0 {
                self.sp -= 1;
                let Some(node) = self.stack.get(self.sp).copied() else {
                    break;
                };
                if node.bound <= self.thr {
                    continue;
                }
                if node.a == 0 && node.k == 0 {
                    self.hypotheses.offer(
                        Hypothesis {
                            pose: pose_at(&g, node.x, node.y, heading_angle(node.j0, self.step)),
                            score: node.bound,
                        },
                        self.config.separation_m,
                        self.config.separation_rad,
                    );
                    self.thr = self.threshold();
                    continue;
                }
                let mut e = self.children(map, layers, &node);
                if !self.evaluate(map, &mut slice, &mut e, limit) {
                    self.pending = Some(e);
                    return Ok(false);
                }
                self.push_kept(&mut e);
            }
            if !self.next_root(map, layers, top) {
                self.finish(true);
                return Ok(true);
            }
        }
    }

    /// Stops the search where it is (when not over): the hypotheses are then the best
    /// found so far and [`SearchReport::complete`] is `false`.
    pub fn conclude(&mut self) {
        if !self.done {
            self.finish(false);
        }
    }

    /// `true` when the search is over (finished or concluded).
    pub fn is_done(&self) -> bool {
        self.done
    }

    /// What the search did so far ([`SearchReport::complete`] is `false` until it is
    /// over).
    pub fn report(&self) -> &SearchReport {
        &self.report
    }

    /// The hypotheses, best first: final once the search is over, the best found so far
    /// before (not yet filtered by [`GlobalSearchConfig::relative_score`]).
    pub fn hypotheses(&self) -> &Hypotheses<N> {
        &self.hypotheses
    }

    /// The pruning threshold: the pass's minimum score, the best score × the relative
    /// score, and the `N`-th best when `N` hypotheses are held.
    fn threshold(&self) -> u32 {
        below_relative(&self.config, self.hypotheses.best())
            .max(self.pass_min.saturating_sub(1))
            .max(self.hypotheses.floor())
    }

    /// Starts a pass at the current minimum-score fraction over the current heading set,
    /// from its first window's first block.
    fn start_pass(&mut self) {
        // Nothing at or below the best held is looked for.
        self.pass_min = (libm::ceilf(self.fraction * self.sel.total as f32) as u32)
            .max(self.beaten.saturating_add(1));
        self.report.min_score = if self.report.passes == 0 {
            self.pass_min
        } else {
            self.report.min_score.min(self.pass_min)
        };
        self.report.passes = self.report.passes.saturating_add(1);
        self.thr = self.threshold();
        self.window = 0;
        self.rx = 0;
        self.ry = 0;
    }

    /// Makes the heading windows (`rest` false) or every heading outside them the
    /// intervals the next pass searches.
    fn select_headings(&mut self, rest: bool) {
        if rest {
            self.n_windows = outside(&self.peaks, self.n_peaks, self.headings, &mut self.windows);
            self.report.full_turn = true;
            self.report.headings_searched = self.headings;
        } else {
            for (w, p) in self.windows.iter_mut().zip(self.peaks.iter()) {
                *w = *p;
            }
            self.n_windows = self.n_peaks;
        }
    }

    /// `true` when the rest of the turn is searched too: there are heading windows and
    /// [`GlobalSearchConfig::full_turn_below`] is set.
    fn full_turn_allowed(&self) -> bool {
        self.n_peaks > 1 && self.config.full_turn_below > 0.0
    }

    /// After a pass: the next one of [`pass_plan`] that can find something new, or
    /// `false` when the search is over — when a pass found a hypothesis scoring
    /// [`GlobalSearchConfig::full_turn_below`] (any hypothesis, without the full turn), or
    /// the plan is done.
    fn next_pass(&mut self) -> bool {
        let c = self.config;
        let best = self.hypotheses.best().map_or(0, |b| b.score);
        let good = libm::ceilf(c.full_turn_below * self.sel.total as f32) as u32;
        let full_turn = self.full_turn_allowed();
        if best > self.beaten {
            if !full_turn || best >= good {
                return false;
            }
            self.found = true;
        }
        self.beaten = best;
        let fractions = pass_fractions(&c);
        loop {
            self.pass_index = self.pass_index.saturating_add(1);
            let Some((rest, i)) = pass_plan(usize::from(self.pass_index), fractions, full_turn)
            else {
                return false;
            };
            // The windows searched down to a hypothesis hold no better one.
            if !rest && self.found {
                continue;
            }
            let fraction = pass_fraction(&c, i, fractions);
            let pass_min =
                (libm::ceilf(fraction * self.sel.total as f32) as u32).max(best.saturating_add(1));
            let set = usize::from(rest);
            if self.searched_at.get(set).is_some_and(|&m| pass_min >= m) {
                continue;
            }
            if let Some(m) = self.searched_at.get_mut(set) {
                *m = pass_min;
            }
            self.select_headings(rest);
            self.fraction = fraction;
            self.start_pass();
            return true;
        }
    }

    /// Moves the cursor to the next top-level block with a free cell (in row order, then
    /// the next window, then the next pass) and pushes its roots: every aligned heading
    /// interval covering the window, the first visited first. `false` when the search is
    /// over.
    fn next_root(&mut self, map: &GridView<'_>, layers: &MaxPoolLayers<'_>, top: u8) -> bool {
        let size = 1i32 << top;
        // All headings in one interval of 2^all at the root.
        let all = (32 - self.headings.saturating_sub(1).leading_zeros()) as u8;
        if self.width <= 0 || self.height <= 0 {
            return false;
        }
        loop {
            let Some(&(lo, hi)) = self
                .windows
                .get(..self.n_windows)
                .and_then(|w| w.get(self.window))
            else {
                if !self.next_pass() {
                    return false;
                }
                continue;
            };
            if self.ry >= self.height {
                self.window += 1;
                self.rx = 0;
                self.ry = 0;
                continue;
            }
            let (bx, by) = (self.rx, self.ry);
            self.rx += size;
            if self.rx >= self.width {
                self.rx = 0;
                self.ry += size;
            }
            if !block_free(map, layers, top, bx, by) {
                continue;
            }
            // The aligned heading intervals of 2^a0 that cover the window (at most two).
            let a0 = (32 - (hi - lo).leading_zeros()).min(u32::from(all)) as u8;
            let mut sp = 0usize;
            let mut j0 = (lo >> a0) << a0;
            while j0 <= hi && j0 < self.headings {
                if let Some(slot) = self.stack.get_mut(sp) {
                    *slot = Node {
                        x: bx,
                        y: by,
                        j0,
                        bound: self.sel.total,
                        a: a0,
                        k: top,
                    };
                    sp += 1;
                }
                j0 += 1 << a0;
            }
            // The first interval is visited first.
            self.stack.get_mut(..sp).unwrap_or(&mut []).reverse();
            self.sp = sp;
            return true;
        }
    }

    /// The children of `node`: its two heading halves while their spread moves the far
    /// beams' ends by more than half the block, else its four sub-blocks with a free cell.
    fn children(&self, map: &GridView<'_>, layers: &MaxPoolLayers<'_>, node: &Node) -> Expansion {
        let mut e = Expansion::default();
        let split_heading = node.a > 0
            && (node.k == 0
                || 2 * dilation(self.rho_max, (1u32 << (node.a - 1)) as f32 * self.step)
                    >= 1 << node.k);
        let mut n = 0;
        if split_heading {
            // The window the node was pushed for (the cursor leaves it only once the
            // stack is empty).
            let (lo, hi) = self.windows.get(self.window).copied().unwrap_or((0, 0));
            let a = node.a - 1;
            for j0 in [node.j0, node.j0 + (1 << a)] {
                if j0 >= self.headings || j0 > hi || j0 + (1 << a) <= lo {
                    continue;
                }
                if let Some(c) = e.children.get_mut(n) {
                    *c = Node { j0, a, ..*node };
                    n += 1;
                }
            }
        } else {
            let k = node.k - 1;
            let half = 1i32 << k;
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let (x, y) = (node.x + dx * half, node.y + dy * half);
                if x >= self.width || y >= self.height || !block_free(map, layers, k, x, y) {
                    continue;
                }
                if let Some(c) = e.children.get_mut(n) {
                    *c = Node { x, y, k, ..*node };
                    n += 1;
                }
            }
        }
        e.made = n as u8;
        e
    }

    /// Evaluates the children of `e` not evaluated yet, keeping those whose bound is
    /// above the threshold; `false` when the work granted so far ran out first (`limit`,
    /// a total over the search).
    fn evaluate(
        &mut self,
        map: &GridView<'_>,
        slice: &mut Slice<'_>,
        e: &mut Expansion,
        limit: u32,
    ) -> bool {
        while e.evaluated < e.made {
            let Some(mut c) = e.children.get(usize::from(e.evaluated)).copied() else {
                break;
            };
            if self.report.work >= limit {
                return false;
            }
            self.report.nodes += 1;
            if let Some(count) = self.report.nodes_per_level.get_mut(usize::from(c.k)) {
                *count += 1;
            }
            if c.a == 0 && c.k == 0 {
                self.report.leaves += 1;
            }
            let cells = slice.end.at(&self.sel, c.reference(), &mut self.report);
            let looked;
            (c.bound, looked) = bound(
                map,
                &slice.levels,
                &slice.dilations,
                cells,
                self.sel.total,
                self.thr,
                c.a,
                c.k,
                c.x,
                c.y,
            );
            self.report.work = self
                .report
                .work
                .saturating_add(looked)
                .saturating_add(NODE_WORK);
            if c.bound > self.thr
                && let Some(slot) = e.children.get_mut(usize::from(e.kept))
            {
                *slot = c;
                e.kept += 1;
            }
            e.evaluated += 1;
        }
        true
    }

    /// Pushes the kept children, best bound on top (equal bounds in child order).
    fn push_kept(&mut self, e: &mut Expansion) {
        let kids = e.children.get_mut(..usize::from(e.kept)).unwrap_or(&mut []);
        sort_decreasing(kids);
        for kid in kids.iter().rev() {
            if let Some(slot) = self.stack.get_mut(self.sp) {
                *slot = *kid;
                self.sp += 1;
            }
        }
    }

    /// The search is over: the hypotheses of every pass stay and compete; those below
    /// the relative score or the lowest pass minimum go.
    fn finish(&mut self, complete: bool) {
        self.report.complete = complete;
        let keep = below_relative(&self.config, self.hypotheses.best())
            .max(self.report.min_score.saturating_sub(1));
        self.hypotheses.keep_above(keep);
        self.done = true;
    }
}

/// Most minimum scores a search steps through (the last one is the configured minimum).
const MAX_PASS_FRACTIONS: usize = 64;

/// The first pass's minimum score (fraction of the total weight): never below the
/// configured minimum.
fn first_fraction(c: &GlobalSearchConfig) -> f32 {
    c.first_pass_fraction.max(c.min_score_fraction)
}

/// How many minimum scores the passes step through: the first pass's, then one
/// [`GlobalSearchConfig::pass_step`] lower each, down to the minimum.
fn pass_fractions(c: &GlobalSearchConfig) -> usize {
    let first = first_fraction(c);
    let mut n = 1;
    while n < MAX_PASS_FRACTIONS && first - n as f32 * c.pass_step > c.min_score_fraction + 1e-6 {
        n += 1;
    }
    // One more at the minimum itself, unless the first pass is already there.
    if first > c.min_score_fraction + 1e-6 {
        n += 1;
    }
    n.min(MAX_PASS_FRACTIONS)
}

/// The minimum score (fraction of the total weight) of the `i`-th of `n` steps.
fn pass_fraction(c: &GlobalSearchConfig, i: usize, n: usize) -> f32 {
    let first = first_fraction(c);
    if i + 1 >= n {
        return c.min_score_fraction.min(first);
    }
    (first - i as f32 * c.pass_step).max(c.min_score_fraction)
}

/// The `p`-th pass of a search over `n` minimum scores: `(rest, i)`, the heading set
/// (`false`: the windows; `true`: every heading outside them) and the minimum score's
/// step. Without the full turn the windows alone, at each step in turn. With it, the
/// rest of the turn follows the windows one step behind: windows 0, windows 1, rest 0,
/// windows 2, rest 1, …, rest n − 1. A pass at a high minimum prunes hard even over
/// the whole turn, one at a low minimum prunes little even in the windows: the whole
/// turn at the first minimum costs about what the windows cost two steps lower, and a
/// robot whose wall directions the windows miss is found without them first being
/// searched down to the lowest minimum (`docs/global-localization.md`).
fn pass_plan(p: usize, n: usize, full_turn: bool) -> Option<(bool, usize)> {
    if !full_turn {
        return (p < n).then_some((false, p));
    }
    let mut k = 0;
    for t in 0..=n {
        if t < n {
            if k == p {
                return Some((false, t));
            }
            k += 1;
        }
        if t >= 1 {
            if k == p {
                return Some((true, t - 1));
            }
            k += 1;
        }
    }
    None
}

/// Writes into `out` the heading intervals outside the `n` windows `windows` (of
/// `headings` in all); returns how many.
fn outside(
    windows: &[(u32, u32); MAX_WINDOWS],
    n: usize,
    headings: u32,
    out: &mut [(u32, u32); MAX_WINDOWS + 1],
) -> usize {
    let mut sorted = *windows;
    let sorted = sorted.get_mut(..n).unwrap_or(&mut []);
    // Insertion sort by start: a few windows (and no sort routine in the firmware's flash).
    for i in 1..sorted.len() {
        let mut j = i;
        while j > 0 && sorted.get(j - 1).map(|w| w.0) > sorted.get(j).map(|w| w.0) {
            sorted.swap(j - 1, j);
            j -= 1;
        }
    }
    let mut k = 0;
    let mut next = 0u32;
    for &(lo, hi) in sorted.iter() {
        if lo > next
            && let Some(slot) = out.get_mut(k)
        {
            *slot = (next, lo - 1);
            k += 1;
        }
        next = next.max(hi.saturating_add(1));
    }
    if next < headings
        && let Some(slot) = out.get_mut(k)
    {
        *slot = (next, headings - 1);
        k += 1;
    }
    k
}

/// The robot pose at the centre of cell `(x, y)` facing `theta`.
fn pose_at(g: &crate::grid::GridGeometry, x: i32, y: i32, theta: f32) -> Pose2<f32> {
    let (px, py) = g.cell_centre(x, y);
    Pose2::new(px, py, theta)
}

/// The brute-force reference of [`search`]: every heading, every free cell, every beam
/// (no bounds, no budget). Same candidates and scores; for tests on small maps.
pub fn search_brute_force<const N: usize>(
    map: &GridView<'_>,
    layers: &MaxPoolLayers<'_>,
    points: &[ScanPoint],
    config: &GlobalSearchConfig,
    out: &mut Hypotheses<N>,
) -> Result<SearchReport, GlobalError> {
    let (sel, step, headings) = prepare(map, layers, points, config)?;
    out.clear();
    let min_score = libm::ceilf(config.min_score_fraction * sel.total as f32) as u32;
    let g = *map.geometry();
    let mut cells = [(0i32, 0i32, 0u32); MAX_SEARCH_BEAMS];
    let mut nodes = 0u32;
    let rotations = Rotations::new(step);
    for j in 0..headings {
        let theta = heading_angle(j, step);
        end_cells(&sel, rotations.at(j), &mut cells);
        let cells = cells.get(..sel.len).unwrap_or(&[]);
        for y in 0..g.height as i32 {
            for x in 0..g.width as i32 {
                if !block_free(map, layers, 0, x, y) {
                    continue;
                }
                nodes = nodes.saturating_add(1);
                let s = leaf_score(map, cells, x, y);
                if s >= min_score.max(1) {
                    out.offer(
                        Hypothesis {
                            pose: pose_at(&g, x, y, theta),
                            score: s,
                        },
                        config.separation_m,
                        config.separation_rad,
                    );
                }
            }
        }
    }
    out.keep_above(below_relative(config, out.best()).max(min_score.saturating_sub(1)));
    Ok(SearchReport {
        beams: sel.len as u16,
        extent_m: sel.extent,
        heading_step: step,
        headings,
        heading_windows: 1,
        headings_searched: headings,
        nodes,
        // Every beam of every leaf.
        work: nodes.saturating_mul(sel.len as u32 + NODE_WORK),
        leaves: nodes,
        rotations: headings,
        nodes_per_level: [nodes, 0, 0, 0, 0, 0, 0, 0, 0],
        total_weight: sel.total,
        min_score,
        passes: 1,
        full_turn: false,
        complete: true,
    })
}

#[cfg(test)]
mod tests;
