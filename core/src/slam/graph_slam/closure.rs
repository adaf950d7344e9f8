//! Loop closure: a new keyframe matched against the old ones near it, a loop edge, and
//! the graph solved, spread over the scans after the keyframe so that no scan pays for
//! all of it: the keyframe's scan builds the old map, the next ones search it
//! (`work_per_scan` look-ups each), the one after the match solves the graph.

use super::stored::load_stored;
use super::{ClosureOutcome, GraphSlam, SlamError};
use crate::geometry::{Pose2, sin_cos_f32};
use crate::slam::graph::LoopEdge;
use crate::slam::keyframes::{KeyframeStorage, KeyframeStore};
use crate::slam::matcher::{MAX_MATCH_POINTS, MatchProgress};

/// A loop closure under way.
#[derive(Clone, Debug)]
// Fixed memory, no heap: the match's state lives in the estimator (one of these).
#[allow(clippy::large_enum_variant)]
pub(super) enum Pending {
    /// None.
    Idle,
    /// The match of keyframe `node` against the old map around keyframe `old`.
    Matching {
        node: u16,
        old: u16,
        progress: MatchProgress,
    },
    /// A loop edge was added: the graph is solved at the next scan.
    Solving,
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
    /// At keyframe `node`: when an old enough keyframe lies within the candidate radius,
    /// builds the map of the old keyframes near it (at their graph poses) and starts the
    /// match of this scan against it, which [`GraphSlam::advance_closure`] runs over the
    /// next scans. The filter is left as it is: its local map holds only what it saw
    /// lately, and the graph's frame follows from the newest keyframe
    /// ([`GraphSlam::pose`]). Nothing is started while another closure is under way
    /// (counted in `closures_skipped`). `true` when the old map was built (the scan's
    /// loop closure work is done).
    pub(super) fn start_closure<S: KeyframeStorage>(
        &mut self,
        node: u16,
        store: &KeyframeStore<S>,
    ) -> Result<bool, SlamError> {
        let lc = self.config.loop_closure;
        let k = usize::from(node);
        let Some(newest_old) = k.checked_sub(usize::from(lc.min_age_keyframes)) else {
            return Ok(false);
        };
        let Some(here) = self.graph.pose(k) else {
            return Ok(false);
        };
        let near = |p: &Pose2<f32>, r: f32| {
            let (dx, dy) = (p.x - here.x, p.y - here.y);
            dx * dx + dy * dy <= r * r
        };
        let Some(old) = self
            .graph
            .poses()
            .iter()
            .take(newest_old + 1)
            .enumerate()
            .filter(|(_, p)| near(p, lc.candidate_radius_m))
            .min_by(|(_, a), (_, b)| {
                let da = (a.x - here.x) * (a.x - here.x) + (a.y - here.y) * (a.y - here.y);
                let db = (b.x - here.x) * (b.x - here.x) + (b.y - here.y) * (b.y - here.y);
                da.total_cmp(&db)
            })
            .map(|(j, _)| j)
        else {
            return Ok(false);
        };
        if !matches!(self.pending, Pending::Idle) {
            self.counters.closures_skipped = self.counters.closures_skipped.saturating_add(1);
            return Ok(false);
        }
        self.counters.attempts = self.counters.attempts.saturating_add(1);
        // The old map around this keyframe: every old keyframe near it at its graph pose.
        let res = self.config.grid.resolution;
        let half = 0.5 * super::MATCH_CELLS as f32 * res;
        let buffers = self.workspace.matching();
        buffers.map.init(
            res,
            here.x - half,
            here.y - half,
            self.config.grid.log_odds.occupied_above,
        )?;
        for j in 0..=newest_old {
            let Some(pose) = self.graph.pose(j) else {
                continue;
            };
            if !near(&pose, lc.submap_radius_m) {
                continue;
            }
            load_stored(&mut self.stored, &mut self.ranges, j, store)?;
            let (s, c) = sin_cos_f32(pose.theta);
            for (px, py) in self.stored.robot_points() {
                buffers
                    .map
                    .set_world(pose.x + c * px - s * py, pose.y + s * px + c * py);
            }
        }
        buffers.levels.build(&buffers.map);
        let mut points = [(0.0f32, 0.0f32); MAX_MATCH_POINTS];
        let mut n = 0;
        let stride = self
            .points
            .as_slice()
            .len()
            .div_ceil(MAX_MATCH_POINTS)
            .max(1);
        for p in self.points.robot_points().step_by(stride) {
            if let Some(slot) = points.get_mut(n) {
                *slot = p;
                n += 1;
            }
        }
        // A scan with nothing to match is no closure, not an error of the run.
        if let Ok(progress) = buffers.levels.start(
            &buffers.map,
            points.get(..n).unwrap_or(&[]),
            &here,
            &lc.window,
        ) {
            self.pending = Pending::Matching {
                node,
                old: u16::try_from(old).unwrap_or(u16::MAX),
                progress,
            };
        }
        Ok(true)
    }

    /// Runs the closure under way for one scan: a slice of the match (and, when it ends
    /// accepted, the loop edge), or the graph's solve after a loop edge. `Some` when a
    /// match ended at this scan.
    pub(super) fn advance_closure(&mut self) -> Result<Option<ClosureOutcome>, SlamError> {
        let lc = self.config.loop_closure;
        match &mut self.pending {
            Pending::Idle => Ok(None),
            Pending::Solving => {
                self.pending = Pending::Idle;
                self.graph.optimise(self.workspace.solving(), &lc.solver)?;
                Ok(None)
            }
            Pending::Matching {
                node,
                old,
                progress,
            } => {
                let (node, old) = (*node, *old);
                let buffers = self.workspace.matching();
                let m = match buffers.levels.resume(
                    &buffers.map,
                    progress,
                    &lc.window,
                    lc.work_per_scan,
                ) {
                    Ok(None) => return Ok(None),
                    Ok(Some(m)) => m,
                    Err(_) => {
                        // The buffers changed under the match: no closure.
                        self.pending = Pending::Idle;
                        return Ok(None);
                    }
                };
                self.pending = Pending::Idle;
                let mut outcome = ClosureOutcome {
                    keyframe: node,
                    old,
                    hits: m.hits,
                    points: m.points,
                    accepted: false,
                };
                let Some(from) = self.graph.pose(usize::from(old)) else {
                    return Ok(Some(outcome));
                };
                if !m.accepted {
                    return Ok(Some(outcome));
                }
                let edge = LoopEdge {
                    from: old,
                    to: node,
                    relative: from.between(&m.centroid),
                    position_information: information_in_frame(
                        m.covariance,
                        lc.position_std_floor_m,
                        from.theta,
                    ),
                    heading_information: 1.0
                        / (m.covariance[3] + lc.heading_std_floor_rad * lc.heading_std_floor_rad),
                };
                if self.graph.add_loop(edge).is_err() {
                    // A full table of loop edges: the match is not kept.
                    return Ok(Some(outcome));
                }
                self.pending = Pending::Solving;
                outcome.accepted = true;
                self.counters.closures = self.counters.closures.saturating_add(1);
                Ok(Some(outcome))
            }
        }
    }
}

/// The information of a position with covariance `[xx, xy, yy, ·]` (world frame) plus
/// `floor²` on each axis, turned into the frame of a node with heading `theta`:
/// `Rᵀ Σ⁻¹ R` as `[xx, xy, yy]`.
fn information_in_frame(covariance: [f32; 4], floor: f32, theta: f32) -> [f32; 3] {
    let f2 = floor * floor;
    let (a, b, d) = (covariance[0] + f2, covariance[1], covariance[2] + f2);
    let det = a * d - b * b;
    if !(det > 0.0 && det.is_finite()) {
        let w = 1.0 / f2;
        return [w, 0.0, w];
    }
    // Σ⁻¹ in the world frame.
    let (ia, ib, id) = (d / det, -b / det, a / det);
    // Rᵀ M R with R the node's rotation.
    let (s, c) = sin_cos_f32(theta);
    let xx = c * c * ia + 2.0 * c * s * ib + s * s * id;
    let xy = -c * s * ia + (c * c - s * s) * ib + c * s * id;
    let yy = s * s * ia - 2.0 * c * s * ib + c * c * id;
    [xx, xy, yy]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn information_turns_with_the_frame() {
        // A covariance long along world x (a corridor along x): in a frame turned by 90°
        // the long axis is the frame's y, so the information is small along y.
        let [xx, xy, yy] =
            information_in_frame([0.25, 0.0, 0.0001, 0.0], 0.01, core::f32::consts::FRAC_PI_2);
        assert!(yy < xx / 100.0, "{xx} {xy} {yy}");
        assert!(xy.abs() < 1e-3 * xx);
        // Unturned: long along x.
        let [xx, _, yy] = information_in_frame([0.25, 0.0, 0.0001, 0.0], 0.01, 0.0);
        assert!(xx < yy / 100.0);
        // The inverse: Σ · Σ⁻¹ = I for a correlated covariance.
        let c = [0.04, 0.01, 0.02, 0.0];
        let [ia, ib, id] = information_in_frame(c, 1e-4, 0.0);
        let (a, b, d) = (c[0] + 1e-8, c[1], c[2] + 1e-8);
        assert!((a * ia + b * ib - 1.0).abs() < 1e-4 && (a * ib + b * id).abs() < 1e-4);
        assert!((b * ib + d * id - 1.0).abs() < 1e-4);
    }
}
