//! A pose graph over keyframes and its solver, in fixed memory: the loop closure of grid
//! SLAM.
//!
//! **The graph.** Nodes `0 … n−1` are keyframes in time order. Node 0 is anchored at the
//! start pose given to [`PoseGraph::reset`]. Every node `k ≥ 1` is joined to node `k − 1`
//! by a [`ChainEdge`]: the particle filter's motion `z_k = x_{k−1}⁻¹ ⊕ x_k` with an
//! isotropic position standard deviation `σ_k` and a heading one `τ_k`; a new node starts
//! at `x_{k−1} ⊕ z_k`. A [`LoopEdge`] joins two nodes `i < j` with a measured pose `z_ij`
//! of node `j` in the frame of node `i`, a 2 × 2 position information `Ω_ij` in the frame
//! of node `i`, and a heading information `ω_ij` (1/variance). The graph keeps the poses,
//! the chain edges and the loop edges, nothing else; the solver's vectors live in a
//! scratch slice that the caller lends to [`PoseGraph::optimise`], so that a firmware can
//! share that buffer with other work.
//!
//! # The solver
//!
//! LAGO (Carlone et al. 2014): two linear least-squares problems, first the headings, then
//! the positions with every edge rotated by the solved headings; here over the increments
//! of the chain (Olson et al. 2006) instead of the poses.
//!
//! **Unknowns.** The increments `δ_k = θ_k − θ_{k−1}` and `d_k = p_k − p_{k−1}` (world
//! frame) for `k = 1 … n−1`; node 0 is fixed. A chain edge is a prior on one increment;
//! a loop edge `(i, j)` is a measurement of the sum of the increments over `(i, j]`: with
//! `a_ij` the indicator of that range, `θ_j − θ_i = a_ijᵀ δ` and
//! `p_j − p_i = Σ_{k∈(i,j]} d_k`.
//!
//! **Headings.** Minimise
//! `Σ_k (δ_k − z_k.θ)² / τ_k² + Σ_(i,j) ω_ij (a_ijᵀ δ − z_ij.θ − 2π ℓ_ij)²`,
//! where `ℓ_ij` is the number of turns the current estimate implies: each edge's residual
//! `z.θ − (θ_j − θ_i)` at the current headings is wrapped to (−π, π] (LAGO's
//! regularisation of the relative headings). A loop around a full turn — chain headings
//! summing to about 2π, a measured relative heading of about 0 — then has a small residual,
//! not one of 2π, and the problem is linear and well posed. The solver finds corrections
//! `Δδ` to the current increments: with `ρ_k = wrap(z_k.θ − (θ_k − θ_{k−1}))` and
//! `ρ_ij = wrap(z_ij.θ − (θ_j − θ_i))` the normal equations are
//! `(T + Σ ω_ij a_ij a_ijᵀ) Δδ = T ρ + Σ ω_ij ρ_ij a_ij` with `T = diag(1/τ_k²)`, and
//! the new headings are `θ_k + Σ_{m≤k} Δδ_m`, wrapped to (−π, π].
//!
//! **Positions.** With the solved headings `θ*`, chain edge `k` says
//! `d_k ≈ R(θ*_{k−1}) z_k.t` with information `I/σ_k²`, and loop edge `(i, j)` says
//! `Σ_{k∈(i,j]} d_k ≈ R(θ*_i) z_ij.t` with information
//! `Ω'_ij = R(θ*_i) Ω_ij R(θ*_i)ᵀ`. In corrections `Δd` to the current increments, with
//! `ρ_k = R(θ*_{k−1}) z_k.t − (p_k − p_{k−1})` and `ρ_ij = R(θ*_i) z_ij.t − (p_j − p_i)`:
//! `(S ⊗ I₂ + Σ (a_ij a_ijᵀ) ⊗ Ω'_ij) Δd = (S ⊗ I₂) ρ + Σ a_ij ⊗ Ω'_ij ρ_ij` with
//! `S = diag(1/σ_k²)`; the new positions are `p_k + Σ_{m≤k} Δd_m`. Both problems are
//! linear, so solving for corrections gives the same answer as solving for the increments
//! themselves; in `f32` it keeps the numbers small (residuals, not metres from the origin)
//! and leaves an already optimal graph where it is.
//!
//! **Conjugate gradients, preconditioned by the chain.** Both normal matrices are
//! `A = C + U W Uᵀ`: `C` block-diagonal from the chain edges (isotropic blocks, `c_k I`),
//! `U` the loops' range indicators, `W` the loops' information. With the unknowns scaled
//! by the chain's standard deviations, `Δ = C^(−1/2) y`, the matrix becomes
//! `C^(−1/2) A C^(−1/2) = I + V W Vᵀ` (`V = C^(−1/2) U`): the identity plus a term of rank
//! at most `L` for the headings and `2L` for the positions (`L` when every `Ω` is
//! isotropic), for `L` loops. Conjugate gradients on it — CG on `A` with the chain's (block-)Jacobi
//! preconditioner `C⁻¹` — end in at most rank + 1 iterations in exact arithmetic, however
//! long the chain and however its noise varies. The eigenvalues lie in
//! `[1, 1 + Σ_ij ω_ij Σ_{k∈(i,j]} τ_k²]` (headings): each loop's information times the
//! variance the chain accumulates over its range, some thousands for a scan-matched loop
//! over a few hundred keyframes. In `f32` that spread costs extra iterations: on a
//! 500-node chain with 10 stiff loops (the tests) the headings take 14 to 16 iterations
//! (bound 11) and the positions 33 to 38 (bound 21; 19 with isotropic loop information,
//! bound 11) to a relative residual of 10⁻⁶, about 3·10⁻⁵ m and 10⁻⁶ rad from a dense
//! `f64` solution. Plain Jacobi — the loops' terms in the diagonal too — splits the
//! identity into as many values as the loops' ends cut the chain into pieces, loses the
//! bound and does not narrow the low-rank part: on the same problems it needed about twice
//! as many iterations for the same accuracy.
//!
//! **Products in O(n + L).** `(I + V W Vᵀ) y`: one pass forms the prefix sums
//! `P_t = Σ_{k≤t} c_k^(−1/2) y_k`; a loop's range sum is `P_j − P_i`, times its `W`; a
//! difference array takes `+u` at `i + 1` and `−u` at `j + 1` for each loop, and a second
//! pass sums it up, scales it and adds `y`. (The range sums are differences of prefix sums,
//! which costs a short loop on a long chain a few ulps of the prefix sum.)
//!
//! **Stopping.** A step stops when its residual norm has fallen to
//! [`SolverSettings::relative_tolerance`] of its initial value (in scaled unknowns: the
//! preconditioned norm `√(rᵀ C⁻¹ r)`), or after [`SolverSettings::max_iterations`]. Its
//! result is kept either way (CG decreases the error of each iterate in the norm of `A`),
//! and [`StepReport::converged`] says which it was.
//!
//! **Determinism.** Only `f32` additions, subtractions, multiplications and divisions (no
//! fused multiply-add), sines and cosines through [`crate::geometry::sin_cos_f32`],
//! wrapping through [`crate::geometry::wrap_near`] (and `libm` beyond three turns), the
//! norm's square root through `libm`: the same graph gives the same poses bit for bit on
//! the host and on a microcontroller.
//!
//! **Failures.** A step whose result is not finite (an overflow of extreme information or
//! noise figures) writes nothing: [`GraphError::NumericalFailure`], the poses as they were.
//!
//! **Cost.** An iteration of the headings is about 17 floating-point operations per node
//! and 4 per loop; one of the positions about 32 per node and 12 per loop; neither divides.
//! Setting up a step costs a division per node, and for the positions a sine and cosine
//! per node and per loop; rebuilding the poses, a pass over the nodes. A whole optimisation
//! is about `(17 n + 4 L) · (heading iterations) + (32 n + 12 L) · (position iterations)`
//! operations plus `O(n + L)`: for 500 nodes, 10 loops and the iterations above, some
//! 0.7 million.
//!
//! **Memory.** [`PoseGraph<N, L>`] is [`graph_bytes`]`(N, L) = 32 N + 32 L + 8` bytes: per
//! node its pose (12 bytes) and its chain edge (20), per loop edge 32 bytes, and two
//! counters (18 440 bytes for 512 nodes and 64 loops). The scratch is
//! [`scratch_len`]`(N, L) = 9 N + 5 L` floats (19 712 bytes for 512 nodes and 64 loops):
//! the solved headings (one a node), four CG vectors of two floats a node, and per loop
//! its rotated information (3) and range sum (2).
//!
//! **Left out.** LAGO's third step (a joint correction of headings and positions with the
//! headings' covariance), iterating to the nonlinear optimum (Gauss–Newton from this
//! estimate), and robust kernels: a wrong loop edge pulls the whole graph, so the caller
//! must only add loops it trusts.
//!
//! ```
//! use microslam::geometry::Pose2;
//! use microslam::slam::graph::{ChainEdge, LoopEdge, PoseGraph, SolverSettings};
//!
//! // 32 keyframes and 4 loop edges (in a firmware, both would be `static`s).
//! let mut graph = PoseGraph::<32, 4>::new();
//! let mut scratch = [0.0_f32; PoseGraph::<32, 4>::SCRATCH_LEN];
//! graph.reset(Pose2::new(0.0, 0.0, 0.0))?;
//! // Four sides of a 2 m square whose odometry turns 0.05 rad too far at each corner.
//! for k in 1..=8 {
//!     let turn = if k % 2 == 0 { core::f32::consts::FRAC_PI_2 + 0.05 } else { 0.0 };
//!     let motion = Pose2::new(1.0, 0.0, turn);
//!     graph.add_node(ChainEdge { motion, position_std: 0.05, heading_std: 0.02 })?;
//! }
//! // Scan matching finds node 8 back at node 0.
//! graph.add_loop(LoopEdge {
//!     from: 0,
//!     to: 8,
//!     relative: Pose2::new(0.0, 0.0, 0.0),
//!     position_information: [1e4, 0.0, 1e4],
//!     heading_information: 1e4,
//! })?;
//! let report = graph.optimise(&mut scratch, &SolverSettings::DEFAULT)?;
//! assert!(report.converged());
//! let end = graph.pose(8).unwrap_or_default();
//! assert!(end.x.abs() < 0.01 && end.y.abs() < 0.01 && end.theta.abs() < 0.01);
//! # Ok::<(), microslam::slam::graph::GraphError>(())
//! ```
//!
//! # References
//!
//! - Carlone et al. 2014: L. Carlone, R. Aragues, J. A. Castellanos, B. Bona, "A fast and
//!   accurate approximation for planar pose graph optimization", The International Journal
//!   of Robotics Research 33(7), 2014, pp. 965–987. LAGO: the headings first, as a linear
//!   problem with the relative headings regularised by the integer turns the current
//!   estimate implies, then the positions with the edges rotated by them.
//! - Olson et al. 2006: E. Olson, J. Leonard, S. Teller, "Fast iterative alignment of pose
//!   graphs with poor initial estimates", IEEE International Conference on Robotics and
//!   Automation (ICRA), 2006, pp. 2262–2269. The incremental parameterisation: the
//!   unknowns are the increments along the trajectory, so a loop constrains a sum of them.

use crate::error::InvalidSetting;
use crate::geometry::{Pose2, sin_cos_f32, wrap_near};
use core::fmt;

mod solver;
#[cfg(test)]
mod tests;

/// The edge that joins a new node to the one before it: the particle filter's motion
/// between the two keyframes, with its noise.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ChainEdge {
    /// The new node's pose in the frame of the one before it, `x_{k−1}⁻¹ ⊕ x_k`.
    pub motion: Pose2<f32>,
    /// Standard deviation of the position of `motion`, the same along and across, metres
    /// (finite, positive and normal: not below `f32::MIN_POSITIVE`).
    pub position_std: f32,
    /// Standard deviation of the heading of `motion`, radians (as `position_std`).
    pub heading_std: f32,
}

/// A loop closure: where node `to` was seen from node `from`, with the information of that
/// measurement.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LoopEdge {
    /// The earlier node.
    pub from: u16,
    /// The later node (`from < to`).
    pub to: u16,
    /// The pose of node `to` in the frame of node `from`.
    pub relative: Pose2<f32>,
    /// Information (inverse covariance) of the position of `relative`, in the frame of node
    /// `from`: `[xx, xy, yy]` of the symmetric 2 × 2 matrix, positive semi-definite
    /// (`xx, yy ≥ 0`, `xy² ≤ xx · yy` to within 10⁻⁴ of it). `[0, 0, w]` constrains only the
    /// sideways direction of node `from`.
    pub position_information: [f32; 3],
    /// Information of the heading of `relative`, 1/rad² (finite, non-negative; 0: the
    /// heading is not constrained).
    pub heading_information: f32,
}

/// Settings of [`PoseGraph::optimise`].
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct SolverSettings {
    /// Conjugate-gradient iterations at most, for each of the two steps (1 or more).
    pub max_iterations: u16,
    /// A step stops when its residual norm is at most this fraction of its initial value
    /// (within 0 ..= 1; 0: only `max_iterations` stops it).
    pub relative_tolerance: f32,
}

impl SolverSettings {
    /// 256 iterations (the positions' bound of `2L + 1 = 129` with 64 loops, twice over:
    /// in `f32` convergence takes up to about 1.8 times the bound, see the module) and a
    /// relative tolerance of 10⁻⁶ (at 10⁻⁵ a 500-node graph ends up to a millimetre from
    /// the exact solution, at 10⁻⁶ some 3·10⁻⁵ m, near `f32`'s resolution at 30 m).
    pub const DEFAULT: Self = Self {
        max_iterations: 256,
        relative_tolerance: 1e-6,
    };

    /// `true` when every setting is in range.
    pub fn is_valid(&self) -> bool {
        self.invalid_setting().is_none()
    }

    /// The first setting out of range (its name and its rule), `None` when all are valid.
    #[inline]
    pub fn invalid_setting(&self) -> Option<InvalidSetting> {
        InvalidSetting::first([
            ("max_iterations", "1 or more", self.max_iterations > 0),
            InvalidSetting::fraction("relative_tolerance", self.relative_tolerance),
        ])
    }
}

impl Default for SolverSettings {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// What one step (headings or positions) of [`PoseGraph::optimise`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StepReport {
    /// Conjugate-gradient iterations run.
    pub iterations: u16,
    /// Final residual norm over the initial one (0 when the initial one was 0).
    pub residual: f32,
    /// `true` when the residual reached the tolerance (or started at 0); `false` when
    /// the iterations ran out first (the result is kept all the same).
    pub converged: bool,
}

/// What [`PoseGraph::optimise`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SolveReport {
    /// The heading step.
    pub headings: StepReport,
    /// The position step.
    pub positions: StepReport,
}

impl SolveReport {
    /// `true` when both steps converged.
    pub fn converged(&self) -> bool {
        self.headings.converged && self.positions.converged
    }
}

/// Why a change to the graph or an optimisation was refused. The graph is unchanged
/// whenever one is returned.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum GraphError {
    /// The graph has no node yet: [`PoseGraph::reset`] adds the first.
    Empty,
    /// The graph holds as many nodes (or loop edges) as it can.
    Full,
    /// A pose held NaN or ±∞, or a new node's pose would.
    NonFiniteInput,
    /// A chain edge's standard deviation is not finite, positive and normal.
    InvalidNoise,
    /// A loop edge's information is negative, not finite, or not positive semi-definite.
    InvalidInformation,
    /// A loop edge names a node the graph does not hold.
    UnknownNode,
    /// A loop edge's `from` is not before its `to`.
    BackwardLoop,
    /// The scratch slice is shorter than [`PoseGraph::SCRATCH_LEN`].
    ScratchTooShort,
    /// A solver setting is out of range ([`SolverSettings::invalid_setting`] names it).
    InvalidSettings,
    /// The solution would not be finite; the poses were kept.
    NumericalFailure,
}

impl fmt::Display for GraphError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Empty => "pose graph has no node (reset it with a start pose)",
            Self::Full => "pose graph is full",
            Self::NonFiniteInput => "pose contains NaN or infinity",
            Self::InvalidNoise => {
                "chain edge standard deviation is not finite, positive and normal"
            }
            Self::InvalidInformation => {
                "loop edge information is negative, not finite or not positive semi-definite"
            }
            Self::UnknownNode => "loop edge names a node the graph does not hold",
            Self::BackwardLoop => "loop edge's `from` is not before its `to`",
            Self::ScratchTooShort => "scratch slice is too short for the pose graph",
            Self::InvalidSettings => "pose graph solver setting out of range",
            Self::NumericalFailure => "pose graph solution would not be finite",
        })
    }
}

impl core::error::Error for GraphError {}

/// Floats of scratch that [`PoseGraph::optimise`] needs for `nodes` nodes and `loops` loop
/// edges: `9 · nodes + 5 · loops` (see the module's **Memory**).
pub const fn scratch_len(nodes: usize, loops: usize) -> usize {
    9 * nodes + 5 * loops
}

/// Bytes of a [`PoseGraph<N, L>`]: `32 · N + 32 · L + 8` (see the module's **Memory**).
pub const fn graph_bytes(nodes: usize, loops: usize) -> usize {
    32 * nodes + 32 * loops + 8
}

/// A heading wrapped to (−π, π] on every target alike: [`wrap_near`] within three turns'
/// reach (no trigonometry), `libm` beyond. NaN for a non-finite input.
#[inline]
fn wrap_heading(angle: f32) -> f32 {
    // Below 3π, so that `wrap_near` never falls back to `wrap_angle`.
    if angle > -9.0 && angle <= 9.0 {
        wrap_near(angle)
    } else {
        crate::pf::prediction::wrap(angle)
    }
}

/// A chain edge's standard deviation is usable: finite, positive and normal (its inverse
/// square stays finite for any sane value).
fn std_ok(std: f32) -> bool {
    std.is_normal() && std > 0.0
}

/// A loop edge's information is usable (see [`LoopEdge::position_information`]).
fn information_ok(edge: &LoopEdge) -> bool {
    let [xx, xy, yy] = edge.position_information;
    let w = edge.heading_information;
    let finite = xx.is_finite() && xy.is_finite() && yy.is_finite() && w.is_finite();
    finite && xx >= 0.0 && yy >= 0.0 && w >= 0.0 && xy * xy <= xx * yy * (1.0 + 1e-4)
}

/// A 2-D pose graph of at most `N` keyframes and `L` loop edges, with its solver
/// (see the [module](self)).
///
/// Build it empty with [`PoseGraph::new`] (a `const fn` of all zero bytes: a `static` of
/// it lives in `.bss`), start it with [`PoseGraph::reset`], extend it with
/// [`PoseGraph::add_node`] and [`PoseGraph::add_loop`], and optimise it with
/// [`PoseGraph::optimise`].
#[derive(Clone, Debug)]
pub struct PoseGraph<const N: usize, const L: usize> {
    poses: [Pose2<f32>; N],
    /// Element `k`: the edge from node `k − 1` to node `k` (element 0 unused).
    chain: [ChainEdge; N],
    loops: [LoopEdge; L],
    nodes: u32,
    loop_count: u32,
}

/// Two graphs are equal when they hold the same nodes, chain edges and loop edges (what
/// their unused capacity holds does not count).
impl<const N: usize, const L: usize> PartialEq for PoseGraph<N, L> {
    fn eq(&self, other: &Self) -> bool {
        self.poses() == other.poses()
            && self.chain_edges() == other.chain_edges()
            && self.loop_edges() == other.loop_edges()
    }
}

impl<const N: usize, const L: usize> Default for PoseGraph<N, L> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize, const L: usize> PoseGraph<N, L> {
    /// Floats of scratch that [`PoseGraph::optimise`] needs: [`scratch_len`]`(N, L)`.
    pub const SCRATCH_LEN: usize = scratch_len(N, L);

    /// Most nodes a graph holds: `N`, and never more than node indices (`u16`) can name.
    const MAX_NODES: usize = if N < 1 << 16 { N } else { 1 << 16 };

    /// An empty graph (no node: [`PoseGraph::reset`] adds the first).
    pub const fn new() -> Self {
        const ORIGIN: Pose2<f32> = Pose2::new(0.0, 0.0, 0.0);
        Self {
            poses: [ORIGIN; N],
            chain: [ChainEdge {
                motion: ORIGIN,
                position_std: 0.0,
                heading_std: 0.0,
            }; N],
            loops: [LoopEdge {
                from: 0,
                to: 0,
                relative: ORIGIN,
                position_information: [0.0; 3],
                heading_information: 0.0,
            }; L],
            nodes: 0,
            loop_count: 0,
        }
    }

    /// Empties the graph in place and adds node 0, anchored at `start` (its heading
    /// wrapped to (−π, π]). Refused when `start` is not finite, or when `N` is 0.
    pub fn reset(&mut self, start: Pose2<f32>) -> Result<(), GraphError> {
        if !start.is_finite() {
            return Err(GraphError::NonFiniteInput);
        }
        let first = self.poses.first_mut().ok_or(GraphError::Full)?;
        *first = Pose2::new(start.x, start.y, wrap_heading(start.theta));
        self.nodes = 1;
        self.loop_count = 0;
        Ok(())
    }

    /// Adds a node at `previous ⊕ edge.motion` joined to the previous node by `edge`, and
    /// returns its index. Refused when the graph is empty or full, when the motion or the
    /// new pose is not finite, or when a standard deviation is not finite, positive and normal.
    pub fn add_node(&mut self, edge: ChainEdge) -> Result<u16, GraphError> {
        let len = self.len();
        let previous = *self
            .poses
            .get(len.wrapping_sub(1))
            .ok_or(GraphError::Empty)?;
        if len >= Self::MAX_NODES {
            return Err(GraphError::Full);
        }
        if !edge.motion.is_finite() {
            return Err(GraphError::NonFiniteInput);
        }
        if !std_ok(edge.position_std) || !std_ok(edge.heading_std) {
            return Err(GraphError::InvalidNoise);
        }
        let moved = previous.compose_unwrapped(&edge.motion, sin_cos_f32(previous.theta));
        let pose = Pose2::new(moved.x, moved.y, wrap_heading(moved.theta));
        if !pose.is_finite() {
            return Err(GraphError::NonFiniteInput);
        }
        let index = u16::try_from(len).map_err(|_| GraphError::Full)?;
        let (Some(slot), Some(chain)) = (self.poses.get_mut(len), self.chain.get_mut(len)) else {
            return Err(GraphError::Full);
        };
        *slot = pose;
        *chain = edge;
        self.nodes += 1;
        Ok(index)
    }

    /// Adds a loop edge. Refused when `L` loop edges are held, when a node is not in the
    /// graph or `from` is not before `to`, when `relative` is not finite, or when the
    /// information is not usable (see [`LoopEdge::position_information`]).
    pub fn add_loop(&mut self, edge: LoopEdge) -> Result<(), GraphError> {
        let count = self.loop_count();
        if count >= L {
            return Err(GraphError::Full);
        }
        if usize::from(edge.to) >= self.len() {
            return Err(GraphError::UnknownNode);
        }
        if edge.from >= edge.to {
            return Err(GraphError::BackwardLoop);
        }
        if !edge.relative.is_finite() {
            return Err(GraphError::NonFiniteInput);
        }
        if !information_ok(&edge) {
            return Err(GraphError::InvalidInformation);
        }
        let slot = self.loops.get_mut(count).ok_or(GraphError::Full)?;
        *slot = edge;
        self.loop_count += 1;
        Ok(())
    }

    /// Moves the nodes to the solution of the two linear steps (headings, then positions;
    /// see the [module](self)); node 0 stays. `scratch` needs [`PoseGraph::SCRATCH_LEN`]
    /// floats (whatever the graph holds now, so that a buffer too short shows at the first
    /// call); what it holds before and after does not matter.
    ///
    /// Refused, with the poses unchanged, when the settings are out of range, the scratch
    /// is too short, or a step's result would not be finite. A step that runs out of
    /// iterations keeps its result and says so in the report.
    pub fn optimise(
        &mut self,
        scratch: &mut [f32],
        settings: &SolverSettings,
    ) -> Result<SolveReport, GraphError> {
        if !settings.is_valid() {
            return Err(GraphError::InvalidSettings);
        }
        if scratch.len() < Self::SCRATCH_LEN {
            return Err(GraphError::ScratchTooShort);
        }
        let n = self.len();
        if n < 2 {
            return Ok(SolveReport::default());
        }
        let graph = solver::Graph {
            poses: self.poses.get(..n).ok_or(GraphError::NumericalFailure)?,
            chain: self.chain.get(1..n).ok_or(GraphError::NumericalFailure)?,
            loops: self.loop_edges(),
        };
        let (headings, rest) = scratch
            .split_at_mut_checked(n)
            .ok_or(GraphError::ScratchTooShort)?;
        let heading_report = solver::solve_headings(&graph, headings, rest, settings)?;
        let (position_report, positions) =
            solver::solve_positions(&graph, headings, rest, settings)?;
        // Both steps checked their results: all finite, so write them.
        let later = self.poses.iter_mut().take(n).skip(1);
        for ((pose, &[x, y]), &theta) in later.zip(positions).zip(headings.iter().skip(1)) {
            *pose = Pose2::new(x, y, theta);
        }
        Ok(SolveReport {
            headings: heading_report,
            positions: position_report,
        })
    }

    /// The pose of node `k`, `None` when the graph does not hold it.
    pub fn pose(&self, k: usize) -> Option<Pose2<f32>> {
        self.poses().get(k).copied()
    }

    /// The poses of the nodes, node 0 first.
    pub fn poses(&self) -> &[Pose2<f32>] {
        self.poses.get(..self.len()).unwrap_or(&[])
    }

    /// The chain edges: element `k` joins node `k` to node `k + 1`.
    pub fn chain_edges(&self) -> &[ChainEdge] {
        self.chain.get(1..self.len()).unwrap_or(&[])
    }

    /// The loop edges, in the order they were added.
    pub fn loop_edges(&self) -> &[LoopEdge] {
        self.loops.get(..self.loop_count()).unwrap_or(&[])
    }

    /// Number of nodes.
    pub fn len(&self) -> usize {
        self.nodes as usize
    }

    /// `true` when the graph has no node (before the first [`PoseGraph::reset`]).
    pub fn is_empty(&self) -> bool {
        self.nodes == 0
    }

    /// Number of loop edges.
    pub fn loop_count(&self) -> usize {
        self.loop_count as usize
    }
}
