//! The dense reference of the tests: LAGO's two linear least-squares problems written
//! over the node poses (not the increments), in `f64`, solved by their normal equations
//! with nalgebra's Cholesky factor. It shares no code with the solver.

use crate::geometry::Pose2;
use crate::slam::graph::{ChainEdge, LoopEdge};
use nalgebra::{DMatrix, DVector, Matrix2, Vector2};
use std::f64::consts::{PI, TAU};

/// An angle wrapped to (−π, π].
pub fn wrap(a: f64) -> f64 {
    let w = a - TAU * (a / TAU).round();
    if w <= -PI { w + TAU } else { w }
}

/// `R(θ)`.
fn rotation(theta: f64) -> Matrix2<f64> {
    let (s, c) = theta.sin_cos();
    Matrix2::new(c, -s, s, c)
}

/// The headings, then the positions, of the graph that starts at `start` and has these
/// chain and loop edges, as LAGO's two linear steps give them: the headings by the
/// chain's odometry unwrapped (LAGO's spanning tree) and each loop's measurement taken
/// with the turns those headings imply.
pub fn solve(start: Pose2<f32>, chain: &[ChainEdge], loops: &[LoopEdge]) -> Vec<Pose2<f64>> {
    let n = chain.len() + 1;
    let m = n - 1;
    let (x0, y0, t0) = (
        f64::from(start.x),
        f64::from(start.y),
        f64::from(start.theta),
    );

    // Odometry headings, unwrapped.
    let mut odometry = vec![t0];
    for c in chain {
        let last = *odometry.last().unwrap();
        odometry.push(last + f64::from(c.motion.theta));
    }

    // Headings: unknowns θ_1 … θ_{n−1}; an edge (a, b) says θ_b − θ_a ≈ z with weight w.
    let mut h = DMatrix::<f64>::zeros(m, m);
    let mut g = DVector::<f64>::zeros(m);
    let mut heading_edge = |a: usize, b: usize, z: f64, w: f64| {
        let target = if a == 0 { z + t0 } else { z };
        h[(b - 1, b - 1)] += w;
        g[b - 1] += w * target;
        if a > 0 {
            h[(a - 1, a - 1)] += w;
            h[(a - 1, b - 1)] -= w;
            h[(b - 1, a - 1)] -= w;
            g[a - 1] -= w * target;
        }
    };
    for (k, c) in chain.iter().enumerate() {
        let std = f64::from(c.heading_std);
        heading_edge(k, k + 1, f64::from(c.motion.theta), 1.0 / (std * std));
    }
    for l in loops {
        let (i, j) = (usize::from(l.from), usize::from(l.to));
        let z = f64::from(l.relative.theta);
        let turns = ((odometry[j] - odometry[i] - z) / TAU).round();
        heading_edge(i, j, z + TAU * turns, f64::from(l.heading_information));
    }
    let theta_solved = h.cholesky().expect("heading normal matrix").solve(&g);
    let theta = |k: usize| if k == 0 { t0 } else { theta_solved[k - 1] };

    // Positions: unknowns p_1 … p_{n−1}; an edge (a, b) says p_b − p_a ≈ t with
    // information Λ.
    let mut h = DMatrix::<f64>::zeros(2 * m, 2 * m);
    let mut g = DVector::<f64>::zeros(2 * m);
    let p0 = Vector2::new(x0, y0);
    let mut position_edge = |a: usize, b: usize, t: Vector2<f64>, lambda: Matrix2<f64>| {
        let target = if a == 0 { t + p0 } else { t };
        let (ib, ia) = (2 * (b - 1), 2 * a.saturating_sub(1));
        let mut add = |r: usize, c: usize, block: Matrix2<f64>| {
            let mut view = h.view_mut((r, c), (2, 2));
            view += block;
        };
        add(ib, ib, lambda);
        if a > 0 {
            add(ia, ia, lambda);
            add(ia, ib, -lambda);
            add(ib, ia, -lambda);
        }
        let lt = lambda * target;
        g[ib] += lt[0];
        g[ib + 1] += lt[1];
        if a > 0 {
            g[ia] -= lt[0];
            g[ia + 1] -= lt[1];
        }
    };
    for (k, c) in chain.iter().enumerate() {
        let r = rotation(theta(k));
        let t = r * Vector2::new(f64::from(c.motion.x), f64::from(c.motion.y));
        let std = f64::from(c.position_std);
        position_edge(k, k + 1, t, Matrix2::identity() / (std * std));
    }
    for l in loops {
        let (i, j) = (usize::from(l.from), usize::from(l.to));
        let r = rotation(theta(i));
        let t = r * Vector2::new(f64::from(l.relative.x), f64::from(l.relative.y));
        let [xx, xy, yy] = l.position_information.map(f64::from);
        let omega = Matrix2::new(xx, xy, xy, yy);
        position_edge(i, j, t, r * omega * r.transpose());
    }
    let p = h.cholesky().expect("position normal matrix").solve(&g);

    let mut poses = vec![Pose2::new(x0, y0, wrap(t0))];
    for k in 1..n {
        poses.push(Pose2::new(
            p[2 * (k - 1)],
            p[2 * (k - 1) + 1],
            wrap(theta(k)),
        ));
    }
    poses
}
