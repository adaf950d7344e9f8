//! Loop closure for grid SLAM on the host: keyframes, a pose graph, and a correlative
//! match of each new keyframe against the map the robot built near it long before.
//!
//! [`microslam::pf::GridSlam`] keeps one shared map. When the robot comes back to a
//! place it mapped long ago, the drift of the loop lies between the old map and the new
//! scans, and the filter's small shift search (±4 cells, no heading) cannot take it up:
//! on the Intel log the default settings lose the map there on 3 of 12 filter seeds
//! (`docs/results-grid.md`). Here:
//!
//! 1. **Keyframes.** A scan becomes a keyframe when the filter's estimate has moved
//!    [`LoopClosureConfig::keyframe_distance_m`] or turned
//!    [`LoopClosureConfig::keyframe_turn_rad`] since the last one; consecutive keyframes
//!    are joined by an edge holding the relative pose the filter estimated. Every scan
//!    keeps its pose relative to the keyframe before it.
//! 2. **Match.** At a new keyframe, the nearest keyframe at least
//!    [`LoopClosureConfig::min_age_keyframes`] older within
//!    [`LoopClosureConfig::search_radius_m`] starts a match: the end points of the scans
//!    of every keyframe that old within [`LoopClosureConfig::submap_radius_m`] (the old
//!    map, untouched by the recent drift) make a score map (2 on an end point's cell, 1 on
//!    its neighbours), and the new scan is scored at every position and heading of a
//!    window around its graph pose (brute force; Olson 2009, "Real-time correlative scan
//!    matching"). The best pose, when it scores at least
//!    [`LoopClosureConfig::min_score_fraction`] of the most the scan can score, is a loop
//!    edge whose covariance is the spread of all candidates weighted by
//!    `exp((score − best) / τ)`: long along a corridor, short across it, so that an
//!    ambiguous direction does not pull.
//! 3. **Graph.** Solved in two linear least-squares steps (Carlone et al. 2014, LAGO):
//!    the headings first, then the positions with the edges rotated by those headings,
//!    each by conjugate gradients on the graph's Laplacian, the first keyframe held.
//! 4. **Correction.** When the graph moves the newest keyframe away from the filter's
//!    estimate by at least [`MIN_CORRECTION_M`] or [`MIN_CORRECTION_RAD`], the map is
//!    rebuilt from every scan at its new pose and the particles are moved by the newest
//!    keyframe's correction; a smaller difference stays in the graph.
//!
//! At the end, every scan's pose is its keyframe's final pose composed with its offset:
//! the trajectory the whole run supports ([`LoopCloser::trajectory`]), not the one the
//! filter believed at each scan. Everything here allocates and runs on the host only;
//! the firmware's grid SLAM does not close loops.

use crate::domain::grid::LoopClosureConfig;
use microslam::geometry::{Pose2, wrap_angle};
use microslam::sensors::lidar::LidarGeometry;
use rayon::prelude::*;

/// A closure that moves the newest keyframe less than this from the filter's estimate
/// (m) …
pub const MIN_CORRECTION_M: f64 = 0.02;
/// … and turns it less than this (rad) leaves the filter as it is: the graph keeps the
/// difference, and the scans' final poses take it.
pub const MIN_CORRECTION_RAD: f64 = 0.003;
/// Cell size of the match's score map, m.
const MATCH_CELL_M: f64 = 0.05;
/// Farthest end point used for matching, m.
const MATCH_MAX_RANGE_M: f64 = 30.0;

/// A keyframe (a scan, whose end points [`LoopCloser`] keeps beside it): its pose in the
/// graph, and the filter's estimate of it.
#[derive(Clone, Copy, Debug)]
struct Keyframe {
    /// Its pose in the graph (optimised).
    pose: Pose2<f64>,
    /// The filter's estimate of it, in the filter's frame: what the edge to the next
    /// keyframe and the offsets of the scans after it are measured from.
    estimate: Pose2<f64>,
}

/// A relative-pose constraint `z = ⊖x_i ⊕ x_j` with the weights of its residuals.
#[derive(Clone, Copy, Debug)]
struct Edge {
    i: usize,
    j: usize,
    z: Pose2<f64>,
    /// Weight (inverse covariance) of the position residual, world frame.
    w_t: [[f64; 2]; 2],
    /// Weight of the heading residual.
    w_r: f64,
}

/// What the loop closure did over a run (in `metrics.json`).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct LoopClosureSummary {
    /// Keyframes made.
    pub keyframes: usize,
    /// Matches tried (a new keyframe near an old one).
    pub attempts: usize,
    /// Loop edges added (matches accepted).
    pub closures: usize,
    /// Closures that moved the filter (map rebuilt, particles moved).
    pub corrections: usize,
    /// Largest distance between the newest keyframe's graph pose and the filter's
    /// estimate after a closure, m.
    pub largest_correction_m: f64,
}

/// What the filter has to do after a closure ([`LoopCloser::add_scan`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Correction {
    /// The rigid motion of the world frame that takes the filter's estimate to the
    /// graph's (`correction ⊕ estimate`), for the particles.
    pub correction: Pose2<f32>,
    /// Every scan so far (index into the inputs) with its new pose, to rebuild the map.
    pub scans: Vec<(usize, Pose2<f32>)>,
}

/// The loop closure's state over a run: keyframes, edges, and every scan's offset.
pub struct LoopCloser {
    config: LoopClosureConfig,
    lidar: LidarGeometry,
    keyframes: Vec<Keyframe>,
    /// Per keyframe: its scan's robot-frame end points ([`LoopCloser::points`]), made
    /// once instead of at every match that reads it.
    keyframe_points: Vec<Vec<[f64; 2]>>,
    edges: Vec<Edge>,
    /// Per scan: its keyframe and its pose relative to the keyframe's estimate.
    offsets: Vec<(usize, Pose2<f64>)>,
    summary: LoopClosureSummary,
}

impl LoopCloser {
    /// A loop closure for scans of `lidar`.
    pub fn new(config: LoopClosureConfig, lidar: LidarGeometry) -> Self {
        Self {
            config,
            lidar,
            keyframes: Vec::new(),
            keyframe_points: Vec::new(),
            edges: Vec::new(),
            offsets: Vec::new(),
            summary: LoopClosureSummary::default(),
        }
    }

    /// What it did so far.
    pub fn summary(&self) -> LoopClosureSummary {
        LoopClosureSummary {
            keyframes: self.keyframes.len(),
            ..self.summary
        }
    }

    /// Takes scan `index` of `scans` (every scan's ranges, in the lidar's beam order)
    /// with the filter's estimate `pose` after it (scans in order, each once); returns
    /// what the filter has to do when a loop was closed.
    pub fn add_scan(
        &mut self,
        index: usize,
        pose: Pose2<f32>,
        scans: &[&[f32]],
    ) -> Option<Correction> {
        let pose = widen(&pose);
        let c = self.config;
        let Some(last) = self.keyframes.last().copied() else {
            self.keyframes.push(Keyframe {
                pose,
                estimate: pose,
            });
            self.keyframe_points.push(self.scan_points(scans, index));
            self.offsets.push((0, Pose2::IDENTITY));
            return None;
        };
        let motion = last.estimate.between(&pose);
        let driven = motion.x.hypot(motion.y);
        if driven < c.keyframe_distance_m && motion.theta.abs() < c.keyframe_turn_rad {
            self.offsets.push((self.keyframes.len() - 1, motion));
            return None;
        }
        let st = c.sequential_std_m + c.sequential_std_per_m * driven;
        let k = self.keyframes.len();
        self.edges.push(Edge {
            i: k - 1,
            j: k,
            z: motion,
            w_t: isotropic(st),
            w_r: (c.sequential_heading_std * c.sequential_heading_std).recip(),
        });
        // Its graph pose: the last keyframe's composed with the filter's motion since (the
        // filter's frame and the graph's differ by what was not corrected).
        self.keyframes.push(Keyframe {
            pose: last.pose.compose(&motion),
            estimate: pose,
        });
        self.keyframe_points.push(self.scan_points(scans, index));
        self.offsets.push((k, Pose2::IDENTITY));
        let old = self.candidate(k)?;
        self.summary.attempts += 1;
        let m = self.match_keyframe(k)?;
        self.edges.push(Edge {
            i: old,
            j: k,
            z: self.keyframes[old].pose.between(&m.pose),
            w_t: m.position_weight,
            w_r: (m.heading_variance + c.loop_heading_std * c.loop_heading_std).recip(),
        });
        self.summary.closures += 1;
        self.optimise();
        let before = self.keyframes[k].estimate;
        let after = self.keyframes[k].pose;
        let moved = (after.x - before.x).hypot(after.y - before.y);
        self.summary.largest_correction_m = self.summary.largest_correction_m.max(moved);
        // correction ⊕ before = after.
        let correction = after.compose(&before.inverse());
        if moved < MIN_CORRECTION_M && correction.theta.abs() < MIN_CORRECTION_RAD {
            return None;
        }
        self.summary.corrections += 1;
        self.keyframes[k].estimate = after;
        Some(Correction {
            correction: narrow(&correction),
            scans: self.trajectory().into_iter().enumerate().collect(),
        })
    }

    /// The pose of every scan taken so far: its keyframe's graph pose ⊕ its offset.
    pub fn trajectory(&self) -> Vec<Pose2<f32>> {
        self.offsets
            .iter()
            .map(|(k, offset)| {
                let kf = self.keyframes.get(*k).map_or(Pose2::IDENTITY, |kf| kf.pose);
                narrow(&kf.compose(offset))
            })
            .collect()
    }

    /// The nearest keyframe old enough to close a loop with keyframe `k`.
    fn candidate(&self, k: usize) -> Option<usize> {
        let c = self.config;
        let newest = k.checked_sub(c.min_age_keyframes)?;
        let p = self.keyframes[k].pose;
        self.keyframes[..=newest]
            .iter()
            .enumerate()
            .map(|(j, q)| (j, (q.pose.x - p.x).hypot(q.pose.y - p.y)))
            .filter(|&(_, d)| d <= c.search_radius_m)
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(j, _)| j)
    }

    /// [`LoopCloser::points`] of scan `index` of `scans` (none when there is no such scan).
    fn scan_points(&self, scans: &[&[f32]], index: usize) -> Vec<[f64; 2]> {
        scans.get(index).map_or_else(Vec::new, |r| self.points(r))
    }

    /// Robot-frame end points of a scan: every `beam_stride`-th beam with a return
    /// closer than [`MATCH_MAX_RANGE_M`].
    fn points(&self, ranges: &[f32]) -> Vec<[f64; 2]> {
        let g = &self.lidar;
        let mount = widen(&g.mount);
        ranges
            .iter()
            .enumerate()
            .step_by(self.config.beam_stride.max(1))
            .filter(|(_, r)| {
                r.is_finite()
                    && **r >= g.min_range
                    && **r < g.max_range
                    && f64::from(**r) <= MATCH_MAX_RANGE_M
            })
            .map(|(i, &r)| {
                let a = f64::from(g.first_angle + i as f32 * g.angle_increment);
                let (s, c) = a.sin_cos();
                let p = mount
                    .transform_point(&nalgebra::Vector2::new(f64::from(r) * c, f64::from(r) * s));
                [p[0], p[1]]
            })
            .collect()
    }

    /// Matches keyframe `k`'s scan against the old map around its graph pose.
    fn match_keyframe(&self, k: usize) -> Option<Match> {
        let c = self.config;
        let pose = self.keyframes[k].pose;
        let points = self.keyframe_points.get(k)?;
        if points.len() < 10 {
            return None;
        }
        let newest_old = k.checked_sub(c.min_age_keyframes)?;
        let reach = MATCH_MAX_RANGE_M + c.window_m + MATCH_CELL_M;
        let mut map = ScoreMap::new([pose.x - reach, pose.y - reach], 2.0 * reach);
        for (kf, kf_points) in self.keyframes[..=newest_old]
            .iter()
            .zip(&self.keyframe_points)
        {
            if (kf.pose.x - pose.x).hypot(kf.pose.y - pose.y) > c.submap_radius_m {
                continue;
            }
            for p in kf_points {
                map.mark(kf.pose.transform_point(&nalgebra::Vector2::new(p[0], p[1])));
            }
        }
        search(&map, points, &pose, &c)
    }

    /// Solves the pose graph (headings, then positions), keyframe 0 held.
    fn optimise(&mut self) {
        let n = self.keyframes.len();
        if n < 2 {
            return;
        }
        // Headings: θ_j − θ_i = z_θ + 2π m_ij, with m_ij from the current headings made
        // continuous along the chain of keyframes.
        let mut unwrapped = vec![self.keyframes[0].pose.theta; n];
        for i in 1..n {
            let step = wrap_angle(self.keyframes[i].pose.theta - self.keyframes[i - 1].pose.theta);
            unwrapped[i] = unwrapped[i - 1] + step;
        }
        let tau = std::f64::consts::TAU;
        let headings: Vec<(usize, usize, f64, f64)> = self
            .edges
            .iter()
            .map(|e| {
                let m = ((unwrapped[e.j] - unwrapped[e.i] - e.z.theta) / tau).round();
                (e.i, e.j, e.z.theta + m * tau, e.w_r)
            })
            .collect();
        let theta = solve_headings(n, &headings, &unwrapped);
        // Positions, the edges' translations rotated by the solved headings.
        let start: Vec<[f64; 2]> = self
            .keyframes
            .iter()
            .map(|k| [k.pose.x, k.pose.y])
            .collect();
        let positions: Vec<PositionEdge> = self
            .edges
            .iter()
            .map(|e| {
                let (s, c) = theta[e.i].sin_cos();
                let d = [c * e.z.x - s * e.z.y, s * e.z.x + c * e.z.y];
                (e.i, e.j, d, e.w_t)
            })
            .collect();
        let p = solve_positions(n, &positions, &start);
        for (kf, (pos, th)) in self.keyframes.iter_mut().zip(p.iter().zip(&theta)) {
            kf.pose = Pose2::new(pos[0], pos[1], wrap_angle(*th));
        }
    }
}

/// An edge of the position step: nodes `i`, `j`, the world-frame translation `d`
/// expected from `i` to `j`, and the 2 × 2 weight of the residual.
type PositionEdge = (usize, usize, [f64; 2], [[f64; 2]; 2]);

/// A matched pose with its uncertainty.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Match {
    pose: Pose2<f64>,
    /// Inverse covariance of the position (world frame), the floor included.
    position_weight: [[f64; 2]; 2],
    /// Variance of the heading (without the floor).
    heading_variance: f64,
}

/// End points of old scans on a square of cells: 2 on an end point's cell, 1 on its
/// eight neighbours (the best mark wins).
struct ScoreMap {
    origin: [f64; 2],
    side: i64,
    cells: Vec<u8>,
}

impl ScoreMap {
    fn new(origin: [f64; 2], extent: f64) -> Self {
        let side = (extent / MATCH_CELL_M).ceil() as i64;
        Self {
            origin,
            side,
            cells: vec![0; (side * side) as usize],
        }
    }

    fn cell(&self, p: [f64; 2]) -> [i64; 2] {
        [
            ((p[0] - self.origin[0]) / MATCH_CELL_M).floor() as i64,
            ((p[1] - self.origin[1]) / MATCH_CELL_M).floor() as i64,
        ]
    }

    fn mark(&mut self, p: nalgebra::Vector2<f64>) {
        let [cx, cy] = self.cell([p[0], p[1]]);
        for dy in -1..=1 {
            for dx in -1..=1 {
                let value = if dx == 0 && dy == 0 { 2 } else { 1 };
                if let Some(i) = self.index(cx + dx, cy + dy) {
                    self.cells[i] = self.cells[i].max(value);
                }
            }
        }
    }

    fn index(&self, x: i64, y: i64) -> Option<usize> {
        (x >= 0 && y >= 0 && x < self.side && y < self.side).then(|| (y * self.side + x) as usize)
    }

    /// The `n` marks from `(x, y)` along x, when they are all on the map.
    fn row(&self, x: i64, y: i64, n: usize) -> Option<&[u8]> {
        let start = self.index(x, y)?;
        (x + n as i64 <= self.side).then(|| self.cells.get(start..start + n))?
    }

    fn score(&self, x: i64, y: i64) -> u32 {
        self.index(x, y).map_or(0, |i| u32::from(self.cells[i]))
    }
}

/// Half-widths of the match's window: cells each way, heading steps each way.
fn window(c: &LoopClosureConfig) -> (i64, i64) {
    (
        (c.window_m / MATCH_CELL_M).round() as i64,
        (c.heading_window_rad / c.heading_step_rad).round() as i64,
    )
}

/// The score of `points` at every pose of the window around `around`: heading-major,
/// then rows (y), then columns (x), each `2 · half + 1` long ([`window`]).
fn window_scores(
    map: &ScoreMap,
    points: &[[f64; 2]],
    around: &Pose2<f64>,
    c: &LoopClosureConfig,
) -> Vec<u32> {
    let (half, steps) = window(c);
    let side = (2 * half + 1) as usize;
    let mut scores = vec![0u32; (2 * steps + 1) as usize * side * side];
    // One heading a job: on the grid run's pool the worker that waits for the next scan
    // takes half of them (integer sums: the same scores whoever adds them).
    scores
        .par_chunks_mut(side * side)
        .enumerate()
        .for_each(|(hi, block)| {
            let h = hi as i64 - steps;
            let theta = around.theta + h as f64 * c.heading_step_rad;
            let (s, co) = theta.sin_cos();
            let cells = points.iter().map(|p| {
                map.cell([
                    around.x + co * p[0] - s * p[1],
                    around.y + s * p[0] + co * p[1],
                ])
            });
            // Point by point, each row of the window at once: the row's `side` cells are
            // contiguous in the map, so one slice is added to one row of scores (integer
            // sums, the same in any order); a row over the map's edge is read cell by cell.
            for [x, y] in cells {
                for (row, sy) in block.chunks_exact_mut(side).zip(-half..=half) {
                    match map.row(x - half, y + sy, side) {
                        Some(marks) => {
                            for (s, &m) in row.iter_mut().zip(marks) {
                                *s += u32::from(m);
                            }
                        }
                        None => {
                            for (s, sx) in row.iter_mut().zip(-half..=half) {
                                *s += map.score(x + sx, y + sy);
                            }
                        }
                    }
                }
            }
        });
    scores
}

/// Scores robot-frame `points` at every pose of the window around `around` against
/// `map`; the best pose and its spread, or `None` when it scores too little.
fn search(
    map: &ScoreMap,
    points: &[[f64; 2]],
    around: &Pose2<f64>,
    c: &LoopClosureConfig,
) -> Option<Match> {
    let (half, steps) = window(c);
    let side = (2 * half + 1) as usize;
    let scores = window_scores(map, points, around, c);
    let unpack = |i: usize| {
        let h = (i / (side * side)) as i64 - steps;
        let r = i % (side * side);
        ((r % side) as i64 - half, (r / side) as i64 - half, h)
    };
    // The best score; among equals the first (nearest the window's start), so that the
    // result does not depend on iteration details.
    let (best_i, &best) = scores
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(&a.0)))?;
    let most = 2 * points.len() as u32;
    if f64::from(best) < c.min_score_fraction * f64::from(most) {
        return None;
    }
    let (bx, by, bh) = unpack(best_i);
    // The spread about the best: every candidate weighted by exp((score − best) / τ).
    let tau = (c.score_temperature * f64::from(most)).max(1.0);
    let (mut xx, mut xy, mut yy, mut hh, mut total) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (i, &v) in scores.iter().enumerate() {
        let w = ((f64::from(v) - f64::from(best)) / tau).exp();
        if w < 1e-9 {
            continue;
        }
        let (x, y, h) = unpack(i);
        let dx = (x - bx) as f64 * MATCH_CELL_M;
        let dy = (y - by) as f64 * MATCH_CELL_M;
        let dh = (h - bh) as f64 * c.heading_step_rad;
        xx += w * dx * dx;
        xy += w * dx * dy;
        yy += w * dy * dy;
        hh += w * dh * dh;
        total += w;
    }
    let floor = c.loop_std_m * c.loop_std_m;
    let (cxx, cxy, cyy) = (xx / total + floor, xy / total, yy / total + floor);
    let det = cxx * cyy - cxy * cxy;
    if !(det.is_finite() && det > 0.0) {
        return None;
    }
    Some(Match {
        pose: Pose2::new(
            around.x + bx as f64 * MATCH_CELL_M,
            around.y + by as f64 * MATCH_CELL_M,
            wrap_angle(around.theta + bh as f64 * c.heading_step_rad),
        ),
        position_weight: [[cyy / det, -cxy / det], [-cxy / det, cxx / det]],
        heading_variance: hh / total,
    })
}

/// Minimises `Σ w (θ_j − θ_i − d)²` over the headings, `θ_0` held at `start[0]`.
fn solve_headings(n: usize, edges: &[(usize, usize, f64, f64)], start: &[f64]) -> Vec<f64> {
    let blocks: Vec<_> = edges
        .iter()
        .map(|&(i, j, d, w)| (i, j, [d, 0.0], [[w, 0.0], [0.0, w]]))
        .collect();
    let lifted: Vec<[f64; 2]> = start.iter().map(|&t| [t, 0.0]).collect();
    solve_positions(n, &blocks, &lifted)
        .into_iter()
        .map(|v| v[0])
        .collect()
}

fn mul(w: &[[f64; 2]; 2], v: [f64; 2]) -> [f64; 2] {
    [
        w[0][0] * v[0] + w[0][1] * v[1],
        w[1][0] * v[0] + w[1][1] * v[1],
    ]
}

fn dot(a: &[[f64; 2]], b: &[[f64; 2]]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| x[0] * y[0] + x[1] * y[1])
        .sum()
}

fn isotropic(std: f64) -> [[f64; 2]; 2] {
    let w = (std * std).recip();
    [[w, 0.0], [0.0, w]]
}

/// Minimises `Σ (p_j − p_i − d)ᵀ W (p_j − p_i − d)` over the positions, `p_0` held at
/// `start[0]`, by conjugate gradients from `start`, block-Jacobi preconditioned (the
/// normal matrix is the graph's Laplacian with 2 × 2 weights, positive definite once a
/// node is held and the graph is connected).
fn solve_positions(n: usize, edges: &[PositionEdge], start: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let mut diag = vec![[[0.0; 2]; 2]; n];
    let mut b = vec![[0.0; 2]; n];
    for &(i, j, d, w) in edges {
        for r in 0..2 {
            for c in 0..2 {
                diag[i][r][c] += w[r][c];
                diag[j][r][c] += w[r][c];
            }
        }
        let wd = mul(&w, d);
        for r in 0..2 {
            b[j][r] += wd[r];
            b[i][r] -= wd[r];
        }
    }
    let inverse: Vec<[[f64; 2]; 2]> = diag
        .iter()
        .map(|m| {
            let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
            if det > 0.0 {
                [
                    [m[1][1] / det, -m[0][1] / det],
                    [-m[1][0] / det, m[0][0] / det],
                ]
            } else {
                [[0.0; 2]; 2]
            }
        })
        .collect();
    // A v for the free nodes (node 0's row dropped).
    let apply = |v: &[[f64; 2]], out: &mut [[f64; 2]]| {
        out.iter_mut().for_each(|o| *o = [0.0; 2]);
        for &(i, j, _, w) in edges {
            let r = mul(&w, [v[j][0] - v[i][0], v[j][1] - v[i][1]]);
            for k in 0..2 {
                out[j][k] += r[k];
                out[i][k] -= r[k];
            }
        }
        out[0] = [0.0; 2];
    };
    let precondition = |r: &[[f64; 2]]| -> Vec<[f64; 2]> {
        r.iter().zip(&inverse).map(|(x, m)| mul(m, *x)).collect()
    };
    let mut v = start.to_vec();
    let mut av = vec![[0.0; 2]; n];
    apply(&v, &mut av);
    let mut r: Vec<[f64; 2]> = (0..n)
        .map(|i| {
            if i == 0 {
                [0.0; 2]
            } else {
                [b[i][0] - av[i][0], b[i][1] - av[i][1]]
            }
        })
        .collect();
    let mut z = precondition(&r);
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    let scale = dot(&b[1..], &b[1..]).sqrt().max(f64::MIN_POSITIVE);
    let mut ap = vec![[0.0; 2]; n];
    for _ in 0..(10 * n).max(200) {
        if dot(&r, &r).sqrt() <= 1e-12 * scale {
            break;
        }
        apply(&p, &mut ap);
        let pap = dot(&p, &ap);
        if pap.is_nan() || pap <= 0.0 {
            break;
        }
        let alpha = rz / pap;
        for i in 1..n {
            for k in 0..2 {
                v[i][k] += alpha * p[i][k];
                r[i][k] -= alpha * ap[i][k];
            }
        }
        z = precondition(&r);
        let rz_next = dot(&r, &z);
        let beta = rz_next / rz;
        rz = rz_next;
        for i in 1..n {
            for k in 0..2 {
                p[i][k] = z[i][k] + beta * p[i][k];
            }
        }
    }
    v
}

fn widen(p: &Pose2<f32>) -> Pose2<f64> {
    Pose2::new(f64::from(p.x), f64::from(p.y), f64::from(p.theta))
}

fn narrow(p: &Pose2<f64>) -> Pose2<f32> {
    Pose2::new(p.x as f32, p.y as f32, p.theta as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A square loop of `n` keyframes per side, 1 m apart, turning left at each corner:
    /// the true poses.
    fn square(n: usize) -> Vec<Pose2<f64>> {
        let mut poses = vec![Pose2::IDENTITY];
        for side in 0..4 {
            for step in 0..n {
                let last = *poses.last().unwrap();
                let turn = if step == n - 1 && side < 3 {
                    std::f64::consts::FRAC_PI_2
                } else {
                    0.0
                };
                poses.push(last.compose(&Pose2::new(1.0, 0.0, turn)));
            }
        }
        poses
    }

    fn closer_with(keyframes: &[Pose2<f64>]) -> LoopCloser {
        let mut c = LoopCloser::new(LoopClosureConfig::DEFAULT, LidarGeometry::CARMEN_SICK_180);
        c.keyframes = keyframes
            .iter()
            .map(|&p| Keyframe {
                pose: p,
                estimate: p,
            })
            .collect();
        c
    }

    fn edge(i: usize, j: usize, z: Pose2<f64>, std: f64, heading_std: f64) -> Edge {
        Edge {
            i,
            j,
            z,
            w_t: isotropic(std),
            w_r: (heading_std * heading_std).recip(),
        }
    }

    #[test]
    fn a_consistent_graph_is_left_as_it_is() {
        let truth = square(5);
        let mut c = closer_with(&truth);
        for i in 1..truth.len() {
            c.edges
                .push(edge(i - 1, i, truth[i - 1].between(&truth[i]), 0.01, 0.001));
        }
        let last = truth.len() - 1;
        c.edges
            .push(edge(0, last, truth[0].between(&truth[last]), 0.05, 0.01));
        c.optimise();
        for (kf, t) in c.keyframes.iter().zip(&truth) {
            assert!(
                (kf.pose.x - t.x).abs() < 1e-9 && (kf.pose.y - t.y).abs() < 1e-9,
                "{kf:?} {t:?}"
            );
            assert!(
                wrap_angle(kf.pose.theta - t.theta).abs() < 1e-9,
                "{kf:?} {t:?}"
            );
        }
    }

    #[test]
    fn a_loop_edge_takes_up_the_drift_of_the_chain() {
        // The chain's edges carry a heading drift of 0.01 rad a step: dead reckoning ends
        // far from the start; one edge saying "the last pose is the first" pulls it back
        // and spreads the drift over the loop.
        let truth = square(5);
        let mut drifted = vec![Pose2::IDENTITY];
        let mut c = closer_with(&truth);
        c.edges.clear();
        for i in 1..truth.len() {
            let mut z = truth[i - 1].between(&truth[i]);
            z.theta += 0.01;
            drifted.push(drifted[i - 1].compose(&z));
            c.edges.push(edge(i - 1, i, z, 0.01, 0.01));
        }
        for (kf, p) in c.keyframes.iter_mut().zip(&drifted) {
            kf.pose = *p;
        }
        let last = truth.len() - 1;
        let end_error = |c: &LoopCloser| {
            let p = c.keyframes[last].pose;
            (p.x - truth[last].x).hypot(p.y - truth[last].y)
        };
        let before = end_error(&c);
        assert!(before > 0.5, "the drift is large: {before}");
        c.edges
            .push(edge(0, last, truth[0].between(&truth[last]), 0.001, 0.0001));
        c.optimise();
        let after = end_error(&c);
        assert!(after < 0.01, "closed: {after} (drifted {before})");
        // Every pose moved towards the truth.
        let worst = c
            .keyframes
            .iter()
            .zip(&truth)
            .map(|(kf, t)| (kf.pose.x - t.x).hypot(kf.pose.y - t.y))
            .fold(0.0, f64::max);
        assert!(worst < 0.2, "{worst}");
    }

    #[test]
    fn the_position_solver_weighs_each_direction_by_its_own_weight() {
        // Node 1 is pulled by two edges from node 0: one says x = 1 (weight only along
        // x), the other y = 2 (weight only along y): both are met.
        let edges = [
            (0, 1, [1.0, 5.0], [[100.0, 0.0], [0.0, 1e-9]]),
            (0, 1, [-3.0, 2.0], [[1e-9, 0.0], [0.0, 100.0]]),
        ];
        let p = solve_positions(2, &edges, &[[0.0, 0.0], [0.0, 0.0]]);
        assert!(
            (p[1][0] - 1.0).abs() < 1e-6 && (p[1][1] - 2.0).abs() < 1e-6,
            "{p:?}"
        );
        assert_eq!(p[0], [0.0, 0.0]);
    }

    /// End points of a 180° scan (SICK geometry, `beams` beams) from `pose` inside the
    /// axis-aligned room `[0, w] × [0, h]` with a pillar, in the robot frame.
    fn room_scan(pose: &Pose2<f64>, beams: usize) -> Vec<[f64; 2]> {
        let g = LidarGeometry::CARMEN_SICK_180;
        let walls: [([f64; 2], [f64; 2]); 8] = [
            ([0.0, 0.0], [8.0, 0.0]),
            ([8.0, 0.0], [8.0, 5.0]),
            ([8.0, 5.0], [0.0, 5.0]),
            ([0.0, 5.0], [0.0, 0.0]),
            ([5.0, 2.0], [5.5, 2.0]),
            ([5.5, 2.0], [5.5, 2.6]),
            ([5.5, 2.6], [5.0, 2.6]),
            ([5.0, 2.6], [5.0, 2.0]),
        ];
        let inc = std::f64::consts::PI / beams as f64;
        (0..beams)
            .filter_map(|i| {
                let a = f64::from(g.first_angle) + i as f64 * inc;
                let (s, c) = (pose.theta + a).sin_cos();
                let mut best = f64::INFINITY;
                for (p, q) in walls {
                    // Ray pose + t (c, s) against segment p + u (q − p).
                    let (ex, ey) = (q[0] - p[0], q[1] - p[1]);
                    let den = c * ey - s * ex;
                    if den.abs() < 1e-12 {
                        continue;
                    }
                    let (wx, wy) = (p[0] - pose.x, p[1] - pose.y);
                    let t = (wx * ey - wy * ex) / den;
                    let u = (wx * s - wy * c) / den;
                    if t > 0.0 && (0.0..=1.0).contains(&u) {
                        best = best.min(t);
                    }
                }
                best.is_finite().then(|| [best * a.cos(), best * a.sin()])
            })
            .collect()
    }

    #[test]
    fn the_match_finds_the_pose_an_old_scan_was_taken_from() {
        let c = LoopClosureConfig::DEFAULT;
        let truth = Pose2::new(3.0, 2.5, 0.3);
        let old_pose = Pose2::new(2.0, 2.0, 0.0);
        let reach = MATCH_MAX_RANGE_M + c.window_m + MATCH_CELL_M;
        let mut map = ScoreMap::new([truth.x - reach, truth.y - reach], 2.0 * reach);
        for p in room_scan(&old_pose, 360) {
            map.mark(old_pose.transform_point(&nalgebra::Vector2::new(p[0], p[1])));
        }
        for p in room_scan(&Pose2::new(6.5, 1.0, 2.0), 360) {
            map.mark(
                Pose2::new(6.5, 1.0, 2.0).transform_point(&nalgebra::Vector2::new(p[0], p[1])),
            );
        }
        let scan = room_scan(&truth, 90);
        // The estimate is off by (−0.3, +0.2) m and −0.08 rad.
        let estimate = Pose2::new(2.7, 2.7, 0.22);
        let m = search(&map, &scan, &estimate, &c).expect("a match");
        assert!(
            (m.pose.x - truth.x).abs() <= 0.05 && (m.pose.y - truth.y).abs() <= 0.05,
            "{m:?}"
        );
        assert!(
            wrap_angle(m.pose.theta - truth.theta).abs() <= 0.011,
            "{m:?}"
        );
        // A room with a pillar pins every direction: the spread is a few centimetres.
        assert!(m.position_weight[0][0] > 1.0 / 0.1f64.powi(2), "{m:?}");
        assert!(m.position_weight[1][1] > 1.0 / 0.1f64.powi(2), "{m:?}");
    }

    #[test]
    fn the_window_scores_are_the_sums_of_each_pose_cell_by_cell() {
        // A map of 6 m, smaller than the room: the windows of the end points on the far
        // wall lie off it and those on the pillar's far side hang over its edge (the
        // cell-by-cell path), the others lie inside (rows).
        let c = LoopClosureConfig {
            window_m: 0.3,
            heading_window_rad: 0.03,
            ..LoopClosureConfig::DEFAULT
        };
        let old_pose = Pose2::new(2.0, 2.0, 0.0);
        let mut map = ScoreMap::new([-0.1, -0.5], 6.0);
        for p in room_scan(&old_pose, 360) {
            map.mark(old_pose.transform_point(&nalgebra::Vector2::new(p[0], p[1])));
        }
        // Marks on the map's first columns, and an end point whose window reaches over
        // its last ones: a row read past the edge would take them.
        for k in 0..=20 {
            map.mark(nalgebra::Vector2::new(-0.05, 2.5 + 0.05 * f64::from(k)));
        }
        let around = Pose2::new(2.1, 2.05, 0.12);
        let mut points = room_scan(&Pose2::new(2.2, 1.9, 0.1), 90);
        let edge = around
            .inverse()
            .transform_point(&nalgebra::Vector2::new(5.75, 3.0));
        points.push([edge[0], edge[1]]);
        let scores = window_scores(&map, &points, &around, &c);
        let (half, steps) = window(&c);
        let mut expected = Vec::new();
        let (mut inside, mut over) = (0, 0);
        let side = (2 * half + 1) as usize;
        let mut rows = [0, 0];
        for h in -steps..=steps {
            let theta = around.theta + h as f64 * c.heading_step_rad;
            let (s, co) = theta.sin_cos();
            for p in &points {
                let [x, y] = map.cell([
                    around.x + co * p[0] - s * p[1],
                    around.y + s * p[0] + co * p[1],
                ]);
                for sy in -half..=half {
                    rows[usize::from(map.row(x - half, y + sy, side).is_some())] += 1;
                }
            }
            for sy in -half..=half {
                for sx in -half..=half {
                    let mut sum = 0;
                    for p in &points {
                        let [x, y] = map.cell([
                            around.x + co * p[0] - s * p[1],
                            around.y + s * p[0] + co * p[1],
                        ]);
                        match map.index(x + sx, y + sy) {
                            Some(i) => {
                                sum += u32::from(map.cells[i]);
                                inside += 1;
                            }
                            None => over += 1,
                        }
                    }
                    expected.push(sum);
                }
            }
        }
        assert!(
            inside > 0 && over > 0,
            "{inside} cells on the map, {over} off it"
        );
        assert!(
            rows[0] > 0 && rows[1] > 0,
            "window rows off / on the map: {rows:?}"
        );
        assert!(expected.iter().any(|&v| v > 0));
        assert_eq!(scores, expected);
    }

    #[test]
    fn a_scan_of_somewhere_else_is_no_match() {
        let c = LoopClosureConfig::DEFAULT;
        let around = Pose2::new(3.0, 2.5, 0.3);
        let reach = MATCH_MAX_RANGE_M + c.window_m + MATCH_CELL_M;
        let mut map = ScoreMap::new([around.x - reach, around.y - reach], 2.0 * reach);
        // The old map: the room seen from one place. The new scan: a long corridor.
        let old_pose = Pose2::new(2.0, 2.0, 0.0);
        for p in room_scan(&old_pose, 360) {
            map.mark(old_pose.transform_point(&nalgebra::Vector2::new(p[0], p[1])));
        }
        let corridor: Vec<[f64; 2]> = (0..90)
            .map(|i| {
                let x = -4.0 + i as f64 * 0.09;
                [x, if i % 2 == 0 { 0.9 } else { -0.9 }]
            })
            .collect();
        assert_eq!(search(&map, &corridor, &around, &c), None);
    }
}
