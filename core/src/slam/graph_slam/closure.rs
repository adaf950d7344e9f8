//! Loop closure: a new keyframe matched against the old ones near it, a loop edge, and
//! the graph solved, spread over the scans after the keyframe so that no scan pays for
//! all of it: the keyframe's scan and the next draw the old map (`old_keyframes_per_scan`
//! old keyframes each), the next ones search it (`work_per_scan` look-ups each), the one
//! after the match solves the graph.

use super::stored::load_stored;
use super::{ClosureOutcome, ClosureWork, GraphSlam, SlamError};
use crate::geometry::{Pose2, sin_cos_f32};
use crate::slam::graph::LoopEdge;
use crate::slam::keyframes::{KeyframeStorage, KeyframeStore};
use crate::slam::matcher::{MAX_MATCH_POINTS, MatchProgress};

/// A loop closure under way. `repr(u8)`: an explicit tag, `Idle` = 0, so that
/// [`GraphSlam::zeroed`] is all zero bytes (without it the tag may hide in a `bool` of
/// the match's state, where `Idle` would be a non-zero value).
#[derive(Clone, Debug)]
// Fixed memory, no heap: the match's state lives in the estimator (one of these).
#[allow(clippy::large_enum_variant)]
#[repr(u8)]
pub(super) enum Pending {
    /// None (tag 0).
    Idle,
    /// The map of the old keyframes near keyframe `node` being drawn, from old keyframe
    /// `next` to `last` (those within the submap radius of `here`, its graph pose), for
    /// the match of its end points (`points`, `n` of them) around keyframe `old`.
    OldMap {
        node: u16,
        old: u16,
        next: u16,
        last: u16,
        here: Pose2<f32>,
        points: [(f32, f32); MAX_MATCH_POINTS],
        n: u16,
    },
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
    /// starts a closure: the old map is cleared and this scan's end points kept for the
    /// match; the map of the old keyframes near it (at their graph poses) is then drawn,
    /// `old_keyframes_per_scan` of them at this scan ([`GraphSlam::draw_old_map`]) and as
    /// many at each of the next ([`GraphSlam::advance_closure`]), and matched over the
    /// scans after that. The filter is left as it is: its local map holds only what it
    /// saw lately, and the graph's frame follows from the newest keyframe
    /// ([`GraphSlam::pose`]). Nothing is started while another closure is under way
    /// (counted in `closures_skipped`). `true` when a closure started.
    pub(super) fn start_closure(&mut self, node: u16) -> Result<bool, SlamError> {
        let lc = self.config.loop_closure;
        let k = usize::from(node);
        let Some(newest_old) = k.checked_sub(usize::from(lc.min_age_keyframes)) else {
            return Ok(false);
        };
        let Some(here) = self.graph.pose(k) else {
            return Ok(false);
        };
        let Some(old) = self
            .graph
            .poses()
            .iter()
            .take(newest_old + 1)
            .enumerate()
            .filter(|(_, p)| within(p, &here, lc.candidate_radius_m))
            .min_by(|(_, a), (_, b)| distance2(a, &here).total_cmp(&distance2(b, &here)))
            .map(|(j, _)| j)
        else {
            return Ok(false);
        };
        if !matches!(self.pending, Pending::Idle) {
            self.counters.closures_skipped = self.counters.closures_skipped.saturating_add(1);
            return Ok(false);
        }
        self.counters.attempts = self.counters.attempts.saturating_add(1);
        let res = self.config.grid.resolution;
        let half = 0.5 * super::MATCH_CELLS as f32 * res;
        self.workspace.matching().map.init(
            res,
            here.x - half,
            here.y - half,
            self.config.grid.log_odds.occupied_above,
        )?;
        // The end points are written in place (a second copy of them on the stack would
        // deepen the peak of a scan's stack by a kilobyte).
        self.pending = Pending::OldMap {
            node,
            old: u16::try_from(old).unwrap_or(u16::MAX),
            next: 0,
            last: u16::try_from(newest_old).unwrap_or(u16::MAX),
            here,
            points: [(0.0, 0.0); MAX_MATCH_POINTS],
            n: 0,
        };
        if let Pending::OldMap { points, n, .. } = &mut self.pending {
            let stride = self
                .points
                .as_slice()
                .len()
                .div_ceil(MAX_MATCH_POINTS)
                .max(1);
            for (slot, p) in points
                .iter_mut()
                .zip(self.points.robot_points().step_by(stride))
            {
                *slot = p;
                *n += 1;
            }
        }
        Ok(true)
    }

    /// Draws the next `old_keyframes_per_scan` old keyframes of the closure under way
    /// into its old map; after the last, builds the matcher's levels and starts the match.
    pub(super) fn draw_old_map<S: KeyframeStorage>(
        &mut self,
        store: &KeyframeStore<S>,
    ) -> Result<(), SlamError> {
        let lc = self.config.loop_closure;
        let Pending::OldMap {
            node,
            old,
            next,
            last,
            here,
            points,
            n,
        } = &mut self.pending
        else {
            return Ok(());
        };
        let buffers = self.workspace.matching();
        let (mut j, end) = (usize::from(*next), usize::from(*last) + 1);
        let mut drawn = 0u16;
        while j < end && drawn < lc.old_keyframes_per_scan {
            let pose = self.graph.pose(j);
            j += 1;
            let Some(pose) = pose.filter(|p| within(p, here, lc.submap_radius_m)) else {
                continue;
            };
            load_stored(&mut self.stored, &mut self.ranges, j - 1, store)?;
            let (s, c) = sin_cos_f32(pose.theta);
            for (px, py) in self.stored.robot_points() {
                buffers
                    .map
                    .set_world(pose.x + c * px - s * py, pose.y + s * px + c * py);
            }
            drawn += 1;
        }
        *next = u16::try_from(j).unwrap_or(u16::MAX);
        if j < end {
            return Ok(());
        }
        for _ in 0..lc.old_map_dilation_cells {
            crate::slam::matcher::dilate(buffers.map.bits_mut(), super::MATCH_CELLS);
        }
        buffers.levels.build(&buffers.map);
        // A scan with nothing to match is no closure, not an error of the run.
        let started = buffers.levels.start(
            &buffers.map,
            points.get(..usize::from(*n)).unwrap_or(&[]),
            here,
            &lc.window,
        );
        self.pending = match started {
            Ok(progress) => Pending::Matching {
                node: *node,
                old: *old,
                progress,
            },
            Err(_) => Pending::Idle,
        };
        Ok(())
    }

    /// Runs the closure under way for one scan: a slice of the match (and, when it ends
    /// accepted, the loop edge), or the graph's solve after a loop edge: the outcome when
    /// a match ended at this scan, and what the scan did.
    pub(super) fn advance_closure<S: KeyframeStorage>(
        &mut self,
        store: &KeyframeStore<S>,
    ) -> Result<(Option<ClosureOutcome>, ClosureWork), SlamError> {
        let work = match self.pending {
            Pending::Idle => ClosureWork::None,
            Pending::OldMap { .. } => ClosureWork::OldMap,
            Pending::Matching { .. } => ClosureWork::Match,
            Pending::Solving => ClosureWork::Solve,
        };
        Ok((self.advance_pending(store)?, work))
    }

    fn advance_pending<S: KeyframeStorage>(
        &mut self,
        store: &KeyframeStore<S>,
    ) -> Result<Option<ClosureOutcome>, SlamError> {
        let lc = self.config.loop_closure;
        match &mut self.pending {
            Pending::Idle => Ok(None),
            Pending::OldMap { .. } => {
                self.draw_old_map(store)?;
                Ok(None)
            }
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

/// Squared distance between the positions of `a` and `b`.
fn distance2(a: &Pose2<f32>, b: &Pose2<f32>) -> f32 {
    let (dx, dy) = (a.x - b.x, a.y - b.y);
    dx * dx + dy * dy
}

/// `true` when `p` lies within `radius` metres of `here`.
fn within(p: &Pose2<f32>, here: &Pose2<f32>, radius: f32) -> bool {
    distance2(p, here) <= radius * radius
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
