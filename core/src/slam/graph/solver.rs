//! The two steps of [`super::PoseGraph::optimise`] (headings, then positions) and the
//! conjugate gradients they share, over the chain's increments in scaled unknowns
//! `Δ_k = c_k^(−1/2) y_k` (see the module doc of [`super`]).
//!
//! Vectors are slices of blocks `[f32; D]`, one block an increment: `D = 1` for the
//! headings, `D = 2` for the positions. Element `k` is the increment of node `k + 1`, so a
//! loop `(i, j)` covers the elements `i ..= j − 1`.

use super::{ChainEdge, GraphError, LoopEdge, SolverSettings, StepReport, wrap_heading};
use crate::geometry::{Pose2, sin_cos_f32};

/// The part of the graph a step reads.
pub(super) struct Graph<'a> {
    /// Poses of nodes `0 … n−1`.
    pub poses: &'a [Pose2<f32>],
    /// Chain edges of nodes `1 … n−1` (element `k`: the edge into node `k + 1`).
    pub chain: &'a [ChainEdge],
    /// Loop edges.
    pub loops: &'a [LoopEdge],
}

impl Graph<'_> {
    /// The pose of node `k` (the graph checked the loops' nodes when it took them).
    fn pose(&self, k: u16) -> Result<Pose2<f32>, GraphError> {
        self.poses
            .get(usize::from(k))
            .copied()
            .ok_or(GraphError::UnknownNode)
    }
}

#[inline]
fn add<const D: usize>(a: [f32; D], b: [f32; D]) -> [f32; D] {
    let mut out = a;
    for (o, b) in out.iter_mut().zip(b) {
        *o += b;
    }
    out
}

#[inline]
fn sub<const D: usize>(a: [f32; D], b: [f32; D]) -> [f32; D] {
    let mut out = a;
    for (o, b) in out.iter_mut().zip(b) {
        *o -= b;
    }
    out
}

#[inline]
fn scale<const D: usize>(s: f32, a: [f32; D]) -> [f32; D] {
    let mut out = a;
    for o in out.iter_mut() {
        *o *= s;
    }
    out
}

#[inline]
fn dot<const D: usize>(a: [f32; D], b: [f32; D]) -> f32 {
    a.iter().zip(b).fold(0.0, |s, (a, b)| s + a * b)
}

/// `W v` for a loop's information `W`: `[xx, xy, yy]` of a symmetric 2 × 2 matrix
/// (`D = 2`), or `[w, _, _]` (`D = 1`).
#[inline]
fn information_times<const D: usize>(w: [f32; 3], v: [f32; D]) -> [f32; D] {
    let [xx, xy, yy] = w;
    let mut out = [0.0; D];
    match (out.as_mut_slice(), v.as_slice()) {
        ([o], [a]) => *o = xx * a,
        ([ox, oy], [a, b]) => {
            *ox = xx * a + xy * b;
            *oy = xy * a + yy * b;
        }
        _ => {}
    }
    out
}

/// `R Ω Rᵀ` for `Ω = [xx, xy, yy]` and `R` the rotation with sine `s` and cosine `c`.
#[inline]
fn rotate_information([xx, xy, yy]: [f32; 3], s: f32, c: f32) -> [f32; 3] {
    let (cc, ss, cs) = (c * c, s * s, c * s);
    [
        cc * xx - 2.0 * cs * xy + ss * yy,
        cs * (xx - yy) + (cc - ss) * xy,
        ss * xx + 2.0 * cs * xy + cc * yy,
    ]
}

/// `R(θ) t` for `(s, c) = (sin θ, cos θ)`.
#[inline]
fn rotate(t: &Pose2<f32>, (s, c): (f32, f32)) -> [f32; 2] {
    [c * t.x - s * t.y, s * t.x + c * t.y]
}

/// The prefix sum up to node `t` from the inclusive prefix sums of the elements
/// (`prefix[k]`: elements `0 ..= k`, i.e. nodes `1 ..= k + 1`); 0 for node 0.
#[inline]
fn prefix_at<const D: usize>(prefix: &[[f32; D]], node: u16) -> [f32; D] {
    usize::from(node)
        .checked_sub(1)
        .and_then(|k| prefix.get(k))
        .copied()
        .unwrap_or([0.0; D])
}

/// Sets `out` to the difference array of the loops' terms: `+u_l` at the first element of
/// loop `l`'s range, `−u_l` just after its last; a running sum of `out` then gives, at each
/// element, the sum of the terms of the loops that cover it.
fn scatter<const D: usize>(loops: &[LoopEdge], terms: &[[f32; D]], out: &mut [[f32; D]]) {
    out.fill([0.0; D]);
    for (edge, &u) in loops.iter().zip(terms) {
        if let Some(o) = out.get_mut(usize::from(edge.from)) {
            *o = add(*o, u);
        }
        if let Some(o) = out.get_mut(usize::from(edge.to)) {
            *o = sub(*o, u);
        }
    }
}

/// The scaled normal matrix of one step, `I + V W Vᵀ`: `V` the loops' range indicators
/// scaled by the chain's standard deviations, `W` the loops' information.
struct Scaled<'a, const D: usize> {
    /// Chain edges of the increments.
    chain: &'a [ChainEdge],
    /// The standard deviation of a chain edge that this step uses.
    std: fn(&ChainEdge) -> f32,
    loops: &'a [LoopEdge],
    /// Each loop's information in this step's world frame.
    information: &'a [[f32; 3]],
}

impl<const D: usize> Scaled<'_, D> {
    /// `q = (I + V W Vᵀ) p` in two passes over the elements and one over the loops
    /// (`terms`: one block a loop); returns `pᵀ q`.
    fn apply(&self, p: &[[f32; D]], q: &mut [[f32; D]], terms: &mut [[f32; D]]) -> f32 {
        // Prefix sums of the scaled increments.
        let mut acc = [0.0; D];
        for ((qk, &pk), c) in q.iter_mut().zip(p).zip(self.chain) {
            acc = add(acc, scale((self.std)(c), pk));
            *qk = acc;
        }
        // Each loop's range sum, times its information.
        for ((u, edge), &w) in terms.iter_mut().zip(self.loops).zip(self.information) {
            let range = sub(prefix_at(q, edge.to), prefix_at(q, edge.from));
            *u = information_times(w, range);
        }
        // Spread back over the ranges, scaled, plus the identity.
        scatter(self.loops, terms, q);
        let mut acc = [0.0; D];
        let mut pq = 0.0;
        for ((qk, &pk), c) in q.iter_mut().zip(p).zip(self.chain) {
            acc = add(acc, *qk);
            let v = add(pk, scale((self.std)(c), acc));
            pq += dot(pk, v);
            *qk = v;
        }
        pq
    }
}

/// The conjugate gradients' vectors, one block an increment, and one block a loop.
struct Vectors<'a, const D: usize> {
    /// The solution (scaled), from 0.
    x: &'a mut [[f32; D]],
    /// The residual; the right-hand side on entry.
    r: &'a mut [[f32; D]],
    /// The search direction.
    p: &'a mut [[f32; D]],
    /// `A p`.
    q: &'a mut [[f32; D]],
    /// The loops' terms of a product.
    terms: &'a mut [[f32; D]],
}

/// Conjugate gradients on `a x = r` from `x = 0` (`v.r` holds the right-hand side).
fn conjugate_gradients<const D: usize>(
    a: &Scaled<'_, D>,
    v: Vectors<'_, D>,
    settings: &SolverSettings,
) -> Result<StepReport, GraphError> {
    let Vectors { x, r, p, q, terms } = v;
    x.fill([0.0; D]);
    let mut rr = 0.0;
    for (pk, &rk) in p.iter_mut().zip(r.iter()) {
        *pk = rk;
        rr += dot(rk, rk);
    }
    if !rr.is_finite() {
        return Err(GraphError::NumericalFailure);
    }
    let (rr0, tolerance) = (rr, settings.relative_tolerance);
    let threshold = tolerance * tolerance * rr0;
    let mut iterations = 0;
    let mut converged = rr <= threshold;
    while !converged && iterations < settings.max_iterations {
        let pq = a.apply(p, q, terms);
        if !pq.is_finite() {
            return Err(GraphError::NumericalFailure);
        }
        if pq <= 0.0 {
            break; // p vanished (underflow): nothing more to gain
        }
        let alpha = rr / pq;
        let mut rr_next = 0.0;
        for ((xk, rk), (&pk, &qk)) in x.iter_mut().zip(r.iter_mut()).zip(p.iter().zip(q.iter())) {
            *xk = add(*xk, scale(alpha, pk));
            *rk = sub(*rk, scale(alpha, qk));
            rr_next += dot(*rk, *rk);
        }
        iterations += 1;
        if !rr_next.is_finite() {
            return Err(GraphError::NumericalFailure);
        }
        let beta = rr_next / rr;
        rr = rr_next;
        converged = rr <= threshold;
        if !converged {
            for (pk, &rk) in p.iter_mut().zip(r.iter()) {
                *pk = add(rk, scale(beta, *pk));
            }
        }
    }
    let residual = if rr0 > 0.0 {
        libm::sqrtf(rr / rr0)
    } else {
        0.0
    };
    Ok(StepReport {
        iterations,
        residual,
        converged,
    })
}

/// Splits `blocks` blocks of `K` floats off the front of `buf`.
fn take<'s, const K: usize>(
    buf: &mut &'s mut [f32],
    blocks: usize,
) -> Result<&'s mut [[f32; K]], GraphError> {
    let len = blocks.checked_mul(K).ok_or(GraphError::ScratchTooShort)?;
    let (head, tail) = core::mem::take(buf)
        .split_at_mut_checked(len)
        .ok_or(GraphError::ScratchTooShort)?;
    *buf = tail;
    Ok(head.as_chunks_mut::<K>().0)
}

/// The heading step: writes the solved headings of every node, wrapped to (−π, π], into
/// `headings` (one a node), using `scratch` (`4 (n − 1) + 4 L` floats).
pub(super) fn solve_headings(
    graph: &Graph<'_>,
    headings: &mut [f32],
    scratch: &mut [f32],
    settings: &SolverSettings,
) -> Result<StepReport, GraphError> {
    let (m, loops) = (graph.chain.len(), graph.loops.len());
    let mut rest = scratch;
    let information = take::<3>(&mut rest, loops)?;
    let terms = take::<1>(&mut rest, loops)?;
    let (x, r) = (take::<1>(&mut rest, m)?, take::<1>(&mut rest, m)?);
    let (p, q) = (take::<1>(&mut rest, m)?, take::<1>(&mut rest, m)?);
    // Right-hand side: the loops' information times their wrapped residuals, spread over
    // their ranges, then each chain edge's own.
    for ((w, u), edge) in information
        .iter_mut()
        .zip(terms.iter_mut())
        .zip(graph.loops)
    {
        let (from, to) = (graph.pose(edge.from)?, graph.pose(edge.to)?);
        let residual = wrap_heading(edge.relative.theta - (to.theta - from.theta));
        *w = [edge.heading_information, 0.0, 0.0];
        *u = [edge.heading_information * residual];
    }
    scatter(graph.loops, terms, r);
    let mut acc = [0.0];
    for ((rk, c), pair) in r.iter_mut().zip(graph.chain).zip(graph.poses.windows(2)) {
        let [before, after] = pair else { continue };
        let residual = wrap_heading(c.motion.theta - (after.theta - before.theta));
        acc = add(acc, *rk);
        *rk = add([residual / c.heading_std], scale(c.heading_std, acc));
    }
    let a = Scaled::<1> {
        chain: graph.chain,
        std: |c| c.heading_std,
        loops: graph.loops,
        information,
    };
    let report = conjugate_gradients(&a, Vectors { x, r, p, q, terms }, settings)?;
    // The new headings: the old ones plus the summed corrections.
    let mut acc = 0.0;
    let mut ok = true;
    let mut nodes = headings.iter_mut().zip(graph.poses);
    if let Some((h, pose)) = nodes.next() {
        *h = pose.theta;
    }
    for ((h, pose), (&[y], c)) in nodes.zip(x.iter().zip(graph.chain)) {
        acc += c.heading_std * y;
        *h = wrap_heading(pose.theta + acc);
        ok &= h.is_finite();
    }
    if ok {
        Ok(report)
    } else {
        Err(GraphError::NumericalFailure)
    }
}

/// The position step, given the solved `headings`: returns the report and the new
/// positions of nodes `1 … n−1`, at the front of `scratch` (`8 (n − 1) + 5 L` floats).
pub(super) fn solve_positions<'s>(
    graph: &Graph<'_>,
    headings: &[f32],
    scratch: &'s mut [f32],
    settings: &SolverSettings,
) -> Result<(StepReport, &'s [[f32; 2]]), GraphError> {
    let (m, loops) = (graph.chain.len(), graph.loops.len());
    let mut rest = scratch;
    let x = take::<2>(&mut rest, m)?;
    let information = take::<3>(&mut rest, loops)?;
    let terms = take::<2>(&mut rest, loops)?;
    let r = take::<2>(&mut rest, m)?;
    let (p, q) = (take::<2>(&mut rest, m)?, take::<2>(&mut rest, m)?);
    // Right-hand side, as for the headings, with every edge rotated by the solved heading
    // of its first node.
    for ((w, u), edge) in information
        .iter_mut()
        .zip(terms.iter_mut())
        .zip(graph.loops)
    {
        let (from, to) = (graph.pose(edge.from)?, graph.pose(edge.to)?);
        let heading = headings
            .get(usize::from(edge.from))
            .ok_or(GraphError::UnknownNode)?;
        let (s, c) = sin_cos_f32(*heading);
        let measured = rotate(&edge.relative, (s, c));
        let residual = sub(measured, [to.x - from.x, to.y - from.y]);
        *w = rotate_information(edge.position_information, s, c);
        *u = information_times(*w, residual);
    }
    scatter(graph.loops, terms, r);
    let mut acc = [0.0; 2];
    let edges = graph.chain.iter().zip(headings);
    for ((rk, (c, &heading)), pair) in r.iter_mut().zip(edges).zip(graph.poses.windows(2)) {
        let [before, after] = pair else { continue };
        let measured = rotate(&c.motion, sin_cos_f32(heading));
        let residual = sub(measured, [after.x - before.x, after.y - before.y]);
        acc = add(acc, *rk);
        let sigma = c.position_std;
        *rk = add(scale(1.0 / sigma, residual), scale(sigma, acc));
    }
    let a = Scaled::<2> {
        chain: graph.chain,
        std: |c| c.position_std,
        loops: graph.loops,
        information,
    };
    let report = conjugate_gradients(&a, Vectors { x, r, p, q, terms }, settings)?;
    // The new positions: the old ones plus the summed corrections.
    let mut acc = [0.0; 2];
    let mut ok = true;
    for ((xk, c), pose) in x
        .iter_mut()
        .zip(graph.chain)
        .zip(graph.poses.iter().skip(1))
    {
        acc = add(acc, scale(c.position_std, *xk));
        *xk = [pose.x + acc[0], pose.y + acc[1]];
        ok &= xk.iter().all(|v| v.is_finite());
    }
    if ok {
        Ok((report, x))
    } else {
        Err(GraphError::NumericalFailure)
    }
}
