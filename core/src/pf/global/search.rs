//! The search itself: [`GlobalSearch`], the resumable state machine of the branch and
//! bound (passes, heading windows, the depth-first stack and the node being expanded),
//! and [`search`] / [`search_with_walls`], one run of it to the end of its work budget.

use super::beams::{Selected, prepare};
use super::bound::{Levels, block_free, bound};
use super::hypotheses::below_relative;
use super::node::{Expansion, Node, STACK, sort_decreasing};
use super::plan::{
    MAX_WINDOWS, first_fraction, heading_windows, outside, pass_fraction, pass_fractions, pass_plan,
};
use super::tables::{Dilations, EndCells, dilation, heading_angle};
use super::{GlobalError, GlobalSearchConfig, Hypotheses, Hypothesis, NODE_WORK, SearchReport};
use crate::geometry::Pose2;
use crate::grid::{GridView, MaxPoolLayers};
use crate::pf::correlation::ScanPoint;
use crate::pf::orientation::DirectionHistogram;

/// The global search: the best `N` hypotheses for the scan `points` (robot frame, as
/// [`super::ScanPoints`](crate::pf::ScanPoints) loads them) anywhere in `map`, bounded
/// by `layers` (built from the same map). See the module documentation for the method
/// and its guarantees.
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
/// ([`super::orientation::DirectionHistogram::of_map`](DirectionHistogram::of_map), one
/// pass over the map that [`search`] makes every time when
/// [`GlobalSearchConfig::heading_peaks`] is set).
pub fn search_with_walls<const N: usize>(
    map: &GridView<'_>,
    layers: &MaxPoolLayers<'_>,
    walls: Option<&DirectionHistogram>,
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
        walls: Option<&DirectionHistogram>,
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

/// The robot pose at the centre of cell `(x, y)` facing `theta`.
pub(super) fn pose_at(g: &crate::grid::GridGeometry, x: i32, y: i32, theta: f32) -> Pose2<f32> {
    let (px, py) = g.cell_centre(x, y);
    Pose2::new(px, py, theta)
}
