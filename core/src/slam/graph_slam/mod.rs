//! [`GraphSlam`]: the particle filter on a [`LocalMap`], keyframes in a
//! [`KeyframeStore`], and a [`PoseGraph`] over them that closes loops.

#[cfg(feature = "map-image")]
mod building_map;
mod closure;
mod estimator;
mod stored;
#[cfg(test)]
mod tests;
mod workspace;

use super::config::GraphSlamConfig;
use super::graph::{ChainEdge, GraphError, PoseGraph};
use super::keyframes::{Keyframe, KeyframeStorage, KeyframeStore, StoreError};
use super::local_map::LocalMap;
use crate::geometry::Pose2;
use crate::grid::{GridError, ScanIntegration, occupancy_bytes};
use crate::pf::{ParticleFilter, PfError, ScanPoints};
use crate::sensors::lidar::LidarScan;
#[cfg(feature = "map-image")]
pub use building_map::{MAX_MAP_CELLS, MapImageSummary};
use core::fmt;
pub use estimator::WithKeyframes;
use workspace::Workspace;
pub use workspace::workspace_bytes;

/// Cells along each edge of the map a loop closure matches against (12.8 m at 5 cm).
pub const MATCH_CELLS: usize = 256;
/// Bytes of that map's bitmap.
pub const MATCH_BYTES: usize = occupancy_bytes(MATCH_CELLS, MATCH_CELLS);
/// Levels of max-pooled copies the loop closure's matcher uses.
pub const MATCH_LEVELS: usize = 2;

/// Why a step of [`GraphSlam`] failed. The estimator is left usable.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SlamError {
    /// [`GraphSlam::init`] has not been called.
    NotStarted,
    /// The particle filter refused the input.
    Filter(PfError),
    /// The local map refused a write.
    Map(GridError),
    /// The keyframe store failed (reading or writing).
    Store(StoreError),
    /// The pose graph refused a change.
    Graph(GraphError),
    /// No keyframe to draw a map from.
    NoKeyframes,
    /// The map would be wider or taller than a map image holds.
    MapTooLarge,
}

impl fmt::Display for SlamError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NotStarted => f.write_str("grid SLAM not started (init it first)"),
            Self::Filter(e) => write!(f, "particle filter: {e}"),
            Self::Map(e) => write!(f, "local map: {e}"),
            Self::Store(e) => write!(f, "keyframe store: {e}"),
            Self::Graph(e) => write!(f, "pose graph: {e}"),
            Self::NoKeyframes => f.write_str("no keyframe to draw a map from"),
            Self::MapTooLarge => f.write_str("the map is larger than a map image holds"),
        }
    }
}

impl core::error::Error for SlamError {}

impl From<PfError> for SlamError {
    fn from(e: PfError) -> Self {
        Self::Filter(e)
    }
}

impl From<GridError> for SlamError {
    fn from(e: GridError) -> Self {
        Self::Map(e)
    }
}

impl From<StoreError> for SlamError {
    fn from(e: StoreError) -> Self {
        Self::Store(e)
    }
}

impl From<GraphError> for SlamError {
    fn from(e: GraphError) -> Self {
        Self::Graph(e)
    }
}

/// What one scan did.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GraphStep {
    /// The estimate in the graph's frame: the newest keyframe's graph pose composed with
    /// the filter's motion since it (what a robot should act on).
    pub pose: Pose2<f32>,
    /// The filter's own estimate (the heaviest particle), in the filter's frame.
    pub filter_pose: Pose2<f32>,
    /// Effective number of particles before resampling.
    pub n_eff: f32,
    /// Beams used.
    pub beams: usize,
    /// Map writing.
    pub map: ScanIntegration,
    /// The keyframe this scan became, if it did.
    pub keyframe: Option<u16>,
    /// A loop closure match that ended at this scan (started at an earlier keyframe),
    /// and what came of it.
    pub closure: Option<ClosureOutcome>,
    /// The loop closure work this scan did (at most one kind a scan).
    pub work: ClosureWork,
}

/// The part of a loop closure a scan did: a closure is spread over the scans after its
/// keyframe so that no scan pays for all of it (what a scan's time budget is checked
/// against).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ClosureWork {
    /// No loop closure work.
    #[default]
    None,
    /// Old keyframes drawn into the map a closure matches against.
    OldMap,
    /// A slice of the match (it may have ended the match: [`GraphStep::closure`]).
    Match,
    /// The pose graph solved after a loop edge was added.
    Solve,
}

/// What a loop closure attempt did.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ClosureOutcome {
    /// The new keyframe that was matched.
    pub keyframe: u16,
    /// The old keyframe the match was made against (the nearest).
    pub old: u16,
    /// End points of the new keyframe that hit the old map at the best candidate.
    pub hits: u32,
    /// End points matched.
    pub points: u32,
    /// `true` when the match was accepted and a loop edge added.
    pub accepted: bool,
}

/// Counts over a run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GraphCounters {
    /// Keyframes made.
    pub keyframes: u32,
    /// Keyframes not made because the graph or the store was full.
    pub keyframes_refused: u32,
    /// Loop closures tried.
    pub attempts: u32,
    /// Loop closures not tried because another was under way.
    pub closures_skipped: u32,
    /// Loop edges added.
    pub closures: u32,
}

/// The newest keyframe: its node and the filter's estimate of it, in the filter's frame.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Newest {
    node: u16,
    estimate: Pose2<f32>,
}

/// Grid SLAM at the scale of a building, in fixed memory (see the [module](super)).
///
/// - `P` particles, at most `B` beams a scan;
/// - the [`LocalMap`]: a `NEAR × NEAR` log-odds window (`NEAR_BITS` bytes of bitmap) and a
///   `FAR × FAR` bitmap (`FAR_BITS` bytes);
/// - a [`PoseGraph`] of at most `NODES` keyframes and `LOOPS` loop edges, solved in
///   `SCRATCH` floats of scratch (at least [`super::graph::scratch_len`]`(NODES, LOOPS)`),
///   which the loop closure's matcher buffers share ([`workspace_bytes`]: the larger of
///   the two, never both);
/// - the keyframes' scans in a [`KeyframeStore`] the caller owns and lends to each step
///   (flash on a microcontroller).
///
/// Built with [`GraphSlam::zeroed`] (all zero bytes: a `static` of it lives in `.bss`)
/// and started with [`GraphSlam::init`].
#[derive(Clone, Debug)]
pub struct GraphSlam<
    const P: usize,
    const B: usize,
    const NEAR: usize,
    const NEAR_BITS: usize,
    const FAR: usize,
    const FAR_BITS: usize,
    const NODES: usize,
    const LOOPS: usize,
    const SCRATCH: usize,
> {
    map: LocalMap<NEAR, NEAR_BITS, FAR, FAR_BITS>,
    /// The particles: zero bytes until [`GraphSlam::init`] builds them (`started`).
    filter: ParticleFilter<P>,
    /// `true` once [`GraphSlam::init`] has built the filter and set the settings.
    started: bool,
    points: ScanPoints<B>,
    /// The points of a stored keyframe (loop closure, imports, rebuilds).
    stored: ScanPoints<B>,
    ranges: [f32; B],
    graph: PoseGraph<NODES, LOOPS>,
    /// The loop closure's matcher buffers, then the graph solver's scratch, in one block.
    workspace: Workspace<SCRATCH>,
    /// The loop closure under way.
    pending: closure::Pending,
    config: GraphSlamConfig,
    scans: u32,
    pose: Pose2<f32>,
    newest: Option<Newest>,
    /// How much the odometry turned since the last scan, radians (the heading search's
    /// span grows with it).
    turned: f32,
    counters: GraphCounters,
}

impl<
    const P: usize,
    const B: usize,
    const NEAR: usize,
    const NEAR_BITS: usize,
    const FAR: usize,
    const FAR_BITS: usize,
    const NODES: usize,
    const LOOPS: usize,
    const SCRATCH: usize,
> GraphSlam<P, B, NEAR, NEAR_BITS, FAR, FAR_BITS, NODES, LOOPS, SCRATCH>
{
    const SCRATCH_OK: () = assert!(
        SCRATCH >= super::graph::scratch_len(NODES, LOOPS),
        "GraphSlam: SCRATCH must be at least scratch_len(NODES, LOOPS)"
    );

    /// An estimator of all zero bytes, for a `static` (`.bss`: no initial image in
    /// flash); [`GraphSlam::init`] starts it. Its settings are zero until then (not valid:
    /// `init` replaces them).
    pub const fn zeroed() -> Self {
        let () = Self::SCRATCH_OK;
        Self {
            map: LocalMap::zeroed(),
            filter: ParticleFilter::zeroed(),
            started: false,
            points: ScanPoints::new(),
            stored: ScanPoints::new(),
            ranges: [0.0; B],
            graph: PoseGraph::new(),
            workspace: Workspace::zeroed(),
            pending: closure::Pending::Idle,
            config: GraphSlamConfig::ZEROED,
            scans: 0,
            pose: Pose2::new(0.0, 0.0, 0.0),
            newest: None,
            turned: 0.0,
            counters: GraphCounters {
                keyframes: 0,
                keyframes_refused: 0,
                attempts: 0,
                closures_skipped: 0,
                closures: 0,
            },
        }
    }

    /// Starts (or restarts) in place at `start` with `config`: the map cleared and centred
    /// on `start`, the particles drawn from the configured seed, no keyframe yet. The
    /// keyframe store is the caller's: create it empty for a new run. Refused (nothing
    /// changed) for invalid settings or a non-finite start.
    pub fn init(&mut self, config: GraphSlamConfig, start: Pose2<f32>) -> Result<(), SlamError> {
        if !config.is_valid() {
            return Err(SlamError::Filter(PfError::InvalidConfig));
        }
        if !start.is_finite() {
            return Err(SlamError::Filter(PfError::NonFiniteInput));
        }
        let filter = ParticleFilter::new(config.grid.filter, start)?;
        self.map.init(
            config.grid.resolution,
            config.grid.log_odds,
            start.x,
            start.y,
        )?;
        self.filter = filter;
        self.started = true;
        self.config = config;
        self.scans = 0;
        self.pose = start;
        self.newest = None;
        self.pending = closure::Pending::Idle;
        self.turned = 0.0;
        self.counters = GraphCounters::default();
        Ok(())
    }

    /// The settings (all zero, not valid, before [`GraphSlam::init`]).
    pub fn config(&self) -> &GraphSlamConfig {
        &self.config
    }

    /// The local map.
    pub fn map(&self) -> &LocalMap<NEAR, NEAR_BITS, FAR, FAR_BITS> {
        &self.map
    }

    /// The pose graph of the keyframes.
    pub fn graph(&self) -> &PoseGraph<NODES, LOOPS> {
        &self.graph
    }

    /// The particles (`None` before [`GraphSlam::init`]).
    pub fn filter(&self) -> Option<&ParticleFilter<P>> {
        self.started.then_some(&self.filter)
    }

    /// Counts over the run.
    pub fn counters(&self) -> GraphCounters {
        self.counters
    }

    /// Scans processed.
    pub fn scans(&self) -> u32 {
        self.scans
    }

    /// The filter's estimate (the heaviest particle after the last scan), in the filter's
    /// frame.
    pub fn filter_pose(&self) -> Pose2<f32> {
        self.pose
    }

    /// The estimate in the graph's frame ([`GraphStep::pose`]).
    pub fn pose(&self) -> Pose2<f32> {
        self.to_graph_frame(&self.pose)
    }

    /// The newest keyframe's node and the filter's estimate of it (in the filter's frame:
    /// the motion of a later scan since it is `estimate⁻¹ ⊕ filter_pose`).
    pub fn newest_keyframe(&self) -> Option<(u16, Pose2<f32>)> {
        self.newest.map(|n| (n.node, n.estimate))
    }

    /// A pose of the filter's frame in the graph's: through the newest keyframe (the
    /// identity before the first).
    fn to_graph_frame(&self, p: &Pose2<f32>) -> Pose2<f32> {
        match self.newest {
            Some(n) => match self.graph.pose(usize::from(n.node)) {
                Some(g) => g.compose(&n.estimate.between(p)),
                None => *p,
            },
            None => *p,
        }
    }

    fn filter_mut(&mut self) -> Result<&mut ParticleFilter<P>, SlamError> {
        if self.started {
            Ok(&mut self.filter)
        } else {
            Err(SlamError::NotStarted)
        }
    }

    /// Prediction with the odometry poses before and after the step (only their
    /// difference is used).
    pub fn predict_odometry(
        &mut self,
        from: &Pose2<f32>,
        to: &Pose2<f32>,
    ) -> Result<(), SlamError> {
        self.filter_mut()?.predict_odometry(from, to)?;
        self.turned += crate::geometry::wrap_near(to.theta - from.theta).abs();
        Ok(())
    }

    /// Prediction with the arc `(distance, heading_change)` driven since the last step.
    pub fn predict(&mut self, distance: f32, heading_change: f32) -> Result<(), SlamError> {
        self.filter_mut()?.predict(distance, heading_change)?;
        self.turned += heading_change.abs();
        Ok(())
    }

    /// Prediction with `(v, ω)` held for `dt` seconds.
    pub fn predict_velocity(&mut self, v: f32, omega: f32, dt: f32) -> Result<(), SlamError> {
        self.filter_mut()?.predict_velocity(v, omega, dt)?;
        self.turned += (omega * dt).abs();
        Ok(())
    }

    /// Processes one scan: scores the particles on the local map (the first scan only
    /// starts it), writes the scan at the heaviest particle, moves the map with the robot,
    /// and makes a keyframe when the estimate has moved far enough: appended to `store`,
    /// added to the graph, and matched against the old keyframes near it (loop closure).
    /// The store must be the one this run's keyframes went to (empty at
    /// [`GraphSlam::init`]).
    pub fn observe<S: KeyframeStorage>(
        &mut self,
        scan: &LidarScan<'_>,
        store: &mut KeyframeStore<S>,
    ) -> Result<GraphStep, SlamError> {
        let search = const { crate::pf::slam_shift_search::<FAR, FAR_BITS>() };
        if !self.started {
            return Err(SlamError::NotStarted);
        }
        let filter = &mut self.filter;
        let view = (self.scans > 0).then(|| (self.map.view(), search));
        let h = self.config.heading_search;
        let span = (h.span_rad + h.span_per_radian * self.turned).min(h.max_span_rad);
        let heading = (span >= h.step_rad).then_some(crate::pf::HeadingSearch {
            span,
            step: h.step_rad,
            coarse: h.coarse_steps,
            min_gain: h.min_gain,
        });
        let (report, _) = crate::pf::score_slam_scan(
            filter,
            &mut self.points,
            &self.config.grid,
            scan,
            view,
            heading,
        )?;
        self.turned = 0.0;
        let map = self.map.integrate(
            &report.pose,
            &scan.geometry.mount,
            self.points.robot_points(),
        )?;
        // The estimate: the particles near the heaviest one, averaged (the heaviest alone
        // jumps from scan to scan by the shift search's whole cells).
        let r = self.config.estimate_radius;
        self.pose = self
            .filter
            .local_mean(&report.pose, r.position_m, r.heading_rad);
        self.scans = self.scans.saturating_add(1);
        self.map.follow(self.pose.x, self.pose.y);
        let mut step = GraphStep {
            pose: self.pose,
            filter_pose: self.pose,
            n_eff: report.n_eff,
            beams: report.beams,
            map,
            keyframe: None,
            closure: None,
            work: ClosureWork::None,
        };
        // A scan that starts a loop closure draws the first old keyframes of its old map
        // and does no more of it; any other scan runs a slice of the one under way: no
        // scan pays for two parts.
        let mut started = false;
        if let Some(node) = self.keyframe(scan, store)? {
            step.keyframe = Some(node);
            if self.config.loop_closure.enabled {
                started = self.start_closure(node)?;
            }
        }
        if started {
            step.work = ClosureWork::OldMap;
            self.draw_old_map(store)?;
        } else {
            (step.closure, step.work) = self.advance_closure(store)?;
        }
        step.pose = self.pose();
        step.filter_pose = self.pose;
        Ok(step)
    }

    /// Makes a keyframe of this scan when it is the first or the estimate has moved far
    /// enough since the newest; `None` when it did not (or the graph or store is full:
    /// counted).
    fn keyframe<S: KeyframeStorage>(
        &mut self,
        scan: &LidarScan<'_>,
        store: &mut KeyframeStore<S>,
    ) -> Result<Option<u16>, SlamError> {
        let spacing = self.config.keyframes;
        let (motion, edge) = match self.newest {
            None => (Pose2::new(0.0, 0.0, 0.0), None),
            Some(n) => {
                let m = n.estimate.between(&self.pose);
                let driven = libm::sqrtf(m.x * m.x + m.y * m.y);
                if driven < spacing.distance_m && m.theta.abs() < spacing.turn_rad {
                    return Ok(None);
                }
                let c = self.config.chain;
                let edge = ChainEdge {
                    motion: m,
                    position_std: c.position_std_m + c.position_std_per_m * driven,
                    heading_std: c.heading_std_rad,
                };
                (m, Some(edge))
            }
        };
        if self.graph.len() >= NODES || store.len() >= store.capacity() {
            self.counters.keyframes_refused = self.counters.keyframes_refused.saturating_add(1);
            return Ok(None);
        }
        // The store first: a keyframe whose scan could not be kept is not a node.
        match store.append(&Keyframe::new(motion, self.pose, scan.ranges)) {
            Ok(_) => {}
            Err(StoreError::Full) => {
                self.counters.keyframes_refused = self.counters.keyframes_refused.saturating_add(1);
                return Ok(None);
            }
            Err(e) => return Err(e.into()),
        }
        let node = match edge {
            None => {
                self.graph.reset(self.pose)?;
                0
            }
            Some(edge) => self.graph.add_node(edge)?,
        };
        self.newest = Some(Newest {
            node,
            estimate: self.pose,
        });
        self.counters.keyframes = self.counters.keyframes.saturating_add(1);
        Ok(Some(node))
    }
}
